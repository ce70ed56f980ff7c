//! `shimmy-sim identifiability`: which of a model's updatable parameters the online model
//! update (`docs/margin-estimator.md`, "Model updating") can separate from the meter's shimmy
//! frequency and damping, at which speeds and noise levels.
//!
//! The Fisher information of one measurement update at speed V is J^T R^-1 J, with J the
//! Jacobian of (frequency, damping) in the ln-factors and R the update's noise (both exactly
//! as the updater computes them: `ModelUpdater::predict`, `ModelUpdater::measurement_noise`);
//! `--seconds-per-speed` of driving give that many updates at the update's period. The
//! posterior covariance after the speeds up to V is (P0^-1 + sum I)^-1 (linearised at the
//! vehicle file): each parameter's sigma against its prior, and the onset speed's sigma
//! (g P g^T, g = dV_onset / d ln factor). A parameter counts as separated when the data halve
//! its prior sigma.
use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use nalgebra::SMatrix;
use shimmy_core::estimator::model_update::{
    ModelUpdateConfig, ModelUpdater, ParamMatrix, MAX_UPDATE_PARAMS,
};
use shimmy_core::model::UpdatableModel;
use shimmy_core::units::{kmh_to_mps, mps_to_kmh};

use crate::model::family::onset_kmh;
use crate::model::registry::{self, Registered, StudyVisitor};
use crate::model::study::StudyModel;
use crate::sim::input::arg_range::{self, Range};
use crate::sim::input::vehicle_file;

/// Options of `shimmy-sim identifiability`.
#[derive(clap::Args, Debug, Clone)]
pub struct IdentifiabilityArgs {
    /// The vehicle (`--vehicle`, a named set or a vehicle file).
    #[command(flatten)]
    pub vehicle: crate::cmd::VehicleArg,
    /// The meter's sigma of the damping ratio, one table per value, each 0.001 to 0.1.
    #[arg(long, value_delimiter = ',', default_value = "0.005,0.01,0.02", value_parser = arg_range::f64_in(SIGMA_ZETA))]
    pub sigma_zeta: Vec<f64>,
    /// Driving time at each speed, s: 1 to 3600.
    #[arg(long, default_value_t = 30.0, value_parser = arg_range::f64_in(SECONDS))]
    pub seconds_per_speed: f64,
    /// Lowest speed as a fraction of the model's onset: 0.1 to 0.95 (the speeds run from it
    /// to 0.95 of the onset in `--speeds` steps).
    #[arg(long, default_value_t = 0.5, value_parser = arg_range::f64_in(FRACTION))]
    pub from_fraction: f64,
    /// Number of speeds: 2 to 50.
    #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u16).range(2..=50))]
    pub speeds: u16,
    /// Output folder (`--out`; default out/identifiability, [`Self::out_dir`]).
    #[command(flatten)]
    pub out: crate::cmd::OutArg,
}

impl IdentifiabilityArgs {
    /// The output folder: `--out`, else out/identifiability.
    pub fn out_dir(&self) -> PathBuf {
        self.out.dir_or("out/identifiability")
    }
}

/// The meter's damping sigma: 0.001 to 0.1.
pub const SIGMA_ZETA: Range = Range::closed(0.001, 0.1, "");
/// Driving time per speed: 1 to 3600 s.
pub const SECONDS: Range = Range::closed(1.0, 3600.0, "s");
/// Lowest speed over the onset: 0.1 to 0.95.
pub const FRACTION: Range = Range::closed(0.1, 0.95, "");

/// A parameter counts as separated when the data bring its sigma below this share of the prior.
pub const SEPARATED_BELOW: f64 = 0.5;

/// One row: the evidence of every speed up to `speed_kmh` at one noise level.
#[derive(Clone, Debug, PartialEq)]
pub struct StudyRow {
    /// The meter's damping sigma.
    pub sigma_zeta: f64,
    /// The highest speed of the evidence, km/h.
    pub speed_kmh: f64,
    /// Posterior sigma of each ln-factor, in the model's order.
    pub sigma_ln: Vec<f64>,
    /// The onset speed's posterior sigma, km/h.
    pub onset_sigma_kmh: f64,
    /// Parameters whose sigma the data halved.
    pub separated: usize,
}

/// The study on `model` (damper off).
pub fn study<M: UpdatableModel<N>, const N: usize>(
    model: &M,
    sigmas_zeta: &[f64],
    seconds_per_speed: f64,
    from_fraction: f64,
    speeds: usize,
) -> Result<Vec<StudyRow>> {
    let k = M::UPDATE_PARAMS.len().min(MAX_UPDATE_PARAMS);
    if k == 0 {
        bail!(
            "the {} model has no parameters the online update estimates",
            M::NAME
        );
    }
    let onset = onset_kmh(model).context("the model has no shimmy onset below 150 km/h")?;
    let up = ModelUpdater::new(*model, ModelUpdateConfig::ON);
    let period = f64::from(up.config().period_s);
    let updates = (seconds_per_speed / period).floor().max(1.0);
    let g = up
        .onset_gradient(kmh_to_mps(onset), 0.0)
        .context("the onset is not a transversal crossing")?;
    let prior = *up.covariance();
    let prior_inv = invert(&prior, k)?;
    let n = speeds.max(2);
    let grid: Vec<f64> = (0..n)
        .map(|i| onset * (from_fraction + (0.95 - from_fraction) * i as f64 / (n - 1) as f64))
        .collect();
    // the predictions depend on the speed only: one eigen-solve per speed for every noise level
    let predictions = grid
        .iter()
        .map(|&v_kmh| {
            up.predict(kmh_to_mps(v_kmh), 0.0)
                .map(|p| (v_kmh, p))
                .with_context(|| format!("no shimmy mode at {v_kmh:.1} km/h"))
        })
        .collect::<Result<Vec<_>>>()?;
    let mut rows = Vec::new();
    for &sz in sigmas_zeta {
        let mut info = ParamMatrix::zeros();
        for &(v_kmh, p) in &predictions {
            let r = up.measurement_noise(sz, p.wn_hz);
            let r_inv = r.try_inverse().context("singular measurement noise")?;
            let j: SMatrix<f64, 2, MAX_UPDATE_PARAMS> = p.jacobian;
            info += j.transpose() * r_inv * j * updates;
            let post = invert(&(prior_inv + info), k)?;
            let sigma_ln: Vec<f64> = (0..k).map(|i| post[(i, i)].max(0.0).sqrt()).collect();
            let separated = (0..k)
                .filter(|&i| sigma_ln[i] < SEPARATED_BELOW * prior[(i, i)].sqrt())
                .count();
            let onset_var = (g.transpose() * post * g)[(0, 0)].max(0.0);
            rows.push(StudyRow {
                sigma_zeta: sz,
                speed_kmh: v_kmh,
                sigma_ln,
                onset_sigma_kmh: mps_to_kmh(onset_var.sqrt()),
                separated,
            });
        }
    }
    Ok(rows)
}

/// The inverse of the leading `k` x `k` block (the rest stays 0).
fn invert(m: &ParamMatrix, k: usize) -> Result<ParamMatrix> {
    let mut padded = *m;
    for i in k..MAX_UPDATE_PARAMS {
        padded[(i, i)] = 1.0;
    }
    let mut inv = padded
        .try_inverse()
        .context("singular information matrix")?;
    for i in k..MAX_UPDATE_PARAMS {
        inv[(i, i)] = 0.0;
    }
    Ok(inv)
}

/// The tables as Markdown, one per noise level.
pub fn markdown<M: UpdatableModel<N>, const N: usize>(rows: &[StudyRow], onset_kmh: f64) -> String {
    let names: Vec<&str> = M::UPDATE_PARAMS.iter().map(|u| u.field).collect();
    let prior: Vec<f64> = M::UPDATE_PARAMS.iter().map(|u| u.prior_sigma_ln).collect();
    let mut s = String::new();
    let mut last = f64::NAN;
    for r in rows {
        if r.sigma_zeta != last {
            last = r.sigma_zeta;
            let _ = writeln!(
                s,
                "\nmeter sigma of zeta {} (onset {onset_kmh:.2} km/h); sigma of each ln-factor in % (prior {}), separated = below {:.0} % of the prior:\n",
                r.sigma_zeta,
                prior
                    .iter()
                    .map(|p| format!("{:.0} %", p * 100.0))
                    .collect::<Vec<_>>()
                    .join(" / "),
                SEPARATED_BELOW * 100.0
            );
            let _ = writeln!(
                s,
                "| data up to [km/h] | {} | onset sigma [km/h] | separated |",
                names.join(" | ")
            );
            let _ = writeln!(s, "|---:|{}---:|---:|", "---:|".repeat(names.len()));
        }
        let cells: Vec<String> = r
            .sigma_ln
            .iter()
            .map(|x| format!("{:.1}", x * 100.0))
            .collect();
        let _ = writeln!(
            s,
            "| {:.1} | {} | {:.2} | {}/{} |",
            r.speed_kmh,
            cells.join(" | "),
            r.onset_sigma_kmh,
            r.separated,
            names.len()
        );
    }
    s
}

fn command_on<M: UpdatableModel<N>, const N: usize>(
    a: &IdentifiabilityArgs,
    model: &M,
) -> Result<()> {
    let _out_dir = crate::sim::input::files::OutDir::claim(&a.out_dir())?;
    let speeds = usize::from(a.speeds);
    let rows = study(
        model,
        &a.sigma_zeta,
        a.seconds_per_speed,
        a.from_fraction,
        speeds,
    )?;
    let onset = onset_kmh(model).unwrap_or(f64::NAN);
    let md = markdown::<M, N>(&rows, onset);
    println!(
        "identifiability of the {} model's updated parameters (`{}`, damper off): {} s at each speed, evidence accumulated from {:.0} % of the onset",
        M::NAME,
        a.vehicle.spec,
        a.seconds_per_speed,
        a.from_fraction * 100.0
    );
    print!("{md}");
    crate::sim::input::files::write_file(&a.out_dir().join("identifiability.md"), md.trim_start())?;
    let mut csv = String::from("sigma_zeta,speed_kmh,field,sigma_ln,onset_sigma_kmh\n");
    for r in &rows {
        for (u, s) in M::UPDATE_PARAMS.iter().zip(&r.sigma_ln) {
            let _ = writeln!(
                csv,
                "{},{:.3},{},{:.6},{:.4}",
                r.sigma_zeta, r.speed_kmh, u.field, s, r.onset_sigma_kmh
            );
        }
    }
    crate::sim::input::files::write_file(&a.out_dir().join("identifiability.csv"), csv)?;
    Ok(())
}

/// `shimmy-sim identifiability`.
pub fn command(a: &IdentifiabilityArgs) -> Result<()> {
    arg_range::ensure_count("--sigma-zeta", a.sigma_zeta.len(), 8)?;
    struct On<'a>(&'a IdentifiabilityArgs);
    impl StudyVisitor for On<'_> {
        type Output = Result<()>;
        fn visit<M: Registered<N> + StudyModel<N>, const N: usize>(self, v: M::File) -> Result<()> {
            command_on(self.0, &M::model_of(&v).linear())
        }
    }
    match registry::with_image_model(vehicle_file::load_model(&a.vehicle.spec)?, On(a)) {
        Ok(r) => r,
        Err(other) => bail!(
            "`identifiability` runs the models with updatable parameters (car, truck), not the {} (vehicle `{}`)",
            other.model_name(),
            a.vehicle.spec
        ),
    }
}
