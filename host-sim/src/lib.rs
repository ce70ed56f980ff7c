//! shimmy-sim: the std host simulator around `shimmy-core`: parameter files, the nonlinear
//! plant, studies (stability, bifurcation, ...) and their reports.

pub mod bifurcation;
pub mod closed_loop;
pub mod compare;
pub mod damper_equiv;
pub mod demo;
pub mod disturbance;
pub mod fault_campaign;
pub mod faults;
pub mod integrator;
pub mod margin_cmd;
pub mod paramfile;
pub mod plant;
pub mod plot_util;
pub mod reference_bench;
pub mod report;
pub mod report_cmd;
pub mod run_cmd;
pub mod scenario_file;
pub mod sensors;
pub mod stability_cmd;
pub mod sweep;
pub mod sweep_td;
