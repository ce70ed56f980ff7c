//! `shimmy-sim margin`: the open-loop eigenvalue-margin demonstration (issue 5, "what to show").
//!
//! The plant runs open loop (damper off: `Damper::None`, i.e. no damper force at all) on a
//! speed ramp with road noise and wheel imbalance; the measured wheel yaw angles, speed and
//! acceleration feed the firmware's [`ShimmyPipeline`] every 1 ms exactly as on the target.
//! Next to the report the *true* eigenvalues of the simulated plant are computed: the shimmy
//! mode of A(V) at the true speed ([`ModeSelect::Shimmy`]) and the Hopf onset of the window by
//! an independent scan ([`stability::hopf_crossings`]). Output: a table on stdout, `margin.csv`
//! and `margin.png` under `--out`, and the warning lead time.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Args;
use plotters::prelude::*;
use shimmy_core::estimator::meter::mode_meter::{Sample, WheelOrder};
use shimmy_core::estimator::monitor::Level;
use shimmy_core::estimator::pipeline::{PipelineParams, ShimmyPipeline};
use shimmy_core::params::{kmh_to_mps, mps_to_kmh, PlantParams};
use shimmy_core::stability::{self, CrossingKind, ModeSelect};
use shimmy_core::vehicle::Vehicle;

use crate::model::disturbance::{Imbalance, RoadNoise, Scenario, SpeedProfile};
use crate::model::plant::{idx, Damper, Plant, Simulator, N_STATE};
use crate::sim::arg_range::{self, Range};
use crate::sim::vehicle_file;

/// Control period, s.
pub const DT_S: f64 = 1e-3;

/// Ramp rate: 0.01 to 50 km/h per s.
pub const RATE_KMH_PER_S: Range = Range::closed(0.01, 50.0, "km/h/s");
/// Lead-in before the ramp: 0 to 600 s.
pub const SETTLE_S: Range = Range::closed(0.0, 600.0, "s");
/// Road-noise and imbalance torques: 0 to 200 N m.
pub const TORQUE_NM: Range = Range::closed(0.0, 200.0, "N m");
/// Simulated time of one run (constant drive, or settle plus ramp): above 0, at most 3600 s.
pub const DURATION_S: Range = Range::above(0.0, 3600.0, "s");

/// Arguments of `shimmy-sim margin`.
#[derive(Args, Debug, Clone)]
pub struct MarginArgs {
    /// Vehicle: a named set (nominal, gentle, hard) or a vehicle file (TOML, see
    /// docs/vehicle-file.md; parameter files are vehicle files). `--params` is the older name.
    #[arg(long, visible_alias = "params", default_value = "nominal")]
    pub vehicle: String,
    /// The vehicle the firmware believes (the pipeline's model and thresholds): a named set or
    /// a vehicle file; default: `--vehicle`.
    #[arg(long)]
    pub model_vehicle: Option<String>,
    /// Ramp start speed, km/h: 1 to 250.
    #[arg(long, default_value_t = 15.0, allow_negative_numbers = true, value_parser = arg_range::speed_kmh())]
    pub ramp_from_kmh: f64,
    /// Ramp end speed, km/h: 1 to 250.
    #[arg(long, default_value_t = 40.0, allow_negative_numbers = true, value_parser = arg_range::speed_kmh())]
    pub ramp_to_kmh: f64,
    /// Ramp rate, km/h per s: 0.01 to 50 (settle plus ramp at most 3600 s).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true, value_parser = arg_range::f64_in(RATE_KMH_PER_S))]
    pub rate_kmh_per_s: f64,
    /// Constant-speed lead-in before the ramp (estimator warm-up), s: 0 to 600.
    #[arg(long, default_value_t = 30.0, allow_negative_numbers = true, value_parser = arg_range::f64_in(SETTLE_S))]
    pub settle_s: f64,
    /// Road-noise yaw torque standard deviation per wheel, N m: 0 to 200.
    #[arg(long, default_value_t = 5.0, allow_negative_numbers = true, value_parser = arg_range::f64_in(TORQUE_NM))]
    pub noise_nm: f64,
    /// Wheel imbalance yaw torque amplitude per wheel, N m: 0 to 200.
    #[arg(long, default_value_t = 2.0, allow_negative_numbers = true, value_parser = arg_range::f64_in(TORQUE_NM))]
    pub imbalance_nm: f64,
    /// Random seed of the road noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Instead of the ramp: a constant-speed drive at this speed (km/h, 1 to 250) for
    /// `--duration-s`.
    #[arg(long, allow_negative_numbers = true, value_parser = arg_range::speed_kmh())]
    pub constant_kmh: Option<f64>,
    /// Duration of the constant-speed drive, s: above 0, at most 3600.
    #[arg(long, default_value_t = 600.0, allow_negative_numbers = true, value_parser = arg_range::f64_in(DURATION_S))]
    pub duration_s: f64,
    /// Output directory.
    #[arg(long, default_value = "out/margin")]
    pub out: PathBuf,
}

/// An open-loop margin scenario.
#[derive(Clone, Debug)]
pub struct MarginScenario {
    /// Plant parameters of the simulated plant (and the pipeline's model unless `model`).
    pub params: PlantParams,
    /// The vehicle the pipeline believes (its model); `None`: `params`.
    pub model: Option<Vehicle>,
    /// Speed profile.
    pub speed: SpeedProfile,
    /// Simulated duration, s.
    pub duration_s: f64,
    /// Road-noise std per wheel, N m (corner 30 Hz, half common to both wheels).
    pub noise_nm: f64,
    /// Imbalance amplitude per wheel, N m (phases 0 and 1 rad).
    pub imbalance_nm: f64,
    /// Noise seed.
    pub seed: u64,
}

impl MarginScenario {
    /// Constant speed `v_kmh` for `settle_s`, then a ramp to `to_kmh` at `rate` km/h/s.
    pub fn ramp(params: PlantParams, from_kmh: f64, to_kmh: f64, rate: f64, settle_s: f64) -> Self {
        let t1 = settle_s + (to_kmh - from_kmh).abs() / rate.max(1e-6);
        Self {
            params,
            model: None,
            speed: SpeedProfile::Ramp {
                v0_mps: kmh_to_mps(from_kmh),
                v1_mps: kmh_to_mps(to_kmh),
                t0_s: settle_s,
                t1_s: t1,
            },
            duration_s: t1,
            noise_nm: 5.0,
            imbalance_nm: 2.0,
            seed: 1,
        }
    }

    /// Constant speed for `duration_s`.
    pub fn constant(params: PlantParams, v_kmh: f64, duration_s: f64) -> Self {
        Self {
            params,
            model: None,
            speed: SpeedProfile::Constant(kmh_to_mps(v_kmh)),
            duration_s,
            noise_nm: 5.0,
            imbalance_nm: 2.0,
            seed: 1,
        }
    }

    fn scenario(&self) -> Scenario {
        let mut s = Scenario::new(self.speed.clone());
        s.current_a = 0.0;
        if self.noise_nm > 0.0 {
            s.noise = Some(RoadNoise::new(self.noise_nm, 30.0, 0.5, self.seed));
        }
        if self.imbalance_nm > 0.0 {
            s.imbalance = Some(Imbalance {
                amplitude_nm: [self.imbalance_nm; 2],
                phase_rad: [0.0, 1.0],
                radius_m: self.params.r,
            });
        }
        s
    }
}

/// One recorded row (every decimated pipeline output, 100 Hz).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MarginRow {
    /// Time, s.
    pub t_s: f64,
    /// True speed, km/h.
    pub speed_kmh: f64,
    /// True shimmy-mode damping of A(V) at the true speed (filled every `true_every` rows).
    pub zeta_true: f64,
    /// True shimmy-mode frequency, Hz.
    pub freq_true_hz: f64,
    /// True speed margin to the onset, km/h (onset - V; negative inside the window).
    pub margin_true_kmh: f64,
    /// Slow data damping.
    pub zeta_data: f64,
    /// Its sigma.
    pub sigma_data: f64,
    /// Fast data damping.
    pub zeta_fast: f64,
    /// Data valid (slow).
    pub data_valid: bool,
    /// Fast valid.
    pub fast_valid: bool,
    /// Model damping (pipeline's model margin).
    pub zeta_model: f64,
    /// Data frequency, Hz.
    pub freq_data_hz: f64,
    /// Reported speed margin, km/h (NaN when none).
    pub margin_kmh: f64,
    /// Time to critical, s (NaN when none).
    pub ttc_s: f64,
    /// Monitor level.
    pub level: Level,
    /// Yaw envelope amplitude, deg.
    pub amplitude_deg: f64,
    /// Mean wheel yaw, deg.
    pub yaw_deg: f64,
}

/// Result of a run.
#[derive(Clone, Debug)]
pub struct MarginRun {
    /// Rows at 100 Hz.
    pub rows: Vec<MarginRow>,
    /// Linear onset speed of the simulated plant, from an independent scan, km/h.
    pub onset_kmh: Option<f64>,
    /// First time the level left Normal: (t, speed km/h, level).
    pub first_warning: Option<(f64, f64, Level)>,
    /// Highest level reached.
    pub max_level: Level,
    /// Time at which the true speed crosses the onset, s.
    pub onset_time_s: Option<f64>,
    /// Largest eigen-solves done in one pipeline call.
    pub max_solves_per_call: u8,
    /// Model cycles completed.
    pub model_cycles: u32,
    /// Wall-clock time of the run, s.
    pub wall_s: f64,
}

impl MarginRun {
    /// Lead of the first warning before the onset: (km/h, s). Positive = before.
    pub fn lead(&self) -> Option<(f64, f64)> {
        let (t, v, _) = self.first_warning?;
        Some((self.onset_kmh? - v, self.onset_time_s? - t))
    }
}

/// The linear onset speed of `p` without damper by a 0.5 km/h scan + Brent (independent of the
/// pipeline's incremental search).
pub fn onset_kmh(p: &PlantParams) -> Option<f64> {
    stability::hopf_crossings(
        p,
        0.0,
        kmh_to_mps(1.0),
        kmh_to_mps(150.0),
        kmh_to_mps(0.5),
        stability::DEFAULT_TOL_MPS,
    )
    .ok()?
    .iter()
    .find(|c| c.kind == CrossingKind::Onset)
    .map(|c| mps_to_kmh(c.speed_mps))
}

/// Runs the open-loop scenario through the pipeline. `true_every`: compute the true
/// eigenvalues every n-th row (0 = never).
pub fn run(sc: &MarginScenario, pp: PipelineParams, true_every: usize) -> Result<MarginRun> {
    let wall = std::time::Instant::now();
    let p = sc.params;
    let mut sim = Simulator::new(Plant::new(p, Damper::None), [0.0; N_STATE]);
    let mut scen = sc.scenario();
    let model = sc.model.map_or(p, |m| m.plant);
    let mut pipe = ShimmyPipeline::<16>::new(model, pp).context("pipeline config")?;
    let onset = onset_kmh(&p);
    let n = (sc.duration_s / DT_S).round() as usize;
    let mut rows = Vec::with_capacity(n / 10 + 1);
    let mut first_warning = None;
    let mut max_level = Level::Normal;
    let mut onset_time = None;
    let mut max_solves = 0u8;
    let (mut zt, mut ft) = (f64::NAN, f64::NAN);
    for k in 0..n {
        let t = k as f64 * DT_S;
        let u = scen.inputs(t, DT_S);
        sim.advance(DT_S, &u)
            .with_context(|| format!("integration failed at t = {t}"))?;
        let t1 = t + DT_S;
        let x = sim.state();
        let v = sc.speed.at(t1);
        let accel = (sc.speed.at(t1 + 0.5 * DT_S) - sc.speed.at(t1 - 0.5 * DT_S)) / DT_S;
        if let (Some(on), None) = (onset, onset_time) {
            if mps_to_kmh(v) >= on {
                onset_time = Some(t1);
            }
        }
        let sample = Sample {
            psi_l_rad: x[idx::PSI_L] as f32,
            psi_r_rad: x[idx::PSI_R] as f32,
            wheel: WheelOrder::Speed {
                speed_mps: v as f32,
                radius_m: p.r as f32,
            },
            damper_cmd: 0.0,
        };
        let out = pipe.push(&sample, v as f32, accel as f32, t1 as f32);
        max_solves = max_solves.max(pipe.model().solves_last_call());
        let Some(o) = out else { continue };
        if o.level > Level::Normal && first_warning.is_none() {
            first_warning = Some((t1, mps_to_kmh(v), o.level));
        }
        max_level = max_level.max(o.level);
        if true_every > 0 && rows.len() % true_every == 0 {
            if let Ok(m) = stability::mode_at(&p, v, 0.0, ModeSelect::Shimmy) {
                zt = m.zeta;
                ft = m.freq_hz;
            }
        }
        let r = &o.report;
        rows.push(MarginRow {
            t_s: t1,
            speed_kmh: mps_to_kmh(v),
            zeta_true: zt,
            freq_true_hz: ft,
            margin_true_kmh: onset.map_or(f64::NAN, |on| on - mps_to_kmh(v)),
            zeta_data: r.zeta_data as f64,
            sigma_data: r.sigma_zeta_data as f64,
            zeta_fast: r.zeta_fast as f64,
            data_valid: r.data_valid,
            fast_valid: r.fast_valid,
            zeta_model: r.zeta_model.map_or(f64::NAN, f64::from),
            freq_data_hz: r.freq_hz as f64,
            margin_kmh: r
                .speed_margin_mps
                .map_or(f64::NAN, |m| mps_to_kmh(m as f64)),
            ttc_s: r.time_to_critical_s.map_or(f64::NAN, f64::from),
            level: o.level,
            amplitude_deg: (o.meter.amplitude_rad as f64).to_degrees(),
            yaw_deg: (0.5 * (x[idx::PSI_L] + x[idx::PSI_R])).to_degrees(),
        });
    }
    Ok(MarginRun {
        rows,
        onset_kmh: onset,
        first_warning,
        max_level,
        onset_time_s: onset_time,
        max_solves_per_call: max_solves,
        model_cycles: pipe.model().cycles(),
        wall_s: wall.elapsed().as_secs_f64(),
    })
}

fn level_num(l: Level) -> u8 {
    match l {
        Level::Normal => 0,
        Level::MarginLow => 1,
        Level::ApproachingCritical => 2,
        Level::ShimmyPresent => 3,
    }
}

/// Writes the rows as CSV.
pub fn write_csv(path: &Path, rows: &[MarginRow]) -> Result<()> {
    let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
    writeln!(
        f,
        "t_s,speed_kmh,zeta_true,freq_true_hz,margin_true_kmh,zeta_model,zeta_data,sigma_zeta_data,\
         zeta_fast,data_valid,fast_valid,freq_data_hz,margin_kmh,ttc_s,level,amplitude_deg,yaw_deg"
    )?;
    for r in rows {
        writeln!(
            f,
            "{:.3},{:.4},{:.5},{:.4},{:.4},{:.5},{:.5},{:.5},{:.5},{},{},{:.4},{:.4},{:.3},{},{:.5},{:.5}",
            r.t_s,
            r.speed_kmh,
            r.zeta_true,
            r.freq_true_hz,
            r.margin_true_kmh,
            r.zeta_model,
            r.zeta_data,
            r.sigma_data,
            r.zeta_fast,
            u8::from(r.data_valid),
            u8::from(r.fast_valid),
            r.freq_data_hz,
            r.margin_kmh,
            r.ttc_s,
            level_num(r.level),
            r.amplitude_deg,
            r.yaw_deg
        )?;
    }
    Ok(())
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;
type Series<'a> = (&'a str, RGBColor, Vec<(f64, f64)>);

fn panel(
    area: &Area<'_>,
    caption: &str,
    t: (f64, f64),
    range: (f64, f64),
    series: &[Series<'_>],
    vlines: &[(f64, RGBColor)],
) -> Result<()> {
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 16))
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(55)
        .build_cartesian_2d(t.0..t.1, range.0..range.1)?;
    crate::out::plot_util::mesh(&mut chart, "t [s]", "")?;
    for (name, col, pts) in series {
        let col = *col;
        chart
            .draw_series(LineSeries::new(
                pts.iter()
                    .filter(|p| p.1.is_finite())
                    .map(|p| (p.0, p.1.clamp(range.0, range.1))),
                col,
            ))?
            .label(*name)
            .legend(crate::out::plot_util::line_marker(col, 1));
    }
    for (x, col) in vlines {
        chart.draw_series(LineSeries::new(
            [(*x, range.0), (*x, range.1)],
            col.stroke_width(2),
        ))?;
    }
    crate::out::plot_util::legend(&mut chart, SeriesLabelPosition::MiddleRight)?;
    Ok(())
}

/// Plots zeta (true, model, data), speed margin (true, reported) and level/speed vs time.
pub fn plot(path: &Path, run: &MarginRun, title: &str) -> Result<()> {
    let rows = &run.rows;
    let (Some(a), Some(b)) = (rows.first(), rows.last()) else {
        return Ok(());
    };
    let t = (a.t_s, b.t_s);
    let root = BitMapBackend::new(path, (1200, 1000)).into_drawing_area();
    root.fill(&WHITE)?;
    let parts = root.split_evenly((3, 1));
    let col = |f: &dyn Fn(&MarginRow) -> f64| rows.iter().map(|r| (r.t_s, f(r))).collect();
    let mut v = Vec::new();
    if let Some((tw, _, _)) = run.first_warning {
        v.push((tw, RGBColor(255, 140, 0)));
    }
    if let Some(to) = run.onset_time_s {
        v.push((to, MAGENTA));
    }
    panel(
        &parts[0],
        &format!("{title}: shimmy-mode damping (true: shimmy mode by shape of the simulated plant's A(V), no damper fitted, at the true speed; model; data)"),
        t,
        (-0.05, 0.2),
        &[
            ("true zeta", BLACK, col(&|r| r.zeta_true)),
            ("model zeta", BLUE, col(&|r| r.zeta_model)),
            ("data zeta (slow)", RED, col(&|r| r.zeta_data)),
            (
                "data zeta (fast)",
                RGBColor(0, 160, 0),
                col(&|r| r.zeta_fast),
            ),
        ],
        &v,
    )?;
    panel(
        &parts[1],
        "speed margin to the onset [km/h] (true vs reported); orange: first warning, magenta: onset",
        t,
        (-5.0, 30.0),
        &[
            ("true margin", BLACK, col(&|r| r.margin_true_kmh)),
            ("reported margin", RED, col(&|r| r.margin_kmh)),
        ],
        &v,
    )?;
    panel(
        &parts[2],
        "speed [km/h / 10], level (0 normal, 1 margin low, 2 approaching, 3 shimmy), amplitude [deg]",
        t,
        (-0.1, 6.0),
        &[
            ("speed / 10", BLACK, col(&|r| r.speed_kmh / 10.0)),
            ("level", RED, col(&|r| f64::from(level_num(r.level)))),
            ("amplitude [deg]", BLUE, col(&|r| r.amplitude_deg)),
        ],
        &v,
    )?;
    root.present()?;
    Ok(())
}

/// The options' ranges again (for arguments built in code) and the simulated time: the
/// constant drive's `--duration-s`, or `--settle-s` plus the ramp, above 0 and at most 3600 s.
pub fn check(a: &MarginArgs) -> Result<()> {
    arg_range::SPEED_KMH.check("--ramp-from-kmh", a.ramp_from_kmh)?;
    arg_range::SPEED_KMH.check("--ramp-to-kmh", a.ramp_to_kmh)?;
    RATE_KMH_PER_S.check("--rate-kmh-per-s", a.rate_kmh_per_s)?;
    SETTLE_S.check("--settle-s", a.settle_s)?;
    TORQUE_NM.check("--noise-nm", a.noise_nm)?;
    TORQUE_NM.check("--imbalance-nm", a.imbalance_nm)?;
    DURATION_S.check("--duration-s", a.duration_s)?;
    if let Some(v) = a.constant_kmh {
        arg_range::SPEED_KMH.check("--constant-kmh", v)?;
    } else {
        let t = a.settle_s + (a.ramp_to_kmh - a.ramp_from_kmh).abs() / a.rate_kmh_per_s;
        DURATION_S.check(
            "--settle-s + |--ramp-to-kmh - --ramp-from-kmh| / --rate-kmh-per-s",
            t,
        )?;
    }
    Ok(())
}

/// `shimmy-sim margin`.
pub fn command(a: &MarginArgs) -> Result<()> {
    check(a)?;
    let vehicle = vehicle_file::load(&a.vehicle)?;
    let model = match &a.model_vehicle {
        Some(m) => vehicle_file::load(m).context("--model-vehicle")?,
        None => vehicle,
    };
    let p = vehicle.plant;
    let mut sc = match a.constant_kmh {
        Some(v) => MarginScenario::constant(p, v, a.duration_s),
        None => MarginScenario::ramp(
            p,
            a.ramp_from_kmh,
            a.ramp_to_kmh,
            a.rate_kmh_per_s,
            a.settle_s,
        ),
    };
    sc.noise_nm = a.noise_nm;
    sc.imbalance_nm = a.imbalance_nm;
    sc.seed = a.seed;
    sc.model = Some(model);
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {:?}", a.out))?;
    let run = run(&sc, model.pipeline_params(), 10)?;
    println!(
        "open loop, damper off (no damper force), vehicle `{}`, model vehicle `{}`, noise {} N m, imbalance {} N m, seed {}",
        a.vehicle,
        a.model_vehicle.as_deref().unwrap_or(&a.vehicle),
        sc.noise_nm,
        sc.imbalance_nm,
        sc.seed
    );
    println!(
        "simulated {:.1} s in {:.1} s wall ({:.0}x real time); model cycles {}, max eigen-solves per 1 ms call {}",
        sc.duration_s,
        run.wall_s,
        sc.duration_s / run.wall_s.max(1e-9),
        run.model_cycles,
        run.max_solves_per_call
    );
    println!("   t[s]  V[km/h] zeta_true zeta_model zeta_data +-sigma zeta_fast margin_true margin_rep  ttc[s] level");
    for r in run.rows.iter().step_by(100) {
        println!(
            "{:7.1} {:8.2} {:9.4} {:10.4} {:9.4} {:7.4} {:9.4} {:11.2} {:10.2} {:7.1} {:?}",
            r.t_s,
            r.speed_kmh,
            r.zeta_true,
            r.zeta_model,
            r.zeta_data,
            r.sigma_data,
            r.zeta_fast,
            r.margin_true_kmh,
            r.margin_kmh,
            r.ttc_s,
            r.level
        );
    }
    match run.onset_kmh {
        Some(on) => println!("linear onset (independent scan): {on:.3} km/h"),
        None => println!("no linear onset for this plant"),
    }
    match (run.first_warning, run.lead()) {
        (Some((t, v, l)), Some((dv, dt))) => println!(
            "first warning {l:?} at t = {t:.2} s, {v:.2} km/h: lead {dv:.2} km/h, {dt:.2} s before the onset"
        ),
        (Some((t, v, l)), None) => println!("first warning {l:?} at t = {t:.2} s, {v:.2} km/h"),
        (None, _) => println!("no warning (max level {:?})", run.max_level),
    }
    let csv = a.out.join("margin.csv");
    write_csv(&csv, &run.rows)?;
    let png = a.out.join("margin.png");
    plot(&png, &run, &a.vehicle)?;
    println!("wrote {} and {}", csv.display(), png.display());
    Ok(())
}
