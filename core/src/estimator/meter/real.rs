//! The float type the estimator state is kept in: `f32` on the target (hardware FPU),
//! `f64` as the reference twin (the long-run test runs both on the same input).
//!
//! All transcendental functions go through `libm` explicitly so host and target compute the
//! same bits (f32 sine, cosine and tangent through [`crate::trig`]: computed in f32, within 2
//! ulps of the exact value, where libm's compute in f64).

use core::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

/// Minimal real-number abstraction for the estimator (implemented for `f32` and `f64`).
pub trait Real:
    Copy
    + Default
    + PartialOrd
    + core::fmt::Debug
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
{
    /// 0
    const ZERO: Self;
    /// 1
    const ONE: Self;
    /// Conversion from f64 (rounds for f32).
    fn from_f64(x: f64) -> Self;
    /// Conversion from f32 (exact for both types).
    fn from_f32(x: f32) -> Self;
    /// Conversion to f64 (exact for both types).
    fn to_f64(self) -> f64;
    /// Conversion to f32 (rounds for f64).
    fn to_f32(self) -> f32;
    /// Square root (libm).
    fn sqrt(self) -> Self;
    /// Absolute value.
    fn abs(self) -> Self;
    /// Sine (libm; f32: [`crate::trig`]).
    fn sin(self) -> Self;
    /// Cosine (libm; f32: [`crate::trig`]).
    fn cos(self) -> Self;
    /// Natural logarithm (libm).
    fn ln(self) -> Self;
    /// Four-quadrant arctangent of `self / x` (libm).
    fn atan2(self, x: Self) -> Self;
    /// Tangent (libm; f32: [`crate::trig`]).
    fn tan(self) -> Self;
    /// Exponential (libm).
    fn exp(self) -> Self;
    /// Evaluates `f` in this precision and returns the result as f64. Design-time math (filter
    /// coefficients, start values) goes through it so that an f32 estimator, the target's,
    /// links no f64 transcendental function (11.8 KB less flash, `cargo xtask size`); the f64
    /// twin computes in f64 exactly as before.
    #[inline]
    fn eval(x: f64, f: impl FnOnce(Self) -> Self) -> f64 {
        f(Self::from_f64(x)).to_f64()
    }
    /// Neither NaN nor infinite.
    fn is_finite(self) -> bool;
    /// Relative step below which the root finder has converged (64 ulps in f32, ~450 in f64):
    /// the roots then carry no more error than the coefficients' own rounding puts into them.
    const ROOT_TOL: Self;
}

impl Real for f32 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    #[inline]
    fn from_f64(x: f64) -> Self {
        x as f32
    }
    #[inline]
    fn from_f32(x: f32) -> Self {
        x
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self as f64
    }
    #[inline]
    fn to_f32(self) -> f32 {
        self
    }
    #[inline]
    fn sqrt(self) -> Self {
        crate::sqrt::sqrtf(self)
    }
    #[inline]
    fn abs(self) -> Self {
        libm::fabsf(self)
    }
    #[inline]
    fn sin(self) -> Self {
        crate::trig::sinf(self)
    }
    #[inline]
    fn cos(self) -> Self {
        crate::trig::cosf(self)
    }
    #[inline]
    fn ln(self) -> Self {
        libm::logf(self)
    }
    #[inline]
    fn atan2(self, x: Self) -> Self {
        libm::atan2f(self, x)
    }
    #[inline]
    fn is_finite(self) -> bool {
        f32::is_finite(self)
    }
    #[inline]
    fn tan(self) -> Self {
        crate::trig::tanf(self)
    }
    #[inline]
    fn exp(self) -> Self {
        libm::expf(self)
    }
    const ROOT_TOL: Self = 64.0 * f32::EPSILON;
}

impl Real for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    #[inline]
    fn from_f64(x: f64) -> Self {
        x
    }
    #[inline]
    fn from_f32(x: f32) -> Self {
        x as f64
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline]
    fn to_f32(self) -> f32 {
        self as f32
    }
    #[inline]
    fn sqrt(self) -> Self {
        libm::sqrt(self)
    }
    #[inline]
    fn abs(self) -> Self {
        libm::fabs(self)
    }
    #[inline]
    fn sin(self) -> Self {
        libm::sin(self)
    }
    #[inline]
    fn cos(self) -> Self {
        libm::cos(self)
    }
    #[inline]
    fn ln(self) -> Self {
        libm::log(self)
    }
    #[inline]
    fn atan2(self, x: Self) -> Self {
        libm::atan2(self, x)
    }
    #[inline]
    fn is_finite(self) -> bool {
        f64::is_finite(self)
    }
    #[inline]
    fn tan(self) -> Self {
        libm::tan(self)
    }
    #[inline]
    fn exp(self) -> Self {
        libm::exp(self)
    }
    const ROOT_TOL: Self = 1e-13;
}
