//! `shimmy-sim stability`: eigenvalue analysis of the linearised plant over speed (optionally
//! with the MR damper as its equivalent viscous damper), Hopf crossings, CSV and PNG.
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::model::family::SimModel;
use anyhow::{Context, Result};
use plotters::prelude::*;
use shimmy_core::eigen::ModeShape;
use shimmy_core::model::LinearModel;
use shimmy_core::stability::{self, Crossings, ModeSelect, ModeSummary, DEFAULT_TOL_MPS};
use shimmy_core::units::{kmh_to_mps, mps_to_kmh};

use crate::model::damper_equiv::damper_equivalent;
use crate::model::hopf_type::{hopf_type_at, Criticality, HopfType, HopfTypeError};
use crate::model::plant::Damper;
use crate::model::registry::{self, ModelVisitor, Registered};
use crate::sim::input::arg_range::{self, Range};
use crate::sim::input::vehicle_file;

/// Options of `shimmy-sim stability`.
#[derive(clap::Args, Debug, Clone)]
pub struct StabilityArgs {
    /// The vehicle (`--vehicle`, a named set or a vehicle file).
    #[command(flatten)]
    pub vehicle: crate::cmd::VehicleArg,
    /// Constant MR-damper coil current in A; the damper enters as its energy-equivalent viscous
    /// coefficient (describing function). Without it there is no damper force. 0 to the
    /// vehicle's coil rating.
    #[arg(long, alias = "damper-current", allow_negative_numbers = true, value_parser = arg_range::current_a())]
    pub damper_current_a: Option<f64>,
    /// Reference wheel-yaw amplitude for the describing function, deg: above 0, at most 20.
    #[arg(long, default_value_t = 0.5, allow_negative_numbers = true, value_parser = arg_range::f64_in(REF_AMPLITUDE_DEG))]
    pub ref_amplitude_deg: f64,
    /// Lowest speed, km/h: 1 to 250, below `--v-max-kmh`.
    #[arg(long, default_value_t = 5.0, allow_negative_numbers = true, value_parser = arg_range::speed_kmh())]
    pub v_min_kmh: f64,
    /// Highest speed, km/h: 1 to 250.
    #[arg(long, default_value_t = 150.0, allow_negative_numbers = true, value_parser = arg_range::speed_kmh())]
    pub v_max_kmh: f64,
    /// Grid step for the sweep and for bracketing crossings, km/h: 0.01 to 50.
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true, value_parser = arg_range::f64_in(STEP_KMH))]
    pub step_kmh: f64,
    /// Output folder (`--out`; default out/stability, [`Self::out_dir`]).
    #[command(flatten)]
    pub out: crate::cmd::OutArg,
}

impl StabilityArgs {
    /// The output folder: `--out`, else out/stability.
    pub fn out_dir(&self) -> PathBuf {
        self.out.dir_or("out/stability")
    }
}

/// Describing-function reference amplitude: above 0, at most 20 deg.
pub const REF_AMPLITUDE_DEG: Range = Range::above(0.0, 20.0, "deg");

/// Speed grid step: 0.01 to 50 km/h.
pub const STEP_KMH: Range = Range::closed(0.01, 50.0, "km/h");

fn sweep<M: LinearModel<N>, const N: usize>(
    p: &M,
    c: f64,
    v_min: f64,
    v_max: f64,
    step: f64,
) -> Result<Vec<ModeSummary>> {
    let n = ((v_max - v_min) / step).round() as usize;
    (0..=n)
        .map(|i| {
            let v = kmh_to_mps(v_min + i as f64 * step);
            stability::mode_summary(p, v, c).with_context(|| format!("eigen at {v} m/s"))
        })
        .collect()
}

/// Runs `shimmy-sim stability`.
pub fn command(args: &StabilityArgs) -> Result<()> {
    arg_range::SPEED_KMH.check("--v-min-kmh", args.v_min_kmh)?;
    arg_range::SPEED_KMH.check("--v-max-kmh", args.v_max_kmh)?;
    STEP_KMH.check("--step-kmh", args.step_kmh)?;
    REF_AMPLITUDE_DEG.check("--ref-amplitude-deg", args.ref_amplitude_deg)?;
    anyhow::ensure!(
        args.v_max_kmh > args.v_min_kmh,
        "--v-min-kmh {} must be below --v-max-kmh {}",
        args.v_min_kmh,
        args.v_max_kmh
    );
    registry::with_model(
        vehicle_file::load_model(&args.vehicle.spec)?,
        Stability(args),
    )
}

/// The command on a vehicle of the model `M`: with its damper, or none when the model's files
/// configure none (the trailer: `sway-damping` sizes its damper).
struct Stability<'a>(&'a StabilityArgs);

impl ModelVisitor for Stability<'_> {
    type Output = Result<()>;
    fn visit<M: Registered<N>, const N: usize>(self, f: M::File) -> Result<()> {
        let args = self.0;
        if let Some(parts) = M::parts_of(&f) {
            if let Some(i) = args.damper_current_a {
                arg_range::check_current("--damper-current-a", i, parts)?;
            }
            let _out_dir = crate::sim::input::files::OutDir::claim(&args.out_dir())?;
            return with_damper(&M::model_of(&f), parts, args);
        }
        anyhow::ensure!(
            args.damper_current_a.is_none(),
            "--damper-current-a: the {} model has no MR damper configured; leave it out \
             (`sway-damping` gives the sway damper it needs)",
            registry::name_of::<M, N>()
        );
        let _out_dir = crate::sim::input::files::OutDir::claim(&args.out_dir())?;
        println!(
            "stability of straight running: vehicle `{}`",
            args.vehicle.spec
        );
        println!("damper: none (F_d = 0)");
        report(&M::model_of(&f), Damper::None, 0.0, args)
    }
}

/// The damper setting of `--damper-current-a` (checked) on the vehicle model `p` (the damper
/// of `parts`), then the report.
fn with_damper<M: SimModel<N>, const N: usize>(
    p: &M,
    parts: &shimmy_core::vehicle::Vehicle,
    args: &StabilityArgs,
) -> Result<()> {
    let (v_min, v_max) = (kmh_to_mps(args.v_min_kmh), kmh_to_mps(args.v_max_kmh));
    let (c, damper) = match args.damper_current_a {
        None => (0.0, None),
        Some(i) => {
            let d = damper_equivalent(
                p,
                &parts.damper.spencer,
                i,
                args.ref_amplitude_deg,
                v_min,
                v_max,
            )?;
            (d.c_eq_nspm, Some(d))
        }
    };
    println!(
        "stability of straight running: vehicle `{}`",
        args.vehicle.spec
    );
    match damper {
        None => println!("damper: none (F_d = 0)"),
        Some(d) => println!(
            "damper: MR at {:.3} A -> equivalent viscous c_eq = {:.1} N s/m (describing function \
             at {:.3} Hz, stroke amplitude {:.3} mm = {} deg in-phase wheel yaw)",
            d.current_a,
            d.c_eq_nspm,
            d.freq_hz,
            d.stroke_amp_m * 1e3,
            args.ref_amplitude_deg
        ),
    }
    // the Hopf type is of the plant the crossings are of: the MR damper's own model with a
    // current, else none
    let plant_damper = match args.damper_current_a {
        None => Damper::None,
        Some(_) => Damper::Mr(parts.damper.spencer),
    };
    report(p, plant_damper, c, args)
}

/// The sweep, the crossings, their Hopf type, the table and the files for any model of the
/// family (`damper` the plant's, for the Hopf type; `c` the linear model's).
fn report<M: SimModel<N>, const N: usize>(
    m: &M,
    damper: Damper,
    c: f64,
    args: &StabilityArgs,
) -> Result<()> {
    let p = &m.linear();
    let (v_min, v_max) = (kmh_to_mps(args.v_min_kmh), kmh_to_mps(args.v_max_kmh));
    let rows = sweep(p, c, args.v_min_kmh, args.v_max_kmh, args.step_kmh)?;
    let crossings = stability::hopf_crossings(
        p,
        c,
        v_min,
        v_max,
        kmh_to_mps(args.step_kmh),
        DEFAULT_TOL_MPS,
    )
    .context("Hopf search")?;

    println!();
    println!(
        "{:>7} | {:>10} | {:>9} {:>8} {:<20} | {:>9} {:>8} {:<20} | {:>11} {:>8}",
        "V km/h",
        "max Re 1/s",
        "crit zeta",
        "f Hz",
        "critical mode",
        "min zeta",
        "f Hz",
        "least-damped mode",
        "shimmy zeta",
        "f Hz"
    );
    for r in &rows {
        let kmh = mps_to_kmh(r.v_mps);
        if (kmh / 5.0 - (kmh / 5.0).round()).abs() > 1e-6 {
            continue;
        }
        let crit_shape = shape_of_critical(p, r.v_mps, c);
        let shimmy = stability::mode_at(p, r.v_mps, c, ModeSelect::Shimmy).ok();
        println!(
            "{:>7.1} | {:>10.4} | {:>9.4} {:>8.3} {:<20} | {:>9.4} {:>8.3} {:<20} | {:>11} {:>8}",
            kmh,
            r.max_re,
            r.critical.zeta,
            r.critical.freq_hz,
            crit_shape.name(),
            r.least_damped.zeta,
            r.least_damped.freq_hz,
            r.least_damped_shape.shape.name(),
            shimmy.map_or("-".into(), |m| format!("{:.4}", m.zeta)),
            shimmy.map_or("-".into(), |m| format!("{:.3}", m.freq_hz))
        );
    }
    println!();
    print_crossings(&crossings, args.v_min_kmh, args.v_max_kmh);
    let types: Vec<Result<HopfType, HopfTypeError>> = crossings
        .iter()
        .map(|x| hopf_type_at(m, damper, x.speed_mps, x.freq_hz))
        .collect();
    print_hopf_types(&crossings, &types);

    let csv = args.out_dir().join("stability.csv");
    write_sweep_csv(&csv, p, c, &rows)?;
    let ccsv = args.out_dir().join("crossings.csv");
    write_crossings_csv(&ccsv, &crossings, &types)?;
    let png = args.out_dir().join("stability.png");
    let shimmy = shimmy_modes(p, c, &rows);
    plot(&png, &rows, &shimmy, &crossings, &args.vehicle.spec, c)?;
    println!(
        "wrote {}, {}, {}",
        csv.display(),
        ccsv.display(),
        png.display()
    );
    Ok(())
}

fn shape_of_critical<M: LinearModel<N>, const N: usize>(p: &M, v: f64, c: f64) -> ModeShape {
    let a = p.linearise(v, c);
    shimmy_core::eigen::eigenvalues(&a)
        .ok()
        .and_then(|vals| shimmy_core::eigen::critical_oscillatory_mode(&vals).ok())
        .and_then(|m| shimmy_core::eigen::mode_shape(p, &a, m.eigenvalue()).ok())
        .map_or(ModeShape::TyreLag, |s| s.shape)
}

fn print_crossings(crossings: &Crossings, v_min_kmh: f64, v_max_kmh: f64) {
    if crossings.is_empty() {
        println!("no Hopf crossing in {v_min_kmh}..{v_max_kmh} km/h");
        return;
    }
    println!("Hopf crossings ({v_min_kmh}..{v_max_kmh} km/h):");
    for x in crossings {
        println!(
            "  {:<6} at {:>9.4} km/h ({:>8.5} m/s), {:.3} Hz, {} mode{}",
            x.kind.name(),
            mps_to_kmh(x.speed_mps),
            x.speed_mps,
            x.freq_hz,
            x.shape.name(),
            if x.converged { "" } else { " (NOT converged)" }
        );
    }
    // every unstable window: each onset with the next offset above it
    let mut onset: Option<f64> = None;
    for x in crossings {
        match (x.kind, onset) {
            (stability::CrossingKind::Onset, _) => onset = Some(x.speed_mps),
            (stability::CrossingKind::Offset, Some(a)) => {
                println!(
                    "Hopf window: {:.2} .. {:.2} km/h ({:.2} km/h wide, {} mode at the offset)",
                    mps_to_kmh(a),
                    mps_to_kmh(x.speed_mps),
                    mps_to_kmh(x.speed_mps - a),
                    x.shape.name()
                );
                onset = None;
            }
            (stability::CrossingKind::Offset, None) => println!(
                "unstable from the start of the range up to {:.2} km/h",
                mps_to_kmh(x.speed_mps)
            ),
        }
    }
    if let Some(a) = onset {
        println!(
            "unstable from {:.2} km/h up to the end of the range (no offset)",
            mps_to_kmh(a)
        );
    }
}

/// Per crossing: l1 and the type, and the small cycle predicted 1 km/h past it on the side
/// where it exists.
fn print_hopf_types(crossings: &Crossings, types: &[Result<HopfType, HopfTypeError>]) {
    if crossings.is_empty() {
        return;
    }
    println!(
        "Hopf type (first Lyapunov coefficient l1 of the nonlinear plant at each crossing, \
         <q,q> = 1 in SI states; cycle: the measured yaw output, normal form):"
    );
    for (x, t) in crossings.iter().zip(types) {
        let head = format!(
            "  {:<6} at {:>9.4} km/h:",
            x.kind.name(),
            mps_to_kmh(x.speed_mps)
        );
        match t {
            Err(e) => println!("{head} {e}"),
            Ok(h) => {
                let (at, amp) = h.cycle_1kmh();
                let amp = amp.map_or("-".into(), |a| {
                    format!("{:.4} deg at {:.2} km/h", a.to_degrees(), mps_to_kmh(at))
                });
                let what = match h.criticality() {
                    Criticality::Supercritical => {
                        "a stable cycle grows from zero on the unstable side"
                    }
                    Criticality::Subcritical => {
                        "an unstable cycle on the stable side: a large enough disturbance \
                         starts shimmy there"
                    }
                    Criticality::Degenerate => "the cubic term does not decide",
                };
                println!(
                    "{head} l1 = {:.4e} (+- {:.1e}), {} ({what}); cycle {amp} \
                     (~ sqrt|V - V_c|)",
                    h.lyapunov.l1,
                    h.lyapunov.l1_err,
                    h.criticality().name()
                );
            }
        }
    }
}

fn write_sweep_csv<M: LinearModel<N>, const N: usize>(
    path: &Path,
    p: &M,
    c: f64,
    rows: &[ModeSummary],
) -> Result<()> {
    let mut f = Vec::new();
    writeln!(
        f,
        "speed_kmh,speed_mps,max_re_1ps,crit_re_1ps,crit_zeta,crit_freq_hz,crit_shape,\
         least_zeta,least_freq_hz,least_re_1ps,least_shape,shimmy_zeta,shimmy_freq_hz,c_damper_nspm"
    )?;
    for r in rows {
        let shimmy = stability::mode_at(p, r.v_mps, c, ModeSelect::Shimmy).ok();
        writeln!(
            f,
            "{:.6},{:.6},{:.9},{:.9},{:.9},{:.6},{},{:.9},{:.6},{:.9},{},{},{},{:.3}",
            mps_to_kmh(r.v_mps),
            r.v_mps,
            r.max_re,
            r.critical.re,
            r.critical.zeta,
            r.critical.freq_hz,
            shape_of_critical(p, r.v_mps, c).name(),
            r.least_damped.zeta,
            r.least_damped.freq_hz,
            r.least_damped.re,
            r.least_damped_shape.shape.name(),
            shimmy.map_or(String::new(), |m| format!("{:.9}", m.zeta)),
            shimmy.map_or(String::new(), |m| format!("{:.6}", m.freq_hz)),
            c
        )?;
    }
    crate::sim::input::files::write_file(path, &f)
}

fn write_crossings_csv(
    path: &Path,
    crossings: &Crossings,
    types: &[Result<HopfType, HopfTypeError>],
) -> Result<()> {
    let mut f = Vec::new();
    writeln!(
        f,
        "kind,speed_kmh,speed_mps,freq_hz,shape,bracket_mps,converged,hopf_type,l1,l1_err,\
         dmu_dv_per_m,cycle_side,cycle_amp_deg_1kmh"
    )?;
    for (x, t) in crossings.iter().zip(types) {
        let hopf = match t {
            Ok(h) => {
                let side = h.cycle_side();
                let amp = h
                    .cycle_1kmh()
                    .1
                    .map_or(String::new(), |a| format!("{:.6}", a.to_degrees()));
                format!(
                    "{},{:.9e},{:.3e},{:.9e},{side},{amp}",
                    h.criticality().name(),
                    h.lyapunov.l1,
                    h.lyapunov.l1_err,
                    h.dmu_dv
                )
            }
            Err(e) => format!("{},,,,,", e.label()),
        };
        writeln!(
            f,
            "{},{:.6},{:.8},{:.6},{},{:.3e},{},{hopf}",
            x.kind.name(),
            mps_to_kmh(x.speed_mps),
            x.speed_mps,
            x.freq_hz,
            x.shape.name(),
            x.bracket_mps,
            x.converged
        )?;
    }
    crate::sim::input::files::write_file(path, &f)
}

/// The shimmy-shaped mode (`ModeSelect::Shimmy`) at each row's speed, `None` where there is
/// none: the plot's line (the critical mode can be another shape's, the 42-47 Hz anti-phase
/// wheel yaw, where the shimmy window is closed).
fn shimmy_modes<M: LinearModel<N>, const N: usize>(
    p: &M,
    c: f64,
    rows: &[ModeSummary],
) -> Vec<Option<shimmy_core::eigen::Mode>> {
    rows.iter()
        .map(|r| stability::mode_at(p, r.v_mps, c, ModeSelect::Shimmy).ok())
        .collect()
}

fn plot(
    path: &Path,
    rows: &[ModeSummary],
    shimmy: &[Option<shimmy_core::eigen::Mode>],
    crossings: &Crossings,
    name: &str,
    c: f64,
) -> Result<()> {
    let png = crate::sim::input::files::PendingFile::new(path);
    let root = BitMapBackend::new(png.tmp(), (1000, 800)).into_drawing_area();
    root.fill(&WHITE)?;
    let (top, bottom) = root.split_vertically(400);
    let xs: Vec<f64> = rows.iter().map(|r| mps_to_kmh(r.v_mps)).collect();
    panel(
        &top,
        &xs,
        &format!(
            "{name}, c_damper = {c:.1} N s/m: Re lambda [1/s] (shimmy mode: line; max of all \
             oscillatory: dots)"
        ),
        &shimmy
            .iter()
            .map(|m| m.map_or(f64::NAN, |m| m.re))
            .collect::<Vec<_>>(),
        &rows.iter().map(|r| r.critical.re).collect::<Vec<_>>(),
        crossings,
    )?;
    panel(
        &bottom,
        &xs,
        "damping ratio zeta [-] (shimmy mode: line; least-damped mode: dots)",
        &shimmy
            .iter()
            .map(|m| m.map_or(f64::NAN, |m| m.zeta))
            .collect::<Vec<_>>(),
        &rows.iter().map(|r| r.least_damped.zeta).collect::<Vec<_>>(),
        crossings,
    )?;
    png.commit(root.present())?;
    Ok(())
}

fn panel(
    area: &DrawingArea<BitMapBackend<'_>, plotters::coord::Shift>,
    xs: &[f64],
    caption: &str,
    main: &[f64],
    second: &[f64],
    crossings: &Crossings,
) -> Result<()> {
    let (x0, x1) = (xs[0], xs[xs.len() - 1]);
    let lo = main
        .iter()
        .chain(second)
        .cloned()
        .filter(|v| v.is_finite())
        .fold(f64::INFINITY, f64::min);
    let hi = main
        .iter()
        .chain(second)
        .cloned()
        .filter(|v| v.is_finite())
        .fold(f64::NEG_INFINITY, f64::max);
    let pad = 0.05 * (hi - lo).max(1e-6);
    let (lo, hi) = (lo.min(0.0) - pad, hi.max(0.0) + pad);
    let mut chart = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(60)
        .build_cartesian_2d(x0..x1, lo..hi)?;
    chart.configure_mesh().x_desc("speed [km/h]").draw()?;
    // the line breaks where the shimmy mode is not found
    for seg in xs
        .iter()
        .cloned()
        .zip(main.iter().cloned())
        .collect::<Vec<_>>()
        .split(|(_, y)| !y.is_finite())
    {
        chart.draw_series(LineSeries::new(seg.iter().copied(), &BLUE))?;
    }
    chart.draw_series(
        xs.iter()
            .cloned()
            .zip(second.iter().cloned())
            .map(|(x, y)| Circle::new((x, y), 2, RED.filled())),
    )?;
    chart.draw_series(LineSeries::new([(x0, 0.0), (x1, 0.0)], &BLACK))?;
    for xc in crossings {
        let k = mps_to_kmh(xc.speed_mps);
        let col = if xc.kind == stability::CrossingKind::Onset {
            MAGENTA
        } else {
            GREEN
        };
        chart.draw_series(LineSeries::new([(k, lo), (k, hi)], col.stroke_width(2)))?;
        chart.draw_series(std::iter::once(Text::new(
            format!(
                "{} {:.2} km/h {:.2} Hz {}",
                xc.kind.name(),
                k,
                xc.freq_hz,
                xc.shape.name()
            ),
            (k, hi - 0.1 * (hi - lo)),
            ("sans-serif", 14),
        )))?;
    }
    Ok(())
}

#[cfg(test)]
mod shimmy_line_tests {
    use super::*;
    use shimmy_core::vehicles::car::{Param, ParamSet};

    /// `gentle` with I_k +20 %: at 220 km/h the critical (largest real part) mode is the
    /// unstable anti-phase one, the plot's line the shimmy mode, stable there and of its own
    /// shape (the line used to be the critical mode's).
    #[test]
    fn the_plots_line_is_the_shimmy_mode() {
        let g = ParamSet::Gentle.params();
        let p = g.with(Param::IK, g.get(Param::IK) * 1.2);
        let rows = sweep(&p, 0.0, 200.0, 220.0, 10.0).unwrap();
        let last = rows.last().unwrap();
        assert!((mps_to_kmh(last.v_mps) - 220.0).abs() < 1e-9);
        assert!(last.critical.re > 0.0, "{last:?}");
        assert_eq!(
            shape_of_critical(&p, last.v_mps, 0.0),
            ModeShape::AntiPhaseWheelYaw
        );
        let m = shimmy_modes(&p, 0.0, &rows).last().unwrap().unwrap();
        assert!(m.re < 0.0 && m.freq_hz < 15.0, "{m:?}");
    }
}
