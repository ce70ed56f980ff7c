//! shimmy-core: the `no_std`, heap-free code shared by the firmware and the host simulator:
//! plant linearisation and stability analysis, signal conditioning, the MR-damper controllers,
//! the eigenvalue-margin estimators, the shimmy monitor and the supervisor.
//!
//! Rules for everything in here: no heap, no panics on the control path, time is an input,
//! units are in the names.
#![cfg_attr(not(test), no_std)]
#![warn(missing_docs)]

#[macro_use]
mod fmt;

pub mod control;
pub mod eigen;
pub mod estimator;
pub mod monitor;
pub mod mr_damper;
pub mod params;
pub mod plant;
pub mod stability;

/// Crate version, reported by the firmware at boot and by the simulator in its reports.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
