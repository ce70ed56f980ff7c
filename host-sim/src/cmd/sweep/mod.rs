//! `shimmy-sim sweep`: stability maps over speed x one parameter. Two independent variants
//! share only their arguments and grid axes.
//!
//! Rule: `eigen` and `time_domain` use `args`, never each other or this file.

pub mod args;
pub mod eigen;
pub mod time_domain;
