//! `shimmy-sim analyze LOG.csv`: the board's mode meter, fusion and monitor on a measured log
//! ([`crate::sim::analyze`]; columns, units and rate from options or a mapping file,
//! [`crate::sim::input::log_file`]). Writes `analysis.csv`, `events.csv`, `analysis.png`,
//! `report.md`, `report.html` and `summary.json` (with provenance) into `--out`. A bad log or
//! option stops it before anything is written, with a message naming the line and column (or
//! the option) and a non-zero exit status.

use crate::out::analysis;
use crate::out::file_name::sanitize;
use crate::out::progress;
use crate::out::provenance::Provenance;
use crate::out::report::write_pages;
use crate::sim::analyze::{analyze_with_progress, level_name, AnalyzeOptions, MAX_GAP_RANGE_S};
use crate::sim::input::arg_range::{self, Range};
use crate::sim::input::log_file::{self, MappingChanges};
use crate::sim::input::vehicle_file;
use anyhow::{bail, Context, Result};
use clap::Args;
use std::path::{Path, PathBuf};

/// Allowed `--max-gap-ms`.
pub const MAX_GAP_MS: Range = Range::closed(MAX_GAP_RANGE_S.0 * 1e3, MAX_GAP_RANGE_S.1 * 1e3, "ms");

/// Options of `shimmy-sim analyze`.
#[derive(Args, Debug, Clone)]
pub struct AnalyzeArgs {
    /// The log (CSV with a header line; `#` lines are comments). Default columns: those of a
    /// `shimmy-sim run` trace (t_s, psi_l_meas_rad, psi_r_meas_rad, speed_meas_mps).
    pub log: PathBuf,
    /// Mapping file (TOML: `delimiter`, `[time]`, `[yaw]`, `[speed]`; see `sim::log_file`); the
    /// options below override it.
    #[arg(long)]
    pub mapping: Option<PathBuf>,
    /// Field separator: "," ";" or "\t".
    #[arg(long)]
    pub delimiter: Option<String>,
    /// Time column.
    #[arg(long)]
    pub time_column: Option<String>,
    /// Unit of the time column: s, ms, us.
    #[arg(long)]
    pub time_unit: Option<String>,
    /// No time column: the rows are equally spaced at this rate, Hz (1 to 100000).
    #[arg(long)]
    pub rate_hz: Option<f64>,
    /// One yaw signal for both wheels (a wheel yaw or a steering angle; needs --yaw-gain).
    #[arg(long)]
    pub yaw_column: Option<String>,
    /// Left wheel yaw column (with --yaw-right).
    #[arg(long)]
    pub yaw_left: Option<String>,
    /// Right wheel yaw column (with --yaw-left).
    #[arg(long)]
    pub yaw_right: Option<String>,
    /// Unit of the yaw column(s): rad, mrad, deg.
    #[arg(long)]
    pub yaw_unit: Option<String>,
    /// Wheel yaw per unit of the signal (1 / steering ratio for a steering-wheel angle);
    /// |gain| 1e-4 to 1e4.
    #[arg(long, allow_negative_numbers = true)]
    pub yaw_gain: Option<f64>,
    /// Speed column.
    #[arg(long)]
    pub speed_column: Option<String>,
    /// Unit of the speed column: m/s, km/h, mph.
    #[arg(long)]
    pub speed_unit: Option<String>,
    /// The vehicle (`--vehicle`, a named set or a vehicle file).
    #[command(flatten)]
    pub vehicle: crate::cmd::VehicleArg,
    /// Data only: no model margin (the fusion then has the data alone).
    #[arg(long)]
    pub data_only: bool,
    /// Log rows further apart than this are not interpolated (the samples between are
    /// missing, as on the board), ms: 1 to 10000.
    #[arg(long, default_value_t = 20.0, allow_negative_numbers = true, value_parser = arg_range::f64_in(MAX_GAP_MS))]
    pub max_gap_ms: f64,
    /// Output folder (`--out`; default: `out/analyze/<log file name>`).
    #[command(flatten)]
    pub out: crate::cmd::OutArg,
}

impl AnalyzeArgs {
    /// The mapping options as changes on top of the mapping file's.
    fn changes(&self) -> MappingChanges {
        MappingChanges {
            delimiter: self.delimiter.clone(),
            time_column: self.time_column.clone(),
            time_unit: self.time_unit.clone(),
            rate_hz: self.rate_hz,
            yaw_column: self.yaw_column.clone(),
            yaw_left: self.yaw_left.clone(),
            yaw_right: self.yaw_right.clone(),
            yaw_unit: self.yaw_unit.clone(),
            yaw_gain: self.yaw_gain,
            speed_column: self.speed_column.clone(),
            speed_unit: self.speed_unit.clone(),
        }
    }
}

fn default_out(log: &Path) -> PathBuf {
    let stem = log
        .file_stem()
        .map_or("log".into(), |s| s.to_string_lossy().to_string());
    PathBuf::from("out/analyze").join(sanitize(&stem))
}

/// The command.
pub fn command(a: &AnalyzeArgs) -> Result<()> {
    let file = match &a.mapping {
        Some(p) => MappingChanges::load(p)?,
        None => MappingChanges::default(),
    };
    let map = file
        .then(&a.changes())
        .mapping()
        .context("log mapping (options or mapping file)")?;
    let vehicle = vehicle_file::load_model(&a.vehicle.spec).context("--vehicle")?;
    let log = log_file::load(&a.log, &map)?;
    let out = a.out.dir.clone().unwrap_or_else(|| default_out(&a.log));
    let _out_dir = crate::sim::input::files::OutDir::claim(&out)?;
    let opts = AnalyzeOptions {
        vehicle,
        model: !a.data_only,
        max_gap_s: a.max_gap_ms * 1e-3,
    };
    let bar = progress::bar(0, "samples at 1 kHz");
    let result = analyze_with_progress(&log.samples, &opts, &mut |done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })
    .with_context(|| format!("analysing {}", a.log.display()))?;
    bar.finish_and_clear();
    let mut provenance = Provenance::of_this_process()
        .file("log", &a.log)?
        .model_vehicle("vehicle", &a.vehicle.spec, &opts.vehicle)?;
    if let Some(p) = &a.mapping {
        provenance = provenance.file("mapping file", p)?;
    }

    analysis::write_rows_csv(&out.join("analysis.csv"), &result)?;
    analysis::write_events_csv(&out.join("events.csv"), &result)?;
    let source = a.log.display().to_string();
    analysis::plot_analysis(&out.join("analysis.png"), &source, &result)?;
    let title = format!("shimmy-sim analyze: {source}");
    let md = format!(
        "# {title}\n\n{}",
        analysis::markdown(&result, &source, &a.vehicle.spec, "analysis.png")
    );
    let pages = write_pages(
        &out,
        &title,
        &md,
        &provenance,
        analysis::summary_json(&result),
    )?;

    let s = result.summary();
    let st = &result.resampling;
    println!(
        "{source}: {} rows ({:.3} ms median spacing) -> {} samples at 1 kHz ({} as logged, {} interpolated, {} without yaw, {} gap(s))",
        st.log_rows,
        st.log_median_dt_s * 1e3,
        st.grid_points,
        st.exact,
        st.interpolated,
        st.missing_yaw,
        st.gaps
    );
    println!(
        "  slow damping: median {:.4} (sigma {:.4}), lowest {:.4}; frequency {:.2} Hz; valid {:.0} %",
        s.zeta_slow_median,
        s.sigma_slow_median,
        s.zeta_slow_min,
        s.freq_slow_median_hz,
        100.0 * s.valid_fraction
    );
    let not_judged = result.not_judged();
    match s.first_warning {
        _ if not_judged.is_some() => println!("  not judged: no valid damping estimate"),
        Some((t, v, l)) => println!(
            "  first warning: {} at {t:.2} s ({:.1} km/h); highest level {}; {} episode(s)",
            level_name(l),
            v * 3.6,
            level_name(s.max_level),
            s.episodes
        ),
        None => println!("  no warning"),
    }
    println!(
        "  wrote {} (and report.md, summary.json, analysis.csv, events.csv, analysis.png)",
        pages.html.display()
    );
    // Without one valid estimate "no warning" says nothing about the vehicle: a failure, so a
    // script that checks the exit code does not take an unusable log for a normal one.
    if let Some(why) = not_judged {
        bail!(
            "{source}: the log could not be judged, no damping estimate: {why}; check the \
             mapping (yaw and speed columns, units, gain); the report in {} shows what the \
             meter saw",
            out.display()
        );
    }
    Ok(())
}
