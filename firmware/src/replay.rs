//! Host/target conformance: replays a recorded sensor trace through the firmware's seams (the
//! encoder angle tracker, [`validate`](crate::control::validate)-equivalent conversion, the
//! core controller, the mode meter + fusion + monitor, the model margin) and digests every
//! output as bit patterns. The host test (`tests/tests/conformance.rs`) and the on-target
//! program (`src/bin/conformance.rs`, under QEMU) run this same function on the same trace;
//! `cargo xtask test` fails unless every channel's digest is identical.
//!
//! Trace format (little-endian, [`SAMPLE_BYTES`] bytes per 1 kHz sample, no header): left raw
//! 14-bit encoder count (u16), right raw count (u16), vehicle speed (f32 bits, m/s). Angles
//! are 0 at raw count [`ZERO_COUNTS`].

use crate::control::ControlInput;
use crate::drivers::as5047p::AngleTracker;
use crate::monitoring::{CoreController, DataMargin, MeterSample, ModelMarginTask, DT_S};
use shimmy_core::estimator::ModelMargin;
use shimmy_core::monitor::Level;

/// Bytes per sample in a trace.
pub const SAMPLE_BYTES: usize = 8;
/// Raw count of 0 rad in traces.
pub const ZERO_COUNTS: u16 = 8192;
/// Model updates every this many meter updates (10 Hz).
pub const MODEL_DIVIDER: u32 = 10;

/// FNV-1a 64-bit hash of a byte stream (order-sensitive, cheap on the M4).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fnv(pub u64);

impl Default for Fnv {
    fn default() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
}

impl Fnv {
    /// Adds bytes.
    pub fn bytes(&mut self, b: &[u8]) {
        for &x in b {
            self.0 ^= u64::from(x);
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01b3);
        }
    }
    /// Adds an f32 by its bit pattern.
    pub fn f32(&mut self, x: f32) {
        self.bytes(&x.to_bits().to_le_bytes());
    }
    /// Adds an f64 by its bit pattern.
    pub fn f64(&mut self, x: f64) {
        self.bytes(&x.to_bits().to_le_bytes());
    }
}

/// One output channel: how many records, their hash, and the last record's first value.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Channel {
    /// Records hashed.
    pub count: u32,
    /// FNV-1a over the records' bit patterns.
    pub hash: Fnv,
    /// Bit pattern of the last record's headline value (f64 bits; f32 values widened).
    pub last_bits: u64,
}

impl Channel {
    fn record(&mut self, f: impl FnOnce(&mut Fnv), headline: f64) {
        self.count += 1;
        f(&mut self.hash);
        self.last_bits = headline.to_bits();
    }
}

/// Names of the channels, in [`Digest::channels`] order.
pub const CHANNELS: [&str; 6] = [
    "coil_current_cmd_a",
    "meter_fast_zeta_freq",
    "meter_slow_zeta_freq_amp",
    "fused_report",
    "warning_level",
    "model_margin",
];

/// Digest of a replay.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Digest {
    /// Per channel, in [`CHANNELS`] order.
    pub channels: [Channel; 6],
    /// Samples replayed.
    pub samples: u32,
    /// Samples the angle tracker rejected (fail-safe steps).
    pub rejected: u32,
    /// Highest warning level seen.
    pub worst_level: Level,
}

/// Errors of [`replay`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReplayError {
    /// The trace length is not a multiple of [`SAMPLE_BYTES`].
    Length,
    /// The core rejected its default configuration.
    Config,
}

/// Decodes sample `k` of a trace: (left raw, right raw, speed).
pub fn sample(trace: &[u8], k: usize) -> Option<(u16, u16, f32)> {
    let b = trace.get(k * SAMPLE_BYTES..(k + 1) * SAMPLE_BYTES)?;
    let u = |i: usize| u16::from_le_bytes([b[i], b[i + 1]]);
    let v = f32::from_bits(u32::from_le_bytes([b[4], b[5], b[6], b[7]]));
    Some((u(0), u(2), v))
}

/// Replays `trace` through the controller and the margin estimation with the default
/// configuration, `params` as the model plant.
pub fn replay(
    trace: &[u8],
    params: &shimmy_core::params::PlantParams,
) -> Result<Digest, ReplayError> {
    if !trace.len().is_multiple_of(SAMPLE_BYTES) {
        return Err(ReplayError::Length);
    }
    let n = trace.len() / SAMPLE_BYTES;
    let mut ctrl = CoreController::asmc();
    let mut data = DataMargin::new().ok_or(ReplayError::Config)?;
    let mut model_task = ModelMarginTask::new(*params, 0.0);
    let mut model: Option<ModelMargin> = None;
    let mut trk = [AngleTracker::new(ZERO_COUNTS, 200); 2];
    let mut d = Digest::default();
    let mut meter_runs = 0u32;
    for k in 0..n {
        let Some((l, r, v)) = sample(trace, k) else {
            break;
        };
        let step = k as u32;
        d.samples += 1;
        let input = match (trk[0].update(l), trk[1].update(r)) {
            (Ok(psi_l_rad), Ok(psi_r_rad)) => Some(ControlInput {
                step,
                dt_s: DT_S,
                psi_l_rad,
                psi_r_rad,
                speed_mps: v,
                coil_current_a: f32::NAN,
            }),
            _ => None,
        };
        let cmd = match &input {
            Some(i) => crate::control::ControlStep::step(&mut ctrl, i),
            None => {
                d.rejected += 1;
                f32::NAN
            }
        };
        d.channels[0].record(|h| h.f32(cmd), f64::from(cmd));
        let ms = MeterSample::of(step, input.as_ref());
        if let Some(u) = data.push(&ms, model.as_ref()) {
            let (f, s) = (&u.meter.fast, &u.meter.slow);
            d.channels[1].record(
                |h| {
                    h.f32(f.zeta);
                    h.f32(f.freq_hz);
                    h.f32(f.sigma_zeta);
                    h.bytes(&[u8::from(f.valid)]);
                },
                f64::from(f.zeta),
            );
            d.channels[2].record(
                |h| {
                    h.f32(s.zeta);
                    h.f32(s.freq_hz);
                    h.f32(s.sigma_zeta);
                    h.bytes(&[u8::from(s.valid)]);
                    h.f32(u.meter.amplitude_rad);
                    h.f32(u.meter.excitation_rms_rad);
                },
                f64::from(s.zeta),
            );
            let rep = &u.report;
            d.channels[3].record(
                |h| {
                    h.f32(rep.speed_margin_mps.unwrap_or(f32::NAN));
                    h.f32(rep.time_to_critical_s.unwrap_or(f32::NAN));
                    h.f32(rep.zeta_model.unwrap_or(f32::NAN));
                    h.bytes(&[
                        rep.margin_source as u8,
                        u8::from(rep.valid),
                        u8::from(rep.model_consistent),
                    ]);
                },
                f64::from(rep.speed_margin_mps.unwrap_or(f32::NAN)),
            );
            d.channels[4].record(|h| h.bytes(&[u.level as u8]), u.level as u8 as f64);
            d.worst_level = d.worst_level.max(u.level);
            meter_runs += 1;
            if meter_runs.is_multiple_of(MODEL_DIVIDER) {
                let m = model_task.update(data.speed_mps());
                d.channels[5].record(
                    |h| {
                        h.f64(m.zeta);
                        h.f64(m.freq_hz);
                        h.f64(m.dzeta_dv_per_mps);
                        h.f64(m.v_crit_onset_mps.unwrap_or(f64::NAN));
                        h.bytes(&[u8::from(m.valid)]);
                    },
                    m.zeta,
                );
                model = Some(m);
            }
        }
    }
    Ok(d)
}
