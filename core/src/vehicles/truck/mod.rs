//! The heavy mining dump truck (5 DOF, hydro-pneumatic struts; `docs/mining-truck.md`).

pub mod board;
mod linear;
mod params;
mod sets;
#[cfg(test)]
mod tests;

pub use linear::*;
pub use params::*;
pub use sets::*;
