//! Bounded eigenvalue solver for the 10x10 state matrix, modes and mode shapes.
//!
//! nalgebra's `eigenvalues()` / `complex_eigenvalues()` iterate without a bound and can hang
//! (nalgebra issues #611, #764, #1528). Here the matrix is checked for NaN/Inf, balanced
//! (Parlett-Reinsch, powers of two, exact similarity) and reduced with
//! `Schur::try_new(m, eps, max_niter)`; a failure to converge is an error, never a hang or a
//! panic. Everything is fixed-size (stack only) and `no_std`.

use nalgebra::{Complex, SMatrix, SVector};

use crate::plant::{
    A_L, A_R, DPHI, DPSI_L, DPSI_R, DTHETA_SW, N_STATES, PHI, PSI_L, PSI_R, THETA_SW,
};

/// State matrix of the linear plant.
pub type StateMatrix = SMatrix<f64, N_STATES, N_STATES>;
/// Eigenvalues of a state matrix, in the solver's order (conjugate pairs adjacent, +Im first).
pub type Eigenvalues = [Complex<f64>; N_STATES];

/// Default bound on the QR iterations (LAPACK allows 30 per eigenvalue).
pub const DEFAULT_MAX_NITER: usize = 30 * N_STATES;

/// Entries above this magnitude are rejected (the balancing norms must not overflow).
const MAX_ABS_ENTRY: f64 = 1e150;

/// Why an eigen-solve failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EigenError {
    /// The matrix holds NaN or +-Inf (or entries too large to balance safely).
    #[error("matrix holds NaN, infinite or too large entries")]
    NonFinite,
    /// `max_niter` was 0 (nalgebra would then iterate without bound).
    #[error("eigen-solve iteration bound is 0")]
    ZeroIterationBound,
    /// The QR iteration did not converge within `max_niter` iterations.
    #[error("QR iteration did not converge within its iteration bound")]
    NotConverged,
    /// The result held NaN/Inf (should not happen for finite input; reported, not trusted).
    #[error("eigen-solve produced a non-finite result")]
    NonFiniteResult,
    /// Inverse iteration for an eigenvector met an exactly singular pivot twice.
    #[error("inverse iteration met a singular pivot twice")]
    Singular,
    /// No eigenvalue matched the request (e.g. no oscillatory mode).
    #[error("no eigenvalue matches the request (e.g. no oscillatory mode)")]
    NoMode,
}

/// Eigenvalues of `a` with the default iteration bound and eps = f64::EPSILON.
pub fn eigenvalues(a: &StateMatrix) -> Result<Eigenvalues, EigenError> {
    eigenvalues_bounded(a, f64::EPSILON, DEFAULT_MAX_NITER)
}

/// Eigenvalues of `a`: finiteness check, balancing, bounded real Schur decomposition.
///
/// Work is bounded: balancing converges in a bounded number of sweeps for finite entries below
/// 1e150 (each accepted rescaling shrinks the row+column norm sum by >= 5 %), and the QR
/// iteration stops after `max_niter` iterations with [`EigenError::NotConverged`].
pub fn eigenvalues_bounded(
    a: &StateMatrix,
    eps: f64,
    max_niter: usize,
) -> Result<Eigenvalues, EigenError> {
    if max_niter == 0 {
        return Err(EigenError::ZeroIterationBound);
    }
    if !(eps.is_finite() && eps > 0.0) {
        return Err(EigenError::NonFinite);
    }
    if a.iter()
        .any(|v| !v.is_finite() || libm::fabs(*v) > MAX_ABS_ENTRY)
    {
        return Err(EigenError::NonFinite);
    }
    balanced_schur_eigenvalues(*a, eps, max_niter)
}

/// Balancing (power-of-two diagonal similarity, exact in any float type) and the bounded real
/// Schur decomposition of `m` in its own float type; eigenvalues widened to f64.
fn balanced_schur_eigenvalues<T: nalgebra::RealField + Copy>(
    mut m: SMatrix<T, N_STATES, N_STATES>,
    eps: T,
    max_niter: usize,
) -> Result<Eigenvalues, EigenError> {
    let _scaling = nalgebra::linalg::balancing::balance_parlett_reinsch(&mut m);
    let schur =
        nalgebra::linalg::Schur::try_new(m, eps, max_niter).ok_or(EigenError::NotConverged)?;
    let vals = schur.complex_eigenvalues();
    let mut out = [Complex::new(0.0, 0.0); N_STATES];
    for (o, v) in out.iter_mut().zip(vals.iter()) {
        let re = nalgebra::try_convert::<T, f64>(v.re).unwrap_or(f64::NAN);
        let im = nalgebra::try_convert::<T, f64>(v.im).unwrap_or(f64::NAN);
        if !(re.is_finite() && im.is_finite()) {
            return Err(EigenError::NonFiniteResult);
        }
        *o = Complex::new(re, im);
    }
    Ok(out)
}

/// Float type of an eigen-solve.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Precision {
    /// f64 throughout (the reference; software floating point on a Cortex-M4F).
    #[default]
    F64,
    /// A is formed in f64, rounded to f32, balanced (exact power-of-two scaling) and solved in
    /// f32 on the FPU: ~20x fewer instructions on the M4. Balancing is what makes this
    /// accurate enough (`docs/margin-estimator.md`: unscaled f32 loses ~0.04 in zeta); the
    /// tracker's critical speeds still meet 0.05 km/h (tests/tests/margin_model.rs).
    F32,
}

/// Largest entry magnitude accepted by the f32 solve (far inside the f32 range, so balancing
/// and the QR sweeps cannot overflow).
const MAX_ABS_ENTRY_F32: f64 = 1e30;

/// Eigenvalues of `a` in the requested precision (default iteration bound, eps = the type's
/// machine epsilon).
pub fn eigenvalues_in(a: &StateMatrix, precision: Precision) -> Result<Eigenvalues, EigenError> {
    match precision {
        Precision::F64 => eigenvalues(a),
        Precision::F32 => eigenvalues_f32(a),
    }
}

fn eigenvalues_f32(a: &StateMatrix) -> Result<Eigenvalues, EigenError> {
    if a.iter()
        .any(|v| !v.is_finite() || libm::fabs(*v) > MAX_ABS_ENTRY_F32)
    {
        return Err(EigenError::NonFinite);
    }
    balanced_schur_eigenvalues(a.map(|v| v as f32), f32::EPSILON, DEFAULT_MAX_NITER)
}

/// Continuous-time mode of one eigenvalue s = re + j im.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mode {
    /// Real part, 1/s (positive = growing).
    pub re: f64,
    /// Imaginary part, rad/s (>= 0 for the representative of a pair).
    pub im: f64,
    /// Damping ratio zeta = -re / |s|.
    pub zeta: f64,
    /// Damped frequency |im| / (2 pi), Hz.
    pub freq_hz: f64,
    /// Natural frequency |s|, rad/s.
    pub omega_n: f64,
}

impl Mode {
    /// The mode of eigenvalue `s`.
    pub fn from_eigenvalue(s: Complex<f64>) -> Self {
        let omega_n = libm::hypot(s.re, s.im);
        let zeta = if omega_n > 0.0 { -s.re / omega_n } else { 1.0 };
        Mode {
            re: s.re,
            im: libm::fabs(s.im),
            zeta,
            freq_hz: libm::fabs(s.im) / (2.0 * core::f64::consts::PI),
            omega_n,
        }
    }

    /// The eigenvalue with non-negative imaginary part.
    pub fn eigenvalue(&self) -> Complex<f64> {
        Complex::new(self.re, self.im)
    }
}

/// An eigenvalue counts as oscillatory when its imaginary part exceeds this fraction of |s|
/// (plus a tiny absolute floor): real eigenvalues from the Schur form have Im exactly 0.
pub const OSCILLATORY_REL_IM: f64 = 1e-7;

/// True when `s` is one of an oscillatory (complex) pair.
pub fn is_oscillatory(s: Complex<f64>) -> bool {
    libm::fabs(s.im) > OSCILLATORY_REL_IM * libm::hypot(s.re, s.im) + 1e-12
}

/// Largest real part over all eigenvalues, 1/s.
pub fn max_real_part(vals: &Eigenvalues) -> f64 {
    vals.iter()
        .fold(f64::NEG_INFINITY, |m, v| if v.re > m { v.re } else { m })
}

/// The oscillatory mode with the largest real part (the one that crosses at a Hopf point).
pub fn critical_oscillatory_mode(vals: &Eigenvalues) -> Result<Mode, EigenError> {
    vals.iter()
        .filter(|v| v.im > 0.0 && is_oscillatory(**v))
        .fold(None::<Complex<f64>>, |best, v| match best {
            Some(b) if b.re >= v.re => Some(b),
            _ => Some(*v),
        })
        .map(Mode::from_eigenvalue)
        .ok_or(EigenError::NoMode)
}

/// The oscillatory mode with the smallest damping ratio.
pub fn least_damped_mode(vals: &Eigenvalues) -> Result<Mode, EigenError> {
    vals.iter()
        .filter(|v| v.im > 0.0 && is_oscillatory(**v))
        .map(|v| Mode::from_eigenvalue(*v))
        .fold(None::<Mode>, |best, m| match best {
            Some(b) if b.zeta <= m.zeta => Some(b),
            _ => Some(m),
        })
        .ok_or(EigenError::NoMode)
}

/// Complex state vector (eigenvector).
pub type CVector = SVector<Complex<f64>, N_STATES>;

/// Right eigenvector of `a` for eigenvalue `lambda` by inverse iteration with a complex LU of
/// (A - mu I), mu = lambda slightly perturbed (so the factor is not exactly singular). Three
/// fixed iterations; normalised to unit 2-norm with the largest entry real and positive.
pub fn eigenvector(a: &StateMatrix, lambda: Complex<f64>) -> Result<CVector, EigenError> {
    eigenvector_in(a, lambda, Precision::F64)
}

/// Left eigenvector w of `a` for `lambda` (w^H A = lambda w^H): conj(w) is a right eigenvector
/// of A^T for the same lambda; same method as [`eigenvector`].
pub fn left_eigenvector(a: &StateMatrix, lambda: Complex<f64>) -> Result<CVector, EigenError> {
    left_eigenvector_in(a, lambda, Precision::F64)
}

/// [`eigenvector`] with the LU and the iteration in the requested precision.
pub fn eigenvector_in(
    a: &StateMatrix,
    lambda: Complex<f64>,
    precision: Precision,
) -> Result<CVector, EigenError> {
    inverse_iteration(a, lambda, false, precision)
}

/// [`left_eigenvector`] with the LU and the iteration in the requested precision.
pub fn left_eigenvector_in(
    a: &StateMatrix,
    lambda: Complex<f64>,
    precision: Precision,
) -> Result<CVector, EigenError> {
    inverse_iteration(a, lambda, true, precision)
}

fn inverse_iteration(
    a: &StateMatrix,
    lambda: Complex<f64>,
    left: bool,
    precision: Precision,
) -> Result<CVector, EigenError> {
    if a.iter().any(|v| !v.is_finite()) || !(lambda.re.is_finite() && lambda.im.is_finite()) {
        return Err(EigenError::NonFinite);
    }
    let scale = a.amax().max(1.0);
    let v = match precision {
        // The shift keeps (A - mu I) from being exactly singular; in f32 it must also survive
        // rounding of A's entries (eps_f32 ~ 1e-7 relative), hence the larger offset there.
        Precision::F64 => {
            let mu = lambda + Complex::new(scale * 1e-11, scale * 1e-11);
            iterate_shifted::<f64>(a, mu, left)?
        }
        Precision::F32 => {
            let mu = lambda + Complex::new(scale * 1e-6, scale * 1e-6);
            iterate_shifted::<f32>(a, mu, left)?
        }
    };
    // Left: conj(w) is a right eigenvector of A^T for the same lambda.
    let mut v = if left { v.map(|c| c.conj()) } else { v };
    // Phase normalisation: largest entry real positive.
    let (imax, _) = v.iter().enumerate().fold((0, -1.0), |(bi, bn), (i, c)| {
        let n = cabs(*c);
        if n > bn {
            (i, n)
        } else {
            (bi, bn)
        }
    });
    let pivot = v[imax];
    let pn = cabs(pivot);
    if pn > 0.0 {
        let rot = pivot.conj() / Complex::new(pn, 0.0);
        v = v.map(|c| c * rot);
    }
    Ok(v)
}

/// Three steps of inverse iteration with (A - mu I) (A^T when `left`) factored in `T`; the
/// result is widened to f64.
fn iterate_shifted<T: nalgebra::RealField + Copy>(
    a: &StateMatrix,
    mu: Complex<f64>,
    left: bool,
) -> Result<CVector, EigenError> {
    let t = |x: f64| nalgebra::convert::<f64, T>(x);
    let mut shifted: SMatrix<Complex<T>, N_STATES, N_STATES> =
        a.map(|v| Complex::new(t(v), T::zero()));
    if left {
        shifted.transpose_mut();
    }
    let mu_t = Complex::new(t(mu.re), t(mu.im));
    for i in 0..N_STATES {
        shifted[(i, i)] -= mu_t;
    }
    let lu = shifted.lu();
    // A fixed start vector with varied entries (not orthogonal to any eigenvector in practice).
    let mut v: SVector<Complex<T>, N_STATES> =
        SVector::from_fn(|i, _| Complex::new(t(1.0 + 0.1 * i as f64), t(0.05 * i as f64)));
    for _ in 0..3 {
        let Some(next) = lu.solve(&v) else {
            return Err(EigenError::Singular);
        };
        let n = next.norm();
        if !(n.is_finite() && n > T::zero()) {
            return Err(EigenError::Singular);
        }
        v = next / Complex::new(n, T::zero());
    }
    Ok(v.map(|c| {
        Complex::new(
            nalgebra::try_convert::<T, f64>(c.re).unwrap_or(f64::NAN),
            nalgebra::try_convert::<T, f64>(c.im).unwrap_or(f64::NAN),
        )
    }))
}

/// |c| via libm (num-complex's `norm` is std-only).
fn cabs(c: Complex<f64>) -> f64 {
    libm::hypot(c.re, c.im)
}

/// Which motion dominates a mode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModeShape {
    /// Both wheels yaw together (|psi_L + psi_R| > |psi_L - psi_R|): the shimmy mode.
    InPhaseWheelYaw,
    /// The wheels yaw against each other (track-rod mode).
    AntiPhaseWheelYaw,
    /// Axle roll (tramp) dominates.
    Tramp,
    /// The steering wheel dominates.
    SteeringWheel,
    /// The lagged slip angles dominate (tyre relaxation mode).
    TyreLag,
}

impl ModeShape {
    /// Short label for tables and CSV.
    pub const fn name(self) -> &'static str {
        match self {
            ModeShape::InPhaseWheelYaw => "in-phase-wheel-yaw",
            ModeShape::AntiPhaseWheelYaw => "anti-phase-wheel-yaw",
            ModeShape::Tramp => "tramp",
            ModeShape::SteeringWheel => "steering-wheel",
            ModeShape::TyreLag => "tyre-lag",
        }
    }
}

/// A mode's shape: the dominant motion and the numbers it was decided on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModeShapeInfo {
    /// Dominant motion.
    pub shape: ModeShape,
    /// Share of the modal kinetic energy in wheel yaw (both wheels).
    pub wheel_energy_frac: f64,
    /// Share of the modal kinetic energy in axle roll.
    pub tramp_energy_frac: f64,
    /// Share of the modal kinetic energy in the steering wheel.
    pub steering_wheel_energy_frac: f64,
    /// |theta_sw| / (i_s max(|psi_L|, |psi_R|)): steering-wheel swing relative to the
    /// kinematic (rigid-link) value.
    pub steering_wheel_ratio: f64,
    /// Phase of psi_R relative to psi_L, rad (0 = in phase, +-pi = anti-phase).
    pub wheel_phase_rad: f64,
    /// max(|a_L|, |a_R|) / max(|psi_L|, |psi_R|, |phi|, |theta_sw|/i_s).
    pub tyre_ratio: f64,
}

/// Classifies the mode with eigenvector `v` (of A) using the modal kinetic energy
/// 0.5 M_jj |dq_j|^2 per degree of freedom (inertias `i_k`, `i_phi`, `j_sw`) and the size of the
/// lagged slip angles relative to the displacements (steering wheel referred through `i_s`).
pub fn classify(v: &CVector, i_k: f64, i_phi: f64, j_sw: f64, i_s: f64) -> ModeShapeInfo {
    let e_wheel = i_k * (v[DPSI_L].norm_sqr() + v[DPSI_R].norm_sqr());
    let e_phi = i_phi * v[DPHI].norm_sqr();
    let e_sw = j_sw * v[DTHETA_SW].norm_sqr();
    let e_tot = e_wheel + e_phi + e_sw;
    let (fw, fp, fs) = if e_tot > 0.0 {
        (e_wheel / e_tot, e_phi / e_tot, e_sw / e_tot)
    } else {
        (0.0, 0.0, 0.0)
    };
    let wheel_amp = cabs(v[PSI_L]).max(cabs(v[PSI_R]));
    let disp = wheel_amp.max(cabs(v[PHI])).max(cabs(v[THETA_SW]) / i_s);
    let tyre = cabs(v[A_L]).max(cabs(v[A_R]));
    let tyre_ratio = if disp > 0.0 {
        tyre / disp
    } else {
        f64::INFINITY
    };
    let steering_wheel_ratio = if wheel_amp > 0.0 {
        cabs(v[THETA_SW]) / (i_s * wheel_amp)
    } else {
        f64::INFINITY
    };
    let rel = v[PSI_R] * v[PSI_L].conj();
    let wheel_phase_rad = libm::atan2(rel.im, rel.re);
    let shape = if tyre_ratio > 3.0 || e_tot == 0.0 {
        ModeShape::TyreLag
    } else if fw >= fp && fw >= fs {
        if cabs(v[PSI_L] + v[PSI_R]) >= cabs(v[PSI_L] - v[PSI_R]) {
            ModeShape::InPhaseWheelYaw
        } else {
            ModeShape::AntiPhaseWheelYaw
        }
    } else if fp >= fs {
        ModeShape::Tramp
    } else {
        ModeShape::SteeringWheel
    };
    ModeShapeInfo {
        shape,
        wheel_energy_frac: fw,
        tramp_energy_frac: fp,
        steering_wheel_energy_frac: fs,
        steering_wheel_ratio,
        wheel_phase_rad,
        tyre_ratio,
    }
}

/// Eigenvector of `lambda` of `a` and its classification, with the plant's inertias.
pub fn mode_shape(
    p: &crate::params::PlantParams,
    a: &StateMatrix,
    lambda: Complex<f64>,
) -> Result<ModeShapeInfo, EigenError> {
    mode_shape_in(p, a, lambda, Precision::F64)
}

/// [`mode_shape`] with the eigenvector computed in the requested precision.
pub fn mode_shape_in(
    p: &crate::params::PlantParams,
    a: &StateMatrix,
    lambda: Complex<f64>,
    precision: Precision,
) -> Result<ModeShapeInfo, EigenError> {
    let v = eigenvector_in(a, lambda, precision)?;
    Ok(classify(&v, p.i_k, p.i_phi, p.j_sw, p.i_s))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::ParamSet;
    use crate::plant::linearise;

    #[test]
    fn nan_and_inf_are_errors_not_hangs() {
        let mut a = linearise(&ParamSet::Nominal.params(), 20.0, 0.0);
        a[(3, 7)] = f64::NAN;
        assert_eq!(eigenvalues(&a), Err(EigenError::NonFinite));
        a[(3, 7)] = f64::INFINITY;
        assert_eq!(eigenvalues(&a), Err(EigenError::NonFinite));
        a[(3, 7)] = 1e200;
        assert_eq!(eigenvalues(&a), Err(EigenError::NonFinite));
    }

    #[test]
    fn too_few_iterations_is_an_error() {
        let a = linearise(&ParamSet::Nominal.params(), 20.0, 0.0);
        assert_eq!(
            eigenvalues_bounded(&a, f64::EPSILON, 0),
            Err(EigenError::ZeroIterationBound)
        );
        assert_eq!(
            eigenvalues_bounded(&a, f64::EPSILON, 2),
            Err(EigenError::NotConverged)
        );
        assert!(eigenvalues(&a).is_ok());
    }

    #[test]
    fn eigenpairs_satisfy_the_definition() {
        let p = ParamSet::Nominal.params();
        for v_mps in [1.0, 10.0, 25.0, 40.0] {
            let a = linearise(&p, v_mps, 0.0);
            let vals = eigenvalues(&a).unwrap();
            let ac = a.map(|x| Complex::new(x, 0.0));
            for l in vals {
                let v = eigenvector(&a, l).unwrap();
                let r = (ac * v - v * l).norm();
                assert!(r < 1e-8 * a.amax(), "V={v_mps} lambda={l} residual {r}");
                let w = left_eigenvector(&a, l).unwrap();
                let rl = (w.adjoint() * ac - w.adjoint() * l).norm();
                assert!(rl < 1e-8 * a.amax(), "left residual {rl}");
            }
            // Trace is the sum of eigenvalues (independent of the solver's internals).
            let sum: Complex<f64> = vals.iter().sum();
            assert!((sum.re - a.trace()).abs() < 1e-9 * a.amax());
            assert!(sum.im.abs() < 1e-9 * a.amax());
        }
    }

    #[test]
    fn mode_from_eigenvalue() {
        let m = Mode::from_eigenvalue(Complex::new(-1.0, 2.0 * core::f64::consts::PI * 5.0));
        assert!((m.freq_hz - 5.0).abs() < 1e-12);
        assert!((m.zeta - 1.0 / m.omega_n).abs() < 1e-15);
    }
}
