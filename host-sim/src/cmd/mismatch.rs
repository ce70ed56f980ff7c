//! `shimmy-sim mismatch`: does the warning survive a model that is wrong? (issue 14)
//!
//! The pipeline's model is the `--vehicle` (nominal by default); the simulated plant differs: on
//! the car each of C_a, sigma, K_d, e, t_p and the load -20 % and +20 % (the load scales F_z and
//! C_a together: a constant cornering coefficient C_a / F_z), and the `hard` and `gentle` sets;
//! on the mining truck each of C_a/F_z, sigma, I_k, c_h, k_h, e, t_p and the payload
//! (`StudyModel::single_variants`). Per case, open loop with
//! the damper off, 5 N m road noise and 2 N m imbalance (`margin_run::run`):
//!
//! - ramps at 1, 2 and 4 km/h per s from 0.6 x the plant's true onset (30 s settle there) to
//!   3 km/h past it: the first warning's lead over the true onset (an independent eigenvalue
//!   scan of the plant, `margin_run::onset_kmh`) in km/h and s, and where the consistency flag first
//!   drops;
//! - the same 1 km/h/s ramp through the data-only arm (no model margin);
//! - a constant drive at 70 % of the true onset (default 10 minutes), full pipeline and
//!   data-only: warning onsets, as false warnings per hour.
//!
//! Targets: lead >= 3 km/h at 1 km/h/s in every single-parameter case, no false warning in any
//! case. Where the plant's onset is so low that 70 % of it lies inside the warning band (the
//! monitor's `MarginLow` conditions hold for the true margin or damping: `hard`), a warning
//! there is due, not false, and the target is that the drive shows it ([`DUE_WARNED_MIN`]). Writes `mismatch.md` (with the provenance), `mismatch.csv` and `summary.json` (the
//! same figures and the provenance, for scripts); exits non-zero when a target is missed.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::Args;
use rayon::prelude::*;
use shimmy_core::estimator::monitor::Level;
use shimmy_core::estimator::pipeline::PipelineParams;
use shimmy_core::model::LinearModel;
use shimmy_core::vehicles::car::PlantParams;
use shimmy_core::vehicles::truck::TruckParams;

use crate::model::family::FamilyVehicle;
use crate::model::study::StudyModel;
use crate::out::progress;
use crate::out::provenance::Provenance;
use crate::out::table::opt;
use crate::sim::arg_range::{self, Range};
use crate::sim::margin_run::{onset_kmh, run, MarginRun, MarginScenario};
use crate::sim::vehicle_file::{self, ModelVehicle};

/// Required warning lead at 1 km/h/s in the single-parameter cases, km/h.
pub const MIN_LEAD_KMH: f64 = 3.0;
/// Constant-drive duration: 10 to 3600 s.
pub const DRIVE_S: Range = Range::closed(10.0, 3600.0, "s");
/// Ramp rate: 0.1 to 10 km/h per s.
pub const RATE: Range = Range::closed(0.1, 10.0, "km/h/s");
/// Settle time at the ramp's start speed, s.
pub const SETTLE_S: f64 = 30.0;
/// The ramp starts at this fraction of the true onset (at least 3 km/h).
pub const RAMP_START_FRACTION: f64 = 0.6;
/// The constant drive runs at this fraction of the true onset.
pub const DRIVE_FRACTION: f64 = 0.7;
/// Where the truth at the drive calls for a warning, the full pipeline must show one for at
/// least this fraction of it (the meter's warm-up is ~2 % of a 10-minute drive).
pub const DUE_WARNED_MIN: f64 = 0.9;

/// Arguments of `shimmy-sim mismatch`.
#[derive(Args, Debug, Clone)]
pub struct MismatchArgs {
    /// The vehicle the firmware believes (the pipeline's model and thresholds), and the base
    /// the plants are varied from: a named set or a vehicle file (docs/vehicle-file.md).
    #[arg(long, visible_alias = "model-vehicle", default_value = "nominal")]
    pub vehicle: String,
    /// Ramp rates, km/h per s, each 0.1 to 10 (the first one is also used by the data-only arm).
    #[arg(long, value_delimiter = ',', default_value = "1,2,4", value_parser = arg_range::f64_in(RATE))]
    pub rates_kmh_per_s: Vec<f64>,
    /// Constant drive at 70 % of the true onset, s: 10 to 3600.
    #[arg(long, default_value_t = 600.0, value_parser = arg_range::f64_in(DRIVE_S))]
    pub drive_s: f64,
    /// Only the cases whose name contains this text (e.g. `C_a`).
    #[arg(long)]
    pub only: Option<String>,
    /// Road-noise seed of every run (another seed: a check that nothing is tuned to the
    /// default one).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Output directory (mismatch.md, mismatch.csv, summary.json).
    #[arg(long, default_value = "out/mismatch")]
    pub out: PathBuf,
}

/// One plant/model pair of the vehicle model `M` (the car by default).
#[derive(Clone, Debug)]
pub struct MismatchCase<M = PlantParams> {
    /// Name, e.g. `C_a +20 %`.
    pub name: String,
    /// The simulated plant.
    pub plant: M,
    /// The pipeline's model.
    pub model: M,
    /// A single parameter off by +-20 % (the lead target applies).
    pub single_parameter: bool,
}

/// The study's cases for the model `model`: the plant equal to the model, the
/// single-parameter +-20 % plants ([`StudyModel::single_variants`]), and the model's other
/// plants (the car: the `hard` and `gentle` sets); the pipeline's model is always `model`.
pub fn cases<M: StudyModel<N>, const N: usize>(model: &M) -> Result<Vec<MismatchCase<M>>> {
    let nom = *model;
    let mut v = vec![MismatchCase {
        name: "plant = model".into(),
        plant: nom,
        model: nom,
        single_parameter: false,
    }];
    let (lower, upper) = (nom.single_variants(0.8)?, nom.single_variants(1.2)?);
    for (lo, hi) in lower.into_iter().zip(upper) {
        for (pct, (name, plant)) in [(-20.0, lo), (20.0, hi)] {
            v.push(MismatchCase {
                name: format!("{name} {pct:+.0} %"),
                plant,
                model: nom,
                single_parameter: true,
            });
        }
    }
    for (name, plant) in M::other_plants() {
        v.push(MismatchCase {
            name,
            plant,
            model: nom,
            single_parameter: false,
        });
    }
    Ok(v)
}

/// One ramp through the onset.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RampResult {
    /// Ramp rate, km/h per s.
    pub rate_kmh_per_s: f64,
    /// First-warning lead over the true onset, km/h (None: no warning).
    pub lead_kmh: Option<f64>,
    /// The same in s.
    pub lead_s: Option<f64>,
    /// Speed at which the consistency flag first dropped, km/h.
    pub inconsistent_kmh: Option<f64>,
}

/// Results of one case.
#[derive(Clone, Debug)]
pub struct CaseResult<M = PlantParams> {
    /// The case.
    pub case: MismatchCase<M>,
    /// True linear onset of the plant, km/h.
    pub plant_onset_kmh: Option<f64>,
    /// The model's onset, km/h.
    pub model_onset_kmh: Option<f64>,
    /// One per ramp rate.
    pub ramps: Vec<RampResult>,
    /// Data-only arm at the first rate: (lead km/h, lead s).
    pub data_only_lead: (Option<f64>, Option<f64>),
    /// Speed of the constant drive, km/h.
    pub drive_kmh: f64,
    /// Warning onsets per hour in the constant drive, full pipeline.
    pub false_per_h: f64,
    /// The same, data-only arm.
    pub data_only_false_per_h: f64,
    /// The plant's true speed margin at the drive, km/h (its onset minus the drive speed).
    pub drive_margin_true_kmh: f64,
    /// The truth at the drive calls for a warning: the monitor's `MarginLow` conditions hold
    /// for the plant's true margin or damping (a plant whose onset is low, `hard`: 70 % of
    /// 7.63 km/h is 2.29 km/h from it, inside the 1.4 m/s band). Its warnings are then due,
    /// not false, and [`Self::warned_fraction`] says how much of the drive they covered.
    pub warning_due: bool,
    /// Fraction of the drive with a warning shown: (full pipeline, data-only).
    pub warned_fraction: (f64, f64),
}

impl<M> CaseResult<M> {
    /// Lead at the first (slowest) ramp rate, km/h.
    pub fn lead_kmh(&self) -> Option<f64> {
        self.ramps.first().and_then(|r| r.lead_kmh)
    }

    /// The case meets its targets: no false warning (or, where one is due at the drive, a
    /// warning for at least [`DUE_WARNED_MIN`] of it); single-parameter cases with an onset
    /// also lead by at least [`MIN_LEAD_KMH`].
    pub fn passes(&self) -> bool {
        let lead_ok = !self.case.single_parameter
            || self.plant_onset_kmh.is_none()
            || self.lead_kmh().is_some_and(|l| l >= MIN_LEAD_KMH);
        let drive_ok = if self.warning_due {
            self.warned_fraction.0 >= DUE_WARNED_MIN
        } else {
            self.false_per_h == 0.0
        };
        lead_ok && drive_ok
    }

    /// The drive's warning column: onsets per hour, or how much of the drive warned when a
    /// warning is due there.
    fn drive_cell(&self) -> String {
        if self.warning_due {
            format!(
                "due (true margin {:.2} km/h): warned {:.0} % / {:.0} % of it",
                self.drive_margin_true_kmh,
                100.0 * self.warned_fraction.0,
                100.0 * self.warned_fraction.1
            )
        } else {
            format!(
                "{:.0} / {:.0}",
                self.false_per_h, self.data_only_false_per_h
            )
        }
    }
}

fn ramp_lead(r: &MarginRun) -> (Option<f64>, Option<f64>) {
    r.lead().map_or((None, None), |(a, b)| (Some(a), Some(b)))
}

/// One ramp through the onset (or to 3 km/h past the model's onset when the plant has none).
pub fn ramp_scenario<M: StudyModel<N>, const N: usize>(
    case: &MismatchCase<M>,
    rate: f64,
    data_only: bool,
    onset_kmh: f64,
) -> MarginScenario<M, N> {
    let start = (RAMP_START_FRACTION * onset_kmh).max(3.0);
    let mut sc = MarginScenario::ramp(case.plant, start, onset_kmh + 3.0, rate, SETTLE_S);
    sc.model = (!data_only).then_some(case.model);
    sc
}

/// The constant drive at [`DRIVE_FRACTION`] of the onset.
pub fn drive_scenario<M: StudyModel<N>, const N: usize>(
    case: &MismatchCase<M>,
    data_only: bool,
    onset_kmh: f64,
    drive_s: f64,
) -> MarginScenario<M, N> {
    let mut sc = MarginScenario::constant(case.plant, DRIVE_FRACTION * onset_kmh, drive_s);
    sc.model = (!data_only).then_some(case.model);
    sc
}

/// Runs one case: every ramp, the data-only ramp and both constant drives. Without a plant
/// onset the model's onset sets the speeds (every warning is then a false one).
pub fn run_case<M: StudyModel<N>, const N: usize>(
    case: &MismatchCase<M>,
    rates: &[f64],
    drive_s: f64,
    pp: PipelineParams,
    seed: u64,
) -> Result<CaseResult<M>> {
    let plant_on = onset_kmh(&case.plant.linear());
    let model_on = onset_kmh(&case.model.linear());
    let reference = plant_on
        .or(model_on)
        .context("neither plant nor model has an onset")?;
    let seeded = |mut sc: MarginScenario<M, N>| {
        sc.seed = seed;
        sc
    };
    let mut ramps = Vec::new();
    for &rate in rates {
        let r = run(&seeded(ramp_scenario(case, rate, false, reference)), pp, 0)?;
        let (lead_kmh, lead_s) = ramp_lead(&r);
        ramps.push(RampResult {
            rate_kmh_per_s: rate,
            lead_kmh,
            lead_s,
            inconsistent_kmh: r.first_inconsistent.map(|x| x.1),
        });
    }
    let rate0 = rates.first().copied().unwrap_or(1.0);
    let d = run(&seeded(ramp_scenario(case, rate0, true, reference)), pp, 0)?;
    let per_h = |r: &MarginRun| f64::from(r.warnings) * 3600.0 / drive_s;
    let full = run(
        &seeded(drive_scenario(case, false, reference, drive_s)),
        pp,
        0,
    )?;
    let data = run(
        &seeded(drive_scenario(case, true, reference, drive_s)),
        pp,
        0,
    )?;
    let truth = full
        .rows
        .first()
        .map_or((f64::NAN, f64::NAN), |r| (r.margin_true_kmh, r.zeta_true));
    let mon = &pp.monitor;
    let warning_due =
        truth.0 < f64::from(mon.dv_low_on_mps) * 3.6 || truth.1 < f64::from(mon.zeta_low_on);
    let warned = |r: &MarginRun| {
        let n = r.rows.iter().filter(|x| x.level > Level::Normal).count();
        n as f64 / r.rows.len().max(1) as f64
    };
    Ok(CaseResult {
        case: case.clone(),
        plant_onset_kmh: plant_on,
        model_onset_kmh: model_on,
        ramps,
        data_only_lead: ramp_lead(&d),
        drive_kmh: DRIVE_FRACTION * reference,
        false_per_h: per_h(&full),
        data_only_false_per_h: per_h(&data),
        drive_margin_true_kmh: truth.0,
        warning_due,
        warned_fraction: (warned(&full), warned(&data)),
    })
}

/// The Markdown table.
pub fn markdown<M>(rows: &[CaseResult<M>], rates: &[f64]) -> String {
    let mut s = String::from("| plant | true onset [km/h] |");
    for r in rates {
        s += &format!(" lead at {r} km/h/s [km/h / s] |");
    }
    s += " flag drops at [km/h] | data-only lead [km/h / s] | drive [km/h] | false warnings/h (full / data-only) | target |\n|---|---|";
    for _ in rates {
        s += "---|";
    }
    s += "---|---|---|---|---|\n";
    for r in rows {
        s += &format!("| {} | {} |", r.case.name, opt(r.plant_onset_kmh, 2));
        for x in &r.ramps {
            s += &format!(" {} / {} |", opt(x.lead_kmh, 2), opt(x.lead_s, 1));
        }
        s += &format!(
            " {} | {} / {} | {:.1} | {} | {} |\n",
            opt(r.ramps.first().and_then(|x| x.inconsistent_kmh), 1),
            opt(r.data_only_lead.0, 2),
            opt(r.data_only_lead.1, 1),
            r.drive_kmh,
            r.drive_cell(),
            if r.passes() { "met" } else { "MISSED" }
        );
    }
    s
}

/// Every case's figures and the provenance, as `summary.json` holds them (`null` where a
/// figure is absent).
pub fn summary_json<M>(rows: &[CaseResult<M>], provenance: &Provenance) -> serde_json::Value {
    let cases: Vec<serde_json::Value> = rows
        .iter()
        .map(|r| {
            serde_json::json!({
                "case": r.case.name,
                "plant_onset_kmh": r.plant_onset_kmh,
                "model_onset_kmh": r.model_onset_kmh,
                "ramps": r.ramps.iter().map(|x| serde_json::json!({
                    "rate_kmh_per_s": x.rate_kmh_per_s,
                    "lead_kmh": x.lead_kmh,
                    "lead_s": x.lead_s,
                    "first_inconsistent_kmh": x.inconsistent_kmh,
                })).collect::<Vec<_>>(),
                "data_only_lead_kmh": r.data_only_lead.0,
                "data_only_lead_s": r.data_only_lead.1,
                "drive_kmh": r.drive_kmh,
                "false_warnings_per_h": r.false_per_h,
                "data_only_false_warnings_per_h": r.data_only_false_per_h,
                "drive_margin_true_kmh": r.drive_margin_true_kmh,
                "warning_due": r.warning_due,
                "drive_warned_fraction": r.warned_fraction.0,
                "data_only_drive_warned_fraction": r.warned_fraction.1,
                "passes": r.passes(),
            })
        })
        .collect();
    serde_json::json!({"provenance": provenance.json(), "cases": cases})
}

/// `shimmy-sim mismatch`.
pub fn command(a: &MismatchArgs) -> Result<()> {
    DRIVE_S.check("--drive-s", a.drive_s)?;
    arg_range::ensure_count("--rates-kmh-per-s", a.rates_kmh_per_s.len(), 8)?;
    for &r in &a.rates_kmh_per_s {
        RATE.check("--rates-kmh-per-s", r)?;
    }
    let vehicle = vehicle_file::load_model(&a.vehicle)?;
    let provenance = Provenance::of_this_process()
        .model_vehicle("model vehicle", &a.vehicle, &vehicle)?
        .seed("road noise", a.seed);
    match vehicle {
        ModelVehicle::Car(v) => command_on(a, &FamilyVehicle::car(v), provenance),
        ModelVehicle::Truck(v) => command_on(a, &v, provenance),
        other => bail!(
            "`mismatch` runs the {} and {} models, not the {} (vehicle `{}`)",
            PlantParams::NAME,
            TruckParams::NAME,
            other.model_name(),
            a.vehicle
        ),
    }
}

/// The study on the model vehicle `vehicle` (its model and its pipeline's thresholds).
fn command_on<M: StudyModel<N>, const N: usize>(
    a: &MismatchArgs,
    vehicle: &FamilyVehicle<M>,
    provenance: Provenance,
) -> Result<()> {
    let all = cases(&vehicle.model)?;
    let chosen: Vec<MismatchCase<M>> = all
        .iter()
        .filter(|c| a.only.as_ref().is_none_or(|o| c.name.contains(o.as_str())))
        .cloned()
        .collect();
    if chosen.is_empty() {
        let names: Vec<&str> = all.iter().map(|c| c.name.as_str()).collect();
        bail!("--only matches no case; cases: {}", names.join(", "));
    }
    let wall = std::time::Instant::now();
    let pp = vehicle.pipeline_params();
    let bar = progress::bar(chosen.len(), "mismatch cases");
    let rows: Vec<CaseResult<M>> = chosen
        .par_iter()
        .map(|c| {
            let r = run_case(c, &a.rates_kmh_per_s, a.drive_s, pp, a.seed);
            bar.inc(1);
            r
        })
        .collect::<Result<_>>()?;
    bar.finish_and_clear();
    let md = markdown(&rows, &a.rates_kmh_per_s);
    println!(
        "plant vs model mismatch (model `{}`; open loop, damper off, 5 N m road noise (seed {}), 2 N m imbalance; drive {:.0} s at 70 % of the true onset), {:.0} s wall",
        a.vehicle,
        a.seed,
        a.drive_s,
        wall.elapsed().as_secs_f64()
    );
    print!("{md}");
    std::fs::create_dir_all(&a.out).with_context(|| format!("creating {:?}", a.out))?;
    std::fs::write(
        a.out.join("mismatch.md"),
        format!("{}\n\n{}", md.trim_end(), provenance.markdown()),
    )?;
    std::fs::write(
        a.out.join("summary.json"),
        serde_json::to_string_pretty(&summary_json(&rows, &provenance))? + "\n",
    )?;
    let mut f = std::fs::File::create(a.out.join("mismatch.csv"))?;
    writeln!(f, "case,plant_onset_kmh,model_onset_kmh,rate_kmh_per_s,lead_kmh,lead_s,first_inconsistent_kmh,data_only_lead_kmh,data_only_lead_s,drive_kmh,false_warnings_per_h,data_only_false_warnings_per_h,drive_margin_true_kmh,warning_due,drive_warned_fraction,data_only_drive_warned_fraction,passes")?;
    let o = |v: Option<f64>| v.map_or(String::new(), |x| format!("{x:.3}"));
    for r in &rows {
        for x in &r.ramps {
            writeln!(
                f,
                "\"{}\",{},{},{},{},{},{},{},{},{:.3},{:.1},{:.1},{:.3},{},{:.4},{:.4},{}",
                r.case.name,
                o(r.plant_onset_kmh),
                o(r.model_onset_kmh),
                x.rate_kmh_per_s,
                o(x.lead_kmh),
                o(x.lead_s),
                o(x.inconsistent_kmh),
                o(r.data_only_lead.0),
                o(r.data_only_lead.1),
                r.drive_kmh,
                r.false_per_h,
                r.data_only_false_per_h,
                r.drive_margin_true_kmh,
                r.warning_due,
                r.warned_fraction.0,
                r.warned_fraction.1,
                r.passes()
            )?;
        }
    }
    let missed: Vec<&str> = rows
        .iter()
        .filter(|r| !r.passes())
        .map(|r| r.case.name.as_str())
        .collect();
    if !missed.is_empty() {
        bail!(
            "targets missed (lead >= {MIN_LEAD_KMH} km/h in single-parameter cases, no false warning, a due warning shown): {}",
            missed.join(", ")
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(case: MismatchCase<PlantParams>) -> CaseResult<PlantParams> {
        CaseResult {
            plant_onset_kmh: Some(30.0),
            model_onset_kmh: Some(29.0),
            ramps: vec![RampResult {
                rate_kmh_per_s: 1.0,
                lead_kmh: Some(4.0),
                lead_s: Some(4.0),
                inconsistent_kmh: None,
            }],
            data_only_lead: (Some(1.0), None),
            drive_kmh: 21.0,
            false_per_h: 0.0,
            data_only_false_per_h: 6.0,
            drive_margin_true_kmh: 9.0,
            warning_due: false,
            warned_fraction: (0.0, 0.01),
            case,
        }
    }

    /// A warning in the drive fails the case where none is due; where one is due (the truth
    /// inside the warning band) the case needs it for most of the drive instead.
    #[test]
    fn a_warning_is_false_only_where_none_is_due() {
        let nominal = shimmy_core::vehicle::Vehicle::nominal();
        let mut r = row(cases(&nominal.plant).unwrap().remove(0));
        assert!(r.passes());
        r.false_per_h = 6.0;
        assert!(!r.passes(), "a false warning");
        r.warning_due = true;
        r.warned_fraction.0 = 0.05;
        assert!(!r.passes(), "a due warning shown 5 % of the drive");
        r.warned_fraction.0 = 0.95;
        assert!(r.passes());
        assert!(r.drive_cell().starts_with("due"), "{}", r.drive_cell());
    }

    #[test]
    fn summary_has_every_case_and_the_provenance() {
        let nominal = shimmy_core::vehicle::Vehicle::nominal();
        let row = row(cases(&nominal.plant).unwrap().remove(0));
        let provenance = Provenance::new(["shimmy-sim", "mismatch"].map(String::from))
            .vehicle("model vehicle", "nominal", &nominal)
            .unwrap()
            .seed("road noise", 3);
        let json = summary_json(std::slice::from_ref(&row), &provenance);
        assert_eq!(json["provenance"]["command_line"], "shimmy-sim mismatch");
        assert_eq!(json["provenance"]["seeds"][0]["seed"], 3);
        assert_eq!(
            json["provenance"]["inputs"][0]["role"],
            "model vehicle record"
        );
        let c = &json["cases"][0];
        assert_eq!(c["case"], row.case.name.as_str());
        assert_eq!(c["ramps"][0]["lead_kmh"], 4.0);
        assert!(c["ramps"][0]["first_inconsistent_kmh"].is_null());
        assert!(c["data_only_lead_s"].is_null());
        assert_eq!(c["passes"], row.passes());
    }
}
