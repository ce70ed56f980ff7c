//! The simulation layer: runs the model -- the closed loop with the core's controller, open-loop
//! plant runs, vehicle and scenario files (the one [`scenario::ScenarioSpec`], turned into a
//! loop configuration and run), the standard scenario set, the demo case, the host link to a device (a board, QEMU or the in-process simulated device), the allowed ranges
//! of the commands' numeric options, and the one way files are read and written ([`files`]).
//!
//! Rule: uses only `model` (and `shimmy-core`; `pil` also the firmware's host-compilable
//! application and the PIL frames), never `out` or `cmd`.

pub mod analyze;
pub mod arg_range;
pub mod closed_loop;
pub mod demo_case;
pub mod device_link;
pub mod dual_axle_study;
pub mod files;
pub mod log_file;
pub mod margin_run;
pub mod open_loop;
pub mod pil;
pub mod reference;
pub mod scenario;
pub mod scenario_file;
pub mod sim_device;
pub mod standard;
pub mod trailer_study;
pub mod truck_study;
pub mod vehicle_file;
