//! Stack high-water mark by painting, and the stack guard.
//!
//! Painting: at boot every word between the end of the static RAM (`_stack_end`, i.e. end of
//! .bss/.uninit) and a little below the current stack pointer is filled with [`PAINT`]; after
//! the workload ran, the lowest word that no longer holds the pattern marks the deepest the
//! stack went. (A word the stack wrote with exactly the pattern would be missed; with
//! 0xDEADBEEF that is rare, and at worst the mark is one word shallow.)
//!
//! Guard ([`guard`]): the stack grows down towards the statics (.bss, .uninit: the supervisor
//! state, the reset record). An MPU region of [`GUARD_SIZE`] bytes without any access sits
//! between them, so an overflow faults (MemManage) instead of silently overwriting them. The
//! MemManage handler cannot use the overflowed stack: it moves the stack pointer back to the
//! top of RAM (the overflowed frames are abandoned) and calls the runtime's stack-overflow
//! path, which reports it and ends the run (board: reset, coil off out of reset; QEMU: exit
//! non-zero). `cargo xtask test` runs `bin/stack-guard.rs` under QEMU to show it.

/// The paint pattern.
pub const PAINT: u32 = 0xDEAD_BEEF;

extern "C" {
    static mut _stack_end: u32;
    static mut _stack_start: u32;
}

/// Bytes below the current stack pointer that `paint` leaves alone (its own frame).
const GUARD_BYTES: usize = 64;

/// Size of the guard region, bytes (a power of two, the region is aligned to it): larger than
/// any single stack frame of the firmware, so a frame cannot jump over it.
pub const GUARD_SIZE: usize = 4096;

fn bounds() -> (usize, usize) {
    // Only the addresses of the linker symbols are taken (no access).
    (
        core::ptr::addr_of!(_stack_end) as usize,
        core::ptr::addr_of!(_stack_start) as usize,
    )
}

/// The guard region [start, start + GUARD_SIZE): the first GUARD_SIZE-aligned block at or above
/// the end of the statics.
pub fn guard_region() -> (usize, usize) {
    let (end, _) = bounds();
    let start = (end + GUARD_SIZE - 1) & !(GUARD_SIZE - 1);
    (start, start + GUARD_SIZE)
}

/// Enables the stack guard: MPU region 0 over [`guard_region`] with no access (privileged or
/// not) and execute-never, the default memory map for everything else, MemManage enabled.
pub fn guard(mpu: &mut cortex_m::peripheral::MPU, scb: &mut cortex_m::peripheral::SCB) {
    let (start, _) = guard_region();
    // RASR: XN (bit 28), AP = 000 (no access), SIZE = log2(GUARD_SIZE) - 1, ENABLE.
    let size_field = GUARD_SIZE.trailing_zeros() - 1;
    // SAFETY: region 0 is this guard only; the default map (PRIVDEFENA) keeps every other
    // access as before; the region lies between the statics and the deepest stack use measured
    // (docs/performance.md, stack high-water marks), so nothing live is in it.
    unsafe {
        mpu.rnr.write(0);
        mpu.rbar.write(start as u32);
        mpu.rasr.write((1 << 28) | (size_field << 1) | 1);
        // ENABLE | PRIVDEFENA.
        mpu.ctrl.write(0b101);
    }
    scb.enable(cortex_m::peripheral::scb::Exception::MemoryManagement);
    cortex_m::asm::dsb();
    cortex_m::asm::isb();
}

/// Paints the unused stack. Call once, early in `main`/`init`.
#[inline(never)]
pub fn paint() {
    let (end, _) = bounds();
    let sp = cortex_m::register::msp::read() as usize;
    let top = sp.saturating_sub(GUARD_BYTES) & !3;
    let mut p = end;
    while p < top {
        // SAFETY: [end, sp - guard) is RAM that no live data uses: below the stack pointer
        // and above all statics.
        unsafe { core::ptr::write_volatile(p as *mut u32, PAINT) };
        p += 4;
    }
}

/// Deepest stack use since [`paint`] [bytes], and the stack size available [bytes] (above the
/// guard region, which must not be read once the guard is on).
pub fn high_water() -> (usize, usize) {
    let (_, start) = bounds();
    let (_, end) = guard_region();
    let mut p = end;
    while p < start {
        // SAFETY: reading RAM between the statics and the top of the stack.
        if unsafe { core::ptr::read_volatile(p as *const u32) } != PAINT {
            break;
        }
        p += 4;
    }
    (start - p, start - end)
}
