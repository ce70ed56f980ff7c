//! The seam between the firmware and the core controller, sensor validation, and the health
//! counters of the control loop.
//!
//! Per control step (1 kHz): [`crate::sensors::Sensors::sample`] -> [`validate`] ->
//! [`ControlStep::step`] (the core controller plugs in here) -> coil current command ->
//! [`crate::drivers::coil_pwm::CoilDriver::set_current_a`]. Without a complete, valid input the
//! controller is not called and the coil gets the fail-safe current.

use crate::drivers::wheel_speed::SpeedStatus;
use crate::sensors::{SampleSet, SensorFault};

/// Validated inputs of one control step (the controller sees only these).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ControlInput {
    /// Control step number since boot.
    pub step: u32,
    /// Control period [s].
    pub dt_s: f32,
    /// Left wheel yaw [rad], relative to straight ahead.
    pub psi_l_rad: f32,
    /// Right wheel yaw [rad].
    pub psi_r_rad: f32,
    /// Vehicle speed [m/s].
    pub speed_mps: f32,
    /// Measured coil current [A].
    pub coil_current_a: f32,
}

/// What the firmware calls once per control step with validated inputs. Returns the coil
/// current command [A]; NaN or out-of-range values are handled by the coil driver (NaN: fail-
/// safe current, range: clamped). The application uses
/// [`crate::monitoring::CoreController`] (the core's ASMC).
pub trait ControlStep {
    /// One 1 kHz step.
    fn step(&mut self, input: &ControlInput) -> f32;
}

/// A fixed current (tests, and the simplest fail-safe law).
#[derive(Clone, Copy, Debug)]
pub struct FixedCurrent {
    /// The current it commands [A].
    pub current_a: f32,
}

impl ControlStep for FixedCurrent {
    fn step(&mut self, _input: &ControlInput) -> f32 {
        self.current_a
    }
}

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
    /// Steps in which the coil got the fail-safe current instead of the controller's command.
    pub failsafe_steps: u32,
    /// Encoder SPI bus errors.
    pub enc_bus: u32,
    /// Encoder responses with wrong parity.
    pub enc_parity: u32,
    /// Encoder responses with the error flag set.
    pub enc_error_flag: u32,
    /// Encoder samples rejected as implausible jumps.
    pub enc_jump: u32,
    /// Speed periods rejected as implausible (value held).
    pub speed_implausible: u32,
    /// Coil-current ADC errors or saturation.
    pub current_faults: u32,
    /// 100 Hz meter requests dropped because the meter task was still busy.
    pub estimator_busy: u32,
    /// 10 Hz model-margin requests dropped because the model task was still busy.
    pub model_busy: u32,
    /// Meter samples dropped because the SPSC queue to the meter task was full.
    pub meter_dropped: u32,
    /// PWM write errors.
    pub pwm_errors: u32,
}

/// A step whose entry latency exceeds this many ticks (1 tick = 1 us) counts as a late start.
pub const LATE_START_TICKS: u32 = 100;

impl Health {
    fn count(&mut self, f: SensorFault) {
        let c = match f {
            SensorFault::Bus => &mut self.enc_bus,
            SensorFault::Parity => &mut self.enc_parity,
            SensorFault::ErrorFlag(_) => &mut self.enc_error_flag,
            SensorFault::Jump => &mut self.enc_jump,
            SensorFault::Saturated => &mut self.current_faults,
        };
        *c = c.saturating_add(1);
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
            self.late_starts = self.late_starts.saturating_add(1);
        }
        if wrapped {
            self.overruns = self.overruns.saturating_add(1);
        }
    }
}

/// Validates one sample set; counts each fault. `None`: the step must use the fail-safe.
pub fn validate(s: &SampleSet, step: u32, dt_s: f32, h: &mut Health) -> Option<ControlInput> {
    if s.speed.status == SpeedStatus::Implausible {
        h.speed_implausible = h.speed_implausible.saturating_add(1);
    }
    let mut ok = true;
    let mut take = |r: Result<f32, SensorFault>, h: &mut Health| match r {
        Ok(v) if v.is_finite() => v,
        Ok(_) => {
            ok = false;
            0.0
        }
        Err(f) => {
            h.count(f);
            ok = false;
            0.0
        }
    };
    let psi_l_rad = take(s.psi_l_rad, h);
    let psi_r_rad = take(s.psi_r_rad, h);
    let coil_current_a = match s.coil_current_a {
        Ok(v) => v,
        Err(_) => {
            // The measured current is not needed for a safe command; count it and go on.
            h.current_faults = h.current_faults.saturating_add(1);
            f32::NAN
        }
    };
    if !ok {
        return None;
    }
    Some(ControlInput {
        step,
        dt_s,
        psi_l_rad,
        psi_r_rad,
        speed_mps: s.speed.speed_mps,
        coil_current_a,
    })
}

/// One control decision: validated input -> controller, otherwise the fail-safe (NaN, which
/// the coil driver turns into [`crate::drivers::coil_pwm::FAILSAFE_CURRENT_A`]).
pub fn decide<C: ControlStep>(
    ctrl: &mut C,
    s: &SampleSet,
    step: u32,
    dt_s: f32,
    h: &mut Health,
) -> (f32, Option<ControlInput>) {
    match validate(s, step, dt_s, h) {
        Some(input) => {
            let cmd = ctrl.step(&input);
            if cmd.is_finite() {
                (cmd, Some(input))
            } else {
                h.failsafe_steps = h.failsafe_steps.saturating_add(1);
                (f32::NAN, Some(input))
            }
        }
        None => {
            h.failsafe_steps = h.failsafe_steps.saturating_add(1);
            (f32::NAN, None)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drivers::wheel_speed::SpeedReading;

    fn good() -> SampleSet {
        SampleSet {
            psi_l_rad: Ok(0.01),
            psi_r_rad: Ok(-0.01),
            speed: SpeedReading {
                speed_mps: 20.0,
                status: SpeedStatus::Valid,
            },
            coil_current_a: Ok(1.0),
        }
    }

    struct Nan;
    impl ControlStep for Nan {
        fn step(&mut self, _: &ControlInput) -> f32 {
            f32::NAN
        }
    }

    #[test]
    fn valid_input_reaches_the_controller() {
        let mut h = Health::default();
        let mut c = FixedCurrent { current_a: 0.7 };
        let (cmd, input) = decide(&mut c, &good(), 5, 1e-3, &mut h);
        assert_eq!(cmd, 0.7);
        assert_eq!(input.unwrap().psi_l_rad, 0.01);
        assert_eq!(h, Health::default());
    }

    #[test]
    fn each_fault_is_counted_and_fails_safe() {
        let mut h = Health::default();
        let mut c = FixedCurrent { current_a: 0.7 };
        let mut s = good();
        s.psi_l_rad = Err(SensorFault::Parity);
        s.psi_r_rad = Err(SensorFault::ErrorFlag(4));
        let (cmd, input) = decide(&mut c, &s, 5, 1e-3, &mut h);
        assert!(cmd.is_nan() && input.is_none());
        assert_eq!(
            (h.enc_parity, h.enc_error_flag, h.failsafe_steps),
            (1, 1, 1)
        );
        // A NaN from the controller also fails safe, and is counted.
        let (cmd, _) = decide(&mut Nan, &good(), 6, 1e-3, &mut h);
        assert!(cmd.is_nan());
        assert_eq!(h.failsafe_steps, 2);
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
