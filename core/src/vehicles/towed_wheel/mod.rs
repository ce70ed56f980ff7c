//! The towed wheel with a stretched-string tyre: the public shimmy benchmark of Takács, Orosz &
//! Stépán (`docs/towed-wheel.md`): one wheel yawing about a vertical king pin, its tyre's
//! contact patch a delay (memory) of length `2a / V`.

mod linear;
mod params;
mod sets;
#[cfg(test)]
mod tests;

pub use linear::*;
pub use params::*;
pub use sets::*;
