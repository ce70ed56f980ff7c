//! Target runtime glue shared by every firmware binary: the defmt transport, what a panic or a
//! HardFault does, and how a run ends.
//!
//! - Board build: defmt over RTT; a panic or fault logs and resets the MCU (the damper driver
//!   defaults to its safe state out of reset).
//! - `qemu` build: defmt over semihosting; a panic or fault logs and exits QEMU with a non-zero
//!   status so a test run fails instead of hanging.

use cortex_m_rt::{exception, ExceptionFrame};

#[cfg(not(feature = "qemu"))]
use defmt_rtt as _;
#[cfg(feature = "qemu")]
use defmt_semihosting as _;

/// How a run ends.
#[derive(Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum Outcome {
    /// Everything went as expected.
    Success,
    /// A test failed, a panic or a fault happened.
    Failure,
}

/// Ends the run under QEMU: a semihosting exit with the outcome as its status.
#[cfg(feature = "qemu")]
pub fn finish(outcome: Outcome) -> ! {
    use cortex_m_semihosting::debug;
    debug::exit(match outcome {
        Outcome::Success => debug::EXIT_SUCCESS,
        Outcome::Failure => debug::EXIT_FAILURE,
    });
    // Only reached without a debugger that implements semihosting exit: fault loudly.
    cortex_m::asm::udf()
}

/// Ends the run on the board: a reset (the damper driver is in its safe state out of reset).
#[cfg(not(feature = "qemu"))]
pub fn finish(_outcome: Outcome) -> ! {
    cortex_m::peripheral::SCB::sys_reset()
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    // Under QEMU (tests) the whole message is formatted. The board build logs the location and a
    // literal message only: formatting arbitrary arguments pulls in core::fmt's float printing
    // (~15 KiB of flash) for a path that the link check shows is unreachable from the control step.
    #[cfg(feature = "qemu")]
    defmt::error!("panic: {}", defmt::Display2Format(info));
    #[cfg(not(feature = "qemu"))]
    {
        let (file, line) = info.location().map_or(("?", 0), |l| (l.file(), l.line()));
        let msg = info.message().as_str().unwrap_or("(formatted message)");
        defmt::error!("panic at {=str}:{=u32}: {=str}", file, line, msg);
    }
    finish(Outcome::Failure)
}

#[exception]
unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
    defmt::error!(
        "HardFault at pc = {=u32:#010x}, lr = {=u32:#010x}",
        frame.pc(),
        frame.lr()
    );
    finish(Outcome::Failure)
}
