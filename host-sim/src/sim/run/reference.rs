//! The reference line of a run: the eigenvalue of the plant *as it runs*, the truth the mode
//! meter's estimate is plotted against.
//!
//! At each reference time the operating point is read off the run: the speed, the mean coil
//! current over [`CURRENT_WINDOW_S`] and the in-phase wheel-yaw envelope at that time. The MR
//! damper enters the linearisation as its energy-equivalent viscous coefficient c_eq at that
//! current, amplitude and the mode's own frequency (describing function,
//! [`crate::model::damper_equiv`]; a two-pass fixed point on the frequency). The damper at 0 A
//! is not "no damper": its yield force and viscous part still dissipate energy, most of all at
//! small amplitude. Only a run without damper (`Arm::NoDamper`) gets c = 0.
//!
//! The tyres stay linear in it: in a developed limit cycle (a few degrees) the Magic Formula
//! saturates, the run's damping is zero and the line stays below it; the line holds where the
//! tyres are linear (`host-sim/tests/sim/reference_line.rs`: within 5 % of the measured growth at
//! 0.1-0.7 deg).
//!
//! The mode is the shimmy mode tracked by its shape (`ModeSelect::Shimmy`: the least-damped
//! in-phase wheel-yaw mode), never simply the least-damped mode, which at some speeds is another
//! mode (e.g. the anti-phase wheel-yaw mode near 47 Hz).

use crate::model::damper_equiv::{mr_equivalent_viscous, stroke_amplitude_m};
use crate::model::family::SimModel;
use crate::sim::run::closed_loop::{Arm, LoopConfig, LoopResult, TraceRow};
use rayon::prelude::*;
use shimmy_core::eigen::{EigenError, Mode};
use shimmy_core::mr_damper::SpencerParams;
use shimmy_core::stability::{mode_at, ModeSelect};

/// What the reference line is, for legends and captions.
pub const REFERENCE_LABEL: &str =
    "shimmy mode of A(V) with the damper's c_eq at the run's current and amplitude";

/// Amplitudes below this (rad, ~0.001 deg: a few encoder quanta of noise) are taken as this:
/// the describing function of a friction damper diverges as the amplitude goes to 0.
pub const MIN_AMPLITUDE_RAD: f64 = 2e-5;

/// The coil current of the operating point is the mean over this window around each time, s
/// (several shimmy periods: a controller's current changes within one).
pub const CURRENT_WINDOW_S: f64 = 1.0;

/// One point of the reference line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RefPoint {
    /// Time, s.
    pub t_s: f64,
    /// Speed, m/s.
    pub speed_mps: f64,
    /// Mean coil current over the window, A.
    pub current_a: f64,
    /// Peak in-phase wheel yaw over the window, rad.
    pub amplitude_rad: f64,
    /// Equivalent viscous coefficient of the damper, N s/m (0 without damper).
    pub c_eq_nspm: f64,
    /// The shimmy mode at this operating point.
    pub mode: Mode,
}

/// The shimmy mode of `p` at `v_mps` with the damper `damper` (`None`: no damper) held at
/// `current_a` and oscillating with in-phase wheel-yaw amplitude `amplitude_rad`; with its c_eq.
pub fn shimmy_mode_with_damper<M: SimModel<N>, const N: usize>(
    p: &M,
    damper: Option<&SpencerParams>,
    v_mps: f64,
    current_a: f64,
    amplitude_rad: f64,
) -> Result<(Mode, f64), EigenError> {
    let lin = p.linear();
    let m0 = mode_at(&lin, v_mps, 0.0, ModeSelect::Shimmy)?;
    let Some(sp) = damper else {
        return Ok((m0, 0.0));
    };
    let amp_m = stroke_amplitude_m(p.steering_arm_m(), amplitude_rad.max(MIN_AMPLITUDE_RAD));
    let mut c = mr_equivalent_viscous(sp, current_a, m0.freq_hz, amp_m);
    let mut m = mode_at(&lin, v_mps, c, ModeSelect::Shimmy)?;
    // The damper stiffens and damps the mode, which moves its frequency; one more pass at the
    // new frequency (the frequency moves little with c).
    c = mr_equivalent_viscous(sp, current_a, m.freq_hz, amp_m);
    m = mode_at(&lin, v_mps, c, ModeSelect::Shimmy)?;
    Ok((m, c))
}

/// The in-phase wheel-yaw envelope of a trace: the peaks of |(psi_L + psi_R) / 2| (one per
/// half cycle) as (time, amplitude), in time order.
pub fn yaw_peaks(trace: &[TraceRow]) -> Vec<(f64, f64)> {
    let y: Vec<f64> = trace
        .iter()
        .map(|r| (0.5 * (r.psi_l_rad + r.psi_r_rad)).abs())
        .collect();
    (1..y.len().saturating_sub(1))
        .filter(|&k| y[k] >= y[k - 1] && y[k] > y[k + 1])
        .map(|k| (trace[k].t_s, y[k]))
        .collect()
}

/// The envelope at `t`: log-linear between the peaks around it (the first or last peak outside
/// their span; 0 without peaks).
fn envelope_at(peaks: &[(f64, f64)], t: f64) -> f64 {
    let after = peaks.partition_point(|p| p.0 <= t);
    match (
        after.checked_sub(1).and_then(|i| peaks.get(i)),
        peaks.get(after),
    ) {
        (Some(&(ta, a)), Some(&(tb, b))) if a > 0.0 && b > 0.0 => {
            a * (b / a).powf((t - ta) / (tb - ta))
        }
        (Some(&(_, a)), _) => a,
        (None, Some(&(_, b))) => b,
        (None, None) => 0.0,
    }
}

/// The reference line of run `r` of `cfg`, one point every `every_s` seconds of its trace
/// ([`reference_at`] on that grid).
pub fn reference_line<M: SimModel<N>, const N: usize>(
    cfg: &LoopConfig<M, N>,
    r: &LoopResult,
    every_s: f64,
) -> Vec<RefPoint> {
    let (Some(first), Some(last)) = (r.trace.first(), r.trace.last()) else {
        return Vec::new();
    };
    let n = ((last.t_s - first.t_s) / every_s).floor() as usize + 1;
    let times: Vec<f64> = (0..n).map(|k| first.t_s + k as f64 * every_s).collect();
    reference_at(cfg, r, &times)
}

/// The reference points of run `r` of `cfg` at `times` (computed in parallel): at each time the
/// speed, the mean coil current over [`CURRENT_WINDOW_S`] and the wheel-yaw envelope
/// ([`yaw_peaks`], interpolated). Times where no shimmy mode is found are left out.
pub fn reference_at<M: SimModel<N>, const N: usize>(
    cfg: &LoopConfig<M, N>,
    r: &LoopResult,
    times: &[f64],
) -> Vec<RefPoint> {
    let damper = match cfg.arm {
        Arm::NoDamper => None,
        Arm::Mr(_) => Some(cfg.damper),
    };
    let trace = &r.trace;
    let Some(last) = trace.last() else {
        return Vec::new();
    };
    let peaks = yaw_peaks(trace);
    times
        .par_iter()
        .filter_map(|&t| {
            // The trace is in time order: binary searches, not scans.
            let speed = trace
                .get(trace.partition_point(|row| row.t_s < t))
                .map_or(last.speed_mps, |row| row.speed_mps)
                .max(0.1);
            let half = 0.5 * CURRENT_WINDOW_S;
            let window = &trace[trace.partition_point(|row| row.t_s < t - half)
                ..trace.partition_point(|row| row.t_s <= t + half)];
            let current = if window.is_empty() {
                0.0
            } else {
                window.iter().map(|row| row.coil_a).sum::<f64>() / window.len() as f64
            };
            let amp = envelope_at(&peaks, t);
            let (mode, c) =
                shimmy_mode_with_damper(&cfg.plant, damper.as_ref(), speed, current, amp).ok()?;
            Some(RefPoint {
                t_s: t,
                speed_mps: speed,
                current_a: current,
                amplitude_rad: amp,
                c_eq_nspm: c,
                mode,
            })
        })
        .collect()
}
