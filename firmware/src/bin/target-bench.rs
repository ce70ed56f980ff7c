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
//! function that calls `measure` on the code under test.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod bench {
    use core::hint::black_box;
    use core::sync::atomic::{AtomicU32, Ordering};
    use shimmy_core::vehicle::BoardVehicle;
    use shimmy_firmware::runtime::{finish, Outcome};

    /// Budget of one control step [instructions] (DESIGN: 1 kHz loop on a 168 MHz M4).
    const CONTROL_STEP_BUDGET: u32 = 5_000;
    /// Instructions per second we count on: 168 MHz at a worst-case 1.5 cycles per
    /// instruction (flash wait states, FPU, branches).
    const INSN_PER_S: u64 = 168_000_000 * 2 / 3;
    /// Budget of one 100 Hz meter run (10 pushes incl. the decimated update, fusion,
    /// monitor): half its 10 ms period, the rest is left to preemption by the control task.
    const METER_RUN_BUDGET: u32 = (INSN_PER_S / 100 / 2) as u32;
    /// Requirement on the model cycle's wall time at the measured load [ms]: the refresh period
    /// `monitoring::MODEL_REFRESH_S` (10 Hz; derivation there).
    const MODEL_REFRESH_BUDGET_MS: u32 =
        (shimmy_firmware::monitoring::MODEL_REFRESH_S * 1000.0) as u32;
    /// Budget of the worst warm model cycle [instructions]: the continuation tracker does one
    /// eigen-solve and a few Newton LUs per cycle.
    const MODEL_CYCLE_BUDGET: u32 = 500_000;
    /// Cycles per instruction assumed for the CPU load row (see `cpu_load_permille`): 1, the
    /// M4's single-cycle ALU/FPU issue with the flash accelerator hiding wait states on
    /// straight-line code; [`INSN_PER_S`] keeps 1.5 for the wall-time budgets.
    const LOAD_CPI: u64 = 1;
    /// Budget of the whole firmware's CPU load at its rates [per mille of the 168 MHz M4]: 5 %,
    /// the share of the M4 the shimmy functions may take (the rest is the vehicle
    /// application's); the measured load is in `docs/measurements.md`.
    #[cfg(not(feature = "model-truck"))]
    const CPU_LOAD_BUDGET_PERMILLE: u32 = 50;
    /// The truck image's budget of the same load (cargo feature `model-truck`, the model task
    /// on the truck's 12-state model): 5.5 %, the car's 5 % and room for the truck's larger
    /// model cycles.
    #[cfg(feature = "model-truck")]
    const CPU_LOAD_BUDGET_PERMILLE: u32 = 55;

    /// Calls of each entry; the largest count is reported (inputs vary between calls).
    const CALLS: u32 = 5;

    /// How an entry's count is judged.
    #[derive(Clone, Copy)]
    enum Budget {
        /// Only reported.
        None,
        /// Enforced: over it fails the run.
        Hard(u32),
    }

    struct Entry {
        name: &'static str,
        budget: Budget,
        run: fn() -> u32,
    }

    const ENTRIES: &[Entry] = &[
        Entry {
            name: "control step: sensors, raw frame, SafeController, PWM",
            budget: Budget::Hard(CONTROL_STEP_BUDGET),
            run: control_step,
        },
        Entry {
            name: "SafeController::step alone (supervisor, margin ASMC)",
            budget: Budget::None,
            run: safe_step,
        },
        Entry {
            name: "DataMargin::push (DataPipeline), plain sample",
            budget: Budget::None,
            run: push_plain,
        },
        Entry {
            name: "DataMargin::push, 10th (RLS, roots, fusion, monitor)",
            budget: Budget::None,
            run: push_decimated,
        },
        Entry {
            name: "meter run at 100 Hz (10 pushes, fusion, monitor)",
            budget: Budget::Hard(METER_RUN_BUDGET),
            run: meter_run,
        },
        Entry {
            name: "meter run with a model margin (fusion corrects it)",
            budget: Budget::Hard(METER_RUN_BUDGET),
            run: meter_run_with_model,
        },
        Entry {
            name: "meter run, the same yaw without a model margin",
            budget: Budget::None,
            run: meter_run_damped_no_model,
        },
        Entry {
            name: "meter task: the log's recorder and the link's update per run (max)",
            budget: Budget::None,
            run: meter_bookkeeping,
        },
        Entry {
            name: "link: a telemetry frame (stream on, 10 Hz)",
            budget: Budget::None,
            run: link_telemetry,
        },
        Entry {
            name: "background loop: a pass per meter run, no cycle due (100 Hz)",
            budget: Budget::None,
            run: idle_pass,
        },
        Entry {
            name: "background loop: a wake with nothing new (~1 kHz)",
            budget: Budget::None,
            run: idle_wake,
        },
        Entry {
            name: "link: a config-get request (handler, record, frame)",
            budget: Budget::None,
            run: link_request,
        },
        Entry {
            name: "link: the last events page of a 40-entry flash log",
            budget: Budget::None,
            run: link_events_page,
        },
        Entry {
            name: "eigen update: linearise + eigenvalues (f32, balanced)",
            budget: Budget::None,
            run: eigen_update_f32,
        },
        Entry {
            name: "model tracker: one call (max over the ramp)",
            budget: Budget::None,
            run: tracker_call,
        },
        Entry {
            name: "model tracker: first cycle (cold, 24 km/h)",
            budget: Budget::None,
            run: tracker_cold_cycle,
        },
        Entry {
            name: "model tracker: cycle, max over 24->36 km/h by 1 km/h",
            budget: Budget::Hard(MODEL_CYCLE_BUDGET),
            run: tracker_cycle,
        },
        Entry {
            name: "eigenvector (f32 inverse iteration, 3 solves)",
            budget: Budget::None,
            run: eigenvector_f32,
        },
        Entry {
            name: "right + left eigenvector (f32, one LU)",
            budget: Budget::None,
            run: eigenvectors_f32,
        },
        Entry {
            name: "linearise (f64)",
            budget: Budget::None,
            run: linearise_only,
        },
        Entry {
            name: "eigenpair Newton step (f32, residual too), warm",
            budget: Budget::None,
            run: newton_f32,
        },
        Entry {
            name: "model update: one measurement update (f32 solves, f64 filter)",
            budget: Budget::None,
            run: model_update_step,
        },
        Entry {
            name: "model update: the onset's sigma (ModelTask::refresh_sigma)",
            budget: Budget::None,
            run: onset_sigma_step,
        },
        Entry {
            name: "model cycle wall time at measured load [ms]",
            budget: Budget::Hard(MODEL_REFRESH_BUDGET_MS),
            run: model_refresh_ms,
        },
        Entry {
            name: "firmware at its rates [per mille of 168 MHz at 1 CPI]",
            budget: Budget::Hard(CPU_LOAD_BUDGET_PERMILLE),
            run: cpu_load_permille,
        },
        Entry {
            name: "libm::sinf (f32)",
            budget: Budget::None,
            run: sinf,
        },
        Entry {
            name: "store: load the vehicle (RAM flash, background loop)",
            budget: Budget::None,
            run: store_load,
        },
        Entry {
            name: "store: append a shimmy entry (RAM flash, background loop)",
            budget: Budget::None,
            run: store_append,
        },
        // Proves that an entry over its budget fails the run (`cargo xtask test` builds it).
        #[cfg(feature = "deliberate-failure")]
        Entry {
            name: "deliberately over budget (proves the check)",
            budget: Budget::Hard(1),
            run: sinf,
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

    /// Instructions of one call of `f` (call overhead subtracted).
    fn measure_once<F: FnMut()>(mut f: F) -> u32 {
        let oh = overhead();
        raw_count(&mut f).saturating_sub(oh)
    }

    // ---- the entries ----------------------------------------------------------------------

    /// The image's compiled-in vehicle (the car's nominal one; the truck image's `truck-full`).
    fn image_vehicle() -> shimmy_firmware::monitoring::ImageVehicle {
        shimmy_firmware::monitoring::ImageVehicle::compiled_in()
    }

    /// A deterministic shimmy-like yaw at step `k`: a 7 Hz oscillation with a slowly varying
    /// amplitude plus pseudo-random noise (an LCG), so the RLS sees real excitation.
    fn yaw(k: u32, seed: &mut u32) -> (f32, f32) {
        *seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        let noise = ((*seed >> 8) as f32 / 16_777_216.0 - 0.5) * 2e-4;
        let t = k as f32 * 1e-3;
        let a = 2e-3 * (1.0 + 0.3 * libm::sinf(0.5 * t));
        let y = a * libm::sinf(2.0 * core::f32::consts::PI * 7.0 * t) + noise;
        (y, y * 0.98)
    }

    /// Results the model-refresh row derives from (stored by the entries that measure them).
    static CONTROL_MAX: AtomicU32 = AtomicU32::new(u32::MAX);
    static METER_RUN_MAX: AtomicU32 = AtomicU32::new(u32::MAX);
    static METER_MODEL_RUN_MAX: AtomicU32 = AtomicU32::new(u32::MAX);
    static METER_DAMPED_RUN_MAX: AtomicU32 = AtomicU32::new(u32::MAX);
    static BOOKKEEPING_MAX: AtomicU32 = AtomicU32::new(u32::MAX);
    static TELEMETRY_MAX: AtomicU32 = AtomicU32::new(u32::MAX);
    static IDLE_PASS_MAX: AtomicU32 = AtomicU32::new(u32::MAX);
    static MODEL_UPDATE_MAX: AtomicU32 = AtomicU32::new(u32::MAX);
    static ONSET_SIGMA_MAX: AtomicU32 = AtomicU32::new(u32::MAX);
    static IDLE_WAKE_MAX: AtomicU32 = AtomicU32::new(u32::MAX);

    /// A valid margin report inside the Hopf window (the margin schedule fully armed).
    const INSIDE_WINDOW: shimmy_core::supervisor::frame::MarginStatus =
        shimmy_core::supervisor::frame::MarginStatus::Valid(
            shimmy_core::control::schedule::MarginSignal {
                speed_margin_mps: 0.0,
                time_to_critical_s: f32::INFINITY,
                zeta_fast: 0.01,
            },
        );

    fn control_step() -> u32 {
        use shimmy_firmware::control::{drive_coil, supervised_step, Health};
        use shimmy_firmware::drivers::coil_pwm::CoilDriver;
        use shimmy_firmware::monitoring::safe_controller;
        use shimmy_firmware::sim::{self, SimPwm, SimWorld};
        static WORLD: SimWorld = SimWorld::new();
        let mut sensors = sim::sensors(&WORLD);
        let Ok(mut coil) = CoilDriver::new(SimPwm::new(&WORLD), sim::COIL);
        let mut ctrl = safe_controller();
        let mut h = Health::default();
        // The simulated world (two sinf per step) is advanced outside the measurement: only
        // the firmware's own work is counted (on the board the sensors answer by themselves).
        // 1100 steps of warm-up (rolling, the boot-time speed fault recovered, shimmy present,
        // ASMC adapting, supervisor in Normal), then 50 measured.
        let mut worst = 0;
        for step in 0..1150 {
            WORLD.set_step(step);
            let mut one = || {
                let s = sensors.sample(sim::TICKS_PER_STEP);
                let o = supervised_step(&mut ctrl, &s, Some(coil.drive_a()), INSIDE_WINDOW, &mut h);
                let _ = drive_coil(&mut coil, &o);
            };
            if step < 1100 {
                one();
            } else {
                worst = worst.max(measure_once(one));
            }
        }
        if ctrl.supervisor().mode() != shimmy_core::supervisor::policy::Mode::Normal {
            return u32::MAX; // not the path we meant to measure
        }
        CONTROL_MAX.store(worst, Ordering::Relaxed);
        worst
    }

    fn safe_step() -> u32 {
        use shimmy_core::supervisor::frame::RawFrame;
        let mut c = shimmy_firmware::monitoring::safe_controller();
        let mut seed = 1;
        let mut worst = 0;
        for k in 0..400u32 {
            let (l, r) = yaw(k, &mut seed);
            let mut f = RawFrame::ok(k * 1000, 10.0 * l, 10.0 * r, 15.0);
            f.coil_current_a = Some(c.last_command_a());
            if k < 300 {
                c.step(&f, INSIDE_WINDOW);
            } else {
                worst = worst.max(measure_once(|| {
                    black_box(c.step(black_box(&f), INSIDE_WINDOW));
                }));
            }
        }
        worst
    }

    /// (worst plain push, worst decimated push, worst meter run) after 3 s of warm-up.
    fn meter_counts() -> (u32, u32, u32) {
        use shimmy_firmware::monitoring::{DataMargin, MeterSample};
        let Ok(mut d) = DataMargin::new() else {
            return (u32::MAX, u32::MAX, u32::MAX);
        };
        let mut seed = 7;
        let (mut plain, mut dec, mut run) = (0, 0, 0);
        let mut run_acc = 0u32;
        for k in 0..3500u32 {
            let (l, r) = yaw(k, &mut seed);
            let s = MeterSample {
                step: k,
                psi_l_rad: l,
                psi_r_rad: r,
                speed_mps: 15.0,
                cmd_a: 0.5,
            };
            if k < 3000 {
                let _ = d.push(&s, None);
                continue;
            }
            let mut got = false;
            let n = measure_once(|| got = black_box(d.push(black_box(&s), None)).is_some());
            run_acc += n;
            if got {
                dec = dec.max(n);
                run = run.max(run_acc);
                run_acc = 0;
            } else {
                plain = plain.max(n);
            }
        }
        METER_RUN_MAX.store(run, Ordering::Relaxed);
        (plain, dec, run)
    }

    /// The worst meter run (10 pushes) with a model margin the data contradict, after the
    /// fusion has decided: the model says zeta 0.2 with its onset 5 m/s ahead, the yaw (a
    /// zeta 0.05 mode at 7 Hz) is far less damped, so the consistency flag drops and every report carries the
    /// corrected margin (the curvature-keeping onset of the shifted model curve), the path the
    /// plain meter run (no model) never reaches. Measured over 0.5 s after 16 s of warm-up
    /// (the slow meter's warm-up, one meter memory and the 3 s hold); `u32::MAX` (over budget)
    /// unless every measured report came from that path.
    fn meter_run_with_model() -> u32 {
        use shimmy_core::estimator::model_margin::ModelMargin;
        let model = ModelMargin {
            zeta: 0.2,
            freq_hz: 7.0,
            dzeta_dv_per_mps: -0.03,
            v_crit_onset_mps: Some(20.0),
            valid: true,
        };
        let run = damped_mode_meter_run(Some(&model));
        METER_MODEL_RUN_MAX.store(run, Ordering::Relaxed);
        run
    }

    /// The same meter run on the same yaw without a model margin (fusion returns early): the
    /// difference to the entry above is the model-margin path's own cost.
    fn meter_run_damped_no_model() -> u32 {
        let run = damped_mode_meter_run(None);
        METER_DAMPED_RUN_MAX.store(run, Ordering::Relaxed);
        run
    }

    /// Worst meter run over 0.5 s after 16 s on a damped-mode yaw, with `model` handed to
    /// every push; with a model, `u32::MAX` unless every measured report carried the
    /// corrected margin.
    fn damped_mode_meter_run(
        model: Option<&shimmy_core::estimator::model_margin::ModelMargin>,
    ) -> u32 {
        use shimmy_core::estimator::fusion::MarginSource;
        use shimmy_firmware::monitoring::{DataMargin, MeterSample};
        let Ok(mut d) = DataMargin::new() else {
            return u32::MAX;
        };
        // a damped mode (zeta 0.05 at 7 Hz: AR(2) poles at exp(s T), T = 1 ms) driven by the
        // LCG's white noise, about 1.4e-3 rad RMS: the corrected damping stays positive, so
        // the whole corrected-onset computation (the root of the shifted quadratic) runs
        let (zeta, w) = (0.05f32, 2.0 * core::f32::consts::PI * 7.0);
        let rho = libm::expf(-zeta * w * 1e-3);
        let a1 = 2.0 * rho * libm::cosf(w * libm::sqrtf(1.0 - zeta * zeta) * 1e-3);
        let a2 = -rho * rho;
        let (mut y1, mut y2) = (0.0f32, 0.0f32);
        let mut seed = 7u32;
        let (mut run, mut run_acc, mut corrected) = (0u32, 0u32, true);
        for k in 0..16_500u32 {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let e = ((seed >> 8) as f32 / 16_777_216.0 - 0.5) * 2e-5;
            let y = a1 * y1 + a2 * y2 + e;
            (y2, y1) = (y1, y);
            let (l, r) = (y, 0.98 * y);
            let s = MeterSample {
                step: k,
                psi_l_rad: l,
                psi_r_rad: r,
                speed_mps: 15.0,
                cmd_a: 0.5,
            };
            if k < 16_000 {
                let _ = d.push(&s, model);
                continue;
            }
            let mut out = None;
            run_acc += measure_once(|| out = black_box(d.push(black_box(&s), model)));
            if let Some((u, _)) = out {
                corrected &= model.is_none()
                    || u.report.margin_source == MarginSource::Data
                        && !u.report.model_consistent
                        && u.report.zeta_correction != 0.0
                        && u.report.speed_margin_mps.is_some_and(|m| m > 0.0);
                run = run.max(run_acc);
                run_acc = 0;
            }
        }
        if !corrected {
            return u32::MAX;
        }
        run
    }

    /// The store's RAM flash for the benchmark: 2 KiB sectors (the page scans of the board's
    /// 128 KiB sectors cost more per operation; the instructions per byte are the same).
    type BenchFlash = shimmy_firmware::store::RamFlash<{ 4 * 2048 }, 2048>;

    /// A booted store on a fresh RAM flash with a saved vehicle and `entries` log entries.
    fn bench_store(entries: u32) -> shimmy_firmware::store::Store<BenchFlash> {
        use shimmy_firmware::fault_memory::ResetCause;
        use shimmy_firmware::store::{Layout, StandstillWatch, Store};
        let Ok(b) = Store::boot(
            BenchFlash::new(),
            Layout::split(2048, 2, 2),
            ResetCause::PowerOn,
            0,
        ) else {
            finish(Outcome::Failure)
        };
        let mut store = b.store;
        let mut watch = StandstillWatch::new();
        watch.observe(0.0, 0.0, 0.0);
        if let Some(token) = watch.check(2.0) {
            let _ = store.save_config(&image_vehicle(), &token);
        }
        for k in 0..entries {
            store.append(&shimmy_entry(k));
        }
        store
    }

    fn shimmy_entry(k: u32) -> shimmy_firmware::store::LogEntry {
        shimmy_firmware::store::LogEntry::Shimmy(shimmy_firmware::store::ShimmyEvent {
            start_s: f64::from(k),
            speed_mps: 20.0,
            freq_hz: 8.0,
            peak_amplitude_rad: 0.02,
            duration_s: 3.0,
            shimmy_s: 2.0,
            level: 3,
            open: false,
            peak_current_a: 2.0,
            mean_current_a: 1.0,
        })
    }

    fn store_load() -> u32 {
        let mut store = bench_store(20);
        measure(|| {
            black_box(store.load_config());
        })
    }

    fn store_append() -> u32 {
        let mut store = bench_store(20);
        let mut k = 100;
        measure(|| {
            k += 1;
            black_box(store.append(&shimmy_entry(k)));
        })
    }

    fn push_plain() -> u32 {
        meter_counts().0
    }

    fn push_decimated() -> u32 {
        meter_counts().1
    }

    fn meter_run() -> u32 {
        meter_counts().2
    }

    /// Per meter run, the meter task's work besides `DataMargin::push` (max over 0.5 s after
    /// 3 s of warm-up): for each of the 10 samples the recorder's command bookkeeping, then the
    /// recorder's episode and fault check and the link's update (`main.rs`).
    fn meter_bookkeeping() -> u32 {
        use shimmy_firmware::control::Health;
        use shimmy_firmware::fault_memory::ResetRecord;
        use shimmy_firmware::link::{Batch, LinkState};
        use shimmy_firmware::monitoring::{DataMargin, MeterSample};
        use shimmy_link::log::Recorder;
        let Ok(mut d) = DataMargin::new() else {
            return u32::MAX;
        };
        let mut link = LinkState::new(&ResetRecord::fresh().sealed(), image_vehicle());
        let mut recorder = Recorder::new();
        let h = Health::default();
        let mut seed = 7;
        let (mut run, mut worst) = (0u32, 0u32);
        for k in 0..3500u32 {
            let (l, r) = yaw(k, &mut seed);
            let s = MeterSample {
                step: k,
                psi_l_rad: l,
                psi_r_rad: r,
                speed_mps: 15.0,
                cmd_a: 0.5,
            };
            run += measure_once(|| {
                recorder.on_command(black_box(s.cmd_a));
            });
            if let Some((u, _)) = d.push(&s, None) {
                let monitor = d.pipeline().monitor();
                run += measure_once(|| {
                    let mut batch = Batch::new();
                    recorder.on_update(monitor, &mut batch);
                    recorder.on_faults(k, black_box(h.active_faults), 0, &mut batch);
                    let open = recorder.open_event(monitor);
                    link.on_update(&u, open, black_box(&h), 0, k);
                    black_box(batch);
                });
                if k >= 3000 {
                    worst = worst.max(run);
                }
                run = 0;
            }
        }
        BOOKKEEPING_MAX.store(worst, Ordering::Relaxed);
        worst
    }

    /// A telemetry frame of the link task while a host watches (`Device::poll_stream` after a
    /// margin update: the report into a frame), max over 0.5 s after 3 s of warm-up.
    fn link_telemetry() -> u32 {
        use shimmy_firmware::control::Health;
        use shimmy_firmware::fault_memory::ResetRecord;
        use shimmy_firmware::link::{BoardLink, LinkState};
        use shimmy_firmware::monitoring::{DataMargin, MeterSample};
        use shimmy_link::device::{Device, REPLY_BYTES};
        use shimmy_link::frame::{encode, MAX_FRAME};
        use shimmy_link::wire::{Request, PROTOCOL_HEADER};
        let Ok(mut d) = DataMargin::new() else {
            return u32::MAX;
        };
        let mut state = LinkState::new(&ResetRecord::fresh().sealed(), image_vehicle());
        let mut task = shimmy_firmware::store::StoreTask::new(bench_store(0));
        let mut dev = Device::new();
        let mut reply = [0u8; REPLY_BYTES];
        let mut req = [0u8; MAX_FRAME + 1];
        let Ok(n) = encode(PROTOCOL_HEADER, &Request::Telemetry { on: true }, &mut req) else {
            return u32::MAX;
        };
        for &b in req.iter().take(n) {
            let mut link = BoardLink {
                state: &mut state,
                store: &mut task,
            };
            let _ = dev.on_byte(b, &mut link, &mut reply);
        }
        let h = Health::default();
        let mut seed = 7;
        let mut worst = 0;
        for k in 0..3500u32 {
            let (l, r) = yaw(k, &mut seed);
            let s = MeterSample {
                step: k,
                psi_l_rad: l,
                psi_r_rad: r,
                speed_mps: 15.0,
                cmd_a: 0.5,
            };
            if let Some((u, _)) = d.push(&s, None) {
                state.on_update(&u, None, &h, 0, k);
                let mut sent = false;
                let n = measure_once(|| {
                    let mut link = BoardLink {
                        state: &mut state,
                        store: &mut task,
                    };
                    sent = black_box(dev.poll_stream(&mut link, &mut reply)).is_some();
                });
                if !sent {
                    return u32::MAX; // not the path we meant to measure
                }
                if k >= 3000 {
                    worst = worst.max(n);
                }
            }
        }
        TELEMETRY_MAX.store(worst, Ordering::Relaxed);
        worst
    }

    /// One pass of the background loop after a meter run with no model cycle due, as `main.rs`
    /// runs it (`background::PassGate`, 100 Hz): the store's pass while moving (no entry, no
    /// fault entry), the check for a host-written vehicle, a model call between two cycles.
    fn idle_pass() -> u32 {
        use shimmy_firmware::fault_memory::ResetRecord;
        use shimmy_firmware::link::LinkState;
        use shimmy_firmware::monitoring::ModelTask;
        use shimmy_firmware::store::{Motion, StoreTask};
        let mut task = StoreTask::new(bench_store(0));
        let mut link = LinkState::new(&ResetRecord::fresh().sealed(), image_vehicle());
        let mut model = ModelTask::new(image_vehicle().model(), board_update());
        let v = 15.0;
        // the cold first cycle completes; the calls measured come before the next one is due
        let mut t = 0.0;
        let mut done = false;
        for _ in 0..2000 {
            t += 1e-3;
            if model.step(t, v).is_some() {
                done = true;
                break;
            }
        }
        if !done {
            return u32::MAX;
        }
        let motion = Motion {
            t_s: t,
            speed_mps: v,
            cmd_peak_a: 0.5,
        };
        let worst = measure(|| {
            black_box(task.step(black_box(motion), core::iter::empty()));
            black_box(link.take_unsaved());
            black_box(model.step(black_box(t), v));
        });
        IDLE_PASS_MAX.store(worst, Ordering::Relaxed);
        worst
    }

    /// A wake of the background loop with nothing new (the other ~1 kHz wakes): the gate's
    /// check, which sends it back to sleep.
    fn idle_wake() -> u32 {
        use shimmy_firmware::background::PassGate;
        use shimmy_firmware::monitoring::ModelTask;
        let model = ModelTask::new(image_vehicle().model(), board_update());
        let mut gate = PassGate::new();
        let t = 1.25;
        gate.due(t, false);
        let mut due = false;
        let worst = measure(|| {
            due |= gate.due(black_box(t), black_box(&model).tracker().busy());
        });
        if due {
            return u32::MAX; // not the path we meant to measure
        }
        IDLE_WAKE_MAX.store(worst, Ordering::Relaxed);
        worst
    }

    /// Instructions the link's handler takes for `req` fed byte by byte (the last byte
    /// completes the frame: decode, answer, reply frame), summed, on a store with `log_entries`
    /// shimmy entries; `u32::MAX` when the reply is shorter than `min_reply` bytes (an error
    /// reply: not the path meant).
    fn request_instructions(
        req: &shimmy_link::wire::Request<'_>,
        log_entries: u32,
        min_reply: usize,
    ) -> u32 {
        use shimmy_firmware::fault_memory::ResetRecord;
        use shimmy_firmware::link::{BoardLink, LinkState};
        use shimmy_link::device::{Device, REPLY_BYTES};
        use shimmy_link::frame::{encode, MAX_FRAME};
        use shimmy_link::wire::PROTOCOL_HEADER;
        let mut state = LinkState::new(&ResetRecord::fresh().sealed(), image_vehicle());
        let mut task = shimmy_firmware::store::StoreTask::new(bench_store(log_entries));
        let mut dev = Device::new();
        let mut frame = [0u8; MAX_FRAME + 1];
        let Ok(n) = encode(PROTOCOL_HEADER, req, &mut frame) else {
            return u32::MAX;
        };
        let mut reply = [0u8; REPLY_BYTES];
        let mut link = BoardLink {
            state: &mut state,
            store: &mut task,
        };
        let mut total = 0;
        let mut replied = 0;
        for &b in frame.iter().take(n) {
            total += measure_once(|| {
                replied = black_box(dev.on_byte(black_box(b), &mut link, &mut reply)).unwrap_or(0);
            });
        }
        if replied < min_reply {
            return u32::MAX;
        }
        total
    }

    /// A host reading the log: the request for the last page (entries 32-40) of a flash log of
    /// 40 shimmy entries and the boot. The handler walks the flash queue from its oldest entry
    /// for every page, so the cost grows with the log. A full page of 8 shimmy entries is more
    /// than 300 bytes; an error reply is short.
    fn link_events_page() -> u32 {
        request_instructions(
            &shimmy_link::wire::Request::ReadEvents { first: 32 },
            40,
            300,
        )
    }

    /// One config-get request through the link's handler (the reply holds the vehicle record,
    /// more than 500 bytes).
    fn link_request() -> u32 {
        request_instructions(&shimmy_link::wire::Request::GetConfig, 0, 500)
    }

    fn eigen_update_f32() -> u32 {
        use shimmy_core::eigen::eigenvalues_of;
        use shimmy_core::vehicles::car::PlantParams;
        let p = PlantParams::nominal();
        let mut v = 12.0;
        measure(|| {
            let a = shimmy_core::vehicles::car::linearise(&p, black_box(v), 0.0);
            let _ = black_box(eigenvalues_of::<f32, _>(&a));
            v += 0.1;
        })
    }

    /// The nominal plant's shimmy pair at 8 m/s (f64 Schur + inverse iteration, for the
    /// eigenvector rows' inputs).
    fn shimmy_pair() -> (
        shimmy_core::eigen::StateMatrix,
        nalgebra::Complex<f64>,
        shimmy_core::eigen::CVector,
    ) {
        use shimmy_core::eigen;
        use shimmy_core::vehicles::car::PlantParams;
        let p = PlantParams::nominal();
        let a = shimmy_core::vehicles::car::linearise(&p, 8.0, 0.0);
        let l = eigen::eigenvalues_of::<f32, _>(&a)
            .and_then(|v| eigen::least_damped_mode(&v))
            .map_or(nalgebra::Complex::new(-1.0, 40.0), |m| m.eigenvalue());
        let v = eigen::eigenvector_of::<f32, _>(&a, l).unwrap_or_else(|_| eigen::CVector::zeros());
        (a, l, v)
    }

    /// The board's model update configuration ([`shimmy_firmware::monitoring::board_pipeline`]).
    fn board_update() -> shimmy_core::estimator::model_update::ModelUpdateConfig {
        shimmy_firmware::monitoring::board_pipeline(&image_vehicle()).matched_update()
    }

    /// A model task after its first tracker cycle at 18 km/h, and a measurement there: the
    /// model's own mode with its damping 0.005 higher, so every update is applied, not gated.
    fn update_case() -> Option<(
        shimmy_firmware::monitoring::ModelTask,
        shimmy_core::estimator::model_update::Measurement,
    )> {
        use shimmy_core::estimator::meter::mode_meter::ModeEstimate;
        use shimmy_core::estimator::model_update::Measurement;
        use shimmy_firmware::monitoring::ModelTask;
        let v = 5.0;
        let mut task = ModelTask::new(image_vehicle().model(), board_update());
        let mut t = 0.0;
        while task.step(t, v).is_none() {
            t += 1e-3;
            if t > 2.0 {
                return None;
            }
        }
        let p = task.updater().predict(f64::from(v), 0.0)?;
        let m = Measurement {
            t_s: t,
            speed_mps: v,
            c_damper_nspm: 0.0,
            slow: ModeEstimate {
                zeta: p.zeta as f32 + 0.005,
                sigma_zeta: 0.01,
                freq_hz: p.freq_hz as f32,
                wn_hz: p.wn_hz as f32,
                valid: true,
                ..ModeEstimate::default()
            },
        };
        Some((task, m))
    }

    /// One measurement update of the online model update (`estimator::model_update`) on the
    /// image's model: the eigen-solves in [`shimmy_firmware::monitoring::ModelFloat`], a
    /// linearisation per parameter for the Jacobian and the filter step in f64; once per
    /// `period_s` (1 s) when the meter's estimate is valid.
    fn model_update_step() -> u32 {
        let Some((task, m)) = update_case() else {
            return u32::MAX;
        };
        let mut up = task.updater().clone();
        let worst = measure(|| {
            let _ = black_box(up.apply(black_box(&m)));
        });
        MODEL_UPDATE_MAX.store(worst, Ordering::Relaxed);
        worst
    }

    /// The onset's sigma the model task re-evaluates after every
    /// [`shimmy_firmware::monitoring::SIGMA_EVERY`]th update (`ModelTask::refresh_sigma`).
    fn onset_sigma_step() -> u32 {
        let Some((mut task, m)) = update_case() else {
            return u32::MAX;
        };
        let _ = task.apply(&m);
        let worst = measure(|| {
            task.refresh_sigma();
            black_box(&task);
        });
        ONSET_SIGMA_MAX.store(worst, Ordering::Relaxed);
        worst
    }

    fn eigenvector_f32() -> u32 {
        let (a, l, _) = shimmy_pair();
        measure(|| {
            let _ = black_box(shimmy_core::eigen::eigenvector_of::<f32, _>(
                black_box(&a),
                l,
            ));
        })
    }

    fn eigenvectors_f32() -> u32 {
        let (a, l, _) = shimmy_pair();
        measure(|| {
            let _ = black_box(shimmy_core::eigen::eigenvectors_of::<f32, _>(
                black_box(&a),
                l,
            ));
        })
    }

    fn linearise_only() -> u32 {
        let p = shimmy_core::vehicles::car::PlantParams::nominal();
        measure(|| {
            let _ = black_box(shimmy_core::vehicles::car::linearise(
                &p,
                black_box(8.0),
                0.0,
            ));
        })
    }

    /// One Newton iteration (the warm case: the start is the converged pair, so one iteration
    /// meets the bound) including the left eigenvector.
    fn newton_f32() -> u32 {
        let (a, l, v) = shimmy_pair();
        let v = shimmy_core::eigen::narrowed::<f32, _>(&v);
        let Ok(ep) = shimmy_core::eigen::refine_eigenpair::<f32, _>(&a, l, &v, 4) else {
            return u32::MAX;
        };
        measure(|| {
            let r = shimmy_core::eigen::refine_eigenpair::<f32, _>(
                black_box(&a),
                ep.lambda_f64(),
                &ep.right,
                1,
            );
            let _ = black_box(r);
        })
    }

    /// (max instructions of one call, first (cold) cycle, max warm cycle): the firmware's
    /// tracker on a speed ramp 24 -> 36 km/h that moves 1 km/h per cycle (10x the 0.1 km/h per
    /// cycle of the 1 km/h/s requirement ramp at 10 Hz: the warm start has more to do, so this
    /// bounds the cycle from above), through the nominal Hopf onset at 29.35 km/h. Each call is
    /// measured; a cycle's count is the sum of its calls. Computed once.
    fn tracker_counts() -> (u32, u32, u32) {
        use shimmy_core::units::kmh_to_mps;
        use shimmy_firmware::monitoring::{ModelTask, MODEL_REFRESH_S};
        static DONE: AtomicU32 = AtomicU32::new(0);
        static CALL: AtomicU32 = AtomicU32::new(0);
        static COLD: AtomicU32 = AtomicU32::new(0);
        static CYCLE: AtomicU32 = AtomicU32::new(0);
        if DONE.load(Ordering::Relaxed) == 0 {
            let mut m = ModelTask::new(image_vehicle().model(), board_update());
            let (mut call, mut cold, mut cycle) = (0u32, 0u32, 0u32);
            for c in 0..13u32 {
                let t = c as f64 * f64::from(MODEL_REFRESH_S);
                let v = kmh_to_mps(24.0 + f64::from(c)) as f32;
                let mut acc = 0u32;
                let mut done = false;
                for k in 0..200u16 {
                    // the clock advances 1 ms per call, as in the firmware's loop (a cycle
                    // starts at the first call at or after its due time)
                    let tk = t + f64::from(k) * 1e-3;
                    let n = measure_once(|| done = black_box(m.step(tk, v)).is_some());
                    call = call.max(n);
                    acc = acc.saturating_add(n);
                    if done {
                        break;
                    }
                }
                if !done {
                    acc = u32::MAX;
                }
                if c == 0 {
                    cold = acc;
                } else {
                    cycle = cycle.max(acc);
                }
            }
            CALL.store(call, Ordering::Relaxed);
            COLD.store(cold, Ordering::Relaxed);
            CYCLE.store(cycle, Ordering::Relaxed);
            DONE.store(1, Ordering::Relaxed);
        }
        (
            CALL.load(Ordering::Relaxed),
            COLD.load(Ordering::Relaxed),
            CYCLE.load(Ordering::Relaxed),
        )
    }

    fn tracker_call() -> u32 {
        tracker_counts().0
    }

    fn tracker_cold_cycle() -> u32 {
        tracker_counts().1
    }

    fn tracker_cycle() -> u32 {
        tracker_counts().2
    }

    /// The meter run the load rows count: the reference run (the 7 Hz yaw of [`yaw`], no
    /// model) plus the model-margin path's own cost, the difference between the two runs on
    /// the damped-mode yaw with and without a model (the firmware always hands the meter
    /// task a model margin). `u32::MAX` when an entry it needs failed. The damped-mode yaw
    /// also costs the meter itself more (its own row, without a model): a signal dependence
    /// of the root solve, not of the fusion.
    fn meter_run_max() -> u32 {
        let [reference, with_model, without] =
            [&METER_RUN_MAX, &METER_MODEL_RUN_MAX, &METER_DAMPED_RUN_MAX]
                .map(|a| a.load(Ordering::Relaxed));
        if [reference, with_model, without].contains(&u32::MAX) {
            return u32::MAX;
        }
        reference.saturating_add(with_model.saturating_sub(without))
    }

    /// Wall time of the worst warm model cycle on the board at the measured load [ms]: the
    /// background loop gets what the control step (1 kHz) and the meter run (100 Hz) leave of
    /// [`INSN_PER_S`] (168 MHz at 1.5 cycles per instruction). `u32::MAX` when nothing is left.
    fn model_refresh_ms() -> u32 {
        let control = u64::from(CONTROL_MAX.load(Ordering::Relaxed)) * 1000;
        let meter = u64::from(meter_run_max()) * 100;
        let avail = INSN_PER_S.saturating_sub(control + meter);
        let cycle = u64::from(tracker_counts().2);
        defmt::info!(
            "model refresh: {=u64} instructions/s available for the background loop ({=u64} - control {=u64} - meter {=u64}), worst cycle {=u64} instructions",
            avail,
            INSN_PER_S,
            control,
            meter,
            cycle
        );
        if avail == 0 {
            return u32::MAX;
        }
        u32::try_from(cycle * 1000 / avail).unwrap_or(u32::MAX)
    }

    /// The whole firmware's CPU load at its rates [per mille]: control step x 1 kHz + meter run
    /// with its link and store bookkeeping x 100 Hz + worst warm model cycle x 10 Hz + one
    /// model update x 1 Hz and the onset's sigma x 1/5 Hz + the
    /// background loop's passes between cycles x 100 Hz and its wakes x 1 kHz + the link's
    /// telemetry frames x 10 Hz
    /// (a host watching; host requests are not counted), in cycles at [`LOAD_CPI`] cycles per
    /// instruction, over 168 MHz.
    fn cpu_load_permille() -> u32 {
        let control = u64::from(CONTROL_MAX.load(Ordering::Relaxed)) * 1000;
        let meter =
            (u64::from(meter_run_max()) + u64::from(BOOKKEEPING_MAX.load(Ordering::Relaxed))) * 100;
        let model = u64::from(tracker_counts().2) * 10;
        // one measurement update per second (`ModelUpdateConfig::period_s`), the onset's
        // sigma after every `SIGMA_EVERY`th
        let update = u64::from(MODEL_UPDATE_MAX.load(Ordering::Relaxed))
            + u64::from(ONSET_SIGMA_MAX.load(Ordering::Relaxed))
                / u64::from(shimmy_firmware::monitoring::SIGMA_EVERY);
        let idle = u64::from(IDLE_PASS_MAX.load(Ordering::Relaxed)) * 100
            + u64::from(IDLE_WAKE_MAX.load(Ordering::Relaxed)) * 1000;
        let link = u64::from(TELEMETRY_MAX.load(Ordering::Relaxed)) * 10;
        let per_s = control + meter + model + update + idle + link;
        defmt::info!(
            "cpu load: control {=u64} + meter with bookkeeping {=u64} + model {=u64} + model update {=u64} + background passes {=u64} + telemetry {=u64} = {=u64} instructions/s, {=u64} cycles/s at {=u64} CPI of 168 MHz",
            control,
            meter,
            model,
            update,
            idle,
            link,
            per_s,
            per_s * LOAD_CPI,
            LOAD_CPI
        );
        // rounded up: a load just over a per-mille step must not pass as the step below
        u32::try_from((per_s * LOAD_CPI * 1000).div_ceil(168_000_000)).unwrap_or(u32::MAX)
    }

    fn sinf() -> u32 {
        let mut x = 0.7f32;
        measure(|| {
            x = black_box(libm::sinf(black_box(x))) + 0.5;
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
                Budget::Hard(b) => {
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
                Budget::None => defmt::info!(
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
