//! Time of one 1 kHz controller step: ASMC with conditioning, inverse model, semi-active clip
//! and current limits (the full `Controller::step`), plus the pieces on their own.
use criterion::{criterion_group, criterion_main, Criterion};
use shimmy_core::control::{
    mr_model::MrModel, ControlInput, ControlParams, Controller, ControllerKind,
};
use std::hint::black_box;

fn shimmy_inputs(n: usize) -> Vec<ControlInput> {
    (0..n)
        .map(|k| {
            let t = k as f32 * 1e-3;
            let psi = 0.01 * (2.0 * core::f32::consts::PI * 6.0 * t).sin();
            ControlInput {
                t_s: t,
                dt_s: 1e-3,
                psi_l_rad: psi,
                psi_r_rad: psi * 0.98,
                speed_mps: 20.0,
                coil_current_a: None,
            }
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let inputs = shimmy_inputs(1000);
    for kind in [
        ControllerKind::Asmc,
        ControllerKind::Smc,
        ControllerKind::PassiveOff,
    ] {
        let mut ctl = Controller::new(kind, ControlParams::default());
        for i in &inputs {
            ctl.step(i); // warm up: filters and gain in their running state
        }
        let mut k = 0;
        c.bench_function(&format!("controller_step_{}", kind.name()), |b| {
            b.iter(|| {
                k = (k + 1) % inputs.len();
                black_box(ctl.step(black_box(&inputs[k])))
            })
        });
    }
    let m = MrModel::FITTED;
    c.bench_function("mr_inverse", |b| {
        b.iter(|| black_box(m.inverse(black_box(150.0), black_box(0.07))))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
