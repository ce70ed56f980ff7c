//! One vehicle: everything that differs from one car (or truck) to the next, in one value that
//! the simulator reads from a TOML file and the firmware can later read from flash.
//!
//! A [`Vehicle`] holds the plant parameters, the MR damper (the simulator's Spencer model of it,
//! the firmware's invertible model of it, the coil rating and resistance), the sensors'
//! calibration, the controller's gains and the warning thresholds. The controller's, the
//! supervisor's and the estimator's parameters are derived from it
//! ([`Vehicle::control_params`], [`Vehicle::supervisor_params`], [`Vehicle::pipeline_params`]),
//! never from a hidden default; [`Vehicle::nominal`] reproduces today's defaults exactly (a
//! test compares them).
//!
//! Every scalar is described once in [`FIELDS`]: section, name, unit, plausible range and a line
//! of documentation. Setting a field by name ([`Vehicle::set`]) and validating a whole vehicle
//! ([`Vehicle::validate`]) both go through that table, so a file, a flash image and a
//! hand-built value are held to the same ranges. Errors ([`VehicleError`]) name the field, the
//! value and the allowed range. No heap, no panics.

use crate::control::actuator::{CoilParams, CurrentLimits};
use crate::control::conditioning::ConditioningParams;
use crate::control::mr_model::MrModel;
use crate::control::schedule::ScheduleParams;
use crate::control::smc::{AsmcParams, NominalPlant, SmcParams};
use crate::control::ControlParams;
use crate::estimator::fusion::FusionParams;
use crate::estimator::monitor::MonitorParams;
use crate::estimator::pipeline::PipelineParams;
use crate::model::LinearModel;
use crate::mr_damper::SpencerParams;
use crate::supervisor::params::SupervisorParams;
use crate::vehicles::car::{Param, ParamSet, PlantParams};

/// The MR damper of the vehicle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DamperSpec {
    /// The physical damper as the simulator models it (Spencer modified Bouc-Wen); `u_max` is
    /// the coil rating, A.
    pub spencer: SpencerParams,
    /// What the firmware believes about the damper (the invertible Bingham model); its
    /// `i_max_a` is the same coil rating.
    pub model: MrModel,
    /// The coil and its driver.
    pub coil: CoilParams,
}

/// Calibration and quality of the sensors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorCalibration {
    /// Wheel-yaw encoder resolution, bits.
    pub encoder_bits: u8,
    /// Encoder noise, standard deviation in LSB.
    pub encoder_noise_lsb: f32,
    /// Wheel-speed scale error of the calibrated tone wheel / rolling radius: measured speed =
    /// (1 + this) true speed.
    pub speed_scale_error: f32,
    /// Full scale of the coil-current measurement, A.
    pub current_full_scale_a: f32,
}

impl SensorCalibration {
    /// The reference board: a 14-bit AS5047P with 0.5 LSB rms noise, an exact speed
    /// calibration, a 2.5 A current channel.
    pub const DEFAULT: Self = SensorCalibration {
        encoder_bits: 14,
        encoder_noise_lsb: 0.5,
        speed_scale_error: 0.0,
        current_full_scale_a: 2.5,
    };
}

impl Default for SensorCalibration {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// The controller's gains (the law's structure and the conditioning chain are fixed).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ControllerGains {
    /// Sliding surface and fixed-gain SMC.
    pub smc: SmcParams,
    /// Adaptation law of the ASMC.
    pub asmc: AsmcParams,
    /// Skyhook coefficient, N s/m.
    pub skyhook_ns_per_m: f32,
    /// Slew limit of the coil command, A/s.
    pub slew_a_per_s: f32,
    /// Speed gate: below it the damper gets the minimum current, m/s.
    pub min_speed_mps: f32,
    /// Margin schedule and quiet coil of the margin-scheduled ASMC.
    pub schedule: ScheduleParams,
}

impl ControllerGains {
    /// The gains of [`ControlParams::DEFAULT`].
    pub const DEFAULT: Self = {
        let c = ControlParams::DEFAULT;
        ControllerGains {
            smc: c.smc,
            asmc: c.asmc,
            skyhook_ns_per_m: c.skyhook_ns_per_m,
            slew_a_per_s: c.limits.slew_a_per_s,
            min_speed_mps: c.min_speed_mps,
            schedule: c.schedule,
        }
    };
}

impl Default for ControllerGains {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Everything vehicle-specific, in one value (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Vehicle {
    /// The steering plant.
    pub plant: PlantParams,
    /// The MR damper.
    pub damper: DamperSpec,
    /// The sensors.
    pub sensors: SensorCalibration,
    /// The controller's gains.
    pub controller: ControllerGains,
    /// The warning thresholds of the margin monitor.
    pub thresholds: MonitorParams,
    /// The fusion of data and model margins (its disagreement threshold is a vehicle field).
    pub fusion: FusionParams,
}

impl Default for Vehicle {
    fn default() -> Self {
        Self::nominal()
    }
}

impl Vehicle {
    /// The reference car: the nominal plant with today's damper, sensors, gains and thresholds.
    // Not inlined: the caller copies the constant (560 B of flash); inlined into the
    // firmware's init its fields were folded into the code that follows (+1.3 KB).
    #[inline(never)]
    pub fn nominal() -> Self {
        Self::NOMINAL
    }

    /// [`Self::nominal`] as a constant: the image copies it from flash (560 B) where code that
    /// stored it field by field took 918 B (`cargo xtask size`).
    pub const NOMINAL: Self = Self::with_plant(PlantParams::nominal());

    /// This vehicle with every force coefficient of its damper (the Spencer model's and the
    /// firmware's Bingham model's) and its skyhook coefficient times `s`: a damper sized for a
    /// heavier model with the same coil (a larger piston and gap, not another coil).
    pub fn with_damper_scaled(mut self, s: f64) -> Self {
        let sp = &mut self.damper.spencer;
        for c in [
            &mut sp.c0a,
            &mut sp.c0b,
            &mut sp.k0,
            &mut sp.c1a,
            &mut sp.c1b,
            &mut sp.k1,
            &mut sp.alpha_a,
            &mut sp.alpha_b,
        ] {
            *c *= s;
        }
        let m = &mut self.damper.model;
        for c in [
            &mut m.f_ca_n,
            &mut m.f_cb_n_per_a,
            &mut m.c_a_ns_per_m,
            &mut m.c_b_ns_per_m_a,
        ] {
            *c *= s as f32;
        }
        self.controller.skyhook_ns_per_m *= s as f32;
        self
    }

    /// A named plant set with the reference damper, sensors, gains and thresholds.
    pub fn from_set(set: ParamSet) -> Self {
        Self::with_plant(set.params())
    }

    /// `plant` with the reference damper, sensors, gains and thresholds.
    pub const fn with_plant(plant: PlantParams) -> Self {
        Vehicle {
            plant,
            damper: DamperSpec {
                spencer: SpencerParams::steering(),
                model: MrModel::FITTED,
                coil: CoilParams::DEFAULT,
            },
            sensors: SensorCalibration::DEFAULT,
            controller: ControllerGains::DEFAULT,
            thresholds: PipelineParams::tuned_monitor(),
            fusion: PipelineParams::tuned_fusion(),
        }
    }

    /// The coil rating, A (the largest current the controller commands and the damper takes).
    pub fn rated_current_a(&self) -> f32 {
        self.damper.model.i_max_a
    }

    /// The controller's parameters: its plant model (I_k, c_k, l_t) from [`Self::plant`], its
    /// damper model and limits from [`Self::damper`], its gains from [`Self::controller`]. The
    /// fail-safe current is the coil rating (the largest damping the damper gives; see
    /// [`crate::control::actuator::FAILSAFE_CURRENT_A`]).
    pub fn control_params(&self) -> ControlParams {
        let rated = self.rated_current_a();
        ControlParams {
            conditioning: ConditioningParams::default(),
            nominal: NominalPlant::from_params(&self.plant),
            mr: self.damper.model,
            smc: self.controller.smc,
            asmc: self.controller.asmc,
            schedule: self.controller.schedule,
            skyhook_ns_per_m: self.controller.skyhook_ns_per_m,
            limits: CurrentLimits {
                i_min_a: 0.0,
                i_max_a: rated,
                slew_a_per_s: self.controller.slew_a_per_s,
            },
            fallback_current_a: rated,
            min_speed_mps: self.controller.min_speed_mps,
            psi_limit_rad: ControlParams::default().psi_limit_rad,
        }
    }

    /// The supervisor's thresholds with this vehicle's coil and speed gate: the fail-safe
    /// current is the coil rating, the expected coil current lags the command by the coil's
    /// time constant 1/eta (`damper.eta`), a coil-current reading at the measurement's full
    /// scale counts as saturated, a low speed must have been reached plausibly below the
    /// controller's speed gate (`controller.min_speed_mps`), and the encoders' noise
    /// (`sensors.encoder_noise_lsb`) says whether a healthy encoder dithers.
    pub fn supervisor_params(&self) -> SupervisorParams {
        SupervisorParams {
            failsafe_current_a: self.rated_current_a(),
            coil_tau_s: (1.0 / self.damper.spencer.eta) as f32,
            coil_full_scale_a: self.sensors.current_full_scale_a,
            speed_low_mps: self.controller.min_speed_mps,
            encoder_noise_lsb: self.sensors.encoder_noise_lsb,
            ..SupervisorParams::default()
        }
    }

    /// The supervisor's thresholds ([`Self::supervisor_params`]) on the model `model`: the
    /// shimmy band of the motion evidence scaled to the model's mode
    /// ([`LinearModel::meter_time_scale`], as the mode meter is; 1 for the car).
    pub fn supervisor_params_for<M: LinearModel<N>, const N: usize>(
        &self,
        model: &M,
    ) -> SupervisorParams {
        self.supervisor_params()
            .time_scaled(model.meter_time_scale())
    }

    /// The margin pipeline's parameters with this vehicle's warning thresholds (its model is
    /// [`Self::plant`], passed to the pipeline next to these).
    pub fn pipeline_params(&self) -> PipelineParams {
        PipelineParams {
            monitor: self.thresholds,
            fusion: self.fusion,
            ..PipelineParams::default()
        }
    }

    /// The controller's parameters ([`Self::control_params`]) with the nominal plant
    /// `nominal` of another model (this vehicle's shared sections on that model).
    pub fn control_params_with(&self, nominal: NominalPlant) -> ControlParams {
        ControlParams {
            nominal,
            ..self.control_params()
        }
    }

    /// The margin pipeline's parameters ([`Self::pipeline_params`]) on the model `model`: the
    /// mode meter slowed to its shimmy mode ([`LinearModel::meter_time_scale`]; 1 for the car,
    /// which leaves every value as it is).
    pub fn pipeline_params_for<M: LinearModel<N>, const N: usize>(
        &self,
        model: &M,
    ) -> PipelineParams {
        let pp = self.pipeline_params();
        PipelineParams {
            estimator: pp.estimator.time_scaled(model.meter_time_scale()),
            ..pp
        }
    }

    /// Sets the field `section.name` to `value` after checking it against the field's range.
    pub fn set(&mut self, section: &str, name: &str, value: f64) -> Result<(), SetError> {
        let field = find_field(section, name).ok_or(SetError::UnknownField)?;
        field.check(value).map_err(SetError::Invalid)?;
        (field.slot)(self).write(value);
        Ok(())
    }

    /// The value of `field` (read through a copy: the table has one accessor per field, which
    /// needs `&mut`; [`Vehicle::validate`] and [`Vehicle::encode_record`] copy once for all).
    pub fn get(&self, field: &Field) -> f64 {
        let mut v = *self;
        (field.slot)(&mut v).read()
    }

    /// Checks every field against its range, then the rules that tie fields together
    /// (hysteresis order of the thresholds, K_min <= K_init <= K_max, one coil rating).
    /// Returns the first offender.
    pub fn validate(&self) -> Result<(), VehicleError> {
        let mut v = *self;
        for field in FIELDS {
            field.check((field.slot)(&mut v).read())?;
        }
        match RULES.iter().find(|r| !(r.holds)(self)) {
            Some(rule) => Err(VehicleError {
                section: rule.section,
                name: rule.name,
                value: (rule.value)(self),
                problem: Problem::Inconsistent(rule.rule),
            }),
            None => Ok(()),
        }
    }
}

/// The sections of a vehicle file, in order.
pub const SECTIONS: [&str; 6] = [
    "plant",
    "damper",
    "damper_model",
    "sensors",
    "controller",
    "thresholds",
];

/// The units of the vehicle fields (`-` for none), in no particular order: a field names its
/// unit by its index here ([`Field::unit`]).
pub const UNITS: [&str; 26] = [
    "-",
    "1/m^2",
    "1/s",
    "A",
    "A/s",
    "Hz",
    "LSB",
    "N",
    "N s/(m A)",
    "N s/m",
    "N/(m A)",
    "N/A",
    "N/m",
    "Ohm",
    "bit",
    "m",
    "m/s",
    "rad",
    "rad/s",
    "rad/s^2",
    "rad/s^2 per rad",
    "s",
    "N m s/rad",
    "N m/rad",
    "N/rad",
    "kg m^2",
];

/// The index of `name` in `table`, `None` when it is not there.
const fn index_in(table: &[&str], name: &str) -> Option<u8> {
    let mut i = 0;
    while i < table.len() {
        if same_str(table[i], name) {
            return Some(i as u8);
        }
        i += 1;
    }
    None
}

/// The index of `$name` in `$table`, evaluated while the program is built (the field table's
/// initialiser): a section or unit missing from its table stops the build there, and no
/// panic is left in the code that runs.
macro_rules! id_in {
    ($table:expr, $name:expr) => {
        const {
            match index_in(&$table, $name) {
                Some(i) => i,
                None => {
                    panic!("a vehicle field's section or unit is missing from SECTIONS or UNITS")
                }
            }
        }
    };
}

/// `a == b` in a constant.
const fn same_str(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    if a.len() != b.len() {
        return false;
    }
    let mut k = 0;
    while k < a.len() && a[k] == b[k] {
        k += 1;
    }
    k == a.len()
}

/// One scalar of a [`Vehicle`]: where it lives, its unit, its plausible range and what it is.
#[derive(Clone, Copy, Debug)]
pub struct Field {
    /// Section of the vehicle file: its index in [`SECTIONS`] ([`Field::section`]). An index
    /// and not a `&str`, like the unit's: 16 B less per field, ~1.4 KB of the firmware image's
    /// table (`cargo xtask size`).
    section_id: u8,
    /// Field name inside the section.
    pub name: &'static str,
    /// SI unit: its index in [`UNITS`] ([`Field::unit`]).
    unit_id: u8,
    /// Smallest allowed value (included).
    pub lo: f64,
    /// Largest allowed value (included).
    pub hi: f64,
    /// Only whole numbers are allowed.
    pub integer: bool,
    /// One line on what it is (only with the `field-docs` feature: the host tools print it; the
    /// firmware image checks names and ranges without ~4 KB of descriptions).
    #[cfg(feature = "field-docs")]
    pub doc: &'static str,
    /// Where the value lives in a vehicle: one accessor per field, not a getter and a setter
    /// (those were ~3.2 KB of the firmware image for 87 fields; `cargo xtask size`).
    pub(crate) slot: fn(&mut Vehicle) -> Slot<'_>,
}

/// Where a field's value is kept, and its type.
pub(crate) enum Slot<'a> {
    F64(&'a mut f64),
    F32(&'a mut f32),
    /// Whole numbers (the range check runs before a write).
    U8(&'a mut u8),
    /// The coil rating: the Spencer model's u_max and the firmware model's i_max_a together.
    Rating(&'a mut DamperSpec),
}

impl Slot<'_> {
    pub(crate) fn read(&self) -> f64 {
        match self {
            Slot::F64(x) => **x,
            Slot::F32(x) => f64::from(**x),
            Slot::U8(x) => f64::from(**x),
            Slot::Rating(d) => d.spencer.u_max,
        }
    }

    pub(crate) fn write(self, x: f64) {
        match self {
            Slot::F64(p) => *p = x,
            Slot::F32(p) => *p = x as f32,
            // Only written after the range check (whole numbers within u8).
            Slot::U8(p) => *p = x as u8,
            Slot::Rating(d) => {
                d.spencer.u_max = x;
                d.model.i_max_a = x as f32;
            }
        }
    }
}

impl Field {
    /// Section of the vehicle file (one of [`SECTIONS`]).
    pub fn section(&self) -> &'static str {
        SECTIONS[usize::from(self.section_id)]
    }

    /// SI unit (`-` for none; one of [`UNITS`]).
    pub fn unit(&self) -> &'static str {
        UNITS[usize::from(self.unit_id)]
    }

    /// `value` is finite, inside `[lo, hi]` and whole if it must be.
    pub fn check(&self, value: f64) -> Result<(), VehicleError> {
        let problem = if !(self.lo..=self.hi).contains(&value) {
            Problem::OutOfRange {
                lo: self.lo,
                hi: self.hi,
                unit: self.unit(),
            }
        } else if self.integer && value != libm::round(value) {
            Problem::NotInteger {
                lo: self.lo,
                hi: self.hi,
            }
        } else {
            return Ok(());
        };
        Err(VehicleError {
            section: self.section(),
            name: self.name,
            value,
            problem,
        })
    }
}

/// What is wrong with a field.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Problem {
    /// Outside the field's range `[lo, hi]` (or not finite).
    OutOfRange {
        /// Smallest allowed value.
        lo: f64,
        /// Largest allowed value.
        hi: f64,
        /// Unit of the field.
        unit: &'static str,
    },
    /// Not a whole number in `[lo, hi]`.
    NotInteger {
        /// Smallest allowed value.
        lo: f64,
        /// Largest allowed value.
        hi: f64,
    },
    /// Inside its range but in conflict with another field; the rule that is broken.
    Inconsistent(&'static str),
}

/// A field that fails validation, with its value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VehicleError {
    /// Section of the offending field.
    pub section: &'static str,
    /// Name of the offending field.
    pub name: &'static str,
    /// Its value.
    pub value: f64,
    /// What is wrong.
    pub problem: Problem,
}

impl VehicleError {
    /// `(section, name)` of the offending field.
    pub fn path(&self) -> (&'static str, &'static str) {
        (self.section, self.name)
    }
}

impl core::fmt::Display for VehicleError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "field `{}.{}` = {}: ",
            self.section, self.name, self.value
        )?;
        match self.problem {
            Problem::OutOfRange { lo, hi, unit } => {
                write!(f, "out of range; allowed: {lo} <= value <= {hi} {unit}")
            }
            Problem::NotInteger { lo, hi } => {
                write!(f, "must be a whole number, {lo} <= value <= {hi}")
            }
            Problem::Inconsistent(rule) => write!(f, "{rule}"),
        }
    }
}

impl core::error::Error for VehicleError {}

/// Why [`Vehicle::set`] refused a value.
#[derive(Clone, Copy, Debug, thiserror::Error)]
pub enum SetError {
    /// No field of that name in that section.
    #[error("no such field")]
    UnknownField,
    /// The value fails the field's check.
    #[error("{0}")]
    Invalid(VehicleError),
}

/// The field `section.name`, if there is one.
pub fn find_field(section: &str, name: &str) -> Option<&'static Field> {
    FIELDS
        .iter()
        // the name first: it tells the fields apart nearly always, so the costlier section
        // lookup is paid about once per call
        .find(|f| f.name == name && f.section() == section)
}

/// A rule between fields, reported against the field `section.name` (whose value is `value`).
struct Rule {
    section: &'static str,
    name: &'static str,
    rule: &'static str,
    value: fn(&Vehicle) -> f64,
    holds: fn(&Vehicle) -> bool,
}

const RULES: &[Rule] = &[
    Rule {
        section: "damper",
        name: "rated_current_a",
        rule: "the firmware model's current limit (damper.model.i_max_a) must be the coil rating \
               (the Spencer model's u_max)",
        value: |v| v.damper.spencer.u_max,
        holds: |v| v.damper.model.i_max_a == v.damper.spencer.u_max as f32,
    },
    Rule {
        section: "controller",
        name: "k_init_radps2",
        rule: "must lie between k_min_radps2 and k_max_radps2",
        value: |v| f64::from(v.controller.asmc.k_init_radps2),
        holds: |v| {
            let a = &v.controller.asmc;
            a.k_min_radps2 <= a.k_init_radps2 && a.k_init_radps2 <= a.k_max_radps2
        },
    },
    Rule {
        section: "controller",
        name: "idle_margin_mps",
        rule: "must not be below arm_margin_mps",
        value: |v| f64::from(v.controller.schedule.idle_margin_mps),
        holds: |v| v.controller.schedule.idle_margin_mps >= v.controller.schedule.arm_margin_mps,
    },
    Rule {
        section: "controller",
        name: "idle_ttc_s",
        rule: "must not be below arm_ttc_s",
        value: |v| f64::from(v.controller.schedule.idle_ttc_s),
        holds: |v| v.controller.schedule.idle_ttc_s >= v.controller.schedule.arm_ttc_s,
    },
    Rule {
        section: "controller",
        name: "idle_zeta",
        rule: "must not be below arm_zeta",
        value: |v| f64::from(v.controller.schedule.idle_zeta),
        holds: |v| v.controller.schedule.idle_zeta >= v.controller.schedule.arm_zeta,
    },
    Rule {
        section: "controller",
        name: "idle_engage_rad",
        rule: "must not be below armed_engage_rad (arming engages the coil earlier)",
        value: |v| f64::from(v.controller.schedule.idle_engage_rad),
        holds: |v| v.controller.schedule.idle_engage_rad >= v.controller.schedule.armed_engage_rad,
    },
    Rule {
        section: "controller",
        name: "base_current_a",
        rule: "must not exceed the coil rating damper.rated_current_a",
        value: |v| f64::from(v.controller.schedule.base_current_a),
        holds: |v| v.controller.schedule.base_current_a <= v.damper.model.i_max_a,
    },
    Rule {
        section: "thresholds",
        name: "zeta_low_off",
        value: |v| f64::from(v.thresholds.zeta_low_off),
        rule: "must not be below zeta_low_on (hysteresis)",
        holds: |v| v.thresholds.zeta_low_off >= v.thresholds.zeta_low_on,
    },
    Rule {
        section: "thresholds",
        name: "dv_low_off_mps",
        value: |v| f64::from(v.thresholds.dv_low_off_mps),
        rule: "must not be below dv_low_on_mps (hysteresis)",
        holds: |v| v.thresholds.dv_low_off_mps >= v.thresholds.dv_low_on_mps,
    },
    Rule {
        section: "thresholds",
        name: "zeta_crit_off",
        value: |v| f64::from(v.thresholds.zeta_crit_off),
        rule: "must not be below zeta_crit_on (hysteresis)",
        holds: |v| v.thresholds.zeta_crit_off >= v.thresholds.zeta_crit_on,
    },
    Rule {
        section: "thresholds",
        name: "dv_crit_off_mps",
        value: |v| f64::from(v.thresholds.dv_crit_off_mps),
        rule: "must not be below dv_crit_on_mps (hysteresis)",
        holds: |v| v.thresholds.dv_crit_off_mps >= v.thresholds.dv_crit_on_mps,
    },
    Rule {
        section: "thresholds",
        name: "ttc_off_s",
        value: |v| f64::from(v.thresholds.ttc_off_s),
        rule: "must not be below ttc_on_s (hysteresis)",
        holds: |v| v.thresholds.ttc_off_s >= v.thresholds.ttc_on_s,
    },
    Rule {
        section: "thresholds",
        name: "amp_off_rad",
        value: |v| f64::from(v.thresholds.amp_off_rad),
        rule: "must not be above amp_on_rad (hysteresis)",
        holds: |v| v.thresholds.amp_off_rad <= v.thresholds.amp_on_rad,
    },
];

/// The [`Slot`] of a stored scalar.
trait Place {
    fn slot(&mut self) -> Slot<'_>;
}

impl Place for f64 {
    fn slot(&mut self) -> Slot<'_> {
        Slot::F64(self)
    }
}

impl Place for f32 {
    fn slot(&mut self) -> Slot<'_> {
        Slot::F32(self)
    }
}

impl Place for u8 {
    fn slot(&mut self) -> Slot<'_> {
        Slot::U8(self)
    }
}

macro_rules! plant_field {
    ($p:ident, $doc:literal) => {
        Field {
            section_id: id_in!(SECTIONS, "plant"),
            name: Param::$p.name(),
            unit_id: id_in!(UNITS, Param::$p.unit()),
            lo: Param::$p.range().0,
            hi: Param::$p.range().1,
            integer: false,
            #[cfg(feature = "field-docs")]
            doc: $doc,
            slot: |v| Slot::F64(v.plant.field_mut(Param::$p)),
        }
    };
}

macro_rules! field {
    ($section:literal, $name:literal, $unit:literal, $lo:expr, $hi:expr, $doc:literal,
     |$v:ident| $place:expr) => {
        field!(@ $section, $name, $unit, $lo, $hi, false, $doc, |$v| $place)
    };
    (int $section:literal, $name:literal, $unit:literal, $lo:expr, $hi:expr, $doc:literal,
     |$v:ident| $place:expr) => {
        field!(@ $section, $name, $unit, $lo, $hi, true, $doc, |$v| $place)
    };
    (@ $section:literal, $name:literal, $unit:literal, $lo:expr, $hi:expr, $int:expr,
     $doc:literal, |$v:ident| $place:expr) => {
        Field {
            section_id: id_in!(SECTIONS, $section),
            name: $name,
            unit_id: id_in!(UNITS, $unit),
            lo: $lo,
            hi: $hi,
            integer: $int,
            #[cfg(feature = "field-docs")]
            doc: $doc,
            slot: |$v| Place::slot(&mut $place),
        }
    };
}

/// Every scalar of a [`Vehicle`], section by section (the one source of the vehicle file's
/// fields, their units, ranges and documentation; `docs/vehicle-file.md` is checked against it).
pub static FIELDS: &[Field] = &[
    plant_field!(IK, "wheel-assembly yaw inertia about the kingpin I_k"),
    plant_field!(IP, "wheel spin inertia I_p (gyroscopic coupling)"),
    plant_field!(R, "rolling radius R"),
    plant_field!(HR, "roll-centre height h_r"),
    plant_field!(IPhi, "axle roll inertia I_phi"),
    plant_field!(KPhi, "tramp (roll) stiffness K_phi"),
    plant_field!(CPhi, "tramp damping c_phi"),
    plant_field!(CA, "cornering stiffness per tyre C_a"),
    plant_field!(Sigma, "tyre relaxation length sigma"),
    plant_field!(E, "caster (mechanical) trail e"),
    plant_field!(TP, "pneumatic trail t_p"),
    plant_field!(LT, "steering-arm length l_t (damper stroke per wheel yaw)"),
    plant_field!(KTr, "track-rod stiffness referred to the kingpin K_tr"),
    plant_field!(KD, "drag link + gear stiffness at the kingpin K_d"),
    plant_field!(IS, "overall steering ratio i_s"),
    plant_field!(JSw, "steering-wheel inertia J_sw"),
    plant_field!(CSw, "steering-wheel damping c_sw"),
    plant_field!(CK, "kingpin damping c_k"),
    plant_field!(FZ, "static load per front wheel F_z"),
    plant_field!(
        Mu,
        "tyre-road friction coefficient mu (Magic Formula peak D = mu F_z)"
    ),
    plant_field!(CS, "Magic-Formula shape factor C_s"),
    // The physical damper (Spencer modified Bouc-Wen, `mr_damper`).
    Field {
        section_id: id_in!(SECTIONS, "damper"),
        name: "rated_current_a",
        unit_id: id_in!(UNITS, "A"),
        lo: 0.1,
        hi: 10.0,
        integer: false,
        #[cfg(feature = "field-docs")]
        doc: "coil rating: the Spencer model's u_max, the firmware model's and the controller's \
              current limit and the fail-safe current",
        slot: |v| Slot::Rating(&mut v.damper),
    },
    field!(
        "damper",
        "coil_resistance_ohm",
        "Ohm",
        0.1,
        100.0,
        "coil resistance (coil energy, PWM duty)",
        |v| v.damper.coil.r_coil_ohm
    ),
    field!(
        "damper",
        "c0a",
        "N s/m",
        0.0,
        1.0e5,
        "viscous coefficient c0 at 0 A",
        |v| v.damper.spencer.c0a
    ),
    field!(
        "damper",
        "c0b",
        "N s/(m A)",
        0.0,
        1.0e5,
        "c0 per ampere",
        |v| v.damper.spencer.c0b
    ),
    field!(
        "damper",
        "k0",
        "N/m",
        0.0,
        1.0e6,
        "internal stiffness k0",
        |v| v.damper.spencer.k0
    ),
    field!(
        "damper",
        "c1a",
        "N s/m",
        1.0,
        1.0e6,
        "viscous coefficient c1 at 0 A",
        |v| v.damper.spencer.c1a
    ),
    field!(
        "damper",
        "c1b",
        "N s/(m A)",
        0.0,
        1.0e6,
        "c1 per ampere",
        |v| v.damper.spencer.c1b
    ),
    field!(
        "damper",
        "k1",
        "N/m",
        0.0,
        1.0e5,
        "accumulator stiffness k1",
        |v| v.damper.spencer.k1
    ),
    field!(
        "damper",
        "x0",
        "m",
        -0.1,
        0.1,
        "accumulator initial displacement x0",
        |v| v.damper.spencer.x0
    ),
    field!(
        "damper",
        "alpha_a",
        "N/m",
        0.0,
        1.0e6,
        "Bouc-Wen coefficient alpha at 0 A",
        |v| v.damper.spencer.alpha_a
    ),
    field!(
        "damper",
        "alpha_b",
        "N/(m A)",
        0.0,
        1.0e6,
        "alpha per ampere",
        |v| v.damper.spencer.alpha_b
    ),
    field!(
        "damper",
        "gamma",
        "1/m^2",
        0.0,
        1.0e8,
        "hysteresis shape gamma",
        |v| v.damper.spencer.gamma
    ),
    field!(
        "damper",
        "beta",
        "1/m^2",
        0.0,
        1.0e8,
        "hysteresis shape beta",
        |v| v.damper.spencer.beta
    ),
    field!(
        "damper",
        "a_bw",
        "-",
        0.0,
        1.0e4,
        "hysteresis scale A",
        |v| v.damper.spencer.a_bw
    ),
    field!("damper", "n", "-", 1.0, 4.0, "hysteresis exponent n", |v| v
        .damper
        .spencer
        .n),
    field!(
        "damper",
        "eta",
        "1/s",
        1.0,
        1.0e4,
        "coil + driver bandwidth eta (1/eta: the supervisor's coil time constant)",
        |v| v.damper.spencer.eta
    ),
    // What the firmware believes about the damper (`control::mr_model`).
    field!(
        "damper_model",
        "f_ca_n",
        "N",
        0.0,
        1.0e4,
        "yield force at 0 A",
        |v| v.damper.model.f_ca_n
    ),
    field!(
        "damper_model",
        "f_cb_n_per_a",
        "N/A",
        0.0,
        1.0e5,
        "yield force per ampere",
        |v| v.damper.model.f_cb_n_per_a
    ),
    field!(
        "damper_model",
        "c_a_ns_per_m",
        "N s/m",
        0.0,
        1.0e5,
        "viscous coefficient at 0 A",
        |v| v.damper.model.c_a_ns_per_m
    ),
    field!(
        "damper_model",
        "c_b_ns_per_m_a",
        "N s/(m A)",
        1.0,
        1.0e5,
        "viscous coefficient per ampere",
        |v| v.damper.model.c_b_ns_per_m_a
    ),
    field!(
        "damper_model",
        "v0_mps",
        "m/s",
        1.0e-4,
        1.0,
        "smoothing velocity of the yield force",
        |v| v.damper.model.v0_mps
    ),
    // Sensors.
    field!(int "sensors", "encoder_bits", "bit", 8.0, 20.0, "wheel-yaw encoder resolution",
        |v| v.sensors.encoder_bits),
    field!(
        "sensors",
        "encoder_noise_lsb",
        "LSB",
        0.0,
        10.0,
        "encoder noise (standard deviation)",
        |v| v.sensors.encoder_noise_lsb
    ),
    field!(
        "sensors",
        "speed_scale_error",
        "-",
        -0.2,
        0.2,
        "wheel-speed calibration error: measured = (1 + this) true speed",
        |v| v.sensors.speed_scale_error
    ),
    field!(
        "sensors",
        "current_full_scale_a",
        "A",
        0.5,
        20.0,
        "full scale of the coil-current measurement",
        |v| v.sensors.current_full_scale_a
    ),
    // Controller gains.
    field!(
        "controller",
        "lambda_per_s",
        "1/s",
        0.1,
        100.0,
        "sliding-surface slope lambda",
        |v| v.controller.smc.lambda_per_s
    ),
    field!(
        "controller",
        "phi_radps",
        "rad/s",
        1.0e-3,
        10.0,
        "boundary-layer half width phi",
        |v| v.controller.smc.phi_radps
    ),
    field!(
        "controller",
        "k_radps2",
        "rad/s^2",
        0.0,
        1.0e3,
        "fixed switching gain K of the SMC",
        |v| v.controller.smc.k_radps2
    ),
    field!(
        "controller",
        "gamma",
        "rad/s^2 per rad",
        0.0,
        1.0e5,
        "ASMC adaptation rate gamma",
        |v| v.controller.asmc.gamma
    ),
    field!(
        "controller",
        "sigma_per_s",
        "1/s",
        0.0,
        100.0,
        "ASMC leakage sigma",
        |v| v.controller.asmc.sigma_per_s
    ),
    field!(
        "controller",
        "dead_zone_radps",
        "rad/s",
        0.0,
        10.0,
        "ASMC dead zone on the sliding variable s",
        |v| v.controller.asmc.dead_zone_radps
    ),
    field!(
        "controller",
        "k_min_radps2",
        "rad/s^2",
        0.0,
        1.0e3,
        "ASMC lower gain bound",
        |v| v.controller.asmc.k_min_radps2
    ),
    field!(
        "controller",
        "k_max_radps2",
        "rad/s^2",
        0.0,
        1.0e3,
        "ASMC upper gain bound",
        |v| v.controller.asmc.k_max_radps2
    ),
    field!(
        "controller",
        "k_init_radps2",
        "rad/s^2",
        0.0,
        1.0e3,
        "ASMC gain at start-up",
        |v| v.controller.asmc.k_init_radps2
    ),
    field!(
        "controller",
        "skyhook_ns_per_m",
        "N s/m",
        0.0,
        1.0e5,
        "skyhook coefficient",
        |v| v.controller.skyhook_ns_per_m
    ),
    field!(
        "controller",
        "slew_a_per_s",
        "A/s",
        1.0,
        1.0e6,
        "slew limit of the coil command",
        |v| v.controller.slew_a_per_s
    ),
    field!(
        "controller",
        "min_speed_mps",
        "m/s",
        0.0,
        30.0,
        "speed gate: minimum current below this speed (and the supervisor's low-speed plausibility limit)",
        |v| v.controller.min_speed_mps
    ),
    field!(
        "controller",
        "arm_margin_mps",
        "m/s",
        0.0,
        50.0,
        "margin schedule: speed margin at and below which the damper is fully armed",
        |v| v.controller.schedule.arm_margin_mps
    ),
    field!(
        "controller",
        "idle_margin_mps",
        "m/s",
        0.0,
        50.0,
        "margin schedule: speed margin at and above which it idles",
        |v| v.controller.schedule.idle_margin_mps
    ),
    field!(
        "controller",
        "arm_ttc_s",
        "s",
        0.0,
        600.0,
        "margin schedule: time to critical speed at and below which it is fully armed",
        |v| v.controller.schedule.arm_ttc_s
    ),
    field!(
        "controller",
        "idle_ttc_s",
        "s",
        0.0,
        600.0,
        "margin schedule: time to critical speed at and above which that term idles",
        |v| v.controller.schedule.idle_ttc_s
    ),
    field!(
        "controller",
        "arm_zeta",
        "-",
        -0.5,
        0.5,
        "margin schedule: fast data damping at and below which it is fully armed (growth)",
        |v| v.controller.schedule.arm_zeta
    ),
    field!(
        "controller",
        "idle_zeta",
        "-",
        -0.5,
        0.5,
        "margin schedule: fast data damping at and above which that term idles",
        |v| v.controller.schedule.idle_zeta
    ),
    field!(
        "controller",
        "base_current_a",
        "A",
        0.0,
        20.0,
        "margin schedule: base current while the coil is engaged and fully armed (at most the coil rating)",
        |v| v.controller.schedule.base_current_a
    ),
    field!(
        "controller",
        "armed_phi_radps",
        "rad/s",
        1.0e-3,
        10.0,
        "margin schedule: ASMC boundary layer when fully armed (idle: phi_radps)",
        |v| v.controller.schedule.armed_phi_radps
    ),
    field!(
        "controller",
        "armed_engage_rad",
        "rad",
        0.0,
        0.1,
        "quiet coil: shimmy-band amplitude that engages the coil when fully armed",
        |v| v.controller.schedule.armed_engage_rad
    ),
    field!(
        "controller",
        "idle_engage_rad",
        "rad",
        0.0,
        0.1,
        "quiet coil: shimmy-band amplitude that engages the coil when idle",
        |v| v.controller.schedule.idle_engage_rad
    ),
    field!(
        "controller",
        "noise_factor",
        "-",
        0.0,
        100.0,
        "quiet coil: the engage amplitude is at least this many times the road-noise floor",
        |v| v.controller.schedule.noise_factor
    ),
    field!(
        "controller",
        "noise_tau_s",
        "s",
        0.0,
        100.0,
        "quiet coil: time constant of the road-noise floor (0: no floor)",
        |v| v.controller.schedule.noise_tau_s
    ),
    field!(
        "controller",
        "hold_s",
        "s",
        0.0,
        10.0,
        "quiet coil: stays engaged this long after the amplitude fell below half the engage amplitude",
        |v| v.controller.schedule.hold_s
    ),
    field!(
        "controller",
        "release_s",
        "s",
        0.0,
        10.0,
        "quiet coil: release time constant of the command envelope",
        |v| v.controller.schedule.release_s
    ),
    field!(
        "controller",
        "band_hz",
        "Hz",
        0.5,
        50.0,
        "quiet coil: frequency that turns the shimmy-band rate into an amplitude (the shimmy mode's)",
        |v| v.controller.schedule.band_hz
    ),
    // Warning thresholds of the margin monitor.
    field!(
        "thresholds",
        "zeta_low_on",
        "-",
        -0.5,
        0.5,
        "MarginLow when slow data zeta < this",
        |v| v.thresholds.zeta_low_on
    ),
    field!(
        "thresholds",
        "zeta_low_off",
        "-",
        -0.5,
        0.5,
        "... cleared above this",
        |v| v.thresholds.zeta_low_off
    ),
    field!(
        "thresholds",
        "dv_low_on_mps",
        "m/s",
        0.0,
        30.0,
        "MarginLow when speed margin < this",
        |v| v.thresholds.dv_low_on_mps
    ),
    field!(
        "thresholds",
        "dv_low_off_mps",
        "m/s",
        0.0,
        30.0,
        "... cleared above this",
        |v| v.thresholds.dv_low_off_mps
    ),
    field!(
        "thresholds",
        "zeta_crit_on",
        "-",
        -0.5,
        0.5,
        "ApproachingCritical when fast data zeta < this",
        |v| v.thresholds.zeta_crit_on
    ),
    field!(
        "thresholds",
        "zeta_crit_off",
        "-",
        -0.5,
        0.5,
        "... cleared above this",
        |v| v.thresholds.zeta_crit_off
    ),
    field!(
        "thresholds",
        "dv_crit_on_mps",
        "m/s",
        0.0,
        30.0,
        "ApproachingCritical when speed margin < this",
        |v| v.thresholds.dv_crit_on_mps
    ),
    field!(
        "thresholds",
        "dv_crit_off_mps",
        "m/s",
        0.0,
        30.0,
        "... cleared above this",
        |v| v.thresholds.dv_crit_off_mps
    ),
    field!(
        "thresholds",
        "ttc_on_s",
        "s",
        0.0,
        600.0,
        "ApproachingCritical when time to critical < this",
        |v| v.thresholds.ttc_on_s
    ),
    field!(
        "thresholds",
        "ttc_off_s",
        "s",
        0.0,
        600.0,
        "... cleared above this",
        |v| v.thresholds.ttc_off_s
    ),
    field!(
        "thresholds",
        "amp_on_rad",
        "rad",
        0.0,
        0.5,
        "ShimmyPresent when amplitude > this",
        |v| v.thresholds.amp_on_rad
    ),
    field!(
        "thresholds",
        "amp_off_rad",
        "rad",
        0.0,
        0.5,
        "... cleared below this",
        |v| v.thresholds.amp_off_rad
    ),
    field!(
        "thresholds",
        "release_s",
        "s",
        0.0,
        60.0,
        "dwell before a level is released",
        |v| v.thresholds.release_s
    ),
    field!(
        "thresholds",
        "mismatch_sigmas",
        "-",
        1.0,
        10.0,
        "data and model disagree beyond this many reported sigmas (the model's margin is \
         then corrected by the measured damping offset)",
        |v| v.fusion.mismatch_sigmas
    ),
];

/// Bytes before the values in an encoded vehicle record: the schema id (u32) and the number of
/// values (u16), little-endian.
pub const RECORD_HEADER_BYTES: usize = 6;
/// The most values a record of any model may carry (the truck's 98, its 32 model fields and the
/// 66 shared ones, is the largest; a test checks every model).
pub const RECORD_MAX_FIELDS: usize = 98;
/// The largest encoded record, bytes: what a flash store or a link frame must make room for.
pub const RECORD_MAX_BYTES: usize = RECORD_HEADER_BYTES + 8 * RECORD_MAX_FIELDS;

/// A vehicle of one model as a stored record holds it: its values in a fixed order, each with a
/// section, name and unit, under the model's schema id. The car ([`Vehicle`]) and the mining
/// truck ([`crate::vehicles::truck::board::TruckVehicle`]: its model's parameters and the shared
/// sections) are records of their own model; one encoder and decoder ([`encode_record`],
/// [`decode_record`]) serves every model, so a record of one model is refused by another
/// model's decoder (another schema id) instead of misread.
pub trait RecordVehicle: Copy {
    /// The vehicle model's name (`LinearModel::NAME`: `car-4dof`, `mining-truck-5dof`).
    const MODEL: &'static str;
    /// Number of values in the record.
    fn values() -> usize;
    /// `(section, name, unit)` of value `i`, for `i < values()`.
    fn describe(i: usize) -> Option<(&'static str, &'static str, &'static str)>;
    /// The vehicle a decoded record starts from (every recorded value is written over it).
    fn record_base() -> Self;
    /// Value `i` (`&mut`: the car's table has one accessor per field; the encoder copies once).
    fn read_value(&mut self, i: usize) -> f64;
    /// Checks value `i` against its field's range, then writes it.
    fn write_value(&mut self, i: usize, x: f64) -> Result<(), VehicleError>;
    /// Every value in range and every rule between them; the first offender.
    fn check_all(&self) -> Result<(), VehicleError>;
}

/// The schema id of the model `V`'s record (FNV-1a over each value's section, name and unit).
pub fn record_schema_of<V: RecordVehicle>() -> u32 {
    schema_of((0..V::values()).filter_map(V::describe))
}

/// The index of the field `section.name` in the model `V`'s record, if it has one.
pub fn record_index<V: RecordVehicle>(section: &str, name: &str) -> Option<usize> {
    (0..V::values()).find(|&i| V::describe(i).is_some_and(|(s, n, _)| s == section && n == name))
}

/// The value `value` of the field `section.name` of the model `V`'s record checked against
/// that field's range (the error names the field and its range); `None` when `V`'s record has
/// no such field. For messages about a record the other side refused.
pub fn check_record_value<V: RecordVehicle>(
    section: &str,
    name: &str,
    value: f64,
) -> Option<Result<(), VehicleError>> {
    let i = record_index::<V>(section, name)?;
    Some(V::record_base().write_value(i, value))
}

/// FNV-1a over the section, name and unit of each of `fields`, in order.
fn schema_of<'a>(fields: impl IntoIterator<Item = (&'a str, &'a str, &'a str)>) -> u32 {
    let mut hash: u32 = 0x811c_9dc5;
    for (section, name, unit) in fields {
        for part in [section, name, unit] {
            // A separator after each part, so "ab"+"c" and "a"+"bc" differ.
            for byte in part.bytes().chain(core::iter::once(0)) {
                hash = (hash ^ u32::from(byte)).wrapping_mul(0x0100_0193);
            }
        }
    }
    hash
}

/// Why a vehicle record could not be written or read.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum RecordError {
    /// The output buffer is shorter than the record.
    #[error("buffer of {have} bytes is too small for a {need}-byte vehicle record")]
    BufferTooSmall {
        /// Bytes the record needs.
        need: usize,
        /// Bytes the buffer has.
        have: usize,
    },
    /// The record's length does not match its header.
    #[error("vehicle record is {have} bytes, its header says {need}")]
    Length {
        /// Bytes the header announces.
        need: usize,
        /// Bytes present.
        have: usize,
    },
    /// Written under another field table (another model's, or another version's).
    #[error("vehicle record schema {found:#010x} is not this firmware's {expected:#010x}")]
    Schema {
        /// The record's schema id ([`crate::vehicles::truck::board::record_model`] names its model, if known).
        found: u32,
        /// The decoder's model's ([`record_schema_of`]).
        expected: u32,
    },
    /// A value fails its field's range or a rule between fields.
    #[error("vehicle record rejected: {0}")]
    Invalid(VehicleError),
}

/// Writes `v` as a record of its model (header, then every value as a little-endian f64) into
/// `out`; returns the number of bytes written. The record is the form a flash store keeps and a
/// host link carries; [`decode_record`] reads it.
pub fn encode_record<V: RecordVehicle>(v: &V, out: &mut [u8]) -> Result<usize, RecordError> {
    let count = V::values();
    let need = RECORD_HEADER_BYTES + 8 * count;
    let have = out.len();
    let Some(record) = out.get_mut(..need) else {
        return Err(RecordError::BufferTooSmall { need, have });
    };
    let (header, values) = record.split_at_mut(RECORD_HEADER_BYTES);
    let (schema, n) = header.split_at_mut(4);
    schema.copy_from_slice(&record_schema_of::<V>().to_le_bytes());
    // values() <= RECORD_MAX_FIELDS (a test), so the count fits a u16.
    n.copy_from_slice(&(count as u16).to_le_bytes());
    let mut v = *v;
    for (i, chunk) in values.as_chunks_mut::<8>().0.iter_mut().enumerate() {
        chunk.copy_from_slice(&v.read_value(i).to_le_bytes());
    }
    Ok(need)
}

/// Reads a record written by [`encode_record`] for the model `V`: the schema must be `V`'s,
/// the length must match, and the vehicle must pass `V`'s checks. Nothing is half-applied: an
/// error returns no vehicle at all.
pub fn decode_record<V: RecordVehicle>(bytes: &[u8]) -> Result<V, RecordError> {
    let have = bytes.len();
    let header_error = RecordError::Length {
        need: RECORD_HEADER_BYTES,
        have,
    };
    let (Some(schema), Some(count)) = (bytes.get(..4), bytes.get(4..RECORD_HEADER_BYTES)) else {
        return Err(header_error);
    };
    let (Ok(schema), Ok(count)) = (<[u8; 4]>::try_from(schema), <[u8; 2]>::try_from(count)) else {
        return Err(header_error);
    };
    let found = u32::from_le_bytes(schema);
    let expected = record_schema_of::<V>();
    if found != expected {
        return Err(RecordError::Schema { found, expected });
    }
    let count = usize::from(u16::from_le_bytes(count));
    let need = RECORD_HEADER_BYTES + 8 * count;
    if count != V::values() || have != need {
        return Err(RecordError::Length { need, have });
    }
    let mut vehicle = V::record_base();
    let values = bytes.get(RECORD_HEADER_BYTES..).unwrap_or_default();
    for (i, chunk) in values.as_chunks::<8>().0.iter().enumerate() {
        vehicle
            .write_value(i, f64::from_le_bytes(*chunk))
            .map_err(RecordError::Invalid)?;
    }
    vehicle.check_all().map_err(RecordError::Invalid)?;
    Ok(vehicle)
}

/// A stored vehicle of one model as a board image is configured from it: the model's linear
/// parameters (the model-margin tracker's model) and the sections every model shares (damper,
/// sensors, gains, thresholds). The car ([`Vehicle`], its plant is the model) and the mining
/// truck ([`crate::vehicles::truck::board::TruckVehicle`]) are members; an image is built for one.
pub trait BoardVehicle<const N: usize>: RecordVehicle + PartialEq {
    /// The vehicle model's linear model.
    type Model: LinearModel<N> + Copy;
    /// The compiled-in vehicle of the model: what a board boots with when no valid record is
    /// stored.
    fn compiled_in() -> Self;
    /// The model's parameters.
    fn model(&self) -> Self::Model;
    /// The shared sections (for a model other than the car its `plant` is not used).
    fn parts(&self) -> &Vehicle;
    /// The controller's nominal plant (I_k, c_k, l_t: the ASMC's model) of [`Self::model`].
    fn nominal_plant(&self) -> NominalPlant;

    /// The controller's parameters: the shared sections' with the model's nominal plant
    /// ([`Vehicle::control_params_with`]).
    fn controller_params(&self) -> ControlParams {
        self.parts().control_params_with(self.nominal_plant())
    }

    /// The supervisor's thresholds for the model ([`Vehicle::supervisor_params_for`]).
    fn supervisor_params(&self) -> SupervisorParams {
        self.parts().supervisor_params_for(&self.model())
    }

    /// The margin pipeline's parameters for the model ([`Vehicle::pipeline_params_for`]).
    fn margin_pipeline(&self) -> PipelineParams {
        self.parts().pipeline_params_for(&self.model())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_nominal_vehicle_reproduces_todays_defaults() {
        let v = Vehicle::nominal();
        assert_eq!(v.control_params(), ControlParams::default());
        assert_eq!(v.pipeline_params(), PipelineParams::default());
        assert_eq!(v.supervisor_params(), SupervisorParams::default());
        assert_eq!(v.damper.spencer, SpencerParams::steering());
        assert!(v.validate().is_ok());
        for set in ParamSet::ALL {
            assert!(Vehicle::from_set(set).validate().is_ok(), "{}", set.name());
        }
    }

    #[test]
    fn the_controller_model_follows_the_vehicle() {
        let mut v = Vehicle::nominal();
        v.set("plant", "l_t", 0.3).unwrap();
        v.set("plant", "i_k", 9.0).unwrap();
        v.set("damper", "rated_current_a", 3.0).unwrap();
        let c = v.control_params();
        assert_eq!(c.nominal.l_t_m, 0.3);
        assert_eq!(c.nominal.i_k_kgm2, 9.0);
        assert_eq!(
            (c.mr.i_max_a, c.limits.i_max_a, c.fallback_current_a),
            (3.0, 3.0, 3.0)
        );
        assert_eq!(v.supervisor_params().failsafe_current_a, 3.0);
        assert_eq!(v.damper.spencer.u_max, 3.0);
        // The supervisor's low-speed plausibility check sits at the controller's speed gate.
        assert_eq!(
            v.supervisor_params().speed_low_mps,
            SupervisorParams::default().speed_low_mps
        );
        v.set("controller", "min_speed_mps", 5.0).unwrap();
        assert_eq!(v.control_params().min_speed_mps, 5.0);
        assert_eq!(v.supervisor_params().speed_low_mps, 5.0);
        // The coil checks' expected current lags by the vehicle's coil time constant.
        assert_eq!(
            Vehicle::nominal().supervisor_params().coil_tau_s,
            SupervisorParams::default().coil_tau_s
        );
        v.set("damper", "eta", 50.0).unwrap();
        assert_eq!(v.supervisor_params().coil_tau_s, 0.02);
        assert!(v.validate().is_ok());
    }

    #[test]
    fn sections_and_units_are_looked_up_in_their_tables() {
        assert_eq!(index_in(&SECTIONS, "thresholds"), Some(5));
        assert_eq!(
            index_in(&UNITS, "N s/(m A)").map(|i| UNITS[usize::from(i)]),
            Some("N s/(m A)")
        );
        // every unit of the table is some field's (no dead entry), and only once
        for (i, u) in UNITS.iter().enumerate() {
            assert!(FIELDS.iter().any(|f| f.unit() == *u), "unused unit {u}");
            assert!(!UNITS[..i].contains(u), "{u} twice");
        }
    }

    #[test]
    fn a_unit_outside_the_table_is_not_found() {
        // in the field table's initialiser (`id_in!`) this stops the build
        assert_eq!(index_in(&UNITS, "furlong"), None);
        assert_eq!(index_in(&UNITS, "N s"), None); // a prefix of an entry is not it
    }

    #[test]
    fn every_field_round_trips_and_the_table_has_no_duplicates() {
        for (i, f) in FIELDS.iter().enumerate() {
            assert!(SECTIONS.contains(&f.section()), "{}", f.name);
            assert!(f.lo <= f.hi, "{}", f.name);
            assert!(FIELDS[..i]
                .iter()
                .all(|g| (g.section(), g.name) != (f.section(), f.name)));
            let mut v = Vehicle::nominal();
            let x = if f.integer { f.hi } else { 0.5 * (f.lo + f.hi) };
            v.set(f.section(), f.name, x).unwrap();
            assert!((v.get(f) - x).abs() <= 1e-6 * x.abs(), "{}", f.name);
        }
        // Every plant parameter is in the table once.
        for p in Param::ALL {
            assert!(find_field("plant", p.name()).is_some(), "{}", p.name());
        }
    }

    #[test]
    fn bad_values_name_the_field_value_and_range() {
        let mut v = Vehicle::nominal();
        let Err(SetError::Invalid(e)) = v.set("plant", "mu", 1000.0) else {
            panic!("mu = 1000 accepted")
        };
        assert_eq!(e.path(), ("plant", "mu"));
        assert!(matches!(
            e.problem,
            Problem::OutOfRange {
                lo: 0.05,
                hi: 1.5,
                ..
            }
        ));
        assert!(matches!(
            v.set("plant", "f_z", 1e12),
            Err(SetError::Invalid(_))
        ));
        assert!(matches!(
            v.set("plant", "f_z", f64::NAN),
            Err(SetError::Invalid(_))
        ));
        assert!(matches!(
            v.set("plant", "mud", 1.0),
            Err(SetError::UnknownField)
        ));
        let Err(SetError::Invalid(e)) = v.set("sensors", "encoder_bits", 12.5) else {
            panic!("12.5 bits accepted")
        };
        assert!(matches!(e.problem, Problem::NotInteger { .. }));
        // Nothing was half-applied.
        assert_eq!(v, Vehicle::nominal());
        // A value built by hand (e.g. read from flash) is held to the same table.
        let mut w = Vehicle::nominal();
        w.plant.mu = 1000.0;
        assert_eq!(w.validate().unwrap_err().path(), ("plant", "mu"));
    }

    #[test]
    fn rules_between_fields_are_checked() {
        let mut v = Vehicle::nominal();
        v.set("thresholds", "dv_low_off_mps", 1.0).unwrap();
        let e = v.validate().unwrap_err();
        assert_eq!(e.path(), ("thresholds", "dv_low_off_mps"));
        assert!(matches!(e.problem, Problem::Inconsistent(_)));
        let mut w = Vehicle::nominal();
        w.damper.model.i_max_a = 1.0;
        assert_eq!(
            w.validate().unwrap_err().path(),
            ("damper", "rated_current_a")
        );
        let mut k = Vehicle::nominal();
        k.set("controller", "k_init_radps2", 40.0).unwrap();
        assert_eq!(
            k.validate().unwrap_err().path(),
            ("controller", "k_init_radps2")
        );
    }

    #[test]
    fn a_record_round_trips_every_field_and_fits_its_bound() {
        assert!(FIELDS.len() <= RECORD_MAX_FIELDS);
        let mut original = Vehicle::from_set(ParamSet::Hard);
        original.set("controller", "slew_a_per_s", 123.0).unwrap();
        let mut buf = [0u8; RECORD_MAX_BYTES];
        let n = original.encode_record(&mut buf).unwrap();
        assert_eq!(n, RECORD_HEADER_BYTES + 8 * FIELDS.len());
        let back = Vehicle::decode_record(&buf[..n]).unwrap();
        for field in FIELDS {
            assert_eq!(
                back.get(field).to_bits(),
                original.get(field).to_bits(),
                "{}.{}",
                field.section(),
                field.name
            );
        }
        assert_ne!(back, Vehicle::nominal());
    }

    #[test]
    fn a_bad_record_is_refused_whole_and_names_what_is_wrong() {
        let mut buf = [0u8; RECORD_MAX_BYTES];
        let n = Vehicle::nominal().encode_record(&mut buf).unwrap();
        assert!(matches!(
            Vehicle::nominal().encode_record(&mut buf[..n - 1]),
            Err(RecordError::BufferTooSmall { .. })
        ));
        assert!(matches!(
            Vehicle::decode_record(&buf[..n - 1]),
            Err(RecordError::Length { .. })
        ));
        assert!(matches!(
            Vehicle::decode_record(&buf[..3]),
            Err(RecordError::Length { .. })
        ));
        let mut other_schema = buf;
        other_schema[0] ^= 1;
        assert!(matches!(
            Vehicle::decode_record(&other_schema[..n]),
            Err(RecordError::Schema { .. })
        ));
        // The first field (plant.i_k) set far out of its range: refused, naming the field.
        let mut out_of_range = buf;
        out_of_range[RECORD_HEADER_BYTES..RECORD_HEADER_BYTES + 8]
            .copy_from_slice(&1.0e9f64.to_le_bytes());
        match Vehicle::decode_record(&out_of_range[..n]) {
            Err(RecordError::Invalid(e)) => {
                assert_eq!(e.path(), (FIELDS[0].section(), FIELDS[0].name))
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn the_schema_id_changes_with_the_table() {
        // The same table with its first two fields swapped.
        let mut table: Vec<_> = FIELDS
            .iter()
            .map(|f| (f.section(), f.name, f.unit()))
            .collect();
        assert_eq!(
            schema_of(table.iter().copied()),
            record_schema_of::<Vehicle>()
        );
        table.swap(0, 1);
        assert_ne!(
            schema_of(table.iter().copied()),
            record_schema_of::<Vehicle>()
        );
    }
}
