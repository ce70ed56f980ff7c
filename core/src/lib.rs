//! shimmy-core: the `no_std`, heap-free code shared by the firmware and the host simulator:
//! plant linearisation and stability analysis, signal conditioning, the MR-damper controllers,
//! the eigenvalue-margin estimators, the shimmy monitor and the supervisor.
//!
//! Rules for everything in here: no heap, no panics on the control path, time is an input,
//! units are in the names.
#![cfg_attr(not(test), no_std)]

#[macro_use]
mod fmt;

#[cfg_attr(
    not(test),
    deny(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::indexing_slicing
    )
)]
pub mod control;
pub mod eigen;
// The estimator's fixed-size numeric kernels index arrays in loops bounded by their capacity;
// that those bounds checks can never fire is shown by the panic-free link check
// (firmware/src/bin/panic-free-check.rs), not by this lint.
#[cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]
pub mod estimator;
pub mod mr_damper;
pub mod params;
pub mod plant;
pub mod stability;
// Control path: panic-free by lint (tests may unwrap/index).
#[cfg_attr(
    not(test),
    deny(
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic,
        clippy::indexing_slicing
    )
)]
pub mod supervisor;

/// Crate version, reported by the firmware at boot and by the simulator in its reports.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
