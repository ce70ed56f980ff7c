//! `shimmy-sim vehicles`: one table of every vehicle model of the family at its named parameter
//! sets (docs/simulator.md, "Every vehicle model"): degrees of freedom, the Hopf window(s) of straight
//! running without damper, the shimmy frequency at the onset, the limit cycle the nonlinear plant
//! settles on inside the first window, and the margin estimator's warning lead on a speed ramp
//! through the onset.
//!
//! Each figure is computed here from the model: the windows by the scan and Brent refinement of
//! `stability::hopf_crossings` (the same as `shimmy-sim stability`), the limit cycle by a run of
//! the model's nonlinear plant (`open_loop::run_speed`, as `shimmy-sim bifurcation`), the lead
//! by the open-loop margin run (`margin_run`, as `shimmy-sim margin`) with the pipeline's model
//! equal to the plant.

use anyhow::{Context, Result};
use clap::Args;
use rayon::prelude::*;
use shimmy_core::model::{LinearModel, ModeShape};
use shimmy_core::stability::{self, CrossingKind};
use shimmy_core::units::{kmh_to_mps, mps_to_kmh};
use shimmy_core::vehicle::Vehicle;
use std::path::PathBuf;

use crate::model::family::{FamilyVehicle, SimModel};
use crate::model::registry::{self, ModelVisitor, Registered};
use crate::sim::input::arg_range;
use crate::sim::input::vehicle_file::{self, ModelVehicle};
use crate::sim::run::margin_run::{run, MarginScenario};
use crate::sim::run::open_loop::{run_speed, DamperSetting, Trend};

/// The named sets of the table by default: one or more per model of the family.
pub const DEFAULT_SETS: &str =
    "nominal,hard,truck-full,truck-empty,dual-axle,dual-axle-frictionless,trailer,towed-wheel";

/// Speed range of the crossing scan, km/h.
const SCAN_KMH: (f64, f64) = (1.0, 150.0);
/// Initial in-phase wheel yaw of the limit-cycle run, deg.
const LC_START_DEG: f64 = 0.5;
/// Speed change of the ramp past the onset, km/h.
const RAMP_PAST_ONSET_KMH: f64 = 3.0;
/// Ramp start as a fraction of the onset speed.
const RAMP_FROM_FRACTION: f64 = 0.6;
/// Constant-speed lead-in of the margin run (as `shimmy-sim margin`), s, for the car's meter;
/// a model whose meter is slowed `k` times (`LinearModel::meter_time_scale`) warms up `k`
/// times longer and gets `k` times this (else its first report, valid only after the warm-up,
/// lands inside the ramp: the trailer's first warning came at the warm-up's end).
const SETTLE_S: f64 = 30.0;

/// Arguments of `shimmy-sim vehicles`.
#[derive(Args, Debug, Clone)]
pub struct VehiclesArgs {
    /// Comma-separated vehicles (named sets or vehicle files), one row each.
    #[arg(long, default_value = DEFAULT_SETS, value_delimiter = ',')]
    pub vehicles: Vec<String>,
    /// Ramp rate of the lead-time run, km/h per s: 0.01 to 50.
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true, value_parser = arg_range::f64_in(arg_range::RATE_KMH_PER_S))]
    pub rate_kmh_per_s: f64,
    /// Road-noise seed of the lead-time run.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output folder (`--out`; default out/vehicles, [`Self::out_dir`]).
    #[command(flatten)]
    pub out: crate::cmd::OutArg,
}

impl VehiclesArgs {
    /// The output folder: `--out`, else out/vehicles.
    pub fn out_dir(&self) -> PathBuf {
        self.out.dir_or("out/vehicles")
    }
}

/// One row of the table.
#[derive(Clone, Debug)]
pub struct VehicleRow {
    /// The vehicle as given (a set name or a file).
    pub vehicle: String,
    /// The model's name.
    pub model: &'static str,
    /// Mechanical degrees of freedom and the state count.
    pub dof: usize,
    /// States of the linear model.
    pub states: usize,
    /// Hopf windows without damper: (onset, offset or `None` = open to the scan's end), km/h.
    pub windows: Vec<(f64, Option<f64>)>,
    /// Shimmy frequency at the first onset, Hz.
    pub onset_freq_hz: Option<f64>,
    /// The limit cycle inside the first window: speed km/h, settled peak wheel yaw deg (`None`:
    /// the run decayed).
    pub limit_cycle: Option<(f64, Option<f64>)>,
    /// First-warning lead before the plant's onset on the ramp: (km/h, s); `None`: no warning.
    pub lead: Option<(f64, f64)>,
    /// Whether the margin run was made (not for a model without a `SimModel`).
    pub lead_measured: bool,
}

/// `shimmy-sim vehicles`.
pub fn command(a: &VehiclesArgs) -> Result<()> {
    anyhow::ensure!(
        !a.vehicles.is_empty(),
        "--vehicles: give at least one vehicle"
    );
    // Every vehicle is read before any run starts: a bad one fails the command at once.
    let loaded: Vec<(String, ModelVehicle)> = a
        .vehicles
        .iter()
        .map(|s| {
            vehicle_file::load_model(s)
                .with_context(|| format!("--vehicles: `{s}`"))
                .map(|v| (s.clone(), v))
        })
        .collect::<Result<_>>()?;
    let _out_dir = crate::sim::input::files::OutDir::claim(&a.out_dir())?;
    let rows: Vec<VehicleRow> = loaded
        .par_iter()
        .map(|(name, v)| row(name, v, a).with_context(|| format!("vehicle `{name}`")))
        .collect::<Result<_>>()?;
    let (header, cells) = table(&rows, a.rate_kmh_per_s);
    let md = markdown(&header, &cells);
    let md_path = a.out_dir().join("vehicles.md");
    crate::sim::input::files::write_file(&md_path, &md)?;
    let csv = a.out_dir().join("vehicles.csv");
    crate::sim::input::files::write_file(&csv, csv_text(&header, &cells))?;
    print!("{md}");
    let md = md_path;
    println!("wrote {} and {}", md.display(), csv.display());
    Ok(())
}

/// The row of one vehicle of any model.
pub fn row(name: &str, v: &ModelVehicle, a: &VehiclesArgs) -> Result<VehicleRow> {
    struct Row<'a>(&'a str, &'a VehiclesArgs);
    impl ModelVisitor for Row<'_> {
        type Output = Result<VehicleRow>;
        fn visit<M: Registered<N>, const N: usize>(self, f: M::File) -> Self::Output {
            let v = registry::family::<M, N>(f)?;
            row_on(self.0, &v.model, &v.parts, self.1)
        }
    }
    registry::with_model(v.clone(), Row(name, a))
}

/// Duration and measuring window of a limit-cycle run for a mode at `f` Hz, s.
fn cycle_run(f_hz: f64) -> (f64, f64) {
    ((120.0 / f_hz).max(40.0), (10.0 / f_hz).max(4.0))
}

impl VehicleRow {
    /// The speed of the limit-cycle run, km/h, and the onset frequency, Hz: a quarter into the
    /// first window (into the first half of the onset speed when it is open), far enough from
    /// the onset for the cycle to settle within the run.
    fn limit_cycle_speed(&self) -> Option<(f64, f64)> {
        let (on, off) = *self.windows.first()?;
        let end = off.unwrap_or((1.5 * on).min(SCAN_KMH.1));
        Some((on + 0.25 * (end - on), self.onset_freq_hz?))
    }
}

/// The row's linear part (windows, frequency) of any linear model; no cycle, no lead.
fn linear_row<M: LinearModel<N>, const N: usize>(name: &str, linear: &M) -> Result<VehicleRow> {
    let crossings = stability::hopf_crossings(
        linear,
        0.0,
        kmh_to_mps(SCAN_KMH.0),
        kmh_to_mps(SCAN_KMH.1),
        kmh_to_mps(0.5),
        stability::DEFAULT_TOL_MPS,
    )
    .context("Hopf crossings")?;
    // Each onset opens a window of its mode (by shape); the next offset of that mode closes it.
    let mut windows: Vec<(ModeShape, f64, Option<f64>)> = Vec::new();
    let mut onset_freq_hz = None;
    for c in &crossings {
        let v = mps_to_kmh(c.speed_mps);
        match c.kind {
            CrossingKind::Onset => {
                windows.push((c.shape, v, None));
                onset_freq_hz.get_or_insert(c.freq_hz);
            }
            CrossingKind::Offset => {
                match windows
                    .iter_mut()
                    .find(|(shape, _, end)| *shape == c.shape && end.is_none())
                {
                    Some((_, _, end)) => *end = Some(v),
                    // Unstable from the scan's start: a window open at its low end.
                    None => windows.push((c.shape, SCAN_KMH.0, Some(v))),
                }
            }
        }
    }
    windows.sort_by(|a, b| a.1.total_cmp(&b.1));
    Ok(VehicleRow {
        vehicle: name.to_string(),
        model: M::NAME,
        dof: M::DOF,
        states: N,
        windows: windows.iter().map(|w| (w.1, w.2)).collect(),
        onset_freq_hz,
        limit_cycle: None,
        lead: None,
        lead_measured: false,
    })
}

/// The whole row of a model of the family: the linear part, the nonlinear plant's cycle, the
/// estimator's lead on a ramp through the onset.
fn row_on<M: SimModel<N>, const N: usize>(
    name: &str,
    model: &M,
    parts: &Vehicle,
    a: &VehiclesArgs,
) -> Result<VehicleRow> {
    let mut r = linear_row(name, &model.linear())?;
    if let Some((v_kmh, f)) = r.limit_cycle_speed() {
        let (duration_s, window_s) = cycle_run(f);
        let run = run_speed(
            model,
            DamperSetting::Off,
            kmh_to_mps(v_kmh),
            LC_START_DEG.to_radians(),
            duration_s,
            window_s,
        )
        .with_context(|| format!("limit-cycle run at {v_kmh:.1} km/h"))?;
        let amp = (run.trend != Trend::Decaying).then(|| run.amp_end_rad.to_degrees());
        r.limit_cycle = Some((v_kmh, amp));
    }
    if let Some(&(on, _)) = r.windows.first() {
        let mut sc = MarginScenario::ramp(
            *model,
            RAMP_FROM_FRACTION * on,
            on + RAMP_PAST_ONSET_KMH,
            a.rate_kmh_per_s,
            SETTLE_S * f64::from(model.linear().meter_time_scale()),
        );
        sc.seed = a.seed;
        r.lead_measured = true;
        // the family vehicle's pipeline: the mode meter slowed to the model's mode
        let pipeline = FamilyVehicle {
            model: *model,
            parts: *parts,
        }
        .pipeline_params();
        r.lead = run(&sc, pipeline, 0).context("margin run")?.lead();
    }
    Ok(r)
}

/// CSV of `header` and `rows` (cells with a comma or a quote quoted, backticks dropped).
fn csv_text(header: &[String], rows: &[Vec<String>]) -> String {
    let cell = |c: &String| {
        let c = c.replace('`', "");
        if c.contains([',', '"']) {
            format!("\"{}\"", c.replace('"', "\"\""))
        } else {
            c
        }
    };
    std::iter::once(header)
        .chain(rows.iter().map(Vec::as_slice))
        .map(|r| r.iter().map(cell).collect::<Vec<_>>().join(",") + "\n")
        .collect()
}

/// A Markdown table of `header` and `rows`.
fn markdown(header: &[String], rows: &[Vec<String>]) -> String {
    let line = |cells: &[String]| format!("| {} |\n", cells.join(" | "));
    let mut s = line(header);
    s += &format!("|{}\n", "---|".repeat(header.len()));
    for r in rows {
        s += &line(r);
    }
    s
}

/// The header and the cells of the table of `rows`.
pub fn table(rows: &[VehicleRow], rate_kmh_per_s: f64) -> (Vec<String>, Vec<Vec<String>>) {
    let header = [
        "vehicle".to_string(),
        "model".into(),
        "DOF (states)".into(),
        "Hopf window(s) [km/h]".into(),
        "f at onset [Hz]".into(),
        "limit cycle [km/h: deg]".into(),
        format!("lead at {rate_kmh_per_s} km/h/s [km/h / s]"),
    ];
    let mut t = Vec::new();
    for r in rows {
        let windows = if r.windows.is_empty() {
            format!("none in {}-{}", SCAN_KMH.0, SCAN_KMH.1)
        } else {
            r.windows
                .iter()
                .map(|(on, off)| match off {
                    Some(off) => format!("{on:.2}-{off:.2}"),
                    None => format!("{on:.2}-(>{})", SCAN_KMH.1),
                })
                .collect::<Vec<_>>()
                .join(", ")
        };
        t.push(vec![
            format!("`{}`", r.vehicle),
            r.model.to_string(),
            format!("{} ({})", r.dof, r.states),
            windows,
            r.onset_freq_hz.map_or("-".into(), |f| format!("{f:.2}")),
            match r.limit_cycle {
                Some((v, Some(a))) => format!("{v:.1}: {a:.2}"),
                Some((v, None)) => format!("{v:.1}: decays"),
                None => "-".into(),
            },
            match (r.lead, r.lead_measured) {
                (Some((dv, dt)), _) => format!("{dv:.2} / {dt:.1}"),
                (None, true) => "no warning".into(),
                (None, false) if r.windows.is_empty() => "-".into(),
                (None, false) => "not run".into(),
            },
        ]);
    }
    (header.to_vec(), t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::run::margin_run::onset_kmh;

    fn args() -> VehiclesArgs {
        VehiclesArgs {
            vehicles: vec![],
            rate_kmh_per_s: 1.0,
            seed: 1,
            out: crate::cmd::OutArg::new(PathBuf::new()),
        }
    }

    /// The car's row: its one window starts at the onset of the margin run's own scan, the
    /// nonlinear plant settles on a cycle inside it, and the estimator warns before the onset;
    /// the empty truck, stable over the whole scan, has no window, no cycle and no warning.
    #[test]
    fn rows_of_an_unstable_and_a_stable_vehicle() {
        let car = vehicle_file::load_model("nominal").unwrap();
        let r = row("nominal", &car, &args()).unwrap();
        let ModelVehicle::Car(v) = &car else {
            panic!("nominal is the car")
        };
        let onset = onset_kmh(&v.plant).unwrap();
        assert_eq!(r.windows.len(), 1, "{:?}", r.windows);
        assert!(
            (r.windows[0].0 - onset).abs() < 0.01,
            "{:?} vs {onset}",
            r.windows
        );
        let (v_lc, amp) = r.limit_cycle.unwrap();
        assert!(v_lc > r.windows[0].0 && v_lc < r.windows[0].1.unwrap());
        assert!(amp.is_some_and(|a| a > 0.5 && a < 45.0), "{amp:?}");
        assert!(r.lead.is_some_and(|(dv, _)| dv > 0.0), "{:?}", r.lead);

        let empty = vehicle_file::load_model("truck-empty").unwrap();
        let r = row("truck-empty", &empty, &args()).unwrap();
        assert!(r.windows.is_empty() && r.limit_cycle.is_none() && r.lead.is_none());
        assert_eq!((r.dof, r.states), (5, 12));
    }

    /// A bad vehicle fails the command before any run, naming it.
    #[test]
    fn a_bad_vehicle_is_named() {
        let mut a = args();
        a.vehicles = vec!["nominal".into(), "no-such-set".into()];
        a.out = crate::cmd::OutArg::new(std::env::temp_dir().join("shimmy-vehicles-bad"));
        let e = format!("{:#}", command(&a).unwrap_err());
        assert!(e.contains("`no-such-set`"), "{e}");
        assert!(!a.out_dir().exists());
    }
}
