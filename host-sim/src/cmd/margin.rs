//! `shimmy-sim margin`: the open-loop eigenvalue-margin demonstration.
//!
//! The run itself (plant, disturbances, pipeline, true eigenvalues) is
//! [`crate::sim::run::margin_run`]; this command prints the report once a second next to the true
//! eigenvalue and writes `margin.csv`, `margin.png` and `summary.json` under `--out`, with the
//! warning lead time.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;
use plotters::prelude::*;
use shimmy_core::estimator::monitor::Level;

use crate::model::disturbance::SpeedProfile;
use crate::model::family::SimModel;
use crate::model::registry::{self, ModelVisitor, Registered};
use crate::out::progress;
use crate::out::provenance::Provenance;
use crate::sim::input::arg_range::{self, Range};
use crate::sim::input::vehicle_file::{self, ModelVehicle};
use crate::sim::run::margin_run::{
    onset_kmh, run_with_progress, MarginRow, MarginRun, MarginScenario,
};

/// Lead-in before the ramp: 0 to 600 s.
pub const SETTLE_S: Range = Range::closed(0.0, 600.0, "s");
/// Road-noise and imbalance torques: 0 to 200 N m.
pub const TORQUE_NM: Range = Range::closed(0.0, 200.0, "N m");
/// Simulated time of one run (constant drive, or settle plus ramp): above 0, at most 3600 s.
pub const DURATION_S: Range = Range::above(0.0, 3600.0, "s");

/// Arguments of `shimmy-sim margin`.
#[derive(Args, Debug, Clone)]
pub struct MarginArgs {
    /// The vehicle (`--vehicle`, a named set or a vehicle file).
    #[command(flatten)]
    pub vehicle: crate::cmd::VehicleArg,
    /// The vehicle the firmware believes (`--model-vehicle`).
    #[command(flatten)]
    pub model_vehicle: crate::cmd::ModelVehicleArg,
    /// Ramp start speed, km/h: 1 to 250.
    #[arg(long, default_value_t = 15.0, allow_negative_numbers = true, value_parser = arg_range::speed_kmh())]
    pub ramp_from_kmh: f64,
    /// Ramp end speed, km/h: 1 to 250.
    #[arg(long, default_value_t = 40.0, allow_negative_numbers = true, value_parser = arg_range::speed_kmh())]
    pub ramp_to_kmh: f64,
    /// Ramp rate, km/h per s: 0.01 to 50 (settle plus ramp at most 3600 s).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true, value_parser = arg_range::f64_in(arg_range::RATE_KMH_PER_S))]
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
    /// Output folder (`--out`; default out/margin, [`Self::out_dir`]).
    #[command(flatten)]
    pub out: crate::cmd::OutArg,
    /// Update the model's parameters online from the data (`docs/margin-estimator.md`, "Model
    /// updating") and print them with their uncertainty and a diagnosis at the end.
    #[arg(long)]
    pub model_update: bool,
}

impl MarginArgs {
    /// The output folder: `--out`, else out/margin.
    pub fn out_dir(&self) -> PathBuf {
        self.out.dir_or("out/margin")
    }
}

fn level_num(l: Level) -> u8 {
    match l {
        Level::Normal => 0,
        Level::MarginLow => 1,
        Level::ApproachingCritical => 2,
        Level::ShimmyPresent => 3,
    }
}

/// The run's key figures for scripts and CI (`summary.json`, with the `provenance` object
/// beside them): the plant's linear onset, the model's onset, the first warning and its lead,
/// and for a constant drive its duration and the number of warning onsets. Absent values are
/// `null`.
pub fn summary_json<M: SimModel<N>, const N: usize>(
    sc: &MarginScenario<M, N>,
    run: &MarginRun,
) -> serde_json::Value {
    let lead = run.lead();
    let constant = matches!(sc.speed, SpeedProfile::Constant(_));
    let mut summary = serde_json::json!({
        "plant_onset_kmh": run.onset_kmh,
        "model_onset_kmh": sc.model.as_ref().and_then(|m| onset_kmh(&m.linear())),
        "first_warning_kmh": run.first_warning.map(|(_, v, _)| v),
        "first_warning_s": run.first_warning.map(|(t, _, _)| t),
        "first_warning_level": run.first_warning.map(|(_, _, l)| format!("{l:?}")),
        "lead_kmh": lead.map(|l| l.0),
        "lead_s": lead.map(|l| l.1),
        "max_level": format!("{:?}", run.max_level),
        "duration_s": constant.then_some(sc.duration_s),
        "warnings": constant.then_some(run.warnings),
    });
    if !run.updated.is_empty() {
        summary["updated"] = serde_json::to_value(&run.updated).unwrap_or_default();
        summary["diagnosis"] =
            serde_json::json!(run.diagnosis.as_ref().map(|d| d.statement().to_string()));
    }
    summary
}

/// Writes the rows as CSV.
pub fn write_csv(path: &Path, rows: &[MarginRow]) -> Result<()> {
    let mut f = Vec::new();
    writeln!(
        f,
        "t_s,speed_kmh,zeta_true,freq_true_hz,margin_true_kmh,zeta_model,zeta_data,sigma_zeta_data,\
         zeta_fast,data_valid,fast_valid,freq_data_hz,margin_kmh,ttc_s,level,amplitude_deg,yaw_deg,\
         model_consistent,zeta_offset,zeta_correction"
    )?;
    for r in rows {
        writeln!(
            f,
            "{:.3},{:.4},{:.5},{:.4},{:.4},{:.5},{:.5},{:.5},{:.5},{},{},{:.4},{:.4},{:.3},{},{:.5},{:.5},{},{:.5},{:.5}",
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
            r.yaw_deg,
            u8::from(r.model_consistent),
            r.zeta_offset,
            r.zeta_correction
        )?;
    }
    crate::sim::input::files::write_file(path, &f)
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
    let png = crate::sim::input::files::PendingFile::new(path);
    let root = BitMapBackend::new(png.tmp(), (1200, 1000)).into_drawing_area();
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
    png.commit(root.present())?;
    Ok(())
}

/// The options' ranges again (for arguments built in code) and the simulated time: the
/// constant drive's `--duration-s`, or `--settle-s` plus the ramp, above 0 and at most 3600 s.
pub fn check(a: &MarginArgs) -> Result<()> {
    arg_range::SPEED_KMH.check("--ramp-from-kmh", a.ramp_from_kmh)?;
    arg_range::SPEED_KMH.check("--ramp-to-kmh", a.ramp_to_kmh)?;
    arg_range::RATE_KMH_PER_S.check("--rate-kmh-per-s", a.rate_kmh_per_s)?;
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
    let vehicle = vehicle_file::load_model(&a.vehicle.spec)?;
    let model = match a.model_vehicle.given() {
        Some(m) => vehicle_file::load_model(m).context("--model-vehicle")?,
        None => vehicle.clone(),
    };
    let mut provenance =
        Provenance::of_this_process().model_vehicle("vehicle", &a.vehicle.spec, &vehicle)?;
    if let Some(m) = a.model_vehicle.given() {
        provenance = provenance.model_vehicle("model vehicle", m, &model)?;
    }
    /// The run on the vehicle's model, the firmware's model of the same.
    struct On<'a>(&'a MarginArgs, ModelVehicle, Provenance);
    impl ModelVisitor for On<'_> {
        type Output = Result<()>;
        fn visit<M: Registered<N>, const N: usize>(self, v: M::File) -> Result<()> {
            let On(a, model, provenance) = self;
            let m = match M::from_any(model) {
                Ok(m) => registry::family::<M, N>(m)?,
                Err(model) => bail!(
                    "--model-vehicle `{}` is a {} vehicle, --vehicle `{}` a {}: the firmware's \
                     model is of the vehicle's model",
                    a.model_vehicle.given().unwrap_or_default(),
                    model.model_name(),
                    a.vehicle.spec,
                    registry::name_of::<M, N>()
                ),
            };
            run_on(a, M::model_of(&v), m.model, m.pipeline_params(), provenance)
        }
    }
    registry::with_model(vehicle, On(a, model, provenance))
}

/// The run on the plant `p` with the pipeline's model `model` (of the same vehicle model).
fn run_on<M: SimModel<N>, const N: usize>(
    a: &MarginArgs,
    p: M,
    model: M,
    pipeline: shimmy_core::estimator::pipeline::PipelineParams,
    provenance: Provenance,
) -> Result<()> {
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
    let mut pipeline = pipeline;
    if a.model_update {
        pipeline.update = shimmy_core::estimator::model_update::ModelUpdateConfig::ON;
    }
    let provenance = provenance.seed("road noise", sc.seed);
    let _out_dir = crate::sim::input::files::OutDir::claim(&a.out_dir())?;
    let bar = progress::bar(0, "1 ms steps");
    let run = run_with_progress(&sc, pipeline, 10, &mut |done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })?;
    bar.finish_and_clear();
    println!(
        "open loop, damper off (no damper force), vehicle `{}`, model vehicle `{}`, noise {} N m, imbalance {} N m (x {:.4} on this model), seed {}",
        a.vehicle.spec,
        a.model_vehicle.or(&a.vehicle.spec),
        sc.noise_nm,
        sc.imbalance_nm,
        p.yaw_torque_scale(),
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
    if !run.updated.is_empty() {
        println!("model update (factor on the vehicle file, 2 sigma, plausible band):");
        for u in &run.updated {
            let (lo, hi) = u.two_sigma();
            println!(
                "  {:<28} {:<10} x{:.3}  (x{:.3}-x{:.3}; x{:.2}-x{:.2}){}",
                u.what,
                u.field,
                u.factor,
                lo,
                hi,
                u.band.0,
                u.band.1,
                if u.out_of_band { "  OUT OF BAND" } else { "" }
            );
        }
        match &run.diagnosis {
            Some(d) => println!("diagnosis: {}", d.statement()),
            None => println!("diagnosis: every updated parameter within its plausible band"),
        }
    }
    let csv = a.out_dir().join("margin.csv");
    write_csv(&csv, &run.rows)?;
    let png = a.out_dir().join("margin.png");
    plot(&png, &run, &a.vehicle.spec)?;
    let json = a.out_dir().join("summary.json");
    let mut summary = summary_json(&sc, &run);
    summary["provenance"] = provenance.json();
    crate::sim::input::files::write_file(&json, serde_json::to_string_pretty(&summary)? + "\n")?;
    println!(
        "wrote {}, {} and {}",
        csv.display(),
        png.display(),
        json.display()
    );
    Ok(())
}
