//! Running the model: the closed loop with the core's controller, open-loop plant runs, the one
//! [`scenario::ScenarioSpec`] (read from a scenario file by [`scenario_file`]) turned into a
//! loop configuration and run, the standard scenario set, the demo case, the margin-ramp runs
//! and the no-control reference line.

pub mod closed_loop;
pub mod demo_case;
pub mod margin_run;
pub mod open_loop;
pub mod reference;
pub mod scenario;
pub mod scenario_file;
pub mod standard;
