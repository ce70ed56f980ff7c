//! The one scenario description of the simulator, [`ScenarioSpec`]: what a closed-loop run
//! needs (the plant's vehicle and the vehicle the firmware believes, inputs, initial state,
//! sensors, faults, controller), whether it comes from a
//! scenario file (`scenario_file`) or from the built-in standard set (`standard`), and the one
//! way to turn it into a [`LoopConfig`] and run it.

use crate::model::disturbance::Scenario;
use crate::model::family::{yaw_state, FamilyVehicle, SimModel};
use crate::model::faults::FaultSpec;
use crate::model::registry::{ReferenceModel, REFERENCE_N};
use crate::model::sensors::SensorConfig;
use crate::sim::input::arg_range;
use crate::sim::input::vehicle_file::FileModel;
use crate::sim::run::closed_loop::{self, Arm, LoopConfig, LoopResult};
use anyhow::{bail, Context, Result};
use shimmy_core::control::ControlParams;
use shimmy_core::model::LinearModel;
use std::path::{Path, PathBuf};

/// The controller names, one per controller, as they appear in tables, legends and file names
/// (`no-damper` = no damper force at all). Every command and scenario file also accepts the
/// short forms `none`, `off` and `on` (see [`controller_name`]).
pub const CONTROLLERS: [&str; 7] = [
    "no-damper",
    "passive-off",
    "passive-on",
    "smc",
    "asmc",
    "skyhook",
    "margin-asmc",
];

/// The one name of the controller called `name` (one of [`CONTROLLERS`] or a short form:
/// `none` = `no-damper`, `off` = `passive-off`, `on` = `passive-on`); `None` if unknown.
pub fn controller_name(name: &str) -> Option<&'static str> {
    Arm::from_name(name, 0.0).map(|a| a.name())
}

/// A scenario file's passive-on current, as error messages name it.
pub const ON_CURRENT_FIELD: &str = "field `controller.on_current_a`";

/// A validated scenario on the vehicle model `M` (the car by default), ready to run.
#[derive(Clone, Debug)]
pub struct ScenarioSpec<M: SimModel<N> = ReferenceModel, const N: usize = { REFERENCE_N }> {
    /// Short name (tables, headings; file names use its sanitised form).
    pub name: String,
    /// One line on what it is (plot titles of `compare`); empty for scenario files.
    pub description: String,
    /// The true vehicle: the simulated plant, damper and sensors.
    pub plant: M::Vehicle,
    /// The vehicle the firmware believes (its controller's and estimator's models, gains and
    /// thresholds); `None`: the plant's vehicle ([`Self::model`]).
    pub model_vehicle: Option<M::Vehicle>,
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

impl<M: SimModel<N>, const N: usize> ScenarioSpec<M, N> {
    /// A scenario with the defaults of a file that gives only these: no description, the plant
    /// at rest, no settling metric, ASMC, default sensors, a trace at 200 Hz, no faults.
    /// The sensors are the plant vehicle's; the firmware believes the plant's vehicle.
    pub fn new(name: &str, plant: &M::Vehicle, scenario: Scenario, duration_s: f64) -> Self {
        let sensors = SensorConfig::from_vehicle(&M::family_vehicle(plant).parts.sensors);
        ScenarioSpec {
            name: name.to_string(),
            description: String::new(),
            plant: *plant,
            model_vehicle: None,
            controller: "asmc".to_string(),
            on_current_a: 0.0,
            initial_yaw_rad: 0.0,
            scenario,
            duration_s,
            t_dist_s: None,
            sensors,
            trace_every: 5,
            faults: Vec::new(),
            out_dir: None,
        }
    }

    /// Replaces the simulated vehicle (and with it the sensors' calibration; the noise seed
    /// stays), e.g. for `--vehicle` on the command line.
    pub fn set_plant(&mut self, plant: M::Vehicle) {
        self.plant = plant;
        self.sensors = SensorConfig {
            seed: self.sensors.seed,
            ..SensorConfig::from_vehicle(&M::family_vehicle(&plant).parts.sensors)
        };
    }

    /// Applies the command line's overrides when given: `--vehicle` (the simulated vehicle,
    /// [`Self::set_plant`]) and `--model-vehicle` (what the firmware believes), each a named
    /// set or a vehicle file, and `--controller` (one of [`CONTROLLERS`]) with its
    /// `--on-current-a`; then checks the passive-on current against the believed vehicle's
    /// coil rating ([`Self::check_on_current`]), naming the option or the file's field.
    pub fn apply_overrides(
        &mut self,
        vehicle: Option<&str>,
        model: Option<&str>,
        controller: Option<(&str, f64)>,
    ) -> Result<()>
    where
        M: FileModel<N>,
    {
        if let Some(v) = vehicle {
            self.set_plant(M::load_vehicle(v, Path::new("")).context("--vehicle")?);
        }
        if let Some(m) = model {
            self.model_vehicle =
                Some(M::load_vehicle(m, Path::new("")).context("--model-vehicle")?);
        }
        let source = match controller {
            Some((name, on_current_a)) => {
                self.controller = name.to_string();
                self.on_current_a = on_current_a;
                "--on-current-a"
            }
            None => ON_CURRENT_FIELD,
        };
        self.check_on_current(source)
    }

    /// The vehicle the firmware believes.
    pub fn model(&self) -> &M::Vehicle {
        self.model_vehicle.as_ref().unwrap_or(&self.plant)
    }

    /// The vehicle the firmware believes, as the model's parameters and the shared sections.
    pub fn model_family(&self) -> FamilyVehicle<M> {
        M::family_vehicle(self.model())
    }

    /// Checks the passive-on current (when that is the controller) against the coil rating of
    /// the vehicle the firmware believes, whose controller limits the command to it; `source`
    /// names where the current was given (an option or a scenario file's field).
    pub fn check_on_current(&self, source: &str) -> Result<()> {
        if self.controller == "passive-on" {
            arg_range::check_current(source, self.on_current_a, &self.model_family().parts)?;
        }
        if self.controller == "margin-asmc" && self.model_family().model.host_app_model().is_none()
        {
            bail!(
                "controller `margin-asmc` reads the firmware's margin report; the firmware is \
                 built for the {} models, this vehicle is a {}: choose another controller",
                crate::model::registry::image_models(),
                <M::Linear as LinearModel<N>>::NAME
            );
        }
        Ok(())
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

/// The closed-loop configuration of `spec` driven by `arm`: the plant vehicle simulated, the
/// model vehicle's controller model and gains.
pub fn loop_config<M: SimModel<N>, const N: usize>(
    spec: &ScenarioSpec<M, N>,
    arm: Arm,
) -> LoopConfig<M, N> {
    let mut cfg = LoopConfig::for_vehicle(&M::family_vehicle(&spec.plant), arm, spec.duration_s)
        .with_model_vehicle(&spec.model_family());
    cfg.sensors = spec.sensors;
    cfg.record_every = spec.trace_every;
    cfg.x0 = yaw_state::<M, N>(spec.initial_yaw_rad);
    cfg.faults = spec.faults.clone();
    cfg
}

/// Runs `spec` with `arm` and the control parameters `control` (e.g. the model vehicle's with
/// a study's gain overrides).
pub fn run_arm<M: SimModel<N>, const N: usize>(
    spec: &ScenarioSpec<M, N>,
    arm: Arm,
    control: &ControlParams,
) -> Result<(LoopConfig<M, N>, LoopResult)> {
    let mut cfg = loop_config(spec, arm);
    cfg.control = *control;
    let mut scenario = spec.scenario.clone();
    let result = closed_loop::run(&cfg, &mut scenario, None)
        .with_context(|| format!("{} / {}: integration failed", spec.name, arm.name()))?;
    Ok((cfg, result))
}

/// Runs `spec` with its own controller and the model vehicle's control parameters.
pub fn run<M: SimModel<N>, const N: usize>(
    spec: &ScenarioSpec<M, N>,
) -> Result<(LoopConfig<M, N>, LoopResult)> {
    run_arm(spec, spec.arm()?, &spec.model_family().control_params())
}
