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
