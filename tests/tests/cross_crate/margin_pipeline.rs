//! The fused shimmy pipeline (mode meter + incremental model margin + fusion + monitor) on the
//! simulated plant, open loop with the damper off (`Damper::None`: no damper force at all),
//! road noise (5 N m per wheel, 30 Hz corner, half common) and wheel imbalance (2 N m per wheel):
//! - a 1 km/h/s ramp through the Hopf onset warns >= 5 km/h (>= 5 s) ahead of it;
//! - a drive well below the window (15 and 20 km/h) raises no warning at all;
//! - with a wrong model (plant C_a +-20 %): an earlier warning and no standing alarm than with
//!   the model alone; negative test: without the offset averaging over speed the corrected
//!   margin false-warns at 70 % of the onset.
//!
//! The onset speed comes from an independent scan (`stability::hopf_crossings`), not from the
//! pipeline. The 10-minute drives take ~5-10 s each in the debug profile (the same runs are
//! available as `shimmy-sim margin --constant-kmh 15 --duration-s 600`).
use shimmy_core::estimator::monitor::Level;
use shimmy_core::estimator::pipeline::PipelineParams;
use shimmy_core::vehicles::car::ParamSet;
use shimmy_sim::sim::run::margin_run::{run, MarginScenario};

/// Constant-speed drive per speed: 10 minutes [s].
const DRIVE_S: f64 = 600.0;

#[test]
fn ramp_through_the_onset_warns_at_least_5_kmh_ahead() {
    let p = ParamSet::Nominal.params();
    // 30 s at 15 km/h (estimator warm-up), then 1 km/h/s to 35 km/h.
    let sc = MarginScenario::ramp(p, 15.0, 35.0, 1.0, 30.0);
    let r = run(&sc, PipelineParams::default(), 0).expect("run");
    let onset = r.onset_kmh.expect("nominal has an onset");
    let (t, v, level) = r.first_warning.expect("a warning");
    let (dv, dt) = r.lead().expect("lead");
    println!(
        "onset {onset:.3} km/h at t = {:.2} s; first warning {level:?} at t = {t:.2} s, \
         {v:.2} km/h: lead {dv:.2} km/h, {dt:.2} s (wall {:.1} s)",
        r.onset_time_s.unwrap(),
        r.wall_s
    );
    assert!(dv >= 5.0 && dt >= 5.0, "lead {dv} km/h {dt} s");
    // not during the 30 s at 15 km/h: the warning comes from the approach, not noise
    assert!(t > 30.0, "warning at t = {t} (constant 15 km/h)");
    assert!(r.max_solves_per_call <= 1);
    // inside the window the plant shimmies and the monitor says so
    assert_eq!(r.max_level, Level::ShimmyPresent);
    // the model tracks the true shimmy-mode damping (same model: to the f32 report precision
    // plus the change of zeta over one 100 ms model period, |dzeta/dV| dV ~ 0.025 x 0.03)
    let r2 = run(&sc, PipelineParams::default(), 1).expect("run");
    let worst = r2
        .rows
        .iter()
        .filter(|x| x.zeta_model.is_finite())
        .map(|x| (x.zeta_model - x.zeta_true).abs())
        .fold(0.0f64, f64::max);
    assert!(worst < 2e-3, "model zeta vs true {worst}");
}

fn drive(kmh: f64, pp: PipelineParams, duration_s: f64) -> (Option<(f64, f64, Level)>, f64) {
    let mut sc = MarginScenario::constant(ParamSet::Nominal.params(), kmh, duration_s);
    sc.seed = 7;
    let r = run(&sc, pp, 0).expect("run");
    (r.first_warning, r.wall_s)
}

#[test]
fn no_false_warning_well_below_the_window() {
    for kmh in [15.0, 20.0] {
        let (w, wall) = drive(kmh, PipelineParams::default(), DRIVE_S);
        println!("{kmh} km/h for {DRIVE_S} s: first warning {w:?} (wall {wall:.1} s)");
        assert_eq!(w, None, "false warning at {kmh} km/h");
    }
}

/// The nominal-model pipeline on a plant that differs from it (reduced `shimmy-sim mismatch`).
mod wrong_model {
    use super::*;
    use shimmy_sim::cmd::mismatch::{cases, drive_scenario, ramp_scenario, MismatchCase};
    use shimmy_sim::sim::run::margin_run::{onset_kmh, MarginRun};

    fn case(name: &str) -> MismatchCase {
        cases(&shimmy_core::vehicle::Vehicle::nominal().plant)
            .expect("cases")
            .into_iter()
            .find(|c| c.name == name)
            .expect("case")
    }

    /// The pipeline with the data correction switched off: data and model always "agree",
    /// so the margin is the (wrong) model's alone.
    fn model_only() -> PipelineParams {
        let mut pp = PipelineParams::default();
        pp.fusion.mismatch_sigmas = f32::INFINITY;
        pp.fusion.less_stable_sigmas = f32::INFINITY;
        pp.fusion.agreement_sigmas = f32::INFINITY;
        pp
    }

    fn ramp_seeded(c: &MismatchCase, pp: PipelineParams, seed: u64) -> MarginRun {
        let on = onset_kmh(&c.plant).expect("onset");
        let mut sc = ramp_scenario(c, 1.0, false, on);
        sc.seed = seed;
        run(&sc, pp, 0).expect("run")
    }

    /// Plant C_a -20 % (more stable than the model: true onset 42.69 km/h, the model's 29.35)
    /// on the 1 km/h/s ramp, three road-noise records: the warning comes before the true onset
    /// on each. Before the corrected onset kept the model's curvature, seeds 2 and 3 gave no
    /// warning by 3 km/h past the onset: past its own onset the model's damping curve is
    /// flat, and the linear shift offset / |dzeta/dV| with that slope put the corrected
    /// onset 13-25 km/h ahead while the plant was 1 km/h from shimmy.
    #[test]
    fn more_stable_plant_warns_before_its_onset_on_three_seeds() {
        let c = case("C_a -20 %");
        for seed in [1, 2, 3] {
            let r = ramp_seeded(&c, PipelineParams::default(), seed);
            let lead = r.lead().map(|l| l.0);
            // and the warning stands where it matters, over the last 0.5 km/h before the onset
            // (not only a nuisance warning at the ramp's start, withdrawn since)
            let on = r.onset_kmh.expect("onset");
            let near: Vec<_> = r
                .rows
                .iter()
                .filter(|x| x.speed_kmh > on - 0.5 && x.speed_kmh < on)
                .collect();
            let standing = near.iter().all(|x| x.level > Level::Normal);
            println!("C_a -20 %, seed {seed}: lead {lead:?} km/h, warning over the last 0.5 km/h: {standing}");
            assert!(lead.is_some_and(|l| l > 0.0), "seed {seed}: lead {lead:?}");
            assert!(
                !near.is_empty() && standing,
                "seed {seed}: no warning at the onset"
            );
        }
    }

    /// Plant C_a +20 % (true onset 23.69 km/h, the model says 29.35) on three road-noise
    /// records: the model alone warns 1.24 / 0.34 / 0.40 km/h ahead (from the data damping
    /// backstop, not from its margin, which reaches its thresholds only past the true onset);
    /// the data correction warns earlier on every seed (figures: `shimmy-sim mismatch --only
    /// "C_a +20" --seed N`). The mismatch is held over 0.25 m/s of speed change as well as 3 s:
    /// with the time hold alone (the negative arm, seed 1) the 1 km/h/s ramp loses the lead to
    /// the hold. The 3 km/h is not met on every seed (docs/margin-estimator.md, "The warning with a wrong model").
    #[test]
    fn less_stable_plant_warns_earlier_with_the_correction() {
        let c = case("C_a +20 %");
        let lead = |pp, seed| ramp_seeded(&c, pp, seed).lead().expect("a warning").0;
        for seed in [1, 2, 3] {
            let (with, without) = (
                lead(PipelineParams::default(), seed),
                lead(model_only(), seed),
            );
            println!("C_a +20 %, seed {seed}: lead {with:.2} km/h with the correction, {without:.2} model only");
            assert!(
                with > 0.0 && with >= without,
                "seed {seed}: {with} vs {without}"
            );
        }
        let mut time_hold = PipelineParams::default();
        time_hold.fusion.mismatch_hold_speed_mps = 0.0;
        let (with, held) = (lead(PipelineParams::default(), 1), lead(time_hold, 1));
        println!("seed 1: {with:.2} km/h, {held:.2} km/h with a time-only hold");
        assert!(with > held + 1.0, "{with} vs time-only hold {held}");
    }

    /// Plant C_a +20 % on seed 1 (reduced `shimmy-sim mismatch --only "C_a +20"`): the
    /// issue's 3 km/h lead is met once the safe side (data below the model) is decided at 2.0
    /// sigmas instead of 2.5 (lead 3.26 km/h, the flag drops at 20.4 km/h); the fusion before,
    /// with 2.5 sigmas both ways (the negative arm), led by 2.72 km/h. The drives at 70 % of the
    /// onset stay free of warnings (`no_false_warning_well_below_the_window` and the table).
    #[test]
    fn less_stable_plant_leads_by_3_kmh_with_the_safe_side_threshold() {
        use shimmy_sim::cmd::mismatch::MIN_LEAD_KMH;
        let c = case("C_a +20 %");
        let pp = PipelineParams::default();
        let mut symmetric = pp;
        symmetric.fusion.less_stable_sigmas = symmetric.fusion.mismatch_sigmas;
        let lead = |pp| ramp_seeded(&c, pp, 1).lead().expect("a warning").0;
        let (with, before) = (lead(pp), lead(symmetric));
        println!("C_a +20 %, seed 1: lead {with:.2} km/h, {before:.2} with 2.5 sigmas both ways");
        assert!(with >= MIN_LEAD_KMH, "lead {with}");
        assert!(
            before < MIN_LEAD_KMH,
            "the symmetric threshold also led by {before}"
        );
    }

    /// Plant C_a -20 % (more stable: true onset 42.69 km/h) driven at 70 % of its onset,
    /// 29.9 km/h, inside the model's window: the model alone keeps a standing alarm, the
    /// corrected margin raises none (share of reports above Normal).
    #[test]
    fn more_stable_plant_raises_no_standing_alarm() {
        let c = case("C_a -20 %");
        let on = onset_kmh(&c.plant).expect("onset");
        let share = |pp| {
            let r = run(&drive_scenario(&c, false, on, 120.0), pp, 0).expect("run");
            let warn = r.rows.iter().filter(|x| x.level > Level::Normal).count();
            (warn as f64 / r.rows.len() as f64, r.warnings)
        };
        let (with, n_with) = share(PipelineParams::default());
        let (without, _) = share(model_only());
        println!(
            "C_a -20 % at 70 % onset: warning {:.0} % of the time, {n_with} onsets (model only {:.0} %)",
            100.0 * with,
            100.0 * without
        );
        assert_eq!(n_with, 0, "warning share {with}");
        assert!(without > 0.8, "model only: warning share {without}");
    }

    /// Negative: without averaging the offset over speed the corrected margin carries the
    /// slow estimate's full scatter (zeta 0.028 +- 0.01 here) and the same drive false-warns.
    #[test]
    fn negative_without_the_offset_averaging_the_corrected_margin_false_warns() {
        let c = case("C_a -20 %");
        let on = onset_kmh(&c.plant).expect("onset");
        let mut pp = PipelineParams::default();
        pp.fusion.offset_tau_max_s = 0.0;
        let r = run(&drive_scenario(&c, false, on, 120.0), pp, 0).expect("run");
        println!(
            "no offset averaging: {} warning onsets in 120 s",
            r.warnings
        );
        assert!(
            r.warnings > 0,
            "expected false warnings without the averaging"
        );
    }

    /// Three parameters off at once (C_a +20 %, K_d -20 %, t_p +20 %: true onset 13.70 km/h,
    /// the model's 29.35) on the 1 km/h/s ramp, seeds 1-3. Today's offset-only fusion (the
    /// negative arm) corrects the model's level but keeps its slope and curvature: on seed 1
    /// it warns less than 3 km/h ahead and on seed 3 after the onset. The online model update
    /// (frequency and damping over the lead-in and the ramp) warns at least 3 km/h ahead on
    /// each seed; on a 120 s drive at 70 % of the onset the steering linkage stiffness it reports is
    /// within two of its sigmas of the plant's (0.8), its sigma a third of the prior's.
    #[test]
    fn combined_error_needs_the_model_update() {
        use shimmy_core::estimator::model_update::ModelUpdateConfig;
        use shimmy_sim::cmd::mismatch::combined_cases;
        let c = combined_cases(&shimmy_core::vehicle::Vehicle::nominal().plant)
            .expect("cases")
            .into_iter()
            .find(|c| c.name == "C_a +20 % & K_d -20 % & t_p +20 %")
            .expect("case");
        let updating = PipelineParams {
            update: ModelUpdateConfig::ON,
            ..PipelineParams::default()
        };
        let mut offset_only_misses = 0;
        for seed in [1, 2, 3] {
            let lead = |pp| ramp_seeded(&c, pp, seed).lead().map(|l| l.0);
            let before = lead(PipelineParams::default());
            let r = ramp_seeded(&c, updating, seed);
            let after = r.lead().map(|l| l.0);
            println!(
                "seed {seed}: lead offset-only {before:?} km/h, with the update {after:?} km/h"
            );
            if before.is_none_or(|l| l < 3.0) {
                offset_only_misses += 1;
            }
            assert!(
                after.is_some_and(|l| l >= 3.0),
                "seed {seed}: lead {after:?}"
            );
        }
        // past the onset the ramp runs into the limit cycle, where no linear model holds:
        // the parameters are checked on a constant drive at 70 % of the onset
        let on = onset_kmh(&c.plant).expect("onset");
        let mut sc = drive_scenario(&c, false, on, 120.0);
        sc.seed = 1;
        let r = run(&sc, updating, 0).expect("drive");
        let kd = r
            .updated
            .iter()
            .find(|u| u.field == "k_d")
            .expect("k_d updated");
        println!(
            "drive: K_d factor {:.3}, sigma_ln {:.3}",
            kd.factor, kd.sigma_ln
        );
        assert!(
            (kd.factor.ln() - 0.8f64.ln()).abs() <= 2.0 * kd.sigma_ln && kd.sigma_ln < 0.05,
            "K_d factor {:.3} +- {:.3} (ln), truth 0.8",
            kd.factor,
            kd.sigma_ln
        );
        assert!(
            offset_only_misses >= 2,
            "the offset-only fusion met 3 km/h on {} of 3 seeds: the case no longer separates",
            3 - offset_only_misses
        );
    }
}
