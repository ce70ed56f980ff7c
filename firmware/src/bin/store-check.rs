//! The flash store under QEMU (whose flash cannot be written: the store runs on the RAM flash
//! of `store::target::qemu`, 16 KiB sectors in RAM that a reset leaves alone), across two
//! system resets:
//!
//! - boot 1 finds the RAM lost (QEMU starts with zeroed RAM: a power-on), formats the flash,
//!   boots with the defaults (no record: a reported config fault), and at standstill saves a
//!   vehicle that differs from the defaults; restarts into it as the application does after a
//!   host's write (`fault_memory::persist::restart`);
//! - boot 2 finds the restart's mark (cause `Restart`, not counted as abnormal) and loads that
//!   vehicle, then runs the scripted drive (`store::drive`: the firmware's
//!   controller, data pipeline and store task): a shimmy episode and a coil short while moving
//!   are appended to the log; reset;
//! - boot 3 reads the log back: the three boots with their causes, the fault and the episode.
//!
//! QEMU has no RCC reset flags: a reset without the restart's mark is given as `Software`, as
//! in `reset-memory`.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod app {
    use cortex_m_rt::entry;
    use shimmy_core::supervisor::faults::FaultKind;
    use shimmy_core::vehicle::{record_index, BoardVehicle, RecordVehicle};
    use shimmy_firmware::fault_memory::{persist, ResetCause, ResetRecord};
    use shimmy_firmware::link::{save_vehicle, Saved};
    use shimmy_firmware::monitoring::ImageVehicle;
    use shimmy_firmware::runtime::{finish, Outcome};
    use shimmy_firmware::store::target::{self as store_target, TargetFlash};
    use shimmy_firmware::store::{drive, ConfigSource, LogEntry, Motion, StoreTask};
    use shimmy_link::wire::{cause_name, fault_code, fault_name};

    fn check(ok: bool, what: &str) {
        if !ok {
            defmt::error!("store check failed: {=str}", what);
            finish(Outcome::Failure);
        }
    }

    /// The vehicle boot 1 saves: the image's compiled-in one (the car's nominal, the truck
    /// image's `truck-full`) with its model's first value 1 % larger and another coil rating,
    /// one value of each part of the record.
    fn configured() -> ImageVehicle {
        let mut v = ImageVehicle::compiled_in();
        let rating = record_index::<ImageVehicle>("damper", "rated_current_a");
        let first = v.read_value(0) * 1.01;
        let set = v.write_value(0, first).is_ok()
            && rating.is_some_and(|i| v.write_value(i, 2.5).is_ok());
        check(set, "the test vehicle is valid");
        v
    }

    fn reset(record: &mut ResetRecord) -> ! {
        record.update(5_000, record.latched_faults);
        persist::store(record);
        cortex_m::peripheral::SCB::sys_reset()
    }

    /// Logs every entry of the log and checks them against what boots 1 and 2 wrote.
    fn read_back(task: &mut StoreTask<TargetFlash>) {
        let mut n = 0usize;
        let mut boots = 0u32;
        let mut shimmy = false;
        let mut fault = false;
        let read = task.store().read_log(&mut |e| {
            n += 1;
            match e {
                Ok(LogEntry::Boot(b)) => {
                    boots += 1;
                    check(b.boot_count == boots, "boots counted in order");
                    let restart = ResetCause::Restart as u8;
                    check(
                        (b.cause == restart) == (boots == 2),
                        "boot 2, and only boot 2, after a restart",
                    );
                    defmt::info!(
                        "log {=usize}: boot {=u32}, cause {=str}, {=u32} resets since power-on",
                        n,
                        b.boot_count,
                        cause_name(b.cause),
                        b.resets_since_power_on
                    );
                }
                Ok(LogEntry::Fault(f)) => {
                    fault |= f.kind == fault_code(FaultKind::CoilShort) && f.latched;
                    defmt::info!(
                        "log {=usize}: fault {=str} at t = {=u32} ms (latched {=bool})",
                        n,
                        fault_name(f.kind),
                        f.t_ms,
                        f.latched
                    );
                }
                Ok(LogEntry::Shimmy(e)) => {
                    shimmy = e.freq_hz > 7.5 && e.freq_hz < 8.5 && e.speed_mps > 19.5;
                    defmt::info!(
                        "log {=usize}: shimmy from t = {=f64} s for {=f32} s at {=f32} m/s, {=f32} Hz, peak {=f32} mrad, level {=u8}; coil peak {=f32} A, mean {=f32} A",
                        n,
                        e.start_s,
                        e.duration_s,
                        e.speed_mps,
                        e.freq_hz,
                        e.peak_amplitude_rad * 1e3,
                        e.level,
                        e.peak_current_a,
                        e.mean_current_a
                    );
                }
                Ok(LogEntry::Diagnosis(d)) => {
                    defmt::error!("log {=usize}: a diagnosis at t = {=u32} ms", n, d.t_ms);
                    check(false, "only what boots 1 and 2 wrote");
                }
                Err(u) => {
                    defmt::error!("log {=usize}: unreadable entry {}", n, u);
                    check(false, "every entry reads back whole");
                }
            }
        });
        check(
            read == Ok(6),
            "six entries: boots 1-3, the latched short, the episode, the braking's margin fault",
        );
        check(
            boots == 3 && shimmy && fault,
            "the boots, the fault and the episode",
        );
    }

    #[entry]
    fn main() -> ! {
        let stored = persist::load();
        let restarted = persist::take_restart();
        let cause = if !stored.is_valid() {
            ResetCause::PowerOn
        } else if restarted {
            ResetCause::Restart
        } else {
            ResetCause::Software
        };
        let (mut record, _) = ResetRecord::on_boot(&stored, cause);
        persist::store(&record);
        let boot = record.resets + 1;
        let Ok((mut task, report)) = store_target::boot(!stored.is_valid(), cause, record.resets)
        else {
            check(false, "the store opens");
            finish(Outcome::Failure)
        };
        check(report.entry.boot_count == boot, "the boot is counted");
        match boot {
            1 => {
                check(
                    report.config.source == ConfigSource::Missing && report.config.is_fault(),
                    "boot 1: no record, the defaults, a fault",
                );
                check(
                    report.config.vehicle == ImageVehicle::compiled_in(),
                    "boot 1: the defaults",
                );
                // Standing for 2 s with the coil off: the token, and the write.
                let still = |t_s| Motion {
                    t_s,
                    speed_mps: 0.0,
                    cmd_peak_a: 0.0,
                };
                task.step(still(0.0), core::iter::empty());
                task.step(still(2.0), core::iter::empty());
                // What the application's background loop does with a host's vehicle.
                check(
                    save_vehicle(&mut task, &configured(), 2.0) == Saved::Saved,
                    "boot 1: the vehicle saved at standstill",
                );
                defmt::info!("boot 1: no configuration (defaults, fault reported); vehicle saved at standstill; restart");
                persist::restart()
            }
            2 => {
                check(
                    cause == ResetCause::Restart && record.quick_resets == 0,
                    "boot 2: a restart, not a failure",
                );
                check(
                    report.config.source == ConfigSource::Stored
                        && report.config.vehicle == configured(),
                    "boot 2: the saved vehicle is loaded",
                );
                let mut loaded = report.config.vehicle;
                defmt::info!(
                    "boot 2: configuration loaded ({=str} {=f64}, coil {=f32} A); driving",
                    ImageVehicle::describe(0).map_or("?", |(_, name, _)| name),
                    loaded.read_value(0),
                    loaded.parts().rated_current_a()
                );
                let d = drive::run(&mut task);
                check(
                    d.appended == 3,
                    "boot 2: the short, the episode and the margin fault appended",
                );
                defmt::info!(
                    "boot 2: drive done, {=u32} entries appended while moving, {=usize} waiting; reset",
                    d.appended,
                    task.store().pending_entries()
                );
                reset(&mut record)
            }
            _ => {
                check(
                    report.config.source == ConfigSource::Stored,
                    "boot 3: still configured",
                );
                defmt::info!(
                    "boot 3: {=usize} log entries found; reading them back",
                    report.log_entries
                );
                read_back(&mut task);
                defmt::info!("store ok: configuration kept, episode and fault logged, log read back after resets");
                finish(Outcome::Success)
            }
        }
    }
}

#[cfg(not(target_os = "none"))]
fn main() {}
