//! Negative tests: each design choice is needed.

mod common;
use common::*;
use shimmy_core::estimator::meter::mode_meter::{EstimatorConfig, MarginEstimator, WheelOrder};
use shimmy_core::estimator::meter::real::Real;
use shimmy_core::estimator::meter::roots::{aberth, mode_of_root, C64, MAX_ORDER};

/// Slow-instance estimates (every 10 s after 30 s) over `runs` runs; the wheel reference is
/// replaced by the speed + radius form when `speed_radius` is given.
fn slow_zetas<T: Real>(
    cfg: EstimatorConfig,
    sc: &Scenario,
    runs: u64,
    secs: f64,
    speed_radius: Option<(f32, f32)>,
) -> (Vec<f64>, Vec<f64>) {
    let (mut z, mut f) = (Vec::new(), Vec::new());
    for seed in 0..runs {
        let mut est = MarginEstimator::<T>::new(cfg).unwrap();
        let mut run = Run::new(sc, 900 + seed);
        let mut next = 30.0;
        for k in 0..(secs * FS) as usize {
            let mut s = run.sample();
            if let Some((v, r)) = speed_radius {
                s.wheel = WheelOrder::Speed {
                    speed_mps: v,
                    radius_m: r,
                };
            }
            if let Some(o) = est.push(&s) {
                if k as f64 / FS >= next {
                    next += 10.0;
                    if o.slow.valid {
                        z.push(o.slow.zeta as f64);
                        f.push(o.slow.freq_hz as f64);
                    } else {
                        z.push(f64::NAN);
                    }
                }
            }
        }
    }
    (z, f)
}

/// A wheel-imbalance line at f_w = 9 Hz (amplitude 2 x the modal RMS) next to an 8 Hz, zeta = 0.05 mode:
/// without the wheel-order regressors the line is fitted as an undamped pole and the reported
/// damping collapses toward zero; with them (phase integrated from speed and radius) the bias
/// stays within 0.25 of the bound. 8 runs x 130 s each way.
#[test]
fn wheel_order_regressors_are_needed_for_a_forced_line() {
    let radius = 0.5f32;
    let f_w = 9.0f64;
    let speed = (f_w * PI2 * radius as f64) as f32;
    let sc = Scenario {
        modes: vec![ModeSpec::unit(0.05, 8.0)],
        snr_db: 20.0,
        y_rms_rad: 2e-3,
        line: Some((f_w, 2.0)),
        give_phase: false,
    };
    let with = EstimatorConfig::default();
    let without = EstimatorConfig {
        wheel_order_regressors: false,
        ..with
    };
    let b = bound(0.05, 8.0, with.lambda_slow as f64, 100.0);
    let (zw, fw) = slow_zetas::<f32>(with, &sc, 8, 130.0, Some((speed, radius)));
    let (zn, fnn) = slow_zetas::<f32>(without, &sc, 8, 130.0, None);
    let (mw, sw) = mean_sd(&zw);
    let (mn, sn) = mean_sd(&zn);
    let (mfw, _) = mean_sd(&fw);
    let (mfn, _) = mean_sd(&fnn);
    println!("with regressors: zeta {mw:.4} (bias {:.2} b, sd {:.2} b) f {mfw:.2} Hz | without: zeta {mn:.4} (bias {:.2} b) f {mfn:.2} Hz", (mw - 0.05) / b, sw / b, (mn - 0.05) / b);
    assert!(zw.iter().all(|z| z.is_finite()));
    assert!((mw - 0.05).abs() < 0.25 * b + 2.0 * sw / (zw.len() as f64).sqrt());
    assert!((mfw - 8.0).abs() < 0.1);
    // without: biased toward zero by more than one bound, and significantly so (> 5 standard
    // errors of the mean)
    let se = sn / (zn.len() as f64).sqrt();
    assert!(
        mn < 0.05 - b && mn < 0.05 - 5.0 * se,
        "without regressors mean zeta {mn} (se {se})"
    );
}

/// Coefficient rounding alone: AR(4) polynomials of an exactly discretised (zeta, f) mode plus a
/// well-damped pair, rounded to f32, rooted in f64. At 1 kHz the poles crowd around z = 1 and
/// the damping error is more than 1000x what it is at 100 Hz, where it is negligible
/// (`docs/margin-estimator.md`: ~1e-5). The full-estimator test below shows the consequence.
#[test]
fn f32_coefficient_rounding_ruins_ar4_at_1khz_but_not_at_100hz() {
    let mut err = [Vec::new(), Vec::new()];
    for (i, fs) in [1000.0f64, 100.0].into_iter().enumerate() {
        for zi in 0..10 {
            for fi in 0..14 {
                let zeta = 0.01 + 0.01 * zi as f64;
                let f = 5.0 + fi as f64;
                let pole = |z: f64, fh: f64| {
                    let w = PI2 * fh;
                    let s = nalgebra::Complex::new(-z * w, w * (1.0 - z * z).sqrt());
                    (s / fs).exp()
                };
                let (p1, p2) = (pole(zeta, f), pole(0.5, 30.0));
                // (z^2 - 2 Re p z + |p|^2) products
                let q1 = [1.0, -2.0 * p1.re, p1.norm_sqr()];
                let q2 = [1.0, -2.0 * p2.re, p2.norm_sqr()];
                let mut c = [0.0f64; 5];
                for a in 0..3 {
                    for bb in 0..3 {
                        c[a + bb] += q1[a] * q2[bb];
                    }
                }
                let c32: Vec<f64> = c[1..].iter().map(|v| (*v as f32) as f64).collect();
                let mut r = [C64::default(); MAX_ORDER];
                let e = match aberth(&c32, &mut r, false, 200) {
                    Ok(_) => r[..4]
                        .iter()
                        .filter_map(|z| mode_of_root(*z, fs))
                        .map(|m| (m.zeta - zeta).abs())
                        .fold(1.0, f64::min), // no oscillatory root left: error 1
                    Err(_) => 1.0,
                };
                err[i].push(e);
            }
        }
    }
    let p99 = |v: &mut Vec<f64>| {
        v.sort_by(|a, b| a.partial_cmp(b).unwrap());
        v[(0.99 * (v.len() - 1) as f64) as usize]
    };
    let (e1k, e100) = (p99(&mut err[0]), p99(&mut err[1]));
    println!("p99 |zeta error| from f32 coefficients: 1 kHz {e1k:.2e}, 100 Hz {e100:.2e}");
    assert!(
        e1k > 1e3 * e100,
        "1 kHz rounding error {e1k} not >> 100 Hz error {e100}"
    );
    assert!(e100 < 1e-5, "100 Hz rounding error: {e100}");
}

/// The full estimator fitted at 1 kHz (no decimation, AR(4), same T_eff) in f32 fails on the
/// same data where the decimated AR(4) f32 estimator passes. 4 runs x 70 s.
#[test]
fn ar4_fitted_at_1khz_in_f32_fails_where_decimated_passes() {
    let sc = Scenario::ambient(vec![ModeSpec::unit(0.05, 8.0)], 40.0);
    let dec = EstimatorConfig {
        ar_order: 4,
        ..EstimatorConfig::default()
    };
    // same effective memory: 1 - lambda scales with the rate
    let full = EstimatorConfig {
        decimation: 1,
        lambda_fast: 1.0 - (1.0 - dec.lambda_fast) / 10.0,
        lambda_slow: 1.0 - (1.0 - dec.lambda_slow) / 10.0,
        ..dec
    };
    let b = bound(0.05, 8.0, dec.lambda_slow as f64, 100.0);
    let rms_err = |z: &[f64]| {
        (z.iter()
            .map(|v| {
                if v.is_finite() {
                    (v - 0.05).powi(2)
                } else {
                    1.0
                }
            })
            .sum::<f64>()
            / z.len() as f64)
            .sqrt()
    };
    let (zd, _) = slow_zetas::<f32>(dec, &sc, 4, 70.0, None);
    let (zf, _) = slow_zetas::<f32>(full, &sc, 4, 70.0, None);
    let (ed, ef) = (rms_err(&zd), rms_err(&zf));
    println!("AR(4) f32: decimated rms error {:.4} ({:.2} b), 1 kHz rms error {:.4} ({:.2} b); 1 kHz values {:?}", ed, ed / b, ef, ef / b, &zf[..zf.len().min(8)]);
    assert!(
        ed < 1.5 * b,
        "decimated estimator should be within the bound: {ed}"
    );
    assert!(
        ef > 3.0 * b,
        "1 kHz f32 estimator unexpectedly accurate: {ef}"
    );
}

/// The forgetting-bias correction is needed: on a lightly damped mode (zeta = 0.01, 5 Hz, the
/// mode lives ~3 s against the slow window's 10 s) the uncorrected RLS roots sit inside the unit
/// circle by the finite-memory shrink, and the slow damping is biased high by ~0.4 of the
/// accuracy bound (outside the 0.25 requirement); the same seeds with the correction are
/// within it. 30 runs x 10 estimates each way.
#[test]
fn forgetting_bias_correction_is_needed_for_light_damping() {
    let sc = Scenario::ambient(vec![ModeSpec::unit(0.01, 5.0)], 40.0);
    let with = EstimatorConfig::default();
    let without = EstimatorConfig {
        forgetting_bias_correction: false,
        ..with
    };
    let b = bound(0.01, 5.0, with.lambda_slow as f64, 100.0);
    let (zw, _) = slow_zetas::<f32>(with, &sc, 30, 130.0, None);
    let (zn, _) = slow_zetas::<f32>(without, &sc, 30, 130.0, None);
    let (mw, sw) = mean_sd(&zw);
    let (mn, _) = mean_sd(&zn);
    let se = sw / (zw.len() as f64).sqrt();
    println!(
        "zeta 0.01 at 5 Hz: corrected bias {:+.2} b, uncorrected {:+.2} b (standard error {:.2} b)",
        (mw - 0.01) / b,
        (mn - 0.01) / b,
        se / b
    );
    assert!((mn - 0.01) / b > 0.25 + 2.0 * se / b);
    assert!((mw - 0.01).abs() / b < 0.25);
}
