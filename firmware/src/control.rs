//! The seam between the drivers and the core's supervised controller, and the health counters
//! of the control loop.
//!
//! Per control step (1 kHz): [`crate::sensors::Sensors::sample`] -> [`raw_frame`] (what only the
//! firmware knows: SPI errors, AS5047P parity / error flag, the tone-wheel decoding, ADC
//! errors; each counted) -> `shimmy_core::supervisor::safe_controller::SafeController::step`
//! (the one validation policy: range, rate, stuck, left/right agreement, speed plausibility, coil
//! checks, timing; fault records, Normal / Degraded / FailSafe with recovery hysteresis; the
//! core controller; the final clamp and slew limit) -> coil current command -> [`drive_coil`]
//! (closed current loop on the measured current). [`supervised_step`] is that chain up to the
//! command; [`ControlTask::run`] is the control task's body around it (the same on the board
//! and in the host's `pil::HostApp`).

use crate::drivers::coil_pwm::CoilDriver;
use crate::drivers::wheel_speed::SpeedStatus;
use crate::monitoring::{MeterCadence, MeterSample};
use crate::sensors::{SampleSet, SensorFault};
use embedded_hal::pwm::SetDutyCycle;
use rtic_core::Mutex;
use shimmy_core::supervisor::frame::{EncoderReading, MarginStatus, RawFrame};
use shimmy_core::supervisor::policy::Mode;
use shimmy_core::supervisor::safe_controller::{SafeController, SafeOutput};

/// The independent watchdog's prescaler (LSI / 4) and reload (80 ticks): fed only when a control
/// step completes, so the coil keeps its last command for at most [`WATCHDOG_TIMEOUT_MAX_S`]
/// when steps stop completing; then the MCU resets and boots with the fail-safe current.
pub const WATCHDOG_PRESCALER: u16 = 4;
/// See [`WATCHDOG_PRESCALER`].
pub const WATCHDOG_RELOAD_TICKS: u16 = 80;
/// The watchdog's timeout at the LSI's slowest 17 kHz (its fastest, 47 kHz, gives 6.8 ms), s.
pub const WATCHDOG_TIMEOUT_MAX_S: f32 =
    (WATCHDOG_PRESCALER as f32) * (WATCHDOG_RELOAD_TICKS as f32) / 17_000.0;

/// Counters of the control loop. Every fault increments one; nothing is silent. Logged by the
/// telemetry and at the end of a QEMU run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(target_os = "none", derive(defmt::Format))]
pub struct Health {
    /// Completed control steps.
    pub steps: u32,
    /// Steps that started late (entry latency above [`LATE_START_TICKS`]).
    pub late_starts: u32,
    /// Steps that ran past their period (the next period's tick arrived before they ended).
    pub overruns: u32,
    /// Largest entry latency seen [timer ticks].
    pub max_latency_ticks: u32,
    /// Longest step seen (entry to exit) [timer ticks].
    pub max_step_ticks: u32,
    /// Steps the supervisor spent in FailSafe (fixed safe current, controller ignored).
    pub failsafe_steps: u32,
    /// Steps the supervisor spent in Degraded (controller runs, possibly with a current floor).
    pub degraded_steps: u32,
    /// Supervisor mode changes.
    pub mode_changes: u32,
    /// Fault activations (a fault kind entering the supervisor's active set).
    pub faults_raised: u32,
    /// The supervisor's active faults now (bit i = `FaultKind::ALL[i]`).
    pub active_faults: u32,
    /// Encoder SPI bus errors.
    pub enc_bus: u32,
    /// Encoder responses with wrong parity.
    pub enc_parity: u32,
    /// Encoder responses with the error flag set.
    pub enc_error_flag: u32,
    /// Wheel-speed periods rejected by the tone-wheel decoder (value held).
    pub speed_implausible: u32,
    /// Coil-current ADC errors or saturation.
    pub current_faults: u32,
    /// 100 Hz meter requests that found the meter task still running.
    pub estimator_busy: u32,
    /// Meter samples dropped because the SPSC queue to the meter task was full.
    pub meter_dropped: u32,
    /// Completed model-margin cycles (background loop).
    pub model_cycles: u32,
    /// Model cycles that took longer than their refresh period (the tracker's overruns).
    pub model_late: u32,
    /// PWM write errors.
    pub pwm_errors: u32,
}

/// A step whose entry latency exceeds this many ticks (1 tick = 1 us) counts as a late start.
pub const LATE_START_TICKS: u32 = 100;

fn bump(c: &mut u32) {
    *c = c.saturating_add(1);
}

impl Health {
    fn count(&mut self, f: SensorFault) {
        bump(match f {
            SensorFault::Bus => &mut self.enc_bus,
            SensorFault::Parity => &mut self.enc_parity,
            SensorFault::ErrorFlag(_) => &mut self.enc_error_flag,
            SensorFault::Saturated => &mut self.current_faults,
            // Unwrap ambiguity (a half-turn step): the NaN angle is the supervisor's fault.
            SensorFault::Jump => return,
        });
    }

    /// Records the timing of one step: `latency_ticks` from the period start to the step's
    /// entry, `duration_ticks` from entry to exit, `wrapped`: the timer's update event fired
    /// again before the exit (the step ran into the next period).
    pub fn record_timing(&mut self, latency_ticks: u32, duration_ticks: u32, wrapped: bool) {
        self.max_latency_ticks = self.max_latency_ticks.max(latency_ticks);
        if !wrapped {
            self.max_step_ticks = self.max_step_ticks.max(duration_ticks);
        }
        if latency_ticks > LATE_START_TICKS {
            bump(&mut self.late_starts);
        }
        if wrapped {
            bump(&mut self.overruns);
        }
    }

    /// Counts one completed control step; `dropped`: its meter sample found the queue full.
    #[inline(always)]
    pub fn record_step(&mut self, dropped: bool) {
        self.meter_dropped += u32::from(dropped);
        self.steps += 1;
    }

    /// Records the supervisor's verdict of one step.
    pub fn record_verdict(&mut self, out: &SafeOutput) {
        let v = &out.verdict;
        match v.mode {
            Mode::Normal => {}
            Mode::Degraded => bump(&mut self.degraded_steps),
            Mode::FailSafe => bump(&mut self.failsafe_steps),
        }
        let bits = v.faults.bits();
        self.faults_raised = self
            .faults_raised
            .saturating_add((bits & !self.active_faults).count_ones());
        self.active_faults = bits;
    }
}

/// One encoder result as the supervisor's reading: the bus and protocol outcome of the driver
/// (the angle is NaN when no angle was received, so the supervisor also records `*-nonfinite`
/// next to `*-read` / `*-flag`).
pub fn encoder_reading(r: Result<f32, SensorFault>) -> EncoderReading {
    let mut e = EncoderReading::ok(f32::NAN);
    match r {
        Ok(v) => e.angle_rad = v,
        Err(SensorFault::Parity) => e.parity_ok = false,
        Err(SensorFault::ErrorFlag(_)) => e.error_flag = true,
        Err(SensorFault::Bus | SensorFault::Saturated) => e.read_ok = false,
        // No angle (the supervisor sees NaN: `*NonFinite`).
        Err(SensorFault::Jump) => {}
    }
    e
}

/// The raw frame of one sample set: the driver results decoded into the supervisor's input,
/// time-stamped by the free-running capture timer; the driver-level faults (bus, parity,
/// error flag, tone-wheel glitch, ADC) are counted here, everything else is judged by the
/// supervisor. `coil_drive_a` is the coil driver's drive over the period just sampled
/// ([`CoilDriver::drive_a`](crate::drivers::coil_pwm::CoilDriver::drive_a)).
pub fn raw_frame(s: &SampleSet, coil_drive_a: Option<f32>, h: &mut Health) -> RawFrame {
    for r in [s.psi_l_rad, s.psi_r_rad] {
        if let Err(f) = r {
            h.count(f);
        }
    }
    let speed_valid = match s.speed.status {
        SpeedStatus::Valid | SpeedStatus::Standstill => true,
        // The decoder rejected one period and holds the last accepted value (a missing or
        // extra tooth is a decoding error, like an SPI parity error).
        SpeedStatus::Implausible => {
            bump(&mut h.speed_implausible);
            true
        }
        SpeedStatus::Starting => false,
    };
    let coil_current_a = match s.coil_current_a {
        Ok(v) => v,
        Err(f) => {
            h.count(f);
            // The supervisor raises `CoilSensor` (advisory: the coil is driven open loop).
            f32::NAN
        }
    };
    RawFrame {
        t_us: s.t_us,
        left: encoder_reading(s.psi_l_rad),
        right: encoder_reading(s.psi_r_rad),
        speed_mps: s.speed.speed_mps,
        speed_valid,
        coil_current_a: Some(coil_current_a),
        coil_drive_a,
    }
}

/// Applies one step's output to the coil: off when the supervisor reports the coil open or
/// shorted (`damper_available == false`), otherwise the command, closed loop on the trusted
/// measured current of the step (open loop while the measurement is not trusted).
pub fn drive_coil<P: SetDutyCycle>(
    coil: &mut CoilDriver<P>,
    out: &SafeOutput,
) -> Result<(), P::Error> {
    if out.verdict.damper_available {
        coil.set_current_a(
            out.current_cmd_a,
            out.validated.coil_current_a,
            out.validated.dt_s,
        )
        .map(|_| ())
    } else {
        coil.off()
    }
}

/// One control step: drivers' results -> [`raw_frame`] -> [`SafeController::step`]. The
/// command (`current_cmd_a` of the output) is finite and inside the coil limits whatever the
/// sensors delivered; `margin` is the validity of the newest margin report.
pub fn supervised_step(
    ctrl: &mut SafeController,
    s: &SampleSet,
    coil_drive_a: Option<f32>,
    margin: MarginStatus,
    h: &mut Health,
) -> SafeOutput {
    let frame = raw_frame(s, coil_drive_a, h);
    let before = ctrl.supervisor().mode();
    let out = ctrl.step(&frame, margin);
    if out.verdict.mode != before {
        bump(&mut h.mode_changes);
    }
    h.record_verdict(&out);
    out
}

/// The control task's own state: the supervised controller, the number of the next step and
/// the meter task's cadence.
pub struct ControlTask {
    ctrl: SafeController,
    step: u32,
    cadence: MeterCadence,
}

/// What one control step did, for the task around it.
#[derive(Clone, Copy, Debug)]
pub struct ControlStep {
    /// The step's number.
    pub step: u32,
    /// The supervised controller's output.
    pub out: SafeOutput,
    /// The step's meter sample found the queue full (count it: [`Health::record_step`]).
    pub dropped: bool,
    /// The meter task is due after this step ([`MeterCadence`]).
    pub meter_due: bool,
}

impl ControlTask {
    /// The task around `ctrl`, before its first step.
    pub fn new(ctrl: SafeController) -> Self {
        ControlTask {
            ctrl,
            step: 0,
            cadence: MeterCadence::default(),
        }
    }

    /// The number of the next step.
    pub fn step_count(&self) -> u32 {
        self.step
    }

    /// The supervised controller (its supervisor's faults).
    pub fn controller(&self) -> &SafeController {
        &self.ctrl
    }

    /// The supervised controller, mutably (fault records and events).
    pub fn controller_mut(&mut self) -> &mut SafeController {
        &mut self.ctrl
    }

    /// One control step on the sensors' `samples`, the one sequence the RTIC app's `control`
    /// task and the host's `pil::HostApp` both run: [`supervised_step`] (`health` locked for it
    /// only), `actuate` on the output at once (the coil on the board), the step's
    /// [`MeterSample`] to the meter task's queue (`enqueue`: false when it is full), the meter
    /// task's cadence. The caller counts the step ([`Health::record_step`]) with its timing,
    /// which ends only after the meter task is spawned.
    #[inline(always)]
    pub fn run(
        &mut self,
        samples: &SampleSet,
        coil_drive_a: Option<f32>,
        margin: MarginStatus,
        health: &mut impl Mutex<T = Health>,
        actuate: impl FnOnce(&SafeOutput),
        enqueue: impl FnOnce(MeterSample) -> bool,
    ) -> ControlStep {
        let step = self.step;
        let ctrl = &mut self.ctrl;
        let out = health.lock(|h| supervised_step(ctrl, samples, coil_drive_a, margin, h));
        actuate(&out);
        let dropped = !enqueue(MeterSample::of(step, &out));
        let meter_due = self.cadence.tick();
        self.step = step.wrapping_add(1);
        ControlStep {
            step,
            out,
            dropped,
            meter_due,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drivers::wheel_speed::SpeedReading;
    use crate::monitoring::safe_controller;
    use shimmy_core::control::actuator::FAILSAFE_CURRENT_A;
    use shimmy_core::supervisor::faults::FaultKind;

    fn good(k: u32) -> SampleSet {
        let y = 0.01 * libm::sinf(k as f32 * 0.05);
        SampleSet {
            t_us: k.wrapping_mul(1000),
            psi_l_rad: Ok(y),
            psi_r_rad: Ok(y * 0.98),
            speed: SpeedReading {
                speed_mps: 20.0,
                status: SpeedStatus::Valid,
            },
            coil_current_a: Ok(1.0),
        }
    }

    /// A healthy coil (L/R = 1/190 s) on the command of the last step, over one 1 ms step.
    fn lagged_coil(i: &mut f32, cmd_a: f32) -> f32 {
        *i += (cmd_a - *i) * (1.0 - libm::expf(-0.19));
        *i
    }

    #[test]
    fn driver_faults_map_onto_the_supervisor_reading() {
        assert!(!encoder_reading(Err(SensorFault::Parity)).parity_ok);
        assert!(encoder_reading(Err(SensorFault::ErrorFlag(2))).error_flag);
        assert!(!encoder_reading(Err(SensorFault::Bus)).read_ok);
        let ok = encoder_reading(Ok(0.1));
        assert!(ok.read_ok && ok.parity_ok && !ok.error_flag && ok.angle_rad == 0.1);
        let mut h = Health::default();
        let mut s = good(0);
        s.psi_l_rad = Err(SensorFault::Parity);
        s.speed.status = SpeedStatus::Starting;
        s.coil_current_a = Err(SensorFault::Saturated);
        let f = raw_frame(&s, None, &mut h);
        assert_eq!(f.t_us, 0);
        assert!(!f.speed_valid && f.coil_current_a.is_some_and(f32::is_nan));
        assert_eq!((h.enc_parity, h.current_faults), (1, 1));
    }

    /// One parity error on one encoder: Degraded (the other stands in, current floor); on both:
    /// FailSafe at the core's fail-safe current; recovery after the core's hysteresis.
    #[test]
    fn parity_errors_drive_the_core_supervisor_and_it_recovers() {
        let mut c = safe_controller();
        let mut h = Health::default();
        let mut modes = Vec::new();
        let mut coil = 0.0;
        for k in 0..4000u32 {
            let mut s = good(k);
            s.coil_current_a = Ok(lagged_coil(&mut coil, c.last_command_a()));
            if k == 100 {
                s.psi_l_rad = Err(SensorFault::Parity);
            }
            if k == 300 {
                s.psi_r_rad = Err(SensorFault::ErrorFlag(2));
            }
            let o = supervised_step(&mut c, &s, None, MarginStatus::NotUsed, &mut h);
            assert!(o.current_cmd_a.is_finite());
            if modes.last() != Some(&o.verdict.mode) {
                modes.push(o.verdict.mode);
            }
            if (310..1000).contains(&k) {
                // Slewed towards the fail-safe current.
                assert_eq!(o.verdict.mode, Mode::FailSafe);
                assert_eq!(o.verdict.safe_current_a, Some(FAILSAFE_CURRENT_A));
            }
        }
        assert_eq!(
            modes,
            [
                Mode::Normal,
                Mode::Degraded,
                Mode::FailSafe,
                Mode::Degraded,
                Mode::Normal
            ]
        );
        assert_eq!((h.enc_parity, h.enc_error_flag, h.mode_changes), (1, 1, 4));
        // Each protocol error raises `*-flag` and `*-nonfinite` (the frame carries no angle).
        assert_eq!(h.faults_raised, 4);
        assert_eq!(h.active_faults, 0);
        assert_eq!(c.supervisor().record(FaultKind::LeftFlag).activations, 1);
        assert_eq!(c.supervisor().record(FaultKind::RightFlag).activations, 1);
        // Recovery times: left clears 1 s after step 100, right 1 s after step 300.
        assert_eq!(h.degraded_steps + h.failsafe_steps, 1300 - 100 + 1);
    }

    /// The frame time stamp is the capture timer's, not the step count: a control period that
    /// comes 6 ms late (the 1 kHz interrupt blocked) raises `timing` and FailSafe; on time it
    /// raises nothing. (With the step count as the time stamp the supervisor could not see it.)
    #[test]
    fn a_late_period_is_a_timing_fault() {
        let mut c = safe_controller();
        let mut h = Health::default();
        let mut t_us = 0u32;
        let mut last = None;
        let mut coil = 0.0;
        for k in 0..1200u32 {
            t_us += if k == 1100 { 6000 } else { 1000 };
            let mut s = SampleSet { t_us, ..good(k) };
            s.coil_current_a = Ok(lagged_coil(&mut coil, c.last_command_a()));
            let o = supervised_step(&mut c, &s, None, MarginStatus::NotUsed, &mut h);
            if k < 1100 {
                assert!(o.verdict.faults.is_empty(), "k={k} {:?}", o.verdict);
            }
            last = Some(o);
        }
        let o = last.unwrap();
        assert!(o.verdict.faults.contains(FaultKind::Timing));
        assert_eq!(o.verdict.mode, Mode::FailSafe);
        assert_eq!(c.supervisor().missed_samples(), 5);
    }

    #[test]
    fn timing_counters() {
        let mut h = Health::default();
        h.record_timing(3, 47, false);
        assert_eq!((h.late_starts, h.overruns), (0, 0));
        h.record_timing(LATE_START_TICKS + 1, 299, false);
        assert_eq!((h.late_starts, h.overruns), (1, 0));
        h.record_timing(5, 20, true);
        assert_eq!(h.overruns, 1);
        assert_eq!(h.max_latency_ticks, LATE_START_TICKS + 1);
        assert_eq!(h.max_step_ticks, 299);
    }
}
