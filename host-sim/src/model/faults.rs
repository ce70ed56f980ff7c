//! Fault injection for the closed loop: sensor faults that rewrite the healthy
//! [`Measurement`] (through the [`FaultInjector`] hook of [`crate::model::sensors::Sensors`]) and coil
//! faults that change the plant's actuator ([`CoilState`]).
//!
//! Each [`FaultSpec`] is active over `[start_s, end_s)` (no end: to the end of the run), on one
//! encoder or both where that applies. Several specs combine (applied in order). Everything is
//! deterministic: the patterns (dropouts, spikes, lost frames) are periodic from the start time,
//! the noise is seeded.
//!
//! | kind | effect on the frame the firmware reads | what the supervisor should see |
//! |---|---|---|
//! | `stuck` | the angle freezes at its value at `start_s` | `*Stuck` (once the other encoder moves > 5 mrad) or `BothStuckSuspect` (2 s) |
//! | `noise` | + Gaussian noise of `std_deg` | `*Rate` (when the sample-to-sample step exceeds 25 rad/s x 1 ms) |
//! | `dropout` | `length_samples` of every `period_samples` failed reads (angle held) | `*Read` |
//! | `spike` | + `amplitude_deg` (alternating sign) on one sample of every `period_samples` | `*Rate` / `*Range` |
//! | `nan` | NaN angle | `*NonFinite` |
//! | `parity` | parity bit wrong | `*Flag` |
//! | `error-flag` | the sensor's error flag set | `*Flag` |
//! | `speed-lost` | speed 0 with the validity qualifier false | `SpeedInvalid` |
//! | `speed-pulses-lost` | the tone-wheel pulse train stops; the decoder's reading (qualifier valid): its value at the start, bounded by one pulse distance over the time since the last edge, then 0 m/s (standstill) after its timeout | `SpeedJump` + `SpeedLowImplausible` (faster than braking; held while below the 2 m/s gate) |
//! | `speed-implausible` | speed replaced by `speed_kmh` (validity true): also a speed frozen at a plausible value | `SpeedInvalid` (> 252 km/h or < 0) / `SpeedJump`; `SpeedLowImplausible` when below the 2 m/s gate |
//! | `frame-loss` | `length_samples` of every `period_samples` whole frames lost (command held) | missed-sample counter; `Timing` for gaps > 5 ms |
//! | `coil-open` | coil carries no current (damper passive-off), shunt reads ~0 | `CoilOpen` (latched) |
//! | `coil-short` | current bypasses the coil (damper passive-off), shunt reads `ratio` x what the drive pushes through the coil (no L/R lag; x the command for an ideal current source) | `CoilShort` (latched) |
//! | `coil-intermittent` | chattering connector: the coil open `length_samples` of every `period_samples` | `CoilOpen` once the accumulated mismatch reaches 50 ms (latched) |
//! | `coil-hot` | coil resistance x `ratio` (a board drive, `coil_drive`, sees it: open loop the current falls by the ratio) | nothing: the closed current loop holds the command |
//! | `supply` | supply voltage of the coil drive, V (a board drive sees it) | nothing: the closed current loop holds the command |
//! | `coil-sensor-offset` | the coil-current reading + `offset_a` (before the ADC) | `CoilSensor` (latched; the coil driven open loop): a reading without drive, or outside the coil's ratio band |
//! | `coil-sensor-gain` | the coil-current reading x `gain` (before the ADC) | `CoilSensor` (latched; open loop): outside the coil's ratio band |
//!
//! The last five are campaign faults (`shimmy-sim faults`), not scenario-file kinds ([`KINDS`]).

use crate::model::coil_drive::DriveCondition;
use crate::model::sensors::{CoilState, EncoderStatus, FaultInjector, Measurement};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

/// Which encoder an encoder fault hits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// Left kingpin encoder.
    Left,
    /// Right kingpin encoder.
    Right,
    /// Both encoders (a common-cause fault: supply, connector, SPI bus).
    Both,
}

impl Side {
    /// Name in scenario files and tables.
    pub fn name(self) -> &'static str {
        match self {
            Side::Left => "left",
            Side::Right => "right",
            Side::Both => "both",
        }
    }

    /// Parses `left`, `right` or `both`.
    pub fn from_name(s: &str) -> Option<Self> {
        match s {
            "left" => Some(Side::Left),
            "right" => Some(Side::Right),
            "both" => Some(Side::Both),
            _ => None,
        }
    }

    fn hits(self, left: bool) -> bool {
        matches!(
            (self, left),
            (Side::Both, _) | (Side::Left, true) | (Side::Right, false)
        )
    }
}

/// What goes wrong.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FaultMode {
    /// Encoder angle frozen at its value when the fault starts.
    Stuck(Side),
    /// Gaussian noise of this standard deviation added to the encoder angle, rad.
    Noise(Side, f64),
    /// `length` failed reads out of every `period` samples (angle held).
    Dropout {
        /// Encoder(s).
        side: Side,
        /// Pattern period, samples.
        period: u32,
        /// Failed reads per period, samples.
        length: u32,
    },
    /// A spike of `amplitude_rad` (alternating sign) on one sample of every `period`.
    Spike {
        /// Encoder(s).
        side: Side,
        /// Pattern period, samples.
        period: u32,
        /// Spike height, rad.
        amplitude_rad: f64,
    },
    /// NaN angle.
    Nan(Side),
    /// Parity error.
    Parity(Side),
    /// The sensor's error flag.
    ErrorFlag(Side),
    /// Speed signal lost: value 0, qualifier invalid.
    SpeedLost,
    /// The tone wheel's pulse train stops (sensor or wire lost): the firmware decoder's reading,
    /// qualifier valid, min(value at the start, [`PULSE_DISTANCE_M`] / time since the last edge)
    /// and 0 m/s (standstill) after [`PULSE_TIMEOUT_S`].
    SpeedPulsesLost,
    /// Speed replaced by an implausible value, m/s (qualifier valid); a plausible value frozen
    /// while the vehicle drives on is the same fault.
    SpeedImplausible(f64),
    /// `length` whole frames lost out of every `period`.
    FrameLoss {
        /// Pattern period, samples.
        period: u32,
        /// Lost frames per period.
        length: u32,
    },
    /// Coil open circuit.
    CoilOpen,
    /// Coil terminals shorted; the shunt reads `ratio` x what the drive pushes through the
    /// coil.
    CoilShort(f64),
    /// Chattering connector: the coil is open `length` of every `period` samples.
    CoilIntermittent {
        /// Pattern period, samples.
        period: u32,
        /// Open samples per period.
        length: u32,
    },
    /// Coil resistance x this factor (a hot coil).
    CoilHot(f64),
    /// Supply voltage of the coil drive, V.
    Supply(f64),
    /// The coil-current sensor reads this much more, A (an offset of the shunt amplifier).
    CoilSensorOffset(f64),
    /// The coil-current sensor reads this many times the current (a gain error).
    CoilSensorGain(f64),
}

/// Distance between two tone-wheel pulses of the board's decoder (48 teeth, 0.35 m rolling
/// radius: `firmware::calibration::WHEEL_SPEED`), m.
pub const PULSE_DISTANCE_M: f64 = 2.0 * std::f64::consts::PI * 0.35 / 48.0;

/// The board decoder's no-edge timeout after which it reports standstill, s.
pub const PULSE_TIMEOUT_S: f64 = 0.5;

/// Fault kinds as named in scenario files.
pub const KINDS: [&str; 13] = [
    "stuck",
    "noise",
    "dropout",
    "spike",
    "nan",
    "parity",
    "error-flag",
    "speed-lost",
    "speed-pulses-lost",
    "speed-implausible",
    "frame-loss",
    "coil-open",
    "coil-short",
];

impl FaultMode {
    /// The kind's name (one of [`KINDS`]).
    pub fn kind(&self) -> &'static str {
        match self {
            FaultMode::Stuck(_) => "stuck",
            FaultMode::Noise(..) => "noise",
            FaultMode::Dropout { .. } => "dropout",
            FaultMode::Spike { .. } => "spike",
            FaultMode::Nan(_) => "nan",
            FaultMode::Parity(_) => "parity",
            FaultMode::ErrorFlag(_) => "error-flag",
            FaultMode::SpeedLost => "speed-lost",
            FaultMode::SpeedPulsesLost => "speed-pulses-lost",
            FaultMode::SpeedImplausible(_) => "speed-implausible",
            FaultMode::FrameLoss { .. } => "frame-loss",
            FaultMode::CoilOpen => "coil-open",
            FaultMode::CoilShort(_) => "coil-short",
            FaultMode::CoilIntermittent { .. } => "coil-intermittent",
            FaultMode::CoilHot(_) => "coil-hot",
            FaultMode::Supply(_) => "supply",
            FaultMode::CoilSensorOffset(_) => "coil-sensor-offset",
            FaultMode::CoilSensorGain(_) => "coil-sensor-gain",
        }
    }

    /// The encoder(s) hit, for encoder faults.
    pub fn side(&self) -> Option<Side> {
        match *self {
            FaultMode::Stuck(s)
            | FaultMode::Noise(s, _)
            | FaultMode::Dropout { side: s, .. }
            | FaultMode::Spike { side: s, .. }
            | FaultMode::Nan(s)
            | FaultMode::Parity(s)
            | FaultMode::ErrorFlag(s) => Some(s),
            _ => None,
        }
    }

    /// Short label for tables: `stuck-left`, `coil-open`, ...
    pub fn label(&self) -> String {
        match self.side() {
            Some(s) => format!("{}-{}", self.kind(), s.name()),
            None => self.kind().to_string(),
        }
    }
}

/// One fault with its activity interval.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FaultSpec {
    /// What goes wrong.
    pub mode: FaultMode,
    /// Active from, s.
    pub start_s: f64,
    /// Active until, s (`None`: to the end of the run).
    pub end_s: Option<f64>,
}

impl FaultSpec {
    /// `mode` from `start_s` to the end of the run.
    pub fn from(mode: FaultMode, start_s: f64) -> Self {
        FaultSpec {
            mode,
            start_s,
            end_s: None,
        }
    }

    /// Whether the fault is active at `t_s` (half-open interval; a half-sample tolerance so
    /// that a start on the sample grid is active on that sample).
    pub fn active(&self, t_s: f64) -> bool {
        t_s >= self.start_s - 1e-9 && self.end_s.is_none_or(|e| t_s < e - 1e-9)
    }
}

/// A set of faults, applied in order: the [`FaultInjector`] of a closed-loop run.
#[derive(Clone, Debug)]
pub struct FaultPlan {
    faults: Vec<FaultSpec>,
    rng: ChaCha8Rng,
    /// Per fault: sample index of its first active sample, frozen angles (stuck), held angles.
    first_k: Vec<Option<u64>>,
    frozen: Vec<[Option<f32>; 2]>,
    last_read: [f32; 2],
}

impl FaultPlan {
    /// A plan of `faults`; `seed` drives the noise.
    pub fn new(faults: Vec<FaultSpec>, seed: u64) -> Self {
        let n = faults.len();
        FaultPlan {
            faults,
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0x5EED_FA17),
            first_k: vec![None; n],
            frozen: vec![[None; 2]; n],
            last_read: [0.0; 2],
        }
    }

    /// The faults.
    pub fn faults(&self) -> &[FaultSpec] {
        &self.faults
    }
}

fn angle(m: &mut Measurement, left: bool) -> &mut f32 {
    if left {
        &mut m.psi_l_rad
    } else {
        &mut m.psi_r_rad
    }
}

fn status(m: &mut Measurement, left: bool) -> &mut EncoderStatus {
    if left {
        &mut m.left_status
    } else {
        &mut m.right_status
    }
}

impl FaultInjector for FaultPlan {
    fn apply(&mut self, k: u64, t_s: f64, m: &mut Measurement) {
        for i in 0..self.faults.len() {
            let f = self.faults[i];
            if !f.active(t_s) {
                self.first_k[i] = None;
                self.frozen[i] = [None; 2];
                continue;
            }
            let k0 = *self.first_k[i].get_or_insert(k);
            let n = k - k0;
            for (j, left) in [true, false].into_iter().enumerate() {
                let Some(side) = f.mode.side() else { break };
                if !side.hits(left) {
                    continue;
                }
                match f.mode {
                    FaultMode::Stuck(_) => {
                        let v = *self.frozen[i][j].get_or_insert(*angle(m, left));
                        *angle(m, left) = v;
                    }
                    FaultMode::Noise(_, std) => {
                        let z: f64 = StandardNormal.sample(&mut self.rng);
                        *angle(m, left) += (std * z) as f32;
                    }
                    FaultMode::Dropout { period, length, .. } => {
                        if n % u64::from(period.max(1)) < u64::from(length) {
                            status(m, left).read_ok = false;
                            *angle(m, left) = self.last_read[j];
                        }
                    }
                    FaultMode::Spike {
                        period,
                        amplitude_rad,
                        ..
                    } => {
                        let p = u64::from(period.max(1));
                        if n.is_multiple_of(p) {
                            let sign = if (n / p).is_multiple_of(2) { 1.0 } else { -1.0 };
                            *angle(m, left) += (sign * amplitude_rad) as f32;
                        }
                    }
                    FaultMode::Nan(_) => *angle(m, left) = f32::NAN,
                    FaultMode::Parity(_) => status(m, left).parity_ok = false,
                    FaultMode::ErrorFlag(_) => status(m, left).error_flag = true,
                    _ => {}
                }
            }
            match f.mode {
                FaultMode::SpeedLost => {
                    m.speed_mps = 0.0;
                    m.speed_valid = false;
                }
                FaultMode::SpeedPulsesLost => {
                    let v0 = *self.frozen[i][0].get_or_insert(m.speed_mps);
                    // The last edge came at the start; `n + 1` sample periods since.
                    let since_s = (n + 1) as f64 * 1e-3;
                    m.speed_mps = if since_s > PULSE_TIMEOUT_S {
                        0.0
                    } else {
                        v0.min((PULSE_DISTANCE_M / since_s) as f32)
                    };
                    m.speed_valid = true;
                }
                FaultMode::SpeedImplausible(v) => m.speed_mps = v as f32,
                FaultMode::FrameLoss { period, length }
                    if n % u64::from(period.max(1)) < u64::from(length) =>
                {
                    m.lost = true;
                }
                _ => {}
            }
        }
        for (j, left) in [true, false].into_iter().enumerate() {
            if status(m, left).read_ok {
                self.last_read[j] = *angle(m, left);
            }
        }
    }

    fn coil_state(&self, t_s: f64) -> CoilState {
        let mut state = CoilState::Healthy;
        for f in self.faults.iter().filter(|f| f.active(t_s)) {
            match f.mode {
                FaultMode::CoilOpen => state = CoilState::Open,
                FaultMode::CoilShort(ratio) => state = CoilState::Short { ratio },
                FaultMode::CoilIntermittent { period, length } => {
                    // Samples since the start (1 kHz grid).
                    let n = ((t_s - f.start_s) * 1e3).round().max(0.0) as u64;
                    if n % u64::from(period.max(1)) < u64::from(length) {
                        state = CoilState::Open;
                    }
                }
                _ => {}
            }
        }
        state
    }

    fn coil_sensor_error(&self, t_s: f64) -> (f64, f64) {
        let (mut gain, mut offset) = (1.0, 0.0);
        for f in self.faults.iter().filter(|f| f.active(t_s)) {
            match f.mode {
                FaultMode::CoilSensorOffset(a) => offset += a,
                FaultMode::CoilSensorGain(g) => gain *= g,
                _ => {}
            }
        }
        (gain, offset)
    }

    fn drive_condition(&self, t_s: f64) -> DriveCondition {
        let mut c = DriveCondition::default();
        for f in self.faults.iter().filter(|f| f.active(t_s)) {
            match f.mode {
                FaultMode::CoilHot(ratio) => c.r_factor = ratio,
                FaultMode::Supply(v) => c.supply_v = Some(v),
                _ => {}
            }
        }
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn meas(l: f32, r: f32) -> Measurement {
        Measurement {
            psi_l_rad: l,
            psi_r_rad: r,
            speed_mps: 20.0,
            coil_current_a: Some(1.0),
            ..Measurement::default()
        }
    }

    /// Each fault is inactive before its start and after its end, and does what the table says
    /// on the chosen encoder only.
    #[test]
    fn faults_act_in_their_interval_on_their_sensor() {
        let spec = |mode| FaultSpec {
            mode,
            start_s: 0.010,
            end_s: Some(0.020),
        };
        let cases = [
            FaultMode::Stuck(Side::Left),
            FaultMode::Noise(Side::Right, 0.1),
            FaultMode::Nan(Side::Left),
            FaultMode::Parity(Side::Right),
            FaultMode::ErrorFlag(Side::Both),
            FaultMode::Dropout {
                side: Side::Left,
                period: 4,
                length: 2,
            },
            FaultMode::Spike {
                side: Side::Right,
                period: 5,
                amplitude_rad: 0.3,
            },
            FaultMode::SpeedLost,
            FaultMode::SpeedPulsesLost,
            FaultMode::SpeedImplausible(100.0),
            FaultMode::FrameLoss {
                period: 3,
                length: 1,
            },
        ];
        for mode in cases {
            let mut p = FaultPlan::new(vec![spec(mode)], 1);
            for k in 0..30u64 {
                let t = k as f64 * 1e-3;
                let healthy = meas(0.01 * k as f32, -0.02 * k as f32);
                let mut m = healthy;
                p.apply(k, t, &mut m);
                let on = (10..20).contains(&k);
                if !on {
                    assert_eq!(m, healthy, "{mode:?} at {k}");
                    continue;
                }
                let n = k - 10;
                match mode {
                    FaultMode::Stuck(_) => {
                        assert_eq!(m.psi_l_rad, 0.01 * 10_f32);
                        assert_eq!(m.psi_r_rad, healthy.psi_r_rad);
                    }
                    FaultMode::Noise(..) => {
                        assert_ne!(m.psi_r_rad, healthy.psi_r_rad);
                        assert_eq!(m.psi_l_rad, healthy.psi_l_rad);
                    }
                    FaultMode::Nan(_) => assert!(m.psi_l_rad.is_nan() && m.psi_r_rad.is_finite()),
                    FaultMode::Parity(_) => {
                        assert!(!m.right_status.parity_ok && m.left_status.parity_ok)
                    }
                    FaultMode::ErrorFlag(_) => {
                        assert!(m.right_status.error_flag && m.left_status.error_flag)
                    }
                    FaultMode::Dropout { .. } => {
                        assert_eq!(!m.left_status.read_ok, n % 4 < 2, "{k}");
                        assert!(m.right_status.read_ok);
                    }
                    FaultMode::Spike { .. } => {
                        let d = m.psi_r_rad - healthy.psi_r_rad;
                        let want = match n {
                            0 => 0.3,
                            5 => -0.3,
                            _ => 0.0,
                        };
                        assert!((d - want).abs() < 1e-6, "{k}: {d}");
                    }
                    FaultMode::SpeedLost => assert!(!m.speed_valid && m.speed_mps == 0.0),
                    FaultMode::SpeedPulsesLost => {
                        // 20 m/s at the start; one pulse (45.8 mm) over (n + 1) ms is less
                        // from the 3rd sample on.
                        let bound = (PULSE_DISTANCE_M / ((n + 1) as f64 * 1e-3)) as f32;
                        assert_eq!(m.speed_mps, bound.min(20.0), "{k}");
                        assert!(m.speed_valid);
                    }
                    FaultMode::SpeedImplausible(_) => assert_eq!(m.speed_mps, 100.0),
                    FaultMode::FrameLoss { .. } => assert_eq!(m.lost, n % 3 == 0),
                    _ => unreachable!(),
                }
            }
        }
    }

    #[test]
    fn coil_state_follows_the_interval() {
        let p = FaultPlan::new(
            vec![
                FaultSpec::from(FaultMode::CoilOpen, 1.0),
                FaultSpec {
                    mode: FaultMode::CoilShort(5.0),
                    start_s: 0.2,
                    end_s: Some(0.5),
                },
            ],
            1,
        );
        assert_eq!(p.coil_state(0.1), CoilState::Healthy);
        assert_eq!(p.coil_state(0.3), CoilState::Short { ratio: 5.0 });
        assert_eq!(p.coil_state(0.7), CoilState::Healthy);
        assert_eq!(p.coil_state(1.5), CoilState::Open);
    }

    #[test]
    fn chattering_connector_and_drive_condition_follow_their_pattern() {
        let p = FaultPlan::new(
            vec![
                FaultSpec::from(
                    FaultMode::CoilIntermittent {
                        period: 50,
                        length: 30,
                    },
                    1.0,
                ),
                FaultSpec::from(FaultMode::CoilHot(1.5), 2.0),
                FaultSpec::from(FaultMode::Supply(14.0), 3.0),
            ],
            1,
        );
        let open: Vec<bool> = (0..100)
            .map(|k| p.coil_state(1.0 + k as f64 * 1e-3) == CoilState::Open)
            .collect();
        assert!(open[..30].iter().all(|&o| o) && open[30..50].iter().all(|&o| !o));
        assert_eq!(open.iter().filter(|&&o| o).count(), 60);
        assert_eq!(p.coil_state(0.5), CoilState::Healthy);
        assert_eq!(p.drive_condition(1.5), DriveCondition::default());
        assert_eq!(p.drive_condition(2.5).r_factor, 1.5);
        let c = p.drive_condition(3.5);
        assert_eq!((c.r_factor, c.supply_v), (1.5, Some(14.0)));
    }
}
