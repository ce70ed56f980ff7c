//! Cost of the model-based margin path: `linearise` + bounded eigen-solve, the least-damped
//! summary, dzeta/dV, and one warm-started `critical_speed_near` update.
use criterion::{criterion_group, criterion_main, Criterion};
use shimmy_core::estimator::model_margin::{ModelMarginConfig, ModelMarginTracker};
use shimmy_core::stability::{self, ModeSelect};
use shimmy_core::vehicles::car::ParamSet;
use shimmy_core::{eigen, vehicles::car as plant};
use std::hint::black_box;

fn bench(c: &mut Criterion) {
    let p = ParamSet::Nominal.params();
    c.bench_function("linearise", |b| {
        b.iter(|| plant::linearise(black_box(&p), black_box(20.0), black_box(0.0)))
    });
    c.bench_function("linearise+eigenvalues", |b| {
        b.iter(|| eigen::eigenvalues(&plant::linearise(black_box(&p), black_box(20.0), 0.0)))
    });
    c.bench_function("mode_summary (eig + shape)", |b| {
        b.iter(|| stability::mode_summary(black_box(&p), black_box(20.0), 0.0))
    });
    c.bench_function("dzeta_dv (critical)", |b| {
        b.iter(|| stability::dzeta_dv(black_box(&p), black_box(20.0), 0.0, ModeSelect::Critical))
    });
    let onset = stability::critical_speed_near(&p, 0.0, 5.0, None, 60)
        .expect("nominal has an onset")
        .speed_mps;
    c.bench_function("critical_speed_near warm (hint +0.05 m/s)", |b| {
        b.iter(|| {
            stability::critical_speed_near(
                black_box(&p),
                0.0,
                black_box(8.0),
                Some(black_box(onset + 0.05)),
                20,
            )
        })
    });
    c.bench_function("critical_speed_near cold (from 5 m/s)", |b| {
        b.iter(|| stability::critical_speed_near(black_box(&p), 0.0, black_box(5.0), None, 60))
    });
    // The incremental model margin: a full cycle (warm: hints from the previous cycle at the
    // same speed) and the mean cost of one call while a cycle is in progress (one unit of work).
    let mut tr = ModelMarginTracker::new(p, ModelMarginConfig::default());
    let mut t = 0.0f32;
    let run_cycle = |tr: &mut ModelMarginTracker, t: &mut f32| -> u16 {
        loop {
            *t += 1e-3;
            if let Some(pt) = tr.step(f64::from(*t), black_box(25.0 / 3.6), 0.0) {
                // idle out the rest of the 100 ms period without timing it
                return pt.calls;
            }
        }
    };
    let calls = run_cycle(&mut tr, &mut t);
    c.bench_function("model margin full cycle (warm, 25 km/h)", |b| {
        b.iter(|| {
            t += 0.2;
            run_cycle(&mut tr, &mut t)
        })
    });
    let calls = f64::from(calls.max(run_cycle(&mut tr, &mut t)));
    println!(
        "model margin: {calls} calls per warm cycle (divide the cycle time by it for one unit)"
    );
    c.bench_function(
        "model margin one unit (g(V) eval = linearise + eigen-solve)",
        |b| b.iter(|| stability::critical_mode_at(black_box(&p), black_box(8.0), 0.0)),
    );
    c.bench_function(
        "model margin heaviest unit (modes: eigen-solve + shimmy shapes)",
        |b| b.iter(|| stability::mode_at(black_box(&p), black_box(8.0), 0.0, ModeSelect::Shimmy)),
    );
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .measurement_time(std::time::Duration::from_secs(2))
        .warm_up_time(std::time::Duration::from_millis(500))
        .sample_size(20);
    targets = bench
}
criterion_main!(benches);
