//! The studies that only one model supports: the mining truck's gas charge, the trailer's sway
//! damping and the dual-axle truck's axle coupling.

pub mod dual_axle_study;
pub mod trailer_study;
pub mod truck_study;
