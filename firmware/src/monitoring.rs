//! The core's supervised controller, data pipeline and model-margin tracker as the firmware's
//! tasks use them. Host-compilable: the conformance replay ([`crate::replay`]) runs exactly
//! this code on the host and on the target.
//!
//! Who calls what (see `main.rs`):
//! - 1 kHz control task: [`safe_controller`] (the core's `SafeController`: supervisor +
//!   margin-scheduled ASMC + limiter) through [`crate::control::supervised_step`], fed the
//!   newest fused margin report ([`DataMargin::margin_status`]); each step's validated sample
//!   becomes a [`MeterSample`] pushed into a lock-free SPSC queue;
//! - 100 Hz meter task, spawned by the step that completes a block of ten samples
//!   ([`MeterCadence`]): drains the queue into [`DataMargin::push`] (the core's
//!   `DataPipeline`: mode meter -> fusion with the newest model margin -> monitor, with the
//!   tuned `PipelineParams`), which answers on the block's last sample, so its report reaches
//!   the next control step: 10 ms cadence, one control period of latency;
//! - background loop (idle, lowest priority): [`ModelTask::step`] (the core's
//!   `ModelMarginTracker`, at most one f32 eigen-solve per call), publishing each completed model
//!   margin to the meter task.
//!
//! Why the queue and not the per-sample push inside the 1 kHz task: nine of ten `push` calls
//! are a decimation-filter step (a few hundred instructions), but the tenth runs the RLS
//! updates and root extractions, far beyond the 5,000-instruction control budget (numbers:
//! `cargo xtask bench`). The queue keeps the control task constant-time and lets the meter work
//! be preempted. Why the tracker is not called per tick as in the simulator's
//! `ShimmyPipeline`: one call can be an eigen-solve plus the cold shape selection (up to ~0.44 M
//! instructions, `cargo xtask bench`), far beyond the control budget.

use shimmy_core::control::{ControlParams, ControllerKind};
use shimmy_core::estimator::meter::mode_meter::{ConfigError, Sample, WheelOrder};
use shimmy_core::estimator::model_margin::{
    ModelMargin, ModelMarginConfig, ModelMarginTracker, ModelPoint,
};
use shimmy_core::estimator::model_update::{
    Measurement, ModelUpdateConfig, ModelUpdater, UpdateClock, UpdateOutcome,
};
use shimmy_core::estimator::monitor::Level;
use shimmy_core::estimator::pipeline::{peak_command, AccelEstimator, PipelineParams};
use shimmy_core::estimator::pipeline::{DataPipeline, PipelineOutput};
use shimmy_core::model::UpdatableModel;
use shimmy_core::supervisor::frame::{MarginStatus, NOMINAL_PERIOD_US};
use shimmy_core::supervisor::params::SupervisorParams;
use shimmy_core::supervisor::safe_controller::{SafeController, SafeOutput};
use shimmy_core::vehicle::{BoardVehicle, Vehicle};

/// Control period, s.
pub const DT_S: f32 = 1e-3;

/// Time of control step `steps` for the margin path, s: `f64`, so the millisecond stays exact
/// over any drive (`f32` seconds lose it after 2^24 ms = 4.66 h).
pub fn step_time_s(steps: u64) -> f64 {
    steps as f64 * (f64::from(NOMINAL_PERIOD_US) * 1e-6)
}
/// Meter samples per meter-task run (1 kHz / 100 Hz).
pub const METER_DECIMATION: u32 = 10;
/// Rolling radius used for the wheel-order phase, m (the reference board's tone wheel).
pub const ROLLING_RADIUS_M: f32 = crate::calibration::WHEEL_SPEED.rolling_radius_m;

/// What the board's calibration adds to a stored vehicle of a model: the rolling radius the
/// mode meter's wheel order takes (the wheel's rotation frequency `v / (2 pi r)`, whose
/// imbalance the meter keeps apart from the shimmy mode).
pub trait BoardCalibration {
    /// The wheel order's rolling radius, m.
    fn wheel_order_radius_m(&self) -> f32;
}

impl BoardCalibration for Vehicle {
    /// The reference board's tone wheel ([`ROLLING_RADIUS_M`]).
    fn wheel_order_radius_m(&self) -> f32 {
        ROLLING_RADIUS_M
    }
}

impl BoardCalibration for shimmy_core::vehicles::truck::board::TruckVehicle {
    /// The truck's loaded rolling radius (its 40.00R57 tyres, 1.72 m): with the car's 0.35 m
    /// the wheel order would sweep through the truck's ~3 Hz shimmy at 20-30 km/h.
    /// TODO(vehicle): the truck board's own tone-wheel calibration, as for the car.
    fn wheel_order_radius_m(&self) -> f32 {
        self.truck.r as f32
    }
}

/// Capacity of the monitor's event log.
pub const EVENT_LOG: usize = 8;
/// Requirement on the model margin's refresh period, s: a new cycle starts every this long and
/// must complete within it (the tracker's `overruns` count the misses).
///
/// 10 Hz, the rate the margin issue asks for. What it buys: the tuned monitor
/// (`PipelineParams::tuned_monitor`) fires `MarginLow` 7.9 km/h ahead of the Hopf onset and
/// needs at least 5 km/h; a model at most one period plus one cycle old (0.2 s) is at most
/// 0.2 km/h stale at the 1 km/h/s of the requirement ramp. What it costs: the worst warm cycle
/// (continuation: one f32 eigenvalue solve and one LU) is 0.19 M instructions, 1.8 ms of the
/// background loop at the measured load, ~1.1 % of the CPU at 1 cycle per instruction; the cold
/// first cycle (the full scan) ~53 ms (`cargo xtask bench`).
pub const MODEL_REFRESH_S: f32 = 0.1;

/// The controller the firmware runs: the margin-scheduled ASMC (`shimmy_core::control::
/// schedule`), armed by the meter task's fused margin report, through the quiet coil.
pub const CONTROLLER: ControllerKind = ControllerKind::MarginAsmc;

/// The core's supervised controller as the firmware runs it: [`CONTROLLER`] with the default
/// (nominal-plant) parameters, the default supervisor thresholds (fail-safe current
/// `shimmy_core::control::actuator::FAILSAFE_CURRENT_A`).
pub fn safe_controller() -> SafeController {
    SafeController::new(
        CONTROLLER,
        ControlParams::default(),
        SupervisorParams::default(),
    )
}

/// The supervised controller for `vehicle` (its controller and supervisor parameters, as the
/// store loaded it; the controller's nominal plant from its model); for `Vehicle::nominal()` it
/// is [`safe_controller`] (the core test `the_nominal_vehicle_reproduces_todays_defaults`).
pub fn safe_controller_for<V: BoardVehicle<N>, const N: usize>(vehicle: &V) -> SafeController {
    SafeController::new(
        CONTROLLER,
        vehicle.controller_params(),
        vehicle.supervisor_params(),
    )
}

/// The margin pipeline the board runs with the pipeline parameters `params` (a vehicle's):
/// the online model update on ([`ModelUpdateConfig::ON`]: the model follows the measured
/// shimmy frequency and damping; `docs/margin-estimator.md`, "Model updating"). The update's
/// expensive step runs in the background loop ([`ModelTask`]); the meter task only decides
/// when one is due.
pub fn on_board(params: PipelineParams) -> PipelineParams {
    PipelineParams {
        update: ModelUpdateConfig::ON,
        ..params
    }
}

/// The margin pipeline the board runs for `vehicle` ([`on_board`] of its pipeline).
pub fn board_pipeline<V: BoardVehicle<N>, const N: usize>(vehicle: &V) -> PipelineParams {
    on_board(vehicle.margin_pipeline())
}

/// When the control task spawns the meter task: on the step whose sample completes a block
/// of [`METER_DECIMATION`] (the 10th, 20th, ... since boot), the sample on which the data
/// path answers. The meter run then reports before the next control step, which takes the
/// report: the simulator's closed loop has the same cadence and latency (it runs the
/// application's tasks, `firmware::pil::HostApp`). A counter, not the step number modulo 10,
/// so the phase survives the wrap of the `u32` step count.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MeterCadence {
    in_block: u32,
}

impl MeterCadence {
    /// Counts one control step's sample; true when the meter task is due after it.
    pub fn tick(&mut self) -> bool {
        self.in_block += 1;
        let due = self.in_block >= METER_DECIMATION;
        if due {
            self.in_block = 0;
        }
        due
    }
}

/// What the control task hands to the meter task per 1 kHz step (20 bytes).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MeterSample {
    /// Control step number.
    pub step: u32,
    /// Left wheel yaw, rad (NaN when the supervisor trusted no wheel yaw: the meter holds).
    pub psi_l_rad: f32,
    /// Right wheel yaw, rad (the left one again when only the left encoder is trusted).
    pub psi_r_rad: f32,
    /// Trusted vehicle speed [m/s] (NaN when the supervisor does not trust it).
    pub speed_mps: f32,
    /// Coil current command of the step, A.
    pub cmd_a: f32,
}

impl MeterSample {
    /// The meter sample of a supervised control step.
    pub fn of(step: u32, out: &SafeOutput) -> Self {
        let (psi_l_rad, psi_r_rad) = out.validated.angles_rad.unwrap_or((f32::NAN, f32::NAN));
        MeterSample {
            step,
            psi_l_rad,
            psi_r_rad,
            speed_mps: out.validated.speed_mps.unwrap_or(f32::NAN),
            cmd_a: out.current_cmd_a,
        }
    }
}

/// One 100 Hz result of the data path.
pub type MarginUpdate = PipelineOutput;

/// The data path at 100 Hz: the core's [`DataPipeline`] (mode meter -> fusion with the
/// newest model margin -> monitor, thresholds from `PipelineParams::default()`), plus the
/// vehicle acceleration the fusion needs (the core's `AccelEstimator` on the sampled speed).
pub struct DataMargin {
    pipe: DataPipeline<EVENT_LOG>,
    last_speed_mps: f32,
    accel: AccelEstimator,
    /// Control steps since the first sample, widened from the samples' wrapping `u32` step
    /// count so the pipeline's time neither wraps (49.7 days at 1 kHz) nor loses the
    /// millisecond (an `f32` second count does after 2^24 ms = 4.66 h).
    steps: u64,
    last_step: Option<u32>,
    last_level: Level,
    last_status: MarginStatus,
    /// The wheel order's rolling radius, m ([`BoardCalibration`]).
    radius_m: f32,
    /// The online model update's configuration (matched to the meter's memory).
    update: ModelUpdateConfig,
    /// When the next measurement update is due (the update itself runs in the model task).
    clock: UpdateClock,
    /// The newest due measurement not yet taken by the model task.
    measurement: Option<Measurement>,
    /// The largest damper command since the last report (the update's damper watch).
    cmd_peak_a: f32,
}

impl DataMargin {
    /// The data path with the core's tuned parameters and the reference board's wheel order
    /// ([`ROLLING_RADIUS_M`]).
    pub fn new() -> Result<Self, ConfigError> {
        Self::with_params(&PipelineParams::default(), ROLLING_RADIUS_M)
    }

    /// The data path with `params` (a vehicle's `margin_pipeline()`) and the wheel order's
    /// rolling radius `radius_m` ([`BoardCalibration::wheel_order_radius_m`]).
    pub fn with_params(params: &PipelineParams, radius_m: f32) -> Result<Self, ConfigError> {
        Ok(DataMargin {
            radius_m,
            pipe: DataPipeline::new(&params.data_path())?,
            update: params.matched_update(),
            clock: UpdateClock::new(),
            measurement: None,
            cmd_peak_a: 0.0,
            last_speed_mps: f32::NAN,
            accel: AccelEstimator::new(),
            steps: 0,
            last_step: None,
            last_level: Level::Normal,
            last_status: MarginStatus::Invalid,
        })
    }

    /// The core data pipeline (meter counters, monitor events).
    pub fn pipeline(&self) -> &DataPipeline<EVENT_LOG> {
        &self.pipe
    }

    /// Newest trusted speed [m/s] (NaN before the first).
    pub fn speed_mps(&self) -> f32 {
        self.last_speed_mps
    }

    /// The newest report as the control task takes it: its validity for the supervisor's
    /// margin check and, when valid, the margin schedule's input.
    pub fn margin_status(&self) -> MarginStatus {
        self.last_status
    }

    /// Feeds one 1 kHz sample; every 10th returns the 100 Hz update (using `model`, the newest
    /// model margin, if any) and whether the warning level changed with it.
    pub fn push(
        &mut self,
        s: &MeterSample,
        model: Option<&shimmy_core::estimator::model_margin::ModelMargin>,
    ) -> Option<(MarginUpdate, bool)> {
        let speed_ok = s.speed_mps.is_finite();
        if speed_ok {
            self.last_speed_mps = s.speed_mps;
        }
        let since_last = self.last_step.map(|last| s.step.wrapping_sub(last));
        self.steps += since_last.map_or(u64::from(s.step), u64::from);
        self.last_step = Some(s.step);
        let v = self.last_speed_mps;
        let sample = Sample {
            psi_l_rad: s.psi_l_rad,
            psi_r_rad: s.psi_r_rad,
            wheel: if speed_ok {
                WheelOrder::Speed {
                    speed_mps: s.speed_mps,
                    radius_m: self.radius_m,
                }
            } else {
                WheelOrder::None
            },
            damper_cmd: s.cmd_a,
        };
        let accel_mps2 = self.update_accel(since_last, v);
        self.cmd_peak_a = peak_command(self.cmd_peak_a, s.cmd_a);
        // the f64 time (soft-float here) only for the tenth sample that reports
        let steps = self.steps;
        let out = self
            .pipe
            .push_timed(&sample, v, accel_mps2, || step_time_s(steps), model)?;
        // the model task's damper-free model (c = 0), as its tracker
        let cmd_peak_a = core::mem::take(&mut self.cmd_peak_a);
        if let Some(m) = self.clock.observe(
            &self.update,
            out.report.t_s,
            v,
            0.0,
            cmd_peak_a,
            &out.meter.slow,
        ) {
            self.measurement = Some(m);
        }
        let changed = out.level != self.last_level;
        self.last_level = out.level;
        self.last_status = MarginStatus::of_report(&out.report);
        Some((out, changed))
    }

    /// One run of the meter task, the one body the RTIC app's `meter` task and the host's
    /// `pil::HostApp` both run: the model cycle `published` (its margin and the onset's
    /// sigma), then every sample `next` gives from the queue into [`Self::push`]. `on` hears of
    /// each sample before it is pushed and of each margin update after (with the sample it
    /// came from and whether the warning level changed). Returns the step of the last sample
    /// (the control step that spawned the run), `None` when the queue was empty.
    pub fn run(
        &mut self,
        published: Option<&Published>,
        mut next: impl FnMut() -> Option<MeterSample>,
        mut on: impl FnMut(&mut Self, MeterEvent<'_>),
    ) -> Option<u32> {
        if let Some(p) = published {
            self.set_margin_sigma(p.onset_sigma_mps);
        }
        let model = published.map(|p| p.margin);
        let mut last = None;
        while let Some(s) = next() {
            last = Some(s.step);
            on(self, MeterEvent::Sample(&s));
            if let Some((u, changed)) = self.push(&s, model.as_ref()) {
                on(self, MeterEvent::Update(&s, &u, changed));
            }
        }
        last
    }

    /// The newest due measurement of the online model update, for the model task
    /// ([`ModelTask::offer`]); None when none came since the last call.
    pub fn take_measurement(&mut self) -> Option<Measurement> {
        self.measurement.take()
    }

    /// The onset speed's one-sigma uncertainty the model task published with its margin
    /// ([`Published::onset_sigma_mps`]): `MarginLow` waits for confidence by it.
    pub fn set_margin_sigma(&mut self, sigma_mps: f32) {
        self.pipe.set_margin_sigma(sigma_mps);
    }

    /// The core's `AccelEstimator` with its time step from the step count, in f32: no f64 on
    /// the 1 kHz path, and exact at any age (one step is `DT_S` whether the drive is 1 s or 40
    /// days old). `v` is the newest trusted speed, finite on every sample after the first
    /// trusted one, so the step since the last update is the step since the last sample.
    fn update_accel(&mut self, steps_since_last: Option<u32>, v: f32) -> f32 {
        let dt_s = steps_since_last.filter(|n| *n > 0).map(|n| n as f32 * DT_S);
        self.accel.update_dt(dt_s, v)
    }
}

/// The model-margin tracker's configuration in the firmware: the core's tuned one with the
/// refresh period [`MODEL_REFRESH_S`].
pub fn model_config() -> ModelMarginConfig {
    ModelMarginConfig {
        period_s: MODEL_REFRESH_S,
        ..PipelineParams::default().model
    }
}

/// Float type of the tracker's eigen-solves and eigenvectors: f32 on the FPU (balanced; the
/// critical speeds still meet 0.05 km/h, `tests/tests/cross_crate/margin_model.rs`). f64 is software
/// floating point on the M4 (~20x the instructions); as a type parameter, only the f32 code is
/// linked into the image.
pub type ModelFloat = f32;

/// The vehicle the image is built for, chosen at compile time: the car (default) or, with the
/// cargo feature `model-truck`, the mining truck (`docs/mining-truck.md`). It is what the flash
/// store keeps and loads, the host link reads and writes, and the control, meter and model tasks
/// are configured from ([`BoardVehicle`]).
#[cfg(not(feature = "model-truck"))]
pub type ImageVehicle = Vehicle;
/// The vehicle the image is built for (`model-truck`: the mining truck).
#[cfg(feature = "model-truck")]
pub type ImageVehicle = shimmy_core::vehicles::truck::board::TruckVehicle;
/// States of the image's vehicle model.
#[cfg(not(feature = "model-truck"))]
pub const IMAGE_MODEL_STATES: usize = shimmy_core::vehicles::car::N_STATES;
/// States of the image's vehicle model.
#[cfg(feature = "model-truck")]
pub const IMAGE_MODEL_STATES: usize = shimmy_core::vehicles::truck::N_STATES;
/// The linear model of the image's model task.
pub type ImageModel = <ImageVehicle as BoardVehicle<IMAGE_MODEL_STATES>>::Model;

/// The tracker type of the model task on `M` (the image's: [`ImageModel`]).
pub type ModelTracker<M = ImageModel, const N: usize = IMAGE_MODEL_STATES> =
    ModelMarginTracker<ModelFloat, M, N>;

/// The model task re-evaluates the onset's sigma after every this many model updates (and
/// after the first): it costs as much as an update, and the sigma narrows over tens of
/// seconds, so 5 s of lag is harmless; every second the truck image would be over its CPU
/// budget (`cargo xtask bench`).
pub const SIGMA_EVERY: u32 = 5;

/// The updater type of the model task on `M`: the core's online model update with its
/// eigen-solves in [`ModelFloat`].
pub type BoardUpdater<M = ImageModel, const N: usize = IMAGE_MODEL_STATES> =
    ModelUpdater<M, N, ModelFloat>;

/// What a meter run ([`DataMargin::run`]) tells its task.
#[derive(Clone, Copy, Debug)]
pub enum MeterEvent<'a> {
    /// A sample from the queue, before it is pushed.
    Sample(&'a MeterSample),
    /// A margin update of that sample, and whether the warning level changed.
    Update(&'a MeterSample, &'a MarginUpdate, bool),
}

/// A completed model cycle as the model task publishes it to the meter task.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Published {
    /// The model margin of the cycle.
    pub margin: ModelMargin,
    /// The onset speed's one-sigma uncertainty after the latest model update, m/s (0 with the
    /// update off: the model is taken as known).
    pub onset_sigma_mps: f32,
}

/// The background model task: the core's incremental [`ModelMarginTracker`] on the linearised
/// plant *without* the MR damper (c = 0: the conservative envelope, the damper only adds
/// damping), for the image's [`ImageModel`], and the online model update
/// ([`shimmy_core::estimator::model_update`]) that moves the tracker's model to the vehicle
/// the meter measures.
pub struct ModelTask<M: UpdatableModel<N> = ImageModel, const N: usize = IMAGE_MODEL_STATES> {
    tracker: ModelTracker<M, N>,
    updater: BoardUpdater<M, N>,
    /// A measurement waiting for the tracker to finish its cycle.
    pending: Option<Measurement>,
    /// A measurement was applied since the last [`ModelTask::take_applied`].
    applied: bool,
    onset_sigma_mps: f32,
}

impl<M: UpdatableModel<N>, const N: usize> ModelTask<M, N> {
    /// The tracker for the model `model` with [`model_config`] and the model update `update`
    /// (a pipeline's [`PipelineParams::matched_update`]).
    pub fn new(model: M, update: ModelUpdateConfig) -> Self {
        ModelTask {
            tracker: ModelTracker::in_precision(model, model_config()),
            updater: BoardUpdater::in_precision(model, update),
            pending: None,
            applied: false,
            onset_sigma_mps: 0.0,
        }
    }

    /// Takes a due measurement of the meter task ([`DataMargin::take_measurement`]). It is
    /// applied between two tracker cycles, so a cycle runs on one model from start to end
    /// (on the target and in the host's application alike).
    pub fn offer(&mut self, m: Option<Measurement>) {
        if m.is_some() {
            self.pending = m;
        }
    }

    /// One unit of work (at most one eigen-solve, or the pending model update when the
    /// tracker is between cycles) at time `t_s` and speed `speed_mps`; the point when a cycle
    /// completes.
    pub fn step(&mut self, t_s: f64, speed_mps: f32) -> Option<ModelPoint> {
        if !self.tracker.busy() {
            if let Some(m) = self.pending.take() {
                self.apply(&m);
                self.applied = true;
            }
        }
        self.tracker.step(t_s, speed_mps, 0.0)
    }

    /// What the meter task gets of the completed cycle `pt`.
    pub fn publish(&self, pt: &ModelPoint) -> Published {
        Published {
            margin: pt.margin(),
            onset_sigma_mps: self.onset_sigma_mps,
        }
    }

    /// One measurement update (what [`Self::step`] does with an offered measurement between
    /// two cycles): the tracker's model becomes the updated one; after the first update and
    /// every [`SIGMA_EVERY`]th the onset's sigma is re-evaluated ([`Self::refresh_sigma`]).
    pub fn apply(&mut self, m: &Measurement) -> UpdateOutcome {
        let outcome = self.updater.apply(m);
        if outcome == UpdateOutcome::Updated {
            self.tracker.set_plant(self.updater.model());
            if self.updater.counts().0 % SIGMA_EVERY == 1 {
                self.refresh_sigma();
            }
        }
        outcome
    }

    /// The onset's sigma of the updated model at the latest cycle's onset (a second
    /// eigen-solve and the onset's gradient).
    pub fn refresh_sigma(&mut self) {
        let sigma = self
            .tracker
            .latest()
            .and_then(|pt| pt.margin().v_crit_onset_mps)
            .and_then(|v| self.updater.onset_sigma_mps(v, 0.0));
        self.onset_sigma_mps = sigma.map_or(0.0, |s| s as f32);
    }

    /// Whether a measurement was applied since the last call (the link reports the update
    /// after each).
    pub fn take_applied(&mut self) -> bool {
        core::mem::take(&mut self.applied)
    }

    /// The tracker (counters, latest point).
    pub fn tracker(&self) -> &ModelTracker<M, N> {
        &self.tracker
    }

    /// The online model update (parameters, uncertainty, diagnosis).
    pub fn updater(&self) -> &BoardUpdater<M, N> {
        &self.updater
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
                cmd_a: 0.0,
            };
            n += usize::from(d.push(&s, None).is_some());
        }
        assert_eq!(n, 10);
    }

    /// The reports' time stamps after 5 h of driving and across the wrap of the `u32` step
    /// count: every 100 Hz report exactly 10 ms after the previous one. With the old
    /// `step as f32 * DT_S` the spacing there is not 10 ms: the f32 second count has lost it.
    #[test]
    fn report_time_keeps_the_millisecond_over_days_and_across_the_step_wrap() {
        for start in [5 * 3600 * 1000u32, u32::MAX - 205] {
            let mut d = DataMargin::new().expect("default config");
            let mut times = heapless::Vec::<f64, 64>::new();
            for k in 0..400u32 {
                let s = MeterSample {
                    step: start.wrapping_add(k),
                    psi_l_rad: 0.0,
                    psi_r_rad: 0.0,
                    speed_mps: 12.0,
                    cmd_a: 0.0,
                };
                if let Some((u, _)) = d.push(&s, None) {
                    times.push(u.report.t_s).expect("capacity");
                }
            }
            assert_eq!(times.len(), 40);
            for w in times.windows(2) {
                assert!((w[1] - w[0] - 0.010).abs() < 1e-9, "start {start}: {w:?}");
            }
            // what the old f32 time did at the same point
            let old = |step: u32| step as f32 * DT_S;
            let gap = old(start.wrapping_add(10)) - old(start);
            assert!((gap - 0.010).abs() > 1e-5, "f32 gap {gap}");
        }
    }

    /// The acceleration's time step comes from the step count, so a speed ramp gives the same
    /// acceleration, bit for bit, at the start and 49.7 days in (across the `u32` wrap). The
    /// time difference of two f64 second stamps, as before, is not one step there.
    #[test]
    fn acceleration_is_the_same_at_any_age() {
        let accel_trace = |start: u32| {
            let mut d = DataMargin::new().expect("default config");
            (0..400u32)
                .map(|k| {
                    let s = MeterSample {
                        step: start.wrapping_add(k),
                        psi_l_rad: 0.0,
                        psi_r_rad: 0.0,
                        speed_mps: 12.0 + 0.001 * k as f32,
                        cmd_a: 0.0,
                    };
                    let _ = d.push(&s, None);
                    d.accel.accel_mps2().to_bits()
                })
                .collect::<Vec<_>>()
        };
        let young = accel_trace(0);
        assert_eq!(young, accel_trace(u32::MAX - 205));
        assert!(
            f32::from_bits(young[399]) > 0.5,
            "the ramp's acceleration shows"
        );
        // what the f64 stamps' difference gives 49.7 days in
        let n = u64::from(u32::MAX) - 100;
        let dt_old = (step_time_s(n + 1) - step_time_s(n)) as f32;
        assert_ne!(dt_old, DT_S, "old dt {dt_old}");
    }

    /// The meter runs after exactly the samples on which the data path answers, so every
    /// run reports once and the report of sample k reaches step k + 1.
    #[test]
    fn the_meter_runs_on_the_samples_that_report() {
        let mut d = DataMargin::new().expect("default config");
        let mut cadence = MeterCadence::default();
        let mut queue = Vec::new();
        let (mut runs, mut reports) = (0, 0);
        for k in 0..1000u32 {
            queue.push(MeterSample {
                step: k,
                psi_l_rad: 0.0,
                psi_r_rad: 0.0,
                speed_mps: 12.0,
                cmd_a: 0.0,
            });
            if !cadence.tick() {
                continue;
            }
            runs += 1;
            let last = queue.len() - 1;
            for (i, s) in queue.drain(..).enumerate() {
                if d.push(&s, None).is_some() {
                    assert_eq!(
                        i, last,
                        "run after step {k}: the report is the last sample's"
                    );
                    reports += 1;
                }
            }
        }
        assert_eq!((runs, reports), (100, 100));
    }

    #[test]
    fn model_margin_inside_and_below_the_window() {
        use shimmy_core::units::kmh_to_mps;
        use shimmy_core::vehicles::car::PlantParams;
        let mut m = ModelTask::new(PlantParams::nominal(), ModelUpdateConfig::OFF);
        let mut run = |t: f64, v: f64| {
            for _ in 0..200 {
                if let Some(p) = m.step(t, v as f32) {
                    return p.margin();
                }
            }
            panic!("no cycle within 200 calls");
        };
        // Nominal window without damper: 29.35 -> 84.15 km/h. At 20 km/h the onset is above.
        let r = run(0.0, kmh_to_mps(20.0));
        assert!(r.valid && r.zeta > 0.0);
        let vc = r.v_crit_onset_mps.expect("onset above");
        assert!((vc - kmh_to_mps(29.35)).abs() < kmh_to_mps(0.05), "{vc}");
        // Inside the window the shimmy mode is unstable: the margin is zero (onset <= V).
        let r = run(f64::from(MODEL_REFRESH_S), kmh_to_mps(50.0));
        assert!(r.valid && r.zeta < 0.0);
        assert!(r.v_crit_onset_mps.is_some_and(|v| v <= kmh_to_mps(50.0)));
    }
}
