//! Stack high-water mark by painting: at boot every word between the end of the static RAM
//! (`_stack_end`, i.e. end of .bss/.uninit) and a little below the current stack pointer is
//! filled with [`PAINT`]; after the workload ran, the lowest word that no longer holds the
//! pattern marks the deepest the stack went. (A word the stack wrote with exactly the pattern
//! would be missed; with 0xDEADBEEF that is rare, and at worst the mark is one word shallow.)

/// The paint pattern.
pub const PAINT: u32 = 0xDEAD_BEEF;

extern "C" {
    static mut _stack_end: u32;
    static mut _stack_start: u32;
}

/// Bytes below the current stack pointer that `paint` leaves alone (its own frame).
const GUARD_BYTES: usize = 64;

fn bounds() -> (usize, usize) {
    // Only the addresses of the linker symbols are taken (no access).
    (
        core::ptr::addr_of!(_stack_end) as usize,
        core::ptr::addr_of!(_stack_start) as usize,
    )
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

/// Deepest stack use since [`paint`] [bytes], and the stack size available [bytes].
pub fn high_water() -> (usize, usize) {
    let (end, start) = bounds();
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
