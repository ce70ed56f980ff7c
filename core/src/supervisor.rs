//! Supervisor: validates every raw sensor frame (1 kHz), keeps fault records, and decides the
//! damper's operating mode. [`SafeController`] combines it with the [`Controller`] so that,
//! whatever the sensors deliver, the coil command is finite, inside [i_min, i_max], and in a
//! known safe state when the inputs cannot be trusted.
//!
//! ```text
//! RawFrame --checks--> detected faults --hysteresis / latches--> active FaultSet --policy-->
//!   SupervisorVerdict { mode: Normal | Degraded | FailSafe, safe_current_a, faults }
//! SafeController: verdict + Controller::step(sanitised input) --> final clamp + slew --> I_cmd
//! ```
//!
//! # Checks (each frame)
//!
//! | fault | rule |
//! |---|---|
//! | `*Read` | the encoder transaction failed (`read_ok == false`) |
//! | `*Flag` | parity error or the sensor's own error flag (magnet field, CORDIC overflow) |
//! | `*NonFinite` | NaN or Inf angle |
//! | `*Range` | \|psi\| > `psi_limit_rad` (beyond full lock) |
//! | `*Rate` | \|psi - psi_last_good\| > `max_rate_radps` x (time since the last good sample) |
//! | `*Stuck` | bit-identical for `stuck_samples` while the *other* encoder moved > `stuck_motion_rad` |
//! | `EncoderDisagree` | both valid but \|psi_L - psi_R\| > `max_disagree_rad` |
//! | `BothStuckSuspect` | both bit-identical for `both_stuck_samples` at speed (advisory) |
//! | `SpeedInvalid` | validity flag false, NaN/Inf, < -`speed_neg_tol_mps`, > `max_speed_mps` |
//! | `SpeedJump` | \|dV\| > `max_accel_mps2` x (time since the last good speed) + `speed_noise_tol_mps` |
//! | `Timing` | time stamp gap > `max_gap_us` or not increasing (missing samples, clock fault) |
//! | `CoilOpen` | command > `coil_min_cmd_a` and measured < `coil_open_ratio` x command for `coil_fault_s` |
//! | `CoilShort` | measured > command + `coil_over_a` (or at the ADC full scale when that is above it) for `coil_fault_s` |
//! | `CoilSensor` | measured coil current NaN/Inf |
//! | `MarginUnavailable` | the margin estimate is invalid for `margin_invalid_s` (advisory) |
//!
//! Rate bound: the no-damper shimmy limit cycle of the reference plant peaks at ~7 deg at
//! ~7 Hz, i.e. ~5.4 rad/s; the default 25 rad/s also passes 0.2 rad at the 20 Hz edge of the
//! shimmy band (the 47 Hz anti-phase mode is milli-radian). A flipped high bit of a 14-bit
//! encoder (> 0.38 rad in one 1 ms sample, i.e. > 380 rad/s) is caught by a factor of 15.
//!
//! # Why the stuck check compares with the other encoder
//!
//! On a perfectly straight, smooth road a healthy wheel-yaw signal can be constant for seconds
//! (the encoder quantum, 0.38 mrad for 14 bits, is larger than the yaw motion), so "no change for
//! N samples" alone would raise false faults exactly when everything is fine. The two wheels are
//! joined by the track rod: in-phase yaw moves both encoders 1:1 and the anti-phase (track-rod
//! compliance) motion is tiny. So an encoder is declared stuck only if it stays bit-identical
//! while the *other* encoder moves by more than `stuck_motion_rad` (default 5 mrad, 13 quanta:
//! no rigid-linkage motion can show that on one wheel and nothing on the other). Both encoders
//! stuck at once cannot be told from a smooth road by comparison; a bit-identical pair for
//! `both_stuck_samples` (2 s) above `zero_current_below_mps` is therefore only *suspected*
//! (`BothStuckSuspect`): the mode goes to Degraded with the fail-safe current as a floor, which
//! is safe and costs only a stiffer damper on a mirror-smooth road.
//!
//! # Policy
//!
//! * **FailSafe** (controller output ignored, fixed current): no trustworthy wheel yaw (both
//!   encoders faulted, or they disagree), timing fault, coil fault. The current is
//!   [`FAILSAFE_CURRENT_A`] (stabilises every analysed plant variant at every speed, see
//!   `tests/tests/failsafe_current.rs`), or 0 A when the speed is trusted and below
//!   [`ZERO_CURRENT_SAFE_BELOW_MPS`] (below the lowest Hopf onset: no shimmy possible, parking
//!   stays light). A coil fault commands 0 A (driving current into a short only heats it; an
//!   open coil cannot be driven): the damper is then passive-off, and the verdict says so with
//!   `damper_available == false`.
//! * **Degraded** (controller runs, possibly with a current floor):
//!   - one encoder lost: the healthy one stands in for both. The controller acts on the
//!     in-phase yaw (psi_L + psi_R)/2, which the track rod makes equal to either wheel's yaw up
//!     to the tiny anti-phase part, so control quality is kept; but the cross-check is gone, so
//!     the command is floored at [`FAILSAFE_CURRENT_A`] (the controller can only add damping);
//!   - speed unknown: the speed gate is disabled and the floor applied (the safe current does not
//!     depend on speed);
//!   - `BothStuckSuspect`: floor;
//!   - coil-current sensor lost or margin estimate unavailable: advisory, no floor (the coil is
//!     then driven open loop; the controller does not use the margin).
//! * **Recovery with hysteresis**: a fault leaves the active set only after it has been absent
//!   for `recovery_s`. Coil open/short are latched until [`Supervisor::clear_latched`] (a burnt
//!   coil does not heal; retrying into a short is harmful). After FailSafe the controller is
//!   reset (its filters restart from the next sample).
//!
//! Time is an input: a free-running microsecond counter (`t_us`, wrapping u32; differences are
//! taken with wrapping arithmetic, so the 71.6 min wrap is harmless).

use crate::control::actuator::{CurrentLimiter, FAILSAFE_CURRENT_A};
use crate::control::{ControlInput, ControlOutput, ControlParams, Controller, ControllerKind};

/// Below this (trusted) speed 0 A is safe: 80 % of the lowest Hopf onset of every analysed
/// variant without damper (checked by `tests/tests/failsafe_current.rs`) [m/s].
pub const ZERO_CURRENT_SAFE_BELOW_MPS: f32 = 1.0;

/// Nominal sample period [us].
pub const NOMINAL_PERIOD_US: u32 = 1000;

/// Number of fault kinds.
pub const N_FAULTS: usize = 21;

/// What went wrong.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum FaultKind {
    /// Left encoder: transaction failed.
    LeftRead = 0,
    /// Left encoder: parity or sensor error flag.
    LeftFlag,
    /// Left encoder: NaN/Inf.
    LeftNonFinite,
    /// Left encoder: beyond full lock.
    LeftRange,
    /// Left encoder: faster than physically possible.
    LeftRate,
    /// Left encoder: frozen while the right one moves.
    LeftStuck,
    /// Right encoder: transaction failed.
    RightRead,
    /// Right encoder: parity or sensor error flag.
    RightFlag,
    /// Right encoder: NaN/Inf.
    RightNonFinite,
    /// Right encoder: beyond full lock.
    RightRange,
    /// Right encoder: faster than physically possible.
    RightRate,
    /// Right encoder: frozen while the left one moves.
    RightStuck,
    /// Both encoders valid but inconsistent with the track-rod linkage.
    EncoderDisagree,
    /// Both encoders bit-identical for long at speed (cannot be proven; advisory).
    BothStuckSuspect,
    /// Speed: flag, NaN/Inf, negative or too high.
    SpeedInvalid,
    /// Speed: changes faster than a vehicle can accelerate.
    SpeedJump,
    /// Missing samples or a bad time stamp.
    Timing,
    /// Coil open (measured current far below the command).
    CoilOpen,
    /// Coil short (measured current above the command).
    CoilShort,
    /// Coil-current measurement NaN/Inf.
    CoilSensor,
    /// Margin estimate unavailable for long (advisory).
    MarginUnavailable,
}

impl FaultKind {
    /// Every kind, in bit order.
    pub const ALL: [FaultKind; N_FAULTS] = [
        FaultKind::LeftRead,
        FaultKind::LeftFlag,
        FaultKind::LeftNonFinite,
        FaultKind::LeftRange,
        FaultKind::LeftRate,
        FaultKind::LeftStuck,
        FaultKind::RightRead,
        FaultKind::RightFlag,
        FaultKind::RightNonFinite,
        FaultKind::RightRange,
        FaultKind::RightRate,
        FaultKind::RightStuck,
        FaultKind::EncoderDisagree,
        FaultKind::BothStuckSuspect,
        FaultKind::SpeedInvalid,
        FaultKind::SpeedJump,
        FaultKind::Timing,
        FaultKind::CoilOpen,
        FaultKind::CoilShort,
        FaultKind::CoilSensor,
        FaultKind::MarginUnavailable,
    ];

    /// Short name for logs and tables.
    pub const fn name(self) -> &'static str {
        match self {
            FaultKind::LeftRead => "left-read",
            FaultKind::LeftFlag => "left-flag",
            FaultKind::LeftNonFinite => "left-nonfinite",
            FaultKind::LeftRange => "left-range",
            FaultKind::LeftRate => "left-rate",
            FaultKind::LeftStuck => "left-stuck",
            FaultKind::RightRead => "right-read",
            FaultKind::RightFlag => "right-flag",
            FaultKind::RightNonFinite => "right-nonfinite",
            FaultKind::RightRange => "right-range",
            FaultKind::RightRate => "right-rate",
            FaultKind::RightStuck => "right-stuck",
            FaultKind::EncoderDisagree => "encoder-disagree",
            FaultKind::BothStuckSuspect => "both-stuck-suspect",
            FaultKind::SpeedInvalid => "speed-invalid",
            FaultKind::SpeedJump => "speed-jump",
            FaultKind::Timing => "timing",
            FaultKind::CoilOpen => "coil-open",
            FaultKind::CoilShort => "coil-short",
            FaultKind::CoilSensor => "coil-sensor",
            FaultKind::MarginUnavailable => "margin-unavailable",
        }
    }

    const fn bit(self) -> u32 {
        1 << (self as u8)
    }

    /// Latched until [`Supervisor::clear_latched`].
    pub const fn latched(self) -> bool {
        matches!(self, FaultKind::CoilOpen | FaultKind::CoilShort)
    }
}

/// A set of faults (bit set over [`FaultKind`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FaultSet(u32);

const LEFT_MASK: u32 = 0b11_1111;
const RIGHT_MASK: u32 = 0b11_1111 << 6;

impl FaultSet {
    /// No fault.
    pub const EMPTY: FaultSet = FaultSet(0);

    /// Whether `k` is in the set.
    pub const fn contains(self, k: FaultKind) -> bool {
        self.0 & k.bit() != 0
    }

    /// Adds `k`.
    pub fn insert(&mut self, k: FaultKind) {
        self.0 |= k.bit();
    }

    /// Whether the set is empty.
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// The raw bits (bit i = `FaultKind::ALL[i]`).
    pub const fn bits(self) -> u32 {
        self.0
    }

    /// Number of faults in the set.
    pub const fn len(self) -> u32 {
        self.0.count_ones()
    }

    /// Any left-encoder fault.
    pub const fn left(self) -> bool {
        self.0 & LEFT_MASK != 0
    }

    /// Any right-encoder fault.
    pub const fn right(self) -> bool {
        self.0 & RIGHT_MASK != 0
    }

    /// The kinds in the set.
    pub fn iter(self) -> impl Iterator<Item = FaultKind> {
        FaultKind::ALL
            .into_iter()
            .filter(move |k| self.contains(*k))
    }
}

/// One wheel-yaw encoder reading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EncoderReading {
    /// Wheel yaw about the kingpin [rad] (already converted from counts).
    pub angle_rad: f32,
    /// The bus transaction completed (SPI/SSI frame received).
    pub read_ok: bool,
    /// The frame's parity bit matched.
    pub parity_ok: bool,
    /// The sensor's own error flag (magnetic field out of range, internal error).
    pub error_flag: bool,
}

impl EncoderReading {
    /// A healthy reading of `angle_rad`.
    pub const fn ok(angle_rad: f32) -> Self {
        EncoderReading {
            angle_rad,
            read_ok: true,
            parity_ok: true,
            error_flag: false,
        }
    }
}

/// One raw sensor frame, as delivered every 1 ms.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RawFrame {
    /// Free-running time stamp [us] (wraps).
    pub t_us: u32,
    /// Left wheel-yaw encoder.
    pub left: EncoderReading,
    /// Right wheel-yaw encoder.
    pub right: EncoderReading,
    /// Vehicle speed [m/s].
    pub speed_mps: f32,
    /// The speed source marks its value valid (e.g. CAN signal qualifier).
    pub speed_valid: bool,
    /// Measured coil current [A], if the board measures it.
    pub coil_current_a: Option<f32>,
}

impl RawFrame {
    /// A healthy frame.
    pub const fn ok(t_us: u32, psi_l_rad: f32, psi_r_rad: f32, speed_mps: f32) -> Self {
        RawFrame {
            t_us,
            left: EncoderReading::ok(psi_l_rad),
            right: EncoderReading::ok(psi_r_rad),
            speed_mps,
            speed_valid: true,
            coil_current_a: None,
        }
    }
}

/// Supervisor thresholds. `Default` is the documented design point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SupervisorParams {
    /// Encoder angles beyond +-this are invalid [rad].
    pub psi_limit_rad: f32,
    /// Largest plausible wheel-yaw rate [rad/s].
    pub max_rate_radps: f32,
    /// Largest plausible |psi_L - psi_R| [rad] (steering-geometry Ackermann difference at
    /// full lock plus compliance).
    pub max_disagree_rad: f32,
    /// Samples of bit-identical value for the single-encoder stuck check.
    pub stuck_samples: u16,
    /// Peak-to-peak motion of the other encoder that must show on a healthy one [rad].
    pub stuck_motion_rad: f32,
    /// Samples of a bit-identical pair (at speed) for `BothStuckSuspect`.
    pub both_stuck_samples: u16,
    /// Largest plausible speed [m/s].
    pub max_speed_mps: f32,
    /// Negative speed tolerated as sensor noise at standstill [m/s].
    pub speed_neg_tol_mps: f32,
    /// Largest plausible |dV/dt| [m/s^2].
    pub max_accel_mps2: f32,
    /// Sample-to-sample speed noise tolerated on top of the acceleration bound [m/s] (a
    /// wheel-speed signal read every 1 ms carries noise much larger than 1.5 g x 1 ms).
    pub speed_noise_tol_mps: f32,
    /// Largest time-stamp gap before `Timing` [us].
    pub max_gap_us: u32,
    /// Coil checks only run above this command [A].
    pub coil_min_cmd_a: f32,
    /// Open coil: measured below this fraction of the command.
    pub coil_open_ratio: f32,
    /// Short: measured above command + this [A].
    pub coil_over_a: f32,
    /// Coil mismatch must last this long [s] (>> the coil's L/R = 5 ms).
    pub coil_fault_s: f32,
    /// Full scale of the coil-current measurement [A]: a reading at or above it means "at least
    /// this much" (ADC saturated), so it counts as over-current whenever full scale is at least
    /// command plus `coil_over_a`. Without this a short at the largest command (2 A + 0.5 A =
    /// the ADC's 2.5 A) could never be seen.
    pub coil_full_scale_a: f32,
    /// Margin invalid for this long raises `MarginUnavailable` [s] (0 disables).
    pub margin_invalid_s: f32,
    /// A fault must be absent this long before it leaves the active set [s].
    pub recovery_s: f32,
    /// Fail-safe current [A].
    pub failsafe_current_a: f32,
    /// Below this trusted speed the safe current is 0 A [m/s].
    pub zero_current_below_mps: f32,
}

impl Default for SupervisorParams {
    /// psi limit 0.8 rad (as the controller); 25 rad/s (module docs); disagreement 0.25 rad
    /// (the Ackermann difference of a road vehicle at full lock is ~0.1-0.2 rad); stuck after
    /// 100 ms with 5 mrad motion on the other side; both-stuck after 2 s; 70 m/s max (the
    /// analysed range); 0.5 m/s negative tolerance; 15 m/s^2 (1.5 g) plus 0.5 m/s
    /// sample-to-sample noise (10 sigma of the simulator's 0.05 m/s wheel-speed noise; the
    /// board's tone-wheel `jump_margin_mps` is 0.5 m/s too); gap 5 ms (4 missed samples); coil
    /// checks above 0.2 A, open < 25 %, short > +0.5 A or a saturated 2.5 A reading, for 50 ms
    /// (10 L/R); margin 10 s; recovery 1 s.
    fn default() -> Self {
        SupervisorParams {
            psi_limit_rad: 0.8,
            max_rate_radps: 25.0,
            max_disagree_rad: 0.25,
            stuck_samples: 100,
            stuck_motion_rad: 5e-3,
            both_stuck_samples: 2000,
            max_speed_mps: 70.0,
            speed_neg_tol_mps: 0.5,
            max_accel_mps2: 15.0,
            speed_noise_tol_mps: 0.5,
            max_gap_us: 5000,
            coil_min_cmd_a: 0.2,
            coil_open_ratio: 0.25,
            coil_over_a: 0.5,
            coil_fault_s: 0.05,
            coil_full_scale_a: 2.5,
            margin_invalid_s: 10.0,
            recovery_s: 1.0,
            failsafe_current_a: FAILSAFE_CURRENT_A,
            zero_current_below_mps: ZERO_CURRENT_SAFE_BELOW_MPS,
        }
    }
}

/// Operating mode.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Mode {
    /// All inputs trusted: the controller's command is used.
    #[default]
    Normal,
    /// Reduced information: the controller runs, possibly with a current floor.
    Degraded,
    /// Inputs not trusted: fixed safe current, controller output ignored.
    FailSafe,
}

impl Mode {
    /// Short name.
    pub const fn name(self) -> &'static str {
        match self {
            Mode::Normal => "normal",
            Mode::Degraded => "degraded",
            Mode::FailSafe => "fail-safe",
        }
    }
}

/// The supervisor's decision for one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SupervisorVerdict {
    /// Mode.
    pub mode: Mode,
    /// FailSafe: the current to command [A]; Degraded: a floor under the controller's command
    /// (if any); Normal: `None`.
    pub safe_current_a: Option<f32>,
    /// Active faults (detected now or not yet recovered).
    pub faults: FaultSet,
    /// Faults detected in this frame.
    pub detected: FaultSet,
    /// False when the coil cannot be driven (open/short): the damper is passive-off.
    pub damper_available: bool,
}

/// Counters of one fault kind.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FaultRecord {
    /// Frames in which the fault was detected.
    pub frames: u32,
    /// Times the fault became active.
    pub activations: u32,
    /// Time stamp of the first detection [us].
    pub first_t_us: Option<u32>,
    /// Time stamp of the last detection [us].
    pub last_t_us: Option<u32>,
    /// Currently active.
    pub active: bool,
}

/// A mode change or fault (de)activation, for the log.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SupervisorEvent {
    /// A fault became active.
    Raised {
        /// Time stamp [us].
        t_us: u32,
        /// Which.
        kind: FaultKind,
    },
    /// A fault left the active set (after the recovery time).
    Cleared {
        /// Time stamp [us].
        t_us: u32,
        /// Which.
        kind: FaultKind,
    },
    /// The mode changed.
    ModeChange {
        /// Time stamp [us].
        t_us: u32,
        /// Previous mode.
        from: Mode,
        /// New mode.
        to: Mode,
    },
}

/// Capacity of the event log.
pub const EVENT_CAPACITY: usize = 32;

/// Input of the margin check: the latest margin report's validity.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MarginStatus {
    /// No margin estimator in this build / not checked.
    NotUsed,
    /// The latest [`crate::estimator::fusion::MarginReport`] is valid.
    Valid,
    /// The latest report is invalid (frozen, warming up, no mode in band).
    Invalid,
}

#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct EncoderTrack {
    last_good_rad: Option<f32>,
    last_good_t_us: u32,
    last_raw_bits: Option<u32>,
    unchanged: u16,
    other_lo_rad: f32,
    other_hi_rad: f32,
}

/// Frame validation, fault records and the mode policy.
#[derive(Clone, Debug)]
pub struct Supervisor {
    p: SupervisorParams,
    last_t_us: Option<u32>,
    enc: [EncoderTrack; 2],
    both_unchanged: u16,
    speed_last_good: Option<(f32, u32)>,
    coil_mismatch_s: [f32; 2],
    margin_invalid_s: f32,
    absent_s: [f32; N_FAULTS],
    records: [FaultRecord; N_FAULTS],
    active: FaultSet,
    mode: Mode,
    events: heapless::Deque<SupervisorEvent, EVENT_CAPACITY>,
    dropped_events: u32,
    missed_samples: u32,
    frames: u32,
}

/// `x <= bound`, false for NaN (a NaN difference fails the check).
#[inline]
fn within(x: f32, bound: f32) -> bool {
    x <= bound
}

/// |x| for the checks (NaN stays NaN and fails every `<=`).
#[inline]
fn abs(x: f32) -> f32 {
    libm::fabsf(x)
}

impl Supervisor {
    /// A supervisor with `p`.
    pub fn new(p: SupervisorParams) -> Self {
        Supervisor {
            p,
            last_t_us: None,
            enc: [EncoderTrack::default(); 2],
            both_unchanged: 0,
            speed_last_good: None,
            coil_mismatch_s: [0.0; 2],
            margin_invalid_s: 0.0,
            absent_s: [0.0; N_FAULTS],
            records: [FaultRecord::default(); N_FAULTS],
            active: FaultSet::EMPTY,
            mode: Mode::Normal,
            events: heapless::Deque::new(),
            dropped_events: 0,
            missed_samples: 0,
            frames: 0,
        }
    }

    /// The thresholds.
    pub fn params(&self) -> &SupervisorParams {
        &self.p
    }

    /// The mode of the last frame.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// Active faults.
    pub fn faults(&self) -> FaultSet {
        self.active
    }

    /// Counters of fault `k`.
    pub fn record(&self, k: FaultKind) -> FaultRecord {
        self.records.get(k as usize).copied().unwrap_or_default()
    }

    /// Frames checked.
    pub fn frames(&self) -> u32 {
        self.frames
    }

    /// Samples missing according to the time stamps (gaps of more than 1.5 periods).
    pub fn missed_samples(&self) -> u32 {
        self.missed_samples
    }

    /// The event log, oldest first (drops the oldest when full).
    pub fn events(&self) -> impl Iterator<Item = &SupervisorEvent> {
        self.events.iter()
    }

    /// Events lost to the log's capacity.
    pub fn dropped_events(&self) -> u32 {
        self.dropped_events
    }

    /// Takes the events out of the log.
    pub fn drain_events(&mut self) -> impl Iterator<Item = SupervisorEvent> + '_ {
        core::iter::from_fn(move || self.events.pop_front())
    }

    /// Clears latched faults (coil open/short): call on an ignition cycle or after service.
    pub fn clear_latched(&mut self) {
        for k in FaultKind::ALL {
            if k.latched() {
                self.active.0 &= !k.bit();
                if let Some(r) = self.records.get_mut(k as usize) {
                    r.active = false;
                }
            }
        }
        self.coil_mismatch_s = [0.0; 2];
    }

    fn log(&mut self, e: SupervisorEvent) {
        if self.events.is_full() {
            let _ = self.events.pop_front();
            self.dropped_events = self.dropped_events.saturating_add(1);
        }
        let _ = self.events.push_back(e);
    }

    /// Checks one encoder; `other` is the other encoder's raw value (for the stuck check).
    fn check_encoder(
        &mut self,
        side: usize,
        r: &EncoderReading,
        other: &EncoderReading,
        t_us: u32,
        det: &mut FaultSet,
    ) {
        let base = if side == 0 { 0u8 } else { 6u8 };
        let kind = |off: u8| FaultKind::ALL.get((base + off) as usize).copied();
        let p = self.p;
        let Some(tr) = self.enc.get_mut(side) else {
            return;
        };
        let mut bad = FaultSet::EMPTY;
        if !r.read_ok {
            bad.0 |= 1 << base;
        }
        if !r.parity_ok || r.error_flag {
            bad.0 |= 1 << (base + 1);
        }
        let x = r.angle_rad;
        if !x.is_finite() {
            bad.0 |= 1 << (base + 2);
        } else if abs(x) > p.psi_limit_rad {
            bad.0 |= 1 << (base + 3);
        }
        // Rate: against the last good sample, over the time since it (grows across gaps).
        if bad.is_empty() {
            if let Some(last) = tr.last_good_rad {
                let dt_s = t_us.wrapping_sub(tr.last_good_t_us) as f32 * 1e-6;
                if !within(abs(x - last), p.max_rate_radps * dt_s) {
                    bad.0 |= 1 << (base + 4);
                }
            }
        }
        // Stuck: bit-identical raw value while the other encoder moves (only transactions that
        // completed count; a failed read is its own fault).
        let other_x = other.angle_rad;
        if r.read_ok && x.is_finite() {
            let bits = x.to_bits();
            if tr.last_raw_bits == Some(bits) {
                tr.unchanged = tr.unchanged.saturating_add(1);
            } else {
                tr.unchanged = 0;
                tr.other_lo_rad = f32::INFINITY;
                tr.other_hi_rad = f32::NEG_INFINITY;
            }
            tr.last_raw_bits = Some(bits);
            if other.read_ok && other_x.is_finite() && abs(other_x) <= p.psi_limit_rad {
                tr.other_lo_rad = tr.other_lo_rad.min(other_x);
                tr.other_hi_rad = tr.other_hi_rad.max(other_x);
            }
            if tr.unchanged >= p.stuck_samples
                && tr.other_hi_rad - tr.other_lo_rad > p.stuck_motion_rad
            {
                bad.0 |= 1 << (base + 5);
            }
        } else {
            tr.last_raw_bits = None;
            tr.unchanged = 0;
        }
        // Only rate/stuck-free, valid samples become the rate reference.
        if bad.is_empty() {
            tr.last_good_rad = Some(x);
            tr.last_good_t_us = t_us;
        }
        for off in 0..6u8 {
            if bad.0 & (1 << (base + off)) != 0 {
                if let Some(k) = kind(off) {
                    det.insert(k);
                }
            }
        }
    }

    fn check_speed(&mut self, f: &RawFrame, det: &mut FaultSet) -> Option<f32> {
        let v = f.speed_mps;
        let p = self.p;
        if !f.speed_valid || !v.is_finite() || v < -p.speed_neg_tol_mps || v > p.max_speed_mps {
            det.insert(FaultKind::SpeedInvalid);
            return None;
        }
        if let Some((last, t_last)) = self.speed_last_good {
            let dt_s = f.t_us.wrapping_sub(t_last) as f32 * 1e-6;
            // One extra sample period of slack: speed signals are often held between updates.
            let bound = p.max_accel_mps2 * (dt_s + 1e-3) + p.speed_noise_tol_mps;
            if !within(abs(v - last), bound) {
                det.insert(FaultKind::SpeedJump);
                return None;
            }
        }
        self.speed_last_good = Some((v, f.t_us));
        Some(v)
    }

    /// Coil check against the command of the previous step `last_cmd_a`.
    fn check_coil(&mut self, f: &RawFrame, last_cmd_a: f32, dt_s: f32, det: &mut FaultSet) {
        let Some(i_meas) = f.coil_current_a else {
            self.coil_mismatch_s = [0.0; 2];
            return;
        };
        if !i_meas.is_finite() {
            det.insert(FaultKind::CoilSensor);
            return;
        }
        let p = self.p;
        let open = last_cmd_a > p.coil_min_cmd_a && i_meas < p.coil_open_ratio * last_cmd_a;
        let over_a = last_cmd_a + p.coil_over_a;
        let short =
            i_meas > over_a || (i_meas >= p.coil_full_scale_a && p.coil_full_scale_a >= over_a);
        for (acc, cond) in self.coil_mismatch_s.iter_mut().zip([open, short]) {
            *acc = if cond { (*acc + dt_s).min(1e3) } else { 0.0 };
        }
        if self.coil_mismatch_s[0] >= p.coil_fault_s {
            det.insert(FaultKind::CoilOpen);
        }
        if self.coil_mismatch_s[1] >= p.coil_fault_s {
            det.insert(FaultKind::CoilShort);
        }
    }

    /// Validates one frame. `last_cmd_a` is the coil command applied since the previous frame
    /// (for the coil checks); `margin` the latest margin validity. Returns the verdict and the
    /// validated inputs.
    pub fn check(
        &mut self,
        f: &RawFrame,
        last_cmd_a: f32,
        margin: MarginStatus,
    ) -> (SupervisorVerdict, Validated) {
        let p = self.p;
        self.frames = self.frames.saturating_add(1);
        let mut det = FaultSet::EMPTY;
        // Timing.
        let period_s = NOMINAL_PERIOD_US as f32 * 1e-6;
        let dt_s = match self.last_t_us {
            None => period_s,
            Some(last) => {
                let gap = f.t_us.wrapping_sub(last);
                if gap == 0 || gap > p.max_gap_us {
                    det.insert(FaultKind::Timing);
                }
                if gap > NOMINAL_PERIOD_US + NOMINAL_PERIOD_US / 2 {
                    let missed = gap.saturating_add(NOMINAL_PERIOD_US / 2) / NOMINAL_PERIOD_US;
                    self.missed_samples =
                        self.missed_samples.saturating_add(missed.saturating_sub(1));
                }
                if gap == 0 || gap > p.max_gap_us {
                    period_s
                } else {
                    gap as f32 * 1e-6
                }
            }
        };
        self.last_t_us = Some(f.t_us);
        // Encoders.
        self.check_encoder(0, &f.left, &f.right, f.t_us, &mut det);
        self.check_encoder(1, &f.right, &f.left, f.t_us, &mut det);
        let l_ok = !det.left();
        let r_ok = !det.right();
        if l_ok
            && r_ok
            && !within(
                abs(f.left.angle_rad - f.right.angle_rad),
                p.max_disagree_rad,
            )
        {
            det.insert(FaultKind::EncoderDisagree);
        }
        // Speed.
        let speed = self.check_speed(f, &mut det);
        // Both encoders frozen at speed (advisory).
        let both_frozen = self.enc.iter().all(|e| e.unchanged > 0);
        let at_speed = speed.is_none_or(|v| v >= p.zero_current_below_mps);
        self.both_unchanged = if both_frozen && at_speed {
            self.both_unchanged.saturating_add(1)
        } else {
            0
        };
        if self.both_unchanged >= p.both_stuck_samples {
            det.insert(FaultKind::BothStuckSuspect);
        }
        // Coil.
        self.check_coil(f, last_cmd_a, dt_s, &mut det);
        // Margin estimate.
        match margin {
            MarginStatus::Invalid if p.margin_invalid_s > 0.0 => {
                self.margin_invalid_s = (self.margin_invalid_s + dt_s).min(1e6);
                if self.margin_invalid_s >= p.margin_invalid_s {
                    det.insert(FaultKind::MarginUnavailable);
                }
            }
            _ => self.margin_invalid_s = 0.0,
        }
        self.update_active(det, f.t_us, dt_s);
        let verdict = self.policy(det, speed);
        if verdict.mode != self.mode {
            log_warn!(
                "supervisor: mode {} -> {}",
                self.mode.name(),
                verdict.mode.name()
            );
            self.log(SupervisorEvent::ModeChange {
                t_us: f.t_us,
                from: self.mode,
                to: verdict.mode,
            });
            self.mode = verdict.mode;
        }
        let a = self.active;
        let left = (!a.left()).then_some(f.left.angle_rad);
        let right = (!a.right()).then_some(f.right.angle_rad);
        let (psi_l, psi_r) = match (left, right) {
            (Some(l), Some(r)) if !a.contains(FaultKind::EncoderDisagree) => (Some(l), Some(r)),
            (Some(l), None) => (Some(l), Some(l)),
            (None, Some(r)) => (Some(r), Some(r)),
            _ => (None, None),
        };
        let angles = match (psi_l, psi_r) {
            (Some(l), Some(r)) if verdict.mode != Mode::FailSafe => Some((l, r)),
            _ => None,
        };
        let validated = Validated {
            t_s: f.t_us as f32 * 1e-6,
            dt_s,
            angles_rad: angles,
            speed_mps: if a.contains(FaultKind::SpeedInvalid) || a.contains(FaultKind::SpeedJump) {
                None
            } else {
                speed
            },
            coil_current_a: if a.contains(FaultKind::CoilSensor) {
                None
            } else {
                f.coil_current_a.filter(|i| i.is_finite())
            },
        };
        (verdict, validated)
    }

    fn update_active(&mut self, det: FaultSet, t_us: u32, dt_s: f32) {
        let recovery = self.p.recovery_s;
        for (i, k) in FaultKind::ALL.into_iter().enumerate() {
            let (Some(rec), Some(absent)) = (self.records.get_mut(i), self.absent_s.get_mut(i))
            else {
                continue;
            };
            let was = self.active.contains(k);
            if det.contains(k) {
                rec.frames = rec.frames.saturating_add(1);
                rec.first_t_us.get_or_insert(t_us);
                rec.last_t_us = Some(t_us);
                *absent = 0.0;
                if !was {
                    rec.activations = rec.activations.saturating_add(1);
                    rec.active = true;
                    self.active.insert(k);
                    log_warn!("supervisor: fault {} raised", k.name());
                    self.log(SupervisorEvent::Raised { t_us, kind: k });
                }
            } else if was && !k.latched() {
                *absent = (*absent + dt_s).min(1e6);
                if *absent >= recovery {
                    rec.active = false;
                    self.active.0 &= !k.bit();
                    log_info!("supervisor: fault {} cleared", k.name());
                    self.log(SupervisorEvent::Cleared { t_us, kind: k });
                }
            }
        }
    }

    fn policy(&self, det: FaultSet, speed: Option<f32>) -> SupervisorVerdict {
        let a = self.active;
        let p = self.p;
        let coil_dead = a.contains(FaultKind::CoilOpen) || a.contains(FaultKind::CoilShort);
        let speed_trusted = speed.is_some()
            && !a.contains(FaultKind::SpeedInvalid)
            && !a.contains(FaultKind::SpeedJump);
        let fixed = match speed {
            Some(v) if speed_trusted && v < p.zero_current_below_mps => 0.0,
            _ => p.failsafe_current_a,
        };
        let no_yaw = (a.left() && a.right()) || a.contains(FaultKind::EncoderDisagree);
        let fail = no_yaw || a.contains(FaultKind::Timing) || coil_dead;
        let (mode, safe) = if coil_dead {
            (Mode::FailSafe, Some(0.0))
        } else if fail {
            (Mode::FailSafe, Some(fixed))
        } else {
            let floor =
                a.left() || a.right() || !speed_trusted || a.contains(FaultKind::BothStuckSuspect);
            let advisory =
                a.contains(FaultKind::CoilSensor) || a.contains(FaultKind::MarginUnavailable);
            if floor {
                (Mode::Degraded, Some(fixed))
            } else if advisory {
                (Mode::Degraded, None)
            } else {
                (Mode::Normal, None)
            }
        };
        SupervisorVerdict {
            mode,
            safe_current_a: safe,
            faults: a,
            detected: det,
            damper_available: !coil_dead,
        }
    }
}

/// Inputs after validation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Validated {
    /// Time [s] (wraps with the us counter; for logs).
    pub t_s: f32,
    /// Time since the previous frame [s] (the nominal period after a timing fault).
    pub dt_s: f32,
    /// Wheel yaw (left, right) [rad] to control on: both encoders, or the healthy one twice;
    /// `None` in FailSafe.
    pub angles_rad: Option<(f32, f32)>,
    /// Trusted speed [m/s].
    pub speed_mps: Option<f32>,
    /// Trusted coil current [A].
    pub coil_current_a: Option<f32>,
}

/// Output of one [`SafeController::step`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SafeOutput {
    /// Coil-current command [A]: finite, in [i_min, i_max] of the controller's limits.
    pub current_cmd_a: f32,
    /// The supervisor's verdict.
    pub verdict: SupervisorVerdict,
    /// Validated inputs.
    pub validated: Validated,
    /// The controller's output, if it ran this step.
    pub control: Option<ControlOutput>,
}

/// Supervisor + controller + final limiter: the one call the firmware and the simulator make
/// every 1 ms.
#[derive(Clone, Debug)]
pub struct SafeController {
    sup: Supervisor,
    ctl: Controller,
    out: CurrentLimiter,
    last_mode: Mode,
}

impl SafeController {
    /// A controller of `kind` with `params`, supervised with `sup`.
    pub fn new(kind: ControllerKind, params: ControlParams, sup: SupervisorParams) -> Self {
        SafeController {
            sup: Supervisor::new(sup),
            ctl: Controller::new(kind, params),
            out: CurrentLimiter::new(params.limits),
            last_mode: Mode::Normal,
        }
    }

    /// The supervisor.
    pub fn supervisor(&self) -> &Supervisor {
        &self.sup
    }

    /// The supervisor, mutable (e.g. [`Supervisor::clear_latched`]).
    pub fn supervisor_mut(&mut self) -> &mut Supervisor {
        &mut self.sup
    }

    /// The controller.
    pub fn controller(&self) -> &Controller {
        &self.ctl
    }

    /// The controller, mutable (e.g. `set_kind`).
    pub fn controller_mut(&mut self) -> &mut Controller {
        &mut self.ctl
    }

    /// The last coil command [A].
    pub fn last_command_a(&self) -> f32 {
        self.out.last()
    }

    /// One step: validate `frame`, run the controller on the validated inputs unless in
    /// FailSafe, apply the verdict, limit. `margin` is the validity of the latest margin report.
    pub fn step(&mut self, frame: &RawFrame, margin: MarginStatus) -> SafeOutput {
        let last_cmd = self.out.last();
        let (verdict, v) = self.sup.check(frame, last_cmd, margin);
        if self.last_mode == Mode::FailSafe && verdict.mode != Mode::FailSafe {
            // Filters hold pre-fault data: restart them.
            self.ctl.reset();
        }
        self.last_mode = verdict.mode;
        let (target, control) = match (verdict.mode, v.angles_rad) {
            (Mode::FailSafe, _) | (_, None) => (
                verdict
                    .safe_current_a
                    .unwrap_or(self.sup.p.failsafe_current_a),
                None,
            ),
            (_, Some((l, r))) => {
                let c = self.ctl.step(&ControlInput {
                    t_s: v.t_s,
                    dt_s: v.dt_s,
                    psi_l_rad: l,
                    psi_r_rad: r,
                    // Unknown speed: do not gate (f32::MAX is above any gate).
                    speed_mps: v.speed_mps.unwrap_or(f32::MAX),
                    coil_current_a: v.coil_current_a,
                });
                let floor = verdict.safe_current_a.unwrap_or(0.0);
                (c.current_cmd_a.max(floor), Some(c))
            }
        };
        // Final clamp (NaN -> i_min) and slew limit: the output contract holds whatever
        // happened above.
        let lim = self.out.apply(target, v.dt_s);
        SafeOutput {
            current_cmd_a: lim.current_a,
            verdict,
            validated: v,
            control,
        }
    }

    /// The validated sample to feed the margin estimator, if the wheel yaw is trusted.
    pub fn estimator_sample(
        out: &SafeOutput,
        wheel: crate::estimator::meter::mode_meter::WheelOrder,
    ) -> Option<crate::estimator::meter::mode_meter::Sample> {
        out.validated
            .angles_rad
            .map(|(l, r)| crate::estimator::meter::mode_meter::Sample {
                psi_l_rad: l,
                psi_r_rad: r,
                wheel,
                damper_cmd: out.current_cmd_a,
            })
    }
}

#[cfg(test)]
mod tests;
