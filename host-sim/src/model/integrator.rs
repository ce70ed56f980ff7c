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
    /// The step size fell below the floor at time `t`, s.
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

/// Floor of the error norm the PI controller remembers (Hairer's 1e-4), also its memory
/// before the first accepted step.
const ERR_FLOOR: f64 = 1e-4;

/// The PI step-size factor safety * err^-alpha * err_old^beta from the logarithms of the two
/// error norms: one `exp` per step with ln(err_old) carried from the previous step, where two
/// `powf` calls cost ~5 % of a closed-loop run (`perf` on the demo's arms).
#[inline]
fn pi_factor(safety: f64, alpha: f64, beta: f64, ln_err: f64, ln_err_old: f64) -> f64 {
    safety * (beta * ln_err_old - alpha * ln_err).exp()
}

/// The PI step-size controller the adaptive steppers share, with its constants.
#[derive(Clone, Copy, Debug)]
struct Pi {
    alpha: f64,
    beta: f64,
    fac_min: f64,
    fac_max: f64,
    safety: f64,
}

impl Pi {
    /// Hairer's DOPRI5 constants for an error estimate of order `q` in h.
    fn hairer(q: f64) -> Self {
        let beta = 0.04;
        Pi {
            alpha: 1.0 / q - beta * 0.75,
            beta,
            fac_min: 0.2,
            fac_max: 10.0,
            safety: 0.9,
        }
    }

    /// After a step of size `h` (`last`: the one landing on the interval's end) with error
    /// norm `err` (NaN or infinite: the step failed): whether it is accepted, with the step to
    /// carry (`h_carried`), the controller's memory (`ln_err_old`) and `last_rejected`
    /// updated.
    fn judge(
        &self,
        err: f64,
        h: f64,
        last: bool,
        h_carried: &mut f64,
        ln_err_old: &mut f64,
        last_rejected: &mut bool,
    ) -> bool {
        if !err.is_finite() {
            // a failed step: shrink hard and retry
            *h_carried = h * self.fac_min;
            *last_rejected = true;
            return false;
        }
        if err > 1.0 {
            let fac =
                pi_factor(self.safety, self.alpha, 0.0, err.ln(), 0.0).clamp(self.fac_min, 1.0);
            *h_carried = h * fac;
            *last_rejected = true;
            return false;
        }
        let ln_err = err.ln();
        let fac = if err == 0.0 {
            self.fac_max
        } else {
            pi_factor(self.safety, self.alpha, self.beta, ln_err, *ln_err_old)
                .clamp(self.fac_min, self.fac_max)
        };
        let fac = if *last_rejected { fac.min(1.0) } else { fac };
        *ln_err_old = ln_err.max(ERR_FLOOR.ln());
        // Do not let the sliver at the end of an interval shrink the carried step.
        if !last || h >= *h_carried {
            *h_carried = h * fac;
        }
        *last_rejected = false;
        true
    }
}

/// The next step from `t` towards `t_end` with the carried step `h_carried`: landing exactly
/// on the end of the interval and avoiding a sliver step; `true` for the landing step.
fn next_step(
    h_carried: f64,
    h_max: f64,
    h_min: f64,
    t: f64,
    t_end: f64,
) -> Result<(f64, bool), IntegrateError> {
    let remaining = t_end - t;
    let mut h = h_carried.min(h_max);
    let last = h >= remaining * (1.0 - 1e-9);
    if last {
        h = remaining;
    } else if h > 0.5 * remaining {
        h = 0.5 * remaining;
    }
    if h < h_min {
        return Err(IntegrateError::StepTooSmall { t });
    }
    Ok((h, last))
}

/// Hairer's first step guess, h ~ 0.01 |y| / |f| in the tolerances' norm, capped by the
/// interval `dt` and `h_max`.
fn first_step<const N: usize>(
    rtol: f64,
    atol: &[f64; N],
    h_max: f64,
    y: &[f64; N],
    f0: &[f64; N],
    dt: f64,
) -> f64 {
    let (mut d0, mut d1) = (0.0, 0.0);
    for i in 0..N {
        let sc = atol[i] + rtol * y[i].abs();
        d0 += (y[i] / sc) * (y[i] / sc);
        d1 += (f0[i] / sc) * (f0[i] / sc);
    }
    let h = if d0 < 1e-10 || d1 < 1e-10 {
        1e-6
    } else {
        0.01 * (d0 / d1).sqrt()
    };
    h.min(dt).min(h_max).max(1e-9)
}

/// Adaptive Dormand-Prince 5(4) stepper for an `N`-dimensional state.
#[derive(Clone, Debug)]
pub struct Dopri5<const N: usize> {
    /// Relative tolerance.
    pub rtol: f64,
    /// Absolute tolerance per component (in the component's unit).
    pub atol: [f64; N],
    /// Largest step, s (also capped by each call's interval).
    pub h_max: f64,
    /// Step-size floor in s: below it the integration fails instead of crawling.
    pub h_min: f64,
    h: f64,
    /// ln of the last accepted step's error norm (the PI controller's memory).
    ln_err_old: f64,
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
            ln_err_old: ERR_FLOOR.ln(),
            k_last: [0.0; N],
            stats: StepStats::default(),
        }
    }

    /// The step size the next step will try, s (0 before the first step).
    pub fn step_size(&self) -> f64 {
        self.h
    }

    /// Sets the derivative [`integrate_fsal`](Self::integrate_fsal) reuses at the start of the
    /// next call: only valid when it is `f` at exactly that call's `y` (the caller evaluated it
    /// there, e.g. for the forces at the start of a period).
    pub fn set_start_derivative(&mut self, k: [f64; N]) {
        self.k_last = k;
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
            self.h = first_step(self.rtol, &self.atol, self.h_max, y, &k1, dt);
        }
        let (mut k2, mut k3, mut k4, mut k5, mut k6, mut k7) =
            ([0.0; N], [0.0; N], [0.0; N], [0.0; N], [0.0; N], [0.0; N]);
        let mut yt = [0.0; N];
        let mut y_new = [0.0; N];
        let pi = Pi::hairer(5.0);
        let mut last_rejected = false;
        while t < t_end {
            let (h, last) = next_step(self.h, self.h_max, self.h_min, t, t_end)?;
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
            let accepted = pi.judge(
                err,
                h,
                last,
                &mut self.h,
                &mut self.ln_err_old,
                &mut last_rejected,
            );
            if accepted {
                *y = y_new;
                k1 = k7; // FSAL
                t = t_new;
                self.stats.accepted += 1;
            } else {
                self.stats.rejected += 1;
            }
        }
        self.k_last = k1;
        if y.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(IntegrateError::NonFinite { t })
        }
    }
}

// Verner's "most efficient" 6(5) pair with lower stage order (Verner 2013, Numer. Algorithms
// 65, 555-577; his RKV65.IIIXb "efficient" coefficients): 9 stages, the 9th at the new point
// with the 6th-order weights (first same as last). Zero entries (columns 2 and 3 from row 4 on)
// are left out of the stage sums below; the tests check the row sums and the orders. The
// coefficients are typed as published, with more digits than f64 holds (rounded once).
#[allow(clippy::excessive_precision)]
mod verner {
    pub(super) const V_C: [f64; 9] = [
        0.0,
        0.06,
        0.095_933_333_333_333_333_333_333,
        0.1439,
        0.4973,
        0.9725,
        0.9995,
        1.0,
        1.0,
    ];
    pub(super) const V_A21: f64 = 0.06;
    pub(super) const V_A31: f64 = 0.019_239_962_962_962_962_962_962_96;
    pub(super) const V_A32: f64 = 0.076_693_370_370_370_370_370_370_37;
    pub(super) const V_A41: f64 = 0.035_975;
    pub(super) const V_A43: f64 = 0.107_925;
    pub(super) const V_A51: f64 = 1.318_683_415_233_148_260_919_747_276;
    pub(super) const V_A53: f64 = -5.042_058_063_628_562_225_427_761_635;
    pub(super) const V_A54: f64 = 4.220_674_648_395_413_964_508_014_358;
    pub(super) const V_A61: f64 = -41.872_591_664_327_514_618_037_577_81;
    pub(super) const V_A63: f64 = 159.432_562_163_137_491_770_036_566_9;
    pub(super) const V_A64: f64 = -122.119_213_565_010_030_920_251_620_3;
    pub(super) const V_A65: f64 = 5.531_743_066_200_053_768_252_631_238;
    pub(super) const V_A71: f64 = -54.430_156_935_316_504_332_506_420_51;
    pub(super) const V_A73: f64 = 207.067_251_365_018_464_427_365_717_4;
    pub(super) const V_A74: f64 = -158.610_813_784_589_999_182_874_242_4;
    pub(super) const V_A75: f64 = 6.991_816_585_950_242_321_992_597_281;
    pub(super) const V_A76: f64 = -0.018_597_231_062_203_233_977_651_717_99;
    pub(super) const V_A81: f64 = -54.663_741_787_281_976_802_412_156_48;
    pub(super) const V_A83: f64 = 207.952_806_255_389_373_451_582_481_7;
    pub(super) const V_A84: f64 = -159.288_957_474_499_507_150_895_980_6;
    pub(super) const V_A85: f64 = 7.018_743_740_796_944_434_698_170_761;
    pub(super) const V_A86: f64 = -0.018_338_785_905_045_723_064_727_820_05;
    pub(super) const V_A87: f64 = -0.000_511_948_499_788_209_907_787_543_249_7;
    // 6th-order weights (b2 = b3 = b9 = 0).
    pub(super) const V_B1: f64 = 0.034_389_578_683_570_360_092_788_201_25;
    pub(super) const V_B4: f64 = 0.258_262_455_563_350_340_465_955_809_9;
    pub(super) const V_B5: f64 = 0.420_937_118_967_353_715_064_255_151_4;
    pub(super) const V_B6: f64 = 4.405_396_469_669_310_170_148_836_816;
    pub(super) const V_B7: f64 = -176.483_119_024_298_657_615_174_094_2;
    pub(super) const V_B8: f64 = 172.364_133_401_415_073_029_402_258_3;
    // Error weights: 5th-order weights minus the 6th-order ones (d2 = d3 = 0).
    pub(super) const V_D1: f64 = 0.014_710_097_800_254_537_216_280_348_03;
    pub(super) const V_D4: f64 = -0.033_151_232_611_697_925_125_816_277_80;
    pub(super) const V_D5: f64 = 0.048_531_106_335_602_488_878_939_701_10;
    pub(super) const V_D6: f64 = -3.598_817_244_670_423_399_385_420_635;
    pub(super) const V_D7: f64 = 176.483_119_024_298_657_615_174_094_2;
    pub(super) const V_D8: f64 = -172.971_252_890_592_869_009_169_553_4;
    pub(super) const V_D9: f64 = 0.056_861_139_440_475_692_411_476_031_79;
}
use verner::*;

/// `out = y + h (a_1 k_1 + ... + a_M k_M)`: one stage's argument (`M` fixed per call, so the
/// sums unroll).
#[inline(always)]
fn combine<const N: usize, const M: usize>(
    y: &[f64; N],
    h: f64,
    a: [f64; M],
    k: [&[f64; N]; M],
    out: &mut [f64; N],
) {
    for i in 0..N {
        let mut acc = 0.0;
        for j in 0..M {
            acc += a[j] * k[j][i];
        }
        out[i] = y[i] + h * acc;
    }
}

/// Adaptive Verner 6(5) stepper for an `N`-dimensional state: the same interface, tolerances
/// and PI step-size control as [`Dopri5`], one order higher. Its error estimate is of 6th
/// order in the step (Dopri5's of 5th), so at a given tolerance its steps are longer: in the
/// closed loop one step of 8 right-hand-side calls usually spans the 1 ms control period,
/// where Dopri5 needs two of 6 each.
#[derive(Clone, Debug)]
pub struct Vern65<const N: usize> {
    /// Relative tolerance.
    pub rtol: f64,
    /// Absolute tolerance per component (in the component's unit).
    pub atol: [f64; N],
    /// Largest step, s (also capped by each call's interval).
    pub h_max: f64,
    /// Step-size floor in s: below it the integration fails instead of crawling.
    pub h_min: f64,
    h: f64,
    /// ln of the last accepted step's error norm (the PI controller's memory).
    ln_err_old: f64,
    /// Running totals.
    pub stats: StepStats,
}

impl<const N: usize> Vern65<N> {
    /// A stepper with relative tolerance `rtol` and per-component absolute tolerances `atol`.
    pub fn new(rtol: f64, atol: [f64; N]) -> Self {
        Vern65 {
            rtol,
            atol,
            h_max: f64::INFINITY,
            h_min: 1e-12,
            h: 0.0,
            ln_err_old: ERR_FLOOR.ln(),
            stats: StepStats::default(),
        }
    }

    /// The step size the next step will try, s (0 before the first step).
    pub fn step_size(&self) -> f64 {
        self.h
    }

    /// Integrates `y` from `t0` to `t0 + dt` with `f(t, y, dy)`; `start` is `f` at `(t0, y)`
    /// when the caller has it (saves one call). The step size is adapted to the tolerances and
    /// carried over to the next call.
    pub fn integrate<F>(
        &mut self,
        f: &mut F,
        t0: f64,
        y: &mut [f64; N],
        dt: f64,
        start: Option<[f64; N]>,
    ) -> Result<(), IntegrateError>
    where
        F: FnMut(f64, &[f64; N], &mut [f64; N]),
    {
        let t_end = t0 + dt;
        let mut t = t0;
        let mut k1 = match start {
            Some(k) => k,
            None => {
                let mut k = [0.0; N];
                f(t, y, &mut k);
                self.stats.evaluations += 1;
                k
            }
        };
        if self.h <= 0.0 {
            self.h = first_step(self.rtol, &self.atol, self.h_max, y, &k1, dt);
        }
        let (mut y_new, mut k9, mut e) = ([0.0; N], [0.0; N], [0.0; N]);
        // an error estimate of order 6 in h
        let pi = Pi::hairer(6.0);
        let mut last_rejected = false;
        while t < t_end {
            let (h, last) = next_step(self.h, self.h_max, self.h_min, t, t_end)?;
            let t_new = if last { t_end } else { t + h };
            vern65_step(f, t, y, h, &k1, &mut y_new, &mut k9, &mut e);
            self.stats.evaluations += 8;
            let mut err2 = 0.0;
            for i in 0..N {
                let sc = self.atol[i] + self.rtol * y[i].abs().max(y_new[i].abs());
                err2 += (e[i] / sc) * (e[i] / sc);
            }
            let err = (err2 / N as f64).sqrt();
            let accepted = pi.judge(
                err,
                h,
                last,
                &mut self.h,
                &mut self.ln_err_old,
                &mut last_rejected,
            );
            if accepted {
                *y = y_new;
                k1 = k9; // FSAL
                t = t_new;
                self.stats.accepted += 1;
            } else {
                self.stats.rejected += 1;
            }
        }
        if y.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(IntegrateError::NonFinite { t })
        }
    }
}

/// One Verner 6(5) step of size `h` from `(t, y)` with `k1 = f(t, y)` (8 calls of `f`): the
/// 6th-order solution `y_new`, `f` there (`k9`) and the error estimate `e` (5th-order solution
/// minus `y_new`).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn vern65_step<const N: usize, F>(
    f: &mut F,
    t: f64,
    y: &[f64; N],
    h: f64,
    k1: &[f64; N],
    y_new: &mut [f64; N],
    k9: &mut [f64; N],
    e: &mut [f64; N],
) where
    F: FnMut(f64, &[f64; N], &mut [f64; N]),
{
    let mut k = [[0.0; N]; 7]; // k2..k8
    let mut yt = [0.0; N];
    combine(y, h, [V_A21], [k1], &mut yt);
    f(t + V_C[1] * h, &yt, &mut k[0]);
    combine(y, h, [V_A31, V_A32], [k1, &k[0]], &mut yt);
    f(t + V_C[2] * h, &yt, &mut k[1]);
    combine(y, h, [V_A41, V_A43], [k1, &k[1]], &mut yt);
    f(t + V_C[3] * h, &yt, &mut k[2]);
    combine(y, h, [V_A51, V_A53, V_A54], [k1, &k[1], &k[2]], &mut yt);
    f(t + V_C[4] * h, &yt, &mut k[3]);
    let a6 = [V_A61, V_A63, V_A64, V_A65];
    combine(y, h, a6, [k1, &k[1], &k[2], &k[3]], &mut yt);
    f(t + V_C[5] * h, &yt, &mut k[4]);
    let a7 = [V_A71, V_A73, V_A74, V_A75, V_A76];
    combine(y, h, a7, [k1, &k[1], &k[2], &k[3], &k[4]], &mut yt);
    f(t + V_C[6] * h, &yt, &mut k[5]);
    let a8 = [V_A81, V_A83, V_A84, V_A85, V_A86, V_A87];
    combine(y, h, a8, [k1, &k[1], &k[2], &k[3], &k[4], &k[5]], &mut yt);
    f(t + h, &yt, &mut k[6]);
    let b = [V_B1, V_B4, V_B5, V_B6, V_B7, V_B8];
    combine(y, h, b, [k1, &k[2], &k[3], &k[4], &k[5], &k[6]], y_new);
    f(t + h, y_new, k9);
    let d = [V_D1, V_D4, V_D5, V_D6, V_D7, V_D8, V_D9];
    combine(
        &[0.0; N],
        h,
        d,
        [k1, &k[2], &k[3], &k[4], &k[5], &k[6], k9],
        e,
    );
}

/// A system split for the additive (IMEX) stepper [`Ark436`]: `f = f_E + f_I`, where `f_I` is the
/// part of the right-hand side in the components flagged by [`implicit`](ImexSystem::implicit)
/// (they are advanced with the implicit tableau) and `f_E` the rest (explicit tableau).
pub trait ImexSystem<const N: usize> {
    /// Full right-hand side `dy = f(y)` (autonomous within one call: inputs are held).
    fn rhs(&self, y: &[f64; N], dy: &mut [f64; N]);
    /// Whether component `i` is treated implicitly.
    fn implicit(&self, i: usize) -> bool;
    /// Solves the stage equation `y_I = c_I + h_gamma f_I(y)` in place: on entry the explicit
    /// components of `y` are final and the implicit ones hold `c_I`; on exit the implicit ones hold
    /// the solution, and `diag[i]` holds `1 - h_gamma df_i/dy_i` there for each implicit `i`
    /// (used to filter the error estimate). `false` if the solve failed (the step is then retried
    /// smaller).
    fn solve_implicit(&self, y: &mut [f64; N], h_gamma: f64, diag: &mut [f64; N]) -> bool;
}

// ARK4(3)6L\[2\]SA of Kennedy & Carpenter (2003, Appl. Numer. Math. 44, 139-181): an explicit
// 6-stage tableau (AE) paired with an L-stable, stiffly accurate ESDIRK (AI, diagonal 1/4), both
// sharing c, b and the embedded 3rd-order weights bh. The order conditions (including the
// coupling conditions between AE and AI) are checked in the tests below.
#[cfg_attr(not(test), allow(dead_code))] // c is implied by the row sums (tests check it)
const ARK_C: [f64; 6] = [0.0, 0.5, 83.0 / 250.0, 31.0 / 50.0, 17.0 / 20.0, 1.0];
const ARK_AE: [[f64; 6]; 6] = [
    [0.0; 6],
    [0.5, 0.0, 0.0, 0.0, 0.0, 0.0],
    [13861.0 / 62500.0, 6889.0 / 62500.0, 0.0, 0.0, 0.0, 0.0],
    [
        -116923316275.0 / 2393684061468.0,
        -2731218467317.0 / 15368042101831.0,
        9408046702089.0 / 11113171139209.0,
        0.0,
        0.0,
        0.0,
    ],
    [
        -451086348788.0 / 2902428689909.0,
        -2682348792572.0 / 7519795681897.0,
        12662868775082.0 / 11960479115383.0,
        3355817975965.0 / 11060851509271.0,
        0.0,
        0.0,
    ],
    [
        647845179188.0 / 3216320057751.0,
        73281519250.0 / 8382639484533.0,
        552539513391.0 / 3454668386233.0,
        3354512671639.0 / 8306763924573.0,
        4040.0 / 17871.0,
        0.0,
    ],
];
const ARK_GAMMA: f64 = 0.25;
const ARK_AI: [[f64; 6]; 6] = [
    [0.0; 6],
    [0.25, 0.25, 0.0, 0.0, 0.0, 0.0],
    [8611.0 / 62500.0, -1743.0 / 31250.0, 0.25, 0.0, 0.0, 0.0],
    [
        5012029.0 / 34652500.0,
        -654441.0 / 2922500.0,
        174375.0 / 388108.0,
        0.25,
        0.0,
        0.0,
    ],
    [
        15267082809.0 / 155376265600.0,
        -71443401.0 / 120774400.0,
        730878875.0 / 902184768.0,
        2285395.0 / 8070912.0,
        0.25,
        0.0,
    ],
    [
        82889.0 / 524892.0,
        0.0,
        15625.0 / 83664.0,
        69875.0 / 102672.0,
        -2260.0 / 8211.0,
        0.25,
    ],
];
const ARK_B: [f64; 6] = [
    82889.0 / 524892.0,
    0.0,
    15625.0 / 83664.0,
    69875.0 / 102672.0,
    -2260.0 / 8211.0,
    0.25,
];
const ARK_BH: [f64; 6] = [
    4586570599.0 / 29645900160.0,
    0.0,
    178811875.0 / 945068544.0,
    814220225.0 / 1159782912.0,
    -3700637.0 / 11593932.0,
    61727.0 / 225920.0,
];

/// Adaptive additive Runge-Kutta (IMEX) stepper ARK4(3)6L\[2\]SA for an `N`-dimensional state:
/// the components an [`ImexSystem`] flags as implicit go through the L-stable ESDIRK tableau,
/// the others through the explicit one. For a system whose stiffness sits in a few components
/// whose implicit stage equations are cheap to solve (here: the scalar Bouc-Wen variable of the
/// MR damper) the step size is set by accuracy, not by the stiff relaxation rate.
/// Order 4, embedded order 3, PI step-size control; the step size is carried across calls.
#[derive(Clone, Debug)]
pub struct Ark436<const N: usize> {
    /// Relative tolerance.
    pub rtol: f64,
    /// Absolute tolerance per component (in the component's unit).
    pub atol: [f64; N],
    /// Largest step, s (also capped by each call's interval).
    pub h_max: f64,
    /// Step-size floor in s: below it the integration fails instead of crawling.
    pub h_min: f64,
    h: f64,
    /// ln of the last accepted step's error norm (the PI controller's memory).
    ln_err_old: f64,
    /// Running totals (evaluations count full right-hand-side calls).
    pub stats: StepStats,
}

impl<const N: usize> Ark436<N> {
    /// A stepper with relative tolerance `rtol` and per-component absolute tolerances `atol`.
    pub fn new(rtol: f64, atol: [f64; N]) -> Self {
        Ark436 {
            rtol,
            atol,
            h_max: f64::INFINITY,
            h_min: 1e-12,
            h: 0.0,
            ln_err_old: ERR_FLOOR.ln(),
            stats: StepStats::default(),
        }
    }

    /// The step size the next step will try, s (0 before the first step).
    pub fn step_size(&self) -> f64 {
        self.h
    }

    /// Integrates `y` from `t0` over `dt` (the system is autonomous over the call). The step size
    /// is adapted to the tolerances and carried over to the next call.
    pub fn integrate<S: ImexSystem<N>>(
        &mut self,
        sys: &S,
        t0: f64,
        y: &mut [f64; N],
        dt: f64,
    ) -> Result<(), IntegrateError> {
        let t_end = t0 + dt;
        let mut t = t0;
        let split = Split::of(sys);
        let mut k = [[0.0; N]; 6];
        sys.rhs(y, &mut k[0]);
        self.stats.evaluations += 1;
        if self.h <= 0.0 {
            // Explicit-component estimate (Hairer's first guess), capped by the interval.
            let (mut d0, mut d1) = (0.0, 0.0);
            for i in 0..N {
                if split.imp[i] {
                    continue;
                }
                let sc = self.atol[i] + self.rtol * y[i].abs();
                d0 += (y[i] / sc) * (y[i] / sc);
                d1 += (k[0][i] / sc) * (k[0][i] / sc);
            }
            let h = if d0 < 1e-10 || d1 < 1e-10 {
                1e-6
            } else {
                0.01 * (d0 / d1).sqrt()
            };
            self.h = h.min(dt).min(self.h_max).max(1e-9);
        }
        // PI controller on the embedded (3rd-order) error: exponents 0.7/4 and 0.4/4.
        let pi = Pi {
            alpha: 0.7 / 4.0,
            beta: 0.4 / 4.0,
            fac_min: 0.2,
            fac_max: 5.0,
            safety: 0.9,
        };
        let mut y_new = [0.0; N];
        let mut last_rejected = false;
        let mut need_k0 = false;
        let mut diag = [1.0; N];
        while t < t_end {
            if need_k0 {
                sys.rhs(y, &mut k[0]);
                self.stats.evaluations += 1;
                need_k0 = false;
            }
            let (h, last) = next_step(self.h, self.h_max, self.h_min, t, t_end)?;
            let solved = ark_step(
                sys,
                &mut self.stats,
                &split,
                y,
                h,
                &mut k,
                &mut y_new,
                &mut diag,
            );
            let mut err2 = 0.0;
            if solved {
                for i in 0..N {
                    let mut e = 0.0;
                    for (j, kj) in k.iter().enumerate() {
                        e += (ARK_B[j] - ARK_BH[j]) * kj[i];
                    }
                    // For a stiff implicit component the raw estimate h (b - bh) k carries the
                    // stiff rate (k ~ lambda times the stage defect): filtered through
                    // (1 - h gamma df/dy)^-1 (Shampine's filter, as in RADAU5/RODAS) it
                    // measures the error of the solution rather than of its derivative.
                    let e = if split.imp[i] {
                        e / diag[i].max(1.0)
                    } else {
                        e
                    };
                    let sc = self.atol[i] + self.rtol * y[i].abs().max(y_new[i].abs());
                    let r = h * e / sc;
                    err2 += r * r;
                }
            }
            // an unsolved implicit stage fails the step as a non-finite error does
            let err = if solved {
                (err2 / N as f64).sqrt()
            } else {
                f64::NAN
            };
            let accepted = pi.judge(
                err,
                h,
                last,
                &mut self.h,
                &mut self.ln_err_old,
                &mut last_rejected,
            );
            if accepted {
                *y = y_new;
                t = if last { t_end } else { t + h };
                self.stats.accepted += 1;
                need_k0 = true;
            } else {
                self.stats.rejected += 1;
            }
        }
        if y.iter().all(|v| v.is_finite()) {
            Ok(())
        } else {
            Err(IntegrateError::NonFinite { t })
        }
    }
}

/// Which components of an [`ImexSystem`] are implicit, as flags and as a short index list (usually
/// one or two entries: touched a second time per stage).
struct Split<const N: usize> {
    imp: [bool; N],
    idx: [usize; N],
    n: usize,
}

impl<const N: usize> Split<N> {
    fn of<S: ImexSystem<N>>(sys: &S) -> Self {
        let mut s = Split {
            imp: [false; N],
            idx: [0; N],
            n: 0,
        };
        for i in 0..N {
            if sys.implicit(i) {
                s.imp[i] = true;
                s.idx[s.n] = i;
                s.n += 1;
            }
        }
        s
    }

    fn implicit_indices(&self) -> &[usize] {
        &self.idx[..self.n]
    }
}

/// One ARK4(3)6L\[2\]SA step of size `h` from `y`, with `k[0] = f(y)` on entry: fills the stage
/// derivatives `k[1..6]` (5 right-hand-side calls), the new state `y_new` and, for the implicit
/// components, `diag` (see [`ImexSystem::solve_implicit`]); counts its calls into `stats`.
/// `false` if a stage solve failed.
#[allow(clippy::too_many_arguments)]
fn ark_step<const N: usize, S: ImexSystem<N>>(
    sys: &S,
    stats: &mut StepStats,
    split: &Split<N>,
    y: &[f64; N],
    h: f64,
    k: &mut [[f64; N]; 6],
    y_new: &mut [f64; N],
    diag: &mut [f64; N],
) -> bool {
    let mut yt = [0.0; N];
    for s in 1..6 {
        let (ae, ai) = (&ARK_AE[s], &ARK_AI[s]);
        for i in 0..N {
            let mut acc = 0.0;
            for (j, kj) in k.iter().enumerate().take(s) {
                acc += ae[j] * kj[i];
            }
            yt[i] = y[i] + h * acc;
        }
        for &i in split.implicit_indices() {
            let mut acc = 0.0;
            for (j, kj) in k.iter().enumerate().take(s) {
                acc += ai[j] * kj[i];
            }
            yt[i] = y[i] + h * acc;
        }
        if !sys.solve_implicit(&mut yt, h * ARK_GAMMA, diag) {
            return false;
        }
        sys.rhs(&yt, &mut k[s]);
        stats.evaluations += 1;
    }
    for i in 0..N {
        // Stiffly accurate: the implicit components' new value is the last stage's.
        y_new[i] = if split.imp[i] {
            yt[i]
        } else {
            let mut acc = 0.0;
            for (j, kj) in k.iter().enumerate() {
                acc += ARK_B[j] * kj[i];
            }
            y[i] + h * acc
        };
    }
    true
}

/// The ARK4(3)6L\[2\]SA pair of [`Ark436`] at a fixed step: `substeps` equal steps per call, no
/// error control. For a closed loop at a fixed control period whose stiffness sits in the
/// implicit components, a step per period (or a few) is accurate to the method's 4th order in
/// the explicit states (shown by step halving in the tests), at 6 right-hand-side calls per
/// step instead of the ~12-17 per millisecond that stability asks of an explicit method.
#[derive(Clone, Debug)]
pub struct ArkFixed<const N: usize> {
    /// Equal steps per `integrate` call (at least 1).
    pub substeps: u32,
    /// Running totals (evaluations count full right-hand-side calls).
    pub stats: StepStats,
}

impl<const N: usize> ArkFixed<N> {
    /// A stepper taking `substeps` equal steps per call.
    pub fn new(substeps: u32) -> Self {
        ArkFixed {
            substeps: substeps.max(1),
            stats: StepStats::default(),
        }
    }

    /// Integrates `y` from `t0` over `dt` in `substeps` equal steps (the system is autonomous
    /// over the call). Fails if a stage solve fails or the state stops being finite.
    ///
    /// `start`: the right-hand side at `y` when the caller has it (evaluated there with the
    /// same system), which saves the first step's first evaluation.
    pub fn integrate<S: ImexSystem<N>>(
        &mut self,
        sys: &S,
        t0: f64,
        y: &mut [f64; N],
        dt: f64,
        mut start: Option<[f64; N]>,
    ) -> Result<(), IntegrateError> {
        let split = Split::of(sys);
        let n = self.substeps.max(1);
        let h = dt / f64::from(n);
        let mut k = [[0.0; N]; 6];
        let mut y_new = [0.0; N];
        let mut diag = [1.0; N];
        for step in 0..n {
            let t = t0 + f64::from(step) * h;
            match start.take() {
                Some(k0) => k[0] = k0,
                None => {
                    sys.rhs(y, &mut k[0]);
                    self.stats.evaluations += 1;
                }
            }
            let solved = ark_step(
                sys,
                &mut self.stats,
                &split,
                y,
                h,
                &mut k,
                &mut y_new,
                &mut diag,
            );
            if !solved || !y_new.iter().all(|v| v.is_finite()) {
                self.stats.rejected += 1;
                return Err(IntegrateError::NonFinite { t });
            }
            *y = y_new;
            self.stats.accepted += 1;
        }
        Ok(())
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

    /// The Verner 6(5) coefficients as typed: each row of A sums to its c, the weights sum to 1
    /// and the error weights to 0, and one step's error on a nonlinear, non-autonomous problem
    /// shrinks by 2^6 per step halving for the embedded 5th-order solution (local error O(h^6))
    /// and by more than 100 for the 6th-order one (O(h^7); measured 187, its leading term is
    /// small here). A mistyped digit drops the order and the ratio to 2^6 or less.
    #[test]
    fn vern65_coefficients_have_their_orders() {
        let rows: [&[f64]; 8] = [
            &[V_A21],
            &[V_A31, V_A32],
            &[V_A41, V_A43],
            &[V_A51, V_A53, V_A54],
            &[V_A61, V_A63, V_A64, V_A65],
            &[V_A71, V_A73, V_A74, V_A75, V_A76],
            &[V_A81, V_A83, V_A84, V_A85, V_A86, V_A87],
            &[V_B1, V_B4, V_B5, V_B6, V_B7, V_B8],
        ];
        for (i, r) in rows.iter().enumerate() {
            // To rounding: the entries reach ~200 in magnitude.
            let sum: f64 = r.iter().sum();
            let tol = 4.0 * f64::EPSILON * r.iter().map(|a| a.abs()).sum::<f64>();
            assert!((sum - V_C[i + 1]).abs() < tol, "row {}: {sum}", i + 2);
        }
        let d = [V_D1, V_D4, V_D5, V_D6, V_D7, V_D8, V_D9];
        let tol = 4.0 * f64::EPSILON * d.iter().map(|a| a.abs()).sum::<f64>();
        assert!(d.iter().sum::<f64>().abs() < tol);
        let mut f = |t: f64, y: &[f64; 2], dy: &mut [f64; 2]| {
            dy[0] = y[1];
            dy[1] = -y[0].sin() + 0.5 * t.cos() * y[1];
        };
        let y0 = [0.7, -0.3];
        // One step of size h from (0.2, y0) in n substeps: the 6th- and 5th-order solutions.
        let mut steps = |h: f64, n: u32| {
            let (mut y, mut y5) = (y0, y0);
            for j in 0..n {
                let t = 0.2 + f64::from(j) * h / f64::from(n);
                let mut k1 = [0.0; 2];
                f(t, &y, &mut k1);
                let (mut y6, mut k9, mut e) = ([0.0; 2], [0.0; 2], [0.0; 2]);
                vern65_step(
                    &mut f,
                    t,
                    &y,
                    h / f64::from(n),
                    &k1,
                    &mut y6,
                    &mut k9,
                    &mut e,
                );
                y5 = [y6[0] + e[0], y6[1] + e[1]];
                y = y6;
            }
            (y, y5)
        };
        let mut err = |h: f64| {
            let (y6, y5) = steps(h, 1);
            // The reference: 64 substeps (error ~ 64^-6 of one step's).
            let (r, _) = steps(h, 64);
            (
                (y6[0] - r[0]).hypot(y6[1] - r[1]),
                (y5[0] - r[0]).hypot(y5[1] - r[1]),
            )
        };
        // The 6th-order solution at larger steps (at 0.05 its error nears rounding).
        let (e6a, _) = err(0.4);
        let (e6b, _) = err(0.2);
        let (_, e5a) = err(0.1);
        let (_, e5b) = err(0.05);
        let (r6, r5) = (e6a / e6b, e5a / e5b);
        assert!(r6 > 100.0, "6th order: ratio {r6} ({e6a:e}, {e6b:e})");
        assert!(
            (48.0..85.0).contains(&r5),
            "5th order: ratio {r5} ({e5a:e}, {e5b:e})"
        );
    }

    /// The ARK4(3)6L\[2\]SA tableaux as typed satisfy the order conditions of an additive RK
    /// method up to order 4 (every mix of the explicit and implicit A, since b and c are shared),
    /// the embedded weights those up to order 3, both A have row sums c, the implicit tableau is
    /// stiffly accurate (b = its last row) with diagonal 1/4. Tolerance 1e-11: the published
    /// rationals of the explicit tableau are 13-digit approximations.
    #[test]
    fn ark436_tableaux_satisfy_the_order_conditions() {
        let c = ARK_C;
        let dot = |u: &[f64; 6], v: &[f64; 6]| (0..6).map(|i| u[i] * v[i]).sum::<f64>();
        let mv = |a: &[[f64; 6]; 6], v: &[f64; 6]| {
            let mut r = [0.0; 6];
            for i in 0..6 {
                r[i] = dot(&a[i], v);
            }
            r
        };
        let had = |u: &[f64; 6], v: &[f64; 6]| {
            let mut r = [0.0; 6];
            for i in 0..6 {
                r[i] = u[i] * v[i];
            }
            r
        };
        let ones = [1.0; 6];
        let tol = 1e-11;
        let mut worst: f64 = 0.0;
        let mut check = |got: f64, want: f64, what: &str| {
            worst = worst.max((got - want).abs());
            assert!((got - want).abs() < tol, "{what}: {got} vs {want}");
        };
        for a in [&ARK_AE, &ARK_AI] {
            let rs = mv(a, &ones);
            for i in 0..6 {
                check(rs[i], c[i], "row sum");
            }
        }
        for i in 0..6 {
            check(ARK_AI[5][i], ARK_B[i], "stiffly accurate");
            check(
                ARK_AI[i][i],
                if i == 0 { 0.0 } else { ARK_GAMMA },
                "diagonal",
            );
        }
        let c2 = had(&c, &c);
        let c3 = had(&c2, &c);
        for (b, order) in [(&ARK_B, 4), (&ARK_BH, 3)] {
            check(dot(b, &ones), 1.0, "order 1");
            check(dot(b, &c), 0.5, "order 2");
            check(dot(b, &c2), 1.0 / 3.0, "order 3 bushy");
            for a in [&ARK_AE, &ARK_AI] {
                check(dot(b, &mv(a, &c)), 1.0 / 6.0, "order 3 tall");
            }
            if order < 4 {
                continue;
            }
            check(dot(b, &c3), 0.25, "order 4 c^3");
            for a in [&ARK_AE, &ARK_AI] {
                check(dot(b, &had(&c, &mv(a, &c))), 1.0 / 8.0, "order 4 c A c");
                check(dot(b, &mv(a, &c2)), 1.0 / 12.0, "order 4 A c^2");
                for a2 in [&ARK_AE, &ARK_AI] {
                    check(dot(b, &mv(a, &mv(a2, &c))), 1.0 / 24.0, "order 4 A A c");
                }
            }
        }
        // The embedded pair differs (else the error estimate would be zero) and is not 4th order.
        let e4 = (dot(&ARK_BH, &c3) - 0.25).abs();
        assert!(e4 > 1e-4, "embedded weights look 4th order: {e4}");
        println!("worst order-condition residual {worst:.2e}");
    }

    /// Oscillator x'' = -w^2 x driving a Bouc-Wen-like hysteresis variable
    /// z' = x' - mu |x'| z |z| (plateaus z = +-1/sqrt(mu), relaxation rate 2 sqrt(mu) |x'| there:
    /// stiff for large mu, like the MR damper's z). z is implicit (scalar Newton solve), x
    /// explicit. With mu = 0 and zero start z = x exactly.
    struct StiffPair {
        w: f64,
        mu: f64,
    }

    impl ImexSystem<3> for StiffPair {
        fn rhs(&self, y: &[f64; 3], dy: &mut [f64; 3]) {
            dy[0] = y[1];
            dy[1] = -self.w * self.w * y[0];
            dy[2] = y[1] - self.mu * y[1].abs() * y[2] * y[2].abs();
        }
        fn implicit(&self, i: usize) -> bool {
            i == 2
        }
        fn solve_implicit(&self, y: &mut [f64; 3], hg: f64, diag: &mut [f64; 3]) -> bool {
            let (c, v) = (y[2], y[1]);
            let mut z = c;
            for _ in 0..50 {
                let g = z - c - hg * (v - self.mu * v.abs() * z * z.abs());
                let dg = 1.0 + hg * self.mu * v.abs() * 2.0 * z.abs();
                if dg <= 1e-12 {
                    return false;
                }
                let dz = g / dg;
                z -= dz;
                if dz.abs() <= 1e-15 * (1.0 + z.abs()) {
                    y[2] = z;
                    diag[2] = dg;
                    return true;
                }
            }
            false
        }
    }

    /// Fixed steps on the non-stiff pair (lambda = 1): halving h divides the error by ~2^4.
    #[test]
    fn ark436_is_fourth_order() {
        let sys = StiffPair { w: 3.0, mu: 0.5 };
        // Reference: Dopri5 at a tight tolerance on the same system.
        let mut f = |_t: f64, y: &[f64; 3], dy: &mut [f64; 3]| sys.rhs(y, dy);
        let mut y_ref = [1.0, 0.0, 0.0];
        let mut d = Dopri5::new(1e-13, [1e-15; 3]);
        d.integrate(&mut f, 0.0, &mut y_ref, 2.0).unwrap();
        let err = |h: f64| {
            let mut s = Ark436::new(1e3, [1e3; 3]);
            s.h_max = h;
            let mut y = [1.0, 0.0, 0.0];
            let mut t = 0.0;
            while t < 2.0 - 1e-12 {
                s.integrate(&sys, t, &mut y, h).unwrap();
                t += h;
            }
            (0..3).map(|i| (y[i] - y_ref[i]).abs()).fold(0.0, f64::max)
        };
        let p = (err(0.04) / err(0.02)).log2();
        assert!((p - 4.0).abs() < 0.4, "ARK order {p}");
    }

    /// Stiff hysteresis (mu = 1e8: plateau 1e-4, relaxation rate up to 2e4 |x'| ~ 9e4 /s at 7 Hz
    /// and amplitude 0.1): the adaptive ARK steps over the plateaus with steps set by accuracy and
    /// needs at most half the evaluations of Dopri5 (stability-limited there; measured 7657 vs
    /// 56078) at the same tolerance; both agree with a tight Dopri5 reference to 1e-7 (tolerance
    /// 1e-8 per step). At mu = 1e6 (rate ~9e3 /s) both need about the same number: the gain
    /// needs stiffness well beyond what accuracy alone asks for.
    #[test]
    fn ark436_steps_over_a_stiff_relaxation() {
        let sys = StiffPair {
            w: 2.0 * std::f64::consts::PI * 7.0,
            mu: 1e8,
        };
        let mut f = |_t: f64, y: &[f64; 3], dy: &mut [f64; 3]| sys.rhs(y, dy);
        let y0 = [0.1, 0.0, 0.0];
        let (mut ya, mut yd, mut yr) = (y0, y0, y0);
        let mut a = Ark436::new(1e-8, [1e-10; 3]);
        let mut d = Dopri5::new(1e-8, [1e-10; 3]);
        let mut r = Dopri5::new(1e-12, [1e-14; 3]);
        let mut t = 0.0;
        let (mut da, mut dd) = (0.0f64, 0.0f64);
        for _ in 0..500 {
            a.integrate(&sys, t, &mut ya, 1e-3).unwrap();
            d.integrate(&mut f, t, &mut yd, 1e-3).unwrap();
            r.integrate(&mut f, t, &mut yr, 1e-3).unwrap();
            t += 1e-3;
            for i in 0..3 {
                da = da.max((ya[i] - yr[i]).abs());
                dd = dd.max((yd[i] - yr[i]).abs());
            }
        }
        println!(
            "ARK {:?} err {da:.2e}; Dopri5 {:?} err {dd:.2e}",
            a.stats, d.stats
        );
        assert!(da < 1e-7 && dd < 1e-7, "errors: ARK {da}, Dopri5 {dd}");
        assert!(
            a.stats.evaluations * 2 < d.stats.evaluations,
            "ARK not cheaper"
        );
    }
}
