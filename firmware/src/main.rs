//! The firmware application (RTIC 2). On the host this binary only explains how to build it.
//!
//! | task | runs | priority | work |
//! |---|---|---|---|
//! | `control` | TIM2 update interrupt, 1 kHz | 3 | sensors -> validation -> core ASMC (`Controller::step`) -> coil PWM; pushes the step's sample into the SPSC queue; every 10th step spawns `meter`; timing counters; feeds the watchdog |
//! | `meter` | software task, 100 Hz | 2 | drains the queue into the core's `MarginEstimator<f32>` (10 pushes, one decimated RLS + roots update), fusion with the newest model margin, monitor; every 10th run spawns `model`; warnings on level changes, telemetry at 1 Hz |
//! | `model` | software task, 10 Hz | 1 | model margin in f64: shimmy mode + d zeta/dV (`dzeta_dv`, `ModeSelect::Shimmy`) and the Hopf onset speed (`critical_speed_near`, warm start) |
//! | `idle` | - | 0 | WFI |
//!
//! Nothing else runs at priority 3. The queue (heapless SPSC, lock-free) is why the 1 kHz task
//! never waits for the meter: see `shimmy_firmware::monitoring` for the instruction budget.
//!
//! The `qemu` build runs the same application on simulated sensors and exits after
//! `board::QEMU_STEPS` steps with the counters, failing if they are not what the simulation
//! injected.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[rtic::app(device = shimmy_firmware::hal::pac, dispatchers = [EXTI0, EXTI1])]
mod app {
    use heapless::spsc::{Consumer, Producer, Queue};
    use shimmy_core::estimator::ModelMargin;
    use shimmy_core::params::PlantParams;
    use shimmy_firmware::board::{self, Board};
    use shimmy_firmware::control::{decide, Health};
    use shimmy_firmware::drivers::coil_pwm::FAILSAFE_CURRENT_A;
    use shimmy_firmware::monitoring::{
        CoreController, DataMargin, MeterSample, ModelMarginTask, DT_S, METER_DECIMATION,
    };
    use shimmy_firmware::periph::PERIOD_TICKS;

    /// Model (eigen-margin) update every this many meter runs (10 Hz).
    const MODEL_DIVIDER: u32 = 10;
    /// Telemetry every this many meter runs (1 Hz).
    const TELEMETRY_DIVIDER: u32 = 100;
    /// SPSC capacity is one less than this: 3 meter periods of samples.
    const QUEUE_N: usize = 32;

    #[shared]
    struct Shared {
        health: Health,
        /// Newest model margin (written by `model`, read by `meter`).
        model: Option<ModelMargin>,
    }

    #[local]
    struct Local {
        board: Board,
        // TODO(core supervisor): wrap in the core's `SafeController` when it lands.
        ctrl: CoreController,
        step: u32,
        tx: Producer<'static, MeterSample>,
        rx: Consumer<'static, MeterSample>,
        data: DataMargin,
        meter_runs: u32,
        model_task: ModelMarginTask,
    }

    #[init(local = [queue: Queue<MeterSample, QUEUE_N> = Queue::new()])]
    fn init(cx: init::Context) -> (Shared, Local) {
        shimmy_firmware::stack::paint();
        defmt::info!(
            "{=str} booted (core {=str}); fail-safe coil current {=f32} A",
            shimmy_firmware::BANNER,
            shimmy_core::VERSION,
            FAILSAFE_CURRENT_A
        );
        let board = board::init(cx.device);
        let (tx, rx) = cx.local.queue.split();
        let Some(data) = DataMargin::new() else {
            // The core's default estimator configuration is checked by a host test; if it
            // were rejected the damper still gets the fail-safe current out of reset.
            panic!("estimator configuration rejected");
        };
        (
            Shared {
                health: Health::default(),
                model: None,
            },
            Local {
                board,
                ctrl: CoreController::asmc(),
                step: 0,
                tx,
                rx,
                data,
                meter_runs: 0,
                model_task: ModelMarginTask::new(PlantParams::nominal(), 0.0),
            },
        )
    }

    #[idle]
    fn idle(_: idle::Context) -> ! {
        loop {
            cortex_m::asm::wfi();
        }
    }

    #[task(binds = TIM2, priority = 3, local = [board, ctrl, step, tx], shared = [health])]
    fn control(cx: control::Context) {
        let b = cx.local.board;
        let entry = b.timer.now_ticks();
        b.timer.clear_update();
        let latency = b.timer.entry_latency_ticks(entry);
        let step = *cx.local.step;
        let mut health = cx.shared.health;
        #[cfg(feature = "qemu")]
        board::WORLD.set_step(step);

        let samples = b.sensors.sample(PERIOD_TICKS);
        let (cmd, input) = health.lock(|h| decide(cx.local.ctrl, &samples, step, DT_S, h));
        let pwm_ok = b.coil.set_current_a(cmd).is_ok();

        let dropped = cx
            .local
            .tx
            .enqueue(MeterSample::of(step, input.as_ref()))
            .is_err();
        let busy = step.is_multiple_of(METER_DECIMATION) && meter::spawn().is_err();

        let exit = b.timer.now_ticks();
        let wrapped = b.timer.update_pending();
        health.lock(|h| {
            h.record_timing(latency, exit.wrapping_sub(entry), wrapped);
            h.pwm_errors += u32::from(!pwm_ok);
            h.estimator_busy += u32::from(busy);
            h.meter_dropped += u32::from(dropped);
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

    #[task(priority = 2, local = [rx, data, meter_runs], shared = [health, model])]
    async fn meter(mut cx: meter::Context) {
        let model = cx.shared.model.lock(|m| *m);
        while let Some(s) = cx.local.rx.dequeue() {
            let Some(u) = cx.local.data.push(&s, model.as_ref()) else {
                continue;
            };
            *cx.local.meter_runs += 1;
            let runs = *cx.local.meter_runs;
            if u.level_changed {
                defmt::warn!(
                    "warning level {=str} at t = {=f32} s, {=f32} m/s: zeta fast {=f32} slow {=f32} ({=f32} Hz), amplitude {=f32} mrad, speed margin {=f32} m/s",
                    level_name(u.level),
                    u.report.t_s,
                    u.report.speed_mps,
                    u.report.zeta_fast,
                    u.report.zeta_data,
                    u.report.freq_hz,
                    u.meter.amplitude_rad * 1e3,
                    u.report.speed_margin_mps.unwrap_or(f32::NAN)
                );
            }
            if runs.is_multiple_of(MODEL_DIVIDER)
                && model::spawn(cx.local.data.speed_mps()).is_err()
            {
                cx.shared.health.lock(|h| h.model_busy += 1);
            }
            if runs.is_multiple_of(TELEMETRY_DIVIDER) {
                let h = cx.shared.health.lock(|h| *h);
                let r = &u.report;
                defmt::info!(
                    "margin: t {=f32} s, v {=f32} m/s, zeta data {=f32} +- {=f32} (valid {=bool}), fast {=f32}, {=f32} Hz, model zeta {=f32}, margin {=f32} m/s, ttc {=f32} s, consistent {=bool}, level {=str}; {}",
                    r.t_s,
                    r.speed_mps,
                    r.zeta_data,
                    r.sigma_zeta_data,
                    r.data_valid,
                    r.zeta_fast,
                    r.freq_hz,
                    r.zeta_model.unwrap_or(f32::NAN),
                    r.speed_margin_mps.unwrap_or(f32::NAN),
                    r.time_to_critical_s.unwrap_or(f32::NAN),
                    r.model_consistent,
                    level_name(u.level),
                    h
                );
            }
        }
    }

    #[task(priority = 1, local = [model_task], shared = [model])]
    async fn model(mut cx: model::Context, speed_mps: f32) {
        let m = cx.local.model_task.update(speed_mps);
        cx.shared.model.lock(|x| *x = Some(m));
    }

    fn level_name(l: shimmy_core::monitor::Level) -> &'static str {
        use shimmy_core::monitor::Level;
        match l {
            Level::Normal => "normal",
            Level::MarginLow => "margin-low",
            Level::ApproachingCritical => "approaching-critical",
            Level::ShimmyPresent => "shimmy-present",
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
            && h.meter_dropped == 0;
        // Not required (yet): `estimator_busy` / `model_busy` count spawns that found the
        // meter / model task still running. The meter's decimated update (~1.24 M
        // instructions) and the model update (~27 M) are over their periods' budgets
        // (`cargo xtask bench`); the queue keeps every sample (meter_dropped == 0 is
        // required) and the 1 kHz task never overruns. TODO(core pipeline / model_margin):
        // require both to be 0 once the incremental versions land.
        if h.estimator_busy + h.model_busy > 0 {
            defmt::warn!(
                "meter busy {=u32} times, model busy {=u32} times (over budget, see bench)",
                h.estimator_busy,
                h.model_busy
            );
        }
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
