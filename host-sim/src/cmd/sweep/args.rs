//! The arguments and grid axes shared by both sweep variants (the eigenvalue map and the
//! time-domain map), so that neither has to import the other.

use anyhow::{bail, Result};
use clap::Args;
use shimmy_core::params::{Param, PlantParams};
use std::path::PathBuf;

/// Options of `shimmy-sim sweep`.
#[derive(Args, Debug, Clone)]
pub struct SweepArgs {
    /// Base parameter set (name or TOML file).
    #[arg(long, default_value = "nominal")]
    pub params: String,
    /// Parameter varied on the vertical axis (field name, see `shimmy-sim params`).
    #[arg(long, default_value = "k_d")]
    pub param: String,
    /// Smallest factor on the parameter's base value.
    #[arg(long, default_value_t = 0.5)]
    pub factor_min: f64,
    /// Largest factor on the parameter's base value.
    #[arg(long, default_value_t = 1.5)]
    pub factor_max: f64,
    /// Number of parameter values [default: 41; 9 with --controllers].
    #[arg(long)]
    pub factor_steps: Option<usize>,
    /// Lowest speed, km/h.
    #[arg(long, default_value_t = 2.0)]
    pub v_min_kmh: f64,
    /// Highest speed, km/h.
    #[arg(long, default_value_t = 150.0)]
    pub v_max_kmh: f64,
    /// Number of speeds [default: 149; 25 with --controllers].
    #[arg(long)]
    pub v_steps: Option<usize>,
    /// MR damper currents, A (one map each, as an equivalent viscous damper); none = no damper.
    #[arg(long, value_delimiter = ',', alias = "damper-currents")]
    pub damper_current_a: Vec<f64>,
    /// Wheel-yaw amplitude of the damper's describing function, deg.
    #[arg(long, default_value_t = 0.5)]
    pub ref_amplitude_deg: f64,
    /// Output folder.
    #[arg(long, default_value = "out/sweep")]
    pub out: PathBuf,
    /// No progress bar (for scripts and tests).
    #[arg(long)]
    pub quiet: bool,
    /// Time-domain sweep over this controller axis instead of the eigenvalue map (comma
    /// separated: no-damper, passive-off, passive-on, smc, asmc, skyhook; short forms none,
    /// off, on): one closed-loop run per grid point
    /// and controller, map of the final wheel-yaw amplitude with the linear Hopf boundary.
    #[arg(long, value_delimiter = ',')]
    pub controllers: Vec<String>,
    /// Time-domain sweep: fixed current of `passive-on`, in A.
    #[arg(long, default_value_t = 1.0, alias = "on-current")]
    pub on_current_a: f64,
    /// Time-domain sweep: simulated time per run, s.
    #[arg(long, default_value_t = 6.0)]
    pub duration_s: f64,
    /// Time-domain sweep: initial in-phase wheel-yaw kick, deg (3 deg breaks through the
    /// damper's friction at 0 A).
    #[arg(long, default_value_t = 3.0)]
    pub kick_deg: f64,
    /// Time-domain sweep: seed of the sensor noise (same seed, same numbers).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

/// The grid axes: speeds in km/h, parameter values and the parameter, validated
/// (`default_steps` = (speeds, values) when not given).
pub fn axes(
    a: &SweepArgs,
    base: &PlantParams,
    default_steps: (usize, usize),
) -> Result<(Vec<f64>, Vec<f64>, Param)> {
    let Some(param) = Param::from_name(&a.param) else {
        let names: Vec<&str> = Param::ALL.iter().map(|p| p.name()).collect();
        bail!(
            "--param {}: no such parameter, allowed: {}",
            a.param,
            names.join(", ")
        );
    };
    let v_steps = a.v_steps.unwrap_or(default_steps.0);
    let factor_steps = a.factor_steps.unwrap_or(default_steps.1);
    let ok = a.factor_min.is_finite()
        && a.factor_max.is_finite()
        && a.factor_min > 0.0
        && a.factor_max >= a.factor_min
        && factor_steps >= 1
        && a.v_min_kmh > 0.0
        && a.v_max_kmh > a.v_min_kmh
        && v_steps >= 2;
    if !ok {
        bail!(
            "need 0 < factor-min <= factor-max, factor-steps >= 1, 0 < v-min < v-max, v-steps >= 2"
        );
    }
    let speeds_kmh: Vec<f64> = (0..v_steps)
        .map(|i| a.v_min_kmh + (a.v_max_kmh - a.v_min_kmh) * i as f64 / (v_steps - 1) as f64)
        .collect();
    let values: Vec<f64> = (0..factor_steps)
        .map(|j| {
            let f = if factor_steps == 1 {
                a.factor_min
            } else {
                a.factor_min + (a.factor_max - a.factor_min) * j as f64 / (factor_steps - 1) as f64
            };
            base.get(param) * f
        })
        .collect();
    Ok((speeds_kmh, values, param))
}
