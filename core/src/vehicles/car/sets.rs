//! The named parameter sets of the car.

#[allow(unused_imports)]
use super::*;

use super::params::PlantParams;

/// The named parameter sets shipped with the project.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamSet {
    /// The reference vehicle.
    Nominal,
    /// Less steering-wheel damping (c_sw = 2.0): a narrower Hopf window.
    Gentle,
    /// Half the drag-link stiffness: a wide window at a lower frequency.
    Hard,
}

impl ParamSet {
    /// Every named set, in display order.
    pub const ALL: [ParamSet; 3] = [ParamSet::Nominal, ParamSet::Gentle, ParamSet::Hard];

    /// The set's name as used on command lines and in scenario files.
    pub const fn name(self) -> &'static str {
        match self {
            ParamSet::Nominal => "nominal",
            ParamSet::Gentle => "gentle",
            ParamSet::Hard => "hard",
        }
    }

    /// Looks a set up by name.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.name() == name)
    }

    /// The parameter values of this set.
    pub fn params(self) -> PlantParams {
        let nominal = PlantParams::nominal();
        match self {
            ParamSet::Nominal => nominal,
            ParamSet::Gentle => nominal.with(Param::CSw, 2.0),
            ParamSet::Hard => nominal.scaled(Param::KD, 0.5),
        }
    }
}

impl PlantParams {
    /// The nominal parameter set of the reference document.
    pub const fn nominal() -> Self {
        let l_t = 0.197;
        PlantParams {
            i_k: 4.54,
            i_p: 7.18,
            r: 0.372,
            h_r: 0.372,
            i_phi: 108.437,
            k_phi: 479_348.0,
            c_phi: 4000.0,
            c_a: 90_000.0,
            sigma: 0.60,
            e: 0.04,
            t_p: 0.04,
            l_t,
            // Track-rod axial stiffness 5e6 N/m referred to the kingpin through the arm.
            k_tr: 5.0e6 * l_t * l_t,
            k_d: 1.0e4,
            i_s: 16.0,
            j_sw: 0.04,
            c_sw: 3.0,
            c_k: 8.0,
            f_z: 6200.0,
            mu: 0.8,
            c_s: 1.3507,
        }
    }
}
