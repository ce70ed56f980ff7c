//! shimmy-sim: the std host simulator around `shimmy-core`. It runs the firmware's own control
//! and estimation code against a nonlinear steering plant and writes the studies' reports.
//!
//! Four layers, each a folder; a layer uses only the layers below it, and no command uses
//! another command:
//!
//! - [`model`]: what is simulated -- the plant, its integrator, disturbances, sensors, sensor
//!   and coil faults, the MR damper's viscous equivalent.
//! - [`sim`]: how it is run, one folder per concern -- what the user hands in (vehicle and
//!   scenario files, option ranges), the closed and open loops (the one
//!   [`sim::run::scenario::ScenarioSpec`]), the device link and PIL, the one-model studies.
//! - [`out`]: what is written -- plots, the Markdown/CSV report and the one file-name
//!   sanitiser.
//! - [`cmd`]: one module per `shimmy-sim` subcommand; `main.rs` only parses the command line
//!   and calls them.

pub mod cmd;
pub mod model;
pub mod out;
pub mod sim;
