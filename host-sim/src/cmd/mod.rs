//! The command layer: one module per `shimmy-sim` subcommand (its clap arguments, its own
//! tables and its `command` entry point).
//!
//! Rule: a command uses `out`, `sim` and `model`, never another command.

pub mod analyze;
pub mod bifurcation;
pub mod compare;
pub mod demo;
pub mod device;
pub mod faults;
pub mod gas_charge;
pub mod identifiability;
pub mod margin;
pub mod meter_accuracy;
pub mod mismatch;
pub mod params;
pub mod pil;
pub mod reference_bench;
pub mod report;
pub mod run;
pub mod sensitivity;
pub mod stability;
pub mod sway_damping;
pub mod sweep;
pub mod vehicles;

use std::path::PathBuf;

/// `--vehicle` of the commands that run one vehicle of any model (`#[command(flatten)]`): one
/// argument with one help text that lists every named set of every model.
#[derive(clap::Args, Clone, Debug, PartialEq)]
pub struct VehicleArg {
    /// The vehicle: a named set or a vehicle file (the help lists the sets).
    #[arg(
        id = "vehicle",
        long = "vehicle",
        value_name = "VEHICLE",
        visible_alias = "params",
        default_value = "nominal",
        help = vehicle_help()
    )]
    pub spec: String,
}

impl VehicleArg {
    /// The vehicle `spec` (a set name or a file).
    pub fn new(spec: &str) -> Self {
        Self { spec: spec.into() }
    }
}

/// The help of `--vehicle`: every named set of every model (from the registry).
fn vehicle_help() -> String {
    format!(
        "Vehicle: a named set ({}) or a vehicle file (TOML, docs/vehicle-file.md); `shimmy-sim \
         vehicles` tabulates the sets. `--params` is the older name",
        crate::model::registry::all_set_names("; ")
    )
}

/// `--model-vehicle` of the commands that let the firmware believe another vehicle than the
/// simulated one (`#[command(flatten)]`): one argument with one help text that lists every
/// named set of every model. Each command resolves its own default ([`ModelVehicleArg::or`]).
#[derive(clap::Args, Clone, Debug, Default, PartialEq)]
pub struct ModelVehicleArg {
    /// The vehicle the firmware believes: a named set or a vehicle file (the help lists the
    /// sets); `None`: the command's own default.
    #[arg(
        id = "model_vehicle",
        long = "model-vehicle",
        value_name = "MODEL_VEHICLE",
        help = model_vehicle_help()
    )]
    pub spec: Option<String>,
}

impl ModelVehicleArg {
    /// The vehicle as given, if it was.
    pub fn given(&self) -> Option<&str> {
        self.spec.as_deref()
    }

    /// The vehicle as given, else the command's own `default`.
    pub fn or<'a>(&'a self, default: &'a str) -> &'a str {
        self.given().unwrap_or(default)
    }
}

/// The help of `--model-vehicle`: every named set of every model (from the registry).
fn model_vehicle_help() -> String {
    format!(
        "The vehicle the firmware believes (its controller's and estimator's models, gains, \
         thresholds): a named set ({}) or a vehicle file (TOML, docs/vehicle-file.md); default: \
         the command's own: --vehicle, or the scenario file's [model]",
        crate::model::registry::all_set_names("; ")
    )
}

/// `--out` of the commands that write files (`#[command(flatten)]`): one argument with one
/// help text. Each command resolves its own default folder ([`OutArg::dir_or`]), or writes
/// where its input says without it (`dir` is `None`).
#[derive(clap::Args, Clone, Debug, Default, PartialEq)]
pub struct OutArg {
    /// The output folder; `None`: the command's own default.
    #[arg(
        id = "out",
        long = "out",
        value_name = "OUT",
        help = "Output folder; default: the command's own: out/<command>, or the scenario \
                file's `output.dir` (run, pil: else out/<scenario name>, out/pil/<scenario \
                name>), or out/analyze/<log file name>"
    )]
    pub dir: Option<PathBuf>,
}

impl OutArg {
    /// `--out dir`.
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self {
            dir: Some(dir.into()),
        }
    }

    /// The folder as given, else the command's own `default`.
    pub fn dir_or(&self, default: &str) -> PathBuf {
        self.dir.clone().unwrap_or_else(|| default.into())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    /// One command's arguments as a whole command line.
    #[derive(Parser)]
    struct Cmd<A: clap::Args> {
        #[command(flatten)]
        a: A,
    }

    fn parse<A: clap::Args>(args: &[&str]) -> A {
        Cmd::<A>::try_parse_from(std::iter::once("shimmy-sim").chain(args.iter().copied()))
            .unwrap()
            .a
    }

    #[test]
    fn out_keeps_each_commands_default_folder() {
        let a: margin::MarginArgs = parse(&[]);
        assert_eq!(a.out_dir(), PathBuf::from("out/margin"));
        let a: sweep::args::SweepArgs = parse(&["--out", "x/y"]);
        assert_eq!(a.out_dir(), PathBuf::from("x/y"));
        let a: run::RunArgs = parse(&["s.toml"]);
        assert_eq!(a.out.dir, None, "run: the scenario file decides");
    }

    #[test]
    fn model_vehicle_defaults_to_the_commands_own() {
        let a: margin::MarginArgs = parse(&["--vehicle", "hard"]);
        assert_eq!(a.model_vehicle.or(&a.vehicle.spec), "hard");
        let a: margin::MarginArgs = parse(&["--vehicle", "hard", "--model-vehicle", "gentle"]);
        assert_eq!(a.model_vehicle.or(&a.vehicle.spec), "gentle");
        let a: run::RunArgs = parse(&["s.toml"]);
        assert_eq!(a.model_vehicle.given(), None);
    }

    #[test]
    fn mismatch_takes_its_vehicle_by_both_names() {
        let a: mismatch::MismatchArgs = parse(&[]);
        assert_eq!(a.model_vehicle.given(), Some("nominal"));
        let a: mismatch::MismatchArgs = parse(&["--vehicle", "hard"]);
        assert_eq!(a.model_vehicle.given(), Some("hard"));
        let a: mismatch::MismatchArgs = parse(&["--model-vehicle", "gentle"]);
        assert_eq!(a.model_vehicle.given(), Some("gentle"));
    }
}
