//! shimmy-core: the `no_std`, heap-free code shared by the firmware and the host simulator
//! (`docs/architecture.md`). The modules, lowest layer first (each uses only those above it):
//!
//! - [`sqrt`]: the correctly rounded f32 square root on the FPU (libm's off the target);
//! - [`trig`]: f32 sine, cosine and tangent with libm's bits up to 2^28 pi/2 (no huge-argument
//!   reduction linked);
//! - [`units`]: unit conversions and physical constants;
//! - [`model`]: the vehicle-model family: the trait a linear steering model with N states
//!   implements (A(V), dA/dV, damper input, measured output, mode shapes);
//! - [`vehicles`]: the models of the family, one folder each (car, mining truck, trailer,
//!   dual-axle truck), laid out alike;
//! - [`eigen`]: bounded eigenvalue solver and shimmy-mode classification of A(V);
//! - [`stability`]: stability over speed: Hopf crossings and critical speeds (any model);
//! - [`mr_damper`]: the Spencer model of the MR steering damper (the simulator's damper);
//! - [`control`]: signal conditioning, the invertible damper model, the actuator path and the
//!   controllers (`docs/control-and-supervisor.md`);
//! - [`estimator`]: the margin path: mode meter, model margin, fusion, monitor, pipeline
//!   (`docs/margin-estimator.md`);
//! - [`supervisor`]: sensor-frame checks, faults, mode policy, and the supervised controller
//!   the firmware and the simulator call every 1 ms;
//! - [`vehicle`]: one vehicle (plant, damper, sensors, gains, thresholds) with one validation by
//!   plausible range; the controller's and the estimator's parameters are derived from it.
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
pub mod float;
pub mod model;
pub mod mr_damper;
pub mod sqrt;
pub mod stability;
pub mod trig;
pub mod units;
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
#[cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]
pub mod vehicle;
#[cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]
pub mod vehicles;

/// Crate version, reported by the firmware at boot and by the simulator in its reports.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
