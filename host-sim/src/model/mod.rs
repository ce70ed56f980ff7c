//! The model layer: the simulated physical system and its sensors -- the nonlinear plant and
//! its integrators, the road/driver disturbances, the sensor models, injected faults and the MR
//! damper's equivalent viscous coefficient.
//!
//! Rule: uses only `shimmy-core` and external crates, never `sim`, `out` or `cmd`.

pub mod board;
pub mod car_plant;
pub mod coil_drive;
pub mod damper_equiv;
pub mod damper_sizing;
pub mod disturbance;
pub mod dual_axle_plant;
pub mod family;
pub mod faults;
pub mod hopf_type;
pub mod integrator;
pub mod periodic_orbit;
pub mod plant;
pub mod registry;
pub mod sensors;
pub mod study;
pub mod towed_wheel_plant;
pub mod trailer_plant;
pub mod truck_plant;
pub mod tyre;
