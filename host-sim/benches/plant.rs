//! Simulated seconds per wall second of the full nonlinear plant with the MR damper at a 1 kHz
//! control rate: each iteration advances one second of simulated time as 1000 `advance(1 ms)`
//! calls with a constant 0.5 A current command re-issued every period, starting inside the
//! Hopf window from a 3 deg wheel-yaw disturbance (the damper sliding hard: the stiff case).
//! Real-time factor = 1 s / (time per iteration).
//!
//! `closed_loop_demo_asmc_30s`: the demo's whole ASMC run (30 s ramp; sensors, the core's
//! supervised controller and mode meter at 1 kHz) per iteration, once per plant integrator;
//! `closed_loop_demo_damper_off_30s`: its other arm (the damper passive at 0 A) at the closed
//! loop's integrator and at Dopri5. Simulated s per wall s = 30 s / (time per iteration).
use criterion::{criterion_group, criterion_main, Criterion};
use shimmy_core::units::kmh_to_mps;
use shimmy_core::vehicles::car::PlantParams;
use shimmy_sim::model::disturbance::initial_yaw;
use shimmy_sim::model::plant::{Damper, Inputs, Method, Plant, Simulator};
use shimmy_sim::sim::run::closed_loop::CLOSED_LOOP_METHOD;
use shimmy_sim::sim::run::demo_case::{self, ARMS};
use std::hint::black_box;

/// The explicit 5(4) pair (the closed loop's integrator before Vern65).
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
    let case = demo_case::demo_case(30.0).expect("demo case");
    let mut g = c.benchmark_group("closed_loop_demo_asmc_30s");
    g.sample_size(10);
    for method in [
        CLOSED_LOOP_METHOD,
        DOPRI5,
        Method::ImexFixed { substeps: 2 },
        Method::ImexFixed { substeps: 1 },
    ] {
        let case = demo_case::DemoCase {
            method,
            ..case.clone()
        };
        g.bench_function(method.name(), |b| {
            b.iter(|| {
                let (_, r) = demo_case::run_arm(&case, ARMS[1].1, 30.0, 5).expect("run");
                black_box(r.sim_s)
            })
        });
    }
    g.finish();
    // The demo's other arm: its run-time line sums both.
    let mut g = c.benchmark_group("closed_loop_demo_damper_off_30s");
    g.sample_size(10);
    for method in [CLOSED_LOOP_METHOD, DOPRI5] {
        let case = demo_case::DemoCase {
            method,
            ..case.clone()
        };
        g.bench_function(method.name(), |b| {
            b.iter(|| {
                let (_, r) = demo_case::run_arm(&case, ARMS[0].1, 30.0, 5).expect("run");
                black_box(r.sim_s)
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
