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
    // Under QEMU (tests) the whole message is formatted. The board build logs a bare "panic" by
    // default: its location and message would keep every panic site's file path and location
    // record and core::fmt in flash (~8.3 KB, docs/performance.md, "Memory") for a path that the link checks
    // (`bin/panic-free-check.rs`, `bin/panic-free-glue.rs`) show is unreachable from the control
    // step. A debug build for the board gets file, line and literal message with the cargo
    // feature `panic-location`.
    #[cfg(feature = "qemu")]
    defmt::error!("panic: {}", defmt::Display2Format(info));
    #[cfg(all(not(feature = "qemu"), feature = "panic-location"))]
    {
        let (file, line) = info.location().map_or(("?", 0), |l| (l.file(), l.line()));
        let msg = info.message().as_str().unwrap_or("(formatted message)");
        defmt::error!("panic at {=str}:{=u32}: {=str}", file, line, msg);
    }
    #[cfg(all(not(feature = "qemu"), not(feature = "panic-location")))]
    {
        let _ = info;
        defmt::error!("panic");
    }
    finish(Outcome::Failure)
}

/// The MemManage fault of the stack guard (`stack::guard`): the stack pointer is inside the
/// guard, so nothing may be pushed. Move it back to the top of RAM (abandoning the overflowed
/// frames) and report from there.
///
/// # Safety
/// Only the vector table calls it.
#[unsafe(naked)]
#[no_mangle]
pub unsafe extern "C" fn MemoryManagement() -> ! {
    core::arch::naked_asm!(
        "ldr r0, ={top}",
        "msr msp, r0",
        "b {report}",
        top = sym _stack_start,
        report = sym stack_overflow,
    )
}

extern "C" {
    static _stack_start: u32;
}

/// Reports a stack overflow caught by the guard and ends the run (board: reset, coil off out
/// of reset; QEMU: exit status from [`STACK_OVERFLOW_OUTCOME`]).
extern "C" fn stack_overflow() -> ! {
    // Coil off before anything else (the PWM keeps its last duty until the reset).
    coil_off();
    defmt::error!("stack overflow: the stack guard caught it (MemManage); coil off, run ended");
    finish(STACK_OVERFLOW_OUTCOME)
}

/// How a caught stack overflow ends the run: a failure, except in the guard's own test binary.
#[cfg(not(feature = "stack-guard-test"))]
const STACK_OVERFLOW_OUTCOME: Outcome = Outcome::Failure;
/// How a caught stack overflow ends the run: the guard test expects exactly this.
#[cfg(feature = "stack-guard-test")]
const STACK_OVERFLOW_OUTCOME: Outcome = Outcome::Success;

/// Coil PWM off by register (TIM4 CCR1 = 0), usable from a fault handler.
fn coil_off() {
    #[cfg(not(feature = "qemu"))]
    // SAFETY: a single store to TIM4's compare register; the control task is not running (the
    // fault handler has the highest priority) and the run ends right after.
    unsafe {
        (*crate::hal::pac::TIM4::ptr()).ccr1().write(|w| w.bits(0));
    }
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
