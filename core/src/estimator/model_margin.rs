//! Model-based eigenvalue margin, computed incrementally so that no control step overruns.
//!
//! One *update cycle* at the speed V latched at its start:
//!
//! 1. `Modes`: A(V) (with the damper's equivalent viscous coefficient c), one bounded
//!    eigen-solve, the shimmy mode ([`ModeSelect::Shimmy`]: least-damped in-phase wheel-yaw
//!    pair; the lightly damped ~47 Hz anti-phase track-rod mode is *not* the shimmy mode), the
//!    critical oscillatory mode (largest Re, the one that crosses at a Hopf point) and max Re;
//! 2. `Slope`: d zeta / dV of the shimmy mode by first-order eigenvalue perturbation
//!    (right and left eigenvector by inverse iteration, dA/dV exact; no eigen-solve);
//! 3. `Above`: the first Hopf crossing of g(V) = max Re over the oscillatory eigenvalues above
//!    V: probes upward (warm start: previous answer +- `hint_probe_mps`, else steps from
//!    `cold_step_mps` doubling up to `max_step_mps`), then Brent's method, resumable, one g
//!    evaluation (= one eigen-solve) per call, to `tol_mps`;
//! 4. `Below`: the same downward;
//! 5. publish [`ModelPoint`] (and [`ModelMargin`] for the fusion) and idle until `period_s`
//!    after the cycle start.
//!
//! Each call of [`ModelMarginTracker::step`] does at most **one** unit of work (at most one
//! eigen-solve plus O(n^3) complex LUs); a full cycle takes a bounded number of calls
//! (<= 2 + 2 `max_evals_per_search`, 2 + 2 x 45 = 92 by default, typically ~20 when warm) so it
//! completes within 100 calls of the 1 kHz control loop, i.e. within one 100 ms period.
//! This is the same search as [`crate::stability::critical_speed_near`] (probe outward from the
//! hint, refine the first bracket with Brent) split into resumable steps and restricted to one
//! side of V. Two crossings closer together than one probe step can be missed (the cap
//! `max_step_mps` bounds this; the nominal window is 55 km/h wide).
//!
//! No allocation, no panics; errors of a solve end that part of the cycle and are counted.

use core::marker::PhantomData;

use nalgebra::Complex;

use crate::eigen::{self, Mode, SolveFloat};
use crate::params::PlantParams;
use crate::plant::{dlinearise_dv, linearise};
use crate::stability::{self, CrossingKind, ModeSelect, V_SEARCH_MAX_MPS, V_SEARCH_MIN_MPS};

/// Tuning of the incremental model margin.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelMarginConfig {
    /// A new cycle starts this long after the previous start (10 Hz), s.
    pub period_s: f32,
    /// Root tolerance of the critical speeds, m/s (1e-4 m/s = 0.00036 km/h).
    pub tol_mps: f64,
    /// Warm-start probe half-width around the previous crossing, m/s.
    pub hint_probe_mps: f64,
    /// First probe step of a cold search, m/s.
    pub cold_step_mps: f64,
    /// Largest probe step (steps double up to this), m/s.
    pub max_step_mps: f64,
    /// Eigen-solves allowed per side (probes + refinement).
    pub max_evals_per_search: u16,
    /// Relative change of the damper coefficient that invalidates the warm-start hints.
    pub c_change_rel: f64,
}

impl Default for ModelMarginConfig {
    fn default() -> Self {
        Self {
            period_s: 0.1,
            tol_mps: 1e-4,
            hint_probe_mps: 0.05,
            cold_step_mps: 0.25,
            max_step_mps: 2.0,
            max_evals_per_search: 45,
            c_change_rel: 0.01,
        }
    }
}

/// A Hopf crossing found by the tracker.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Crossing {
    /// Critical speed, m/s.
    pub speed_mps: f64,
    /// Onset (stable below) or offset (unstable below).
    pub kind: CrossingKind,
    /// Final bracket width, m/s.
    pub bracket_mps: f64,
    /// Tolerance met within the budget.
    pub converged: bool,
}

/// The result of one full update cycle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelPoint {
    /// Time the cycle started (speed latched), s.
    pub t_s: f32,
    /// Latched speed, m/s.
    pub speed_mps: f64,
    /// Damper equivalent viscous coefficient used, N s/m.
    pub c_damper_nspm: f64,
    /// The shimmy mode (in-phase wheel yaw); the critical mode if none was classified so.
    pub shimmy: Mode,
    /// A pair was classified as in-phase wheel yaw.
    pub shimmy_found: bool,
    /// The oscillatory mode with the largest real part.
    pub critical: Mode,
    /// Largest real part over all eigenvalues, 1/s.
    pub max_re: f64,
    /// d zeta / dV of the shimmy mode, 1/(m/s) (0 when the slope computation failed).
    pub dzeta_dv_per_mps: f64,
    /// The slope is valid.
    pub slope_valid: bool,
    /// First Hopf crossing above the latched speed.
    pub above: Option<Crossing>,
    /// First Hopf crossing below the latched speed.
    pub below: Option<Crossing>,
    /// Calls of `step` the cycle took (from its start to its publication).
    pub calls: u16,
    /// Eigen-solves the cycle used.
    pub eigen_solves: u16,
    /// Solve errors in this cycle.
    pub errors: u16,
}

impl ModelPoint {
    /// The linear model is unstable at the latched speed (a crossing mode has Re > 0).
    pub fn unstable(&self) -> bool {
        self.critical.re > 0.0
    }

    /// The fusion's input. `v_crit_onset_mps`: the onset above V when stable; when V is inside
    /// the unstable window, the onset below it (or V itself), so the model margin is zero.
    pub fn margin(&self) -> ModelMargin {
        let onset = if self.unstable() {
            Some(
                self.below
                    .filter(|c| c.kind == CrossingKind::Onset)
                    .map_or(self.speed_mps, |c| c.speed_mps),
            )
        } else {
            self.above
                .filter(|c| c.kind == CrossingKind::Onset)
                .map(|c| c.speed_mps)
        };
        ModelMargin {
            zeta: self.shimmy.zeta,
            freq_hz: self.shimmy.freq_hz,
            dzeta_dv_per_mps: self.dzeta_dv_per_mps,
            v_crit_onset_mps: onset,
            valid: self.slope_valid
                && self.shimmy.zeta.is_finite()
                && self.dzeta_dv_per_mps.is_finite(),
        }
    }
}

/// Model-based quantities at the current operating point (f64: the model path): the fusion's
/// model input, from [`ModelPoint::margin`].
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct ModelMargin {
    /// Damping ratio of the model's least-damped shimmy mode.
    pub zeta: f64,
    /// Its damped frequency, Hz.
    pub freq_hz: f64,
    /// Slope d zeta / dV at the current speed, 1/(m/s).
    pub dzeta_dv_per_mps: f64,
    /// Onset (Hopf) speed of the linear model above the current speed, if any, m/s.
    pub v_crit_onset_mps: Option<f64>,
    /// The model computation succeeded and is current.
    pub valid: bool,
}

/// Brent's method split into propose / tell steps (same iteration as
/// [`crate::stability::brent`]), so one function evaluation can be done per call.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ResumableBrent {
    a: f64,
    b: f64,
    c: f64,
    fa: f64,
    fb: f64,
    fc: f64,
    d: f64,
    e: f64,
    tol: f64,
}

/// What Brent wants next.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BrentStep {
    /// Evaluate f here and call [`ResumableBrent::tell`].
    Eval(f64),
    /// Converged: (root, bracket lo, bracket hi).
    Done(f64, f64, f64),
}

impl ResumableBrent {
    /// Bracket [a, b] with fa fb <= 0.
    pub fn new(a: f64, b: f64, fa: f64, fb: f64, tol: f64) -> Self {
        Self {
            a,
            b,
            c: a,
            fa,
            fb,
            fc: fa,
            d: b - a,
            e: b - a,
            tol,
        }
    }

    /// Current best estimate and bracket.
    pub fn best(&self) -> (f64, f64, f64) {
        let (lo, hi) = if self.b < self.c {
            (self.b, self.c)
        } else {
            (self.c, self.b)
        };
        (self.b, lo, hi)
    }

    /// The next point to evaluate, or the converged root.
    pub fn propose(&mut self) -> BrentStep {
        if self.fa == 0.0 || self.fb == 0.0 {
            let x = if self.fb == 0.0 { self.b } else { self.a };
            return BrentStep::Done(x, x, x);
        }
        if (self.fb > 0.0) == (self.fc > 0.0) {
            self.c = self.a;
            self.fc = self.fa;
            self.d = self.b - self.a;
            self.e = self.d;
        }
        if libm::fabs(self.fc) < libm::fabs(self.fb) {
            self.a = self.b;
            self.b = self.c;
            self.c = self.a;
            self.fa = self.fb;
            self.fb = self.fc;
            self.fc = self.fa;
        }
        let tol1 = 2.0 * f64::EPSILON * libm::fabs(self.b) + 0.5 * self.tol;
        let xm = 0.5 * (self.c - self.b);
        if libm::fabs(xm) <= tol1 {
            let (x, lo, hi) = self.best();
            return BrentStep::Done(x, lo, hi);
        }
        if libm::fabs(self.e) >= tol1 && libm::fabs(self.fa) > libm::fabs(self.fb) {
            let s = self.fb / self.fa;
            let (mut pp, mut q);
            if self.a == self.c {
                pp = 2.0 * xm * s;
                q = 1.0 - s;
            } else {
                let qa = self.fa / self.fc;
                let r = self.fb / self.fc;
                pp = s * (2.0 * xm * qa * (qa - r) - (self.b - self.a) * (r - 1.0));
                q = (qa - 1.0) * (r - 1.0) * (s - 1.0);
            }
            if pp > 0.0 {
                q = -q;
            }
            pp = libm::fabs(pp);
            let min1 = 3.0 * xm * q - libm::fabs(tol1 * q);
            let min2 = libm::fabs(self.e * q);
            if 2.0 * pp < min1.min(min2) {
                self.e = self.d;
                self.d = pp / q;
            } else {
                self.d = xm;
                self.e = self.d;
            }
        } else {
            self.d = xm;
            self.e = self.d;
        }
        self.a = self.b;
        self.fa = self.fb;
        self.b += if libm::fabs(self.d) > tol1 {
            self.d
        } else if xm > 0.0 {
            tol1
        } else {
            -tol1
        };
        BrentStep::Eval(self.b)
    }

    /// The value of f at the last proposed point.
    pub fn tell(&mut self, fx: f64) {
        self.fb = fx;
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Search {
    /// Probing away from V: last point and its g, next step, whether the hint pair is pending.
    Probe {
        x: f64,
        gx: f64,
        step: f64,
        hint: Option<f64>,
    },
    /// Refining a bracket; `pending` is the point proposed last (awaiting its g).
    Refine {
        brent: ResumableBrent,
        kind: CrossingKind,
        pending: f64,
    },
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Phase {
    Idle,
    Modes,
    Slope,
    Above(Search),
    Below(Search),
    Publish,
}

/// The incremental model-margin state machine. Call [`ModelMarginTracker::step`] every control
/// tick; it returns `Some` when a cycle completes. `T` is the float type of the eigen-solves and
/// eigenvectors (f64 by default; the firmware uses f32, f64 being software on the M4): a type
/// parameter, so an image links only the precision it runs.
#[derive(Clone, Debug)]
pub struct ModelMarginTracker<T: SolveFloat = f64> {
    p: PlantParams,
    cfg: ModelMarginConfig,
    phase: Phase,
    work: ModelPoint,
    evals_this_search: u16,
    latest: Option<ModelPoint>,
    hint_above: Option<f64>,
    hint_below: Option<f64>,
    last_c: f64,
    cycle_start_s: Option<f32>,
    next_due_s: Option<f32>,
    total_eigen_solves: u64,
    solves_last_call: u8,
    cycles: u32,
    overruns: u32,
    precision: PhantomData<T>,
}

const EMPTY_MODE: Mode = Mode {
    re: 0.0,
    im: 0.0,
    zeta: 0.0,
    freq_hz: 0.0,
    omega_n: 0.0,
};

impl ModelMarginTracker<f64> {
    /// A tracker for the plant `p` solving in f64 (the host's reference precision).
    pub fn new(p: PlantParams, cfg: ModelMarginConfig) -> Self {
        Self::in_precision(p, cfg)
    }
}

impl<T: SolveFloat> ModelMarginTracker<T> {
    /// A tracker for the plant `p` solving in `T`.
    pub fn in_precision(p: PlantParams, cfg: ModelMarginConfig) -> Self {
        Self {
            p,
            cfg,
            phase: Phase::Idle,
            work: Self::blank(0.0, 0.0, 0.0),
            evals_this_search: 0,
            latest: None,
            hint_above: None,
            hint_below: None,
            last_c: 0.0,
            cycle_start_s: None,
            next_due_s: None,
            total_eigen_solves: 0,
            solves_last_call: 0,
            cycles: 0,
            overruns: 0,
            precision: PhantomData,
        }
    }

    fn blank(t_s: f32, v: f64, c: f64) -> ModelPoint {
        ModelPoint {
            t_s,
            speed_mps: v,
            c_damper_nspm: c,
            shimmy: EMPTY_MODE,
            shimmy_found: false,
            critical: EMPTY_MODE,
            max_re: 0.0,
            dzeta_dv_per_mps: 0.0,
            slope_valid: false,
            above: None,
            below: None,
            calls: 0,
            eigen_solves: 0,
            errors: 0,
        }
    }

    /// Configuration.
    pub fn config(&self) -> &ModelMarginConfig {
        &self.cfg
    }

    /// The latest completed cycle.
    pub fn latest(&self) -> Option<&ModelPoint> {
        self.latest.as_ref()
    }

    /// Eigen-solves since construction.
    pub fn total_eigen_solves(&self) -> u64 {
        self.total_eigen_solves
    }

    /// Eigen-solves done by the last `step` call (0 or 1).
    pub fn solves_last_call(&self) -> u8 {
        self.solves_last_call
    }

    /// Completed cycles.
    pub fn cycles(&self) -> u32 {
        self.cycles
    }

    /// Cycles that took longer than `period_s` (the next one then starts late).
    pub fn overruns(&self) -> u32 {
        self.overruns
    }

    /// True while a cycle is in progress.
    pub fn busy(&self) -> bool {
        self.phase != Phase::Idle
    }

    /// Drop the warm-start hints (e.g. after a parameter change).
    pub fn forget_hints(&mut self) {
        self.hint_above = None;
        self.hint_below = None;
    }

    /// g(V) = largest real part over the oscillatory eigenvalues: one eigen-solve. The only
    /// place (besides `Modes`) that solves, so the per-call count is exact.
    fn g(&mut self, v: f64) -> Option<f64> {
        self.solves_last_call = self.solves_last_call.saturating_add(1);
        self.total_eigen_solves = self.total_eigen_solves.saturating_add(1);
        self.work.eigen_solves = self.work.eigen_solves.saturating_add(1);
        self.evals_this_search = self.evals_this_search.saturating_add(1);
        let a = linearise(&self.p, v, self.work.c_damper_nspm);
        match eigen::eigenvalues_of::<T>(&a)
            .and_then(|vals| eigen::critical_oscillatory_mode(&vals))
        {
            Ok(m) if m.re.is_finite() => Some(m.re),
            _ => {
                self.work.errors = self.work.errors.saturating_add(1);
                None
            }
        }
    }

    /// One unit of work. `t_s` time, `speed_mps` the current speed, `c_damper_nspm` the
    /// damper's equivalent viscous coefficient (0 = none). Returns the new point when a cycle
    /// completes on this call.
    pub fn step(&mut self, t_s: f32, speed_mps: f32, c_damper_nspm: f32) -> Option<ModelPoint> {
        self.solves_last_call = 0;
        if self.phase != Phase::Idle {
            self.work.calls = self.work.calls.saturating_add(1);
        }
        match self.phase {
            Phase::Idle => {
                let due = match self.next_due_s {
                    None => true,
                    Some(t1) => t_s >= t1 || t_s.is_nan(),
                };
                let v = speed_mps as f64;
                let c = c_damper_nspm as f64;
                if due && v.is_finite() && c.is_finite() && c >= 0.0 {
                    if libm::fabs(c - self.last_c) > self.cfg.c_change_rel * self.last_c.max(1.0) {
                        self.forget_hints();
                    }
                    self.last_c = c;
                    let v = v.clamp(V_SEARCH_MIN_MPS, V_SEARCH_MAX_MPS);
                    self.work = Self::blank(t_s, v, c);
                    self.work.calls = 1;
                    let t = if t_s.is_finite() { t_s } else { 0.0 };
                    self.cycle_start_s = Some(t);
                    // 10 Hz on the schedule (no drift from the 1 ms call grid), unless late
                    self.next_due_s = Some(match self.next_due_s {
                        Some(d) if d + self.cfg.period_s > t => d + self.cfg.period_s,
                        _ => t + self.cfg.period_s,
                    });
                    self.phase = Phase::Modes;
                    // The first unit of work is done on this same call.
                    self.modes();
                }
                None
            }
            Phase::Modes => {
                self.modes();
                None
            }
            Phase::Slope => {
                self.slope();
                None
            }
            Phase::Above(s) => {
                let next = self.search(s, true);
                self.phase = match next {
                    Some(s) => Phase::Above(s),
                    None => self.start_search(false),
                };
                None
            }
            Phase::Below(s) => {
                let next = self.search(s, false);
                self.phase = match next {
                    Some(s) => Phase::Below(s),
                    None => Phase::Publish,
                };
                None
            }
            Phase::Publish => {
                let w = self.work;
                self.hint_above = w.above.map(|c| c.speed_mps);
                self.hint_below = w.below.map(|c| c.speed_mps);
                self.latest = Some(w);
                self.cycles = self.cycles.saturating_add(1);
                if let Some(t0) = self.cycle_start_s {
                    if t_s - t0 > self.cfg.period_s {
                        self.overruns = self.overruns.saturating_add(1);
                    }
                }
                self.phase = Phase::Idle;
                Some(w)
            }
        }
    }

    fn modes(&mut self) {
        self.solves_last_call = self.solves_last_call.saturating_add(1);
        self.total_eigen_solves = self.total_eigen_solves.saturating_add(1);
        self.work.eigen_solves = self.work.eigen_solves.saturating_add(1);
        let a = linearise(&self.p, self.work.speed_mps, self.work.c_damper_nspm);
        let ok = eigen::eigenvalues_of::<T>(&a).and_then(|vals| {
            let crit = eigen::critical_oscillatory_mode(&vals)?;
            let (shimmy, found) =
                match stability::select_mode_of::<T>(&self.p, &a, &vals, ModeSelect::Shimmy) {
                    Ok(m) => (m, true),
                    Err(_) => (crit, false),
                };
            Ok((crit, shimmy, found, eigen::max_real_part(&vals)))
        });
        match ok {
            Ok((crit, shimmy, found, max_re)) => {
                self.work.critical = crit;
                self.work.shimmy = shimmy;
                self.work.shimmy_found = found;
                self.work.max_re = max_re;
                self.phase = Phase::Slope;
            }
            Err(_) => {
                self.work.errors = self.work.errors.saturating_add(1);
                self.phase = Phase::Publish;
            }
        }
    }

    fn slope(&mut self) {
        let a = linearise(&self.p, self.work.speed_mps, self.work.c_damper_nspm);
        let lambda = self.work.shimmy.eigenvalue();
        let r = (|| {
            let v = eigen::eigenvector_of::<T>(&a, lambda).ok()?;
            let w = eigen::left_eigenvector_of::<T>(&a, lambda).ok()?;
            let da = dlinearise_dv(&self.p).map(|x| Complex::new(x, 0.0));
            let num = (w.adjoint() * da * v)[(0, 0)];
            let den = (w.adjoint() * v)[(0, 0)];
            if den.re == 0.0 && den.im == 0.0 {
                return None;
            }
            let dl = num / den;
            let wn = self.work.shimmy.omega_n;
            if wn <= 0.0 {
                return None;
            }
            let dr = (lambda.re * dl.re + lambda.im * dl.im) / wn;
            let dz = -(dl.re * wn - lambda.re * dr) / (wn * wn);
            dz.is_finite().then_some(dz)
        })();
        match r {
            Some(dz) => {
                self.work.dzeta_dv_per_mps = dz;
                self.work.slope_valid = true;
            }
            None => self.work.errors = self.work.errors.saturating_add(1),
        }
        self.phase = self.start_search(true);
    }

    fn start_search(&mut self, up: bool) -> Phase {
        self.evals_this_search = 0;
        let v = self.work.speed_mps;
        let hint = if up {
            self.hint_above.filter(|h| *h > v)
        } else {
            self.hint_below.filter(|h| *h < v)
        };
        let s = Search::Probe {
            x: v,
            gx: self.work.critical.re,
            step: self.cfg.cold_step_mps,
            hint,
        };
        if up {
            Phase::Above(s)
        } else {
            Phase::Below(s)
        }
    }

    /// One evaluation of a one-sided search. `None` when this side is finished (result stored).
    fn search(&mut self, s: Search, up: bool) -> Option<Search> {
        let (lim, sgn) = if up {
            (V_SEARCH_MAX_MPS, 1.0)
        } else {
            (V_SEARCH_MIN_MPS, -1.0)
        };
        let out_of_budget = self.evals_this_search >= self.cfg.max_evals_per_search;
        match s {
            Search::Probe { x, gx, step, hint } => {
                if out_of_budget || (x - lim) * sgn >= 0.0 {
                    return self.finish(None, up);
                }
                // next probe point
                let (xn, hint_n, step_n) = match hint {
                    Some(h) => {
                        let lo_side = h - sgn * self.cfg.hint_probe_mps;
                        if (lo_side - x) * sgn > 0.0 {
                            // first the near side of the hint, then its far side
                            (lo_side, Some(h), 2.0 * self.cfg.hint_probe_mps)
                        } else {
                            (
                                h + sgn * self.cfg.hint_probe_mps,
                                None,
                                2.0 * self.cfg.hint_probe_mps,
                            )
                        }
                    }
                    None => (
                        x + sgn * step,
                        None,
                        (2.0 * step).min(self.cfg.max_step_mps),
                    ),
                };
                let xn = if up { xn.min(lim) } else { xn.max(lim) };
                let Some(gn) = self.g(xn) else {
                    return self.finish(None, up);
                };
                if (gn < 0.0) != (gx < 0.0) {
                    let (a, b, fa, fb) = if up { (x, xn, gx, gn) } else { (xn, x, gn, gx) };
                    let kind = if fa < 0.0 {
                        CrossingKind::Onset
                    } else {
                        CrossingKind::Offset
                    };
                    let brent = ResumableBrent::new(a, b, fa, fb, self.cfg.tol_mps);
                    return self.refine(brent, kind, up);
                }
                Some(Search::Probe {
                    x: xn,
                    gx: gn,
                    step: step_n,
                    hint: hint_n,
                })
            }
            Search::Refine {
                mut brent,
                kind,
                pending,
            } => {
                if out_of_budget {
                    let (r, lo, hi) = brent.best();
                    return self.finish(
                        Some(Crossing {
                            speed_mps: r,
                            kind,
                            bracket_mps: hi - lo,
                            converged: false,
                        }),
                        up,
                    );
                }
                let Some(gp) = self.g(pending) else {
                    return self.finish(None, up);
                };
                brent.tell(gp);
                self.refine(brent, kind, up)
            }
        }
    }

    /// The next Brent step on a bracketed crossing: finished (stored) or the point to evaluate.
    fn refine(
        &mut self,
        mut brent: ResumableBrent,
        kind: CrossingKind,
        up: bool,
    ) -> Option<Search> {
        match brent.propose() {
            BrentStep::Done(r, lo, hi) => self.finish(
                Some(Crossing {
                    speed_mps: r,
                    kind,
                    bracket_mps: hi - lo,
                    converged: true,
                }),
                up,
            ),
            BrentStep::Eval(p) => Some(Search::Refine {
                brent,
                kind,
                pending: p,
            }),
        }
    }

    fn finish(&mut self, c: Option<Crossing>, up: bool) -> Option<Search> {
        if up {
            self.work.above = c;
        } else {
            self.work.below = c;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::ParamSet;

    #[test]
    fn resumable_brent_matches_the_one_shot_brent() {
        let f = |x: f64| x * x * x - 2.0 * x - 5.0;
        let one =
            stability::brent(|x| Ok::<_, ()>(f(x)), 2.0, 3.0, f(2.0), f(3.0), 1e-12, 100).unwrap();
        let mut b = ResumableBrent::new(2.0, 3.0, f(2.0), f(3.0), 1e-12);
        let mut n = 0;
        let r = loop {
            match b.propose() {
                BrentStep::Eval(x) => {
                    n += 1;
                    b.tell(f(x));
                }
                BrentStep::Done(x, _, _) => break x,
            }
        };
        assert_eq!(r, one.x);
        assert_eq!(n, one.evals);
    }

    #[test]
    fn one_cycle_at_most_one_solve_per_call() {
        let p = ParamSet::Nominal.params();
        let mut t = ModelMarginTracker::new(p, ModelMarginConfig::default());
        let mut done = None;
        for k in 0..200 {
            let r = t.step(k as f32 * 1e-3, 5.0, 0.0);
            assert!(t.solves_last_call() <= 1);
            if let Some(r) = r {
                done = Some((k, r));
                break;
            }
        }
        let (k, r) = done.expect("a cycle completes");
        assert!(k < 100, "{k}");
        assert_eq!(r.above.unwrap().kind, CrossingKind::Onset);
        assert!(r.below.is_none());
    }
}
