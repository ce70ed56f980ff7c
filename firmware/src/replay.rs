//! Host/target conformance: replays a recorded sensor trace through the firmware's code
//! path (the encoder angle tracker, [`crate::control::supervised_step`]-equivalent frame
//! building, the core's `SafeController` (supervisor + ASMC + limiter), the core's data
//! pipeline (mode meter + fusion + monitor) and the model-margin tracker) and digests every
//! output as bit patterns. The host test (`tests/tests/cross_crate/conformance.rs`) and the on-target
//! program (`src/bin/conformance.rs`, under QEMU) run this same function on the same trace;
//! `cargo xtask test` fails unless every channel's digest is identical.
//!
//! The replay injects encoder faults at fixed samples ([`FAULTS`]) so the supervisor's
//! Degraded / FailSafe modes and its recovery are part of the comparison.
//!
//! Trace format (little-endian, [`SAMPLE_BYTES`] bytes per 1 kHz sample, no header): left raw
//! 14-bit encoder count (u16), right raw count (u16), vehicle speed (f32 bits, m/s). Angles
//! are 0 at raw count [`ZERO_COUNTS`].

use crate::drivers::as5047p::AngleTracker;
use crate::monitoring::{
    safe_controller, step_time_s, DataMargin, MeterSample, ModelTask, ROLLING_RADIUS_M,
};
use shimmy_core::estimator::model_margin::ModelMargin;
use shimmy_core::estimator::monitor::Level;
use shimmy_core::estimator::pipeline::PipelineParams;
use shimmy_core::supervisor::frame::{EncoderReading, RawFrame};
use shimmy_core::supervisor::policy::Mode;

/// Bytes per sample in a trace.
pub const SAMPLE_BYTES: usize = 8;
/// Raw count of 0 rad in traces.
pub const ZERO_COUNTS: u16 = 8192;
/// An encoder fault the replay injects.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Injected {
    /// Parity error on the left encoder's response.
    LeftParity,
    /// The right encoder's error flag.
    RightErrorFlag,
    /// The right encoder's raw count frozen.
    RightStuck,
}

/// Injected faults: (first sample, end sample (exclusive), fault). A parity error on the left
/// (Degraded), then the right error flag while the left has not recovered (FailSafe), both
/// recover (1 s each); later the right encoder freezes for 0.3 s.
pub const FAULTS: [(usize, usize, Injected); 3] = [
    (1500, 1501, Injected::LeftParity),
    (1700, 1701, Injected::RightErrorFlag),
    (4000, 4300, Injected::RightStuck),
];

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
pub const CHANNELS: [&str; 7] = [
    "coil_current_cmd_a",
    "supervisor_mode_faults",
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
    pub channels: [Channel; 7],
    /// Samples replayed.
    pub samples: u32,
    /// Samples in which the supervisor was in FailSafe.
    pub failsafe: u32,
    /// Samples in which the supervisor was in Degraded.
    pub degraded: u32,
    /// Supervisor mode changes.
    pub mode_changes: u32,
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

fn reading(
    tracker: &mut AngleTracker,
    raw: u16,
    fault: Option<Injected>,
    left: bool,
) -> EncoderReading {
    let mut e = EncoderReading::ok(f32::NAN);
    match fault {
        Some(Injected::LeftParity) if left => e.parity_ok = false,
        Some(Injected::RightErrorFlag) if !left => e.error_flag = true,
        _ => match tracker.update(raw) {
            Ok(a) => e.angle_rad = a,
            Err(_) => e.read_ok = false,
        },
    }
    e
}

/// Replays `trace` through the supervised controller and the margin estimation with the
/// firmware's configuration, `params` as the model plant.
pub fn replay(
    trace: &[u8],
    params: &shimmy_core::vehicles::car::PlantParams,
) -> Result<Digest, ReplayError> {
    if !trace.len().is_multiple_of(SAMPLE_BYTES) {
        return Err(ReplayError::Length);
    }
    let n = trace.len() / SAMPLE_BYTES;
    let mut ctrl = safe_controller();
    let pipeline = PipelineParams::default();
    let mut data =
        DataMargin::with_params(&pipeline, ROLLING_RADIUS_M).map_err(|_| ReplayError::Config)?;
    let mut model_task = ModelTask::new(*params, pipeline.matched_update());
    let mut model: Option<ModelMargin> = None;
    let mut trk = [AngleTracker::new(ZERO_COUNTS, 8191); 2];
    let mut d = Digest::default();
    let mut stuck_r: Option<u16> = None;
    let mut mode = Mode::Normal;
    for k in 0..n {
        let Some((l, mut r, v)) = sample(trace, k) else {
            break;
        };
        let fault = FAULTS
            .iter()
            .find(|(a, b, _)| (*a..*b).contains(&k))
            .map(|f| f.2);
        if fault == Some(Injected::RightStuck) {
            r = *stuck_r.get_or_insert(r);
        }
        let step = k as u32;
        d.samples += 1;
        let frame = RawFrame {
            t_us: step.wrapping_mul(shimmy_core::supervisor::frame::NOMINAL_PERIOD_US),
            left: reading(&mut trk[0], l, fault, true),
            right: reading(&mut trk[1], r, fault, false),
            speed_mps: v,
            speed_valid: true,
            coil_current_a: None,
            coil_drive_a: None,
        };
        let out = ctrl.step(&frame, data.margin_status());
        let cmd = out.current_cmd_a;
        d.channels[0].record(|h| h.f32(cmd), f64::from(cmd));
        let vd = &out.verdict;
        d.channels[1].record(
            |h| {
                h.bytes(&[vd.mode as u8]);
                h.bytes(&vd.faults.bits().to_le_bytes());
                h.bytes(&vd.detected.bits().to_le_bytes());
                h.f32(vd.safe_current_a.unwrap_or(f32::NAN));
            },
            f64::from(vd.mode as u8),
        );
        match vd.mode {
            Mode::Normal => {}
            Mode::Degraded => d.degraded += 1,
            Mode::FailSafe => d.failsafe += 1,
        }
        d.mode_changes += u32::from(vd.mode != mode);
        mode = vd.mode;
        let ms = MeterSample::of(step, &out);
        if let Some((u, _)) = data.push(&ms, model.as_ref()) {
            let (f, s) = (&u.meter.fast, &u.meter.slow);
            d.channels[2].record(
                |h| {
                    h.f32(f.zeta);
                    h.f32(f.freq_hz);
                    h.f32(f.sigma_zeta);
                    h.bytes(&[u8::from(f.valid)]);
                },
                f64::from(f.zeta),
            );
            d.channels[3].record(
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
            d.channels[4].record(
                |h| {
                    h.f32(rep.zeta_data);
                    h.f32(rep.sigma_zeta_data);
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
            d.channels[5].record(|h| h.bytes(&[u.level as u8]), u.level as u8 as f64);
            d.worst_level = d.worst_level.max(u.level);
        }
        // The background model loop: one tracker call per sample here (on the board as many as
        // the CPU leaves; the results are the same per completed cycle, only their timing
        // differs).
        model_task.offer(data.take_measurement());
        if let Some(pt) = model_task.step(step_time_s(u64::from(step)), data.speed_mps()) {
            let published = model_task.publish(&pt);
            data.set_margin_sigma(published.onset_sigma_mps);
            let m = published.margin;
            d.channels[6].record(
                |h| {
                    h.f64(m.zeta);
                    h.f64(m.freq_hz);
                    h.f64(m.dzeta_dv_per_mps);
                    h.f64(m.v_crit_onset_mps.unwrap_or(f64::NAN));
                    h.bytes(&[u8::from(m.valid)]);
                    h.f64(pt.above.map_or(f64::NAN, |c| c.speed_mps));
                    h.f64(pt.below.map_or(f64::NAN, |c| c.speed_mps));
                    h.f64(pt.max_re);
                    h.bytes(&pt.eigen_solves.to_le_bytes());
                },
                m.zeta,
            );
            model = Some(m);
        }
    }
    Ok(d)
}
