//! The MR steering damper as the simulator models it: Spencer et al. (1997) modified Bouc-Wen
//! model with a first-order coil lag (`docs/plant-model.md`).
//!
//! This is the *plant's* damper: the simulator integrates it and the firmware's simple invertible
//! model is fitted to it. The firmware never calls it (so it is not linked there). It lives in
//! `core` so both the simulator and the fitting tests use one definition.
//!
//! The model is stiff (beta ~ 2e6 m^-2): integrate it with sub-steps or an implicit method.

/// Parameters of the modified Bouc-Wen model. Units: N, m, s, V (1 V per A of coil current).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpencerParams {
    /// Viscous coefficient c0 = c0a + c0b u: c0a, N s/m.
    pub c0a: f64,
    /// c0b [N s/(m V)].
    pub c0b: f64,
    /// Internal stiffness k0, N/m.
    pub k0: f64,
    /// Viscous coefficient c1 = c1a + c1b u: c1a, N s/m.
    pub c1a: f64,
    /// c1b [N s/(m V)].
    pub c1b: f64,
    /// Accumulator stiffness k1, N/m.
    pub k1: f64,
    /// Accumulator initial displacement x0, m.
    pub x0: f64,
    /// Evolutionary coefficient alpha = alpha_a + alpha_b u: alpha_a, N/m.
    pub alpha_a: f64,
    /// alpha_b [N/(m V)].
    pub alpha_b: f64,
    /// Hysteresis shape gamma, m^-2.
    pub gamma: f64,
    /// Hysteresis shape beta, m^-2.
    pub beta: f64,
    /// Hysteresis scale A.
    pub a_bw: f64,
    /// Hysteresis exponent n.
    pub n: f64,
    /// Coil + driver bandwidth eta, 1/s.
    pub eta: f64,
    /// Largest coil input u, V (= A).
    pub u_max: f64,
}

/// Force coefficients of the automotive-size calibration are scaled by this factor to make a
/// steering-damper-sized device (`docs/plant-model.md`).
pub const STEERING_DAMPER_FORCE_SCALE: f64 = 0.25;

impl SpencerParams {
    /// The calibrated automotive damper (MTS dyno calibration), unscaled.
    pub const fn automotive() -> Self {
        SpencerParams {
            c0a: 784.0,
            c0b: 1803.0,
            k0: 3610.0,
            c1a: 14649.0,
            c1b: 34622.0,
            k1: 840.0,
            x0: 0.0,
            alpha_a: 12441.0,
            alpha_b: 38430.0,
            gamma: 136_320.0,
            beta: 2_059_020.0,
            a_bw: 58.0,
            n: 2.0,
            eta: 190.0,
            u_max: 2.0,
        }
    }

    /// The steering damper of the reference plant: the automotive calibration with every force
    /// coefficient scaled by [`STEERING_DAMPER_FORCE_SCALE`].
    pub const fn steering() -> Self {
        let s = STEERING_DAMPER_FORCE_SCALE;
        let a = Self::automotive();
        SpencerParams {
            c0a: a.c0a * s,
            c0b: a.c0b * s,
            k0: a.k0 * s,
            c1a: a.c1a * s,
            c1b: a.c1b * s,
            k1: a.k1 * s,
            alpha_a: a.alpha_a * s,
            alpha_b: a.alpha_b * s,
            ..a
        }
    }

    /// (alpha(u), c0(u), c1(u)) at coil input `u`, V.
    pub fn coefficients(&self, u: f64) -> (f64, f64, f64) {
        (
            self.alpha_a + self.alpha_b * u,
            self.c0a + self.c0b * u,
            self.c1a + self.c1b * u,
        )
    }
}

/// Internal states of the damper model.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SpencerState {
    /// Filtered coil input u, V.
    pub u: f64,
    /// Internal displacement y, m.
    pub y: f64,
    /// Evolutionary (hysteretic) variable z, m.
    pub z: f64,
}

/// Time derivatives of [`SpencerState`] and the damper force at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpencerRates {
    /// du/dt, V/s.
    pub du: f64,
    /// dy/dt, m/s.
    pub dy: f64,
    /// dz/dt, m/s.
    pub dz: f64,
    /// Damper force F in N, positive when resisting a positive stroke rate.
    pub force_n: f64,
}

/// Evaluates the model: state derivatives and force for stroke `x_m`, stroke rate `v_mps` and
/// commanded coil input `u_cmd`, V (clamped to [0, u_max]).
pub fn rates(
    p: &SpencerParams,
    s: &SpencerState,
    x_m: f64,
    v_mps: f64,
    u_cmd: f64,
) -> SpencerRates {
    let u_cmd = u_cmd.clamp(0.0, p.u_max);
    let du = -p.eta * (s.u - u_cmd);
    let (alpha, c0, c1) = p.coefficients(s.u);
    let dy = (alpha * s.z + c0 * v_mps + p.k0 * (x_m - s.y)) / (c0 + c1);
    let rel = v_mps - dy;
    let abs_z = libm::fabs(s.z);
    // |z|^n and |z|^(n-1) z; n = 2 is the common case and avoids pow.
    let (z_n, z_n1_z) = if p.n == 2.0 {
        (abs_z * abs_z, abs_z * s.z)
    } else {
        (libm::pow(abs_z, p.n), libm::pow(abs_z, p.n - 1.0) * s.z)
    };
    let dz = p.a_bw * rel - p.beta * rel * z_n - p.gamma * libm::fabs(rel) * z_n1_z;
    let force_n = c1 * dy + p.k1 * (x_m - p.x0);
    SpencerRates {
        du,
        dy,
        dz,
        force_n,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steering_damper_is_the_scaled_calibration() {
        let a = SpencerParams::automotive();
        let s = SpencerParams::steering();
        assert_eq!(s.c1a, a.c1a * 0.25);
        assert_eq!(s.alpha_b, a.alpha_b * 0.25);
        assert_eq!(s.beta, a.beta);
        assert_eq!(s.eta, a.eta);
    }

    #[test]
    fn at_rest_there_is_no_force_and_no_motion() {
        let p = SpencerParams::steering();
        let r = rates(&p, &SpencerState::default(), 0.0, 0.0, 0.0);
        assert_eq!((r.du, r.dy, r.dz, r.force_n), (0.0, 0.0, 0.0, 0.0));
    }

    #[test]
    fn coil_input_is_clamped_and_lags() {
        let p = SpencerParams::steering();
        let r = rates(&p, &SpencerState::default(), 0.0, 0.0, 5.0);
        assert_eq!(r.du, p.eta * p.u_max);
    }

    #[test]
    fn force_resists_motion_and_grows_with_current() {
        // Steady sliding (z at its plateau, dy from the quasi-static balance) resists the motion.
        let p = SpencerParams::steering();
        let v = 0.05;
        let force_at = |u: f64| {
            let z_ss = libm::sqrt(p.a_bw / (p.beta + p.gamma)); // plateau of z for rel > 0
            let s = SpencerState { u, y: 0.0, z: z_ss };
            rates(&p, &s, 0.0, v, u).force_n
        };
        assert!(force_at(0.0) > 0.0);
        assert!(force_at(2.0) > 2.0 * force_at(0.0));
    }
}
