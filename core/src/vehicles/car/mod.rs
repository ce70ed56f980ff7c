//! The car-class 4-DOF solid-axle steering plant with tyre lag (`docs/plant-model.md`).

pub mod board;
mod linear;
mod params;
mod sets;
#[cfg(test)]
mod tests;

pub use linear::*;
pub use params::*;
pub use sets::*;
