//! The demo's case (`shimmy-sim` with no arguments): the nominal plant (or `--vehicle`) on a
//! speed ramp 20 -> 120 km/h through the Hopf window with road noise, wheel imbalance and a
//! pothole, and its two arms (damper off, ASMC). Shared by the demo command, the reference
//! benchmark and the golden test.

use crate::model::disturbance::{Scenario, SpeedProfile};
use crate::model::family::SimModel;
use crate::model::plant::Method;
use crate::model::registry::{ReferenceModel, REFERENCE_N};
use crate::sim::run::closed_loop::{self, Arm, LoopConfig, LoopResult};
use crate::sim::run::standard::{fastest_growth_speed, pothole, road, POTHOLE_NM};
use anyhow::{Context, Result};
use shimmy_core::control::ControllerKind;
use shimmy_core::stability::{hopf_crossings, CrossingKind, HopfCrossing};
use shimmy_core::units::{kmh_to_mps, mps_to_kmh};
use shimmy_core::vehicle::Vehicle;

/// The demo's case on the vehicle model `M` (the car by default): the vehicles, the ramp
/// scenario and the facts the report states.
#[derive(Clone, Debug)]
pub struct DemoCase<M: SimModel<N> = ReferenceModel, const N: usize = { REFERENCE_N }> {
    /// The simulated vehicle.
    pub plant: M::Vehicle,
    /// The vehicle the firmware believes (its controller's and estimator's models, gains).
    pub model: M::Vehicle,
    /// Ramp 20 -> 120 km/h with road noise, imbalance and a pothole.
    pub scenario: Scenario,
    /// Hopf crossings of the plant without damper (1-50 m/s).
    pub crossings: Vec<HopfCrossing>,
    /// The no-damper Hopf window in km/h, when there is one.
    pub window_kmh: Option<(f64, f64)>,
    /// Speed of fastest shimmy growth, m/s (where the pothole hits).
    pub v_fastest_mps: f64,
    /// Time of the pothole, s.
    pub t_pothole_s: f64,
    /// The plant integrator of both arms ([`closed_loop::CLOSED_LOOP_METHOD`] unless changed).
    pub method: Method,
}

/// The demo's two arms with their report labels: damper off (0 A) and ASMC.
pub const ARMS: [(&str, Arm); 2] = [
    ("damper off (0 A)", Arm::Mr(ControllerKind::PassiveOff)),
    ("ASMC", Arm::Mr(ControllerKind::Asmc)),
];

/// Builds the demo's case on the reference vehicle for a ramp of `ramp_s` seconds (all
/// numbers computed).
pub fn demo_case(ramp_s: f64) -> Result<DemoCase> {
    let nominal = Vehicle::nominal();
    demo_case_for(&nominal, &nominal, ramp_s)
}

/// Seed of the demo's road noise.
pub const ROAD_SEED: u64 = 7;

/// The demo's case on the simulated vehicle `plant` with a firmware that believes `model`;
/// the Hopf window and the pothole's speed are the simulated plant's.
pub fn demo_case_for(plant: &Vehicle, model: &Vehicle, ramp_s: f64) -> Result<DemoCase> {
    demo_case_on::<ReferenceModel, { REFERENCE_N }>(plant, model, ramp_s)
}

/// [`demo_case_for`] on a vehicle of any model of the family (the road's torques are the
/// car's; the loop scales them to the model, [`SimModel::yaw_torque_scale`]).
pub fn demo_case_on<M: SimModel<N>, const N: usize>(
    plant: &M::Vehicle,
    model: &M::Vehicle,
    ramp_s: f64,
) -> Result<DemoCase<M, N>> {
    let p = M::family_vehicle(plant).model;
    let crossings: Vec<HopfCrossing> = hopf_crossings(&p.linear(), 0.0, 1.0, 50.0, 0.25, 1e-3)
        .context("hopf_crossings")?
        .iter()
        .copied()
        .collect();
    let onset = crossings.iter().find(|c| c.kind == CrossingKind::Onset);
    let offset = crossings.iter().find(|c| c.kind != CrossingKind::Onset);
    let window_kmh = match (onset, offset) {
        (Some(a), Some(b)) => Some((mps_to_kmh(a.speed_mps), mps_to_kmh(b.speed_mps))),
        _ => None,
    };
    let v_fg = fastest_growth_speed(&p.linear());
    let (v0, v1) = (kmh_to_mps(20.0), kmh_to_mps(120.0));
    let mut sc = Scenario::new(SpeedProfile::Ramp {
        v0_mps: v0,
        v1_mps: v1,
        t0_s: 0.0,
        t1_s: ramp_s,
    });
    let (n, im) = road(ROAD_SEED, p.rolling_radius_m());
    sc.noise = Some(n);
    sc.imbalance = Some(im);
    let t_hit = ramp_s * (v_fg - v0) / (v1 - v0);
    sc.impulses.push(pothole(t_hit, POTHOLE_NM));
    Ok(DemoCase {
        plant: *plant,
        model: *model,
        scenario: sc,
        crossings,
        window_kmh,
        v_fastest_mps: v_fg,
        t_pothole_s: t_hit,
        method: closed_loop::CLOSED_LOOP_METHOD,
    })
}

/// Runs one arm of the demo (the golden regression trace and the benchmark use the ASMC arm).
pub fn run_arm<M: SimModel<N>, const N: usize>(
    case: &DemoCase<M, N>,
    arm: Arm,
    ramp_s: f64,
    record_every: usize,
) -> Result<(LoopConfig<M, N>, LoopResult)> {
    let mut cfg = LoopConfig::for_vehicle(&M::family_vehicle(&case.plant), arm, ramp_s)
        .with_model_vehicle(&M::family_vehicle(&case.model));
    cfg.record_every = record_every;
    cfg.method = case.method;
    let mut s = case.scenario.clone();
    let r = closed_loop::run(&cfg, &mut s, None)
        .with_context(|| format!("{}: integration failed", arm.name()))?;
    Ok((cfg, r))
}
