//! `shimmy-sim run SCENARIO.toml`: one closed-loop run from a scenario file (see
//! [`scenario_file`]): metrics table, trace CSV with units, a time plot (wheel yaw, coil
//! current, adaptive gain) and a margin plot (the mode meter's damping estimate over time next to
//! the true eigenvalue of the plant's shimmy mode at the same speed).

use crate::model::family::SimModel;
use crate::model::registry::Registered;
use crate::out::file_name::sanitize;
use crate::out::plots::{plot_margin, plot_runs};
use crate::sim::input::vehicle_file::FileModel;
use crate::sim::run::closed_loop::LoopResult;
use crate::sim::run::scenario::{self, controller_name, ScenarioSpec, CONTROLLERS};
use crate::sim::run::scenario_file::{self, ScenarioVisitor};
use anyhow::{Context, Result};
use clap::Args;
use std::f64::consts::PI;
use std::path::PathBuf;

/// Options of `shimmy-sim run`.
#[derive(Args, Debug)]
pub struct RunArgs {
    /// Scenario file (TOML); the standard ones are in host-sim/scenarios/.
    pub scenario: PathBuf,
    /// Output folder (`--out`; overrides the file's `output.dir`, [`out_dir`]).
    #[command(flatten)]
    pub out: crate::cmd::OutArg,
    /// Controller (overrides the file's `controller.kind`; passive-on needs `--on-current-a`).
    #[arg(long)]
    pub controller: Option<String>,
    /// Fixed current for `--controller passive-on`, in A: 0 to the coil rating of the vehicle
    /// the firmware believes.
    #[arg(long, default_value_t = 1.0, alias = "on-current", allow_negative_numbers = true, value_parser = crate::sim::input::arg_range::current_a())]
    pub on_current_a: f64,
    /// The simulated vehicle (overrides the file's `[plant]`, sensors included): a named set
    /// (`shimmy-sim vehicles` lists them) or a vehicle file (TOML, see docs/vehicle-file.md).
    #[arg(long, visible_alias = "params")]
    pub vehicle: Option<String>,
    /// The vehicle the firmware believes (`--model-vehicle`).
    #[command(flatten)]
    pub model_vehicle: crate::cmd::ModelVehicleArg,
    /// Record every n-th 1 ms period in trace.csv (overrides the file's `output.trace_every`;
    /// 1 makes the trace the mode meter's 1 kHz input log for `shimmy-sim analyze`): 1 to 1000.
    #[arg(long, value_parser = clap::value_parser!(u64).range(1..=1000))]
    pub trace_every: Option<u64>,
}

/// The output folder of a run: `--out`, else the file's `output.dir`, else `out/<name>` with
/// the name sanitised.
pub fn out_dir<M: SimModel<N>, const N: usize>(a: &RunArgs, spec: &ScenarioSpec<M, N>) -> PathBuf {
    a.out
        .dir
        .clone()
        .or_else(|| spec.out_dir.clone())
        .unwrap_or_else(|| PathBuf::from("out").join(sanitize(&spec.name)))
}

/// The command.
pub fn command(a: &RunArgs) -> Result<()> {
    struct On<'a>(&'a RunArgs);
    impl ScenarioVisitor for On<'_> {
        type Output = Result<()>;
        fn visit<M: Registered<N>, const N: usize>(self, s: ScenarioSpec<M, N>) -> Result<()> {
            run_spec(self.0, s)
        }
    }
    scenario_file::load_any(&a.scenario)?.visit(On(a))
}

/// The command on the scenario `spec` of any vehicle model.
fn run_spec<M: FileModel<N>, const N: usize>(
    a: &RunArgs,
    mut spec: ScenarioSpec<M, N>,
) -> Result<()> {
    let controller = match &a.controller {
        Some(c) => match controller_name(c) {
            Some(name) => Some((name, a.on_current_a)),
            None => anyhow::bail!("--controller {c}: allowed: {}", CONTROLLERS.join(", ")),
        },
        None => None,
    };
    spec.apply_overrides(a.vehicle.as_deref(), a.model_vehicle.given(), controller)
        .with_context(|| format!("scenario file {}", a.scenario.display()))?;
    if let Some(n) = a.trace_every {
        spec.trace_every = n as usize;
    }
    let out = out_dir(a, &spec);
    let _out_dir = crate::sim::input::files::OutDir::claim(&out)?;
    let (cfg, r) = scenario::run(&spec)?;
    let m = r.metrics(&cfg, spec.t_dist_s);

    let trace = out.join("trace.csv");
    r.write_trace_csv(&trace)?;
    let time_png = out.join("time.png");
    plot_runs(&time_png, &spec.name, &[(spec.controller.as_str(), &r)])?;
    let margin_png = out.join("margin.png");
    plot_margin(
        &margin_png,
        &spec.name,
        &[(spec.controller.as_str(), &cfg, &r)],
    )?;

    let deg = 180.0 / PI;
    println!(
        "scenario `{}`: {} s, controller {}, {} simulated s in {:.2} wall s",
        spec.name, spec.duration_s, spec.controller, r.sim_s, r.wall_s
    );
    println!("  peak wheel yaw        {:>9.3} deg", m.peak_yaw_rad * deg);
    println!("  RMS wheel yaw         {:>9.3} deg", m.rms_yaw_rad * deg);
    match m.settle_s {
        Some(s) => println!("  2 % settling          {s:>9.3} s"),
        None => println!("  2 % settling                  - (does not settle)"),
    }
    println!(
        "  peak steering {:<7} {:>9.3} deg",
        M::STEERING,
        m.peak_sw_rad * deg
    );
    println!(
        "  RMS / peak current    {:>9.3} / {:.3} A",
        m.rms_current_a, m.peak_current_a
    );
    println!("  coil energy           {:>9.3} J", m.energy_j);
    println!("  chattering (TV)       {:>9.3} A", m.chatter_a);
    println!("  RMS damper force      {:>9.3} N", m.rms_force_n);
    println!(
        "  time in shimmy        {:>9.3} s (amplitude > 0.5 deg)",
        m.shimmy_s
    );
    println!(
        "  shimmy at the end     {}",
        if m.shimmies() { "YES" } else { "no" }
    );
    println!(
        "  wrote {}, {}, {}",
        trace.display(),
        time_png.display(),
        margin_png.display()
    );
    if !spec.faults.is_empty() {
        print_faults(&spec, &r);
    }
    Ok(())
}

/// The injected faults and what the supervisor did about them.
fn print_faults<M: SimModel<N>, const N: usize>(spec: &ScenarioSpec<M, N>, r: &LoopResult) {
    let log = &r.faults;
    println!("  injected faults:");
    for f in &spec.faults {
        let end = f.end_s.map_or("end".into(), |e| format!("{e} s"));
        println!("    {:<22} {} s .. {end}", f.mode.label(), f.start_s);
    }
    let t = |x: Option<f64>| x.map_or("-".into(), |v| format!("{v:.3} s"));
    println!(
        "  supervisor: first detection {}, degraded from {}, fail-safe from {}, worst mode {}, final mode {}",
        t(log.first_detect_s),
        t(log.first_degraded_s),
        t(log.first_failsafe_s),
        log.worst_mode.name(),
        log.final_mode.name()
    );
    for (k, rec) in &log.records {
        println!(
            "    {:<20} {:>6} frames, {} activation(s), active at the end: {}",
            k.name(),
            rec.frames,
            rec.activations,
            rec.active
        );
    }
    println!(
        "  lost frames {}, missed samples {}, invalid commands {}",
        log.lost_frames, log.missed_samples, log.invalid_commands
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_scenario_file_runs_end_to_end() {
        let out = std::env::temp_dir().join(format!("shimmy-run-{}", std::process::id()));
        let spec = scenario_file::parse(
            "duration_s = 2.0\n[controller]\nkind = \"asmc\"\n[speed]\nconstant_kmh = 55.0\n[initial]\nyaw_deg = 1.0\n",
            "t",
        )
        .unwrap();
        let (cfg, r) = scenario::run(&spec).unwrap();
        assert!((r.sim_s - 2.0).abs() < 1e-9);
        // The initial perturbation reached the plant: the first recorded yaw is the file's.
        let m = r.metrics(&cfg, None);
        assert!(
            (m.peak_yaw_rad - 1f64.to_radians()).abs() < 0.05 * 1f64.to_radians(),
            "{m:?}"
        );
        let args = RunArgs {
            scenario: PathBuf::from("unused"),
            out: crate::cmd::OutArg::new(&out),
            controller: None,
            on_current_a: 1.0,
            vehicle: None,
            model_vehicle: Default::default(),
            trace_every: None,
        };
        // The command path itself (with a file on disk).
        let file = out.with_extension("toml");
        std::fs::write(&file, "duration_s = 1.0\n[speed]\nconstant_kmh = 40.0\n").unwrap();
        command(&RunArgs {
            scenario: file.clone(),
            ..args
        })
        .unwrap();
        for f in ["trace.csv", "time.png", "margin.png"] {
            assert!(std::fs::metadata(out.join(f)).unwrap().len() > 1000, "{f}");
        }
        let _ = std::fs::remove_dir_all(&out);
        let _ = std::fs::remove_file(&file);
    }
}
