//! `shimmy-sim sway-damping`: the trailer's sway damper (`docs/trailer.md`): the damper it needs
//! to stay stable (and to keep a damping-ratio target) over speed, and Diboll & Hagen's
//! dimensionless map, the damping ratio needed over the Strouhal number `s omega / V` with the
//! energy term `mu G z / V^2` as parameter (PNG + CSV).
use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use plotters::prelude::*;
use shimmy_core::model::LinearModel;
use shimmy_core::stability::{self, CrossingKind, DEFAULT_TOL_MPS};
use shimmy_core::units::{kmh_to_mps, mps_to_kmh};
use shimmy_core::vehicles::trailer::TrailerParams;

use crate::model::registry::Registered;
use crate::out::plot_util;
use crate::sim::input::arg_range::{self, Range};
use crate::sim::input::vehicle_file;
use crate::sim::study::trailer_study::{self, DhPoint, ZETA_DAMPER_MAX};

/// Options of `shimmy-sim sway-damping`.
#[derive(clap::Args, Debug, Clone)]
pub struct SwayDampingArgs {
    /// Trailer: `trailer` or a vehicle file with `model = "trailer-2dof"`.
    #[arg(long, default_value = "trailer")]
    pub vehicle: String,
    /// Damping-ratio target of the second curve (every oscillatory mode at least this): 0.001
    /// to 0.5.
    #[arg(long, default_value_t = 0.05, allow_negative_numbers = true, value_parser = arg_range::f64_in(ZETA_TARGET))]
    pub zeta: f64,
    /// Lowest speed, km/h: 1 to 250, below `--v-max-kmh`.
    #[arg(long, default_value_t = 40.0, allow_negative_numbers = true, value_parser = arg_range::speed_kmh())]
    pub v_min_kmh: f64,
    /// Highest speed, km/h: 1 to 250.
    #[arg(long, default_value_t = 180.0, allow_negative_numbers = true, value_parser = arg_range::speed_kmh())]
    pub v_max_kmh: f64,
    /// Speed step, km/h: 0.1 to 50.
    #[arg(long, default_value_t = 2.0, allow_negative_numbers = true, value_parser = arg_range::f64_in(STEP_KMH))]
    pub step_kmh: f64,
    /// Output folder (`--out`; default out/sway-damping, [`Self::out_dir`]).
    #[command(flatten)]
    pub out: crate::cmd::OutArg,
}

impl SwayDampingArgs {
    /// The output folder: `--out`, else out/sway-damping.
    pub fn out_dir(&self) -> PathBuf {
        self.out.dir_or("out/sway-damping")
    }
}

/// Damping-ratio target: 0.001 to 0.5.
pub const ZETA_TARGET: Range = Range::closed(0.001, 0.5, "-");
/// Speed step: 0.1 to 50 km/h.
pub const STEP_KMH: Range = Range::closed(0.1, 50.0, "km/h");

/// Speeds of the named trailer that set the map's energy terms, km/h.
pub const DH_SPEEDS_KMH: [f64; 5] = [60.0, 80.0, 100.0, 120.0, 140.0];
/// Strouhal numbers of the map: 0.02 to 0.6.
fn dh_strouhals() -> Vec<f64> {
    (0..=58).map(|i| 0.02 + 0.01 * f64::from(i)).collect()
}

/// One row of the damper-vs-speed table.
struct SpeedRow {
    v_kmh: f64,
    c_crit: Option<f64>,
    c_target: Option<f64>,
}

/// Runs `shimmy-sim sway-damping`.
pub fn command(args: &SwayDampingArgs) -> Result<()> {
    arg_range::SPEED_KMH.check("--v-min-kmh", args.v_min_kmh)?;
    arg_range::SPEED_KMH.check("--v-max-kmh", args.v_max_kmh)?;
    STEP_KMH.check("--step-kmh", args.step_kmh)?;
    ZETA_TARGET.check("--zeta", args.zeta)?;
    anyhow::ensure!(
        args.v_max_kmh > args.v_min_kmh,
        "--v-min-kmh {} must be below --v-max-kmh {}",
        args.v_min_kmh,
        args.v_max_kmh
    );
    let t = match TrailerParams::from_any(vehicle_file::load_model(&args.vehicle)?) {
        Ok(t) => t,
        Err(_) => bail!(
            "--vehicle `{}`: sway-damping needs a {} vehicle (`trailer` or a file with that model)",
            args.vehicle,
            TrailerParams::NAME
        ),
    };
    let _out_dir = crate::sim::input::files::OutDir::claim(&args.out_dir())?;
    let crossings = stability::hopf_crossings(
        &t,
        0.0,
        kmh_to_mps(1.0),
        kmh_to_mps(250.0),
        kmh_to_mps(1.0),
        DEFAULT_TOL_MPS,
    )
    .context("Hopf search")?;
    println!(
        "sway damper of `{}` (damper lever l_d = {} m)",
        args.vehicle, t.l_d
    );
    match crossings.iter().find(|c| c.kind == CrossingKind::Onset) {
        Some(c) => println!(
            "without damper: sway onset {:.2} km/h, {:.3} Hz ({} mode)",
            mps_to_kmh(c.speed_mps),
            c.freq_hz,
            c.shape.name()
        ),
        None => println!("without damper: no sway onset in 1..250 km/h"),
    }
    let n = ((args.v_max_kmh - args.v_min_kmh) / args.step_kmh).round() as usize;
    let mut rows = Vec::with_capacity(n + 1);
    for i in 0..=n {
        let v_kmh = args.v_min_kmh + i as f64 * args.step_kmh;
        let v = kmh_to_mps(v_kmh);
        rows.push(SpeedRow {
            v_kmh,
            c_crit: trailer_study::damper_needed(&t, v, 0.0)?,
            c_target: trailer_study::damper_needed(&t, v, args.zeta)?,
        });
    }
    let opt = |c: Option<f64>, f: &dyn Fn(f64) -> f64| {
        c.map_or(
            format!("> {:.0}", f(t.damper_of_zeta(ZETA_DAMPER_MAX))),
            |c| format!("{:.0}", f(c)),
        )
    };
    println!();
    println!(
        "{:>8} | {:>16} {:>18} {:>9} | {:>16} {:>18}",
        "V km/h",
        "c_crit N s/m",
        "c_crit l_d^2 Nms/rd",
        "zeta_d",
        format!("c(zeta {}) N s/m", args.zeta),
        "c l_d^2 N m s/rad"
    );
    let ld2 = t.l_d * t.l_d;
    for r in rows
        .iter()
        .filter(|r| (r.v_kmh / 10.0 - (r.v_kmh / 10.0).round()).abs() < 1e-9)
    {
        println!(
            "{:>8.1} | {:>16} {:>18} {:>9} | {:>16} {:>18}",
            r.v_kmh,
            opt(r.c_crit, &|c| c),
            opt(r.c_crit, &|c| c * ld2),
            r.c_crit
                .map_or("-".into(), |c| format!("{:.4}", t.damper_zeta(c))),
            opt(r.c_target, &|c| c),
            opt(r.c_target, &|c| c * ld2),
        );
    }
    let energy: Vec<f64> = DH_SPEEDS_KMH
        .iter()
        .map(|&v| t.energy_term(kmh_to_mps(v)))
        .collect();
    let strouhals = dh_strouhals();
    let map = trailer_study::dh_map(&t, &energy, &strouhals)?;
    println!();
    println!(
        "Diboll & Hagen's map: zeta needed over s omega / V (s = l = {} m, omega = sqrt(k_y/m)), \
         one curve per mu G z / V^2 (mu = C_a/F_z, z = a); the vehicle at 100 km/h: \
         s omega / V = {:.3}, mu G z / V^2 = {:.3}",
        t.l,
        t.strouhal(kmh_to_mps(100.0)),
        t.energy_term(kmh_to_mps(100.0))
    );
    for (e, v) in energy.iter().zip(DH_SPEEDS_KMH) {
        let curve: Vec<&DhPoint> = map.iter().filter(|p| p.energy_term == *e).collect();
        // the stiff-hitch end: the first Strouhal number after the last one that needs damping
        let free = curve
            .iter()
            .rposition(|p| p.zeta_needed != Some(0.0))
            .map_or(Some(0), |i| (i + 1 < curve.len()).then_some(i + 1))
            .map_or("-".into(), |i| format!("{:.3}", curve[i].strouhal));
        let peak = curve
            .iter()
            .filter_map(|p| p.zeta_needed.map(|z| (p.strouhal, z)))
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .map_or("-".into(), |(s, z)| format!("{z:.4} at {s:.2}"));
        let at = |s: f64| {
            curve
                .iter()
                .min_by(|a, b| (a.strouhal - s).abs().total_cmp(&(b.strouhal - s).abs()))
                .and_then(|p| p.zeta_needed)
                .map_or("-".into(), |z| format!("{z:.4}"))
        };
        println!(
            "  mu G z / V^2 = {e:.3} ({v:.0} km/h): zeta needed {} at s omega / V 0.1, {} at 0.2, \
             {} at 0.3; peak {peak}; none needed from s omega / V {free} up",
            at(0.1),
            at(0.2),
            at(0.3)
        );
    }

    let csv = args.out_dir().join("damping.csv");
    write_speed_csv(&csv, &t, &rows, args.zeta)?;
    let dcsv = args.out_dir().join("diboll-hagen.csv");
    write_dh_csv(&dcsv, &map)?;
    let png = args.out_dir().join("sway-damping.png");
    plot(&png, &t, &rows, &map, &energy, &args.vehicle, args.zeta)?;
    println!(
        "wrote {}, {}, {}",
        csv.display(),
        dcsv.display(),
        png.display()
    );
    Ok(())
}

fn write_speed_csv(path: &Path, t: &TrailerParams, rows: &[SpeedRow], zeta: f64) -> Result<()> {
    let mut f = Vec::new();
    writeln!(
        f,
        "speed_kmh,c_crit_nspm,zeta_d_crit,zeta_target,c_target_nspm,zeta_d_target,l_d_m"
    )?;
    let o = |x: Option<f64>| x.map_or(String::new(), |x| format!("{x:.6}"));
    for r in rows {
        writeln!(
            f,
            "{:.3},{},{},{zeta},{},{},{}",
            r.v_kmh,
            o(r.c_crit),
            o(r.c_crit.map(|c| t.damper_zeta(c))),
            o(r.c_target),
            o(r.c_target.map(|c| t.damper_zeta(c))),
            t.l_d
        )?;
    }
    crate::sim::input::files::write_file(path, &f)
}

fn write_dh_csv(path: &Path, map: &[DhPoint]) -> Result<()> {
    let mut f = Vec::new();
    writeln!(
        f,
        "energy_term,strouhal,speed_kmh,k_y_npm,c_needed_nspm,zeta_needed"
    )?;
    let o = |x: Option<f64>| x.map_or(String::new(), |x| format!("{x:.8}"));
    for p in map {
        writeln!(
            f,
            "{:.6},{:.6},{:.4},{:.4},{},{}",
            p.energy_term,
            p.strouhal,
            mps_to_kmh(p.v_mps),
            p.k_y_npm,
            o(p.c_needed_nspm),
            o(p.zeta_needed)
        )?;
    }
    crate::sim::input::files::write_file(path, &f)
}

fn plot(
    path: &Path,
    t: &TrailerParams,
    rows: &[SpeedRow],
    map: &[DhPoint],
    energy: &[f64],
    name: &str,
    zeta: f64,
) -> Result<()> {
    let png = crate::sim::input::files::PendingFile::new(path);
    let root = BitMapBackend::new(png.tmp(), (1000, 900)).into_drawing_area();
    root.fill(&WHITE)?;
    let (top, bottom) = root.split_vertically(430);
    // top: the damper needed over speed, kN s/m
    let xs: Vec<f64> = rows.iter().map(|r| r.v_kmh).collect();
    let hi = rows
        .iter()
        .filter_map(|r| r.c_target)
        .fold(1.0_f64, f64::max)
        * 1.05e-3;
    let mut chart = ChartBuilder::on(&top)
        .caption(
            format!("{name}: sway damper needed (lever {} m) [kN s/m]", t.l_d),
            ("sans-serif", 18),
        )
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(xs[0]..xs[xs.len() - 1], 0.0..hi)?;
    plot_util::mesh(&mut chart, "speed [km/h]", "c [kN s/m]")?;
    for (sel, label, col) in [
        (
            0usize,
            "stable (zeta = 0)".to_string(),
            plot_util::COLORS[1],
        ),
        (
            1,
            format!("every mode zeta >= {zeta}"),
            plot_util::COLORS[2],
        ),
    ] {
        let pts: Vec<(f64, f64)> = rows
            .iter()
            .filter_map(|r| {
                let c = if sel == 0 { r.c_crit } else { r.c_target };
                c.map(|c| (r.v_kmh, c * 1e-3))
            })
            .collect();
        chart
            .draw_series(LineSeries::new(pts, col.stroke_width(2)))?
            .label(label)
            .legend(plot_util::line_marker(col, 2));
    }
    plot_util::legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
    // bottom: Diboll & Hagen's map
    let z_hi = map
        .iter()
        .filter_map(|p| p.zeta_needed)
        .fold(0.01_f64, f64::max)
        * 1.05;
    let s: Vec<f64> = map.iter().map(|p| p.strouhal).collect();
    let (s0, s1) = (
        s.iter().copied().fold(f64::INFINITY, f64::min),
        s.iter().copied().fold(f64::NEG_INFINITY, f64::max),
    );
    let mut chart = ChartBuilder::on(&bottom)
        .caption(
            "damping ratio needed vs Strouhal number s omega / V (one curve per mu G z / V^2)",
            ("sans-serif", 18),
        )
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(s0..s1, 0.0..z_hi)?;
    plot_util::mesh(&mut chart, "s omega / V", "zeta needed")?;
    for (i, e) in energy.iter().enumerate() {
        let col = plot_util::COLORS[(i + 1) % plot_util::COLORS.len()];
        let pts: Vec<(f64, f64)> = map
            .iter()
            .filter(|p| p.energy_term == *e)
            .filter_map(|p| p.zeta_needed.map(|z| (p.strouhal, z)))
            .collect();
        chart
            .draw_series(LineSeries::new(pts, col.stroke_width(2)))?
            .label(format!("mu G z / V^2 = {e:.3}"))
            .legend(plot_util::line_marker(col, 2));
    }
    plot_util::legend(&mut chart, SeriesLabelPosition::UpperRight)?;
    png.commit(root.present())?;
    Ok(())
}
