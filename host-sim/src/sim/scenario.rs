//! The one scenario description of the simulator, [`ScenarioSpec`]: what a closed-loop run
//! needs (plant, inputs, initial state, sensors, faults, controller), whether it comes from a
//! scenario file (`scenario_file`) or from the built-in standard set (`standard`), and the one
//! way to turn it into a [`LoopConfig`] and run it.

use crate::model::disturbance::{initial_yaw, Scenario};
use crate::model::faults::FaultSpec;
use crate::model::sensors::SensorConfig;
use crate::sim::closed_loop::{self, Arm, LoopConfig, LoopResult};
use anyhow::{Context, Result};
use shimmy_core::control::ControlParams;
use shimmy_core::params::PlantParams;
use std::path::PathBuf;

/// The controller names, one per controller, as they appear in tables, legends and file names
/// (`no-damper` = no damper force at all). Every command and scenario file also accepts the
/// short forms `none`, `off` and `on` (see [`controller_name`]).
pub const CONTROLLERS: [&str; 6] = [
    "no-damper",
    "passive-off",
    "passive-on",
    "smc",
    "asmc",
    "skyhook",
];

/// The one name of the controller called `name` (one of [`CONTROLLERS`] or a short form:
/// `none` = `no-damper`, `off` = `passive-off`, `on` = `passive-on`); `None` if unknown.
pub fn controller_name(name: &str) -> Option<&'static str> {
    Arm::from_name(name, 0.0).map(|a| a.name())
}

/// A validated scenario, ready to run.
#[derive(Clone, Debug)]
pub struct ScenarioSpec {
    /// Short name (tables, headings; file names use its sanitised form).
    pub name: String,
    /// One line on what it is (plot titles of `compare`); empty for scenario files.
    pub description: String,
    /// The true plant (the controllers know only the nominal set).
    pub plant: PlantParams,
    /// Controller name, one of [`CONTROLLERS`] (callers running several controllers override it).
    pub controller: String,
    /// Fixed current of `passive-on`, in A.
    pub on_current_a: f64,
    /// Initial in-phase wheel yaw, in rad (0: the plant starts at rest).
    pub initial_yaw_rad: f64,
    /// Speed, driver and road inputs.
    pub scenario: Scenario,
    /// Simulated time, in s.
    pub duration_s: f64,
    /// When the settling metric is measured from, in s (`None`: no settling metric).
    pub t_dist_s: Option<f64>,
    /// Sensor models (encoder resolution and noise, noise seed).
    pub sensors: SensorConfig,
    /// Trace decimation: record every n-th control period.
    pub trace_every: usize,
    /// Injected faults.
    pub faults: Vec<FaultSpec>,
    /// Output folder given by the scenario file (`output.dir`); `None`: the command decides.
    pub out_dir: Option<PathBuf>,
}

impl ScenarioSpec {
    /// A scenario with the defaults of a file that gives only these: no description, the plant
    /// at rest, no settling metric, ASMC, default sensors, a trace at 200 Hz, no faults.
    pub fn new(name: &str, plant: PlantParams, scenario: Scenario, duration_s: f64) -> Self {
        ScenarioSpec {
            name: name.to_string(),
            description: String::new(),
            plant,
            controller: "asmc".to_string(),
            on_current_a: 0.0,
            initial_yaw_rad: 0.0,
            scenario,
            duration_s,
            t_dist_s: None,
            sensors: SensorConfig::default(),
            trace_every: 5,
            faults: Vec::new(),
            out_dir: None,
        }
    }

    /// The scenario's own controller as a closed-loop arm.
    pub fn arm(&self) -> Result<Arm> {
        Arm::from_name(&self.controller, self.on_current_a as f32).with_context(|| {
            format!(
                "controller `{}` is not known to the closed loop",
                self.controller
            )
        })
    }
}

/// The closed-loop configuration of `spec` driven by `arm` (default control gains).
pub fn loop_config(spec: &ScenarioSpec, arm: Arm) -> LoopConfig {
    let mut cfg = LoopConfig::new(spec.plant, arm, spec.duration_s);
    cfg.sensors = spec.sensors;
    cfg.record_every = spec.trace_every;
    cfg.x0 = initial_yaw(spec.initial_yaw_rad);
    cfg.faults = spec.faults.clone();
    cfg
}

/// Runs `spec` with `arm` and the control parameters `control`.
pub fn run_arm(
    spec: &ScenarioSpec,
    arm: Arm,
    control: &ControlParams,
) -> Result<(LoopConfig, LoopResult)> {
    let mut cfg = loop_config(spec, arm);
    cfg.control = *control;
    let mut scenario = spec.scenario.clone();
    let result = closed_loop::run(&cfg, &mut scenario, None)
        .with_context(|| format!("{} / {}: integration failed", spec.name, arm.name()))?;
    Ok((cfg, result))
}

/// Runs `spec` with its own controller and the default control parameters.
pub fn run(spec: &ScenarioSpec) -> Result<(LoopConfig, LoopResult)> {
    run_arm(spec, spec.arm()?, &ControlParams::default())
}
