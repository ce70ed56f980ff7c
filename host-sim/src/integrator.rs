//! Small explicit Runge-Kutta integrators for fixed-size states (`[f64; N]`).
//!
//! - [`Dopri5`]: the Dormand-Prince 5(4) embedded pair with FSAL and a PI step-size controller
//!   (Hairer, Norsett & Wanner, *Solving ODEs I*, II.4/II.5). Adaptive, used by default.
//! - [`rk4_step`]: the classical fixed-step RK4, an independent second solver for tests.
//!
//! Why hand-written and not `ode_solvers`: the simulator integrates one control period (1 ms)
//! at a time with the input held (zero-order hold). `ode_solvers::Dopri5` is built per
//! integration interval, re-estimates the initial step each time and stores every accepted step
//! in `Vec`s; per 1 ms period that overhead dominates the work. Here the stepper is a value
//! that lives across periods and carries its step size over, and nothing allocates.

/// Result of an integration over one interval.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StepStats {
    /// Accepted steps.
    pub accepted: u64,
    /// Rejected steps.
    pub rejected: u64,
    /// Right-hand-side evaluations.
    pub evaluations: u64,
}

/// Why an integration failed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum IntegrateError {
    /// The step size fell below the floor at time `t` [s].
    StepTooSmall {
        /// Time at which it happened.
        t: f64,
    },
    /// A state became NaN or infinite.
    NonFinite {
        /// Time at which it happened.
        t: f64,
    },
}

impl std::fmt::Display for IntegrateError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            IntegrateError::StepTooSmall { t } => write!(f, "step size underflow at t = {t} s"),
            IntegrateError::NonFinite { t } => write!(f, "non-finite state at t = {t} s"),
        }
    }
}

impl std::error::Error for IntegrateError {}

// Dormand-Prince 5(4) tableau.
const C2: f64 = 1.0 / 5.0;
const C3: f64 = 3.0 / 10.0;
const C4: f64 = 4.0 / 5.0;
const C5: f64 = 8.0 / 9.0;
const A21: f64 = 1.0 / 5.0;
const A31: f64 = 3.0 / 40.0;
const A32: f64 = 9.0 / 40.0;
const A41: f64 = 44.0 / 45.0;
const A42: f64 = -56.0 / 15.0;
const A43: f64 = 32.0 / 9.0;
const A51: f64 = 19372.0 / 6561.0;
const A52: f64 = -25360.0 / 2187.0;
const A53: f64 = 64448.0 / 6561.0;
const A54: f64 = -212.0 / 729.0;
const A61: f64 = 9017.0 / 3168.0;
const A62: f64 = -355.0 / 33.0;
const A63: f64 = 46732.0 / 5247.0;
const A64: f64 = 49.0 / 176.0;
const A65: f64 = -5103.0 / 18656.0;
const A71: f64 = 35.0 / 384.0;
const A73: f64 = 500.0 / 1113.0;
const A74: f64 = 125.0 / 192.0;
const A75: f64 = -2187.0 / 6784.0;
const A76: f64 = 11.0 / 84.0;
// Error coefficients: 5th-order weights minus the embedded 4th-order weights.
const E1: f64 = 71.0 / 57600.0;
const E3: f64 = -71.0 / 16695.0;
const E4: f64 = 71.0 / 1920.0;
const E5: f64 = -17253.0 / 339200.0;
const E6: f64 = 22.0 / 525.0;
const E7: f64 = -1.0 / 40.0;

/// Adaptive Dormand-Prince 5(4) stepper for an `N`-dimensional state.
#[derive(Clone, Debug)]
pub struct Dopri5<const N: usize> {
    /// Relative tolerance.
    pub rtol: f64,
    /// Absolute tolerance per component (in the component's unit).
    pub atol: [f64; N],
    /// Largest step [s] (also capped by each call's interval).
    pub h_max: f64,
    /// Step-size floor [s]: below it the integration fails instead of crawling.
    pub h_min: f64,
    h: f64,
    err_old: f64,
    k_last: [f64; N],
    /// Running totals.
    pub stats: StepStats,
}

impl<const N: usize> Dopri5<N> {
    /// A stepper with relative tolerance `rtol` and per-component absolute tolerances `atol`.
    pub fn new(rtol: f64, atol: [f64; N]) -> Self {
        Dopri5 {
            rtol,
            atol,
            h_max: f64::INFINITY,
            h_min: 1e-12,
            h: 0.0,
            err_old: 1e-4,
            k_last: [0.0; N],
            stats: StepStats::default(),
        }
    }

    /// The step size the next step will try [s] (0 before the first step).
    pub fn step_size(&self) -> f64 {
        self.h
    }

    /// Integrates `y` from `t0` to `t0 + dt` with `f(t, y, dy)`. The step size is adapted to the
    /// tolerances and carried over to the next call.
    pub fn integrate<F>(
        &mut self,
        f: &mut F,
        t0: f64,
        y: &mut [f64; N],
        dt: f64,
    ) -> Result<(), IntegrateError>
    where
        F: FnMut(f64, &[f64; N], &mut [f64; N]),
    {
        self.integrate_fsal(f, t0, y, dt, false)
    }

    /// As [`integrate`](Self::integrate); with `reuse_derivative` the derivative at the start is
    /// taken from the end of the previous call (first-same-as-last across calls). Only valid when
    /// `f` and `y` are exactly those the previous call ended with (same held input, state not
    /// modified in between): the caller guarantees it.
    pub fn integrate_fsal<F>(
        &mut self,
        f: &mut F,
        t0: f64,
        y: &mut [f64; N],
        dt: f64,
        reuse_derivative: bool,
    ) -> Result<(), IntegrateError>
    where
        F: FnMut(f64, &[f64; N], &mut [f64; N]),
    {
        let t_end = t0 + dt;
        let mut t = t0;
        let mut k1 = [0.0; N];
        if reuse_derivative && self.h > 0.0 {
            k1 = self.k_last;
        } else {
            f(t, y, &mut k1);
            self.stats.evaluations += 1;
        }
        if self.h <= 0.0 {
            self.h = self.initial_step(y, &k1, dt);
        }
        let (mut k2, mut k3, mut k4, mut k5, mut k6, mut k7) =
            ([0.0; N], [0.0; N], [0.0; N], [0.0; N], [0.0; N], [0.0; N]);
        let mut yt = [0.0; N];
        let mut y_new = [0.0; N];
        // PI controller constants (Hairer's DOPRI5 defaults).
        let (beta, fac_min, fac_max, safety) = (0.04, 0.2, 10.0, 0.9);
        let alpha = 0.2 - beta * 0.75;
        let mut last_rejected = false;
        while t < t_end {
            let remaining = t_end - t;
            // Land exactly on the end of the interval; avoid a sliver step.
            let mut h = self.h.min(self.h_max);
            let last = h >= remaining * (1.0 - 1e-9);
            if last {
                h = remaining;
            } else if h > 0.5 * remaining {
                h = 0.5 * remaining;
            }
            if h < self.h_min {
                return Err(IntegrateError::StepTooSmall { t });
            }
            for i in 0..N {
                yt[i] = y[i] + h * A21 * k1[i];
            }
            f(t + C2 * h, &yt, &mut k2);
            for i in 0..N {
                yt[i] = y[i] + h * (A31 * k1[i] + A32 * k2[i]);
            }
            f(t + C3 * h, &yt, &mut k3);
            for i in 0..N {
                yt[i] = y[i] + h * (A41 * k1[i] + A42 * k2[i] + A43 * k3[i]);
            }
            f(t + C4 * h, &yt, &mut k4);
            for i in 0..N {
                yt[i] = y[i] + h * (A51 * k1[i] + A52 * k2[i] + A53 * k3[i] + A54 * k4[i]);
            }
            f(t + C5 * h, &yt, &mut k5);
            for i in 0..N {
                yt[i] = y[i]
                    + h * (A61 * k1[i] + A62 * k2[i] + A63 * k3[i] + A64 * k4[i] + A65 * k5[i]);
            }
            let t_new = if last { t_end } else { t + h };
            f(t_new, &yt, &mut k6);
            for i in 0..N {
                y_new[i] = y[i]
                    + h * (A71 * k1[i] + A73 * k3[i] + A74 * k4[i] + A75 * k5[i] + A76 * k6[i]);
            }
            f(t_new, &y_new, &mut k7);
            self.stats.evaluations += 6;
            let mut err2 = 0.0;
            for i in 0..N {
                let e = h
                    * (E1 * k1[i] + E3 * k3[i] + E4 * k4[i] + E5 * k5[i] + E6 * k6[i] + E7 * k7[i]);
                let sc = self.atol[i] + self.rtol * y[i].abs().max(y_new[i].abs());
                err2 += (e / sc) * (e / sc);
            }
            let err = (err2 / N as f64).sqrt();
            if !err.is_finite() {
                // Treat as a failed step: shrink hard and retry.
                self.stats.rejected += 1;
                self.h = h * fac_min;
                last_rejected = true;
                continue;
            }
            if err <= 1.0 {
                let fac = if err == 0.0 {
                    fac_max
                } else {
                    (safety * err.powf(-alpha) * self.err_old.powf(beta)).clamp(fac_min, fac_max)
                };
                let fac = if last_rejected { fac.min(1.0) } else { fac };
                self.err_old = err.max(1e-4);
                *y = y_new;
                k1 = k7; // FSAL
                t = t_new;
                self.stats.accepted += 1;
                // Do not let the sliver at the end of an interval shrink the carried step.
                if !last || h >= self.h {
                    self.h = h * fac;
                }
                last_rejected = false;
            } else {
                let fac = (safety * err.powf(-alpha)).clamp(fac_min, 1.0);
                self.h = h * fac;
                self.stats.rejected += 1;
                last_rejected = true;
            }
        }
        self.k_last = k1;
        if y.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(IntegrateError::NonFinite { t })
        }
    }

    fn initial_step(&self, y: &[f64; N], f0: &[f64; N], dt: f64) -> f64 {
        // Hairer's heuristic, first part: h ~ 0.01 |y| / |f|, capped by the interval.
        let (mut d0, mut d1) = (0.0, 0.0);
        for i in 0..N {
            let sc = self.atol[i] + self.rtol * y[i].abs();
            d0 += (y[i] / sc) * (y[i] / sc);
            d1 += (f0[i] / sc) * (f0[i] / sc);
        }
        let h = if d0 < 1e-10 || d1 < 1e-10 {
            1e-6
        } else {
            0.01 * (d0 / d1).sqrt()
        };
        h.min(dt).min(self.h_max).max(1e-9)
    }
}

/// One classical RK4 step of size `h` from `(t, y)`.
pub fn rk4_step<const N: usize, F>(f: &mut F, t: f64, y: &mut [f64; N], h: f64)
where
    F: FnMut(f64, &[f64; N], &mut [f64; N]),
{
    let (mut k1, mut k2, mut k3, mut k4) = ([0.0; N], [0.0; N], [0.0; N], [0.0; N]);
    let mut yt = [0.0; N];
    f(t, y, &mut k1);
    for i in 0..N {
        yt[i] = y[i] + 0.5 * h * k1[i];
    }
    f(t + 0.5 * h, &yt, &mut k2);
    for i in 0..N {
        yt[i] = y[i] + 0.5 * h * k2[i];
    }
    f(t + 0.5 * h, &yt, &mut k3);
    for i in 0..N {
        yt[i] = y[i] + h * k3[i];
    }
    f(t + h, &yt, &mut k4);
    for i in 0..N {
        y[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Harmonic oscillator x'' = -w^2 x: exact solution known.
    fn osc(w: f64) -> impl FnMut(f64, &[f64; 2], &mut [f64; 2]) {
        move |_t, y, dy| {
            dy[0] = y[1];
            dy[1] = -w * w * y[0];
        }
    }

    #[test]
    fn dopri5_meets_its_tolerance_on_an_oscillator() {
        let w = 2.0 * std::f64::consts::PI * 7.0;
        let mut f = osc(w);
        let mut y = [1.0, 0.0];
        let mut s = Dopri5::new(1e-9, [1e-12, 1e-10]);
        let mut t = 0.0;
        for _ in 0..2000 {
            s.integrate(&mut f, t, &mut y, 1e-3).unwrap();
            t += 1e-3;
        }
        let exact = (w * 2.0).cos();
        // 14 periods at rtol 1e-9: global error stays well below 1e-6.
        assert!((y[0] - exact).abs() < 1e-6, "{} vs {}", y[0], exact);
        // Looser tolerance gives a larger, still bounded, error: the tolerance is what acts.
        let mut y2 = [1.0, 0.0];
        let mut s2 = Dopri5::new(1e-4, [1e-7, 1e-5]);
        s2.integrate(&mut f, 0.0, &mut y2, 2.0).unwrap();
        let e2 = (y2[0] - exact).abs();
        assert!(e2 > (y[0] - exact).abs() && e2 < 1e-1, "{e2}");
    }

    #[test]
    fn dopri5_is_fifth_order_and_rk4_fourth_order() {
        // Fixed step sizes: force Dopri5 to take exactly the given steps via h_max and loose tol.
        let w = 3.0;
        let exact = |t: f64| (w * t).cos();
        let err_dopri = |h: f64| {
            let mut f = osc(w);
            let mut y = [1.0, 0.0];
            let mut s = Dopri5::new(1e3, [1e3, 1e3]);
            s.h_max = h;
            let mut t = 0.0;
            while t < 2.0 - 1e-12 {
                s.integrate(&mut f, t, &mut y, h).unwrap();
                t += h;
            }
            (y[0] - exact(2.0)).abs()
        };
        let err_rk4 = |h: f64| {
            let mut f = osc(w);
            let mut y = [1.0, 0.0];
            let n = (2.0 / h).round() as usize;
            for k in 0..n {
                rk4_step(&mut f, k as f64 * h, &mut y, h);
            }
            (y[0] - exact(2.0)).abs()
        };
        let p_dopri = (err_dopri(0.02) / err_dopri(0.01)).log2();
        let p_rk4 = (err_rk4(0.02) / err_rk4(0.01)).log2();
        assert!((p_dopri - 5.0).abs() < 0.3, "dopri order {p_dopri}");
        assert!((p_rk4 - 4.0).abs() < 0.3, "rk4 order {p_rk4}");
    }

    #[test]
    fn dopri5_handles_a_stiff_decay_by_shrinking_steps() {
        // y' = -1e5 (y - cos t): stability-limited, must stay bounded and accurate.
        let mut f = |t: f64, y: &[f64; 1], dy: &mut [f64; 1]| dy[0] = -1e5 * (y[0] - t.cos());
        let mut y = [0.0];
        let mut s = Dopri5::new(1e-8, [1e-10]);
        let mut t = 0.0;
        for _ in 0..100 {
            s.integrate(&mut f, t, &mut y, 1e-3).unwrap();
            t += 1e-3;
        }
        // Slow manifold y = cos t + sin t / 1e5 + O(1e-10).
        let slow = t.cos() + t.sin() / 1e5;
        assert!((y[0] - slow).abs() < 1e-7, "{} vs {}", y[0], slow);
    }
}
