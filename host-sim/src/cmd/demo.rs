//! The built-in demo (`shimmy-sim` with no arguments): damper off vs ASMC on a speed ramp
//! through the Hopf window with road noise, wheel imbalance and a pothole, the data-driven mode
//! meter running in the loop, and a self-contained Markdown report with plots and metrics.
//! `--vehicle` and `--model-vehicle` run it on another vehicle (the ramp stays 20 -> 120 km/h).

use crate::model::family::SimModel;
use crate::model::plant::Method;
use crate::model::registry::image_models;
use crate::model::registry::{self, Registered, StudyVisitor};
use crate::model::registry::{ReferenceModel, REFERENCE_N};
use crate::model::study::StudyModel;
use crate::out::plot_util;
use crate::out::provenance::Provenance;
use crate::out::report::{self, Report, ReportRun, Section};
use crate::sim::input::arg_range::{self, Range};
use crate::sim::input::vehicle_file::{self, FileModel, ModelVehicle};
use crate::sim::run::closed_loop::{LoopResult, RunMetrics, CLOSED_LOOP_METHOD};
use crate::sim::run::demo_case::{demo_case_on, run_arm, ARMS, ROAD_SEED};
use crate::sim::run::scenario_file::ScenarioModel;
use crate::sim::run::standard::POTHOLE_NM;
use anyhow::{bail, Context, Result};
use rayon::prelude::*;
use shimmy_core::model::LinearModel;
use shimmy_core::units::mps_to_kmh;
use shimmy_core::vehicle::Vehicle;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Options of the demo on the command line (`shimmy-sim [--vehicle V] [--model-vehicle M]`).
#[derive(clap::Args, Clone, Debug)]
pub struct DemoArgs {
    /// The demo's simulated vehicle: a named set of a model with a firmware image (`shimmy-sim
    /// vehicles` lists the sets) or a vehicle file (TOML, see docs/vehicle-file.md) [default:
    /// nominal].
    #[arg(long, visible_alias = "params")]
    pub vehicle: Option<String>,
    /// The vehicle the firmware believes (`--model-vehicle`).
    #[command(flatten)]
    pub model_vehicle: crate::cmd::ModelVehicleArg,
    /// Length of the speed ramp 20 -> 120 km/h, s: 1 to 600.
    #[arg(long, default_value_t = RAMP_S_DEFAULT, allow_negative_numbers = true, value_parser = arg_range::f64_in(RAMP_S))]
    pub ramp_s: f64,
    /// The plant integrator: `dopri5[:RTOL]` (adaptive, rtol 1e-7 without RTOL),
    /// `imex-fixed[:SUBSTEPS]` (IMEX at SUBSTEPS fixed steps per 1 ms period, z implicit) or
    /// `imex:RTOL` (adaptive IMEX) [default: dopri5].
    #[arg(long)]
    pub integrator: Option<String>,
}

/// The demo's ramp length: 1 to 600 s.
pub const RAMP_S: Range = Range::closed(1.0, 600.0, "s");
/// The demo's ramp length without `--ramp-s`, s.
pub const RAMP_S_DEFAULT: f64 = 30.0;

/// Demo options, on the vehicle model `M` (the car by default).
#[derive(Clone, Debug)]
pub struct DemoOptions<M: SimModel<N> = ReferenceModel, const N: usize = { REFERENCE_N }> {
    /// Output directory.
    pub out: PathBuf,
    /// Ramp duration, s (20 -> 120 km/h).
    pub ramp_s: f64,
    /// The simulated vehicle and its name (as given: a set or a file).
    pub plant: (String, M::Vehicle),
    /// The vehicle the firmware believes and its name; `None`: the simulated one.
    pub model: Option<(String, M::Vehicle)>,
    /// The plant integrator of both arms.
    pub method: Method,
}

impl Default for DemoOptions {
    fn default() -> Self {
        DemoOptions {
            out: PathBuf::from("out/demo"),
            ramp_s: RAMP_S_DEFAULT,
            plant: ("nominal".into(), Vehicle::nominal()),
            model: None,
            method: CLOSED_LOOP_METHOD,
        }
    }
}

impl<M: FileModel<N>, const N: usize> DemoOptions<M, N> {
    /// The default demo on the simulated vehicle `plant` (`--vehicle` as given, or `nominal`)
    /// with the options of `a` (range-checked, the model vehicle loaded and validated).
    pub fn from_args(a: &DemoArgs, plant: M::Vehicle) -> Result<Self> {
        let default = DemoOptions::<ReferenceModel>::default();
        Ok(DemoOptions {
            ramp_s: RAMP_S.check("--ramp-s", a.ramp_s)?,
            method: match &a.integrator {
                Some(name) => {
                    Method::from_name(name).map_err(|e| anyhow::anyhow!("--integrator: {e}"))?
                }
                None => CLOSED_LOOP_METHOD,
            },
            out: default.out,
            plant: (a.vehicle.clone().unwrap_or(default.plant.0), plant),
            model: match a.model_vehicle.given() {
                Some(m) => Some((
                    m.to_string(),
                    M::load_vehicle(m, Path::new("")).context("--model-vehicle")?,
                )),
                None => None,
            },
        })
    }
}

/// What the demo produced.
#[derive(Clone, Debug)]
pub struct DemoOutput {
    /// The report file.
    pub report: PathBuf,
    /// Plot files.
    pub plots: Vec<PathBuf>,
    /// Metrics of (damper off, ASMC).
    pub metrics: [RunMetrics; 2],
}

fn plot_meter(
    path: &Path,
    runs: &[(&str, &LoopResult)],
    window_kmh: Option<(f64, f64)>,
) -> Result<()> {
    use plotters::prelude::*;
    let png = crate::sim::input::files::PendingFile::new(path);
    let root = BitMapBackend::new(png.tmp(), (1100, 700)).into_drawing_area();
    root.fill(&WHITE)?;
    let (a, b) = root.split_vertically(350);
    let colors = [RGBColor(220, 50, 32), RGBColor(0, 158, 115)];
    let v_lo = 15.0;
    let v_hi = 125.0;
    for (pi, area) in [a, b].iter().enumerate() {
        let (lo, hi, label) = if pi == 0 {
            (-0.1, 0.3, "meter damping ratio zeta (slow)")
        } else {
            (0.0, 20.0, "meter frequency [Hz]")
        };
        let mut chart = ChartBuilder::on(area)
            .margin(8)
            .x_label_area_size(35)
            .y_label_area_size(60)
            .build_cartesian_2d(v_lo..v_hi, lo..hi)?;
        plot_util::mesh(&mut chart, "speed [km/h]", label)?;
        if let Some((w0, w1)) = window_kmh {
            chart.draw_series(std::iter::once(Rectangle::new(
                [(w0, lo), (w1, hi)],
                RGBColor(200, 200, 255).mix(0.3).filled(),
            )))?;
        }
        if pi == 0 {
            chart.draw_series(LineSeries::new(vec![(v_lo, 0.0), (v_hi, 0.0)], BLACK))?;
        }
        for (i, (name, r)) in runs.iter().enumerate() {
            let c = colors[i % colors.len()];
            let pts = r.meter.iter().filter(|m| m.valid).map(|m| {
                let y = if pi == 0 { m.zeta_slow } else { m.freq_hz };
                (mps_to_kmh(m.speed_mps), y.clamp(lo, hi))
            });
            let s = chart.draw_series(pts.map(|p| Circle::new(p, 1, c.filled())))?;
            if pi == 0 {
                s.label(name.to_string()).legend(plot_util::dot_marker(c));
            }
        }
        if pi == 0 {
            plot_util::legend(&mut chart, SeriesLabelPosition::UpperRight)?;
        }
    }
    png.commit(root.present())?;
    Ok(())
}

/// Runs the demo and writes `report.md` with its plots into `o.out` (through
/// [`report::write`], the same writer as `shimmy-sim report`).
pub fn run_demo<M: ScenarioModel<N>, const N: usize>(o: &DemoOptions<M, N>) -> Result<DemoOutput> {
    let out_dir = crate::sim::input::files::OutDir::claim(&o.out)?;
    let (plant_name, plant) = &o.plant;
    let model = o.model.as_ref().map_or(plant, |(_, m)| m);
    let mut case = demo_case_on::<M, N>(plant, model, o.ramp_s)?;
    case.method = o.method;
    let results: Vec<ReportRun<M, N>> = ARMS
        .par_iter()
        .map(|&(label, arm)| {
            let (cfg, r) = run_arm(&case, arm, o.ramp_s, 5)?;
            Ok(ReportRun::new(label, cfg, r, None))
        })
        .collect::<Result<_>>()?;
    let runs: Vec<(&str, &LoopResult)> = results
        .iter()
        .map(|r| (r.label.as_str(), &r.result))
        .collect();
    plot_meter(&o.out.join("meter.png"), &runs, case.window_kmh)?;
    let metrics = [results[0].metrics, results[1].metrics];

    let mut intro = String::new();
    let _ = writeln!(
        intro,
        "Plant: `{plant_name}` ({}) with the Spencer MR damper (coil lag included); sensors: {}-bit encoders with noise and 1 sample delay, noisy wheel speed; control and mode meter: the firmware's `shimmy-core` code at 1 kHz.\n",
        <M::Linear as LinearModel<N>>::NAME,
        M::family_vehicle(plant).parts.sensors.encoder_bits
    );
    if let Some((model_name, _)) = &o.model {
        let _ = writeln!(
            intro,
            "The firmware believes `{model_name}` (its controller's and estimator's models, gains and thresholds).\n"
        );
    }
    let _ = writeln!(
        intro,
        "## Hopf window of `{plant_name}` (no damper, eigenvalues)\n"
    );
    if case.crossings.is_empty() {
        let _ = writeln!(intro, "No Hopf crossing between 1 and 50 m/s.\n");
    }
    for c in &case.crossings {
        let _ = writeln!(
            intro,
            "- {:?} at {:.2} km/h ({:.2} m/s), {:.2} Hz",
            c.kind,
            mps_to_kmh(c.speed_mps),
            c.speed_mps,
            c.freq_hz
        );
    }
    let _ = writeln!(
        intro,
        "- fastest growth of the shimmy mode at {:.1} km/h",
        mps_to_kmh(case.v_fastest_mps)
    );
    let description = format!(
        "Speed ramp 20 -> 120 km/h in {:.0} s, road yaw-torque noise 4 N m rms (20 Hz), wheel imbalance 3 N m per wheel, pothole ({POTHOLE_NM} N m, 20 ms) at {:.1} s ({:.1} km/h).",
        o.ramp_s,
        case.t_pothole_s,
        mps_to_kmh(case.v_fastest_mps)
    );
    let mut provenance = Provenance::of_this_process().model_vehicle(
        "vehicle",
        plant_name,
        &M::any_vehicle(plant),
    )?;
    if let Some((model_name, m)) = &o.model {
        provenance = provenance.model_vehicle("model vehicle", model_name, &M::any_vehicle(m))?;
    }
    let provenance = provenance
        .seed("road noise", ROAD_SEED)
        .seed("sensor noise", results[0].cfg.sensors.seed);
    let report = Report {
        title: "shimmy demo: MR damper off vs adaptive sliding-mode control".into(),
        intro,
        sections: vec![Section {
            name: "ramp 20-120 km/h".into(),
            description,
            runs: results,
            extra_plots: vec![(
                format!("Data-driven mode meter (slow estimate) vs speed; shaded: the no-damper Hopf window of `{plant_name}`"),
                "meter.png".into(),
            )],
        }],
        provenance: Some(provenance),
    };
    let w = report::write(&out_dir, &report)?;
    Ok(DemoOutput {
        report: w.report,
        plots: w.plots,
        metrics,
    })
}

/// The no-argument command (with `--vehicle` / `--model-vehicle` only).
pub fn command(a: &DemoArgs) -> Result<()> {
    let vehicle = match &a.vehicle {
        Some(v) => vehicle_file::load_model(v).context("--vehicle")?,
        None => ModelVehicle::from(Vehicle::nominal()),
    };
    struct On<'a>(&'a DemoArgs);
    impl StudyVisitor for On<'_> {
        type Output = Result<()>;
        fn visit<M: Registered<N> + StudyModel<N>, const N: usize>(self, v: M::File) -> Result<()> {
            command_on::<M, N>(self.0, M::vehicle(v)?)
        }
    }
    match registry::with_image_model(vehicle, On(a)) {
        Ok(r) => r,
        Err(other) => bail!(
            "the demo runs the {} models, not the {}",
            image_models(),
            other.model_name()
        ),
    }
}

/// The demo on the simulated vehicle `plant` of the model `M`.
fn command_on<M: ScenarioModel<N>, const N: usize>(a: &DemoArgs, plant: M::Vehicle) -> Result<()> {
    let o = DemoOptions::<M, N>::from_args(a, plant)?;
    println!("shimmy demo: damper off vs ASMC through the Hopf window (see `shimmy-sim --help` for the other commands)");
    let out = run_demo(&o)?;
    println!(
        "damper off: shimmy {:.1} s, peak yaw {:.2} deg | ASMC: shimmy {:.1} s, peak yaw {:.2} deg, coil energy {:.2} J",
        out.metrics[0].shimmy_s,
        out.metrics[0].peak_yaw_rad.to_degrees(),
        out.metrics[1].shimmy_s,
        out.metrics[1].peak_yaw_rad.to_degrees(),
        out.metrics[1].energy_j
    );
    println!("report: {}", out.report.display());
    Ok(())
}
