//! The firmware application (RTIC 2). On the host this binary only explains how to build it.
//!
//! | task | runs | priority | work |
//! |---|---|---|---|
//! | `control` | TIM2 update interrupt, 1 kHz | 3 | sensors -> raw frame -> core `SafeController` (supervisor + margin-scheduled ASMC on the newest margin report + limiter) -> closed-loop coil current (PWM); pushes the step's validated sample into the SPSC queue; spawns `meter` on every 10th sample (`MeterCadence`); timing counters; feeds the watchdog |
//! | `meter` | software task, 100 Hz | 2 | drains the queue into the core's `DataPipeline` (mode meter, fusion with the newest model margin, monitor); publishes the report for the next control step; warnings on level changes; the log's recorder (episodes and faults to the store's queue); with the feature `probe-telemetry` the margin report and counters over the probe at 1 Hz |
//! | `link` | USART1 interrupt (a received byte; pended by `meter` at 10 Hz for the stream) | 1 | the host link (`shimmy_link::device::Device` over `shimmy_firmware::link::BoardLink`: the link's state and the flash store): one reply per request frame, telemetry frames while the stream is on; announces itself with a ready frame on its first run |
//! | `idle` | background loop | 0 | the core's `ModelMarginTracker`: one f32 eigen-solve per call, each completed cycle published to `meter`; between cycles the online model update's due measurement from `meter` (the tracker then runs on the updated model; the link serves the update's parameters and diagnosis); the flash store (`shimmy_firmware::store`: the event log the meter's recorder fills, erases only at standstill), a host-written vehicle saved at standstill and run after a restart; WFI when no cycle is due; a pass only after a meter run or while a cycle is under way (`shimmy_firmware::background::PassGate`) |
//!
//! Each task's shared work is a host-compilable function of the library, which the host's
//! `pil::HostApp` runs too: `control::ControlTask::run`, `monitoring::DataMargin::run`,
//! `background::model_pass`; the tasks here add the board's side (timers, coil, watchdog,
//! fault memory, store, link, logging).
//!
//! Nothing else runs at priority 3. The queue (heapless SPSC, lock-free) is why the 1 kHz task
//! never waits for the meter: see `shimmy_firmware::monitoring` for the instruction budget.
//!
//! The `qemu` build runs the same application on simulated sensors with injected faults and
//! exits after `board::QEMU_STEPS` steps with the counters, failing if they are not what the
//! simulation injected. The `pil` build runs it on the host's plant in lockstep
//! (`board/pil.rs`): the tasks call the build's hooks (`board::hooks`), which there report to
//! the host, and the idle loop starts the next step at once where the board would wait for the
//! timer; on the board they are empty.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[rtic::app(device = shimmy_firmware::hal::pac, dispatchers = [EXTI0, EXTI1])]
mod app {
    use heapless::spsc::{Consumer, Producer, Queue};
    use shimmy_core::control::actuator::FAILSAFE_CURRENT_A;
    use shimmy_core::estimator::model_update::Measurement;
    use shimmy_core::supervisor::faults::{FaultKind, FaultSet};
    use shimmy_core::supervisor::frame::MarginStatus;
    use shimmy_core::vehicle::BoardVehicle;
    use shimmy_firmware::background::{model_pass, PassGate};
    use shimmy_firmware::board::hooks::AppHooks;
    use shimmy_firmware::board::{self, Board, Hooks};
    use shimmy_firmware::control::{drive_coil, ControlTask, Health};
    use shimmy_firmware::fault_memory::{persist, BootPolicy, ResetCause, ResetRecord};
    use shimmy_firmware::link::{may_restart, save_vehicle, Batch, BoardLink, LinkState, Saved};
    use shimmy_firmware::monitoring::{
        board_pipeline, safe_controller_for, BoardCalibration, DataMargin, MeterEvent, MeterSample,
        ModelTask, Published,
    };
    use shimmy_firmware::periph::{LinkPort, PERIOD_TICKS};
    use shimmy_firmware::store::target::{self as store_target, TargetFlash};
    use shimmy_firmware::store::{ConfigSource, LogEntry, Motion, StoreTask};
    use shimmy_link::device::{Device, REPLY_BYTES};
    use shimmy_link::log::{DiagnosisWatch, Recorder};

    /// The probe's telemetry line every this many meter runs (1 Hz; feature `probe-telemetry`).
    #[cfg(feature = "probe-telemetry")]
    const TELEMETRY_DIVIDER: u32 = 100;
    /// The link's telemetry stream every this many meter runs (10 Hz).
    const LINK_STREAM_DIVIDER: u32 = 10;
    /// SPSC capacity is one less than this: 3 meter periods of samples.
    const QUEUE_N: usize = 32;
    /// Log entries from `meter` to the store in the background loop (capacity one less).
    const LOG_QUEUE_N: usize = 8;

    #[shared]
    struct Shared {
        health: Health,
        /// Newest model cycle (written by the background loop, read by `meter`).
        model: Option<Published>,
        /// Newest due measurement of the online model update (written by `meter`, taken by
        /// the background loop).
        measurement: Option<Measurement>,
        /// Time (s) and trusted speed (m/s) of the newest meter sample (for the model loop).
        now: (f64, f32),
        /// Validity of the newest margin report (for the supervisor's margin check).
        margin: MarginStatus,
        /// Time, trusted speed and peak coil command of the newest meter run (for the store's
        /// standstill watch).
        motion: Motion,
        /// The supervisor's latched faults (written by `control`, recorded by `meter`).
        latched: FaultSet,
        /// What the host link serves besides the store (written by `meter`, read and
        /// configured by `link`).
        link: LinkState,
        /// The flash store (the background loop's passes; the link reads and clears its log).
        store_task: StoreTask<TargetFlash>,
    }

    #[local]
    struct Local {
        board: Board,
        /// The supervised controller, the step count and which step spawns the meter task.
        control: ControlTask,
        /// The fault memory of this run (written back when it changes).
        record: ResetRecord,
        /// A reset loop was detected at boot: stay in the safe state.
        hold_safe: bool,
        tx: Producer<'static, MeterSample>,
        rx: Consumer<'static, MeterSample>,
        data: DataMargin,
        meter_runs: u32,
        model_task: ModelTask,
        log_tx: Producer<'static, LogEntry>,
        log_rx: Consumer<'static, LogEntry>,
        /// The one recorder of the event log (episodes and faults).
        recorder: Recorder,
        port: LinkPort,
        /// The ready frame has been sent.
        announced: bool,
    }

    #[init(local = [
        queue: Queue<MeterSample, QUEUE_N> = Queue::new(),
        log_queue: Queue<LogEntry, LOG_QUEUE_N> = Queue::new(),
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        shimmy_firmware::stack::paint();
        // An overflow into the statics faults instead (MemManage: coil off, reported, reset).
        let mut core = cx.core;
        shimmy_firmware::stack::guard(&mut core.MPU, &mut core.SCB);
        defmt::info!(
            "{=str} booted (core {=str}); fail-safe coil current {=f32} A",
            shimmy_firmware::BANNER,
            shimmy_core::VERSION,
            FAILSAFE_CURRENT_A
        );
        let cause = reset_cause(&cx.device.RCC);
        let stored = persist::load();
        let (record, policy) = ResetRecord::on_boot(&stored, cause);
        persist::store(&record);
        let latched = FaultSet::from_bits(record.latched_faults);
        // The store opens before board::init starts the watchdog: a boot after a power cut in a
        // standstill write may finish the compaction the cut interrupted (an erase).
        let Ok((store_task, boot)) = store_target::boot(!stored.is_valid(), cause, record.resets)
        else {
            // Only a second call or a layout that does not fit could fail (the layout is a
            // constant); the damper still gets the fail-safe current out of reset.
            panic!("store layout rejected");
        };
        report_config(&boot);
        let vehicle = boot.config.vehicle;
        let coil_dead =
            latched.contains(FaultKind::CoilOpen) || latched.contains(FaultKind::CoilShort);
        let hold_safe = policy == BootPolicy::HoldSafe;
        defmt::warn!(
            "reset record: {=u32} resets since power-on, {=u8} abnormal in a row within 60 s, latched faults {=u32:#x}{=str}",
            record.resets,
            record.quick_resets,
            latched.bits(),
            if hold_safe {
                "; RESET LOOP: holding the safe state, controller not run"
            } else {
                ""
            }
        );
        let mut ctrl = safe_controller_for(&vehicle);
        ctrl.supervisor_mut().restore_latched(latched);
        let (board, port) = board::init(cx.device, coil_dead);
        let (tx, rx) = cx.local.queue.split();
        let (log_tx, log_rx) = cx.local.log_queue.split();
        let Ok(data) =
            DataMargin::with_params(&board_pipeline(&vehicle), vehicle.wheel_order_radius_m())
        else {
            // The core's default configuration is checked by a host test; if it were rejected
            // the damper still gets the fail-safe current out of reset.
            panic!("estimator configuration rejected");
        };
        let model_task = ModelTask::new(vehicle.model(), board_pipeline(&vehicle).matched_update());
        let mut link = LinkState::new(&record, vehicle);
        link.on_model_update(model_task.updater());
        // The link task's first run sends the ready frame (the port listens from now on).
        rtic::pend(shimmy_firmware::hal::pac::Interrupt::USART1);
        // The watchdog runs since the board's first line; init ends here.
        board.watchdog.feed();
        (
            Shared {
                health: Health::default(),
                model: None,
                measurement: None,
                now: (0.0, f32::NAN),
                margin: MarginStatus::Invalid,
                motion: Motion::UNKNOWN,
                latched,
                link,
                store_task,
            },
            Local {
                board,
                control: ControlTask::new(ctrl),
                record,
                hold_safe,
                tx,
                rx,
                data,
                meter_runs: 0,
                model_task,
                log_tx,
                log_rx,
                // The run that latched the restored faults logged them.
                recorder: Recorder::after_boot(latched.bits()),
                port,
                announced: false,
            },
        )
    }

    /// The background loop: the model-margin tracker, one unit of work (at most one f32
    /// eigen-solve, ~0.16 M instructions, or one mode-shape/slope step) per call; the control and
    /// meter tasks preempt it at any instruction. Each cycle's margin is published; one in ten
    /// (1 Hz) is logged. A pass runs after each meter run or while a cycle is under way
    /// (`PassGate`); other wakes go back to sleep.
    #[idle(local = [model_task, log_rx, gate: PassGate = PassGate::new(), restart_due: bool = false, diagnosis: DiagnosisWatch = DiagnosisWatch::new(), diagnosis_entry: Option<LogEntry> = None], shared = [model, measurement, now, health, motion, link, store_task])]
    fn idle(mut cx: idle::Context) -> ! {
        loop {
            let motion = cx.shared.motion.lock(|m| *m);
            if !cx
                .local
                .gate
                .due(motion.t_s, cx.local.model_task.tracker().busy())
            {
                // Nothing new since the last pass: sleep until the next interrupt (PIL: the
                // next step at once, as after a pass with nothing due; its timer is off).
                Hooks::idle(false);
                continue;
            }
            let log_rx = &mut *cx.local.log_rx;
            let restart_due = &mut *cx.local.restart_due;
            let diagnosis = cx.local.diagnosis_entry.take();
            let link = &mut cx.shared.link;
            cx.shared.store_task.lock(|task| {
                store_pass(task, log_rx, diagnosis, motion);
                *restart_due |= save_host_config(task, link, motion.t_s);
                if *restart_due && may_restart(task, motion.t_s, log_rx.ready()) {
                    defmt::info!("restarting to run the saved vehicle");
                    persist::restart();
                }
            });
            let now = cx.shared.now.lock(|n| *n);
            let measurement = cx.shared.measurement.lock(Option::take);
            let task = &mut *cx.local.model_task;
            let link = &mut cx.shared.link;
            let (watch, entry) = (&mut *cx.local.diagnosis, &mut *cx.local.diagnosis_entry);
            let model = &mut cx.shared.model;
            let done = model_pass::<Hooks, _, _>(
                task,
                now,
                measurement,
                &mut cx.shared.health,
                |task| {
                    let up = task.updater();
                    link.lock(|l| l.on_model_update(up));
                    // the diagnosis in the log when it names another part (or none any more)
                    let d = up.diagnosis_indexed();
                    let t_ms = (now.0 * 1e3) as u32;
                    if let Some(e) = watch.on_update(t_ms, d) {
                        *entry = Some(LogEntry::Diagnosis(e));
                        match d.map(|(_, d)| d) {
                            Some(d) => {
                                let (lo, hi) = d.two_sigma();
                                defmt::warn!(
                                    "model update: {=str} ({=str}) x{=f64}, 2 sigma x{=f64}-x{=f64}, plausible x{=f64}-x{=f64}",
                                    d.what,
                                    d.field,
                                    d.factor,
                                    lo,
                                    hi,
                                    d.band.0,
                                    d.band.1
                                )
                            }
                            None => defmt::info!("model update: every part within its band"),
                        }
                    }
                },
                |published| {
                    model.lock(|x| {
                        *x = Some(published);
                        Hooks::model_published();
                    })
                },
            );
            if let Some((pt, cycles)) = done {
                if cycles % 10 == 1 {
                    let m = pt.margin();
                    defmt::info!(
                    "model: t {=f64} s, v {=f64} m/s: shimmy zeta {=f64} at {=f64} Hz, dzeta/dV {=f64} per m/s, onset {=f64} m/s; {=u16} eigen-solves in {=u16} calls, {=u16} errors",
                    pt.t_s,
                    pt.speed_mps,
                    m.zeta,
                    m.freq_hz,
                    m.dzeta_dv_per_mps,
                    m.v_crit_onset_mps.unwrap_or(f64::NAN),
                    pt.eigen_solves,
                    pt.calls,
                    pt.errors
                    );
                }
            }
            // Nothing due: sleep until the next interrupt, at most 1 ms (PIL: the next step at
            // once when nothing is due, else at the period's end).
            Hooks::idle(task.tracker().busy());
        }
    }

    #[task(binds = TIM2, priority = 3, local = [board, control, tx, record, hold_safe], shared = [health, margin, latched])]
    fn control(cx: control::Context) {
        let b = cx.local.board;
        let task = cx.local.control;
        let entry_instructions = Hooks::entry();
        let entry = b.timer.now_ticks();
        b.timer.clear_update();
        if *cx.local.hold_safe {
            // Reset loop: the fixed safe current (coil off if a coil fault is latched), the
            // watchdog fed, nothing else run.
            let f = task.controller().supervisor().faults();
            let dead = f.contains(FaultKind::CoilOpen) || f.contains(FaultKind::CoilShort);
            let _ = if dead {
                b.coil.off()
            } else {
                b.coil.fail_safe().map(|_| ())
            };
            b.watchdog.feed();
            return;
        }
        let latency = b.timer.entry_latency_ticks(entry);
        let mut health = cx.shared.health;
        let mut margin = cx.shared.margin;
        #[cfg(all(feature = "qemu", not(feature = "pil")))]
        board::WORLD.set_step(task.step_count());

        let samples = b.sensors.sample(PERIOD_TICKS);
        let status = margin.lock(|m| *m);
        let drive = b.coil_drive_a();
        let tx = cx.local.tx;
        let coil = &mut b.coil;
        let mut pwm_ok = true;
        let s = task.run(
            &samples,
            drive,
            status,
            &mut health,
            |out| pwm_ok = drive_coil(coil, out).is_ok(),
            |sample| tx.enqueue(sample).is_ok(),
        );
        let busy = s.meter_due && meter::spawn().is_err();

        let exit = b.timer.now_ticks();
        let wrapped = b.timer.update_pending();
        health.lock(|h| {
            h.record_timing(latency, exit.wrapping_sub(entry), wrapped);
            h.pwm_errors += u32::from(!pwm_ok);
            h.estimator_busy += u32::from(busy);
            h.record_step(s.dropped);
        });
        // Fault memory: uptime (whole seconds) and the latched faults survive a reset.
        let uptime_ms = (s.step / 1000).wrapping_mul(1000);
        let latched = task.controller().supervisor().latched().bits();
        if cx.local.record.update(uptime_ms, latched) {
            persist::store(cx.local.record);
            let mut shared_latched = cx.shared.latched;
            shared_latched.lock(|l| *l = FaultSet::from_bits(latched));
        }
        // Fed only here: a control loop that stops completing steps resets the MCU.
        b.watchdog.feed();
        Hooks::report_step(s.step, &s.out, entry_instructions);

        #[cfg(all(feature = "qemu", not(feature = "pil")))]
        if s.step + 1 == board::QEMU_STEPS {
            qemu_finish(health.lock(|h| *h));
        }
    }

    #[task(priority = 2, local = [rx, data, meter_runs, recorder, log_tx, cmd_peak_a: f32 = 0.0], shared = [health, model, measurement, now, margin, motion, link, latched])]
    async fn meter(mut cx: meter::Context) {
        let entry_instructions = Hooks::entry();
        let published = cx.shared.model.lock(|m| {
            Hooks::meter_took_model();
            *m
        });
        let rx = &mut *cx.local.rx;
        let recorder = &mut *cx.local.recorder;
        let cmd_peak_a = &mut *cx.local.cmd_peak_a;
        let log_tx = &mut *cx.local.log_tx;
        let meter_runs = &mut *cx.local.meter_runs;
        let shared = &mut cx.shared;
        let spawned_by = cx.local.data.run(
            published.as_ref(),
            || rx.dequeue(),
            |data, event| match event {
                MeterEvent::Sample(s) => {
                    recorder.on_command(s.cmd_a);
                    *cmd_peak_a = cmd_peak_a.max(s.cmd_a);
                }
                MeterEvent::Update(s, u, changed) => {
                    Hooks::report_margin(s.step, &u.report, u.level);
                    let health = shared.health.lock(|h| *h);
                    let latched = shared.latched.lock(|l| l.bits());
                    let monitor = data.pipeline().monitor();
                    // The log: closed episodes and raised faults to the store, the open episode to the
                    // link; then the motion for the store's standstill watch.
                    let mut batch = Batch::new();
                    recorder.on_update(monitor, &mut batch);
                    recorder.on_faults(s.step, health.active_faults, latched, &mut batch);
                    let open = recorder.open_event(monitor);
                    shared
                        .link
                        .lock(|l| l.on_update(u, open, &health, latched, s.step));
                    let lost = batch.lost;
                    for e in batch {
                        if log_tx.enqueue(e).is_err() {
                            defmt::error!("store queue full: a log entry at step {=u32} lost", s.step);
                        }
                    }
                    if lost > 0 {
                        defmt::error!("{=u32} log entries at step {=u32} lost", lost, s.step);
                    }
                    let motion = Motion {
                        t_s: u.report.t_s,
                        speed_mps: data.speed_mps(),
                        cmd_peak_a: core::mem::take(cmd_peak_a),
                    };
                    shared.motion.lock(|m| *m = motion);
                    let now = (u.report.t_s, data.speed_mps());
                    shared.now.lock(|n| *n = now);
                    if let Some(m) = data.take_measurement() {
                        shared.measurement.lock(|x| *x = Some(m));
                    }
                    let status = data.margin_status();
                    shared.margin.lock(|m| *m = status);
                    *meter_runs += 1;
                    let runs = *meter_runs;
                    if runs.is_multiple_of(LINK_STREAM_DIVIDER) {
                        rtic::pend(shimmy_firmware::hal::pac::Interrupt::USART1);
                    }
                    if changed {
                        defmt::warn!(
                            "warning level {=str} at t = {=f64} s, {=f32} m/s: zeta fast {=f32} slow {=f32} ({=f32} Hz), amplitude {=f32} mrad, speed margin {=f32} m/s",
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
                    // The margin report and the counters over the probe at 1 Hz, for a debug build: a
                    // host watches the report over the link (`watch`, 10 Hz) instead.
                    #[cfg(feature = "probe-telemetry")]
                    if runs.is_multiple_of(TELEMETRY_DIVIDER) {
                        let h = shared.health.lock(|h| *h);
                        let r = &u.report;
                        defmt::info!(
                            "margin: t {=f64} s, v {=f32} m/s, zeta data {=f32} +- {=f32} (valid {=bool}), fast {=f32}, {=f32} Hz, model zeta {=f32}, margin {=f32} m/s, ttc {=f32} s, consistent {=bool}, level {=str}; {}",
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
            },
        );
        if let Some(step) = spawned_by {
            Hooks::report_meter_run(step, entry_instructions);
        }
    }

    /// Logs where the configuration came from. Anything but a stored record is a fault; a
    /// refused record names what was wrong (the field, its value and the allowed range).
    fn report_config(boot: &shimmy_firmware::store::BootReport) {
        use shimmy_core::vehicle::{Problem, RecordError};
        const DEFAULTS: &str = "running the compiled-in defaults";
        match boot.config.source {
            ConfigSource::Stored => defmt::info!("config: stored vehicle record loaded"),
            ConfigSource::Missing => {
                defmt::error!("config fault: no vehicle record stored; {=str}", DEFAULTS)
            }
            ConfigSource::Unreadable(_) => {
                defmt::error!("config fault: the store cannot be read; {=str}", DEFAULTS)
            }
            ConfigSource::Rejected(RecordError::Invalid(e)) => match e.problem {
                Problem::OutOfRange { lo, hi, unit } => defmt::error!(
                    "config fault: stored {=str}.{=str} = {=f64} is outside [{=f64}, {=f64}] {=str}; {=str}",
                    e.section, e.name, e.value, lo, hi, unit, DEFAULTS
                ),
                Problem::NotInteger { lo, hi } => defmt::error!(
                    "config fault: stored {=str}.{=str} = {=f64} is not a whole number in [{=f64}, {=f64}]; {=str}",
                    e.section, e.name, e.value, lo, hi, DEFAULTS
                ),
                Problem::Inconsistent(rule) => defmt::error!(
                    "config fault: stored {=str}.{=str} = {=f64} breaks the rule {=str}; {=str}",
                    e.section, e.name, e.value, rule, DEFAULTS
                ),
            },
            ConfigSource::Rejected(RecordError::Schema { found, expected }) => defmt::error!(
                "config fault: stored record schema {=u32:#x} is not this firmware's {=u32:#x}; {=str}",
                found, expected, DEFAULTS
            ),
            ConfigSource::Rejected(
                RecordError::Length { need, have } | RecordError::BufferTooSmall { need, have },
            ) => defmt::error!(
                "config fault: stored record is {=usize} B, expected {=usize} B; {=str}",
                have, need, DEFAULTS
            ),
        }
        defmt::info!(
            "store: boot {=u32}, {=usize} log entries",
            boot.entry.boot_count,
            boot.log_entries
        );
    }

    /// One pass of the store in the background loop; reports what it did.
    fn store_pass(
        task: &mut StoreTask<TargetFlash>,
        rx: &mut Consumer<'static, LogEntry>,
        diagnosis: Option<LogEntry>,
        motion: Motion,
    ) {
        let pass = task.step(
            motion,
            core::iter::from_fn(|| rx.dequeue()).chain(diagnosis),
        );
        if pass.appended > 0 {
            defmt::info!(
                "store: {=u32} log entries appended at t = {=f64} s ({=usize} waiting for a standstill)",
                pass.appended,
                motion.t_s,
                task.store().pending_entries()
            );
        }
        match pass.maintained {
            Some(Ok(m)) => defmt::info!(
                "store: standstill, {=u32} waiting entries written",
                m.written
            ),
            Some(Err(_)) => defmt::error!("store: standstill maintenance failed, retried later"),
            None => {}
        }
    }

    /// A vehicle the host link accepted goes to flash here, with the store's standstill token
    /// (the erase a write may need stalls flash reads): saved at the first standstill, kept in
    /// the link's state until then. True when saved: the board restarts into it.
    fn save_host_config(
        task: &mut StoreTask<TargetFlash>,
        link: &mut impl rtic::Mutex<T = LinkState>,
        t_s: f64,
    ) -> bool {
        let Some(v) = link.lock(|l| l.take_unsaved()) else {
            return false;
        };
        match save_vehicle(task, &v, t_s) {
            Saved::Saved => {
                defmt::info!("store: the host's vehicle saved at t = {=f64} s", t_s);
                return true;
            }
            Saved::Failed => {
                defmt::error!("store: saving the host's vehicle failed, retried at the next pass")
            }
            Saved::Waiting => {}
        }
        link.lock(|l| l.keep_unsaved(v));
        false
    }

    /// The host link, below `meter` and `control`: every received byte goes to the protocol
    /// handler, each complete request frame gets its reply (polled transmit, at most ~9 ms at
    /// 921,600 baud); while the stream is on, the newest margin report goes out when `meter`
    /// pends this task (10 Hz). `link` is locked only to run the handler, never while sending.
    #[task(binds = USART1, priority = 1, local = [port, announced, device: Device = Device::new(), reply: [u8; REPLY_BYTES] = [0; REPLY_BYTES]], shared = [link, store_task])]
    fn link(cx: link::Context) {
        let (port, device, reply) = (cx.local.port, cx.local.device, cx.local.reply);
        let mut shared = (cx.shared.link, cx.shared.store_task);
        let mut serve = |f: &mut dyn FnMut(&mut BoardLink<'_, TargetFlash>) -> Option<usize>| {
            shared.lock(|state, store| f(&mut BoardLink { state, store }))
        };
        if !*cx.local.announced {
            *cx.local.announced = true;
            let n = serve(&mut |b| Some(Device::ready(b, reply))).unwrap_or(0);
            port.write(reply.get(..n).unwrap_or_default());
        }
        while let Some(byte) = port.read() {
            if let Some(n) = serve(&mut |b| device.on_byte(byte, b, reply)) {
                port.write(reply.get(..n).unwrap_or_default());
            }
        }
        if let Some(n) = serve(&mut |b| device.poll_stream(b, reply)) {
            port.write(reply.get(..n).unwrap_or_default());
        }
    }

    /// Why the MCU (re)started (RCC_CSR reset flags, RM0090 6.3.21), logged; clears the flags.
    /// A power-on also sets the brown-out flag, so power-on is tested first.
    fn reset_cause(rcc: &shimmy_firmware::hal::pac::RCC) -> ResetCause {
        let f = rcc.csr().read();
        // Read every boot, so that a mark left by a restart is never taken for a later one.
        let restarted = persist::take_restart();
        // One log call per cause: defmt keeps a literal's text in the ELF, not in flash (a
        // `{=str}` argument sends it from flash).
        let cause = if f.wdgrstf().bit_is_set() {
            defmt::warn!(
                "reset cause: independent watchdog (the control loop stopped completing steps)"
            );
            ResetCause::Watchdog
        } else if f.wwdgrstf().bit_is_set() {
            defmt::warn!("reset cause: window watchdog");
            ResetCause::Watchdog
        } else if f.sftrstf().bit_is_set() && restarted {
            defmt::info!("reset cause: restart to run the new vehicle configuration");
            ResetCause::Restart
        } else if f.sftrstf().bit_is_set() {
            defmt::warn!("reset cause: software reset (panic or fault handler)");
            ResetCause::Software
        } else if f.porrstf().bit_is_set() {
            defmt::warn!("reset cause: power-on");
            ResetCause::PowerOn
        } else if f.borrstf().bit_is_set() {
            defmt::warn!("reset cause: brown-out (supply below the BOR level)");
            ResetCause::PowerOn
        } else if f.lpwrrstf().bit_is_set() {
            defmt::warn!("reset cause: low-power management");
            ResetCause::Other
        } else if f.padrstf().bit_is_set() {
            defmt::warn!("reset cause: reset pin (NRST, debug probe)");
            ResetCause::Pin
        } else {
            defmt::warn!("reset cause: none flagged");
            ResetCause::Other
        };
        rcc.csr().modify(|_, w| w.rmvf().set_bit());
        cause
    }

    /// The level's name, as the host link spells it.
    fn level_name(l: shimmy_core::estimator::monitor::Level) -> &'static str {
        shimmy_link::wire::level_name(shimmy_link::wire::level_code(l))
    }

    /// End of a `qemu` run: the counters must be exactly what the simulation injected (driver
    /// faults once each, the supervisor's FailSafe time, every fault recovered), with no
    /// overrun, no late start, no busy meter and at least one completed model cycle, none late.
    #[cfg(all(feature = "qemu", not(feature = "pil")))]
    fn qemu_finish(h: Health) -> ! {
        use shimmy_firmware::runtime::{finish, Outcome};
        use shimmy_firmware::sim::{
            expected_faults, EXPECTED_FAILSAFE_STEPS, EXPECTED_FAULTS_RAISED, EXPECTED_MODES,
        };
        let (stack_used, stack_size) = shimmy_firmware::stack::high_water();
        defmt::info!("final counters: {}", h);
        defmt::info!(
            "stack high-water mark {=usize} B of {=usize} B",
            stack_used,
            stack_size
        );
        // Announced for `cargo xtask qemu`, which checks the logged mode changes against it.
        let mut modes = heapless::String::<160>::new();
        for m in EXPECTED_MODES {
            let _ = modes.push_str(m.name());
            let _ = modes.push(' ');
        }
        defmt::info!("scenario: expected supervisor modes {=str}", modes.as_str());
        let (par, ef, glitch) = expected_faults(h.steps);
        let checks = [
            ("steps", h.steps == board::QEMU_STEPS),
            (
                "driver faults (parity, error flag, speed glitch) counted once each",
                (h.enc_parity, h.enc_error_flag, h.speed_implausible) == (par, ef, glitch),
            ),
            (
                "no other driver fault",
                h.enc_bus + h.current_faults + h.pwm_errors == 0,
            ),
            (
                "supervisor: FailSafe steps",
                h.failsafe_steps == EXPECTED_FAILSAFE_STEPS,
            ),
            (
                "supervisor: faults raised",
                h.faults_raised == EXPECTED_FAULTS_RAISED,
            ),
            (
                "supervisor: mode changes",
                h.mode_changes as usize == EXPECTED_MODES.len() - 1,
            ),
            ("supervisor: every fault recovered", h.active_faults == 0),
            ("no overrun, no late start", h.overruns + h.late_starts == 0),
            (
                "meter never busy, no sample dropped",
                h.estimator_busy + h.meter_dropped == 0,
            ),
            (
                "model cycles completed, none late",
                h.model_cycles > 0 && h.model_late == 0,
            ),
        ];
        let mut ok = true;
        for (name, pass) in checks {
            if !pass {
                defmt::error!("qemu run check failed: {=str}", name);
            }
            ok &= pass;
        }
        if ok {
            defmt::info!(
                "qemu run ok: {=u32} steps, injected faults counted (parity {=u32}, error flag {=u32}, speed {=u32}), supervisor recovered, {=u32} model cycles, no overrun",
                h.steps, par, ef, glitch, h.model_cycles
            );
            finish(Outcome::Success)
        } else {
            finish(Outcome::Failure)
        }
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!(
        "shimmy-firmware runs on a Cortex-M4F: build it with --target thumbv7em-none-eabihf, \
         run it under QEMU with `cargo xtask qemu`, or flash a board (see docs/firmware.md)."
    );
    std::process::exit(2);
}
