//! `shimmy-sim pil SCENARIO.toml`: processor in the loop. The scenario's plant, sensors and
//! faults exactly as in `run` (the same `closed_loop` code), with the firmware image under QEMU
//! in place of the in-process controller (`sim::pil`); the same trace CSV and plots as `run`,
//! plus the instruction counts of the image's three tasks under closed-loop data and their CPU
//! share at 168 MHz. `--check-sil` runs the scenario again with the firmware's application
//! natively and fails unless both runs agree bit for bit.

use crate::model::registry::image_models;
use crate::out::file_name::sanitize;
use crate::out::plots::{plot_margin, plot_runs};
use crate::sim::device::pil::{
    check_firmware_matches, compare, costs, PilFirmware, PilModel, SilFirmware, TaskCost,
};
use crate::sim::run::closed_loop;
use crate::sim::run::scenario::{self, ScenarioSpec};
use crate::sim::run::scenario_file::{self, ImageScenarioVisitor, ScenarioModel};
use anyhow::{bail, Context, Result};
use clap::Args;
use shimmy_core::vehicle::record_schema_of;
use std::path::PathBuf;
use std::time::Instant;

/// The core clock of the board's STM32F405, Hz.
const CPU_HZ: f64 = 168e6;

/// Options of `shimmy-sim pil`.
#[derive(Args, Debug)]
pub struct PilArgs {
    /// Scenario file (TOML, as for `run`) of the car or the mining truck; the image is built
    /// for its model's default vehicle (`nominal`, `truck-full`) with the margin-scheduled
    /// ASMC, so the scenario must believe that vehicle.
    pub scenario: PathBuf,
    /// The firmware image built with the `pil` feature for the scenario's model (`cargo xtask
    /// pil` builds both; default target/xtask/shimmy-firmware.pil.elf for the car,
    /// target/xtask/shimmy-firmware.pil+model-truck.elf for the truck).
    #[arg(long)]
    pub elf: Option<PathBuf>,
    /// Output folder (`--out`; overrides the file's `output.dir`; default `out/pil/<name>`).
    #[command(flatten)]
    pub out: crate::cmd::OutArg,
    /// Also run the firmware's application natively (SIL) and fail unless the coil commands,
    /// supervisor outputs, margin reports, warning levels and model margins agree bit for bit.
    #[arg(long)]
    pub check_sil: bool,
}

fn cost_table(name: &str, t: &TaskCost, sim_s: f64) -> String {
    format!(
        "| {name} | {} | {} | {} | {} | {:.2} % |\n",
        t.counts.len(),
        t.total().checked_div(t.counts.len() as u64).unwrap_or(0),
        t.quantile(0.99),
        t.max(),
        100.0 * t.cpu_share(sim_s, CPU_HZ)
    )
}

/// The command.
pub fn command(a: &PilArgs) -> Result<()> {
    struct Run<'a>(&'a PilArgs);
    impl ImageScenarioVisitor for Run<'_> {
        type Output = Result<()>;
        fn visit<M: ScenarioModel<N>, const N: usize>(self, s: ScenarioSpec<M, N>) -> Result<()> {
            run_spec(self.0, s)
        }
    }
    match scenario_file::load_any(&a.scenario)?.visit_image(Run(a)) {
        Ok(r) => r,
        Err(s) => bail!(
            "scenario file {}: its vehicle is a {}; the firmware is built for the {} models",
            a.scenario.display(),
            s.model_name(),
            image_models()
        ),
    }
}

/// The command on a scenario of a model the firmware is built for.
fn run_spec<M: PilModel<N>, const N: usize>(a: &PilArgs, spec: ScenarioSpec<M, N>) -> Result<()> {
    let arm = spec
        .arm()
        .with_context(|| format!("scenario file {}", a.scenario.display()))?;
    let cfg = scenario::loop_config(&spec, arm);
    check_firmware_matches(&cfg, &spec.model_family())
        .map_err(anyhow::Error::msg)
        .with_context(|| format!("scenario file {}", a.scenario.display()))?;
    let out = a
        .out
        .dir
        .clone()
        .or_else(|| spec.out_dir.clone())
        .unwrap_or_else(|| PathBuf::from("out/pil").join(sanitize(&spec.name)));
    let _out_dir = crate::sim::input::files::OutDir::claim(&out)?;
    let elf = a.elf.clone().unwrap_or_else(|| PathBuf::from(M::PIL_ELF));
    if !elf.exists() {
        bail!(
            "PIL image {} not found: build it with `cargo xtask pil` (or `cargo build --release \
             -p shimmy-firmware --target thumbv7em-none-eabihf --features pil`, with \
             `model-truck` for the truck) and pass --elf",
            elf.display()
        );
    }

    let wall = Instant::now();
    let mut fw =
        PilFirmware::start(&elf, record_schema_of::<M::Board>()).map_err(anyhow::Error::msg)?;
    let r = closed_loop::run_on(&cfg, &mut spec.scenario.clone(), None, &mut fw)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let run = fw.finish().map_err(anyhow::Error::msg)?;
    let wall_s = wall.elapsed().as_secs_f64();

    let trace = out.join("trace.csv");
    r.write_trace_csv(&trace)?;
    let label = format!("{} (PIL)", cfg.arm.name());
    let label = label.as_str();
    let time_png = out.join("time.png");
    plot_runs(&time_png, &spec.name, &[(label, &r)])?;
    let margin_png = out.join("margin.png");
    plot_margin(&margin_png, &spec.name, &[(label, &cfg, &r)])?;
    let m = r.metrics(&cfg, spec.t_dist_s);
    println!(
        "scenario `{}` processor in the loop: {} simulated s in {:.2} wall s ({:.0}x real time, QEMU start and exit included)",
        spec.name,
        r.sim_s,
        wall_s,
        r.sim_s / wall_s
    );
    println!(
        "  peak wheel yaw {:.3} deg, RMS current {:.3} A, shimmy at the end: {}",
        m.peak_yaw_rad.to_degrees(),
        m.rms_current_a,
        if m.shimmies() { "YES" } else { "no" }
    );
    println!(
        "  supervisor: worst mode {}, final mode {}, lost frames {}",
        r.faults.worst_mode.name(),
        r.faults.final_mode.name(),
        r.faults.lost_frames
    );
    // Where the wall time goes: QEMU's CPU per guest instruction against the host side's CPU.
    let guest = run.instructions.map_or(f64::NAN, |n| n as f64);
    println!(
        "  QEMU: {:.2} s of CPU for {:.1} M guest instructions ({:.0} M instructions per CPU s); \
         host side (plant, sensors, frames): {:.2} s of CPU",
        run.qemu_cpu_s,
        guest * 1e-6,
        guest * 1e-6 / run.qemu_cpu_s,
        run.host_cpu_s
    );

    let c = costs(&run.periods);
    let mut table = String::from(
        "| task | runs | mean | p99 | max | CPU at 168 MHz, 1 cycle/instruction |\n|---|---:|---:|---:|---:|---:|\n",
    );
    table += &cost_table("control (1 kHz), per step", &c.control, r.sim_s);
    table += &cost_table("meter (100 Hz), per run", &c.meter, r.sim_s);
    table += &cost_table("model loop, per cycle", &c.model, r.sim_s);
    let mut hist = String::from("control step instructions | steps\n---|---:\n");
    for (lo, hi, n) in c.control.histogram(10) {
        hist += &format!("{lo}..{hi} | {n}\n");
    }
    println!("\ninstructions per task (QEMU -icount shift=0, closed-loop data):\n{table}");
    println!("histogram of the control step:\n{hist}");
    let report = out.join("instructions.md");
    crate::sim::input::files::write_file(
        &report,
        format!("# Instructions per task: {}\n\n{table}\n{hist}", spec.name),
    )?;
    println!(
        "  wrote {}, {}, {}, {}",
        trace.display(),
        time_png.display(),
        margin_png.display(),
        report.display()
    );

    if a.check_sil {
        let mut sil = SilFirmware::<M::Linear, N>::new::<M::Board>(Some(&run.periods))
            .map_err(anyhow::Error::msg)?;
        let rs = closed_loop::run_on(&cfg, &mut spec.scenario.clone(), None, &mut sil)
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        let agreement = compare(&run.periods, &sil.periods())
            .map_err(|e| anyhow::anyhow!("PIL and SIL disagree (scenario `{}`): {e}", spec.name))?;
        let same_plant = r.series.psi_l_rad.len() == rs.series.psi_l_rad.len()
            && r.series
                .psi_l_rad
                .iter()
                .zip(&rs.series.psi_l_rad)
                .all(|(x, y)| x.to_bits() == y.to_bits());
        if !same_plant {
            bail!("PIL and SIL agree on the firmware's outputs but the plant trajectories differ");
        }
        println!(
            "PIL = SIL bit for bit: {} steps (coil command, verdict, validated inputs, controller output), {} margin updates (report, level), {} model cycles, identical plant trajectory",
            agreement.steps, agreement.margin_updates, agreement.model_cycles
        );
    }
    Ok(())
}
