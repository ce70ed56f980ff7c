//! The trailer's nonlinear plant (`docs/trailer.md`): the linear model of `shimmy_core::trailer`
//! with the tyres' saturation added as its departure from the linearisation, so that the
//! small-motion limit is the linear model exactly: the Magic-Formula force
//! `F = D sin(C_s atan(B alpha))` of the lagged slip (`D = mu F_z`, `B = C_a / (C_s D)`: slope
//! C_a at 0, saturating at D) in place of `C_a alpha` in both equations of motion. The sway
//! damper is the linear viscous one of the model (coefficient `c_damper_nspm`).
//!
//! Fixed-step RK4 at 2 ms: the fastest pole, the tyre lag's `-V / sigma`, is at most
//! 70 / 0.4 = 175 1/s at the top speed of the named set, 0.35 per step (RK4's real-axis limit
//! is 2.8).

use nalgebra::SVector;
use shimmy_core::model::{LinearModel, Matrix};
use shimmy_core::trailer::{TrailerParams, ALPHA, DPSI, DY, N_STATES, PSI};

use super::integrator::rk4_step;

/// Integration step, s.
pub const DT_S: f64 = 2e-3;

/// The trailer at a forward speed (changeable between steps) with a viscous sway damper.
pub struct TrailerSim {
    t: TrailerParams,
    c_damper_nspm: f64,
    v_mps: f64,
    a: Matrix<N_STATES>,
    /// Generalised-force input column: dx/dt per unit yaw moment on the trailer, N m.
    yaw_moment_input: SVector<f64, N_STATES>,
    /// Time, s.
    pub time_s: f64,
    /// State (the linear model's order).
    pub x: [f64; N_STATES],
}

impl TrailerSim {
    /// A simulation of `t` at `v_mps` with a sway damper `c_damper_nspm` from the state `x0`.
    pub fn new(t: &TrailerParams, v_mps: f64, c_damper_nspm: f64, x0: [f64; N_STATES]) -> Self {
        let mut yaw_moment_input = SVector::<f64, N_STATES>::zeros();
        // M^-1 [0, 1]: the damper column per unit moment (its lever is l_d)
        let b = t.damper_force_input();
        yaw_moment_input[DY] = -b[DY] / t.l_d;
        yaw_moment_input[DPSI] = -b[DPSI] / t.l_d;
        Self {
            t: *t,
            c_damper_nspm,
            v_mps,
            a: t.linearise(v_mps, c_damper_nspm),
            yaw_moment_input,
            time_s: 0.0,
            x: x0,
        }
    }

    /// The forward speed, m/s.
    pub fn speed_mps(&self) -> f64 {
        self.v_mps
    }

    /// Sets the forward speed (the state matrix is relinearised; A is affine in V).
    pub fn set_speed(&mut self, v_mps: f64) {
        if v_mps != self.v_mps {
            self.v_mps = v_mps;
            self.a = self.t.linearise(v_mps, self.c_damper_nspm);
        }
    }

    /// The axle's lateral force at lagged slip `alpha`, N.
    pub fn tyre_force_n(&self, alpha: f64) -> f64 {
        let d = self.t.mu * self.t.axle_load_n();
        let b = self.t.cornering_stiffness() / (self.t.c_s * d);
        d * (self.t.c_s * (b * alpha).atan()).sin()
    }

    fn rhs(&self, x: &[f64; N_STATES], yaw_moment_nm: f64, dx: &mut [f64; N_STATES]) {
        let xv = SVector::<f64, N_STATES>::from_column_slice(x);
        let lin = self.a * xv + self.yaw_moment_input * yaw_moment_nm;
        dx.copy_from_slice(lin.as_slice());
        // tyres: nonlinear force minus the linear C_a alpha already in A, through M^-1 [1, -l]
        let extra = self.tyre_force_n(x[ALPHA]) - self.t.cornering_stiffness() * x[ALPHA];
        let (m, iz, a) = (self.t.m, self.t.i_z, self.t.a);
        let b = self.t.l - a;
        dx[DY] += extra * (iz - m * a * b) / (m * iz);
        dx[DPSI] -= extra * b / iz;
    }

    /// One step of [`DT_S`] with the external yaw moment `yaw_moment_nm` on the trailer (road,
    /// wind), held over the step.
    pub fn step(&mut self, yaw_moment_nm: f64) {
        let mut f =
            |_t: f64, y: &[f64; N_STATES], dy: &mut [f64; N_STATES]| self.rhs(y, yaw_moment_nm, dy);
        let mut x = self.x;
        rk4_step(&mut f, self.time_s, &mut x, DT_S);
        self.x = x;
        self.time_s += DT_S;
    }

    /// Advances by `duration_s` in steps of [`DT_S`] without external forces, calling
    /// `each(time, state)` after every step.
    pub fn run(&mut self, duration_s: f64, mut each: impl FnMut(f64, &[f64; N_STATES])) {
        let n = (duration_s / DT_S).round() as usize;
        for _ in 0..n {
            self.step(0.0);
            each(self.time_s, &self.x);
        }
    }
}

/// Growth rate of the yaw envelope, 1/s: the log ratio of the largest |psi| in the last and
/// the first `window_s` after `settle_s` (the hitch-lateral mode decayed), over their distance
/// in time.
pub fn envelope_growth_1ps(
    t: &TrailerParams,
    v_mps: f64,
    c_damper_nspm: f64,
    psi0_rad: f64,
    settle_s: f64,
    duration_s: f64,
    window_s: f64,
) -> f64 {
    let mut sim = TrailerSim::new(t, v_mps, c_damper_nspm, yaw_start(psi0_rad));
    let (mut first, mut last) = (0.0_f64, 0.0_f64);
    let (w0, w1) = (settle_s + window_s, duration_s - window_s);
    sim.run(duration_s, |time, x| {
        let yaw = x[PSI].abs();
        if time > settle_s && time <= w0 {
            first = first.max(yaw);
        }
        if time > w1 {
            last = last.max(yaw);
        }
    });
    (last / first).ln() / (w1 - settle_s)
}

/// The largest |psi| over the last `window_s` of a `duration_s` run from the yaw `psi0_rad`,
/// rad: the limit-cycle amplitude when the run has settled on one.
pub fn final_yaw_amplitude_rad(
    t: &TrailerParams,
    v_mps: f64,
    c_damper_nspm: f64,
    psi0_rad: f64,
    duration_s: f64,
    window_s: f64,
) -> f64 {
    let mut sim = TrailerSim::new(t, v_mps, c_damper_nspm, yaw_start(psi0_rad));
    let mut amp = 0.0_f64;
    sim.run(duration_s, |time, x| {
        if time > duration_s - window_s {
            amp = amp.max(x[PSI].abs());
        }
    });
    amp
}

/// A yaw start, rad (the hitch on the tow path, at rest).
pub fn yaw_start(psi_rad: f64) -> [f64; N_STATES] {
    let mut x = [0.0; N_STATES];
    x[PSI] = psi_rad;
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use shimmy_core::stability::{self, CrossingKind, DEFAULT_TOL_MPS};
    use shimmy_core::trailer::TrailerSet;

    /// The tyre has the linear model's slope at 0 and saturates at mu F_z.
    #[test]
    fn the_tyre_linearises_to_the_model_and_saturates() {
        let t = TrailerSet::Caravan.params();
        let sim = TrailerSim::new(&t, 20.0, 0.0, [0.0; N_STATES]);
        let h = 1e-7;
        let slope = (sim.tyre_force_n(h) - sim.tyre_force_n(-h)) / (2.0 * h);
        let ca = t.cornering_stiffness();
        assert!((slope - ca).abs() < 1e-6 * ca);
        let peak = (1..200)
            .map(|i| sim.tyre_force_n(f64::from(i) * 0.005))
            .fold(0.0, f64::max);
        assert!(
            (peak - t.mu * t.axle_load_n()).abs() < 1e-3 * peak,
            "{peak}"
        );
    }

    /// The Hopf speed in the time domain: from a 0.1 deg yaw start the nonlinear plant's yaw
    /// envelope grows 3 km/h above the eigenvalue onset and decays 3 km/h below it, at the
    /// eigenvalues' rate (10 % + 2e-3 1/s), damper off and with a sway damper of zeta 0.05.
    #[test]
    fn hopf_speed_matches_the_time_domain_onset() {
        let t = TrailerSet::Caravan.params();
        for c in [0.0, t.damper_of_zeta(0.05)] {
            let cs = stability::hopf_crossings(&t, c, 1.0, 70.0, 0.5, DEFAULT_TOL_MPS).unwrap();
            let onset = cs
                .iter()
                .find(|x| x.kind == CrossingKind::Onset)
                .unwrap()
                .speed_mps;
            for dv_kmh in [-3.0, 3.0] {
                let v = onset + dv_kmh / 3.6;
                let g = envelope_growth_1ps(&t, v, c, 0.1_f64.to_radians(), 10.0, 70.0, 6.0);
                let re = stability::critical_mode_at(&t, v, c).unwrap().re;
                println!(
                    "damper {c:.0} N s/m: onset {:.3} km/h, at {:.3} km/h: envelope {g:.5} 1/s, \
                     eigenvalue {re:.5} 1/s",
                    onset * 3.6,
                    v * 3.6
                );
                assert_eq!(g > 0.0, dv_kmh > 0.0, "{dv_kmh} km/h from the onset: {g}");
                assert!(
                    (g - re).abs() < 0.1 * re.abs() + 2e-3,
                    "envelope {g} vs {re}"
                );
            }
        }
    }

    /// Above the onset the tyres' saturation stops the growth on a limit cycle (the same one
    /// from a small and a large start); below it both starts decay (no coexisting cycle there).
    #[test]
    fn sway_settles_on_one_limit_cycle_above_the_onset() {
        let t = TrailerSet::Caravan.params();
        let onset = stability::hopf_crossings(&t, 0.0, 1.0, 70.0, 0.5, DEFAULT_TOL_MPS).unwrap()[0]
            .speed_mps;
        let above = onset + 10.0 / 3.6;
        let small = final_yaw_amplitude_rad(&t, above, 0.0, 0.5_f64.to_radians(), 200.0, 20.0);
        let large = final_yaw_amplitude_rad(&t, above, 0.0, 8.0_f64.to_radians(), 200.0, 20.0);
        println!(
            "limit cycle at {:.1} km/h: {:.3} deg (small start), {:.3} deg (large start)",
            above * 3.6,
            small.to_degrees(),
            large.to_degrees()
        );
        assert!(small.to_degrees() > 1.0, "{small}");
        assert!((small - large).abs() < 1e-3 * small, "{small} vs {large}");
        let below = onset - 5.0 / 3.6;
        let big = final_yaw_amplitude_rad(&t, below, 0.0, 8.0_f64.to_radians(), 200.0, 20.0);
        assert!(big < 0.05_f64.to_radians(), "{}", big.to_degrees());
    }
}
