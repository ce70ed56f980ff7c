//! Time-domain checks of the nonlinear plant (host-sim/src/model/plant.rs): integration accuracy,
//! energy at standstill, agreement with the FD-Jacobian eigenvalues at small amplitude, limit
//! cycles inside the Hopf window, suppression by the MR damper, and the Hopf window itself.
//!
//! Runs are short (seconds of simulated time); the full-speed-grid study is the
//! `shimmy-sim bifurcation` command.

use shimmy_core::units::kmh_to_mps;
use shimmy_core::vehicles::car::{Param, PlantParams};
use shimmy_sim::model::disturbance::initial_yaw;
use shimmy_sim::model::plant::{
    fd_eigenvalues, idx, jacobian_fd, least_damped_mode, Damper, Inputs, Method, Plant, Simulator,
    State, N_PLANT, N_STATE,
};
use shimmy_sim::sim::run::open_loop::{fit_growth, peaks, run_speed, DamperSetting, Trend};

const DT: f64 = 1e-3;

fn run(sim: &mut Simulator, u: &Inputs, seconds: f64) -> Vec<State> {
    let n = (seconds / DT).round() as usize;
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        sim.advance(DT, u).expect("integration");
        out.push(*sim.state());
    }
    out
}

fn max_abs_diff(a: &[State], b: &[State], i: usize) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x[i] - y[i]).abs())
        .fold(0.0, f64::max)
}

/// Speed inside the Hopf window used below, chosen from the FD-Jacobian eigenvalues (the speed
/// of the grid 5..130 km/h with the largest growth rate), never typed in.
fn most_unstable_speed_mps(p: &PlantParams) -> f64 {
    (1..=26)
        .map(|k| kmh_to_mps(5.0 * f64::from(k)))
        .max_by(|a, b| {
            let ra = least_damped_mode(p, *a).expect("eig").0;
            let rb = least_damped_mode(p, *b).expect("eig").0;
            ra.total_cmp(&rb)
        })
        .expect("grid")
}

/// Relative tolerance of the IMEX method as the accuracy tests run it (the default of
/// `Method::Imex` in the simulator's benchmark and `Method::default()` when it is the IMEX one).
const IMEX_RTOL: f64 = 3e-6;

/// Step halving with the MR damper on (0 A: the damper slides, the stiff case) inside the Hopf
/// window from a 3 deg start, 2 s: RK4 with 10 and 20 sub-steps per 1 ms period must agree to
/// 1e-6 rad on wheel yaw over the whole run; the adaptive Dopri5 (rtol 1e-7), the IMEX ARK
/// method and whatever `Simulator::new` defaults to must each agree with the 20-sub-step RK4 to
/// the same 1e-6 rad (independent second solvers).
#[test]
fn step_halving_and_second_solver_agree_with_damper_on() {
    let p = PlantParams::nominal();
    let v = most_unstable_speed_mps(&p);
    let plant = Plant::with_mr_damper(p);
    let u = Inputs {
        current_cmd_a: 0.0,
        speed_mps: v,
        ..Inputs::default()
    };
    let x0 = initial_yaw(3f64.to_radians());
    let coarse = run(
        &mut Simulator::with_method(plant, x0, Method::Rk4 { substeps: 10 }),
        &u,
        2.0,
    );
    let fine = run(
        &mut Simulator::with_method(plant, x0, Method::Rk4 { substeps: 20 }),
        &u,
        2.0,
    );
    let dopri = run(
        &mut Simulator::with_method(plant, x0, Method::Dopri5 { rtol: 1e-7 }),
        &u,
        2.0,
    );
    let imex = run(
        &mut Simulator::with_method(plant, x0, Method::Imex { rtol: IMEX_RTOL }),
        &u,
        2.0,
    );
    let default = run(&mut Simulator::new(plant, x0), &u, 2.0);
    let d_half = max_abs_diff(&coarse, &fine, idx::PSI_L);
    let d_dopri = max_abs_diff(&dopri, &fine, idx::PSI_L);
    let d_imex = max_abs_diff(&imex, &fine, idx::PSI_L);
    let d_default = max_abs_diff(&default, &fine, idx::PSI_L);
    // The run must actually exercise the damper: it slides (z reaches its plateau region).
    let z_max = fine.iter().map(|x| x[idx::Z].abs()).fold(0.0, f64::max);
    println!(
        "step halving: {d_half:.3e} rad, dopri5 vs rk4/20: {d_dopri:.3e} rad, imex vs rk4/20: \
         {d_imex:.3e} rad, default vs rk4/20: {d_default:.3e} rad, z_max {z_max:.2e} m"
    );
    assert!(z_max > 1e-3, "damper did not slide: z_max {z_max}");
    assert!(
        d_half < 1e-6,
        "RK4 10 vs 20 sub-steps differ by {d_half} rad"
    );
    assert!(d_dopri < 1e-6, "Dopri5 vs RK4 differ by {d_dopri} rad");
    assert!(d_imex < 1e-6, "IMEX vs RK4 differ by {d_imex} rad");
    assert!(
        d_default < 1e-6,
        "default method vs RK4 differ by {d_default} rad"
    );
    // Negative check: a far too coarse RK4 (1 step per ms) is visibly wrong or unstable here,
    // so the comparison above can fail.
    let mut bad = Simulator::with_method(plant, x0, Method::Rk4 { substeps: 1 });
    let mut worst: f64 = 0.0;
    for xf in &fine {
        if bad.advance(DT, &u).is_err() {
            worst = f64::INFINITY;
            break;
        }
        let d = (bad.state()[idx::PSI_L] - xf[idx::PSI_L]).abs();
        worst = worst.max(if d.is_finite() { d } else { f64::INFINITY });
    }
    println!("1 RK4 step per ms: worst error {worst:.3e} rad");
    assert!(
        worst > 1e-5,
        "1 RK4 step per ms unexpectedly accurate: {worst}"
    );
}

/// The fixed-step IMEX integrator (`Method::ImexFixed`: ARK4(3)6L\[2\]SA, z implicit, no error
/// control) on the stiff case of the test above (damper sliding at 0 A in the Hopf window, 3 deg
/// start, 2 s), against a tight Dopri5 (rtol 1e-11, an independent solver). Halving the step
/// (1, 2, 4 steps per 1 ms period) shrinks the error by at least 2^2 each time: the method is
/// 4th order where the right-hand side is smooth, but z's law has kinks (|rel| and |z| at each
/// stroke reversal) that the steps straddle, and a step over a kink has an O(h^2) local error,
/// so the global order tends to 2 (measured 3.4 then 2.4). Two steps per period meet the
/// 1e-6 rad of the test above. Negative check: an
/// explicit method at the same cost (RK4 with 3 steps per period, 12 evaluations like 2 IMEX
/// steps) is unstable or far less accurate on the same run.
#[test]
fn imex_fixed_step_converges_where_explicit_fails() {
    let p = PlantParams::nominal();
    let v = most_unstable_speed_mps(&p);
    let plant = Plant::with_mr_damper(p);
    let u = Inputs {
        current_cmd_a: 0.0,
        speed_mps: v,
        ..Inputs::default()
    };
    let x0 = initial_yaw(3f64.to_radians());
    let reference = run(
        &mut Simulator::with_method(plant, x0, Method::Dopri5 { rtol: 1e-11 }),
        &u,
        2.0,
    );
    let z_max = reference
        .iter()
        .map(|x| x[idx::Z].abs())
        .fold(0.0, f64::max);
    assert!(z_max > 1e-3, "damper did not slide: z_max {z_max}");
    // Worst |psi_L| error over the run (infinite if the integration fails or blows up).
    let err = |method: Method| {
        let mut sim = Simulator::with_method(plant, x0, method);
        let mut worst: f64 = 0.0;
        for xr in &reference {
            if sim.advance(DT, &u).is_err() {
                return f64::INFINITY;
            }
            let d = (sim.state()[idx::PSI_L] - xr[idx::PSI_L]).abs();
            worst = worst.max(if d.is_finite() { d } else { f64::INFINITY });
        }
        worst
    };
    let [e1, e2, e4] = [1, 2, 4].map(|substeps| err(Method::ImexFixed { substeps }));
    let (p12, p24) = ((e1 / e2).log2(), (e2 / e4).log2());
    let e_rk4 = err(Method::Rk4 { substeps: 3 });
    println!(
        "imex-fixed vs Dopri5 1e-11: 1 step {e1:.3e}, 2 steps {e2:.3e}, 4 steps {e4:.3e} rad; \
         orders {p12:.2}, {p24:.2}; RK4 3 steps: {e_rk4:.3e} rad"
    );
    assert!(e2 < 1e-6, "two IMEX steps per ms: error {e2} rad");
    assert!(p12 > 2.0 && p24 > 2.0, "observed orders {p12}, {p24}");
    assert!(
        e_rk4 > 10.0 * e2,
        "explicit RK4 at equal cost unexpectedly accurate: {e_rk4} rad"
    );
}

/// Total energy at standstill: kinetic + springs + the tyres' lagged deformation.
///
/// At V = 0 the tyre-lag equation is sigma a' = e dpsi - h_r dphi: the contact patch is a lateral
/// spring, and sigma * int_0^a F(s) ds is its stored energy. With E = T + U + sum_i sigma int F,
/// dE/dt = -(c_k dpsi_L^2 + c_k dpsi_R^2 + c_phi dphi^2 + c_sw dtheta^2) - t_p (F_L dpsi_L +
/// F_R dpsi_R): every term is dissipative except the pneumatic-trail one, which can inject
/// energy (at standstill a real tyre has no pneumatic trail: t_p is a rolling-tyre quantity).
fn standstill_start() -> State {
    let mut x = [0.0; N_STATE];
    x[idx::PSI_L] = 0.02;
    x[idx::PSI_R] = -0.01;
    x[idx::PHI] = 0.005;
    x[idx::THETA_SW] = 0.3;
    x[idx::DPSI_L] = 0.5;
    x[idx::DPHI] = -0.2;
    x[idx::A_L] = 0.01;
    x[idx::A_R] = -0.03; // beyond the linear region of the Magic Formula
    x
}

fn total_energy(plant: &Plant, x: &State) -> f64 {
    plant.mechanical_energy_j(x)
        + plant.tyre_strain_energy_j(x[idx::A_L])
        + plant.tyre_strain_energy_j(x[idx::A_R])
}

/// With t_p = 0 the energy never increases along a standstill trajectory (tolerance 1e-9 of the
/// initial energy per step: integration and quadrature error), and it does decrease.
#[test]
fn energy_never_increases_at_standstill_without_pneumatic_trail() {
    let p = PlantParams::nominal().with(Param::TP, 0.0);
    let plant = Plant::new(p, Damper::None);
    let x0 = standstill_start();
    let e0 = total_energy(&plant, &x0);
    let mut sim = Simulator::with_method(plant, x0, Method::Dopri5 { rtol: 1e-10 });
    let u = Inputs::default();
    let mut e_prev = e0;
    for _ in 0..2000 {
        sim.advance(DT, &u).expect("integration");
        let e = total_energy(&plant, sim.state());
        assert!(
            e <= e_prev + 1e-9 * e0,
            "energy rose from {e_prev} to {e} J"
        );
        e_prev = e;
    }
    assert!(
        e_prev < 0.5 * e0,
        "energy barely dissipated: {e_prev} of {e0} J"
    );
    // The tyre term matters: without it the mechanical energy alone is not monotone.
    let mut sim = Simulator::with_method(plant, x0, Method::Dopri5 { rtol: 1e-10 });
    let mut rises = false;
    let mut em_prev = plant.mechanical_energy_j(&x0);
    for _ in 0..2000 {
        sim.advance(DT, &u).expect("integration");
        let em = plant.mechanical_energy_j(sim.state());
        rises |= em > em_prev + 1e-6 * e0;
        em_prev = em;
    }
    assert!(
        rises,
        "mechanical energy alone never rose: the tyre energy term is untested"
    );
}

/// With the nominal pneumatic trail the power balance dE/dt = -dissipation - t_p sum F dpsi holds
/// along the trajectory (integrated, to 1e-6 of E0), and the trail term does inject energy at some
/// instants (positive power): the model at V = 0 is not passive unless t_p = 0.
#[test]
fn pneumatic_trail_power_balance_at_standstill() {
    let p = PlantParams::nominal();
    let plant = Plant::new(p, Damper::None);
    let x0 = standstill_start();
    let e0 = total_energy(&plant, &x0);
    let mut sim = Simulator::with_method(plant, x0, Method::Dopri5 { rtol: 1e-11 });
    let u = Inputs::default();
    let power = |x: &State| {
        let f = plant.forces(x, &u).tyre_n;
        let diss =
            p.c_k * (x[4] * x[4] + x[5] * x[5]) + p.c_phi * x[6] * x[6] + p.c_sw * x[7] * x[7];
        let trail = -p.t_p * (f[0] * x[4] + f[1] * x[5]);
        (diss, trail)
    };
    let h = 1e-4;
    let (mut integral, mut injects) = (0.0, false);
    let (d0, t0) = power(&x0);
    let mut prev = t0 - d0;
    for _ in 0..10_000 {
        sim.advance(h, &u).expect("integration");
        let (d, t) = power(sim.state());
        injects |= t > 0.0 && t > 1e-3 * d;
        let now = t - d;
        integral += 0.5 * h * (prev + now);
        prev = now;
    }
    let e1 = total_energy(&plant, sim.state());
    let mismatch = (e1 - e0 - integral).abs();
    println!(
        "E0 {e0:.4} J, E1 {e1:.4} J, integral of power {integral:.4} J, mismatch {mismatch:.2e} J"
    );
    assert!(mismatch < 1e-6 * e0, "power balance off by {mismatch} J");
    assert!(injects, "the pneumatic trail never injected energy");
}

/// Eigenvector of the FD Jacobian for eigenvalue `(re, im)` by one step of complex inverse
/// iteration with a slightly shifted eigenvalue; returned as the real initial state that excites
/// only this mode (Re v, scaled so |psi_L| = `psi_l_rad`).
fn mode_start(p: &PlantParams, v_mps: f64, (re, im): (f64, f64), psi_l_rad: f64) -> State {
    use nalgebra::{Complex, DMatrix, DVector};
    let j = jacobian_fd(p, v_mps);
    let n = N_PLANT;
    let lam = Complex::new(re, im) * (1.0 + 1e-9);
    let a = DMatrix::from_fn(n, n, |r, c| {
        Complex::new(j[(r, c)], 0.0) - if r == c { lam } else { Complex::new(0.0, 0.0) }
    });
    let lu = a.lu();
    let mut v = DVector::from_element(n, Complex::new(1.0, 0.0));
    for _ in 0..2 {
        v = lu.solve(&v).expect("solve");
        let s = v[idx::PSI_L];
        v /= s; // psi_L component real and 1
    }
    let mut x = [0.0; N_STATE];
    for i in 0..n {
        x[i] = psi_l_rad * v[i].re;
    }
    x
}

/// Small amplitude (1e-5 rad, Magic Formula in its linear region to ~1e-7 relative): growth rate
/// and frequency from successive peaks of psi_L over 3 s match the shimmy eigenvalue of the FD
/// Jacobian within 2 %, inside the window (growing, most unstable grid speed) and below it
/// (25 km/h, decaying), no damper. The run starts on the mode's eigenvector so the fit sees one
/// mode (the 47 Hz anti-phase wheel mode is less damped at some speeds).
#[test]
fn small_amplitude_time_domain_matches_eigenvalue() {
    let p = PlantParams::nominal();
    let v_in = most_unstable_speed_mps(&p);
    let shimmy_omega = least_damped_mode(&p, v_in).expect("eig").1;
    for (v, label) in [(v_in, "inside"), (kmh_to_mps(25.0), "below")] {
        // The eigenvalue nearest the shimmy frequency at this speed.
        let (re, im) = fd_eigenvalues(&p, v)
            .expect("eig")
            .into_iter()
            .filter(|e| e.1 > 0.0)
            .min_by(|a, b| {
                (a.1 - shimmy_omega)
                    .abs()
                    .total_cmp(&(b.1 - shimmy_omega).abs())
            })
            .expect("mode");
        let x0 = mode_start(&p, v, (re, im), 1e-5);
        let mut sim = Simulator::with_method(
            Plant::new(p, Damper::None),
            x0,
            Method::Dopri5 { rtol: 1e-9 },
        );
        let u = Inputs {
            speed_mps: v,
            ..Inputs::default()
        };
        let xs = run(&mut sim, &u, 3.0);
        let s: Vec<f64> = xs.iter().map(|x| x[idx::PSI_L]).collect();
        let pk = peaks(DT, DT, &s);
        let (rate, omega) = fit_growth(&pk).expect("peaks");
        let peak_max = s.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        println!(
            "{label} ({:.1} km/h): eig {re:.4} {im:.3} | time domain {rate:.4} {omega:.3} | peak {peak_max:.2e} rad",
            v * 3.6
        );
        assert!(peak_max < 1e-3, "left the linear region");
        assert!(
            (rate - re).abs() <= 0.02 * re.abs(),
            "{label}: rate {rate} vs {re}"
        );
        assert!(
            (omega - im).abs() <= 0.02 * im,
            "{label}: omega {omega} vs {im}"
        );
    }
}

/// Inside the Hopf window with the damper off the plant settles on a limit cycle: amplitude
/// clearly nonzero (> 0.5 deg), bounded (< 20 deg) and steady (last two 1 s windows within 2 %):
/// with no damper from a small start (0.05 deg), with the MR damper at 0 A from a large start
/// (3 deg). The MR damper at 0 A is not "no damper": its pre-yield Bouc-Wen stiffness
/// (alpha_a A_bw) and c0a viscosity make the straight running locally stable, so a 0.05 deg start
/// decays while a 3 deg start breaks through to shimmy (bistability, asserted here).
/// Below the window a 3 deg start decays without a damper.
#[test]
fn damper_off_limit_cycle_inside_window_decay_outside() {
    let p = PlantParams::nominal();
    let v_in = most_unstable_speed_mps(&p);
    for (d, start_deg) in [
        (DamperSetting::Off, 0.05),
        (DamperSetting::reference_mr(0.0), 3.0),
    ] {
        let r = run_speed(&p, d, v_in, f64::to_radians(start_deg), 12.0, 1.0).expect("run");
        println!(
            "{d:?} at {:.1} km/h from {start_deg} deg: {:.3} deg {:?}",
            v_in * 3.6,
            r.amp_end_rad.to_degrees(),
            r.trend
        );
        assert_eq!(r.trend, Trend::Steady, "{d:?}: not settled: {r:?}");
        assert!(
            r.amp_end_rad > 0.5f64.to_radians() && r.amp_end_rad < 20f64.to_radians(),
            "{d:?}: {r:?}"
        );
    }
    let r = run_speed(
        &p,
        DamperSetting::reference_mr(0.0),
        v_in,
        0.05f64.to_radians(),
        6.0,
        1.0,
    )
    .expect("run");
    assert!(
        r.amp_end_rad < 0.1 * 0.05f64.to_radians(),
        "0 A, small start: {r:?}"
    );
    // Below the window (10 km/h: the FD eigenvalue there must be stable for this to mean much).
    let v_low = kmh_to_mps(10.0);
    assert!(least_damped_mode(&p, v_low).expect("eig").0 < 0.0);
    let r = run_speed(&p, DamperSetting::Off, v_low, 3f64.to_radians(), 6.0, 1.0).expect("run");
    assert!(
        r.amp_end_rad < 0.1 * 3f64.to_radians(),
        "no decay below the window: {r:?}"
    );
}

/// The MR damper at 2 A: no shimmy anywhere on a 5..130 km/h grid (every 10 km/h) from a 3 deg
/// start: after 4 s the amplitude is below 5 % of the start and not growing.
#[test]
fn damper_at_2a_suppresses_shimmy_at_every_speed() {
    let p = PlantParams::nominal();
    for k in 0..=12 {
        let v_kmh = 5.0 + 10.0 * f64::from(k);
        let r = run_speed(
            &p,
            DamperSetting::reference_mr(2.0),
            kmh_to_mps(v_kmh),
            3f64.to_radians(),
            4.0,
            0.5,
        )
        .expect("run");
        assert!(
            r.amp_end_rad < 0.05 * 3f64.to_radians() && r.trend != Trend::Growing,
            "shimmy at {v_kmh} km/h with 2 A: {r:?}"
        );
    }
}

/// Growth rate (1/s) of a small disturbance (1e-5 rad in-phase start) in the time domain at
/// `v_mps`, no damper: after 3 s of transients, ln of the ratio of the peak in-phase wheel yaw
/// |psi_L + psi_R| over [4, 5] s to that over [3, 4] s. The in-phase sum hides the anti-phase
/// 47 Hz wheel mode, which is the least damped mode outside the window.
fn time_domain_rate(p: &PlantParams, v_mps: f64) -> f64 {
    let mut sim = Simulator::new(Plant::new(*p, Damper::None), initial_yaw(1e-5));
    let u = Inputs {
        speed_mps: v_mps,
        ..Inputs::default()
    };
    run(&mut sim, &u, 3.0);
    let env = |xs: &[State]| {
        xs.iter()
            .map(|x| (x[idx::PSI_L] + x[idx::PSI_R]).abs())
            .fold(0.0, f64::max)
    };
    let a1 = env(&run(&mut sim, &u, 1.0));
    let a2 = env(&run(&mut sim, &u, 1.0));
    (a2 / a1).ln()
}

fn bisect(
    p: &PlantParams,
    mut lo: f64,
    mut hi: f64,
    rate: impl Fn(&PlantParams, f64) -> f64,
) -> f64 {
    let s_lo = rate(p, lo).signum();
    for _ in 0..12 {
        let mid = 0.5 * (lo + hi);
        if rate(p, mid).signum() == s_lo {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Hopf window from the time domain: the speeds where small disturbances start to grow and stop
/// growing, by bisection on the sign of the measured growth rate, agree with the sign changes of
/// the FD-Jacobian's least-damped eigenvalue within 0.5 km/h; and the window closes at the top
/// only because of the gyroscopic coupling: with I_p = 0 small disturbances still grow at 130 km/h.
#[test]
fn hopf_window_from_time_domain() {
    let p = PlantParams::nominal();
    let v_mid = most_unstable_speed_mps(&p);
    let (v_lo, v_hi) = (kmh_to_mps(5.0), kmh_to_mps(130.0));
    assert!(time_domain_rate(&p, v_lo) < 0.0 && time_domain_rate(&p, v_hi) < 0.0);
    assert!(time_domain_rate(&p, v_mid) > 0.0);
    let on_td = bisect(&p, v_lo, v_mid, time_domain_rate);
    let off_td = bisect(&p, v_mid, v_hi, time_domain_rate);
    // The shimmy mode's real part (the oscillatory eigenvalue below 20 Hz with the largest real
    // part; the anti-phase wheel mode at ~47 Hz is excluded, as in the time-domain measure).
    let eig_rate = |p: &PlantParams, v: f64| {
        fd_eigenvalues(p, v)
            .expect("eig")
            .into_iter()
            .filter(|e| e.1 > 1.0 && e.1 < 2.0 * std::f64::consts::PI * 20.0)
            .map(|e| e.0)
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let on_eig = bisect(&p, v_lo, v_mid, eig_rate);
    let off_eig = bisect(&p, v_mid, v_hi, eig_rate);
    println!(
        "Hopf window, time domain: {:.2} .. {:.2} km/h; FD eigenvalues: {:.2} .. {:.2} km/h",
        on_td * 3.6,
        off_td * 3.6,
        on_eig * 3.6,
        off_eig * 3.6
    );
    assert!((on_td - on_eig).abs() * 3.6 < 0.5);
    assert!((off_td - off_eig).abs() * 3.6 < 0.5);
    let no_gyro = p.with(Param::IP, 0.0);
    assert!(
        time_domain_rate(&no_gyro, v_hi) > 0.0,
        "without gyroscopic coupling the window should stay open"
    );
}

/// An open-loop scenario with every disturbance (speed ramp, road noise, wheel imbalance,
/// pothole impulse, lane change) runs through `simulate`, records a consistent trace, and is
/// bit-for-bit reproducible with the same seed (and differs with another seed).
#[test]
fn scenario_runs_are_reproducible_and_record_the_trace() {
    use shimmy_sim::model::disturbance::{
        DriverTorque, Imbalance, Impulse, RoadNoise, Scenario, SpeedProfile,
    };
    use shimmy_sim::sim::run::open_loop::simulate;
    let p = PlantParams::nominal();
    let make = |seed: u64| {
        let mut s = Scenario::new(SpeedProfile::Ramp {
            v0_mps: kmh_to_mps(20.0),
            v1_mps: kmh_to_mps(60.0),
            t0_s: 0.0,
            t1_s: 3.0,
        });
        s.current_a = 0.5;
        s.driver = DriverTorque::LaneChange {
            amplitude_nm: 3.0,
            period_s: 1.5,
            t0_s: 0.5,
        };
        s.impulses.push(Impulse {
            t0_s: 1.0,
            duration_s: 0.02,
            peak_nm: [200.0, 200.0],
        });
        s.noise = Some(RoadNoise::new(5.0, 30.0, 0.5, seed));
        s.imbalance = Some(Imbalance {
            amplitude_nm: [2.0, 2.0],
            phase_rad: [0.0, 1.0],
            radius_m: p.r,
        });
        s
    };
    let go = |seed: u64| {
        let mut sim = Simulator::new(Plant::with_mr_damper(p), [0.0; N_STATE]);
        simulate(&mut sim, &mut make(seed), 3.0, DT, 10).expect("sim")
    };
    let (a, b, c) = (go(1), go(1), go(2));
    assert_eq!(a.t_s.len(), 301);
    assert_eq!(a.x.len(), a.damper_force_n.len());
    assert!((a.speed_mps[0] - kmh_to_mps(20.0)).abs() < 0.02);
    assert!((a.speed_mps[300] - kmh_to_mps(60.0)).abs() < 0.02);
    assert!(a.current_cmd_a.iter().all(|&i| i == 0.5));
    assert_eq!(a.x, b.x);
    assert_ne!(a.x, c.x);
    // The wheels move and the damper works.
    let psi = a.series(idx::PSI_L);
    assert!(psi.iter().fold(0.0f64, |m, v| m.max(v.abs())) > 1e-4);
    assert!(a.damper_force_n.iter().any(|f| f.abs() > 1.0));
}

/// The IMEX method against the fine RK4 reference (20 sub-steps per 1 ms, itself checked by step
/// halving above) on a sliding case that also exercises input changes: 60 km/h, 3 deg start,
/// the coil current command switching between 0 and 1 A every 50 ms (so the coil state u moves
/// and the held inputs change between periods) for 2 s. Wheel yaw must agree to 1e-6 rad (the
/// accuracy bar of the step-halving test) and the damper force to 1e-3 of its peak (the force
/// swings by twice its peak within ~1 ms at each reversal, so a small phase error shows up
/// amplified in it). The IMEX method must also need fewer right-hand-side evaluations than the
/// explicit Dopri5 at its default tolerance (rtol 1e-7, the same accuracy bar): that is its
/// reason to exist. With the tolerance loosened 3x (1e-5) the IMEX method misses the 1e-6 rad
/// bar here (1.2e-6 rad measured), so the chosen tolerance is not far inside the bar.
#[test]
fn imex_matches_fine_rk4_while_sliding_with_switching_current() {
    let p = PlantParams::nominal();
    let plant = Plant::with_mr_damper(p);
    let x0 = initial_yaw(3f64.to_radians());
    let inputs = |k: usize| Inputs {
        current_cmd_a: if (k / 50).is_multiple_of(2) { 0.0 } else { 1.0 },
        speed_mps: kmh_to_mps(60.0),
        ..Inputs::default()
    };
    let n = 2000;
    let mut sims = [
        Simulator::with_method(plant, x0, Method::Rk4 { substeps: 20 }),
        Simulator::with_method(plant, x0, Method::Imex { rtol: IMEX_RTOL }),
        Simulator::with_method(plant, x0, Method::Dopri5 { rtol: 1e-7 }),
    ];
    let (mut d_psi, mut d_force, mut z_max, mut f_max) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for k in 0..n {
        let u = inputs(k);
        for s in sims.iter_mut() {
            s.advance(DT, &u).expect("integration");
        }
        let u_next = inputs(k + 1);
        let (r, m) = (&sims[0], &sims[1]);
        d_psi = d_psi.max((r.state()[idx::PSI_L] - m.state()[idx::PSI_L]).abs());
        let fr = r.forces(&u_next).damper_n;
        d_force = d_force.max((fr - m.forces(&u_next).damper_n).abs());
        z_max = z_max.max(r.state()[idx::Z].abs());
        f_max = f_max.max(fr.abs());
    }
    let (ev_imex, ev_dopri) = (sims[1].stats().evaluations, sims[2].stats().evaluations);
    println!(
        "imex vs rk4/20: psi {d_psi:.3e} rad, force {d_force:.3e} N (peak {f_max:.1} N), \
         z_max {z_max:.2e} m; evaluations imex {ev_imex}, dopri5 {ev_dopri}"
    );
    assert!(z_max > 1e-3, "damper did not slide: z_max {z_max}");
    assert!(d_psi < 1e-6, "IMEX vs RK4: {d_psi} rad");
    assert!(d_force < 1e-3 * f_max, "IMEX vs RK4: {d_force} N");
    assert!(
        ev_imex < ev_dopri,
        "IMEX not cheaper: {ev_imex} vs {ev_dopri} evaluations"
    );
}
