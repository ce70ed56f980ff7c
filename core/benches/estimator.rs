//! Criterion benchmarks: one 100 Hz RLS update (both instances' regressor dimension), one
//! warm-started root extraction, one full decimated estimator step and one 1 kHz input sample.
//! `cargo bench -p shimmy-core --bench estimator`

use criterion::{criterion_group, criterion_main, Criterion};
use shimmy_core::estimator::meter::mode_meter::{
    EstimatorConfig, MarginEstimator, Sample, WheelOrder,
};
use shimmy_core::estimator::meter::rls::{Rls, N_MAX};
use shimmy_core::estimator::meter::roots::{aberth, C64, MAX_ORDER};
use std::hint::black_box;

fn signal(k: usize) -> f32 {
    let t = k as f32 * 0.01;
    // deterministic pseudo-ambient signal: two lines + LCG noise
    let mut x = (k as u32).wrapping_mul(2_654_435_761);
    x ^= x >> 13;
    (6.1 * t).sin() + 0.3 * (50.3 * t).sin() + 0.2 * ((x % 1000) as f32 / 500.0 - 1.0)
}

fn bench(c: &mut Criterion) {
    // RLS update, dimension 9 (AR(6) + cos + sin + bias), f32
    let mut rls = Rls::<f32>::new(9, 0.995, 100.0, Some(1e5));
    let mut hist = [0.0f32; N_MAX];
    let mut k = 0usize;
    for _ in 0..1000 {
        let y = signal(k);
        let mut phi = hist;
        phi[6] = 1.0;
        let _ = rls.update(&phi, y);
        hist.copy_within(0..5, 1);
        hist[0] = y;
        k += 1;
    }
    c.bench_function("rls_update_f32_n9", |b| {
        b.iter(|| {
            let y = signal(k);
            let mut phi = hist;
            phi[6] = (k as f32 * 0.1).cos();
            phi[7] = (k as f32 * 0.1).sin();
            phi[8] = 1.0;
            let r = rls.update(black_box(&phi), black_box(y));
            hist.copy_within(0..5, 1);
            hist[0] = y;
            k += 1;
            r
        })
    });

    // root extraction of an AR(6) polynomial, warm start (the tracking case) and cold start
    let coeffs = {
        let th = rls.theta();
        let mut c6 = [0.0f64; 6];
        for i in 0..6 {
            c6[i] = -(th[i] as f64);
        }
        c6
    };
    let mut roots = [C64::default(); MAX_ORDER];
    aberth(&coeffs, &mut roots, false, 60).unwrap();
    c.bench_function("roots_ar6_warm", |b| {
        b.iter(|| {
            let mut r = roots;
            aberth(black_box(&coeffs), &mut r, true, 60)
        })
    });
    c.bench_function("roots_ar6_cold", |b| {
        b.iter(|| {
            let mut r = roots;
            aberth(black_box(&coeffs), &mut r, false, 60)
        })
    });

    // full estimator: cost per 1 kHz input sample (amortised over the decimated steps)
    let mut est = MarginEstimator::<f32>::new(EstimatorConfig::default()).unwrap();
    let mut n = 0usize;
    let sample = |n: usize| Sample {
        psi_l_rad: 1e-3 * signal(n),
        psi_r_rad: 1e-3 * signal(n + 7),
        wheel: WheelOrder::Speed {
            speed_mps: 20.0,
            radius_m: 0.5,
        },
        damper_cmd: 0.0,
    };
    for _ in 0..20_000 {
        est.push(&sample(n));
        n += 1;
    }
    c.bench_function("estimator_10_input_samples_incl_one_decimated_step", |b| {
        b.iter(|| {
            for _ in 0..10 {
                black_box(est.push(&sample(n)));
                n += 1;
            }
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
