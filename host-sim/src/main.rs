//! `shimmy-sim`: the simulator's command-line tool. Parses the command line and calls the
//! subcommand's `command` in `shimmy_sim::cmd`; nothing else happens here (but for making a
//! failed write to the standard output an error, `shimmy_sim::sim::input::files`).
use anyhow::Result;
use clap::{Parser, Subcommand};
use shimmy_sim::cmd;

/// Shimmy simulator: the 4-DOF solid-axle steering plant with an MR damper, in the loop with
/// the firmware's own control and estimation code.
#[derive(Parser)]
#[command(version, about, long_about = None, args_conflicts_with_subcommands = true)]
struct Cli {
    /// Without a command: the demo (damper off vs ASMC on a speed ramp through the Hopf
    /// window, report in out/demo/), on these vehicles.
    #[command(flatten, next_help_heading = "Demo options (without a command)")]
    demo: cmd::demo::DemoArgs,
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand)]
enum Command {
    /// Print and validate a vehicle (a named set, `shimmy-sim vehicles` lists them, or a vehicle
    /// file): every field with its unit and allowed range.
    Params {
        /// Named set or vehicle file (TOML: `base = "nominal"` plus sections of fields by name,
        /// docs/vehicle-file.md; parameter files with `[overrides]` are vehicle files).
        #[arg(default_value = "nominal")]
        params: String,
    },
    /// Time-domain bifurcation diagram of the nonlinear plant: limit-cycle amplitude vs speed
    /// from a small and a large initial wheel-yaw disturbance (table, CSV, PNG).
    Bifurcation(cmd::bifurcation::BifurcationArgs),
    /// Eigenvalues of the linearised plant vs speed: least-damped mode table, Hopf crossings,
    /// CSV and PNG (optionally with the MR damper as an equivalent viscous damper).
    Stability(cmd::stability::StabilityArgs),
    /// The mining truck's struts: the initial gas volumes that keep it free of shimmy at a
    /// load and speed, and the Hopf-window maps over gas volume and payload (CSV, PNG).
    GasCharge(cmd::gas_charge::GasChargeArgs),
    /// The trailer's sway damper: the damper it needs over speed (stable, and a damping-ratio
    /// target), and Diboll & Hagen's map of the damping ratio needed over the Strouhal number
    /// (CSV, PNG).
    SwayDamping(cmd::sway_damping::SwayDampingArgs),
    /// How the Hopf onset/offset speeds and frequency move with +-20 % on each parameter.
    Sensitivity(cmd::sensitivity::SensitivityArgs),
    /// Every vehicle model of the family at its named sets: degrees of freedom, Hopf windows,
    /// frequency, limit-cycle amplitude, the margin estimator's warning lead (Markdown, CSV).
    Vehicles(cmd::vehicles::VehiclesArgs),
    /// Speed and agreement against an independent NumPy/SciPy implementation of the plant
    /// (needs python3 with numpy and scipy).
    ReferenceBench(cmd::reference_bench::ReferenceBenchArgs),
    /// Stability maps over speed x one parameter (x damper current): growth-rate heat map with
    /// the Hopf boundary (PNG) and CSV, computed in parallel; with `--controllers off,asmc`
    /// time-domain maps per controller instead.
    Sweep(cmd::sweep::args::SweepArgs),
    /// Every controller over the standard scenario set: one table, CSV and PNG plots.
    Compare(cmd::compare::CompareArgs),
    /// Run one scenario file (TOML, see host-sim/scenarios/): metrics, trace CSV, plots.
    Run(cmd::run::RunArgs),
    /// Processor in the loop: a scenario with the firmware image under QEMU in lockstep
    /// (trace, plots, instruction counts per task; --check-sil: bit-exact against SIL).
    Pil(cmd::pil::PilArgs),
    /// Open-loop eigenvalue-margin run (damper off, speed ramp or constant drive, road noise,
    /// imbalance): the shimmy pipeline's report next to the true eigenvalues, warning lead time.
    Margin(cmd::margin::MarginArgs),
    /// The mode meter's damping estimate against the true shimmy-mode damping on the simulated
    /// plant (constant speeds, damper off and on, seeds): bias, spread, sigma coverage.
    MeterAccuracy(cmd::meter_accuracy::MeterAccuracyArgs),
    /// Plant != model: warning lead over the true onset and false warnings at 70 % of it, with
    /// the model nominal and the plant off by +-20 % in one parameter (or `hard`, `gentle`).
    Mismatch(cmd::mismatch::MismatchArgs),
    /// Which of a model's parameters the online model update can separate from the meter's
    /// shimmy frequency and damping, at which speeds and noise levels (Fisher information).
    Identifiability(cmd::identifiability::IdentifiabilityArgs),
    /// Fault campaign: every sensor/coil fault (and combinations) injected into the supervised
    /// ASMC loop inside and outside the Hopf window: detection time, safe state, suppression.
    Faults(cmd::faults::FaultsArgs),
    /// The host link to a device (a board's serial port, QEMU over TCP, or the in-process
    /// simulated device): identity, vehicle configuration, event log, faults, live margin.
    Device(cmd::device::DeviceArgs),
    /// Run scenario files (default: the standard set in host-sim/scenarios/) and write one
    /// self-contained report: Markdown page, PNG plots, metrics table and CSV traces.
    Report(cmd::report::ReportArgs),
    /// The board's mode meter, fusion and monitor on a measured log (CSV: wheel yaw or a
    /// steering signal, speed): damping and frequency over time with uncertainty, warnings and
    /// events as CSV, plot, Markdown/HTML report and JSON summary.
    Analyze(cmd::analyze::AnalyzeArgs),
}

fn main() -> Result<()> {
    shimmy_sim::sim::input::files::report_stdout_errors();
    let cli = Cli::parse();
    match cli.command {
        Some(Command::Params { params }) => cmd::params::command(&params),
        Some(Command::Bifurcation(a)) => cmd::bifurcation::command(&a),
        Some(Command::Stability(a)) => cmd::stability::command(&a),
        Some(Command::GasCharge(a)) => cmd::gas_charge::command(&a),
        Some(Command::SwayDamping(a)) => cmd::sway_damping::command(&a),
        Some(Command::Sensitivity(a)) => cmd::sensitivity::command(&a),
        Some(Command::Vehicles(a)) => cmd::vehicles::command(&a),
        Some(Command::ReferenceBench(a)) => cmd::reference_bench::command(&a),
        Some(Command::Sweep(a)) if a.controllers.is_empty() => cmd::sweep::eigen::command(&a),
        Some(Command::Sweep(a)) => cmd::sweep::time_domain::command(&a).map(|_| ()),
        Some(Command::Compare(a)) => cmd::compare::command(&a),
        Some(Command::Run(a)) => cmd::run::command(&a),
        Some(Command::Pil(a)) => cmd::pil::command(&a),
        Some(Command::Margin(a)) => cmd::margin::command(&a),
        Some(Command::MeterAccuracy(a)) => cmd::meter_accuracy::command(&a),
        Some(Command::Mismatch(a)) => cmd::mismatch::command(&a),
        Some(Command::Identifiability(a)) => cmd::identifiability::command(&a),
        Some(Command::Device(a)) => cmd::device::command(&a),
        Some(Command::Faults(a)) => cmd::faults::command(&a),
        Some(Command::Report(a)) => cmd::report::command(&a),
        Some(Command::Analyze(a)) => cmd::analyze::command(&a),
        None => cmd::demo::command(&cli.demo),
    }
}
