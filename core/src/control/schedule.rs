//! Control that knows its margin: the margin schedule of the margin-scheduled ASMC, the quiet
//! coil that shapes its command, and the speed-only schedule of production dampers (the
//! baseline it is compared with).
//!
//! # The schedule
//!
//! Input: [`MarginSignal`], what the fused margin report says every 10 ms (speed margin to the
//! critical speed, time to reach it, the fast data damping), or `None` when the report is not
//! valid. Output: [`Schedule`], the *arming* `a` in [0, 1] and from it the pre-arm base current,
//! the ASMC's boundary layer and the shimmy-band amplitude that engages the coil:
//!
//! ```text
//! a = max( ramp(dV;   arm_margin_mps, idle_margin_mps),
//!          ramp(ttc;  arm_ttc_s,      idle_ttc_s),
//!          ramp(zeta_fast; arm_zeta,  idle_zeta) )       ramp(x; lo, hi) = 1 at x <= lo, 0 at x >= hi
//! base current = a I_base,   phi = phi_idle + a (phi_armed - phi_idle),
//! engage amplitude = A_idle + a (A_armed - A_idle)
//! ```
//!
//! Each term is non-increasing in its margin, so the schedule is monotone in the margin: a
//! smaller speed margin, a shorter time to critical or a lower measured damping never lowers the
//! base current nor widens the layer (property tests). Far from the Hopf window (a = 0) the
//! damper idles: no base current, the ASMC's own layer, and the coil engages only for a
//! large shimmy-band amplitude. Inside the window (dV = 0, or the fast damping at or below
//! `arm_zeta`: the first sign of growth) it is fully armed. An invalid or missing report is
//! treated as no margin at all (a = 1): the safe side.
//!
//! # The quiet coil ([`QuietCoil`])
//!
//! The ASMC's semi-active clip switches the current on and off every half cycle of the
//! shimmy mode, and its switching term reacts to every road-noise peak of the sliding
//! variable; the coil (L/R = 5.3 ms) and the MR fluid (a few ms) cannot follow that, the
//! command's total variation says it is wasted, and every switch is a steering-force ripple.
//! The quiet coil therefore drives the coil from the shimmy-band *amplitude*
//! A = sqrt(psi^2 + (psi'/w)^2) (w = 2 pi `band_hz`; exact for a sinusoid at w, smooth for a
//! narrow-band signal), not from the sign of s:
//!
//! 0. amplitude: the pair (psi_hp, psi_hp') through one first-order band-pass from half to
//!    twice `band_hz` (steering harmonics below, the rate observer's quantisation noise up to
//!    60 Hz above), A of the filtered pair;
//! 1. noise floor: the running mean of A while the coil is not engaged, over at most
//!    `noise_tau_s` (then a first-order average with that time constant), so road noise raises its own threshold: the engage amplitude is
//!    max(scheduled amplitude, `noise_factor` x floor), the floor's part capped at the idle
//!    engage amplitude (a slow growth, which the floor follows with a lag, still engages);
//! 2. engage when A exceeds it; stay engaged until A has stayed below half of it for `hold_s`
//!    (the tail of a decay is damped, not left to the 0 A damper);
//! 3. while engaged the target is max(ASMC current, base current), in the hold the base
//!    current alone (the ASMC's switching term would act on sensor noise there); otherwise 0 A;
//! 4. envelope: the command follows a rising target at once (the coil driver's current loop
//!    and the coil's own L/R limit the rise) and falls with the time constant `release_s`,
//!    so the clipped half cycles of one burst keep their current instead of switching it.
//!
//! # Stability argument
//!
//! Let E = I_k psi'^2/2 + U(psi) be the energy of the in-phase wheel-yaw mode. The damper
//! contributes -(l_t/2) F_d psi' to E', and the MR damper is passive at every current:
//! F(I, v) v >= 0 for I >= 0 (the Bingham model's yield and viscous terms both resist v, and
//! dF/dI v = f_cb S(v/v0) v + c_b v^2 >= 0). Hence
//!
//! 1. *never worse than the passive damper at 0 A*: whatever the schedule and the envelope
//!    command, the damper only removes energy from the mode; the command is clamped to
//!    [0, I_max] and never NaN;
//! 2. *at least the ASMC's dissipation while engaged*: the command is the envelope of
//!    max(ASMC current, base current), so on every sample it is >= the ASMC's current and the
//!    damper removes at least the energy the ASMC's own command would remove from the same
//!    state; where the ASMC's argument holds (its module, [`super::smc`]: (s, K) uniformly
//!    ultimately bounded when the damper's authority suffices) the extra dissipation only
//!    shrinks dE/dt further. Outside the engaged intervals the amplitude is below the engage
//!    amplitude, which is the ultimate bound the scheme guarantees: at most the idle engage
//!    amplitude when the margin is wrong, the armed one when it is small or unknown;
//! 3. *slow variation*: the base current and the envelope change on the scale of `release_s`
//!    and the 10 ms report, slower than the shimmy period, so the frozen-current picture holds:
//!    at each instant the mode sees a damper at a current >= a I_base, whose describing-function
//!    damping c_eq grows with the current (`shimmy-sim stability --damper-current-a`), so arming
//!    near the window moves the closed loop away from the Hopf condition;
//! 4. *the margin loop*: the margin only selects thresholds and levels, monotonically, between
//!    two settings that are each stable in the sense of 1-2; a wrong margin costs energy (too
//!    high) or a larger ultimate bound (too low), never passivity.

// NaN must take the "safe" branch of these comparisons, hence `!(x > y)` style.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

/// What the schedule takes from a valid fused margin report (`MarginReport`), copied every
/// 10 ms by the meter task. Absent quantities are +infinity (no limit from them).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MarginSignal {
    /// Speed margin to the critical speed, m/s (0 inside the window).
    pub speed_margin_mps: f32,
    /// Time to the critical speed at the current acceleration, s (+inf when not approaching).
    pub time_to_critical_s: f32,
    /// Damping ratio of the fast data estimate (+inf when it is not valid).
    pub zeta_fast: f32,
}

/// Parameters of the schedule and the quiet coil (vehicle fields, `docs/vehicle-file.md`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScheduleParams {
    /// Speed margin at and below which the damper is fully armed, m/s.
    pub arm_margin_mps: f32,
    /// Speed margin at and above which it idles, m/s.
    pub idle_margin_mps: f32,
    /// Time to critical at and below which it is fully armed, s.
    pub arm_ttc_s: f32,
    /// Time to critical at and above which that term idles, s.
    pub idle_ttc_s: f32,
    /// Fast data damping at and below which it is fully armed (growth).
    pub arm_zeta: f32,
    /// Fast data damping at and above which that term idles.
    pub idle_zeta: f32,
    /// Base current while engaged and fully armed, A.
    pub base_current_a: f32,
    /// ASMC boundary layer when fully armed, rad/s (idle: the ASMC's own `phi_radps`).
    pub armed_phi_radps: f32,
    /// Shimmy-band amplitude that engages the coil when fully armed, rad.
    pub armed_engage_rad: f32,
    /// ... when idle, rad.
    pub idle_engage_rad: f32,
    /// The engage amplitude is at least this many times the noise floor.
    pub noise_factor: f32,
    /// Time constant of the noise floor, s.
    pub noise_tau_s: f32,
    /// The coil stays engaged this long after the amplitude fell below half the engage
    /// amplitude, s.
    pub hold_s: f32,
    /// Release time constant of the command envelope, s.
    pub release_s: f32,
    /// Frequency that turns the shimmy-band rate into an amplitude, Hz (the shimmy mode's).
    pub band_hz: f32,
}

impl ScheduleParams {
    /// Tuned in the closed loop (`shimmy-sim compare`, docs/margin-estimator.md, "Control that knows its
    /// margin"): arming over 4 -> 1 m/s of speed margin (14 -> 4 km/h: the warning monitor's
    /// `MarginLow` threshold is 1.4 m/s) and 10 -> 3 s to critical; the fast damping arms below
    /// 0.02 and fully at 0 (growth). Armed: the coil engages at 0.06 deg shimmy-band amplitude
    /// (about 3 encoder quanta, above the encoder noise), 3x the road-noise floor; idle at
    /// 0.3 deg (below the 0.5 deg that counts as shimmy). Hold 0.4 s and release 0.15 s: the
    /// tail of a decay is damped to the 2 % band, the clipped half cycles (83 ms at 6 Hz) keep
    /// most of their current. Band 6 Hz: the reference plant's shimmy mode (5.8-7.2 Hz).
    pub const DEFAULT: Self = ScheduleParams {
        arm_margin_mps: 1.0,
        idle_margin_mps: 4.0,
        arm_ttc_s: 3.0,
        idle_ttc_s: 10.0,
        arm_zeta: 0.0,
        idle_zeta: 0.02,
        base_current_a: 1.0,
        armed_phi_radps: 0.05,
        armed_engage_rad: 0.1f32 * (core::f32::consts::PI / 180.0),
        idle_engage_rad: 0.3f32 * (core::f32::consts::PI / 180.0),
        noise_factor: 3.0,
        noise_tau_s: 2.0,
        hold_s: 0.4,
        release_s: 0.1,
        band_hz: 6.0,
    };
}

impl Default for ScheduleParams {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// The schedule's output for one report.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Schedule {
    /// Arming in [0, 1]: 0 idle, 1 fully armed.
    pub arming: f32,
    /// Base current while engaged, A.
    pub base_current_a: f32,
    /// ASMC boundary layer, rad/s.
    pub phi_radps: f32,
    /// Shimmy-band amplitude that engages the coil (before the noise floor), rad.
    pub engage_rad: f32,
}

/// 1 at `x <= lo`, 0 at `x >= hi`, linear between; NaN -> 1 (no margin known: armed).
#[inline]
fn closeness(x: f32, lo: f32, hi: f32) -> f32 {
    if !(x > lo) {
        1.0
    } else if !(x < hi) {
        0.0
    } else {
        (hi - x) / (hi - lo)
    }
}

/// `lo + a (hi - lo)` with `a` in [0, 1].
#[inline]
fn blend(a: f32, idle: f32, armed: f32) -> f32 {
    idle + a * (armed - idle)
}

impl ScheduleParams {
    /// The arming for `margin` (`None`: no valid report, the safe side: fully armed).
    pub fn arming(&self, margin: Option<&MarginSignal>) -> f32 {
        let Some(m) = margin else {
            return 1.0;
        };
        // Each term is in [0, 1] (NaN maps to 1), so their largest is too.
        closeness(
            m.speed_margin_mps,
            self.arm_margin_mps,
            self.idle_margin_mps,
        )
        .max(closeness(
            m.time_to_critical_s,
            self.arm_ttc_s,
            self.idle_ttc_s,
        ))
        .max(closeness(m.zeta_fast, self.arm_zeta, self.idle_zeta))
    }

    /// The schedule for `margin`; `idle_phi_radps` is the ASMC's own boundary layer.
    pub fn schedule(&self, margin: Option<&MarginSignal>, idle_phi_radps: f32) -> Schedule {
        let a = self.arming(margin);
        Schedule {
            arming: a,
            base_current_a: a * self.base_current_a,
            phi_radps: blend(a, idle_phi_radps, self.armed_phi_radps),
            engage_rad: blend(a, self.idle_engage_rad, self.armed_engage_rad),
        }
    }
}

/// Shimmy-band amplitude sqrt(psi^2 + (psi' / w)^2), w = 2 pi `band_hz`, rad: exact for a
/// sinusoid at w.
#[inline]
pub fn band_amplitude_rad(psi_rad: f32, rate_radps: f32, band_hz: f32) -> f32 {
    let w = 2.0 * core::f32::consts::PI * band_hz;
    let r = rate_radps / w;
    crate::sqrt::sqrtf(psi_rad * psi_rad + r * r)
}

/// The amplitude's band-pass passes `band_hz` / this to this x `band_hz` (first-order edges).
pub const AMPLITUDE_BP_RATIO: f32 = 2.0;

/// One step of the quiet coil.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct QuietStep {
    /// Shaped coil command, A, in [0, i_max].
    pub current_a: f32,
    /// The coil is engaged (the law reaches it).
    pub engaged: bool,
    /// Engage amplitude in use (scheduled, raised by the noise floor), rad.
    pub engage_rad: f32,
}

/// State of the quiet coil: noise floor, engagement with its hold timer, command envelope.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct QuietCoil {
    in_psi_rad: f32,
    in_rate_radps: f32,
    hp_psi_rad: f32,
    hp_rate_radps: f32,
    lp_psi_rad: f32,
    lp_rate_radps: f32,
    noise_rad: f32,
    learnt_s: f32,
    engaged: bool,
    below_s: f32,
    envelope_a: f32,
}

impl QuietCoil {
    /// Idle, no noise floor yet, 0 A.
    pub fn new() -> Self {
        Self::default()
    }

    /// Noise floor of the shimmy-band amplitude, rad.
    pub fn noise_floor_rad(&self) -> f32 {
        self.noise_rad
    }

    /// The shimmy-band amplitude of the conditioned pair (psi_hp, psi_hp'): both through the
    /// same first-order band-pass, a high-pass at `band_hz` / [`AMPLITUDE_BP_RATIO`] (steering
    /// manoeuvres leave their harmonics in the 1.5 Hz conditioning high-pass) and a low-pass at
    /// [`AMPLITUDE_BP_RATIO`] x `band_hz` (the rate observer's quantisation noise reaches
    /// 60 Hz); one filter on both keeps them in quadrature. Scaled back by the filter's gain at
    /// `band_hz`, then [`band_amplitude_rad`].
    pub fn band_amplitude(
        &mut self,
        p: &ScheduleParams,
        psi_hp_rad: f32,
        rate_hp_radps: f32,
        dt_s: f32,
    ) -> f32 {
        let two_pi = 2.0 * core::f32::consts::PI;
        let tau_lp = 1.0 / (two_pi * AMPLITUDE_BP_RATIO * p.band_hz);
        let tau_hp = AMPLITUDE_BP_RATIO / (two_pi * p.band_hz);
        let k_lp = dt_s / (tau_lp + dt_s);
        let k_hp = tau_hp / (tau_hp + dt_s);
        // A non-finite input leaves the filters as they were.
        if psi_hp_rad.is_finite()
            && rate_hp_radps.is_finite()
            && k_lp.is_finite()
            && k_hp.is_finite()
        {
            let hp = |y: f32, x: f32, x_prev: f32| k_hp * (y + x - x_prev);
            self.hp_psi_rad = hp(self.hp_psi_rad, psi_hp_rad, self.in_psi_rad);
            self.hp_rate_radps = hp(self.hp_rate_radps, rate_hp_radps, self.in_rate_radps);
            self.in_psi_rad = psi_hp_rad;
            self.in_rate_radps = rate_hp_radps;
            self.lp_psi_rad += k_lp * (self.hp_psi_rad - self.lp_psi_rad);
            self.lp_rate_radps += k_lp * (self.hp_rate_radps - self.lp_rate_radps);
        }
        // 1 / |H| at band_hz: each first-order section passes 1 / sqrt(1 + 1/ratio^2) there.
        let inv_gain = 1.0 + 1.0 / (AMPLITUDE_BP_RATIO * AMPLITUDE_BP_RATIO);
        inv_gain * band_amplitude_rad(self.lp_psi_rad, self.lp_rate_radps, p.band_hz)
    }

    /// One step over `dt_s`: the shimmy-band amplitude, the ASMC's current for this sample and
    /// the schedule in force give the shaped command (clamped to [0, `i_max_a`]).
    pub fn step(
        &mut self,
        p: &ScheduleParams,
        sch: &Schedule,
        amplitude_rad: f32,
        law_current_a: f32,
        i_max_a: f32,
        dt_s: f32,
    ) -> QuietStep {
        // A NaN amplitude counts as large (engage: the safe side); the floor ignores it.
        let amp = if amplitude_rad.is_nan() {
            f32::INFINITY
        } else {
            amplitude_rad
        };
        if !self.engaged && amp.is_finite() && p.noise_tau_s > 0.0 && dt_s > 0.0 {
            // The running mean over the time learnt so far, then a first-order average over
            // `noise_tau_s` (backward Euler, no expf): the floor is there within the first
            // second of driving, not after several time constants.
            self.learnt_s = (self.learnt_s + dt_s).min(p.noise_tau_s);
            self.noise_rad += dt_s / (self.learnt_s + dt_s) * (amp - self.noise_rad);
        }
        // The floor raises the threshold at most to the idle one: a slow growth, which the
        // floor follows with a lag, is still engaged at the idle amplitude.
        let floor = (p.noise_factor * self.noise_rad).min(p.idle_engage_rad);
        let engage = sch.engage_rad.max(floor);
        if amp > engage {
            self.engaged = true;
            self.below_s = 0.0;
        } else if self.engaged {
            if amp < 0.5 * engage {
                self.below_s += dt_s;
            } else {
                self.below_s = 0.0;
            }
            if !(self.below_s < p.hold_s) {
                self.engaged = false;
                self.below_s = 0.0;
            }
        }
        // Engaged: the law's current, at least the base; holding (the amplitude below half the
        // engage amplitude, the tail of a decay): the base current only, because the law's
        // switching term then acts on sensor noise at near-zero stroke rates.
        let target = match (self.engaged, self.below_s > 0.0) {
            (true, false) => law_current_a.max(sch.base_current_a),
            (true, true) => sch.base_current_a,
            (false, _) => 0.0,
        };
        let released = if p.release_s > 0.0 {
            self.envelope_a * (p.release_s / (p.release_s + dt_s))
        } else {
            0.0
        };
        let cmd = target.max(released);
        // Clamp, NaN -> 0 A.
        self.envelope_a = if cmd >= 0.0 { cmd.min(i_max_a) } else { 0.0 };
        QuietStep {
            current_a: self.envelope_a,
            engaged: self.engaged,
            engage_rad: engage,
        }
    }
}

/// The production damper's schedule: current as a function of speed only, a trapezoid over
/// the speed band the vehicle file's model says is critical.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpeedSchedule {
    /// Lower edge of the full-current band, m/s.
    pub v_lo_mps: f32,
    /// Upper edge of the full-current band, m/s.
    pub v_hi_mps: f32,
    /// Width of the linear ramps outside the band, m/s.
    pub ramp_mps: f32,
    /// Current inside the band, A.
    pub current_a: f32,
}

impl SpeedSchedule {
    /// Current at speed `v_mps`, A (0 outside the band and its ramps; NaN speed: the band's).
    pub fn current_at(&self, v_mps: f32) -> f32 {
        let below = self.v_lo_mps - v_mps;
        let above = v_mps - self.v_hi_mps;
        let out = below.max(above);
        if !(out > 0.0) {
            return self.current_a;
        }
        let w = if self.ramp_mps > 0.0 {
            1.0 - out / self.ramp_mps
        } else {
            0.0
        };
        self.current_a * w.max(0.0)
    }
}
