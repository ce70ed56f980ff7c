//! What the board layer hands to the application, generic over the variant's sensor and PWM
//! types so that both variants (board, QEMU) fill the same struct without importing the layer's
//! map (`board/mod.rs` re-exports the variant's `init` and its `Board` alias).

use crate::drivers::coil_pwm::CoilDriver;
use crate::periph::{ControlTimer, Watchdog};
use embedded_hal::pwm::SetDutyCycle;

/// What the application gets from the board layer.
pub struct BoardParts<S, P> {
    /// All sensors of the control loop.
    pub sensors: S,
    /// The coil driver (already at the fail-safe current).
    pub coil: CoilDriver<P>,
    /// The 1 kHz period timer (interrupt TIM2).
    pub timer: ControlTimer,
    /// The independent watchdog (running).
    pub watchdog: Watchdog,
}

/// Where the supervisor's coil drive of the period just sampled comes from
/// (`RawFrame::coil_drive_a`): the board's own coil driver, unless the sensor set reports
/// another (in PIL the host drives the plant's coil).
pub trait CoilDriveSource {
    /// The drive, given the coil driver's own `own_a`, A (`None`: an ideal current source).
    fn coil_drive_a(&self, own_a: f32) -> Option<f32> {
        Some(own_a)
    }
}

/// The board's and QEMU's sensors: the coil driver's own drive.
impl<SL, SR, P, A> CoilDriveSource for crate::sensors::Sensors<SL, SR, P, A> {}

impl<S: CoilDriveSource, P: SetDutyCycle> BoardParts<S, P> {
    /// The coil drive over the period just sampled ([`CoilDriveSource`]).
    pub fn coil_drive_a(&self) -> Option<f32> {
        self.sensors.coil_drive_a(self.coil.drive_a())
    }
}
