//! The arguments and grid axes shared by both sweep variants (the eigenvalue map and the
//! time-domain map), so that neither has to import the other.

use crate::model::family::{param_names, ParamInfo, SimModel};
use crate::sim::input::arg_range::{self, Range};
use crate::sim::run::scenario::controller_name;
use anyhow::{bail, Result};
use clap::Args;
use shimmy_core::vehicle::Vehicle;
use std::path::PathBuf;

/// Options of `shimmy-sim sweep`.
#[derive(Args, Debug, Clone)]
pub struct SweepArgs {
    /// The vehicle (`--vehicle`, a named set or a vehicle file).
    #[command(flatten)]
    pub vehicle: crate::cmd::VehicleArg,
    /// Parameter varied on the vertical axis (field name, see `shimmy-sim params`).
    #[arg(long, default_value = "k_d")]
    pub param: String,
    /// Smallest factor on the parameter's base value: above 0, at most 10.
    #[arg(long, default_value_t = 0.5, allow_negative_numbers = true, value_parser = arg_range::f64_in(FACTOR))]
    pub factor_min: f64,
    /// Largest factor on the parameter's base value: above 0, at most 10, at least
    /// `--factor-min`.
    #[arg(long, default_value_t = 1.5, allow_negative_numbers = true, value_parser = arg_range::f64_in(FACTOR))]
    pub factor_max: f64,
    /// Number of parameter values [default: 41; 9 with --controllers]: 1 to 401.
    #[arg(long, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=401))]
    pub factor_steps: Option<usize>,
    /// Lowest speed, km/h: 1 to 250, below `--v-max-kmh`.
    #[arg(long, default_value_t = 2.0, allow_negative_numbers = true, value_parser = arg_range::speed_kmh())]
    pub v_min_kmh: f64,
    /// Highest speed, km/h: 1 to 250.
    #[arg(long, default_value_t = 150.0, allow_negative_numbers = true, value_parser = arg_range::speed_kmh())]
    pub v_max_kmh: f64,
    /// Number of speeds [default: 149; 25 with --controllers]: 2 to 1001.
    #[arg(long, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(2..=1001))]
    pub v_steps: Option<usize>,
    /// MR damper currents, A (one map each, as an equivalent viscous damper); none = no damper.
    /// Each 0 to the vehicle's coil rating, at most 16.
    #[arg(long, value_delimiter = ',', alias = "damper-currents", allow_negative_numbers = true, value_parser = arg_range::current_a())]
    pub damper_current_a: Vec<f64>,
    /// Wheel-yaw amplitude of the damper's describing function, deg: above 0, at most 20.
    #[arg(long, default_value_t = 0.5, allow_negative_numbers = true, value_parser = arg_range::f64_in(REF_AMPLITUDE_DEG))]
    pub ref_amplitude_deg: f64,
    /// Output folder (`--out`; default out/sweep, [`Self::out_dir`]).
    #[command(flatten)]
    pub out: crate::cmd::OutArg,
    /// No progress bar (for scripts and tests).
    #[arg(long)]
    pub quiet: bool,
    /// Time-domain sweep over this controller axis instead of the eigenvalue map (comma
    /// separated: no-damper, passive-off, passive-on, smc, asmc, skyhook; short forms none,
    /// off, on): one closed-loop run per grid point
    /// and controller, map of the final wheel-yaw amplitude with the linear Hopf boundary.
    #[arg(long, value_delimiter = ',')]
    pub controllers: Vec<String>,
    /// Time-domain sweep: fixed current of `passive-on`, in A: 0 to the vehicle's coil rating.
    #[arg(long, default_value_t = 1.0, alias = "on-current", allow_negative_numbers = true, value_parser = arg_range::current_a())]
    pub on_current_a: f64,
    /// Time-domain sweep: simulated time per run, s: 1 to 600.
    #[arg(long, default_value_t = 6.0, allow_negative_numbers = true, value_parser = arg_range::f64_in(DURATION_S))]
    pub duration_s: f64,
    /// Time-domain sweep: initial in-phase wheel-yaw kick, deg (3 deg breaks through the
    /// damper's friction at 0 A): -20 to 20 deg.
    #[arg(long, default_value_t = 3.0, allow_negative_numbers = true, value_parser = arg_range::f64_in(KICK_DEG))]
    pub kick_deg: f64,
    /// Time-domain sweep: seed of the sensor noise (same seed, same numbers).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

impl SweepArgs {
    /// The output folder: `--out`, else out/sweep.
    pub fn out_dir(&self) -> PathBuf {
        self.out.dir_or("out/sweep")
    }
}

/// Factor on the parameter's base value: above 0, at most 10.
pub const FACTOR: Range = Range::above(0.0, 10.0, "");
/// Describing-function reference amplitude: above 0, at most 20 deg.
pub const REF_AMPLITUDE_DEG: Range = Range::above(0.0, 20.0, "deg");
/// Time-domain run length: 1 to 600 s.
pub const DURATION_S: Range = Range::closed(1.0, 600.0, "s");
/// Time-domain kick: -20 to 20 deg.
pub const KICK_DEG: Range = Range::closed(-20.0, 20.0, "deg");
/// Most damper currents (maps) in one eigenvalue sweep.
pub const MAX_CURRENTS: usize = 16;
/// Most closed-loop runs (speeds x values x controllers) in one time-domain sweep.
pub const MAX_RUNS: usize = 20_000;

/// The grid axes for the vehicle model `model`: speeds in km/h, parameter values and the
/// parameter, validated, and the currents checked against the coil rating of `parts`
/// (`default_steps` = (speeds, values) when not given).
pub fn axes_of<M: SimModel<N>, const N: usize>(
    a: &SweepArgs,
    model: &M,
    parts: &Vehicle,
    default_steps: (usize, usize),
) -> Result<(Vec<f64>, Vec<f64>, ParamInfo)> {
    let (Some(info), Some(base)) = (
        M::params().into_iter().find(|p| p.name == a.param),
        model.param(&a.param),
    ) else {
        bail!(
            "--param {}: no such parameter, allowed: {}",
            a.param,
            param_names::<M, N>()
        );
    };
    let v_steps = a.v_steps.unwrap_or(default_steps.0);
    let factor_steps = a.factor_steps.unwrap_or(default_steps.1);
    check(a)?;
    for &i in &a.damper_current_a {
        arg_range::check_current("--damper-current-a", i, parts)?;
    }
    if a.controllers
        .iter()
        .any(|c| controller_name(c) == Some("passive-on"))
    {
        arg_range::check_current("--on-current-a", a.on_current_a, parts)?;
    }
    if !(1..=401).contains(&factor_steps) || !(2..=1001).contains(&v_steps) {
        bail!("--factor-steps {factor_steps}, --v-steps {v_steps}: allowed 1 to 401 and 2 to 1001");
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
            base * f
        })
        .collect();
    Ok((speeds_kmh, values, info))
}

/// The single-option ranges again (for arguments built in code rather than parsed; the
/// currents are checked in [`axes_of`], against the vehicle) and the checks that involve several
/// options: `--factor-min <= --factor-max`, `--v-min-kmh <
/// --v-max-kmh`, at most [`MAX_CURRENTS`] currents and [`MAX_RUNS`] time-domain runs.
pub fn check(a: &SweepArgs) -> Result<()> {
    FACTOR.check("--factor-min", a.factor_min)?;
    FACTOR.check("--factor-max", a.factor_max)?;
    arg_range::SPEED_KMH.check("--v-min-kmh", a.v_min_kmh)?;
    arg_range::SPEED_KMH.check("--v-max-kmh", a.v_max_kmh)?;
    REF_AMPLITUDE_DEG.check("--ref-amplitude-deg", a.ref_amplitude_deg)?;
    DURATION_S.check("--duration-s", a.duration_s)?;
    KICK_DEG.check("--kick-deg", a.kick_deg)?;
    if a.damper_current_a.len() > MAX_CURRENTS {
        bail!(
            "--damper-current-a: {} values; allowed: at most {MAX_CURRENTS}",
            a.damper_current_a.len()
        );
    }
    if a.factor_max < a.factor_min {
        bail!(
            "--factor-min {} must not exceed --factor-max {}",
            a.factor_min,
            a.factor_max
        );
    }
    if a.v_max_kmh <= a.v_min_kmh {
        bail!(
            "--v-min-kmh {} must be below --v-max-kmh {}",
            a.v_min_kmh,
            a.v_max_kmh
        );
    }
    Ok(())
}
