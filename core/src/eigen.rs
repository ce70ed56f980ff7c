//! Bounded eigenvalue solver for the N x N state matrix of any model of the family
//! ([`crate::model`]), modes and mode shapes (the car's: 10 x 10).
//!
//! nalgebra's `eigenvalues()` / `complex_eigenvalues()` iterate without a bound and can hang
//! (nalgebra issues #611, #764, #1528). Here the matrix is checked for NaN/Inf, balanced
//! (Parlett-Reinsch, powers of two, exact similarity) and solved by the eigenvalue-only
//! Hessenberg QR iteration of `hessenberg_qr` with a bound on its sweeps; a failure to converge
//! is an error, never a hang or a panic. Everything is fixed-size (stack only) and `no_std`.

use nalgebra::Complex;

mod hessenberg_qr;

pub use crate::float::{narrowed, widened, widened_complex, SolveFloat, VectorIn};
use crate::model::LinearModel;
pub use crate::model::{ComplexVector, Matrix, ModeShape, ModeShapeInfo};
use crate::vehicles::car::N_STATES;

/// State matrix of the car's linear plant.
pub type StateMatrix = Matrix<N_STATES>;
/// Eigenvalues of an N x N state matrix, in the solver's order (conjugate pairs adjacent, +Im
/// first).
pub type EigenvaluesOf<const N: usize> = [Complex<f64>; N];
/// Eigenvalues of the car's state matrix.
pub type Eigenvalues = EigenvaluesOf<N_STATES>;

/// Default bound on the QR iterations of an N x N solve (LAPACK allows 30 per eigenvalue).
pub const fn default_max_niter(n: usize) -> usize {
    30 * n
}
/// Default bound on the QR iterations of the car's solve.
pub const DEFAULT_MAX_NITER: usize = default_max_niter(N_STATES);

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

/// Eigenvalues of `a` in f64 with the default iteration bound and eps = f64::EPSILON.
pub fn eigenvalues<const N: usize>(a: &Matrix<N>) -> Result<EigenvaluesOf<N>, EigenError> {
    eigenvalues_of::<f64, N>(a)
}

/// Eigenvalues of `a` solved in `T` (default iteration bound, eps = the type's machine
/// epsilon), widened to f64.
pub fn eigenvalues_of<T: SolveFloat, const N: usize>(
    a: &Matrix<N>,
) -> Result<EigenvaluesOf<N>, EigenError> {
    eigenvalues_bounded::<T, N>(a, T::EPS, default_max_niter(N))
}

/// Eigenvalues of `a` in `T`: finiteness check, balancing, bounded Hessenberg QR iteration.
///
/// Work is bounded: balancing converges in a bounded number of sweeps for finite entries below
/// `T::MAX_ABS_ENTRY` (each accepted rescaling shrinks the row+column norm sum by >= 5 %), and
/// the QR iteration stops after `max_niter` iterations with [`EigenError::NotConverged`].
pub fn eigenvalues_bounded<T: SolveFloat, const N: usize>(
    a: &Matrix<N>,
    eps: T,
    max_niter: usize,
) -> Result<EigenvaluesOf<N>, EigenError> {
    if max_niter == 0 {
        return Err(EigenError::ZeroIterationBound);
    }
    if !(eps.to_f64().is_finite() && eps > T::zero()) {
        return Err(EigenError::NonFinite);
    }
    let amax = abs_max(a);
    if amax.is_nan() || amax > T::MAX_ABS_ENTRY {
        return Err(EigenError::NonFinite);
    }
    let mut m = core::array::from_fn(|i| core::array::from_fn(|j| T::of_f64(a[(i, j)])));
    balance(&mut m);
    let vals =
        hessenberg_qr::eigenvalues::<T, N>(m, eps, max_niter).ok_or(EigenError::NotConverged)?;
    let mut out = [Complex::new(0.0, 0.0); N];
    for (o, v) in out.iter_mut().zip(vals.iter()) {
        let (re, im) = (v.re.to_f64(), v.im.to_f64());
        if !(re.is_finite() && im.is_finite()) {
            return Err(EigenError::NonFiniteResult);
        }
        *o = Complex::new(re, im);
    }
    Ok(out)
}

/// Balances `m` in place: the modified Parlett-Reinsch iteration with 2-norms and radix 2 of
/// nalgebra's `balance_parlett_reinsch` (<https://arxiv.org/pdf/1401.5766.pdf>), a diagonal
/// similarity by powers of two, so exact in any float type. Written out here, with the same
/// decisions and so the same balanced matrix (a unit test against nalgebra's), because
/// nalgebra's takes its square roots through num-traits, i.e. libm's software `sqrtf` (0.5 KB
/// of the target's flash) where the M4F has `VSQRT` ([`crate::sqrt`]).
fn balance<T: SolveFloat, const N: usize>(m: &mut [[T; N]; N]) {
    let two = T::one() + T::one();
    let threshold = T::of_f64(0.95);
    let mut converged = false;
    while !converged {
        converged = true;
        for i in 0..N {
            let col2 = m.iter().fold(T::zero(), |s, row| s + row[i] * row[i]);
            let row2 = m[i].iter().fold(T::zero(), |s, &x| s + x * x);
            let (mut col, mut row) = (col2.sqrt_rounded(), row2.sqrt_rounded());
            if col == T::zero() || row == T::zero() {
                continue;
            }
            let mut f = T::one();
            while col < row / two {
                (col, row, f) = (col * two, row / two, f * two);
            }
            while col >= row * two {
                (col, row, f) = (col / two, row * two, f / two);
            }
            if col * col + row * row < threshold * (col2 + row2) {
                converged = false;
                m.iter_mut().for_each(|r| r[i] *= f);
                m[i].iter_mut().for_each(|x| *x /= f);
            }
        }
    }
}

/// max |a_ij|, or NaN/inf when an entry is: the integer maximum of the bit patterns without
/// the sign, which order like the magnitudes (NaN above inf above every finite value). One
/// pass of integer compares, not 100 soft-float ones on the M4.
fn abs_max<const N: usize>(a: &Matrix<N>) -> f64 {
    let bits = a.iter().map(|v| v.to_bits() & !(1u64 << 63)).max();
    f64::from_bits(bits.unwrap_or(0))
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
        // sqrt of the squares, not hypot: eigenvalues are far from overflow (the solvers reject
        // entries above 1e150) and hypot is ~4 k soft-float instructions on the M4
        let omega_n = crate::sqrt::sqrt(s.norm_sqr());
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

/// True when `s` is one of an oscillatory (complex) pair: |Im| > `OSCILLATORY_REL_IM` |s| +
/// 1e-12, tested squared (no soft-float `hypot` on the M4).
pub fn is_oscillatory(s: Complex<f64>) -> bool {
    let excess = libm::fabs(s.im) - 1e-12;
    excess > 0.0 && excess * excess > OSCILLATORY_REL_IM * OSCILLATORY_REL_IM * s.norm_sqr()
}

/// Largest real part over all eigenvalues, 1/s.
pub fn max_real_part<const N: usize>(vals: &EigenvaluesOf<N>) -> f64 {
    vals.iter()
        .fold(f64::NEG_INFINITY, |m, v| if v.re > m { v.re } else { m })
}

/// The oscillatory mode with the largest real part (the one that crosses at a Hopf point).
pub fn critical_oscillatory_mode<const N: usize>(
    vals: &EigenvaluesOf<N>,
) -> Result<Mode, EigenError> {
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
pub fn least_damped_mode<const N: usize>(vals: &EigenvaluesOf<N>) -> Result<Mode, EigenError> {
    vals.iter()
        .filter(|v| v.im > 0.0 && is_oscillatory(**v))
        .map(|v| Mode::from_eigenvalue(*v))
        .fold(None::<Mode>, |best, m| match best {
            Some(b) if b.zeta <= m.zeta => Some(b),
            _ => Some(m),
        })
        .ok_or(EigenError::NoMode)
}

/// Complex state vector (eigenvector) of the car.
pub type CVector = ComplexVector<N_STATES>;

/// Right eigenvector of `a` for eigenvalue `lambda` by inverse iteration with a complex LU of
/// (A - mu I), mu = lambda slightly perturbed (so the factor is not exactly singular). Three
/// fixed iterations; normalised to unit 2-norm with the largest entry real and positive.
pub fn eigenvector<const N: usize>(
    a: &Matrix<N>,
    lambda: Complex<f64>,
) -> Result<ComplexVector<N>, EigenError> {
    eigenvector_of::<f64, N>(a, lambda)
}

/// Left eigenvector w of `a` for `lambda` (w^H A = lambda w^H): conj(w) is a right eigenvector
/// of A^T for the same lambda; same method as [`eigenvector`].
pub fn left_eigenvector<const N: usize>(
    a: &Matrix<N>,
    lambda: Complex<f64>,
) -> Result<ComplexVector<N>, EigenError> {
    left_eigenvector_of::<f64, N>(a, lambda)
}

/// [`eigenvector`] with the LU and the iteration in `T`.
pub fn eigenvector_of<T: SolveFloat, const N: usize>(
    a: &Matrix<N>,
    lambda: Complex<f64>,
) -> Result<ComplexVector<N>, EigenError> {
    inverse_iteration::<T, N>(a, lambda, false)
}

/// [`left_eigenvector`] with the LU and the iteration in `T`.
pub fn left_eigenvector_of<T: SolveFloat, const N: usize>(
    a: &Matrix<N>,
    lambda: Complex<f64>,
) -> Result<ComplexVector<N>, EigenError> {
    inverse_iteration::<T, N>(a, lambda, true)
}

/// [`eigenvector_of`] in `T` and in the phase the iteration leaves it (unit 2-norm): a start
/// for [`refine_eigenpair`], whose result does not depend on the start's phase, without the
/// rotation's soft-float f64 on the target.
pub fn eigenvector_in<T: SolveFloat, const N: usize>(
    a: &Matrix<N>,
    lambda: Complex<f64>,
) -> Result<VectorIn<T, N>, EigenError> {
    iterate_shifted::<T, N>(a, shift::<T, N>(a, lambda)?, false)
}

fn inverse_iteration<T: SolveFloat, const N: usize>(
    a: &Matrix<N>,
    lambda: Complex<f64>,
    left: bool,
) -> Result<ComplexVector<N>, EigenError> {
    let v = iterate_shifted::<T, N>(a, shift::<T, N>(a, lambda)?, left)?;
    Ok(phase_normalised(widened(&v)))
}

/// The shift mu of inverse iteration for `lambda`: `T::SHIFT_REL` max|a_ij| off it, so that
/// (A - mu I) is not exactly singular; [`EigenError::NonFinite`] for non-finite input.
fn shift<T: SolveFloat, const N: usize>(
    a: &Matrix<N>,
    lambda: Complex<f64>,
) -> Result<Complex<f64>, EigenError> {
    let amax = abs_max(a);
    if !amax.is_finite() || !(lambda.re.is_finite() && lambda.im.is_finite()) {
        return Err(EigenError::NonFinite);
    }
    let scale = amax.max(1.0);
    Ok(lambda + Complex::new(scale * T::SHIFT_REL, scale * T::SHIFT_REL))
}

/// Right and left eigenvectors of `a` for `lambda` from **one** complex LU of (A - mu I) in
/// `T` (mu as in [`eigenvector`]): two inverse-iteration steps with its factors for the right
/// vector and two with their adjoint (P M = L U, so M^H y = x is U^H, L^H and P^-1) for the
/// left one, which (A - lambda I)^H w = 0 makes a left eigenvector. Two steps, not three: the
/// shift is within ~1e-6 max|a_ij| of lambda, so each step shrinks the other components by
/// that over the eigenvalue gap (< 1e-3). Unit 2-norm, phase as the iteration leaves it (what
/// uses them, the eigenvalue derivative and the mode shape, does not depend on it; rotating
/// them costs ~13 k soft-float instructions each on the M4); half the LUs of
/// [`eigenvector_of`] + [`left_eigenvector_of`].
pub fn eigenvectors_of<T: SolveFloat, const N: usize>(
    a: &Matrix<N>,
    lambda: Complex<f64>,
) -> Result<(ComplexVector<N>, ComplexVector<N>), EigenError> {
    let (v, w) = eigenvectors_in::<T, N>(a, lambda)?;
    Ok((widened(&v), widened(&w)))
}

/// [`eigenvectors_of`] in `T`, as the iteration leaves them (for [`LinearModel::classify_in`]).
pub fn eigenvectors_in<T: SolveFloat, const N: usize>(
    a: &Matrix<N>,
    lambda: Complex<f64>,
) -> Result<(VectorIn<T, N>, VectorIn<T, N>), EigenError> {
    let lu = shifted_lu::<T, N>(a, shift::<T, N>(a, lambda)?)?;
    let t = T::of_f64;
    let start: [Complex<T>; N] =
        core::array::from_fn(|i| Complex::new(t(1.0 + 0.1 * i as f64), t(0.05 * i as f64)));
    let (mut v, mut w) = (start, start);
    for _ in 0..2 {
        v = unit_array(lu.solve(&v))?;
        w = unit_array(lu.solve_adjoint(&w))?;
    }
    Ok((v, w))
}

/// `x / |x|` of an array, or [`EigenError::Singular`] when |x| is 0 or not finite.
fn unit_array<T: SolveFloat, const N: usize>(
    x: [Complex<T>; N],
) -> Result<[Complex<T>; N], EigenError> {
    let n2 = x
        .iter()
        .fold(T::zero(), |acc, c| acc + c.re * c.re + c.im * c.im);
    let n = n2.sqrt_rounded();
    if !(n.to_f64().is_finite() && n > T::zero()) {
        return Err(EigenError::Singular);
    }
    let inv = T::one() / n;
    Ok(x.map(|c| Complex::new(c.re * inv, c.im * inv)))
}

/// A complex LU with partial pivoting on plain arrays (P M = L U, L unit lower, both stored in
/// `m`): with solves for M and for its adjoint M^H from the same factors. Hand-written because
/// nalgebra's generic LU of a complex matrix costs ~2x on the M4 at opt-level "s"
/// (`cargo xtask bench`, eigenvector rows), and it has no adjoint solve without copying L and U.
struct ComplexLu<T, const N: usize> {
    m: [[Complex<T>; N]; N],
    /// Row i of the factors is row `perm[i]` of M.
    perm: [usize; N],
}

impl<T: SolveFloat, const N: usize> ComplexLu<T, N> {
    /// Factors `m`; [`EigenError::Singular`] on a zero (or non-finite) pivot.
    #[inline(never)] // one copy per size, not one per caller (flash)
    fn factor(mut m: [[Complex<T>; N]; N]) -> Result<Self, EigenError> {
        let mut perm: [usize; N] = core::array::from_fn(|i| i);
        let norm1 = |c: Complex<T>| c.re.abs() + c.im.abs();
        for k in 0..N {
            let mut p = k;
            let mut best = norm1(m[k][k]);
            for (i, row) in m.iter().enumerate().skip(k + 1) {
                let n = norm1(row[k]);
                if n > best {
                    best = n;
                    p = i;
                }
            }
            if !(best > T::zero() && best.to_f64().is_finite()) {
                return Err(EigenError::Singular);
            }
            // Entry by entry: `m.swap(k, p)` of whole rows is an overlapping copy that links
            // `memmove` (1.4 KB of flash; `cargo xtask size`).
            if p > k {
                let (upper, lower) = m.split_at_mut(p);
                for (a, b) in upper[k].iter_mut().zip(lower[0].iter_mut()) {
                    core::mem::swap(a, b);
                }
            }
            perm.swap(k, p);
            // 1 / pivot, scaled by its 1-norm so that |pivot|^2 cannot overflow
            let d = m[k][k];
            let (dr, di) = (d.re / best, d.im / best);
            let q = best * (dr * dr + di * di);
            let inv = Complex::new(dr / q, -di / q);
            let pivot_row = m[k];
            for row in m.iter_mut().skip(k + 1) {
                let f = row[k] * inv;
                row[k] = f;
                for (x, u) in row.iter_mut().zip(pivot_row.iter()).skip(k + 1) {
                    *x -= f * *u;
                }
            }
        }
        Ok(Self { m, perm })
    }

    /// x with M x = b.
    #[inline(never)]
    // one copy per size, not one per caller (flash)
    // triangular solves: i and j index the factors and the vector alike
    #[allow(clippy::needless_range_loop)]
    fn solve(&self, b: &[Complex<T>; N]) -> [Complex<T>; N] {
        let mut y: [Complex<T>; N] = core::array::from_fn(|i| b[self.perm[i]]);
        for i in 0..N {
            let mut acc = y[i];
            for j in 0..i {
                acc -= self.m[i][j] * y[j];
            }
            y[i] = acc;
        }
        for i in (0..N).rev() {
            let mut acc = y[i];
            for j in i + 1..N {
                acc -= self.m[i][j] * y[j];
            }
            y[i] = acc / self.m[i][i];
        }
        y
    }

    /// x with M^H x = b: M^H = U^H L^H P, so U^H t = b (forward), L^H z = t (backward), and
    /// x = P^-1 z.
    #[inline(never)]
    // one copy per size, not one per caller (flash)
    // triangular solves: i and j index the factors and the vector alike
    #[allow(clippy::needless_range_loop)]
    fn solve_adjoint(&self, b: &[Complex<T>; N]) -> [Complex<T>; N] {
        let mut t = *b;
        for i in 0..N {
            let mut acc = t[i];
            for j in 0..i {
                acc -= self.m[j][i].conj() * t[j];
            }
            t[i] = acc / self.m[i][i].conj();
        }
        for i in (0..N).rev() {
            let mut acc = t[i];
            for j in i + 1..N {
                acc -= self.m[j][i].conj() * t[j];
            }
            t[i] = acc;
        }
        let mut x = t;
        for (i, z) in t.iter().enumerate() {
            x[self.perm[i]] = *z;
        }
        x
    }
}

/// Rotates `v` so that its largest entry is real and positive. The largest entry by |c|^2 and
/// one square root: `hypot` per entry in soft-float f64 cost ~4 k instructions each on the M4
/// (`cargo xtask bench`, eigenvector rows).
fn phase_normalised<const N: usize>(v: ComplexVector<N>) -> ComplexVector<N> {
    let (imax, _) = v.iter().enumerate().fold((0, -1.0), |(bi, bn), (i, c)| {
        let n = c.norm_sqr();
        if n > bn {
            (i, n)
        } else {
            (bi, bn)
        }
    });
    let pivot = v[imax];
    let pn = libm::sqrt(pivot.norm_sqr());
    if pn > 0.0 {
        let rot = pivot.conj() / Complex::new(pn, 0.0);
        v.map(|c| c * rot)
    } else {
        v
    }
}

/// Three steps of inverse iteration with (A - mu I) factored in `T` (its adjoint when `left`:
/// (A - lambda I)^H w = 0 is the left eigenvector); unit 2-norm, in `T`.
fn iterate_shifted<T: SolveFloat, const N: usize>(
    a: &Matrix<N>,
    mu: Complex<f64>,
    left: bool,
) -> Result<VectorIn<T, N>, EigenError> {
    let lu = shifted_lu::<T, N>(a, mu)?;
    let t = T::of_f64;
    // A fixed start vector with varied entries (not orthogonal to any eigenvector in practice).
    let mut v: [Complex<T>; N] =
        core::array::from_fn(|i| Complex::new(t(1.0 + 0.1 * i as f64), t(0.05 * i as f64)));
    for _ in 0..3 {
        v = unit_array(if left {
            lu.solve_adjoint(&v)
        } else {
            lu.solve(&v)
        })?;
    }
    Ok(v)
}

/// The LU of (A - mu I) in `T`.
#[inline(never)]
fn shifted_lu<T: SolveFloat, const N: usize>(
    a: &Matrix<N>,
    mu: Complex<f64>,
) -> Result<ComplexLu<T, N>, EigenError> {
    let t = T::of_f64;
    let mu_t = Complex::new(t(mu.re), t(mu.im));
    ComplexLu::factor(core::array::from_fn(|i| {
        core::array::from_fn(|j| {
            let x = Complex::new(t(a[(i, j)]), T::zero());
            if i == j {
                x - mu_t
            } else {
                x
            }
        })
    }))
}

/// An (N+1)-vector as N entries and one more: the bordered Newton system of
/// [`refine_eigenpair`] has one row and column more than A, and stable Rust cannot write
/// `[_; N + 1]` for a const generic N. A row of the bordered matrix is an `Ext` of entries, the
/// matrix an `Ext` of rows.
#[derive(Clone, Copy)]
struct Ext<E, const N: usize> {
    head: [E; N],
    tail: E,
}

impl<E: Copy, const N: usize> Ext<E, N> {
    fn from_fn(mut f: impl FnMut(usize) -> E) -> Self {
        Self {
            head: core::array::from_fn(&mut f),
            tail: f(N),
        }
    }

    fn at(&self, i: usize) -> &E {
        match self.head.get(i) {
            Some(e) => e,
            None => &self.tail,
        }
    }

    fn get(&self, i: usize) -> E {
        *self.at(i)
    }

    fn at_mut(&mut self, i: usize) -> &mut E {
        match self.head.get_mut(i) {
            Some(e) => e,
            None => &mut self.tail,
        }
    }

    fn swap(&mut self, i: usize, j: usize) {
        let (a, b) = (self.get(i), self.get(j));
        *self.at_mut(i) = b;
        *self.at_mut(j) = a;
    }
}

impl<E: Copy, const N: usize> Ext<Ext<E, N>, N> {
    /// Swaps rows `i` and `j` entry by entry: [`Ext::swap`] of whole rows compiles to an
    /// overlapping copy that links `memmove` (1.4 KB of flash; `cargo xtask size`).
    fn swap_rows(&mut self, i: usize, j: usize) {
        if i == j {
            return;
        }
        for c in 0..=N {
            let (a, b) = (self.at(i).get(c), self.at(j).get(c));
            *self.at_mut(i).at_mut(c) = b;
            *self.at_mut(j).at_mut(c) = a;
        }
    }
}

/// The complex LU with partial pivoting of the (N+1) x (N+1) bordered matrix: the same
/// operations, in the same order, as [`ComplexLu`] of that size (the car's Newton steps are
/// bit-identical to the former 11 x 11 arrays).
struct BorderedLu<T, const N: usize> {
    m: Ext<Ext<Complex<T>, N>, N>,
    perm: Ext<usize, N>,
}

impl<T: SolveFloat, const N: usize> BorderedLu<T, N> {
    #[inline(never)] // one copy per size, not one per caller (flash)
    fn factor(mut m: Ext<Ext<Complex<T>, N>, N>) -> Result<Self, EigenError> {
        let mut perm = Ext::<usize, N>::from_fn(|i| i);
        let norm1 = |c: Complex<T>| c.re.abs() + c.im.abs();
        for k in 0..=N {
            let mut p = k;
            let mut best = norm1(m.at(k).get(k));
            for i in k + 1..=N {
                let n = norm1(m.at(i).get(k));
                if n > best {
                    best = n;
                    p = i;
                }
            }
            if !(best > T::zero() && best.to_f64().is_finite()) {
                return Err(EigenError::Singular);
            }
            m.swap_rows(k, p);
            perm.swap(k, p);
            // 1 / pivot, scaled by its 1-norm so that |pivot|^2 cannot overflow
            let d = m.at(k).get(k);
            let (dr, di) = (d.re / best, d.im / best);
            let q = best * (dr * dr + di * di);
            let inv = Complex::new(dr / q, -di / q);
            let pivot_row = m.get(k);
            for i in k + 1..=N {
                let row = m.at_mut(i);
                let f = row.get(k) * inv;
                *row.at_mut(k) = f;
                for j in k + 1..=N {
                    *row.at_mut(j) -= f * pivot_row.get(j);
                }
            }
        }
        Ok(Self { m, perm })
    }

    /// x with M x = b.
    #[inline(never)]
    fn solve(&self, b: &Ext<Complex<T>, N>) -> Ext<Complex<T>, N> {
        let mut y = Ext::<Complex<T>, N>::from_fn(|i| b.get(self.perm.get(i)));
        for i in 0..=N {
            let row = self.m.at(i);
            let mut acc = y.get(i);
            for j in 0..i {
                acc -= row.get(j) * y.get(j);
            }
            *y.at_mut(i) = acc;
        }
        for i in (0..=N).rev() {
            let row = self.m.at(i);
            let mut acc = y.get(i);
            for j in i + 1..=N {
                acc -= row.get(j) * y.get(j);
            }
            *y.at_mut(i) = acc / row.get(i);
        }
        y
    }

    /// x with M^H x = b (as [`ComplexLu`]'s adjoint solve).
    #[inline(never)]
    fn solve_adjoint(&self, b: &Ext<Complex<T>, N>) -> Ext<Complex<T>, N> {
        let mut t = *b;
        for i in 0..=N {
            let mut acc = t.get(i);
            for j in 0..i {
                acc -= self.m.at(j).get(i).conj() * t.get(j);
            }
            *t.at_mut(i) = acc / self.m.at(i).get(i).conj();
        }
        for i in (0..=N).rev() {
            let mut acc = t.get(i);
            for j in i + 1..=N {
                acc -= self.m.at(j).get(i).conj() * t.get(j);
            }
            *t.at_mut(i) = acc;
        }
        let mut x = t;
        for i in 0..=N {
            *x.at_mut(self.perm.get(i)) = t.get(i);
        }
        x
    }
}

/// An eigenpair with its left eigenvector, from [`refine_eigenpair`], in the precision `T` the
/// Newton computed it in (f32 on the target: no soft-float f64 to widen, scale or
/// differentiate it); N states (the car's 10 by default).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Eigenpair<T: SolveFloat = f64, const N: usize = N_STATES> {
    /// The eigenvalue.
    pub lambda: Complex<T>,
    /// Right eigenvector (A v = lambda v), scaled so that c^H v = 1 for the start vector c.
    pub right: VectorIn<T, N>,
    /// Left eigenvector (w^H A = lambda w^H), arbitrary scale.
    pub left: VectorIn<T, N>,
    /// Newton iterations used (each one complex LU of the bordered system).
    pub iterations: u8,
}

impl<T: SolveFloat, const N: usize> Eigenpair<T, N> {
    /// The eigenvalue widened to f64 (exact).
    pub fn lambda_f64(&self) -> Complex<f64> {
        widened_complex(self.lambda)
    }

    /// d lambda / dp = w^H (dA/dp) v / (w^H v) for a simple eigenvalue (first-order
    /// perturbation), in `T` with dA/dp's entries rounded to `T`; `None` when w^H v vanishes
    /// (defective or not converged).
    pub fn derivative(&self, da: &Matrix<N>) -> Option<Complex<T>> {
        let zero = Complex::new(T::zero(), T::zero());
        let num = self
            .left
            .iter()
            .zip(real_times(|i, j| T::of_f64(da[(i, j)]), &self.right).iter())
            .fold(zero, |acc, (w, dv)| acc + w.conj() * *dv);
        let den = self
            .left
            .iter()
            .zip(self.right.iter())
            .fold(zero, |acc, (w, v)| acc + w.conj() * *v);
        if den.re == T::zero() && den.im == T::zero() {
            return None;
        }
        let d = num / den;
        (d.re.to_f64().is_finite() && d.im.to_f64().is_finite()).then_some(d)
    }
}

/// Newton's method for the eigenpair of `a` near (`lambda0`, `v0`): solves
/// (A - lambda I) v = 0, c^H v = 1 with c = v0 / |v0|^2, so each iteration is one complex LU of
/// the bordered matrix J = [[A - lambda I, -v], [c^H, 0]] and converges quadratically from a
/// close start (the previous cycle's pair). Everything in `T`: the residual as well, so the
/// firmware's f32 pair is f32-accurate (~3e-7 |lambda|, `newton_continues_an_eigenpair_to_its_precision`;
/// the tracker's critical speeds stay within 0.005 km/h of a dense f64 sweep,
/// `tests/tests/cross_crate/margin_model.rs`) and links no soft-float f64 (the residual in f64
/// was ~1.4 KB of flash, `cargo xtask size`). The left eigenvector comes from the last LU:
/// J^H [w; beta] = [0; 1] gives beta = 0 and (A - lambda I)^H w = 0.
///
/// At most `max_iter` iterations; converged when the eigenvalue correction is below
/// `T::NEWTON_TOL` |lambda| (+ the same absolute; 1e-10 in f64, 1e-5 in f32). Errors:
/// non-finite input, a singular J (lambda not simple or the start orthogonal to its
/// eigenvector), no convergence within the bound.
pub fn refine_eigenpair<T: SolveFloat, const N: usize>(
    a: &Matrix<N>,
    lambda0: Complex<f64>,
    v0: &VectorIn<T, N>,
    max_iter: u8,
) -> Result<Eigenpair<T, N>, EigenError> {
    let amax = abs_max(a);
    let finite = |z: &Complex<T>| z.re.to_f64().is_finite() && z.im.to_f64().is_finite();
    if amax.is_nan()
        || amax > T::MAX_ABS_ENTRY
        || !(lambda0.re.is_finite() && lambda0.im.is_finite())
        || !v0.iter().all(finite)
    {
        return Err(EigenError::NonFinite);
    }
    let zero = Complex::new(T::zero(), T::zero());
    let n0 = v0.iter().fold(T::zero(), |acc, z| acc + z.norm_sqr());
    if !(n0 > T::zero() && n0.to_f64().is_finite()) {
        return Err(EigenError::Singular);
    }
    let t = T::of_f64;
    let c: VectorIn<T, N> = core::array::from_fn(|i| v0[i].unscale(n0));
    let at: [[T; N]; N] = core::array::from_fn(|i| core::array::from_fn(|j| t(a[(i, j)])));
    let (mut lambda, mut v): (Complex<T>, VectorIn<T, N>) =
        (Complex::new(t(lambda0.re), t(lambda0.im)), *v0);
    let tol = t(T::NEWTON_TOL);
    for k in 0..max_iter {
        // residual in T
        let av = real_times(|i, j| at[i][j], &v);
        let r: VectorIn<T, N> = core::array::from_fn(|i| av[i] - v[i] * lambda);
        let rb = c
            .iter()
            .zip(v.iter())
            .fold(zero, |acc, (ci, vi)| acc + ci.conj() * *vi)
            - Complex::new(T::one(), T::zero());
        let lu = BorderedLu::<T, N>::factor(Ext::from_fn(|row| {
            Ext::from_fn(|col| match (row < N, col < N) {
                (true, true) if row == col => Complex::new(at[row][col], T::zero()) - lambda,
                (true, true) => Complex::new(at[row][col], T::zero()),
                (true, false) => -v[row],
                (false, true) => c[col].conj(),
                (false, false) => zero,
            })
        }))?;
        let rhs = Ext::<Complex<T>, N>::from_fn(|row| if row < N { -r[row] } else { -rb });
        let x = lu.solve(&rhs);
        if !x.head.iter().chain(core::iter::once(&x.tail)).all(finite) {
            return Err(EigenError::Singular);
        }
        let dl = x.tail;
        for (vi, xi) in v.iter_mut().zip(x.head.iter()) {
            *vi += *xi;
        }
        lambda += dl;
        if !finite(&lambda) {
            return Err(EigenError::NonFiniteResult);
        }
        let abs = |z: Complex<T>| z.norm_sqr().sqrt_rounded();
        if abs(dl) <= tol * (abs(lambda) + T::one()) {
            // left eigenvector: J^H y = e_n through the factors of P J = L U
            let e = Ext::<Complex<T>, N>::from_fn(|i| {
                if i < N {
                    zero
                } else {
                    Complex::new(T::one(), T::zero())
                }
            });
            let y = lu.solve_adjoint(&e);
            let left: VectorIn<T, N> = core::array::from_fn(|i| y.get(i));
            if !left.iter().all(finite) {
                return Err(EigenError::NonFiniteResult);
            }
            return Ok(Eigenpair {
                lambda,
                right: v,
                left,
                iterations: k + 1,
            });
        }
    }
    Err(EigenError::NotConverged)
}

/// A x for real A (entry (i, j) from `a`) and complex x, skipping A's zeros (A(V) is about
/// half zeros, dA/dV almost all): soft-float f64 on the M4, so the skipped work matters.
fn real_times<T: SolveFloat, const N: usize>(
    a: impl Fn(usize, usize) -> T,
    x: &VectorIn<T, N>,
) -> VectorIn<T, N> {
    core::array::from_fn(|i| {
        let mut y = Complex::new(T::zero(), T::zero());
        for (j, xj) in x.iter().enumerate() {
            let aij = a(i, j);
            if aij != T::zero() {
                y += *xj * aij;
            }
        }
        y
    })
}

/// The car's mode classification ([`crate::vehicles::car::classify`]), kept here for its callers.
pub fn classify(v: &CVector, i_k: f64, i_phi: f64, j_sw: f64, i_s: f64) -> ModeShapeInfo {
    crate::vehicles::car::classify(v, i_k, i_phi, j_sw, i_s)
}

/// Eigenvector of `lambda` of `a` and its classification by the model `m`.
pub fn mode_shape<M: LinearModel<N>, const N: usize>(
    m: &M,
    a: &Matrix<N>,
    lambda: Complex<f64>,
) -> Result<ModeShapeInfo, EigenError> {
    mode_shape_of::<f64, M, N>(m, a, lambda)
}

/// [`mode_shape`] with the eigenvector computed in `T`.
pub fn mode_shape_of<T: SolveFloat, M: LinearModel<N>, const N: usize>(
    m: &M,
    a: &Matrix<N>,
    lambda: Complex<f64>,
) -> Result<ModeShapeInfo, EigenError> {
    // in T, as the iteration leaves the vector (the shape does not depend on its phase)
    Ok(m.classify_in(&eigenvector_in::<T, N>(a, lambda)?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vehicles::car::linearise;
    use crate::vehicles::car::ParamSet;

    #[test]
    fn the_f32_mode_shape_is_the_f64_one() {
        // The firmware classifies its f32 eigenvectors in f32 (`LinearModel::classify_in`);
        // against the f64 vector's classification in f64, on every oscillatory mode of the
        // three parameter sets over 0.5-60 m/s.
        let mut modes = 0;
        for set in ParamSet::ALL {
            let p = set.params();
            for k in 1..=120 {
                let a = linearise(&p, 0.5 * f64::from(k), 0.0);
                for l in eigenvalues(&a).unwrap().iter().filter(|l| l.im > 0.0) {
                    let (wide, narrow) = (
                        mode_shape(&p, &a, *l).unwrap(),
                        mode_shape_of::<f32, _, N_STATES>(&p, &a, *l).unwrap(),
                    );
                    assert_eq!(wide.shape, narrow.shape, "{set:?} at {k}: {l}");
                    let d = (wide.wheel_energy_frac - narrow.wheel_energy_frac).abs();
                    assert!(d < 1e-3, "{set:?} at {k}: wheel energy share off by {d}");
                    modes += 1;
                }
            }
        }
        assert!(modes > 1000, "{modes}");
    }

    /// The own balancing is nalgebra's bit for bit, in f32 and f64: on the three parameter
    /// sets' matrices over 0.5-60 m/s and on random matrices whose entries span 24 decades.
    #[test]
    fn balancing_is_nalgebras() {
        fn both<T: SolveFloat>(a: &Matrix<N_STATES>) -> bool {
            let mut ours = core::array::from_fn(|i| core::array::from_fn(|j| T::of_f64(a[(i, j)])));
            balance::<T, N_STATES>(&mut ours);
            let mut theirs = a.map(T::of_f64);
            nalgebra::linalg::balancing::balance_parlett_reinsch(&mut theirs);
            (0..N_STATES).all(|i| (0..N_STATES).all(|j| ours[i][j] == theirs[(i, j)]))
        }
        let mut cases = 0;
        for set in ParamSet::ALL {
            for k in 1..=120 {
                let a = linearise(&set.params(), 0.5 * f64::from(k), 500.0 * f64::from(k % 3));
                assert!(both::<f32>(&a) && both::<f64>(&a), "{set:?} at {k}");
                cases += 1;
            }
        }
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut changed = 0;
        for _ in 0..2000 {
            let a = Matrix::<N_STATES>::from_fn(|_, _| {
                let (mag, sign, zero) = (next(), next(), next());
                if zero < 0.2 {
                    0.0
                } else {
                    (if sign < 0.5 { -1.0 } else { 1.0 }) * 10f64.powf(24.0 * mag - 12.0)
                }
            });
            assert!(both::<f32>(&a) && both::<f64>(&a), "{a}");
            let mut b = core::array::from_fn(|i| core::array::from_fn(|j| a[(i, j)]));
            balance::<f64, N_STATES>(&mut b);
            changed += usize::from(b.iter().flatten().ne(a.transpose().iter()));
            cases += 1;
        }
        // the random matrices are unbalanced: the comparison is of real work
        assert!(changed > 1900, "{changed}");
        assert_eq!(cases, 360 + 2000);
    }

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
            eigenvalues_bounded::<f64, _>(&a, f64::EPSILON, 0),
            Err(EigenError::ZeroIterationBound)
        );
        assert_eq!(
            eigenvalues_bounded::<f64, _>(&a, f64::EPSILON, 2),
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

    /// The shimmy-band eigenvalue (4-9 Hz, +Im) of the f64 Schur solve nearest `near`.
    fn nearest(vals: &Eigenvalues, near: Complex<f64>) -> Complex<f64> {
        *vals
            .iter()
            .min_by(|a, b| (*a - near).norm().total_cmp(&(*b - near).norm()))
            .unwrap()
    }

    /// Newton from the previous speed's pair lands on the eigenvalue of the Schur solve at the
    /// new speed to its precision's accuracy (f32: ~3e-7 relative, the whole Newton in f32),
    /// with a left eigenvector that satisfies its definition and an eigenvalue derivative that
    /// matches a central difference of Schur eigenvalues.
    #[test]
    fn newton_continues_an_eigenpair_to_its_precision() {
        fn check<T: SolveFloat>() {
            let p = ParamSet::Nominal.params();
            let da = crate::vehicles::car::dlinearise_dv(&p);
            let a0 = linearise(&p, 8.0, 0.0);
            let l0 = least_damped_mode(&eigenvalues(&a0).unwrap())
                .unwrap()
                .eigenvalue();
            let v0 = eigenvector(&a0, l0).unwrap();
            for v_new in [8.05, 8.5, 10.0] {
                let a = linearise(&p, v_new, 0.0);
                let exact = nearest(&eigenvalues(&a).unwrap(), l0);
                let ep = refine_eigenpair::<T, _>(&a, l0, &narrowed(&v0), 6).unwrap();
                let err = (ep.lambda_f64() - exact).norm() / exact.norm();
                // f32: measured 3.3e-7 at 8.05 m/s, a few of its epsilons
                let etol = if T::NAME == "f32" { 1e-6 } else { 1e-11 };
                assert!(err < etol, "{} V={v_new}: rel error {err:e}", T::NAME);
                let ac = a.map(|x| Complex::new(x, 0.0));
                let w = widened(&ep.left);
                let rl = (w.adjoint() * ac - w.adjoint() * ep.lambda_f64()).norm() / w.norm();
                let tol = if T::NAME == "f32" { 1e-4 } else { 1e-9 };
                assert!(rl < tol * a.amax(), "{} left residual {rl:e}", T::NAME);
                let h = 1e-4;
                let lp = nearest(&eigenvalues(&linearise(&p, v_new + h, 0.0)).unwrap(), exact);
                let lm = nearest(&eigenvalues(&linearise(&p, v_new - h, 0.0)).unwrap(), exact);
                let fd = (lp - lm) / (2.0 * h);
                let d = widened_complex(ep.derivative(&da).unwrap());
                let dtol = if T::NAME == "f32" { 1e-4 } else { 1e-6 };
                assert!(
                    (d - fd).norm() < dtol * fd.norm().max(1.0),
                    "{} {d} vs {fd}",
                    T::NAME
                );
            }
        }
        check::<f64>();
        check::<f32>();
    }

    /// One LU for both vectors gives the vectors of the two separate inverse iterations (all
    /// unit-norm: equal up to a phase, |r^H e| = 1).
    #[test]
    fn one_lu_gives_the_right_and_the_left_eigenvector() {
        let p = ParamSet::Nominal.params();
        let along = |x: &CVector, y: &CVector| (x.adjoint() * y)[(0, 0)].norm();
        for v_mps in [3.0, 12.0, 30.0] {
            let a = linearise(&p, v_mps, 0.0);
            for l in eigenvalues(&a).unwrap() {
                let (r, w) = eigenvectors_of::<f64, _>(&a, l).unwrap();
                let e = eigenvector(&a, l).unwrap();
                assert!((along(&r, &e) - 1.0).abs() < 1e-8, "V={v_mps} {l}");
                let e = left_eigenvector(&a, l).unwrap();
                assert!((along(&w, &e) - 1.0).abs() < 1e-8, "V={v_mps} {l}");
            }
        }
    }

    #[test]
    fn newton_reports_no_convergence_and_bad_input() {
        let p = ParamSet::Nominal.params();
        let a = linearise(&p, 20.0, 0.0);
        let l = least_damped_mode(&eigenvalues(&a).unwrap())
            .unwrap()
            .eigenvalue();
        let v = narrowed::<f64, N_STATES>(&eigenvector(&a, l).unwrap());
        // one iteration from a start 5 % off cannot meet the 1e-10 correction bound
        assert_eq!(
            refine_eigenpair::<f64, _>(&a, l * 1.05, &v, 1),
            Err(EigenError::NotConverged)
        );
        assert!(refine_eigenpair::<f64, _>(&a, l * 1.05, &v, 8).is_ok());
        assert_eq!(
            refine_eigenpair::<f64, _>(&a, l, &narrowed(&CVector::zeros()), 8),
            Err(EigenError::Singular)
        );
        let mut bad = a;
        bad[(2, 3)] = f64::NAN;
        assert_eq!(
            refine_eigenpair::<f32, _>(&bad, l, &narrowed(&widened(&v)), 8),
            Err(EigenError::NonFinite)
        );
    }

    /// The bordered LU over `Ext` rows does the square LU's operations in its order: factors
    /// and both solves of an (N+1) x (N+1) bordered matrix equal, bit for bit, those of
    /// [`ComplexLu`] on the same matrix as plain arrays (the former 11 x 11 path of
    /// `refine_eigenpair`), in both precisions; so the car's Newton steps are unchanged.
    #[test]
    fn bordered_lu_is_bit_identical_to_the_square_lu() {
        fn check<T: SolveFloat>() {
            const N: usize = N_STATES;
            let p = ParamSet::Nominal.params();
            let a = linearise(&p, 12.0, 300.0);
            let l = least_damped_mode(&eigenvalues(&a).unwrap())
                .unwrap()
                .eigenvalue();
            let v = eigenvector(&a, l).unwrap();
            let t = T::of_f64;
            let tc = |z: Complex<f64>| Complex::new(t(z.re), t(z.im));
            let entry = |row: usize, col: usize| match (row < N, col < N) {
                (true, true) if row == col => Complex::new(t(a[(row, col)]), T::zero()) - tc(l),
                (true, true) => Complex::new(t(a[(row, col)]), T::zero()),
                (true, false) => -tc(v[row]),
                (false, true) => tc(v[col].conj()),
                (false, false) => Complex::new(T::zero(), T::zero()),
            };
            let square = ComplexLu::<T, { N + 1 }>::factor(core::array::from_fn(|r| {
                core::array::from_fn(|c| entry(r, c))
            }))
            .unwrap();
            let bordered =
                BorderedLu::<T, N>::factor(Ext::from_fn(|r| Ext::from_fn(|c| entry(r, c))))
                    .unwrap();
            let bits = |z: Complex<T>| (z.re.to_f64().to_bits(), z.im.to_f64().to_bits());
            for r in 0..=N {
                assert_eq!(square.perm[r], bordered.perm.get(r));
                for c in 0..=N {
                    assert_eq!(
                        bits(square.m[r][c]),
                        bits(bordered.m.at(r).get(c)),
                        "{r} {c}"
                    );
                }
            }
            let b: [Complex<T>; N + 1] =
                core::array::from_fn(|i| Complex::new(t(1.0 + 0.3 * i as f64), t(-0.2 * i as f64)));
            let eb = Ext::<Complex<T>, N>::from_fn(|i| b[i]);
            let (x, y) = (square.solve(&b), bordered.solve(&eb));
            let (xa, ya) = (square.solve_adjoint(&b), bordered.solve_adjoint(&eb));
            for i in 0..=N {
                assert_eq!(bits(x[i]), bits(y.get(i)), "solve {i}");
                assert_eq!(bits(xa[i]), bits(ya.get(i)), "adjoint solve {i}");
            }
        }
        check::<f64>();
        check::<f32>();
    }

    #[test]
    fn mode_from_eigenvalue() {
        let m = Mode::from_eigenvalue(Complex::new(-1.0, 2.0 * core::f64::consts::PI * 5.0));
        assert!((m.freq_hz - 5.0).abs() < 1e-12);
        assert!((m.zeta - 1.0 / m.omega_n).abs() < 1e-15);
    }
}
