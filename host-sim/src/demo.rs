//! The built-in demo (`shimmy-sim` with no arguments): damper off vs ASMC on a speed ramp
//! through the Hopf window with road noise, wheel imbalance and a pothole, the data-driven mode
//! meter running in the loop, and a self-contained Markdown report with plots and metrics.

use crate::closed_loop::{self, Arm, LoopConfig, LoopResult, RunMetrics};
use crate::compare::{fastest_growth_speed, pothole, road, POTHOLE_NM};
use crate::disturbance::{Scenario, SpeedProfile};
use crate::plot_util;
use crate::report::{self, Report, ReportRun, Section};
use anyhow::{Context, Result};
use rayon::prelude::*;
use shimmy_core::control::ControllerKind;
use shimmy_core::params::{kmh_to_mps, mps_to_kmh, ParamSet, PlantParams};
use shimmy_core::stability::{hopf_crossings, CrossingKind, HopfCrossing};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Demo options.
#[derive(Clone, Debug)]
pub struct DemoOptions {
    /// Output directory.
    pub out: PathBuf,
    /// Ramp duration [s] (20 -> 120 km/h).
    pub ramp_s: f64,
}

impl Default for DemoOptions {
    fn default() -> Self {
        DemoOptions {
            out: PathBuf::from("out/demo"),
            ramp_s: 30.0,
        }
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
    let root = BitMapBackend::new(path, (1100, 700)).into_drawing_area();
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
    root.present()?;
    Ok(())
}

/// The demo's case: the nominal plant, the ramp scenario and the facts the report states.
#[derive(Clone, Debug)]
pub struct DemoCase {
    /// The true (and nominal) plant.
    pub plant: PlantParams,
    /// Ramp 20 -> 120 km/h with road noise, imbalance and a pothole.
    pub scenario: Scenario,
    /// Hopf crossings of the plant without damper (1-50 m/s).
    pub crossings: Vec<HopfCrossing>,
    /// The no-damper Hopf window [km/h], when there is one.
    pub window_kmh: Option<(f64, f64)>,
    /// Speed of fastest shimmy growth [m/s] (where the pothole hits).
    pub v_fastest_mps: f64,
    /// Time of the pothole [s].
    pub t_pothole_s: f64,
}

/// The demo's two arms with their report labels: damper off (0 A) and ASMC.
pub const ARMS: [(&str, Arm); 2] = [
    ("damper off (0 A)", Arm::Mr(ControllerKind::PassiveOff)),
    ("ASMC", Arm::Mr(ControllerKind::Asmc)),
];

/// Builds the demo's case for a ramp of `ramp_s` seconds (all numbers computed).
pub fn demo_case(ramp_s: f64) -> Result<DemoCase> {
    let p = ParamSet::Nominal.params();
    let crossings: Vec<HopfCrossing> = hopf_crossings(&p, 0.0, 1.0, 50.0, 0.25, 1e-3)
        .map_err(|e| anyhow::anyhow!("hopf_crossings: {e:?}"))?
        .iter()
        .copied()
        .collect();
    let onset = crossings.iter().find(|c| c.kind == CrossingKind::Onset);
    let offset = crossings.iter().find(|c| c.kind != CrossingKind::Onset);
    let window_kmh = match (onset, offset) {
        (Some(a), Some(b)) => Some((mps_to_kmh(a.speed_mps), mps_to_kmh(b.speed_mps))),
        _ => None,
    };
    let v_fg = fastest_growth_speed(&p);
    let (v0, v1) = (kmh_to_mps(20.0), kmh_to_mps(120.0));
    let mut sc = Scenario::new(SpeedProfile::Ramp {
        v0_mps: v0,
        v1_mps: v1,
        t0_s: 0.0,
        t1_s: ramp_s,
    });
    let (n, im) = road(7, &p);
    sc.noise = Some(n);
    sc.imbalance = Some(im);
    let t_hit = ramp_s * (v_fg - v0) / (v1 - v0);
    sc.impulses.push(pothole(t_hit, POTHOLE_NM));
    Ok(DemoCase {
        plant: p,
        scenario: sc,
        crossings,
        window_kmh,
        v_fastest_mps: v_fg,
        t_pothole_s: t_hit,
    })
}

/// Runs one arm of the demo (the golden regression trace and the benchmark use the ASMC arm).
pub fn run_arm(
    case: &DemoCase,
    arm: Arm,
    ramp_s: f64,
    record_every: usize,
) -> Result<(LoopConfig, LoopResult)> {
    let mut cfg = LoopConfig::new(case.plant, arm, ramp_s);
    cfg.record_every = record_every;
    let mut s = case.scenario.clone();
    let r = closed_loop::run(&cfg, &mut s, None)
        .map_err(|e| anyhow::anyhow!("{}: integration failed: {e:?}", arm.name()))?;
    Ok((cfg, r))
}

/// Runs the demo and writes `report.md` with its plots into `o.out` (through
/// [`crate::report::write`], the same writer as `shimmy-sim report`).
pub fn run_demo(o: &DemoOptions) -> Result<DemoOutput> {
    std::fs::create_dir_all(&o.out).with_context(|| format!("creating {}", o.out.display()))?;
    let case = demo_case(o.ramp_s)?;
    let results: Vec<ReportRun> = ARMS
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
        "Plant: `nominal` 4-DOF solid axle with the Spencer MR damper (coil lag included); sensors: 14-bit encoders with noise and 1 sample delay, noisy wheel speed; control and mode meter: the firmware's `shimmy-core` code at 1 kHz.\n"
    );
    let _ = writeln!(intro, "## Nominal Hopf window (no damper, eigenvalues)\n");
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
    let report = Report {
        title: "shimmy demo: MR damper off vs adaptive sliding-mode control".into(),
        intro,
        sections: vec![Section {
            name: "ramp 20-120 km/h".into(),
            description,
            plant: case.plant,
            runs: results,
            extra_plots: vec![(
                "Data-driven mode meter (slow estimate) vs speed; shaded: the nominal no-damper Hopf window".into(),
                "meter.png".into(),
            )],
        }],
    };
    let w = report::write(&o.out, &report)?;
    Ok(DemoOutput {
        report: w.report,
        plots: w.plots,
        metrics,
    })
}

/// The no-argument command.
pub fn command() -> Result<()> {
    println!("shimmy demo: damper off vs ASMC through the Hopf window (see `shimmy-sim --help` for the other commands)");
    let out = run_demo(&DemoOptions::default())?;
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
