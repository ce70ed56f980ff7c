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
