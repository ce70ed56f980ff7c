//! Instruction count of one `Controller::step` on the Cortex-M4F, under QEMU with -icount.
//! Not a workspace member (it needs cortex-m-rt and the target). Run from this directory:
//!
//! ```text
//! CARGO_TARGET_DIR=/tmp/shimmy-target-count cargo build --release
//! qemu-system-arm -machine netduinoplus2 -nographic -semihosting-config enable=on,target=native \
//!     -icount shift=4 -kernel /tmp/shimmy-target-count/thumbv7em-none-eabihf/release/shimmy-target-count
//! ```
//!
//! With -icount every instruction advances virtual time by the same amount, so SysTick ticks are
//! proportional to instructions; a call of 200 NOPs (202 instructions) calibrates ticks per instruction.
//! Instructions per step = (step ticks) / (calibration ticks / 202).
#![no_std]
#![no_main]
use cortex_m::peripheral::{syst::SystClkSource, SYST};
use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use shimmy_core::control::{ControlInput, ControlParams, Controller, ControllerKind};

/// 200 NOPs plus the call and return: 202 instructions.
#[inline(never)]
fn nops() {
    unsafe { core::arch::asm!(".rept 200", "nop", ".endr") }
}

fn ticks(start: u32) -> u32 { start.wrapping_sub(SYST::get_current()) & 0x00FF_FFFF }

#[entry]
fn main() -> ! {
    let mut cp = cortex_m::Peripherals::take().unwrap();
    cp.SYST.set_clock_source(SystClkSource::Core);
    cp.SYST.set_reload(0x00FF_FFFF);
    cp.SYST.clear_current();
    cp.SYST.enable_counter();
    // calibration: 200 nops
    let t0 = SYST::get_current();
    nops();
    let cal = ticks(t0);
    let t0 = SYST::get_current();
    let empty = ticks(t0);
    for kind in [ControllerKind::Asmc, ControllerKind::Smc, ControllerKind::PassiveOff] {
        let mut c = Controller::new(kind, ControlParams::default());
        let mut worst = 0u32; let mut sum = 0u32; let n = 2000u32;
        let mut psi = 0.0f32; let mut dpsi = 0.0377f32 * 0.01 * 6.0;
        for _k in 0..n {
            // 6 Hz oscillator by rotation (no sinf in the loop)
            let w = 2.0 * 3.14159265 * 6.0 * 1e-3;
            let np = psi + w * dpsi; dpsi -= w * np; psi = np;
            let inp = ControlInput { t_s: 0.0, dt_s: 1e-3, psi_l_rad: psi * 0.01 / 0.0023, psi_r_rad: psi * 0.01 / 0.0023, speed_mps: 20.0, coil_current_a: None };
            let t0 = SYST::get_current();
            let o = core::hint::black_box(c.step(core::hint::black_box(&inp)));
            let dt = ticks(t0).saturating_sub(empty);
            core::hint::black_box(o);
            worst = worst.max(dt); sum += dt;
        }
        let per_insn = (cal - empty) as f32 / 202.0;
        hprintln!(
            "{}: mean {} instructions, worst {} (ticks: mean {}, worst {}; 202 instructions = {} ticks)",
            kind.name(),
            (sum / n) as f32 / per_insn,
            worst as f32 / per_insn,
            sum / n,
            worst,
            cal - empty
        );
    }
    debug::exit(debug::EXIT_SUCCESS);
    loop {}
}
#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! { debug::exit(debug::EXIT_FAILURE); loop {} }
