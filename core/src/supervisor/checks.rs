//! The [`Supervisor`]: per-frame checks, fault hysteresis and latches, fault records and the
//! event log; each frame ends with the verdict of [`super::policy`].
//!
//! # Checks (each frame)
//!
//!
//! | fault | rule |
//! |---|---|
//! | `*Read` | the encoder transaction failed (`read_ok == false`) |
//! | `*Flag` | parity error or the sensor's own error flag (magnet field, CORDIC overflow) |
//! | `*NonFinite` | NaN or Inf angle |
//! | `*Range` | \|psi\| > `psi_limit_rad` (beyond full lock) |
//! | `*Rate` | \|psi - psi_last_good\| > `max_rate_radps` x (time since the last good sample) |
//! | `*Stuck` | bit-identical for `stuck_samples` while the *other* encoder moved > `stuck_motion_rad`, or at all when the encoders dither (`encoder_noise_lsb` >= `DITHER_MIN_LSB`) |
//! | `EncoderDisagree` | both valid but \|psi_L - psi_R\| > `max_disagree_rad` |
//! | `BothStuckSuspect` | both bit-identical for `both_stuck_samples` at speed, or for `pair_freeze_s` when they froze while the wheels oscillated in the shimmy band (advisory) |
//! | `SpeedInvalid` | validity flag false, NaN/Inf, < -`speed_neg_tol_mps`, > `max_speed_mps` |
//! | `SpeedJump` | \|dV\| > `max_accel_mps2` x (time since the last good speed) + `speed_noise_tol_mps` |
//! | `SpeedLowImplausible` | V < `speed_low_mps` and V < the deceleration envelope of the trusted speeds (each decays at `max_accel_mps2`) - `speed_noise_tol_mps`, (held while V < `speed_low_mps`), or V < `speed_low_mps` while the wheels oscillate in the shimmy band and V is either below `zero_current_below_mps` or unchanged for `stuck_samples` (then a held speed below the gate is not used either: the speed is unknown; held while V < `speed_low_mps`) |
//! | `Timing` | time stamp gap > `max_gap_us` or not increasing (missing samples, clock fault) |
//! | `CoilOpen` | expected current (the drive, `RawFrame::coil_drive_a` or else the command, through the coil's L/R `coil_tau_s`) and the drive both > `coil_min_expected_a`, and measured < `coil_open_ratio` x expected, for `coil_fault_s` of accumulated mismatch (drains at `coil_heal_ratio` while it matches) |
//! | `CoilShort` | drive and expected >= `coil_short_min_a` and measured > `coil_short_ratio` x expected (a reading at the ADC's `coil_full_scale_a` proves it only where that is above the ratio), accumulated the same way |
//! | `CoilSensor` | measured NaN/Inf; or, accumulated the same way: measured > expected + `coil_sensor_zero_a` with no drive (drive <= `coil_no_drive_a`, expected <= `coil_no_drive_check_a`), measured < -`coil_sensor_zero_a`, or (checkable as for open) measured outside [`coil_sensor_lo`, `coil_sensor_hi`] x expected (above it only below full scale) and neither open nor short |
//! | `MarginUnavailable` | the margin estimate is invalid for `margin_invalid_s` (advisory) |
//!
//! Coil sensor or coil: the drive and the measured current are the coil's voltage-current
//! relation. No coil fault makes current flow without drive, a hot or cold coil stays within
//! the ratio band, and only a path around the coil carries three times what the drive pushes
//! through it; a sensor's offset or gain error shows as a reading at zero drive or outside the
//! band. `CoilSensor` is latched and the coil driven open loop (the policy keeps the damper);
//! the open and short checks go on with the drive's model, so a short the current loop hid
//! (it lowers the duty until the reading matches) is found once the loop is open.
//!
//! Latent coil faults: after `coil_test_idle_s` without `coil_fault_s` of open checks in a row
//! (little current demanded, or only single-sample spikes of a chattering command) the verdict
//! asks for a test pulse of `coil_test_current_a` for `coil_test_pulse_s`.
//!
//! Intermittent faults: the `intermittent_count`-th activation of a fault within
//! `intermittent_window_s` of the first latches it (`SupervisorEvent::Latched`, until
//! [`Supervisor::clear_latched`]), so a recurring glitch does not toggle the mode forever.
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
//! is safe and costs only a stiffer damper on a mirror-smooth road. A pair that freezes in the
//! middle of a shimmy-band oscillation is suspected much sooner (`pair_freeze_s`, half a period
//! of the band's lower edge): an oscillating wheel cannot come to rest that fast, and waiting
//! 2 s lets shimmy grow on an unstable vehicle.

use super::faults::{FaultKind, FaultRecord, FaultSet, N_FAULTS};
use super::frame::{EncoderReading, MarginStatus, RawFrame, NOMINAL_PERIOD_US};
use super::motion::YawOscillation;
use super::params::SupervisorParams;
use super::policy::{decide, Mode, SpeedUse, SupervisorVerdict};

/// A mode change or fault (de)activation, for the log.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SupervisorEvent {
    /// A fault became active.
    Raised {
        /// Time stamp, us.
        t_us: u32,
        /// Which.
        kind: FaultKind,
    },
    /// A fault recurred often enough to be latched (intermittent).
    Latched {
        /// Time stamp, us.
        t_us: u32,
        /// Which.
        kind: FaultKind,
    },
    /// A fault left the active set (after the recovery time).
    Cleared {
        /// Time stamp, us.
        t_us: u32,
        /// Which.
        kind: FaultKind,
    },
    /// The mode changed.
    ModeChange {
        /// Time stamp, us.
        t_us: u32,
        /// Previous mode.
        from: Mode,
        /// New mode.
        to: Mode,
    },
}

/// Capacity of the event log.
pub const EVENT_CAPACITY: usize = 32;

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
    motion: YawOscillation,
    /// Both encoders froze while the wheels oscillated (captured when the freeze began).
    pair_froze_moving: bool,
    speed_last_good: Option<(f32, u32)>,
    speed_floor: (f32, u32),
    speed_suspect: bool,
    /// The low speed reading is contradicted by the wheels' oscillation: no speed below the
    /// gate is trusted (not even a held one) until the reading is back above the gate (still
    /// wheels prove nothing once the fail-safe floor damps them).
    speed_contradicted: bool,
    /// The last speed reading's bits and how many frames in a row it has not changed.
    speed_bits: Option<u32>,
    speed_same: u16,
    speed_trusted: Option<(f32, u32)>,
    coil_expected_a: f32,
    coil_mismatch_s: [f32; 3],
    coil_idle_s: f32,
    /// Time the coil checks have run without a break, s.
    coil_checked_s: f32,
    coil_pulse_left_s: f32,
    margin_invalid_s: f32,
    absent_s: [f32; N_FAULTS],
    /// Per kind: time stamp of the first activation in the current recurrence window and the
    /// activations since.
    recurrences: [(u32, u8); N_FAULTS],
    records: [FaultRecord; N_FAULTS],
    active: FaultSet,
    escalated: FaultSet,
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

/// A coil-mismatch accumulator: grows by `dt_s` while `cond` holds, drains by `heal_s` while
/// `judged` and not `cond`, held otherwise (and reset if it ever became non-finite).
#[inline(always)]
fn accumulate(acc: &mut f32, cond: bool, judged: bool, dt_s: f32, heal_s: f32) {
    if cond {
        *acc = (*acc + dt_s).min(1e3);
    } else if judged {
        *acc = (*acc - heal_s).max(0.0);
    }
    if !acc.is_finite() {
        *acc = 0.0;
    }
}

/// Seconds from time stamp `earlier_us` to `now_us` (wrapping: right across the u32 wrap).
#[inline]
fn seconds_since(now_us: u32, earlier_us: u32) -> f32 {
    now_us.wrapping_sub(earlier_us) as f32 * 1e-6
}

/// A frame interval usable in the coil lag: NaN or negative -> 0, at most 1 s.
#[inline]
fn clamp_dt(dt_s: f32) -> f32 {
    if dt_s > 0.0 {
        dt_s.min(1.0)
    } else {
        0.0
    }
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
            motion: YawOscillation::default(),
            pair_froze_moving: false,
            speed_last_good: None,
            speed_floor: (0.0, 0),
            speed_suspect: false,
            speed_contradicted: false,
            speed_bits: None,
            speed_same: 0,
            speed_trusted: None,
            coil_expected_a: 0.0,
            coil_mismatch_s: [0.0; 3],
            coil_idle_s: 0.0,
            coil_checked_s: 0.0,
            coil_pulse_left_s: 0.0,
            margin_invalid_s: 0.0,
            absent_s: [0.0; N_FAULTS],
            recurrences: [(0, 0); N_FAULTS],
            records: [FaultRecord::default(); N_FAULTS],
            active: FaultSet::EMPTY,
            escalated: FaultSet::EMPTY,
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

    /// Faults latched because they recurred ([`SupervisorParams::intermittent_count`] times
    /// within the window); they stay active until [`Supervisor::clear_latched`].
    pub fn escalated(&self) -> FaultSet {
        self.escalated
    }

    /// Active faults that only [`Supervisor::clear_latched`] removes: coil open/short and the
    /// escalated intermittent faults.
    pub fn latched(&self) -> FaultSet {
        let mut l = self.escalated;
        for k in self.active.iter().filter(|k| k.latched()) {
            l.insert(k);
        }
        l
    }

    /// Restores latched faults remembered across a reset (see [`Supervisor::latched`]): they
    /// are active from the first frame on and stay until [`Supervisor::clear_latched`]. Kinds
    /// that neither latch nor escalate are ignored.
    pub fn restore_latched(&mut self, set: FaultSet) {
        for k in set.iter() {
            if !(k.latched() || k.escalates()) || self.active.contains(k) {
                continue;
            }
            if !k.latched() {
                self.escalated.insert(k);
            }
            self.active.insert(k);
            if let Some(r) = self.records.get_mut(k as usize) {
                r.active = true;
                r.activations = r.activations.saturating_add(1);
            }
            self.log(SupervisorEvent::Latched { t_us: 0, kind: k });
        }
    }

    /// Clears latched faults (coil open/short, escalated intermittent faults) and the
    /// recurrence counts: call on an ignition cycle or after service.
    pub fn clear_latched(&mut self) {
        for k in FaultKind::ALL {
            if k.latched() || self.escalated.contains(k) {
                self.active.0 &= !k.bit();
                if let Some(r) = self.records.get_mut(k as usize) {
                    r.active = false;
                }
            }
        }
        self.escalated = FaultSet::EMPTY;
        self.recurrences = [(0, 0); N_FAULTS];
        self.coil_mismatch_s = [0.0; 3];
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
                let dt_s = seconds_since(t_us, tr.last_good_t_us);
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
                && (p.encoders_dither() || tr.other_hi_rad - tr.other_lo_rad > p.stuck_motion_rad)
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

    /// `moving`: the wheels oscillate in the shimmy band (the vehicle rolls).
    fn check_speed(&mut self, f: &RawFrame, moving: bool, det: &mut FaultSet) -> Option<f32> {
        let v = f.speed_mps;
        let p = self.p;
        if !f.speed_valid || !v.is_finite() || v < -p.speed_neg_tol_mps || v > p.max_speed_mps {
            det.insert(FaultKind::SpeedInvalid);
        } else {
            // Low-speed plausibility: the lowest speed the vehicle can have now is the
            // deceleration envelope of the trusted speeds (`max_accel_mps2` from each). A reading
            // below the controller's gate and below the envelope came faster than braking allows
            // (lost pulse train, frozen value); once seen, it stays suspect (time alone does not
            // make it plausible) until the reading is back at or above `speed_low_mps`.
            // A low reading while the wheels oscillate in the shimmy band is contradicted
            // whatever the history (a sensor lost or frozen before the vehicle set off) when
            // it says standstill (below `zero_current_below_mps` no analysed vehicle can
            // shimmy) or has not changed for `stuck_samples` (a frozen value: a rolling wheel's
            // reading moves); between the two a slowly rolling vehicle near its onset may
            // oscillate (the `hard` set's onset is 7.6 km/h, above the 7.2 km/h gate).
            let bits = v.to_bits();
            self.speed_same = if self.speed_bits == Some(bits) {
                self.speed_same.saturating_add(1)
            } else {
                0
            };
            self.speed_bits = Some(bits);
            let implausible_low =
                v < p.zero_current_below_mps || self.speed_same >= p.stuck_samples;
            if v < p.speed_low_mps && moving && implausible_low {
                self.speed_contradicted = true;
            } else if v >= p.speed_low_mps {
                self.speed_contradicted = false;
            }
            if v < p.speed_low_mps && v < self.speed_floor_at(f.t_us) - p.speed_noise_tol_mps {
                self.speed_suspect = true;
            } else if v >= p.speed_low_mps {
                self.speed_suspect = false;
            }
            if self.speed_suspect || self.speed_contradicted {
                det.insert(FaultKind::SpeedLowImplausible);
            }
            if let Some((last, t_last)) = self.speed_last_good {
                let dt_s = seconds_since(f.t_us, t_last);
                // One extra sample period of slack: speed signals are often held between updates.
                let bound = p.max_accel_mps2 * (dt_s + 1e-3) + p.speed_noise_tol_mps;
                if !within(abs(v - last), bound) {
                    det.insert(FaultKind::SpeedJump);
                }
            }
            if !det.contains(FaultKind::SpeedJump) {
                self.speed_last_good = Some((v, f.t_us));
            }
        }
        if det.speed() {
            return None;
        }
        if v >= self.speed_floor_at(f.t_us) {
            self.speed_floor = (v, f.t_us);
        }
        self.speed_trusted = Some((v, f.t_us));
        Some(v)
    }

    /// The deceleration envelope of the trusted speeds at `t_us`, m/s (>= 0).
    fn speed_floor_at(&mut self, t_us: u32) -> f32 {
        let (v0, t0) = self.speed_floor;
        let floor = v0 - self.p.max_accel_mps2 * seconds_since(t_us, t0);
        if floor > 0.0 {
            floor
        } else {
            // Reached zero: restart from here (keeps the time difference far from the wrap).
            self.speed_floor = (0.0, t_us);
            0.0
        }
    }

    /// The speed to use while the speed is untrusted: the last trusted one, for `speed_hold_s`.
    fn held_speed(&self, t_us: u32) -> Option<f32> {
        let (v, t) = self.speed_trusted?;
        within(seconds_since(t_us, t), self.p.speed_hold_s).then_some(v)
    }

    /// Coil checks: the measured current against the drive of the previous step (the frame's
    /// `coil_drive_a`, else the command `last_cmd_a`) passed through the coil's lag (the
    /// expected current); schedules the test pulse while no check can run.
    fn check_coil(&mut self, f: &RawFrame, last_cmd_a: f32, dt_s: f32, det: &mut FaultSet) {
        let p = &self.p;
        let drive = match f.coil_drive_a {
            Some(d) if d.is_finite() => d,
            _ => last_cmd_a,
        };
        // The current the coil should carry now: first-order lag of the drive (backward
        // Euler, no `expf`: lags the true coil by a fraction of a sample, which only makes the
        // check more tolerant; a NaN or negative dt holds it).
        let dt = clamp_dt(dt_s);
        let alpha = dt / (p.coil_tau_s + dt);
        // The gap to the drive decays; below 1 uA it is closed, so a steady drive is reached
        // exactly (f32 rounding would otherwise stall a few ulps short of it).
        let gap = (1.0 - alpha) * (drive - self.coil_expected_a);
        let expected = if abs(gap) < 1e-6 { drive } else { drive - gap };
        self.coil_expected_a = if expected.is_finite() { expected } else { 0.0 };
        let Some(i_meas) = f.coil_current_a else {
            self.coil_mismatch_s = [0.0; 3];
            self.coil_idle_s = 0.0;
            self.coil_pulse_left_s = 0.0;
            return;
        };
        if !i_meas.is_finite() {
            det.insert(FaultKind::CoilSensor);
            self.coil_idle_s = 0.0;
            self.coil_pulse_left_s = 0.0;
            return;
        }
        let e = self.coil_expected_a;
        let heal = dt_s * p.coil_heal_ratio;
        let [acc_open, acc_short, acc_sensor] = &mut self.coil_mismatch_s;
        // Each accumulator grows while its condition holds and drains only while it is
        // judged and does not hold. A negative reading is the sensor's whatever the drive
        // (the driver is unidirectional).
        let negative = i_meas < -p.coil_sensor_zero_a;
        // Open and the sensor's ratio band are judged while the coil should carry current and
        // the drive still pushes it: on a falling drive a current that falls faster than the
        // coil's lag is a short's signature (no inductance in the path), not an open coil's.
        let checkable = e > p.coil_min_expected_a && drive > p.coil_min_expected_a;
        if drive <= p.coil_no_drive_a {
            // No drive: open and short are not judged. A reading above the decaying coil
            // current is the sensor's (no coil fault makes current flow without voltage),
            // judged once that current is small enough for the nominal L/R to predict it.
            let no_drive = e <= p.coil_no_drive_check_a;
            let sensor = (no_drive && i_meas > e + p.coil_sensor_zero_a) || negative;
            accumulate(acc_sensor, sensor, no_drive || negative, dt_s, heal);
        } else {
            let open = checkable && i_meas < p.coil_open_ratio * e;
            // Short: far more current than the drive can push through the coil (a path around
            // it); judged while the drive and the expected current are at least
            // `coil_short_min_a` (below it a sensor offset could pass for one), and not on a
            // saturated reading that cannot prove the ratio.
            let short_judged = e >= p.coil_short_min_a
                && drive >= p.coil_short_min_a
                && (i_meas < p.coil_full_scale_a || p.coil_full_scale_a > p.coil_short_ratio * e);
            let short = short_judged && i_meas > p.coil_short_ratio * e;
            // The sensor: a reading outside the band that the coil's resistance over
            // temperature allows (above it only when not saturated: a saturated reading may
            // be a short's).
            let sensor = negative
                || (checkable
                    && !open
                    && !short
                    && (i_meas < p.coil_sensor_lo * e
                        || (i_meas > p.coil_sensor_hi * e && i_meas < p.coil_full_scale_a)));
            accumulate(acc_open, open, checkable, dt_s, heal);
            accumulate(acc_short, short, short_judged, dt_s, heal);
            accumulate(acc_sensor, sensor, checkable || negative, dt_s, heal);
        }
        if *acc_open >= p.coil_fault_s {
            det.insert(FaultKind::CoilOpen);
        }
        if *acc_short >= p.coil_fault_s {
            det.insert(FaultKind::CoilShort);
        }
        if *acc_sensor >= p.coil_fault_s {
            det.insert(FaultKind::CoilSensor);
        }
        // Test pulse: after `coil_test_idle_s` without an open check (and never into a coil
        // already found dead).
        let dead =
            self.active.contains(FaultKind::CoilOpen) || self.active.contains(FaultKind::CoilShort);
        // Only `coil_fault_s` of checks in a row count as a check: single-sample command spikes
        // (a chattering controller) must not postpone the pulse forever.
        if checkable {
            self.coil_checked_s += dt_s;
        } else {
            self.coil_checked_s = 0.0;
        }
        if self.coil_checked_s >= p.coil_fault_s {
            self.coil_idle_s = 0.0;
            self.coil_checked_s = 0.0;
        } else {
            self.coil_idle_s = (self.coil_idle_s + dt_s).min(1e6);
        }
        if self.coil_pulse_left_s > 0.0 {
            self.coil_pulse_left_s -= dt_s;
        } else if !dead && p.coil_test_current_a > 0.0 && self.coil_idle_s >= p.coil_test_idle_s {
            self.coil_pulse_left_s = p.coil_test_pulse_s;
            self.coil_idle_s = 0.0;
            self.coil_checked_s = 0.0;
        }
        if dead || !self.coil_pulse_left_s.is_finite() {
            self.coil_pulse_left_s = 0.0;
        }
    }

    /// The expected coil current (the applied command through the coil's lag), A.
    pub fn coil_expected_a(&self) -> f32 {
        self.coil_expected_a
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
        // Motion evidence: the in-phase yaw of the encoders that passed their checks.
        let in_phase = match (
            l_ok.then_some(f.left.angle_rad),
            r_ok.then_some(f.right.angle_rad),
        ) {
            (Some(l), Some(r)) => Some(0.5 * (l + r)),
            (one, other) => one.or(other),
        };
        self.motion.update(in_phase, dt_s, &p);
        let moving = self.motion.oscillating(&p);
        // Speed.
        let speed = self.check_speed(f, moving, &mut det);
        // Both encoders frozen at speed (advisory): after `both_stuck_samples`, or after
        // `pair_freeze_s` when they froze in the middle of an oscillation.
        let both_frozen = self.enc.iter().all(|e| e.unchanged > 0);
        let at_speed = speed.is_none_or(|v| v >= p.zero_current_below_mps);
        self.both_unchanged = if both_frozen && at_speed {
            self.both_unchanged.saturating_add(1)
        } else {
            0
        };
        if self.both_unchanged == 1 {
            self.pair_froze_moving = moving;
        }
        let frozen_s = f32::from(self.both_unchanged) * period_s;
        if self.both_unchanged >= p.both_stuck_samples
            || (self.pair_froze_moving && frozen_s >= p.pair_freeze_s())
        {
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
        let speed_use = match speed {
            Some(v) if !self.active.speed() => SpeedUse::Trusted(v),
            // A held speed below the gate is as contradicted as the reading.
            _ if self.speed_contradicted => self
                .held_speed(f.t_us)
                .filter(|&v| v >= p.speed_low_mps)
                .map_or(SpeedUse::Unknown, SpeedUse::Held),
            _ => self
                .held_speed(f.t_us)
                .map_or(SpeedUse::Unknown, SpeedUse::Held),
        };
        let mut verdict = decide(self.active, det, speed_use, &self.p);
        if self.coil_pulse_left_s > 0.0 && verdict.damper_available {
            verdict.test_current_a = Some(p.coil_test_current_a);
        }
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
            speed_mps: match speed_use {
                SpeedUse::Trusted(v) | SpeedUse::Held(v) => Some(v),
                SpeedUse::Unknown => None,
            },
            // Not for the current loop while the sensor is distrusted, nor during a test
            // pulse: the pulse is driven open loop, so the coil's voltage-current relation
            // shows undisturbed by the loop (which hides a short by lowering the duty).
            coil_current_a: if a.contains(FaultKind::CoilSensor) || verdict.test_current_a.is_some()
            {
                None
            } else {
                f.coil_current_a.filter(|i| i.is_finite())
            },
        };
        (verdict, validated)
    }

    fn update_active(&mut self, det: FaultSet, t_us: u32, dt_s: f32) {
        let p = self.p;
        // Only kinds detected now or still active change; on a healthy frame none does.
        let touched = det.0 | self.active.0;
        if touched == 0 {
            return;
        }
        for (i, k) in FaultKind::ALL.into_iter().enumerate() {
            if touched & k.bit() == 0 {
                continue;
            }
            let (Some(rec), Some(absent), Some(recur)) = (
                self.records.get_mut(i),
                self.absent_s.get_mut(i),
                self.recurrences.get_mut(i),
            ) else {
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
                    // Recurrence count: a new window when the last one started too long ago.
                    let (t0, n) = *recur;
                    *recur = if n == 0 || seconds_since(t_us, t0) > p.intermittent_window_s {
                        (t_us, 1)
                    } else {
                        (t0, n.saturating_add(1))
                    };
                    let escalate = k.escalates()
                        && recur.1 >= p.intermittent_count
                        && !self.escalated.contains(k);
                    self.log(SupervisorEvent::Raised { t_us, kind: k });
                    if escalate {
                        self.escalated.insert(k);
                        log_warn!("supervisor: fault {} latched (intermittent)", k.name());
                        self.log(SupervisorEvent::Latched { t_us, kind: k });
                    }
                }
            } else if was && !k.latched() && !self.escalated.contains(k) {
                *absent = (*absent + dt_s).min(1e6);
                if *absent >= p.recovery_s {
                    rec.active = false;
                    self.active.0 &= !k.bit();
                    log_info!("supervisor: fault {} cleared", k.name());
                    self.log(SupervisorEvent::Cleared { t_us, kind: k });
                }
            }
        }
    }
}

/// Inputs after validation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Validated {
    /// Time, s (wraps with the us counter; for logs).
    pub t_s: f32,
    /// Time since the previous frame, s (the nominal period after a timing fault).
    pub dt_s: f32,
    /// Wheel yaw (left, right) in rad to control on: both encoders, or the healthy one twice;
    /// `None` in FailSafe.
    pub angles_rad: Option<(f32, f32)>,
    /// Speed to control on, m/s: the trusted reading; while the speed is untrusted, the last
    /// trusted reading for `speed_hold_s`; then `None` (unknown).
    pub speed_mps: Option<f32>,
    /// Trusted coil current, A.
    pub coil_current_a: Option<f32>,
}
