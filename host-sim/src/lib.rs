//! shimmy-sim: the std host simulator around `shimmy-core`.
pub use shimmy_core as core_lib;
