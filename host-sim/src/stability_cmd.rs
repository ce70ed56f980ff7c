//! `shimmy-sim stability` and `shimmy-sim sensitivity`: eigenvalue analysis of the linearised
//! plant over speed, Hopf crossings, CSV and PNG reports, and a parameter sensitivity table.
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use plotters::prelude::*;
use shimmy_core::eigen::ModeShape;
use shimmy_core::mr_damper::SpencerParams;
use shimmy_core::params::{kmh_to_mps, mps_to_kmh, Param, PlantParams};
use shimmy_core::stability::{self, Crossings, ModeSelect, ModeSummary, DEFAULT_TOL_MPS};

use crate::damper_equiv;
use crate::paramfile;

/// Options of `shimmy-sim stability`.
#[derive(clap::Args, Debug, Clone)]
pub struct StabilityArgs {
    /// Named set (nominal, gentle, hard) or TOML parameter file.
    #[arg(long, default_value = "nominal")]
    pub params: String,
    /// Constant MR-damper coil current [A]; the damper enters as its energy-equivalent viscous
    /// coefficient (describing function). Without it there is no damper force.
    #[arg(long)]
    pub damper_current: Option<f64>,
    /// Reference wheel-yaw amplitude for the describing function [deg].
    #[arg(long, default_value_t = 0.5)]
    pub ref_amplitude_deg: f64,
    /// Lowest speed [km/h].
    #[arg(long, default_value_t = 5.0)]
    pub v_min_kmh: f64,
    /// Highest speed [km/h].
    #[arg(long, default_value_t = 150.0)]
    pub v_max_kmh: f64,
    /// Grid step for the sweep and for bracketing crossings [km/h].
    #[arg(long, default_value_t = 1.0)]
    pub step_kmh: f64,
    /// Output directory (CSV, PNG).
    #[arg(long, default_value = "out/stability")]
    pub out: PathBuf,
}

/// Options of `shimmy-sim sensitivity`.
#[derive(clap::Args, Debug, Clone)]
pub struct SensitivityArgs {
    /// Named set (nominal, gentle, hard) or TOML parameter file.
    #[arg(long, default_value = "nominal")]
    pub params: String,
    /// Relative change applied down and up [%].
    #[arg(long, default_value_t = 20.0)]
    pub percent: f64,
    /// Output directory (CSV).
    #[arg(long, default_value = "out/sensitivity")]
    pub out: PathBuf,
}

/// The equivalent viscous damper coefficient for a coil current, with the frequency it was
/// evaluated at.
#[derive(Clone, Copy, Debug)]
pub struct DamperEquivalent {
    /// Coil current [A].
    pub current_a: f64,
    /// Mode frequency the describing function was evaluated at [Hz].
    pub freq_hz: f64,
    /// Stroke amplitude [m].
    pub stroke_amp_m: f64,
    /// Equivalent viscous coefficient [N s/m].
    pub c_eq_nspm: f64,
}

/// Energy-equivalent viscous coefficient of the MR damper at `current_a`, evaluated at the
/// frequency of the shimmy (in-phase wheel-yaw) mode at the speed where the damper-free growth
/// rate of the critical mode is largest in [v_min, v_max]; the frequency is updated once with
/// the damper in place (a two-pass fixed point: the mode frequency moves little with c).
pub fn damper_equivalent(
    p: &PlantParams,
    current_a: f64,
    ref_amp_deg: f64,
    v_min_mps: f64,
    v_max_mps: f64,
) -> Result<DamperEquivalent> {
    let sp = SpencerParams::steering();
    let amp = damper_equiv::stroke_amplitude_m(p.l_t, ref_amp_deg.to_radians());
    let n = 100;
    let mut v_ref = v_min_mps;
    let mut g_best = f64::NEG_INFINITY;
    for i in 0..=n {
        let v = v_min_mps + (v_max_mps - v_min_mps) * i as f64 / n as f64;
        let m = stability::critical_mode_at(p, v, 0.0).map_err(|e| anyhow::anyhow!("{e:?}"))?;
        if m.re > g_best {
            g_best = m.re;
            v_ref = v;
        }
    }
    let mut freq = stability::mode_at(p, v_ref, 0.0, ModeSelect::Shimmy)
        .map_err(|e| anyhow::anyhow!("{e:?}"))?
        .freq_hz;
    let mut c = damper_equiv::mr_equivalent_viscous(&sp, current_a, freq, amp);
    for _ in 0..1 {
        freq = stability::mode_at(p, v_ref, c, ModeSelect::Shimmy)
            .map_err(|e| anyhow::anyhow!("{e:?}"))?
            .freq_hz;
        c = damper_equiv::mr_equivalent_viscous(&sp, current_a, freq, amp);
    }
    Ok(DamperEquivalent {
        current_a,
        freq_hz: freq,
        stroke_amp_m: amp,
        c_eq_nspm: c,
    })
}

fn sweep(p: &PlantParams, c: f64, v_min: f64, v_max: f64, step: f64) -> Result<Vec<ModeSummary>> {
    let n = ((v_max - v_min) / step).round() as usize;
    (0..=n)
        .map(|i| {
            let v = kmh_to_mps(v_min + i as f64 * step);
            stability::mode_summary(p, v, c).map_err(|e| anyhow::anyhow!("eigen at {v} m/s: {e:?}"))
        })
        .collect()
}

/// Runs `shimmy-sim stability`.
pub fn run_stability(args: &StabilityArgs) -> Result<()> {
    anyhow::ensure!(
        args.v_min_kmh > 0.0 && args.v_max_kmh > args.v_min_kmh && args.step_kmh > 0.0,
        "need 0 < v-min < v-max and step > 0"
    );
    let p = paramfile::load(&args.params)?;
    let (v_min, v_max) = (kmh_to_mps(args.v_min_kmh), kmh_to_mps(args.v_max_kmh));
    let (c, damper) = match args.damper_current {
        None => (0.0, None),
        Some(i) => {
            let d = damper_equivalent(&p, i, args.ref_amplitude_deg, v_min, v_max)?;
            (d.c_eq_nspm, Some(d))
        }
    };
    println!(
        "stability of straight running: parameter set `{}`",
        args.params
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
    let rows = sweep(&p, c, args.v_min_kmh, args.v_max_kmh, args.step_kmh)?;
    let crossings = stability::hopf_crossings(
        &p,
        c,
        v_min,
        v_max,
        kmh_to_mps(args.step_kmh),
        DEFAULT_TOL_MPS,
    )
    .map_err(|e| anyhow::anyhow!("Hopf search: {e:?}"))?;

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
        let crit_shape = shape_of_critical(&p, r.v_mps, c);
        let shimmy = stability::mode_at(&p, r.v_mps, c, ModeSelect::Shimmy).ok();
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

    fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let csv = args.out.join("stability.csv");
    write_sweep_csv(&csv, &p, c, &rows)?;
    let ccsv = args.out.join("crossings.csv");
    write_crossings_csv(&ccsv, &crossings)?;
    let png = args.out.join("stability.png");
    plot(&png, &rows, &crossings, &args.params, c)?;
    println!(
        "wrote {}, {}, {}",
        csv.display(),
        ccsv.display(),
        png.display()
    );
    Ok(())
}

fn shape_of_critical(p: &PlantParams, v: f64, c: f64) -> ModeShape {
    let a = shimmy_core::plant::linearise(p, v, c);
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
    let on = crossings
        .iter()
        .find(|x| x.kind == stability::CrossingKind::Onset);
    let off = crossings
        .iter()
        .find(|x| x.kind == stability::CrossingKind::Offset);
    match (on, off) {
        (Some(a), Some(b)) => println!(
            "Hopf window: {:.2} .. {:.2} km/h ({:.2} km/h wide)",
            mps_to_kmh(a.speed_mps),
            mps_to_kmh(b.speed_mps),
            mps_to_kmh(b.speed_mps - a.speed_mps)
        ),
        (Some(a), None) => println!(
            "unstable from {:.2} km/h up to the end of the range (no offset)",
            mps_to_kmh(a.speed_mps)
        ),
        _ => {}
    }
}

fn write_sweep_csv(path: &Path, p: &PlantParams, c: f64, rows: &[ModeSummary]) -> Result<()> {
    let mut f = fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
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
    Ok(())
}

fn write_crossings_csv(path: &Path, crossings: &Crossings) -> Result<()> {
    let mut f = fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
    writeln!(
        f,
        "kind,speed_kmh,speed_mps,freq_hz,shape,bracket_mps,converged"
    )?;
    for x in crossings {
        writeln!(
            f,
            "{},{:.6},{:.8},{:.6},{},{:.3e},{}",
            x.kind.name(),
            mps_to_kmh(x.speed_mps),
            x.speed_mps,
            x.freq_hz,
            x.shape.name(),
            x.bracket_mps,
            x.converged
        )?;
    }
    Ok(())
}

fn plot(
    path: &Path,
    rows: &[ModeSummary],
    crossings: &Crossings,
    name: &str,
    c: f64,
) -> Result<()> {
    let root = BitMapBackend::new(path, (1000, 800)).into_drawing_area();
    root.fill(&WHITE)?;
    let (top, bottom) = root.split_vertically(400);
    let xs: Vec<f64> = rows.iter().map(|r| mps_to_kmh(r.v_mps)).collect();
    panel(
        &top,
        &xs,
        &format!(
            "{name}, c_damper = {c:.1} N s/m: max Re lambda [1/s] (oscillatory: line; all: dots)"
        ),
        &rows.iter().map(|r| r.critical.re).collect::<Vec<_>>(),
        &rows.iter().map(|r| r.max_re).collect::<Vec<_>>(),
        crossings,
    )?;
    panel(
        &bottom,
        &xs,
        "damping ratio zeta [-] (critical mode: line; least-damped mode: dots)",
        &rows.iter().map(|r| r.critical.zeta).collect::<Vec<_>>(),
        &rows.iter().map(|r| r.least_damped.zeta).collect::<Vec<_>>(),
        crossings,
    )?;
    root.present()?;
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
        .fold(f64::INFINITY, f64::min);
    let hi = main
        .iter()
        .chain(second)
        .cloned()
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
    chart.draw_series(LineSeries::new(
        xs.iter().cloned().zip(main.iter().cloned()),
        &BLUE,
    ))?;
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
            format!("{} {:.2} km/h {:.2} Hz", xc.kind.name(), k, xc.freq_hz),
            (k, hi - 0.1 * (hi - lo)),
            ("sans-serif", 14),
        )))?;
    }
    Ok(())
}

/// Parameters varied by the sensitivity study (those the linear model depends on; F_z, mu, C_s
/// only shape the nonlinear tyre and l_t only the damper lever, so they have no effect without
/// a damper).
pub const SENSITIVITY_PARAMS: [Param; 15] = [
    Param::CA,
    Param::Sigma,
    Param::E,
    Param::TP,
    Param::KD,
    Param::CSw,
    Param::CK,
    Param::IP,
    Param::IK,
    Param::KTr,
    Param::JSw,
    Param::IS,
    Param::HR,
    Param::KPhi,
    Param::IPhi,
];

/// Onset/offset speeds [km/h] and onset frequency [Hz] of a parameter set (None where absent),
/// searching 1..250 km/h.
pub fn window_of(p: &PlantParams) -> Result<(Option<f64>, Option<f64>, Option<f64>)> {
    let xs = stability::hopf_crossings(
        p,
        0.0,
        kmh_to_mps(1.0),
        kmh_to_mps(250.0),
        kmh_to_mps(1.0),
        DEFAULT_TOL_MPS,
    )
    .map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let on = xs.iter().find(|x| x.kind == stability::CrossingKind::Onset);
    let off = xs
        .iter()
        .find(|x| x.kind == stability::CrossingKind::Offset);
    Ok((
        on.map(|x| mps_to_kmh(x.speed_mps)),
        off.map(|x| mps_to_kmh(x.speed_mps)),
        on.map(|x| x.freq_hz),
    ))
}

fn fmt_opt(v: Option<f64>) -> String {
    v.map_or("-".to_string(), |x| format!("{x:.2}"))
}

/// Runs `shimmy-sim sensitivity`.
pub fn run_sensitivity(args: &SensitivityArgs) -> Result<()> {
    let p = paramfile::load(&args.params)?;
    let (on0, off0, f0) = window_of(&p)?;
    println!(
        "Hopf window sensitivity of `{}` (+-{}% per parameter, no damper, 1..250 km/h)",
        args.params, args.percent
    );
    println!(
        "base: onset {} km/h, offset {} km/h, onset frequency {} Hz",
        fmt_opt(on0),
        fmt_opt(off0),
        fmt_opt(f0)
    );
    println!(
        "{:<7} | {:>9} {:>9} {:>7} | {:>9} {:>9} {:>7} | {:>8} {:>8}",
        "param", "on -", "off -", "f -", "on +", "off +", "f +", "d on/d%", "d off/d%"
    );
    fs::create_dir_all(&args.out)?;
    let path = args.out.join("sensitivity.csv");
    let mut f = fs::File::create(&path)?;
    writeln!(
        f,
        "param,unit,base_value,factor,onset_kmh,offset_kmh,onset_freq_hz,base_onset_kmh,base_offset_kmh,base_onset_freq_hz"
    )?;
    let k = args.percent / 100.0;
    for q in SENSITIVITY_PARAMS {
        let mut res = Vec::new();
        for factor in [1.0 - k, 1.0 + k] {
            let w = window_of(&p.scaled(q, factor))?;
            writeln!(
                f,
                "{},{},{},{},{},{},{},{},{},{}",
                q.name(),
                q.unit(),
                p.get(q),
                factor,
                w.0.map_or(String::new(), |x| format!("{x:.6}")),
                w.1.map_or(String::new(), |x| format!("{x:.6}")),
                w.2.map_or(String::new(), |x| format!("{x:.6}")),
                on0.map_or(String::new(), |x| format!("{x:.6}")),
                off0.map_or(String::new(), |x| format!("{x:.6}")),
                f0.map_or(String::new(), |x| format!("{x:.6}")),
            )?;
            res.push(w);
        }
        // Central-difference slope in km/h per % change.
        let slope = |a: Option<f64>, b: Option<f64>| match (a, b) {
            (Some(a), Some(b)) => format!("{:.3}", (b - a) / (2.0 * args.percent)),
            _ => "-".into(),
        };
        println!(
            "{:<7} | {:>9} {:>9} {:>7} | {:>9} {:>9} {:>7} | {:>8} {:>8}",
            q.name(),
            fmt_opt(res[0].0),
            fmt_opt(res[0].1),
            fmt_opt(res[0].2),
            fmt_opt(res[1].0),
            fmt_opt(res[1].1),
            fmt_opt(res[1].2),
            slope(res[0].0, res[1].0),
            slope(res[0].1, res[1].1)
        );
    }
    println!("wrote {}", path.display());
    Ok(())
}
