//! MR damper coil drive: a PWM channel (`embedded_hal::pwm::SetDutyCycle`) into a low-side
//! switch with a freewheeling diode; the coil's L/R filters the PWM into a current.
//!
//! # Fail-safe policy
//! - Out of reset (before the firmware runs, during a reset or a watchdog reset) the PWM pin is
//!   high-impedance and the gate driver's pull-down holds the switch off: **coil off**, the damper
//!   gives its passive (zero-field) damping. This cannot be changed by software.
//! - As soon as the driver is constructed, and whenever the control loop has no valid command
//!   (invalid sensors, a NaN from the controller, the supervisor's fault state), it drives
//!   [`FAILSAFE_CURRENT_A`]: the supervisor's fail-safe current, chosen from the stability
//!   analysis (`shimmy_core::control::actuator::FAILSAFE_CURRENT_A`, checked by
//!   `tests/tests/failsafe_current.rs`).

use embedded_hal::pwm::SetDutyCycle;

/// Coil current commanded while the loop has no valid command, A: the supervisor's fail-safe
/// current (one definition, in core).
pub const FAILSAFE_CURRENT_A: f32 = shimmy_core::control::actuator::FAILSAFE_CURRENT_A;

/// Electrical data of the coil drive.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoilConfig {
    /// Coil resistance (hot), ohm.
    pub coil_ohm: f32,
    /// Supply voltage of the switch, V.
    pub supply_v: f32,
    /// Largest current the coil may carry, A (thermal / damper saturation).
    pub max_current_a: f32,
}

/// The coil driver.
pub struct CoilDriver<P> {
    pwm: P,
    cfg: CoilConfig,
    commanded_a: f32,
}

impl<P: SetDutyCycle> CoilDriver<P> {
    /// Takes the PWM channel and immediately drives the fail-safe current.
    pub fn new(pwm: P, cfg: CoilConfig) -> Result<Self, P::Error> {
        let mut d = CoilDriver {
            pwm,
            cfg,
            commanded_a: 0.0,
        };
        d.fail_safe()?;
        Ok(d)
    }

    /// Steady-state duty for a current: I = duty * V / R, clamped to [0, max current].
    pub fn duty_for(&self, current_a: f32) -> f32 {
        let i = clamp_current(current_a, self.cfg.max_current_a);
        (i * self.cfg.coil_ohm / self.cfg.supply_v).clamp(0.0, 1.0)
    }

    /// Commands a coil current, A. NaN commands the fail-safe current; values outside
    /// [0, max] are clamped (a semi-active damper cannot use negative current).
    pub fn set_current_a(&mut self, current_a: f32) -> Result<(), P::Error> {
        let i = if current_a.is_nan() {
            FAILSAFE_CURRENT_A
        } else {
            current_a
        };
        let duty = self.duty_for(i);
        let max = u32::from(self.pwm.max_duty_cycle());
        // duty in [0, 1], so the product is in [0, max]: the cast cannot truncate.
        let d = libm::roundf(duty * max as f32) as u32;
        self.pwm.set_duty_cycle(d.min(max) as u16)?;
        self.commanded_a = clamp_current(i, self.cfg.max_current_a);
        Ok(())
    }

    /// Drives the fail-safe current.
    pub fn fail_safe(&mut self) -> Result<(), P::Error> {
        self.set_current_a(FAILSAFE_CURRENT_A)
    }

    /// The current last commanded (after clamping), A.
    pub fn commanded_a(&self) -> f32 {
        self.commanded_a
    }

    /// Gives the PWM channel back.
    pub fn release(self) -> P {
        self.pwm
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
            supply_v: 12.0,
            max_current_a: 2.0,
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
    fn clamps_and_nan() {
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
        ]);
        let mut d = CoilDriver::new(pwm.clone(), cfg()).unwrap();
        d.set_current_a(5.0).unwrap();
        assert_eq!(d.commanded_a(), 2.0);
        d.set_current_a(-1.0).unwrap();
        assert_eq!(d.commanded_a(), 0.0);
        d.set_current_a(f32::NAN).unwrap();
        assert_eq!(d.commanded_a(), FAILSAFE_CURRENT_A);
        pwm.done();
    }
}
