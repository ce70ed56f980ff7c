//! `shimmy-sim sweep`: stability maps over speed x one parameter (x damper current): the largest
//! real part of the oscillatory eigenvalues of A(V) on a grid, the Hopf boundary of each
//! parameter row refined by the bounded Brent search, a PNG heat map with the boundary drawn on
//! it, and CSV. Rows run in parallel (rayon) with a progress bar; the result does not depend on
//! the number of threads (each grid point is computed independently, rows are written in order).

use super::args::{axes_of, SweepArgs};
use crate::model::damper_equiv::damper_equivalent;
use crate::model::family::{ParamInfo, SimModel};
use crate::model::registry::{self, ModelVisitor, Registered};
use crate::out::plot_util;
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use plotters::prelude::*;
use rayon::prelude::*;
use shimmy_core::eigen::ModeShape;
use shimmy_core::model::LinearModel;
use shimmy_core::stability::{self, CrossingKind};
use shimmy_core::units::{kmh_to_mps, mps_to_kmh};
use shimmy_core::vehicle::Vehicle;
use std::fmt::Write as _;
use std::path::Path;

/// One parameter row of a map.
#[derive(Debug, Clone)]
pub struct SweepRow {
    /// Parameter value.
    pub value: f64,
    /// Largest real part of the oscillatory eigenvalues at each speed, 1/s.
    pub max_re: Vec<f64>,
    /// Hopf crossings in the speed range: (speed in km/h, onset?, the crossing mode's shape).
    pub crossings: Vec<(f64, bool, ModeShape)>,
}

/// One map (one damper setting).
#[derive(Debug, Clone)]
pub struct SweepMap {
    /// Label of the damper setting.
    pub damper: String,
    /// Equivalent viscous damper coefficient, N s/m.
    pub c_nspm: f64,
    /// Speeds, km/h.
    pub speeds_kmh: Vec<f64>,
    /// Rows, by increasing parameter value.
    pub rows: Vec<SweepRow>,
}

/// Computes the maps on the vehicle of `--vehicle`, of any model of the family; `ready` is
/// called once every option has passed its checks, before the sweep (the command claims its
/// output folder there).
pub fn compute(
    a: &SweepArgs,
    ready: &mut dyn FnMut() -> Result<()>,
) -> Result<(ParamInfo, Vec<SweepMap>)> {
    struct On<'a, 'r>(&'a SweepArgs, &'r mut dyn FnMut() -> Result<()>);
    impl ModelVisitor for On<'_, '_> {
        type Output = Result<(ParamInfo, Vec<SweepMap>)>;
        fn visit<M: Registered<N>, const N: usize>(self, f: M::File) -> Self::Output {
            let v = registry::family::<M, N>(f)?;
            compute_on(self.0, &v.model, &v.parts, self.1)
        }
    }
    registry::with_model(
        crate::sim::input::vehicle_file::load_model(&a.vehicle.spec)?,
        On(a, ready),
    )
}

/// The maps of the vehicle model `base` with the damper of `vehicle` ([`compute`]'s `ready`).
pub fn compute_on<M: SimModel<N>, const N: usize>(
    a: &SweepArgs,
    base: &M,
    vehicle: &Vehicle,
    ready: &mut dyn FnMut() -> Result<()>,
) -> Result<(ParamInfo, Vec<SweepMap>)> {
    let (speeds_kmh, values, param) = axes_of(a, base, vehicle, (149, 41))?;
    let mut dampers: Vec<(String, f64)> = Vec::new();
    if a.damper_current_a.is_empty() {
        dampers.push(("no damper".into(), 0.0));
    }
    for &i in &a.damper_current_a {
        let d = damper_equivalent(
            base,
            &vehicle.damper.spencer,
            i,
            a.ref_amplitude_deg,
            kmh_to_mps(a.v_min_kmh),
            kmh_to_mps(a.v_max_kmh),
        )?;
        dampers.push((format!("MR {i:.2} A"), d.c_eq_nspm));
    }
    ready()?;

    let bar = if a.quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new((dampers.len() * values.len()) as u64)
    };
    bar.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} rows {elapsed_precise} eta {eta}")
            .context("progress template")?,
    );
    let mut maps = Vec::new();
    for (label, c) in dampers {
        let rows: Result<Vec<SweepRow>> = values
            .par_iter()
            .map(|&value| {
                let row = base
                    .with_param(param.name, value)
                    .and_then(|p| row(&p.linear(), value, c, &speeds_kmh, a));
                bar.inc(1);
                row
            })
            .collect();
        maps.push(SweepMap {
            damper: label,
            c_nspm: c,
            speeds_kmh: speeds_kmh.clone(),
            rows: rows?,
        });
    }
    bar.finish_and_clear();
    Ok((param, maps))
}

fn row<M: LinearModel<N>, const N: usize>(
    p: &M,
    value: f64,
    c: f64,
    speeds_kmh: &[f64],
    a: &SweepArgs,
) -> Result<SweepRow> {
    let max_re = speeds_kmh
        .iter()
        .map(|&v| {
            stability::critical_mode_at(p, kmh_to_mps(v), c)
                .map(|m| m.re)
                .with_context(|| format!("eigenvalues at {v} km/h, {} = {value}", a.param))
        })
        .collect::<Result<Vec<f64>>>()?;
    let step = kmh_to_mps(speeds_kmh[1] - speeds_kmh[0]);
    let crossings = stability::hopf_crossings(
        p,
        c,
        kmh_to_mps(a.v_min_kmh),
        kmh_to_mps(a.v_max_kmh),
        step,
        1e-4,
    )
    .with_context(|| format!("Hopf crossings, {} = {value}", a.param))?
    .iter()
    .map(|x| {
        (
            mps_to_kmh(x.speed_mps),
            x.kind == CrossingKind::Onset,
            x.shape,
        )
    })
    .collect();
    Ok(SweepRow {
        value,
        max_re,
        crossings,
    })
}

/// The command: compute, write CSV + PNG per map, print the boundary table.
pub fn command(a: &SweepArgs) -> Result<()> {
    let mut _out_dir = None;
    let (param, maps) = compute(a, &mut || {
        _out_dir = Some(crate::sim::input::files::OutDir::claim(&a.out_dir())?);
        Ok(())
    })?;
    for (k, map) in maps.iter().enumerate() {
        let tag = if map.c_nspm == 0.0 {
            "no-damper".to_string()
        } else {
            format!("damper{k}")
        };
        let grid = a.out_dir().join(format!("sweep-{}-{tag}.csv", param.name));
        let boundary = a
            .out_dir()
            .join(format!("boundary-{}-{tag}.csv", param.name));
        let png = a.out_dir().join(format!("sweep-{}-{tag}.png", param.name));
        write_csv(&grid, &boundary, param, map)?;
        plot(&png, param, map, &a.vehicle.spec)?;
        println!(
            "{} ({}, c = {:.1} N s/m): Hopf boundary vs {} [{}]",
            a.vehicle.spec, map.damper, map.c_nspm, param.name, param.unit
        );
        println!(
            "  {:>14}  {:>12} {:>12}",
            param.name, "onset km/h", "offset km/h"
        );
        let every = (map.rows.len() / 10).max(1);
        for r in map.rows.iter().step_by(every) {
            let (on, off) = shimmy_window(&r.crossings);
            let on = on.map(|v| format!("{v:.2}"));
            let off = off.map(|v| format!("{v:.2}"));
            println!(
                "  {:>14.6e}  {:>12} {:>12}",
                r.value,
                on.unwrap_or_else(|| "-".into()),
                off.unwrap_or_else(|| "-".into())
            );
        }
        println!(
            "  wrote {}, {}, {}",
            grid.display(),
            boundary.display(),
            png.display()
        );
    }
    Ok(())
}

/// The shimmy window of a row's crossings: the first onset of the shimmy-shaped mode
/// ([`ModeShape::is_shimmy`]) and its first offset above it (km/h); another mode's crossing
/// (the 42-47 Hz anti-phase wheel yaw) is never the window.
pub fn shimmy_window(crossings: &[(f64, bool, ModeShape)]) -> (Option<f64>, Option<f64>) {
    let on = crossings
        .iter()
        .find(|c| c.1 && c.2.is_shimmy())
        .map(|c| c.0);
    let off = crossings
        .iter()
        .find(|c| !c.1 && c.2.is_shimmy() && on.is_none_or(|o| c.0 > o))
        .map(|c| c.0);
    (on, off)
}

fn write_csv(grid: &Path, boundary: &Path, param: ParamInfo, map: &SweepMap) -> Result<()> {
    let mut s = format!(
        "{} [{}],speed [km/h],max Re lambda (oscillatory) [1/s]\n",
        param.name, param.unit
    );
    for r in &map.rows {
        for (v, re) in map.speeds_kmh.iter().zip(&r.max_re) {
            let _ = writeln!(s, "{:e},{v},{re:e}", r.value);
        }
    }
    crate::sim::input::files::write_file(grid, s)?;
    let mut b = format!(
        "{} [{}],crossing speed [km/h],kind,mode\n",
        param.name, param.unit
    );
    for r in &map.rows {
        for (v, onset, shape) in &r.crossings {
            let _ = writeln!(
                b,
                "{:e},{v:.4},{},{}",
                r.value,
                if *onset { "onset" } else { "offset" },
                shape.name()
            );
        }
    }
    crate::sim::input::files::write_file(boundary, b)?;
    Ok(())
}

fn plot(path: &Path, param: ParamInfo, map: &SweepMap, set: &str) -> Result<()> {
    let png = crate::sim::input::files::PendingFile::new(path);
    let picture =
        BitMapBackend::new(png.tmp(), (1000 + plot_util::COLOUR_BAR_PX, 700)).into_drawing_area();
    picture.fill(&WHITE)?;
    let (root, bar) = picture.split_horizontally(1000);
    let cells = plot_util::cells(
        &map.speeds_kmh,
        map.rows[0].value,
        map.rows[map.rows.len() - 1].value,
        map.rows.len(),
    );
    let (dv, dp) = (cells.dx, cells.dy);
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!(
                "{set}, {}: growth rate max Re lambda [1/s] (red unstable, blue stable); black: Hopf boundary",
                map.damper
            ),
            ("sans-serif", 18),
        )
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(80)
        .build_cartesian_2d(cells.x, cells.y)?;
    chart
        .configure_mesh()
        .x_desc("speed [km/h]")
        .y_desc(format!("{} [{}]", param.name, param.unit))
        .draw()?;
    // Symmetric colour scale around zero, clipped at the 95th percentile of |Re|.
    let mut mags: Vec<f64> = map
        .rows
        .iter()
        .flat_map(|r| r.max_re.iter().map(|x| x.abs()))
        .collect();
    mags.sort_by(f64::total_cmp);
    let scale = mags
        .get(mags.len() * 95 / 100)
        .copied()
        .unwrap_or(1.0)
        .max(1e-9);
    chart.draw_series(map.rows.iter().flat_map(|r| {
        map.speeds_kmh.iter().zip(&r.max_re).map(move |(&v, &re)| {
            Rectangle::new(
                [
                    (v - dv / 2.0, r.value - dp / 2.0),
                    (v + dv / 2.0, r.value + dp / 2.0),
                ],
                plot_util::diverging(re / scale).filled(),
            )
        })
    }))?;
    plot_util::colour_bar(
        &bar,
        -scale,
        scale,
        "max Re lambda [1/s] (clipped)",
        40,
        |re| plot_util::diverging(re / scale),
    )?;
    // the shimmy mode's crossings filled, another mode's hollow
    chart.draw_series(map.rows.iter().flat_map(|r| {
        r.crossings.iter().map(move |&(v, _, shape)| {
            let style = if shape.is_shimmy() {
                BLACK.filled()
            } else {
                BLACK.stroke_width(1)
            };
            Circle::new((v, r.value), 3, style)
        })
    }))?;
    png.commit(picture.present())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(out: &Path) -> SweepArgs {
        SweepArgs {
            vehicle: crate::cmd::VehicleArg::new("nominal"),
            param: "k_d".into(),
            factor_min: 0.8,
            factor_max: 1.0,
            factor_steps: Some(3),
            v_min_kmh: 5.0,
            v_max_kmh: 120.0,
            v_steps: Some(47),
            damper_current_a: vec![],
            ref_amplitude_deg: 0.5,
            out: crate::cmd::OutArg::new(out),
            quiet: true,
            controllers: vec![],
            on_current_a: 1.0,
            duration_s: 6.0,
            kick_deg: 3.0,
            seed: 1,
        }
    }

    #[test]
    fn map_matches_the_stability_command_and_is_deterministic() {
        let out = std::env::temp_dir().join(format!("shimmy-sweep-{}", std::process::id()));
        let a = args(&out);
        let (_, maps) = compute(&a, &mut || Ok(())).unwrap();
        let (_, again) = compute(&a, &mut || Ok(())).unwrap();
        let last = &maps[0].rows[2]; // factor 1.0: the nominal set
        assert_eq!(last.max_re, again[0].rows[2].max_re, "deterministic");
        // The boundary of the nominal row is the nominal Hopf window found independently by a
        // fine hopf_crossings call.
        let p = shimmy_core::vehicles::car::PlantParams::nominal();
        let fine =
            stability::hopf_crossings(&p, 0.0, kmh_to_mps(5.0), kmh_to_mps(120.0), 0.05, 1e-6)
                .unwrap();
        assert_eq!(last.crossings.len(), fine.len());
        for (c, f) in last.crossings.iter().zip(fine.iter()) {
            assert!(
                (c.0 - mps_to_kmh(f.speed_mps)).abs() < 0.01,
                "{c:?} vs {f:?}"
            );
        }
        // Lower K_d widens the window (sensitivity result): onset moves down.
        let soft = &maps[0].rows[0];
        assert!(soft.crossings[0].0 < last.crossings[0].0);
        // Grid sign agrees with the boundary: unstable strictly inside the window.
        let (on, off) = (last.crossings[0].0, last.crossings[1].0);
        for (v, re) in maps[0].speeds_kmh.iter().zip(&last.max_re) {
            if *v > on + 0.5 && *v < off - 0.5 {
                assert!(*re > 0.0, "{v} km/h inside the window must be unstable");
            } else if *v < on - 0.5 || *v > off + 0.5 {
                assert!(*re < 0.0, "{v} km/h outside the window must be stable");
            }
        }
        command(&a).unwrap();
        let png = out.join("sweep-k_d-no-damper.png");
        assert!(
            std::fs::metadata(&png).unwrap().len() > 10_000,
            "a non-empty heat map"
        );
        let _ = std::fs::remove_dir_all(&out);
    }

    #[test]
    fn bad_arguments_are_rejected_with_the_name() {
        let out = std::env::temp_dir();
        let mut a = args(&out);
        a.param = "kd".into();
        assert!(format!("{:#}", compute(&a, &mut || Ok(())).unwrap_err()).contains("--param kd"));
        let mut a = args(&out);
        a.v_max_kmh = 1.0;
        assert!(compute(&a, &mut || Ok(())).is_err());
    }

    /// The table's window is the shimmy mode's: `gentle` with I_k +20 % has only the 42.8 Hz
    /// anti-phase mode's onset (212.4 km/h) in 5..250 km/h, so no window (the first onset of
    /// any mode used to be printed as the window's onset); `nominal`'s is its own.
    #[test]
    fn the_window_is_the_shimmy_modes() {
        use shimmy_core::vehicles::car::{Param, ParamSet};
        let row = |p: &shimmy_core::vehicles::car::PlantParams| -> Vec<(f64, bool, ModeShape)> {
            stability::hopf_crossings(p, 0.0, kmh_to_mps(5.0), kmh_to_mps(250.0), 0.25, 1e-4)
                .unwrap()
                .iter()
                .map(|x| {
                    (
                        mps_to_kmh(x.speed_mps),
                        x.kind == CrossingKind::Onset,
                        x.shape,
                    )
                })
                .collect()
        };
        let g = ParamSet::Gentle.params();
        let closed = row(&g.with(Param::IK, g.get(Param::IK) * 1.2));
        assert_eq!(closed.len(), 1, "{closed:?}");
        assert_eq!(closed[0].2, ModeShape::AntiPhaseWheelYaw);
        assert!((closed[0].0 - 212.4).abs() < 0.1, "{closed:?}");
        assert_eq!(shimmy_window(&closed), (None, None));
        let (on, off) = shimmy_window(&row(&ParamSet::Nominal.params()));
        assert!((on.unwrap() - 29.35).abs() < 0.01 && (off.unwrap() - 84.15).abs() < 0.01);
    }
}
