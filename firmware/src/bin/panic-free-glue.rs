//! Panic-freedom of the firmware glue of the control task, shown by the linker (the
//! "panic-never" technique of `panic-free-check.rs`, which covers the core step, the mode
//! meter and fusion).
//!
//! On inputs the optimiser cannot know (volatile reads) this runs what the 1 kHz task runs
//! around the core step: the encoder unwrapping (`AngleTracker`), the tone-wheel decoder
//! (`WheelSpeed`), the shunt scaling and ADC error mapping, `control::supervised_step` (raw
//! frame, health counters, `SafeController::step`), `control::drive_coil` (the closed current
//! loop into a PWM channel), the fault memory (`ResetRecord::on_boot`, `update`) and the clock
//! decision (`clock::choose`). It links only if no input can reach a panic there. Built with
//! the `panic-check` feature (the library without its runtime, so this binary's panic handler
//! is the only one). Kept apart from `panic-free-check.rs` because linking the library's
//! estimator instances changes LLVM's inlining of the meter's root solver enough to leave two
//! (unreachable) bounds checks in place. Not covered: board bring-up (`board::init`, once,
//! before the loop), the HAL's register access, RTIC's dispatcher, the defmt transport.
#![cfg_attr(target_os = "none", no_std, no_main)]

/// Without `panic-check` the library brings its own runtime (panic handler, logger), so there is
/// nothing to show: a stub that builds with the other binaries.
#[cfg(all(target_os = "none", not(feature = "panic-check")))]
mod stub {
    use shimmy_firmware as _;

    #[cortex_m_rt::entry]
    fn main() -> ! {
        loop {
            cortex_m::asm::nop();
        }
    }
}

#[cfg(all(target_os = "none", feature = "panic-check"))]
mod check {
    use core::ptr::{read_volatile, write_volatile};
    use cortex_m_rt::entry;
    use shimmy_core::control::schedule::MarginSignal;
    use shimmy_core::control::{ControlParams, ControllerKind};
    use shimmy_core::supervisor::frame::MarginStatus;
    use shimmy_core::supervisor::params::SupervisorParams;
    use shimmy_core::supervisor::safe_controller::SafeController;
    use shimmy_firmware::calibration::{COIL, SHUNT, WHEEL_SPEED};
    use shimmy_firmware::clock;
    use shimmy_firmware::control::{drive_coil, supervised_step, Health};
    use shimmy_firmware::drivers::as5047p::AngleTracker;
    use shimmy_firmware::drivers::coil_current::{AdcChannel, CoilCurrentSensor};
    use shimmy_firmware::drivers::coil_pwm::CoilDriver;
    use shimmy_firmware::drivers::wheel_speed::{PulseSample, WheelSpeed};
    use shimmy_firmware::fault_memory::{ResetCause, ResetRecord};
    use shimmy_firmware::sensors::{SampleSet, SensorFault};
    // The device crate supplies the interrupt vector table the runtime's linker script expects.
    use stm32f4xx_hal as _;

    /// A PWM channel whose maximum duty is opaque.
    struct OpaquePwm;

    impl embedded_hal::pwm::ErrorType for OpaquePwm {
        type Error = core::convert::Infallible;
    }

    impl embedded_hal::pwm::SetDutyCycle for OpaquePwm {
        fn max_duty_cycle(&self) -> u16 {
            word(6) as u16
        }
        fn set_duty_cycle(&mut self, duty: u16) -> Result<(), Self::Error> {
            out(1, u32::from(duty));
            Ok(())
        }
    }

    /// An ADC whose counts are opaque.
    struct OpaqueAdc;

    impl AdcChannel for OpaqueAdc {
        type Error = ();
        fn read_counts(&mut self) -> Result<u16, ()> {
            let w = word(5);
            if w & 0x1_0000 != 0 {
                Err(())
            } else {
                Ok(w as u16)
            }
        }
    }

    fn fault(w: u32) -> SensorFault {
        match w % 5 {
            0 => SensorFault::Bus,
            1 => SensorFault::Parity,
            2 => SensorFault::ErrorFlag(w as u16),
            3 => SensorFault::Jump,
            _ => SensorFault::Saturated,
        }
    }

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

    #[entry]
    fn main() -> ! {
        let kind = match word(9) % 5 {
            0 => ControllerKind::PassiveOff,
            1 => ControllerKind::PassiveOn {
                current_a: f32::from_bits(word(8)),
            },
            2 => ControllerKind::Smc,
            3 => ControllerKind::Asmc,
            _ => ControllerKind::Skyhook,
        };
        let mut safe =
            SafeController::new(kind, ControlParams::default(), SupervisorParams::default());
        // Configuration is constant in the firmware (as here); the data is opaque.
        let tracker = AngleTracker::new(shimmy_firmware::sim::ZERO_COUNTS, 8191);
        let mut trackers = [tracker, tracker];
        let mut speed = WheelSpeed::new(WHEEL_SPEED);
        let mut shunt = CoilCurrentSensor::new(OpaqueAdc, SHUNT);
        let mut health = Health::default();
        let Ok(mut coil) = CoilDriver::new(OpaquePwm, COIL);
        let stored = ResetRecord::fresh();
        let cause = ResetCause::from_code(word(9) as u8);
        let (mut record, _) = ResetRecord::on_boot(&stored, cause);
        let source = clock::choose(|| word(0) & 1 != 0, clock::HSE_STARTUP_POLLS, || out(0, 1));
        out(0, source as u32);
        loop {
            // The firmware glue on opaque inputs: the 1 kHz path as the control task runs it.
            let flags = word(3);
            let angle = |i: usize, t: &mut AngleTracker, ok: bool| {
                if ok {
                    t.update(word(i) as u16).map_err(|_| SensorFault::Jump)
                } else {
                    Err(fault(word(i)))
                }
            };
            let [tl, tr] = &mut trackers;
            let set = SampleSet {
                t_us: word(0),
                psi_l_rad: angle(1, tl, flags & 1 != 0),
                psi_r_rad: angle(2, tr, flags & 2 != 0),
                speed: speed.update(
                    PulseSample {
                        new_period_ticks: (flags & 4 != 0).then(|| word(8)),
                        ticks_since_edge: word(7),
                    },
                    shimmy_firmware::sim::TICKS_PER_STEP,
                ),
                coil_current_a: shunt.read_a().map_err(SensorFault::from),
            };
            let margin = match flags >> 8 & 3 {
                0 => MarginStatus::NotUsed,
                1 => MarginStatus::Valid(MarginSignal {
                    speed_margin_mps: f32::from_bits(word(5)),
                    time_to_critical_s: f32::from_bits(word(6)),
                    zeta_fast: f32::from_bits(word(7)),
                }),
                _ => MarginStatus::Invalid,
            };
            let drive = Some(coil.drive_a());
            let o = supervised_step(&mut safe, &set, drive, margin, &mut health);
            let _ = drive_coil(&mut coil, &o);
            if record.update(word(4), safe.supervisor().latched().bits()) {
                out(0, record.resets);
            }
            let (r, _) = ResetRecord::on_boot(&record, ResetCause::from_code(flags as u8));
            out(1, r.quick_resets.into());
            out(0, o.current_cmd_a.to_bits());
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
            fn a_panic_is_reachable_in_the_firmware_glue() -> !;
        }
        // SAFETY: never runs: the symbol does not exist, so this only links if unreachable.
        unsafe { a_panic_is_reachable_in_the_firmware_glue() }
    }
}

#[cfg(not(target_os = "none"))]
fn main() {}
