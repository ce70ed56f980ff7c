//! Trailer sway: 2 DOF on a laterally compliant hitch (`docs/trailer.md`).

mod linear;
mod params;
mod sets;
#[cfg(test)]
mod tests;

pub use linear::*;
pub use params::*;
pub use sets::*;
