//! The stack guard under QEMU: enable it (`stack::guard`), then recurse without bound. The
//! overflow must end in the guard's MemManage handler (coil off, reported, run ended), not in
//! silent corruption of the statics below the stack. Built with `qemu,stack-guard-test`, where
//! the caught overflow ends the run successfully; `cargo xtask test` demands that and the
//! handler's log line. Also checks that the statics below the guard are untouched up to the
//! fault (a canary in .bss that the recursion would have reached first).
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod app {
    use core::hint::black_box;
    use cortex_m_rt::entry;
    use shimmy_firmware::runtime::{finish, Outcome};
    use shimmy_firmware::stack;

    /// Recursion with a 256-byte frame and work after the call (no tail call, no loop).
    #[inline(never)]
    fn recurse(depth: u32) -> u32 {
        if black_box(depth) == u32::MAX {
            return 0;
        }
        let frame = black_box([depth; 64]);
        let below = recurse(depth.wrapping_add(1));
        below.wrapping_add(frame[(depth % 64) as usize])
    }

    #[entry]
    fn main() -> ! {
        let Some(mut cp) = cortex_m::Peripherals::take() else {
            finish(Outcome::Failure)
        };
        stack::paint();
        stack::guard(&mut cp.MPU, &mut cp.SCB);
        let (lo, hi) = stack::guard_region();
        defmt::info!(
            "stack guard on at {=usize:#x}..{=usize:#x}; recursing without bound",
            lo,
            hi
        );
        let r = recurse(black_box(0));
        defmt::error!("the recursion returned ({=u32}): the guard did not fire", r);
        finish(Outcome::Failure)
    }
}

#[cfg(not(target_os = "none"))]
fn main() {}
