//! The data-driven mode meter: the damping ratio of the shimmy mode, estimated from the measured
//! wheel yaw alone (details and accuracy: `docs/margin-estimator.md`).
//!
//! Signal path, in the order the data flows (one module each):
//!
//! 1. input ([`mode_meter::Sample`]): in-phase wheel yaw y = (psi_L + psi_R) / 2 at the input
//!    rate (1 kHz); NaN/Inf samples are replaced by the last good one and counted;
//! 2. [`decimate`]: 8th-order inverse-Chebyshev anti-alias filter (flat to 20 Hz, >= 60 dB from
//!    80 Hz) and decimation by 10 to 100 Hz;
//! 3. [`rls`]: two RLS instances, fast (lambda_fast, for warnings) and slow (lambda_slow, for
//!    the margin), on the ARX model
//!    `y[k] = sum_i a_i y[k-i] + b_c cos(theta_k) + b_s sin(theta_k) + c + d u[k-1] + e[k]`
//!    where theta is the wheel-order phase (imbalance forcing at f_w = V / (2 pi R)), c an offset
//!    (steering angle) and u the damper command (optional);
//! 4. [`roots`]: roots of `z^p - a_1 z^(p-1) - ... - a_p`, each with the forgetting bias of
//!    its RLS undone ([`roots::ForgettingBias`]), s = ln(z) f_s, zeta = -Re(s)/|s|; the
//!    least-damped pair in the shimmy band, tracked for continuity, with sigma_zeta from the
//!    fit's own covariance (innovation variance x P / (1 + lambda)) carried to zeta by the
//!    root sensitivity ([`roots::zeta_sigma`]);
//! 5. [`mode_meter`]: the meter itself ([`mode_meter::MarginEstimator`]) runs steps 1-4 and the
//!    safeguards: freeze on low band energy (RMS of the 1 Hz high-passed decimated yaw below
//!    `min_excitation_rms_rad`), covariance reset after a long freeze / on `regime_change()` /
//!    on divergence, bounded trace of P, symmetric P, NaN guards. Its output
//!    ([`mode_meter::MeterOutput`], 100 Hz) goes to the fusion ([`super::fusion`]).
//!
//! The state is generic over [`real::Real`] (`f32` on the target, `f64` as the reference twin).
//!
//! Known limitation (tested, see `tests/estimator_accuracy.rs`): an AR(4-8) model cannot
//! represent two in-band modes with comparable shares of the yaw variance; the lighter-damped
//! one is then biased high (infinite-data Yule-Walker AR(6): 0.03 -> 0.13 for 8 Hz + 15 Hz at
//! equal gain). One dominant mode (the shimmy mode) plus weakly observed others is fine.

pub mod decimate;
pub mod mode_meter;
pub mod real;
pub mod rls;
pub mod roots;
