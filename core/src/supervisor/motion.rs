//! Evidence that the vehicle rolls, from the wheel yaw alone: an oscillation in the shimmy
//! band ([`YawOscillation`]). Shimmy is self-excited by the rolling tyre, so a sustained
//! wheel-yaw oscillation at the shimmy frequency cannot happen at standstill; the driver's
//! steering at a standstill is slow (a few reversals, well below the band). The supervisor uses it
//! twice: a low speed reading while the wheels oscillate is contradicted (a speed sensor lost
//! or frozen below the speed gate), and both encoders freezing at once in the middle of an
//! oscillation is a common-cause freeze, not a wheel that came to rest.
//!
//! The in-phase yaw is high-passed (first order, corner at half the band's lower edge, so
//! steering ramps and offsets do not count), and each lobe of the high-passed signal beyond
//! +-`motion_rad` is a half-cycle. Consecutive half-cycles of alternating sign whose spacing is a
//! half-period inside the band count up; `motion_half_cycles` of them make an oscillation. A
//! spacing outside the band, or no new half-cycle for a period of the band's lower edge,
//! restarts the count.

use super::params::SupervisorParams;

/// Half-cycle counter of the high-passed in-phase wheel yaw.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct YawOscillation {
    /// The previous input and the high-passed output, rad.
    last_in: Option<f32>,
    hp: f32,
    /// Sign of the last lobe beyond the threshold (0: none yet) and the time since it
    /// started, s (frames without a trusted encoder count too).
    lobe_sign: i8,
    since_lobe_s: f32,
    /// Consecutive half-cycles in the band.
    half_cycles: u8,
}

impl YawOscillation {
    /// Feeds the in-phase yaw `y_rad` (`None`: no trusted encoder this frame) after `dt_s`.
    pub(super) fn update(&mut self, y_rad: Option<f32>, dt_s: f32, p: &SupervisorParams) {
        self.since_lobe_s = (self.since_lobe_s + dt_s).min(1e6);
        let period_lo_s = 1.0 / p.shimmy_band_lo_hz;
        if self.since_lobe_s > period_lo_s {
            self.half_cycles = 0;
        }
        let Some(y) = y_rad.filter(|y| y.is_finite()) else {
            self.last_in = None;
            return;
        };
        // First-order high-pass, corner at half the band's lower edge.
        let tau_s = 1.0 / (core::f32::consts::PI * p.shimmy_band_lo_hz);
        let a = tau_s / (tau_s + dt_s);
        self.hp = match self.last_in {
            Some(prev) => a * (self.hp + y - prev),
            None => 0.0,
        };
        self.last_in = Some(y);
        let sign = if self.hp > p.motion_rad {
            1
        } else if self.hp < -p.motion_rad {
            -1
        } else {
            return;
        };
        if sign == self.lobe_sign {
            return;
        }
        let spacing_s = self.since_lobe_s;
        let in_band = self.lobe_sign != 0
            && spacing_s >= 0.5 / p.shimmy_band_hi_hz
            && spacing_s <= 0.5 * period_lo_s;
        self.half_cycles = if in_band {
            self.half_cycles.saturating_add(1)
        } else {
            0
        };
        self.lobe_sign = sign;
        self.since_lobe_s = 0.0;
    }

    /// The wheels oscillate in the shimmy band (`motion_half_cycles` half-cycles in a row).
    pub(super) fn oscillating(&self, p: &SupervisorParams) -> bool {
        self.half_cycles >= p.motion_half_cycles
    }
}
