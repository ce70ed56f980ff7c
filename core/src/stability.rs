//! Stability of straight running vs speed: least-damped mode, Hopf crossings, critical speed.
//!
//! The growth rate g(V) = max Re lambda over the *oscillatory* eigenvalues of A(V) (real
//! eigenvalues are excluded: a Hopf point is a complex pair crossing the imaginary axis). A
//! crossing is bracketed on a speed grid and refined with Brent's method to a speed tolerance
//! (default 1e-5 m/s). Nothing here allocates; all work is bounded by explicit evaluation
//! budgets. The Hopf window is computed, never typed in. Every function works for any model of
//! the family ([`LinearModel`]); the car's [`crate::vehicles::car::PlantParams`] is one.

use heapless::Vec;
use nalgebra::Complex;

use crate::eigen::{
    self, critical_oscillatory_mode, least_damped_mode, EigenError, EigenvaluesOf, Matrix, Mode,
    ModeShape, ModeShapeInfo,
};
use crate::model::LinearModel;

/// Capacity of a crossing list.
pub const MAX_CROSSINGS: usize = 8;

/// Default speed tolerance of the root refinement, m/s.
pub const DEFAULT_TOL_MPS: f64 = 1e-5;

/// Lowest speed the searches look at, m/s (at V = 0 the tyre states are pure integrators).
pub const V_SEARCH_MIN_MPS: f64 = 0.1;
/// Highest speed the searches look at, m/s (252 km/h).
pub const V_SEARCH_MAX_MPS: f64 = 70.0;

/// Errors of the stability analysis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StabilityError {
    /// An eigen-solve failed.
    #[error("eigen-solve failed: {0}")]
    Eigen(EigenError),
    /// Speed range or step not finite/positive/ordered.
    #[error("speed range or step is not finite, positive and ordered")]
    BadRange,
    /// More crossings than [`MAX_CROSSINGS`].
    #[error("more Hopf crossings than MAX_CROSSINGS")]
    TooManyCrossings,
    /// No sign change of g(V) found within the budget and range.
    #[error("no sign change of the growth rate within the budget and range")]
    NotFound,
    /// The evaluation budget is too small to do anything (< 2).
    #[error("evaluation budget below 2")]
    BudgetTooSmall,
}

impl From<EigenError> for StabilityError {
    fn from(e: EigenError) -> Self {
        StabilityError::Eigen(e)
    }
}

/// Direction of a Hopf crossing with increasing speed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CrossingKind {
    /// Stable below, unstable above (shimmy begins).
    Onset,
    /// Unstable below, stable above (shimmy ends).
    Offset,
}

impl CrossingKind {
    /// Label for tables and CSV.
    pub const fn name(self) -> &'static str {
        match self {
            CrossingKind::Onset => "onset",
            CrossingKind::Offset => "offset",
        }
    }
}

/// One Hopf crossing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HopfCrossing {
    /// Critical speed, m/s.
    pub speed_mps: f64,
    /// Onset or offset.
    pub kind: CrossingKind,
    /// Frequency of the crossing mode, Hz.
    pub freq_hz: f64,
    /// Shape of the crossing mode.
    pub shape: ModeShape,
    /// Width of the final bracket, m/s (<= the tolerance when converged).
    pub bracket_mps: f64,
    /// Whether Brent met the tolerance within its iteration bound.
    pub converged: bool,
}

/// Crossings found over a range, in increasing speed.
pub type Crossings = Vec<HopfCrossing, MAX_CROSSINGS>;

/// Eigenvalues of A(V) with a viscous damper `c_damper_nspm`.
pub fn eigenvalues_at<M: LinearModel<N>, const N: usize>(
    p: &M,
    v_mps: f64,
    c_damper_nspm: f64,
) -> Result<EigenvaluesOf<N>, EigenError> {
    eigen::eigenvalues(&p.linearise(v_mps, c_damper_nspm))
}

/// Growth rate g(V) = max Re lambda over the oscillatory eigenvalues in 1/s, and that mode.
pub fn critical_mode_at<M: LinearModel<N>, const N: usize>(
    p: &M,
    v_mps: f64,
    c_damper_nspm: f64,
) -> Result<Mode, EigenError> {
    critical_oscillatory_mode(&eigenvalues_at(p, v_mps, c_damper_nspm)?)
}

/// Which mode a query is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModeSelect {
    /// The oscillatory mode with the smallest damping ratio (can be the lightly damped
    /// ~47 Hz anti-phase track-rod mode outside the Hopf window).
    LeastDamped,
    /// The oscillatory mode with the largest real part (the one that crosses at a Hopf point).
    Critical,
    /// The least-damped oscillatory mode whose shape is the shimmy mode ([`ModeShape::is_shimmy`]:
    /// in-phase wheel yaw, the trailer's sway), the one the data-driven mode meter sees. Costs
    /// one complex LU per oscillatory pair.
    Shimmy,
}

/// The selected mode of A and its eigenvalue (+Im member).
pub fn select_mode<M: LinearModel<N>, const N: usize>(
    p: &M,
    a: &Matrix<N>,
    vals: &EigenvaluesOf<N>,
    select: ModeSelect,
) -> Result<Mode, EigenError> {
    select_mode_of::<f64, M, N>(p, a, vals, select)
}

/// [`select_mode`] with the mode-shape eigenvectors computed in `T`.
pub fn select_mode_of<T: eigen::SolveFloat, M: LinearModel<N>, const N: usize>(
    p: &M,
    a: &Matrix<N>,
    vals: &EigenvaluesOf<N>,
    select: ModeSelect,
) -> Result<Mode, EigenError> {
    match select {
        ModeSelect::LeastDamped => least_damped_mode(vals),
        ModeSelect::Critical => critical_oscillatory_mode(vals),
        ModeSelect::Shimmy => {
            let mut best: Option<Mode> = None;
            for l in vals
                .iter()
                .filter(|l| l.im > 0.0 && eigen::is_oscillatory(**l))
            {
                let shape = eigen::mode_shape_of::<T, M, N>(p, a, *l)?;
                if shape.shape.is_shimmy() {
                    let m = Mode::from_eigenvalue(*l);
                    if best.is_none_or(|b| m.zeta < b.zeta) {
                        best = Some(m);
                    }
                }
            }
            best.ok_or(EigenError::NoMode)
        }
    }
}

/// The selected mode of A(V) with a viscous damper `c_damper_nspm`.
pub fn mode_at<M: LinearModel<N>, const N: usize>(
    p: &M,
    v_mps: f64,
    c_damper_nspm: f64,
    select: ModeSelect,
) -> Result<Mode, EigenError> {
    let a = p.linearise(v_mps, c_damper_nspm);
    let vals = eigen::eigenvalues(&a)?;
    select_mode(p, &a, &vals, select)
}

/// Summary of the modes at one speed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModeSummary {
    /// Speed, m/s.
    pub v_mps: f64,
    /// Largest real part over all eigenvalues, 1/s.
    pub max_re: f64,
    /// Oscillatory mode with the largest real part.
    pub critical: Mode,
    /// Oscillatory mode with the smallest damping ratio.
    pub least_damped: Mode,
    /// Shape of the least-damped mode.
    pub least_damped_shape: ModeShapeInfo,
}

/// Modes at one speed, with the least-damped mode's shape (one eigen-solve + one complex LU).
pub fn mode_summary<M: LinearModel<N>, const N: usize>(
    p: &M,
    v_mps: f64,
    c_damper_nspm: f64,
) -> Result<ModeSummary, EigenError> {
    let a = p.linearise(v_mps, c_damper_nspm);
    let vals = eigen::eigenvalues(&a)?;
    let least = least_damped_mode(&vals)?;
    Ok(ModeSummary {
        v_mps,
        max_re: eigen::max_real_part(&vals),
        critical: critical_oscillatory_mode(&vals)?,
        least_damped: least,
        least_damped_shape: eigen::mode_shape(p, &a, least.eigenvalue())?,
    })
}

/// The selected mode and its sensitivities d(lambda)/dV and d(zeta)/dV at `v_mps`, from the
/// first-order eigenvalue perturbation dlambda = w^H (dA/dV) v / (w^H v) with the right and left
/// eigenvectors v, w (A is affine in V, so dA/dV is exact). Returns (mode, dzeta/dV in s/m,
/// dlambda/dV in 1/m).
pub fn dzeta_dv<M: LinearModel<N>, const N: usize>(
    p: &M,
    v_mps: f64,
    c_damper_nspm: f64,
    select: ModeSelect,
) -> Result<(Mode, f64, Complex<f64>), EigenError> {
    let a = p.linearise(v_mps, c_damper_nspm);
    let vals = eigen::eigenvalues(&a)?;
    let mode = select_mode(p, &a, &vals, select)?;
    let lambda = mode.eigenvalue();
    let v = eigen::eigenvector(&a, lambda)?;
    let w = eigen::left_eigenvector(&a, lambda)?;
    let da = p.dlinearise_dv().map(|x| Complex::new(x, 0.0));
    let num = (w.adjoint() * da * v)[(0, 0)];
    let den = (w.adjoint() * v)[(0, 0)];
    if den.re == 0.0 && den.im == 0.0 {
        return Err(EigenError::Singular);
    }
    let dl = num / den;
    let r = mode.omega_n;
    // zeta = -re / |lambda|; d|lambda| = (re dre + im dim) / |lambda|.
    let dr = (lambda.re * dl.re + lambda.im * dl.im) / r;
    let dzeta = -(dl.re * r - lambda.re * dr) / (r * r);
    if !dzeta.is_finite() {
        return Err(EigenError::NonFiniteResult);
    }
    Ok((mode, dzeta, dl))
}

/// Result of a bounded Brent search.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Root {
    /// Best estimate of the root.
    pub x: f64,
    /// Final bracket [lo, hi] (contains a sign change).
    pub lo: f64,
    /// Upper end of the bracket.
    pub hi: f64,
    /// Function evaluations used.
    pub evals: usize,
    /// Whether |hi - lo| <= 2 tol (or f(x) == 0) was reached within `max_evals`.
    pub converged: bool,
}

/// Brent's method (inverse quadratic / secant / bisection) on a bracket [a, b] with
/// fa fb < 0, at most `max_evals` further evaluations of `f`. Never panics; errors of `f` are
/// passed through.
pub fn brent<E>(
    mut f: impl FnMut(f64) -> Result<f64, E>,
    a0: f64,
    b0: f64,
    fa0: f64,
    fb0: f64,
    tol: f64,
    max_evals: usize,
) -> Result<Root, E> {
    let (mut a, mut b, mut fa, mut fb) = (a0, b0, fa0, fb0);
    let mut evals = 0;
    if fa == 0.0 || fb == 0.0 {
        let x = if fa == 0.0 { a } else { b };
        return Ok(Root {
            x,
            lo: x,
            hi: x,
            evals,
            converged: true,
        });
    }
    // c is the previous b (contrapoint side); d, e are the last two steps.
    let (mut c, mut fc) = (a, fa);
    let mut d = b - a;
    let mut e = d;
    loop {
        if (fb > 0.0) == (fc > 0.0) {
            c = a;
            fc = fa;
            d = b - a;
            e = d;
        }
        if libm::fabs(fc) < libm::fabs(fb) {
            a = b;
            b = c;
            c = a;
            fa = fb;
            fb = fc;
            fc = fa;
        }
        let tol1 = 2.0 * f64::EPSILON * libm::fabs(b) + 0.5 * tol;
        let xm = 0.5 * (c - b);
        let (lo, hi) = if b < c { (b, c) } else { (c, b) };
        if libm::fabs(xm) <= tol1 || fb == 0.0 {
            return Ok(Root {
                x: b,
                lo,
                hi,
                evals,
                converged: true,
            });
        }
        if evals >= max_evals {
            return Ok(Root {
                x: b,
                lo,
                hi,
                evals,
                converged: false,
            });
        }
        if libm::fabs(e) >= tol1 && libm::fabs(fa) > libm::fabs(fb) {
            // Interpolation step.
            let s = fb / fa;
            let (mut pp, mut q);
            if a == c {
                pp = 2.0 * xm * s;
                q = 1.0 - s;
            } else {
                let qa = fa / fc;
                let r = fb / fc;
                pp = s * (2.0 * xm * qa * (qa - r) - (b - a) * (r - 1.0));
                q = (qa - 1.0) * (r - 1.0) * (s - 1.0);
            }
            if pp > 0.0 {
                q = -q;
            }
            pp = libm::fabs(pp);
            let min1 = 3.0 * xm * q - libm::fabs(tol1 * q);
            let min2 = libm::fabs(e * q);
            if 2.0 * pp < min1.min(min2) {
                e = d;
                d = pp / q;
            } else {
                d = xm;
                e = d;
            }
        } else {
            d = xm;
            e = d;
        }
        a = b;
        fa = fb;
        b += if libm::fabs(d) > tol1 {
            d
        } else if xm > 0.0 {
            tol1
        } else {
            -tol1
        };
        fb = f(b)?;
        evals += 1;
    }
}

fn g<M: LinearModel<N>, const N: usize>(p: &M, c: f64, v: f64) -> Result<f64, EigenError> {
    Ok(critical_mode_at(p, v, c)?.re)
}

/// All Hopf crossings of the straight-running equilibrium in [v_min, v_max] (m/s): g(V) is
/// sampled every `step_mps`, each sign change is refined with Brent to `tol_mps`. Two crossings
/// closer than one grid step can be missed (documented limitation; use a finer step).
pub fn hopf_crossings<M: LinearModel<N>, const N: usize>(
    p: &M,
    c_damper_nspm: f64,
    v_min_mps: f64,
    v_max_mps: f64,
    step_mps: f64,
    tol_mps: f64,
) -> Result<Crossings, StabilityError> {
    let ok = v_min_mps.is_finite()
        && v_max_mps.is_finite()
        && step_mps.is_finite()
        && tol_mps.is_finite()
        && v_min_mps > 0.0
        && v_max_mps > v_min_mps
        && step_mps > 0.0
        && tol_mps > 0.0
        && (v_max_mps - v_min_mps) / step_mps < 1e6;
    if !ok {
        return Err(StabilityError::BadRange);
    }
    let mut out = Crossings::new();
    let n = libm::ceil((v_max_mps - v_min_mps) / step_mps) as usize;
    let mut v_prev = v_min_mps;
    let mut g_prev = g(p, c_damper_nspm, v_prev)?;
    for i in 1..=n {
        let v = (v_min_mps + i as f64 * step_mps).min(v_max_mps);
        let gv = g(p, c_damper_nspm, v)?;
        if (g_prev < 0.0) != (gv < 0.0) {
            let root = brent(
                |x| g(p, c_damper_nspm, x),
                v_prev,
                v,
                g_prev,
                gv,
                tol_mps,
                200,
            )?;
            let kind = if g_prev < 0.0 {
                CrossingKind::Onset
            } else {
                CrossingKind::Offset
            };
            let a = p.linearise(root.x, c_damper_nspm);
            let vals = eigen::eigenvalues(&a)?;
            let mode = critical_oscillatory_mode(&vals)?;
            let shape = eigen::mode_shape(p, &a, mode.eigenvalue())?;
            out.push(HopfCrossing {
                speed_mps: root.x,
                kind,
                freq_hz: mode.freq_hz,
                shape: shape.shape,
                bracket_mps: root.hi - root.lo,
                converged: root.converged,
            })
            .map_err(|_| StabilityError::TooManyCrossings)?;
        }
        v_prev = v;
        g_prev = gv;
    }
    Ok(out)
}

/// Answer of [`critical_speed_near`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CriticalSpeed {
    /// Critical (Hopf) speed, m/s: the best estimate, inside the final bracket.
    pub speed_mps: f64,
    /// Onset or offset (direction of the sign change with increasing speed).
    pub kind: CrossingKind,
    /// Frequency of the critical mode at `speed_mps`, Hz (from the last evaluation).
    pub freq_hz: f64,
    /// Final bracket width, m/s.
    pub bracket_mps: f64,
    /// Eigen-solves used.
    pub evals: usize,
    /// Whether the tolerance was met within the budget.
    pub converged: bool,
}

/// The Hopf crossing nearest to `hint` (or to `v_now_mps` without a hint), with at most
/// `max_evals` eigen-solves (one solve = `linearise` + balanced bounded Schur of an N x N).
///
/// Warm start: pass the previous answer as `hint`; the search then probes hint +- 0.05 m/s,
/// widening the step by 2x per probe pair, and refines the first bracket with Brent to
/// [`DEFAULT_TOL_MPS`]. If the budget runs out during refinement the best estimate is returned
/// with `converged = false`; if no bracket is found, [`StabilityError::NotFound`].
/// No allocation; work is bounded by `max_evals`.
pub fn critical_speed_near<M: LinearModel<N>, const N: usize>(
    p: &M,
    c_damper_nspm: f64,
    v_now_mps: f64,
    hint_mps: Option<f64>,
    max_evals: usize,
) -> Result<CriticalSpeed, StabilityError> {
    if max_evals < 2 {
        return Err(StabilityError::BudgetTooSmall);
    }
    let (center, mut step) = match hint_mps {
        Some(h) if h.is_finite() => (h, 0.05),
        _ => (v_now_mps, 1.0),
    };
    if !center.is_finite() {
        return Err(StabilityError::BadRange);
    }
    let center = center.clamp(V_SEARCH_MIN_MPS, V_SEARCH_MAX_MPS);
    let mut evals = 0usize;
    let g0 = g(p, c_damper_nspm, center)?;
    evals += 1;
    // Probe outward, alternating sides; lo/hi are the innermost points on each side so far.
    let (mut lo, mut g_lo) = (center, g0);
    let (mut hi, mut g_hi) = (center, g0);
    let mut bracket: Option<(f64, f64, f64, f64)> = None;
    // Keep one evaluation for the mode at the root.
    while evals + 1 < max_evals && bracket.is_none() {
        let can_up = hi < V_SEARCH_MAX_MPS;
        let can_down = lo > V_SEARCH_MIN_MPS;
        if !can_up && !can_down {
            break;
        }
        if can_up {
            let v = (hi + step).min(V_SEARCH_MAX_MPS);
            let gv = g(p, c_damper_nspm, v)?;
            evals += 1;
            if (gv < 0.0) != (g_hi < 0.0) {
                bracket = Some((hi, v, g_hi, gv));
                break;
            }
            hi = v;
            g_hi = gv;
        }
        if can_down && evals + 1 < max_evals {
            let v = (lo - step).max(V_SEARCH_MIN_MPS);
            let gv = g(p, c_damper_nspm, v)?;
            evals += 1;
            if (gv < 0.0) != (g_lo < 0.0) {
                bracket = Some((v, lo, gv, g_lo));
                break;
            }
            lo = v;
            g_lo = gv;
        }
        step *= 2.0;
    }
    let Some((a, b, fa, fb)) = bracket else {
        return Err(StabilityError::NotFound);
    };
    let kind = if fa < 0.0 {
        CrossingKind::Onset
    } else {
        CrossingKind::Offset
    };
    let budget = max_evals.saturating_sub(evals).saturating_sub(1);
    let root = brent(
        |x| g(p, c_damper_nspm, x),
        a,
        b,
        fa,
        fb,
        DEFAULT_TOL_MPS,
        budget,
    )?;
    evals += root.evals;
    let mode = critical_mode_at(p, root.x, c_damper_nspm)?;
    evals += 1;
    Ok(CriticalSpeed {
        speed_mps: root.x,
        kind,
        freq_hz: mode.freq_hz,
        bracket_mps: root.hi - root.lo,
        evals,
        converged: root.converged,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::units::{kmh_to_mps, mps_to_kmh};
    use crate::vehicles::car::{Param, ParamSet, PlantParams};

    fn ab(c: Complex<f64>) -> f64 {
        c.re.hypot(c.im)
    }

    fn window(p: &PlantParams, c: f64) -> Crossings {
        hopf_crossings(
            p,
            c,
            kmh_to_mps(1.0),
            kmh_to_mps(150.0),
            kmh_to_mps(1.0),
            DEFAULT_TOL_MPS,
        )
        .unwrap()
    }

    #[test]
    fn nominal_has_a_hopf_window_of_the_in_phase_mode_with_the_steering_wheel_swinging() {
        let p = ParamSet::Nominal.params();
        let w = window(&p, 0.0);
        assert_eq!(w.len(), 2, "{w:?}");
        assert_eq!(
            (w[0].kind, w[1].kind),
            (CrossingKind::Onset, CrossingKind::Offset)
        );
        let (on, off) = (mps_to_kmh(w[0].speed_mps), mps_to_kmh(w[1].speed_mps));
        // "At road speeds": inside 10..130 km/h, and a window, not a point.
        assert!(on > 10.0 && off < 130.0 && off - on > 10.0, "{on} {off}");
        for c in &w {
            assert!(c.converged && c.bracket_mps <= 2.0 * DEFAULT_TOL_MPS);
            assert_eq!(c.shape, ModeShape::InPhaseWheelYaw);
            // "A few Hz": between 1 and 20 Hz.
            assert!(c.freq_hz > 1.0 && c.freq_hz < 20.0, "{}", c.freq_hz);
        }
        // Inside the window: the least-damped mode is the in-phase wheel-yaw mode, the steering
        // wheel swings (a sizeable fraction of the rigid-link amplitude) and the wheels move in
        // phase.
        let mid = 0.5 * (w[0].speed_mps + w[1].speed_mps);
        let s = mode_summary(&p, mid, 0.0).unwrap();
        assert!(s.max_re > 0.0 && s.least_damped.zeta < 0.0);
        assert_eq!(s.least_damped_shape.shape, ModeShape::InPhaseWheelYaw);
        assert!(s.least_damped_shape.steering_wheel_ratio > 0.1);
        assert!(s.least_damped_shape.wheel_phase_rad.abs() < 0.2);
        // Outside it, straight running is stable.
        for v in [w[0].speed_mps - 1.0, w[1].speed_mps + 1.0] {
            assert!(critical_mode_at(&p, v, 0.0).unwrap().re < 0.0);
        }
    }

    #[test]
    fn without_spin_inertia_there_is_no_offset() {
        let p = ParamSet::Nominal.params().with(Param::IP, 0.0);
        let w = window(&p, 0.0);
        assert_eq!(w.len(), 1, "{w:?}");
        assert_eq!(w[0].kind, CrossingKind::Onset);
    }

    #[test]
    fn hard_is_wider_and_slower_gentle_narrower() {
        let width = |s: ParamSet| {
            let w = window(&s.params(), 0.0);
            assert_eq!(w.len(), 2, "{}: {w:?}", s.name());
            (
                w[1].speed_mps - w[0].speed_mps,
                w[0].freq_hz.max(w[1].freq_hz),
            )
        };
        let (wn, fn_) = width(ParamSet::Nominal);
        let (wh, fh) = width(ParamSet::Hard);
        let (wg, _) = width(ParamSet::Gentle);
        assert!(wh > wn && fh < fn_, "hard {wh} {fh} nominal {wn} {fn_}");
        assert!(wg < wn, "gentle {wg} nominal {wn}");
    }

    #[test]
    fn a_large_viscous_damper_removes_the_window_and_a_small_one_does_not() {
        let p = ParamSet::Nominal.params();
        assert_eq!(window(&p, 10.0).len(), 2);
        assert!(window(&p, 20_000.0).is_empty());
    }

    #[test]
    fn brent_root_agrees_with_a_dense_sweep() {
        // Independent of Brent: the sign change of g on a 0.001 km/h grid around the root.
        let p = ParamSet::Nominal.params();
        for c in window(&p, 0.0) {
            let centre = mps_to_kmh(c.speed_mps);
            let mut prev = None;
            let mut found = None;
            for i in -50..=50 {
                let kmh = (centre * 1000.0).round() / 1000.0 + i as f64 * 0.001;
                let gv = g(&p, 0.0, kmh_to_mps(kmh)).unwrap();
                if let Some((k0, g0)) = prev {
                    if (g0 < 0.0) != (gv < 0.0) {
                        found = Some(0.5 * (k0 + kmh));
                    }
                }
                prev = Some((kmh, gv));
            }
            let dense = found.expect("sign change near the Brent root");
            assert!(
                (dense - centre).abs() <= 0.001,
                "dense {dense} brent {centre}"
            );
        }
    }

    #[test]
    fn critical_speed_near_warm_and_cold_start_agree_with_the_scan() {
        let p = ParamSet::Nominal.params();
        let w = window(&p, 0.0);
        // Cold start from below the onset finds the onset.
        let cold = critical_speed_near(&p, 0.0, w[0].speed_mps - 3.0, None, 40).unwrap();
        assert!(cold.converged);
        assert_eq!(cold.kind, CrossingKind::Onset);
        assert!((cold.speed_mps - w[0].speed_mps).abs() < 1e-4);
        // Warm start from a hint 0.2 m/s off uses few evaluations.
        let warm = critical_speed_near(&p, 0.0, 20.0, Some(w[1].speed_mps + 0.2), 20).unwrap();
        assert!(warm.converged && warm.kind == CrossingKind::Offset);
        assert!((warm.speed_mps - w[1].speed_mps).abs() < 1e-4);
        println!("cold evals {}, warm evals {}", cold.evals, warm.evals);
        assert!(warm.evals <= 15, "{}", warm.evals);
        // A tiny budget returns an unconverged estimate or NotFound, never hangs.
        match critical_speed_near(&p, 0.0, 5.0, None, 3) {
            Ok(r) => assert!(!r.converged && r.evals <= 3),
            Err(e) => assert_eq!(e, StabilityError::NotFound),
        }
        // No crossing at all with a big damper.
        assert_eq!(
            critical_speed_near(&p, 20_000.0, 20.0, None, 60),
            Err(StabilityError::NotFound)
        );
    }

    #[test]
    fn dzeta_dv_matches_central_differences() {
        let p = ParamSet::Nominal.params();
        for (v, sel) in [
            (12.0, ModeSelect::Shimmy),
            (20.0, ModeSelect::Critical),
            (30.0, ModeSelect::LeastDamped),
        ] {
            let (m, dz, dl) = dzeta_dv(&p, v, 0.0, sel).unwrap();
            let h = 1e-4;
            // Track the same mode: eigenvalue nearest the one at v.
            let near = |vv: f64| {
                let vals = eigenvalues_at(&p, vv, 0.0).unwrap();
                let l = m.eigenvalue();
                *vals
                    .iter()
                    .min_by(|a, b| ab(**a - l).total_cmp(&ab(**b - l)))
                    .unwrap()
            };
            let (lp, lm) = (near(v + h), near(v - h));
            let fd = (lp - lm) / (2.0 * h);
            assert!(ab(fd - dl) < 1e-5 * (1.0 + ab(dl)), "{fd} {dl}");
            let z = |l: Complex<f64>| -l.re / ab(l);
            let fdz = (z(lp) - z(lm)) / (2.0 * h);
            assert!((fdz - dz).abs() < 1e-6 * (1.0 + dz.abs()), "{fdz} {dz}");
        }
    }
}
