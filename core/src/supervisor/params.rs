//! The supervisor's thresholds ([`SupervisorParams`]) and the two currents its policy uses.

use crate::control::actuator::FAILSAFE_CURRENT_A;
use crate::estimator::meter::mode_meter::EstimatorConfig;

/// Encoder noise from which a healthy encoder never holds one value for `stuck_samples`, LSB
/// rms: at 0.4 LSB a reading in the middle of a quantum repeats with probability ~0.65 per
/// sample, so 100 repeats in a row happen with probability ~1e-19.
pub const DITHER_MIN_LSB: f32 = 0.4;

/// Below this (trusted) speed 0 A is safe: 80 % of the lowest Hopf onset of every analysed
/// variant without damper (checked by `tests/tests/cross_crate/failsafe_current.rs`), m/s.
pub const ZERO_CURRENT_SAFE_BELOW_MPS: f32 = 1.0;

/// Supervisor thresholds. `Default` is the documented design point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SupervisorParams {
    /// Encoder angles beyond +-this are invalid, rad.
    pub psi_limit_rad: f32,
    /// Largest plausible wheel-yaw rate, rad/s.
    pub max_rate_radps: f32,
    /// Largest plausible |psi_L - psi_R|, rad (steering-geometry Ackermann difference at
    /// full lock plus compliance).
    pub max_disagree_rad: f32,
    /// Samples of bit-identical value for the single-encoder stuck check.
    pub stuck_samples: u16,
    /// Peak-to-peak motion of the other encoder that must show on a healthy one, rad.
    pub stuck_motion_rad: f32,
    /// The encoders' noise, LSB rms (the vehicle's `sensors.encoder_noise_lsb`): from
    /// [`DITHER_MIN_LSB`] on, a healthy encoder dithers and `stuck_samples` bit-identical
    /// values alone prove a freeze, whatever the other encoder does.
    pub encoder_noise_lsb: f32,
    /// Samples of a bit-identical pair (at speed) for `BothStuckSuspect`.
    pub both_stuck_samples: u16,
    /// Largest plausible speed, m/s.
    pub max_speed_mps: f32,
    /// Negative speed tolerated as sensor noise at standstill, m/s.
    pub speed_neg_tol_mps: f32,
    /// Largest plausible |dV/dt|, m/s^2.
    pub max_accel_mps2: f32,
    /// Sample-to-sample speed noise tolerated on top of the acceleration bound, m/s (a
    /// wheel-speed signal read every 1 ms carries noise much larger than 1.5 g x 1 ms).
    pub speed_noise_tol_mps: f32,
    /// A speed reading below this must have been reached plausibly (deceleration bound from the
    /// trusted speeds) to be trusted, m/s: the controller's speed gate
    /// (`ControlParams::min_speed_mps`), below which the damper switches itself off.
    pub speed_low_mps: f32,
    /// After the speed becomes untrusted, the last trusted speed is held for this long (the
    /// controller keeps running on it, no current floor), then the speed counts as unknown
    /// (speed gate off, fail-safe current as a floor), s.
    pub speed_hold_s: f32,
    /// Largest time-stamp gap before `Timing`, us.
    pub max_gap_us: u32,
    /// The coil's time constant L/R, s: the coil checks compare the measured current with the
    /// command passed through this first-order lag (the *expected* current), so a command step
    /// is not a mismatch.
    pub coil_tau_s: f32,
    /// Open coil and the sensor's ratio band are judged while the expected current and the
    /// drive are above this, A.
    pub coil_min_expected_a: f32,
    /// Open coil: measured below this fraction of the expected current.
    pub coil_open_ratio: f32,
    /// Short: measured above this multiple of the expected current (no coil resistance over
    /// temperature and no plausible sensor gain comes near it: only a path around the coil).
    pub coil_short_ratio: f32,
    /// The short is judged from this expected current on, A: below it a sensor offset of up
    /// to (`coil_short_ratio` - 1) x this could pass for a short.
    pub coil_short_min_a: f32,
    /// No drive: the drive is at most this, A.
    pub coil_no_drive_a: f32,
    /// The no-drive reading is judged while the expected (decaying) current is at most this,
    /// A: a coil 20 % slower than the nominal L/R then differs from it by < 0.05 A.
    pub coil_no_drive_check_a: f32,
    /// `CoilSensor`: a reading this far above the expected current with no drive (no coil
    /// fault makes current flow without voltage), or below minus this (the driver is
    /// unidirectional), A.
    pub coil_sensor_zero_a: f32,
    /// `CoilSensor`: while the coil is checkable, a reading outside [lo, hi] x the expected
    /// current that is neither open nor short. The band holds a healthy coil from -40 C (R
    /// x0.76: x1.31) to 150 C (R x1.5: x0.67) on the nominal drive model.
    pub coil_sensor_lo: f32,
    /// Upper end of the band, see `coil_sensor_lo`.
    pub coil_sensor_hi: f32,
    /// Accumulated mismatch time that raises a coil fault, s (>> the coil's L/R = 5 ms). The
    /// accumulator grows by the time of a mismatch and drains by `coil_heal_ratio` x the time
    /// of a match, so an intermittent fault (a chattering connector) adds up instead of being
    /// forgotten at the first good sample.
    pub coil_fault_s: f32,
    /// Drain rate of the mismatch accumulator while the current matches (fraction of real
    /// time): a mismatch present more than `h / (1 + h)` of the time (h = this) adds up to a fault.
    pub coil_heal_ratio: f32,
    /// Test-pulse current, A (0 disables): when the coil checks could not run for
    /// `coil_test_idle_s` (the expected current stayed below `coil_min_expected_a`), the command
    /// is raised to at least this for `coil_test_pulse_s`, so an open coil is found while the
    /// controller demands little current.
    pub coil_test_current_a: f32,
    /// Length of a test pulse, s.
    pub coil_test_pulse_s: f32,
    /// Time without a coil check before a test pulse, s.
    pub coil_test_idle_s: f32,
    /// Full scale of the coil-current measurement, A: a reading at or above it means "at least
    /// this much" (ADC saturated), so it proves a short only where the short's ratio times the
    /// expected current is below it.
    pub coil_full_scale_a: f32,
    /// Margin invalid for this long raises `MarginUnavailable`, s (0 disables).
    pub margin_invalid_s: f32,
    /// A fault must be absent this long before it leaves the active set, s.
    pub recovery_s: f32,
    /// A fault that becomes active this many times within `intermittent_window_s` of the first
    /// of them is latched (intermittent: it would otherwise toggle the mode forever).
    pub intermittent_count: u8,
    /// Window of the recurrence count, s.
    pub intermittent_window_s: f32,
    /// Fail-safe current, A.
    pub failsafe_current_a: f32,
    /// Below this trusted speed the safe current is 0 A, m/s.
    pub zero_current_below_mps: f32,
    /// The shimmy band's lower edge, Hz: the wheel-yaw oscillation that proves the vehicle
    /// rolls (`super::motion`) has its half-periods inside the band.
    pub shimmy_band_lo_hz: f32,
    /// The shimmy band's upper edge, Hz.
    pub shimmy_band_hi_hz: f32,
    /// A half-cycle of the high-passed in-phase wheel yaw counts when it exceeds +-this, rad.
    pub motion_rad: f32,
    /// Consecutive half-cycles in the band that make an oscillation.
    pub motion_half_cycles: u8,
}

impl Default for SupervisorParams {
    /// psi limit 0.8 rad (as the controller); 25 rad/s (module docs); disagreement 0.25 rad
    /// (the Ackermann difference of a road vehicle at full lock is ~0.1-0.2 rad); stuck after
    /// 100 ms with 5 mrad motion on the other side; both-stuck after 2 s; 70 m/s max (the
    /// analysed range); 0.5 m/s negative tolerance; 15 m/s^2 (1.5 g) plus 0.5 m/s
    /// sample-to-sample noise (10 sigma of the simulator's 0.05 m/s wheel-speed noise; the
    /// board's tone-wheel `jump_margin_mps` is 0.5 m/s too); low-speed plausibility below the
    /// controller's 2 m/s gate, the last trusted speed held for 1 s; gap 5 ms (4 missed samples); coil
    /// checks against the command through the coil's L/R = 1/190 s (the simulator's damper lag)
    /// while that is above 0.2 A: open < 25 %, short > +0.5 A or a saturated 2.5 A reading, for
    /// 50 ms of mismatch (10 L/R) draining at a quarter of real time (a mismatch more than 20 %
    /// of the time adds up); a 0.4 A x 80 ms test pulse after 1 s without a check (the
    /// check runs from 3.6 ms into the pulse, so an open coil is flagged 54 ms into it); margin
    /// 10 s; recovery 1 s; latched on the 3rd activation within 10 s of the first (one bad read in
    /// 1,500 frames: latched at the third, 3 s after the first; one in 15 s never). Motion
    /// evidence: the mode meter's shimmy band (3-20 Hz for the car), half-cycles beyond 1.5 mrad
    /// (0.09 deg: 4 quanta of a 14-bit encoder, 6 sigma of its high-passed noise, well below a
    /// shimmy that matters), three in a row (the `hard` set's shimmy grows so fast that a fourth
    /// lets it past 0.5 deg before the fail-safe floor comes). The reference 14-bit encoder's
    /// 0.5 LSB rms of noise (a vehicle's own: `Vehicle::supervisor_params`).
    fn default() -> Self {
        let band = EstimatorConfig::default();
        SupervisorParams {
            psi_limit_rad: 0.8,
            max_rate_radps: 25.0,
            max_disagree_rad: 0.25,
            stuck_samples: 100,
            stuck_motion_rad: 5e-3,
            encoder_noise_lsb: 0.5,
            both_stuck_samples: 2000,
            max_speed_mps: 70.0,
            speed_neg_tol_mps: 0.5,
            max_accel_mps2: 15.0,
            speed_noise_tol_mps: 0.5,
            speed_low_mps: 2.0,
            speed_hold_s: 1.0,
            max_gap_us: 5000,
            coil_tau_s: 1.0 / 190.0,
            coil_min_expected_a: 0.2,
            coil_open_ratio: 0.25,
            coil_short_ratio: 3.0,
            coil_short_min_a: 0.3,
            coil_no_drive_a: 0.02,
            coil_no_drive_check_a: 0.5,
            coil_sensor_zero_a: 0.15,
            coil_sensor_lo: 0.55,
            coil_sensor_hi: 1.5,
            coil_fault_s: 0.05,
            coil_heal_ratio: 0.25,
            coil_test_current_a: 0.4,
            coil_test_pulse_s: 0.08,
            coil_test_idle_s: 1.0,
            coil_full_scale_a: 2.5,
            margin_invalid_s: 10.0,
            recovery_s: 1.0,
            intermittent_count: 3,
            intermittent_window_s: 10.0,
            failsafe_current_a: FAILSAFE_CURRENT_A,
            zero_current_below_mps: ZERO_CURRENT_SAFE_BELOW_MPS,
            shimmy_band_lo_hz: band.band_lo_hz,
            shimmy_band_hi_hz: band.band_hi_hz,
            motion_rad: 1.5e-3,
            motion_half_cycles: 3,
        }
    }
}

impl SupervisorParams {
    /// The same thresholds for a shimmy mode `k` times slower than the car's (the model's
    /// [`crate::model::LinearModel::meter_time_scale`], as the mode meter is scaled): the shimmy
    /// band divided by `k`. `k = 1` is `self`.
    pub fn time_scaled(self, k: u16) -> Self {
        let kf = f32::from(k.max(1));
        SupervisorParams {
            shimmy_band_lo_hz: self.shimmy_band_lo_hz / kf,
            shimmy_band_hi_hz: self.shimmy_band_hi_hz / kf,
            ..self
        }
    }

    /// A healthy encoder dithers ([`DITHER_MIN_LSB`]).
    pub fn encoders_dither(&self) -> bool {
        self.encoder_noise_lsb >= DITHER_MIN_LSB
    }

    /// How long both encoders may hold bit-identical values right after an oscillation before
    /// the pair counts as frozen, s: half a period of the band's lower edge. A rolling wheel's
    /// yaw dwells within one encoder quantum of a turning point for much less than a quarter
    /// period once its amplitude is several quanta, so a healthy pair cannot do this.
    pub fn pair_freeze_s(&self) -> f32 {
        0.5 / self.shimmy_band_lo_hz
    }
}
