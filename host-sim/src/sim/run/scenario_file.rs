//! Scenario files (TOML): everything one simulator run needs, validated as a whole before
//! anything runs. A bad file is rejected with a message that names the field and the allowed
//! range; unknown fields are errors (a typo must not silently fall back to a default).
//!
//! ```toml
//! name = "ramp through the Hopf window"
//! duration_s = 60.0
//! seed = 7                        # road noise and sensor noise
//!
//! [plant]                         # the simulated vehicle
//! vehicle = "nominal"             # nominal | gentle | hard | path to a vehicle file, relative
//!                                 # to this file (`params` is the older name of this key)
//! overrides = { c_a = 72000.0 }   # optional: plant fields by name (see `shimmy-sim params`)
//!
//! [model]                         # optional: the vehicle the firmware believes (its controller's
//! vehicle = "nominal"             # and estimator's models, gains, thresholds); default: the
//! overrides = { c_a = 90000.0 }   # plant's vehicle. Same keys as [plant].
//!
//! [controller]
//! kind = "asmc"                   # no-damper | passive-off | passive-on | smc | asmc | skyhook
//! on_current_a = 1.0              # passive-on only
//!
//! [speed]                         # exactly one of: constant_kmh | ramp | points
//! ramp = { from_kmh = 20.0, to_kmh = 120.0, start_s = 0.0, end_s = 60.0 }
//!
//! [initial]
//! yaw_deg = 0.5                   # initial in-phase wheel-yaw perturbation
//!
//! [[impulse]]                     # pothole / road joint: half-sine yaw torque on both wheels
//! t_s = 10.0
//! duration_s = 0.02
//! peak_nm = 400.0
//!
//! [road_noise]
//! std_nm = 15.0
//! corner_hz = 20.0
//! common = 0.5
//!
//! [imbalance]
//! amplitude_nm = 4.0
//! phase_deg = [0.0, 90.0]
//!
//! [driver]                        # lane_change or slalom
//! slalom = { amplitude_nm = 3.0, freq_hz = 0.5, start_s = 1.0 }
//!
//! [sensors]                       # optional: overrides the plant vehicle's `[sensors]`
//! encoder_bits = 14
//! encoder_noise_lsb = 0.5
//!
//! [output]
//! dir = "out/ramp"
//! trace_every = 5                 # record every n-th 1 ms period
//!
//! [[fault]]                       # any number; see `crate::model::faults` for what each does
//! kind = "stuck"                  # stuck | noise | dropout | spike | nan | parity | error-flag |
//!                                 # speed-lost | speed-pulses-lost | speed-implausible | frame-loss |
//!                                 # coil-open | coil-short
//! sensor = "left"                 # encoder faults only: left | right | both (default left)
//! start_s = 5.0                   # active from (0 ..= duration_s)
//! end_s = 8.0                     # optional, active until (start_s ..= duration_s)
//! # kind-specific (only allowed with their kind):
//! # std_deg = 2.0                 noise: standard deviation (0 ..= 90 deg)
//! # amplitude_deg = 20.0          spike: height (0 ..= 180 deg)
//! # period_samples = 100          dropout | spike | frame-loss: pattern period (1 ..= 100000)
//! # length_samples = 3            dropout | frame-loss: bad samples per period (1 ..= period)
//! # speed_kmh = 300.0             speed-implausible: the reported speed (-500 ..= 1000 km/h)
//! # ratio = 5.0                   coil-short: measured / commanded current (1 ..= 100)
//! ```

use crate::model::disturbance::{
    DriverTorque, Imbalance, Impulse, RoadNoise, Scenario, SpeedProfile,
};
use crate::model::family::SimModel;
use crate::model::faults::{FaultMode, FaultSpec, Side, KINDS};
use crate::model::registry::{
    self, for_each_model, ModelTypeVisitor, ModelVisitor, ReferenceModel, Registered,
    StudyTypeVisitor, REFERENCE_N,
};
use crate::model::sensors::SensorConfig;
use crate::model::study::StudyModel;
use crate::sim::input::arg_range::Range;
use crate::sim::input::vehicle_file::{self, ModelVehicle};
use crate::sim::run::scenario::{controller_name, ScenarioSpec, CONTROLLERS, ON_CURRENT_FIELD};
use anyhow::{bail, Context, Result};
use serde::Deserialize;
use shimmy_core::units::kmh_to_mps;
use shimmy_core::vehicle::Vehicle;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    name: Option<String>,
    duration_s: f64,
    #[serde(default = "default_seed")]
    seed: u64,
    plant: Option<VehicleSection>,
    model: Option<VehicleSection>,
    controller: Option<ControllerSection>,
    speed: SpeedSection,
    initial: Option<InitialSection>,
    #[serde(default)]
    impulse: Vec<ImpulseSection>,
    road_noise: Option<RoadNoiseSection>,
    imbalance: Option<ImbalanceSection>,
    driver: Option<DriverSection>,
    sensors: Option<SensorSection>,
    output: Option<OutputSection>,
    #[serde(default)]
    fault: Vec<FaultSection>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FaultSection {
    kind: String,
    sensor: Option<String>,
    start_s: f64,
    end_s: Option<f64>,
    std_deg: Option<f64>,
    amplitude_deg: Option<f64>,
    period_samples: Option<f64>,
    length_samples: Option<f64>,
    speed_kmh: Option<f64>,
    ratio: Option<f64>,
}

fn default_seed() -> u64 {
    1
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct VehicleSection {
    #[serde(alias = "params")]
    vehicle: Option<String>,
    #[serde(default)]
    overrides: BTreeMap<String, f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ControllerSection {
    kind: String,
    on_current_a: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SpeedSection {
    constant_kmh: Option<f64>,
    ramp: Option<RampSection>,
    /// `[[t_s, v_kmh], ...]`
    points: Option<Vec<[f64; 2]>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RampSection {
    from_kmh: f64,
    to_kmh: f64,
    start_s: f64,
    end_s: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct InitialSection {
    yaw_deg: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ImpulseSection {
    t_s: f64,
    duration_s: f64,
    peak_nm: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RoadNoiseSection {
    std_nm: f64,
    corner_hz: f64,
    #[serde(default)]
    common: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ImbalanceSection {
    amplitude_nm: f64,
    #[serde(default)]
    phase_deg: [f64; 2],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct DriverSection {
    lane_change: Option<LaneChangeSection>,
    slalom: Option<SlalomSection>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LaneChangeSection {
    amplitude_nm: f64,
    period_s: f64,
    start_s: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SlalomSection {
    amplitude_nm: f64,
    freq_hz: f64,
    start_s: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SensorSection {
    encoder_bits: Option<f64>,
    encoder_noise_lsb: Option<f64>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct OutputSection {
    dir: Option<String>,
    trace_every: Option<usize>,
}

/// Checks `lo <= value <= hi` (and finiteness, the command-line options' rule
/// [`Range::contains`]), naming the field and the range on failure.
fn in_range(field: &str, value: f64, lo: f64, hi: f64, unit: &str) -> Result<f64> {
    if Range::closed(lo, hi, "").contains(value) {
        Ok(value)
    } else {
        bail!("field `{field}` = {value}: allowed range {lo} ..= {hi} {unit}")
    }
}

/// Reads and validates a scenario file; vehicle files it names are found relative to it.
pub fn load(path: &Path) -> Result<ScenarioSpec> {
    car(load_any(path)?).with_context(|| format!("in scenario file {}", path.display()))
}

/// [`load`] for a scenario on a vehicle of any model of the family.
pub fn load_any(path: &Path) -> Result<AnyScenario> {
    let text = crate::sim::input::files::read_text(path, crate::sim::input::files::TEXT_LIMIT)?;
    let stem = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let dir = path.parent().unwrap_or(Path::new(""));
    parse_any_in(&text, &stem, dir).with_context(|| format!("in scenario file {}", path.display()))
}

/// Parses and validates scenario TOML; `default_name` names the run when the file does not;
/// vehicle files are looked up relative to the working directory.
pub fn parse(text: &str, default_name: &str) -> Result<ScenarioSpec> {
    parse_in(text, default_name, Path::new(""))
}

/// A scenario on a vehicle of any model of the family (the `[plant]` vehicle's model; the
/// `[model]` vehicle must be of the same): its [`ScenarioSpec`] of that model, behind a type
/// check instead of an enum of the models (the model registry, `crate::model::registry`).
#[derive(Debug)]
pub struct AnyScenario {
    spec: Box<dyn AnySpec>,
    model: &'static str,
}

/// A [`ScenarioSpec`] of some model, cloned and taken back by its type.
trait AnySpec: std::any::Any + std::fmt::Debug + Send + Sync {
    fn clone_box(&self) -> Box<dyn AnySpec>;
    fn name(&self) -> &str;
    fn into_any(self: Box<Self>) -> Box<dyn std::any::Any>;
}

impl<M: SimModel<N>, const N: usize> AnySpec for ScenarioSpec<M, N> {
    fn clone_box(&self) -> Box<dyn AnySpec> {
        Box::new(self.clone())
    }
    fn name(&self) -> &str {
        &self.name
    }
    fn into_any(self: Box<Self>) -> Box<dyn std::any::Any> {
        self
    }
}

impl Clone for AnyScenario {
    fn clone(&self) -> Self {
        Self {
            spec: self.spec.clone_box(),
            model: self.model,
        }
    }
}

/// A generic call on a scenario of some model: [`AnyScenario::visit`] calls [`Self::visit`]
/// with the scenario's model as `M`.
pub trait ScenarioVisitor {
    /// What the call gives.
    type Output;
    /// The call on the scenario `s` of the model `M`.
    fn visit<M: Registered<N>, const N: usize>(self, s: ScenarioSpec<M, N>) -> Self::Output;
}

impl AnyScenario {
    /// The scenario `s` of the model `M`.
    pub fn new<M: Registered<N>, const N: usize>(s: ScenarioSpec<M, N>) -> Self {
        Self {
            spec: Box::new(s),
            model: registry::name_of::<M, N>(),
        }
    }

    /// The scenario's name.
    pub fn name(&self) -> &str {
        self.spec.name()
    }

    /// The name of the scenario's vehicle model.
    pub fn model_name(&self) -> &'static str {
        self.model
    }

    /// The scenario if it is on the model `M`, else itself.
    pub fn into_spec<M: SimModel<N>, const N: usize>(
        self,
    ) -> std::result::Result<ScenarioSpec<M, N>, Self> {
        if !(self.spec.as_ref() as &dyn std::any::Any).is::<ScenarioSpec<M, N>>() {
            return Err(self);
        }
        Ok(*self
            .spec
            .into_any()
            .downcast::<ScenarioSpec<M, N>>()
            .expect("checked above"))
    }

    /// The scenario in `slot` if it is on the model `M` (taken out), else `None` (left in).
    fn take_spec<M: SimModel<N>, const N: usize>(
        slot: &mut Option<Self>,
    ) -> Option<ScenarioSpec<M, N>> {
        match slot.take()?.into_spec::<M, N>() {
            Ok(spec) => Some(spec),
            Err(s) => {
                *slot = Some(s);
                None
            }
        }
    }

    /// Calls `visitor` on the scenario with its model as `M`.
    pub fn visit<V: ScenarioVisitor>(self, visitor: V) -> V::Output {
        struct Find<V: ScenarioVisitor> {
            s: Option<AnyScenario>,
            visitor: Option<V>,
            out: Option<V::Output>,
        }
        impl<V: ScenarioVisitor> ModelTypeVisitor for Find<V> {
            fn visit<M: Registered<N>, const N: usize>(&mut self) {
                if let Some(spec) = AnyScenario::take_spec::<M, N>(&mut self.s) {
                    let v = self.visitor.take().expect("called once");
                    self.out = Some(v.visit(spec));
                }
            }
        }
        let mut f = Find {
            s: Some(self),
            visitor: Some(visitor),
            out: None,
        };
        for_each_model(&mut f);
        f.out.expect("a scenario is of a registered model")
    }
}

/// A generic call on a scenario of a model with a firmware image:
/// [`AnyScenario::visit_image`] calls [`Self::visit`] with the scenario's model as `M`.
pub trait ImageScenarioVisitor {
    /// What the call gives.
    type Output;
    /// The call on the scenario `s` of the model `M`.
    fn visit<M: ScenarioModel<N>, const N: usize>(self, s: ScenarioSpec<M, N>) -> Self::Output;
}

impl AnyScenario {
    /// Calls `visitor` on the scenario with its model as `M` if that is a model with a
    /// firmware image, else gives the scenario back.
    pub fn visit_image<V: ImageScenarioVisitor>(
        self,
        visitor: V,
    ) -> std::result::Result<V::Output, Self> {
        struct Find<V: ImageScenarioVisitor> {
            s: Option<AnyScenario>,
            visitor: Option<V>,
            out: Option<V::Output>,
        }
        impl<V: ImageScenarioVisitor> StudyTypeVisitor for Find<V> {
            fn visit<M: Registered<N> + StudyModel<N>, const N: usize>(&mut self) {
                if let Some(spec) = AnyScenario::take_spec::<M, N>(&mut self.s) {
                    let v = self.visitor.take().expect("called once");
                    self.out = Some(v.visit(spec));
                }
            }
        }
        let mut f = Find {
            s: Some(self),
            visitor: Some(visitor),
            out: None,
        };
        registry::for_each_image_model(&mut f);
        match (f.out, f.s) {
            (Some(out), _) => Ok(out),
            (None, Some(s)) => Err(s),
            (None, None) => unreachable!("the scenario is either taken or given back"),
        }
    }
}

/// The car's scenario, or an error naming the model of another.
fn car(s: AnyScenario) -> Result<ScenarioSpec> {
    s.into_spec().map_err(|s| {
        anyhow::anyhow!(
            "scenario `{}` is on a {} vehicle; this command runs the {} only",
            s.name(),
            s.model_name(),
            registry::name_of::<ReferenceModel, REFERENCE_N>()
        )
    })
}

/// The vehicle of a `[plant]` or `[model]` section (`key`): the named set or file, then the
/// plant overrides (the model's parameters by name), validated as a whole.
fn vehicle_of(key: &str, section: &VehicleSection, dir: &Path) -> Result<ModelVehicle> {
    let spec = section.vehicle.as_deref().unwrap_or("nominal");
    let v = vehicle_file::load_model_relative(spec, dir)
        .with_context(|| format!("field `{key}.vehicle`"))?;
    registry::with_model(v, Overrides { key, section })
}

/// A `[plant]` or `[model]` section's overrides on its vehicle: the car's `[plant]` fields
/// (through the vehicle file's checks), another model's parameters by name.
struct Overrides<'a> {
    key: &'a str,
    section: &'a VehicleSection,
}

impl ModelVisitor for Overrides<'_> {
    type Output = Result<ModelVehicle>;
    fn visit<M: Registered<N>, const N: usize>(self, mut f: M::File) -> Result<ModelVehicle> {
        let Overrides { key, section } = self;
        anyhow::ensure!(
            M::SCENARIOS,
            "field `{key}.vehicle`: a {} vehicle; scenario files take the car, the mining truck or the trailer",
            registry::name_of::<M, N>()
        );
        match (M::SECTION, M::parts_of_mut(&mut f)) {
            (None, Some(v)) => {
                for (name, value) in &section.overrides {
                    vehicle_file::set_field(v, "plant", &format!("{key}.overrides"), name, *value)?;
                }
                v.validate()
                    .with_context(|| format!("field `{key}.overrides`"))?;
            }
            (own, _) => {
                let t = M::model_mut(&mut f);
                for (name, value) in &section.overrides {
                    *t = t
                        .with_param(name, *value)
                        .with_context(|| format!("field `{key}.overrides.{name}`"))?;
                }
                t.check()
                    .map_err(|e| anyhow::anyhow!("{}: {e}", own.unwrap_or("plant")))
                    .with_context(|| format!("field `{key}.overrides`"))?;
            }
        }
        Ok(M::into_any(f))
    }
}

/// [`parse`] with vehicle files looked up relative to `dir` (the scenario file's folder).
pub fn parse_in(text: &str, default_name: &str, dir: &Path) -> Result<ScenarioSpec> {
    car(parse_any_in(text, default_name, dir)?)
}

/// [`parse_in`] for a scenario on a vehicle of any model of the family.
pub fn parse_any_in(text: &str, default_name: &str, dir: &Path) -> Result<AnyScenario> {
    let f: File = toml::from_str(text)?;
    let duration_s = in_range("duration_s", f.duration_s, 0.01, 3600.0, "s")?;

    let plant = match &f.plant {
        Some(p) => vehicle_of("plant", p, dir)?,
        None => ModelVehicle::from(Vehicle::nominal()),
    };
    let model_vehicle = match &f.model {
        Some(m) => Some(vehicle_of("model", m, dir)?),
        None => None,
    };
    registry::with_model(
        plant,
        Build {
            f: &f,
            model_vehicle,
            default_name,
            duration_s,
        },
    )
}

/// The rest of the file on its plant vehicle of the model `M`, the believed vehicle of the same.
struct Build<'a> {
    f: &'a File,
    model_vehicle: Option<ModelVehicle>,
    default_name: &'a str,
    duration_s: f64,
}

impl ModelVisitor for Build<'_> {
    type Output = Result<AnyScenario>;
    fn visit<M: Registered<N>, const N: usize>(self, p: M::File) -> Result<AnyScenario> {
        let Build {
            f,
            model_vehicle,
            default_name,
            duration_s,
        } = self;
        let name = registry::name_of::<M, N>();
        let m = match model_vehicle.map(M::from_any) {
            None => None,
            Some(Ok(m)) => Some(M::vehicle(m)?),
            Some(Err(other)) => bail!(
                "field `model.vehicle`: a {} vehicle, the plant a {name}: the firmware's model is \
                 of the plant's model",
                other.model_name(),
            ),
        };
        if let (Some(why), Some(_)) = (M::NO_DRIVER, &f.driver) {
            bail!("field `driver`: the {name} {why}; leave the section out");
        }
        build::<M, N>(f, M::vehicle(p)?, m, default_name, duration_s).map(AnyScenario::new)
    }
}

/// The rest of the file on the plant vehicle `plant` (and the believed `model_vehicle`).
fn build<M: SimModel<N>, const N: usize>(
    f: &File,
    mut plant: M::Vehicle,
    model_vehicle: Option<M::Vehicle>,
    default_name: &str,
    duration_s: f64,
) -> Result<ScenarioSpec<M, N>> {
    let (controller, on_current_a) = match &f.controller {
        Some(c) => {
            let Some(kind) = controller_name(&c.kind) else {
                bail!(
                    "field `controller.kind` = {:?}: allowed: {}",
                    c.kind,
                    CONTROLLERS.join(", ")
                );
            };
            let on = match (kind, c.on_current_a) {
                ("passive-on", Some(i)) => i,
                ("passive-on", None) => {
                    bail!("field `controller.on_current_a` is required for passive-on")
                }
                (_, Some(_)) => bail!("field `controller.on_current_a` only applies to passive-on"),
                (_, None) => 0.0,
            };
            (kind.to_string(), on)
        }
        None => ("asmc".to_string(), 0.0),
    };

    let speed = parse_speed(&f.speed, duration_s)?;
    let mut scenario = Scenario::new(speed);

    for (i, imp) in f.impulse.iter().enumerate() {
        let t0_s = in_range(&format!("impulse[{i}].t_s"), imp.t_s, 0.0, duration_s, "s")?;
        let dur = in_range(
            &format!("impulse[{i}].duration_s"),
            imp.duration_s,
            1e-3,
            1.0,
            "s",
        )?;
        let peak = in_range(
            &format!("impulse[{i}].peak_nm"),
            imp.peak_nm,
            -5000.0,
            5000.0,
            "N m",
        )?;
        scenario.impulses.push(Impulse {
            t0_s,
            duration_s: dur,
            peak_nm: [peak, peak],
        });
    }
    if let Some(n) = &f.road_noise {
        let std_nm = in_range("road_noise.std_nm", n.std_nm, 0.0, 500.0, "N m")?;
        let corner_hz = in_range("road_noise.corner_hz", n.corner_hz, 0.1, 200.0, "Hz")?;
        let common = in_range("road_noise.common", n.common, 0.0, 1.0, "")?;
        scenario.noise = Some(RoadNoise::new(std_nm, corner_hz, common, f.seed));
    }
    if let Some(b) = &f.imbalance {
        let a = in_range("imbalance.amplitude_nm", b.amplitude_nm, 0.0, 200.0, "N m")?;
        let mut phase_rad = [0.0; 2];
        for (k, p) in b.phase_deg.iter().enumerate() {
            phase_rad[k] = in_range(
                &format!("imbalance.phase_deg[{k}]"),
                *p,
                -360.0,
                360.0,
                "deg",
            )?
            .to_radians();
        }
        scenario.imbalance = Some(Imbalance {
            amplitude_nm: [a, a],
            phase_rad,
            radius_m: M::family_vehicle(&plant).model.rolling_radius_m(),
        });
    }
    if let Some(d) = &f.driver {
        scenario.driver = match (&d.lane_change, &d.slalom) {
            (Some(l), None) => DriverTorque::LaneChange {
                amplitude_nm: in_range(
                    "driver.lane_change.amplitude_nm",
                    l.amplitude_nm,
                    -50.0,
                    50.0,
                    "N m",
                )?,
                period_s: in_range("driver.lane_change.period_s", l.period_s, 0.2, 20.0, "s")?,
                t0_s: in_range(
                    "driver.lane_change.start_s",
                    l.start_s,
                    0.0,
                    duration_s,
                    "s",
                )?,
            },
            (None, Some(s)) => DriverTorque::Slalom {
                amplitude_nm: in_range(
                    "driver.slalom.amplitude_nm",
                    s.amplitude_nm,
                    -50.0,
                    50.0,
                    "N m",
                )?,
                freq_hz: in_range("driver.slalom.freq_hz", s.freq_hz, 0.05, 3.0, "Hz")?,
                t0_s: in_range("driver.slalom.start_s", s.start_s, 0.0, duration_s, "s")?,
            },
            _ => bail!("field `driver`: give exactly one of `lane_change` or `slalom`"),
        };
    }

    let initial_yaw_rad = match &f.initial {
        Some(i) => in_range("initial.yaw_deg", i.yaw_deg, -10.0, 10.0, "deg")?.to_radians(),
        None => 0.0,
    };
    // The scenario's sensors override the plant vehicle's, through the vehicle's validation.
    if let Some(s) = &f.sensors {
        for (name, value) in [
            ("encoder_bits", s.encoder_bits),
            ("encoder_noise_lsb", s.encoder_noise_lsb),
        ] {
            if let Some(x) = value {
                vehicle_file::set_field(M::parts_mut(&mut plant), "sensors", "sensors", name, x)?;
            }
        }
    }
    let name = f.name.clone().unwrap_or_else(|| default_name.to_string());
    let (out_dir, trace_every) = match &f.output {
        Some(o) => (
            o.dir.clone().map(PathBuf::from),
            in_range(
                "output.trace_every",
                o.trace_every.unwrap_or(5) as f64,
                1.0,
                1000.0,
                "",
            )? as usize,
        ),
        None => (None, 5),
    };
    let faults = f
        .fault
        .iter()
        .enumerate()
        .map(|(i, fs)| parse_fault(i, fs, duration_s))
        .collect::<Result<Vec<_>>>()?;
    let sensors = SensorConfig {
        seed: f.seed,
        ..SensorConfig::from_vehicle(&M::family_vehicle(&plant).parts.sensors)
    };
    // Settling is measured from the initial perturbation (t = 0), else from the first impulse.
    let t_dist_s = if initial_yaw_rad != 0.0 {
        Some(0.0)
    } else {
        scenario.impulses.first().map(|i| i.t0_s)
    };

    let spec = ScenarioSpec {
        name,
        description: String::new(),
        plant,
        model_vehicle,
        controller,
        on_current_a,
        initial_yaw_rad,
        scenario,
        duration_s,
        t_dist_s,
        sensors,
        trace_every,
        faults,
        out_dir,
    };
    spec.check_on_current(ON_CURRENT_FIELD)?;
    Ok(spec)
}

/// Validates one `[[fault]]` entry.
fn parse_fault(i: usize, f: &FaultSection, duration_s: f64) -> Result<FaultSpec> {
    let field = |name: &str| format!("fault[{i}].{name}");
    let kind = f.kind.as_str();
    if !KINDS.contains(&kind) {
        bail!(
            "field `{}` = {:?}: allowed: {}",
            field("kind"),
            f.kind,
            KINDS.join(", ")
        );
    }
    let encoder = matches!(
        kind,
        "stuck" | "noise" | "dropout" | "spike" | "nan" | "parity" | "error-flag"
    );
    let side = match (&f.sensor, encoder) {
        (None, _) => Side::Left,
        (Some(s), true) => Side::from_name(s).ok_or_else(|| {
            anyhow::anyhow!(
                "field `{}` = {s:?}: allowed: left, right, both",
                field("sensor")
            )
        })?,
        (Some(_), false) => bail!(
            "field `{}` only applies to encoder faults (stuck, noise, dropout, spike, nan, parity, error-flag), not to `{kind}`",
            field("sensor")
        ),
    };
    let start_s = in_range(&field("start_s"), f.start_s, 0.0, duration_s, "s")?;
    let end_s = match f.end_s {
        Some(e) => Some(in_range(&field("end_s"), e, start_s, duration_s, "s")?),
        None => None,
    };
    // Kind-specific parameters: required for their kind, rejected for every other.
    let param = |name: &str,
                 value: Option<f64>,
                 kinds: &[&str],
                 default: Option<f64>,
                 lo: f64,
                 hi: f64,
                 unit: &str|
     -> Result<f64> {
        match (value, kinds.contains(&kind)) {
            (Some(v), true) => in_range(&field(name), v, lo, hi, unit),
            (None, true) => default.ok_or_else(|| {
                anyhow::anyhow!("field `{}` is required for kind `{kind}`", field(name))
            }),
            (Some(_), false) => bail!(
                "field `{}` only applies to kind {}, not to `{kind}`",
                field(name),
                kinds.join(" / ")
            ),
            (None, false) => Ok(0.0),
        }
    };
    let std_deg = param("std_deg", f.std_deg, &["noise"], None, 0.0, 90.0, "deg")?;
    let amp_deg = param(
        "amplitude_deg",
        f.amplitude_deg,
        &["spike"],
        None,
        0.0,
        180.0,
        "deg",
    )?;
    let period = param(
        "period_samples",
        f.period_samples,
        &["dropout", "spike", "frame-loss"],
        None,
        1.0,
        100_000.0,
        "samples",
    )?;
    let length = param(
        "length_samples",
        f.length_samples,
        &["dropout", "frame-loss"],
        None,
        1.0,
        period.max(1.0),
        "samples (at most period_samples)",
    )?;
    for (name, v) in [("period_samples", period), ("length_samples", length)] {
        if v.fract() != 0.0 {
            bail!("field `{}` = {v}: must be a whole number", field(name));
        }
    }
    let speed_kmh = param(
        "speed_kmh",
        f.speed_kmh,
        &["speed-implausible"],
        None,
        -500.0,
        1000.0,
        "km/h",
    )?;
    let ratio = param("ratio", f.ratio, &["coil-short"], Some(5.0), 1.0, 100.0, "")?;
    let (period, length) = (period as u32, length as u32);
    let mode = match kind {
        "stuck" => FaultMode::Stuck(side),
        "noise" => FaultMode::Noise(side, std_deg.to_radians()),
        "dropout" => FaultMode::Dropout {
            side,
            period,
            length,
        },
        "spike" => FaultMode::Spike {
            side,
            period,
            amplitude_rad: amp_deg.to_radians(),
        },
        "nan" => FaultMode::Nan(side),
        "parity" => FaultMode::Parity(side),
        "error-flag" => FaultMode::ErrorFlag(side),
        "speed-lost" => FaultMode::SpeedLost,
        "speed-pulses-lost" => FaultMode::SpeedPulsesLost,
        "speed-implausible" => FaultMode::SpeedImplausible(kmh_to_mps(speed_kmh)),
        "frame-loss" => FaultMode::FrameLoss { period, length },
        "coil-open" => FaultMode::CoilOpen,
        _ => FaultMode::CoilShort(ratio),
    };
    Ok(FaultSpec {
        mode,
        start_s,
        end_s,
    })
}

fn parse_speed(s: &SpeedSection, duration_s: f64) -> Result<SpeedProfile> {
    const MAX_KMH: f64 = 200.0;
    match (s.constant_kmh, &s.ramp, &s.points) {
        (Some(v), None, None) => Ok(SpeedProfile::Constant(kmh_to_mps(in_range(
            "speed.constant_kmh",
            v,
            0.0,
            MAX_KMH,
            "km/h",
        )?))),
        (None, Some(r), None) => {
            let v0 = in_range("speed.ramp.from_kmh", r.from_kmh, 0.0, MAX_KMH, "km/h")?;
            let v1 = in_range("speed.ramp.to_kmh", r.to_kmh, 0.0, MAX_KMH, "km/h")?;
            let t0 = in_range("speed.ramp.start_s", r.start_s, 0.0, duration_s, "s")?;
            let t1 = in_range("speed.ramp.end_s", r.end_s, t0, f64::MAX, "s")?;
            Ok(SpeedProfile::Ramp {
                v0_mps: kmh_to_mps(v0),
                v1_mps: kmh_to_mps(v1),
                t0_s: t0,
                t1_s: t1,
            })
        }
        (None, None, Some(pts)) => {
            if pts.is_empty() {
                bail!("field `speed.points`: give at least one [t_s, v_kmh] point");
            }
            let mut out = Vec::with_capacity(pts.len());
            let mut last_t = f64::NEG_INFINITY;
            for (i, [t, v]) in pts.iter().enumerate() {
                let t = in_range(
                    &format!("speed.points[{i}][0] (t_s)"),
                    *t,
                    0.0,
                    f64::MAX,
                    "s",
                )?;
                if t < last_t {
                    bail!("field `speed.points[{i}]`: times must not decrease ({t} s after {last_t} s)");
                }
                last_t = t;
                let v = in_range(
                    &format!("speed.points[{i}][1] (v_kmh)"),
                    *v,
                    0.0,
                    MAX_KMH,
                    "km/h",
                )?;
                out.push((t, kmh_to_mps(v)));
            }
            Ok(SpeedProfile::Piecewise(out))
        }
        _ => bail!("field `speed`: give exactly one of `constant_kmh`, `ramp` or `points`"),
    }
}

/// A model whose scenarios scenario files give: how its scenario is taken out of an
/// [`AnyScenario`] (and, from [`StudyModel`], where its shipped scenarios are: `shimmy-sim
/// report` on a vehicle of the model). Every study model of the registry is one.
pub trait ScenarioModel<const N: usize>:
    crate::sim::input::vehicle_file::FileModel<N> + StudyModel<N>
{
    /// The scenario `s` if it is on this model, else an error naming both models.
    fn scenario(s: AnyScenario) -> Result<ScenarioSpec<Self, N>> {
        s.into_spec().map_err(|other| {
            other_model(
                other.name(),
                other.model_name(),
                registry::name_of::<Self, N>(),
            )
        })
    }
    /// `v` as a vehicle of any model (provenance).
    fn any_vehicle(v: &Self::Vehicle) -> ModelVehicle {
        Self::into_any(Self::file_of(v))
    }
    /// `v` with its model's parameters replaced by `model` (the shared sections stay).
    fn with_model(v: &Self::Vehicle, model: Self) -> Self::Vehicle {
        Self::with_params(v, model)
    }
}

impl<M: Registered<N> + StudyModel<N>, const N: usize> ScenarioModel<N> for M {}

/// The error of a scenario on another model than the run's.
fn other_model(name: &str, is: &str, wanted: &str) -> anyhow::Error {
    anyhow::anyhow!(
        "scenario `{name}` is on a {is} vehicle, this run's vehicle is a {wanted} (one model per \
         run: give scenario files of the {wanted}, e.g. host-sim/scenarios/truck/ for the truck)"
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use shimmy_core::model::LinearModel;
    use shimmy_core::vehicles::truck::TruckParams;

    const GOOD: &str = r#"
name = "ramp"
duration_s = 30.0
seed = 3
[plant]
params = "hard"
overrides = { c_a = 72000.0 }
[controller]
kind = "passive-on"
on_current_a = 1.0
[speed]
ramp = { from_kmh = 20.0, to_kmh = 120.0, start_s = 0.0, end_s = 30.0 }
[initial]
yaw_deg = 0.5
[[impulse]]
t_s = 5.0
duration_s = 0.02
peak_nm = 300.0
[road_noise]
std_nm = 10.0
corner_hz = 20.0
common = 0.5
[imbalance]
amplitude_nm = 4.0
phase_deg = [0.0, 90.0]
[driver]
slalom = { amplitude_nm = 3.0, freq_hz = 0.5, start_s = 1.0 }
"#;

    #[test]
    fn a_complete_file_parses_into_the_run() {
        let s = parse(GOOD, "x").unwrap();
        assert_eq!(s.name, "ramp");
        assert_eq!(s.plant.plant.c_a, 72000.0);
        assert_eq!(s.plant.plant.k_d, 5000.0, "hard set");
        assert_eq!(
            s.model(),
            &s.plant,
            "no [model]: the firmware believes the plant"
        );
        assert_eq!(s.controller, "passive-on");
        assert!((s.scenario.speed.at(15.0) - kmh_to_mps(70.0)).abs() < 1e-12);
        assert_eq!(s.scenario.impulses.len(), 1);
        assert!(s.scenario.noise.is_some() && s.scenario.imbalance.is_some());
        assert!(matches!(s.scenario.driver, DriverTorque::Slalom { .. }));
        assert!((s.initial_yaw_rad - 0.5f64.to_radians()).abs() < 1e-15);
        assert_eq!(s.out_dir, None, "no `[output]`: the command decides");
        assert_eq!(s.t_dist_s, Some(0.0), "from the initial yaw");
    }

    fn err(text: &str) -> String {
        format!("{:#}", parse(text, "x").unwrap_err())
    }

    #[test]
    fn bad_files_name_the_field_and_the_range() {
        let base = "duration_s = 10.0\n[speed]\nconstant_kmh = 50.0\n";
        assert!(parse(base, "x").is_ok());
        let e = err("duration_s = 10.0\n[speed]\nconstant_kmh = 900.0\n");
        assert!(
            e.contains("speed.constant_kmh") && e.contains("0 ..= 200"),
            "{e}"
        );
        let e = err(&format!("{base}[controller]\nkind = \"pid\"\n"));
        assert!(e.contains("controller.kind") && e.contains("asmc"), "{e}");
        let e = err(&format!("{base}[controller]\nkind = \"passive-on\"\n"));
        assert!(e.contains("controller.on_current_a"), "{e}");
        let e = err(&format!(
            "{base}[road_noise]\nstd_nm = 10.0\ncorner_hz = -1.0\n"
        ));
        assert!(e.contains("road_noise.corner_hz"), "{e}");
        let e = err(&format!("{base}[plant]\noverrides = {{ k_dd = 1.0 }}\n"));
        assert!(e.contains("plant.overrides.k_dd"), "{e}");
        let e = err(&format!("{base}[plant]\noverrides = {{ sigma = -1.0 }}\n"));
        assert!(e.contains("plant.overrides.sigma"), "{e}");
        let e = err(&format!("{base}[initial]\nyaw_degs = 1.0\n"));
        assert!(e.contains("yaw_degs"), "unknown fields are errors: {e}");
        let e = err("duration_s = 10.0\n[speed]\nconstant_kmh = 50.0\nramp = { from_kmh = 1.0, to_kmh = 2.0, start_s = 0.0, end_s = 1.0 }\n");
        assert!(e.contains("exactly one"), "{e}");
        let e =
            err("duration_s = 10.0\n[speed]\npoints = [[0.0, 10.0], [5.0, 20.0], [4.0, 30.0]]\n");
        assert!(e.contains("speed.points[2]"), "{e}");
        let e = err("[speed]\nconstant_kmh = 50.0\n");
        assert!(
            e.contains("duration_s"),
            "a missing required field is named: {e}"
        );
        let e = err(&format!(
            "{base}[[impulse]]\nt_s = 20.0\nduration_s = 0.02\npeak_nm = 1.0\n"
        ));
        assert!(e.contains("impulse[0].t_s"), "{e}");
    }

    #[test]
    fn fault_entries_parse_and_bad_ones_name_field_and_range() {
        let base = "duration_s = 10.0\n[speed]\nconstant_kmh = 50.0\n";
        let s = parse(
            &format!(
                "{base}[[fault]]\nkind = \"stuck\"\nsensor = \"right\"\nstart_s = 2.0\nend_s = 4.0\n\
                 [[fault]]\nkind = \"dropout\"\nstart_s = 1.0\nperiod_samples = 10\nlength_samples = 3\n\
                 [[fault]]\nkind = \"coil-short\"\nstart_s = 5.0\n"
            ),
            "x",
        )
        .unwrap();
        assert_eq!(s.faults.len(), 3);
        assert_eq!(s.faults[0].mode, FaultMode::Stuck(Side::Right));
        assert_eq!(s.faults[0].end_s, Some(4.0));
        assert_eq!(
            s.faults[1].mode,
            FaultMode::Dropout {
                side: Side::Left,
                period: 10,
                length: 3
            }
        );
        assert_eq!(s.faults[2].mode, FaultMode::CoilShort(5.0));
        let cases = [
            (
                "kind = \"melt\"\nstart_s = 1.0",
                "fault[0].kind",
                "coil-short",
            ),
            (
                "kind = \"nan\"\nstart_s = 11.0",
                "fault[0].start_s",
                "0 ..= 10",
            ),
            (
                "kind = \"nan\"\nstart_s = 5.0\nend_s = 4.0",
                "fault[0].end_s",
                "5 ..= 10",
            ),
            (
                "kind = \"nan\"\nsensor = \"middle\"\nstart_s = 1.0",
                "fault[0].sensor",
                "both",
            ),
            (
                "kind = \"speed-lost\"\nsensor = \"left\"\nstart_s = 1.0",
                "fault[0].sensor",
                "encoder faults",
            ),
            (
                "kind = \"noise\"\nstart_s = 1.0",
                "fault[0].std_deg",
                "required",
            ),
            (
                "kind = \"noise\"\nstart_s = 1.0\nstd_deg = 200.0",
                "fault[0].std_deg",
                "0 ..= 90",
            ),
            (
                "kind = \"nan\"\nstart_s = 1.0\nstd_deg = 1.0",
                "fault[0].std_deg",
                "only applies",
            ),
            (
                "kind = \"dropout\"\nstart_s = 1.0\nperiod_samples = 10\nlength_samples = 11",
                "fault[0].length_samples",
                "1 ..= 10",
            ),
            (
                "kind = \"frame-loss\"\nstart_s = 1.0\nperiod_samples = 10.5\nlength_samples = 1",
                "fault[0].period_samples",
                "whole",
            ),
            (
                "kind = \"coil-short\"\nstart_s = 1.0\nratio = 0.5",
                "fault[0].ratio",
                "1 ..= 100",
            ),
            (
                "kind = \"nan\"\nstart_s = 1.0\nside = \"left\"",
                "side",
                "unknown",
            ),
        ];
        for (entry, field, range) in cases {
            let e = err(&format!("{base}[[fault]]\n{entry}\n"));
            assert!(e.contains(field) && e.contains(range), "{entry}: {e}");
        }
    }

    #[test]
    fn plant_and_model_vehicles_resolve_relative_to_the_scenario_file() {
        let dir = std::env::temp_dir().join(format!("shimmy-sc-vehicle-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("vehicles")).unwrap();
        std::fs::write(dir.join("vehicles/truck.toml"), "[plant]\nf_z = 30000.0\n").unwrap();
        let base = "duration_s = 1.0\n[speed]\nconstant_kmh = 50.0\n";
        let s = parse_in(
            &format!("{base}[plant]\nvehicle = \"vehicles/truck.toml\"\n[model]\nvehicle = \"nominal\"\noverrides = {{ c_a = 80000.0 }}\n"),
            "x",
            &dir,
        )
        .unwrap();
        assert_eq!(s.plant.plant.f_z, 30000.0);
        assert_eq!(s.model().plant.f_z, 6200.0);
        assert_eq!(s.model().plant.c_a, 80000.0);
        // Relative to the scenario's folder, not to the working directory.
        let e = format!(
            "{:#}",
            parse(
                &format!("{base}[plant]\nvehicle = \"vehicles/truck.toml\"\n"),
                "x"
            )
            .unwrap_err()
        );
        assert!(
            e.contains("plant.vehicle") && e.contains("no such file"),
            "{e}"
        );
        let e = format!(
            "{:#}",
            parse_in(
                &format!("{base}[model]\noverrides = {{ mu = 1000.0 }}\n"),
                "x",
                &dir
            )
            .unwrap_err()
        );
        assert!(e.contains("model.overrides.mu") && e.contains("1.5"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn every_shipped_scenario_is_valid() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios");
        let mut n = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "toml") {
                load(&path).unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
                n += 1;
            }
        }
        assert!(
            n >= 5,
            "expected the standard scenarios in {}",
            dir.display()
        );
    }

    /// The truck's shipped scenarios parse as truck scenarios; the car-only loader and a truck
    /// scenario with a driver torque are rejected, naming why; the margin-scheduled controller
    /// (whose report exists for the models a firmware image is built for) is taken for the
    /// truck and refused for the trailer.
    #[test]
    fn the_trucks_shipped_scenarios_are_truck_scenarios() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("scenarios")
            .join("truck");
        let mut n = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "toml") {
                let s = load_any(&path).unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
                assert_eq!(s.model_name(), TruckParams::NAME, "{}", path.display());
                let e = format!("{:#}", load(&path).unwrap_err());
                assert!(e.contains("mining-truck-5dof"), "{e}");
                n += 1;
            }
        }
        assert_eq!(n, 3);
        let truck =
            "duration_s = 1.0\n[plant]\nvehicle = \"truck-full\"\n[speed]\nconstant_kmh = 30.0\n";
        let e =
            |text: String| format!("{:#}", parse_any_in(&text, "t", Path::new("")).unwrap_err());
        let msg = e(format!(
            "{truck}[driver]\nslalom = {{ amplitude_nm = 2.0, freq_hz = 0.5, start_s = 0.0 }}\n"
        ));
        assert!(msg.contains("field `driver`"), "{msg}");
        let margin_asmc = "[controller]\nkind = \"margin-asmc\"\n";
        assert_eq!(
            parse_any_in(&format!("{truck}{margin_asmc}"), "t", Path::new(""))
                .unwrap()
                .model_name(),
            TruckParams::NAME
        );
        let trailer = truck.replace("\"truck-full\"", "\"trailer\"");
        let msg = e(format!("{trailer}{margin_asmc}"));
        assert!(
            msg.contains("margin-asmc") && msg.contains("mining-truck-5dof"),
            "{msg}"
        );
        let msg = e(format!("{truck}[model]\nvehicle = \"nominal\"\n"));
        assert!(msg.contains("field `model.vehicle`"), "{msg}");
        // overrides of a truck plant are its [truck] fields by name
        let Ok(s) = parse_any_in(
            &truck.replace(
                "\"truck-full\"",
                "\"truck-full\"\noverrides = { hps_v0_m3 = 0.02 }",
            ),
            "t",
            Path::new(""),
        )
        .unwrap()
        .into_spec::<TruckParams, { shimmy_core::vehicles::truck::N_STATES }>() else {
            panic!("a truck scenario")
        };
        assert_eq!(s.plant.model.hps.v0_m3, 0.02);
    }
}
