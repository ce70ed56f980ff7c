//! Model-based eigenvalue margin by continuation, computed incrementally so that no control
//! step overruns.
//!
//! One *update cycle* at the speed V latched at its start:
//!
//! 1. `Modes`: A(V) (with the damper's equivalent viscous coefficient c) and one bounded
//!    eigen-solve (the full Schur solve, every cycle: the check of everything tracked): the
//!    critical oscillatory mode (largest Re, the one that crosses at a Hopf point), max Re, and
//!    the start of the shimmy mode: the eigenvalue nearest the one tracked from the last cycle
//!    (predicted to V with its d lambda/dV), or, cold, [`ModeSelect::Shimmy`] (least-damped
//!    in-phase wheel-yaw pair by mode shape; the ~47 Hz anti-phase track-rod mode is not it);
//! 2. `Shimmy`: Newton on the eigenpair ([`eigen::refine_eigenpair`], in the tracker's
//!    precision) from the inverse-iteration vector; its shape must still be in-phase wheel yaw
//!    (else the cold selection); d zeta/dV from the left/right eigenvectors and the exact dA/dV;
//! 3. `Track`: each known Hopf crossing V* by Newton on the Hopf condition Re s(V*) = 0, with
//!    dRe s/dV from the eigenpair at V* (one call per Newton step), warm-started at the last
//!    cycle's V* and eigenvalue; a crossing that does not converge, or known crossings whose
//!    order and kinds contradict the stability at V from the Schur solve, send the cycle to
//!    4. `Scan` (cold, also after a change of c): probe g(V) = max Re over the oscillatory
//!    eigenvalues upward from V to [`V_SEARCH_MAX_MPS`] and downward to [`V_SEARCH_MIN_MPS`]
//!    (steps from `cold_step_mps` doubling up to `max_step_mps`, restarted after each crossing),
//!    each bracket refined by Brent's method (resumable, one eigen-solve per call) to `tol_mps`:
//!    every crossing in the range becomes a known crossing, so the crossing above V is known when
//!    V passes the one below it;
//! 5. publish [`ModelPoint`] (the first known crossing above and below V; [`ModelMargin`] for
//!    the fusion) and idle until `period_s` after the cycle start.
//!
//! Each call of [`ModelMarginTracker::step`] does at most **one** unit of work (at most one
//! eigen-solve plus O(n^3) complex LUs); a cycle takes at most `max_calls` calls (99 by
//! default, so it completes within 100 calls of the 1 kHz loop, i.e. within one 100 ms period;
//! a scan cut short by it is repeated in the next cycle). A warm cycle is one eigen-solve and a
//! few LUs. Two crossings closer together than one probe step can be missed (the cap
//! `max_step_mps` bounds this; the nominal window is 55 km/h wide); the scan sees the plant
//! once per c, so crossings that appear later without a change of c by more than `c_change_rel`
//! in one cycle are found only by the parity check.
//!
//! No allocation, no panics; errors of a solve end that part of the cycle and are counted.

use core::marker::PhantomData;

use nalgebra::Complex;

use crate::eigen::{self, Eigenpair, EigenvaluesOf, Matrix, Mode, SolveFloat};
use crate::float::{narrowed_complex, widened_complex};
use crate::model::LinearModel;
use crate::stability::{self, CrossingKind, ModeSelect, V_SEARCH_MAX_MPS, V_SEARCH_MIN_MPS};
use crate::vehicles::car::PlantParams;
use crate::vehicles::car::N_STATES;

/// Most Hopf crossings the tracker keeps (the nominal window has two; a scan that finds more
/// is incomplete and repeated).
pub const MAX_CROSSINGS: usize = 4;
/// Newton iterations per eigenpair refinement (warm: 1-2).
const EIGEN_NEWTON_ITERS: u8 = 4;
/// Newton steps on the Hopf condition per crossing and cycle (warm at unchanged c: 1).
const HOPF_NEWTON_ITERS: u8 = 6;

/// Tuning of the incremental model margin.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelMarginConfig {
    /// A new cycle starts this long after the previous start (10 Hz), s.
    pub period_s: f32,
    /// Root tolerance of the critical speeds, m/s (1e-4 m/s = 0.00036 km/h).
    pub tol_mps: f64,
    /// Speeds this close to a known crossing skip the parity check (the f32 Schur solve's sign
    /// of max Re is not trusted there), m/s.
    pub parity_band_mps: f64,
    /// First probe step of a cold search, m/s.
    pub cold_step_mps: f64,
    /// Largest probe step (steps double up to this), m/s.
    pub max_step_mps: f64,
    /// Calls a cycle may take (the scan stops there, incomplete, and is repeated).
    pub max_calls: u16,
    /// Relative change of the damper coefficient that invalidates the warm-start hints.
    pub c_change_rel: f64,
}

impl Default for ModelMarginConfig {
    fn default() -> Self {
        Self {
            period_s: 0.1,
            tol_mps: 1e-4,
            parity_band_mps: 0.05,
            cold_step_mps: 0.25,
            max_step_mps: 2.0,
            max_calls: 99,
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
    /// Final bracket width (scan), or the size of the last Newton step (tracked), m/s.
    pub bracket_mps: f64,
    /// Tolerance met within the budget.
    pub converged: bool,
}

/// The result of one full update cycle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelPoint {
    /// Time the cycle started (speed latched), s.
    pub t_s: f64,
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
    /// Newton iterations (complex LUs of the bordered system) the cycle used.
    pub newton_iterations: u16,
    /// The crossings came from tracking (no scan in this cycle).
    pub tracked: bool,
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
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
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
/// [`crate::stability::brent`]), so one function evaluation can be done per call; in the
/// tracker's precision `T` (f32 on the target: no soft-float f64).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ResumableBrent<T: SolveFloat = f64> {
    a: T,
    b: T,
    c: T,
    fa: T,
    fb: T,
    fc: T,
    d: T,
    e: T,
    tol: T,
}

/// What Brent wants next.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BrentStep<T = f64> {
    /// Evaluate f here and call [`ResumableBrent::tell`].
    Eval(T),
    /// Converged: (root, bracket lo, bracket hi).
    Done(T, T, T),
}

impl<T: SolveFloat> ResumableBrent<T> {
    /// Bracket [a, b] with fa fb <= 0.
    pub fn new(a: T, b: T, fa: T, fb: T, tol: T) -> Self {
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
    pub fn best(&self) -> (T, T, T) {
        let (lo, hi) = if self.b < self.c {
            (self.b, self.c)
        } else {
            (self.c, self.b)
        };
        (self.b, lo, hi)
    }

    /// The next point to evaluate, or the converged root.
    pub fn propose(&mut self) -> BrentStep<T> {
        let (zero, one, two) = (T::zero(), T::one(), T::of_f64(2.0));
        let half = T::of_f64(0.5);
        if self.fa == zero || self.fb == zero {
            let x = if self.fb == zero { self.b } else { self.a };
            return BrentStep::Done(x, x, x);
        }
        if (self.fb > zero) == (self.fc > zero) {
            self.c = self.a;
            self.fc = self.fa;
            self.d = self.b - self.a;
            self.e = self.d;
        }
        if self.fc.abs() < self.fb.abs() {
            self.a = self.b;
            self.b = self.c;
            self.c = self.a;
            self.fa = self.fb;
            self.fb = self.fc;
            self.fc = self.fa;
        }
        let tol1 = two * T::EPS * self.b.abs() + half * self.tol;
        let xm = half * (self.c - self.b);
        if xm.abs() <= tol1 {
            let (x, lo, hi) = self.best();
            return BrentStep::Done(x, lo, hi);
        }
        if self.e.abs() >= tol1 && self.fa.abs() > self.fb.abs() {
            let s = self.fb / self.fa;
            let (mut pp, mut q);
            if self.a == self.c {
                pp = two * xm * s;
                q = one - s;
            } else {
                let qa = self.fa / self.fc;
                let r = self.fb / self.fc;
                pp = s * (two * xm * qa * (qa - r) - (self.b - self.a) * (r - one));
                q = (qa - one) * (r - one) * (s - one);
            }
            if pp > zero {
                q = -q;
            }
            pp = pp.abs();
            let min1 = T::of_f64(3.0) * xm * q - (tol1 * q).abs();
            let min2 = (self.e * q).abs();
            if two * pp < min1.min(min2) {
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
        self.b += if self.d.abs() > tol1 {
            self.d
        } else if xm > zero {
            tol1
        } else {
            -tol1
        };
        BrentStep::Eval(self.b)
    }

    /// The value of f at the last proposed point.
    pub fn tell(&mut self, fx: T) {
        self.fb = fx;
    }

    /// The bracket end above (`up`) or below the root, and f there.
    pub fn end(&self, up: bool) -> (T, T) {
        if (self.b > self.c) == up {
            (self.b, self.fb)
        } else {
            (self.c, self.fc)
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Search<T: SolveFloat> {
    /// Probing away from V: last point and its g, next step.
    Probe { x: T, gx: T, step: T },
    /// Refining a bracket; `pending` is the point proposed last (awaiting its g).
    Refine {
        brent: ResumableBrent<T>,
        kind: CrossingKind,
        pending: T,
    },
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Phase<T: SolveFloat> {
    Idle,
    Modes,
    /// Newton on the Hopf condition for known crossing `index`, step `iter`.
    Track {
        index: usize,
        iter: u8,
    },
    Above(Search<T>),
    Below(Search<T>),
    Publish,
}

/// A Hopf crossing known from a scan and tracked since: its speed and the crossing eigenvalue.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Known<T: SolveFloat> {
    speed_mps: T,
    /// The eigenvalue that crosses (Re ~ 0) at `speed_mps`.
    lambda: Complex<T>,
    kind: CrossingKind,
    /// Final bracket (scan) or last Newton step (tracked), m/s.
    bracket_mps: T,
    converged: bool,
    /// The damper coefficient it was found or last converged at: the crossings depend on c
    /// alone, so at the same c they are reused without work.
    c_nspm: f64,
}

/// The shimmy eigenvalue of the last cycle and its speed derivative (the predictor).
#[derive(Clone, Copy, Debug, PartialEq)]
struct ShimmyTrack<T: SolveFloat> {
    speed_mps: T,
    lambda: Complex<T>,
    dl_dv: Complex<T>,
}

/// The incremental model-margin state machine. Call [`ModelMarginTracker::step`] every control
/// tick; it returns `Some` when a cycle completes. `T` is the float type of the eigen-solves and
/// eigenvector LUs, and of the speed search (Brent, the Newton on the Hopf condition, the
/// tracked crossings): f64 by default; the firmware uses f32, f64 being software on the M4. A
/// type parameter, so an image links only the precision it runs; the published [`ModelPoint`]
/// is f64 either way. `M` is the vehicle model with `N`
/// states (the car's [`PlantParams`] by default).
#[derive(Clone, Debug)]
pub struct ModelMarginTracker<
    T: SolveFloat = f64,
    M: LinearModel<N> = PlantParams,
    const N: usize = N_STATES,
> {
    p: M,
    cfg: ModelMarginConfig,
    phase: Phase<T>,
    work: ModelPoint,
    latest: Option<ModelPoint>,
    /// The cycle's shimmy start: the eigenvalue chosen from the Schur solve.
    shimmy_start: Complex<f64>,
    /// The start came from the track (its shape is checked) rather than the shape selection.
    shimmy_from_track: bool,
    shimmy_track: Option<ShimmyTrack<T>>,
    /// Every crossing in the search range, ascending, when `known_valid`.
    known: heapless::Vec<Known<T>, MAX_CROSSINGS>,
    /// The last scan covered the whole range at the current c and found at most
    /// [`MAX_CROSSINGS`].
    known_valid: bool,
    /// The crossing eigenvalue nearest Re = 0 seen while refining the current bracket.
    refine_best: Option<(T, Complex<T>)>,
    last_c: f64,
    cycle_start_s: Option<f64>,
    next_due_s: Option<f64>,
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

impl<M: LinearModel<N>, const N: usize> ModelMarginTracker<f64, M, N> {
    /// A tracker for the plant `p` solving in f64 (the host's reference precision).
    pub fn new(p: M, cfg: ModelMarginConfig) -> Self {
        Self::in_precision(p, cfg)
    }
}

impl<T: SolveFloat, M: LinearModel<N>, const N: usize> ModelMarginTracker<T, M, N> {
    /// A tracker for the plant `p` solving in `T`.
    pub fn in_precision(p: M, cfg: ModelMarginConfig) -> Self {
        Self {
            p,
            cfg,
            phase: Phase::Idle,
            work: Self::blank(0.0, 0.0, 0.0),
            latest: None,
            shimmy_start: Complex::new(0.0, 0.0),
            shimmy_from_track: false,
            shimmy_track: None,
            known: heapless::Vec::new(),
            known_valid: false,
            refine_best: None,
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

    fn blank(t_s: f64, v: f64, c: f64) -> ModelPoint {
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
            newton_iterations: 0,
            tracked: false,
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

    /// Drop what is tracked (the shimmy pair and the known crossings), e.g. after a parameter
    /// change: the next cycle starts cold (shape selection and a full scan).
    pub fn forget_hints(&mut self) {
        self.shimmy_track = None;
        self.known.clear();
        self.known_valid = false;
    }

    /// Replaces the plant (an updated model of the same vehicle): the known crossings are kept
    /// as Newton starts and refined in the next cycle (a scan only if Newton loses one).
    pub fn set_plant(&mut self, p: M) {
        self.p = p;
        for k in self.known.iter_mut() {
            k.converged = false;
        }
    }

    /// The plant the tracker linearises.
    pub fn plant(&self) -> &M {
        &self.p
    }

    fn error(&mut self) {
        self.work.errors = self.work.errors.saturating_add(1);
    }

    /// One bounded eigen-solve of `a`, counted (the only place that solves, so the per-call
    /// count is exact).
    fn solve(&mut self, a: &Matrix<N>) -> Result<EigenvaluesOf<N>, eigen::EigenError> {
        self.solves_last_call = self.solves_last_call.saturating_add(1);
        self.total_eigen_solves = self.total_eigen_solves.saturating_add(1);
        self.work.eigen_solves = self.work.eigen_solves.saturating_add(1);
        eigen::eigenvalues_of::<T, N>(a)
    }

    /// The critical oscillatory eigenvalue at `v` (its Re is g(v)): one eigen-solve.
    fn g(&mut self, v: T) -> Option<Complex<T>> {
        let a = self.p.linearise(v.to_f64(), self.work.c_damper_nspm);
        match self
            .solve(&a)
            .and_then(|vals| eigen::critical_oscillatory_mode(&vals))
        {
            Ok(m) if m.re.is_finite() => Some(narrowed_complex(m.eigenvalue())),
            _ => {
                self.error();
                None
            }
        }
    }

    /// Newton on the eigenpair of A(v) near `lambda`, from its inverse-iteration vector.
    fn eigenpair(&mut self, a: &Matrix<N>, lambda: Complex<f64>) -> Option<Eigenpair<T, N>> {
        // the start in the phase the iteration leaves it: the refined pair does not depend on it
        let r = eigen::eigenvector_in::<T, N>(a, lambda)
            .and_then(|v0| eigen::refine_eigenpair::<T, N>(a, lambda, &v0, EIGEN_NEWTON_ITERS));
        match r {
            Ok(ep) => {
                self.work.newton_iterations = self
                    .work
                    .newton_iterations
                    .saturating_add(u16::from(ep.iterations));
                Some(ep)
            }
            Err(_) => {
                self.error();
                None
            }
        }
    }

    /// One unit of work. `t_s` time, `speed_mps` the current speed, `c_damper_nspm` the
    /// damper's equivalent viscous coefficient (0 = none). Returns the new point when a cycle
    /// completes on this call.
    pub fn step(&mut self, t_s: f64, speed_mps: f32, c_damper_nspm: f32) -> Option<ModelPoint> {
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
                        Some(d) if d + f64::from(self.cfg.period_s) > t => {
                            d + f64::from(self.cfg.period_s)
                        }
                        _ => t + f64::from(self.cfg.period_s),
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
            Phase::Track { index, iter } => {
                self.phase = self.track(index, iter);
                None
            }
            Phase::Above(s) => {
                self.phase = match self.search(s, true) {
                    Some(s) => Phase::Above(s),
                    None => self.start_search(false),
                };
                None
            }
            Phase::Below(s) => {
                self.phase = match self.search(s, false) {
                    Some(s) => Phase::Below(s),
                    None => Phase::Publish,
                };
                None
            }
            Phase::Publish => {
                self.publish_crossings();
                let w = self.work;
                self.latest = Some(w);
                self.cycles = self.cycles.saturating_add(1);
                if let Some(t0) = self.cycle_start_s {
                    if (t_s - t0) as f32 > self.cfg.period_s {
                        self.overruns = self.overruns.saturating_add(1);
                    }
                }
                self.phase = Phase::Idle;
                Some(w)
            }
        }
    }

    /// The Schur solve at V: critical mode, max Re, and the shimmy start (tracked or selected),
    /// then the shimmy step on the same A in the same call (one eigen-solve plus LUs).
    fn modes(&mut self) {
        let v = self.work.speed_mps;
        let a = self.p.linearise(v, self.work.c_damper_nspm);
        let vals = match self.solve(&a) {
            Ok(vals) => vals,
            Err(_) => {
                self.error();
                self.phase = Phase::Publish;
                return;
            }
        };
        let Ok(crit) = eigen::critical_oscillatory_mode(&vals) else {
            self.error();
            self.phase = Phase::Publish;
            return;
        };
        self.work.critical = crit;
        self.work.max_re = eigen::max_real_part(&vals);
        // the tracked shimmy eigenvalue, predicted to V: the nearest +Im eigenvalue of the solve
        let tracked = self.shimmy_track.and_then(|tr| {
            let pred = tr.lambda + tr.dl_dv * (T::of_f64(v) - tr.speed_mps);
            vals.iter()
                .filter(|l| l.im > 0.0 && eigen::is_oscillatory(**l))
                .map(|l| ((narrowed_complex::<T>(*l) - pred).norm_sqr(), *l))
                .fold(None::<(T, Complex<f64>)>, |best, c| match best {
                    Some(b) if b.0 <= c.0 => Some(b),
                    _ => Some(c),
                })
                // a start farther than 10 % of |lambda| from the prediction is another branch
                // (squared magnitudes: no hypot per candidate)
                .filter(|(d2, _)| *d2 <= T::of_f64(0.01) * pred.norm_sqr())
                .map(|(_, l)| l)
        });
        match tracked {
            Some(l) => {
                self.shimmy_start = l;
                self.shimmy_from_track = true;
                self.work.shimmy_found = true;
            }
            None => self.select_shimmy(&a, &vals),
        }
        self.shimmy(&a);
    }

    /// Cold: the shimmy mode by mode shape over all oscillatory pairs (one LU each).
    fn select_shimmy(&mut self, a: &Matrix<N>, vals: &EigenvaluesOf<N>) {
        let (l, found) =
            match stability::select_mode_of::<T, M, N>(&self.p, a, vals, ModeSelect::Shimmy) {
                Ok(m) => (m.eigenvalue(), true),
                Err(_) => (self.work.critical.eigenvalue(), false),
            };
        self.shimmy_start = l;
        self.shimmy_from_track = false;
        self.work.shimmy_found = found;
    }

    /// The shimmy mode's right and left eigenvectors (one LU), its shape check (tracked start)
    /// and d zeta/dV.
    fn shimmy(&mut self, a: &Matrix<N>) {
        let v = self.work.speed_mps;
        let lambda = self.shimmy_start;
        // classified in T, as the solve leaves the vector (no soft-float f64 on the target)
        let (ep, shape_ok) = match eigen::eigenvectors_in::<T, N>(a, lambda) {
            Ok((right, left)) => (
                Some(Eigenpair {
                    lambda: Complex::new(T::of_f64(lambda.re), T::of_f64(lambda.im)),
                    right,
                    left,
                    iterations: 0,
                }),
                self.p.classify_in(&right).shape.is_shimmy(),
            ),
            Err(_) => {
                self.error();
                (None, false)
            }
        };
        if self.shimmy_from_track && !shape_ok {
            // lost the branch: the next call solves again and selects by shape
            self.shimmy_track = None;
            self.phase = Phase::Modes;
            return;
        }
        let slope = ep.and_then(|ep| {
            let dl = ep.derivative(&self.p.dlinearise_dv())?;
            let m = Mode::from_eigenvalue(lambda);
            if m.omega_n <= 0.0 {
                return None;
            }
            let (l, wn) = (narrowed_complex(m.eigenvalue()), T::of_f64(m.omega_n));
            // the +Im member: conjugate the derivative if Newton landed on the -Im one
            let dl = if lambda.im < 0.0 { dl.conj() } else { dl };
            let dr = (l.re * dl.re + l.im * dl.im) / wn;
            let dz = -(dl.re * wn - l.re * dr) / (wn * wn);
            dz.to_f64().is_finite().then_some((m, l, dl, dz))
        });
        match slope {
            Some((m, l, dl, dz)) => {
                self.work.shimmy = m;
                self.work.dzeta_dv_per_mps = dz.to_f64();
                self.work.slope_valid = true;
                self.shimmy_track = self.work.shimmy_found.then_some(ShimmyTrack {
                    speed_mps: T::of_f64(v),
                    lambda: l,
                    dl_dv: dl,
                });
            }
            None => {
                self.error();
                self.work.shimmy = Mode::from_eigenvalue(self.shimmy_start);
                self.shimmy_track = None;
            }
        }
        self.phase = if self.known_valid {
            self.first_track()
        } else {
            self.start_scan()
        };
    }

    fn first_track(&mut self) -> Phase<T> {
        self.work.tracked = true;
        let c = self.work.c_damper_nspm;
        match self
            .known
            .iter()
            .position(|k| !(k.converged && k.c_nspm == c))
        {
            Some(index) => Phase::Track { index, iter: 0 },
            None => self.check_parity(),
        }
    }

    /// One Newton step on Re s(V*) = 0 for known crossing `index`.
    fn track(&mut self, index: usize, iter: u8) -> Phase<T> {
        let Some(k) = self.known.get(index).copied() else {
            return self.check_parity();
        };
        if k.converged && k.c_nspm == self.work.c_damper_nspm {
            // same plant, same crossing: nothing to do
            return self.next_track(index);
        }
        let a = self
            .p
            .linearise(k.speed_mps.to_f64(), self.work.c_damper_nspm);
        let step = self
            .eigenpair(&a, widened_complex(k.lambda))
            .and_then(|ep| {
                let ds = ep.derivative(&self.p.dlinearise_dv())?;
                let dv = -ep.lambda.re / ds.re;
                dv.to_f64().is_finite().then_some((ep.lambda, ds, dv))
            });
        let Some((l, ds, dv)) = step else {
            return self.start_scan();
        };
        // the crossing moves with c only: a long step means another branch or a lost crossing
        // (min/max, not f64::clamp: its panic message would link float formatting, ~9 KB)
        let max_step = T::of_f64(self.cfg.max_step_mps);
        let dv = dv.min(max_step).max(-max_step);
        let x = k.speed_mps + dv;
        // the kind follows from the sign of dRe s/dV
        let kind = if ds.re > T::zero() {
            CrossingKind::Onset
        } else {
            CrossingKind::Offset
        };
        if !(T::of_f64(V_SEARCH_MIN_MPS)..=T::of_f64(V_SEARCH_MAX_MPS)).contains(&x)
            || kind != k.kind
        {
            return self.start_scan();
        }
        let converged = dv.abs() <= T::of_f64(self.cfg.tol_mps);
        if let Some(slot) = self.known.get_mut(index) {
            *slot = Known {
                speed_mps: x,
                lambda: l + ds * dv,
                kind,
                bracket_mps: dv.abs(),
                converged,
                c_nspm: self.work.c_damper_nspm,
            };
        }
        if converged {
            self.next_track(index)
        } else if iter + 1 >= HOPF_NEWTON_ITERS {
            self.start_scan()
        } else {
            Phase::Track {
                index,
                iter: iter + 1,
            }
        }
    }

    /// After crossing `index`: the next one (skipping those known at this c), or the check.
    fn next_track(&mut self, index: usize) -> Phase<T> {
        let c = self.work.c_damper_nspm;
        match self
            .known
            .iter()
            .enumerate()
            .skip(index + 1)
            .find(|(_, k)| !(k.converged && k.c_nspm == c))
        {
            Some((i, _)) => Phase::Track { index: i, iter: 0 },
            None => self.check_parity(),
        }
    }

    /// The known crossings must alternate in kind and agree with the sign of max Re at V from
    /// this cycle's Schur solve (unless V is within `parity_band_mps` of one); else scan.
    fn check_parity(&mut self) -> Phase<T> {
        let v = T::of_f64(self.work.speed_mps);
        let alternate = self
            .known
            .windows(2)
            .all(|w| matches!(w, [a, b] if a.kind != b.kind && a.speed_mps < b.speed_mps));
        let near = self
            .known
            .iter()
            .any(|k| (k.speed_mps - v).abs() <= T::of_f64(self.cfg.parity_band_mps));
        let below = self.known.iter().rev().find(|k| k.speed_mps < v);
        let above = self.known.iter().find(|k| k.speed_mps > v);
        let predicted_unstable = match (below, above) {
            (Some(b), _) => Some(b.kind == CrossingKind::Onset),
            (None, Some(a)) => Some(a.kind == CrossingKind::Offset),
            (None, None) => None,
        };
        let consistent =
            near || predicted_unstable.is_none_or(|u| u == (self.work.critical.re > 0.0));
        if alternate && consistent {
            Phase::Publish
        } else {
            self.start_scan()
        }
    }

    /// Cold: forget the known crossings and scan the whole range.
    fn start_scan(&mut self) -> Phase<T> {
        self.work.tracked = false;
        self.known.clear();
        self.known_valid = true;
        self.start_search(true)
    }

    fn start_search(&mut self, up: bool) -> Phase<T> {
        let s = Search::Probe {
            x: T::of_f64(self.work.speed_mps),
            gx: T::of_f64(self.work.critical.re),
            step: T::of_f64(self.cfg.cold_step_mps),
        };
        if up {
            Phase::Above(s)
        } else {
            Phase::Below(s)
        }
    }

    /// A side of the scan ended before its limit: the known crossings are not the whole range.
    fn scan_cut(&mut self) -> Option<Search<T>> {
        self.known_valid = false;
        None
    }

    /// One evaluation of a one-sided scan. `None` when this side is finished.
    fn search(&mut self, s: Search<T>, up: bool) -> Option<Search<T>> {
        let zero = T::zero();
        let (lim, sgn) = if up {
            (T::of_f64(V_SEARCH_MAX_MPS), T::one())
        } else {
            (T::of_f64(V_SEARCH_MIN_MPS), -T::one())
        };
        // keep one call for the publication
        let out_of_budget = self.work.calls >= self.cfg.max_calls.saturating_sub(1);
        match s {
            Search::Probe { x, gx, step } => {
                if (x - lim) * sgn >= zero {
                    return None;
                }
                if out_of_budget {
                    return self.scan_cut();
                }
                let xn = x + sgn * step;
                let xn = if up { xn.min(lim) } else { xn.max(lim) };
                let Some(ln) = self.g(xn) else {
                    return self.scan_cut();
                };
                let gn = ln.re;
                if (gn < zero) != (gx < zero) {
                    let (a, b, fa, fb) = if up { (x, xn, gx, gn) } else { (xn, x, gn, gx) };
                    let kind = if fa < zero {
                        CrossingKind::Onset
                    } else {
                        CrossingKind::Offset
                    };
                    self.refine_best = Some((gn.abs(), ln));
                    let brent = ResumableBrent::new(a, b, fa, fb, T::of_f64(self.cfg.tol_mps));
                    return self.refine(brent, kind, up);
                }
                Some(Search::Probe {
                    x: xn,
                    gx: gn,
                    step: (step + step).min(T::of_f64(self.cfg.max_step_mps)),
                })
            }
            Search::Refine {
                mut brent,
                kind,
                pending,
            } => {
                if out_of_budget {
                    return self.scan_cut();
                }
                let Some(lp) = self.g(pending) else {
                    return self.scan_cut();
                };
                if self.refine_best.is_none_or(|(b, _)| lp.re.abs() < b) {
                    self.refine_best = Some((lp.re.abs(), lp));
                }
                brent.tell(lp.re);
                self.refine(brent, kind, up)
            }
        }
    }

    /// The next Brent step on a bracketed crossing: the point to evaluate, or (converged) the
    /// crossing stored and the probing resumed beyond it.
    fn refine(
        &mut self,
        mut brent: ResumableBrent<T>,
        kind: CrossingKind,
        up: bool,
    ) -> Option<Search<T>> {
        match brent.propose() {
            BrentStep::Done(r, lo, hi) => {
                let lambda = self
                    .refine_best
                    .map_or(Complex::new(T::zero(), T::zero()), |(_, l)| l);
                let known = Known {
                    speed_mps: r,
                    lambda,
                    kind,
                    bracket_mps: hi - lo,
                    converged: true,
                    c_nspm: self.work.c_damper_nspm,
                };
                // kept ascending by insertion (no sort: 4 entries, and no sort code linked)
                let at = self
                    .known
                    .iter()
                    .position(|k| k.speed_mps > r)
                    .unwrap_or(self.known.len());
                if self.known.is_full() {
                    return self.scan_cut();
                }
                // Rebuilt, not `Vec::insert`: its overlapping shift links `memmove` (1.4 KB of
                // flash; `cargo xtask size`).
                let mut merged = heapless::Vec::<Known<T>, MAX_CROSSINGS>::new();
                for (i, k) in self.known.iter().enumerate() {
                    if i == at {
                        let _ = merged.push(known);
                    }
                    let _ = merged.push(*k);
                }
                if at >= self.known.len() {
                    let _ = merged.push(known);
                }
                self.known = merged;
                let (x, gx) = brent.end(up);
                Some(Search::Probe {
                    x,
                    gx,
                    step: T::of_f64(self.cfg.cold_step_mps),
                })
            }
            BrentStep::Eval(p) => Some(Search::Refine {
                brent,
                kind,
                pending: p,
            }),
        }
    }

    /// The first known crossing above and below V into the point.
    fn publish_crossings(&mut self) {
        let v = T::of_f64(self.work.speed_mps);
        let as_crossing = |k: &Known<T>| Crossing {
            speed_mps: k.speed_mps.to_f64(),
            kind: k.kind,
            bracket_mps: k.bracket_mps.to_f64(),
            converged: k.converged,
        };
        self.work.above = self.known.iter().find(|k| k.speed_mps > v).map(as_crossing);
        self.work.below = self
            .known
            .iter()
            .rev()
            .find(|k| k.speed_mps < v)
            .map(as_crossing);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vehicles::car::ParamSet;

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
            let r = t.step(k as f64 * 1e-3, 5.0, 0.0);
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

    /// The parity check is what catches a wrong list of known crossings: with the onset
    /// dropped, the list says "unstable below the offset", the Schur solve at 5 m/s says
    /// stable, so the cycle rescans and publishes the onset again (without the check it would
    /// publish no onset above, i.e. no speed margin).
    #[test]
    fn known_crossings_that_contradict_the_schur_solve_are_rescanned() {
        let p = ParamSet::Nominal.params();
        let mut t = ModelMarginTracker::new(p, ModelMarginConfig::default());
        let run = |t: &mut ModelMarginTracker, t0: f64| {
            (0..200u16)
                .find_map(|k| t.step(t0 + f64::from(k) * 1e-3, 5.0, 0.0))
                .expect("a cycle completes")
        };
        let cold = run(&mut t, 0.0);
        let onset = cold.above.unwrap();
        assert_eq!(onset.kind, CrossingKind::Onset);
        let warm = run(&mut t, 1.0);
        assert!(warm.tracked && warm.eigen_solves == 1);
        assert_eq!(t.known.len(), 2);
        t.known.remove(0);
        let checked = run(&mut t, 2.0);
        assert!(!checked.tracked, "the contradiction was not noticed");
        assert_eq!(checked.above, Some(onset));
        assert_eq!(checked.margin().v_crit_onset_mps, Some(onset.speed_mps));
    }
}
