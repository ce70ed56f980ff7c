//! What `shimmy-sim analyze` writes about an [`Analysis`]: the 100 Hz estimates
//! (`analysis.csv`, units in the column names), the warning episodes (`events.csv`), a plot of
//! damping, frequency, speed and warning level over time (`analysis.png`), and the report's
//! Markdown and metrics (written as `report.md`, `report.html` and `summary.json` by
//! [`crate::out::report::write_pages`]).

use crate::out::plot_util::{self, COLORS};
use crate::out::table::opt;
use crate::sim::analyze::{level_name, Analysis, AnalysisSummary};
use anyhow::Result;
use plotters::prelude::*;
use serde_json::{json, Value};
use shimmy_core::estimator::monitor::Level;
use std::fmt::Write as _;
use std::path::Path;

/// Column names of `analysis.csv`.
pub const CSV_HEADER: &str = "t_s,speed_kmh,zeta_slow,sigma_zeta_slow,freq_slow_hz,slow_valid,zeta_fast,sigma_zeta_fast,freq_fast_hz,fast_valid,amplitude_deg,zeta_model,speed_margin_kmh,time_to_critical_s,model_consistent,level";

/// Writes `analysis.csv` (NaN: absent).
pub fn write_rows_csv(path: &Path, a: &Analysis) -> Result<()> {
    let mut s = format!("{CSV_HEADER}\n");
    for r in &a.rows {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            r.t_s,
            r.speed_mps * 3.6,
            r.zeta_slow,
            r.sigma_zeta_slow,
            r.freq_slow_hz,
            u8::from(r.slow_valid),
            r.zeta_fast,
            r.sigma_zeta_fast,
            r.freq_fast_hz,
            u8::from(r.fast_valid),
            r.amplitude_rad.to_degrees(),
            r.zeta_model,
            r.speed_margin_mps * 3.6,
            r.time_to_critical_s,
            u8::from(r.model_consistent),
            level_name(r.level)
        );
    }
    crate::sim::input::files::write_file(path, s)
}

/// Writes `events.csv`: one warning episode a row.
pub fn write_events_csv(path: &Path, a: &Analysis) -> Result<()> {
    let mut s = String::from(
        "start_s,speed_kmh,freq_hz,peak_amplitude_deg,worst_level,duration_s,shimmy_s,open\n",
    );
    for e in &a.events {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{}",
            e.start_s,
            f64::from(e.speed_mps) * 3.6,
            e.freq_hz,
            f64::from(e.peak_amplitude_rad).to_degrees(),
            level_name(e.worst),
            e.duration_s,
            e.shimmy_s,
            u8::from(e.open)
        );
    }
    crate::sim::input::files::write_file(path, s)
}

fn level_color(l: Level) -> RGBColor {
    match l {
        Level::Normal => WHITE,
        Level::MarginLow => RGBColor(255, 221, 120),
        Level::ApproachingCritical => RGBColor(245, 150, 60),
        Level::ShimmyPresent => RGBColor(220, 50, 32),
    }
}

/// Spans of constant level above Normal: (from s, to s, level).
fn level_spans(a: &Analysis) -> Vec<(f64, f64, Level)> {
    let mut spans: Vec<(f64, f64, Level)> = Vec::new();
    for r in &a.rows {
        match spans.last_mut() {
            Some(s) if s.2 == r.level => s.1 = r.t_s,
            _ => spans.push((r.t_s, r.t_s, r.level)),
        }
    }
    spans.retain(|s| s.2 > Level::Normal);
    spans
}

/// Damping (slow +- sigma, fast, model), frequency and speed over time; the warning levels
/// as coloured bands behind every panel.
pub fn plot_analysis(path: &Path, title: &str, a: &Analysis) -> Result<()> {
    let png = crate::sim::input::files::PendingFile::new(path);
    let root = BitMapBackend::new(png.tmp(), (1100, 900)).into_drawing_area();
    root.fill(&WHITE)?;
    let (top, rest) = root.split_vertically(40);
    top.draw(&Text::new(
        format!("{title}: bands = warning level (yellow margin-low, orange approaching-critical, red shimmy-present)"),
        (15, 10),
        ("sans-serif", 16).into_font(),
    ))?;
    let panels = rest.split_evenly((3, 1));
    let t0 = a.rows.first().map_or(0.0, |r| r.t_s);
    let t1 = a.rows.last().map_or(1.0, |r| r.t_s).max(t0 + 0.1);
    let spans = level_spans(a);
    let v_max = a
        .rows
        .iter()
        .map(|r| r.speed_mps * 3.6)
        .filter(|v| v.is_finite())
        .fold(1.0f64, f64::max);
    let ranges = [(-0.1, 0.3), (0.0, 20.0), (0.0, 1.1 * v_max)];
    let labels = ["zeta [-]", "frequency [Hz]", "speed [km/h]"];
    for (pi, (area, ((lo, hi), label))) in panels
        .iter()
        .zip(ranges.into_iter().zip(labels))
        .enumerate()
    {
        let mut chart = ChartBuilder::on(area)
            .margin(8)
            .x_label_area_size(35)
            .y_label_area_size(60)
            .build_cartesian_2d(t0..t1, lo..hi)?;
        plot_util::mesh(&mut chart, "t [s]", label)?;
        chart.draw_series(spans.iter().map(|&(s, e, l)| {
            Rectangle::new(
                [(s, lo), (e.max(s + 0.01), hi)],
                level_color(l).mix(0.5).filled(),
            )
        }))?;
        let clamp = |y: f64| y.clamp(lo, hi);
        let valid_slow = || a.rows.iter().filter(|r| r.slow_valid);
        match pi {
            0 => {
                chart.draw_series(LineSeries::new([(t0, 0.0), (t1, 0.0)], BLACK))?;
                chart.draw_series(valid_slow().map(|r| {
                    PathElement::new(
                        [
                            (r.t_s, clamp(r.zeta_slow - r.sigma_zeta_slow)),
                            (r.t_s, clamp(r.zeta_slow + r.sigma_zeta_slow)),
                        ],
                        COLORS[2].mix(0.25),
                    )
                }))?;
                chart
                    .draw_series(
                        a.rows.iter().filter(|r| r.fast_valid).map(|r| {
                            Circle::new((r.t_s, clamp(r.zeta_fast)), 1, COLORS[3].filled())
                        }),
                    )?
                    .label("fast (warning) estimate")
                    .legend(plot_util::dot_marker(COLORS[3]));
                chart
                    .draw_series(
                        valid_slow().map(|r| {
                            Circle::new((r.t_s, clamp(r.zeta_slow)), 1, COLORS[2].filled())
                        }),
                    )?
                    .label("slow (margin) estimate +- sigma")
                    .legend(plot_util::dot_marker(COLORS[2]));
                if a.model {
                    chart
                        .draw_series(LineSeries::new(
                            a.rows
                                .iter()
                                .filter(|r| r.zeta_model.is_finite())
                                .map(|r| (r.t_s, clamp(r.zeta_model))),
                            COLORS[1].stroke_width(2),
                        ))?
                        .label("model (vehicle's plant, no damper)")
                        .legend(plot_util::line_marker(COLORS[1], 2));
                }
                plot_util::legend(&mut chart, SeriesLabelPosition::UpperRight)?;
            }
            1 => {
                chart
                    .draw_series(valid_slow().map(|r| {
                        Circle::new((r.t_s, clamp(r.freq_slow_hz)), 1, COLORS[2].filled())
                    }))?
                    .label("slow estimate")
                    .legend(plot_util::dot_marker(COLORS[2]));
                plot_util::legend(&mut chart, SeriesLabelPosition::UpperRight)?;
            }
            _ => {
                chart.draw_series(LineSeries::new(
                    a.rows.iter().map(|r| (r.t_s, clamp(r.speed_mps * 3.6))),
                    COLORS[0].stroke_width(2),
                ))?;
            }
        }
    }
    png.commit(root.present())?;
    Ok(())
}

/// The headline numbers as JSON (NaN and absent values as null).
pub fn summary_json(a: &Analysis) -> Value {
    let s = a.summary();
    let num = |x: f64| if x.is_finite() { json!(x) } else { Value::Null };
    let st = &a.resampling;
    json!({
        "not_judged": a.not_judged(),
        "duration_s": num(s.duration_s),
        "valid_fraction": num(s.valid_fraction),
        "zeta_slow_min": num(s.zeta_slow_min),
        "zeta_slow_median": num(s.zeta_slow_median),
        "sigma_slow_median": num(s.sigma_slow_median),
        "freq_slow_median_hz": num(s.freq_slow_median_hz),
        "max_level": level_name(s.max_level),
        "first_warning": s.first_warning.map(|(t, v, l)| json!({
            "t_s": t, "speed_kmh": v * 3.6, "level": level_name(l),
        })),
        "episodes": s.episodes,
        "model": a.model,
        "rejected_samples": a.rejected_samples,
        "resampling": {
            "log_rows": st.log_rows,
            "log_median_dt_s": st.log_median_dt_s,
            "log_max_dt_s": st.log_max_dt_s,
            "grid_points": st.grid_points,
            "exact": st.exact,
            "interpolated": st.interpolated,
            "missing_yaw": st.missing_yaw,
            "missing_speed": st.missing_speed,
            "gaps": st.gaps,
        },
    })
}

fn summary_table(s: &AnalysisSummary, a: &Analysis) -> String {
    let mut t = String::from("| quantity | value |\n|---|---|\n");
    let f = |x: f64, p: usize| opt(x.is_finite().then_some(x), p);
    let rows: [(&str, String); 10] = [
        (
            "verdict",
            a.not_judged()
                .map_or("judged".into(), |why| format!("**not judged**: {why}")),
        ),
        ("analysed length [s]", format!("{:.2}", s.duration_s)),
        (
            "valid slow estimates [%]",
            format!("{:.1}", 100.0 * s.valid_fraction),
        ),
        ("median slow damping ratio [-]", f(s.zeta_slow_median, 4)),
        ("median sigma of it [-]", f(s.sigma_slow_median, 4)),
        ("lowest slow damping ratio [-]", f(s.zeta_slow_min, 4)),
        ("median frequency [Hz]", f(s.freq_slow_median_hz, 3)),
        ("highest warning level", level_name(s.max_level).to_string()),
        (
            "first warning",
            s.first_warning.map_or("none".into(), |(t, v, l)| {
                format!("{} at {t:.2} s, {:.1} km/h", level_name(l), v * 3.6)
            }),
        ),
        (
            "warning episodes",
            format!(
                "{} ({} not kept in the event log)",
                s.episodes, a.dropped_events
            ),
        ),
    ];
    for (k, v) in rows {
        let _ = writeln!(t, "| {k} | {v} |");
    }
    t
}

/// The report's Markdown (without provenance): `source` names the log, `plot` and the CSV
/// files are linked relative to the report.
pub fn markdown(a: &Analysis, source: &str, vehicle: &str, plot: &str) -> String {
    let s = a.summary();
    let st = &a.resampling;
    let mut md = format!(
        "The board's margin path (the `shimmy-core` mode meter, fusion and monitor, as in the firmware's meter task) on the measured log `{source}`: wheel yaw and speed resampled to the meter's 1 kHz input. Vehicle `{vehicle}` (rolling radius, warning thresholds{}).\n\n",
        if a.model { ", model margin from its plant without damper" } else { "; data only, no model margin" }
    );
    md += "## Summary\n\n";
    md += &summary_table(&s, a);
    md += "\n## Resampling\n\n| quantity | value |\n|---|---|\n";
    for (k, v) in [
        ("log rows", st.log_rows.to_string()),
        (
            "median log spacing [ms]",
            format!("{:.3}", st.log_median_dt_s * 1e3),
        ),
        (
            "largest log spacing [ms]",
            format!("{:.3}", st.log_max_dt_s * 1e3),
        ),
        ("1 kHz grid points", st.grid_points.to_string()),
        ("taken as logged", st.exact.to_string()),
        ("interpolated", st.interpolated.to_string()),
        (
            "without yaw (gaps, empty cells)",
            st.missing_yaw.to_string(),
        ),
        ("without speed", st.missing_speed.to_string()),
        ("gaps longer than the limit", st.gaps.to_string()),
        ("samples the meter rejected", a.rejected_samples.to_string()),
    ] {
        let _ = writeln!(md, "| {k} | {v} |");
    }
    md += "\n## Over time\n\n";
    let _ = writeln!(
        md,
        "![damping, frequency, speed and warning level over time]({plot})\n"
    );
    md += "## Warning episodes\n\n";
    if a.events.is_empty() {
        md += "None.\n\n";
    } else {
        md += "| start [s] | speed [km/h] | frequency [Hz] | peak amplitude [deg] | worst level | duration [s] | open |\n|---:|---:|---:|---:|---|---:|---|\n";
        for e in &a.events {
            let _ = writeln!(
                md,
                "| {:.2} | {:.1} | {:.2} | {:.3} | {} | {:.2} | {} |",
                e.start_s,
                f64::from(e.speed_mps) * 3.6,
                e.freq_hz,
                f64::from(e.peak_amplitude_rad).to_degrees(),
                level_name(e.worst),
                e.duration_s,
                if e.open { "yes" } else { "no" }
            );
        }
        md.push('\n');
    }
    md += "Files: [analysis.csv](analysis.csv) (every 100 Hz estimate, units in the column names), [events.csv](events.csv), [summary.json](summary.json).\n\n";
    md
}
