//! shimmy-sim: the std host simulator around `shimmy-core`. It runs the firmware's own control
//! and estimation code against a nonlinear steering plant and writes the studies' reports.
//!
//! Four layers, each a folder; a layer uses only the layers below it, and no command uses
//! another command:
//!
//! - [`model`]: what is simulated -- the plant, its integrator, disturbances, sensors, sensor
//!   and coil faults, the MR damper's viscous equivalent.
//! - [`sim`]: how it is run -- the closed and open loops, parameter and scenario files (the one
//!   [`sim::scenario::ScenarioSpec`]), the standard scenario set and the demo case.
//! - [`out`]: what is written -- plots, the Markdown/CSV report and the one file-name
//!   sanitiser.
//! - [`cmd`]: one module per `shimmy-sim` subcommand; `main.rs` only parses the command line
//!   and calls them.

pub mod cmd;
pub mod model;
pub mod out;
pub mod sim;
