#![cfg_attr(target_os = "none", no_std, no_main)]
#[cfg(target_os = "none")]
mod bench {
    use shimmy_firmware::runtime::{finish, Outcome};
    const TIM2: usize = 0x4000_0000;
    fn w(off: usize, v: u32) { unsafe { core::ptr::write_volatile((TIM2 + off) as *mut u32, v) } }
    fn r(off: usize) -> u32 { unsafe { core::ptr::read_volatile((TIM2 + off) as *const u32) } }
    #[inline(never)]
    fn nops1000() { unsafe { core::arch::asm!(".rept 1000", "nop", ".endr") } }
    #[inline(never)]
    fn nops0() { unsafe { core::arch::asm!("nop") } }
    #[cortex_m_rt::entry]
    fn main() -> ! {
        let mut cp = cortex_m::Peripherals::take().unwrap();
        // RCC APB1ENR TIM2EN
        unsafe { core::ptr::write_volatile(0x4002_3840 as *mut u32, 1) };
        w(0x28, 0); w(0x2C, 0xFFFF_FFFF); w(0x14, 1); w(0x00, 1);
        cp.SYST.set_clock_source(cortex_m::peripheral::syst::SystClkSource::Core);
        cp.SYST.set_reload(0x00FF_FFFF); cp.SYST.clear_current(); cp.SYST.enable_counter();
        for _ in 0..3 {
            let a = r(0x24); let sa = cortex_m::peripheral::SYST::get_current();
            nops0();
            let b = r(0x24); let sb = cortex_m::peripheral::SYST::get_current();
            nops1000();
            let c = r(0x24); let sc = cortex_m::peripheral::SYST::get_current();
            defmt::info!("tim2: empty {=u32} 1000nop {=u32}; systick: empty {=u32} 1000nop {=u32}", b.wrapping_sub(a), c.wrapping_sub(b), sa.wrapping_sub(sb), sb.wrapping_sub(sc));
        }
        finish(Outcome::Success)
    }
}
#[cfg(not(target_os = "none"))]
fn main() {}
