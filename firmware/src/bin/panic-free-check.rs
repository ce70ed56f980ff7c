//! Panic-freedom of the control path, shown by the linker (the "panic-never" technique).
//!
//! This binary runs the 1 kHz path exactly as the firmware does — `SafeController::step`
//! (supervisor + controller + limiter) on a raw sensor frame, then `MarginEstimator::push` with
//! the validated sample and `Fusion::update` on its output — on inputs the optimiser cannot
//! know (volatile reads: any bit pattern, NaN, Inf, any flags, any time stamps). Its panic
//! handler calls a function that does not exist. Built in release (fat LTO) for
//! thumbv7em-none-eabihf, it links only if the optimiser removed every panic path, i.e. no
//! input can reach a panic (bounds checks, unwraps, overflow checks, divisions). Any reachable
//! panic fails the link with `undefined symbol: a_panic_is_reachable_on_the_control_path`.
//! `cargo xtask test` builds it as one step. It is never flashed.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod check {
    use core::ptr::{read_volatile, write_volatile};
    use cortex_m_rt::entry;
    // The device crate supplies the interrupt vector table the runtime's linker script expects.
    use shimmy_core::control::schedule::MarginSignal;
    use shimmy_core::control::{ControlParams, ControllerKind};
    use shimmy_core::estimator::fusion::{Fusion, FusionInput, FusionParams};
    use shimmy_core::estimator::meter::mode_meter::{EstimatorConfig, MarginEstimator, WheelOrder};
    use shimmy_core::supervisor::frame::{EncoderReading, MarginStatus, RawFrame};
    use shimmy_core::supervisor::params::SupervisorParams;
    use shimmy_core::supervisor::safe_controller::SafeController;
    use stm32f4xx_hal as _;

    /// Raw input words, written by "hardware" (opaque to the optimiser).
    static mut INPUT: [u32; 10] = [0; 10];
    /// Output words (kept alive).
    static mut OUTPUT: [u32; 2] = [0; 2];

    fn word(i: usize) -> u32 {
        // SAFETY: single-threaded, plain volatile read of a static.
        unsafe { read_volatile((&raw const INPUT).cast::<u32>().wrapping_add(i % 10)) }
    }

    fn out(i: usize, v: u32) {
        // SAFETY: as above.
        unsafe { write_volatile((&raw mut OUTPUT).cast::<u32>().wrapping_add(i % 2), v) }
    }

    fn encoder(angle: u32, flags: u32) -> EncoderReading {
        EncoderReading {
            angle_rad: f32::from_bits(angle),
            read_ok: flags & 1 != 0,
            parity_ok: flags & 2 != 0,
            error_flag: flags & 4 != 0,
        }
    }

    #[entry]
    fn main() -> ! {
        let kind = match word(9) % 6 {
            0 => ControllerKind::PassiveOff,
            1 => ControllerKind::PassiveOn {
                current_a: f32::from_bits(word(8)),
            },
            2 => ControllerKind::Smc,
            3 => ControllerKind::Asmc,
            4 => ControllerKind::MarginAsmc,
            _ => ControllerKind::Skyhook,
        };
        let mut safe =
            SafeController::new(kind, ControlParams::default(), SupervisorParams::default());
        let Ok(mut est) = MarginEstimator::<f32>::new(EstimatorConfig::default()) else {
            loop {
                cortex_m::asm::nop();
            }
        };
        let mut fusion = Fusion::new(FusionParams::default());
        loop {
            let flags = word(3);
            let frame = RawFrame {
                t_us: word(0),
                left: encoder(word(1), flags),
                right: encoder(word(2), flags >> 3),
                speed_mps: f32::from_bits(word(4)),
                speed_valid: flags & 64 != 0,
                coil_current_a: (flags & 128 != 0).then(|| f32::from_bits(word(5))),
                coil_drive_a: (flags & 1024 != 0).then(|| f32::from_bits(word(9))),
            };
            let margin = match flags >> 8 & 3 {
                0 => MarginStatus::NotUsed,
                1 => MarginStatus::Valid(MarginSignal {
                    speed_margin_mps: f32::from_bits(word(3)),
                    time_to_critical_s: f32::from_bits(word(5)),
                    zeta_fast: f32::from_bits(word(6)),
                }),
                _ => MarginStatus::Invalid,
            };
            let o = safe.step(&frame, margin);
            out(0, o.current_cmd_a.to_bits());
            let wheel = WheelOrder::Speed {
                speed_mps: f32::from_bits(word(4)),
                radius_m: f32::from_bits(word(6)),
            };
            if let Some(sample) = SafeController::estimator_sample(&o, wheel) {
                if let Some(m) = est.push(&sample) {
                    let r = fusion.update(&FusionInput {
                        t_s: f64::from(o.validated.t_s),
                        speed_mps: f32::from_bits(word(4)),
                        accel_mps2: f32::from_bits(word(7)),
                        fast: &m.fast,
                        slow: &m.slow,
                        model: None,
                    });
                    out(1, r.zeta_data.to_bits());
                }
            }
        }
    }

    /// No-op defmt transport (core logs through defmt on the target).
    #[defmt::global_logger]
    struct NoLog;

    // SAFETY: does nothing, so it is trivially re-entrancy safe.
    unsafe impl defmt::Logger for NoLog {
        fn acquire() {}
        unsafe fn flush() {}
        unsafe fn release() {}
        unsafe fn write(_bytes: &[u8]) {}
    }

    #[panic_handler]
    fn panic(_: &core::panic::PanicInfo) -> ! {
        extern "Rust" {
            fn a_panic_is_reachable_on_the_control_path() -> !;
        }
        // SAFETY: never runs: the symbol does not exist, so this only links if unreachable.
        unsafe { a_panic_is_reachable_on_the_control_path() }
    }
}

#[cfg(not(target_os = "none"))]
fn main() {}
