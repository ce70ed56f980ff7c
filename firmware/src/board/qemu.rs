//! QEMU (netduinoplus2) board layer: no clock setup, simulated sensors.

use super::parts::BoardParts;
use crate::drivers::coil_pwm::CoilDriver;
use crate::hal::pac;
use crate::periph::{ControlTimer, LinkPort, Watchdog};
use crate::sim::{self, SimPwm, SimWorld};

/// The simulated sensor set.
pub type BoardSensors = sim::SimSensors;
/// The simulated coil PWM.
pub type Pwm = SimPwm;

/// The simulated world the devices read.
pub static WORLD: SimWorld = SimWorld::new();

/// Control steps before the `qemu` run exits: the simulated fault scenario. The host link's
/// end-to-end run (`link-e2e`) does not end by itself: the host tool reads the scenario's
/// events after it and then stops QEMU.
pub const QEMU_STEPS: u32 = if cfg!(feature = "link-e2e") {
    u32::MAX
} else {
    sim::SCENARIO_STEPS
};

/// QEMU's stm32f405 clocks its timers at 1 GHz (verified by `cargo xtask bench`'s
/// calibration: TIM2 at prescaler 0 counts one per instruction at `-icount shift=0`).
const TIMER_CLOCK_HZ: u32 = 1_000_000_000;

/// The parts of this variant the application gets.
pub type Board = BoardParts<BoardSensors, Pwm>;

/// Brings up the simulated board and the host link's port; the coil at the fail-safe current, or off (`coil_off`: a
/// coil fault latched before the reset).
pub fn init(dp: pac::Peripherals, coil_off: bool) -> (Board, LinkPort) {
    let pwm = SimPwm::new(&WORLD);
    let coil = match if coil_off {
        CoilDriver::new_off(pwm, sim::COIL)
    } else {
        CoilDriver::new(pwm, sim::COIL)
    } {
        Ok(c) => c,
        Err(e) => match e {},
    };
    let watchdog = Watchdog::start(dp.IWDG);
    let board = Board {
        sensors: sim::sensors(&WORLD),
        coil,
        timer: ControlTimer::start(dp.TIM2, TIMER_CLOCK_HZ),
        watchdog,
    };
    (board, LinkPort::start(dp.USART1, TIMER_CLOCK_HZ))
}
