//! On-target benchmark: instructions per call of the functions that must fit the 1 kHz loop
//! and the estimator budget, and the stack high-water mark, under QEMU with `-icount shift=0`
//! (`cargo xtask bench`).
//!
//! How instructions are counted: with `-icount shift=0` QEMU advances its virtual clock by
//! exactly 1 ns per executed instruction, and its STM32 timers run at 1 GHz of that clock, so
//! TIM2 at prescaler 0 counts one per instruction. The run first proves it: a block of 1000
//! `nop`s must measure exactly 1000 more than an empty call, and SysTick (clocked at QEMU's
//! 168 MHz core clock, an independent counter) must agree within one tick. Instructions are
//! not cycles: on a real Cortex-M4 at 168 MHz loads from flash wait, FPU and branch timing
//! differ; count roughly 1-1.5 cycles per instruction.
//!
//! Adding an entry is one line in `ENTRIES`: a name, a budget (or `None` to only report) and a
//! function that calls [`measure`] on the code under test.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod bench {
    use core::hint::black_box;
    use shimmy_firmware::control::{decide, EstimatorStep, FixedCurrent, Health, RmsEstimator};
    use shimmy_firmware::runtime::{finish, Outcome};

    /// Budget of one control step [instructions] (DESIGN: 1 kHz loop on a 168 MHz M4).
    const CONTROL_STEP_BUDGET: u32 = 5_000;

    /// Calls of each entry; the largest count is reported (inputs vary between calls).
    const CALLS: u32 = 5;

    struct Entry {
        name: &'static str,
        budget: Option<u32>,
        run: fn() -> u32,
    }

    const ENTRIES: &[Entry] = &[
        Entry {
            name: "control step (sim sensors, validate, seam, PWM)",
            budget: Some(CONTROL_STEP_BUDGET),
            run: control_step,
        },
        Entry {
            name: "estimator update (placeholder RMS, 100 Hz)",
            budget: None,
            run: estimator_update,
        },
        Entry {
            name: "estimator slow update (placeholder, 10 Hz)",
            budget: None,
            run: estimator_slow,
        },
        Entry {
            name: "f32 biquad, one sample",
            budget: None,
            run: biquad,
        },
        Entry {
            name: "libm::sinf (f32)",
            budget: None,
            run: sinf,
        },
        Entry {
            name: "mr_damper::rates (f64 soft-float)",
            budget: None,
            run: damper_rates,
        },
        Entry {
            name: "10x10 f64 matrix product (nalgebra)",
            budget: None,
            run: matmul10,
        },
        // Proves that an entry over its budget fails the run (`cargo xtask test` builds it).
        #[cfg(feature = "deliberate-failure")]
        Entry {
            name: "deliberately over budget (proves the check)",
            budget: Some(1),
            run: biquad,
        },
        Entry {
            name: "eigen update stand-in: Schur 10x10 f64",
            budget: None,
            run: schur10,
        },
    ];

    // ---- the counter --------------------------------------------------------------------

    const TIM2: usize = 0x4000_0000;
    const CNT: usize = 0x24;

    fn cnt() -> u32 {
        // SAFETY: reading TIM2 CNT, a plain 32-bit register.
        unsafe { core::ptr::read_volatile((TIM2 + CNT) as *const u32) }
    }

    fn start_counter() {
        // SAFETY: RCC APB1ENR TIM2EN, then TIM2 PSC = 0, ARR = max, UG, CEN (RM0090).
        unsafe {
            let w = |addr: usize, v: u32| core::ptr::write_volatile(addr as *mut u32, v);
            w(0x4002_3840, 1);
            w(TIM2 + 0x28, 0);
            w(TIM2 + 0x2C, u32::MAX);
            w(TIM2 + 0x14, 1);
            w(TIM2, 1); // CR1 (offset 0): CEN
        }
    }

    /// Instructions of one call of `f`, the call overhead excluded (subtracted with an empty
    /// closure measured the same way).
    #[inline(never)]
    fn raw_count<F: FnMut()>(f: &mut F) -> u32 {
        let a = cnt();
        f();
        let b = cnt();
        b.wrapping_sub(a)
    }

    fn overhead() -> u32 {
        let mut empty = || {};
        raw_count(&mut empty)
    }

    /// Largest instruction count of [`CALLS`] calls of `f`.
    pub fn measure<F: FnMut()>(mut f: F) -> u32 {
        let oh = overhead();
        let mut worst = 0;
        for _ in 0..CALLS {
            worst = worst.max(raw_count(&mut f).saturating_sub(oh));
        }
        worst
    }

    #[inline(never)]
    fn nops_1000() {
        // SAFETY: nops only.
        unsafe { core::arch::asm!(".rept 1000", "nop", ".endr", options(nomem, nostack)) }
    }

    #[inline(never)]
    fn nops_2000() {
        // SAFETY: nops only.
        unsafe { core::arch::asm!(".rept 2000", "nop", ".endr", options(nomem, nostack)) }
    }

    /// The counter must count instructions: 1000 more nops measure exactly 1000 more, and
    /// SysTick (168 MHz) agrees.
    fn calibrate(syst: &mut cortex_m::peripheral::SYST) -> bool {
        use cortex_m::peripheral::{syst::SystClkSource, SYST};
        let n1 = measure(nops_1000);
        let n2 = measure(nops_2000);
        let ok_tim = n2.wrapping_sub(n1) == 1000;
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(0x00FF_FFFF);
        syst.clear_current();
        syst.enable_counter();
        let s0 = SYST::get_current();
        let t0 = cnt();
        for _ in 0..100 {
            nops_1000();
        }
        let t1 = cnt();
        let s1 = SYST::get_current();
        let insns = t1.wrapping_sub(t0);
        let ticks = s0.wrapping_sub(s1) & 0x00FF_FFFF;
        // 168 MHz SysTick vs a 1 GHz instruction clock: ticks = insns * 0.168, +-1 tick.
        let expect = insns as u64 * 168 / 1000;
        let ok_syst = (ticks as i64 - expect as i64).abs() <= 1;
        defmt::info!(
            "calibration: call of 2000 nops {=u32} - call of 1000 nops {=u32} = {=u32} instructions (expect 1000); {=u32} instructions = {=u32} SysTick ticks at 168 MHz (expect {=u64} +- 1) -> {=str}",
            n2, n1, n2.wrapping_sub(n1), insns, ticks, expect,
            if ok_tim && ok_syst { "counter counts instructions" } else { "COUNTER NOT INSTRUCTION-ACCURATE" }
        );
        ok_tim && ok_syst
    }

    // ---- the entries ----------------------------------------------------------------------

    fn control_step() -> u32 {
        use shimmy_firmware::drivers::coil_pwm::CoilDriver;
        use shimmy_firmware::sim::{self, SimPwm, SimWorld};
        static WORLD: SimWorld = SimWorld::new();
        let mut sensors = sim::sensors(&WORLD);
        let Ok(mut coil) = CoilDriver::new(SimPwm::new(&WORLD), sim::COIL);
        let mut ctrl = FixedCurrent { current_a: 1.0 };
        let mut h = Health::default();
        // The simulated world (two sinf per step) is advanced outside the measurement: only
        // the firmware's own work is counted (on the board the sensors answer by themselves).
        WORLD.set_step(200);
        measure(|| {
            let s = sensors.sample(sim::TICKS_PER_STEP);
            let (cmd, _) = decide(&mut ctrl, &s, 200, 1e-3, &mut h);
            let _ = coil.set_current_a(cmd);
        })
    }

    fn estimator_update() -> u32 {
        let mut e = RmsEstimator::default();
        let input = shimmy_firmware::control::ControlInput {
            psi_l_rad: 0.01,
            psi_r_rad: -0.003,
            ..Default::default()
        };
        measure(|| e.update(black_box(&input)))
    }

    fn estimator_slow() -> u32 {
        let mut e = RmsEstimator::default();
        measure(|| {
            e.update(black_box(&Default::default()));
            e.slow_update()
        })
    }

    fn biquad() -> u32 {
        // Second-order low-pass (direct form II transposed), 1 kHz / 50 Hz Butterworth-ish.
        let (b0, b1, b2, a1, a2) = (0.0201f32, 0.0402, 0.0201, -1.561, 0.6414);
        let (mut z1, mut z2) = (0.0f32, 0.0f32);
        let mut x = 0.3f32;
        measure(|| {
            let xi = black_box(x);
            let y = b0 * xi + z1;
            z1 = b1 * xi - a1 * y + z2;
            z2 = b2 * xi - a2 * y;
            x = black_box(y) + 0.1;
        })
    }

    fn sinf() -> u32 {
        let mut x = 0.7f32;
        measure(|| {
            x = black_box(libm::sinf(black_box(x))) + 0.5;
        })
    }

    fn damper_rates() -> u32 {
        use shimmy_core::mr_damper::{rates, SpencerParams, SpencerState};
        let p = SpencerParams::steering();
        let s = SpencerState {
            u: 0.8,
            y: 0.001,
            z: 0.0005,
        };
        measure(|| {
            black_box(rates(&p, black_box(&s), 0.002, 0.05, 1.0));
        })
    }

    type M10 = nalgebra::SMatrix<f64, 10, 10>;

    fn test_matrix() -> M10 {
        // A non-symmetric matrix with complex eigenvalues (a chain of damped oscillators).
        M10::from_fn(|i, j| {
            let (i, j) = (i as f64, j as f64);
            if i == j {
                -0.5 - 0.1 * i
            } else {
                1.0 / (1.0 + (i - j) * (i - j)) * if i < j { 1.0 } else { -0.7 }
            }
        })
    }

    fn matmul10() -> u32 {
        let a = test_matrix();
        let b = a.transpose();
        measure(|| {
            black_box(black_box(&a) * black_box(&b));
        })
    }

    fn schur10() -> u32 {
        let a = test_matrix();
        measure(|| {
            black_box(black_box(a).schur());
        })
    }

    #[cortex_m_rt::entry]
    fn main() -> ! {
        shimmy_firmware::stack::paint();
        start_counter();
        let Some(mut cp) = cortex_m::Peripherals::take() else {
            finish(Outcome::Failure)
        };
        let mut ok = calibrate(&mut cp.SYST);
        for e in ENTRIES {
            let n = (e.run)();
            match e.budget {
                Some(b) => {
                    let pass = n <= b;
                    ok &= pass;
                    defmt::info!(
                        "bench | {=str} | {=u32} | {=u32} | {=str}",
                        e.name,
                        n,
                        b,
                        if pass { "ok" } else { "OVER BUDGET" }
                    );
                }
                None => defmt::info!(
                    "bench | {=str} | {=u32} | {=str} | reported",
                    e.name,
                    n,
                    "-"
                ),
            }
        }
        let (used, size) = shimmy_firmware::stack::high_water();
        defmt::info!(
            "stack high-water mark (bench workload) {=usize} B of {=usize} B",
            used,
            size
        );
        finish(if ok {
            Outcome::Success
        } else {
            Outcome::Failure
        })
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("target-bench runs on the Cortex-M4F: use `cargo xtask bench` (QEMU, -icount).");
    std::process::exit(2);
}
