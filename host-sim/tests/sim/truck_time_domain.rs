//! The mining truck in the time domain (`docs/mining-truck.md`): the nonlinear plant
//! (`model::truck_plant`, Magic-Formula tyres and gas-law struts) from a small wheel-yaw start
//! must grow just above the linear model's Hopf speed and decay just below it, at the rate the
//! eigenvalues give; and the least gas charge of `gas-charge` must separate growth (less gas)
//! from decay (more gas) at its load and speed.
use shimmy_core::params::{kmh_to_mps, mps_to_kmh};
use shimmy_core::stability::{self, CrossingKind, DEFAULT_TOL_MPS};
use shimmy_core::truck::{TruckParams, TruckSet};
use shimmy_sim::model::truck_plant::{envelope_growth_1ps, yaw_start};
use shimmy_sim::sim::truck_study;

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
