//! Random sequences of store operations (configuration writes, appends, standstill flushes, log
//! clears, reboots) with power cuts at random bytes, on the firmware's RAM flash with small
//! pages (so page turns of both queues happen every few operations). After every operation
//! and every reboot the store must hold what a model of it says:
//!
//! - the configuration is the last one written, or, after a cut during a write, the one being
//!   written; never a mix (the core validates the record whole) and never lost;
//! - every log entry reads back whole; the shimmy entries (numbered in order) are the ones in
//!   flash in order, of which a cut or a standstill flush may only drop the oldest, plus at
//!   most the one being written at the cut; without a cut nothing else changes;
//! - a log clear is not atomic: after a cut during one, any of the entries it was clearing may
//!   survive (and show again after later repairs) until the next clear completes; they are
//!   always older than every entry written after it, and in order.
//!
//! Run: `cargo xtask fuzz --target store_ops` (part of `cargo xtask test`).
#![no_main]

use libfuzzer_sys::fuzz_target;
use shimmy_core::vehicle::{Vehicle, FIELDS};
use shimmy_firmware::fault_memory::ResetCause;
use shimmy_firmware::store::{
    Appended, ConfigSource, Layout, LogEntry, RamFlash, ShimmyEvent, StandstillWatch, Store,
};

const PAGE: usize = 2048;
type Flash = RamFlash<{ 4 * PAGE }, PAGE>;
const LAYOUT: Layout = Layout::split(PAGE as u32, 2, 2);

fn vehicle(k: u8) -> Vehicle {
    let f = &FIELDS[usize::from(k) % 8];
    let mut v = Vehicle::nominal();
    let frac = 0.2 + 0.6 * f64::from(k) / 255.0;
    // The first fields are plant parameters without cross rules: any value in range is valid.
    v.set(f.section(), f.name, f.lo + (f.hi - f.lo) * frac)
        .expect("in range");
    v
}

fn shimmy(seq: u32) -> LogEntry {
    LogEntry::Shimmy(ShimmyEvent {
        start_s: f64::from(seq),
        speed_mps: 20.0,
        freq_hz: 8.0,
        peak_amplitude_rad: 0.02,
        duration_s: 1.0,
        shimmy_s: 0.5,
        level: 3,
        open: false,
        peak_current_a: 2.0,
        mean_current_a: 1.0,
    })
}

/// The shimmy sequence numbers in the log newer than `ghost_max` (every entry must read back
/// whole, all in order).
fn shimmies(s: &mut Store<Flash>, ghost_max: u32) -> Vec<u32> {
    let mut seqs = Vec::new();
    s.read_log(
        &mut |e| match e.expect("an entry that does not read back whole") {
            &LogEntry::Shimmy(x) => seqs.push(x.start_s as u32),
            LogEntry::Boot(_) | LogEntry::Fault(_) | LogEntry::Diagnosis(_) => {}
        },
    )
    .expect("the log reads");
    assert!(
        seqs.windows(2).all(|w| w[0] < w[1]),
        "out of order: {seqs:?}"
    );
    seqs.retain(|&q| q > ghost_max);
    seqs
}

/// What the store must hold.
struct Model {
    config: Option<Vehicle>,
    /// Shimmy entries in flash, in order.
    flash: Vec<u32>,
    /// Shimmy entries waiting in RAM.
    pending: Vec<u32>,
}

fn boot(flash: Flash) -> Store<Flash> {
    Store::boot(flash, LAYOUT, ResetCause::PowerOn, 0)
        .expect("the layout fits")
        .store
}

fn check_config(s: &mut Store<Flash>, allowed: &[Option<Vehicle>]) -> Option<Vehicle> {
    let l = s.load_config();
    let got = match l.source {
        ConfigSource::Stored => Some(l.vehicle),
        ConfigSource::Missing => None,
        other => panic!("configuration lost: {other:?}"),
    };
    assert!(
        allowed.contains(&got),
        "configuration {got:?} is none of the allowed"
    );
    got
}

fuzz_target!(|data: &[u8]| {
    let mut watch = StandstillWatch::new();
    watch.observe(0.0, 0.0, 0.0);
    let token = watch.check(10.0).expect("standing");
    let mut store = boot(Flash::new());
    let mut m = Model {
        config: None,
        flash: Vec::new(),
        pending: Vec::new(),
    };
    let mut seq = 0u32;
    // Entries up to this number may survive an interrupted clear.
    let mut ghost_max = 0u32;
    let mut ops = data.chunks_exact(3);
    for op in &mut ops {
        let (code, arg) = (op[0], u16::from_le_bytes([op[1], op[2]]));
        // The high bit of the code arms a power cut `arg` bytes into the operation.
        let cut = code & 0x80 != 0;
        let kind = (code & 0x7F) % 5;
        if cut {
            store.flash_mut().cut_power_after(Some(u32::from(arg)));
        }
        let mut inflight_config = None;
        let mut inflight_entry = None;
        let mut flushed = Vec::new();
        let failed = match kind {
            0 => {
                let v = vehicle(op[1]);
                inflight_config = Some(v);
                let r = store.save_config(&v, &token);
                if r.is_ok() {
                    m.config = Some(v);
                }
                r.is_err()
            }
            1 => {
                seq += 1;
                // An append that fails part-way keeps its entry pending (and may have left it
                // whole in flash if the cut fell after its last byte).
                match store.append(&shimmy(seq)) {
                    Appended::Written => m.flash.push(seq),
                    Appended::Pending => {
                        m.pending.push(seq);
                        inflight_entry = Some(seq);
                    }
                }
                false
            }
            2 => {
                let waiting = std::mem::take(&mut m.pending);
                let r = store.maintain(&token);
                // The store's pending queue may start with a boot entry; the shimmies are its
                // newest.
                let written = waiting.len() - store.pending_entries().min(waiting.len());
                m.flash.extend(&waiting[..written]);
                flushed = waiting[..written].to_vec();
                m.pending = waiting[written..].to_vec();
                inflight_entry = m.pending.first().copied();
                r.is_err()
            }
            3 => {
                let r = store.clear_log(&token);
                m.flash.clear();
                m.pending.clear();
                if r.is_ok() {
                    ghost_max = 0;
                } else {
                    ghost_max = seq;
                }
                r.is_err()
            }
            _ => false,
        };
        if !cut && kind != 4 {
            assert!(!failed, "an operation failed without a power cut");
            check_config(&mut store, &[m.config]);
            let got = shimmies(&mut store, ghost_max);
            let expect: Vec<u32> = m.flash.iter().chain(&m.pending).copied().collect();
            if kind == 2 {
                // The flush may drop the oldest of the log to make room, never what it wrote.
                assert!(
                    expect.ends_with(&got),
                    "{got:?} is not a suffix of {expect:?}"
                );
                assert!(
                    m.pending.is_empty() && got.ends_with(&flushed),
                    "flushed {flushed:?} lost"
                );
                m.flash = got;
            } else {
                assert_eq!(got, expect, "the log changed without a cut");
            }
            continue;
        }
        // Power off (the RAM and its pending entries are gone), power on.
        let mut flash = store.into_flash();
        flash.cut_power_after(None);
        store = boot(flash);
        m.config = check_config(&mut store, &[m.config, inflight_config]);
        let got = shimmies(&mut store, ghost_max);
        let mut allowed = m.flash.clone();
        if inflight_entry.is_some() && got.last() == inflight_entry.as_ref() {
            allowed.extend(inflight_entry);
        }
        match kind {
            // A cut clear: whatever survived is a ghost (only its order is checked, above).
            3 => {}
            // A flush may have dropped the oldest entries before the cut.
            2 => assert!(
                allowed.ends_with(&got),
                "{got:?} is not a suffix of {allowed:?}"
            ),
            // Anything else leaves the flash's entries as they were (plus the one appended).
            _ => assert_eq!(got, allowed, "entries lost or changed by a cut"),
        }
        m.flash = got;
        m.pending.clear();
    }
});
