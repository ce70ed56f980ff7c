//! Power cuts at every byte of a configuration write and of an event append, on the RAM flash
//! (the store's own NOR model: write-once bytes, page erase, a cut stops an operation part-way).

use super::*;
use crate::store::drive;
use crate::store::{FaultEvent, RamFlash, ShimmyEvent, StandstillWatch, StoreTask};
use shimmy_core::estimator::monitor::Level;
use shimmy_core::supervisor::faults::FaultKind;
use shimmy_core::vehicle::{Vehicle, FIELDS};
use shimmy_link::wire::{fault_code, level_code};

/// Small pages so a handful of writes fill one and force the page turns of both queues (each with an erase) under the cut.
const PAGE: usize = 2048;
type Flash = RamFlash<{ 4 * PAGE }, PAGE>;
const LAYOUT: Layout = Layout::split(PAGE as u32, 2, 2);

fn store(flash: Flash) -> Store<Flash> {
    Store::new(flash, LAYOUT).unwrap()
}

/// Power back on after a cut: the boot repairs what the cut interrupted.
fn reboot(mut flash: Flash) -> Boot<Flash> {
    flash.cut_power_after(None);
    Store::boot(flash, LAYOUT, ResetCause::PowerOn, 0).unwrap()
}

/// A watch that has seen the vehicle stand since t = 0 (its token is granted at t >= 2 s).
fn standing() -> StandstillWatch {
    let mut w = StandstillWatch::new();
    w.observe(0.0, 0.0, 0.0);
    w
}

/// The k-th test vehicle: the nominal one with the first field (I_k) moved through its range.
fn vehicle(k: u32) -> Vehicle {
    let f = &FIELDS[0];
    let mut v = Vehicle::nominal();
    let frac = 0.1 + 0.8 * f64::from(k % 17) / 17.0;
    v.set(f.section(), f.name, f.lo + (f.hi - f.lo) * frac)
        .unwrap();
    v
}

fn shimmy(k: u32) -> LogEntry {
    LogEntry::Shimmy(ShimmyEvent {
        start_s: 10.0 * f64::from(k),
        speed_mps: 20.0 + k as f32,
        freq_hz: 8.0,
        peak_amplitude_rad: 0.01 * k as f32,
        duration_s: 2.5,
        shimmy_s: 1.5,
        level: level_code(Level::ShimmyPresent),
        open: false,
        peak_current_a: 2.0,
        mean_current_a: 1.25,
    })
}

fn log_of(s: &mut Store<Flash>) -> Vec<LogEntry> {
    let mut v = Vec::new();
    s.read_log(&mut |e| v.push(*e.expect("every stored entry reads back whole")))
        .unwrap();
    v
}

/// Stores `record` as the vehicle record, unchecked (as another firmware or a bit flip left it).
fn store_raw(s: &mut Store<Flash>, record: &[u8]) {
    s.store_record(|out| {
        out[..record.len()].copy_from_slice(record);
        Ok(record.len())
    })
    .unwrap();
}

#[test]
fn a_missing_or_refused_record_gives_the_defaults_and_says_why() {
    let mut s = store(Flash::new());
    let l = s.load_config();
    assert_eq!(l.source, ConfigSource::Missing);
    assert_eq!(l.vehicle, Vehicle::nominal());
    assert!(l.is_fault(), "running the defaults is reported");

    // A record of another schema (as a firmware with another field table wrote it).
    let mut bytes = [0u8; RECORD_MAX_BYTES];
    let n = vehicle(3).encode_record(&mut bytes).unwrap();
    bytes[0] ^= 1;
    store_raw(&mut s, &bytes[..n]);
    let l = s.load_config();
    assert!(matches!(
        l.source,
        ConfigSource::Rejected(RecordError::Schema { .. })
    ));
    assert!(l.is_fault());
    assert_eq!(l.vehicle, Vehicle::nominal(), "nothing half-applied");

    // A value out of its range: refused whole.
    let mut bytes = [0u8; RECORD_MAX_BYTES];
    let n = vehicle(3).encode_record(&mut bytes).unwrap();
    bytes[6..14].copy_from_slice(&(-1.0f64).to_le_bytes());
    store_raw(&mut s, &bytes[..n]);
    let l = s.load_config();
    assert!(matches!(
        l.source,
        ConfigSource::Rejected(RecordError::Invalid(_))
    ));
    assert_eq!(l.vehicle, Vehicle::nominal());

    // Flash that is not a store at all (zeros, as QEMU's RAM after a power-on): the defaults,
    // no panic.
    let mut zeros = Flash::new();
    block_on(zeros.write(0, &[0; 4 * PAGE])).unwrap();
    let l = store(zeros).load_config();
    assert_ne!(l.source, ConfigSource::Stored);
    assert_eq!(l.vehicle, Vehicle::nominal());
    // A flash that cannot be read: unreadable, the defaults.
    let mut s = store(Flash::new());
    s.flash_mut().cut_power_after(Some(0));
    assert_eq!(
        s.load_config().source,
        ConfigSource::Unreadable(StoreError::Flash(FlashError::PowerCut))
    );
}

#[test]
fn an_invalid_vehicle_is_not_saved() {
    let mut s = store(Flash::new());
    let mut w = standing();
    let t = w.check(2.0).unwrap();
    s.save_config(&vehicle(1), &t).unwrap();
    let mut bad = vehicle(2);
    bad.thresholds.zeta_low_off = bad.thresholds.zeta_low_on - 0.01;
    assert!(matches!(
        s.save_config(&bad, &t),
        Err(StoreError::Record(RecordError::Invalid(_)))
    ));
    assert_eq!(s.load_config().vehicle, vehicle(1));
}

/// The test: a power cut at every byte of each of a run of configuration writes
/// (several fill a page, so the configuration queue's page turns and their erases are cut too). After every cut
/// the board boots with the old or the new vehicle, never a mix, and the next write works.
#[test]
fn a_power_cut_at_any_byte_of_a_config_write_leaves_the_old_or_the_new_one() {
    let mut w = standing();
    let t = w.check(2.0).unwrap();
    let mut flash = Flash::new();
    let (mut saw_old, mut saw_new, mut cuts) = (0, 0, 0);
    for k in 0..8u32 {
        let old = (k > 0).then(|| vehicle(k));
        let new = vehicle(k + 1);
        for cut in 0.. {
            let mut s = store(flash.clone());
            s.flash_mut().cut_power_after(Some(cut));
            let done = s.save_config(&new, &t);
            if done.is_ok() {
                break;
            }
            assert_eq!(done, Err(StoreError::Flash(FlashError::PowerCut)));
            cuts += 1;
            // Reboot on what the cut left.
            let Boot {
                store: mut s,
                report,
            } = reboot(s.into_flash());
            let l = report.config;
            match (l.source, old) {
                (ConfigSource::Stored, Some(o)) if l.vehicle == o => saw_old += 1,
                (ConfigSource::Missing, None) => saw_old += 1,
                (ConfigSource::Stored, _) if l.vehicle == new => saw_new += 1,
                other => panic!("write {k}, cut at byte {cut}: {other:?}"),
            }
            // The store still works after the cut.
            s.save_config(&vehicle(k + 2), &t).unwrap();
            assert_eq!(s.load_config().vehicle, vehicle(k + 2));
        }
        let mut s = store(flash);
        s.save_config(&new, &t).unwrap();
        flash = s.into_flash();
    }
    // An item becomes valid with its last byte, so every cut before the end of a write left the
    // old vehicle (the new one is what the completed write gives, checked above).
    assert_eq!((saw_old, saw_new), (cuts, 0));
    eprintln!("config writes: {cuts} power cuts, each booted with the old vehicle");
    assert!(cuts > 8 * MIN_CUTS_PER_WRITE, "{cuts} cuts");
}

/// At least this many bytes are cut into per write (a record is 590 bytes).
const MIN_CUTS_PER_WRITE: u32 = 500;

/// A power cut at every byte of an append (writes only) and of a standstill flush that turns the
/// log onto its oldest page (an erase: the oldest entries go first). After every cut the log
/// reads back whole entries: the old ones, possibly without the oldest page's, plus or minus
/// the one being written; nothing else is lost or mixed.
#[test]
fn a_power_cut_at_any_byte_of_an_append_loses_at_most_the_entry_being_written() {
    let mut w = standing();
    let t = w.check(2.0).unwrap();
    let mut flash = Flash::new();
    let mut old: Vec<LogEntry> = Vec::new();
    let mut dropped_seen = false;
    let mut cuts = 0u32;
    for k in 0..120u32 {
        let new = shimmy(k);
        // What the append (or, when it must wait, the flush) does without a cut.
        let mut clean = store(flash.clone());
        let pending = clean.append(&new) == Appended::Pending;
        if pending {
            clean.maintain(&t).unwrap();
        }
        let full = log_of(&mut clean);
        let drop_full = old.len() + 1 - full.len();
        assert_eq!(full[..], [&old[drop_full..], &[new][..]].concat()[..]);
        dropped_seen |= drop_full > 0;
        for cut in 0.. {
            let mut s = store(flash.clone());
            s.flash_mut().cut_power_after(Some(cut));
            let a = s.append(&new);
            let finished = if pending {
                assert_eq!(a, Appended::Pending);
                s.maintain(&t).is_ok()
            } else {
                a == Appended::Written
            };
            if finished {
                break;
            }
            cuts += 1;
            let mut s = reboot(s.into_flash()).store;
            let got: Vec<LogEntry> = log_of(&mut s)
                .into_iter()
                .filter(|e| !matches!(e, LogEntry::Boot(_)))
                .collect();
            let ok = (0..=drop_full).any(|d| {
                let kept = &old[d.min(old.len())..];
                got[..] == *kept || got[..] == [kept, &[new][..]].concat()[..]
            });
            assert!(ok, "entry {k}, cut at byte {cut}: {} read back", got.len());
            // The log still takes entries.
            let mut s2 = store(s.into_flash());
            if s2.append(&shimmy(999)) == Appended::Pending {
                s2.maintain(&t).unwrap();
            }
            assert_eq!(log_of(&mut s2).last(), Some(&shimmy(999)));
        }
        flash = clean.into_flash();
        old = full;
    }
    assert!(
        dropped_seen,
        "the log filled and dropped its oldest entries"
    );
    assert!(cuts > 120 * 40, "{cuts} cuts");
    eprintln!("appends and flushes: {cuts} power cuts, at most the entry being written lost");
}

/// While the vehicle moves, an append that needs an erase waits in RAM (the flash is never
/// erased without the token) and order is kept; the standstill flush writes it.
#[test]
fn without_the_token_nothing_is_erased() {
    let mut s = store(Flash::new());
    let mut k = 0;
    while s.append(&shimmy(k)) == Appended::Written {
        k += 1;
    }
    // Both pages of the log are full: the next entry needs the oldest page erased.
    assert!(k > 20, "{k} entries fit the log");
    assert!(
        u32::from(s.log_capacity()) <= k / 2,
        "the capacity claimed ({}) is what a full queue keeps after turning a page ({})",
        s.log_capacity(),
        k / 2
    );
    let erased_before = s.flash().bytes().to_vec();
    let fault = LogEntry::Fault(FaultEvent {
        t_ms: 5000,
        kind: fault_code(FaultKind::CoilShort),
        latched: true,
    });
    assert_eq!(s.append(&fault), Appended::Pending);
    assert_eq!(s.pending_entries(), 2);
    assert_eq!(
        log_of(&mut s).last(),
        Some(&fault),
        "a pending entry is read last"
    );
    assert_eq!(s.flash().bytes(), &erased_before[..], "no byte changed");
    // A config write needs the token by its signature; the flush too.
    let mut w = standing();
    let t = w.check(2.0).unwrap();
    let done = s.maintain(&t).unwrap();
    assert_eq!(done.written, 2);
    // The flush dropped the oldest page (half the entries) for them, nothing else.
    let log = log_of(&mut s);
    assert_eq!(log.len(), k as usize / 2 + 2);
    assert_eq!(log[0], shimmy(k / 2));
    assert_eq!(log.last(), Some(&fault));
    // Clearing the log keeps the configuration.
    s.save_config(&vehicle(5), &t).unwrap();
    s.clear_log(&t).unwrap();
    assert!(log_of(&mut s).is_empty());
    assert_eq!(s.load_config().vehicle, vehicle(5));
}

#[test]
fn boots_are_counted_across_power_offs_and_logged_with_their_cause() {
    let mut flash = Flash::new();
    for boot in 1..=3u32 {
        let b = Store::boot(flash, LAYOUT, ResetCause::Watchdog, boot - 1).unwrap();
        assert_eq!(b.report.entry.boot_count, boot);
        assert_eq!(b.report.log_entries, boot as usize - 1);
        flash = b.store.into_flash();
    }
    let mut s = store(flash);
    let log = log_of(&mut s);
    assert_eq!(log.len(), 3);
    assert_eq!(
        log[2],
        LogEntry::Boot(BootEvent {
            cause: ResetCause::Watchdog as u8,
            resets_since_power_on: 2,
            boot_count: 3
        })
    );
}

/// Every boot appends a whole configuration state (boot count, clearing mark, vehicle record),
/// so the configuration queue turns its pages again and again: the page it erases holds only
/// older states, and the vehicle saved once, long ago, survives with the count.
#[test]
fn the_vehicle_survives_many_boots_that_turn_the_configuration_pages() {
    let mut w = standing();
    let t = w.check(2.0).unwrap();
    let mut s = Store::boot(Flash::new(), LAYOUT, ResetCause::PowerOn, 0)
        .unwrap()
        .store;
    s.save_config(&vehicle(4), &t).unwrap();
    let mut flash = s.into_flash();
    // ~600 B per state, 2 KiB pages: three per page, so 30 boots turn the pages ~10 times.
    for boot in 2..=31u32 {
        let b = Store::boot(flash, LAYOUT, ResetCause::Software, 0).unwrap();
        assert_eq!(b.report.entry.boot_count, boot);
        assert_eq!(b.report.config.source, ConfigSource::Stored, "boot {boot}");
        assert_eq!(b.report.config.vehicle, vehicle(4), "boot {boot}");
        flash = b.store.into_flash();
    }
}

#[test]
fn a_layout_that_does_not_fit_is_refused() {
    for bad in [
        Layout::split(PAGE as u32, 1, 3),
        Layout::split(PAGE as u32, 3, 2),
        Layout {
            config: 0..2 * PAGE as u32,
            log: PAGE as u32..3 * PAGE as u32,
        },
        Layout {
            config: 100..2 * PAGE as u32 + 100,
            log: 3 * PAGE as u32..4 * PAGE as u32,
        },
    ] {
        assert!(matches!(
            Store::new(Flash::new(), bad),
            Err(StoreError::Layout)
        ));
    }
}

/// The firmware chain on a scripted drive (`drive`): a shimmy episode and a coil short while
/// moving are logged with what the monitor and the supervisor saw; with a full log they wait in
/// RAM and the standstill at the end writes them.
#[test]
fn a_drive_logs_the_shimmy_episode_and_the_faults() {
    for prefill in [0u32, 88] {
        let mut flash = Flash::new();
        if prefill > 0 {
            let mut s = store(flash);
            for k in 0..prefill {
                assert_eq!(s.append(&shimmy(k)), Appended::Written);
            }
            flash = s.into_flash();
        }
        let b = Store::boot(flash, LAYOUT, ResetCause::PowerOn, 0).unwrap();
        let boot_entry = b.report.entry;
        let mut task = StoreTask::new(b.store);
        let d = drive::run(&mut task);
        assert_eq!(d.appended, 3, "{d:?} {:?}", log_of(task.store()));
        assert_eq!(d.maintenance_errors, 0);
        assert_eq!(d.final_cmd_a, 0.0, "standing with the coil off");
        let log = log_of(task.store());
        // The newest prefilled entries, this boot, then the drive's three: the short is latched
        // before the episode closes (the yaw envelope falls below its release threshold ~3 s
        // after the shimmy ends); braking, the margin report becomes unavailable (the mode
        // meter does not trust a decelerating drive), a fault the supervisor raises.
        let kept = log.len() - 4;
        assert!(log[..kept].iter().eq((prefill - kept as u32..prefill)
            .map(shimmy)
            .collect::<Vec<_>>()
            .iter()));
        let [LogEntry::Boot(boot), LogEntry::Fault(f), LogEntry::Shimmy(s), LogEntry::Fault(g)] =
            log[kept..]
        else {
            panic!("{log:?}");
        };
        assert_eq!(g.kind, fault_code(FaultKind::MarginUnavailable), "{g:?}");
        assert!(!g.latched && (9000..10_500).contains(&g.t_ms), "{g:?}");
        assert_eq!(boot, boot_entry);
        let e = &s;
        assert_eq!(e.level, level_code(Level::ShimmyPresent));
        assert!((e.freq_hz - drive::SHIMMY_HZ).abs() < 0.5, "{e:?}");
        assert!((e.speed_mps - drive::CRUISE_MPS).abs() < 0.5, "{e:?}");
        assert!(
            (e.peak_amplitude_rad / drive::SHIMMY_RAD - 1.0).abs() < 0.25,
            "{e:?}"
        );
        assert!(
            e.start_s < 1.0 && e.duration_s > 4.0 && e.shimmy_s > 2.0,
            "{e:?}"
        );
        assert!(
            s.peak_current_a > 0.0 && s.mean_current_a > 0.0,
            "the controller acted: {s:?}"
        );
        assert_eq!(f.kind, fault_code(FaultKind::CoilShort));
        assert!(f.latched, "{f:?}");
        assert!((6000..7500).contains(&f.t_ms), "{f:?}");
        // With the log full (the short boot entry still fits its last page), the drive's
        // entries waited for the standstill, which dropped the oldest page (half the log) for
        // them.
        let (written, kept_expected) = if prefill > 0 {
            (3, prefill as usize / 2)
        } else {
            (0, 0)
        };
        assert_eq!(
            (d.written_at_standstill, kept),
            (written, kept_expected),
            "{d:?}"
        );
    }
}

/// A log clear cut by a power loss at any byte: the boot finishes it (the clearing mark), so
/// the log is either untouched or empty, never half erased (without the mark this fails at the
/// first cut into the erase; `store_ops` found a later append lost under such a page).
#[test]
fn a_cut_clear_is_finished_at_boot() {
    let mut w = standing();
    let t = w.check(2.0).unwrap();
    let mut s = store(Flash::new());
    for k in 0..30 {
        s.append(&shimmy(k));
    }
    let flash = s.into_flash();
    let (mut untouched, mut cleared) = (0, 0);
    for cut in 0.. {
        let mut s = store(flash.clone());
        s.flash_mut().cut_power_after(Some(cut));
        if s.clear_log(&t).is_ok() {
            break;
        }
        let mut s = reboot(s.into_flash()).store;
        let shimmies: Vec<LogEntry> = log_of(&mut s)
            .into_iter()
            .filter(|e| matches!(e, LogEntry::Shimmy(_)))
            .collect();
        if shimmies.is_empty() {
            cleared += 1;
        } else {
            assert_eq!(
                shimmies,
                (0..30).map(shimmy).collect::<Vec<_>>(),
                "cut at {cut}"
            );
            untouched += 1;
        }
        // New entries stay.
        for k in 100..140 {
            s.append(&shimmy(k));
        }
        let got: Vec<LogEntry> = log_of(&mut s)
            .into_iter()
            .filter(|e| matches!(e, LogEntry::Shimmy(s) if s.start_s >= 1000.0))
            .collect();
        let kept = got.len();
        assert!(got[..] == (140 - kept as u32..140).map(shimmy).collect::<Vec<_>>()[..]);
    }
    assert!(untouched > 0 && cleared > 0, "{untouched} {cleared}");
}
