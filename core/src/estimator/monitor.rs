//! Shimmy monitor: warning levels with hysteresis and a fixed-capacity event log.
//!
//! Levels, in increasing severity:
//! - `Normal`;
//! - `MarginLow`: valid slow damping below `zeta_low_on` or speed margin below `dv_low_on_mps`;
//! - `ApproachingCritical`: valid fast damping below `zeta_crit_on`, or speed margin below
//!   `dv_crit_on_mps`, or time to critical below `ttc_on_s`;
//! - `ShimmyPresent`: yaw envelope amplitude above `amp_on_rad`. This is independent of the
//!   linear margin, so it also catches subcritical (bistable) shimmy below the linear critical
//!   speed.
//!
//! Hysteresis: every condition has an `_on` and a looser `_off` threshold; a level is entered as
//! soon as its `_on` condition holds and left only after its `_off` condition has failed for
//! `release_s` (dwell). Invalid or non-finite inputs never raise or clear a level on their own.
//!
//! Every episode above `Normal` becomes an [`Event`] (start time, speed, frequency, peak amplitude,
//! worst level, duration) in a ring buffer of `N` entries (oldest dropped, drop count kept).

use super::fusion::MarginReport;

/// Warning level.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum Level {
    /// No warning.
    #[default]
    Normal,
    /// Damping or speed margin low.
    MarginLow,
    /// Close to the critical speed or fast damping very low.
    ApproachingCritical,
    /// Shimmy oscillation present (amplitude).
    ShimmyPresent,
}

/// Thresholds (one place).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MonitorParams {
    /// MarginLow when slow zeta < this.
    pub zeta_low_on: f32,
    /// ... cleared when slow zeta > this.
    pub zeta_low_off: f32,
    /// MarginLow when speed margin < this, m/s.
    pub dv_low_on_mps: f32,
    /// ... cleared above, m/s.
    pub dv_low_off_mps: f32,
    /// ApproachingCritical when fast zeta < this.
    pub zeta_crit_on: f32,
    /// ... cleared above.
    pub zeta_crit_off: f32,
    /// ApproachingCritical when speed margin < this, m/s.
    pub dv_crit_on_mps: f32,
    /// ... cleared above, m/s.
    pub dv_crit_off_mps: f32,
    /// ApproachingCritical when time to critical < this, s.
    pub ttc_on_s: f32,
    /// ... cleared above, s.
    pub ttc_off_s: f32,
    /// ShimmyPresent when amplitude > this, rad.
    pub amp_on_rad: f32,
    /// ... cleared below, rad.
    pub amp_off_rad: f32,
    /// A level's release condition must hold this long before it is left, s.
    pub release_s: f32,
    /// The damping thresholds compare zeta + `data_sigmas` x its reported sigma: a data
    /// level is raised only when the estimate is below the threshold by that many of its own
    /// sigmas (0: the estimate itself).
    pub data_sigmas: f32,
    /// `MarginLow` on the speed margin compares the margin + `margin_sigmas` x its model-side
    /// sigma: the advisory level waits until the margin is low with that confidence, the
    /// critical level does not wait (it compares the margin itself).
    pub margin_sigmas: f32,
}

impl Default for MonitorParams {
    fn default() -> Self {
        Self {
            zeta_low_on: 0.04,
            zeta_low_off: 0.05,
            dv_low_on_mps: 5.0,
            dv_low_off_mps: 6.0,
            zeta_crit_on: 0.02,
            zeta_crit_off: 0.03,
            dv_crit_on_mps: 2.0,
            dv_crit_off_mps: 3.0,
            ttc_on_s: 10.0,
            ttc_off_s: 15.0,
            amp_on_rad: 0.01,
            amp_off_rad: 0.005,
            release_s: 1.0,
            data_sigmas: 0.0,
            margin_sigmas: 1.0,
        }
    }
}

/// One warning episode.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Event {
    /// Start time, s.
    pub start_s: f64,
    /// Speed at the start, m/s.
    pub speed_mps: f32,
    /// Data frequency at the start (or at the amplitude peak once shimmy is present), Hz.
    pub freq_hz: f32,
    /// Peak amplitude during the episode, rad.
    pub peak_amplitude_rad: f32,
    /// Worst level reached.
    pub worst: Level,
    /// Duration, s (grows while the episode is open).
    pub duration_s: f32,
    /// Time spent in `ShimmyPresent` during the episode, s.
    pub shimmy_s: f32,
    /// The episode is still open.
    pub open: bool,
}

/// Monitor inputs of one step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MonitorInput<'a> {
    /// Time, s (`f64`, as in `FusionInput::t_s`).
    pub t_s: f64,
    /// Yaw envelope amplitude (peak), rad.
    pub amplitude_rad: f32,
    /// Fused margin report.
    pub report: &'a MarginReport,
    /// One-sigma uncertainty of the report's speed margin from the model side (the online
    /// model update's posterior; 0 when the model is taken as known), m/s.
    pub speed_margin_sigma_mps: f32,
}

/// The shimmy monitor with an event log of capacity `N`.
#[derive(Clone, Debug)]
pub struct Monitor<const N: usize> {
    params: MonitorParams,
    level: Level,
    release_since: Option<f64>,
    events: heapless::Deque<Event, N>,
    dropped: u32,
    open: Option<Event>,
    last_t: f64,
}

fn lt(x: Option<f32>, th: f32) -> bool {
    x.is_some_and(|v| v.is_finite() && v < th)
}

impl<const N: usize> Monitor<N> {
    /// New monitor.
    pub fn new(params: MonitorParams) -> Self {
        Self {
            params,
            level: Level::Normal,
            release_since: None,
            events: heapless::Deque::new(),
            dropped: 0,
            open: None,
            last_t: 0.0,
        }
    }

    /// Thresholds.
    pub fn params(&self) -> &MonitorParams {
        &self.params
    }

    /// Current level.
    pub fn level(&self) -> Level {
        self.level
    }

    /// Closed events, oldest first, plus the open one (last) if any.
    pub fn events(&self) -> impl Iterator<Item = &Event> {
        self.events.iter().chain(self.open.as_ref())
    }

    /// Events dropped because the log was full.
    pub fn dropped_events(&self) -> u32 {
        self.dropped
    }

    /// The level whose `_on` (`strict` = true) or `_off` (false) condition holds now.
    fn condition_level(&self, inp: &MonitorInput<'_>, strict: bool) -> Level {
        let p = &self.params;
        let r = inp.report;
        let pick = |on: f32, off: f32| if strict { on } else { off };
        let amp = inp.amplitude_rad;
        // "off" conditions for the amplitude are "amplitude still above amp_off"
        if amp.is_finite() && amp > pick(p.amp_on_rad, p.amp_off_rad) {
            return Level::ShimmyPresent;
        }
        let k = p.data_sigmas;
        let fast = r.fast_valid.then_some(r.zeta_fast + k * r.sigma_zeta_fast);
        let slow = r.data_valid.then_some(r.zeta_data + k * r.sigma_zeta_data);
        let dv = if r.valid { r.speed_margin_mps } else { None };
        let ttc = if r.valid { r.time_to_critical_s } else { None };
        if lt(fast, pick(p.zeta_crit_on, p.zeta_crit_off))
            || lt(dv, pick(p.dv_crit_on_mps, p.dv_crit_off_mps))
            || lt(ttc, pick(p.ttc_on_s, p.ttc_off_s))
        {
            return Level::ApproachingCritical;
        }
        let sigma_dv = inp.speed_margin_sigma_mps;
        let dv_low = if sigma_dv.is_finite() && sigma_dv > 0.0 {
            dv.map(|d| d + p.margin_sigmas * sigma_dv)
        } else {
            dv
        };
        if lt(slow, pick(p.zeta_low_on, p.zeta_low_off))
            || lt(dv_low, pick(p.dv_low_on_mps, p.dv_low_off_mps))
        {
            return Level::MarginLow;
        }
        Level::Normal
    }

    /// One monitor step; returns the (possibly new) level.
    pub fn update(&mut self, inp: &MonitorInput<'_>) -> Level {
        let t = inp.t_s;
        if !t.is_finite() {
            return self.level;
        }
        let on = self.condition_level(inp, true);
        let hold = self.condition_level(inp, false);
        let prev = self.level;
        if on > self.level {
            self.level = on;
            self.release_since = None;
        } else if hold < self.level {
            let since = *self.release_since.get_or_insert(t);
            if (t - since) as f32 >= self.params.release_s {
                // drop to the highest level whose hold condition still holds
                self.level = hold.max(on);
                self.release_since = None;
            }
        } else {
            self.release_since = None;
        }
        self.log(prev, inp);
        self.level
    }

    fn log(&mut self, prev: Level, inp: &MonitorInput<'_>) {
        let last_t = self.last_t;
        self.last_t = inp.t_s;
        let t = inp.t_s;
        let amp = if inp.amplitude_rad.is_finite() {
            inp.amplitude_rad
        } else {
            0.0
        };
        if prev == Level::Normal && self.level > Level::Normal {
            self.open = Some(Event {
                start_s: t,
                speed_mps: inp.report.speed_mps,
                freq_hz: inp.report.freq_hz,
                peak_amplitude_rad: amp,
                worst: self.level,
                duration_s: 0.0,
                shimmy_s: 0.0,
                open: true,
            });
        }
        if let Some(ev) = self.open.as_mut() {
            if prev == Level::ShimmyPresent {
                ev.shimmy_s += ((t - last_t) as f32).max(0.0);
            }
            ev.duration_s = (t - ev.start_s) as f32;
            if self.level > ev.worst {
                ev.worst = self.level;
            }
            if amp > ev.peak_amplitude_rad {
                ev.peak_amplitude_rad = amp;
                if self.level == Level::ShimmyPresent && inp.report.freq_hz > 0.0 {
                    ev.freq_hz = inp.report.freq_hz;
                }
            }
            if self.level == Level::Normal {
                ev.open = false;
                // Through an opaque local: copied straight from `self.open` into the deque the
                // move compiles to a `memmove` (may overlap), which alone links 1.4 KB of flash.
                let closed = core::hint::black_box(*ev);
                self.open = None;
                if self.events.is_full() {
                    let _ = self.events.pop_front();
                    self.dropped = self.dropped.saturating_add(1);
                }
                let _ = self.events.push_back(closed);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report(zeta_slow: f32, zeta_fast: f32, dv: Option<f32>) -> MarginReport {
        MarginReport {
            zeta_data: zeta_slow,
            zeta_fast,
            sigma_zeta_data: 0.01,
            sigma_zeta_fast: 0.01,
            freq_hz: 8.0,
            speed_mps: 20.0,
            speed_margin_mps: dv,
            data_valid: true,
            fast_valid: true,
            valid: dv.is_some(),
            model_consistent: true,
            ..MarginReport::default()
        }
    }

    #[test]
    fn hysteresis_levels_and_dwell() {
        let mut m = Monitor::<4>::new(MonitorParams::default());
        let mut t = 0.0;
        let mut step = |m: &mut Monitor<4>, r: &MarginReport, amp: f32, dt: f32| {
            t += f64::from(dt);
            m.update(&MonitorInput {
                t_s: t,
                amplitude_rad: amp,
                report: r,
                speed_margin_sigma_mps: 0.0,
            })
        };
        assert_eq!(
            step(&mut m, &report(0.08, 0.08, Some(20.0)), 0.0, 0.01),
            Level::Normal
        );
        // slow zeta 0.039 < 0.04 -> MarginLow at once
        assert_eq!(
            step(&mut m, &report(0.039, 0.06, Some(20.0)), 0.0, 0.01),
            Level::MarginLow
        );
        // 0.045 is between on (0.04) and off (0.05): stays MarginLow for ever
        for _ in 0..500 {
            assert_eq!(
                step(&mut m, &report(0.045, 0.06, Some(20.0)), 0.0, 0.01),
                Level::MarginLow
            );
        }
        // above off: leaves only after the 1 s dwell
        for _ in 0..99 {
            assert_eq!(
                step(&mut m, &report(0.06, 0.06, Some(20.0)), 0.0, 0.01),
                Level::MarginLow
            );
        }
        for _ in 0..3 {
            step(&mut m, &report(0.06, 0.06, Some(20.0)), 0.0, 0.01);
        }
        assert_eq!(m.level(), Level::Normal);
        // speed margin below 2 m/s -> ApproachingCritical; amplitude -> ShimmyPresent
        assert_eq!(
            step(&mut m, &report(0.06, 0.06, Some(1.5)), 0.0, 0.01),
            Level::ApproachingCritical
        );
        assert_eq!(
            step(&mut m, &report(0.06, 0.06, Some(1.5)), 0.02, 0.01),
            Level::ShimmyPresent
        );
        // amplitude 0.007 is between off (0.005) and on: stays
        for _ in 0..300 {
            assert_eq!(
                step(&mut m, &report(0.06, 0.06, Some(1.5)), 0.007, 0.01),
                Level::ShimmyPresent
            );
        }
        // amplitude gone, margin still critical -> falls back to ApproachingCritical after dwell
        for _ in 0..120 {
            step(&mut m, &report(0.06, 0.06, Some(1.5)), 0.001, 0.01);
        }
        assert_eq!(m.level(), Level::ApproachingCritical);
        // invalid data does not raise warnings
        let mut inv = report(0.0, 0.0, None);
        inv.data_valid = false;
        inv.fast_valid = false;
        let mut m2 = Monitor::<4>::new(MonitorParams::default());
        assert_eq!(
            m2.update(&MonitorInput {
                t_s: 0.0,
                amplitude_rad: 0.0,
                report: &inv,
                speed_margin_sigma_mps: 0.0,
            }),
            Level::Normal
        );
    }

    /// The advisory level on the speed margin waits for confidence: a margin of 4.5 m/s
    /// (below the 5 m/s threshold) with a model-side sigma of 1 m/s raises nothing, the same
    /// margin known exactly raises `MarginLow`; the critical level (below 2 m/s) does not wait.
    #[test]
    fn margin_low_waits_for_a_confident_margin() {
        let level = |dv: f32, sigma: f32| {
            let mut m = Monitor::<4>::new(MonitorParams::default());
            m.update(&MonitorInput {
                t_s: 0.0,
                amplitude_rad: 0.0,
                report: &report(0.08, 0.08, Some(dv)),
                speed_margin_sigma_mps: sigma,
            })
        };
        assert_eq!(level(4.5, 0.0), Level::MarginLow);
        assert_eq!(level(4.5, 1.0), Level::Normal);
        assert_eq!(level(3.5, 1.0), Level::MarginLow);
        assert_eq!(level(1.5, 5.0), Level::ApproachingCritical);
    }

    #[test]
    fn event_log_records_episodes_and_drops_oldest() {
        let mut m = Monitor::<2>::new(MonitorParams::default());
        let mut t = 0.0f64;
        for ep in 0..3 {
            // 2 s quiet, then 3 s shimmy with a peak of 0.02 + ep * 0.01
            for _ in 0..200 {
                t += 0.01;
                m.update(&MonitorInput {
                    t_s: t,
                    amplitude_rad: 0.0,
                    report: &report(0.08, 0.08, Some(20.0)),
                    speed_margin_sigma_mps: 0.0,
                });
            }
            for k in 0..300 {
                t += 0.01;
                let amp = (0.02 + ep as f32 * 0.01) * (1.0 - ((k as f32 - 150.0) / 150.0).abs());
                m.update(&MonitorInput {
                    t_s: t,
                    amplitude_rad: amp,
                    report: &report(0.08, 0.08, Some(20.0)),
                    speed_margin_sigma_mps: 0.0,
                });
            }
        }
        for _ in 0..200 {
            t += 0.01;
            m.update(&MonitorInput {
                t_s: t,
                amplitude_rad: 0.0,
                report: &report(0.08, 0.08, Some(20.0)),
                speed_margin_sigma_mps: 0.0,
            });
        }
        let ev: Vec<Event> = m.events().copied().collect();
        assert_eq!(ev.len(), 2);
        assert_eq!(m.dropped_events(), 1);
        for (e, ep) in ev.iter().zip(1..) {
            assert!(!e.open);
            assert_eq!(e.worst, Level::ShimmyPresent);
            assert!((e.peak_amplitude_rad - (0.02 + ep as f32 * 0.01)).abs() < 1e-3);
            assert_eq!(e.speed_mps, 20.0);
            assert_eq!(e.freq_hz, 8.0);
            // on when amp > 0.01, off after amp < 0.005 plus 1 s dwell: compute from the ramp
            let a = 0.02 + ep as f32 * 0.01;
            // ramp a * k/150 up over 1.5 s, then down: above 0.01 at 1.5 * 0.01 / a,
            // below 0.005 at 1.5 + 1.5 (1 - 0.005 / a), then the 1 s dwell
            let t_on = 1.5 * 0.01 / a;
            let t_off = 1.5 + 1.5 * (1.0 - 0.005 / a) + 1.0;
            assert!(
                (e.duration_s - (t_off - t_on)).abs() < 0.05,
                "dur {} vs {}",
                e.duration_s,
                t_off - t_on
            );
        }
    }

    #[test]
    fn nan_inputs_never_change_state_or_give_nan() {
        let mut m = Monitor::<4>::new(MonitorParams::default());
        let r = report(f32::NAN, f32::NAN, Some(f32::NAN));
        for k in 0..100 {
            let lvl = m.update(&MonitorInput {
                t_s: k as f64 * 0.01,
                amplitude_rad: f32::NAN,
                report: &r,
                speed_margin_sigma_mps: 0.0,
            });
            assert_eq!(lvl, Level::Normal);
        }
        m.update(&MonitorInput {
            t_s: f64::NAN,
            amplitude_rad: 1.0,
            report: &r,
            speed_margin_sigma_mps: 0.0,
        });
        assert_eq!(m.level(), Level::Normal);
        assert_eq!(m.events().count(), 0);
    }
}
