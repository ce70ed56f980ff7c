//! Tests of the controllers, the MR model and its fit (unit, property and closed-loop).

use super::mr_fit::{self, FitSample, Smoothing, REFERENCE_GRID};
use super::*;
use crate::mr_damper::{rates, SpencerParams, SpencerState};
use core::f64::consts::PI;
use proptest::prelude::*;
use schedule::ScheduleParams;

fn input(psi: f32, dt: f32) -> ControlInput {
    ControlInput {
        t_s: 0.0,
        dt_s: dt,
        psi_l_rad: psi,
        psi_r_rad: psi,
        speed_mps: 20.0,
        coil_current_a: None,
    }
}

// ---------------------------------------------------------------- MR model and fit

fn reference_fit(sm: Smoothing) -> mr_fit::BinghamFit {
    let mut buf = vec![FitSample::default(); REFERENCE_GRID.sample_count()];
    mr_fit::fit_reference(&mut buf, sm).expect("fit")
}

#[test]
fn fitted_constants_match_a_fresh_fit() {
    // The firmware constants are the fit rounded to 4 significant digits (0.05 %); 1 % catches
    // any change of the Spencer model, the grid or the fit routine.
    let f = reference_fit(Smoothing::Algebraic);
    let m = MrModel::FITTED;
    let close = |a: f32, b: f64, what: &str| {
        assert!(
            ((a as f64) - b).abs() <= 0.01 * b.abs(),
            "{what}: firmware {a}, fresh fit {b}"
        );
    };
    close(m.f_ca_n, f.f_ca_n, "f_ca");
    close(m.f_cb_n_per_a, f.f_cb_n_per_a, "f_cb");
    close(m.c_a_ns_per_m, f.c_a_ns_per_m, "c_a");
    close(m.c_b_ns_per_m_a, f.c_b_ns_per_m_a, "c_b");
    close(m.v0_mps, f.v0_mps, "v0");
    println!(
        "MR fit (algebraic): RMS force error {:.2} % ({:.1} N of {:.1} N rms)",
        f.rms_error_pct(),
        f.rms_error_n,
        f.rms_force_n
    );
    // The remaining error is the Spencer model's pre-yield hysteresis (the yield force reverses
    // after ~0.2 mm of stroke reversal, not at zero velocity), which no memoryless model has.
    // Guard against the fit getting worse.
    assert!(f.rms_error_pct() < 20.0);
}

#[test]
fn algebraic_smoothing_fits_as_well_as_tanh() {
    let t = reference_fit(Smoothing::Tanh);
    let a = reference_fit(Smoothing::Algebraic);
    println!(
        "RMS force error: tanh {:.2} %, algebraic {:.2} %",
        t.rms_error_pct(),
        a.rms_error_pct()
    );
    assert!(a.rms_error_pct() < t.rms_error_pct() + 0.5);
}

#[test]
fn fit_recovers_a_known_bingham_model() {
    // Samples from a known model (the fit routine's own check, independent of Spencer).
    let truth = mr_fit::BinghamFit {
        f_ca_n: 20.0,
        f_cb_n_per_a: 50.0,
        c_a_ns_per_m: 150.0,
        c_b_ns_per_m_a: 400.0,
        v0_mps: 0.02,
        smoothing: Smoothing::Tanh,
        rms_error_n: 0.0,
        rms_force_n: 0.0,
    };
    let mut s = Vec::new();
    for i in [0.0, 0.7, 1.3, 2.0] {
        for k in -100..=100 {
            let v = 0.5 * k as f64 / 100.0;
            s.push(FitSample {
                current_a: i,
                v_mps: v,
                force_n: truth.force_n(i, v),
            });
        }
    }
    let f = mr_fit::fit(&s, Smoothing::Tanh).unwrap();
    assert!((f.v0_mps / 0.02 - 1.0).abs() < 1e-4, "{}", f.v0_mps);
    assert!((f.f_cb_n_per_a - 50.0).abs() < 1e-3);
    assert!((f.c_b_ns_per_m_a - 400.0).abs() < 1e-3);
    assert!(f.rms_error_n < 1e-6);
    assert!(mr_fit::fit(&[], Smoothing::Tanh).is_none());
}

#[test]
fn spencer_integration_is_converged_at_the_fit_step() {
    // Halving the RK4 step changes the force by < 0.2 % of its rms (worst case of the grid:
    // 2 A, 8 mm, 14 Hz: the stiffest).
    let p = SpencerParams::steering();
    let mut g2 = REFERENCE_GRID;
    g2.substeps_per_cycle *= 2;
    let n = REFERENCE_GRID.record_cycles * REFERENCE_GRID.samples_per_cycle;
    let (mut a, mut b) = (vec![FitSample::default(); n], vec![FitSample::default(); n]);
    mr_fit::simulate_sine(&p, &REFERENCE_GRID, 2.0, 0.008, 14.0, &mut a);
    mr_fit::simulate_sine(&p, &g2, 2.0, 0.008, 14.0, &mut b);
    let rms = (a.iter().map(|s| s.force_n * s.force_n).sum::<f64>() / n as f64).sqrt();
    let worst = a
        .iter()
        .zip(&b)
        .map(|(x, y)| (x.force_n - y.force_n).abs())
        .fold(0.0, f64::max);
    assert!(worst < 2e-3 * rms, "{worst} vs {rms}");
}

#[test]
fn inverse_round_trips_the_forward_model() {
    let m = MrModel::FITTED;
    for ki in 0..=20 {
        let i = 0.1 * ki as f32;
        for &v in &[-0.8f32, -0.2, -0.03, -0.005, 0.005, 0.03, 0.2, 0.8] {
            let f = m.force_n(i, v);
            let r = m.inverse(f, v);
            assert!(!r.clipped);
            assert!(
                (r.current_a - i).abs() < 2e-3,
                "I {i} v {v}: {}",
                r.current_a
            );
        }
    }
    // Beyond the damper: saturated at I_max. Below its 0 A force: 0 A.
    let r = m.inverse(1e5, 0.3);
    assert!(r.saturated && r.current_a == m.i_max_a);
    let r = m.inverse(1.0, 0.3);
    assert!(r.at_minimum && r.current_a == 0.0);
}

#[test]
fn inverse_never_pushes() {
    let m = MrModel::FITTED;
    for &(f, v) in &[(100.0f32, -0.1f32), (-100.0, 0.1), (100.0, 0.0), (0.0, 0.5)] {
        let r = m.inverse(f, v);
        assert!(r.clipped && r.current_a == 0.0, "{f} {v}");
    }
    for &(f, v) in &[
        (f32::NAN, 0.1),
        (100.0, f32::NAN),
        (f32::INFINITY, f32::INFINITY),
        (f32::INFINITY, 1e-30),
    ] {
        let r = m.inverse(f, v);
        assert!(r.current_a >= 0.0 && r.current_a <= m.i_max_a);
    }
}

// ---------------------------------------------------------------- controller unit tests

#[test]
fn passive_modes_command_their_currents() {
    let p = ControlParams::default();
    let mut c = Controller::new(ControllerKind::PassiveOff, p);
    assert_eq!(c.step(&input(0.01, 1e-3)).current_cmd_a, 0.0);
    c.set_kind(ControllerKind::PassiveOn { current_a: 1.2 });
    assert_eq!(c.step(&input(0.01, 1e-3)).current_cmd_a, 1.2);
    c.set_kind(ControllerKind::PassiveOn { current_a: 9.0 });
    let o = c.step(&input(0.01, 1e-3));
    assert_eq!(o.current_cmd_a, 2.0);
    assert!(o.flags.saturated);
    assert_eq!(
        ControllerKind::from_name("asmc", 0.0),
        Some(ControllerKind::Asmc)
    );
    assert_eq!(ControllerKind::from_name("nope", 0.0), None);
}

#[test]
fn invalid_inputs_command_the_fallback_and_hold_the_filters() {
    let p = ControlParams::default();
    let mut c = Controller::new(ControllerKind::Asmc, p);
    for k in 0..100 {
        c.step(&input(0.01 * (k as f32 * 0.05).sin(), 1e-3));
    }
    let before = c.step(&input(0.0, 1e-3)).conditioned;
    for bad in [
        input(f32::NAN, 1e-3),
        input(f32::INFINITY, 1e-3),
        input(2.0, 1e-3),
        input(0.0, f32::NAN),
        input(0.0, -1e-3),
        input(0.0, 5.0),
    ] {
        let o = c.step(&bad);
        assert!(o.flags.input_invalid);
        assert_eq!(o.current_cmd_a, p.fallback_current_a);
        assert_eq!(o.conditioned, before);
    }
}

#[test]
fn speed_gate_leaves_the_damper_off() {
    let mut c = Controller::new(ControllerKind::Smc, ControlParams::default());
    for k in 0..500 {
        let psi = 0.02 * (2.0 * PI * 6.0 * k as f64 / 1000.0).sin();
        let mut i = input(psi as f32, 1e-3);
        i.speed_mps = 1.0;
        let o = c.step(&i);
        assert!(o.flags.below_speed && o.current_cmd_a == 0.0);
    }
}

/// Encoder model: 14-bit quantisation.
fn quantise(psi: f64) -> f32 {
    let q = 2.0 * PI / 16384.0;
    ((psi / q).round() * q) as f32
}

/// Runs a controller on a prescribed in-phase yaw signal; returns (mean current, final gain).
fn run_open(
    kind: ControllerKind,
    p: ControlParams,
    secs: f64,
    sig: impl Fn(f64) -> f64,
) -> (f64, f32) {
    let mut c = Controller::new(kind, p);
    let n = (secs * 1000.0) as usize;
    let mut sum = 0.0;
    for k in 0..n {
        let t = k as f64 / 1000.0;
        let o = c.step(&input(quantise(sig(t)), 1e-3));
        assert!(o.current_cmd_a >= 0.0 && o.current_cmd_a <= 2.0);
        sum += o.current_cmd_a as f64;
    }
    (sum / n as f64, c.adaptive_gain())
}

/// Deterministic pseudo-noise in [-1, 1] (xorshift), so the tests are reproducible.
fn noise(seed: u64) -> impl FnMut() -> f64 {
    let mut x = seed | 1;
    move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        (x >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

/// Straight running with realistic 14-bit encoders: +-1 LSB uniform noise on each encoder
/// (independent), then quantisation. Returns (rms of s, mean current, final K).
fn run_noise(p: ControlParams, secs: f64) -> (f64, f64, f32) {
    run_noise_kind(ControllerKind::Asmc, p, secs)
}

fn run_noise_kind(kind: ControllerKind, p: ControlParams, secs: f64) -> (f64, f64, f32) {
    let lsb = 2.0 * PI / 16384.0;
    let (mut nl, mut nr) = (noise(7), noise(11));
    let mut c = Controller::new(kind, p);
    let n = (secs * 1000.0) as usize;
    let (mut ss, mut isum) = (0.0, 0.0);
    for _ in 0..n {
        let mut i = input(0.0, 1e-3);
        i.psi_l_rad = quantise(lsb * nl());
        i.psi_r_rad = quantise(lsb * nr());
        let o = c.step(&i);
        ss += (o.s_radps as f64).powi(2);
        isum += o.current_cmd_a as f64;
    }
    ((ss / n as f64).sqrt(), isum / n as f64, c.adaptive_gain())
}

#[test]
fn asmc_stays_quiet_on_sensor_noise_and_the_dead_zone_is_needed() {
    let p = ControlParams::default();
    let (s_rms, i_mean, k) = run_noise(p, 3.0);
    println!("noise: s rms {s_rms:.4} rad/s, mean current {i_mean:.4} A, K {k:.3}");
    // The dead zone sits above 1.5 sigma of the noise on s (tuned down from 2 sigma in the
    // 4-DOF closed loop for settling, see AsmcParams::default): noise excursions then raise K
    // a little (< 1 rad/s^2, 3 % of K_max) but the quiet zone keeps the current near zero.
    assert!(p.asmc.dead_zone_radps > 1.5 * s_rms as f32, "s rms {s_rms}");
    assert!(k < 1.0, "K {k}");
    assert!(i_mean < 0.05, "mean current {i_mean}");
    // Without the dead zone the noise pumps K up.
    let mut p0 = p;
    p0.asmc.dead_zone_radps = 0.0;
    let (_, i0, k0) = run_noise(p0, 3.0);
    println!("without dead zone / quiet zone: K {k0:.3}, mean current {i0:.3} A");
    // (K 0.55 -> 1.49 with gamma 300, dead zone 0.04; the current shows it more: 0.008 -> 1.9 A.)
    assert!(k0 > 2.0 * k.max(0.25), "K without dead zone {k0}");
    // ... and without the quiet zone the viscous part keeps current on the coil for noise.
    assert!(i0 > 0.1, "{i0}");
    // The fixed-gain SMC has neither: its switching term acts on noise at near-zero stroke
    // rates, where the inverse needs a large current for any force.
    let (_, i_smc, _) = run_noise_kind(ControllerKind::Smc, p, 3.0);
    println!("fixed-gain SMC on noise: mean current {i_smc:.3} A");
    assert!(i_smc > 0.1 && i_smc > 100.0 * i_mean, "{i_smc}");
}

#[test]
fn asmc_gain_grows_on_shimmy_and_leaks_back_when_it_stops() {
    let p = ControlParams::default();
    let shimmy = |t: f64| {
        if t < 1.0 {
            0.01 * (2.0 * PI * 6.0 * t).sin()
        } else {
            0.0
        }
    };
    let mut c = Controller::new(ControllerKind::Asmc, p);
    let mut k_peak = 0.0f32;
    for k in 0..6000 {
        let t = k as f64 / 1000.0;
        c.step(&input(quantise(shimmy(t)), 1e-3));
        if k == 999 {
            k_peak = c.adaptive_gain();
        }
    }
    // K grows until the damper saturates (then the anti-windup freezes it): at 0.01 rad, 6 Hz
    // the damper saturates from K ~ 2.5 rad/s^2 on.
    assert!(k_peak > 1.5, "K after 1 s of shimmy {k_peak}");
    // Leakage: K(5 s later) ~ K_peak exp(-sigma 5) = 0.08 K_peak.
    let k_end = c.adaptive_gain();
    assert!(k_end < 0.15 * k_peak, "{k_end} vs {k_peak}");
    // Without leakage it would stay up.
    let mut p0 = p;
    p0.asmc.sigma_per_s = 0.0;
    let mut c0 = Controller::new(ControllerKind::Asmc, p0);
    for k in 0..6000 {
        c0.step(&input(quantise(shimmy(k as f64 / 1000.0)), 1e-3));
    }
    assert!(c0.adaptive_gain() > 0.9 * k_peak);
}

#[test]
fn asmc_adaptation_freezes_while_the_actuator_cannot_act() {
    // A shimmy the damper cannot follow at all: large amplitude so the inverse saturates; the
    // gain must not run to K_max while saturated (anti-windup), and does without the freeze.
    let p = ControlParams::default();
    let big = |t: f64| 0.08 * (2.0 * PI * 6.0 * t).sin();
    let mut c = Controller::new(ControllerKind::Asmc, p);
    let mut frac_frozen = 0.0;
    for k in 0..2000 {
        let o = c.step(&input(quantise(big(k as f64 / 1000.0)), 1e-3));
        if o.flags.saturated || o.flags.clipped {
            frac_frozen += 1.0 / 2000.0;
            assert!(!o.flags.adapting);
        }
    }
    assert!(frac_frozen > 0.5, "{frac_frozen}");
    let k_with = c.adaptive_gain();
    let mut p0 = p;
    p0.asmc.anti_windup = false;
    let mut c0 = Controller::new(ControllerKind::Asmc, p0);
    for k in 0..2000 {
        c0.step(&input(quantise(big(k as f64 / 1000.0)), 1e-3));
    }
    assert!(c0.adaptive_gain() >= 0.99 * p.asmc.k_max_radps2);
    assert!(k_with < 0.8 * c0.adaptive_gain(), "{k_with}");
}

#[test]
fn slow_steering_does_not_make_the_damper_work() {
    // Driver steering 0.1 rad at 0.3 Hz: ASMC current stays low because of the shimmy-band
    // high-pass; without it (identity filter) the law reacts to the steering rate.
    let steer = |t: f64| 0.1 * (2.0 * PI * 0.3 * t).sin();
    let p = ControlParams::default();
    let (i_hp, _) = run_open(ControllerKind::Asmc, p, 6.0, steer);
    let mut p0 = p;
    p0.conditioning.split_hz = 0.0; // identity high-pass
    let (i_raw, _) = run_open(ControllerKind::Asmc, p0, 6.0, steer);
    println!("mean current on 0.3 Hz steering: {i_hp:.3} A with HP, {i_raw:.3} A without");
    // (0.039 A with the closed-loop-tuned dead zone of 0.04 rad/s; 0.03 A would hold for 0.06.)
    assert!(i_hp < 0.05, "{i_hp}");
    assert!(i_raw > 5.0 * i_hp.max(0.02), "{i_raw}");
}

// ---------------------------------------------------------------- closed loop

/// 1-DOF stand-in for the in-phase wheel-yaw mode: a van der Pol oscillator at 6 Hz with
/// negative damping (-4 % of critical, the tyre's self-excitation) saturating at large rates,
/// I_k psi'' = (c_n - c_3 psi'^2) psi' - k psi - (l_t/2) F_d, with the simulator's Spencer damper
/// (coil lag included) on the stroke x_d = l_t psi. Returns (max |psi| over the last 0.5 s,
/// mean current).
fn closed_loop(kind: ControllerKind, secs: f64) -> (f64, f64) {
    let pp = crate::vehicles::car::PlantParams::nominal();
    let (ik, lt) = (pp.i_k, pp.l_t);
    let w = 2.0 * PI * 6.0;
    let k = ik * w * w;
    let c_n = 0.04 * 2.0 * ik * w;
    let c_3 = 4.0 * c_n / (3.0 * (0.05 * w) * (0.05 * w)); // limit cycle ~0.05 rad without damper
    let sp = SpencerParams::steering();
    let mut c = Controller::new(kind, ControlParams::default());
    // state: psi, dpsi, spencer (u, y, z)
    let (mut psi, mut dpsi) = (0.02f64, 0.0f64);
    // Damper at rest at the initial stroke.
    let mut d = SpencerState {
        y: lt * psi,
        ..SpencerState::default()
    };
    let mut i_cmd = 0.0f64;
    let n = (secs * 1000.0) as usize;
    let (mut amp_end, mut i_sum) = (0.0f64, 0.0);
    let sub = 20;
    let h = 1e-3 / sub as f64;
    let f = |psi: f64, dpsi: f64, d: &SpencerState, i: f64| {
        let r = rates(&sp, d, lt * psi, lt * dpsi, i);
        let acc = ((c_n - c_3 * dpsi * dpsi) * dpsi - k * psi - 0.5 * lt * r.force_n) / ik;
        [dpsi, acc, r.du, r.dy, r.dz]
    };
    for step in 0..n {
        let o = c.step(&input(quantise(psi), 1e-3));
        i_cmd = o.current_cmd_a as f64;
        i_sum += i_cmd;
        for _ in 0..sub {
            let x0 = [psi, dpsi, d.u, d.y, d.z];
            let ev = |x: &[f64; 5]| {
                f(
                    x[0],
                    x[1],
                    &SpencerState {
                        u: x[2],
                        y: x[3],
                        z: x[4],
                    },
                    i_cmd,
                )
            };
            let add = |x: &[f64; 5], k: &[f64; 5], s: f64| {
                let mut y = *x;
                for j in 0..5 {
                    y[j] += s * k[j];
                }
                y
            };
            let k1 = ev(&x0);
            let k2 = ev(&add(&x0, &k1, 0.5 * h));
            let k3 = ev(&add(&x0, &k2, 0.5 * h));
            let k4 = ev(&add(&x0, &k3, h));
            let mut x = x0;
            for j in 0..5 {
                x[j] += h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
            }
            psi = x[0];
            dpsi = x[1];
            d = SpencerState {
                u: x[2],
                y: x[3],
                z: x[4],
            };
        }
        if step >= n - 500 {
            amp_end = amp_end.max(psi.abs());
        }
    }
    let _ = i_cmd;
    (amp_end, i_sum / n as f64)
}

#[test]
fn smc_and_asmc_stop_a_growing_oscillation_that_passive_off_does_not() {
    let secs = 4.0;
    let (a_off, _) = closed_loop(ControllerKind::PassiveOff, secs);
    let (a_smc, i_smc) = closed_loop(ControllerKind::Smc, secs);
    let (a_asmc, i_asmc) = closed_loop(ControllerKind::Asmc, secs);
    let (a_sky, i_sky) = closed_loop(ControllerKind::Skyhook, secs);
    println!(
        "stand-in plant, amplitude after {secs} s from 0.02 rad: off {a_off:.4}, smc {a_smc:.4} \
         ({i_smc:.2} A mean), asmc {a_asmc:.4} ({i_asmc:.2} A), skyhook {a_sky:.4} ({i_sky:.2} A)"
    );
    assert!(a_off > 0.03, "passive off must grow: {a_off}");
    assert!(a_smc < 0.005, "smc {a_smc}");
    assert!(a_asmc < 0.005, "asmc {a_asmc}");
    assert!(a_sky < 0.005, "skyhook {a_sky}");
    // The adaptive law does it with less current than the fixed-gain one.
    assert!(i_asmc < 0.7 * i_smc, "asmc {i_asmc} A vs smc {i_smc} A");
}

// ---------------------------------------------------------------- properties

fn wild_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        4 => -0.5f32..0.5,
        1 => any::<f32>(),
        1 => Just(f32::NAN),
        1 => Just(f32::INFINITY),
        1 => Just(f32::NEG_INFINITY),
        1 => Just(f32::MAX),
        1 => Just(-1e-38f32),
    ]
}

fn wild_input() -> impl Strategy<Value = ControlInput> {
    (
        wild_f32(),
        wild_f32(),
        prop_oneof![4 => Just(1e-3f32), 1 => wild_f32()],
        prop_oneof![3 => 0.0f32..40.0, 1 => wild_f32()],
        prop_oneof![Just(None), wild_f32().prop_map(Some)],
    )
        .prop_map(|(l, r, dt, v, i)| ControlInput {
            t_s: 0.0,
            dt_s: dt,
            psi_l_rad: l,
            psi_r_rad: r,
            speed_mps: v,
            coil_current_a: i,
        })
}

fn kinds() -> impl Strategy<Value = ControllerKind> {
    prop_oneof![
        Just(ControllerKind::PassiveOff),
        wild_f32().prop_map(|c| ControllerKind::PassiveOn { current_a: c }),
        Just(ControllerKind::Smc),
        Just(ControllerKind::Asmc),
        Just(ControllerKind::Skyhook),
        Just(ControllerKind::MarginAsmc),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn output_current_is_always_bounded_and_finite(
        kind in kinds(),
        seq in proptest::collection::vec(wild_input(), 1..200),
    ) {
        let p = ControlParams::default();
        let mut c = Controller::new(kind, p);
        for i in &seq {
            let o = c.step(i);
            prop_assert!(o.current_cmd_a >= 0.0 && o.current_cmd_a <= p.limits.i_max_a,
                "current {}", o.current_cmd_a);
            prop_assert!(o.gain_radps2.is_finite());
            let k = c.adaptive_gain();
            prop_assert!(k >= p.asmc.k_min_radps2 && k <= p.asmc.k_max_radps2, "K {}", k);
        }
    }

    #[test]
    fn semi_active_controllers_never_ask_to_push(
        kind in prop_oneof![Just(ControllerKind::Smc), Just(ControllerKind::Asmc),
                            Just(ControllerKind::Skyhook)],
        seq in proptest::collection::vec(wild_input(), 1..200),
    ) {
        // Whenever the law's request reached the inverse unclipped, force and stroke rate agree
        // in sign; whenever they do not, the inverse asked for 0 A.
        let mut p = ControlParams::default();
        p.limits.slew_a_per_s = 1e9; // so the command is the inverse's current
        let mut c = Controller::new(kind, p);
        for i in &seq {
            let o = c.step(i);
            if o.flags.input_invalid || o.flags.below_speed {
                continue;
            }
            if o.desired_force_n * o.stroke_rate_mps > 0.0 {
                prop_assert!(!o.flags.clipped);
            } else {
                prop_assert!(o.flags.clipped);
                // 0 A unless a tiny dt made the slew limit hold the previous command.
                prop_assert!(o.current_cmd_a == 0.0 || o.flags.slew_limited);
            }
        }
    }

    #[test]
    fn mr_inverse_is_bounded_and_semi_active(f in wild_f32(), v in wild_f32()) {
        let m = MrModel::FITTED;
        let r = m.inverse(f * 1000.0, v);
        prop_assert!(r.current_a >= 0.0 && r.current_a <= m.i_max_a);
        // By signs, not by the product: f * v underflows to 0 for tiny same-signed values.
        let resists = (f > 0.0 && v > 0.0) || (f < 0.0 && v < 0.0);
        if !resists {
            prop_assert!(r.clipped && r.current_a == 0.0);
        }
    }

    #[test]
    fn adaptive_gain_stays_in_its_bounds(
        s in proptest::collection::vec((wild_f32(), wild_f32(), any::<bool>()), 1..300),
    ) {
        let p = AsmcParams::default();
        let mut g = AdaptiveGain::new(&p);
        for (sv, dt, fr) in s {
            g.update(&p, sv * 100.0, dt, fr);
            prop_assert!(g.get() >= p.k_min_radps2 && g.get() <= p.k_max_radps2);
        }
    }
}

#[test]
fn switching_the_law_at_run_time_keeps_the_state() {
    // A simulator or the firmware switches laws between steps: the conditioning keeps running
    // (no start-up transient) and the adaptive gain keeps its value.
    let p = ControlParams::default();
    let sig = |k: usize| 0.01 * (2.0 * PI * 6.0 * k as f64 / 1000.0).sin();
    let mut a = Controller::new(ControllerKind::Asmc, p);
    let mut b = Controller::new(ControllerKind::Asmc, p);
    for k in 0..500 {
        a.step(&input(quantise(sig(k)), 1e-3));
        b.step(&input(quantise(sig(k)), 1e-3));
    }
    let k_before = a.adaptive_gain();
    a.set_kind(ControllerKind::Smc);
    assert_eq!(a.kind(), ControllerKind::Smc);
    let oa = a.step(&input(quantise(sig(500)), 1e-3));
    let ob = b.step(&input(quantise(sig(500)), 1e-3));
    assert_eq!(oa.conditioned, ob.conditioned);
    assert_eq!(a.adaptive_gain(), k_before);
    a.set_kind(ControllerKind::Asmc);
    assert_eq!(a.adaptive_gain(), k_before);
    a.reset();
    assert_eq!(a.adaptive_gain(), p.asmc.k_init_radps2);
}

// ---------------------------------------------------------------- margin schedule, quiet coil

/// Encoder noise alone (+-1 LSB on each 14-bit encoder): (rms and max of the shimmy-band
/// amplitude, mean current, TV of the command) of `kind`.
fn noise_amplitude(kind: ControllerKind, p: ControlParams, secs: f64) -> (f64, f64, f64, f64) {
    let lsb = 2.0 * PI / 16384.0;
    let (mut nl, mut nr) = (noise(7), noise(11));
    let mut c = Controller::new(kind, p);
    let mut amp = schedule::QuietCoil::new();
    let n = (secs * 1000.0) as usize;
    let (mut aa, mut amax, mut isum, mut tv, mut last) = (0.0, 0.0f64, 0.0, 0.0, 0.0);
    for k in 0..n {
        let mut i = input(0.0, 1e-3);
        i.psi_l_rad = quantise(lsb * nl());
        i.psi_r_rad = quantise(lsb * nr());
        let o = c.step(&i);
        let a = f64::from(amp.band_amplitude(
            &p.schedule,
            o.conditioned.psi_hp_rad,
            o.conditioned.rate_hp_radps,
            1e-3,
        ));
        if k > 500 {
            aa += a * a;
            amax = amax.max(a);
        }
        isum += f64::from(o.current_cmd_a);
        tv += (f64::from(o.current_cmd_a) - last).abs();
        last = f64::from(o.current_cmd_a);
    }
    ((aa / (n - 501) as f64).sqrt(), amax, isum / n as f64, tv)
}

#[test]
fn quiet_coil_stays_off_on_encoder_noise() {
    // Encoder noise alone must not reach the coil, even fully armed (no margin report).
    let p = ControlParams::default();
    let (a_rms, a_max, i_mean, tv) = noise_amplitude(ControllerKind::MarginAsmc, p, 5.0);
    println!(
        "encoder noise: band amplitude rms {:.4} deg, max {:.4} deg; margin-asmc mean current {i_mean:.4} A, TV {tv:.3} A",
        a_rms.to_degrees(),
        a_max.to_degrees()
    );
    assert!(
        a_max < 0.5 * f64::from(p.schedule.armed_engage_rad),
        "{a_max}"
    );
    assert_eq!(tv, 0.0);
    // The band-pass is what keeps it off: the raw pair's amplitude (the observer's rate noise
    // up to 60 Hz) reaches several times the armed engage amplitude.
    let mut c = Controller::new(ControllerKind::MarginAsmc, p);
    let lsb = 2.0 * PI / 16384.0;
    let (mut nl, mut nr) = (noise(7), noise(11));
    let mut raw_max = 0.0f32;
    for k in 0..5000 {
        let mut i = input(0.0, 1e-3);
        i.psi_l_rad = quantise(lsb * nl());
        i.psi_r_rad = quantise(lsb * nr());
        let o = c.step(&i);
        if k > 500 {
            raw_max = raw_max.max(schedule::band_amplitude_rad(
                o.conditioned.psi_hp_rad,
                o.conditioned.rate_hp_radps,
                p.schedule.band_hz,
            ));
        }
    }
    assert!(
        raw_max > p.schedule.armed_engage_rad,
        "raw amplitude max {raw_max}"
    );
}

/// A decaying 6 Hz shimmy burst (0.5 deg, decay 2 1/s) on noisy 14-bit encoders: (total
/// variation of the command, coil energy at 4 ohm) over 3 s.
fn burst_chatter(kind: ControllerKind, p: ControlParams) -> (f64, f64) {
    let lsb = 2.0 * PI / 16384.0;
    let (mut nl, mut nr) = (noise(3), noise(5));
    let mut c = Controller::new(kind, p);
    let (mut tv, mut e, mut last) = (0.0, 0.0, 0.0);
    for k in 0..3000 {
        let t = k as f64 * 1e-3;
        let y = 0.5f64.to_radians() * (-2.0 * t).exp() * (2.0 * PI * 6.0 * t).sin();
        let mut i = input(0.0, 1e-3);
        i.psi_l_rad = quantise(y + lsb * nl());
        i.psi_r_rad = quantise(y + lsb * nr());
        let cmd = f64::from(c.step(&i).current_cmd_a);
        tv += (cmd - last).abs();
        e += 4.0 * cmd * cmd * 1e-3;
        last = cmd;
    }
    (tv, e)
}

#[test]
fn quiet_coil_holds_the_chatter_down() {
    // The measured chatter figure: the margin-scheduled law's command has a small fraction of
    // the plain ASMC's total variation on the same burst (the ASMC switches every half cycle).
    let p = ControlParams::default();
    let (tv_m, e_m) = burst_chatter(ControllerKind::MarginAsmc, p);
    let (tv_a, e_a) = burst_chatter(ControllerKind::Asmc, p);
    println!("burst: TV margin-asmc {tv_m:.1} A ({e_m:.2} J), asmc {tv_a:.1} A ({e_a:.2} J)");
    assert!(tv_m > 0.0, "the coil must act on the burst");
    assert!(tv_m < 20.0 && 5.0 * tv_m < tv_a, "TV {tv_m} vs {tv_a}");
    // Without the envelope (release 0) the clipped half cycles switch again.
    let mut q = p;
    q.schedule.release_s = 0.0;
    let (tv_0, _) = burst_chatter(ControllerKind::MarginAsmc, q);
    println!("without the envelope: TV {tv_0:.1} A");
    assert!(tv_0 > 3.0 * tv_m, "{tv_0}");
}

/// The arming is a function of the margin: a reference margin and the same with one quantity
/// smaller.
fn margin_signal() -> impl Strategy<Value = schedule::MarginSignal> {
    let q = || prop_oneof![4 => -1.0f32..50.0, 1 => Just(f32::INFINITY), 1 => any::<f32>()];
    (q(), q(), q()).prop_map(|(dv, ttc, z)| schedule::MarginSignal {
        speed_margin_mps: dv,
        time_to_critical_s: ttc,
        zeta_fast: z / 100.0,
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn schedule_is_monotone_in_the_margin(
        m in margin_signal(),
        which in 0usize..3,
        cut in 0.0f32..1.0,
    ) {
        // A smaller margin (any one quantity moved towards critical) never lowers the base
        // current, never widens the boundary layer, never raises the engage amplitude.
        let p = ScheduleParams::default();
        let phi = SmcParams::default().phi_radps;
        let mut closer = m;
        match which {
            0 => closer.speed_margin_mps = m.speed_margin_mps * cut,
            1 => closer.time_to_critical_s = m.time_to_critical_s * cut,
            _ => closer.zeta_fast = m.zeta_fast - cut,
        }
        let (far, near) = (p.schedule(Some(&m), phi), p.schedule(Some(&closer), phi));
        for s in [far, near] {
            prop_assert!(s.arming.is_finite() && (0.0..=1.0).contains(&s.arming));
            prop_assert!(s.base_current_a.is_finite() && s.phi_radps.is_finite());
        }
        let finite = m.speed_margin_mps.is_finite() && m.time_to_critical_s.is_finite()
            && m.zeta_fast.is_finite();
        if finite && m.speed_margin_mps >= 0.0 && m.time_to_critical_s >= 0.0 {
            prop_assert!(near.arming >= far.arming, "{far:?} -> {near:?}");
            prop_assert!(near.base_current_a >= far.base_current_a);
            prop_assert!(near.phi_radps <= far.phi_radps);
            prop_assert!(near.engage_rad <= far.engage_rad);
        }
        // No report is the safe side: at least as armed as any report.
        let none = p.schedule(None, phi);
        prop_assert!(none.arming >= far.arming && none.base_current_a >= far.base_current_a);
    }

    #[test]
    fn margin_asmc_command_is_bounded_finite_and_semi_active(
        seq in proptest::collection::vec((wild_input(), prop_oneof![Just(None), margin_signal().prop_map(Some)]), 1..300),
    ) {
        // Whatever the inputs and margin reports: never NaN, always in [0, I_max], and the
        // damper model's force at the command always resists the stroke rate (semi-active).
        let p = ControlParams::default();
        let mut c = Controller::new(ControllerKind::MarginAsmc, p);
        for (i, m) in &seq {
            c.set_margin(*m);
            let o = c.step(i);
            prop_assert!(o.current_cmd_a.is_finite());
            prop_assert!(o.current_cmd_a >= 0.0 && o.current_cmd_a <= p.limits.i_max_a,
                "current {}", o.current_cmd_a);
            let v = o.stroke_rate_mps;
            if v.is_finite() {
                prop_assert!(p.mr.force_n(o.current_cmd_a, v) * v >= 0.0);
            }
            let k = c.adaptive_gain();
            prop_assert!(k >= p.asmc.k_min_radps2 && k <= p.asmc.k_max_radps2, "K {}", k);
        }
    }
}

#[test]
fn speed_schedule_is_a_trapezoid_over_speed() {
    let t = schedule::SpeedSchedule {
        v_lo_mps: 10.0,
        v_hi_mps: 20.0,
        ramp_mps: 2.0,
        current_a: 1.5,
    };
    assert_eq!(t.current_at(15.0), 1.5);
    assert_eq!(t.current_at(10.0), 1.5);
    assert!((t.current_at(9.0) - 0.75).abs() < 1e-6);
    assert!((t.current_at(21.5) - 0.375).abs() < 1e-6);
    assert_eq!(t.current_at(5.0), 0.0);
    assert_eq!(t.current_at(f32::NAN), 1.5);
}
