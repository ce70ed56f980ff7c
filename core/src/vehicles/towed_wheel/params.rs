//! The towed wheel's parameters: a wheel yawing by `psi` about a vertical king pin that moves
//! straight at speed V, its centre the caster length `l` behind the pin, rolling on a
//! stretched-string tyre (Takács, Orosz & Stépán, "Delay effects in shimmy dynamics of wheels
//! with stretched string-like tyres", Eur. J. Mech. A/Solids 28 (2009) 516-525; every value's
//! source is in `docs/towed-wheel.md`).
//!
//! The tyre's contact line has lateral deformation `q(x, t)` over the patch `-a <= x <= a`
//! (x forward from the wheel centre). Its particles stick to the road in the patch (no
//! sliding), so the deformation travels backwards through it at V and the patch remembers the
//! wheel's motion for `2a / V`; outside the patch the string decays exponentially over the
//! relaxation length `sigma`. The tyre acts with a lateral stiffness `k` and damping `b` per
//! unit length. An optional steering damper acts at the lever `l_d` about the king pin.

#[allow(unused_imports)]
use super::*;
use crate::vehicles::fields::{FieldError, FieldTable, ModelField};

/// Physical parameters of the towed wheel (`docs/towed-wheel.md`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TowedWheelParams {
    /// Half length of the contact patch a, m.
    pub a: f64,
    /// Relaxation length of the stretched string sigma, m.
    pub sigma: f64,
    /// Lateral tyre stiffness per unit length k, N/m^2.
    pub k: f64,
    /// Lateral tyre damping per unit length b, N s/m^2.
    pub b: f64,
    /// Caster length l (king pin to wheel centre), m.
    pub l: f64,
    /// Yaw inertia of the wheel and fork about the king pin J_A, kg m^2.
    pub j_a: f64,
    /// Lever of a steering damper about the king pin l_d, m.
    pub l_d: f64,
    /// Vertical load on the wheel F_z, N (the simulator's friction limit only).
    pub f_z: f64,
    /// Tyre-road friction coefficient mu (the simulator's friction limit only).
    pub mu: f64,
}

impl TowedWheelParams {
    /// The dimensionless static yaw stiffness `K(L, Sigma) = L^2 + 1/3 + Sigma (L^2 + 1 +
    /// Sigma)` with `L = l / a`, `Sigma = sigma / a`: the standing tyre's yaw stiffness about
    /// the king pin is `2 k a^3 K`.
    pub fn stiffness_factor(&self) -> f64 {
        let (ll, ss) = (self.l / self.a, self.sigma / self.a);
        ll * ll + 1.0 / 3.0 + ss * (ll * ll + 1.0 + ss)
    }

    /// The standing tyre's yaw stiffness about the king pin `2 k a^3 K`, N m/rad.
    pub fn yaw_stiffness_nm_per_rad(&self) -> f64 {
        2.0 * self.k * self.a * self.a * self.a * self.stiffness_factor()
    }

    /// Natural angular frequency of the standing wheel's yaw on its tyre, rad/s.
    pub fn natural_frequency_radps(&self) -> f64 {
        libm::sqrt(self.yaw_stiffness_nm_per_rad() / self.j_a)
    }

    /// The benchmark's dimensionless speed `V / (2 a omega_n)`: the standing wheel's natural
    /// period against the contact patch's memory.
    pub fn dimensionless_speed(&self, v_mps: f64) -> f64 {
        v_mps / (2.0 * self.a * self.natural_frequency_radps())
    }

    /// The benchmark's tyre damping ratio `omega_n b / (2 k)`.
    pub fn damping_ratio(&self) -> f64 {
        self.natural_frequency_radps() * self.b / (2.0 * self.k)
    }

    /// The deformation at which the patch slides, m: the friction limit `mu F_z` spread over the
    /// string as a uniform deformation (`k q (2a + 2 sigma)`, the patch and both tails).
    pub fn sliding_deformation_m(&self) -> f64 {
        self.mu * self.f_z / (self.k * 2.0 * (self.a + self.sigma))
    }

    /// The yaw inertia that gives the natural frequency `omega_n_radps` at this geometry.
    pub fn inertia_for_frequency(&self, omega_n_radps: f64) -> f64 {
        self.yaw_stiffness_nm_per_rad() / (omega_n_radps * omega_n_radps)
    }
}

/// Every field of [`TowedWheelParams`], in the order of `docs/towed-wheel.md`'s table.
pub const TOWED_WHEEL_FIELDS: [ModelField; 9] = [
    ModelField::new("a", "m", 0.005, 0.5),
    ModelField::new("sigma", "m", 0.005, 2.0),
    ModelField::new("k", "N/m^2", 1.0e3, 1.0e8),
    ModelField::new("b", "N s/m^2", 0.0, 1.0e5),
    ModelField::new("l", "m", 0.0, 2.0),
    ModelField::new("j_a", "kg m^2", 1.0e-4, 1.0e3),
    ModelField::new("l_d", "m", 0.005, 1.0),
    ModelField::new("f_z", "N", 1.0, 1.0e5),
    ModelField::new("mu", "-", 0.05, 1.5),
];

impl FieldTable for TowedWheelParams {
    const FIELDS: &'static [ModelField] = &TOWED_WHEEL_FIELDS;

    fn field_mut(&mut self, name: &str) -> Option<&mut f64> {
        Some(match name {
            "a" => &mut self.a,
            "sigma" => &mut self.sigma,
            "k" => &mut self.k,
            "b" => &mut self.b,
            "l" => &mut self.l,
            "j_a" => &mut self.j_a,
            "l_d" => &mut self.l_d,
            "f_z" => &mut self.f_z,
            "mu" => &mut self.mu,
            _ => return None,
        })
    }
}

impl TowedWheelParams {
    /// Every field inside its range; the first offender.
    pub fn validate(&self) -> Result<(), FieldError> {
        self.check_ranges()
    }
}
