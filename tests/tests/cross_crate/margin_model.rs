//! The incremental model margin (`ModelMarginTracker`) against independent computations:
//! nalgebra's dense Schur solve for the modes (`eigen_vs_nalgebra::reference_eigenvalues`), and
//! a dense max-Re sweep (those eigenvalues on a 0.01 km/h grid) for the Hopf speeds; plus its
//! work bound (<= 1 eigen-solve per call, a full update within 100 calls).
use super::eigen_vs_nalgebra::reference_eigenvalues;
use shimmy_core::eigen::SolveFloat;
use shimmy_core::estimator::model_margin::{ModelMarginConfig, ModelMarginTracker, ModelPoint};
use shimmy_core::stability::CrossingKind;
use shimmy_core::units::{kmh_to_mps, mps_to_kmh};
use shimmy_core::vehicles::car::{ParamSet, PlantParams};

/// max Re over the oscillatory eigenvalues (|Im| > 1e-6 |lambda|) of the reference solve.
fn g_reference(p: &PlantParams, v_mps: f64, c: f64) -> f64 {
    reference_eigenvalues(p, v_mps, c)
        .into_iter()
        .filter(|l| l.im.abs() > 1e-6 * l.norm())
        .map(|l| l.re)
        .fold(f64::NEG_INFINITY, f64::max)
}

/// Hopf speeds [km/h] from a dense sweep: 0.5 km/h grid over 1..150 km/h to find the sign
/// changes, then a 0.01 km/h grid inside each to locate it (midpoint of the last cell).
fn dense_crossings(p: &PlantParams, c: f64) -> Vec<(f64, CrossingKind)> {
    let mut out = Vec::new();
    let mut prev = (1.0, g_reference(p, kmh_to_mps(1.0), c));
    let mut k = 1.5;
    while k <= 150.0 {
        let gk = g_reference(p, kmh_to_mps(k), c);
        if (gk < 0.0) != (prev.1 < 0.0) {
            let mut q = (prev.0, prev.1);
            for i in 1..=50 {
                let x = prev.0 + 0.01 * i as f64;
                let gx = g_reference(p, kmh_to_mps(x), c);
                if (gx < 0.0) != (q.1 < 0.0) {
                    let kind = if q.1 < 0.0 {
                        CrossingKind::Onset
                    } else {
                        CrossingKind::Offset
                    };
                    out.push((0.5 * (q.0 + x), kind));
                    break;
                }
                q = (x, gx);
            }
        }
        prev = (k, gk);
        k += 0.5;
    }
    out
}

/// Runs the tracker at constant speed until a cycle completes; returns the point and the calls
/// used, asserting <= 1 eigen-solve per call.
fn cycle<T: SolveFloat>(
    t: &mut ModelMarginTracker<T>,
    t0: f64,
    v_mps: f64,
    c: f64,
) -> (ModelPoint, usize) {
    for k in 0..1000usize {
        let before = t.total_eigen_solves();
        let r = t.step(t0 + k as f64 * 1e-3, v_mps as f32, c as f32);
        let solves = t.total_eigen_solves() - before;
        assert!(solves <= 1, "{solves} eigen-solves in one call");
        assert_eq!(u64::from(t.solves_last_call()), solves);
        if let Some(p) = r {
            return (p, k + 1);
        }
    }
    panic!("no cycle completed in 1000 calls");
}

#[test]
fn modes_and_critical_speeds_agree_with_nalgebras_schur_and_a_dense_sweep() {
    // Tolerances: eigenvalues 1e-9 relative (both solvers backward stable, as in
    // eigen_vs_nalgebra.rs); critical speeds 0.05 km/h (the requirement; the dense grid itself
    // locates the sign change to +-0.005 km/h and the tracker's Brent tolerance is 1e-4 m/s).
    tracker_agrees_with_the_reference::<f64>(1e-9);
}

#[test]
fn f32_eigen_solves_still_meet_the_critical_speed_requirement() {
    // The firmware's configuration: A rounded to f32, balanced, solved in f32. Eigenvalues are
    // then only as good as f32 rounding of the balanced matrix allows: eps_f32 = 1.2e-7 times
    // the eigenvalue condition numbers (O(10-100) here), so 2e-5 relative to |lambda| (to the
    // mode's omega_n for the real part; measured worst 2.9e-6). The critical speeds must still
    // meet the 0.05 km/h requirement.
    tracker_agrees_with_the_reference::<f32>(2e-5);
}

fn tracker_agrees_with_the_reference<T: SolveFloat>(eig_rel: f64) {
    let cfg = ModelMarginConfig::default();
    let mut worst_kmh = 0.0f64;
    let mut worst_eig = 0.0f64;
    for (set, c) in [
        (ParamSet::Nominal, 0.0),
        (ParamSet::Hard, 0.0),
        (ParamSet::Gentle, 0.0),
        (ParamSet::Nominal, 300.0),
    ] {
        let p = set.params();
        let dense = dense_crossings(&p, c);
        assert!(!dense.is_empty(), "{}: no window", set.name());
        println!("{} c={c}: dense crossings {dense:?}", set.name());
        let mut tr = ModelMarginTracker::<T>::in_precision(p, cfg);
        let mut t0 = 0.0f64;
        for kmh in [5.0, 20.0, 45.0, 75.0, 100.0, 130.0] {
            let v = kmh_to_mps(kmh);
            // cold (fresh tracker) and warm (this one, hints from the previous speed)
            for warm in [false, true] {
                let (pt, calls) = if warm {
                    cycle(&mut tr, t0, v, c)
                } else {
                    cycle(
                        &mut ModelMarginTracker::<T>::in_precision(p, cfg),
                        0.0,
                        v,
                        c,
                    )
                };
                t0 += 1.0;
                assert!(calls <= 100, "{} {kmh} km/h: {calls} calls", set.name());
                // modes: the shimmy and critical eigenvalues are eigenvalues of the reference solve
                // (at the latched speed: the tracker takes the speed as f32)
                let v = pt.speed_mps;
                let eig = reference_eigenvalues(&p, v, c);
                for m in [pt.shimmy, pt.critical] {
                    let l = m.eigenvalue();
                    let d = eig
                        .iter()
                        .map(|e| (e - l).norm())
                        .fold(f64::INFINITY, f64::min);
                    worst_eig = worst_eig.max(d / l.norm().max(1.0));
                    assert!(
                        d < eig_rel * l.norm().max(1.0),
                        "{l} not in the reference spectrum"
                    );
                }
                assert!(pt.shimmy_found);
                assert!(
                    (pt.critical.re - g_reference(&p, v, c)).abs() < eig_rel * pt.critical.omega_n
                );
                let max_re = eig.iter().map(|e| e.re).fold(f64::NEG_INFINITY, f64::max);
                let max_abs = eig.iter().map(|e| e.norm()).fold(1.0, f64::max);
                assert!((pt.max_re - max_re).abs() < eig_rel * max_abs);
                // shimmy mode = the in-phase wheel-yaw mode in the 4-9 Hz band, never 47 Hz
                assert!(pt.shimmy.freq_hz > 3.0 && pt.shimmy.freq_hz < 12.0);
                // critical speeds: first dense crossing above / below
                let above = dense.iter().find(|(x, _)| *x > kmh);
                let below = dense.iter().rev().find(|(x, _)| *x < kmh);
                for (ours, theirs, side) in [(pt.above, above, "above"), (pt.below, below, "below")]
                {
                    match (ours, theirs) {
                        (Some(o), Some((x, kind))) => {
                            let ok = mps_to_kmh(o.speed_mps);
                            worst_kmh = worst_kmh.max((ok - x).abs());
                            assert!(
                                (ok - x).abs() < 0.05,
                                "{} {kmh} km/h {side}: {ok} vs dense {x}",
                                set.name()
                            );
                            assert_eq!(o.kind, *kind);
                            assert!(o.converged);
                        }
                        (None, None) => {}
                        (o, t) => panic!("{} {kmh} km/h {side}: {o:?} vs {t:?}", set.name()),
                    }
                }
            }
        }
    }
    println!(
        "{}: worst eigenvalue distance {worst_eig:.1e} x |lambda|, worst critical speed {worst_kmh:.4} km/h",
        T::NAME
    );
}

#[test]
fn slope_agrees_with_central_differences_of_reference_eigenvalues() {
    // dzeta/dV of the shimmy mode vs a central difference (h = 1e-3 m/s) of the damping of the
    // reference eigenvalue nearest to it: O(h^2) truncation ~1e-8, tolerance 1e-5 absolute, in both
    // precisions (f32: eigenvalue and eigenvectors from f32 solves, the firmware's setting).
    slope_agrees::<f64>();
    slope_agrees::<f32>();
}

fn slope_agrees<T: SolveFloat>() {
    let cfg = ModelMarginConfig::default();
    let p = ParamSet::Nominal.params();
    let mut worst = 0.0f64;
    for kmh in [10.0, 20.0, 28.0, 50.0] {
        let v = kmh_to_mps(kmh);
        let (pt, _) = cycle(
            &mut ModelMarginTracker::<T>::in_precision(p, cfg),
            0.0,
            v,
            0.0,
        );
        let l0 = pt.shimmy.eigenvalue();
        let zeta_near = |vv: f64| {
            let l = reference_eigenvalues(&p, vv, 0.0)
                .into_iter()
                .min_by(|a, b| (a - l0).norm().total_cmp(&(b - l0).norm()))
                .unwrap();
            -l.re / l.norm()
        };
        let h = 1e-3;
        let fd = (zeta_near(v + h) - zeta_near(v - h)) / (2.0 * h);
        worst = worst.max((fd - pt.dzeta_dv_per_mps).abs());
        assert!(pt.slope_valid);
        assert!(
            (fd - pt.dzeta_dv_per_mps).abs() < 1e-5,
            "{kmh} km/h: fd {fd} ours {}",
            pt.dzeta_dv_per_mps
        );
        // and the fusion input carries the onset above (stable) or 0 margin inside the window
        let m = pt.margin();
        if pt.unstable() {
            assert!(m.v_crit_onset_mps.unwrap() <= v);
        } else {
            assert!(m.v_crit_onset_mps.unwrap() > v);
        }
    }
    println!(
        "{}: worst |dzeta/dV - central difference| {worst:.1e} per m/s",
        T::NAME
    );
}

#[test]
fn incremental_update_never_exceeds_one_solve_per_call_and_finishes_in_100_calls() {
    // A 1 kHz loop for 120 s: speed ramps 2 -> 150 km/h and back, the damper coefficient
    // switches (hints dropped -> cold searches). Every call does <= 1 eigen-solve; every cycle
    // completes within 100 calls; a new cycle starts every 100 ms.
    let p = ParamSet::Nominal.params();
    let mut tr = ModelMarginTracker::new(p, ModelMarginConfig::default());
    let (mut max_calls, mut cycles, mut max_solves) = (0u16, 0u32, 0u16);
    let mut sum_solves = 0u64;
    for k in 0..120_000usize {
        let t = k as f64 * 1e-3;
        let kmh = if t < 60.0 {
            2.0 + t * 2.5
        } else {
            152.0 - (t - 60.0) * 2.5
        };
        let c = if (40.0..50.0).contains(&t) {
            500.0
        } else {
            0.0
        };
        let before = tr.total_eigen_solves();
        let r = tr.step(t, kmh_to_mps(kmh) as f32, c);
        assert!(tr.total_eigen_solves() - before <= 1, "t = {t}");
        if let Some(pt) = r {
            cycles += 1;
            max_calls = max_calls.max(pt.calls);
            max_solves = max_solves.max(pt.eigen_solves);
            sum_solves += u64::from(pt.eigen_solves);
        }
    }
    println!(
        "cycles {cycles}, max calls per cycle {max_calls}, max solves per cycle {max_solves}, \
         mean solves per cycle {:.1}",
        sum_solves as f64 / f64::from(cycles)
    );
    assert!(max_calls <= 100, "{max_calls}");
    assert_eq!(tr.overruns(), 0);
    // 10 Hz: one cycle per 100 ms over 120 s (the first at t = 0)
    assert!((1199..=1201).contains(&cycles), "{cycles}");
}

#[test]
fn crossings_follow_a_slowly_changing_damper_by_newton_on_the_hopf_condition() {
    // The damper coefficient drifts 300 -> 360 N s/m in steps below the 1 % that would force a
    // scan, at a speed below the window: after the first (scanning) cycle every cycle tracks the
    // known crossings by Newton (one eigen-solve per cycle), and they must stay on the dense
    // sweep's crossings of the plant at the current c (which moves them by ~1 km/h here).
    fn run<T: SolveFloat>() {
        let p = ParamSet::Nominal.params();
        let mut tr = ModelMarginTracker::<T>::in_precision(p, ModelMarginConfig::default());
        let v = kmh_to_mps(20.0);
        let mut c = 300.0;
        let mut t0 = 0.0f64;
        let mut moved = 0.0f64;
        let first = cycle(&mut tr, t0, v, c).0;
        assert!(!first.tracked && first.eigen_solves > 10);
        let onset0 = first.above.unwrap().speed_mps;
        for k in 1..=24 {
            c += 2.5;
            t0 += 1.0;
            let (pt, _) = cycle(&mut tr, t0, v, c);
            assert!(pt.tracked, "cycle {k} scanned");
            assert_eq!(pt.eigen_solves, 1, "cycle {k}");
            if k % 8 == 0 {
                // c as the tracker saw it (f32)
                let dense = dense_crossings(&p, f64::from(c as f32));
                let ours = mps_to_kmh(pt.above.unwrap().speed_mps);
                let (x, kind) = dense.iter().find(|(x, _)| *x > 20.0).unwrap();
                assert_eq!(pt.above.unwrap().kind, *kind);
                assert!(
                    (ours - x).abs() < 0.05,
                    "{} c={c}: {ours} vs dense {x}",
                    T::NAME
                );
                moved = moved.max((pt.above.unwrap().speed_mps - onset0).abs());
            }
        }
        // the check has teeth: the crossing moved by far more than the tolerance
        assert!(mps_to_kmh(moved) > 0.5, "onset moved only {moved} m/s");
    }
    run::<f64>();
    run::<f32>();
}
