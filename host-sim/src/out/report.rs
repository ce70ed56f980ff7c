//! Self-contained run reports (Markdown page + PNG plots + trace CSVs + metrics table), written
//! in one place for the no-argument demo and for `shimmy-sim report SCENARIO.toml...`.
//!
//! A [`Report`] is a title, an introduction and [`Section`]s (one scenario each) holding the
//! closed-loop runs of one or more controllers. [`write()`] produces in the output folder:
//! `report.md`, `metrics.csv` (every run, units in the header), per section `<name>-time.png`
//! (wheel yaw, coil current, gain vs time), `<name>-margin.png` (the mode meter's damping
//! estimate next to each run's reference line, the plant's shimmy mode as it runs, when the
//! meter ran) and one trace CSV per run; next to `report.md` the same page as one self-contained
//! `report.html` (plots embedded) and `summary.json` (the metrics for scripts), both with the
//! report's [`Provenance`] ([`write_pages`], also used by `shimmy-sim analyze`).

use crate::model::family::SimModel;
use crate::model::registry::{ReferenceModel, REFERENCE_N};
use crate::out::file_name::sanitize;
use crate::out::html;
use crate::out::plots::{plot_margin, plot_runs};
use crate::out::provenance::Provenance;
use crate::out::table::opt;
use crate::sim::run::closed_loop::{LoopConfig, LoopResult, RunMetrics};
use crate::sim::run::reference::REFERENCE_LABEL;
use anyhow::{Context, Result};
use serde_json::{json, Value};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// One closed-loop run of a report, on the vehicle model `M` (the car by default).
#[derive(Clone, Debug)]
pub struct ReportRun<M: SimModel<N> = ReferenceModel, const N: usize = { REFERENCE_N }> {
    /// Legend and table label (usually the controller).
    pub label: String,
    /// Its configuration.
    pub cfg: LoopConfig<M, N>,
    /// Its result.
    pub result: LoopResult,
    /// Its metrics.
    pub metrics: RunMetrics,
}

impl<M: SimModel<N>, const N: usize> ReportRun<M, N> {
    /// A run with its metrics (settling measured from `t_dist_s`).
    pub fn new(
        label: &str,
        cfg: LoopConfig<M, N>,
        result: LoopResult,
        t_dist_s: Option<f64>,
    ) -> Self {
        let metrics = result.metrics(&cfg, t_dist_s);
        ReportRun {
            label: label.to_string(),
            cfg,
            result,
            metrics,
        }
    }
}

/// One scenario with its runs.
#[derive(Clone, Debug)]
pub struct Section<M: SimModel<N> = ReferenceModel, const N: usize = { REFERENCE_N }> {
    /// Scenario name (heading; file names use a sanitised form).
    pub name: String,
    /// Markdown text under the heading.
    pub description: String,
    /// The runs, one per controller.
    pub runs: Vec<ReportRun<M, N>>,
    /// Further plots already written into the output folder: (caption, file name).
    pub extra_plots: Vec<(String, String)>,
}

/// A whole report.
#[derive(Clone, Debug)]
pub struct Report<M: SimModel<N> = ReferenceModel, const N: usize = { REFERENCE_N }> {
    /// Page title.
    pub title: String,
    /// Markdown under the title.
    pub intro: String,
    /// The scenarios.
    pub sections: Vec<Section<M, N>>,
    /// Where it comes from (`None`: this process's command line only).
    pub provenance: Option<Provenance>,
}

/// What [`write_pages`] produced.
#[derive(Clone, Debug)]
pub struct Pages {
    /// `report.md`.
    pub markdown: PathBuf,
    /// `report.html`.
    pub html: PathBuf,
    /// `summary.json`.
    pub json: PathBuf,
}

/// Writes a report's pages into `out`: `report.md` (`md` with the provenance section
/// appended), `report.html` (the same page, self-contained: every referenced plot embedded)
/// and `summary.json` (`{"title", "provenance", "metrics": metrics}`). The Markdown's tables
/// are checked first: an invalid table is an error, not a broken page.
pub fn write_pages(
    out: &Path,
    title: &str,
    md: &str,
    provenance: &Provenance,
    metrics: Value,
) -> Result<Pages> {
    let md = format!("{}\n\n{}", md.trim_end(), provenance.markdown());
    html::check_tables(&md).context("report.md")?;
    let page = html::page(title, &md, out)?;
    let pages = Pages {
        markdown: out.join("report.md"),
        html: out.join("report.html"),
        json: out.join("summary.json"),
    };
    let summary = json!({"title": title, "provenance": provenance.json(), "metrics": metrics});
    for (path, text) in [
        (&pages.markdown, md),
        (&pages.html, page),
        (
            &pages.json,
            format!("{}\n", serde_json::to_string_pretty(&summary)?),
        ),
    ] {
        crate::sim::input::files::write_file(path, text)?;
    }
    Ok(pages)
}

/// The metrics of every run as JSON (for `summary.json`).
fn metrics_json<M: SimModel<N>, const N: usize>(report: &Report<M, N>) -> Value {
    let runs: Vec<Value> = report
        .sections
        .iter()
        .flat_map(|sec| {
            sec.runs.iter().map(move |r| {
                let m = &r.metrics;
                json!({
                    "scenario": sec.name,
                    "controller": r.label,
                    "peak_yaw_deg": m.peak_yaw_rad.to_degrees(),
                    "rms_yaw_deg": m.rms_yaw_rad.to_degrees(),
                    "settle_s": m.settle_s,
                    "peak_sw_deg": m.peak_sw_rad.to_degrees(),
                    "rms_current_a": m.rms_current_a,
                    "peak_current_a": m.peak_current_a,
                    "energy_j": m.energy_j,
                    "chatter_a": m.chatter_a,
                    "rms_force_n": m.rms_force_n,
                    "shimmy_s": m.shimmy_s,
                    "amp_end_deg": m.amp_end_rad.to_degrees(),
                    "amp_max_deg": m.amp_max_rad.to_degrees(),
                    "shimmies": m.shimmies(),
                    "sim_s": r.result.sim_s,
                    "wall_s": r.result.wall_s,
                })
            })
        })
        .collect();
    json!({ "runs": runs })
}

/// What [`write()`] produced.
#[derive(Clone, Debug)]
pub struct Written {
    /// `report.md`.
    pub report: PathBuf,
    /// `report.html` and `summary.json`.
    pub pages: Pages,
    /// Every PNG written.
    pub plots: Vec<PathBuf>,
    /// `metrics.csv` and the trace CSVs.
    pub csv: Vec<PathBuf>,
}

/// Column headings and units of the metrics table.
const METRIC_COLUMNS: [(&str, &str); 11] = [
    ("peak yaw", "deg"),
    ("rms yaw", "deg"),
    ("2 % settling", "s"),
    ("peak steering wheel", "deg"),
    ("rms current", "A"),
    ("peak current", "A"),
    ("coil energy", "J"),
    ("TV(I)", "A"),
    ("rms force", "N"),
    ("shimmy time", "s"),
    ("shimmy at end", "-"),
];

fn metric_cells(m: &RunMetrics) -> [String; 11] {
    [
        format!("{:.3}", m.peak_yaw_rad.to_degrees()),
        format!("{:.3}", m.rms_yaw_rad.to_degrees()),
        opt(m.settle_s, 2),
        format!("{:.2}", m.peak_sw_rad.to_degrees()),
        format!("{:.3}", m.rms_current_a),
        format!("{:.3}", m.peak_current_a),
        format!("{:.2}", m.energy_j),
        format!("{:.1}", m.chatter_a),
        format!("{:.1}", m.rms_force_n),
        format!("{:.1}", m.shimmy_s),
        if m.shimmies() { "YES" } else { "no" }.into(),
    ]
}

/// The Markdown metrics table of `rows` (scenario, run).
pub fn metrics_table<M: SimModel<N>, const N: usize>(rows: &[(&str, &ReportRun<M, N>)]) -> String {
    let mut s = String::from("| scenario | controller |");
    for (h, u) in METRIC_COLUMNS {
        let _ = write!(s, " {h} [{u}] |");
    }
    s.push_str("\n|---|---|");
    s.push_str(&"---|".repeat(METRIC_COLUMNS.len()));
    s.push('\n');
    for (sc, r) in rows {
        let _ = write!(s, "| {sc} | {} |", r.label);
        for c in metric_cells(&r.metrics) {
            let _ = write!(s, " {c} |");
        }
        s.push('\n');
    }
    s
}

fn write_metrics_csv<M: SimModel<N>, const N: usize>(
    path: &Path,
    report: &Report<M, N>,
) -> Result<()> {
    let mut s = format!(
        "scenario,controller,{},shimmies,sim_s,wall_s\n",
        RunMetrics::CSV_HEADER
    );
    for sec in &report.sections {
        for r in &sec.runs {
            let _ = writeln!(
                s,
                "{},{},{},{},{},{}",
                sec.name,
                r.label,
                r.metrics.csv_fields(),
                r.metrics.shimmies(),
                r.result.sim_s,
                r.result.wall_s
            );
        }
    }
    crate::sim::input::files::write_file(path, s)
}

/// Writes the report into the output folder `out`, claimed by the caller for its run.
pub fn write<M: SimModel<N>, const N: usize>(
    out: &crate::sim::input::files::OutDir,
    report: &Report<M, N>,
) -> Result<Written> {
    let out = out.path();
    let mut plots = Vec::new();
    let mut csv = Vec::new();
    let mut md = String::new();
    let _ = writeln!(md, "# {}\n", report.title);
    let _ = writeln!(md, "{}\n", report.intro.trim_end());
    let _ = writeln!(md, "## Metrics\n");
    let rows: Vec<(&str, &ReportRun<M, N>)> = report
        .sections
        .iter()
        .flat_map(|s| s.runs.iter().map(move |r| (s.name.as_str(), r)))
        .collect();
    let _ = writeln!(md, "{}", metrics_table(&rows));
    let _ = writeln!(
        md,
        "Peak/rms yaw: left wheel psi_L; 2 % settling: after the disturbance, about the final value; \
         TV(I): total variation of the current command (chattering); shimmy time: total length of \
         0.5 s blocks whose 2 Hz high-passed psi_L amplitude exceeds 0.5 deg; shimmy at end: above \
         0.5 deg in the last 0.5 s or for 3 s or longer. All runs also in `metrics.csv`.\n"
    );
    let metrics_csv = out.join("metrics.csv");
    write_metrics_csv(&metrics_csv, report)?;
    csv.push(metrics_csv);
    for sec in &report.sections {
        let slug = sanitize(&sec.name);
        let _ = writeln!(md, "## {}\n", sec.name);
        let _ = writeln!(md, "{}\n", sec.description.trim_end());
        let runs: Vec<(&str, &LoopResult)> = sec
            .runs
            .iter()
            .map(|r| (r.label.as_str(), &r.result))
            .collect();
        let time_png = format!("{slug}-time.png");
        plot_runs(&out.join(&time_png), &sec.name, &runs)?;
        plots.push(out.join(&time_png));
        let _ = writeln!(
            md,
            "Wheel yaw, coil current and switching gain:\n\n![{} time histories]({time_png})\n",
            sec.name
        );
        let with_meter: Vec<(&str, &LoopConfig<M, N>, &LoopResult)> = sec
            .runs
            .iter()
            .filter(|r| r.result.meter.iter().any(|m| m.valid))
            .map(|r| (r.label.as_str(), &r.cfg, &r.result))
            .collect();
        if !with_meter.is_empty() {
            let margin_png = format!("{slug}-margin.png");
            plot_margin(&out.join(&margin_png), &sec.name, &with_meter)?;
            plots.push(out.join(&margin_png));
            let _ = writeln!(
                md,
                "Mode meter (data) vs the reference line, the {REFERENCE_LABEL}:\n\n![{} margin]({margin_png})\n",
                sec.name
            );
        }
        for (caption, file) in &sec.extra_plots {
            plots.push(out.join(file));
            let _ = writeln!(md, "{caption}\n\n![{caption}]({file})\n");
        }
        let mut traces = Vec::new();
        for r in &sec.runs {
            let f = format!("{slug}_{}.csv", sanitize(&r.label));
            r.result
                .write_trace_csv(&out.join(&f))
                .with_context(|| format!("writing {f}"))?;
            csv.push(out.join(&f));
            traces.push(format!("[{}]({f})", r.label));
        }
        let _ = writeln!(
            md,
            "Traces (CSV, units in the column names): {}\n",
            traces.join(", ")
        );
    }
    let sim: f64 = rows.iter().map(|(_, r)| r.result.sim_s).sum();
    let wall: f64 = rows.iter().map(|(_, r)| r.result.wall_s).sum();
    let _ = writeln!(
        md,
        "Run time: {sim:.1} s simulated in {wall:.2} s of summed run wall time ({:.0} simulated s per wall s per core).\n",
        sim / wall.max(1e-9)
    );
    let provenance = report
        .provenance
        .clone()
        .unwrap_or_else(Provenance::of_this_process);
    let pages = write_pages(out, &report.title, &md, &provenance, metrics_json(report))?;
    Ok(Written {
        report: pages.markdown.clone(),
        pages,
        plots,
        csv,
    })
}
