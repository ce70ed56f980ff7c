//! What the board layer hands to the application, generic over the variant's sensor and PWM
//! types so that both variants (board, QEMU) fill the same struct without importing the layer's
//! map (`board/mod.rs` re-exports the variant's `init` and its `Board` alias).

use crate::drivers::coil_pwm::CoilDriver;
use crate::periph::{ControlTimer, Watchdog};

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
