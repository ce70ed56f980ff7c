//! The simulation layer, by concern: what the user hands in ([`input`]: files, vehicle and
//! scenario files, option ranges), running the model ([`run`]: closed and open loop, scenarios,
//! the demo), the link to a device and PIL ([`device`]), the one-model studies ([`study`]) and
//! the analysis of a measured log ([`analyze`]).
//!
//! Rule: uses only `model` (and `shimmy-core`; `pil` also the firmware's host-compilable
//! application and the PIL frames), never `out` or `cmd`.

pub mod analyze;
pub mod device;
pub mod input;
pub mod run;
pub mod study;
