//! MR damper coil drive: a PWM channel (`embedded_hal::pwm::SetDutyCycle`) into a low-side
//! switch with a freewheeling diode; the coil's L/R filters the PWM into a current.
//!
//! The current is **closed loop** whenever the shunt measurement is trusted: the core's PI
//! current controller (`shimmy_core::control::actuator::CoilDriver`: feed-forward I R plus a
//! PI on the current error, gains by pole-zero cancellation of the coil's L/R, conditional
//! integration and a clamped integrator as anti-windup). So a hot coil (+50 % R) or a 14 V
//! supply still carries the commanded current; the open-loop map d = I R / V (nominal R and V)
//! is only the fallback while no trusted measurement exists (before the first sample, a
//! `coil-sensor` fault), and there it is off by the ratio of the true to the nominal R / V.
//! The board does not measure the supply voltage, so the integrator absorbs its deviation.
//!
//! # Fail-safe policy
//! - Out of reset (before the firmware runs, during a reset or a watchdog reset) the PWM pin is
//!   high-impedance and the gate driver's pull-down holds the switch off: **coil off**, the damper
//!   gives its passive (zero-field) damping. This cannot be changed by software.
//! - As soon as the driver is constructed, and whenever the control loop has no valid command
//!   (a NaN), it drives [`FAILSAFE_CURRENT_A`]: the supervisor's fail-safe current, chosen from
//!   the stability analysis (`shimmy_core::control::actuator::FAILSAFE_CURRENT_A`, checked by
//!   `tests/tests/cross_crate/failsafe_current.rs`).
//! - [`CoilDriver::off`] (duty 0, integrator cleared) when the supervisor reports the coil
//!   open or shorted: driving current into a short only heats it.

use embedded_hal::pwm::SetDutyCycle;
use shimmy_core::control::actuator::{self, CoilParams, DriveReport};

/// Coil current commanded while the loop has no valid command, A: the supervisor's fail-safe
/// current (one definition, in core).
pub const FAILSAFE_CURRENT_A: f32 = actuator::FAILSAFE_CURRENT_A;

/// Electrical data of the coil drive (nominal values: the feed-forward and the loop gains).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoilConfig {
    /// Coil resistance (nominal, hot), ohm.
    pub coil_ohm: f32,
    /// Coil inductance, H.
    pub coil_h: f32,
    /// Supply voltage of the switch (nominal), V.
    pub supply_v: f32,
    /// Largest current the coil may carry, A (thermal / damper saturation).
    pub max_current_a: f32,
    /// Current-loop bandwidth, rad/s.
    pub loop_bandwidth_radps: f32,
}

impl CoilConfig {
    /// The core's coil parameters.
    pub const fn params(&self) -> CoilParams {
        CoilParams {
            r_coil_ohm: self.coil_ohm,
            l_coil_h: self.coil_h,
            v_supply_v: self.supply_v,
            loop_bandwidth_radps: self.loop_bandwidth_radps,
        }
    }
}

/// Nominal sample period of [`CoilDriver::fail_safe`], s (the control period).
const PERIOD_S: f32 = 1e-3;

/// The coil driver.
pub struct CoilDriver<P> {
    inner: actuator::CoilDriver<P>,
    cfg: CoilConfig,
    commanded_a: f32,
}

impl<P: SetDutyCycle> CoilDriver<P> {
    /// Takes the PWM channel and immediately drives the fail-safe current (open loop: nothing
    /// is measured yet).
    pub fn new(pwm: P, cfg: CoilConfig) -> Result<Self, P::Error> {
        let mut d = CoilDriver {
            inner: actuator::CoilDriver::new(pwm, cfg.params()),
            cfg,
            commanded_a: 0.0,
        };
        d.fail_safe()?;
        Ok(d)
    }

    /// Takes the PWM channel with the coil off (a coil fault latched before the reset: no
    /// current into a coil known to be shorted).
    pub fn new_off(pwm: P, cfg: CoilConfig) -> Result<Self, P::Error> {
        let mut d = CoilDriver {
            inner: actuator::CoilDriver::new(pwm, cfg.params()),
            cfg,
            commanded_a: 0.0,
        };
        d.off()?;
        Ok(d)
    }

    /// Open-loop steady-state duty for a current at the nominal R and V: I R / V, for the
    /// current clamped to [0, max current].
    pub fn duty_for(&self, current_a: f32) -> f32 {
        self.cfg
            .params()
            .open_loop_duty(clamp_current(current_a, self.cfg.max_current_a))
    }

    /// Commands a coil current, A, one control period `dt_s` long. `measured_a`: the trusted
    /// coil current of this step (closes the loop); `None` drives open loop. NaN commands the
    /// fail-safe current; values outside [0, max] are clamped (a semi-active damper cannot use
    /// negative current).
    pub fn set_current_a(
        &mut self,
        current_a: f32,
        measured_a: Option<f32>,
        dt_s: f32,
    ) -> Result<DriveReport, P::Error> {
        let i = if current_a.is_nan() {
            FAILSAFE_CURRENT_A
        } else {
            current_a
        };
        let i = clamp_current(i, self.cfg.max_current_a);
        let r = self.inner.drive(i, measured_a, dt_s)?;
        self.commanded_a = i;
        Ok(r)
    }

    /// Drives the fail-safe current (open loop).
    pub fn fail_safe(&mut self) -> Result<DriveReport, P::Error> {
        self.set_current_a(FAILSAFE_CURRENT_A, None, PERIOD_S)
    }

    /// Coil off: duty 0, the current loop's integrator cleared.
    pub fn off(&mut self) -> Result<(), P::Error> {
        self.commanded_a = 0.0;
        self.inner.off()
    }

    /// The drive now: the steady current the written duty pushes through the nominal coil,
    /// A (the supervisor's `RawFrame::coil_drive_a`).
    pub fn drive_a(&self) -> f32 {
        self.inner.drive_a()
    }

    /// The current last commanded (after clamping), A.
    pub fn commanded_a(&self) -> f32 {
        self.commanded_a
    }

    /// Gives the PWM channel back.
    pub fn release(self) -> P {
        self.inner.release()
    }
}

fn clamp_current(i: f32, max: f32) -> f32 {
    if i.is_nan() {
        return 0.0;
    }
    // Not f32::clamp: its (unreachable) panic message for a NaN bound links core::fmt's float
    // formatting into the image (~9 KiB of flash).
    i.max(0.0).min(max)
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_hal_mock::eh1::pwm::{Mock, Transaction};

    fn cfg() -> CoilConfig {
        CoilConfig {
            coil_ohm: 4.0,
            coil_h: 4.0 / 190.0,
            supply_v: 12.0,
            max_current_a: 2.0,
            loop_bandwidth_radps: 2.0 * core::f32::consts::PI * 50.0,
        }
    }

    #[test]
    fn default_duty_is_the_failsafe_current() {
        // 2 A * 4 ohm / 12 V = 2/3 of 1000 = 667.
        let expect = (FAILSAFE_CURRENT_A * 4.0 / 12.0 * 1000.0).round() as u16;
        let mut pwm = Mock::new(&[
            Transaction::max_duty_cycle(1000),
            Transaction::set_duty_cycle(expect),
        ]);
        let d = CoilDriver::new(pwm.clone(), cfg()).unwrap();
        assert_eq!(d.commanded_a(), FAILSAFE_CURRENT_A);
        pwm.done();
    }

    #[test]
    fn clamps_nan_and_off() {
        let fs = (FAILSAFE_CURRENT_A * 4.0 / 12.0 * 1000.0).round() as u16;
        let mut pwm = Mock::new(&[
            Transaction::max_duty_cycle(1000),
            Transaction::set_duty_cycle(fs),
            // 5 A is clamped to 2 A: 2 * 4 / 12 = 0.667.
            Transaction::max_duty_cycle(1000),
            Transaction::set_duty_cycle(667),
            // Negative: 0.
            Transaction::max_duty_cycle(1000),
            Transaction::set_duty_cycle(0),
            // NaN: fail-safe.
            Transaction::max_duty_cycle(1000),
            Transaction::set_duty_cycle(fs),
            // Off.
            Transaction::set_duty_cycle(0),
        ]);
        let mut d = CoilDriver::new(pwm.clone(), cfg()).unwrap();
        d.set_current_a(5.0, None, 1e-3).unwrap();
        assert_eq!(d.commanded_a(), 2.0);
        d.set_current_a(-1.0, None, 1e-3).unwrap();
        assert_eq!(d.commanded_a(), 0.0);
        d.set_current_a(f32::NAN, None, 1e-3).unwrap();
        assert_eq!(d.commanded_a(), FAILSAFE_CURRENT_A);
        d.off().unwrap();
        assert_eq!(d.commanded_a(), 0.0);
        pwm.done();
    }

    #[test]
    fn a_measured_current_closes_the_loop() {
        let mut pwm = Mock::new(&[
            Transaction::max_duty_cycle(1000),
            Transaction::set_duty_cycle(667),
            Transaction::max_duty_cycle(1000),
            // 1 A commanded, 0.5 A measured: feed-forward 4 V + K_p 6.61 V/A x 0.5 A = 7.31 V,
            // + the integrator's first step K_i e dt = 1257 x 0.5 x 1e-3 = 0.63 V (applied next
            // step) -> 7.31 / 12 = 0.609.
            Transaction::set_duty_cycle(609),
        ]);
        let mut d = CoilDriver::new(pwm.clone(), cfg()).unwrap();
        let r = d.set_current_a(1.0, Some(0.5), 1e-3).unwrap();
        assert!(r.closed_loop);
        pwm.done();
    }
}
