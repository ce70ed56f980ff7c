//! Fusion of the data-driven damping (level) with the model-based slope and critical speed:
//! "data for the level, model for the slope".
//!
//! - speed margin: the model margin dV_model = V_crit,model - V (the model's onset speed above
//!   V, or below it inside its window), corrected by the data (always with
//!   `DataMarginUse::Always`; with `DataMarginUse::WhenModelInconsistent`, the pipeline's, only
//!   when they disagree): the measured damping offset
//!   delta = zeta_hat - zeta_model,window (the model damping averaged with the slow meter's own
//!   forgetting, so a ramp's data lag is not mistaken for a mismatch) shifts the model's onset by
//!   delta / |dzeta/dV|: dV = max(V_crit,model - V + delta / |dzeta/dV|, 0), in both directions;
//! - time to critical speed = dV / (a d) where d = -sign(dzeta/dV) is the direction of
//!   decreasing damping (None when not approaching, |a| below `min_accel_mps2`);
//! - model consistency: |delta| > k sigma_zeta (k = 3) held for
//!   `mismatch_hold_s` (or over `mismatch_hold_speed_mps` of speed change) sets the mismatch flag; it clears after `mismatch_release_s` of agreement.
//!
//! The model-based quantities are plain inputs ([`ModelMargin`]), computed from the plant model
//! by [`super::model_margin`].

use super::meter::mode_meter::ModeEstimate;
use super::model_margin::ModelMargin;

/// Fusion parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FusionParams {
    /// Mismatch threshold in sigmas (3).
    pub mismatch_sigmas: f32,
    /// Agreement threshold in sigmas: the flag clears (and a first check passes) only while
    /// |delta| stays below this many sigmas (<= `mismatch_sigmas`: hysteresis).
    pub agreement_sigmas: f32,
    /// Longest averaging time of the damping offset delta, s (0: no averaging). The offset
    /// is a function of speed, so it is averaged over a speed interval: time constant
    /// min(`offset_tau_max_s`, `offset_speed_window_mps` / |acceleration|).
    pub offset_tau_max_s: f32,
    /// Speed interval the offset is averaged over, m/s.
    pub offset_speed_window_mps: f32,
    /// Mismatch must persist this long to raise the flag, s.
    pub mismatch_hold_s: f32,
    /// ... or over this much speed change, m/s, whichever comes first (0: time only). The
    /// offset is a function of speed: on a ramp each second of holding costs lead in km/h.
    pub mismatch_hold_speed_mps: f32,
    /// Agreement must persist this long to clear the flag, s.
    pub mismatch_release_s: f32,
    /// Slopes smaller than this (|dzeta/dV|) give no data-based margin, 1/(m/s).
    pub min_slope_per_mps: f32,
    /// Accelerations smaller than this give no time-to-critical, m/s^2.
    pub min_accel_mps2: f32,
    /// When the data-based margin zeta_hat / |dzeta/dV| enters the reported minimum.
    pub data_margin: DataMarginUse,
}

/// When the (noisy) data-based speed margin is used.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum DataMarginUse {
    /// Always: the data correct the model margin on every update (no consistency gate).
    #[default]
    Always,
    /// Only when the model has no onset above V or is flagged inconsistent with the data
    /// (the flutterometer idea: data that agree with the model within k sigma confirm the
    /// model's low-noise margin; data that disagree correct it). The correction is the
    /// measured damping offset delta carried to speed by the model slope: the model's onset
    /// moves by delta / |dzeta/dV|, earlier when the plant is less damped than the model, later
    /// when it is more damped. Without an onset above V the margin is
    /// (zeta_model + delta) / |dzeta/dV|. The ambient-data spread of a data margin (~0.5 m/s
    /// at 20 km/h on the nominal plant) would cause false warnings if it were always used.
    WhenModelInconsistent,
}

impl Default for FusionParams {
    fn default() -> Self {
        Self {
            mismatch_sigmas: 3.0,
            agreement_sigmas: 3.0,
            offset_tau_max_s: 0.0,
            offset_speed_window_mps: 2.0,
            mismatch_hold_s: 3.0,
            mismatch_hold_speed_mps: 0.0,
            mismatch_release_s: 3.0,
            min_slope_per_mps: 1.0e-5,
            min_accel_mps2: 0.05,
            data_margin: DataMarginUse::Always,
        }
    }
}

/// Which estimate limits the speed margin.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum MarginSource {
    /// No margin available.
    #[default]
    None,
    /// zeta_hat / |dzeta/dV|.
    Data,
    /// V_crit,model - V.
    Model,
}

/// Inputs of one fusion step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FusionInput<'a> {
    /// Time, s (`f64`: the millisecond stays exact over days of driving).
    pub t_s: f64,
    /// Vehicle speed, m/s.
    pub speed_mps: f32,
    /// Vehicle acceleration, m/s^2.
    pub accel_mps2: f32,
    /// Fast (warning) data estimate.
    pub fast: &'a ModeEstimate,
    /// Slow (margin) data estimate.
    pub slow: &'a ModeEstimate,
    /// Model margin, if available.
    pub model: Option<&'a ModelMargin>,
}

/// The fused margin report. No field is ever NaN; absent quantities are `None`.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct MarginReport {
    /// Time, s (as in [`FusionInput::t_s`]).
    pub t_s: f64,
    /// Speed, m/s.
    pub speed_mps: f32,
    /// Data damping (slow instance, for the margin).
    pub zeta_data: f32,
    /// Its sigma.
    pub sigma_zeta_data: f32,
    /// Data damping (fast instance, for warnings).
    pub zeta_fast: f32,
    /// Its sigma.
    pub sigma_zeta_fast: f32,
    /// Data mode frequency (slow), Hz.
    pub freq_hz: f32,
    /// Model damping.
    pub zeta_model: Option<f32>,
    /// Model frequency, Hz.
    pub freq_model_hz: Option<f32>,
    /// Speed margin, m/s.
    pub speed_margin_mps: Option<f32>,
    /// Which one limits it.
    pub margin_source: MarginSource,
    /// Time to the critical speed at the current acceleration, s.
    pub time_to_critical_s: Option<f32>,
    /// False when data and model disagree by > k sigma for a sustained time.
    pub model_consistent: bool,
    /// Measured damping offset delta = zeta_data - window-averaged zeta_model (0 without
    /// a model or valid data).
    pub zeta_offset: f32,
    /// The part of `zeta_offset` applied to the model margin (0 while data and model agree).
    pub zeta_correction: f32,
    /// The slow data estimate is valid.
    pub data_valid: bool,
    /// The fast data estimate is valid.
    pub fast_valid: bool,
    /// The report carries a usable margin: data valid, a margin present and (with
    /// `DataMarginUse::WhenModelInconsistent`) data and model compared for a full hold or
    /// release time since the start.
    pub valid: bool,
}

/// Fusion state (mismatch timer).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fusion {
    params: FusionParams,
    mismatch_since_s: Option<f64>,
    agree_since_s: Option<f64>,
    consistent: bool,
    /// Data and model have been compared for a full hold or release time since the start.
    checked: bool,
    /// Forgetting factor of the slow data estimate per update (None: compare with the
    /// current model damping).
    window_lambda: Option<f32>,
    model_sum: f32,
    model_weight: f32,
    offset: f32,
    /// Time of the last offset update (None before the first).
    offset_t_s: Option<f64>,
}

fn finite_or(v: f32, d: f32) -> f32 {
    if v.is_finite() {
        v
    } else {
        d
    }
}

impl Fusion {
    /// New fusion with the given parameters.
    pub fn new(params: FusionParams) -> Self {
        Self {
            params,
            mismatch_since_s: None,
            agree_since_s: None,
            consistent: true,
            checked: false,
            window_lambda: None,
            model_sum: 0.0,
            model_weight: 0.0,
            offset: 0.0,
            offset_t_s: None,
        }
    }

    /// Compares the data with the model damping averaged over the slow estimate's own
    /// exponential window (`lambda_slow` per update, one update per meter output): on a speed
    /// ramp the data estimate lags by about its memory, and the same lag in the model side
    /// keeps that lag out of the measured offset.
    pub fn matched_to(mut self, lambda_slow: f32) -> Self {
        self.window_lambda = (lambda_slow > 0.0 && lambda_slow < 1.0).then_some(lambda_slow);
        self
    }

    /// Parameters.
    pub fn params(&self) -> &FusionParams {
        &self.params
    }

    /// One fusion step (any rate; typically every decimated sample or 10 Hz).
    pub fn update(&mut self, inp: &FusionInput<'_>) -> MarginReport {
        let t = if inp.t_s.is_finite() { inp.t_s } else { 0.0 };
        let v = finite_or(inp.speed_mps, 0.0);
        let a = finite_or(inp.accel_mps2, 0.0);
        let data_valid = inp.slow.valid;
        let model = inp
            .model
            .filter(|m| m.valid && m.zeta.is_finite() && m.dzeta_dv_per_mps.is_finite());

        let mut r = MarginReport {
            t_s: t,
            speed_mps: v,
            zeta_data: finite_or(inp.slow.zeta, 0.0),
            sigma_zeta_data: finite_or(inp.slow.sigma_zeta, 0.0),
            zeta_fast: finite_or(inp.fast.zeta, 0.0),
            sigma_zeta_fast: finite_or(inp.fast.sigma_zeta, 0.0),
            freq_hz: finite_or(inp.slow.freq_hz, 0.0),
            data_valid,
            fast_valid: inp.fast.valid,
            ..MarginReport::default()
        };

        let Some(m) = model else {
            // No model: no margin, consistency unknown (kept at its last value).
            r.model_consistent = self.consistent;
            return r;
        };
        r.zeta_model = Some(m.zeta as f32);
        r.freq_model_hz = m.freq_hz.is_finite().then_some(m.freq_hz as f32);

        // the model damping over the data's window, and the offset between them
        let zm = m.zeta as f32;
        let zm_window = match self.window_lambda {
            Some(l) => {
                self.model_sum = l * self.model_sum + zm;
                self.model_weight = l * self.model_weight + 1.0;
                self.model_sum / self.model_weight
            }
            None => zm,
        };
        if data_valid {
            let raw = finite_or(r.zeta_data - zm_window, 0.0);
            let tau = (self.params.offset_speed_window_mps / libm::fabsf(a).max(1e-3))
                .min(self.params.offset_tau_max_s);
            self.offset = match self.offset_t_s {
                Some(t0) if tau > 0.0 => {
                    // backward-Euler first-order average (no expf in the image)
                    let dt = ((t - t0) as f32).clamp(0.0, 1.0);
                    self.offset + dt / (tau + dt) * (raw - self.offset)
                }
                _ => raw,
            };
            self.offset_t_s = Some(t);
        }
        r.zeta_offset = self.offset;
        // consistency with hysteresis in time
        if data_valid {
            let sigma = r.sigma_zeta_data.max(1e-6);
            let dev = libm::fabsf(self.offset) / sigma;
            if dev > self.params.mismatch_sigmas {
                self.agree_since_s = None;
                let since = *self.mismatch_since_s.get_or_insert(t);
                let mut hold = self.params.mismatch_hold_s;
                if self.params.mismatch_hold_speed_mps > 0.0 {
                    hold = hold.min(self.params.mismatch_hold_speed_mps / libm::fabsf(a).max(1e-3));
                }
                if (t - since) as f32 >= hold {
                    self.consistent = false;
                    self.checked = true;
                }
            } else if dev < self.params.agreement_sigmas {
                self.mismatch_since_s = None;
                let since = *self.agree_since_s.get_or_insert(t);
                if (t - since) as f32 >= self.params.mismatch_release_s {
                    self.consistent = true;
                    self.checked = true;
                }
            } else {
                // between the two thresholds: neither decision advances
                self.mismatch_since_s = None;
                self.agree_since_s = None;
            }
        }
        let slope = m.dzeta_dv_per_mps;
        let slope_ok = libm::fabs(slope) >= self.params.min_slope_per_mps as f64;
        let inv_slope = if slope_ok {
            1.0 / libm::fabs(slope)
        } else {
            0.0
        };
        let model_onset = m.v_crit_onset_mps.filter(|x| x.is_finite());
        let use_data = data_valid
            && slope_ok
            && match self.params.data_margin {
                DataMarginUse::Always => true,
                DataMarginUse::WhenModelInconsistent => !self.consistent || model_onset.is_none(),
            };
        let correction = if use_data { self.offset } else { 0.0 };
        r.zeta_correction = correction;
        let shift = correction as f64 * inv_slope;
        let candidate = match model_onset {
            Some(vc) if use_data => Some((vc - v as f64 + shift, MarginSource::Data)),
            Some(vc) => Some((vc - v as f64, MarginSource::Model)),
            None if use_data => {
                Some(((m.zeta + correction as f64) * inv_slope, MarginSource::Data))
            }
            None => None,
        };
        let best = candidate
            .map(|(dv, src)| (dv.max(0.0) as f32, src))
            .filter(|(dv, _)| dv.is_finite());
        if let Some((dv, src)) = best {
            r.speed_margin_mps = Some(dv);
            r.margin_source = src;
            // direction of decreasing damping: +1 (faster) when the slope is negative
            let dir = if src == MarginSource::Model || slope < 0.0 {
                1.0
            } else {
                -1.0
            };
            let closing = a * dir;
            if closing > self.params.min_accel_mps2 {
                r.time_to_critical_s = Some(dv / closing);
            }
        }

        r.model_consistent = self.consistent;
        // The corrected margin is trusted only once data and model have been compared: before
        // the first decision a wrong model's margin (e.g. 0 for a plant more stable than the
        // model) would raise a warning that the comparison then withdraws.
        let gate = match self.params.data_margin {
            DataMarginUse::Always => true,
            DataMarginUse::WhenModelInconsistent => self.checked,
        };
        r.valid = data_valid && gate && r.speed_margin_mps.is_some();
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimator::meter::mode_meter::EstimateStatus;

    fn est(zeta: f32, sigma: f32) -> ModeEstimate {
        ModeEstimate {
            zeta,
            sigma_zeta: sigma,
            freq_hz: 8.0,
            wn_hz: 8.0,
            valid: true,
            status: EstimateStatus::Ok,
        }
    }

    /// One update at a constant 20 m/s with `e` as both data estimates.
    fn steady_at_20_mps(f: &mut Fusion, e: &ModeEstimate, t: f64, m: &ModelMargin) -> MarginReport {
        f.update(&FusionInput {
            t_s: t,
            speed_mps: 20.0,
            accel_mps2: 0.0,
            fast: e,
            slow: e,
            model: Some(m),
        })
    }

    #[test]
    fn always_mode_corrects_the_model_margin_with_the_data() {
        let mut f = Fusion::new(FusionParams::default());
        let e = est(0.04, 0.01);
        let m = ModelMargin {
            zeta: 0.045,
            freq_hz: 8.0,
            dzeta_dv_per_mps: -0.004,
            v_crit_onset_mps: Some(25.0),
            valid: true,
        };
        // model margin 25 - 20 = 5 m/s, moved by (0.04 - 0.045) / 0.004 = -1.25 m/s; ttc 3.75/0.5
        let r = f.update(&FusionInput {
            t_s: 0.0,
            speed_mps: 20.0,
            accel_mps2: 0.5,
            fast: &e,
            slow: &e,
            model: Some(&m),
        });
        assert_eq!(r.margin_source, MarginSource::Data);
        assert!((r.speed_margin_mps.unwrap() - 3.75).abs() < 1e-5, "{r:?}");
        assert!((r.time_to_critical_s.unwrap() - 7.5).abs() < 1e-4);
        assert!(r.valid && r.model_consistent);
        // no onset from the model: its damping corrected by the data over the slope,
        // (0.045 - 0.005) / 0.004 = 10 m/s; decelerating -> no time to critical
        let m2 = ModelMargin {
            v_crit_onset_mps: None,
            ..m
        };
        let r = f.update(&FusionInput {
            t_s: 0.1,
            speed_mps: 20.0,
            accel_mps2: -0.5,
            fast: &e,
            slow: &e,
            model: Some(&m2),
        });
        assert_eq!(r.margin_source, MarginSource::Data);
        assert!((r.speed_margin_mps.unwrap() - 10.0).abs() < 1e-4);
        assert_eq!(r.time_to_critical_s, None);
    }

    #[test]
    fn mismatch_flag_needs_sustained_disagreement_and_clears_with_hysteresis() {
        let mut f = Fusion::new(FusionParams::default());
        let m = ModelMargin {
            zeta: 0.08,
            freq_hz: 8.0,
            dzeta_dv_per_mps: -0.004,
            v_crit_onset_mps: None,
            valid: true,
        };
        let bad = est(0.02, 0.01); // 6 sigma off
        let good = est(0.075, 0.01);
        let mut t = 0.0f64;
        let step = |f: &mut Fusion, e: &ModeEstimate, t: f64| steady_at_20_mps(f, e, t, &m);
        // a 2 s excursion does not trip the 3 s hold
        while t < 2.0 {
            assert!(step(&mut f, &bad, t).model_consistent);
            t += 0.01;
        }
        assert!(step(&mut f, &good, t).model_consistent);
        let t0 = t;
        while t < t0 + 3.5 {
            step(&mut f, &bad, t);
            t += 0.01;
        }
        assert!(!step(&mut f, &bad, t).model_consistent);
        // a short agreement does not clear it
        let t1 = t;
        while t < t1 + 1.0 {
            assert!(!step(&mut f, &good, t).model_consistent);
            t += 0.01;
        }
        while t < t1 + 4.5 {
            step(&mut f, &good, t);
            t += 0.01;
        }
        assert!(step(&mut f, &good, t).model_consistent);
    }

    #[test]
    fn data_margin_only_when_the_model_is_inconsistent() {
        let mut f = Fusion::new(FusionParams {
            data_margin: DataMarginUse::WhenModelInconsistent,
            ..FusionParams::default()
        });
        // model: onset 5 m/s ahead, slope -0.004; data 0.01 -> dV_data 2.5 m/s
        let m = ModelMargin {
            zeta: 0.012,
            freq_hz: 8.0,
            dzeta_dv_per_mps: -0.004,
            v_crit_onset_mps: Some(25.0),
            valid: true,
        };
        let agree = est(0.01, 0.01);
        let step = |f: &mut Fusion, e: &ModeEstimate, t: f64| steady_at_20_mps(f, e, t, &m);
        let r = step(&mut f, &agree, 0.0);
        assert_eq!(r.margin_source, MarginSource::Model);
        assert!((r.speed_margin_mps.unwrap() - 5.0).abs() < 1e-5);
        // data much lower than the model for longer than the hold: data margin takes over
        let low = est(-0.03, 0.005);
        let mut t = 0.0;
        let mut r = r;
        while t < 4.0 {
            t += 0.01;
            r = step(&mut f, &low, t);
        }
        assert!(!r.model_consistent);
        assert_eq!(r.margin_source, MarginSource::Data, "{r:?}");
        assert_eq!(r.speed_margin_mps, Some(0.0));
        // the model's 5 m/s moved by the measured offset: (0.004 - 0.012) / 0.004 = -2 m/s
        let lowish = est(0.004, 0.0005);
        r = step(&mut f, &lowish, t + 0.01);
        assert_eq!(r.margin_source, MarginSource::Data);
        assert!((r.speed_margin_mps.unwrap() - 3.0).abs() < 1e-4, "{r:?}");
        assert!((r.zeta_correction + 0.008).abs() < 1e-6);
        // more damped than the model: the onset moves away (no standing alarm)
        let high = est(0.052, 0.001);
        while t < 9.0 {
            t += 0.01;
            r = step(&mut f, &high, t);
        }
        assert!(!r.model_consistent);
        assert!((r.speed_margin_mps.unwrap() - 15.0).abs() < 1e-3, "{r:?}");
        // with the default (Always) the same data margin is used at once
        let mut g = Fusion::new(FusionParams::default());
        let r = step(&mut g, &agree, 0.0);
        assert_eq!(r.margin_source, MarginSource::Data);
    }

    /// A steady 5-sigma mismatch on a 1 km/h/s ramp: with the speed hold the flag drops after
    /// 0.25 m/s of speed change (0.9 s), with the time hold alone after 3 s.
    #[test]
    fn mismatch_hold_over_speed_shortens_the_hold_on_a_ramp() {
        let flag_time = |hold_speed: f32| {
            let mut f = Fusion::new(FusionParams {
                mismatch_hold_speed_mps: hold_speed,
                ..FusionParams::default()
            });
            let m = ModelMargin {
                zeta: 0.05,
                freq_hz: 8.0,
                dzeta_dv_per_mps: -0.004,
                v_crit_onset_mps: Some(30.0),
                valid: true,
            };
            let e = est(0.0, 0.01);
            (0..1000)
                .map(|k| f64::from(k) * 0.01)
                .find(|&t| {
                    !f.update(&FusionInput {
                        t_s: t,
                        speed_mps: 5.0 + 0.278 * t as f32,
                        accel_mps2: 0.278,
                        fast: &e,
                        slow: &e,
                        model: Some(&m),
                    })
                    .model_consistent
                })
                .unwrap_or(f64::INFINITY)
        };
        let with = flag_time(0.25);
        let without = flag_time(0.0);
        assert!((with - 0.25 / 0.278).abs() < 0.02, "{with}");
        assert!((without - 3.0).abs() < 0.02, "{without}");
    }

    #[test]
    fn nan_inputs_give_no_nan_outputs() {
        let mut f = Fusion::new(FusionParams::default());
        let e = ModeEstimate {
            zeta: f32::NAN,
            sigma_zeta: f32::NAN,
            freq_hz: f32::NAN,
            ..est(0.0, 0.0)
        };
        let m = ModelMargin {
            zeta: f64::NAN,
            freq_hz: f64::NAN,
            dzeta_dv_per_mps: f64::NAN,
            v_crit_onset_mps: Some(f64::NAN),
            valid: true,
        };
        let r = f.update(&FusionInput {
            t_s: f64::NAN,
            speed_mps: f32::NAN,
            accel_mps2: f32::INFINITY,
            fast: &e,
            slow: &e,
            model: Some(&m),
        });
        assert!(r.t_s.is_finite());
        for v in [
            r.speed_mps,
            r.zeta_data,
            r.sigma_zeta_data,
            r.zeta_fast,
            r.sigma_zeta_fast,
            r.freq_hz,
        ] {
            assert!(v.is_finite());
        }
        assert_eq!(r.zeta_model, None);
        let m2 = ModelMargin {
            zeta: 0.05,
            freq_hz: 8.0,
            dzeta_dv_per_mps: -0.01,
            v_crit_onset_mps: Some(f64::NAN),
            valid: true,
        };
        let r = f.update(&FusionInput {
            t_s: 1.0,
            speed_mps: 10.0,
            accel_mps2: 1.0,
            fast: &e,
            slow: &e,
            model: Some(&m2),
        });
        assert!(r.speed_margin_mps.is_none_or(f32::is_finite));
        assert!(r.time_to_critical_s.is_none_or(f32::is_finite));
    }
}
