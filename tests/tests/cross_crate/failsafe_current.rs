//! The supervisor's fail-safe coil current
//! (`shimmy_core::control::actuator::FAILSAFE_CURRENT_A`) is derived here from the stability
//! analysis, not guessed:
//!
//! 1. Plant variants: the `nominal` and `hard` sets, each as is and with the tyre data
//!    C_a, sigma, e scaled by 0.8 and 1.2 one at a time (14 plants).
//! 2. The MR damper at a constant current I enters the linear analysis through its
//!    energy-equivalent viscous coefficient (describing function,
//!    `shimmy_sim::model::damper_equiv::mr_equivalent_viscous`). The MR damper is friction-like, so
//!    c_eq falls with amplitude and changes with frequency: the coefficient used is the least
//!    over the shimmy frequencies of the variants' Hopf crossings (no damper) and wheel-yaw
//!    amplitudes 0.5, 1, 2 and 3 deg (3 deg is the time-domain check's start).
//! 3. c_req = the least viscous coefficient (bisection) for which every variant of a family has no
//!    in-phase Hopf crossing in 0.1 m/s-150 km/h and is stable at the lowest speed
//!    (`hopf_crossings` + `critical_mode_at`); I_min(amplitude) = the least current whose c_eq
//!    is >= 1.2 c_req.
//! 4. The constant must be >= 1.25 I_min(0.5 deg) of the nominal family (the design basis);
//!    where the requirement cannot be met within the coil rating (larger amplitudes, the hard
//!    family) the constant must be the rating itself.
//! 5. Time domain: the nonlinear simulator with the Spencer MR damper held at the constant,
//!    5-130 km/h: nominal set from 3 deg and hard set from 0.5 deg must decay; at 0 A the same
//!    check must find shimmy (the check can fail). The hard set from 3 deg does not recover
//!    even at full current (asserted as a documented limitation).
//!
//! The zero-current speed `ZERO_CURRENT_SAFE_BELOW_MPS` is checked the same way: below it every
//! variant is stable with no damper at all.

use shimmy_core::control::actuator::FAILSAFE_CURRENT_A;
use shimmy_core::mr_damper::SpencerParams;
use shimmy_core::stability::{critical_mode_at, hopf_crossings, V_SEARCH_MIN_MPS};
use shimmy_core::supervisor::params::ZERO_CURRENT_SAFE_BELOW_MPS;
use shimmy_core::units::{kmh_to_mps, mps_to_kmh};
use shimmy_core::vehicles::car::{Param, ParamSet, PlantParams};
use shimmy_sim::model::damper_equiv::mr_equivalent_viscous;
use shimmy_sim::sim::run::open_loop::{run_speed, DamperSetting};

/// Safety margin on the current.
const MARGIN: f64 = 1.25;
/// Wheel-yaw amplitudes of the describing function [deg].
const AMPS_DEG: [f64; 4] = [0.5, 1.0, 2.0, 3.0];
/// Grid step of the Hopf search [m/s] (crossings closer than this could be missed; the windows
/// are >= 5 m/s wide when they exist).
const STEP_MPS: f64 = 0.25;

/// Upper edge of the shimmy band [Hz].
const SHIMMY_BAND_HI_HZ: f64 = 20.0;

/// Highest speed analysed [m/s]: 150 km/h, above the top speed of a solid-steered-axle vehicle.
fn v_max_mps() -> f64 {
    kmh_to_mps(150.0)
}

fn variants() -> Vec<(String, PlantParams)> {
    let mut v = family(ParamSet::Nominal);
    v.extend(family(ParamSet::Hard));
    v
}

/// A named set with C_a, sigma, e scaled by 0.8 and 1.2 one at a time (7 plants).
fn family(set: ParamSet) -> Vec<(String, PlantParams)> {
    let mut out = Vec::new();
    {
        let base = set.params();
        out.push((set.name().to_string(), base));
        for p in [Param::CA, Param::Sigma, Param::E] {
            for f in [0.8, 1.2] {
                out.push((
                    format!("{} {}x{f}", set.name(), p.name()),
                    base.scaled(p, f),
                ));
            }
        }
    }
    out
}

/// Stable over the whole speed range with viscous damper `c`: no Hopf crossing and stable at
/// the lowest speed.
fn stable_everywhere(p: &PlantParams, c: f64) -> bool {
    let crossings =
        hopf_crossings(p, c, V_SEARCH_MIN_MPS, v_max_mps(), STEP_MPS, 1e-3).expect("hopf");
    let g0 = critical_mode_at(p, V_SEARCH_MIN_MPS, c).expect("eig").re;
    crossings.is_empty() && g0 < 0.0
}

/// Shimmy frequencies [Hz] of the variants' crossings without a damper.
fn shimmy_freqs(vars: &[(String, PlantParams)]) -> Vec<f64> {
    let mut f = Vec::new();
    for (_, p) in vars {
        let c =
            hopf_crossings(p, 0.0, V_SEARCH_MIN_MPS, v_max_mps(), STEP_MPS, 1e-3).expect("hopf");
        // In-phase shimmy crossings only: the ~47 Hz anti-phase mode that some +20 % variants
        // lose above ~200 km/h does not move the damper (its stroke is in-phase only).
        f.extend(
            c.iter()
                .map(|x| x.freq_hz)
                .filter(|f| *f < SHIMMY_BAND_HI_HZ),
        );
    }
    f
}

/// Least equivalent viscous coefficient [N s/m] of the MR damper at `current_a` and wheel-yaw
/// amplitude `amp_deg` over the shimmy frequencies `freqs`.
fn c_eq_min(current_a: f64, freqs: &[f64], amp_deg: f64, l_t_m: f64) -> f64 {
    let sp = SpencerParams::steering();
    freqs
        .iter()
        .map(|&f| mr_equivalent_viscous(&sp, current_a, f, l_t_m * amp_deg.to_radians()))
        .fold(f64::INFINITY, f64::min)
}

fn freq_extremes(freqs: &[f64]) -> Vec<f64> {
    let lo = freqs.iter().cloned().fold(f64::INFINITY, f64::min);
    let hi = freqs.iter().cloned().fold(0.0, f64::max);
    vec![lo, hi]
}

/// Bisection for the least x in [lo, hi] with `ok(x)` (monotone), to `tol`.
fn least(mut lo: f64, mut hi: f64, tol: f64, ok: impl Fn(f64) -> bool) -> Option<f64> {
    if ok(lo) {
        return Some(lo);
    }
    if !ok(hi) {
        return None;
    }
    while hi - lo > tol {
        let mid = 0.5 * (lo + hi);
        if ok(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    Some(hi)
}

struct Requirement {
    /// Least viscous coefficient that removes every variant's window [N s/m].
    c_req: f64,
    /// Least current [A] per describing-function amplitude (None: not reachable within u_max).
    i_min: Vec<(f64, Option<f64>)>,
}

fn requirement(vars: &[(String, PlantParams)]) -> Requirement {
    let freqs = freq_extremes(&shimmy_freqs(vars));
    let l_t = vars.iter().map(|v| v.1.l_t).fold(f64::INFINITY, f64::min);
    let c_req = least(0.0, 20_000.0, 10.0, |c| {
        vars.iter().all(|(_, p)| stable_everywhere(p, c))
    })
    .expect("some viscous damping stabilises every variant");
    assert!(c_req > 0.0, "no damper needed: nothing to compute");
    let u_max = SpencerParams::steering().u_max;
    let i_min = AMPS_DEG
        .iter()
        .map(|&a| {
            let i = least(0.0, u_max, 0.005, |i| {
                c_eq_min(i, &freqs, a, l_t) >= MARGIN_C * c_req
            });
            (a, i)
        })
        .collect();
    println!(
        "shimmy freqs {:.2}-{:.2} Hz; c_req = {c_req:.0} N s/m (I_min needs c_eq >= {MARGIN_C} c_req)",
        freqs[0], freqs[1]
    );
    Requirement { c_req, i_min }
}

/// Margin on the equivalent damping.
const MARGIN_C: f64 = 1.2;

#[test]
fn failsafe_current_removes_every_hopf_window_with_margin() {
    let u_max = SpencerParams::steering().u_max;
    // Nominal family at the reference amplitude 0.5 deg: the design basis, with the margins on
    // c (x1.2) and on the current (x1.25).
    let nom = requirement(&family(ParamSet::Nominal));
    let i_ref = nom.i_min[0]
        .1
        .expect("nominal, 0.5 deg: reachable within the coil rating");
    println!("  nominal family: c_req = {:.0} N s/m", nom.c_req);
    assert!(
        f64::from(FAILSAFE_CURRENT_A) >= MARGIN * i_ref,
        "FAILSAFE_CURRENT_A = {FAILSAFE_CURRENT_A} A < {MARGIN} x I_min(0.5 deg) = {:.3} A",
        MARGIN * i_ref
    );
    // Larger amplitudes (the friction-like damper's c_eq falls with amplitude): where the
    // requirement is unmet, the fail-safe current must be the rating (c_eq grows with the
    // current at every amplitude, so the most current is the best fixed choice). The time
    // domain test shows the nominal set recovers from 3 deg at this current.
    for (a, i) in &nom.i_min {
        println!("  nominal family, {a} deg: I_min = {i:?} A");
        let ok = i.is_some_and(|i| f64::from(FAILSAFE_CURRENT_A) >= MARGIN * i);
        assert!(
            ok || f64::from(FAILSAFE_CURRENT_A) == u_max,
            "nominal, {a} deg: requirement unmet and the fail-safe current is not the rating"
        );
    }
    // Hard family: report what it needs. If no current within the coil rating meets the
    // requirement, the fail-safe current must be the rating itself (c_eq grows with the
    // current at every amplitude, so the most current is the best fixed choice).
    let hard = requirement(&family(ParamSet::Hard));
    println!("  hard family: c_req = {:.0} N s/m", hard.c_req);
    for (a, i) in &hard.i_min {
        println!("  hard family, {a} deg: I_min = {i:?} A");
        let ok = i.is_some_and(|i| f64::from(FAILSAFE_CURRENT_A) >= MARGIN * i);
        assert!(
            ok || f64::from(FAILSAFE_CURRENT_A) == u_max,
            "hard, {a} deg: requirement unmet and the fail-safe current is not the rating"
        );
    }
    assert!(
        f64::from(FAILSAFE_CURRENT_A) <= u_max,
        "beyond the coil rating"
    );
}

/// Peak |psi_L| [deg] in the last second of a 4 s run from an in-phase start `psi0_deg`.
fn end_amplitude_deg(set: ParamSet, setting: DamperSetting, v_kmh: f64, psi0_deg: f64) -> f64 {
    let r = run_speed(
        &set.params(),
        setting,
        kmh_to_mps(v_kmh),
        psi0_deg.to_radians(),
        4.0,
        1.0,
    )
    .expect("integrate");
    r.amp_end_rad.to_degrees()
}

/// The oscillation has died out: below 30 % of the start after 3-4 s (the MR damper's yield
/// force may hold the wheels at a small static angle, which is not shimmy; a developed limit
/// cycle grows instead).
const DECAY_FRACTION: f64 = 0.3;

fn speeds_kmh() -> Vec<f64> {
    (1..=26).map(|k| 5.0 * k as f64).collect()
}

#[test]
fn failsafe_current_stops_shimmy_in_the_time_domain() {
    let fs = DamperSetting::reference_mr(f64::from(FAILSAFE_CURRENT_A));
    // Nominal set from 3 deg, hard set from the 0.5 deg design amplitude: no shimmy anywhere.
    for (set, psi0) in [(ParamSet::Nominal, 3.0), (ParamSet::Hard, 0.5)] {
        for v in speeds_kmh() {
            let a = end_amplitude_deg(set, fs, v, psi0);
            assert!(
                a < DECAY_FRACTION * psi0,
                "{} from {psi0} deg: shimmy at {v} km/h with {FAILSAFE_CURRENT_A} A: {a:.2} deg",
                set.name()
            );
        }
        // Negative: without current the same check finds shimmy somewhere.
        let worst = speeds_kmh()
            .into_iter()
            .map(|v| end_amplitude_deg(set, DamperSetting::reference_mr(0.0), v, psi0))
            .fold(0.0, f64::max);
        assert!(
            worst > DECAY_FRACTION * psi0,
            "{}: 0 A shows no shimmy ({worst:.2} deg): the check is blind",
            set.name()
        );
    }
}

/// Documented limitation (asserted so a model change shows up): on the hard set a 3 deg
/// disturbance at 20 km/h grows into shimmy even at the coil's full 2 A. No fixed current can
/// make the hard set safe against large disturbances; there the active controller (and the
/// warning) are needed, and the fail-safe state is "the most damping the damper has".
#[test]
fn hard_set_large_disturbance_beats_any_fixed_current() {
    let a = end_amplitude_deg(
        ParamSet::Hard,
        DamperSetting::reference_mr(SpencerParams::steering().u_max),
        20.0,
        3.0,
    );
    println!("hard set, 20 km/h, 3 deg start, full current: {a:.2} deg after 4 s");
    assert!(
        a > 3.0,
        "hard set now recovers from 3 deg at full current: revisit the docs"
    );
}

#[test]
fn zero_current_is_safe_below_the_lowest_onset() {
    let mut lowest = f64::INFINITY;
    for (name, p) in variants() {
        let g0 = critical_mode_at(&p, V_SEARCH_MIN_MPS, 0.0).expect("eig").re;
        assert!(
            g0 < 0.0,
            "{name}: unstable at the lowest speed without damper"
        );
        let c =
            hopf_crossings(&p, 0.0, V_SEARCH_MIN_MPS, v_max_mps(), STEP_MPS, 1e-3).expect("hopf");
        if let Some(first) = c.first() {
            lowest = lowest.min(first.speed_mps);
        }
    }
    println!(
        "lowest Hopf onset without damper: {:.2} km/h; zero-current limit {:.2} km/h",
        mps_to_kmh(lowest),
        mps_to_kmh(f64::from(ZERO_CURRENT_SAFE_BELOW_MPS))
    );
    assert!(
        f64::from(ZERO_CURRENT_SAFE_BELOW_MPS) <= 0.8 * lowest,
        "zero-current speed not 20 % below the lowest onset {lowest:.3} m/s"
    );
}
