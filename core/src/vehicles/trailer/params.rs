//! Trailer sway: a 2-DOF single-axle trailer (lateral and yaw motion) on a laterally compliant
//! hitch, after Diboll & Hagen, "Lateral stability of a highway or rail trailer" (J. Eng. Ind.
//! 91(4), 1969, 1069-1074), who found the sway a self-excited vibration governed by the lateral
//! springing at the towing pivot (`docs/trailer.md`; every number's source or reasoning is
//! there).
//!
//! The tow vehicle runs straight at V; the hitch (ball) is held to its path by a lateral spring
//! `k_y` and damper `c_y` (Diboll & Hagen's springing at the towing pivot; for a car-towed
//! caravan, the car's lateral compliance at the ball). Degrees of freedom `q = [y, psi]`:
//! - `y`: lateral displacement of the hitch from the tow path, m, positive to the left;
//! - `psi`: trailer yaw, rad, positive nose left; the tow vehicle does not yaw in this model, so
//!   `psi` is also the hitch (articulation) angle the sway damper and the sensor see.
//!
//! The trailer (mass `m`, yaw inertia `i_z` about its centre of gravity) has its centre of
//! gravity `a` and its axle `l` behind the hitch (nose load `m g (l - a) / l`). State vector (5):
//! `x = [y, psi, y', psi', alpha]` with the axle's lagged slip angle `alpha` (tyre force
//! `F = C_a alpha` to the left, relaxation length `sigma`):
//! `sigma alpha' = V (psi - alpha) - (y' - l psi')` (the axle's lateral velocity is
//! `y' - l psi'`). The lag keeps A(V) affine in V, as the family's trait requires (the lag-free
//! tyre's `1/V` damping is not), and it is physical: a trailer tyre's relaxation length is a
//! sizeable share of the sway's ~25-40 m wavelength.
//!
//! The damper is a sway-control damper at the hitch: a linear damper between the tow bar and
//! the drawbar at the lateral lever `l_d` from the ball, stroke rate `l_d psi'`, so its force
//! `F_d` puts the yaw moment `-l_d F_d` on the trailer (torsional coefficient `c l_d^2`).

#[allow(unused_imports)]
use super::*;
use crate::vehicles::fields::{FieldError, FieldTable, ModelField};

use crate::units::G_MPS2;

/// Physical parameters of the trailer and its hitch (`docs/trailer.md`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrailerParams {
    /// Laden trailer mass m, kg.
    pub m: f64,
    /// Yaw inertia about the centre of gravity I_z, kg m^2.
    pub i_z: f64,
    /// Hitch to axle l (Diboll & Hagen's length s in the Strouhal number), m.
    pub l: f64,
    /// Hitch to centre of gravity a (< l: a positive nose load), m.
    pub a: f64,
    /// Cornering stiffness of the axle (both tyres) per unit axle load C_a / F_z, 1/rad.
    pub c_a_per_fz: f64,
    /// Tyre relaxation length sigma, m.
    pub sigma: f64,
    /// Lateral stiffness of the hitch against the tow path k_y, N/m.
    pub k_y: f64,
    /// Lateral damping of the hitch against the tow path c_y, N s/m.
    pub c_y: f64,
    /// Lateral lever of the sway damper from the ball l_d, m.
    pub l_d: f64,
    /// Tyre-road friction coefficient mu (the simulator's tyre: peak force mu F_z).
    pub mu: f64,
    /// Magic-Formula shape factor C_s of the simulator's tyre.
    pub c_s: f64,
}

impl TrailerParams {
    /// Static load on the axle (both tyres) F_z = m g a / l, N.
    pub fn axle_load_n(&self) -> f64 {
        self.m * G_MPS2 * self.a / self.l
    }

    /// Static nose load on the hitch m g (l - a) / l, N (negative: a tail-heavy trailer).
    pub fn nose_load_n(&self) -> f64 {
        self.m * G_MPS2 * (self.l - self.a) / self.l
    }

    /// Cornering stiffness of the axle C_a = (C_a/F_z) F_z, N/rad.
    pub fn cornering_stiffness(&self) -> f64 {
        self.c_a_per_fz * self.axle_load_n()
    }

    /// Yaw inertia about the hitch I_z + m a^2, kg m^2.
    pub fn i_hitch(&self) -> f64 {
        self.i_z + self.m * self.a * self.a
    }

    /// Natural frequency of the hitch's lateral springing sqrt(k_y / m), rad/s (the omega of
    /// the Strouhal number, `docs/trailer.md`).
    pub fn hitch_omega_radps(&self) -> f64 {
        libm::sqrt(self.k_y / self.m)
    }

    /// Diboll & Hagen's Strouhal number s omega / V with s = l and omega the hitch frequency.
    pub fn strouhal(&self, v_mps: f64) -> f64 {
        self.l * self.hitch_omega_radps() / v_mps
    }

    /// Diboll & Hagen's energy term mu G z / V^2 with mu = C_a/F_z, G = g and z = a:
    /// `C_a l / (m V^2)`, the tyres' yaw stiffness about the hitch over the kinetic energy.
    pub fn energy_term(&self, v_mps: f64) -> f64 {
        self.c_a_per_fz * G_MPS2 * self.a / (v_mps * v_mps)
    }

    /// Damping ratio of a sway damper of coefficient `c_nspm`: its torsional coefficient
    /// `c l_d^2` over `2 I_hitch omega` (the hitch frequency).
    pub fn damper_zeta(&self, c_nspm: f64) -> f64 {
        c_nspm * self.l_d * self.l_d / (2.0 * self.i_hitch() * self.hitch_omega_radps())
    }

    /// The sway damper coefficient of damping ratio `zeta` ([`Self::damper_zeta`]'s inverse),
    /// N s/m.
    pub fn damper_of_zeta(&self, zeta: f64) -> f64 {
        zeta * 2.0 * self.i_hitch() * self.hitch_omega_radps() / (self.l_d * self.l_d)
    }
}

/// Every field of [`TrailerParams`], in the order of `docs/trailer.md`'s table.
pub const TRAILER_FIELDS: [ModelField; 11] = [
    ModelField::new("m", "kg", 1.0, 20000.0),
    ModelField::new("i_z", "kg m^2", 0.01, 500000.0),
    ModelField::new("l", "m", 0.1, 15.0),
    ModelField::new("a", "m", 0.05, 15.0),
    ModelField::new("c_a_per_fz", "1/rad", 0.5, 30.0),
    ModelField::new("sigma", "m", 0.001, 3.0),
    ModelField::new("k_y", "N/m", 1.0, 100000000.0),
    ModelField::new("c_y", "N s/m", 0.0, 1000000.0),
    ModelField::new("l_d", "m", 0.01, 2.0),
    ModelField::new("mu", "-", 0.05, 1.5),
    ModelField::new("c_s", "-", 0.5, 3.0),
];

/// Why a trailer parameter set is rejected.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum TrailerFieldError {
    /// A field unknown or out of its range.
    #[error(transparent)]
    Field(#[from] FieldError),
    /// The centre of gravity is too far behind the axle for a single-axle trailer on a ball.
    #[error(
        "field `a` = {a} m: the centre of gravity must lie ahead of 1.5 l = {max:.3} m (at most a \
         tail load of half the mass on the hitch)"
    )]
    TailHeavy {
        /// Hitch to centre of gravity, m.
        a: f64,
        /// 1.5 l, m.
        max: f64,
    },
}

impl FieldTable for TrailerParams {
    const FIELDS: &'static [ModelField] = &TRAILER_FIELDS;

    fn field_mut(&mut self, name: &str) -> Option<&mut f64> {
        Some(match name {
            "m" => &mut self.m,
            "i_z" => &mut self.i_z,
            "l" => &mut self.l,
            "a" => &mut self.a,
            "c_a_per_fz" => &mut self.c_a_per_fz,
            "sigma" => &mut self.sigma,
            "k_y" => &mut self.k_y,
            "c_y" => &mut self.c_y,
            "l_d" => &mut self.l_d,
            "mu" => &mut self.mu,
            "c_s" => &mut self.c_s,
            _ => return None,
        })
    }
}

impl TrailerParams {
    /// Every field inside its range, and a centre of gravity ahead of 1.5 l; the first
    /// offender.
    pub fn validate(&self) -> Result<(), TrailerFieldError> {
        self.check_ranges()?;
        let max = 1.5 * self.l;
        if self.a > max {
            return Err(TrailerFieldError::TailHeavy { a: self.a, max });
        }
        Ok(())
    }
}
