//! The mining truck's nonlinear plant (`docs/mining-truck.md`): the linear model of
//! `shimmy_core::truck` plus its two nonlinear elements, each added as its departure from its
//! linearisation so that the small-motion limit is the linear model exactly:
//!
//! - the tyres: Magic-Formula force `F = D sin(C_s atan(B a))` of the lagged slip (`D = mu F_z`,
//!   `B = C_a / (C_s D)`: slope C_a at 0, saturating at D) in place of `C_a a`, in the yaw, roll
//!   and lateral equations;
//! - the struts: the polytropic gas springs `Hps::force_n` at the strokes `x_s +- (s/2) phi`
//!   (left strut compressed by positive roll) in place of their linear roll stiffness: the
//!   large-stroke stiffening of the gas.
//!
//! Fixed-step RK4 at 1 ms (the stiffest mode, the linkage at ~46 Hz, is far inside its
//! stability limit).

use nalgebra::SVector;
use shimmy_core::model::{LinearModel, Matrix};
use shimmy_core::truck::{
    TruckOperatingPoint, TruckParams, A_L, A_R, DPHI, DPSI_L, DPSI_R, DY, N_STATES, PHI,
};

use super::integrator::rk4_step;

/// Integration step, s.
pub const DT_S: f64 = 1e-3;

/// The truck at a constant speed, damper off.
pub struct TruckSim {
    t: TruckParams,
    op: TruckOperatingPoint,
    a: Matrix<N_STATES>,
    /// Time, s.
    pub time_s: f64,
    /// State (the linear model's order).
    pub x: [f64; N_STATES],
}

impl TruckSim {
    /// A simulation of `t` at `v_mps` from the state `x0`; fails when the struts cannot carry
    /// the load.
    pub fn new(
        t: &TruckParams,
        v_mps: f64,
        x0: [f64; N_STATES],
    ) -> Result<Self, shimmy_core::truck::HpsError> {
        Ok(Self {
            t: *t,
            op: t.operating_point()?,
            a: t.linearise(v_mps, 0.0),
            time_s: 0.0,
            x: x0,
        })
    }

    /// The tyre's lateral force at lagged slip `a`, N.
    pub fn tyre_force_n(&self, a: f64) -> f64 {
        let d = self.t.mu * self.op.f_z;
        let b = self.op.c_a / (self.t.c_s * d);
        d * (self.t.c_s * (b * a).atan()).sin()
    }

    /// The struts' roll moment on the axle at roll `phi`, N m (restoring), from the gas law.
    pub fn strut_roll_moment_nm(&self, phi: f64) -> f64 {
        let half_s = 0.5 * self.t.strut_spacing;
        let x_s = self.op.strut.stroke_m;
        let (f_l, f_r) = (
            self.t.hps.force_n(x_s + half_s * phi),
            self.t.hps.force_n(x_s - half_s * phi),
        );
        -half_s * (f_l - f_r)
    }

    fn rhs(&self, x: &[f64; N_STATES], dx: &mut [f64; N_STATES]) {
        let xv = SVector::<f64, N_STATES>::from_column_slice(x);
        let lin = self.a * xv;
        dx.copy_from_slice(lin.as_slice());
        let t = &self.t;
        let lever = t.e + t.t_p;
        // tyres: nonlinear force minus the linear C_a a already in A
        for (slip, wheel) in [(A_L, DPSI_L), (A_R, DPSI_R)] {
            let extra = self.tyre_force_n(x[slip]) - self.op.c_a * x[slip];
            dx[wheel] -= lever * extra / t.i_k;
            dx[DPHI] += t.h_r * extra / t.i_phi;
            dx[DY] += extra / t.m_axle;
        }
        // struts: the gas law's moment minus the linear strut part of K_phi in A
        let half_s = 0.5 * t.strut_spacing;
        let linear_struts = -2.0 * self.op.strut.stiffness_npm * half_s * half_s * x[PHI];
        dx[DPHI] += (self.strut_roll_moment_nm(x[PHI]) - linear_struts) / t.i_phi;
    }

    /// Advances by `duration_s` in steps of [`DT_S`], calling `each(time, state)` after every
    /// step.
    pub fn run(&mut self, duration_s: f64, mut each: impl FnMut(f64, &[f64; N_STATES])) {
        let n = (duration_s / DT_S).round() as usize;
        for _ in 0..n {
            let mut f = |_t: f64, y: &[f64; N_STATES], dy: &mut [f64; N_STATES]| self.rhs(y, dy);
            let mut x = self.x;
            rk4_step(&mut f, self.time_s, &mut x, DT_S);
            self.x = x;
            self.time_s += DT_S;
            each(self.time_s, &self.x);
        }
    }
}

/// Growth rate of the wheel-yaw envelope, 1/s: the log ratio of the largest |psi_L + psi_R|/2
/// in the last and the first `window_s` after `settle_s` (fast modes decayed), over their
/// distance in time.
pub fn envelope_growth_1ps(
    t: &TruckParams,
    v_mps: f64,
    x0: [f64; N_STATES],
    settle_s: f64,
    duration_s: f64,
    window_s: f64,
) -> Result<f64, shimmy_core::truck::HpsError> {
    let mut sim = TruckSim::new(t, v_mps, x0)?;
    let (mut first, mut last) = (0.0_f64, 0.0_f64);
    let (w0, w1) = (settle_s + window_s, duration_s - window_s);
    sim.run(duration_s, |time, x| {
        let yaw = (0.5 * (x[0] + x[1])).abs();
        if time > settle_s && time <= w0 {
            first = first.max(yaw);
        }
        if time > w1 {
            last = last.max(yaw);
        }
    });
    Ok((last / first).ln() / (w1 - settle_s))
}

/// A small in-phase wheel-yaw start, rad (both wheels).
pub fn yaw_start(psi_rad: f64) -> [f64; N_STATES] {
    let mut x = [0.0; N_STATES];
    x[0] = psi_rad;
    x[1] = psi_rad;
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use shimmy_core::truck::TruckSet;

    /// Both nonlinear elements have the linear model's slope at 0 and depart from it at large
    /// motion in the physical direction (the tyre saturates, the gas stiffens).
    #[test]
    fn the_nonlinear_elements_linearise_to_the_model() {
        let t = TruckSet::Full.params();
        let sim = TruckSim::new(&t, 8.0, [0.0; N_STATES]).unwrap();
        let h = 1e-7;
        let slope = (sim.tyre_force_n(h) - sim.tyre_force_n(-h)) / (2.0 * h);
        assert!((slope - sim.op.c_a).abs() < 1e-6 * sim.op.c_a);
        assert!(sim.tyre_force_n(0.3) < 0.5 * sim.op.c_a * 0.3);
        let half_s = 0.5 * t.strut_spacing;
        let k_lin = 2.0 * sim.op.strut.stiffness_npm * half_s * half_s;
        let m_slope = -(sim.strut_roll_moment_nm(h) - sim.strut_roll_moment_nm(-h)) / (2.0 * h);
        assert!((m_slope - k_lin).abs() < 1e-5 * k_lin, "{m_slope} {k_lin}");
        assert_eq!(sim.strut_roll_moment_nm(0.0), 0.0);
        // 2 deg of roll: the gas spring's moment exceeds the linear one
        let phi = 2.0_f64.to_radians();
        assert!(-sim.strut_roll_moment_nm(phi) > 1.001 * k_lin * phi);
    }
}
