//! `shimmy-sim sweep --controllers passive-off,asmc`: the time-domain map over speed x parameter x
//! controller. Every grid point is one closed-loop run (nonlinear plant with the MR damper,
//! simulated sensors, the core's controller at 1 kHz) at constant speed from an in-phase
//! wheel-yaw kick; the result is the shimmy-band wheel-yaw amplitude at the end of the run and a
//! shimmy yes/no (same rule as every other command: [`RunMetrics::shimmies`]). The map is drawn
//! with the linear Hopf boundary of the undamped plant on top, so the plane shows where the
//! nonlinear closed loop does better or worse than the linear no-damper prediction.
//!
//! Deterministic: each point is an independent run with the same sensor seed; points are
//! computed in parallel (rayon) and collected in grid order, so the CSV does not depend on the
//! number of threads.

use super::args::{axes_of, SweepArgs, MAX_RUNS};
use crate::model::disturbance::Scenario;
use crate::model::family::{yaw_state, FamilyVehicle, ParamInfo, SimModel};
use crate::model::registry::{self, ModelVisitor, Registered};
use crate::out::plot_util;
use crate::sim::run::closed_loop::{self, Arm, LoopConfig, RunMetrics};
use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use plotters::prelude::*;
use rayon::prelude::*;
use shimmy_core::control::ControllerKind;
use shimmy_core::stability::{self, CrossingKind};
use shimmy_core::units::{kmh_to_mps, mps_to_kmh};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Default grid of the time-domain sweep: speeds x parameter values.
pub const DEFAULT_STEPS: (usize, usize) = (25, 9);

/// One grid point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TdPoint {
    /// Parameter value.
    pub value: f64,
    /// Speed, km/h.
    pub speed_kmh: f64,
    /// Peak |psi_L| over the run, kick included, rad.
    pub peak_yaw_rad: f64,
    /// Shimmy-band amplitude in the last 0.5 s, rad.
    pub amp_end_rad: f64,
    /// Largest shimmy-band block amplitude, rad.
    pub amp_max_rad: f64,
    /// Sustained shimmy ([`RunMetrics::shimmies`]).
    pub shimmy: bool,
    /// Coil energy, J.
    pub energy_j: f64,
}

/// The map of one controller.
#[derive(Clone, Debug)]
pub struct TdMap {
    /// Controller (arm) name.
    pub controller: String,
    /// Points, parameter-major (row j = value j, column i = speed i).
    pub points: Vec<TdPoint>,
}

/// The grid and the linear reference shared by all controllers.
#[derive(Clone, Debug)]
pub struct TdGrid {
    /// Varied parameter.
    pub param: ParamInfo,
    /// Speeds, km/h.
    pub speeds_kmh: Vec<f64>,
    /// Parameter values.
    pub values: Vec<f64>,
    /// Linear Hopf crossings of the undamped plant per value: (speed in km/h, onset?).
    pub hopf: Vec<Vec<(f64, bool)>>,
}

/// Parses `--controllers` (the short forms `none`, `off`, `on` are accepted).
pub fn arms(a: &SweepArgs) -> Result<Vec<Arm>> {
    a.controllers
        .iter()
        .map(|n| {
            Arm::from_name(n, a.on_current_a as f32).with_context(|| {
                format!("--controllers {n}: allowed: no-damper, passive-off, passive-on, smc, asmc, skyhook (or none, off, on)")
            })
        })
        .collect()
}

fn grid<M: SimModel<N>, const N: usize>(
    a: &SweepArgs,
    vehicle: &FamilyVehicle<M>,
) -> Result<TdGrid> {
    let base = vehicle.model;
    let (speeds_kmh, values, param) = axes_of(a, &base, &vehicle.parts, DEFAULT_STEPS)?;
    let step = kmh_to_mps((a.v_max_kmh - a.v_min_kmh) / (speeds_kmh.len() - 1) as f64 / 4.0);
    let hopf = values
        .iter()
        .map(|&v| {
            let p = base.with_param(param.name, v)?;
            stability::hopf_crossings(
                &p.linear(),
                0.0,
                kmh_to_mps(a.v_min_kmh),
                kmh_to_mps(a.v_max_kmh),
                step,
                1e-4,
            )
            .map(|c| {
                c.iter()
                    .map(|x| (mps_to_kmh(x.speed_mps), x.kind == CrossingKind::Onset))
                    .collect()
            })
            .with_context(|| format!("Hopf crossings at {} = {v}", param.name))
        })
        .collect::<Result<_>>()?;
    Ok(TdGrid {
        param,
        speeds_kmh,
        values,
        hopf,
    })
}

/// One run: the vehicle with the swept parameter changed, its firmware still believing `base`.
fn point<M: SimModel<N>, const N: usize>(
    base: &FamilyVehicle<M>,
    g: &TdGrid,
    j: usize,
    i: usize,
    arm: Arm,
    a: &SweepArgs,
) -> Result<TdPoint> {
    let (value, v_kmh) = (g.values[j], g.speeds_kmh[i]);
    let plant = FamilyVehicle {
        model: base.model.with_param(g.param.name, value)?,
        ..*base
    };
    let mut cfg = LoopConfig::for_vehicle(&plant, arm, a.duration_s).with_model_vehicle(base);
    cfg.estimator = false;
    cfg.record_every = usize::MAX;
    cfg.sensors.seed = a.seed;
    cfg.x0 = yaw_state::<M, N>(a.kick_deg.to_radians());
    let mut sc = Scenario::constant_speed(kmh_to_mps(v_kmh));
    let r = closed_loop::run(&cfg, &mut sc, None)
        .with_context(|| format!("{} at {v_kmh} km/h, {} = {value}", arm.name(), g.param.name))?;
    let m: RunMetrics = r.metrics(&cfg, Some(0.0));
    Ok(TdPoint {
        value,
        speed_kmh: v_kmh,
        peak_yaw_rad: m.peak_yaw_rad,
        amp_end_rad: m.amp_end_rad,
        amp_max_rad: m.amp_max_rad,
        shimmy: m.shimmies(),
        energy_j: m.energy_j,
    })
}

/// Computes every controller's map (all points in parallel, collected in grid order); `ready`
/// is called once every option has passed its checks, before the runs (the command claims its
/// output folder there).
pub fn compute(
    a: &SweepArgs,
    ready: &mut dyn FnMut() -> Result<()>,
) -> Result<(TdGrid, Vec<TdMap>)> {
    struct On<'a, 'r>(&'a SweepArgs, &'r mut dyn FnMut() -> Result<()>);
    impl ModelVisitor for On<'_, '_> {
        type Output = Result<(TdGrid, Vec<TdMap>)>;
        fn visit<M: Registered<N>, const N: usize>(self, f: M::File) -> Self::Output {
            compute_on(self.0, &registry::family::<M, N>(f)?, self.1)
        }
    }
    registry::with_model(
        crate::sim::input::vehicle_file::load_model(&a.vehicle.spec)?,
        On(a, ready),
    )
}

/// [`compute`] on the vehicle `base` of any model of the family.
fn compute_on<M: SimModel<N>, const N: usize>(
    a: &SweepArgs,
    base: &FamilyVehicle<M>,
    ready: &mut dyn FnMut() -> Result<()>,
) -> Result<(TdGrid, Vec<TdMap>)> {
    let arms = arms(a)?;
    if arms.contains(&Arm::Mr(ControllerKind::MarginAsmc)) && base.model.host_app_model().is_none()
    {
        bail!(
            "--controllers margin-asmc: the firmware's margin report exists for the {} models \
             only",
            crate::model::registry::image_models()
        );
    }
    super::args::check(a)?;
    let runs = a.v_steps.unwrap_or(DEFAULT_STEPS.0)
        * a.factor_steps.unwrap_or(DEFAULT_STEPS.1)
        * arms.len();
    if runs > MAX_RUNS {
        bail!("--v-steps x --factor-steps x --controllers: {runs} closed-loop runs; allowed: at most {MAX_RUNS}");
    }
    let g = grid(a, base)?;
    ready()?;
    let (nv, np) = (g.speeds_kmh.len(), g.values.len());
    let jobs: Vec<(usize, usize, usize)> = (0..arms.len())
        .flat_map(|c| (0..np).flat_map(move |j| (0..nv).map(move |i| (c, j, i))))
        .collect();
    let bar = if a.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(jobs.len() as u64)
    };
    bar.set_style(
        ProgressStyle::with_template(
            "{bar:40} {pos}/{len} closed-loop runs {elapsed_precise} eta {eta}",
        )
        .context("progress template")?,
    );
    let pts: Vec<TdPoint> = jobs
        .par_iter()
        .map(|&(c, j, i)| {
            let p = point(base, &g, j, i, arms[c], a);
            bar.inc(1);
            p
        })
        .collect::<Result<_>>()?;
    bar.finish_and_clear();
    let maps = arms
        .iter()
        .zip(pts.chunks(nv * np))
        .map(|(arm, c)| TdMap {
            controller: arm.name().to_string(),
            points: c.to_vec(),
        })
        .collect();
    Ok((g, maps))
}

/// The CSV of one map (units in the header; the linear boundary is in `boundary-*.csv`).
pub fn csv(g: &TdGrid, m: &TdMap) -> String {
    let mut s = format!(
        "{} [{}],speed [km/h],controller,peak yaw [deg],end amplitude [deg],max amplitude [deg],shimmy [0/1],coil energy [J]\n",
        g.param.name,
        g.param.unit
    );
    for p in &m.points {
        let _ = writeln!(
            s,
            "{:e},{},{},{:e},{:e},{:e},{},{:e}",
            p.value,
            p.speed_kmh,
            m.controller,
            p.peak_yaw_rad.to_degrees(),
            p.amp_end_rad.to_degrees(),
            p.amp_max_rad.to_degrees(),
            u8::from(p.shimmy),
            p.energy_j
        );
    }
    s
}

fn boundary_csv(g: &TdGrid) -> String {
    let mut b = format!(
        "{} [{}],linear Hopf crossing without damper [km/h],kind\n",
        g.param.name, g.param.unit
    );
    for (v, cs) in g.values.iter().zip(&g.hopf) {
        for (s, on) in cs {
            let _ = writeln!(b, "{v:e},{s:.4},{}", if *on { "onset" } else { "offset" });
        }
    }
    b
}

/// Heat map of the end amplitude (white 0 -> red at `scale_deg`), shimmy cells marked with a
/// black cross, the linear no-damper Hopf boundary as black dots joined per onset/offset.
pub fn plot(path: &Path, g: &TdGrid, m: &TdMap, set: &str, scale_deg: f64) -> Result<()> {
    let png = crate::sim::input::files::PendingFile::new(path);
    let picture =
        BitMapBackend::new(png.tmp(), (1000 + plot_util::COLOUR_BAR_PX, 700)).into_drawing_area();
    picture.fill(&WHITE)?;
    let (root, bar) = picture.split_horizontally(1000);
    let cells = plot_util::cells(
        &g.speeds_kmh,
        g.values[0],
        g.values[g.values.len() - 1],
        g.values.len(),
    );
    let (dv, dp) = (cells.dx, cells.dy);
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "{set}, {}: wheel-yaw amplitude at the end [deg] (white 0, red >= {scale_deg:.1}); x: shimmy; black: linear Hopf boundary, no damper",
                m.controller
            ),
            ("sans-serif", 16),
        )
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(80)
        .build_cartesian_2d(cells.x, cells.y)?;
    plot_util::mesh(
        &mut chart,
        "speed [km/h]",
        &format!("{} [{}]", g.param.name, g.param.unit),
    )?;
    chart.draw_series(m.points.iter().map(|p| {
        Rectangle::new(
            [
                (p.speed_kmh - dv / 2.0, p.value - dp / 2.0),
                (p.speed_kmh + dv / 2.0, p.value + dp / 2.0),
            ],
            plot_util::white_to_red(p.amp_end_rad.to_degrees() / scale_deg).filled(),
        )
    }))?;
    plot_util::colour_bar(
        &bar,
        0.0,
        scale_deg,
        "amplitude at the end [deg]",
        40,
        |a| plot_util::white_to_red(a / scale_deg),
    )?;
    chart.draw_series(
        m.points
            .iter()
            .filter(|p| p.shimmy)
            .map(|p| Cross::new((p.speed_kmh, p.value), 4, BLACK)),
    )?;
    for onset in [true, false] {
        let line: Vec<(f64, f64)> = g
            .values
            .iter()
            .zip(&g.hopf)
            .filter_map(|(v, cs)| cs.iter().find(|c| c.1 == onset).map(|c| (c.0, *v)))
            .collect();
        chart.draw_series(LineSeries::new(line.clone(), BLACK.stroke_width(2)))?;
        chart.draw_series(line.iter().map(|&p| Circle::new(p, 3, BLACK.filled())))?;
    }
    png.commit(picture.present())?;
    Ok(())
}

/// The command: compute, write CSV + PNG per controller, print a summary.
pub fn command(a: &SweepArgs) -> Result<Vec<PathBuf>> {
    let mut _out_dir = None;
    let wall = std::time::Instant::now();
    let (g, maps) = compute(a, &mut || {
        _out_dir = Some(crate::sim::input::files::OutDir::claim(&a.out_dir())?);
        Ok(())
    })?;
    let wall_s = wall.elapsed().as_secs_f64();
    let name = g.param.name;
    let boundary = a.out_dir().join(format!("td-boundary-{name}.csv"));
    crate::sim::input::files::write_file(&boundary, boundary_csv(&g))?;
    let mut files = vec![boundary];
    // One colour scale for all controllers (so maps compare), at least 1 deg.
    let scale_deg = maps
        .iter()
        .flat_map(|m| m.points.iter().map(|p| p.amp_end_rad.to_degrees()))
        .fold(1.0f64, f64::max);
    let inside = |v: f64, j: usize| {
        let on = g.hopf[j].iter().find(|c| c.1).map(|c| c.0);
        let off = g.hopf[j].iter().find(|c| !c.1).map(|c| c.0);
        on.is_some_and(|on| v > on && off.is_none_or(|off| v < off))
    };
    println!(
        "{} x {} grid ({} = {:.4e}..{:.4e} {}, {:.1}..{:.1} km/h), {} s from a {} deg kick, seed {}: {} runs in {:.1} s wall",
        g.speeds_kmh.len(),
        g.values.len(),
        name,
        g.values[0],
        g.values[g.values.len() - 1],
        g.param.unit,
        a.v_min_kmh,
        a.v_max_kmh,
        a.duration_s,
        a.kick_deg,
        a.seed,
        maps.len() * g.speeds_kmh.len() * g.values.len(),
        wall_s
    );
    println!(
        "  {:<12} {:>14} {:>22} {:>22} {:>16}",
        "controller",
        "shimmy points",
        "inside linear window",
        "outside lin. window",
        "max end amp deg"
    );
    for m in &maps {
        let nv = g.speeds_kmh.len();
        let (mut n, mut n_in, mut n_out, mut tot_in) = (0, 0, 0, 0);
        for (k, p) in m.points.iter().enumerate() {
            let ins = inside(p.speed_kmh, k / nv);
            tot_in += usize::from(ins);
            if p.shimmy {
                n += 1;
                if ins {
                    n_in += 1;
                } else {
                    n_out += 1;
                }
            }
        }
        let amp = m
            .points
            .iter()
            .map(|p| p.amp_end_rad.to_degrees())
            .fold(0.0, f64::max);
        println!(
            "  {:<12} {:>8}/{:<5} {:>16}/{:<5} {:>16}/{:<5} {:>16.3}",
            m.controller,
            n,
            m.points.len(),
            n_in,
            tot_in,
            n_out,
            m.points.len() - tot_in,
            amp
        );
        let c = a.out_dir().join(format!("td-{name}-{}.csv", m.controller));
        crate::sim::input::files::write_file(&c, csv(&g, m))?;
        let png = a.out_dir().join(format!("td-{name}-{}.png", m.controller));
        plot(&png, &g, m, &a.vehicle.spec, scale_deg)?;
        files.push(c);
        files.push(png);
    }
    for f in &files {
        println!("  wrote {}", f.display());
    }
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(out: &Path) -> SweepArgs {
        SweepArgs {
            vehicle: crate::cmd::VehicleArg::new("nominal"),
            param: "k_d".into(),
            factor_min: 1.0,
            factor_max: 1.0,
            factor_steps: Some(1),
            v_min_kmh: 20.0,
            v_max_kmh: 130.0,
            v_steps: Some(3), // 20, 75, 130 km/h
            damper_current_a: vec![],
            ref_amplitude_deg: 0.5,
            out: crate::cmd::OutArg::new(out),
            quiet: true,
            controllers: vec!["no-damper".into(), "asmc".into()],
            on_current_a: 1.0,
            duration_s: 4.0,
            kick_deg: 3.0,
            seed: 3,
        }
    }

    fn in_pool(threads: usize, a: &SweepArgs) -> (TdGrid, Vec<TdMap>) {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| compute(a, &mut || Ok(())).unwrap())
    }

    /// Same seed, same numbers: a small grid computed on 1 and on 2 threads gives byte-identical
    /// CSV; a different seed changes the numbers (the seed reaches the runs).
    #[test]
    fn time_domain_sweep_is_deterministic() {
        let out = std::env::temp_dir().join(format!("shimmy-sweep-td-{}", std::process::id()));
        let a = args(&out);
        let (g1, m1) = in_pool(1, &a);
        let (g2, m2) = in_pool(2, &a);
        for (x, y) in m1.iter().zip(&m2) {
            assert_eq!(csv(&g1, x).as_bytes(), csv(&g2, y).as_bytes());
        }
        let (g3, m3) = in_pool(
            2,
            &SweepArgs {
                seed: 4,
                ..a.clone()
            },
        );
        assert_ne!(csv(&g1, &m1[1]), csv(&g3, &m3[1]), "the seed must matter");
    }

    /// The time-domain map agrees with the linear prediction where it must: without a damper
    /// the plant shimmies inside the Hopf window (75 km/h, between the nominal 29 and 84 km/h
    /// computed here) and not far above it (130 km/h); ASMC removes the shimmy inside the
    /// window. The command writes a CSV per controller and real PNG maps.
    #[test]
    fn map_agrees_with_the_linear_window_and_asmc_suppresses() {
        let out = std::env::temp_dir().join(format!("shimmy-sweep-td2-{}", std::process::id()));
        let a = args(&out);
        let (g, maps) = compute(&a, &mut || Ok(())).unwrap();
        let (on, off) = (g.hopf[0][0], g.hopf[0][1]);
        assert!(
            on.1 && !off.1 && on.0 < 75.0 && off.0 > 75.0 && off.0 < 130.0,
            "{on:?} {off:?}"
        );
        let nd = &maps[0].points;
        let asmc = &maps[1].points;
        assert!(nd[1].shimmy, "no damper at 75 km/h: {:?}", nd[1]);
        assert!(!nd[2].shimmy, "no damper at 130 km/h: {:?}", nd[2]);
        assert!(!asmc[1].shimmy, "asmc at 75 km/h: {:?}", asmc[1]);
        assert!(asmc[1].amp_end_rad < 0.1 * nd[1].amp_end_rad);
        let files = command(&a).unwrap();
        assert_eq!(files.len(), 5);
        for f in files
            .iter()
            .filter(|f| f.extension().is_some_and(|e| e == "png"))
        {
            crate::out::plot_util::assert_real_plot(f, 4).unwrap();
        }
        let text = std::fs::read_to_string(out.join("td-k_d-asmc.csv")).unwrap();
        assert!(text.starts_with("k_d [N m/rad],speed [km/h],controller,peak yaw [deg]"));
        assert_eq!(text.lines().count(), 4);
        let _ = std::fs::remove_dir_all(&out);
    }

    #[test]
    fn unknown_controller_is_named() {
        let mut a = args(Path::new("/nonexistent"));
        a.controllers = vec!["pid".into()];
        assert!(
            format!("{:#}", compute(&a, &mut || Ok(())).unwrap_err()).contains("--controllers pid")
        );
    }
}
