//! The standard scenario set of `shimmy-sim compare` (kicks, pothole, speed ramp, slalom and
//! the robustness variants) and the building blocks the demo shares with it: the speed of
//! fastest shimmy growth, the standard pothole and the road (noise + imbalance).

use crate::model::disturbance::{
    DriverTorque, Imbalance, Impulse, RoadNoise, Scenario, SpeedProfile,
};
use crate::model::registry::{ReferenceModel, REFERENCE_N};
use crate::model::study::StudyModel;
use crate::sim::run::scenario::ScenarioSpec;
use crate::sim::run::scenario_file::ScenarioModel;
use anyhow::Result;
use shimmy_core::model::LinearModel;
use shimmy_core::stability::{mode_at, ModeSelect};
use shimmy_core::units::{kmh_to_mps, mps_to_kmh};
use shimmy_core::vehicle::Vehicle;

/// The speed (m/s) where the no-damper shimmy mode grows fastest (largest real part of the
/// in-phase wheel-yaw mode of the linearisation), on a 0.25 m/s grid over 2-45 m/s.
pub fn fastest_growth_speed<L: LinearModel<N>, const N: usize>(p: &L) -> f64 {
    let mut best = (f64::NEG_INFINITY, 15.0);
    let mut v = 2.0;
    while v <= 45.0 {
        if let Ok(m) = mode_at(p, v, 0.0, ModeSelect::Shimmy) {
            if m.re > best.0 {
                best = (m.re, v);
            }
        }
        v += 0.25;
    }
    best.1
}

/// Pothole: a 20 ms half-sine yaw-torque pulse on both wheels.
pub fn pothole(t0_s: f64, peak_nm: f64) -> Impulse {
    Impulse {
        t0_s,
        duration_s: 0.02,
        peak_nm: [peak_nm, peak_nm],
    }
}

/// Peak torque of the standard pothole, N m.
pub const POTHOLE_NM: f64 = 1000.0;
/// Initial yaw of the "large" kick, deg (breaks through the 0 A damper's friction).
pub const BIG_KICK_DEG: f64 = 3.0;

/// Road noise + imbalance used in the ramp and the demo, on wheels of rolling radius
/// `radius_m`.
pub fn road(seed: u64, radius_m: f64) -> (RoadNoise, Imbalance) {
    (
        RoadNoise::new(4.0, 20.0, 0.5, seed),
        Imbalance {
            amplitude_nm: [3.0, 3.0],
            phase_rad: [0.0, 1.0],
            radius_m,
        },
    )
}

/// The standard scenario set on `vehicle` (its plant, damper, sensors; the firmware believes
/// it). `quick` shortens the runs (for tests).
pub fn standard_scenarios(vehicle: &Vehicle, quick: bool) -> Vec<ScenarioSpec> {
    standard_scenarios_on::<ReferenceModel, { REFERENCE_N }>(vehicle, quick)
        .expect("the car's variants are infallible")
}

/// [`standard_scenarios`] on a vehicle of any model of the family (the torques are the car's;
/// the loop scales them to the model): without the slalom on a model that takes no driver
/// torque, with the model's robustness plants ([`StudyModel::robustness_variants`]).
pub fn standard_scenarios_on<M: StudyModel<N> + ScenarioModel<N>, const N: usize>(
    vehicle: &M::Vehicle,
    quick: bool,
) -> Result<Vec<ScenarioSpec<M, N>>> {
    let nominal = vehicle;
    let model = M::family_vehicle(vehicle).model;
    let v_fg = fastest_growth_speed(&model.linear());
    let dur = if quick { 4.0 } else { 10.0 };
    let mut out = vec![
        ScenarioSpec {
            description: format!(
                "0.5 deg in-phase wheel-yaw disturbance at {:.1} km/h (fastest growth)",
                mps_to_kmh(v_fg)
            ),
            initial_yaw_rad: 0.5f64.to_radians(),
            t_dist_s: Some(0.0),
            ..ScenarioSpec::new("kick-0.5deg", nominal, Scenario::constant_speed(v_fg), dur)
        },
        ScenarioSpec {
            description: format!(
                "{BIG_KICK_DEG} deg wheel-yaw disturbance at {:.1} km/h",
                mps_to_kmh(v_fg)
            ),
            initial_yaw_rad: BIG_KICK_DEG.to_radians(),
            t_dist_s: Some(0.0),
            ..ScenarioSpec::new("kick-3deg", nominal, Scenario::constant_speed(v_fg), dur)
        },
        {
            let mut s = Scenario::constant_speed(v_fg);
            s.impulses.push(pothole(0.5, POTHOLE_NM));
            ScenarioSpec {
                description: format!(
                    "pothole: 20 ms half-sine, {POTHOLE_NM} N m per wheel at {:.1} km/h",
                    mps_to_kmh(v_fg)
                ),
                t_dist_s: Some(0.5),
                ..ScenarioSpec::new("pothole", nominal, s, dur)
            }
        },
    ];
    // Speed ramp 20 -> 120 km/h with road noise, imbalance and a pothole inside the window.
    {
        let t_ramp = if quick { 8.0 } else { 30.0 };
        let mut s = Scenario::new(SpeedProfile::Ramp {
            v0_mps: kmh_to_mps(20.0),
            v1_mps: kmh_to_mps(120.0),
            t0_s: 0.0,
            t1_s: t_ramp,
        });
        let (n, im) = road(11, model.rolling_radius_m());
        s.noise = Some(n);
        s.imbalance = Some(im);
        // The pothole where the ramp passes the fastest-growth speed.
        let t_hit = t_ramp * (v_fg - kmh_to_mps(20.0)) / kmh_to_mps(100.0);
        s.impulses.push(pothole(t_hit, POTHOLE_NM));
        out.push(ScenarioSpec {
            description: format!(
                "speed ramp 20 -> 120 km/h in {t_ramp} s, road noise 4 N m rms, imbalance 3 N m, pothole at {:.1} km/h",
                mps_to_kmh(v_fg)
            ),
            ..ScenarioSpec::new("ramp", nominal, s, t_ramp)
        });
    }
    // Slalom with driver torque inside the window (road noise on).
    if M::DRIVER_TORQUE {
        let mut s = Scenario::constant_speed(kmh_to_mps(60.0));
        s.driver = DriverTorque::Slalom {
            amplitude_nm: 4.0,
            freq_hz: 0.5,
            t0_s: 0.5,
        };
        s.noise = Some(RoadNoise::new(2.0, 20.0, 0.5, 12));
        out.push(ScenarioSpec {
            description: "slalom at 60 km/h: 4 N m, 0.5 Hz steering-wheel torque, road noise"
                .into(),
            ..ScenarioSpec::new("slalom", nominal, s, dur)
        });
    }
    // Robustness: the car's hard set (half K_d) and +-20 % on C_a, sigma, e, or the model's
    // analogues (3 deg kick at the perturbed plant's fastest-growth speed; the firmware keeps
    // believing `vehicle`).
    for (name, p) in model.robustness_variants()? {
        let v = fastest_growth_speed(&p.linear());
        let plant = M::with_model(vehicle, p);
        out.push(ScenarioSpec {
            description: format!(
                "{BIG_KICK_DEG} deg disturbance, plant `{name}` at its fastest-growth speed {:.1} km/h",
                mps_to_kmh(v)
            ),
            initial_yaw_rad: BIG_KICK_DEG.to_radians(),
            t_dist_s: Some(0.0),
            model_vehicle: Some(*vehicle),
            ..ScenarioSpec::new(&format!("kick-3deg-{name}"), &plant, Scenario::constant_speed(v), dur)
        });
    }
    Ok(out)
}
