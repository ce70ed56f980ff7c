//! Host-side fit of the firmware's invertible MR model ([`super::mr_model`]) to the simulator's
//! damper (Spencer modified Bouc-Wen, [`crate::mr_damper`]).
//!
//! The Spencer model is driven by sinusoidal strokes x = A sin(2 pi f t) at constant coil current
//! (u held at I: the fit describes the steady force-velocity behaviour; the coil lag is the
//! actuator's business) over a grid of currents, amplitudes and shimmy-band frequencies. It is
//! integrated with classical RK4 at a fixed number of sub-steps per cycle (the hysteresis variable
//! z is stiff: |d(dz)/dz| ~ 2 beta |v| |z| ~ 1e4 1/s at 0.5 m/s, so the step is kept at
//! h |lambda| < 0.5, far inside RK4's stability limit 2.8). After settling cycles the force is
//! sampled and the model
//!
//! F = (f_ca + f_cb I) S(v / v0) + (c_a + c_b I) v
//!
//! is fitted by least squares: linear in (f_ca, f_cb, c_a, c_b) for given v0 (4x4 normal
//! equations), with v0 found by a log-spaced scan refined by golden-section search. S is tanh or
//! the algebraic sigmoid x / sqrt(1 + x^2) ([`Smoothing`]).
//!
//! Everything here is f64, heap-free (the caller provides the sample buffer) and not on the
//! control path; the firmware only links the fitted constants in [`super::mr_model::MrModel::FITTED`].

use crate::mr_damper::{rates, SpencerParams, SpencerState};
use core::f64::consts::PI;

/// The excitation grid of a fit.
#[derive(Clone, Copy, Debug)]
pub struct FitGrid<'a> {
    /// Constant coil currents, A.
    pub currents_a: &'a [f64],
    /// Stroke amplitudes, m.
    pub amplitudes_m: &'a [f64],
    /// Stroke frequencies, Hz.
    pub freqs_hz: &'a [f64],
    /// Cycles run before sampling starts.
    pub settle_cycles: usize,
    /// Cycles sampled.
    pub record_cycles: usize,
    /// Samples taken per recorded cycle.
    pub samples_per_cycle: usize,
    /// RK4 sub-steps per cycle (must be a multiple of `samples_per_cycle`).
    pub substeps_per_cycle: usize,
}

/// The reference grid: 0-2 A, 1-8 mm stroke (0.005-0.04 rad of in-phase wheel yaw at
/// l_t = 0.197 m), 4-14 Hz.
pub const REFERENCE_GRID: FitGrid<'static> = FitGrid {
    currents_a: &[0.0, 0.25, 0.5, 1.0, 1.5, 2.0],
    amplitudes_m: &[0.001, 0.003, 0.008],
    freqs_hz: &[4.0, 8.0, 14.0],
    settle_cycles: 2,
    record_cycles: 2,
    samples_per_cycle: 100,
    substeps_per_cycle: 4000,
};

impl FitGrid<'_> {
    /// Number of samples [`collect_samples`] produces.
    pub fn sample_count(&self) -> usize {
        self.currents_a.len()
            * self.amplitudes_m.len()
            * self.freqs_hz.len()
            * self.record_cycles
            * self.samples_per_cycle
    }
}

/// One force sample.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FitSample {
    /// Coil current, A.
    pub current_a: f64,
    /// Stroke rate, m/s.
    pub v_mps: f64,
    /// Spencer-model force, N.
    pub force_n: f64,
}

/// Runs the Spencer model under one sinusoidal stroke and writes the recorded samples into
/// `out`. Returns the number written (limited by `out.len()`).
pub fn simulate_sine(
    p: &SpencerParams,
    grid: &FitGrid<'_>,
    current_a: f64,
    amp_m: f64,
    freq_hz: f64,
    out: &mut [FitSample],
) -> usize {
    let w = 2.0 * PI * freq_hz;
    let n_sub = grid.substeps_per_cycle.max(1);
    let every = (n_sub / grid.samples_per_cycle.max(1)).max(1);
    let h = 1.0 / (freq_hz * n_sub as f64);
    let mut s = SpencerState {
        u: current_a,
        y: 0.0,
        z: 0.0,
    };
    let f = |t: f64, y: f64, z: f64| {
        let st = SpencerState { u: current_a, y, z };
        let r = rates(
            p,
            &st,
            amp_m * libm::sin(w * t),
            amp_m * w * libm::cos(w * t),
            current_a,
        );
        (r.dy, r.dz, r.force_n)
    };
    let total = n_sub * (grid.settle_cycles + grid.record_cycles);
    let start = n_sub * grid.settle_cycles;
    let mut n = 0;
    for k in 0..total {
        let t = k as f64 * h;
        if k >= start && (k - start).is_multiple_of(every) {
            if let Some(slot) = out.get_mut(n) {
                let (_, _, force) = f(t, s.y, s.z);
                *slot = FitSample {
                    current_a,
                    v_mps: amp_m * w * libm::cos(w * t),
                    force_n: force,
                };
                n += 1;
            }
        }
        let (k1y, k1z, _) = f(t, s.y, s.z);
        let (k2y, k2z, _) = f(t + 0.5 * h, s.y + 0.5 * h * k1y, s.z + 0.5 * h * k1z);
        let (k3y, k3z, _) = f(t + 0.5 * h, s.y + 0.5 * h * k2y, s.z + 0.5 * h * k2z);
        let (k4y, k4z, _) = f(t + h, s.y + h * k3y, s.z + h * k3z);
        s.y += h / 6.0 * (k1y + 2.0 * k2y + 2.0 * k3y + k4y);
        s.z += h / 6.0 * (k1z + 2.0 * k2z + 2.0 * k3z + k4z);
    }
    n
}

/// Runs the whole grid; returns the number of samples written into `out`.
pub fn collect_samples(p: &SpencerParams, grid: &FitGrid<'_>, out: &mut [FitSample]) -> usize {
    let mut n = 0;
    for &i in grid.currents_a {
        for &a in grid.amplitudes_m {
            for &f in grid.freqs_hz {
                let rest = out.get_mut(n..).unwrap_or(&mut []);
                n += simulate_sine(p, grid, i, a, f, rest);
            }
        }
    }
    n
}

/// The smoothing function S of the Bingham model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Smoothing {
    /// S(x) = tanh(x).
    Tanh,
    /// S(x) = x / sqrt(1 + x^2): same slope at 0 and same limits, one hardware sqrt on the M4F.
    Algebraic,
}

impl Smoothing {
    /// S(x).
    pub fn eval(self, x: f64) -> f64 {
        match self {
            Smoothing::Tanh => libm::tanh(x),
            Smoothing::Algebraic => x / libm::sqrt(1.0 + x * x),
        }
    }
}

/// A fitted Bingham model and its error.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BinghamFit {
    /// Yield force at 0 A, N.
    pub f_ca_n: f64,
    /// Yield force per ampere, N/A.
    pub f_cb_n_per_a: f64,
    /// Viscous coefficient at 0 A, N s/m.
    pub c_a_ns_per_m: f64,
    /// Viscous coefficient per ampere [N s/(m A)].
    pub c_b_ns_per_m_a: f64,
    /// Smoothing velocity, m/s.
    pub v0_mps: f64,
    /// The smoothing function used.
    pub smoothing: Smoothing,
    /// RMS force error, N.
    pub rms_error_n: f64,
    /// RMS of the fitted forces, N.
    pub rms_force_n: f64,
}

impl BinghamFit {
    /// RMS force error as a percentage of the RMS force.
    pub fn rms_error_pct(&self) -> f64 {
        100.0 * self.rms_error_n / self.rms_force_n
    }

    /// Model force at current `i_a` and stroke rate `v_mps`.
    pub fn force_n(&self, i_a: f64, v_mps: f64) -> f64 {
        (self.f_ca_n + self.f_cb_n_per_a * i_a) * self.smoothing.eval(v_mps / self.v0_mps)
            + (self.c_a_ns_per_m + self.c_b_ns_per_m_a * i_a) * v_mps
    }
}

/// Solves the 4x4 system `a x = b` by Gaussian elimination with partial pivoting.
fn solve4(mut a: [[f64; 4]; 4], mut b: [f64; 4]) -> Option<[f64; 4]> {
    for col in 0..4 {
        let piv = (col..4).max_by(|&i, &j| {
            libm::fabs(a[i][col])
                .partial_cmp(&libm::fabs(a[j][col]))
                .unwrap_or(core::cmp::Ordering::Equal)
        })?;
        if libm::fabs(a[piv][col]) < 1e-300 {
            return None;
        }
        a.swap(col, piv);
        b.swap(col, piv);
        let pivot_row = a[col];
        for r in col + 1..4 {
            let m = a[r][col] / pivot_row[col];
            for (arc, pc) in a[r].iter_mut().zip(pivot_row.iter()).skip(col) {
                *arc -= m * pc;
            }
            b[r] -= m * b[col];
        }
    }
    let mut x = [0.0; 4];
    for r in (0..4).rev() {
        let mut acc = b[r];
        for (arc, xc) in a[r].iter().zip(x.iter()).skip(r + 1) {
            acc -= arc * xc;
        }
        x[r] = acc / a[r][r];
    }
    Some(x)
}

/// Linear least squares for fixed v0: returns (coefficients, sum of squared errors).
fn fit_linear(samples: &[FitSample], v0: f64, sm: Smoothing) -> Option<([f64; 4], f64)> {
    let mut ata = [[0.0; 4]; 4];
    let mut atb = [0.0; 4];
    let basis = |s: &FitSample| {
        let g = sm.eval(s.v_mps / v0);
        [g, s.current_a * g, s.v_mps, s.current_a * s.v_mps]
    };
    for s in samples {
        let phi = basis(s);
        for r in 0..4 {
            for c in 0..4 {
                ata[r][c] += phi[r] * phi[c];
            }
            atb[r] += phi[r] * s.force_n;
        }
    }
    let x = solve4(ata, atb)?;
    let sse = samples
        .iter()
        .map(|s| {
            let phi = basis(s);
            let e = s.force_n - (0..4).map(|k| x[k] * phi[k]).sum::<f64>();
            e * e
        })
        .sum();
    Some((x, sse))
}

/// Fits the Bingham model to the samples. `None` if there are no samples or the normal
/// equations are singular.
pub fn fit(samples: &[FitSample], sm: Smoothing) -> Option<BinghamFit> {
    if samples.is_empty() {
        return None;
    }
    let cost =
        |ln_v0: f64| fit_linear(samples, libm::exp(ln_v0), sm).map_or(f64::INFINITY, |r| r.1);
    // Coarse log scan of v0 in [1e-4, 1] m/s, then golden section around the best point.
    let (lo, hi, n) = (libm::log(1e-4), libm::log(1.0), 41);
    let step = (hi - lo) / (n - 1) as f64;
    let mut best = (f64::INFINITY, lo);
    for k in 0..n {
        let x = lo + step * k as f64;
        let c = cost(x);
        if c < best.0 {
            best = (c, x);
        }
    }
    let (mut a, mut b) = (best.1 - step, best.1 + step);
    let g = 0.5 * (libm::sqrt(5.0) - 1.0);
    let (mut x1, mut x2) = (b - g * (b - a), a + g * (b - a));
    let (mut f1, mut f2) = (cost(x1), cost(x2));
    for _ in 0..60 {
        if f1 < f2 {
            b = x2;
            x2 = x1;
            f2 = f1;
            x1 = b - g * (b - a);
            f1 = cost(x1);
        } else {
            a = x1;
            x1 = x2;
            f1 = f2;
            x2 = a + g * (b - a);
            f2 = cost(x2);
        }
    }
    let v0 = libm::exp(0.5 * (a + b));
    let (x, sse) = fit_linear(samples, v0, sm)?;
    let n = samples.len() as f64;
    let ss: f64 = samples.iter().map(|s| s.force_n * s.force_n).sum();
    Some(BinghamFit {
        f_ca_n: x[0],
        f_cb_n_per_a: x[1],
        c_a_ns_per_m: x[2],
        c_b_ns_per_m_a: x[3],
        v0_mps: v0,
        smoothing: sm,
        rms_error_n: libm::sqrt(sse / n),
        rms_force_n: libm::sqrt(ss / n),
    })
}

/// Collects the reference grid and fits it (convenience for tests and the simulator).
/// `buf` must hold at least `REFERENCE_GRID.sample_count()` samples.
pub fn fit_reference(buf: &mut [FitSample], sm: Smoothing) -> Option<BinghamFit> {
    let n = collect_samples(&SpencerParams::steering(), &REFERENCE_GRID, buf);
    fit(buf.get(..n)?, sm)
}
