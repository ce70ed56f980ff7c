//! What the event log keeps, and its byte form in flash: a tag byte, then fixed little-endian
//! fields. An entry with an unknown tag or a wrong length is reported as unreadable, never
//! guessed at.
//!
//! - [`ShimmyEntry`]: one closed episode of the core monitor ([`Event`]: start time, speed,
//!   frequency, peak amplitude, duration, time in shimmy, highest level) with the controller's
//!   action during it (peak and mean coil command), made by [`EpisodeRecorder`];
//! - [`FaultEntry`]: a fault the supervisor latched (coil open or short, an escalated
//!   intermittent fault), with the whole latched set;
//! - [`BootEntry`]: a boot, with the reset cause and count of the fault memory
//!   (`crate::fault_memory`) and the store's persistent boot count.

use crate::fault_memory::ResetCause;
use shimmy_core::estimator::monitor::{Event, Level, Monitor};
use shimmy_core::supervisor::faults::{FaultKind, FaultSet};

/// The longest entry, bytes.
pub const ENTRY_MAX_BYTES: usize = 40;

const TAG_SHIMMY: u8 = 1;
const TAG_FAULT: u8 = 2;
const TAG_BOOT: u8 = 3;

/// A closed shimmy episode and what the controller did during it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShimmyEntry {
    /// The monitor's event (closed).
    pub event: Event,
    /// Largest coil-current command during the episode, A.
    pub cmd_peak_a: f32,
    /// Mean coil-current command during the episode, A.
    pub cmd_mean_a: f32,
}

/// A latched fault.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FaultEntry {
    /// When it was latched (margin-path time since boot), s.
    pub t_s: f64,
    /// The fault newly latched.
    pub fault: FaultKind,
    /// Every latched fault at that moment.
    pub latched: FaultSet,
}

/// A boot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BootEntry {
    /// Why the MCU started.
    pub cause: ResetCause,
    /// Resets since power-on (the fault memory's count).
    pub resets_since_power_on: u32,
    /// Boots of this board the store has counted (persistent across power-offs).
    pub boot_count: u32,
}

/// One entry of the event log.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LogEntry {
    /// A shimmy episode.
    Shimmy(ShimmyEntry),
    /// A latched fault.
    Fault(FaultEntry),
    /// A boot.
    Boot(BootEntry),
}

/// Why bytes from the log are not an entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(target_os = "none", derive(defmt::Format))]
pub struct Unreadable {
    /// The tag byte found (0 for an empty entry).
    pub tag: u8,
    /// The length found.
    pub len: usize,
}

struct Writer<'a> {
    out: &'a mut [u8; ENTRY_MAX_BYTES],
    at: usize,
}

impl Writer<'_> {
    fn put(&mut self, bytes: &[u8]) {
        if let Some(dst) = self.out.get_mut(self.at..self.at + bytes.len()) {
            dst.copy_from_slice(bytes);
        }
        self.at += bytes.len();
    }
}

struct Reader<'a> {
    bytes: &'a [u8],
}

impl Reader<'_> {
    fn take<const N: usize>(&mut self) -> Option<[u8; N]> {
        let (head, rest) = self.bytes.split_first_chunk::<N>()?;
        self.bytes = rest;
        Some(*head)
    }
    fn f32(&mut self) -> Option<f32> {
        self.take().map(f32::from_le_bytes)
    }
    fn f64(&mut self) -> Option<f64> {
        self.take().map(f64::from_le_bytes)
    }
    fn u32(&mut self) -> Option<u32> {
        self.take().map(u32::from_le_bytes)
    }
    fn u8(&mut self) -> Option<u8> {
        self.take::<1>().map(|[b]| b)
    }
}

fn level_code(l: Level) -> u8 {
    match l {
        Level::Normal => 0,
        Level::MarginLow => 1,
        Level::ApproachingCritical => 2,
        Level::ShimmyPresent => 3,
    }
}

fn level_of(code: u8) -> Option<Level> {
    match code {
        0 => Some(Level::Normal),
        1 => Some(Level::MarginLow),
        2 => Some(Level::ApproachingCritical),
        3 => Some(Level::ShimmyPresent),
        _ => None,
    }
}

impl LogEntry {
    /// The entry's bytes in `out`; returns how many.
    pub fn encode(&self, out: &mut [u8; ENTRY_MAX_BYTES]) -> usize {
        let mut w = Writer { out, at: 0 };
        match self {
            LogEntry::Shimmy(s) => {
                let e = &s.event;
                w.put(&[TAG_SHIMMY]);
                w.put(&e.start_s.to_le_bytes());
                for v in [
                    e.speed_mps,
                    e.freq_hz,
                    e.peak_amplitude_rad,
                    e.duration_s,
                    e.shimmy_s,
                    s.cmd_peak_a,
                    s.cmd_mean_a,
                ] {
                    w.put(&v.to_le_bytes());
                }
                w.put(&[level_code(e.worst)]);
            }
            LogEntry::Fault(f) => {
                w.put(&[TAG_FAULT]);
                w.put(&f.t_s.to_le_bytes());
                w.put(&[f.fault as u8]);
                w.put(&f.latched.bits().to_le_bytes());
            }
            LogEntry::Boot(b) => {
                w.put(&[TAG_BOOT, b.cause as u8]);
                w.put(&b.resets_since_power_on.to_le_bytes());
                w.put(&b.boot_count.to_le_bytes());
            }
        }
        w.at
    }

    /// The entry of `bytes` (exactly one entry's bytes).
    pub fn decode(bytes: &[u8]) -> Result<LogEntry, Unreadable> {
        let bad = Unreadable {
            tag: bytes.first().copied().unwrap_or(0),
            len: bytes.len(),
        };
        let mut r = Reader { bytes };
        let entry = match r.u8() {
            Some(TAG_SHIMMY) => (|| {
                let start_s = r.f64()?;
                let [speed_mps, freq_hz, peak_amplitude_rad, duration_s, shimmy_s, cmd_peak_a, cmd_mean_a] = [
                    r.f32()?,
                    r.f32()?,
                    r.f32()?,
                    r.f32()?,
                    r.f32()?,
                    r.f32()?,
                    r.f32()?,
                ];
                let worst = level_of(r.u8()?)?;
                Some(LogEntry::Shimmy(ShimmyEntry {
                    event: Event {
                        start_s,
                        speed_mps,
                        freq_hz,
                        peak_amplitude_rad,
                        worst,
                        duration_s,
                        shimmy_s,
                        open: false,
                    },
                    cmd_peak_a,
                    cmd_mean_a,
                }))
            })(),
            Some(TAG_FAULT) => (|| {
                let t_s = r.f64()?;
                let fault = *FaultKind::ALL.get(usize::from(r.u8()?))?;
                let latched = FaultSet::from_bits(r.u32()?);
                Some(LogEntry::Fault(FaultEntry {
                    t_s,
                    fault,
                    latched,
                }))
            })(),
            Some(TAG_BOOT) => (|| {
                let cause = ResetCause::from_code(r.u8()?);
                let resets_since_power_on = r.u32()?;
                let boot_count = r.u32()?;
                Some(LogEntry::Boot(BootEntry {
                    cause,
                    resets_since_power_on,
                    boot_count,
                }))
            })(),
            _ => None,
        };
        match entry {
            Some(e) if r.bytes.is_empty() => Ok(e),
            _ => Err(bad),
        }
    }
}

/// Turns the core monitor's closed events into [`ShimmyEntry`]s, adding the controller's
/// action: fed every 1 kHz sample's coil command ([`Self::sample`]) and the monitor after each
/// 100 Hz update ([`Self::update`]).
#[derive(Clone, Debug, Default)]
pub struct EpisodeRecorder {
    /// Closed events seen so far (the monitor's closed log plus its dropped count).
    closed_seen: u32,
    open: bool,
    peak_a: f32,
    sum_a: f32,
    n: u32,
}

impl EpisodeRecorder {
    /// Nothing seen.
    pub const fn new() -> Self {
        EpisodeRecorder {
            closed_seen: 0,
            open: false,
            peak_a: 0.0,
            sum_a: 0.0,
            n: 0,
        }
    }

    /// One control step's coil command, A (counted while an episode is open).
    pub fn sample(&mut self, cmd_a: f32) {
        if self.open && cmd_a.is_finite() {
            self.peak_a = self.peak_a.max(cmd_a);
            self.sum_a += cmd_a;
            self.n += 1;
        }
    }

    /// After a monitor update: the episode that closed with it, if one did.
    pub fn update<const N: usize>(&mut self, monitor: &Monitor<N>) -> Option<ShimmyEntry> {
        let mut closed = 0u32;
        let mut newest = None;
        let mut open = false;
        for e in monitor.events() {
            if e.open {
                open = true;
            } else {
                closed += 1;
                newest = Some(*e);
            }
        }
        let closed = closed.saturating_add(monitor.dropped_events());
        let entry = if closed != self.closed_seen {
            self.closed_seen = closed;
            newest.map(|event| ShimmyEntry {
                event,
                cmd_peak_a: self.peak_a,
                cmd_mean_a: if self.n > 0 {
                    self.sum_a / self.n as f32
                } else {
                    0.0
                },
            })
        } else {
            None
        };
        if entry.is_some() || (open && !self.open) {
            self.peak_a = 0.0;
            self.sum_a = 0.0;
            self.n = 0;
        }
        self.open = open;
        entry
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shimmy() -> LogEntry {
        LogEntry::Shimmy(ShimmyEntry {
            event: Event {
                start_s: 1234.5,
                speed_mps: 21.5,
                freq_hz: 8.25,
                peak_amplitude_rad: 0.02,
                worst: Level::ShimmyPresent,
                duration_s: 3.5,
                shimmy_s: 2.0,
                open: false,
            },
            cmd_peak_a: 1.75,
            cmd_mean_a: 0.5,
        })
    }

    #[test]
    fn every_kind_of_entry_round_trips_and_a_bad_one_is_unreadable() {
        let mut latched = FaultSet::EMPTY;
        latched.insert(FaultKind::CoilShort);
        let entries = [
            shimmy(),
            LogEntry::Fault(FaultEntry {
                t_s: 99.25,
                fault: FaultKind::CoilShort,
                latched,
            }),
            LogEntry::Boot(BootEntry {
                cause: ResetCause::Watchdog,
                resets_since_power_on: 3,
                boot_count: 1000,
            }),
        ];
        for e in entries {
            let mut buf = [0u8; ENTRY_MAX_BYTES];
            let n = e.encode(&mut buf);
            assert_eq!(LogEntry::decode(&buf[..n]), Ok(e));
            // One byte short or long, or an unknown tag: refused, not misread.
            assert!(LogEntry::decode(&buf[..n - 1]).is_err());
            assert!(LogEntry::decode(&buf[..n + 1]).is_err());
            buf[0] = 9;
            assert_eq!(
                LogEntry::decode(&buf[..n]),
                Err(Unreadable { tag: 9, len: n })
            );
        }
    }
}
