//! Vehicle speed from wheel-speed pulses measured by timer input capture.
//!
//! The board layer reports, once per control step, the newest complete pulse period (if a new
//! edge arrived) and how long ago the last edge was, both in timer ticks ([`PulseSample`]).
//! [`WheelSpeed`] turns that into m/s with the pulses per revolution and the rolling radius:
//! - no edge for longer than the timeout: standstill, 0 m/s (only a candidate: a stop and a
//!   lost pulse train look the same here; the core's supervisor trusts it only if it was reached
//!   within its deceleration bound, `speed-low-implausible`);
//! - between edges the speed can only be as high as one pulse distance over the time since the
//!   last edge, so a decelerating wheel is followed without waiting for the next edge;
//! - a new period whose speed differs from the last accepted one by more than the plausible
//!   acceleration allows is flagged [`SpeedStatus::Implausible`] and the last value is held.

use core::f32::consts::PI;

/// What the input-capture timer saw since the previous control step.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PulseSample {
    /// Ticks between the last two edges, if a new edge arrived since the previous sample.
    pub new_period_ticks: Option<u32>,
    /// Ticks since the most recent edge (saturating).
    pub ticks_since_edge: u32,
}

/// Source of [`PulseSample`]s (timer input capture on the board, a table in simulation).
pub trait PulseCapture {
    /// Takes what was captured since the last call.
    fn take(&mut self) -> PulseSample;

    /// The free-running count of the capture timer now, ticks (wraps): the control loop's time
    /// base (at 1 MHz a tick is a microsecond).
    fn now_ticks(&mut self) -> u32;
}

/// Configuration of the speed computation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpeedConfig {
    /// Pulses per wheel revolution (tone-wheel teeth).
    pub pulses_per_rev: u16,
    /// Dynamic rolling radius, m.
    pub rolling_radius_m: f32,
    /// Input-capture timer tick rate, Hz.
    pub tick_hz: u32,
    /// No edge for this long means standstill, s.
    pub timeout_s: f32,
    /// Largest plausible |acceleration| [m/s^2] (braking and traction of a road vehicle stay
    /// below ~12 m/s^2; a larger jump is a missing or extra tooth or electrical noise).
    pub max_accel_mps2: f32,
    /// Speed change allowed on top of the acceleration bound (quantisation, tooth spacing
    /// errors) [m/s].
    pub jump_margin_mps: f32,
}

/// Quality of a speed reading.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(target_os = "none", derive(defmt::Format))]
pub enum SpeedStatus {
    /// Computed from a fresh, plausible period (or bounded by the time since the last edge).
    Valid,
    /// No edge within the timeout: the vehicle stands still (0 m/s).
    Standstill,
    /// The new period implied an impossible speed change; the previous value is held.
    Implausible,
    /// Edges arrive but no complete period has been measured yet (rolling just started, or
    /// the MCU restarted while driving): the speed is unknown, reported as 0 m/s and marked
    /// invalid for the supervisor (a restart at 70 km/h must not read as standstill).
    Starting,
}

/// A speed reading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpeedReading {
    /// Vehicle speed [m/s] (>= 0; the tone wheel does not tell the direction).
    pub speed_mps: f32,
    /// How it was obtained.
    pub status: SpeedStatus,
}

/// Speed estimator state.
#[derive(Clone, Copy, Debug)]
pub struct WheelSpeed {
    cfg: SpeedConfig,
    metres_per_pulse: f32,
    /// Last accepted speed (before the between-edges bound) [m/s].
    accepted_mps: f32,
    /// Ticks since the last accepted period (for the acceleration bound).
    ticks_since_accept: u32,
    have_speed: bool,
    implausible_count: u32,
}

impl WheelSpeed {
    /// A new estimator at standstill.
    pub fn new(cfg: SpeedConfig) -> Self {
        let ppr = if cfg.pulses_per_rev == 0 {
            1.0
        } else {
            f32::from(cfg.pulses_per_rev)
        };
        WheelSpeed {
            cfg,
            metres_per_pulse: 2.0 * PI * cfg.rolling_radius_m / ppr,
            accepted_mps: 0.0,
            ticks_since_accept: 0,
            have_speed: false,
            implausible_count: 0,
        }
    }

    /// How many periods were rejected as implausible so far.
    pub fn implausible_count(&self) -> u32 {
        self.implausible_count
    }

    /// Speed that a period of `ticks` means [m/s].
    pub fn speed_from_period(&self, ticks: u32) -> f32 {
        if ticks == 0 {
            return f32::INFINITY;
        }
        self.metres_per_pulse * self.cfg.tick_hz as f32 / ticks as f32
    }

    /// One update per control step; `dt_ticks` is the step length in capture-timer ticks.
    pub fn update(&mut self, s: PulseSample, dt_ticks: u32) -> SpeedReading {
        let tick_s = 1.0 / self.cfg.tick_hz as f32;
        self.ticks_since_accept = self.ticks_since_accept.saturating_add(dt_ticks);
        if s.ticks_since_edge as f32 * tick_s > self.cfg.timeout_s {
            self.accepted_mps = 0.0;
            self.have_speed = false;
            return SpeedReading {
                speed_mps: 0.0,
                status: SpeedStatus::Standstill,
            };
        }
        let mut status = SpeedStatus::Valid;
        if let Some(period) = s.new_period_ticks {
            let v = self.speed_from_period(period);
            let elapsed_s = self.ticks_since_accept as f32 * tick_s;
            let allowed = self.cfg.max_accel_mps2 * elapsed_s + self.cfg.jump_margin_mps;
            let plausible =
                v.is_finite() && (!self.have_speed || (v - self.accepted_mps).abs() <= allowed);
            if plausible {
                self.accepted_mps = v;
                self.have_speed = true;
                self.ticks_since_accept = 0;
            } else {
                self.implausible_count = self.implausible_count.saturating_add(1);
                status = SpeedStatus::Implausible;
            }
        }
        if !self.have_speed {
            // Edges seen but no complete period yet (just started rolling, or a restart while
            // driving): unknown, not standstill.
            return SpeedReading {
                speed_mps: 0.0,
                status: SpeedStatus::Starting,
            };
        }
        // Between edges: no faster than one pulse distance over the time since the last edge.
        let bound = if s.ticks_since_edge == 0 {
            f32::INFINITY
        } else {
            self.metres_per_pulse / (s.ticks_since_edge as f32 * tick_s)
        };
        SpeedReading {
            speed_mps: self.accepted_mps.min(bound),
            status,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One capture sample: the newest complete period (if an edge came) and the ticks since
    /// the last edge.
    fn pulse(new_period_ticks: Option<u32>, ticks_since_edge: u32) -> PulseSample {
        PulseSample {
            new_period_ticks,
            ticks_since_edge,
        }
    }

    fn cfg() -> SpeedConfig {
        SpeedConfig {
            pulses_per_rev: 48,
            rolling_radius_m: 0.35,
            tick_hz: 1_000_000,
            timeout_s: 0.5,
            max_accel_mps2: 12.0,
            jump_margin_mps: 0.5,
        }
    }

    #[test]
    fn period_to_speed() {
        let w = WheelSpeed::new(cfg());
        // 20 m/s: one revolution (2 pi 0.35 m) takes 0.10996 s, one of 48 pulses 2290.8 us.
        let period_s = 2.0 * std::f64::consts::PI * 0.35 / 48.0 / 20.0;
        let ticks = (period_s * 1e6).round() as u32;
        let v = w.speed_from_period(ticks);
        // Tolerance: rounding the period to whole ticks, 0.5/2291 relative.
        assert!((v - 20.0).abs() < 20.0 * 0.5 / 2290.0 + 1e-4, "{v}");
    }

    #[test]
    fn timeout_gives_standstill() {
        let mut w = WheelSpeed::new(cfg());
        let r = w.update(pulse(Some(2291), 10), 1000);
        assert_eq!(r.status, SpeedStatus::Valid);
        assert!(r.speed_mps > 19.9);
        // No edges for 0.5 s + 1 tick: standstill.
        let r = w.update(pulse(None, 500_001), 1000);
        assert_eq!(r.status, SpeedStatus::Standstill);
        assert_eq!(r.speed_mps, 0.0);
    }

    #[test]
    fn decays_between_edges() {
        let mut w = WheelSpeed::new(cfg());
        w.update(pulse(Some(2291), 0), 1000);
        // 10 ms without an edge: at most 45.8 mm / 10 ms = 4.58 m/s.
        let r = w.update(pulse(None, 10_000), 1000);
        let bound = 2.0 * PI * 0.35 / 48.0 / 0.01;
        assert!((r.speed_mps - bound).abs() < 1e-4, "{}", r.speed_mps);
    }

    #[test]
    fn implausible_jump_is_flagged_and_held() {
        let mut w = WheelSpeed::new(cfg());
        let first = w.update(pulse(Some(2291), 0), 1000);
        // Half the period one step later: 40 m/s after 1 ms is 20,000 m/s^2.
        let r = w.update(pulse(Some(1145), 0), 1000);
        assert_eq!(r.status, SpeedStatus::Implausible);
        assert_eq!(r.speed_mps, first.speed_mps);
        assert_eq!(w.implausible_count(), 1);
        // A slightly faster period (within 12 m/s^2 * 2 ms + 0.5 m/s) is accepted.
        let r = w.update(pulse(Some(2250), 0), 1000);
        assert_eq!(r.status, SpeedStatus::Valid);
        assert!(r.speed_mps > first.speed_mps);
    }
}
