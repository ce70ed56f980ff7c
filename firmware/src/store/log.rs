//! The event log's byte form in flash: a tag byte, then fixed little-endian fields. The entries
//! are the host link's ([`LogEntry`]: what the link serves is what the flash keeps, made by the
//! one recorder, `shimmy_link::log::Recorder`). An entry with an unknown tag, a wrong length or
//! a code out of range is reported as unreadable, never guessed at.
//!
//! - shimmy episode ([`ShimmyEvent`], closed): start time (f64), then speed, frequency, peak
//!   amplitude, duration, time in shimmy, peak and mean coil command (f32), then the level;
//! - fault ([`FaultEvent`]): time (u32 ms), kind, latched (0 or 1);
//! - boot ([`BootEvent`]): cause, resets since power-on, the store's persistent boot count;
//! - diagnosis ([`DiagnosisEvent`]): time (u32 ms), the parameter's index (255: none), factor,
//!   sigma of ln(factor), band low and high (f32).

use shimmy_core::supervisor::faults::FaultKind;
pub use shimmy_link::wire::{BootEvent, DiagnosisEvent, FaultEvent, LogEntry, ShimmyEvent};

/// The longest entry, bytes.
pub const ENTRY_MAX_BYTES: usize = 40;

const TAG_SHIMMY: u8 = 1;
const TAG_FAULT: u8 = 2;
const TAG_BOOT: u8 = 3;
const TAG_DIAGNOSIS: u8 = 4;
/// The diagnosis' parameter index for "none".
const NO_PARAM: u8 = u8::MAX;
/// Level codes run 0..=this (`shimmy_link::wire::level_code`).
const LEVEL_MAX: u8 = 3;

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

/// The entry's bytes in `out`; returns how many.
pub fn encode(entry: &LogEntry, out: &mut [u8; ENTRY_MAX_BYTES]) -> usize {
    let mut w = Writer { out, at: 0 };
    match entry {
        LogEntry::Shimmy(e) => {
            w.put(&[TAG_SHIMMY]);
            w.put(&e.start_s.to_le_bytes());
            for v in [
                e.speed_mps,
                e.freq_hz,
                e.peak_amplitude_rad,
                e.duration_s,
                e.shimmy_s,
                e.peak_current_a,
                e.mean_current_a,
            ] {
                w.put(&v.to_le_bytes());
            }
            w.put(&[e.level]);
        }
        LogEntry::Fault(f) => {
            w.put(&[TAG_FAULT]);
            w.put(&f.t_ms.to_le_bytes());
            w.put(&[f.kind, u8::from(f.latched)]);
        }
        LogEntry::Boot(b) => {
            w.put(&[TAG_BOOT, b.cause]);
            w.put(&b.resets_since_power_on.to_le_bytes());
            w.put(&b.boot_count.to_le_bytes());
        }
        LogEntry::Diagnosis(d) => {
            w.put(&[TAG_DIAGNOSIS]);
            w.put(&d.t_ms.to_le_bytes());
            w.put(&[d.param.unwrap_or(NO_PARAM)]);
            for v in [d.factor, d.sigma_ln, d.band_low, d.band_high] {
                w.put(&v.to_le_bytes());
            }
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
            let [speed_mps, freq_hz, peak_amplitude_rad, duration_s, shimmy_s, peak_current_a, mean_current_a] = [
                r.f32()?,
                r.f32()?,
                r.f32()?,
                r.f32()?,
                r.f32()?,
                r.f32()?,
                r.f32()?,
            ];
            let level = r.u8().filter(|&l| l <= LEVEL_MAX)?;
            Some(LogEntry::Shimmy(ShimmyEvent {
                start_s,
                speed_mps,
                freq_hz,
                peak_amplitude_rad,
                duration_s,
                shimmy_s,
                level,
                open: false,
                peak_current_a,
                mean_current_a,
            }))
        })(),
        Some(TAG_FAULT) => (|| {
            let t_ms = r.u32()?;
            let kind = r.u8().filter(|&k| usize::from(k) < FaultKind::ALL.len())?;
            let latched = match r.u8()? {
                0 => false,
                1 => true,
                _ => return None,
            };
            Some(LogEntry::Fault(FaultEvent {
                t_ms,
                kind,
                latched,
            }))
        })(),
        Some(TAG_BOOT) => (|| {
            let cause = r.u8()?;
            let resets_since_power_on = r.u32()?;
            let boot_count = r.u32()?;
            Some(LogEntry::Boot(BootEvent {
                cause,
                resets_since_power_on,
                boot_count,
            }))
        })(),
        Some(TAG_DIAGNOSIS) => (|| {
            let t_ms = r.u32()?;
            let param = match r.u8()? {
                NO_PARAM => None,
                i => Some(i),
            };
            let [factor, sigma_ln, band_low, band_high] = [r.f32()?, r.f32()?, r.f32()?, r.f32()?];
            Some(LogEntry::Diagnosis(DiagnosisEvent {
                t_ms,
                param,
                factor,
                sigma_ln,
                band_low,
                band_high,
            }))
        })(),
        _ => None,
    };
    match entry {
        Some(e) if r.bytes.is_empty() => Ok(e),
        _ => Err(bad),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fault_memory::ResetCause;
    use shimmy_link::wire::fault_code;

    fn shimmy() -> LogEntry {
        LogEntry::Shimmy(ShimmyEvent {
            start_s: 1234.5,
            speed_mps: 21.5,
            freq_hz: 8.25,
            peak_amplitude_rad: 0.02,
            duration_s: 3.5,
            shimmy_s: 2.0,
            level: 3,
            open: false,
            peak_current_a: 1.75,
            mean_current_a: 0.5,
        })
    }

    #[test]
    fn every_kind_of_entry_round_trips_and_a_bad_one_is_unreadable() {
        let entries = [
            shimmy(),
            LogEntry::Fault(FaultEvent {
                t_ms: 99_250,
                kind: fault_code(FaultKind::CoilShort),
                latched: true,
            }),
            LogEntry::Boot(BootEvent {
                cause: ResetCause::Watchdog as u8,
                resets_since_power_on: 3,
                boot_count: 1000,
            }),
            LogEntry::Diagnosis(DiagnosisEvent {
                t_ms: 61_000,
                param: Some(2),
                factor: 0.5,
                sigma_ln: 0.02,
                band_low: 0.7,
                band_high: 1.3,
            }),
            LogEntry::Diagnosis(DiagnosisEvent {
                t_ms: 62_000,
                param: None,
                factor: 0.0,
                sigma_ln: 0.0,
                band_low: 0.0,
                band_high: 0.0,
            }),
        ];
        for e in entries {
            let mut buf = [0u8; ENTRY_MAX_BYTES];
            let n = encode(&e, &mut buf);
            assert_eq!(decode(&buf[..n]), Ok(e));
            // One byte short or long, or an unknown tag: refused, not misread.
            assert!(decode(&buf[..n - 1]).is_err());
            assert!(decode(&buf[..n + 1]).is_err());
            buf[0] = 9;
            assert_eq!(decode(&buf[..n]), Err(Unreadable { tag: 9, len: n }));
        }
        // A code out of range: a level, a fault kind, a latched flag.
        let mut buf = [0u8; ENTRY_MAX_BYTES];
        let n = encode(&shimmy(), &mut buf);
        buf[n - 1] = LEVEL_MAX + 1;
        assert!(decode(&buf[..n]).is_err());
        for (at, bad) in [(5, FaultKind::ALL.len() as u8), (6, 2)] {
            let f = LogEntry::Fault(FaultEvent {
                t_ms: 1,
                kind: 0,
                latched: false,
            });
            let n = encode(&f, &mut buf);
            buf[at] = bad;
            assert!(decode(&buf[..n]).is_err(), "byte {at} = {bad}");
        }
    }
}
