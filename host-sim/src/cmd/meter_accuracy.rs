//! `shimmy-sim meter-accuracy`: the mode meter's accuracy on the simulated plant.
//!
//! The vehicle's nonlinear plant (the car's 10-state plant or the mining truck's, any
//! [`SimModel`]; Magic-Formula tyres) runs open loop at constant speed with
//! road noise and wheel imbalance, damper off (`Damper::None`) or on: the MR damper's
//! energy-equivalent viscous coefficient at a constant coil current (`damper_equivalent`, the
//! coefficient `shimmy-sim stability --damper-current-a` uses) as a viscous track-rod damper
//! (`Damper::Viscous`). Why not the MR damper itself: at road-noise amplitudes it works
//! pre-yield, as a spring as much as a damper, and no viscous linearisation gives its "true"
//! damping (at 0.5 A the meter reads the mode at 9.7 Hz where the c_eq model says 5.8 Hz); the
//! viscous damper is exactly what the linear model assumes. The mode meter
//! (`MarginEstimator<f32>`, the vehicle's configuration as the firmware runs it: the default
//! one slowed by the model's `meter_time_scale`, 2 on the ~3 Hz truck) sees the two
//! measured wheel yaws; its slow estimate is sampled once per second after a warm-up. The
//! truth is the shimmy mode of the linearised plant A(V) with the same damper
//! (`ModeSelect::Shimmy`: chosen by its in-phase wheel-yaw shape).
//!
//! Per speed: bias and spread of zeta_hat - zeta_true in units of the ambient-data bound
//! b = sqrt(zeta / (w_n T_eff)) of the slow instance, and the one-sigma coverage (share of
//! estimates with |error| <= the reported sigma). Exits non-zero when a row misses a target.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::Args;
use rayon::prelude::*;
use shimmy_core::estimator::meter::mode_meter::{
    EstimatorConfig, MarginEstimator, Sample, WheelOrder,
};
use shimmy_core::model::LinearModel;
use shimmy_core::stability::{self, ModeSelect};
use shimmy_core::units::kmh_to_mps;

use crate::model::damper_equiv::{damper_equivalent, REF_WHEEL_YAW_AMPL_RAD};
use crate::model::disturbance::{Imbalance, RoadNoise, Scenario, SpeedProfile};
use crate::model::family::{FamilyVehicle, SimModel, SimPlant};
use crate::model::plant::{Damper, Method};
use crate::model::registry::{self, Registered, StudyVisitor};
use crate::model::study::StudyModel;
use crate::out::progress;
use crate::sim::input::arg_range::{self, Range};
use crate::sim::input::vehicle_file;

/// Control period, s.
const DT_S: f64 = 1e-3;
/// Seeds per speed: 1 to 1000.
pub const SEEDS: Range = Range::closed(1.0, 1000.0, "seeds");
/// Recorded time per run after the warm-up: 10 to 3600 s.
pub const RECORD_S: Range = Range::closed(10.0, 3600.0, "s");

/// The meter's accuracy targets.
pub const MAX_ABS_BIAS_B: f64 = 0.5;
/// Largest spread, in b.
pub const MAX_SPREAD_B: f64 = 1.5;
/// One-sigma coverage window, %.
pub const COVERAGE_PCT: (f64, f64) = (60.0, 76.0);

/// Arguments of `shimmy-sim meter-accuracy`.
#[derive(Args, Debug, Clone)]
pub struct MeterAccuracyArgs {
    /// The vehicle (`--vehicle`, a named set or a vehicle file).
    #[command(flatten)]
    pub vehicle: crate::cmd::VehicleArg,
    /// Speeds of the damper-off arm, km/h (outside the plant's Hopf window), each 1 to 250
    /// [default: 10,20,90,105,120 on the car, 8,12,16,20 on the mining truck].
    #[arg(long, value_delimiter = ',', value_parser = arg_range::speed_kmh())]
    pub speeds_off_kmh: Option<Vec<f64>>,
    /// Speeds of the damper-on arm, km/h, each 1 to 250 [default: 10,40,60,90,120 on the car,
    /// 10,30,50 on the mining truck].
    #[arg(long, value_delimiter = ',', value_parser = arg_range::speed_kmh())]
    pub speeds_on_kmh: Option<Vec<f64>>,
    /// Constant coil current of the damper-on arm, A: 0 to the vehicle's coil rating.
    #[arg(long, default_value_t = 0.5, value_parser = arg_range::current_a())]
    pub current_a: f64,
    /// Seeds per speed: 1 to 1000.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(1..=1000))]
    pub seeds: u32,
    /// Recorded time per run after the warm-up (30 s + 2 slow time constants), s: 10 to 3600.
    #[arg(long, default_value_t = 60.0, value_parser = arg_range::f64_in(RECORD_S))]
    pub record_s: f64,
    /// AR order of the meter's slow instance, 2 to 10 (default: the meter's own, 10; 8 and 6
    /// show the previous meters).
    #[arg(long, value_parser = clap::value_parser!(u8).range(2..=10))]
    pub slow_ar_order: Option<u8>,
    /// The meter slowed by this factor instead of the model's own
    /// (`LinearModel::meter_time_scale`: 1 for the car, 2 for the mining truck), 1 to 8: what
    /// the model's factor was chosen by.
    #[arg(long, value_parser = clap::value_parser!(u16).range(1..=8))]
    pub meter_time_scale: Option<u16>,
    /// Output folder (`--out`; default out/meter-accuracy, [`Self::out_dir`]).
    #[command(flatten)]
    pub out: crate::cmd::OutArg,
}

impl MeterAccuracyArgs {
    /// The output folder: `--out`, else out/meter-accuracy.
    pub fn out_dir(&self) -> PathBuf {
        self.out.dir_or("out/meter-accuracy")
    }
}

/// One cell of the study: a damper setting and a speed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Case {
    /// Coil current whose MR-damper equivalent is fitted as a viscous damper, A; `None` = no
    /// damper at all.
    pub current_a: Option<f64>,
    /// Constant speed, km/h.
    pub speed_kmh: f64,
}

/// The meter's slow estimates of one run and the truth they are compared with.
#[derive(Clone, Debug)]
pub struct CaseRun {
    /// True shimmy-mode damping ratio.
    pub zeta_true: f64,
    /// True damped frequency, Hz.
    pub freq_true_hz: f64,
    /// True natural frequency, Hz.
    pub wn_true_hz: f64,
    /// Viscous damper coefficient of plant and truth, N s/m (0 without damper).
    pub c_eq_nspm: f64,
    /// (zeta, sigma, freq Hz) of the valid slow estimates, one per second.
    pub estimates: Vec<(f64, f64, f64)>,
    /// Per-second sampling instants (valid or not).
    pub attempts: usize,
}

/// Accuracy of one cell over its seeds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CellStats {
    /// The cell.
    pub case: Case,
    /// True damping (mean over seeds: it differs only through c_eq with the damper on).
    pub zeta_true: f64,
    /// True damped frequency, Hz.
    pub freq_true_hz: f64,
    /// Mean reported frequency, Hz.
    pub freq_est_hz: f64,
    /// The bound b of the slow instance at the true mode.
    pub b: f64,
    /// Mean error / b.
    pub bias_b: f64,
    /// Standard deviation of the error / b.
    pub spread_b: f64,
    /// Median reported sigma / b.
    pub sigma_b: f64,
    /// Share of estimates with |error| <= sigma, %.
    pub coverage_pct: f64,
    /// Number of estimates.
    pub n: usize,
    /// Share of the per-second samples that were valid, %.
    pub valid_pct: f64,
}

impl CellStats {
    /// The row meets all three targets.
    pub fn passes(&self) -> bool {
        self.bias_b.abs() <= MAX_ABS_BIAS_B
            && self.spread_b <= MAX_SPREAD_B
            && (COVERAGE_PCT.0..=COVERAGE_PCT.1).contains(&self.coverage_pct)
    }
}

/// Warm-up before recording: 30 s plus two slow time constants of the meter.
pub fn warmup_s(cfg: &EstimatorConfig) -> f64 {
    30.0 + 2.0 * slow_t_eff_s(cfg)
}

/// Effective memory of the slow instance, T_eff = 2 / ((1 - lambda) f_s), s.
pub fn slow_t_eff_s(cfg: &EstimatorConfig) -> f64 {
    let fs = cfg.input_rate_hz as f64 / cfg.decimation as f64;
    2.0 / ((1.0 - cfg.lambda_slow as f64) * fs)
}

/// Runs one seed of one cell through a meter configured by `cfg`: `record_s` of per-second
/// slow estimates after the warm-up. Road noise 5 N m per wheel (30 Hz corner, half common),
/// imbalance 2 N m (phases 0, 1 rad), both for the car: times the model's
/// [`SimModel::yaw_torque_scale`].
pub fn run_case<M: SimModel<N>, const N: usize>(
    vehicle: &FamilyVehicle<M>,
    cfg: EstimatorConfig,
    case: Case,
    seed: u64,
    record_s: f64,
) -> Result<CaseRun> {
    let p = &vehicle.model;
    let v = kmh_to_mps(case.speed_kmh);
    let c_eq = match case.current_a {
        Some(i) => {
            damper_equivalent(
                p,
                &vehicle.parts.damper.spencer,
                i,
                REF_WHEEL_YAW_AMPL_RAD.to_degrees(),
                kmh_to_mps(5.0),
                kmh_to_mps(150.0),
            )?
            .c_eq_nspm
        }
        None => 0.0,
    };
    let damper = if case.current_a.is_some() {
        Damper::Viscous(c_eq)
    } else {
        Damper::None
    };
    let mut sim = p.plant(damper, Method::default());
    let mut scen = Scenario::new(SpeedProfile::Constant(v));
    let scale = p.yaw_torque_scale();
    scen.noise = Some(RoadNoise::new(5.0 * scale, 30.0, 0.5, seed));
    scen.imbalance = Some(Imbalance {
        amplitude_nm: [2.0 * scale; 2],
        phase_rad: [0.0, 1.0],
        radius_m: p.rolling_radius_m(),
    });
    let mut est = MarginEstimator::<f32>::new(cfg).context("meter config")?;
    let warm = warmup_s(&cfg);
    let n = ((warm + record_s) / DT_S).round() as usize;
    let per_s = (1.0 / DT_S).round() as usize;
    let mut estimates = Vec::new();
    let mut attempts = 0usize;
    for k in 0..n {
        let t = k as f64 * DT_S;
        let u = scen.inputs(t, DT_S);
        sim.advance(DT_S, &u)
            .with_context(|| format!("integration failed at t = {t}"))?;
        let [psi_l, psi_r] = sim.wheel_yaw_rad();
        let t1 = t + DT_S;
        est.push(&Sample {
            psi_l_rad: psi_l as f32,
            psi_r_rad: psi_r as f32,
            wheel: WheelOrder::Speed {
                speed_mps: v as f32,
                radius_m: p.rolling_radius_m() as f32,
            },
            damper_cmd: 0.0,
        });
        if t1 >= warm && (k + 1) % per_s == 0 {
            attempts += 1;
            let s = est.output().slow;
            if s.valid {
                estimates.push((s.zeta as f64, s.sigma_zeta as f64, s.freq_hz as f64));
            }
        }
    }
    let m = stability::mode_at(&p.linear(), v, c_eq, ModeSelect::Shimmy)?;
    Ok(CaseRun {
        zeta_true: m.zeta,
        freq_true_hz: m.freq_hz,
        wn_true_hz: m.freq_hz / (1.0 - m.zeta * m.zeta).max(1e-12).sqrt(),
        c_eq_nspm: c_eq,
        estimates,
        attempts,
    })
}

/// Bias, spread and coverage of one cell over its runs (b from `cfg`'s slow memory).
pub fn cell_stats(cfg: &EstimatorConfig, case: Case, runs: &[CaseRun]) -> Option<CellStats> {
    let t_eff = slow_t_eff_s(cfg);
    let nr = runs.len() as f64;
    let zeta_true = runs.iter().map(|r| r.zeta_true).sum::<f64>() / nr;
    let freq_true = runs.iter().map(|r| r.freq_true_hz).sum::<f64>() / nr;
    let wn = runs.iter().map(|r| r.wn_true_hz).sum::<f64>() / nr * 2.0 * std::f64::consts::PI;
    let b = (zeta_true.max(1e-4) / (wn * t_eff)).sqrt();
    let mut err = Vec::new();
    let mut sig = Vec::new();
    let mut fsum = 0.0;
    let mut covered = 0usize;
    for r in runs {
        for &(z, s, f) in &r.estimates {
            let e = z - r.zeta_true;
            err.push(e);
            sig.push(s);
            fsum += f;
            covered += usize::from(e.abs() <= s);
        }
    }
    let n = err.len();
    if n < 2 {
        return None;
    }
    let mean = err.iter().sum::<f64>() / n as f64;
    let var = err.iter().map(|e| (e - mean) * (e - mean)).sum::<f64>() / (n - 1) as f64;
    sig.sort_by(f64::total_cmp);
    Some(CellStats {
        case,
        zeta_true,
        freq_true_hz: freq_true,
        freq_est_hz: fsum / n as f64,
        b,
        bias_b: mean / b,
        spread_b: var.sqrt() / b,
        sigma_b: sig[n / 2] / b,
        coverage_pct: 100.0 * covered as f64 / n as f64,
        n,
        valid_pct: 100.0 * n as f64 / runs.iter().map(|r| r.attempts).sum::<usize>().max(1) as f64,
    })
}

/// Runs every cell with `seeds` seeds (in parallel) and returns the statistics in order.
pub fn study<M: SimModel<N>, const N: usize>(
    vehicle: &FamilyVehicle<M>,
    cfg: EstimatorConfig,
    cases: &[Case],
    seeds: u32,
    record_s: f64,
) -> Result<Vec<CellStats>> {
    let jobs: Vec<(usize, u64)> = (0..cases.len())
        .flat_map(|c| (1..=u64::from(seeds)).map(move |s| (c, s)))
        .collect();
    let bar = progress::bar(jobs.len(), "meter runs");
    let runs: Vec<(usize, CaseRun)> = jobs
        .par_iter()
        .map(|&(c, s)| {
            let r = run_case(vehicle, cfg, cases[c], s, record_s).map(|r| (c, r));
            bar.inc(1);
            r
        })
        .collect::<Result<_>>()?;
    bar.finish_and_clear();
    cases
        .iter()
        .enumerate()
        .map(|(i, &case)| {
            let mine: Vec<CaseRun> = runs
                .iter()
                .filter(|(c, _)| *c == i)
                .map(|(_, r)| r.clone())
                .collect();
            cell_stats(&cfg, case, &mine).with_context(|| {
                format!(
                    "no valid estimate at {} km/h ({})",
                    case.speed_kmh,
                    damper_label(case.current_a)
                )
            })
        })
        .collect()
}

fn damper_label(current_a: Option<f64>) -> String {
    current_a.map_or("off".into(), |i| format!("viscous = MR {i} A"))
}

/// The Markdown table of the study.
pub fn markdown(rows: &[CellStats]) -> String {
    let mut s = String::from(
        "| damper | V [km/h] | true zeta | f true / est [Hz] | b | bias | spread | sigma | 1-sigma coverage | n (valid) | targets |\n\
         |---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        s += &format!(
            "| {} | {:.0} | {:.4} | {:.2} / {:.2} | {:.4} | {:+.2} b | {:.2} b | {:.2} b | {:.0} % | {} ({:.0} %) | {} |\n",
            damper_label(r.case.current_a),
            r.case.speed_kmh,
            r.zeta_true,
            r.freq_true_hz,
            r.freq_est_hz,
            r.b,
            r.bias_b,
            r.spread_b,
            r.sigma_b,
            r.coverage_pct,
            r.n,
            r.valid_pct,
            if r.passes() { "met" } else { "MISSED" }
        );
    }
    s
}

/// `shimmy-sim meter-accuracy`.
pub fn command(a: &MeterAccuracyArgs) -> Result<()> {
    SEEDS.check("--seeds", f64::from(a.seeds))?;
    RECORD_S.check("--record-s", a.record_s)?;
    struct On<'a>(&'a MeterAccuracyArgs);
    impl StudyVisitor for On<'_> {
        type Output = Result<()>;
        fn visit<M: Registered<N> + StudyModel<N>, const N: usize>(self, v: M::File) -> Result<()> {
            command_on(self.0, &registry::family::<M, N>(v)?)
        }
    }
    match registry::with_image_model(vehicle_file::load_model(&a.vehicle.spec)?, On(a)) {
        Ok(r) => r,
        Err(other) => bail!(
            "`meter-accuracy` runs the {} models, not the {} (vehicle `{}`)",
            crate::model::registry::image_models(),
            other.model_name(),
            a.vehicle.spec
        ),
    }
}

/// The command on a vehicle of the model `M`: its meter is the vehicle's (time-scaled to the
/// model's mode, [`FamilyVehicle::pipeline_params`]).
fn command_on<M: StudyModel<N>, const N: usize>(
    a: &MeterAccuracyArgs,
    vehicle: &FamilyVehicle<M>,
) -> Result<()> {
    let (off, on) = M::meter_speeds_kmh();
    let speeds_off = a.speeds_off_kmh.clone().unwrap_or_else(|| off.to_vec());
    let speeds_on = a.speeds_on_kmh.clone().unwrap_or_else(|| on.to_vec());
    for &v in speeds_off.iter().chain(&speeds_on) {
        arg_range::SPEED_KMH.check("--speeds-off-kmh / --speeds-on-kmh", v)?;
    }
    arg_range::check_current("--current-a", a.current_a, &vehicle.parts)?;
    let cases: Vec<Case> = speeds_off
        .iter()
        .map(|&v| Case {
            current_a: None,
            speed_kmh: v,
        })
        .chain(speeds_on.iter().map(|&v| Case {
            current_a: Some(a.current_a),
            speed_kmh: v,
        }))
        .collect();
    let _out_dir = crate::sim::input::files::OutDir::claim(&a.out_dir())?;
    let wall = std::time::Instant::now();
    let scale = a
        .meter_time_scale
        .unwrap_or_else(|| vehicle.model.linear().meter_time_scale());
    let mut cfg = vehicle.parts.pipeline_params().estimator.time_scaled(scale);
    if let Some(order) = a.slow_ar_order {
        cfg.ar_order = order;
    }
    let rows = study(vehicle, cfg, &cases, a.seeds, a.record_s)?;
    let md = markdown(&rows);
    println!(
        "mode meter (slow, AR({}), f32, time scale {}) on the simulated plant `{}`: {} seeds x {:.0} s per speed, {:.0} s wall",
        cfg.ar_order,
        scale,
        a.vehicle.spec,
        a.seeds,
        a.record_s,
        wall.elapsed().as_secs_f64()
    );
    print!("{md}");
    crate::sim::input::files::write_file(&a.out_dir().join("meter_accuracy.md"), &md)?;
    let mut f = Vec::new();
    writeln!(f, "current_a,speed_kmh,zeta_true,freq_true_hz,freq_est_hz,b,bias_b,spread_b,sigma_b,coverage_pct,n,valid_pct,passes")?;
    for r in &rows {
        writeln!(
            f,
            "{},{},{:.5},{:.4},{:.4},{:.5},{:.3},{:.3},{:.3},{:.1},{},{:.1},{}",
            r.case.current_a.map_or(String::new(), |i| i.to_string()),
            r.case.speed_kmh,
            r.zeta_true,
            r.freq_true_hz,
            r.freq_est_hz,
            r.b,
            r.bias_b,
            r.spread_b,
            r.sigma_b,
            r.coverage_pct,
            r.n,
            r.valid_pct,
            r.passes()
        )?;
    }
    crate::sim::input::files::write_file(&a.out_dir().join("meter_accuracy.csv"), &f)?;
    let missed = rows.iter().filter(|r| !r.passes()).count();
    if missed > 0 {
        bail!(
            "{missed} of {} rows miss a target (|bias| <= {MAX_ABS_BIAS_B} b, spread <= {MAX_SPREAD_B} b, coverage {}-{} %)",
            rows.len(),
            COVERAGE_PCT.0,
            COVERAGE_PCT.1
        );
    }
    Ok(())
}
