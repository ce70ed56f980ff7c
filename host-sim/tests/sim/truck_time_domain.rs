//! The mining truck in the time domain (`docs/mining-truck.md`): the nonlinear plant
//! (`model::truck_plant`, Magic-Formula tyres and gas-law struts) from a small wheel-yaw start
//! must grow just above the linear model's Hopf speed and decay just below it, at the rate the
//! eigenvalues give; and the least gas charge of `gas-charge` must separate growth (less gas)
//! from decay (more gas) at its load and speed.
use shimmy_core::stability::{self, CrossingKind, DEFAULT_TOL_MPS};
use shimmy_core::units::{kmh_to_mps, mps_to_kmh};
use shimmy_core::vehicles::truck::{TruckParams, TruckSet};
use shimmy_sim::model::truck_plant::{envelope_growth_1ps, yaw_start};
use shimmy_sim::sim::study::truck_study;

/// Settle 5 s (the tyre-lag and linkage transients decay), compare the 3-s envelopes at the
/// start and end of 30 s (about 90 shimmy cycles at 3 Hz).
fn growth(t: &TruckParams, v_mps: f64) -> f64 {
    envelope_growth_1ps(t, v_mps, yaw_start(0.05_f64.to_radians()), 5.0, 30.0, 3.0).unwrap()
}

#[test]
fn hopf_speed_matches_the_time_domain_onset() {
    let t = TruckSet::Full.params();
    let cs = stability::hopf_crossings(&t, 0.0, 0.5, 25.0, 0.25, DEFAULT_TOL_MPS).unwrap();
    let onset = cs
        .iter()
        .find(|c| c.kind == CrossingKind::Onset)
        .unwrap()
        .speed_mps;
    for dv_kmh in [-2.0, 2.0] {
        let v = onset + kmh_to_mps(dv_kmh);
        let g = growth(&t, v);
        let re = stability::critical_mode_at(&t, v, 0.0).unwrap().re;
        println!(
            "onset {:.3} km/h, at {:.3} km/h: envelope {g:.5} 1/s, eigenvalue {re:.5} 1/s",
            mps_to_kmh(onset),
            mps_to_kmh(v)
        );
        assert_eq!(
            g > 0.0,
            dv_kmh > 0.0,
            "{dv_kmh} km/h from the onset: growth {g}"
        );
        assert!(
            (g - re).abs() < 0.05 * re.abs() + 5e-4,
            "envelope {g} vs eigenvalue {re}"
        );
    }
}

#[test]
fn the_least_gas_charge_separates_growth_from_decay_in_the_time_domain() {
    let t = TruckSet::Full.params();
    let ans = truck_study::gas_charge(&t, 30.0, 1.0, 60.0, 1.0).unwrap();
    let lo = ans
        .least_l()
        .expect("a charge that keeps the full truck stable at 30 km/h");
    let v = kmh_to_mps(30.0);
    let less = growth(&t.with_gas_volume((lo - 6.0) * 1e-3), v);
    let more = growth(&t.with_gas_volume((lo + 6.0) * 1e-3), v);
    println!("least charge {lo:.3} l: envelope {less:.5} 1/s at -6 l, {more:.5} 1/s at +6 l");
    assert!(less > 0.0, "{less}");
    assert!(more < 0.0, "{more}");
}

/// The truck through the whole closed loop (the truck's vehicle: its MR damper, sensors, gains
/// and thresholds, the ASMC's nominal plant = the truck's I_k, c_k, l_t): on the shipped
/// pothole scenario (loaded, 35 km/h, inside the window the damper at 0 A leaves open) the
/// damper at 0 A ends in a limit cycle and the ASMC suppresses it, with less shimmy energy
/// (mean square wheel yaw) by more than 4x; with no damper at all the limit cycle is larger.
#[test]
fn truck_closed_loop_asmc_suppresses_the_shimmy_that_the_damper_at_0_a_leaves() {
    use shimmy_sim::sim::run::closed_loop::Arm;
    use shimmy_sim::sim::run::scenario::{self, ScenarioSpec};
    use shimmy_sim::sim::run::scenario_file;
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenarios")
        .join("truck")
        .join("pothole-loaded.toml");
    let Ok(mut spec) = scenario_file::load_any(&path)
        .unwrap()
        .into_spec::<TruckParams, { shimmy_core::vehicles::truck::N_STATES }>()
    else {
        panic!("a car scenario")
    };
    spec.duration_s = 7.0;
    let run = |spec: &ScenarioSpec<TruckParams, { shimmy_core::vehicles::truck::N_STATES }>,
               name| {
        let arm = Arm::from_name(name, 0.0).unwrap();
        let control = spec.model_family().control_params();
        let (cfg, r) = scenario::run_arm(spec, arm, &control).unwrap();
        let ms =
            r.series.psi_l_rad.iter().map(|x| x * x).sum::<f64>() / r.series.psi_l_rad.len() as f64;
        (r.metrics(&cfg, spec.t_dist_s), ms)
    };
    let (none, e_none) = run(&spec, "no-damper");
    let (off, e_off) = run(&spec, "passive-off");
    let (asmc, e_asmc) = run(&spec, "asmc");
    println!(
        "mean square yaw: no damper {e_none:.3e}, 0 A {e_off:.3e}, ASMC {e_asmc:.3e} rad^2; \
         end amplitude {:.3} / {:.3} / {:.3} deg",
        none.amp_end_rad.to_degrees(),
        off.amp_end_rad.to_degrees(),
        asmc.amp_end_rad.to_degrees()
    );
    assert!(none.shimmies() && off.shimmies(), "{none:?} {off:?}");
    assert!(!asmc.shimmies(), "{asmc:?}");
    assert!(
        e_asmc < 0.25 * e_off && e_off < e_none,
        "{e_asmc} {e_off} {e_none}"
    );
    // the controller's model is the truck's, not the car's
    let c = spec.model_family().control_params();
    assert_eq!(
        f64::from(c.nominal.i_k_kgm2),
        (TruckSet::Full.params().i_k as f32) as f64
    );
}

/// The margin warning on the truck: open loop on a speed ramp 10 -> 35 km/h through the loaded
/// truck's onset (road noise and imbalance, the tracker on the truck's linear model, the data
/// meter on its wheel yaw), the first warning comes before the true onset (positive lead), and
/// the run's onset is the linear model's independent scan.
#[test]
fn the_trucks_margin_warning_leads_its_onset_on_a_ramp() {
    use shimmy_sim::model::family::FamilyVehicle;
    use shimmy_sim::sim::input::vehicle_file::{load_model, ModelVehicle};
    use shimmy_sim::sim::run::margin_run::{self, MarginScenario};
    let ModelVehicle::Truck(FamilyVehicle { model: t, parts }) = load_model("truck-full").unwrap()
    else {
        panic!("truck-full is a truck")
    };
    let sc = MarginScenario::ramp(t, 10.0, 35.0, 1.0, 20.0);
    let run = margin_run::run(&sc, parts.pipeline_params(), 0).unwrap();
    let onset = stability::hopf_crossings(&t, 0.0, 1.0, 20.0, 0.1, DEFAULT_TOL_MPS)
        .unwrap()
        .iter()
        .find(|c| c.kind == CrossingKind::Onset)
        .map(|c| mps_to_kmh(c.speed_mps))
        .unwrap();
    assert!(
        (run.onset_kmh.unwrap() - onset).abs() < 0.01,
        "{:?}",
        run.onset_kmh
    );
    let (dv, dt) = run.lead().expect("a warning before the end of the ramp");
    println!(
        "truck ramp: first warning {:?}, lead {dv:.2} km/h, {dt:.2} s",
        run.first_warning
    );
    assert!(dv > 0.0 && dt > 0.0, "lead {dv} km/h, {dt} s");
    assert!(
        run.model_cycles > 100,
        "the tracker ran: {}",
        run.model_cycles
    );
}
