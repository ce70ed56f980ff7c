//! `shimmy-sim mismatch`: does the warning survive a model that is wrong?
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

use crate::model::registry::ReferenceModel;
use anyhow::{bail, Context, Result};
use clap::Args;
use rayon::prelude::*;
use shimmy_core::estimator::model_update::ModelUpdateConfig;
use shimmy_core::estimator::monitor::Level;
use shimmy_core::estimator::pipeline::PipelineParams;
use shimmy_core::model::UpdatableModel;

use crate::model::family::FamilyVehicle;
use crate::model::registry::image_models;
use crate::model::registry::{self, Registered, StudyVisitor};
use crate::model::study::StudyModel;
use crate::out::progress;
use crate::out::provenance::Provenance;
use crate::out::table::opt;
use crate::sim::input::arg_range::{self, Range};
use crate::sim::input::vehicle_file;
use crate::sim::run::margin_run::{onset_kmh, run, MarginRun, MarginScenario};

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

/// The vehicle the firmware believes without `--vehicle`.
pub const DEFAULT_VEHICLE: &str = "nominal";

/// Arguments of `shimmy-sim mismatch`.
// The plants are varied from the vehicle the firmware believes, so this command names that
// vehicle `--vehicle` (with `--model-vehicle` as an alias), nominal by default.
#[derive(Args, Debug, Clone)]
#[command(mut_arg("model_vehicle", |a| a
    .long("vehicle")
    .value_name("VEHICLE")
    .visible_alias("model-vehicle")
    .default_value(DEFAULT_VEHICLE)))]
pub struct MismatchArgs {
    /// The vehicle the firmware believes, and the base the plants are varied from
    /// (`--vehicle`, alias `--model-vehicle`; default [`DEFAULT_VEHICLE`]).
    #[command(flatten)]
    pub model_vehicle: crate::cmd::ModelVehicleArg,
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
    /// Road-noise seeds, a list of numbers and ranges (e.g. `1-10` or `1,4,7-9`; at most 100
    /// seeds): every case runs on each. Replaces `--seed`; with more than one seed the table
    /// summarises the runs by kind of error (every run is in mismatch.csv).
    #[arg(long, conflicts_with = "seed")]
    pub seeds: Option<String>,
    /// Run the full pipeline with the online model update (`docs/margin-estimator.md`, "Model
    /// updating"), and next to it the information-limit arm: the pipeline with the plant's own
    /// model. Targets: a warning before the onset in every run, >= 3 km/h ahead at 1 km/h/s in
    /// 95 % of the runs and within 1 km/h of the limit arm in 90 %.
    #[arg(long)]
    pub model_update: bool,
    /// Add the combined-error cases: each single parameter also at -10 % and +10 %, and pairs
    /// and triples of the parameters at 10 % and 20 % in both sign patterns.
    #[arg(long)]
    pub combined: bool,
    /// Output folder (`--out`; default out/mismatch, [`Self::out_dir`]).
    #[command(flatten)]
    pub out: crate::cmd::OutArg,
}

impl MismatchArgs {
    /// The output folder: `--out`, else out/mismatch.
    pub fn out_dir(&self) -> PathBuf {
        self.out.dir_or("out/mismatch")
    }
}

/// Most seeds one run takes.
pub const MAX_SEEDS: usize = 100;

/// Parses `--seeds`: numbers and ranges `a-b` separated by commas, ascending ranges only.
pub fn parse_seeds(text: &str) -> Result<Vec<u64>> {
    let mut out = Vec::new();
    for part in text.split(',').map(str::trim) {
        let (a, b) = match part.split_once('-') {
            Some((a, b)) => (a.trim(), b.trim()),
            None => (part, part),
        };
        let (Ok(a), Ok(b)) = (a.parse::<u64>(), b.parse::<u64>()) else {
            bail!("--seeds: `{part}` is not a seed or a range a-b of seeds (e.g. `1-10`)");
        };
        if b < a {
            bail!("--seeds: the range `{part}` is descending");
        }
        out.extend(a..=b);
        if out.len() > MAX_SEEDS {
            bail!("--seeds: more than {MAX_SEEDS} seeds; allowed: 1 to {MAX_SEEDS}");
        }
    }
    Ok(out)
}

/// One plant/model pair of the vehicle model `M` (the car by default).
#[derive(Clone, Debug)]
pub struct MismatchCase<M = ReferenceModel> {
    /// Name, e.g. `C_a +20 %`.
    pub name: String,
    /// The simulated plant.
    pub plant: M,
    /// The pipeline's model.
    pub model: M,
    /// A single parameter off by +-20 % (the lead target applies).
    pub single_parameter: bool,
    /// The kind of error, for the summary over seeds: e.g. `2 parameters, 10 %`, or `other`.
    pub group: String,
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
        group: "none".into(),
    }];
    let (lower, upper) = (nom.single_variants(0.8)?, nom.single_variants(1.2)?);
    for (lo, hi) in lower.into_iter().zip(upper) {
        for (pct, (name, plant)) in [(-20.0, lo), (20.0, hi)] {
            v.push(MismatchCase {
                name: format!("{name} {pct:+.0} %"),
                plant,
                model: nom,
                single_parameter: true,
                group: "1 parameter, 20 %".into(),
            });
        }
    }
    for (name, plant) in M::other_plants() {
        v.push(MismatchCase {
            name,
            plant,
            model: nom,
            single_parameter: false,
            group: "other".into(),
        });
    }
    Ok(v)
}

/// The combined-error cases of `--combined` for the model `model`: every single parameter
/// (group) of [`StudyModel::single_variants`] at -10 % and +10 %, every pair and every triple
/// of them at 10 % and 20 % with the signs alternating and with their opposite (`+ -` and
/// `- +`; `+ - +` and `- + -`).
pub fn combined_cases<M: StudyModel<N>, const N: usize>(model: &M) -> Result<Vec<MismatchCase<M>>> {
    let nom = *model;
    let labels: Vec<&'static str> = nom.single_variants(1.0)?.into_iter().map(|x| x.0).collect();
    let n = labels.len();
    // the plant `p` with group `i` scaled by `f`
    let scale = |p: M, i: usize, f: f64| -> Result<M> {
        p.single_variants(f)?
            .into_iter()
            .nth(i)
            .map(|x| x.1)
            .context("variant index")
    };
    let mut v = Vec::new();
    let mut push = |groups: &[usize], pct: f64, first_sign: f64| -> Result<()> {
        let mut plant = nom;
        let mut name = Vec::new();
        for (k, &g) in groups.iter().enumerate() {
            let sign = if k % 2 == 0 { first_sign } else { -first_sign };
            plant = scale(plant, g, 1.0 + sign * pct / 100.0)?;
            name.push(format!("{} {:+.0} %", labels[g], sign * pct));
        }
        v.push(MismatchCase {
            name: name.join(" & "),
            plant,
            model: nom,
            single_parameter: false,
            group: format!(
                "{} parameter{}, {pct:.0} %",
                groups.len(),
                if groups.len() > 1 { "s" } else { "" }
            ),
        });
        Ok(())
    };
    for i in 0..n {
        for sign in [-1.0, 1.0] {
            push(&[i], 10.0, sign)?;
        }
    }
    for pct in [10.0, 20.0] {
        for i in 0..n {
            for j in i + 1..n {
                for sign in [1.0, -1.0] {
                    push(&[i, j], pct, sign)?;
                }
            }
        }
        for i in 0..n {
            for j in i + 1..n {
                for k in j + 1..n {
                    for sign in [1.0, -1.0] {
                        push(&[i, j, k], pct, sign)?;
                    }
                }
            }
        }
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
    /// With `--model-update`: the information-limit arm's lead (the pipeline with the plant's
    /// own model), km/h.
    pub limit_lead_kmh: Option<f64>,
}

/// Results of one case.
#[derive(Clone, Debug)]
pub struct CaseResult<M = ReferenceModel> {
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
    /// Road-noise seed.
    pub seed: u64,
    /// With `--model-update`: per updated parameter at the end of the drive, its field, the
    /// estimated and the true factor (plant over model) and the sigma of ln(factor).
    pub updated: Vec<UpdatedParam>,
}

/// One parameter of the online model update at the end of a constant drive.
#[derive(Clone, Debug, PartialEq)]
pub struct UpdatedParam {
    /// Field name.
    pub field: &'static str,
    /// Estimated factor on the model's value.
    pub factor: f64,
    /// The plant's true factor.
    pub true_factor: f64,
    /// One-sigma uncertainty of ln(factor).
    pub sigma_ln: f64,
}

impl UpdatedParam {
    /// The true factor lies within two reported sigmas of the estimate.
    pub fn covered(&self) -> bool {
        (self.factor.ln() - self.true_factor.ln()).abs() <= 2.0 * self.sigma_ln
    }
}

impl<M> CaseResult<M> {
    /// Lead at the first (slowest) ramp rate, km/h.
    pub fn lead_kmh(&self) -> Option<f64> {
        self.ramps.first().and_then(|r| r.lead_kmh)
    }

    /// The case meets its targets: no false warning (or, where one is due at the drive, a
    /// warning for at least [`DUE_WARNED_MIN`] of it); single-parameter cases with an onset
    /// also lead by at least [`MIN_LEAD_KMH`]; with the model update every ramp warns before
    /// the onset (the shares of leads of 3 km/h and near the limit are judged over all runs).
    pub fn passes(&self) -> bool {
        let updating = self.ramps.iter().any(|r| r.limit_lead_kmh.is_some());
        let lead_ok = if updating {
            self.plant_onset_kmh.is_none()
                || self
                    .ramps
                    .iter()
                    .all(|r| r.lead_kmh.is_some_and(|l| l > 0.0))
        } else {
            !self.case.single_parameter
                || self.plant_onset_kmh.is_none()
                || self.lead_kmh().is_some_and(|l| l >= MIN_LEAD_KMH)
        };
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
    let limit_pp = PipelineParams {
        update: ModelUpdateConfig::OFF,
        ..pp
    };
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
        let limit_lead_kmh = if pp.update.enabled {
            let mut sc = seeded(ramp_scenario(case, rate, false, reference));
            sc.model = Some(case.plant);
            ramp_lead(&run(&sc, limit_pp, 0)?).0
        } else {
            None
        };
        ramps.push(RampResult {
            rate_kmh_per_s: rate,
            lead_kmh,
            lead_s,
            inconsistent_kmh: r.first_inconsistent.map(|x| x.1),
            limit_lead_kmh,
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
        seed,
        updated: full
            .updated
            .iter()
            .enumerate()
            .map(|(i, e)| UpdatedParam {
                field: e.field,
                factor: e.factor,
                true_factor: case.plant.linear().update_param(i)
                    / case.model.linear().update_param(i),
                sigma_ln: e.sigma_ln,
            })
            .collect(),
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
            s += &format!(" {} / {}", opt(x.lead_kmh, 2), opt(x.lead_s, 1));
            if x.limit_lead_kmh.is_some() {
                s += &format!(" (limit {})", opt(x.limit_lead_kmh, 2));
            }
            s += " |";
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

/// The study's shares over the runs at one rate.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LeadShares {
    /// Ramps with a plant onset.
    pub runs: usize,
    /// ... warned before the onset.
    pub before_onset: usize,
    /// ... at least [`MIN_LEAD_KMH`] ahead.
    pub lead_3: usize,
    /// ... within 1 km/h of the information-limit arm (or ahead of it).
    pub near_limit: usize,
    /// Smallest lead, km/h (None: some run did not warn at all).
    pub worst_lead_kmh: Option<f64>,
}

impl LeadShares {
    fn of<'a, M: 'a>(rows: impl Iterator<Item = &'a CaseResult<M>>, rate_index: usize) -> Self {
        let mut s = Self {
            worst_lead_kmh: Some(f64::INFINITY),
            ..Self::default()
        };
        for r in rows.filter(|r| r.plant_onset_kmh.is_some()) {
            let Some(x) = r.ramps.get(rate_index) else {
                continue;
            };
            s.runs += 1;
            let lead = x.lead_kmh.unwrap_or(f64::NEG_INFINITY);
            s.before_onset += usize::from(lead > 0.0);
            s.lead_3 += usize::from(lead >= MIN_LEAD_KMH);
            s.near_limit += usize::from(x.limit_lead_kmh.is_none_or(|l| lead >= l - 1.0));
            s.worst_lead_kmh = match (s.worst_lead_kmh, x.lead_kmh) {
                (Some(w), Some(l)) => Some(w.min(l)),
                _ => None,
            };
        }
        s
    }

    fn pct(n: usize, of: usize) -> f64 {
        100.0 * n as f64 / of.max(1) as f64
    }
}

/// Required share of runs at 1 km/h/s leading by [`MIN_LEAD_KMH`] with the model update.
pub const LEAD_3_SHARE_MIN: f64 = 0.95;
/// Required share of runs at 1 km/h/s within 1 km/h of the information-limit arm.
pub const NEAR_LIMIT_SHARE_MIN: f64 = 0.90;
/// Required share of updated parameters within two sigmas of the truth after the drive.
pub const COVERAGE_MIN: f64 = 0.90;

/// The summary over cases and seeds by kind of error: per rate the share of runs that warned
/// before the onset, at least 3 km/h ahead, and within 1 km/h of the information-limit arm;
/// the drives with a false warning; the updated parameters within two sigmas of the truth.
pub fn summary_markdown<M>(rows: &[CaseResult<M>], rates: &[f64]) -> String {
    let mut groups: Vec<&str> = Vec::new();
    for r in rows {
        if !groups.contains(&r.case.group.as_str()) {
            groups.push(&r.case.group);
        }
    }
    groups.push("all");
    let mut s = String::from(
        "| error | rate [km/h/s] | runs | warned before onset | >= 3 km/h ahead | within 1 km/h of the limit | worst lead [km/h] | drives with a false warning | parameters within 2 sigma |\n|---|---|---|---|---|---|---|---|---|\n",
    );
    for g in groups {
        let of_group = || rows.iter().filter(move |r| g == "all" || r.case.group == g);
        let false_drives = of_group()
            .filter(|r| !r.warning_due && r.false_per_h > 0.0)
            .count();
        let drives = of_group().count();
        let params: Vec<bool> = of_group()
            .flat_map(|r| r.updated.iter().map(UpdatedParam::covered))
            .collect();
        let coverage = if params.is_empty() {
            "-".to_string()
        } else {
            let n = params.iter().filter(|c| **c).count();
            format!(
                "{n}/{} ({:.0} %)",
                params.len(),
                LeadShares::pct(n, params.len())
            )
        };
        for (i, rate) in rates.iter().enumerate() {
            let l = LeadShares::of(of_group(), i);
            s += &format!(
                "| {g} | {rate} | {} | {:.0} % | {:.0} % | {:.0} % | {} | {} | {} |\n",
                l.runs,
                LeadShares::pct(l.before_onset, l.runs),
                LeadShares::pct(l.lead_3, l.runs),
                LeadShares::pct(l.near_limit, l.runs),
                opt(l.worst_lead_kmh.filter(|w| w.is_finite()), 2),
                if i == 0 {
                    format!("{false_drives}/{drives}")
                } else {
                    String::new()
                },
                if i == 0 {
                    coverage.clone()
                } else {
                    String::new()
                },
            );
        }
    }
    s
}

/// With the model update: the study's shared targets over all runs (see
/// [`MismatchArgs::model_update`]); the names of those missed.
pub fn study_misses<M>(rows: &[CaseResult<M>], rates: &[f64]) -> Vec<String> {
    let mut missed = Vec::new();
    if let Some(i) = rates.iter().position(|r| (*r - 1.0).abs() < 1e-9) {
        let l = LeadShares::of(rows.iter(), i);
        let share = |n: usize| n as f64 / l.runs.max(1) as f64;
        if share(l.lead_3) < LEAD_3_SHARE_MIN {
            missed.push(format!(
                "{:.1} % of the runs at 1 km/h/s lead by {MIN_LEAD_KMH} km/h (target {:.0} %)",
                100.0 * share(l.lead_3),
                100.0 * LEAD_3_SHARE_MIN
            ));
        }
        if share(l.near_limit) < NEAR_LIMIT_SHARE_MIN {
            missed.push(format!(
                "{:.1} % of the runs at 1 km/h/s within 1 km/h of the limit arm (target {:.0} %)",
                100.0 * share(l.near_limit),
                100.0 * NEAR_LIMIT_SHARE_MIN
            ));
        }
    }
    let params: Vec<bool> = rows
        .iter()
        .flat_map(|r| r.updated.iter().map(UpdatedParam::covered))
        .collect();
    let covered = params.iter().filter(|c| **c).count() as f64 / params.len().max(1) as f64;
    if !params.is_empty() && covered < COVERAGE_MIN {
        missed.push(format!(
            "{:.1} % of the updated parameters within 2 sigma of the truth after the drive (target {:.0} %)",
            100.0 * covered,
            100.0 * COVERAGE_MIN
        ));
    }
    missed
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
                "seed": r.seed,
                "limit_leads_kmh": r.ramps.iter().map(|x| x.limit_lead_kmh).collect::<Vec<_>>(),
                "updated": r.updated.iter().map(|u| serde_json::json!({
                    "field": u.field,
                    "factor": u.factor,
                    "true_factor": u.true_factor,
                    "sigma_ln": u.sigma_ln,
                    "within_2_sigma": u.covered(),
                })).collect::<Vec<_>>(),
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
    let seeds = match &a.seeds {
        Some(text) => parse_seeds(text)?,
        None => vec![a.seed],
    };
    let spec = a.model_vehicle.or(DEFAULT_VEHICLE);
    let vehicle = vehicle_file::load_model(spec)?;
    let mut provenance =
        Provenance::of_this_process().model_vehicle("model vehicle", spec, &vehicle)?;
    for &seed in &seeds {
        provenance = provenance.seed("road noise", seed);
    }
    struct On<'a>(&'a MismatchArgs, &'a [u64], Provenance);
    impl StudyVisitor for On<'_> {
        type Output = Result<()>;
        fn visit<M: Registered<N> + StudyModel<N>, const N: usize>(self, v: M::File) -> Result<()> {
            command_on(self.0, self.1, &registry::family::<M, N>(v)?, self.2)
        }
    }
    match registry::with_image_model(vehicle, On(a, &seeds, provenance)) {
        Ok(r) => r,
        Err(other) => bail!(
            "`mismatch` runs the {} models, not the {} (vehicle `{}`)",
            image_models(),
            other.model_name(),
            spec
        ),
    }
}

/// The study on the model vehicle `vehicle` (its model and its pipeline's thresholds).
fn command_on<M: StudyModel<N>, const N: usize>(
    a: &MismatchArgs,
    seeds: &[u64],
    vehicle: &FamilyVehicle<M>,
    provenance: Provenance,
) -> Result<()> {
    let mut all = cases(&vehicle.model)?;
    if a.combined {
        all.extend(combined_cases(&vehicle.model)?);
    }
    let chosen: Vec<MismatchCase<M>> = all
        .iter()
        .filter(|c| a.only.as_ref().is_none_or(|o| c.name.contains(o.as_str())))
        .cloned()
        .collect();
    if chosen.is_empty() {
        let names: Vec<&str> = all.iter().map(|c| c.name.as_str()).collect();
        bail!("--only matches no case; cases: {}", names.join(", "));
    }
    let _out_dir = crate::sim::input::files::OutDir::claim(&a.out_dir())?;
    let wall = std::time::Instant::now();
    let mut pp = vehicle.pipeline_params();
    if a.model_update {
        pp.update = ModelUpdateConfig::ON;
    }
    let runs: Vec<(&MismatchCase<M>, u64)> = chosen
        .iter()
        .flat_map(|c| seeds.iter().map(move |&s| (c, s)))
        .collect();
    let bar = progress::bar(runs.len(), "mismatch cases");
    let rows: Vec<CaseResult<M>> = runs
        .par_iter()
        .map(|&(c, seed)| {
            let r = run_case(c, &a.rates_kmh_per_s, a.drive_s, pp, seed);
            bar.inc(1);
            r
        })
        .collect::<Result<_>>()?;
    bar.finish_and_clear();
    let seed_text = match seeds {
        [one] => format!("seed {one}"),
        _ => format!("{} seeds", seeds.len()),
    };
    let mut md = if seeds.len() == 1 {
        markdown(&rows, &a.rates_kmh_per_s)
    } else {
        String::new()
    };
    if a.model_update || seeds.len() > 1 {
        if !md.is_empty() {
            md += "\n";
        }
        md += &summary_markdown(&rows, &a.rates_kmh_per_s);
    }
    println!(
        "plant vs model mismatch (model `{}`{}; open loop, damper off, 5 N m road noise ({seed_text}), 2 N m imbalance; drive {:.0} s at 70 % of the true onset), {:.0} s wall",
        a.model_vehicle.or(DEFAULT_VEHICLE),
        if a.model_update { ", updated online" } else { "" },
        a.drive_s,
        wall.elapsed().as_secs_f64()
    );
    print!("{md}");
    crate::sim::input::files::write_file(
        &a.out_dir().join("mismatch.md"),
        format!("{}\n\n{}", md.trim_end(), provenance.markdown()),
    )?;
    crate::sim::input::files::write_file(
        &a.out_dir().join("summary.json"),
        serde_json::to_string_pretty(&summary_json(&rows, &provenance))? + "\n",
    )?;
    let mut f = Vec::new();
    writeln!(f, "case,plant_onset_kmh,model_onset_kmh,rate_kmh_per_s,lead_kmh,lead_s,first_inconsistent_kmh,data_only_lead_kmh,data_only_lead_s,drive_kmh,false_warnings_per_h,data_only_false_warnings_per_h,drive_margin_true_kmh,warning_due,drive_warned_fraction,data_only_drive_warned_fraction,passes,seed,limit_lead_kmh")?;
    let o = |v: Option<f64>| v.map_or(String::new(), |x| format!("{x:.3}"));
    for r in &rows {
        for x in &r.ramps {
            writeln!(
                f,
                "\"{}\",{},{},{},{},{},{},{},{},{:.3},{:.1},{:.1},{:.3},{},{:.4},{:.4},{},{},{}",
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
                r.passes(),
                r.seed,
                o(x.limit_lead_kmh),
            )?;
        }
    }
    crate::sim::input::files::write_file(&a.out_dir().join("mismatch.csv"), &f)?;
    let mut missed: Vec<String> = rows
        .iter()
        .filter(|r| !r.passes())
        .map(|r| format!("{} (seed {})", r.case.name, r.seed))
        .collect();
    if a.model_update {
        missed.extend(study_misses(&rows, &a.rates_kmh_per_s));
    }
    if !missed.is_empty() {
        bail!(
            "targets missed ({}no false warning, a due warning shown): {}",
            if a.model_update {
                "a warning before the onset in every run, "
            } else {
                "lead >= 3 km/h in single-parameter cases, "
            },
            missed.join(", ")
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use shimmy_core::vehicles::car::PlantParams;

    fn row(case: MismatchCase<PlantParams>) -> CaseResult<PlantParams> {
        CaseResult {
            plant_onset_kmh: Some(30.0),
            model_onset_kmh: Some(29.0),
            ramps: vec![RampResult {
                rate_kmh_per_s: 1.0,
                lead_kmh: Some(4.0),
                lead_s: Some(4.0),
                inconsistent_kmh: None,
                limit_lead_kmh: None,
            }],
            data_only_lead: (Some(1.0), None),
            drive_kmh: 21.0,
            false_per_h: 0.0,
            data_only_false_per_h: 6.0,
            drive_margin_true_kmh: 9.0,
            warning_due: false,
            warned_fraction: (0.0, 0.01),
            seed: 1,
            updated: Vec::new(),
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
