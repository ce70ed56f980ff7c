//! The mode meter itself: its configuration, the 1 kHz input [`Sample`], the damping estimates
//! it reports, and [`MarginEstimator`], which runs the signal path of [`super`] (decimation,
//! two RLS instances, roots, mode selection, safeguards) on every pushed sample.

use super::decimate::Decimator;
use super::real::Real;
use super::rls::{Rls, N_MAX};
use super::roots::{aberth, select_mode, zeta_sigma, Cx, ForgettingBias, MAX_ORDER};

/// Configuration of the mode meter. `Default` is the tested design point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EstimatorConfig {
    /// Input (control-loop) sample rate, Hz.
    pub input_rate_hz: f32,
    /// Decimation factor (1 disables filter and decimation: only for the negative test).
    pub decimation: u16,
    /// Anti-alias stop-band edge, Hz (default: output rate - band_hi = 80 Hz, so nothing folds
    /// into the shimmy band unattenuated).
    pub aa_stop_hz: f32,
    /// Anti-alias stop-band attenuation, dB.
    pub aa_atten_db: f32,
    /// AR order p of the slow (margin) instance, 2..=10 (10 is the tested default: on the
    /// vehicle the in-phase yaw carries the tramp, steering-wheel and tyre-lag dynamics next
    /// to the shimmy mode, and a lower order reads a well-damped shimmy pole high: AR(8) by
    /// +0.7 to +2.3 b at 105-120 km/h, `shimmy-sim meter-accuracy --slow-ar-order 8`).
    pub ar_order: u8,
    /// AR order of the fast (warning) instance, 2..=10 (6: its 4 s memory estimates fewer
    /// coefficients with less scatter).
    pub ar_order_fast: u8,
    /// Include cos/sin wheel-order regressors.
    pub wheel_order_regressors: bool,
    /// Include a constant (offset) regressor.
    pub bias_regressor: bool,
    /// Include the previous decimated damper command as exogenous input.
    pub damper_input_regressor: bool,
    /// Forgetting factor of the fast (warning) RLS at the decimated rate.
    pub lambda_fast: f32,
    /// Forgetting factor of the slow (margin) RLS at the decimated rate.
    pub lambda_slow: f32,
    /// Undo the finite-memory (forgetting) bias of each RLS on its AR roots
    /// ([`ForgettingBias`]); `false` only for the negative test.
    pub forgetting_bias_correction: bool,
    /// Initial covariance P0 = p0 I (regressors are O(1) after scaling).
    pub p0: f32,
    /// Bound on tr(P) (`None` disables the safeguard: negative tests only).
    pub trace_max: Option<f32>,
    /// Yaw scale: the estimator works on y / signal_scale_rad so its regressors are O(1).
    pub signal_scale_rad: f32,
    /// Freeze the RLS updates on low band energy (`false` only for negative tests).
    pub freeze_enabled: bool,
    /// Freeze when the band RMS of the yaw is below this, rad.
    pub min_excitation_rms_rad: f32,
    /// Time constant of the band-energy average, s.
    pub excitation_tau_s: f32,
    /// After a freeze longer than this the covariances are reset on resumption, s.
    pub freeze_reset_s: f32,
    /// High-pass cut-off used for the band energy and the amplitude detector, Hz.
    pub highpass_hz: f32,
    /// Time constant of the amplitude (envelope) detector, s.
    pub amplitude_tau_s: f32,
    /// Shimmy band (damped frequency), Hz.
    pub band_lo_hz: f32,
    /// Shimmy band upper edge, Hz.
    pub band_hi_hz: f32,
    /// Prefer a pair within this distance of the last reported frequency, Hz.
    pub track_tol_hz: f32,
    /// ... if its damping is within this of the least-damped pair.
    pub track_zeta_tol: f32,
    /// Warm-up after a reset, in time constants 1/(1-lambda) of each RLS.
    pub warmup_time_constants: f32,
    /// Root-finder iteration bound (sweeps).
    pub root_max_iter: u32,
    /// Solve one instance's AR polynomial per decimated step, the fast and the slow one in
    /// turn (each at half the decimated rate): a meter run then holds one root solve, not two.
    /// Both RLS instances still update on every step; only the read-out of their roots is
    /// spread. `false` roots both on every step.
    pub interleave_roots: bool,
    /// Consecutive rejected input samples that force a covariance reset.
    pub max_rejected_run: u16,
}

impl Default for EstimatorConfig {
    fn default() -> Self {
        Self {
            input_rate_hz: 1000.0,
            decimation: 10,
            aa_stop_hz: 80.0,
            aa_atten_db: 60.0,
            ar_order: 10,
            ar_order_fast: 6,
            wheel_order_regressors: true,
            bias_regressor: true,
            damper_input_regressor: false,
            lambda_fast: 0.995,
            lambda_slow: 0.998,
            forgetting_bias_correction: true,
            p0: 100.0,
            trace_max: Some(1.0e5),
            signal_scale_rad: 1.0e-3,
            freeze_enabled: true,
            min_excitation_rms_rad: 5.0e-5,
            excitation_tau_s: 0.3,
            freeze_reset_s: 5.0,
            highpass_hz: 1.0,
            amplitude_tau_s: 0.3,
            band_lo_hz: 3.0,
            band_hi_hz: 20.0,
            track_tol_hz: 1.0,
            track_zeta_tol: 0.02,
            warmup_time_constants: 1.0,
            root_max_iter: 60,
            interleave_roots: true,
            max_rejected_run: 20,
        }
    }
}

impl EstimatorConfig {
    /// The same meter for a mode `k` times slower (lower in frequency) than the one it was
    /// tuned for: every frequency (anti-alias edge, band, high-pass, tracking tolerance) divided
    /// by `k`, every time constant multiplied by `k`, and the decimation multiplied by `k`, so
    /// the decimated rate falls by `k` and the forgetting factors (per decimated step) keep the
    /// same number of mode cycles in memory. `k = 1` is `self`; a model states its `k` as
    /// [`crate::model::LinearModel::meter_time_scale`].
    pub fn time_scaled(self, k: u16) -> Self {
        let kf = f32::from(k.max(1));
        Self {
            decimation: self.decimation.saturating_mul(k.max(1)),
            aa_stop_hz: self.aa_stop_hz / kf,
            excitation_tau_s: self.excitation_tau_s * kf,
            freeze_reset_s: self.freeze_reset_s * kf,
            highpass_hz: self.highpass_hz / kf,
            amplitude_tau_s: self.amplitude_tau_s * kf,
            band_lo_hz: self.band_lo_hz / kf,
            band_hi_hz: self.band_hi_hz / kf,
            track_tol_hz: self.track_tol_hz / kf,
            ..self
        }
    }
}

/// Invalid configuration.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigError {
    /// ar_order or ar_order_fast outside 2..=10.
    #[error("estimator ar_order or ar_order_fast outside 2..=10")]
    ArOrder,
    /// A forgetting factor outside (0, 1).
    #[error("estimator forgetting factor outside (0, 1)")]
    Lambda,
    /// Decimation 0 or anti-alias cut-off not below the input Nyquist.
    #[error("estimator decimation is 0 or the anti-alias cut-off is not below the input Nyquist frequency")]
    Decimation,
    /// A non-positive scale, rate, or time constant, or an empty band.
    #[error("estimator scale, rate or time constant not positive, or empty band")]
    Range,
}

/// The wheel-order (imbalance) reference for the current 1 kHz sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum WheelOrder {
    /// No reference (regressors are zero).
    None,
    /// Wheel rotation angle measured by the caller (e.g. from a wheel-speed encoder), rad.
    Phase {
        /// Angle, any range (only its sine and cosine are used).
        phase_rad: f32,
    },
    /// The estimator integrates the phase from speed and rolling radius: dtheta/dt = V / R.
    Speed {
        /// Vehicle speed, m/s.
        speed_mps: f32,
        /// Rolling radius, m.
        radius_m: f32,
    },
}

/// One control-loop (1 kHz) input sample.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Left wheel yaw about its kingpin, rad.
    pub psi_l_rad: f32,
    /// Right wheel yaw, rad.
    pub psi_r_rad: f32,
    /// Wheel-order reference.
    pub wheel: WheelOrder,
    /// Damper command (any consistent unit, e.g. coil current in A); used only when
    /// `damper_input_regressor` is set.
    pub damper_cmd: f32,
}

/// Why an estimate is (in)valid.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum EstimateStatus {
    /// No estimate yet.
    #[default]
    NotStarted,
    /// Fewer updates since the last reset than the warm-up.
    WarmingUp,
    /// Updates frozen (low excitation): the last estimate is held.
    Frozen,
    /// No pole pair inside the shimmy band.
    NoModeInBand,
    /// The root finder did not converge (value held).
    RootFailure,
    /// Valid.
    Ok,
}

/// A damping estimate of one RLS instance. Never NaN: invalid estimates hold the last value.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct ModeEstimate {
    /// Damping ratio of the tracked shimmy-band mode.
    pub zeta: f32,
    /// One-sigma uncertainty of `zeta`: the fit's coefficient covariance carried to the root
    /// (see module docs).
    pub sigma_zeta: f32,
    /// Damped frequency, Hz.
    pub freq_hz: f32,
    /// Natural frequency, Hz.
    pub wn_hz: f32,
    /// `status == Ok`.
    pub valid: bool,
    /// Detail.
    pub status: EstimateStatus,
}

/// What a decimated (100 Hz) step produced.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct MeterOutput {
    /// Fast (warning) estimate.
    pub fast: ModeEstimate,
    /// Slow (margin) estimate.
    pub slow: ModeEstimate,
    /// Envelope amplitude of the in-phase yaw in the band, rad (peak).
    pub amplitude_rad: f32,
    /// Band RMS used for the excitation check, rad.
    pub excitation_rms_rad: f32,
    /// Updates were frozen on this step.
    pub frozen: bool,
}

/// Counters for diagnostics/telemetry.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct MeterCounters {
    /// Non-finite input samples replaced by the last good one.
    pub rejected_samples: u32,
    /// RLS updates refused (non-finite regressors, bad denominator, divergence).
    pub rls_rejects: u32,
    /// Root-finder failures.
    pub root_failures: u32,
    /// Covariance resets (regime change, long freeze, divergence, long reject runs).
    pub resets: u32,
    /// Decimated steps with frozen updates.
    pub frozen_steps: u32,
}

/// Exponentially weighted mean square of an RLS instance's a-priori innovations, with the
/// instance's own forgetting factor (normalised, so it is unbiased from the first sample on).
#[derive(Clone, Copy, Debug)]
struct InnovationVariance<T> {
    lambda: T,
    sum: T,
    weight: T,
}

impl<T: Real> InnovationVariance<T> {
    fn new(lambda: f64) -> Self {
        Self {
            lambda: T::from_f64(lambda),
            sum: T::ZERO,
            weight: T::ZERO,
        }
    }

    fn push(&mut self, e: T) {
        let sum = self.lambda * self.sum + e * e;
        if sum.is_finite() {
            self.sum = sum;
            self.weight = self.lambda * self.weight + T::ONE;
        }
    }

    fn variance(&self) -> T {
        if self.weight > T::ZERO {
            self.sum / self.weight
        } else {
            T::ZERO
        }
    }
}

#[derive(Clone, Copy, Debug)]
struct Track<T> {
    roots: [Cx<T>; MAX_ORDER],
    roots_ok: bool,
    last_freq_hz: Option<T>,
    est: ModeEstimate,
    innovation: InnovationVariance<T>,
    bias: ForgettingBias<T>,
    warmup_updates: u32,
}

/// `ceil(x)` as a count (0 for negative and NaN, saturating above u32::MAX), as
/// `libm::ceil(x) as u32` gives it without linking an f64 `ceil` into the target (0.2 KB).
fn ceil_count(x: f64) -> u32 {
    let floor = x as u32;
    floor.saturating_add(u32::from((floor as f64) < x))
}

impl<T: Real> Track<T> {
    fn new(lambda: f64, warmup_tc: f64) -> Self {
        let tc = 1.0 / (1.0 - lambda);
        Self {
            roots: [Cx::default(); MAX_ORDER],
            roots_ok: false,
            last_freq_hz: None,
            est: ModeEstimate::default(),
            innovation: InnovationVariance::new(lambda),
            bias: ForgettingBias::new(lambda),
            warmup_updates: ceil_count(warmup_tc * tc),
        }
    }
}

/// The mode meter. Feed it every control-loop sample with [`MarginEstimator::push`].
#[derive(Clone, Debug)]
pub struct MarginEstimator<T> {
    cfg: EstimatorConfig,
    fs_dec_hz: f64,
    n_reg: usize,
    /// Extra (non-AR) regressors, at the front of the regressor.
    extra: usize,
    /// Lags kept: the larger of the two orders.
    p: usize,
    p_fast: usize,
    p_slow: usize,
    dec_y: Decimator<T>,
    dec_u: Decimator<T>,
    inv_scale: T,
    last_y: T,
    last_u: T,
    rejected_run: u16,
    phase: T,
    last_phase: T,
    hist: [T; MAX_ORDER],
    hist_len: usize,
    u_prev: T,
    fast: Rls<T>,
    slow: Rls<T>,
    tr_fast: Track<T>,
    tr_slow: Track<T>,
    hp_prev_in: T,
    hp_state: T,
    hp_alpha: T,
    exc_ms: T,
    exc_beta: T,
    amp_ms: T,
    amp_beta: T,
    frozen_steps_run: u32,
    freeze_reset_steps: u32,
    pending_reset: bool,
    step_count: u32,
    counters: MeterCounters,
    out: MeterOutput,
}

impl<T: Real> MarginEstimator<T> {
    /// Builds the estimator (all filter coefficients computed here).
    pub fn new(cfg: EstimatorConfig) -> Result<Self, ConfigError> {
        let (p_slow, p_fast) = (cfg.ar_order as usize, cfg.ar_order_fast as usize);
        if !((2..=MAX_ORDER).contains(&p_slow) && (2..=MAX_ORDER).contains(&p_fast)) {
            return Err(ConfigError::ArOrder);
        }
        let p = p_slow.max(p_fast);
        let lam_ok = |l: f32| l > 0.0 && l < 1.0;
        if !(lam_ok(cfg.lambda_fast) && lam_ok(cfg.lambda_slow)) {
            return Err(ConfigError::Lambda);
        }
        let pos = |v: f32| v > 0.0 && v.is_finite();
        if !(pos(cfg.input_rate_hz)
            && pos(cfg.signal_scale_rad)
            && pos(cfg.excitation_tau_s)
            && pos(cfg.amplitude_tau_s)
            && pos(cfg.highpass_hz)
            && pos(cfg.p0)
            && cfg.band_hi_hz > cfg.band_lo_hz
            && cfg.band_lo_hz >= 0.0)
        {
            return Err(ConfigError::Range);
        }
        let fs_in = cfg.input_rate_hz as f64;
        let dec_y = Decimator::new(
            fs_in,
            cfg.decimation,
            cfg.aa_stop_hz as f64,
            cfg.aa_atten_db as f64,
        )
        .ok_or(ConfigError::Decimation)?;
        let dec_u = dec_y;
        let fs_dec = fs_in / cfg.decimation as f64;
        if cfg.band_hi_hz as f64 >= 0.5 * fs_dec {
            return Err(ConfigError::Range);
        }
        let extra = if cfg.wheel_order_regressors { 2 } else { 0 }
            + usize::from(cfg.bias_regressor)
            + usize::from(cfg.damper_input_regressor);
        let n_reg = extra + p_slow;
        let tmax = cfg.trace_max.map(T::from_f32);
        let p0 = T::from_f32(cfg.p0);
        let dt = 1.0 / fs_dec;
        let hp_alpha = 1.0 / (1.0 + 2.0 * core::f64::consts::PI * cfg.highpass_hz as f64 * dt);
        Ok(Self {
            fs_dec_hz: fs_dec,
            n_reg,
            extra,
            p,
            p_fast,
            p_slow,
            dec_y,
            dec_u,
            inv_scale: T::from_f64(1.0 / cfg.signal_scale_rad as f64),
            last_y: T::ZERO,
            last_u: T::ZERO,
            rejected_run: 0,
            phase: T::ZERO,
            last_phase: T::ZERO,
            hist: [T::ZERO; MAX_ORDER],
            hist_len: 0,
            u_prev: T::ZERO,
            fast: Rls::new(p_fast + extra, T::from_f32(cfg.lambda_fast), p0, tmax),
            slow: Rls::new(n_reg, T::from_f32(cfg.lambda_slow), p0, tmax),
            tr_fast: Track::new(cfg.lambda_fast as f64, cfg.warmup_time_constants as f64),
            tr_slow: Track::new(cfg.lambda_slow as f64, cfg.warmup_time_constants as f64),
            hp_prev_in: T::ZERO,
            hp_state: T::ZERO,
            hp_alpha: T::from_f64(hp_alpha),
            exc_ms: T::ZERO,
            exc_beta: T::from_f64(1.0 - T::eval(-dt / cfg.excitation_tau_s as f64, T::exp)),
            amp_ms: T::ZERO,
            amp_beta: T::from_f64(1.0 - T::eval(-dt / cfg.amplitude_tau_s as f64, T::exp)),
            frozen_steps_run: 0,
            freeze_reset_steps: ceil_count(cfg.freeze_reset_s as f64 * fs_dec),
            pending_reset: false,
            step_count: 0,
            counters: MeterCounters::default(),
            out: MeterOutput::default(),
            cfg,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &EstimatorConfig {
        &self.cfg
    }

    /// Decimated (estimator) sample rate, Hz.
    pub fn decimated_rate_hz(&self) -> f64 {
        self.fs_dec_hz
    }

    /// Regressor dimension of the slow instance's ARX model.
    pub fn regressor_dim(&self) -> usize {
        self.n_reg
    }

    /// Latest output (also returned by `push` on decimated steps).
    pub fn output(&self) -> &MeterOutput {
        &self.out
    }

    /// Diagnostic counters.
    pub fn counters(&self) -> &MeterCounters {
        &self.counters
    }

    /// The fast RLS (for inspection and tests).
    pub fn fast_rls(&self) -> &Rls<T> {
        &self.fast
    }

    /// The slow RLS.
    pub fn slow_rls(&self) -> &Rls<T> {
        &self.slow
    }

    /// Signals a regime change (damper mode switch, sensor recovery, load change...): both
    /// covariances are reset to P0 (parameters kept) and the estimates re-enter warm-up.
    pub fn regime_change(&mut self) {
        self.fast.reset_covariance();
        self.slow.reset_covariance();
        self.counters.resets = self.counters.resets.saturating_add(1);
        self.pending_reset = false;
    }

    /// Feeds one control-loop sample. Returns the new output on decimated steps (every
    /// `decimation` samples), `None` otherwise. Constant work per call, never blocks.
    pub fn push(&mut self, s: &Sample) -> Option<MeterOutput> {
        // 1. input validation (hold last good value)
        let y_raw = 0.5 * (s.psi_l_rad + s.psi_r_rad);
        let y_in = if y_raw.is_finite() {
            self.rejected_run = 0;
            let v = T::from_f32(y_raw) * self.inv_scale;
            self.last_y = v;
            v
        } else {
            self.counters.rejected_samples = self.counters.rejected_samples.saturating_add(1);
            self.rejected_run = self.rejected_run.saturating_add(1);
            if self.rejected_run == self.cfg.max_rejected_run {
                self.pending_reset = true;
            }
            self.last_y
        };
        let u_in = if s.damper_cmd.is_finite() {
            self.last_u = T::from_f32(s.damper_cmd);
            self.last_u
        } else {
            self.last_u
        };
        // 2. wheel-order phase
        match s.wheel {
            WheelOrder::None => {}
            WheelOrder::Phase { phase_rad } => {
                if phase_rad.is_finite() {
                    self.phase = T::from_f32(phase_rad);
                }
            }
            WheelOrder::Speed {
                speed_mps,
                radius_m,
            } => {
                let w = speed_mps / radius_m;
                if w.is_finite() {
                    self.phase += T::from_f32(w / self.cfg.input_rate_hz);
                    let two_pi = T::from_f64(2.0 * core::f64::consts::PI);
                    let pi = T::from_f64(core::f64::consts::PI);
                    // bounded wrap into [-pi, pi)
                    for _ in 0..4 {
                        if self.phase >= pi {
                            self.phase -= two_pi;
                        } else if self.phase < -pi {
                            self.phase += two_pi;
                        }
                    }
                    if !self.phase.is_finite() || self.phase.abs() > pi {
                        self.phase = T::ZERO;
                    }
                }
            }
        }
        let wheel_active = !matches!(s.wheel, WheelOrder::None);
        // 3. decimation
        let u_dec = if self.cfg.damper_input_regressor {
            self.dec_u.push(u_in)
        } else {
            None
        };
        let y = self.dec_y.push(y_in)?;
        let u = u_dec.unwrap_or(T::ZERO);
        self.decimated_step(y, u, wheel_active);
        Some(self.out)
    }

    fn decimated_step(&mut self, y: T, u: T, wheel_active: bool) {
        self.step_count = self.step_count.wrapping_add(1);
        // band energy and amplitude: first-order high-pass then exponential mean square
        let hp = self.hp_alpha * (self.hp_state + y - self.hp_prev_in);
        self.hp_prev_in = y;
        self.hp_state = hp;
        self.exc_ms += self.exc_beta * (hp * hp - self.exc_ms);
        self.amp_ms += self.amp_beta * (hp * hp - self.amp_ms);
        if !(self.exc_ms.is_finite() && self.amp_ms.is_finite()) {
            self.exc_ms = T::ZERO;
            self.amp_ms = T::ZERO;
            self.hp_state = T::ZERO;
        }
        let scale = self.cfg.signal_scale_rad;
        let exc_rms = self.exc_ms.sqrt().to_f32() * scale;
        self.out.excitation_rms_rad = exc_rms;
        self.out.amplitude_rad = (T::from_f64(2.0) * self.amp_ms).sqrt().to_f32() * scale;

        // `min` lets the optimiser drop the bounds checks (panic-free check).
        let p = self.p.min(MAX_ORDER);
        let (p_fast, p_slow) = (self.p_fast.min(p), self.p_slow.min(p));
        if self.hist_len >= p {
            let phi = self.regressor(p, wheel_active);
            let frozen = self.cfg.freeze_enabled && exc_rms < self.cfg.min_excitation_rms_rad;
            self.out.frozen = frozen;
            if frozen {
                self.counters.frozen_steps = self.counters.frozen_steps.saturating_add(1);
                self.frozen_steps_run = self.frozen_steps_run.saturating_add(1);
                if self.frozen_steps_run >= self.freeze_reset_steps {
                    self.pending_reset = true;
                }
            } else {
                self.frozen_steps_run = 0;
                if self.pending_reset {
                    self.regime_change();
                }
                for (rls, tr) in [
                    (&mut self.fast, &mut self.tr_fast),
                    (&mut self.slow, &mut self.tr_slow),
                ] {
                    match rls.update(&phi, y) {
                        Ok(e) => tr.innovation.push(e),
                        Err(_) => {
                            self.counters.rls_rejects = self.counters.rls_rejects.saturating_add(1)
                        }
                    }
                    if self.cfg.wheel_order_regressors && !wheel_active {
                        rls.hold_direction(0);
                        rls.hold_direction(1);
                    }
                }
            }
            // interleaved: fast roots on odd steps, slow roots on even ones
            let odd = !self.step_count.is_multiple_of(2);
            if odd || !self.cfg.interleave_roots {
                Self::extract(
                    &self.cfg,
                    self.fs_dec_hz,
                    (self.extra, p_fast),
                    &self.fast,
                    &mut self.tr_fast,
                    frozen,
                    &mut self.counters,
                );
            }
            if !odd || !self.cfg.interleave_roots {
                Self::extract(
                    &self.cfg,
                    self.fs_dec_hz,
                    (self.extra, p_slow),
                    &self.slow,
                    &mut self.tr_slow,
                    frozen,
                    &mut self.counters,
                );
            }
            self.out.fast = self.tr_fast.est;
            self.out.slow = self.tr_slow.est;
        }
        // shift history (y in at index 0; no indexing, so no bounds check: panic-free check)
        let mut carry = y;
        for h in self.hist.iter_mut().take(p) {
            core::mem::swap(h, &mut carry);
        }
        self.hist_len = (self.hist_len + 1).min(p);
        self.u_prev = u;
        self.last_phase = self.phase;
    }

    /// The ARX regressor, extras first so both instances share it: the enabled extras (cos/sin
    /// of the wheel-order phase, the offset, the damper command; `self.extra` entries), then
    /// y[k-1..k-p] for the larger order p. An instance of order q uses the first extra + q.
    fn regressor(&self, p: usize, wheel_active: bool) -> [T; N_MAX] {
        let mut phi = [T::ZERO; N_MAX];
        let mut k = 0;
        if self.cfg.wheel_order_regressors {
            if wheel_active {
                phi[0] = self.phase.cos();
                phi[1] = self.phase.sin();
            }
            k = 2;
        }
        if self.cfg.bias_regressor {
            phi[k] = T::ONE;
            k += 1;
        }
        if self.cfg.damper_input_regressor {
            phi[k] = self.u_prev;
            k += 1;
        }
        for (slot, h) in phi.iter_mut().skip(k).zip(self.hist.iter().take(p)) {
            *slot = *h;
        }
        phi
    }

    /// Roots and mode of one instance; `(extra, p)`: its AR coefficients are theta[extra..extra + p].
    fn extract(
        cfg: &EstimatorConfig,
        fs: f64,
        (extra, p): (usize, usize),
        rls: &Rls<T>,
        tr: &mut Track<T>,
        frozen: bool,
        counters: &mut MeterCounters,
    ) {
        let mut c = [T::ZERO; MAX_ORDER];
        for (ci, th) in c.iter_mut().zip(rls.theta().iter().skip(extra)).take(p) {
            *ci = -*th;
        }
        let coeffs = c.get(..p).unwrap_or(&[]);
        let status = match aberth(coeffs, &mut tr.roots, tr.roots_ok, cfg.root_max_iter) {
            Err(_) => {
                tr.roots_ok = false;
                counters.root_failures = counters.root_failures.saturating_add(1);
                EstimateStatus::RootFailure
            }
            Ok(_) => {
                tr.roots_ok = true;
                // corrected copy: the raw roots stay the warm start of the next solve
                let mut roots = tr.roots;
                if cfg.forgetting_bias_correction {
                    for z in roots.iter_mut() {
                        *z = tr.bias.correct(*z);
                    }
                }
                match select_mode(
                    roots.get(..p).unwrap_or(&[]),
                    T::from_f64(fs),
                    T::from_f32(cfg.band_lo_hz),
                    T::from_f32(cfg.band_hi_hz),
                    tr.last_freq_hz,
                    T::from_f32(cfg.track_tol_hz),
                    T::from_f32(cfg.track_zeta_tol),
                ) {
                    None => EstimateStatus::NoModeInBand,
                    Some(m) => {
                        tr.last_freq_hz = Some(m.freq_hz);
                        // the raw root: its sensitivity is that of the fitted polynomial
                        let raw = tr.roots.get(m.root_index).copied().unwrap_or_default();
                        let a = rls.theta().get(extra..extra + p).unwrap_or(&[]);
                        let cov_scale = tr.innovation.variance() / (T::ONE + rls.lambda());
                        let sigma =
                            zeta_sigma(a, raw, fs, |i, j| rls.p(extra + i, extra + j) * cov_scale)
                                .map_or(f32::NAN, Real::to_f32);
                        tr.est.zeta = m.zeta.to_f32();
                        tr.est.freq_hz = m.freq_hz.to_f32();
                        tr.est.wn_hz = m.wn_hz.to_f32();
                        tr.est.sigma_zeta = sigma;
                        if rls.updates() < tr.warmup_updates {
                            EstimateStatus::WarmingUp
                        } else if frozen {
                            EstimateStatus::Frozen
                        } else {
                            EstimateStatus::Ok
                        }
                    }
                }
            }
        };
        tr.est.status = status;
        tr.est.valid = status == EstimateStatus::Ok
            && tr.est.zeta.is_finite()
            && tr.est.sigma_zeta.is_finite();
        if !(tr.est.zeta.is_finite()
            && tr.est.sigma_zeta.is_finite()
            && tr.est.freq_hz.is_finite()
            && tr.est.wn_hz.is_finite())
        {
            tr.est = ModeEstimate::default();
            tr.est.status = EstimateStatus::RootFailure;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ceil_count_is_libms_ceil_as_a_count() {
        let xs = [
            -3.5,
            -0.0,
            0.0,
            1e-300,
            0.5,
            1.0,
            1.0 + f64::EPSILON,
            2.5,
            99.999_999,
            1e6,
            4_294_967_295.0,
            4_294_967_295.5,
            1e12,
            f64::NAN,
            f64::INFINITY,
        ];
        for x in xs {
            assert_eq!(ceil_count(x), libm::ceil(x) as u32, "{x}");
        }
    }

    #[test]
    fn config_is_validated_and_state_is_small() {
        let ok = EstimatorConfig::default();
        assert!(MarginEstimator::<f32>::new(ok).is_ok());
        for k in [1, 2, 10] {
            let scaled = ok.time_scaled(k);
            assert!(MarginEstimator::<f32>::new(scaled).is_ok(), "k = {k}");
            assert_eq!(u32::from(scaled.decimation), 10 * u32::from(k));
            assert!((scaled.band_lo_hz * f32::from(k) - ok.band_lo_hz).abs() < 1e-5);
            assert!((scaled.amplitude_tau_s / f32::from(k) - ok.amplitude_tau_s).abs() < 1e-6);
        }
        assert_eq!(ok.time_scaled(1), ok);
        let bad = |c: EstimatorConfig| MarginEstimator::<f32>::new(c).err();
        assert_eq!(
            bad(EstimatorConfig { ar_order: 1, ..ok }),
            Some(ConfigError::ArOrder)
        );
        assert_eq!(
            bad(EstimatorConfig { ar_order: 11, ..ok }),
            Some(ConfigError::ArOrder)
        );
        assert_eq!(
            bad(EstimatorConfig {
                lambda_fast: 1.0,
                ..ok
            }),
            Some(ConfigError::Lambda)
        );
        assert_eq!(
            bad(EstimatorConfig {
                decimation: 0,
                ..ok
            }),
            Some(ConfigError::Decimation)
        );
        assert_eq!(
            bad(EstimatorConfig {
                band_hi_hz: 60.0,
                ..ok
            }),
            Some(ConfigError::Range)
        );
        assert_eq!(
            bad(EstimatorConfig {
                signal_scale_rad: f32::NAN,
                ..ok
            }),
            Some(ConfigError::Range)
        );
        // RAM budget on the target (128 KiB SRAM): the whole f32 mode meter
        let bytes = core::mem::size_of::<MarginEstimator<f32>>();
        assert!(bytes < 4096, "MarginEstimator<f32> is {bytes} bytes");
    }

    /// With `interleave_roots` each instance's estimate is refreshed on every other decimated
    /// step and never both on the same one (the CPU bound of one root solve per meter run);
    /// without it both change on (nearly) every step.
    #[test]
    fn interleaved_roots_refresh_each_instance_every_other_step() {
        // a 6 Hz resonance (zeta 0.03) at 1 kHz driven by a deterministic pseudo-random input
        let (dt, w, zeta) = (1e-3_f64, 2.0 * core::f64::consts::PI * 6.0, 0.03);
        let r = libm::exp(-zeta * w * dt);
        let (a1, a2) = (2.0 * r * libm::cos(w * dt), -r * r);
        let changes = |interleave: bool| {
            let cfg = EstimatorConfig {
                interleave_roots: interleave,
                ..EstimatorConfig::default()
            };
            let mut m = MarginEstimator::<f32>::new(cfg).unwrap();
            let (mut y1, mut y2, mut seed) = (0.0_f64, 0.0_f64, 12345_u32);
            let (mut fast, mut slow, mut both, mut steps) = (0, 0, 0, 0);
            let mut last: Option<MeterOutput> = None;
            for k in 0..20_000 {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                let e = (f64::from(seed >> 8) / f64::from(1u32 << 24) - 0.5) * 1e-4;
                let y = a1 * y1 + a2 * y2 + e;
                (y2, y1) = (y1, y);
                let s = Sample {
                    psi_l_rad: y as f32,
                    psi_r_rad: y as f32,
                    wheel: WheelOrder::None,
                    damper_cmd: 0.0,
                };
                if let Some(o) = m.push(&s) {
                    if let (Some(p), true) = (last, k >= 10_000) {
                        let f = o.fast.zeta != p.fast.zeta;
                        let sl = o.slow.zeta != p.slow.zeta;
                        fast += usize::from(f);
                        slow += usize::from(sl);
                        both += usize::from(f && sl);
                        steps += 1;
                    }
                    last = Some(o);
                }
            }
            (fast, slow, both, steps)
        };
        let (fast, slow, both, steps) = changes(true);
        assert_eq!(both, 0, "both refreshed on one step");
        assert!(fast <= steps / 2 + 1 && slow <= steps / 2 + 1);
        assert!(
            fast >= steps / 2 - 1 && slow >= steps / 2 - 1,
            "{fast} {slow} of {steps}"
        );
        let (fast, slow, both, steps) = changes(false);
        assert!(
            both >= steps * 9 / 10,
            "{both} of {steps} without interleaving"
        );
        assert!(fast >= steps * 9 / 10 && slow >= steps * 9 / 10);
    }
}
