//! The dual-front-axle heavy truck: 8 DOF, two steered axles linked by a mid-shift transmission
//! (`docs/dual-axle-truck.md`).

mod linear;
mod params;
mod sets;
#[cfg(test)]
mod tests;

pub use linear::*;
pub use params::*;
pub use sets::*;
