//! The core's controller, mode meter and model margin behind the firmware's seams. Host-
//! compilable: the conformance replay ([`crate::replay`]) runs exactly this code on the host
//! and on the target.
//!
//! Who calls what (see `main.rs`):
//! - 1 kHz control task: [`CoreController`] (ASMC) through [`ControlStep`]; each validated
//!   step becomes a [`MeterSample`] pushed into a lock-free SPSC queue;
//! - 100 Hz meter task: drains the queue into [`DataMargin::push`] (the core's
//!   `MarginEstimator<f32>`, which returns one output per 10 samples), fuses with the newest
//!   model margin and updates the monitor;
//! - 10 Hz model task (lowest priority): [`ModelMarginTask::update`] (eigenvalues of the
//!   linearised plant, critical speed with a warm start) in f64.
//!
//! Why the queue and not the per-sample push inside the 1 kHz task: nine of ten `push` calls
//! are a decimation-filter step (a few hundred instructions), but the tenth runs two RLS
//! updates and two polynomial-root extractions (f64, soft-float on the M4), far beyond the
//! 5,000-instruction control budget (numbers: `cargo xtask bench`). Running it inline would
//! make every 10th control step ~10x longer than the others; the queue keeps the control task
//! constant-time and lets the meter work be preempted.
//!
//! Swapping in the core's fused pipeline / incremental model-margin state machine /
//! supervisor when they land: [`DataMargin`] and [`ModelMarginTask`] are the only types
//! `main.rs` names for that work (plus [`CoreController`] for a `SafeController`); replace
//! their bodies, keep their signatures.

use crate::control::{ControlInput, ControlStep};
use shimmy_core::control::{ControlOutput, ControlParams, Controller, ControllerKind};
use shimmy_core::estimator::{
    EstimatorConfig, Fusion, FusionInput, FusionParams, MarginEstimator, MarginReport, MeterOutput,
    ModelMargin, Sample, WheelOrder,
};
use shimmy_core::monitor::{Level, Monitor, MonitorInput, MonitorParams};
use shimmy_core::params::PlantParams;
use shimmy_core::stability::{self, CrossingKind, ModeSelect};

/// Control period [s].
pub const DT_S: f32 = 1e-3;
/// Meter samples per meter-task run (1 kHz / 100 Hz).
pub const METER_DECIMATION: u32 = 10;
/// Rolling radius used for the wheel-order phase [m] (the reference board's tone wheel).
pub const ROLLING_RADIUS_M: f32 = 0.35;
/// Capacity of the monitor's event log.
pub const EVENT_LOG: usize = 8;

/// The core's controller behind the firmware seam (ASMC by default).
#[derive(Clone, Copy, Debug)]
pub struct CoreController {
    ctrl: Controller,
    /// Output of the last step (telemetry).
    pub last: ControlOutput,
}

impl CoreController {
    /// A controller of `kind` with `params`.
    pub fn new(kind: ControllerKind, params: ControlParams) -> Self {
        CoreController {
            ctrl: Controller::new(kind, params),
            last: ControlOutput::default(),
        }
    }

    /// The adaptive sliding-mode controller with the default (nominal-plant) parameters.
    pub fn asmc() -> Self {
        Self::new(ControllerKind::Asmc, ControlParams::default())
    }

    /// The core controller (telemetry, law switching).
    pub fn inner(&mut self) -> &mut Controller {
        &mut self.ctrl
    }
}

/// The firmware's validated input as the core controller's input.
pub fn core_input(i: &ControlInput) -> shimmy_core::control::ControlInput {
    shimmy_core::control::ControlInput {
        t_s: i.step as f32 * i.dt_s,
        dt_s: i.dt_s,
        psi_l_rad: i.psi_l_rad,
        psi_r_rad: i.psi_r_rad,
        speed_mps: i.speed_mps,
        coil_current_a: i.coil_current_a.is_finite().then_some(i.coil_current_a),
    }
}

impl ControlStep for CoreController {
    fn step(&mut self, input: &ControlInput) -> f32 {
        self.last = self.ctrl.step(&core_input(input));
        self.last.current_cmd_a
    }
}

/// What the control task hands to the meter task per 1 kHz step (16 bytes).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MeterSample {
    /// Control step number.
    pub step: u32,
    /// Left wheel yaw [rad] (NaN when the step had no valid input: the meter holds).
    pub psi_l_rad: f32,
    /// Right wheel yaw [rad].
    pub psi_r_rad: f32,
    /// Vehicle speed [m/s].
    pub speed_mps: f32,
}

impl MeterSample {
    /// The meter sample of a control step (`None`: invalid input, angles NaN).
    pub fn of(step: u32, input: Option<&ControlInput>) -> Self {
        match input {
            Some(i) => MeterSample {
                step,
                psi_l_rad: i.psi_l_rad,
                psi_r_rad: i.psi_r_rad,
                speed_mps: i.speed_mps,
            },
            None => MeterSample {
                step,
                psi_l_rad: f32::NAN,
                psi_r_rad: f32::NAN,
                speed_mps: f32::NAN,
            },
        }
    }
}

/// One 100 Hz result of the data path.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MarginUpdate {
    /// Mode-meter output.
    pub meter: MeterOutput,
    /// Fused report.
    pub report: MarginReport,
    /// Warning level after this update.
    pub level: Level,
    /// The level changed with this update.
    pub level_changed: bool,
}

/// The data path at 100 Hz: mode meter -> fusion (with the newest model margin) -> monitor.
///
/// TODO(core pipeline): when `shimmy_core::estimator::pipeline` lands, this struct wraps it.
pub struct DataMargin {
    est: MarginEstimator<f32>,
    fusion: Fusion,
    monitor: Monitor<EVENT_LOG>,
    last_speed_mps: f32,
    speed_filt_mps: f32,
    accel_mps2: f32,
    last_t_s: Option<f32>,
}

impl DataMargin {
    /// The data path with the core's default configuration. `None` if the core rejects it
    /// (cannot happen with the defaults; checked by a host test).
    pub fn new() -> Option<Self> {
        Some(DataMargin {
            est: MarginEstimator::new(EstimatorConfig::default()).ok()?,
            fusion: Fusion::new(FusionParams::default()),
            monitor: Monitor::new(MonitorParams::default()),
            last_speed_mps: 0.0,
            speed_filt_mps: 0.0,
            accel_mps2: 0.0,
            last_t_s: None,
        })
    }

    /// The mode meter (counters, configuration).
    pub fn meter(&self) -> &MarginEstimator<f32> {
        &self.est
    }

    /// The monitor (events).
    pub fn monitor(&self) -> &Monitor<EVENT_LOG> {
        &self.monitor
    }

    /// Newest speed seen [m/s] (for the model task).
    pub fn speed_mps(&self) -> f32 {
        self.last_speed_mps
    }

    /// Feeds one 1 kHz sample; every 10th returns the fused 100 Hz update (using `model`, the
    /// newest model margin, if any).
    pub fn push(&mut self, s: &MeterSample, model: Option<&ModelMargin>) -> Option<MarginUpdate> {
        let speed_ok = s.speed_mps.is_finite();
        if speed_ok {
            self.last_speed_mps = s.speed_mps;
        }
        let meter = self.est.push(&Sample {
            psi_l_rad: s.psi_l_rad,
            psi_r_rad: s.psi_r_rad,
            wheel: if speed_ok {
                WheelOrder::Speed {
                    speed_mps: s.speed_mps,
                    radius_m: ROLLING_RADIUS_M,
                }
            } else {
                WheelOrder::None
            },
            damper_cmd: 0.0,
        })?;
        let t_s = s.step as f32 * DT_S;
        // Acceleration from a first-order filtered speed (tau 0.5 s) at the meter rate.
        let v = self.last_speed_mps;
        match self.last_t_s {
            Some(t0) if t_s > t0 => {
                let dt = t_s - t0;
                let a = dt / (0.5 + dt);
                let prev = self.speed_filt_mps;
                self.speed_filt_mps += a * (v - self.speed_filt_mps);
                self.accel_mps2 = (self.speed_filt_mps - prev) / dt;
            }
            _ => self.speed_filt_mps = v,
        }
        self.last_t_s = Some(t_s);
        let report = self.fusion.update(&FusionInput {
            t_s,
            speed_mps: v,
            accel_mps2: self.accel_mps2,
            fast: &meter.fast,
            slow: &meter.slow,
            model,
        });
        let before = self.monitor.level();
        let level = self.monitor.update(&MonitorInput {
            t_s,
            amplitude_rad: meter.amplitude_rad,
            report: &report,
        });
        Some(MarginUpdate {
            meter,
            report,
            level,
            level_changed: level != before,
        })
    }
}

/// Eigen-solves one model update may use for the critical-speed search.
pub const MODEL_MAX_EVALS: usize = 12;

/// The model-based margin at 10 Hz: shimmy mode and d zeta/dV at the current speed, and the
/// Hopf onset speed above it (warm-started from the previous answer).
///
/// The model is the linearised plant *without* the MR damper (c = 0): the conservative
/// envelope (the damper only adds damping). TODO(core model_margin): the incremental
/// state machine replaces `update` (and brings the damper's equivalent viscous coefficient).
pub struct ModelMarginTask {
    params: PlantParams,
    c_damper_nspm: f64,
    hint_mps: Option<f64>,
    /// Eigen-solves used by the last update.
    pub last_evals: usize,
}

impl ModelMarginTask {
    /// Model margin of `params` with a viscous damper `c_damper_nspm` [N s/m].
    pub fn new(params: PlantParams, c_damper_nspm: f64) -> Self {
        ModelMarginTask {
            params,
            c_damper_nspm,
            hint_mps: None,
            last_evals: 0,
        }
    }

    /// One model update at `speed_mps`. Never panics; a failed eigen-solve gives
    /// `valid = false`.
    pub fn update(&mut self, speed_mps: f32) -> ModelMargin {
        let v = f64::from(speed_mps);
        let (p, c) = (&self.params, self.c_damper_nspm);
        let Ok((mode, dzeta, _)) = stability::dzeta_dv(p, v, c, ModeSelect::Shimmy) else {
            return ModelMargin::default();
        };
        let onset = match stability::critical_speed_near(p, c, v, self.hint_mps, MODEL_MAX_EVALS) {
            Ok(cs) => {
                self.hint_mps = Some(cs.speed_mps);
                self.last_evals = cs.evals;
                (cs.kind == CrossingKind::Onset && cs.speed_mps > v).then_some(cs.speed_mps)
            }
            Err(_) => {
                self.hint_mps = None;
                self.last_evals = MODEL_MAX_EVALS;
                None
            }
        };
        ModelMargin {
            zeta: mode.zeta,
            freq_hz: mode.freq_hz,
            dzeta_dv_per_mps: dzeta,
            v_crit_onset_mps: onset,
            valid: true,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_build_and_the_meter_answers_every_tenth_sample() {
        let mut d = DataMargin::new().expect("default config");
        let mut n = 0;
        for k in 0..100u32 {
            let s = MeterSample {
                step: k,
                psi_l_rad: 0.0,
                psi_r_rad: 0.0,
                speed_mps: 12.0,
            };
            n += usize::from(d.push(&s, None).is_some());
        }
        assert_eq!(n, 10);
    }

    #[test]
    fn model_margin_inside_and_below_the_window() {
        use shimmy_core::params::kmh_to_mps;
        let mut m = ModelMarginTask::new(PlantParams::nominal(), 0.0);
        // Nominal window without damper: 29.35 -> 84.15 km/h. At 20 km/h the onset is above.
        let r = m.update(kmh_to_mps(20.0) as f32);
        assert!(r.valid && r.zeta > 0.0);
        let vc = r.v_crit_onset_mps.expect("onset above");
        assert!((vc - kmh_to_mps(29.35)).abs() < kmh_to_mps(0.05), "{vc}");
        // Inside the window the shimmy mode is unstable and no onset is above.
        let r = m.update(kmh_to_mps(50.0) as f32);
        assert!(r.valid && r.zeta < 0.0 && r.v_crit_onset_mps.is_none());
    }
}
