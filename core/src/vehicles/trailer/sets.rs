//! The named sets of the trailer.

#[allow(unused_imports)]
use super::*;

use super::params::TrailerParams;

/// The named trailer parameter sets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TrailerSet {
    /// A laden single-axle touring caravan behind a car.
    Caravan,
}

impl TrailerSet {
    /// Every named set.
    pub const ALL: [TrailerSet; 1] = [TrailerSet::Caravan];

    /// The set's name (vehicle files, command lines).
    pub const fn name(self) -> &'static str {
        match self {
            TrailerSet::Caravan => "trailer",
        }
    }

    /// Looks a set up by name.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.name() == name)
    }

    /// The set's parameters.
    pub fn params(self) -> TrailerParams {
        match self {
            TrailerSet::Caravan => TrailerParams::reference(),
        }
    }
}

impl TrailerParams {
    /// The reference caravan, every value explained in `docs/trailer.md`.
    pub fn reference() -> Self {
        let m = 1400.0;
        // radius of gyration: a uniform 5.5 m x 2.3 m box has sqrt((5.5^2 + 2.3^2)/12) = 1.72 m;
        // end-heavy loading (gas locker at the nose, washroom at the back) puts it at 1.8 m
        let k_g = 1.8;
        let l = 4.3;
        // nose load 6 % of the laden mass (the towing clubs' 5-7 %)
        let nose_frac = 0.06;
        Self {
            m,
            i_z: m * k_g * k_g,
            l,
            a: (1.0 - nose_frac) * l,
            c_a_per_fz: 7.0,
            sigma: 0.4,
            k_y: 5.0e3,
            c_y: 1.0e3,
            l_d: 0.3,
            mu: 0.9,
            c_s: 1.3,
        }
    }
}
