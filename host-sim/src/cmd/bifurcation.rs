//! `shimmy-sim bifurcation`: bifurcation study of the nonlinear plant. For each speed, open-loop
//! runs ([`run_speed`]) from a small and a large initial wheel-yaw disturbance measure the
//! settled oscillation amplitude (peak |psi_L| over the last window) and whether it still grows
//! or decays; the periodic orbits, stable and unstable, continued in speed by shooting
//! ([`crate::model::periodic_orbit`]) give the Hopf type, the folds of cycles, the bistable
//! window and the disturbance margin in it; table, CSV and PNG.

use crate::model::family::{param_names, SimModel};
use crate::model::periodic_orbit::{Branch, HopfPoint, Limits, Shooting, Start};
use crate::model::registry::{self, ModelVisitor, Registered};
use crate::model::registry::{ReferenceModel, REFERENCE_N};
use crate::sim::input::arg_range::{self, Range};
use crate::sim::run::open_loop::{run_speed, DamperSetting, RunSummary};
use crate::sim::run::reference::shimmy_mode_with_damper;
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use rayon::prelude::*;
use shimmy_core::units::{kmh_to_mps, mps_to_kmh};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Options of the `bifurcation` command, on the vehicle model `M` (the car by default).
#[derive(Clone, Debug)]
pub struct BifurcationOptions<M: SimModel<N> = ReferenceModel, const N: usize = { REFERENCE_N }> {
    /// Parameter set.
    pub params: M,
    /// Name of the parameter set (for titles).
    pub params_name: String,
    /// Damper setting.
    pub damper: DamperSetting,
    /// Speed grid, km/h.
    pub v_min_kmh: f64,
    /// Speed grid, km/h.
    pub v_max_kmh: f64,
    /// Speed grid, km/h.
    pub step_kmh: f64,
    /// Small start, deg.
    pub small_deg: f64,
    /// Large start, deg.
    pub large_deg: f64,
    /// Run length, s.
    pub duration_s: f64,
    /// Measurement window, s.
    pub window_s: f64,
    /// Output directory.
    pub out: PathBuf,
}

/// One row of the study.
#[derive(Clone, Copy, Debug)]
pub struct BifurcationRow {
    /// Speed, km/h.
    pub v_kmh: f64,
    /// From the small start.
    pub small: RunSummary,
    /// From the large start.
    pub large: RunSummary,
    /// Real part (1/s) of the shimmy mode (tracked by its shape) of the plant as the small start
    /// runs: A(V) with the damper's equivalent viscous coefficient at its current and the small
    /// start's amplitude (c = 0 without damper): the linear prediction to compare with.
    pub eig_re_per_s: f64,
}

/// Runs the study in parallel over speeds (both starts per speed).
pub fn sweep<M: SimModel<N>, const N: usize>(
    o: &BifurcationOptions<M, N>,
    progress: bool,
) -> Result<Vec<BifurcationRow>> {
    anyhow::ensure!(
        o.step_kmh > 0.0 && o.v_max_kmh >= o.v_min_kmh,
        "bad speed grid"
    );
    let n = ((o.v_max_kmh - o.v_min_kmh) / o.step_kmh + 1e-9).floor() as usize + 1;
    let speeds: Vec<f64> = (0..n)
        .map(|k| o.v_min_kmh + k as f64 * o.step_kmh)
        .collect();
    let bar = if progress {
        let b = ProgressBar::new(2 * n as u64);
        b.set_style(
            ProgressStyle::with_template(
                "{bar:40} {pos}/{len} runs  {elapsed_precise} (eta {eta})",
            )
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        b
    } else {
        ProgressBar::hidden()
    };
    let jobs: Vec<(usize, f64, f64)> = speeds
        .iter()
        .enumerate()
        .flat_map(|(i, &v)| [(i, v, o.small_deg), (i, v, o.large_deg)])
        .collect();
    let results: Vec<Result<(usize, RunSummary)>> = jobs
        .par_iter()
        .map(|&(i, v_kmh, deg)| {
            let r = run_speed(
                &o.params,
                o.damper,
                kmh_to_mps(v_kmh),
                deg.to_radians(),
                o.duration_s,
                o.window_s,
            )
            .with_context(|| format!("run at {v_kmh} km/h from {deg} deg"))?;
            bar.inc(1);
            Ok((i, r))
        })
        .collect();
    bar.finish_and_clear();
    let mut small = vec![None; n];
    let mut large = vec![None; n];
    for r in results {
        let (i, s) = r?;
        if (s.psi0_rad - o.small_deg.to_radians()).abs() < 1e-15 {
            small[i] = Some(s);
        } else {
            large[i] = Some(s);
        }
    }
    speeds
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            let (damper, current) = match &o.damper {
                DamperSetting::Off => (None, 0.0),
                DamperSetting::Mr { damper, current_a } => (Some(damper), *current_a),
            };
            let eig_re_per_s = shimmy_mode_with_damper(
                &o.params,
                damper,
                kmh_to_mps(v),
                current,
                o.small_deg.to_radians(),
            )
            .map_or(f64::NAN, |(m, _)| m.re);
            Ok(BifurcationRow {
                eig_re_per_s,
                v_kmh: v,
                small: small[i].context("missing run")?,
                large: large[i].context("missing run")?,
            })
        })
        .collect()
}

/// The `bifurcation` command: sweep, table, CSV, PNG.
pub fn run<M: SimModel<N>, const N: usize>(o: &BifurcationOptions<M, N>) -> Result<()> {
    let _out_dir = crate::sim::input::files::OutDir::claim(&o.out)?;
    let t0 = std::time::Instant::now();
    let rows = sweep(o, true)?;
    let wall = t0.elapsed().as_secs_f64();
    let damper = match o.damper {
        DamperSetting::Off => "no damper".to_string(),
        DamperSetting::Mr { current_a, .. } => format!("MR damper at {current_a} A"),
    };
    println!(
        "bifurcation: `{}`, {damper}; {} s runs, amplitude = peak |psi_L| over the last {} s",
        o.params_name, o.duration_s, o.window_s
    );
    println!(
        "{:>8} | {:>10} {:>9} | {:>10} {:>9} | {:>14}",
        "V km/h",
        format!("{}deg amp", o.small_deg),
        "trend",
        format!("{}deg amp", o.large_deg),
        "trend",
        "eig re 1/s (*)"
    );
    for r in &rows {
        println!(
            "{:>8.1} | {:>10.4} {:>9} | {:>10.4} {:>9} | {:>14.4}",
            r.v_kmh,
            r.small.amp_end_rad.to_degrees(),
            r.small.trend.name(),
            r.large.amp_end_rad.to_degrees(),
            r.large.trend.name(),
            r.eig_re_per_s
        );
    }
    println!(
        "amplitudes in deg; (*) shimmy mode of A(V) with the damper's c_eq at its current and \
         the small start's amplitude (no damper: c = 0)"
    );
    if let Some((lo, hi)) = window(&rows, |r| r.small.shimmies()) {
        println!("small disturbances end in shimmy from {lo} to {hi} km/h (grid points)");
    } else {
        println!("small disturbances decay at every speed of the grid");
    }
    if let Some((lo, hi)) = window(&rows, |r| r.large.shimmies()) {
        println!("large disturbances end in shimmy from {lo} to {hi} km/h (grid points)");
    }
    let simulated = 2.0 * rows.len() as f64 * o.duration_s;
    println!(
        "{} runs, {simulated:.0} s simulated in {wall:.1} s wall ({:.0}x real time over all cores)",
        2 * rows.len(),
        simulated / wall
    );
    let t1 = std::time::Instant::now();
    let study = orbits(o, &rows)?;
    print_orbits(&study, &rows);
    println!(
        "periodic orbits: {} on {} branches in {:.1} s wall",
        study.branches.iter().map(|b| b.orbits.len()).sum::<usize>(),
        study.branches.len(),
        t1.elapsed().as_secs_f64()
    );
    let csv = o.out.join("bifurcation.csv");
    write_csv(&csv, &rows)?;
    let orbits_csv = o.out.join("orbits.csv");
    write_orbits_csv(&orbits_csv, &study)?;
    let png = o.out.join("bifurcation.png");
    plot(&png, &rows, &study, o, &damper)?;
    println!(
        "wrote {}, {} and {}",
        csv.display(),
        orbits_csv.display(),
        png.display()
    );
    Ok(())
}

/// The periodic orbits of a study: the branches continued from the plant's Hopf points in the
/// speed range or, with none, from the cycle the large start settles on at the highest grid
/// speed where it shimmies.
#[derive(Clone, Debug)]
pub struct OrbitStudy {
    /// The plant's Hopf points in the speed range.
    pub hopf: Vec<HopfPoint>,
    /// The continued branches.
    pub branches: Vec<Branch>,
    /// Speeds (m/s) where the straight run's Jacobian has a pair in the right half-plane, on
    /// the grid of the rows.
    pub straight_unstable: Vec<(f64, bool)>,
}

impl OrbitStudy {
    /// The amplitudes (rad) of the stable and the unstable cycles at `v_mps`: linear
    /// interpolation between neighbouring orbits of the same stability that bracket it
    /// (`lo <= v < hi`).
    pub fn cycles_at(&self, v_mps: f64) -> (Vec<f64>, Vec<f64>) {
        let (mut stable, mut unstable) = (Vec::new(), Vec::new());
        for b in &self.branches {
            for w in b.orbits.windows(2) {
                let (a, c) = (&w[0], &w[1]);
                if a.stable() != c.stable() {
                    continue;
                }
                let (lo, hi) = (a.speed_mps.min(c.speed_mps), a.speed_mps.max(c.speed_mps));
                // half-open, so that a speed on an orbit joining two segments counts once
                if v_mps < lo || v_mps >= hi {
                    continue;
                }
                let f = (v_mps - a.speed_mps) / (c.speed_mps - a.speed_mps);
                let amp = a.amp_rad + f * (c.amp_rad - a.amp_rad);
                if a.stable() {
                    stable.push(amp);
                } else {
                    unstable.push(amp);
                }
            }
        }
        (stable, unstable)
    }

    /// The type of the Hopf point `h` from the branch through it: supercritical (`true`) when
    /// the orbits within 0.2 km/h of it and below 0.1 deg are stable, subcritical when they
    /// are unstable; `None` without such orbits.
    pub fn supercritical(&self, h: &HopfPoint) -> Option<bool> {
        let near: Vec<bool> = self
            .branches
            .iter()
            .flat_map(|b| b.orbits.iter())
            .filter(|o| {
                (o.speed_mps - h.speed_mps).abs() < kmh_to_mps(0.2)
                    && o.amp_rad < 0.1f64.to_radians()
            })
            .map(|o| o.stable())
            .collect();
        match (near.iter().all(|&s| s), near.iter().any(|&s| s)) {
            _ if near.is_empty() => None,
            (true, _) => Some(true),
            (false, false) => Some(false),
            _ => None,
        }
    }

    /// The folds of cycles, m/s, in speed order (one per 0.01 km/h).
    pub fn folds_mps(&self) -> Vec<f64> {
        let mut f: Vec<f64> = self
            .branches
            .iter()
            .flat_map(|b| b.folds_mps.iter().copied())
            .collect();
        f.sort_by(f64::total_cmp);
        f.dedup_by(|a, b| (*a - *b).abs() < kmh_to_mps(0.01));
        f
    }

    /// The grid speeds (km/h) where the straight run is linearly stable and a stable cycle
    /// coexists with it (a large enough disturbance starts shimmy), with the smallest
    /// unstable cycle's amplitude there (rad): the disturbance margin.
    pub fn bistable(&self) -> Vec<(f64, Option<f64>)> {
        self.straight_unstable
            .iter()
            .filter(|(_, unstable)| !unstable)
            .filter_map(|&(v, _)| {
                let (stable, unstable) = self.cycles_at(v);
                (!stable.is_empty()).then(|| {
                    let margin = unstable.into_iter().reduce(f64::min);
                    (mps_to_kmh(v), margin)
                })
            })
            .collect()
    }
}

/// Continues the periodic orbits of the study `o` (its rows give the seed when the plant has
/// no Hopf point in the range).
pub fn orbits<M: SimModel<N>, const N: usize>(
    o: &BifurcationOptions<M, N>,
    rows: &[BifurcationRow],
) -> Result<OrbitStudy> {
    let (damper, current) = o.damper.damper();
    let (v_lo, v_hi) = (kmh_to_mps(o.v_min_kmh), kmh_to_mps(o.v_max_kmh));
    let mut sh = Shooting::<M, N>::new(&o.params, damper, current)
        .map_err(|e| anyhow::anyhow!("periodic orbits: {e}"))?;
    let lim = Limits::speeds(v_lo, v_hi);
    let hopf = sh.hopf_points(v_lo, v_hi, kmh_to_mps(1.0));
    let mut branches: Vec<Branch> = Vec::new();
    for h in &hopf {
        // a branch from an earlier Hopf point may have ended at this one (shrinking to zero)
        let reached = branches.iter().any(|b| {
            b.orbits.last().is_some_and(|o| {
                (o.speed_mps - h.speed_mps).abs() < kmh_to_mps(0.1)
                    && o.amp_rad < 0.05f64.to_radians()
            })
        });
        if reached {
            continue;
        }
        match sh.continue_from_hopf(h, &lim) {
            Ok(b) => branches.push(b),
            Err(e) => println!(
                "periodic orbits: the branch from {:.2} km/h failed: {e}",
                mps_to_kmh(h.speed_mps)
            ),
        }
    }
    if hopf.is_empty() {
        // Seeds: the highest grid speed where the large start shimmies, then the middle of
        // that window (the highest can sit so close to a fold that Newton fails there).
        let shimmy: Vec<&BifurcationRow> = rows.iter().filter(|r| r.large.shimmies()).collect();
        let seeds = [shimmy.last(), shimmy.get(shimmy.len() / 2)];
        for r in seeds.into_iter().flatten() {
            let seed = sh.continue_from_run(
                kmh_to_mps(r.v_kmh),
                o.large_deg.to_radians(),
                o.duration_s,
                &lim,
            );
            match seed {
                Ok(Some(b)) => {
                    branches.push(b);
                    break;
                }
                Ok(None) => {}
                Err(e) => println!(
                    "periodic orbits: the branch from the run at {} km/h failed: {e}",
                    r.v_kmh
                ),
            }
        }
    }
    let straight_unstable = rows
        .iter()
        .map(|r| {
            let v = kmh_to_mps(r.v_kmh);
            (v, sh.unstable_pairs(v) > 0)
        })
        .collect();
    Ok(OrbitStudy {
        hopf,
        branches,
        straight_unstable,
    })
}

/// The orbit study's lines: Hopf types, folds, the bistable window and its margins.
fn print_orbits(s: &OrbitStudy, rows: &[BifurcationRow]) {
    println!(
        "periodic orbits (shooting, continued in speed; amplitude = peak |measured yaw| on the \
         orbit, stability by Floquet multipliers):"
    );
    for h in &s.hopf {
        let kind = match s.supercritical(h) {
            Some(true) => "supercritical (a stable cycle grows from zero)",
            Some(false) => {
                "subcritical (an unstable cycle: shimmy from a large enough disturbance on the \
                 stable side)"
            }
            None => "undetermined (no small cycle continued)",
        };
        println!(
            "  Hopf {} of the plant at {:.2} km/h ({:.2} Hz): {kind}",
            if h.onset { "onset" } else { "offset" },
            mps_to_kmh(h.speed_mps),
            h.omega / (2.0 * std::f64::consts::PI)
        );
    }
    for b in &s.branches {
        if let Start::Run {
            speed_mps,
            psi0_rad,
        } = b.start
        {
            println!(
                "  no Hopf point of the plant in the range (its straight run is linearly stable): \
                 branch from the cycle the {:.2} deg start settles on at {:.1} km/h",
                psi0_rad.to_degrees(),
                mps_to_kmh(speed_mps)
            );
        }
    }
    for f in s.folds_mps() {
        println!(
            "  fold of cycles at {:.2} km/h: a stable and an unstable cycle are born there",
            mps_to_kmh(f)
        );
    }
    let bi = s.bistable();
    match (bi.first(), bi.last()) {
        (Some(lo), Some(hi)) => {
            // the window's ends: the folds next to the first and the last bistable grid speed
            let folds: Vec<f64> = s.folds_mps().into_iter().map(mps_to_kmh).collect();
            let from = folds
                .iter()
                .rev()
                .find(|&&f| f <= lo.0)
                .map_or(format!("{:.1} km/h (grid point)", lo.0), |f| {
                    format!("{f:.2} km/h (fold)")
                });
            let grid_end = rows.last().map_or(0.0, |r| r.v_kmh);
            let to = folds.iter().find(|&&f| f >= hi.0).map_or(
                format!(
                    "{:.1} km/h (grid point{})",
                    hi.0,
                    if hi.0 >= grid_end {
                        ", the grid's end"
                    } else {
                        ""
                    }
                ),
                |f| format!("{f:.2} km/h (fold)"),
            );
            println!(
                "  bistable: the straight run and a stable shimmy cycle coexist from {from} to \
                 {to}; disturbance margin = the unstable cycle's amplitude (a larger disturbance \
                 ends in shimmy):"
            );
            for (v, m) in &bi {
                let (stable, _) = s.cycles_at(kmh_to_mps(*v));
                println!(
                    "    {v:>7.1} km/h: margin {} deg, shimmy cycle {} deg",
                    m.map_or("-".into(), |a| format!("{:.4}", a.to_degrees())),
                    stable
                        .iter()
                        .map(|a| format!("{:.3}", a.to_degrees()))
                        .collect::<Vec<_>>()
                        .join(", ")
                );
            }
        }
        _ => println!("  no bistable speed on the grid"),
    }
}

fn write_orbits_csv(path: &Path, s: &OrbitStudy) -> Result<()> {
    let mut w = Vec::new();
    writeln!(w, "branch,v_kmh,period_s,amp_deg,stable,max_multiplier")?;
    for (k, b) in s.branches.iter().enumerate() {
        for o in &b.orbits {
            writeln!(
                w,
                "{k},{:.6},{:.8},{:.8},{},{:.8}",
                mps_to_kmh(o.speed_mps),
                o.period_s,
                o.amp_rad.to_degrees(),
                o.stable(),
                o.max_multiplier
            )?;
        }
    }
    crate::sim::input::files::write_file(path, &w)?;
    Ok(())
}

/// First and last grid speed where `pred` holds, if any.
pub fn window(
    rows: &[BifurcationRow],
    pred: impl Fn(&BifurcationRow) -> bool,
) -> Option<(f64, f64)> {
    let hits: Vec<f64> = rows.iter().filter(|r| pred(r)).map(|r| r.v_kmh).collect();
    Some((*hits.first()?, *hits.last()?))
}

fn write_csv(path: &Path, rows: &[BifurcationRow]) -> Result<()> {
    let mut w = Vec::new();
    writeln!(
        w,
        "v_kmh,small_start_deg,small_amp_deg,small_prev_amp_deg,small_trend,large_start_deg,large_amp_deg,large_prev_amp_deg,large_trend,eig_re_shimmy_per_s"
    )?;
    for r in rows {
        writeln!(
            w,
            "{},{},{},{},{},{},{},{},{},{}",
            r.v_kmh,
            r.small.psi0_rad.to_degrees(),
            r.small.amp_end_rad.to_degrees(),
            r.small.amp_prev_rad.to_degrees(),
            r.small.trend.name(),
            r.large.psi0_rad.to_degrees(),
            r.large.amp_end_rad.to_degrees(),
            r.large.amp_prev_rad.to_degrees(),
            r.large.trend.name(),
            r.eig_re_per_s
        )?;
    }
    crate::sim::input::files::write_file(path, &w)?;
    Ok(())
}

fn plot<M: SimModel<N>, const N: usize>(
    path: &Path,
    rows: &[BifurcationRow],
    study: &OrbitStudy,
    o: &BifurcationOptions<M, N>,
    damper: &str,
) -> Result<()> {
    use plotters::prelude::*;
    let png = crate::sim::input::files::PendingFile::new(path);
    let root = BitMapBackend::new(png.tmp(), (1000, 620)).into_drawing_area();
    root.fill(&WHITE)?;
    let y_max = rows
        .iter()
        .map(|r| r.small.amp_end_rad.max(r.large.amp_end_rad).to_degrees())
        .fold(0.0f64, f64::max)
        .max(o.large_deg)
        .max(
            study
                .branches
                .iter()
                .flat_map(|b| b.orbits.iter().map(|x| x.amp_rad.to_degrees()))
                .fold(0.0, f64::max),
        )
        * 1.1;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "Wheel-yaw limit-cycle amplitude vs speed (`{}`, {damper})",
                o.params_name
            ),
            ("sans-serif", 22),
        )
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(o.v_min_kmh..o.v_max_kmh, 0.0..y_max)?;
    chart
        .configure_mesh()
        .x_desc("speed V [km/h]")
        .y_desc(format!(
            "runs: peak |psi_L| over last {} s; orbits: peak |measured yaw| [deg]",
            o.window_s
        ))
        .draw()?;
    let series = [
        (format!("start {} deg", o.small_deg), BLUE, true),
        (format!("start {} deg", o.large_deg), RED, false),
    ];
    for (label, color, small) in series {
        let pts: Vec<(f64, f64)> = rows
            .iter()
            .map(|r| {
                let s = if small { r.small } else { r.large };
                (r.v_kmh, s.amp_end_rad.to_degrees())
            })
            .collect();
        chart
            .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))?
            .label(label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
        let marker = if small { 4 } else { 6 };
        chart.draw_series(pts.iter().map(|&(x, y)| {
            if small {
                Circle::new((x, y), marker, color.filled()).into_dyn()
            } else {
                Cross::new((x, y), marker, color.stroke_width(2)).into_dyn()
            }
        }))?;
    }
    // the continued orbits: stable solid, unstable dashed (runs of equal stability)
    let mut legend = [false, false];
    for b in &study.branches {
        let mut k = 0;
        while k < b.orbits.len() {
            let stable = b.orbits[k].stable();
            let mut e = k;
            while e + 1 < b.orbits.len() && b.orbits[e + 1].stable() == stable {
                e += 1;
            }
            // a segment joins the next run so that the curve is unbroken
            let pts: Vec<(f64, f64)> = b.orbits[k..=(e + 1).min(b.orbits.len() - 1)]
                .iter()
                .map(|x| (mps_to_kmh(x.speed_mps), x.amp_rad.to_degrees()))
                .collect();
            let style = BLACK.stroke_width(2);
            let drawn = if stable {
                chart.draw_series(LineSeries::new(pts, style))?
            } else {
                chart.draw_series(DashedLineSeries::new(pts, 6, 4, style))?
            };
            let slot = usize::from(!stable);
            if !legend[slot] {
                legend[slot] = true;
                let name = if stable {
                    "stable cycle (shooting)"
                } else {
                    "unstable cycle (shooting)"
                };
                drawn.label(name).legend(move |(x, y)| {
                    if stable {
                        PathElement::new(vec![(x, y), (x + 20, y)], style).into_dyn()
                    } else {
                        PathElement::new(vec![(x, y), (x + 6, y)], style).into_dyn()
                    }
                });
            }
            k = e + 1;
        }
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()?;
    png.commit(root.present())?;
    Ok(())
}

/// Speed step: 0.1 to 100 km/h.
pub const STEP_KMH: Range = Range::closed(0.1, 100.0, "km/h");
/// Initial wheel yaw: above 0, at most 20 deg.
pub const START_DEG: Range = Range::above(0.0, 20.0, "deg");
/// Run length: above 0, at most 600 s.
pub const DURATION_S: Range = Range::above(0.0, 600.0, "s");
/// End window: above 0, at most 300 s.
pub const WINDOW_S: Range = Range::above(0.0, 300.0, "s");

/// Command-line arguments of `shimmy-sim bifurcation`.
#[derive(clap::Args, Clone, Debug)]
pub struct BifurcationArgs {
    /// The vehicle (`--vehicle`, a named set or a vehicle file).
    #[command(flatten)]
    pub vehicle: crate::cmd::VehicleArg,
    /// Fit the MR damper and hold this coil current in A (0 to the vehicle's coil rating);
    /// without it there is no damper (F_d = 0).
    #[arg(long, alias = "damper-current", allow_negative_numbers = true, value_parser = arg_range::current_a())]
    pub damper_current_a: Option<f64>,
    /// Lowest speed, km/h: 1 to 250, at most `--v-max-kmh`.
    #[arg(long, default_value_t = 5.0, allow_negative_numbers = true, value_parser = arg_range::speed_kmh())]
    pub v_min_kmh: f64,
    /// Highest speed, km/h: 1 to 250.
    #[arg(long, default_value_t = 130.0, allow_negative_numbers = true, value_parser = arg_range::speed_kmh())]
    pub v_max_kmh: f64,
    /// Speed step, km/h: 0.1 to 100.
    #[arg(long, default_value_t = 2.5, allow_negative_numbers = true, value_parser = arg_range::f64_in(STEP_KMH))]
    pub step_kmh: f64,
    /// Small initial in-phase wheel yaw, deg: above 0, at most 20.
    #[arg(long, default_value_t = 0.05, allow_negative_numbers = true, value_parser = arg_range::f64_in(START_DEG))]
    pub small_deg: f64,
    /// Large initial in-phase wheel yaw, deg: above 0, at most 20.
    #[arg(long, default_value_t = 3.0, allow_negative_numbers = true, value_parser = arg_range::f64_in(START_DEG))]
    pub large_deg: f64,
    /// Length of each run, s: above 0, at most 600, at least twice `--window-s`.
    #[arg(long, default_value_t = 40.0, allow_negative_numbers = true, value_parser = arg_range::f64_in(DURATION_S))]
    pub duration_s: f64,
    /// Amplitude window at the end of each run, s (the trend compares it with the one before):
    /// above 0, at most 300.
    #[arg(long, default_value_t = 3.0, allow_negative_numbers = true, value_parser = arg_range::f64_in(WINDOW_S))]
    pub window_s: f64,
    /// Two-parameter chart over the damper's coil current: the study at each of these
    /// currents, A (comma separated, each 0 to the vehicle's coil rating, at most 16); per
    /// current the plant's Hopf points and the folds of cycles, into `chart.csv` and
    /// `chart.png` instead of the one-current diagram.
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true, value_parser = arg_range::current_a())]
    pub chart_currents_a: Vec<f64>,
    /// Two-parameter chart over a vehicle parameter (a field name, see `shimmy-sim params`):
    /// the study at each of `--chart-factors` times its value, with the damper of
    /// `--damper-current-a` (none: no damper, so the chart shows the Hopf curve).
    #[arg(long, requires = "chart_factors")]
    pub chart_param: Option<String>,
    /// The factors on `--chart-param`'s value (comma separated, each above 0 and at most 10,
    /// at most 16).
    #[arg(long, value_delimiter = ',', allow_negative_numbers = true, requires = "chart_param", value_parser = arg_range::f64_in(CHART_FACTOR))]
    pub chart_factors: Vec<f64>,
    /// Output folder (`--out`; default out/bifurcation, [`Self::out_dir`]).
    #[command(flatten)]
    pub out: crate::cmd::OutArg,
    /// The dual-axle truck: the kingpin friction's smoothing `tanh(psi'/eps)`, rad/s: above 0,
    /// at most 1.
    #[arg(long, default_value_t = crate::model::dual_axle_plant::DEFAULT_EPS_RADPS, allow_negative_numbers = true, value_parser = arg_range::f64_in(EPS_RADPS))]
    pub friction_eps_radps: f64,
    /// The dual-axle truck: leave out the table of the paper's directions (transition rod,
    /// friction, trail, caster at -20 % / +20 %).
    #[arg(long)]
    pub no_directions: bool,
}

impl BifurcationArgs {
    /// The output folder: `--out`, else out/bifurcation.
    pub fn out_dir(&self) -> PathBuf {
        self.out.dir_or("out/bifurcation")
    }
}

/// Friction smoothing: above 0, at most 1 rad/s.
pub const EPS_RADPS: Range = Range::above(0.0, 1.0, "rad/s");
/// The dual-axle truck's reference speed for the limit-cycle amplitude of the directions table,
/// km/h (the class's limited top speed).
pub const DUAL_AXLE_REF_KMH: f64 = 90.0;

/// Entry point of `shimmy-sim bifurcation`.
pub fn command(a: &BifurcationArgs) -> Result<()> {
    arg_range::SPEED_KMH.check("--v-min-kmh", a.v_min_kmh)?;
    arg_range::SPEED_KMH.check("--v-max-kmh", a.v_max_kmh)?;
    STEP_KMH.check("--step-kmh", a.step_kmh)?;
    START_DEG.check("--small-deg", a.small_deg)?;
    START_DEG.check("--large-deg", a.large_deg)?;
    DURATION_S.check("--duration-s", a.duration_s)?;
    WINDOW_S.check("--window-s", a.window_s)?;
    anyhow::ensure!(
        a.v_min_kmh <= a.v_max_kmh,
        "--v-min-kmh {} must not exceed --v-max-kmh {}",
        a.v_min_kmh,
        a.v_max_kmh
    );
    anyhow::ensure!(
        a.duration_s >= 2.0 * a.window_s,
        "--duration-s {} must be at least twice --window-s {}",
        a.duration_s,
        a.window_s
    );
    EPS_RADPS.check("--friction-eps-radps", a.friction_eps_radps)?;
    struct On<'a>(&'a BifurcationArgs);
    impl ModelVisitor for On<'_> {
        type Output = Result<()>;
        fn visit<M: Registered<N>, const N: usize>(self, f: M::File) -> Result<()> {
            let a = self.0;
            let v = registry::family::<M, N>(f)?;
            // The dual-axle truck has a bifurcation of its own (its kingpins' dry friction).
            let any: &dyn std::any::Any = &v.model;
            let Some(t) = any.downcast_ref::<shimmy_core::vehicles::dual_axle::DualAxleParams>()
            else {
                return command_on(a, &v.model, &v.parts);
            };
            anyhow::ensure!(
                a.damper_current_a.is_none() && a.chart_currents_a.is_empty(),
                "--damper-current-a, --chart-currents-a: the {} model has no MR damper \
                 configured; leave them out",
                registry::name_of::<M, N>()
            );
            dual_axle(t, a)
        }
    }
    registry::with_model(
        crate::sim::input::vehicle_file::load_model(&a.vehicle.spec)?,
        On(a),
    )
}

/// The command on the vehicle model `model` with the damper of `parts`.
fn command_on<M: SimModel<N>, const N: usize>(
    a: &BifurcationArgs,
    model: &M,
    parts: &shimmy_core::vehicle::Vehicle,
) -> Result<()> {
    let axis = match (&a.chart_param, a.chart_currents_a.is_empty()) {
        (Some(_), false) => anyhow::bail!("--chart-param and --chart-currents-a: give one of them"),
        (None, true) => None,
        (None, false) => {
            anyhow::ensure!(
                a.damper_current_a.is_none(),
                "--damper-current-a and --chart-currents-a: give one of them"
            );
            for &i in &a.chart_currents_a {
                arg_range::check_current("--chart-currents-a", i, parts)?;
            }
            Some(ChartAxis::CurrentA(a.chart_currents_a.clone()))
        }
        (Some(name), true) => {
            let base = model.param(name).with_context(|| {
                format!(
                    "--chart-param {name:?}: not a parameter of this model; it has: {}",
                    param_names::<M, N>()
                )
            })?;
            for &f in &a.chart_factors {
                CHART_FACTOR.check("--chart-factors", f)?;
                model
                    .with_param(name, base * f)
                    .context("--chart-factors")?;
            }
            Some(ChartAxis::Param {
                name: name.clone(),
                factors: a.chart_factors.clone(),
            })
        }
    };
    if let Some(axis) = &axis {
        anyhow::ensure!(
            axis.len() <= MAX_CHART_VALUES,
            "the chart: {} values, at most {MAX_CHART_VALUES}",
            axis.len()
        );
    }
    let damper = match a.damper_current_a.or(a.chart_currents_a.first().copied()) {
        None => DamperSetting::Off,
        Some(i) => DamperSetting::Mr {
            damper: parts.damper.spencer,
            current_a: arg_range::check_current("--damper-current-a", i, parts)?,
        },
    };
    let o = BifurcationOptions {
        params: *model,
        params_name: a.vehicle.spec.clone(),
        damper,
        v_min_kmh: a.v_min_kmh,
        v_max_kmh: a.v_max_kmh,
        step_kmh: a.step_kmh,
        small_deg: a.small_deg,
        large_deg: a.large_deg,
        duration_s: a.duration_s,
        window_s: a.window_s,
        out: a.out_dir(),
    };
    match axis {
        None => run(&o),
        Some(axis) => run_chart(&o, &axis),
    }
}

/// A factor of `--chart-factors`: above 0, at most 10.
pub const CHART_FACTOR: Range = Range::above(0.0, 10.0, "");

/// Most values of one chart axis.
pub const MAX_CHART_VALUES: usize = 16;

/// The second axis of a two-parameter chart.
#[derive(Clone, Debug)]
pub enum ChartAxis {
    /// The MR damper's coil current, A.
    CurrentA(Vec<f64>),
    /// The vehicle parameter `name` at these factors on its value.
    Param {
        /// Field name ([`SimModel::params`]).
        name: String,
        /// Factors on the vehicle's value.
        factors: Vec<f64>,
    },
}

impl ChartAxis {
    fn len(&self) -> usize {
        match self {
            ChartAxis::CurrentA(v) => v.len(),
            ChartAxis::Param { factors, .. } => factors.len(),
        }
    }

    /// The axis label.
    pub fn label(&self) -> String {
        match self {
            ChartAxis::CurrentA(_) => "MR damper coil current [A]".into(),
            ChartAxis::Param { name, .. } => name.clone(),
        }
    }
}

/// One value of the chart's second axis.
#[derive(Clone, Debug)]
pub struct ChartRow {
    /// The axis value: the coil current (A) or the parameter's value.
    pub value: f64,
    /// The plant's Hopf points in the speed range: (speed km/h, onset, supercritical).
    pub hopf: Vec<(f64, bool, Option<bool>)>,
    /// The folds of cycles, km/h.
    pub folds_kmh: Vec<f64>,
    /// The first and last grid speed (km/h) where the straight run is stable and a stable
    /// shimmy cycle coexists with it.
    pub bistable_kmh: Option<(f64, f64)>,
}

/// The two-parameter chart: the study of `o` at each value of `axis` (the coil current needs
/// `o`'s damper to be the MR damper).
pub fn chart<M: SimModel<N>, const N: usize>(
    o: &BifurcationOptions<M, N>,
    axis: &ChartAxis,
) -> Result<Vec<ChartRow>> {
    let studies: Vec<(f64, BifurcationOptions<M, N>)> = match axis {
        ChartAxis::CurrentA(currents) => {
            let DamperSetting::Mr { damper, .. } = o.damper else {
                anyhow::bail!("the chart over the coil current needs the MR damper");
            };
            currents
                .iter()
                .map(|&current_a| {
                    let damper = DamperSetting::Mr { damper, current_a };
                    (
                        current_a,
                        BifurcationOptions {
                            damper,
                            ..o.clone()
                        },
                    )
                })
                .collect()
        }
        ChartAxis::Param { name, factors } => {
            let base = o
                .params
                .param(name)
                .with_context(|| format!("{name}: not a parameter of this model"))?;
            factors
                .iter()
                .map(|&f| {
                    let params = o.params.with_param(name, base * f)?;
                    Ok((
                        base * f,
                        BifurcationOptions {
                            params,
                            ..o.clone()
                        },
                    ))
                })
                .collect::<Result<_>>()?
        }
    };
    studies
        .into_iter()
        .map(|(value, oi)| {
            let rows = sweep(&oi, false)?;
            let study = orbits(&oi, &rows)?;
            let bi = study.bistable();
            Ok(ChartRow {
                value,
                hopf: study
                    .hopf
                    .iter()
                    .map(|h| (mps_to_kmh(h.speed_mps), h.onset, study.supercritical(h)))
                    .collect(),
                folds_kmh: study.folds_mps().into_iter().map(mps_to_kmh).collect(),
                bistable_kmh: bi.first().zip(bi.last()).map(|(a, b)| (a.0, b.0)),
            })
        })
        .collect()
}

/// `bifurcation --chart-currents-a` / `--chart-param`: the chart's table, `chart.csv` and
/// `chart.png`.
fn run_chart<M: SimModel<N>, const N: usize>(
    o: &BifurcationOptions<M, N>,
    axis: &ChartAxis,
) -> Result<()> {
    let _out_dir = crate::sim::input::files::OutDir::claim(&o.out)?;
    let t0 = std::time::Instant::now();
    let rows = chart(o, axis)?;
    let damper = match (axis, o.damper) {
        (ChartAxis::CurrentA(_), _) => "MR damper".to_string(),
        (_, DamperSetting::Off) => "no damper".to_string(),
        (_, DamperSetting::Mr { current_a, .. }) => format!("MR damper at {current_a} A"),
    };
    println!(
        "two-parameter chart: `{}`, {damper}, {} x speed ({}-{} km/h): the plant's Hopf points \
         and the folds of cycles (continued periodic orbits), {:.1} s wall",
        o.params_name,
        axis.label(),
        o.v_min_kmh,
        o.v_max_kmh,
        t0.elapsed().as_secs_f64()
    );
    println!(
        "{:>12} | {:<48} | {:<22} | bistable (grid) [km/h]",
        "value", "Hopf points [km/h]", "folds of cycles [km/h]"
    );
    let mut csv = Vec::new();
    writeln!(csv, "value,kind,speed_kmh,hopf_type")?;
    for r in &rows {
        let hopf: Vec<String> = r
            .hopf
            .iter()
            .map(|&(v, onset, sup)| {
                format!(
                    "{v:.2} {} {}",
                    if onset { "on" } else { "off" },
                    hopf_type(sup)
                )
            })
            .collect();
        let folds: Vec<String> = r.folds_kmh.iter().map(|v| format!("{v:.2}")).collect();
        println!(
            "{:>12} | {:<48} | {:<22} | {}",
            format!("{:.6}", r.value)
                .trim_end_matches('0')
                .trim_end_matches('.'),
            if hopf.is_empty() {
                "-".into()
            } else {
                hopf.join(", ")
            },
            if folds.is_empty() {
                "-".into()
            } else {
                folds.join(", ")
            },
            r.bistable_kmh
                .map_or("-".into(), |(lo, hi)| format!("{lo:.1}-{hi:.1}"))
        );
        for &(v, onset, sup) in &r.hopf {
            let kind = if onset { "hopf-onset" } else { "hopf-offset" };
            writeln!(csv, "{},{kind},{v:.4},{}", r.value, hopf_type(sup))?;
        }
        for v in &r.folds_kmh {
            writeln!(csv, "{},fold,{v:.4},", r.value)?;
        }
    }
    let csv_path = o.out.join("chart.csv");
    crate::sim::input::files::write_file(&csv_path, &csv)?;
    let png = o.out.join("chart.png");
    plot_chart(&png, &rows, o, &axis.label())?;
    println!("wrote {} and {}", csv_path.display(), png.display());
    Ok(())
}

fn hopf_type(supercritical: Option<bool>) -> &'static str {
    match supercritical {
        Some(true) => "supercritical",
        Some(false) => "subcritical",
        None => "undetermined",
    }
}

/// The chart: speed across, the second axis (`y_label`) up; Hopf points as circles, folds of
/// cycles as crosses, bistable grid speeds as bars.
fn plot_chart<M: SimModel<N>, const N: usize>(
    path: &Path,
    rows: &[ChartRow],
    o: &BifurcationOptions<M, N>,
    y_label: &str,
) -> Result<()> {
    use plotters::prelude::*;
    let png = crate::sim::input::files::PendingFile::new(path);
    let root = BitMapBackend::new(png.tmp(), (1000, 620)).into_drawing_area();
    root.fill(&WHITE)?;
    let y_max = rows.iter().map(|r| r.value).fold(f64::MIN, f64::max);
    let y_min = rows.iter().map(|r| r.value).fold(f64::MAX, f64::min);
    let pad = (0.05 * (y_max - y_min)).max(0.05 * y_max.abs()).max(1e-9);
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "Hopf points and folds of cycles over speed and {y_label} (`{}`)",
                o.params_name
            ),
            ("sans-serif", 22),
        )
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(o.v_min_kmh..o.v_max_kmh, y_min - pad..y_max + pad)?;
    chart
        .configure_mesh()
        .x_desc("speed V [km/h]")
        .y_desc(y_label)
        .draw()?;
    let folds: Vec<(f64, f64)> = rows
        .iter()
        .flat_map(|r| r.folds_kmh.iter().map(move |&v| (v, r.value)))
        .collect();
    chart
        .draw_series(folds.iter().map(|&p| Cross::new(p, 6, RED.stroke_width(2))))?
        .label("fold of cycles (a stable and an unstable cycle are born)")
        .legend(|(x, y)| Cross::new((x + 10, y), 5, RED.stroke_width(2)));
    let hopf: Vec<(f64, f64)> = rows
        .iter()
        .flat_map(|r| r.hopf.iter().map(move |h| (h.0, r.value)))
        .collect();
    chart
        .draw_series(hopf.iter().map(|&p| Circle::new(p, 5, BLUE.filled())))?
        .label("Hopf point of the straight run")
        .legend(|(x, y)| Circle::new((x + 10, y), 4, BLUE.filled()));
    // the bistable band per current (grid speeds)
    let band = BLACK.mix(0.5).stroke_width(3);
    chart
        .draw_series(rows.iter().filter_map(|r| {
            r.bistable_kmh
                .map(|(lo, hi)| PathElement::new(vec![(lo, r.value), (hi, r.value)], band))
        }))?
        .label("bistable: straight run and shimmy cycle both stable (grid speeds)")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], band));
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperRight)
        .draw()?;
    png.commit(root.present())?;
    Ok(())
}

/// `bifurcation` on the dual-axle truck (`docs/dual-axle-truck.md`): friction off and on from
/// the small start, friction on from the large start; the friction's onsets refined; the
/// paper's directions; table, `bifurcation.csv`, `directions.csv`, `bifurcation.png`.
pub fn dual_axle(
    t: &shimmy_core::vehicles::dual_axle::DualAxleParams,
    a: &BifurcationArgs,
) -> Result<()> {
    use crate::sim::study::dual_axle_study::{self as study, CycleRuns};
    let _out_dir = crate::sim::input::files::OutDir::claim(&a.out_dir())?;
    let runs = CycleRuns {
        small_deg: a.small_deg,
        large_deg: a.large_deg,
        duration_s: a.duration_s,
        window_s: a.window_s,
        eps_radps: a.friction_eps_radps,
    };
    let n = ((a.v_max_kmh - a.v_min_kmh) / a.step_kmh + 1e-9).floor() as usize + 1;
    let speeds: Vec<f64> = (0..n)
        .map(|k| a.v_min_kmh + k as f64 * a.step_kmh)
        .collect();
    let t0 = std::time::Instant::now();
    let rows = study::sweep(t, &runs, &speeds)?;
    println!(
        "bifurcation: `{}` (dual-axle truck, kingpin friction M_f = {} N m smoothed by eps = {} \
         rad/s); {} s runs, amplitude = peak |(psi_1L + psi_1R)/2| over the last {} s",
        a.vehicle.spec, t.m_f, a.friction_eps_radps, a.duration_s, a.window_s
    );
    println!(
        "{:>8} | {:>12} | {:>12} | {:>12} | {:>10}",
        "V km/h",
        format!("free {}deg", a.small_deg),
        format!("fric {}deg", a.small_deg),
        format!("fric {}deg", a.large_deg),
        "eig re 1/s"
    );
    let cell = |c: &crate::model::dual_axle_plant::CycleSummary| {
        format!(
            "{:.4}{}",
            c.amp_end_rad.to_degrees(),
            if c.shimmies() { " *" } else { "  " }
        )
    };
    for r in &rows {
        println!(
            "{:>8.1} | {:>12} | {:>12} | {:>12} | {:>10.4}",
            r.v_kmh,
            cell(&r.free),
            cell(&r.small),
            cell(&r.large),
            r.eig_re_per_s
        );
    }
    println!("amplitudes in deg; * = shimmy at the end of the run (not decaying, above 1e-4 rad)");
    let grid = |pred: &dyn Fn(&study::DualBifurcationRow) -> bool| {
        let hits: Vec<f64> = rows.iter().filter(|r| pred(r)).map(|r| r.v_kmh).collect();
        hits.first().zip(hits.last()).map(|(a, b)| (*a, *b))
    };
    let (lo, hi) = (a.v_min_kmh, a.v_max_kmh);
    let onset = study::linear_onset(t, lo, hi)?;
    let lin = onset.map(|c| shimmy_core::units::mps_to_kmh(c.speed_mps));
    let on_small = study::friction_onset_kmh(t, &runs, a.small_deg, lo, hi, 0.25)?;
    let on_large = study::friction_onset_kmh(t, &runs, a.large_deg, lo, hi, 0.25)?;
    let text =
        |x: Option<f64>| x.map_or("none in the range".to_string(), |v| format!("{v:.2} km/h"));
    println!("linear (friction-free) Hopf onset: {}", text(lin));
    if let Some(h) = onset
        .map(|c| study::friction_free_hopf_type(t, &c))
        .transpose()?
    {
        let (at, amp) = h.cycle_1kmh();
        println!(
            "friction-free Hopf type: {} (l1 = {:.4e}; normal-form cycle {} at {:.2} km/h; \
             with friction the plant is not smooth: the runs above)",
            h.criticality().name(),
            h.lyapunov.l1,
            amp.map_or("-".into(), |a| format!("{:.2} deg", a.to_degrees())),
            shimmy_core::units::mps_to_kmh(at)
        );
    }
    println!(
        "with friction: shimmy from the {} deg start from {}, from the {} deg start from {} \
         (bisection to 0.25 km/h)",
        a.small_deg,
        text(on_small),
        a.large_deg,
        text(on_large)
    );
    let both = grid(&|r| r.large.shimmies() && !r.small.shimmies());
    if let Some((l, h)) = both {
        println!(
            "coexisting: the straight run (small start) and a limit cycle (large start) from {l} \
             to {h} km/h (grid points)"
        );
    }
    if let Some((l, h)) = grid(&|r| r.large.shimmies()) {
        println!("limit cycles with friction (large start) from {l} to {h} km/h (grid points)");
    }
    let v_ref = DUAL_AXLE_REF_KMH.clamp(lo, hi);
    let threshold = study::threshold_start_deg(t, &runs, v_ref, a.small_deg, a.large_deg, 0.01)?;
    if let Some(d) = threshold {
        println!(
            "at {v_ref} km/h with friction: starts below {d:.2} deg return to the straight run, \
             larger ones end in the limit cycle (an unstable cycle of about this size separates \
             the two; bisection to 0.01 deg)"
        );
    }
    let csv = a.out_dir().join("bifurcation.csv");
    let mut w = Vec::new();
    writeln!(
        w,
        "v_kmh,free_small_amp_deg,free_small_shimmy,fric_small_amp_deg,fric_small_shimmy,fric_large_amp_deg,fric_large_shimmy,eig_re_per_s,small_start_deg,large_start_deg,m_f_nm,eps_radps"
    )?;
    for r in &rows {
        writeln!(
            w,
            "{},{:.9e},{},{:.9e},{},{:.9e},{},{},{},{},{},{}",
            r.v_kmh,
            r.free.amp_end_rad.to_degrees(),
            r.free.shimmies(),
            r.small.amp_end_rad.to_degrees(),
            r.small.shimmies(),
            r.large.amp_end_rad.to_degrees(),
            r.large.shimmies(),
            r.eig_re_per_s,
            a.small_deg,
            a.large_deg,
            t.m_f,
            a.friction_eps_radps
        )?;
    }
    crate::sim::input::files::write_file(&csv, &w)?;
    let png = a.out_dir().join("bifurcation.png");
    plot_dual(&png, &rows, a, lin, on_large)?;
    println!("wrote {} and {}", csv.display(), png.display());
    if !a.no_directions {
        let dirs = study::directions(t, &runs, 0.2, lo, hi, DUAL_AXLE_REF_KMH)?;
        println!(
            "paper's directions (Wei et al. 2015), each at -20 % / +20 %: linear onset, friction \
             onset from {} deg, limit-cycle amplitude at {DUAL_AXLE_REF_KMH} km/h from {} deg",
            a.large_deg, a.large_deg
        );
        let path = a.out_dir().join("directions.csv");
        let mut f = Vec::new();
        writeln!(
            f,
            "param,what,factor,linear_onset_kmh,friction_onset_kmh,amp_ref_deg,ref_kmh,agrees_linear_onset,agrees_friction_onset,agrees_amplitude"
        )?;
        for r in &dirs {
            let agrees = study::agrees_with_paper(&dirs, r.name);
            println!(
                "  {:<5} x{:<4} | linear onset {:>18} | friction onset {:>18} | amplitude {:>7.3} deg | {}",
                r.name,
                r.factor,
                text(r.linear_onset_kmh),
                text(r.friction_onset_kmh),
                r.amp_ref_deg,
                agrees.map_or(String::new(), |g| g.text())
            );
            writeln!(
                f,
                "{},{},{},{},{},{},{},{},{},{}",
                r.name,
                r.what,
                r.factor,
                r.linear_onset_kmh
                    .map_or(String::new(), |x| format!("{x:.4}")),
                r.friction_onset_kmh
                    .map_or(String::new(), |x| format!("{x:.4}")),
                r.amp_ref_deg,
                DUAL_AXLE_REF_KMH,
                agrees.map_or(String::new(), |g| g.linear_onset.to_string()),
                agrees.map_or(String::new(), |g| g.friction_onset.to_string()),
                agrees.map_or(String::new(), |g| g.amplitude.to_string())
            )?;
        }
        crate::sim::input::files::write_file(&path, &f)?;
        println!("wrote {}", path.display());
    }
    let simulated = 3.0 * rows.len() as f64 * a.duration_s;
    println!(
        "{} grid runs, {simulated:.0} s simulated; {:.1} s wall in all",
        3 * rows.len(),
        t0.elapsed().as_secs_f64()
    );
    Ok(())
}

fn plot_dual(
    path: &Path,
    rows: &[crate::sim::study::dual_axle_study::DualBifurcationRow],
    a: &BifurcationArgs,
    linear_onset_kmh: Option<f64>,
    friction_onset_kmh: Option<f64>,
) -> Result<()> {
    use plotters::prelude::*;
    let png = crate::sim::input::files::PendingFile::new(path);
    let root = BitMapBackend::new(png.tmp(), (1000, 620)).into_drawing_area();
    root.fill(&WHITE)?;
    let y_max = rows
        .iter()
        .map(|r| r.free.amp_end_rad.max(r.large.amp_end_rad).to_degrees())
        .fold(0.0f64, f64::max)
        .max(a.large_deg)
        * 1.1;
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "Dual-axle truck: wheel-yaw amplitude vs speed (`{}`)",
                a.vehicle.spec
            ),
            ("sans-serif", 22),
        )
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(a.v_min_kmh..a.v_max_kmh, 0.0..y_max)?;
    chart
        .configure_mesh()
        .x_desc("speed V [km/h]")
        .y_desc(format!(
            "peak |(psi_1L+psi_1R)/2| over last {} s [deg]",
            a.window_s
        ))
        .draw()?;
    type Pick = fn(&crate::sim::study::dual_axle_study::DualBifurcationRow) -> f64;
    let series: [(String, RGBColor, Pick); 3] = [
        (
            format!("no friction, start {} deg", a.small_deg),
            GREEN,
            |r| r.free.amp_end_rad,
        ),
        (format!("friction, start {} deg", a.small_deg), BLUE, |r| {
            r.small.amp_end_rad
        }),
        (format!("friction, start {} deg", a.large_deg), RED, |r| {
            r.large.amp_end_rad
        }),
    ];
    for (label, color, pick) in series {
        let pts: Vec<(f64, f64)> = rows
            .iter()
            .map(|r| (r.v_kmh, pick(r).to_degrees()))
            .collect();
        chart
            .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))?
            .label(label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
        chart.draw_series(
            pts.iter()
                .map(|&(x, y)| Circle::new((x, y), 3, color.filled())),
        )?;
    }
    for (v, color, name, y) in [
        (linear_onset_kmh, BLACK, "linear Hopf onset", 0.95),
        (
            friction_onset_kmh,
            MAGENTA,
            "friction onset (large start)",
            0.88,
        ),
    ] {
        if let Some(v) = v {
            chart.draw_series(LineSeries::new(
                [(v, 0.0), (v, y_max)],
                color.stroke_width(1),
            ))?;
            chart.draw_series(std::iter::once(Text::new(
                format!("{name} {v:.1} km/h"),
                (v, y * y_max),
                ("sans-serif", 14),
            )))?;
        }
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .position(SeriesLabelPosition::UpperLeft)
        .draw()?;
    png.commit(root.present())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use shimmy_core::vehicles::car::PlantParams;

    #[test]
    fn command_writes_table_csv_and_png() {
        let out = std::env::temp_dir().join(format!("shimmy-bif-{}", std::process::id()));
        let o = BifurcationOptions {
            params: PlantParams::nominal(),
            params_name: "nominal".into(),
            damper: DamperSetting::Off,
            v_min_kmh: 10.0,
            v_max_kmh: 60.0,
            step_kmh: 25.0,
            small_deg: 0.05,
            large_deg: 3.0,
            duration_s: 2.0,
            window_s: 0.5,
            out: out.clone(),
        };
        run(&o).expect("run");
        let csv = std::fs::read_to_string(out.join("bifurcation.csv")).expect("csv");
        assert!(csv.starts_with("v_kmh,small_start_deg,small_amp_deg"));
        assert_eq!(csv.lines().count(), 1 + 3);
        // the branch from the onset: stable cycles only, from 29.35 km/h up to the grid's end
        let orbits = std::fs::read_to_string(out.join("orbits.csv")).expect("orbits");
        let rows: Vec<Vec<&str>> = orbits
            .lines()
            .skip(1)
            .map(|l| l.split(',').collect())
            .collect();
        assert!(orbits.starts_with("branch,v_kmh,period_s,amp_deg,stable,max_multiplier"));
        assert!(
            rows.len() > 10 && rows.iter().all(|r| r[4] == "true"),
            "{orbits}"
        );
        let v: Vec<f64> = rows.iter().map(|r| r[1].parse().unwrap()).collect();
        assert!(
            (v[0] - 29.35).abs() < 0.01 && *v.last().unwrap() > 60.0,
            "{v:?}"
        );
        let png = std::fs::read(out.join("bifurcation.png")).expect("png");
        assert_eq!(&png[1..4], b"PNG");
        std::fs::remove_dir_all(&out).ok();
    }

    /// The dual-axle truck's mode: table, CSV (three runs per speed) and PNG from a vehicle
    /// file of that model.
    #[test]
    fn the_dual_axle_mode_writes_csv_and_png() {
        let out = std::env::temp_dir().join(format!("shimmy-bif-dual-{}", std::process::id()));
        std::fs::create_dir_all(&out).unwrap();
        let file = out.join("dual.toml");
        std::fs::write(
            &file,
            "model = \"dual-axle-truck-8dof\"\n[dual_axle]\nm_f = 20.0\n",
        )
        .unwrap();
        let a = BifurcationArgs {
            vehicle: crate::cmd::VehicleArg::new(&file.display().to_string()),
            damper_current_a: None,
            v_min_kmh: 30.0,
            v_max_kmh: 90.0,
            step_kmh: 30.0,
            small_deg: 0.05,
            large_deg: 3.0,
            duration_s: 4.0,
            window_s: 1.0,
            chart_currents_a: Vec::new(),
            chart_param: None,
            chart_factors: Vec::new(),
            out: crate::cmd::OutArg::new(&out),
            friction_eps_radps: 0.01,
            no_directions: true,
        };
        command(&a).expect("run");
        let csv = std::fs::read_to_string(out.join("bifurcation.csv")).expect("csv");
        assert!(csv.starts_with("v_kmh,free_small_amp_deg"));
        assert_eq!(csv.lines().count(), 1 + 3);
        assert!(csv.lines().nth(1).unwrap().ends_with(",20,0.01"), "{csv}");
        let png = std::fs::read(out.join("bifurcation.png")).expect("png");
        assert_eq!(&png[1..4], b"PNG");
        std::fs::remove_dir_all(&out).ok();
    }

    /// The car with the MR damper at 0 A on the orbit study's branch (seeded at 45 km/h by the
    /// 3-deg run, continued from 30 to 46 km/h).
    fn mr_branch() -> Branch {
        let mut sh = Shooting::<PlantParams, 10>::new(
            &PlantParams::nominal(),
            DamperSetting::reference_mr(0.0).damper().0,
            0.0,
        )
        .unwrap();
        assert!(sh
            .hopf_points(kmh_to_mps(5.0), kmh_to_mps(150.0), kmh_to_mps(1.0))
            .is_empty());
        let lim = Limits::speeds(kmh_to_mps(30.0), kmh_to_mps(46.0));
        sh.continue_from_run(kmh_to_mps(45.0), 3f64.to_radians(), 20.0, &lim)
            .unwrap()
            .unwrap()
    }

    /// The measured yaw's peak over the last 3 s of a 20 s run of the car with the MR damper at
    /// 0 A from the state `x0` at `v_mps` (the default integrator, 1 ms periods).
    fn end_amplitude_rad(x0: &[f64], v_mps: f64) -> f64 {
        use crate::model::family::SimPlant;
        let (damper, current) = DamperSetting::reference_mr(0.0).damper();
        let mut sim = SimModel::plant(
            &PlantParams::nominal(),
            damper,
            crate::model::plant::Method::default(),
        );
        SimPlant::set_state(&mut sim, x0);
        let u = crate::model::plant::Inputs {
            current_cmd_a: current,
            speed_mps: v_mps,
            ..Default::default()
        };
        let mut amp = 0.0f64;
        for k in 0..20_000 {
            SimPlant::advance(&mut sim, 1e-3, &u).unwrap();
            if k >= 17_000 {
                let y = SimPlant::wheel_yaw_rad(&sim);
                amp = amp.max((0.5 * (y[0] + y[1])).abs());
            }
        }
        amp
    }

    /// At 45 km/h, inside the car's 0 A bistable window, the unstable cycle separates the
    /// starts that decay from those that end in shimmy: direct simulation from the cycle's
    /// state with its mechanical part scaled by s (about straight running) decays for s = 0.99 and shimmies for
    /// s = 1.01, and a bisection of s by simulation lands within 1 % of 1, the amplitude within
    /// 5 %. An in-phase start at rest (the wheels yawed, nothing moving) needs more: its
    /// threshold, bisected the same way with `run_speed`, lies between 1 and 1.1 times the
    /// cycle's amplitude (the start also excites the fast modes, which take energy as they
    /// decay), so the margin the command prints is the conservative one.
    #[test]
    fn the_unstable_cycle_is_the_threshold_of_direct_simulation() {
        let b = mr_branch();
        let v = kmh_to_mps(45.0);
        let study = OrbitStudy {
            hopf: Vec::new(),
            branches: vec![b.clone()],
            straight_unstable: vec![(v, false)],
        };
        let (stable, unstable) = study.cycles_at(v);
        assert_eq!((stable.len(), unstable.len()), (1, 1), "{study:?}");
        let cycle = unstable[0];
        // the continued orbit nearest 45 km/h on the unstable side
        let o = b
            .orbits
            .iter()
            .filter(|o| !o.stable())
            .min_by(|x, y| (x.speed_mps - v).abs().total_cmp(&(y.speed_mps - v).abs()))
            .unwrap();
        let sh = Shooting::<PlantParams, 10>::new(
            &PlantParams::nominal(),
            DamperSetting::reference_mr(0.0).damper().0,
            0.0,
        )
        .unwrap();
        let x_e = sh.equilibrium().clone();
        // the 10 mechanical states scaled, the damper's as on the cycle (a Bouc-Wen z
        // scaled past its saturation would be no state the damper can reach)
        let scaled_shimmies = |s: f64| {
            let mut x = o.x0.clone();
            for i in 0..10 {
                x[i] = x_e[i] + (o.x0[i] - x_e[i]) * s;
            }
            end_amplitude_rad(x.as_slice(), o.speed_mps) > 2.0 * o.amp_rad
        };
        assert!(!scaled_shimmies(0.99) && scaled_shimmies(1.01));
        let (mut lo, mut hi) = (0.8f64, 1.25f64);
        while hi / lo > 1.001 {
            let m = (lo * hi).sqrt();
            if scaled_shimmies(m) {
                hi = m;
            } else {
                lo = m;
            }
        }
        let s_star = (lo * hi).sqrt();
        let p = PlantParams::nominal();
        let shimmies = |psi0: f64| {
            run_speed(&p, DamperSetting::reference_mr(0.0), v, psi0, 30.0, 3.0)
                .unwrap()
                .shimmies()
        };
        let (mut lo, mut hi) = (0.05f64.to_radians(), 3f64.to_radians());
        assert!(!shimmies(lo) && shimmies(hi));
        while hi / lo > 1.005 {
            let m = (lo * hi).sqrt();
            if shimmies(m) {
                hi = m;
            } else {
                lo = m;
            }
        }
        let kick = (lo * hi).sqrt();
        println!(
            "45 km/h: unstable cycle {:.4} deg; scaled-cycle threshold s = {s_star:.4} ({:.4} deg \
             at {:.3} km/h); threshold of a start at rest {:.4} deg",
            cycle.to_degrees(),
            (s_star * o.amp_rad).to_degrees(),
            mps_to_kmh(o.speed_mps),
            kick.to_degrees()
        );
        assert!((s_star - 1.0).abs() < 0.01, "{s_star}");
        assert!((s_star * o.amp_rad / cycle - 1.0).abs() < 0.05);
        assert!(kick > cycle && kick < 1.1 * cycle, "{kick} vs {cycle}");
    }

    /// The nominal car with the damper at 0 A over 30-80 km/h (2.5 km/h grid, 40 s runs): the
    /// speeds of its bistable window.
    fn car_window_at_0a() -> BifurcationOptions {
        BifurcationOptions {
            params: PlantParams::nominal(),
            params_name: "nominal".into(),
            damper: DamperSetting::reference_mr(0.0),
            v_min_kmh: 30.0,
            v_max_kmh: 80.0,
            step_kmh: 2.5,
            small_deg: 0.05,
            large_deg: 3.0,
            duration_s: 40.0,
            window_s: 3.0,
            out: PathBuf::new(),
        }
    }

    /// The two-parameter chart over the coil current: more current closes the bistable window
    /// from both ends (the folds move inwards), and at each current the folds bracket the speeds
    /// where the direct simulation's large start ends in shimmy (an independent check of the
    /// continuation: time-domain runs against shooting).
    #[test]
    fn the_chart_folds_close_in_with_current_and_bracket_the_large_starts() {
        let o = car_window_at_0a();
        let rows = chart(&o, &ChartAxis::CurrentA(vec![0.0, 0.3])).unwrap();
        let folds: Vec<(f64, f64)> = rows
            .iter()
            .map(|r| {
                assert_eq!(r.folds_kmh.len(), 2, "{r:?}");
                (r.folds_kmh[0], r.folds_kmh[1])
            })
            .collect();
        assert!(
            folds[1].0 > folds[0].0 + 2.0 && folds[1].1 < folds[0].1 - 2.0,
            "{folds:?}"
        );
        for (r, &(lo, hi)) in rows.iter().zip(&folds) {
            let oi = BifurcationOptions {
                damper: DamperSetting::reference_mr(r.value),
                ..o.clone()
            };
            for s in sweep(&oi, false).unwrap() {
                let inside = s.v_kmh > lo + 0.5 && s.v_kmh < hi - 0.5;
                let outside = s.v_kmh < lo - 0.5 || s.v_kmh > hi + 0.5;
                assert!(
                    !(inside && !s.large.shimmies()) && !(outside && s.large.shimmies()),
                    "{} A, folds {lo:.2}-{hi:.2} km/h: {s:?}",
                    r.value
                );
            }
        }
    }

    /// The nominal car (the plant) with the firmware believing `believed`, started at 3 deg
    /// at `v_kmh` under `kind`: the peak wheel yaw over the last 3 s of 30 s, deg.
    fn large_start_end_peak_deg(
        believed: &shimmy_core::vehicle::Vehicle,
        kind: shimmy_core::control::ControllerKind,
        v_kmh: f64,
    ) -> f64 {
        use crate::model::disturbance::{initial_yaw, Scenario, SpeedProfile};
        use crate::model::family::FamilyVehicle;
        use crate::sim::run::closed_loop::{self, Arm, LoopConfig};
        use shimmy_core::units::kmh_to_mps;
        use shimmy_core::vehicle::Vehicle;
        let car = FamilyVehicle::car(Vehicle::nominal());
        let mut cfg = LoopConfig::for_vehicle(&car, Arm::Mr(kind), 30.0).with_model(believed);
        cfg.x0 = initial_yaw(3f64.to_radians());
        let mut sc = Scenario::new(SpeedProfile::Constant(kmh_to_mps(v_kmh)));
        let r = closed_loop::run(&cfg, &mut sc, None).unwrap();
        let psi = &r.series.psi_l_rad;
        psi[psi.len() - 3000..]
            .iter()
            .fold(0.0_f64, |m, x| m.max(x.abs()))
            .to_degrees()
    }

    /// The bistable window of the car at 0 A (between its folds of cycles, where a large
    /// disturbance starts shimmy that a small one does not) lies above the no-damper onset the
    /// board's model tracker watches, so the monitor's margin there is already below zero and
    /// the margin-scheduled ASMC damps: inside the window, below the 0 A linear onset
    /// (`stability --damper-current-a 0`: 37.5 km/h), a 3 deg start that the damper at 0 A lets
    /// grow into shimmy decays under `margin-asmc`.
    #[test]
    fn the_margin_scheduled_asmc_damps_large_starts_in_the_bistable_window() {
        use crate::model::family::onset_kmh;
        use shimmy_core::control::ControllerKind;
        use shimmy_core::vehicle::Vehicle;
        let o = car_window_at_0a();
        let rows = chart(&o, &ChartAxis::CurrentA(vec![0.0])).unwrap();
        let fold = rows[0].folds_kmh[0];
        let onset = onset_kmh(&PlantParams::nominal()).unwrap();
        println!("fold of cycles at 0 A {fold:.2} km/h, no-damper onset {onset:.2} km/h");
        assert!(fold > onset + 1.0, "fold {fold}, onset {onset}");
        let v_kmh = fold + 1.5;
        let end_peak_deg =
            |kind: ControllerKind| large_start_end_peak_deg(&Vehicle::nominal(), kind, v_kmh);
        let (passive, scheduled) = (
            end_peak_deg(ControllerKind::PassiveOff),
            end_peak_deg(ControllerKind::MarginAsmc),
        );
        println!(
            "{v_kmh:.2} km/h, 3 deg start, peak over the last 3 s: 0 A {passive:.3} deg, \
             margin-asmc {scheduled:.4} deg"
        );
        assert!(passive > 1.0, "the damper at 0 A shimmies: {passive} deg");
        assert!(scheduled < 0.1, "margin-asmc damps: {scheduled} deg");
    }

    /// The same large start when the firmware's model is wrong in the dangerous direction: its
    /// tyre 20 % softer in cornering than the plant's, so the model's no-damper onset
    /// (42.69 km/h) lies above the plant's fold at 0 A and the model margin calls the speeds
    /// between them safe. Inside that stretch of the plant's bistable window a 3 deg start
    /// that shimmies with the damper at 0 A still decays under `margin-asmc`.
    #[test]
    fn the_margin_scheduled_asmc_damps_the_window_below_a_wrong_models_onset() {
        use crate::model::family::onset_kmh;
        use shimmy_core::control::ControllerKind;
        use shimmy_core::vehicle::Vehicle;
        let fold =
            chart(&car_window_at_0a(), &ChartAxis::CurrentA(vec![0.0])).unwrap()[0].folds_kmh[0];
        let mut believed = Vehicle::nominal();
        believed.plant.c_a *= 0.8;
        let model_onset = onset_kmh(&believed.plant).unwrap();
        println!("plant's fold at 0 A {fold:.2} km/h, the model's onset {model_onset:.2} km/h");
        assert!(
            model_onset > fold + 5.0,
            "fold {fold}, model onset {model_onset}"
        );
        for v_kmh in [fold + 1.5, model_onset - 2.5] {
            let end_peak_deg =
                |kind: ControllerKind| large_start_end_peak_deg(&believed, kind, v_kmh);
            let (passive, scheduled) = (
                end_peak_deg(ControllerKind::PassiveOff),
                end_peak_deg(ControllerKind::MarginAsmc),
            );
            println!(
                "{v_kmh:.2} km/h, 3 deg start, peak over the last 3 s: 0 A {passive:.3} deg, \
                 margin-asmc {scheduled:.4} deg"
            );
            assert!(passive > 1.0, "the damper at 0 A shimmies: {passive} deg");
            assert!(scheduled < 0.1, "margin-asmc damps: {scheduled} deg");
        }
    }

    /// The chart over a vehicle parameter without damper is the Hopf curve: at each tyre
    /// cornering stiffness the onset and offset agree with the linear model's crossings
    /// (`stability::hopf_crossings` on the eigenvalues of A(V), against the shooting's Hopf
    /// points on the nonlinear plant's Jacobian), and a stiffer tyre widens the window.
    #[test]
    fn the_chart_over_a_parameter_is_the_hopf_curve() {
        use shimmy_core::stability::{hopf_crossings, CrossingKind};
        let o = BifurcationOptions {
            params: PlantParams::nominal(),
            params_name: "nominal".into(),
            damper: DamperSetting::Off,
            v_min_kmh: 5.0,
            v_max_kmh: 130.0,
            step_kmh: 5.0,
            small_deg: 0.05,
            large_deg: 3.0,
            duration_s: 20.0,
            window_s: 2.0,
            out: PathBuf::new(),
        };
        let axis = ChartAxis::Param {
            name: "c_a".into(),
            factors: vec![0.8, 1.2],
        };
        let rows = chart(&o, &axis).unwrap();
        let mut windows = Vec::new();
        for r in &rows {
            let p = PlantParams::nominal().with_param("c_a", r.value).unwrap();
            let c = hopf_crossings(&p, 0.0, 1.0, 70.0, 0.25, 1e-4).unwrap();
            let on = c.iter().find(|x| x.kind == CrossingKind::Onset).unwrap();
            let off = c
                .iter()
                .find(|x| x.kind != CrossingKind::Onset && x.speed_mps > on.speed_mps)
                .unwrap();
            let hopf: Vec<f64> = r.hopf.iter().map(|h| h.0).collect();
            assert_eq!(hopf.len(), 2, "{r:?}");
            for (got, want) in hopf.iter().zip([on.speed_mps, off.speed_mps]) {
                assert!((got - mps_to_kmh(want)).abs() < 0.05, "{r:?}: {want} m/s");
            }
            assert!(
                r.hopf.iter().all(|h| h.2 == Some(true)),
                "supercritical: {r:?}"
            );
            windows.push(hopf[1] - hopf[0]);
        }
        assert!(windows[1] > windows[0] + 10.0, "{windows:?}");
    }

    /// The fold of the car's 0 A branch is where the old two-simulation sweep's large start
    /// first shimmies: the sweep on a 0.25 km/h grid about it finds the large start shimmying
    /// at the first grid speed above the fold and decaying at every one below it.
    #[test]
    fn the_fold_is_the_large_starts_onset() {
        let b = mr_branch();
        assert_eq!(b.folds_mps.len(), 1, "{:?}", b.folds_mps);
        let fold = mps_to_kmh(b.folds_mps[0]);
        // the stable cycles lie above the fold in speed, the unstable ones too
        assert!(b
            .orbits
            .iter()
            .all(|o| mps_to_kmh(o.speed_mps) > fold - 1e-3));
        let lo = (fold * 4.0).floor() / 4.0 - 0.5;
        let o = BifurcationOptions {
            params: PlantParams::nominal(),
            params_name: "nominal".into(),
            damper: DamperSetting::reference_mr(0.0),
            v_min_kmh: lo,
            v_max_kmh: lo + 1.0,
            step_kmh: 0.25,
            small_deg: 0.05,
            large_deg: 3.0,
            duration_s: 40.0,
            window_s: 3.0,
            out: PathBuf::new(),
        };
        let rows = sweep(&o, false).unwrap();
        for r in &rows {
            println!("{} km/h: large start {:?}", r.v_kmh, r.large.trend);
            assert_eq!(r.large.shimmies(), r.v_kmh > fold, "fold {fold}: {r:?}");
            assert!(!r.small.shimmies());
        }
    }
}
