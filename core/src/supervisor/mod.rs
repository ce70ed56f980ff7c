//! Supervisor: validates every raw sensor frame (1 kHz), keeps fault records, and decides the
//! damper's operating mode. [`safe_controller::SafeController`] combines it with the
//! [`Controller`](crate::control::Controller) so that, whatever the sensors deliver, the coil
//! command is finite, between i_min and i_max, and in a known safe state when the inputs cannot
//! be trusted (`docs/control-and-supervisor.md`).
//!
//! ```text
//! RawFrame --checks--> detected faults --hysteresis / latches--> active FaultSet --policy-->
//!   SupervisorVerdict { mode: Normal | Degraded | FailSafe, safe_current_a, faults }
//! SafeController: verdict + Controller::step(sanitised input) --> final clamp + slew --> I_cmd
//! ```
//!
//! The modules, in the order a frame passes through them:
//! - [`frame`]: what comes in ([`frame::RawFrame`], [`frame::MarginStatus`]);
//! - [`params`]: the thresholds ([`params::SupervisorParams`]);
//! - [`faults`]: fault kinds, sets and records ([`faults::FaultKind`], [`faults::FaultSet`]);
//! - [`checks`]: the [`checks::Supervisor`]: per-frame checks, hysteresis, latches, event log;
//!   `motion`: the wheel-yaw oscillation that proves the vehicle rolls, for two of the checks;
//! - [`policy`]: active faults to mode and safe current ([`policy::SupervisorVerdict`]);
//! - [`safe_controller`]: supervisor + controller + final limiter, the one call per 1 ms.

pub mod checks;
pub mod faults;
pub mod frame;
mod motion;
pub mod params;
pub mod policy;
pub mod safe_controller;

#[cfg(test)]
mod tests;
