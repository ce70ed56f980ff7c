//! `shimmy-sim`: the simulator's command-line tool.
use anyhow::Result;
use clap::{Parser, Subcommand};
use shimmy_core::params::Param;
use shimmy_sim::paramfile;

/// Shimmy simulator: the 4-DOF solid-axle steering plant with an MR damper, in the loop with
/// the firmware's own control and estimation code.
#[derive(Parser)]
#[command(version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand)]
enum Command {
    /// Print and validate a parameter set (a name: nominal, gentle, hard; or a TOML file).
    Params {
        /// Named set or TOML file (`base = "nominal"` plus `[overrides]` by field name).
        #[arg(default_value = "nominal")]
        params: String,
    },
    /// Time-domain bifurcation diagram of the nonlinear plant: limit-cycle amplitude vs speed
    /// from a small and a large initial wheel-yaw disturbance (table, CSV, PNG).
    Bifurcation(shimmy_sim::bifurcation::BifurcationArgs),
    /// Eigenvalues of the linearised plant vs speed: least-damped mode table, Hopf crossings,
    /// CSV and PNG (optionally with the MR damper as an equivalent viscous damper).
    Stability(shimmy_sim::stability_cmd::StabilityArgs),
    /// How the Hopf onset/offset speeds and frequency move with +-20 % on each parameter.
    Sensitivity(shimmy_sim::stability_cmd::SensitivityArgs),
    /// Speed and agreement against an independent NumPy/SciPy implementation of the plant
    /// (needs python3 with numpy and scipy).
    ReferenceBench(shimmy_sim::reference_bench::ReferenceBenchArgs),
    /// Stability maps over speed x one parameter (x damper current): growth-rate heat map with
    /// the Hopf boundary (PNG) and CSV, computed in parallel; with `--controllers off,asmc`
    /// time-domain maps per controller instead.
    Sweep(shimmy_sim::sweep::SweepArgs),
    /// Every controller over the standard scenario set: one table, CSV and PNG plots.
    Compare(shimmy_sim::compare::CompareArgs),
    /// Run one scenario file (TOML, see host-sim/scenarios/): metrics, trace CSV, plots.
    Run(shimmy_sim::run_cmd::RunArgs),
    /// Open-loop eigenvalue-margin run (damper off, speed ramp or constant drive, road noise,
    /// imbalance): the shimmy pipeline's report next to the true eigenvalues, warning lead time.
    Margin(shimmy_sim::margin_cmd::MarginArgs),
    /// Fault campaign: every sensor/coil fault (and combinations) injected into the supervised
    /// ASMC loop inside and outside the Hopf window: detection time, safe state, suppression.
    Faults(shimmy_sim::fault_campaign::FaultsArgs),
    /// Run scenario files (default: the standard set in host-sim/scenarios/) and write one
    /// self-contained report: Markdown page, PNG plots, metrics table and CSV traces.
    Report(shimmy_sim::report_cmd::ReportArgs),
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Some(Command::Params { params }) => print_params(&params),
        Some(Command::Bifurcation(args)) => shimmy_sim::bifurcation::command(&args),
        Some(Command::Stability(a)) => shimmy_sim::stability_cmd::run_stability(&a),
        Some(Command::Sensitivity(a)) => shimmy_sim::stability_cmd::run_sensitivity(&a),
        Some(Command::ReferenceBench(a)) => shimmy_sim::reference_bench::command(&a),
        Some(Command::Sweep(a)) => shimmy_sim::sweep::command(&a),
        Some(Command::Compare(a)) => shimmy_sim::compare::command(&a),
        Some(Command::Run(a)) => shimmy_sim::run_cmd::command(&a),
        Some(Command::Margin(a)) => shimmy_sim::margin_cmd::command(&a),
        Some(Command::Faults(a)) => shimmy_sim::fault_campaign::command(&a),
        Some(Command::Report(a)) => shimmy_sim::report_cmd::command(&a),
        None => shimmy_sim::demo::command(),
    }
}

fn print_params(spec: &str) -> Result<()> {
    let p = paramfile::load(spec)?;
    println!("parameter set `{spec}` (valid)");
    for q in Param::ALL {
        println!("  {:<6} = {:>14.6} {}", q.name(), p.get(q), q.unit());
    }
    Ok(())
}
