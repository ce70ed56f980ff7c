//! The firmware application (RTIC 2). On the host this binary only explains how to build it.
//!
//! - `control` (TIM2 update interrupt, 1 kHz, priority 3): sensors -> validation -> control seam
//!   -> coil PWM; timing check (late start / overrun counters); feeds the watchdog. Nothing
//!   else may run at this priority.
//! - `estimator` (software task, priority 1, spawned every 10th step = 100 Hz): the mode
//!   meter / eigen-margin seam (slow update every 10th run = 10 Hz) and 1 Hz telemetry.
//! - `idle`: WFI.
//!
//! The `qemu` build runs the same application on simulated sensors and exits after
//! `board::QEMU_STEPS` steps with the counters, failing if they are not what the simulation
//! injected.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[rtic::app(device = shimmy_firmware::hal::pac, dispatchers = [EXTI0, EXTI1])]
mod app {
    use shimmy_firmware::board::{self, Board};
    use shimmy_firmware::control::{
        decide, ControlInput, EstimatorStep, FixedCurrent, Health, RmsEstimator,
    };
    use shimmy_firmware::drivers::coil_pwm::FAILSAFE_CURRENT_A;
    use shimmy_firmware::periph::PERIOD_TICKS;

    /// Control period [s].
    const DT_S: f32 = 1e-3;
    /// Estimator runs every this many control steps (100 Hz).
    const ESTIMATOR_DECIMATION: u32 = 10;
    /// Slow (eigen-margin) update every this many estimator runs (10 Hz).
    const SLOW_DIVIDER: u32 = 10;
    /// Telemetry every this many estimator runs (1 Hz).
    const TELEMETRY_DIVIDER: u32 = 100;

    #[shared]
    struct Shared {
        health: Health,
        /// Newest validated input for the estimator (decimated).
        latest: Option<ControlInput>,
    }

    #[local]
    struct Local {
        board: Board,
        // TODO(core controller): replace by the core's controller behind `ControlStep`.
        ctrl: FixedCurrent,
        step: u32,
        // TODO(core estimator): replace by the core's estimator behind `EstimatorStep`.
        est: RmsEstimator,
        est_runs: u32,
    }

    #[init]
    fn init(cx: init::Context) -> (Shared, Local) {
        shimmy_firmware::stack::paint();
        defmt::info!(
            "{=str} booted (core {=str}); fail-safe coil current {=f32} A",
            shimmy_firmware::BANNER,
            shimmy_core::VERSION,
            FAILSAFE_CURRENT_A
        );
        let board = board::init(cx.device);
        (
            Shared {
                health: Health::default(),
                latest: None,
            },
            Local {
                board,
                ctrl: FixedCurrent {
                    current_a: FAILSAFE_CURRENT_A,
                },
                step: 0,
                est: RmsEstimator::default(),
                est_runs: 0,
            },
        )
    }

    #[idle]
    fn idle(_: idle::Context) -> ! {
        loop {
            cortex_m::asm::wfi();
        }
    }

    #[task(binds = TIM2, priority = 3, local = [board, ctrl, step], shared = [health, latest])]
    fn control(cx: control::Context) {
        let b = cx.local.board;
        let entry = b.timer.now_ticks();
        b.timer.clear_update();
        let latency = b.timer.entry_latency_ticks(entry);
        let step = *cx.local.step;
        let (mut health, mut latest) = (cx.shared.health, cx.shared.latest);
        #[cfg(feature = "qemu")]
        board::WORLD.set_step(step);

        let samples = b.sensors.sample(PERIOD_TICKS);
        let (cmd, input) = health.lock(|h| decide(cx.local.ctrl, &samples, step, DT_S, h));
        let pwm_ok = b.coil.set_current_a(cmd).is_ok();

        let mut busy = false;
        if step.is_multiple_of(ESTIMATOR_DECIMATION) {
            if input.is_some() {
                latest.lock(|l| *l = input);
            }
            busy = estimator::spawn().is_err();
        }

        let exit = b.timer.now_ticks();
        let wrapped = b.timer.update_pending();
        health.lock(|h| {
            h.record_timing(latency, exit.wrapping_sub(entry), wrapped);
            h.pwm_errors += u32::from(!pwm_ok);
            h.estimator_busy += u32::from(busy);
            h.steps += 1;
        });
        // Fed only here: a control loop that stops completing steps resets the MCU.
        b.watchdog.feed();
        *cx.local.step = step.wrapping_add(1);

        #[cfg(feature = "qemu")]
        if step + 1 == board::QEMU_STEPS {
            qemu_finish(health.lock(|h| *h));
        }
    }

    #[task(priority = 1, local = [est, est_runs], shared = [health, latest])]
    async fn estimator(mut cx: estimator::Context) {
        if let Some(i) = cx.shared.latest.lock(|l| l.take()) {
            cx.local.est.update(&i);
        }
        *cx.local.est_runs += 1;
        let runs = *cx.local.est_runs;
        if runs.is_multiple_of(SLOW_DIVIDER) {
            cx.local.est.slow_update();
        }
        if runs.is_multiple_of(TELEMETRY_DIVIDER) {
            let h = cx.shared.health.lock(|h| *h);
            defmt::info!(
                "telemetry: toe-difference rms {=f32} mrad; {}",
                cx.local.est.last_rms_rad * 1e3,
                h
            );
        }
    }

    /// End of a `qemu` run: the counters must be exactly what the simulation injected, with
    /// no overrun and no late start.
    #[cfg(feature = "qemu")]
    fn qemu_finish(h: Health) -> ! {
        use shimmy_firmware::runtime::{finish, Outcome};
        use shimmy_firmware::sim::expected_faults;
        let (stack_used, stack_size) = shimmy_firmware::stack::high_water();
        defmt::info!("final counters: {}", h);
        defmt::info!(
            "stack high-water mark {=usize} B of {=usize} B",
            stack_used,
            stack_size
        );
        let (par, ef, glitch) = expected_faults(h.steps);
        let ok = h.steps == board::QEMU_STEPS
            && (h.enc_parity, h.enc_error_flag, h.speed_implausible) == (par, ef, glitch)
            && h.failsafe_steps == par + ef
            && h.enc_bus + h.enc_jump + h.current_faults + h.pwm_errors == 0
            && h.overruns == 0
            && h.late_starts == 0
            && h.estimator_busy == 0;
        if ok {
            defmt::info!(
                "qemu run ok: {=u32} steps, injected faults counted (parity {=u32}, error flag {=u32}, speed {=u32}), no overrun",
                h.steps, par, ef, glitch
            );
            finish(Outcome::Success)
        } else {
            defmt::error!(
                "qemu run: counters differ from the injected faults (parity {=u32}, error flag {=u32}, speed {=u32}) or timing failed",
                par, ef, glitch
            );
            finish(Outcome::Failure)
        }
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "shimmy-firmware runs on a Cortex-M4F: build it with --target thumbv7em-none-eabihf, \
         run it under QEMU with `cargo xtask qemu`, or flash a board (see README)."
    );
    std::process::exit(2);
}
