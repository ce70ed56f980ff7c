//! The plant integrators on the demo's closed loop, compared on equal inputs: runs one arm of
//! the demo (30 s ramp) recording the plant's inputs of every 1 ms period, then replays them
//! open loop (forces at the start of each period, as the loop does) at the closed loop's
//! integrator and at each one named, and prints per period the right-hand-side calls and
//! accepted and rejected steps, and the largest state error against Dopri5 at rtol 1e-11.
//!
//!     cargo run --release -p shimmy-sim --example integrator_replay -- ARM [METHOD ...]
//!
//! ARM: 0 damper off, 1 ASMC (default); METHOD as `--integrator` takes (e.g. `dopri5`).
use shimmy_sim::model::family::SimModel;
use shimmy_sim::model::plant::{Damper, Inputs, Method, Plant, Simulator, State, N_STATE};
use shimmy_sim::sim::run::closed_loop::{self, LoopConfig, LoopObserver, SampleRecord};
use shimmy_sim::sim::run::demo_case::{self, ARMS};

/// The state at the start of each period and the inputs held over it.
struct Recorder(Vec<(State, Inputs)>);

impl LoopObserver for Recorder {
    fn on_sample(&mut self, r: &SampleRecord<'_>) {
        let mut x = [0.0; N_STATE];
        x.copy_from_slice(r.state);
        self.0.push((x, *r.inputs));
    }
}

/// The states at the start of each period, replayed at `m`, and the integrator's totals.
fn replay(
    plant: Plant,
    rec: &[(State, Inputs)],
    m: Method,
) -> (Vec<State>, shimmy_sim::model::integrator::StepStats) {
    let mut sim = Simulator::with_method(plant, rec[0].0, m);
    let mut out = Vec::with_capacity(rec.len());
    for (_, u) in rec {
        out.push(*sim.state());
        sim.forces(u);
        sim.advance(1e-3, u).expect("integration");
    }
    (out, sim.stats())
}

fn main() {
    let mut args = std::env::args().skip(1);
    let arm: usize = args.next().map_or(1, |a| a.parse().expect("ARM: 0 or 1"));
    let methods: Vec<Method> = args
        .map(|n| Method::from_name(&n).expect("METHOD"))
        .collect();
    let ramp_s = 30.0;
    let case = demo_case::demo_case(ramp_s).expect("demo case");
    let cfg = LoopConfig::new(&case.plant, ARMS[arm].1, ramp_s);
    let mut rec = Recorder(Vec::new());
    closed_loop::run(&cfg, &mut case.scenario.clone(), Some(&mut rec)).expect("closed loop");
    let plant = *cfg
        .plant
        .plant(Damper::Mr(cfg.damper), closed_loop::CLOSED_LOOP_METHOD)
        .plant();
    let (own, _) = replay(plant, &rec.0, closed_loop::CLOSED_LOOP_METHOD);
    let same = own.iter().zip(&rec.0).all(|(a, (b, _))| a == b);
    println!(
        "{}: {} periods; the replay at {} reproduces the loop's states bit for bit: {same}",
        ARMS[arm].0,
        rec.0.len(),
        closed_loop::CLOSED_LOOP_METHOD.name()
    );
    let (truth, _) = replay(plant, &rec.0, Method::Dopri5 { rtol: 1e-11 });
    let mut scale = [0.0f64; N_STATE];
    for x in &truth {
        for i in 0..N_STATE {
            scale[i] = scale[i].max(x[i].abs());
        }
    }
    let n = rec.0.len() as f64;
    for m in std::iter::once(closed_loop::CLOSED_LOOP_METHOD).chain(methods) {
        let (xs, st) = replay(plant, &rec.0, m);
        let mut worst = [0.0f64; N_STATE];
        for (a, b) in xs.iter().zip(&truth) {
            for i in 0..N_STATE {
                worst[i] = worst[i].max((a[i] - b[i]).abs());
            }
        }
        let rel = (0..N_STATE)
            .map(|i| worst[i] / scale[i].max(f64::MIN_POSITIVE))
            .fold(0.0, f64::max);
        println!(
            "{:>14}: {:.1} right-hand sides, {:.2} steps, {:.3} rejected per period; \
             error psi_L {:.2e} rad, theta_sw {:.2e} rad, z {:.2e} m, largest of the state's \
             range {rel:.2e}",
            m.name(),
            st.evaluations as f64 / n,
            st.accepted as f64 / n,
            st.rejected as f64 / n,
            worst[0],
            worst[3],
            worst[12],
        );
    }
}
