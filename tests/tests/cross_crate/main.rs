//! The cross-crate tests, one test binary (`cargo test -p shimmy-tests --test cross_crate`; one
//! file's tests: `cargo test -p shimmy-tests --test cross_crate conformance::`). Each file used
//! to be a binary of its own that linked the simulator and the firmware library; one binary
//! compiles and links once.

mod architecture;
mod conformance;
mod eigen_vs_nalgebra;
mod failsafe_current;
mod hopf_bialternate;
mod linear_vs_nonlinear;
mod margin_model;
mod margin_pipeline;
mod scipy_reference;
mod workspace;
