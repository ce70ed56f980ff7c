//! The standstill token: the only way to open the store's erase ([`super::Store::maintain`],
//! [`super::Store::save_config`], [`super::Store::clear_log`]). Erasing a 128 KiB sector of the
//! F405 stalls every read of the flash, code included, for over a second, so it may only happen
//! with the vehicle stopped and the damper idle.
//!
//! A [`Standstill`] can only be made here (its field is private), by
//! [`StandstillWatch::check`] after the trusted speed has stayed below
//! [`STANDSTILL_SPEED_MPS`] and the coil command at or below [`IDLE_CURRENT_A`] for
//! [`STANDSTILL_HOLD_S`]; it borrows the watch, so it cannot be kept past the moment it was
//! granted for. The 1 kHz control task owns no watch and no store (RTIC resources), so no erase
//! can be reached from it.

use core::marker::PhantomData;

/// Below this trusted speed the vehicle stands, m/s.
pub const STANDSTILL_SPEED_MPS: f32 = 0.1;
/// At or below this coil command the damper is idle, A.
pub const IDLE_CURRENT_A: f32 = 0.01;
/// Both must have held this long, s.
pub const STANDSTILL_HOLD_S: f64 = 2.0;

/// Proof that the vehicle stands and the damper is idle now (see the module documentation).
pub struct Standstill<'w> {
    _watch: PhantomData<&'w mut StandstillWatch>,
}

/// Watches speed and coil command for standstill.
#[derive(Clone, Debug, Default)]
pub struct StandstillWatch {
    since_s: Option<f64>,
}

impl StandstillWatch {
    /// Not standing.
    pub const fn new() -> Self {
        StandstillWatch { since_s: None }
    }

    /// One observation at time `t_s`: the trusted speed (NaN when not trusted: not a
    /// standstill) and the largest coil command since the last observation.
    pub fn observe(&mut self, t_s: f64, speed_mps: f32, cmd_peak_a: f32) {
        let still = speed_mps.is_finite()
            && speed_mps.abs() < STANDSTILL_SPEED_MPS
            && cmd_peak_a.is_finite()
            && cmd_peak_a <= IDLE_CURRENT_A
            && t_s.is_finite();
        self.since_s = match (still, self.since_s) {
            (false, _) => None,
            (true, None) => Some(t_s),
            (true, Some(s)) => Some(s),
        };
    }

    /// The token, when the standstill has lasted [`STANDSTILL_HOLD_S`] up to `t_s`.
    pub fn check(&mut self, t_s: f64) -> Option<Standstill<'_>> {
        let since = self.since_s?;
        (t_s - since >= STANDSTILL_HOLD_S).then_some(Standstill {
            _watch: PhantomData,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_token_needs_two_seconds_stopped_with_the_damper_idle() {
        let mut w = StandstillWatch::new();
        let mut granted = None;
        for k in 0..400 {
            let t = f64::from(k) * 0.01;
            w.observe(t, 0.0, 0.0);
            if w.check(t).is_some() && granted.is_none() {
                granted = Some(t);
            }
        }
        let t = granted.unwrap();
        assert!((t - STANDSTILL_HOLD_S).abs() < 0.011, "granted at {t}");
        // Rolling, a current in the coil, or an untrusted speed: no token, the clock restarts.
        for (speed, cmd) in [(0.5, 0.0), (0.0, 0.3), (f32::NAN, 0.0)] {
            w.observe(10.0, speed, cmd);
            assert!(w.check(10.0).is_none());
            w.observe(11.0, 0.0, 0.0);
            assert!(w.check(12.9).is_none() && w.check(13.0).is_some());
        }
    }
}
