//! shimmy-sim: the std host simulator around `shimmy-core`: parameter files, the nonlinear
//! plant, studies (stability, bifurcation, ...) and their reports.

pub mod bifurcation;
pub mod damper_equiv;
pub mod disturbance;
pub mod integrator;
pub mod margin_cmd;
pub mod paramfile;
pub mod plant;
pub mod stability_cmd;
