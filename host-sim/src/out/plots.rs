//! The run plots several commands share: time histories of closed-loop runs ([`plot_runs`]) and
//! the mode meter's damping estimate against the plant's eigenvalue as it runs ([`plot_margin`]).

use crate::model::family::SimModel;
use crate::out::plot_util::{self, COLORS};
use crate::sim::run::closed_loop::{LoopConfig, LoopResult, MeterRow, TraceRow};
use crate::sim::run::reference::{reference_line, REFERENCE_LABEL};
use anyhow::Result;
use plotters::prelude::*;
use std::path::Path;

/// Spacing of the reference line's points, s (each costs two describing-function evaluations).
pub const REFERENCE_EVERY_S: f64 = 0.25;

/// Wheel yaw, coil current and adaptive gain vs time, one line per run, three panels.
pub fn plot_runs(path: &Path, title: &str, runs: &[(&str, &LoopResult)]) -> Result<()> {
    let png = crate::sim::input::files::PendingFile::new(path);
    let root = BitMapBackend::new(png.tmp(), (1100, 900)).into_drawing_area();
    root.fill(&WHITE)?;
    let (top, rest) = root.split_vertically(40);
    top.draw(&Text::new(
        title.to_string(),
        (15, 10),
        ("sans-serif", 20).into_font(),
    ))?;
    let panels = rest.split_evenly((3, 1));
    let t_max = runs
        .iter()
        .filter_map(|(_, r)| r.trace.last().map(|x| x.t_s))
        .fold(0.1f64, f64::max);
    type Get = fn(&TraceRow) -> f64;
    let specs: [(&str, Get); 3] = [
        ("psi_L [deg]", |r| r.psi_l_rad.to_degrees()),
        ("coil current [A]", |r| r.coil_a),
        ("adaptive / switching gain [rad/s^2]", |r| r.gain_radps2),
    ];
    for (pi, (area, (label, get))) in panels.iter().zip(specs).enumerate() {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for (_, r) in runs {
            for row in &r.trace {
                let y = get(row);
                if y.is_finite() {
                    lo = lo.min(y);
                    hi = hi.max(y);
                }
            }
        }
        if !(lo.is_finite() && hi.is_finite()) {
            (lo, hi) = (0.0, 1.0);
        } else if hi - lo < 1e-9 {
            (lo, hi) = (lo - 0.5, lo + 0.5);
        }
        let pad = 0.05 * (hi - lo);
        let mut chart = ChartBuilder::on(area)
            .margin(8)
            .x_label_area_size(35)
            .y_label_area_size(60)
            .build_cartesian_2d(0.0..t_max, (lo - pad)..(hi + pad))?;
        plot_util::mesh(&mut chart, "t [s]", label)?;
        for (i, (name, r)) in runs.iter().enumerate() {
            let c = plot_util::COLORS[i % plot_util::COLORS.len()];
            let s = chart.draw_series(LineSeries::new(
                r.trace.iter().map(|row| (row.t_s, get(row))),
                c.stroke_width(1),
            ))?;
            if pi == 0 {
                s.label(name.to_string())
                    .legend(plot_util::line_marker(c, 2));
            }
        }
        if pi == 0 {
            plot_util::legend(&mut chart, SeriesLabelPosition::UpperRight)?;
        }
    }
    png.commit(root.present())?;
    Ok(())
}

/// Mode-meter damping estimate (slow: dots in a shaded +- one sigma band) of each run over time
/// next to its reference line (same colour, drawn on top): the damping ratio of the plant's
/// shimmy mode as the run goes, linearised with the damper's equivalent viscous coefficient at
/// the run's current and amplitude ([`crate::sim::run::reference`]). The axis spans the data (and 0).
pub fn plot_margin<M: SimModel<N>, const N: usize>(
    path: &Path,
    title: &str,
    runs: &[(&str, &LoopConfig<M, N>, &LoopResult)],
) -> Result<()> {
    let png = crate::sim::input::files::PendingFile::new(path);
    let root = BitMapBackend::new(png.tmp(), (1100, 500)).into_drawing_area();
    root.fill(&WHITE)?;
    let t_end = runs
        .iter()
        .filter_map(|(_, _, r)| r.meter.last().map(|m| m.t_s))
        .fold(0.1f64, f64::max);
    let lines: Vec<Vec<(f64, f64)>> = runs
        .iter()
        .map(|(_, cfg, r)| {
            reference_line(cfg, r, REFERENCE_EVERY_S)
                .iter()
                .map(|p| (p.t_s, p.mode.zeta))
                .collect()
        })
        .collect();
    let meters: Vec<Vec<&MeterRow>> = runs
        .iter()
        .map(|(_, _, r)| r.meter.iter().filter(|m| m.valid).collect())
        .collect();
    let (lo, hi) = zeta_axis(
        lines.iter().flatten().map(|p| p.1),
        meters.iter().flatten().map(|m| m.zeta_slow),
    );
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!("{title}: damping ratio of the shimmy mode"),
            ("sans-serif", 16),
        )
        .margin(8)
        .x_label_area_size(35)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..t_end, lo..hi)?;
    plot_util::mesh(&mut chart, "time [s]", "zeta [-]")?;
    chart.draw_series(LineSeries::new([(0.0, 0.0), (t_end, 0.0)], BLACK))?;
    for (i, (name, valid)) in runs.iter().map(|r| r.0).zip(&meters).enumerate() {
        let c = COLORS[(i + 1) % COLORS.len()];
        for span in contiguous(valid) {
            let band: Vec<(f64, f64)> = span
                .iter()
                .map(|m| (m.t_s, (m.zeta_slow + m.sigma_zeta_slow).clamp(lo, hi)))
                .chain(
                    span.iter()
                        .rev()
                        .map(|m| (m.t_s, (m.zeta_slow - m.sigma_zeta_slow).clamp(lo, hi))),
                )
                .collect();
            chart.draw_series(std::iter::once(Polygon::new(band, c.mix(0.15).filled())))?;
        }
        chart
            .draw_series(
                valid
                    .iter()
                    .map(|m| Circle::new((m.t_s, m.zeta_slow.clamp(lo, hi)), 1, c.filled())),
            )?
            .label(format!("mode meter (slow) +- sigma, {name}"))
            .legend(plot_util::dot_marker(c));
    }
    for (i, (name, line)) in runs.iter().map(|r| r.0).zip(&lines).enumerate() {
        let c = COLORS[(i + 1) % COLORS.len()];
        chart
            .draw_series(LineSeries::new(
                line.iter().map(|&(t, z)| (t, z.clamp(lo, hi))),
                c.stroke_width(3),
            ))?
            .label(format!("{REFERENCE_LABEL}, {name}"))
            .legend(plot_util::line_marker(c, 3));
    }
    plot_util::legend(&mut chart, SeriesLabelPosition::UpperRight)?;
    png.commit(root.present())?;
    Ok(())
}

/// The damping axis: the reference lines and the meter's estimates between their 2nd and 98th
/// percentiles (a start-up transient of the meter does not squash the rest), and 0, with 10 %
/// room; at least 0.1 wide.
fn zeta_axis(reference: impl Iterator<Item = f64>, meter: impl Iterator<Item = f64>) -> (f64, f64) {
    let mut m: Vec<f64> = meter.filter(|z| z.is_finite()).collect();
    m.sort_by(f64::total_cmp);
    let pick = |q: f64| {
        m.get(((m.len().saturating_sub(1)) as f64 * q) as usize)
            .copied()
    };
    let (mut lo, mut hi) = (0.0f64, 0.0f64);
    for z in reference
        .filter(|z| z.is_finite())
        .chain(pick(0.02))
        .chain(pick(0.98))
    {
        lo = lo.min(z);
        hi = hi.max(z);
    }
    let pad = (0.1 * (hi - lo)).max(0.5 * (0.1 - (hi - lo)).max(0.0));
    (lo - pad, hi + pad)
}

/// The runs of `rows` without a gap of more than 0.5 s (the meter was not valid in between).
fn contiguous<'a>(rows: &'a [&'a MeterRow]) -> impl Iterator<Item = &'a [&'a MeterRow]> {
    rows.chunk_by(|a, b| b.t_s - a.t_s <= 0.5)
}
