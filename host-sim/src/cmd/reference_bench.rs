//! `shimmy-sim reference-bench`: the simulator next to an independent NumPy/SciPy implementation
//! of the same plant (`host-sim/reference/plant_scipy.py`, written from `docs/plant-model.md`), run
//! in one command: speed ratios for the time-domain run and the eigenvalue sweep, and agreement
//! of the two implementations' trajectories and eigenvalues.
//!
//! The time-domain case is the nonlinear plant with the MR damper at a constant coil current
//! (SciPy gets its best case: one `solve_ivp` call over the whole run, where the Rust simulator
//! advances in 1 ms control periods as it does in closed loop).
//!
//! The closed-loop row is the standard closed-loop run: the demo's ASMC arm (30 s ramp
//! 20 -> 120 km/h, road noise, imbalance, pothole; simulated sensors, the core's controller and
//! mode meter at 1 kHz). The Python side has no controller, no sensors, no estimator and no road
//! noise: it integrates the same plant over the same drive (ramp, imbalance, pothole) with the
//! coil current from a simple continuous law `I = min(i_max, gain |mean wheel-yaw rate|)` inside
//! the right-hand side, `solve_ivp` in three pieces (before, over and after the pothole, so it
//! cannot step over it). So the Rust side does strictly more work per
//! simulated second; the ratio is a lower bound of the speed-up on equal work.

use crate::model::plant::{default_atol, idx, Inputs, Method, Plant, Simulator, N_STATE};
use crate::sim::input::arg_range::{self, Range};
use crate::sim::input::files::{self, OutDir};
use anyhow::{bail, Context, Result};
use clap::Args;
use shimmy_core::mr_damper::SpencerParams;
use shimmy_core::units::kmh_to_mps;
use shimmy_core::vehicles::car::{Param, PlantParams};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// Time-domain run: above 0, at most 600 s.
pub const DURATION_S: Range = Range::above(0.0, 600.0, "s");
/// Initial wheel yaw: -20 to 20 deg.
pub const YAW_DEG: Range = Range::closed(-20.0, 20.0, "deg");
/// Closed-loop ramp: 1 to 600 s.
pub const CL_RAMP_S: Range = Range::closed(1.0, 600.0, "s");
/// Python current-law gain: 0 to 1000 A per rad/s.
pub const CL_GAIN: Range = Range::closed(0.0, 1000.0, "A/(rad/s)");

/// The simulator's integrator tolerance in every row (its default, `Method::default`); SciPy
/// gets the same rtol and the same per-state atol (`default_atol`).
const SIM_RTOL: f64 = 1e-7;

/// Options of `shimmy-sim reference-bench`.
#[derive(Args, Debug)]
pub struct ReferenceBenchArgs {
    /// The vehicle (`--vehicle`, a named set or a vehicle file).
    #[command(flatten)]
    pub vehicle: crate::cmd::VehicleArg,
    /// Simulated time of the time-domain run, s: above 0, at most 600.
    #[arg(long, default_value_t = 10.0, allow_negative_numbers = true, value_parser = arg_range::f64_in(DURATION_S))]
    pub duration_s: f64,
    /// Forward speed, km/h (inside the Hopf window by default): 1 to 250.
    #[arg(long, default_value_t = 60.0, allow_negative_numbers = true, value_parser = arg_range::speed_kmh())]
    pub speed_kmh: f64,
    /// Constant coil current, in A (`--damper-current-a` as in `stability` and `bifurcation`;
    /// the field keeps its name for callers that build the arguments): 0 to the vehicle's coil
    /// rating.
    #[arg(long = "damper-current-a", alias = "current-a", default_value_t = 0.5, allow_negative_numbers = true, value_parser = arg_range::current_a())]
    pub current_a: f64,
    /// Initial in-phase wheel yaw, deg (large enough for the damper to slide): -20 to 20.
    #[arg(long, default_value_t = 3.0, allow_negative_numbers = true, value_parser = arg_range::f64_in(YAW_DEG))]
    pub initial_yaw_deg: f64,
    /// Points of the eigenvalue sweep (1-150 km/h): 2 to 100000.
    #[arg(long, default_value_t = 2000, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(2..=100_000))]
    pub sweep_points: usize,
    /// SciPy integrators timed on the time-domain run (each at the simulator's rtol and
    /// per-state atol); the fastest is the peer, and it runs the closed-loop row.
    #[arg(long, alias = "scipy-method", value_delimiter = ',', default_value = "LSODA,RK45,DOP853,BDF,Radau", value_parser = ["LSODA", "RK45", "RK23", "DOP853", "BDF", "Radau"])]
    pub scipy_methods: Vec<String>,
    /// Python interpreter with numpy and scipy.
    #[arg(long, default_value = "python3")]
    pub python: String,
    /// Ramp length of the closed-loop row, s (the demo's is 30 s): 1 to 600.
    #[arg(long, default_value_t = 30.0, allow_negative_numbers = true, value_parser = arg_range::f64_in(CL_RAMP_S))]
    pub cl_ramp_s: f64,
    /// Gain of the Python side's current law in the closed-loop row, A per rad/s: 0 to 1000.
    #[arg(long, default_value_t = 4.0, allow_negative_numbers = true, value_parser = arg_range::f64_in(CL_GAIN))]
    pub cl_gain_a_per_radps: f64,
    /// Output folder (`--out`; default out/reference-bench, [`Self::out_dir`]).
    #[command(flatten)]
    pub out: crate::cmd::OutArg,
}

impl ReferenceBenchArgs {
    /// The output folder: `--out`, else out/reference-bench.
    pub fn out_dir(&self) -> PathBuf {
        self.out.dir_or("out/reference-bench")
    }
}

/// What one comparison measured.
#[derive(Debug)]
pub struct ReferenceResult {
    /// Simulated seconds per wall second, Rust.
    pub rust_sim_rate: f64,
    /// Simulated seconds per wall second, SciPy's fastest method.
    pub scipy_sim_rate: f64,
    /// SciPy's methods: (name, simulated seconds per wall second, right-hand-side calls).
    pub scipy_methods: Vec<(String, f64, u64)>,
    /// The fastest of them.
    pub scipy_fastest: String,
    /// Eigen-sweep points per wall second, Rust: A(V) and its eigenvalues.
    pub rust_sweep_rate: f64,
    /// The same, eigenvalues of the prebuilt matrices only.
    pub rust_eig_rate: f64,
    /// Eigen-sweep points per wall second, NumPy: A(V) (a Python loop) and one batched
    /// `eigvals`.
    pub numpy_sweep_rate: f64,
    /// The same, the batched `eigvals` call only.
    pub numpy_eig_rate: f64,
    /// Largest |psi_L(Rust) - psi_L(SciPy)| over the sample times, rad.
    pub max_traj_diff_rad: f64,
    /// Largest |psi_L| of the run, rad (scale of the difference).
    pub max_psi_rad: f64,
    /// Largest |max Re lambda (Rust) - max Re lambda (NumPy)| over the sweep, 1/s.
    pub max_eig_diff: f64,
    /// Closed loop (the demo's ASMC run): simulated seconds per wall second, Rust.
    pub rust_cl_rate: f64,
    /// The same closed loop with the plant on `imex-fixed:2` (2 IMEX steps per period).
    pub rust_cl_imex_rate: f64,
    /// The same drive in SciPy with a simple current law: simulated seconds per wall second.
    pub scipy_cl_rate: f64,
    /// Simulated time of the closed-loop row, s.
    pub cl_duration_s: f64,
    /// Peak |psi_L| of the closed-loop runs in rad: (Rust with ASMC, SciPy with the simple law).
    pub cl_peak_psi_rad: (f64, f64),
}

/// Runs both implementations and compares them; returns the result and the output folder,
/// claimed once the options pass their checks and held until the caller has written it.
pub fn compare(a: &ReferenceBenchArgs) -> Result<(ReferenceResult, OutDir)> {
    DURATION_S.check("--duration-s", a.duration_s)?;
    arg_range::SPEED_KMH.check("--speed-kmh", a.speed_kmh)?;
    YAW_DEG.check("--initial-yaw-deg", a.initial_yaw_deg)?;
    CL_RAMP_S.check("--cl-ramp-s", a.cl_ramp_s)?;
    CL_GAIN.check("--cl-gain-a-per-radps", a.cl_gain_a_per_radps)?;
    if !(2..=100_000).contains(&a.sweep_points) {
        bail!("--sweep-points {}: allowed 2 to 100000", a.sweep_points);
    }
    let vehicle = crate::sim::input::vehicle_file::load(&a.vehicle.spec)?;
    arg_range::check_current("--damper-current-a", a.current_a, &vehicle)?;
    let (params, damper) = (vehicle.plant, vehicle.damper.spencer);
    let v_mps = kmh_to_mps(a.speed_kmh);
    let out_dir = OutDir::claim(&a.out_dir())?;

    let sample_every = 10; // every 10 ms
    let n_periods = (a.duration_s * 1000.0).round() as usize;
    let sample_times: Vec<f64> = (0..=n_periods)
        .step_by(sample_every)
        .map(|k| k as f64 * 1e-3)
        .collect();
    let sweep: Vec<f64> = (0..a.sweep_points)
        .map(|i| kmh_to_mps(1.0 + 149.0 * i as f64 / (a.sweep_points.max(2) - 1) as f64))
        .collect();

    // Rust: the simulator in 1 ms control periods.
    let mut x0 = [0.0; N_STATE];
    x0[idx::PSI_L] = a.initial_yaw_deg.to_radians();
    x0[idx::PSI_R] = x0[idx::PSI_L];
    let mut sim = Simulator::with_method(
        Plant::with_mr_damper(params),
        x0,
        Method::Dopri5 { rtol: SIM_RTOL },
    );
    let inputs = Inputs {
        current_cmd_a: a.current_a,
        driver_torque_nm: 0.0,
        yaw_torque_nm: [0.0; 2],
        speed_mps: v_mps,
    };
    let mut psi_rust = vec![sim.state()[idx::PSI_L]];
    let start = Instant::now();
    for k in 1..=n_periods {
        sim.advance(1e-3, &inputs).context("simulator")?;
        if k % sample_every == 0 {
            psi_rust.push(sim.state()[idx::PSI_L]);
        }
    }
    let rust_sim_wall = start.elapsed().as_secs_f64();

    let start = Instant::now();
    let matrices: Vec<_> = sweep
        .iter()
        .map(|&v| shimmy_core::vehicles::car::linearise(&params, v, 0.0))
        .collect();
    let rust_build_wall = start.elapsed().as_secs_f64();
    let start = Instant::now();
    let mut max_re_rust = Vec::with_capacity(sweep.len());
    for m in &matrices {
        let ev = shimmy_core::eigen::eigenvalues(m).context("eigen")?;
        max_re_rust.push(ev.iter().map(|l| l.re).fold(f64::NEG_INFINITY, f64::max));
    }
    let rust_eig_wall = start.elapsed().as_secs_f64();

    // Closed loop: the demo's ASMC run (nominal plant, as the demo).
    let ramp_s = a.cl_ramp_s;
    let demo_case = crate::sim::run::demo_case::demo_case(ramp_s)?;
    let (_, cl) = crate::sim::run::demo_case::run_arm(
        &demo_case,
        crate::sim::run::demo_case::ARMS[1].1,
        ramp_s,
        5,
    )?;
    // The same run with the plant on the fixed-step IMEX (2 steps per period), side by side.
    let imex_case = crate::sim::run::demo_case::DemoCase {
        method: Method::ImexFixed { substeps: 2 },
        ..demo_case.clone()
    };
    let (_, cl_imex) = crate::sim::run::demo_case::run_arm(
        &imex_case,
        crate::sim::run::demo_case::ARMS[1].1,
        ramp_s,
        5,
    )?;
    let cl_peak = cl
        .series
        .psi_l_rad
        .iter()
        .fold(0.0f64, |m, x| m.max(x.abs()));

    // SciPy: the same case, from a case file.
    let case = a.out_dir().join("case.toml");
    let mut text = case_toml(&params, &damper, a, v_mps, &sample_times, &sweep);
    text.push_str(&ramp_toml(&demo_case, ramp_s, a.cl_gain_a_per_radps)?);
    crate::sim::input::files::write_file(&case, text)?;
    let result = a.out_dir().join("scipy.json");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("reference/plant_scipy.py");
    let status = Command::new(&a.python)
        .arg(&script)
        .arg(&case)
        .arg(&result)
        .status()
        .with_context(|| format!("starting {} (needs numpy and scipy)", a.python))?;
    if !status.success() {
        bail!(
            "{} {} failed ({status}); it needs numpy and scipy (pip install numpy scipy)",
            a.python,
            script.display()
        );
    }
    let json: serde_json::Value =
        serde_json::from_str(&files::read_text(&result, files::DATA_LIMIT)?)?;
    let num = |k: &str| {
        json[k]
            .as_f64()
            .with_context(|| format!("scipy.json: `{k}`"))
    };
    let list = |k: &str| -> Result<Vec<f64>> {
        json[k]
            .as_array()
            .with_context(|| format!("scipy.json: `{k}`"))?
            .iter()
            .map(|v| v.as_f64().context("number"))
            .collect()
    };
    let psi_scipy = list("psi_l_rad")?;
    let scipy_methods = json["methods"]
        .as_object()
        .context("scipy.json: `methods`")?
        .iter()
        .map(|(name, m)| -> Result<(String, f64, u64)> {
            let wall = m["wall_s"].as_f64().context("scipy.json: method wall_s")?;
            let evals = m["rhs_evals"].as_u64().context("scipy.json: rhs_evals")?;
            Ok((name.clone(), a.duration_s / wall, evals))
        })
        .collect::<Result<Vec<_>>>()?;
    let max_re_numpy = list("max_re")?;
    if psi_scipy.len() != psi_rust.len() || max_re_numpy.len() != max_re_rust.len() {
        bail!("the SciPy result has a different number of samples");
    }
    let max_abs_diff = |a: &[f64], b: &[f64]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max)
    };
    Ok((
        ReferenceResult {
            rust_sim_rate: a.duration_s / rust_sim_wall,
            scipy_sim_rate: a.duration_s / num("sim_wall_s")?,
            scipy_methods,
            scipy_fastest: json["fastest"]
                .as_str()
                .context("scipy.json: `fastest`")?
                .to_string(),
            rust_sweep_rate: sweep.len() as f64 / (rust_build_wall + rust_eig_wall),
            rust_eig_rate: sweep.len() as f64 / rust_eig_wall,
            numpy_sweep_rate: sweep.len() as f64
                / (num("sweep_build_wall_s")? + num("sweep_eig_wall_s")?),
            numpy_eig_rate: sweep.len() as f64 / num("sweep_eig_wall_s")?,
            max_traj_diff_rad: max_abs_diff(&psi_rust, &psi_scipy),
            max_psi_rad: psi_rust.iter().fold(0.0, |m: f64, x| m.max(x.abs())),
            max_eig_diff: max_abs_diff(&max_re_rust, &max_re_numpy),
            rust_cl_rate: cl.sim_s / cl.wall_s.max(1e-12),
            rust_cl_imex_rate: cl_imex.sim_s / cl_imex.wall_s.max(1e-12),
            scipy_cl_rate: ramp_s / num("ramp_wall_s")?,
            cl_duration_s: ramp_s,
            cl_peak_psi_rad: (cl_peak, num("ramp_peak_psi_l_rad")?),
        },
        out_dir,
    ))
}

/// The `[ramp]` section: the demo's drive (nominal plant parameters are the `[plant]` section
/// only when `--params nominal`; the demo always uses nominal, so its plant is written here).
fn ramp_toml(
    case: &crate::sim::run::demo_case::DemoCase,
    ramp_s: f64,
    gain: f64,
) -> Result<String> {
    use crate::model::disturbance::SpeedProfile;
    let SpeedProfile::Ramp {
        v0_mps,
        v1_mps,
        t0_s,
        t1_s,
    } = case.scenario.speed
    else {
        bail!("the demo's speed profile is not a ramp");
    };
    let im = case
        .scenario
        .imbalance
        .as_ref()
        .context("the demo has an imbalance")?;
    let hole = case
        .scenario
        .impulses
        .first()
        .context("the demo has a pothole")?;
    let i_max = case.plant.rated_current_a();
    let mut s = String::from("\n[ramp]\n");
    let _ = writeln!(s, "duration_s = {ramp_s:e}");
    let _ = writeln!(
        s,
        "v0_mps = {v0_mps:e}\nv1_mps = {v1_mps:e}\nt_ramp_s = {:e}",
        t1_s - t0_s
    );
    let _ = writeln!(
        s,
        "imbalance_nm = {:e}\nimbalance_phase_rad = [{:e}, {:e}]",
        im.amplitude_nm[0], im.phase_rad[0], im.phase_rad[1]
    );
    let _ = writeln!(
        s,
        "pothole_t_s = {:e}\npothole_duration_s = {:e}\npothole_nm = {:e}",
        hole.t0_s, hole.duration_s, hole.peak_nm[0]
    );
    let _ = writeln!(s, "i_max_a = {i_max:e}\ngain_a_per_radps = {gain:e}");
    let _ = writeln!(s, "[ramp.plant]");
    for q in Param::ALL {
        let _ = writeln!(s, "{} = {:e}", q.name(), case.plant.plant.get(q));
    }
    Ok(s)
}

/// The Spencer damper's parameters by their names in the reference's `[damper]` section
/// (`host-sim/reference/plant_scipy.py`), already scaled to the steering damper.
pub fn spencer_fields(d: &SpencerParams) -> [(&'static str, f64); 15] {
    [
        ("c0a", d.c0a),
        ("c0b", d.c0b),
        ("k0", d.k0),
        ("c1a", d.c1a),
        ("c1b", d.c1b),
        ("k1", d.k1),
        ("x0", d.x0),
        ("alpha_a", d.alpha_a),
        ("alpha_b", d.alpha_b),
        ("gamma", d.gamma),
        ("beta", d.beta),
        ("a_bw", d.a_bw),
        ("n", d.n),
        ("eta", d.eta),
        ("u_max", d.u_max),
    ]
}

fn case_toml(
    p: &PlantParams,
    d: &SpencerParams,
    a: &ReferenceBenchArgs,
    v_mps: f64,
    sample_times: &[f64],
    sweep: &[f64],
) -> String {
    let mut s = String::from("[plant]\n");
    for q in Param::ALL {
        let _ = writeln!(s, "{} = {:e}", q.name(), p.get(q));
    }
    s.push_str("\n[damper]\n");
    for (k, v) in spencer_fields(d) {
        let _ = writeln!(s, "{k} = {v:e}");
    }
    let list = |xs: &[f64]| {
        xs.iter()
            .map(|x| format!("{x:e}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let _ = write!(
        s,
        "\n[case]\nspeed_mps = {v_mps:e}\ncurrent_a = {:e}\ninitial_yaw_deg = {:e}\nduration_s = {:e}\n\
         methods = [{}]\nrtol = {SIM_RTOL:e}\natol = [{}]\nsample_times_s = [{}]\nsweep_speeds_mps = [{}]\n",
        a.current_a,
        a.initial_yaw_deg,
        a.duration_s,
        a.scipy_methods
            .iter()
            .map(|m| format!("\"{m}\""))
            .collect::<Vec<_>>()
            .join(", "),
        list(&default_atol(SIM_RTOL)),
        list(sample_times),
        list(sweep)
    );
    s
}

/// The command: run, print the table, write it to `summary.txt`.
pub fn command(a: &ReferenceBenchArgs) -> Result<()> {
    let (r, _out_dir) = compare(a)?;
    let mut t = String::new();
    let _ = writeln!(
        t,
        "reference bench: {} at {} km/h, MR damper at {} A, {} deg start, {} s; sweep of {} speeds",
        a.vehicle.spec, a.speed_kmh, a.current_a, a.initial_yaw_deg, a.duration_s, a.sweep_points
    );
    let _ = writeln!(
        t,
        "  {:<34} {:>14} {:>14} {:>8}",
        "", "shimmy-sim", "SciPy/NumPy", "ratio"
    );
    let _ = writeln!(
        t,
        "  {:<34} {:>14.1} {:>14.2} {:>7.0}x",
        format!("time domain, {} [sim s / wall s]", r.scipy_fastest),
        r.rust_sim_rate,
        r.scipy_sim_rate,
        r.rust_sim_rate / r.scipy_sim_rate
    );
    let _ = writeln!(
        t,
        "  {:<34} {:>14.0} {:>14.0} {:>7.1}x",
        "eigen sweep, A(V) + eig [points/s]",
        r.rust_sweep_rate,
        r.numpy_sweep_rate,
        r.rust_sweep_rate / r.numpy_sweep_rate
    );
    let _ = writeln!(
        t,
        "  {:<34} {:>14.0} {:>14.0} {:>7.1}x",
        "eigen sweep, eig only [points/s]",
        r.rust_eig_rate,
        r.numpy_eig_rate,
        r.rust_eig_rate / r.numpy_eig_rate
    );
    let _ = writeln!(
        t,
        "  {:<34} {:>14.1} {:>14.2} {:>7.0}x",
        format!("closed loop, {:.0} s [sim s / wall s]", r.cl_duration_s),
        r.rust_cl_rate,
        r.scipy_cl_rate,
        r.rust_cl_rate / r.scipy_cl_rate
    );
    let _ = writeln!(
        t,
        "  {:<34} {:>14.1} {:>14.2} {:>7.0}x",
        "  the same, plant on imex-fixed:2",
        r.rust_cl_imex_rate,
        r.scipy_cl_rate,
        r.rust_cl_imex_rate / r.scipy_cl_rate
    );
    let _ = writeln!(
        t,
        "    closed loop: Rust = the demo's ASMC run (sensors, core controller and mode meter at 1 kHz, road noise);\n    \
         SciPy = the same plant and drive (ramp, imbalance, pothole) with no controller: I = min(i_max, {} A s/rad |mean yaw rate|)\n    \
         inside the RHS, solve_ivp ({}) in 3 pieces (before, over, after the pothole), no noise. Peak |psi_L|: {:.3} deg (ASMC) vs {:.3} deg (simple law).",
        a.cl_gain_a_per_radps,
        r.scipy_fastest,
        r.cl_peak_psi_rad.0.to_degrees(),
        r.cl_peak_psi_rad.1.to_degrees()
    );
    let _ = writeln!(
        t,
        "    time domain: both at rtol {SIM_RTOL:e} with the same per-state atol; Rust in 1 ms periods (as in closed loop),\n    \
         SciPy in one solve_ivp call; every SciPy method timed, the fastest is the peer [sim s / wall s, rhs calls]: {}",
        r.scipy_methods
            .iter()
            .map(|(m, rate, n)| format!("{m} {rate:.2} ({n})"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    let _ = writeln!(
        t,
        "    eigen sweep: Rust = linearise + eigenvalues (balancing, Hessenberg QR) per speed, one thread;\n    \
         NumPy = A(V) in a Python loop + one batched numpy.linalg.eigvals (LAPACK); 'eig only' times the eigenvalues alone."
    );
    let _ = writeln!(
        t,
        "  agreement: max |psi_L diff| = {:.3e} rad (of max |psi_L| {:.3e} rad); max |max Re lambda diff| = {:.3e} 1/s",
        r.max_traj_diff_rad, r.max_psi_rad, r.max_eig_diff
    );
    print!("{t}");
    crate::sim::input::files::write_file(&a.out_dir().join("summary.txt"), &t)?;
    Ok(())
}
