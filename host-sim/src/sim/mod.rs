//! The simulation layer: runs the model -- the closed loop with the core's controller, open-loop
//! plant runs, vehicle and scenario files (the one [`scenario::ScenarioSpec`], turned into a
//! loop configuration and run), the standard scenario set, the demo case and the allowed ranges
//! of the commands' numeric options.
//!
//! Rule: uses only `model` (and `shimmy-core`), never `out` or `cmd`.

pub mod analyze;
pub mod arg_range;
pub mod closed_loop;
pub mod demo_case;
pub mod log_file;
pub mod margin_run;
pub mod open_loop;
pub mod reference;
pub mod scenario;
pub mod scenario_file;
pub mod standard;
pub mod vehicle_file;
