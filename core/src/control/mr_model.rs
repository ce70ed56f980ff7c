//! The firmware's invertible MR damper model and its inverse (f32, control path).
//!
//! Bingham model with a smooth sign:
//!
//! F(I, v) = (f_ca + f_cb I) S(v / v0) + (c_a + c_b I) v,   S(x) = x / sqrt(1 + x^2)
//!
//! F is positive when it resists a positive stroke rate v (the sign convention of
//! [`crate::mr_damper`]). The constants [`MrModel::FITTED`] are a least-squares fit to the
//! simulator's Spencer model ([`super::mr_fit`], reference grid 0-2 A, 1-8 mm, 4-14 Hz); a test
//! refits and checks them.
//!
//! Why S(x) = x / sqrt(1 + x^2) and not tanh: both have slope 1 at 0 and limits +-1, and a
//! fit with either shape has practically the same force error against the Spencer model (the
//! test `algebraic_smoothing_fits_as_well_as_tanh` fits both and compares), but tanh costs a
//! software expf (~1-2 k instructions on the M4F) while x / sqrt(1 + x^2) costs one hardware
//! VSQRT and one VDIV. It is the exact model the firmware uses, not an approximation of tanh.
//!
//! The inverse ([`MrModel::inverse`]) turns a desired force and the measured stroke rate into a
//! coil current: it applies the **semi-active clip** first (a damper can only resist motion: if
//! F_des v <= 0 the minimum current is commanded), then solves the model (linear in I) and
//! clips the current to [0, I_max]. Non-finite inputs give 0 A (the clip takes NaN as "cannot").

// NaN must take the "no" branch of these comparisons, hence `!(x > 0.0)` style.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

/// Parameters of the invertible model. Units in the names.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MrModel {
    /// Yield force at 0 A, N.
    pub f_ca_n: f32,
    /// Yield force per ampere, N/A.
    pub f_cb_n_per_a: f32,
    /// Viscous coefficient at 0 A, N s/m.
    pub c_a_ns_per_m: f32,
    /// Viscous coefficient per ampere [N s/(m A)].
    pub c_b_ns_per_m_a: f32,
    /// Smoothing velocity, m/s.
    pub v0_mps: f32,
    /// Largest coil current, A.
    pub i_max_a: f32,
}

/// Result of the inverse model.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct InverseResult {
    /// Coil current in A, within [0, I_max].
    pub current_a: f32,
    /// The semi-active constraint removed the request (F_des v <= 0 or invalid input).
    pub clipped: bool,
    /// The request needed more than I_max.
    pub saturated: bool,
    /// The request was below what the damper gives at 0 A.
    pub at_minimum: bool,
}

/// Stroke rates beyond this are treated as this (keeps the arithmetic finite), m/s.
pub const V_LIMIT_MPS: f32 = 10.0;

/// Clamp that maps NaN to `lo`.
#[inline]
pub(crate) fn clamp_nan_lo(x: f32, lo: f32, hi: f32) -> f32 {
    if x >= lo {
        if x > hi {
            hi
        } else {
            x
        }
    } else {
        lo
    }
}

impl MrModel {
    /// Fitted to `SpencerParams::steering()` by `mr_fit::fit_reference(.., Smoothing::Algebraic)`;
    /// the test `fitted_constants_match_a_fresh_fit` keeps them in step.
    pub const FITTED: MrModel = MrModel {
        f_ca_n: 14.98,
        f_cb_n_per_a: 46.42,
        c_a_ns_per_m: 186.7,
        c_b_ns_per_m_a: 430.0,
        v0_mps: 0.03143,
        // The damper's rated coil input (1 V per A in the Spencer model).
        i_max_a: crate::mr_damper::SpencerParams::automotive().u_max as f32,
    };

    /// S(v / v0) = x / sqrt(1 + x^2).
    #[inline]
    fn smooth(&self, v_mps: f32) -> f32 {
        let x = v_mps / self.v0_mps;
        x / crate::sqrt::sqrtf(1.0 + x * x)
    }

    /// Model force in N at coil current `current_a` and stroke rate `v_mps`.
    #[inline]
    pub fn force_n(&self, current_a: f32, v_mps: f32) -> f32 {
        let v = clamp_nan_lo(v_mps, -V_LIMIT_MPS, V_LIMIT_MPS);
        (self.f_ca_n + self.f_cb_n_per_a * current_a) * self.smooth(v)
            + (self.c_a_ns_per_m + self.c_b_ns_per_m_a * current_a) * v
    }

    /// Coil current for desired force `force_n` at stroke rate `v_mps`, with the semi-active clip.
    #[inline]
    pub fn inverse(&self, force_n: f32, v_mps: f32) -> InverseResult {
        // Semi-active clip. `!(x > 0)` is also true for NaN.
        if !(force_n * v_mps > 0.0) {
            return InverseResult {
                current_a: 0.0,
                clipped: true,
                saturated: false,
                at_minimum: true,
            };
        }
        let v = clamp_nan_lo(v_mps, -V_LIMIT_MPS, V_LIMIT_MPS);
        let f_abs = libm::fabsf(force_n);
        let s_abs = libm::fabsf(self.smooth(v));
        let v_abs = libm::fabsf(v);
        // |F| = (f_ca + f_cb I) |S| + (c_a + c_b I) |v|  ->  I = (|F| - F(0)) / dF/dI
        let f0 = self.f_ca_n * s_abs + self.c_a_ns_per_m * v_abs;
        let df_di = self.f_cb_n_per_a * s_abs + self.c_b_ns_per_m_a * v_abs;
        if !(df_di > 1e-6) {
            // Stroke rate ~0: no current gives force now; prepare for the motion with full
            // current (not a saturation: the request is not beyond the damper).
            return InverseResult {
                current_a: self.i_max_a,
                clipped: false,
                saturated: false,
                at_minimum: false,
            };
        }
        let raw = (f_abs - f0) / df_di;
        let current = clamp_nan_lo(raw, 0.0, self.i_max_a);
        InverseResult {
            current_a: current,
            clipped: false,
            saturated: raw >= self.i_max_a,
            at_minimum: !(raw > 0.0),
        }
    }
}
