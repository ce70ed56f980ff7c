//! Simulated seconds per wall second of the full nonlinear plant with the MR damper at a 1 kHz
//! control rate: each iteration advances one second of simulated time as 1000 `advance(1 ms)`
//! calls with a constant 0.5 A current command re-issued every period, starting inside the
//! Hopf window from a 3 deg wheel-yaw disturbance (the damper sliding hard: the stiff case).
//! Real-time factor = 1 s / (time per iteration).
use criterion::{criterion_group, criterion_main, Criterion};
use shimmy_core::params::{kmh_to_mps, PlantParams};
use shimmy_sim::model::disturbance::initial_yaw;
use shimmy_sim::model::plant::{Damper, Inputs, Method, Plant, Simulator};
use std::hint::black_box;

/// The explicit baseline (the previous default).
const DOPRI5: Method = Method::Dopri5 { rtol: 1e-7 };
/// The IMEX method under test at the tolerance the accuracy tests use.
const IMEX: Method = Method::Imex { rtol: 3e-6 };

fn one_second(method: Method, current_a: f64, psi0_deg: f64, damper: bool) -> f64 {
    let p = PlantParams::nominal();
    let plant = if damper {
        Plant::with_mr_damper(p)
    } else {
        Plant::new(p, Damper::None)
    };
    let mut sim = Simulator::with_method(plant, initial_yaw(psi0_deg.to_radians()), method);
    let u = Inputs {
        current_cmd_a: current_a,
        speed_mps: kmh_to_mps(60.0),
        ..Inputs::default()
    };
    for _ in 0..1000 {
        sim.advance(1e-3, black_box(&u)).expect("integration");
    }
    sim.state()[0]
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("plant_1s_at_1khz");
    g.sample_size(20);
    g.bench_function("mr_damper_0p5A_dopri5", |b| {
        b.iter(|| one_second(DOPRI5, 0.5, 3.0, true))
    });
    g.bench_function("mr_damper_0A_dopri5", |b| {
        b.iter(|| one_second(DOPRI5, 0.0, 3.0, true))
    });
    g.bench_function("mr_damper_0p5A_imex", |b| {
        b.iter(|| one_second(IMEX, 0.5, 3.0, true))
    });
    g.bench_function("mr_damper_0A_imex", |b| {
        b.iter(|| one_second(IMEX, 0.0, 3.0, true))
    });
    g.bench_function("no_damper_imex", |b| {
        b.iter(|| one_second(IMEX, 0.0, 3.0, false))
    });
    g.bench_function("mr_damper_0p5A_rk4_8sub", |b| {
        b.iter(|| one_second(Method::Rk4 { substeps: 8 }, 0.5, 3.0, true))
    });
    g.bench_function("no_damper_dopri5", |b| {
        b.iter(|| one_second(DOPRI5, 0.0, 3.0, false))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
