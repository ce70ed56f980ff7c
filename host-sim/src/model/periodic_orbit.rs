//! Periodic orbits of a vehicle model's nonlinear plant at held inputs (speed, coil current),
//! continued in speed by shooting (`docs/plant-model.md`, "Periodic orbits").
//!
//! An orbit is its initial state `x0` on the Poincare section "the measured wheel yaw at an
//! extremum" (`c^T f(x0) = 0`, c the linear model's wheel-yaw output row) and its period T. The
//! shooting residual is `phi(x0, T; V) - x0` (phi the plant's own integrator, Dopri5 at a tight
//! tolerance) with the section condition; its Jacobian (the monodromy matrix among its columns)
//! comes from central differences of the flow, which also hold across the MR damper's
//! non-smooth Bouc-Wen terms (no variational equations to differentiate). Newton corrects, the
//! linear systems by SVD (the MR damper's hysteresis leaves a direction of near-neutral
//! offset, which the pseudo-inverse steps over). Pseudo-arclength continuation in (x0, T, V)
//! starts at a Hopf point of the plant's own Jacobian (the small cycle along the critical
//! eigenvector), steps along the secant, and follows the branch through folds. Stability:
//! the Floquet multipliers (the monodromy's eigenvalues) other than the trivial one (the one
//! nearest 1) inside the unit circle. A fold of cycles is where V turns along the branch.
//!
//! Generic over [`SimModel`]: every model gets it; a model's damper states are part of the
//! orbit.

use nalgebra::{Complex, DMatrix, DVector};
use rayon::prelude::*;
use shimmy_core::model::LinearModel;

use super::family::{SimModel, SimPlant};
use super::integrator::IntegrateError;
use super::plant::{Damper, Inputs, Method};

type C64 = Complex<f64>;

/// Relative tolerance of the flow (Dopri5): the shooting's differences divide its error by
/// their step, so it is tight.
pub const FLOW_RTOL: f64 = 1e-10;
/// Output samples per period for the orbit's amplitude (and sub-steps of the flow).
pub const SAMPLES: usize = 256;
/// Difference step of the shooting Jacobian, in scaled units (deg of measured yaw).
const FD_STEP: f64 = 1e-5;
/// Largest Floquet multiplier modulus (other than the trivial one) of a stable orbit: 1 plus
/// the differences' error.
pub const STABLE_TOL: f64 = 1e-4;

/// Why an orbit computation failed.
#[derive(Clone, Debug, PartialEq)]
pub enum OrbitError {
    /// The plant's integrator failed.
    Integrate(String),
    /// No Hopf point of the plant's Jacobian in the speed range.
    NoHopf,
    /// A linear solve failed.
    Singular,
    /// Newton did not converge at the smallest step.
    NoConvergence,
}

impl std::fmt::Display for OrbitError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Integrate(e) => write!(f, "the plant's integrator failed: {e}"),
            Self::NoHopf => write!(f, "no Hopf point of the plant in the speed range"),
            Self::Singular => write!(f, "singular shooting system"),
            Self::NoConvergence => write!(f, "Newton did not converge at the smallest step"),
        }
    }
}

impl std::error::Error for OrbitError {}

impl From<IntegrateError> for OrbitError {
    fn from(e: IntegrateError) -> Self {
        Self::Integrate(format!("{e:?}"))
    }
}

/// A Hopf point of the plant (its own Jacobian at straight running).
#[derive(Clone, Debug)]
pub struct HopfPoint {
    /// Speed, m/s.
    pub speed_mps: f64,
    /// Angular frequency of the critical pair, rad/s.
    pub omega: f64,
    /// The critical eigenvector (whole simulated state).
    pub q: DVector<C64>,
    /// Onset (a pair becomes unstable as speed rises) or offset.
    pub onset: bool,
}

/// One periodic orbit.
#[derive(Clone, Debug)]
pub struct Orbit {
    /// Speed, m/s.
    pub speed_mps: f64,
    /// Period, s.
    pub period_s: f64,
    /// Initial state on the section (whole simulated state).
    pub x0: DVector<f64>,
    /// Amplitude of the measured wheel yaw: max |c^T x - c^T x_e| over the orbit, rad.
    pub amp_rad: f64,
    /// The largest Floquet multiplier modulus other than the trivial one.
    pub max_multiplier: f64,
}

impl Orbit {
    /// Stable: every non-trivial multiplier inside the unit circle (within [`STABLE_TOL`]).
    pub fn stable(&self) -> bool {
        self.max_multiplier < 1.0 + STABLE_TOL
    }
}

/// Where a branch was started.
#[derive(Clone, Debug)]
pub enum Start {
    /// At a Hopf point of the plant, from the small cycle along its eigenvector.
    Hopf(HopfPoint),
    /// On the cycle a run settled on (no Hopf point in the range).
    Run {
        /// Speed, m/s.
        speed_mps: f64,
        /// The run's in-phase wheel-yaw start, rad.
        psi0_rad: f64,
    },
}

/// Where a continuation stops, and its step in scaled units.
#[derive(Clone, Copy, Debug)]
pub struct Limits {
    /// Lowest speed, m/s.
    pub v_lo_mps: f64,
    /// Highest speed, m/s.
    pub v_hi_mps: f64,
    /// Largest amplitude, rad.
    pub amp_max_rad: f64,
    /// Smallest amplitude of a shrinking branch, rad (it ends at the straight run).
    pub amp_min_rad: f64,
    /// Most orbits per direction.
    pub max_orbits: usize,
    /// Largest step (scaled: deg of measured yaw, km/h).
    pub ds_max: f64,
    /// Smallest step before giving up.
    pub ds_min: f64,
}

impl Limits {
    /// Speeds `v_lo_mps` to `v_hi_mps`, amplitudes up to 20 deg (a branch shrinking below
    /// 0.03 deg ends: the start's cycle at a Hopf point is 0.02 deg), at most 400 orbits,
    /// steps 1e-4 to 0.5 (deg, km/h).
    pub fn speeds(v_lo_mps: f64, v_hi_mps: f64) -> Self {
        Self {
            v_lo_mps,
            v_hi_mps,
            amp_max_rad: 20.0_f64.to_radians(),
            amp_min_rad: 0.03_f64.to_radians(),
            max_orbits: 400,
            ds_max: 0.5,
            ds_min: 1e-4,
        }
    }
}

/// A branch of orbits, in continuation order.
#[derive(Clone, Debug)]
pub struct Branch {
    /// Where it starts.
    pub start: Start,
    /// The orbits.
    pub orbits: Vec<Orbit>,
    /// Speeds (m/s) where the branch turns back in speed (folds of cycles), by a parabola
    /// through the three orbits about each turn.
    pub folds_mps: Vec<f64>,
}

impl Branch {
    /// For a branch from a Hopf point: supercritical (`true`) when its first orbits are stable
    /// (the cycle grows where the straight run is unstable), subcritical when they are
    /// unstable; `None` without orbits.
    pub fn supercritical(&self) -> Option<bool> {
        self.orbits
            .iter()
            .find(|o| o.amp_rad > 0.0)
            .map(Orbit::stable)
    }
}

/// The shooting problem of model `M` with `damper` at a held coil current.
pub struct Shooting<M: SimModel<N>, const N: usize> {
    model: M,
    damper: Damper,
    current_a: f64,
    /// The measured output row on the whole state.
    c: DVector<f64>,
    /// Size of each state per degree of measured yaw on the critical mode (the scaled units).
    scale: DVector<f64>,
    /// The equilibrium (straight running at the held current).
    x_e: DVector<f64>,
    /// The states that move (a row or column of the Jacobian not zero).
    active: Vec<usize>,
}

impl<M: SimModel<N>, const N: usize> Shooting<M, N> {
    /// The problem for `m` with `damper` held at `current_a` (0 without MR damper).
    pub fn new(m: &M, damper: Damper, current_a: f64) -> Result<Self, OrbitError> {
        let mut plant = m.plant(damper, Method::Dopri5 { rtol: FLOW_RTOL });
        // the plant's state is the shooting's whole state
        let n = M::State::default().as_ref().len();
        let mut c = DVector::zeros(n);
        let row = m.linear().wheel_yaw_output();
        for i in 0..N {
            c[i] = row[i];
        }
        // straight running: the coil filter settled at the held current, all else at rest
        plant.set_state(M::State::default().as_ref());
        let u = Inputs {
            current_cmd_a: current_a,
            ..Inputs::default()
        };
        plant.advance(2.0, &u)?;
        let x_e = DVector::from_column_slice(plant.state());
        let mut s = Self {
            model: *m,
            damper,
            current_a,
            c,
            scale: DVector::from_element(n, 1.0_f64.to_radians()),
            x_e,
            active: Vec::new(),
        };
        let j = s.jacobian(10.0);
        s.active = (0..n)
            .filter(|&k| j.row(k).amax() > 0.0 || j.column(k).amax() > 0.0)
            .collect();
        Ok(s)
    }

    /// A plant of the model (each flow and each field evaluation its own: the plants are not
    /// `Sync`, the differences run in parallel).
    fn plant(&self) -> M::Plant {
        self.model
            .plant(self.damper, Method::Dopri5 { rtol: FLOW_RTOL })
    }

    fn inputs(&self, v_mps: f64) -> Inputs {
        Inputs {
            current_cmd_a: self.current_a,
            speed_mps: v_mps,
            ..Inputs::default()
        }
    }

    /// The state count.
    pub fn dim(&self) -> usize {
        self.x_e.len()
    }

    /// The straight-running state.
    pub fn equilibrium(&self) -> &DVector<f64> {
        &self.x_e
    }

    /// dx/dt at `x`, speed `v_mps`.
    pub fn field(&self, x: &DVector<f64>, v_mps: f64) -> DVector<f64> {
        let mut dx = DVector::zeros(x.len());
        self.plant()
            .vector_field(x.as_slice(), &self.inputs(v_mps), dx.as_mut_slice());
        dx
    }

    /// The measured yaw of `x` relative to straight running, rad.
    pub fn output(&self, x: &DVector<f64>) -> f64 {
        self.c.dot(&(x - &self.x_e))
    }

    /// The flow from `x0` over `t_s` at `v_mps`: the end state and max |output| on the way
    /// ([`SAMPLES`] samples).
    pub fn flow(
        &self,
        x0: &DVector<f64>,
        t_s: f64,
        v_mps: f64,
    ) -> Result<(DVector<f64>, f64), OrbitError> {
        let mut p = self.plant();
        p.set_state(x0.as_slice());
        let u = self.inputs(v_mps);
        let dt = t_s / SAMPLES as f64;
        let mut amp = self.output(x0).abs();
        for _ in 0..SAMPLES {
            p.advance(dt, &u)?;
            let x = DVector::from_column_slice(p.state());
            amp = amp.max(self.output(&x).abs());
        }
        Ok((DVector::from_column_slice(p.state()), amp))
    }

    /// The plant's Jacobian at straight running (central differences at 1e-7).
    pub fn jacobian(&self, v_mps: f64) -> DMatrix<f64> {
        let n = self.dim();
        let h = 1e-7;
        let mut j = DMatrix::zeros(n, n);
        for k in 0..n {
            let mut xp = self.x_e.clone();
            xp[k] += h;
            let mut xm = self.x_e.clone();
            xm[k] -= h;
            let d = (self.field(&xp, v_mps) - self.field(&xm, v_mps)) / (2.0 * h);
            j.set_column(k, &d);
        }
        j
    }

    /// The number of oscillatory eigenvalue pairs of the Jacobian in the right half-plane.
    pub fn unstable_pairs(&self, v_mps: f64) -> usize {
        let j = self.jacobian(v_mps);
        j.complex_eigenvalues()
            .iter()
            .filter(|z| z.im > 1e-6 && z.re > 0.0)
            .count()
    }

    /// The Hopf points of the plant between `v_lo` and `v_hi` (m/s): a scan at `step` where
    /// the count of unstable oscillatory pairs changes, refined by bisection to 1e-6 m/s.
    pub fn hopf_points(&self, v_lo: f64, v_hi: f64, step: f64) -> Vec<HopfPoint> {
        let n = ((v_hi - v_lo) / step).ceil().max(1.0) as usize;
        let grid: Vec<f64> = (0..=n)
            .map(|k| v_lo + (v_hi - v_lo) * k as f64 / n as f64)
            .collect();
        let counts: Vec<usize> = grid.iter().map(|&v| self.unstable_pairs(v)).collect();
        let mut out = Vec::new();
        for k in 0..n {
            if counts[k] == counts[k + 1] {
                continue;
            }
            let onset = counts[k + 1] > counts[k];
            let (mut a, mut b) = (grid[k], grid[k + 1]);
            while b - a > 1e-6 {
                let m = 0.5 * (a + b);
                if self.unstable_pairs(m) == counts[k] {
                    a = m;
                } else {
                    b = m;
                }
            }
            let v = 0.5 * (a + b);
            if let Some(h) = self.critical_pair(v, onset) {
                out.push(h);
            }
        }
        out
    }

    /// The pair nearest the imaginary axis at `v_mps` and its eigenvector.
    fn critical_pair(&self, v_mps: f64, onset: bool) -> Option<HopfPoint> {
        self.pair_minimising(v_mps, onset, |z| z.re.abs())
    }

    /// The oscillatory pair (upper half plane) of the Jacobian at `v_mps` with the least
    /// `key`, and its eigenvector.
    fn pair_minimising(
        &self,
        v_mps: f64,
        onset: bool,
        key: impl Fn(&C64) -> f64,
    ) -> Option<HopfPoint> {
        let lambda = self
            .jacobian(v_mps)
            .complex_eigenvalues()
            .iter()
            .copied()
            .filter(|z| z.im > 1e-6)
            .min_by(|x, y| key(x).total_cmp(&key(y)))?;
        self.pair_at(v_mps, lambda, onset)
    }

    /// The eigenvalue `lambda` of the Jacobian at `v_mps` with its eigenvector (SVD null vector
    /// of `J - lambda I`).
    fn pair_at(&self, v_mps: f64, lambda: C64, onset: bool) -> Option<HopfPoint> {
        let n = self.dim();
        let jc = self.jacobian(v_mps).map(|v| C64::new(v, 0.0));
        let m = jc - DMatrix::<C64>::identity(n, n) * lambda;
        let svd = m.svd(false, true);
        let v_t = svd.v_t?;
        let (k, _) = svd
            .singular_values
            .iter()
            .enumerate()
            .min_by(|x, y| x.1.total_cmp(y.1))?;
        Some(HopfPoint {
            speed_mps: v_mps,
            omega: lambda.im,
            q: v_t.row(k).adjoint(),
            onset,
        })
    }

    /// Scaled unknowns `(x / scale, T / T_ref * 10, V in km/h)` from physical ones.
    fn pack(&self, x0: &DVector<f64>, t: f64, v: f64, t_ref: f64) -> DVector<f64> {
        let n = self.dim();
        let mut u = DVector::zeros(n + 2);
        for i in 0..n {
            u[i] = (x0[i] - self.x_e[i]) / self.scale[i];
        }
        u[n] = 10.0 * t / t_ref;
        u[n + 1] = shimmy_core::units::mps_to_kmh(v);
        u
    }

    fn unpack(&self, u: &DVector<f64>, t_ref: f64) -> (DVector<f64>, f64, f64) {
        let n = self.dim();
        let x0 = DVector::from_fn(n, |i, _| self.x_e[i] + u[i] * self.scale[i]);
        (
            x0,
            u[n] * t_ref / 10.0,
            shimmy_core::units::kmh_to_mps(u[n + 1]),
        )
    }

    /// The shooting residual (n + 1, scaled) at scaled unknowns `u`, and the orbit's amplitude.
    fn residual(
        &self,
        u: &DVector<f64>,
        t_ref: f64,
        omega: f64,
    ) -> Result<(DVector<f64>, f64), OrbitError> {
        let n = self.dim();
        let (x0, t, v) = self.unpack(u, t_ref);
        let (x1, amp) = self.flow(&x0, t, v)?;
        let mut r = DVector::zeros(n + 1);
        for i in 0..n {
            r[i] = (x1[i] - x0[i]) / self.scale[i];
        }
        r[n] = self.c.dot(&self.field(&x0, v)) / (omega * 1.0_f64.to_radians());
        Ok((r, amp))
    }

    /// The residual's Jacobian in `u` by central differences (columns in parallel).
    fn residual_jacobian(
        &self,
        u: &DVector<f64>,
        t_ref: f64,
        omega: f64,
    ) -> Result<DMatrix<f64>, OrbitError> {
        let m = u.len();
        let cols: Vec<Result<DVector<f64>, OrbitError>> = (0..m)
            .into_par_iter()
            .map(|k| {
                let mut up = u.clone();
                up[k] += FD_STEP;
                let mut um = u.clone();
                um[k] -= FD_STEP;
                let rp = self.residual(&up, t_ref, omega)?.0;
                let rm = self.residual(&um, t_ref, omega)?.0;
                Ok((rp - rm) / (2.0 * FD_STEP))
            })
            .collect();
        let mut j = DMatrix::zeros(m - 1, m);
        for (k, c) in cols.into_iter().enumerate() {
            j.set_column(k, &c?);
        }
        Ok(j)
    }

    /// Sets the scaled units from the critical eigenvector: each state's size per degree of
    /// measured yaw on the mode (at least 1e-3 of the largest, so that every state counts).
    fn scale_from(&mut self, q: &DVector<C64>) {
        let cq = self.c.map(|v| C64::new(v, 0.0)).dot(q).norm();
        let per_deg = q.map(|z| z.norm() / cq * 1.0_f64.to_radians());
        let floor = 1e-3 * per_deg.max();
        self.scale = per_deg.map(|s| s.max(floor));
    }

    /// Continues the branch of cycles born at `hopf` while its speed stays in `[v_lo, v_hi]`
    /// (m/s) and its amplitude below `amp_max_rad`, at most `max_orbits` orbits.
    pub fn continue_from_hopf(
        &mut self,
        hopf: &HopfPoint,
        lim: &Limits,
    ) -> Result<Branch, OrbitError> {
        self.scale_from(&hopf.q);
        let omega = hopf.omega;
        let t_ref = 2.0 * std::f64::consts::PI / omega;
        // the small cycle 0.02 deg along the eigenvector, phased to the output's maximum
        let cq = self.c.map(|v| C64::new(v, 0.0)).dot(&hopf.q);
        let rot = cq.conj() / cq.norm();
        let dir = hopf.q.map(|z| (z * rot).re / cq.norm());
        let x_start = &self.x_e + &dir * 0.02_f64.to_radians();
        let u_eq = self.pack(&self.x_e, t_ref, hopf.speed_mps, t_ref);
        let pred = self.pack(&x_start, t_ref, hopf.speed_mps, t_ref);
        // the first cycle on the hyperplane through the guess normal to the eigenvector
        let (u1, jac, _) = self.correct(&pred, &(&pred - &u_eq).normalize(), t_ref, omega)?;
        let first = self.orbit(&u1, &jac, t_ref)?;
        let (mut orbits, us, _) = self.march(&u_eq, &u1, t_ref, omega, lim)?;
        orbits.insert(0, first);
        let mut all = vec![u1];
        all.extend(us);
        let folds_mps = folds(&all, &orbits, self.dim() + 1);
        Ok(Branch {
            start: Start::Hopf(hopf.clone()),
            orbits,
            folds_mps,
        })
    }

    /// The branch through the cycle that a run from the in-phase wheel yaw `psi0_rad` at
    /// `v_mps` settles on after `settle_s` (none if it decays), continued both ways in speed.
    pub fn continue_from_run(
        &mut self,
        v_mps: f64,
        psi0_rad: f64,
        settle_s: f64,
        lim: &Limits,
    ) -> Result<Option<Branch>, OrbitError> {
        let Some((x0, t)) = self.settled_cycle(v_mps, psi0_rad, settle_s)? else {
            return Ok(None);
        };
        let omega = 2.0 * std::f64::consts::PI / t;
        // the scaled units from the mode of the straight run at the cycle's frequency
        if let Some(h) = self.pair_nearest(v_mps, omega) {
            self.scale_from(&h.q);
        }
        let t_ref = t;
        let n = self.dim();
        let mut e_v = DVector::zeros(n + 2);
        e_v[n + 1] = 1.0;
        let u0 = self.pack(&x0, t, v_mps, t_ref);
        let (ua, jac, _) = self.correct(&u0, &e_v, t_ref, omega)?;
        let seed = self.orbit(&ua, &jac, t_ref)?;
        let mut sides = Vec::new();
        let mut closed = false;
        for sign in [-1.0, 1.0] {
            if closed {
                // a closed branch (an isola): the first direction went all the way round
                sides.push((Vec::new(), Vec::new()));
                continue;
            }
            // a second cycle 0.1 km/h away at fixed speed gives the secant
            let (ub, jac_b, _) = self.correct(&(&ua + &e_v * (0.1 * sign)), &e_v, t_ref, omega)?;
            let ob = self.orbit(&ub, &jac_b, t_ref)?;
            let (mut o, mut u, round) = self.march(&ua, &ub, t_ref, omega, lim)?;
            closed = round;
            o.insert(0, ob);
            u.insert(0, ub);
            sides.push((o, u));
        }
        let (mut down_o, mut down_u) = sides.remove(0);
        let (up_o, up_u) = sides.remove(0);
        down_o.reverse();
        down_u.reverse();
        down_o.push(seed);
        down_u.push(ua);
        down_o.extend(up_o);
        down_u.extend(up_u);
        let folds_mps = folds(&down_u, &down_o, n + 1);
        Ok(Some(Branch {
            start: Start::Run {
                speed_mps: v_mps,
                psi0_rad,
            },
            orbits: down_o,
            folds_mps,
        }))
    }

    /// The orbit at corrected unknowns `u` with the residual's Jacobian `jac` there.
    fn orbit(&self, u: &DVector<f64>, jac: &DMatrix<f64>, t_ref: f64) -> Result<Orbit, OrbitError> {
        let (x0, t, v) = self.unpack(u, t_ref);
        let (_, amp) = self.flow(&x0, t, v)?;
        // the monodromy on the states that move (a model's absent damper's states do not)
        let k = self.active.len();
        let mono = DMatrix::from_fn(k, k, |i, j| {
            let (a, b) = (self.active[i], self.active[j]);
            jac[(a, b)] + if a == b { 1.0 } else { 0.0 }
        });
        Ok(Orbit {
            speed_mps: v,
            period_s: t,
            x0,
            amp_rad: amp,
            max_multiplier: nontrivial_max(&mono),
        })
    }

    /// The state at an output maximum and the period of the cycle a run from `psi0_rad` at
    /// `v_mps` is on after `settle_s`; `None` when the run has decayed below 1e-4 rad.
    fn settled_cycle(
        &self,
        v_mps: f64,
        psi0_rad: f64,
        settle_s: f64,
    ) -> Result<Option<(DVector<f64>, f64)>, OrbitError> {
        let mut p = self.plant();
        let mut x = M::kick_state(psi0_rad);
        for (xi, ei) in x.as_mut().iter_mut().zip(self.x_e.iter()) {
            if *xi == 0.0 {
                *xi = *ei;
            }
        }
        p.set_state(x.as_ref());
        let u = self.inputs(v_mps);
        p.advance(settle_s, &u)?;
        // two output maxima in up to 3 s of 1 ms steps: the later state and their spacing
        let dt = 1e-3;
        let rate = |p: &M::Plant| {
            let x = DVector::from_column_slice(p.state());
            self.c.dot(&self.field(&x, v_mps))
        };
        let mut maxima: Vec<(f64, DVector<f64>)> = Vec::new();
        let mut r_prev = rate(&p);
        let mut t = 0.0;
        while t < 3.0 && maxima.len() < 2 {
            let before = DVector::from_column_slice(p.state());
            p.advance(dt, &u)?;
            t += dt;
            let r = rate(&p);
            if r_prev > 0.0 && r <= 0.0 {
                // the crossing by linear interpolation of the rate: a Newton start
                let w = r_prev / (r_prev - r);
                let x = &before + (DVector::from_column_slice(p.state()) - &before) * w;
                maxima.push((t - dt + w * dt, x));
            }
            r_prev = r;
        }
        if maxima.len() < 2 || self.output(&maxima[1].1).abs() < 1e-4 {
            return Ok(None);
        }
        let period = maxima[1].0 - maxima[0].0;
        Ok(Some((maxima[1].1.clone(), period)))
    }

    /// The oscillatory pair of the Jacobian at `v_mps` with the frequency nearest `omega`.
    fn pair_nearest(&self, v_mps: f64, omega: f64) -> Option<HopfPoint> {
        self.pair_minimising(v_mps, false, |z| (z.im - omega).abs())
    }

    /// Pseudo-arclength continuation from the branch points `u_a`, `u_b` (scaled unknowns)
    /// along the secant: the orbits after `u_b`, their unknowns, and whether the branch came
    /// back to `u_a` (a closed branch; it stops there).
    fn march(
        &self,
        u_a: &DVector<f64>,
        u_b: &DVector<f64>,
        t_ref: f64,
        omega: f64,
        lim: &Limits,
    ) -> Result<Marched, OrbitError> {
        let (mut u_prev, mut u) = (u_a.clone(), u_b.clone());
        let mut ds = (&u - &u_prev).norm().min(lim.ds_max);
        let u_b_amp = {
            let (x0, t, v) = self.unpack(u_b, t_ref);
            self.flow(&x0, t, v)?.1
        };
        let (mut orbits, mut us) = (Vec::new(), Vec::new());
        while orbits.len() < lim.max_orbits {
            let tangent = (&u - &u_prev).normalize();
            let pred = &u + &tangent * ds;
            match self.correct(&pred, &tangent, t_ref, omega) {
                Ok((u_new, jac, iters)) => {
                    let o = self.orbit(&u_new, &jac, t_ref)?;
                    // back at the start: within this step of it, having been farther
                    let far = us
                        .iter()
                        .any(|x: &DVector<f64>| (x - u_a).norm() > 4.0 * lim.ds_max);
                    if far && (&u_new - u_a).norm() <= ds {
                        return Ok((orbits, us, true));
                    }
                    // a branch shrinking to the straight run ends there (a Hopf point)
                    let shrinking =
                        orbits.last().map_or(u_b_amp, |p: &Orbit| p.amp_rad) > o.amp_rad;
                    let done = o.speed_mps < lim.v_lo_mps
                        || o.speed_mps > lim.v_hi_mps
                        || o.amp_rad > lim.amp_max_rad
                        || (shrinking && o.amp_rad < lim.amp_min_rad);
                    orbits.push(o);
                    us.push(u_new.clone());
                    u_prev = std::mem::replace(&mut u, u_new);
                    if done {
                        break;
                    }
                    if iters <= 3 {
                        ds = (ds * 1.5).min(lim.ds_max);
                    }
                }
                Err(_) if ds > lim.ds_min => ds *= 0.5,
                Err(_) => break,
            }
        }
        Ok((orbits, us, false))
    }

    /// Newton on the residual with the arclength row `tangent . (u - pred) = 0`: the corrected
    /// unknowns, the iterations taken, and the residual's Jacobian at the solution.
    fn correct(
        &self,
        pred: &DVector<f64>,
        tangent: &DVector<f64>,
        t_ref: f64,
        omega: f64,
    ) -> Result<(DVector<f64>, DMatrix<f64>, usize), OrbitError> {
        let m = pred.len();
        let mut u = pred.clone();
        for it in 1..=8 {
            let (r, _) = self.residual(&u, t_ref, omega)?;
            let j = self.residual_jacobian(&u, t_ref, omega)?;
            let mut a = DMatrix::zeros(m, m);
            a.view_mut((0, 0), (m - 1, m)).copy_from(&j);
            a.set_row(m - 1, &tangent.transpose());
            let mut b = DVector::zeros(m);
            b.rows_mut(0, m - 1).copy_from(&(-r));
            b[m - 1] = -tangent.dot(&(&u - pred));
            let svd = a.svd(true, true);
            let tol = 1e-10 * svd.singular_values.max();
            let du = svd.solve(&b, tol).map_err(|_| OrbitError::Singular)?;
            u += &du;
            if !u.iter().all(|v| v.is_finite()) {
                return Err(OrbitError::NoConvergence);
            }
            if du.amax() < 1e-7 {
                return Ok((u, j, it));
            }
        }
        Err(OrbitError::NoConvergence)
    }
}

/// A continuation's orbits, their scaled unknowns, and whether it closed on its start.
type Marched = (Vec<Orbit>, Vec<DVector<f64>>, bool);

/// The largest multiplier modulus of `mono` other than the one nearest 1 (the trivial one).
fn nontrivial_max(mono: &DMatrix<f64>) -> f64 {
    let mut ev: Vec<C64> = mono.complex_eigenvalues().iter().copied().collect();
    if let Some((k, _)) = ev
        .iter()
        .enumerate()
        .min_by(|x, y| (x.1 - 1.0).norm().total_cmp(&(y.1 - 1.0).norm()))
    {
        ev.remove(k);
    }
    ev.iter().map(|z| z.norm()).fold(0.0, f64::max)
}

/// The speeds (m/s) where the continued unknowns `us` (speed in km/h at `k`) of `orbits` turn
/// back in speed and the stability changes across the turn (within three orbits each side: a
/// multiplier passes +1 there; a turn without it is the branch passing through a Hopf point):
/// the vertex of the parabola through the three points about each turn, in arclength.
fn folds(us: &[DVector<f64>], orbits: &[Orbit], k: usize) -> Vec<f64> {
    let mut out = Vec::new();
    for (i, w) in us.windows(3).enumerate() {
        let (a, b, c) = (w[0][k], w[1][k], w[2][k]);
        if (b - a) * (c - b) >= 0.0 {
            continue;
        }
        let before = &orbits[i.saturating_sub(2)..=i];
        let after = &orbits[i + 2..(i + 5).min(orbits.len())];
        let changes = before.iter().any(|o| o.stable()) && after.iter().any(|o| !o.stable())
            || before.iter().any(|o| !o.stable()) && after.iter().any(|o| o.stable());
        if !changes {
            continue;
        }
        let s1 = (&w[1] - &w[0]).norm();
        let s2 = s1 + (&w[2] - &w[1]).norm();
        // V(s) = a + p s + r s^2 through (0, a), (s1, b), (s2, c)
        let d1 = (b - a) / s1;
        let d2 = (c - b) / (s2 - s1);
        let r = (d2 - d1) / s2;
        let p = d1 - r * s1;
        let s_star = -p / (2.0 * r);
        out.push(shimmy_core::units::kmh_to_mps(
            a + p * s_star + r * s_star * s_star,
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::hopf_type::{hopf_type_at, Criticality};
    use shimmy_core::units::{kmh_to_mps, mps_to_kmh};
    use shimmy_core::vehicles::car::{ParamSet, PlantParams};

    fn car() -> PlantParams {
        ParamSet::Nominal.params()
    }

    /// The amplitudes (rad) of the branch's cycles of stability `stable` at `v_mps`
    /// (interpolated between the orbits that bracket it).
    fn amps_at(b: &Branch, v_mps: f64, stable: bool) -> Vec<f64> {
        b.orbits
            .windows(2)
            .filter(|w| w[0].stable() == stable && w[1].stable() == stable)
            .filter(|w| {
                let (a, c) = (w[0].speed_mps, w[1].speed_mps);
                a.min(c) <= v_mps && v_mps <= a.max(c) && a != c
            })
            .map(|w| {
                let f = (v_mps - w[0].speed_mps) / (w[1].speed_mps - w[0].speed_mps);
                w[0].amp_rad + f * (w[1].amp_rad - w[0].amp_rad)
            })
            .collect()
    }

    /// The car without damper: one Hopf onset at the linear model's (the plant's Jacobian is
    /// A(V)); its first cycles are stable (supercritical, as l1 < 0 says) and, 0.25 km/h past
    /// the onset, the continued cycle's amplitude is the normal form's within 3 %; 1 km/h past
    /// it the two differ more (the normal form's error grows with V - V_c), so the comparison
    /// can fail.
    #[test]
    fn the_small_cycle_near_a_supercritical_onset_is_the_normal_forms() {
        let p = car();
        let mut s = Shooting::<PlantParams, 10>::new(&p, Damper::None, 0.0).unwrap();
        let hs = s.hopf_points(kmh_to_mps(10.0), kmh_to_mps(60.0), kmh_to_mps(1.0));
        assert_eq!(hs.len(), 1, "{hs:?}");
        let h = &hs[0];
        let v_lin = crate::model::family::onset_kmh(&p).unwrap();
        assert!(
            (mps_to_kmh(h.speed_mps) - v_lin).abs() < 1e-3,
            "{h:?} vs {v_lin}"
        );
        let mut lim = Limits::speeds(kmh_to_mps(10.0), h.speed_mps + kmh_to_mps(1.5));
        lim.ds_max = 0.1;
        let b = s.continue_from_hopf(h, &lim).unwrap();
        assert_eq!(b.supercritical(), Some(true));
        assert!(b.folds_mps.is_empty());
        let nf = hopf_type_at(
            &p,
            Damper::None,
            h.speed_mps,
            h.omega / std::f64::consts::TAU,
        )
        .unwrap();
        assert_eq!(nf.criticality(), Criticality::Supercritical);
        let mut errs = Vec::new();
        for dk in [0.25, 1.0] {
            let v = h.speed_mps + kmh_to_mps(dk);
            let got = amps_at(&b, v, true);
            assert_eq!(got.len(), 1, "{dk} km/h: {got:?}");
            let want = nf.cycle_amplitude_rad(v).unwrap();
            let err = (got[0] / want - 1.0).abs();
            println!(
                "V_c + {dk} km/h: shooting {:.4} deg, normal form {:.4} deg ({:.2} %)",
                got[0].to_degrees(),
                want.to_degrees(),
                100.0 * err
            );
            errs.push(err);
        }
        assert!(errs[0] < 0.03, "{errs:?}");
        assert!(errs[1] > errs[0], "{errs:?}");
    }
}
