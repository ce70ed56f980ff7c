//! The mode meter on the simulated vehicle (reduced `shimmy-sim meter-accuracy`): the slow
//! damping estimate against the true shimmy-mode damping of the linearised plant, where the
//! measured in-phase yaw also carries the tramp, steering-wheel and tyre-lag dynamics.
//!
//! - the meter as configured meets the targets (|bias| <= 0.5 b, spread <= 1.5 b,
//!   one-sigma coverage 60-76 %) pooled over 20 and 105 km/h without damper and 60 km/h with
//!   the viscous damper, 6 seeds x 60 s each, and the bias of each of those cells;
//! - negative: with the previous AR(8) slow instance the well-damped 105 and 120 km/h points
//!   read high (bias > 0.5 b), the optimistic margin the AR(10) removes.
//!
//! The full table (20 seeds, 5 speeds per arm) is `shimmy-sim meter-accuracy`.
use shimmy_core::estimator::meter::mode_meter::EstimatorConfig;
use shimmy_core::vehicle::Vehicle;
use shimmy_core::vehicles::car::ParamSet;
use shimmy_sim::cmd::meter_accuracy::{
    cell_stats, run_case, Case, CaseRun, CellStats, COVERAGE_PCT, MAX_ABS_BIAS_B, MAX_SPREAD_B,
};
use shimmy_sim::model::family::FamilyVehicle;

/// Pools the runs of several cells into one: errors in units of each cell's own b.
fn pooled(cfg: EstimatorConfig, cases: &[Case], seeds: u64) -> (f64, f64, f64, Vec<CellStats>) {
    let p = FamilyVehicle::car(Vehicle::from_set(ParamSet::Nominal));
    let mut cells = Vec::new();
    let (mut sum, mut sum2, mut covered, mut n) = (0.0, 0.0, 0usize, 0usize);
    for &case in cases {
        let runs: Vec<CaseRun> = (1..=seeds)
            .map(|s| run_case(&p, cfg, case, s, 60.0).expect("run"))
            .collect();
        let st = cell_stats(&cfg, case, &runs).expect("estimates");
        for r in &runs {
            for &(z, s, _) in &r.estimates {
                let e = (z - r.zeta_true) / st.b;
                sum += e;
                sum2 += e * e;
                covered += usize::from((z - r.zeta_true).abs() <= s);
                n += 1;
            }
        }
        println!("{st:?}");
        cells.push(st);
    }
    let mean = sum / n as f64;
    let sd = (sum2 / n as f64 - mean * mean).sqrt();
    (mean, sd, 100.0 * covered as f64 / n as f64, cells)
}

#[test]
fn slow_estimate_meets_the_targets_on_the_simulated_plant() {
    let off = |v| Case {
        current_a: None,
        speed_kmh: v,
    };
    let cases = [
        off(20.0),
        off(105.0),
        Case {
            current_a: Some(0.5),
            speed_kmh: 60.0,
        },
    ];
    let (bias, spread, cover, cells) = pooled(EstimatorConfig::default(), &cases, 6);
    println!("pooled: bias {bias:+.2} b, spread {spread:.2} b, coverage {cover:.0} %");
    // per cell too: the well-damped 105 km/h point is where the previous AR(8) read high
    // (+0.69 b in the negative test below, +0.73 b over 20 seeds)
    for c in &cells {
        assert!(
            c.bias_b.abs() <= MAX_ABS_BIAS_B,
            "bias {:+.2} b at {} km/h",
            c.bias_b,
            c.case.speed_kmh
        );
    }
    assert!(bias.abs() <= MAX_ABS_BIAS_B, "bias {bias}");
    assert!(spread <= MAX_SPREAD_B, "spread {spread}");
    assert!(
        (COVERAGE_PCT.0..=COVERAGE_PCT.1).contains(&cover),
        "coverage {cover}"
    );
}

#[test]
fn negative_the_previous_ar8_meter_reads_high_on_the_plant() {
    let cfg = EstimatorConfig {
        ar_order: 8,
        ..EstimatorConfig::default()
    };
    let cases = [105.0, 120.0].map(|v| Case {
        current_a: None,
        speed_kmh: v,
    });
    let (bias, _, cover, _) = pooled(cfg, &cases, 4);
    println!("AR(8): bias {bias:+.2} b, coverage {cover:.0} %");
    assert!(bias > MAX_ABS_BIAS_B, "expected the AR(8) bias, got {bias}");
}
