//! The fused shimmy pipeline: the one object the firmware and the simulator both call every
//! 1 kHz control tick.
//!
//! Per call ([`ShimmyPipeline::push`]):
//! 1. [`ModelMarginTracker::step`]: at most one eigen-solve (a full model update every
//!    `model.period_s` = 100 ms);
//! 2. [`MarginEstimator::push`] (the data-driven mode meter); on its decimated (100 Hz) steps:
//! 3. [`Fusion::update`] with the latest model margin, then [`Monitor::update`]; the report and
//!    the level are returned.
//!
//! All thresholds live in [`PipelineParams`]; `PipelineParams::default()` is the tuned design
//! point (see [`PipelineParams::tuned_monitor`] for how each threshold was chosen).

use super::fusion::{DataMarginUse, Fusion, FusionInput, FusionParams, MarginReport};
use super::meter::mode_meter::{
    ConfigError, EstimatorConfig, MarginEstimator, MeterOutput, Sample,
};
use super::model_margin::{ModelMargin, ModelMarginConfig, ModelMarginTracker, ModelPoint};
use super::model_update::{ModelUpdateConfig, ModelUpdater, UpdateOutcome};
use super::monitor::{Level, Monitor, MonitorInput, MonitorParams};
use crate::model::UpdatableModel;
use crate::vehicles::car::PlantParams;

/// Every tunable of the pipeline in one place.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PipelineParams {
    /// Data-driven mode meter.
    pub estimator: EstimatorConfig,
    /// Fusion of data and model.
    pub fusion: FusionParams,
    /// Warning thresholds.
    pub monitor: MonitorParams,
    /// Incremental model margin.
    pub model: ModelMarginConfig,
    /// Online model update from the meter's frequency and damping (off by default; on the
    /// host with `--model-update`; the board turns it on, `shimmy_firmware::monitoring::
    /// on_board`).
    pub update: ModelUpdateConfig,
}

impl PipelineParams {
    /// Fusion for the pipeline (`DataMarginUse::WhenModelInconsistent`, policy and failure
    /// modes in `docs/margin-estimator.md`): the model margin while data and model agree, the
    /// model corrected by the measured damping offset when they do not. The averaged offset is
    /// judged against its own sigma (the meter's reported sigma, the fit's covariance with
    /// one-sigma coverage 62-75 % on the plant, reduced by the averaging over the meter's
    /// correlation time): mismatch above 2.5 sigma (2.0 when the data say the plant is less
    /// damped than the model: the safe side needs less evidence; at 2.5 the C_a +20 % ramp
    /// on seed 1 warned 2.72 km/h ahead, at 2.0 3.26, `shimmy-sim mismatch`), agreement below
    /// 1 sigma (hysteresis),
    /// each held 3 s, the first one not before one meter memory after the first estimate;
    /// with no decision 15 s after it the smaller of the model and corrected margins counts
    /// (a meter reading 1-2 sigmas off otherwise left a right model unconfirmed and the
    /// warning off, `shimmy-sim mismatch --seed 3`); a mismatch also counts
    /// once held over 0.25 m/s of speed change (0.9 s at 1 km/h/s: the time hold alone cost
    /// 3 km/h of lead, `shimmy-sim mismatch`). The offset is averaged over 1 m/s of speed
    /// change (at most 30 s): at constant speed the meter's 10 s memory then spans three
    /// independent windows, on the 1 km/h/s ramp 3.6 s of extra lag.
    pub const fn tuned_fusion() -> FusionParams {
        FusionParams {
            mismatch_sigmas: 2.5,
            less_stable_sigmas: 2.0,
            agreement_sigmas: 1.0,
            offset_tau_max_s: 30.0,
            offset_speed_window_mps: 1.0,
            mismatch_hold_speed_mps: 0.25,
            first_decision_timeout_s: 15.0,
            data_margin: DataMarginUse::WhenModelInconsistent,
            ..FusionParams::DEFAULT
        }
    }

    /// Monitor thresholds for the shimmy pipeline (the monitor's own `Default` is generic).
    ///
    /// Requirement: on a 1 km/h/s ramp through the Hopf onset with road noise and wheel
    /// imbalance the first warning comes >= 5 km/h (>= 5 s) before the onset, and a 10-minute
    /// drive at 15-20 km/h (>= 9.35 km/h below the nominal onset at 29.35 km/h) raises none;
    /// with a wrong model (`shimmy-sim mismatch`) none at 70 % of the true onset.
    /// - speed margin: `MarginLow` below 1.4 m/s (5.0 km/h), cleared above 1.6 m/s; at 70 % of
    ///   the nominal onset the margin is 8.8 km/h, so a data-corrected margin may scatter by
    ///   3.8 km/h (about 1.6 of its sigmas at 20 km/h) before a false warning;
    ///   `ApproachingCritical` below 1.0 m/s (3.6 km/h); with the online model update the
    ///   `MarginLow` comparison adds one sigma of the updated onset (`margin_sigmas`), so a
    ///   drive whose margin is uncertain by about the band's width does not sit in it;
    /// - time to critical: `ApproachingCritical` below 6 s (6 km/h ahead at 1 km/h/s: the
    ///   nominal ramp's first warning);
    /// - data damping, a backstop for a plant far from its model: the estimate plus one of its
    ///   sigmas (`data_sigmas`) below 0.005 for the slow instance (`MarginLow`), below -0.02 for
    ///   the fast one (`ApproachingCritical`, oscillation growing);
    /// - amplitude: `ShimmyPresent` above 0.5 deg peak in-phase yaw (road noise and imbalance
    ///   give < 0.2 deg envelope at 15-20 km/h; the limit cycle is ~7 deg), cleared below
    ///   0.25 deg; all levels are released after a 2 s dwell.
    pub const fn tuned_monitor() -> MonitorParams {
        MonitorParams {
            zeta_low_on: 0.005,
            zeta_low_off: 0.015,
            dv_low_on_mps: 1.4,
            dv_low_off_mps: 1.6,
            zeta_crit_on: -0.02,
            zeta_crit_off: -0.01,
            dv_crit_on_mps: 1.0,
            dv_crit_off_mps: 1.3,
            ttc_on_s: 6.0,
            ttc_off_s: 8.0,
            amp_on_rad: 0.5f32.to_radians(),
            amp_off_rad: 0.25f32.to_radians(),
            release_s: 2.0,
            data_sigmas: 1.0,
            margin_sigmas: 1.0,
        }
    }
}

impl PipelineParams {
    /// The online model update's configuration with the slow meter's memory
    /// ([`ModelUpdateConfig::matched_to`]).
    pub fn matched_update(&self) -> ModelUpdateConfig {
        let est = &self.estimator;
        self.update.matched_to(
            est.lambda_slow,
            est.input_rate_hz / f32::from(est.decimation.max(1)),
        )
    }

    /// The parameters of the data path ([`DataPipeline`]): with the model update on, the
    /// updated model is the data's correction, so the fusion does not correct it again.
    pub fn data_path(&self) -> Self {
        let mut p = *self;
        if self.update.enabled {
            p.fusion.data_margin = DataMarginUse::Never;
        }
        p
    }
}

impl Default for PipelineParams {
    fn default() -> Self {
        Self {
            estimator: EstimatorConfig::default(),
            fusion: Self::tuned_fusion(),
            monitor: Self::tuned_monitor(),
            model: ModelMarginConfig::default(),
            update: ModelUpdateConfig::OFF,
        }
    }
}

/// The vehicle acceleration the fusion needs, from sampled speed: the derivative of the
/// first-order filtered speed (time constant [`AccelEstimator::TAU_S`]). One place for the
/// firmware's meter task and for `shimmy-sim analyze` on measured logs, so both hand the
/// fusion the same number.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AccelEstimator {
    speed_filt_mps: f32,
    accel_mps2: f32,
    last_t_s: Option<f64>,
}

impl AccelEstimator {
    /// Time constant of the speed filter, s (a wheel-speed sensor's tooth noise differentiated
    /// raw would swamp the fusion's time to critical).
    pub const TAU_S: f32 = 0.5;

    /// Zero acceleration, no speed seen yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Takes the speed `v` at time `t_s` (a non-finite speed is ignored, a time that does not
    /// advance only re-seeds the filter) and returns the acceleration estimate, m/s^2.
    /// (Inlined: it was the meter task's own code, and a call costs the task 7 instructions a
    /// sample, `cargo xtask bench`.)
    #[inline]
    pub fn update(&mut self, t_s: f64, v: f32) -> f32 {
        if !v.is_finite() {
            return self.accel_mps2;
        }
        let dt_s = self
            .last_t_s
            .filter(|t0| t_s > *t0)
            .map(|t0| (t_s - t0) as f32);
        self.last_t_s = Some(t_s);
        self.update_dt(dt_s, v)
    }

    /// [`Self::update`] given the time step itself: `dt_s` since the last accepted speed, `None`
    /// for the first one or when time did not advance (re-seeds the filter). The firmware's
    /// form: its dt comes from the step count in f32, so no f64 arithmetic (soft-float on the
    /// M4) runs per 1 kHz sample.
    #[inline]
    pub fn update_dt(&mut self, dt_s: Option<f32>, v: f32) -> f32 {
        if !v.is_finite() {
            return self.accel_mps2;
        }
        match dt_s {
            Some(dt) => {
                let a = dt / (Self::TAU_S + dt);
                let prev = self.speed_filt_mps;
                self.speed_filt_mps += a * (v - self.speed_filt_mps);
                self.accel_mps2 = (self.speed_filt_mps - prev) / dt;
            }
            None => self.speed_filt_mps = v,
        }
        self.accel_mps2
    }

    /// The latest estimate, m/s^2.
    pub fn accel_mps2(&self) -> f32 {
        self.accel_mps2
    }
}

/// What a decimated step of the pipeline produced.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PipelineOutput {
    /// The fused margin report.
    pub report: MarginReport,
    /// The monitor level after this step.
    pub level: Level,
    /// The mode meter's raw output (amplitude, excitation, both estimates).
    pub meter: MeterOutput,
}

/// The data part of the pipeline: mode meter -> fusion (with a model margin supplied by the
/// caller) -> monitor, with an event log of `N` entries.
///
/// [`ShimmyPipeline`] feeds it the margin of its own [`ModelMarginTracker`] every 1 kHz tick
/// (host simulator). The firmware cannot: one tracker call costs up to one f64 eigen-solve
/// (millions of soft-float instructions on the M4), so it runs this type in its 100 Hz meter
/// task and the tracker in a background loop, and hands the newest completed model margin in.
/// Both therefore use the same meter, fusion, monitor and thresholds ([`PipelineParams`]).
#[derive(Clone, Debug)]
pub struct DataPipeline<const N: usize> {
    meter: MarginEstimator<f32>,
    fusion: Fusion,
    monitor: Monitor<N>,
    margin_sigma_mps: f32,
}

impl<const N: usize> DataPipeline<N> {
    /// The data part with `params.estimator`, `params.fusion` and `params.monitor`.
    pub fn new(params: &PipelineParams) -> Result<Self, ConfigError> {
        Ok(Self {
            meter: MarginEstimator::new(params.estimator)?,
            fusion: Fusion::new(params.fusion).matched_to(params.estimator.lambda_slow),
            monitor: Monitor::new(params.monitor),
            margin_sigma_mps: 0.0,
        })
    }

    /// The model side's one-sigma uncertainty of the onset speed, m/s (the online model
    /// update's posterior; 0, the default, takes the model as known). The monitor's
    /// `MarginLow` on the speed margin waits for confidence by `margin_sigmas` of it.
    pub fn set_margin_sigma(&mut self, sigma_mps: f32) {
        self.margin_sigma_mps = if sigma_mps.is_finite() && sigma_mps > 0.0 {
            sigma_mps
        } else {
            0.0
        };
    }

    /// One 1 kHz sample: `sample` (wheel yaw angles, wheel order), vehicle speed and
    /// acceleration, time, and the newest model margin (if any). Returns the report and level
    /// on decimated steps (100 Hz).
    pub fn push(
        &mut self,
        sample: &Sample,
        speed_mps: f32,
        accel_mps2: f32,
        t_s: f64,
        model: Option<&ModelMargin>,
    ) -> Option<PipelineOutput> {
        self.push_timed(sample, speed_mps, accel_mps2, || t_s, model)
    }

    /// [`Self::push`] with the time asked for only on the decimated steps that answer: `t_s`
    /// is called once per report (100 Hz), not per sample. The firmware's time is `f64`
    /// seconds, soft-float on the M4, so it pays for it at a tenth of the rate.
    pub fn push_timed(
        &mut self,
        sample: &Sample,
        speed_mps: f32,
        accel_mps2: f32,
        t_s: impl FnOnce() -> f64,
        model: Option<&ModelMargin>,
    ) -> Option<PipelineOutput> {
        let out = self.meter.push(sample)?;
        let t_s = t_s();
        let report = self.fusion.update(&FusionInput {
            t_s,
            speed_mps,
            accel_mps2,
            fast: &out.fast,
            slow: &out.slow,
            model,
        });
        let level = self.monitor.update(&MonitorInput {
            t_s,
            amplitude_rad: out.amplitude_rad,
            report: &report,
            speed_margin_sigma_mps: self.margin_sigma_mps,
        });
        Some(PipelineOutput {
            report,
            level,
            meter: out,
        })
    }

    /// Tells the mode meter that the plant changed (e.g. the damper setting): it forgets
    /// faster for a while.
    pub fn regime_change(&mut self) {
        self.meter.regime_change();
    }

    /// Current level.
    pub fn level(&self) -> Level {
        self.monitor.level()
    }

    /// The monitor (event log).
    pub fn monitor(&self) -> &Monitor<N> {
        &self.monitor
    }

    /// The mode meter.
    pub fn meter(&self) -> &MarginEstimator<f32> {
        &self.meter
    }
}

/// Mode meter + incremental model margin + fusion + monitor with an event log of `N` entries:
/// a [`DataPipeline`] fed by a [`ModelMarginTracker`] stepped on every call, on the vehicle
/// model `M` with `S` states (the car's by default).
#[derive(Clone, Debug)]
pub struct ShimmyPipeline<
    const N: usize,
    M: UpdatableModel<S> = PlantParams,
    const S: usize = { crate::vehicles::car::N_STATES },
> {
    params: PipelineParams,
    data: DataPipeline<N>,
    model: ModelMarginTracker<f64, M, S>,
    updater: ModelUpdater<M, S>,
    model_margin: Option<ModelMargin>,
    c_damper_nspm: f32,
    /// The largest damper command since the last report (the model update's damper watch).
    cmd_peak_a: f32,
}

/// The larger of two damper commands, A; a NaN (a command not known) sticks: the model
/// update counts it as active.
pub fn peak_command(peak_a: f32, cmd_a: f32) -> f32 {
    if peak_a.is_nan() || cmd_a.is_nan() {
        f32::NAN
    } else {
        peak_a.max(cmd_a)
    }
}

impl<const N: usize> ShimmyPipeline<N> {
    /// A pipeline for the car's plant `plant` (the model side linearises it).
    pub fn new(plant: PlantParams, params: PipelineParams) -> Result<Self, ConfigError> {
        Self::for_model(plant, params)
    }
}

impl<const N: usize, M: UpdatableModel<S>, const S: usize> ShimmyPipeline<N, M, S> {
    /// A pipeline whose model side tracks the vehicle model `plant` (updated from the data
    /// when `params.update.enabled`).
    pub fn for_model(plant: M, params: PipelineParams) -> Result<Self, ConfigError> {
        Ok(Self {
            data: DataPipeline::new(&params.data_path())?,
            model: ModelMarginTracker::new(plant, params.model),
            updater: ModelUpdater::new(plant, params.matched_update()),
            model_margin: None,
            c_damper_nspm: 0.0,
            cmd_peak_a: 0.0,
            params,
        })
    }

    /// Parameters.
    pub fn params(&self) -> &PipelineParams {
        &self.params
    }

    /// Sets the damper's equivalent viscous coefficient the model uses (0 = no damper), N s/m.
    /// Also signals a regime change to the mode meter when it changes by more than 1 %.
    pub fn set_damper_viscous(&mut self, c_nspm: f32) {
        if c_nspm.is_finite() && c_nspm >= 0.0 {
            if libm::fabsf(c_nspm - self.c_damper_nspm) > 0.01 * self.c_damper_nspm.max(1.0) {
                self.data.regime_change();
            }
            self.c_damper_nspm = c_nspm;
        }
    }

    /// One control tick: `sample` (wheel yaw angles, wheel order), vehicle speed and
    /// acceleration, time. Returns the report and level on decimated steps (100 Hz).
    pub fn push(
        &mut self,
        sample: &Sample,
        speed_mps: f32,
        accel_mps2: f32,
        t_s: f64,
    ) -> Option<PipelineOutput> {
        if let Some(pt) = self.model.step(t_s, speed_mps, self.c_damper_nspm) {
            self.model_margin = Some(pt.margin());
        }
        self.cmd_peak_a = peak_command(self.cmd_peak_a, sample.damper_cmd);
        let out = self.data.push(
            sample,
            speed_mps,
            accel_mps2,
            t_s,
            self.model_margin.as_ref(),
        )?;
        let outcome = self.updater.update(
            t_s,
            speed_mps,
            self.c_damper_nspm,
            core::mem::take(&mut self.cmd_peak_a),
            &out.meter.slow,
        );
        if outcome == UpdateOutcome::Updated {
            self.model.set_plant(self.updater.model());
            let sigma = self
                .model_margin
                .and_then(|m| m.v_crit_onset_mps)
                .and_then(|v| {
                    self.updater
                        .onset_sigma_mps(v, f64::from(self.c_damper_nspm))
                });
            self.data.set_margin_sigma(sigma.map_or(0.0, |s| s as f32));
        }
        Some(out)
    }

    /// The online model update (its parameters, their uncertainty and the diagnosis).
    pub fn updater(&self) -> &ModelUpdater<M, S> {
        &self.updater
    }

    /// Current level.
    pub fn level(&self) -> Level {
        self.data.level()
    }

    /// The monitor (event log).
    pub fn monitor(&self) -> &Monitor<N> {
        self.data.monitor()
    }

    /// The mode meter.
    pub fn meter(&self) -> &MarginEstimator<f32> {
        self.data.meter()
    }

    /// The data part (meter, fusion, monitor).
    pub fn data(&self) -> &DataPipeline<N> {
        &self.data
    }

    /// The model-margin tracker.
    pub fn model(&self) -> &ModelMarginTracker<f64, M, S> {
        &self.model
    }

    /// The latest completed model point.
    pub fn model_point(&self) -> Option<&ModelPoint> {
        self.model.latest()
    }

    /// The model margin the fusion currently uses.
    pub fn model_margin(&self) -> Option<&ModelMargin> {
        self.model_margin.as_ref()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimator::meter::mode_meter::WheelOrder;

    /// On a speed ramp the estimate settles on the ramp's slope (after a few filter time
    /// constants), and a NaN speed leaves it alone.
    #[test]
    fn accel_estimator_follows_a_ramp() {
        let mut acc = AccelEstimator::new();
        let mut a = 0.0;
        for k in 0..5000u32 {
            let t = f64::from(k) * 1e-3;
            a = acc.update(t, 5.0 + 0.8 * t as f32);
        }
        assert!((a - 0.8).abs() < 0.01, "{a}");
        assert_eq!(acc.update(5.0, f32::NAN), a);
        assert_eq!(acc.accel_mps2(), a);
    }

    /// `ShimmyPipeline` is exactly a `DataPipeline` fed by a tracker stepped each tick: the
    /// composition by hand gives bit-identical outputs (so the firmware, which composes them
    /// across tasks, runs the same data path as the simulator).
    #[test]
    fn shimmy_pipeline_is_data_pipeline_plus_tracker() {
        let pp = PipelineParams::default();
        let plant = PlantParams::nominal();
        let mut whole = ShimmyPipeline::<8>::new(plant, pp).unwrap();
        let mut data = DataPipeline::<8>::new(&pp).unwrap();
        let mut tracker = ModelMarginTracker::new(plant, pp.model);
        let mut mm: Option<ModelMargin> = None;
        let mut seed = 3u32;
        let mut outputs = 0;
        let mut with_model = 0;
        for k in 0..1500u32 {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let noise = ((seed >> 8) as f32 / 16_777_216.0 - 0.5) * 2e-4;
            let t = k as f32 * 1e-3;
            let y = 2e-3 * libm::sinf(2.0 * core::f32::consts::PI * 6.5 * t) + noise;
            let v = 6.0 + 0.5 * t;
            let s = Sample {
                psi_l_rad: y,
                psi_r_rad: 0.98 * y,
                wheel: WheelOrder::Speed {
                    speed_mps: v,
                    radius_m: 0.35,
                },
                damper_cmd: 0.0,
            };
            let a = whole.push(&s, v, 0.5, f64::from(t));
            if let Some(pt) = tracker.step(f64::from(t), v, 0.0) {
                mm = Some(pt.margin());
            }
            let b = data.push(&s, v, 0.5, f64::from(t), mm.as_ref());
            // Debug text: bit-exact for finite values and equal for NaN (== would not be).
            assert_eq!(format!("{a:?}"), format!("{b:?}"), "tick {k}");
            outputs += usize::from(a.is_some());
            with_model += usize::from(a.is_some_and(|o| o.report.zeta_model.is_some()));
        }
        assert_eq!(outputs, 1500 / usize::from(pp.estimator.decimation));
        assert!(3 * with_model > 2 * outputs, "{with_model} of {outputs}");
        assert_eq!(whole.level(), data.level());
    }
}
