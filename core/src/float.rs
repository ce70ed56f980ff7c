//! The float type the numeric kernels compute in (eigen-solves, eigenvectors, mode shapes):
//! f32 on the target's FPU, f64 on the host, a type parameter chosen at compile time. Below
//! the model family and the eigen solver, which both use it.

use nalgebra::{Complex, SVector};

/// Float type of the eigen-solves, eigenvectors and mode shapes, chosen at compile time (a type
/// parameter, not a run-time setting), so an image links only the precision it uses: the
/// firmware solves in f32 on the FPU and carries no f64 Schur or LU code; the host and the
/// simulator use f64.
///
/// f32: A is formed in f64, rounded to f32, balanced (exact power-of-two scaling) and solved in
/// f32: ~20x fewer instructions on the M4 than soft-float f64. Balancing is what makes this
/// accurate enough (`docs/margin-estimator.md`: unscaled f32 loses ~0.04 in zeta); the
/// tracker's critical speeds still meet 0.05 km/h (tests/tests/cross_crate/margin_model.rs).
pub trait SolveFloat: nalgebra::RealField + Copy + crate::sqrt::Sqrt + sealed::Sealed {
    /// Name for reports ("f32", "f64").
    const NAME: &'static str;
    /// Machine epsilon: the QR deflation threshold.
    const EPS: Self;
    /// Largest entry magnitude accepted (far inside the type's range, so balancing norms and
    /// the QR sweeps cannot overflow).
    const MAX_ABS_ENTRY: f64;
    /// Shift of inverse iteration off the eigenvalue, relative to max |a_ij|: keeps
    /// (A - mu I) from being exactly singular, also after rounding A's entries to this type.
    const SHIFT_REL: f64;
    /// Newton on an eigenpair has converged when the eigenvalue's correction is below this
    /// times |lambda| + 1 (each iteration's residual in this type).
    const NEWTON_TOL: f64;
    /// Rounds an f64 to this type.
    fn of_f64(x: f64) -> Self;
    /// Widens to f64 (exact).
    fn to_f64(self) -> f64;
}

mod sealed {
    pub trait Sealed {}
    impl Sealed for f32 {}
    impl Sealed for f64 {}
}

impl SolveFloat for f64 {
    const NAME: &'static str = "f64";
    const EPS: f64 = f64::EPSILON;
    const MAX_ABS_ENTRY: f64 = 1e150;
    const SHIFT_REL: f64 = 1e-11;
    const NEWTON_TOL: f64 = 1e-10;
    fn of_f64(x: f64) -> Self {
        x
    }
    fn to_f64(self) -> f64 {
        self
    }
}

impl SolveFloat for f32 {
    const NAME: &'static str = "f32";
    const EPS: f32 = f32::EPSILON;
    const MAX_ABS_ENTRY: f64 = 1e30;
    // eps_f32 ~ 1e-7 relative: the shift must survive the rounding of A's entries.
    const SHIFT_REL: f64 = 1e-6;
    const NEWTON_TOL: f64 = 1e-5;
    fn of_f64(x: f64) -> Self {
        x as f32
    }
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
}

/// A complex vector (an eigenvector) in the precision `T`, as the solver keeps it.
pub type VectorIn<T, const N: usize> = [Complex<T>; N];

/// A vector in `T` widened to f64 (exact; the model family's `ComplexVector`).
pub fn widened<T: SolveFloat, const N: usize>(x: &VectorIn<T, N>) -> SVector<Complex<f64>, N> {
    SVector::<Complex<f64>, N>::from_fn(|i, _| Complex::new(x[i].re.to_f64(), x[i].im.to_f64()))
}

/// A complex number in `T` widened to f64 (exact).
pub fn widened_complex<T: SolveFloat>(z: Complex<T>) -> Complex<f64> {
    Complex::new(z.re.to_f64(), z.im.to_f64())
}

/// An f64 vector rounded to `T` (a start vector for the solvers in `T`).
pub fn narrowed<T: SolveFloat, const N: usize>(x: &SVector<Complex<f64>, N>) -> VectorIn<T, N> {
    core::array::from_fn(|i| Complex::new(T::of_f64(x[i].re), T::of_f64(x[i].im)))
}

/// A complex f64 rounded to `T`.
pub fn narrowed_complex<T: SolveFloat>(z: Complex<f64>) -> Complex<T> {
    Complex::new(T::of_f64(z.re), T::of_f64(z.im))
}
