//! shimmy-sim: the std host simulator around `shimmy-core`: parameter files, the nonlinear
//! plant, studies (stability, bifurcation, ...) and their reports.

pub mod damper_equiv;
pub mod paramfile;
pub mod stability_cmd;
