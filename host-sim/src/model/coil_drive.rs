//! The coil drive between the controller's current command and the damper: either an ideal
//! current source (the plant receives the command; the default of every study) or the board's
//! drive, the core's `control::actuator::CoilDriver` on a 20 kHz PWM into the true coil, closed
//! loop on the measured current (the firmware) or open loop (d = I R / V with the nominal R and
//! V, the firmware before the current loop).
//!
//! Model: the driver's duty d sets the coil's steady current d V_true / R_true, which is the
//! plant's current input; the plant's first-order coil lag (eta = 190 1/s, the nominal L/R)
//! turns it into the coil current the shunt measures. So a hot coil (R x 1.5) or another supply
//! changes the current the duty gives; its shorter L/R is not modelled (the lag stays nominal).

use embedded_hal::pwm::{ErrorType, SetDutyCycle};
use shimmy_core::control::actuator::{CoilDriver, CoilParams};
use std::convert::Infallible;

/// How the command reaches the coil.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum CoilDrive {
    /// The plant receives the command (a perfect current loop).
    #[default]
    Ideal,
    /// The board's PI current loop on the measured current.
    ClosedLoop,
    /// The board's duty I R / V from the nominal coil and supply, no feedback.
    OpenLoop,
}

/// The true coil and supply relative to the drive's nominal coil, as the fault plan sets them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriveCondition {
    /// True coil resistance / nominal.
    pub r_factor: f64,
    /// True supply voltage, V (`None`: the nominal supply).
    pub supply_v: Option<f64>,
}

impl Default for DriveCondition {
    /// The nominal coil on its nominal supply.
    fn default() -> Self {
        DriveCondition {
            r_factor: 1.0,
            supply_v: None,
        }
    }
}

/// TIM4 at 20 kHz from the 168 MHz clock: 8400 duty counts.
const PWM_COUNTS: u16 = 8400;

/// A PWM channel that only remembers its duty.
#[derive(Debug, Default)]
struct DutyOnly {
    counts: u16,
}

impl ErrorType for DutyOnly {
    type Error = Infallible;
}

impl SetDutyCycle for DutyOnly {
    fn max_duty_cycle(&self) -> u16 {
        PWM_COUNTS
    }
    fn set_duty_cycle(&mut self, duty: u16) -> Result<(), Infallible> {
        self.counts = duty.min(PWM_COUNTS);
        Ok(())
    }
}

/// The board's drive of one run.
#[derive(Debug)]
pub struct BoardDrive {
    driver: CoilDriver<DutyOnly>,
    nominal: CoilParams,
    closed_loop: bool,
}

impl BoardDrive {
    /// The drive for `mode` (`None` for [`CoilDrive::Ideal`]) of the nominal coil `nominal` (the
    /// vehicle's: feed-forward, loop gains, open-loop map).
    pub fn new(mode: CoilDrive, nominal: CoilParams) -> Option<Self> {
        let closed_loop = match mode {
            CoilDrive::Ideal => return None,
            CoilDrive::ClosedLoop => true,
            CoilDrive::OpenLoop => false,
        };
        Some(BoardDrive {
            driver: CoilDriver::new(DutyOnly::default(), nominal),
            nominal,
            closed_loop,
        })
    }

    /// One control period `dt_s` of the command `cmd_a`, with the trusted measured current
    /// `measured_a` (used closed loop only) and the true coil `cond`: the steady current of the
    /// written duty in the true coil, A (the plant's current input).
    pub fn plant_input_a(
        &mut self,
        cmd_a: f32,
        measured_a: Option<f32>,
        dt_s: f32,
        cond: DriveCondition,
    ) -> f64 {
        let fb = if self.closed_loop { measured_a } else { None };
        let Ok(r) = self.driver.drive(cmd_a, fb, dt_s);
        let duty = f64::from(r.duty_counts) / f64::from(PWM_COUNTS);
        let supply_v = cond.supply_v.unwrap_or(f64::from(self.nominal.v_supply_v));
        duty * supply_v / (f64::from(self.nominal.r_coil_ohm) * cond.r_factor)
    }

    /// The drive written last, as the board knows it: the steady current of its duty in the
    /// nominal coil, A (the supervisor's `RawFrame::coil_drive_a`).
    pub fn drive_a(&self) -> f32 {
        self.driver.drive_a()
    }

    /// Coil off (the supervisor found the coil open or shorted).
    pub fn off(&mut self) {
        let Ok(()) = self.driver.off();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Steady state over 0.3 s with the plant's lag as the measured current.
    fn settle(mode: CoilDrive, cond: DriveCondition) -> f64 {
        let mut d = BoardDrive::new(mode, CoilParams::default()).unwrap();
        let mut i = 0.0f64;
        let alpha = 1.0 - (-1e-3f64 * 190.0).exp();
        for _ in 0..300 {
            let u = d.plant_input_a(2.0, Some(i as f32), 1e-3, cond);
            i += alpha * (u - i);
        }
        i
    }

    #[test]
    fn closed_loop_holds_the_command_open_loop_follows_r_and_v() {
        let hot = DriveCondition {
            r_factor: 1.5,
            ..DriveCondition::default()
        };
        assert!((settle(CoilDrive::ClosedLoop, hot) - 2.0).abs() < 0.02);
        assert!((settle(CoilDrive::OpenLoop, hot) - 2.0 / 1.5).abs() < 1e-3);
        assert!((settle(CoilDrive::OpenLoop, DriveCondition::default()) - 2.0).abs() < 1e-3);
        assert!(BoardDrive::new(CoilDrive::Ideal, CoilParams::default()).is_none());
    }
}
