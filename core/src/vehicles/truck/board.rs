//! The mining truck as a stored vehicle: its model's parameters ([`TruckParams`], the `[truck]`
//! section of a vehicle file) and the sections every model shares (damper, damper model,
//! sensors, controller, thresholds: a [`Vehicle`] whose plant is not used), as one record of
//! its own model through the core's one record code ([`crate::vehicle::encode_record`],
//! [`crate::vehicle::decode_record`]). The record holds the truck's 32 fields, then every
//! shared field in the car record's order (the car's `plant` section left out).

use crate::estimator::monitor::MonitorParams;
use crate::estimator::pipeline::PipelineParams;
use crate::model::LinearModel;
use crate::vehicle::{BoardVehicle, Problem, RecordVehicle, Vehicle, VehicleError, FIELDS};
use crate::vehicles::car::Param;
use crate::vehicles::fields::{FieldError, FieldTable};
use crate::vehicles::truck::{
    HpsError, TruckFieldError, TruckParams, TruckSet, N_STATES, TRUCK_FIELDS,
};

/// The section of the truck's fields in a vehicle file and its record.
pub const TRUCK_SECTION: &str = "truck";

/// Fields of the car record's `plant` section, which lead [`FIELDS`] (a test checks it): the
/// truck's record leaves them out.
const PLANT_FIELDS: usize = Param::ALL.len();

/// A truck vehicle: the model's parameters and the shared sections.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TruckVehicle {
    /// The truck's linear model's parameters.
    pub truck: TruckParams,
    /// The damper, sensors, gains and thresholds (its `plant` is not part of the record).
    pub parts: Vehicle,
}

/// The factor on the car's reference damper that sizes the truck's: every force coefficient
/// of the damper and the skyhook coefficient times this ([`Vehicle::with_damper_scaled`]), so
/// that its energy-equivalent viscous coefficient at the rated current is the same multiple of
/// the least coefficient that closes the loaded truck's Hopf window as the car's is of the
/// `nominal` car's. The sizing takes a describing-function study that has no place in the
/// firmware, so the value is the simulator's result (`shimmy-sim`'s
/// `damper_sizing::damper_scale_like_the_cars` for `truck-full`, `docs/mining-truck.md`); a host test
/// recomputes it and fails when the two differ.
pub const TRUCK_DAMPER_SCALE: f64 = 34.15839289106305;

impl TruckVehicle {
    /// The truck's shared sections by default: the car's reference damper, sensors, gains and
    /// thresholds with the damper sized by [`TRUCK_DAMPER_SCALE`], the truck's own warning
    /// thresholds ([`TruckParams::warning_thresholds`]) and a stricter less-stable decision of
    /// the fusion (3 sigmas instead of the car's 2: the truck's lightly damped mode, zeta 0.009
    /// at 70 % of its onset, is read 1.5-2 sigmas low for 10-20 s at a time, which with 2 sigmas
    /// lowered the margin into a warning at plant = model; `shimmy-sim mismatch --vehicle
    /// truck-full`, `docs/mining-truck.md`). The coil, its rating and the sensors are the car's;
    /// the ASMC's gains are angular accelerations of the wheel, its force comes from the
    /// truck's nominal plant.
    pub fn default_parts() -> Vehicle {
        let mut v = Vehicle::nominal().with_damper_scaled(TRUCK_DAMPER_SCALE);
        v.thresholds = TruckParams::warning_thresholds();
        v.fusion.less_stable_sigmas = 3.0;
        v
    }

    /// The named truck set `set` with the default shared sections.
    pub fn of_set(set: TruckSet) -> Self {
        TruckVehicle {
            truck: set.params(),
            parts: Self::default_parts(),
        }
    }

    /// The shared fields of the record (the car record's fields after its plant section).
    fn shared() -> &'static [crate::vehicle::Field] {
        FIELDS.get(PLANT_FIELDS..).unwrap_or_default()
    }
}

/// The truck field's error in the vehicle's words (section `truck`, the field, its range).
fn truck_error(e: TruckFieldError, t: &TruckParams) -> VehicleError {
    match e {
        TruckFieldError::Field(FieldError::OutOfRange {
            name,
            value,
            lo,
            hi,
            unit,
        }) => VehicleError {
            section: TRUCK_SECTION,
            name,
            value,
            problem: Problem::OutOfRange { lo, hi, unit },
        },
        TruckFieldError::Strut(s) => VehicleError {
            section: TRUCK_SECTION,
            name: "hps_v0_m3",
            value: t.hps.v0_m3,
            problem: Problem::Inconsistent(match s {
                HpsError::ToppedOut { .. } => {
                    "the struts stay topped out: their load is below the pre-charge force \
                     (hps_p0_pa x hps_area_m2)"
                }
                HpsError::BottomedOut { .. } => {
                    "the struts bottom out: the static gas volume at this load is below the \
                     strut's minimum"
                }
            }),
        },
        // Only from a name that is not in the table; the record's names all are.
        TruckFieldError::Field(FieldError::Unknown) => VehicleError {
            section: TRUCK_SECTION,
            name: "?",
            value: f64::NAN,
            problem: Problem::Inconsistent("no such truck field"),
        },
    }
}

impl RecordVehicle for TruckVehicle {
    const MODEL: &'static str = <TruckParams as LinearModel<N_STATES>>::NAME;

    fn values() -> usize {
        TRUCK_FIELDS.len() + Self::shared().len()
    }

    fn describe(i: usize) -> Option<(&'static str, &'static str, &'static str)> {
        match TRUCK_FIELDS.get(i) {
            Some(f) => Some((TRUCK_SECTION, f.name, f.unit)),
            None => Self::shared()
                .get(i - TRUCK_FIELDS.len())
                .map(|f| (f.section(), f.name, f.unit())),
        }
    }

    /// The full truck with the truck's default shared sections (the decoder overwrites every
    /// recorded value; the rest, such as the fusion's less-stable threshold, are the truck's).
    fn record_base() -> Self {
        Self::of_set(TruckSet::Full)
    }

    fn read_value(&mut self, i: usize) -> f64 {
        match TRUCK_FIELDS.get(i) {
            Some(f) => self.truck.get(f.name).unwrap_or(f64::NAN),
            None => Self::shared()
                .get(i - TRUCK_FIELDS.len())
                .map_or(f64::NAN, |f| self.parts.get(f)),
        }
    }

    fn write_value(&mut self, i: usize, x: f64) -> Result<(), VehicleError> {
        match TRUCK_FIELDS.get(i) {
            Some(f) => self
                .truck
                .set(f.name, x)
                .map_err(|e| truck_error(e.into(), &self.truck)),
            None => match Self::shared().get(i - TRUCK_FIELDS.len()) {
                Some(f) => self.parts.set(f.section(), f.name, x).map_err(|e| match e {
                    crate::vehicle::SetError::Invalid(v) => v,
                    // The table's own names: always found.
                    crate::vehicle::SetError::UnknownField => VehicleError {
                        section: f.section(),
                        name: f.name,
                        value: x,
                        problem: Problem::Inconsistent("no such field"),
                    },
                }),
                None => Ok(()),
            },
        }
    }

    /// The truck's fields and struts ([`TruckParams::validate`]), then the shared sections'
    /// ranges and rules ([`Vehicle::validate`]).
    fn check_all(&self) -> Result<(), VehicleError> {
        self.truck
            .validate()
            .map_err(|e| truck_error(e, &self.truck))?;
        self.parts.validate()
    }
}

impl BoardVehicle<N_STATES> for TruckVehicle {
    type Model = TruckParams;

    /// The loaded truck (`truck-full`, the worst case of its Hopf window) with the default
    /// shared sections.
    fn compiled_in() -> Self {
        Self::of_set(TruckSet::Full)
    }

    fn model(&self) -> TruckParams {
        self.truck
    }

    fn parts(&self) -> &Vehicle {
        &self.parts
    }

    fn nominal_plant(&self) -> crate::control::smc::NominalPlant {
        self.truck.nominal_plant()
    }
}

/// The model whose record carries the schema id `schema`, if it is one of the family's stored
/// models (for messages: a host names what it got, the device keeps only its own decoder).
pub fn record_model(schema: u32) -> Option<&'static str> {
    [
        (
            crate::vehicle::record_schema_of::<Vehicle>(),
            Vehicle::MODEL,
        ),
        (
            crate::vehicle::record_schema_of::<TruckVehicle>(),
            TruckVehicle::MODEL,
        ),
    ]
    .into_iter()
    .find(|(s, _)| *s == schema)
    .map(|(_, m)| m)
}

impl TruckParams {
    /// The controller's nominal plant: the wheel assembly's yaw inertia I_k and kingpin
    /// damping c_k, and the steering arm l_t (the ASMC's model).
    pub fn nominal_plant(&self) -> crate::control::smc::NominalPlant {
        crate::control::smc::NominalPlant {
            i_k_kgm2: self.i_k as f32,
            c_k_nms_per_rad: self.c_k as f32,
            l_t_m: self.l_t as f32,
        }
    }

    /// The truck vehicle's warning thresholds by default (its `[thresholds]` section): the
    /// car's ([`PipelineParams::tuned_monitor`]) with the data path's MarginLow damping
    /// thresholds lowered for the truck's lightly damped mode (zeta 0.0098 at 70 % of the
    /// loaded truck's onset, where the car's `zeta_low_on` 0.005 flickers: 24-42 false
    /// warnings per hour on the data-only arm, 0 with these) and the speed-margin thresholds
    /// lowered (the truck's 70 % point is only 7 km/h from its onset), chosen by `shimmy-sim
    /// mismatch --vehicle truck-full` (`docs/mining-truck.md`, "Warning thresholds").
    pub fn warning_thresholds() -> MonitorParams {
        MonitorParams {
            zeta_low_on: -0.005,
            zeta_low_off: 0.005,
            dv_low_on_mps: 1.2,
            dv_low_off_mps: 1.4,
            dv_crit_on_mps: 0.6,
            dv_crit_off_mps: 0.9,
            ..PipelineParams::tuned_monitor()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vehicle::{
        decode_record, encode_record, record_index, record_schema_of, RecordError,
        RECORD_HEADER_BYTES, RECORD_MAX_BYTES, RECORD_MAX_FIELDS,
    };
    use crate::vehicles::car::board::record_schema;

    fn truck() -> TruckVehicle {
        let mut t = TruckVehicle::of_set(TruckSet::Empty);
        t.truck.set("hps_v0_m3", 0.0145).unwrap();
        t.truck.set("payload_kg", 100_000.0).unwrap();
        t.parts.set("damper", "rated_current_a", 3.0).unwrap();
        t.parts.set("thresholds", "zeta_low_on", 0.001).unwrap();
        t
    }

    #[test]
    fn the_record_is_the_trucks_fields_then_every_shared_one() {
        assert!(FIELDS[..PLANT_FIELDS]
            .iter()
            .all(|f| f.section() == "plant"));
        assert!(FIELDS[PLANT_FIELDS..]
            .iter()
            .all(|f| f.section() != "plant"));
        assert_eq!(TruckVehicle::values(), RECORD_MAX_FIELDS);
        assert!(Vehicle::values() <= RECORD_MAX_FIELDS);
        assert_eq!(TruckVehicle::describe(0), Some(("truck", "i_k", "kg m^2")));
        assert_eq!(
            TruckVehicle::describe(TRUCK_FIELDS.len()),
            Some(("damper", "rated_current_a", "A"))
        );
        assert_eq!(TruckVehicle::describe(TruckVehicle::values()), None);
    }

    #[test]
    fn a_truck_record_round_trips_every_value() {
        let t = truck();
        assert!(t.check_all().is_ok());
        let mut buf = [0u8; RECORD_MAX_BYTES];
        let n = encode_record(&t, &mut buf).unwrap();
        assert_eq!(n, RECORD_MAX_BYTES);
        let back: TruckVehicle = decode_record(&buf[..n]).unwrap();
        let (mut a, mut b) = (t, back);
        for i in 0..TruckVehicle::values() {
            assert_eq!(
                a.read_value(i).to_bits(),
                b.read_value(i).to_bits(),
                "{:?}",
                TruckVehicle::describe(i)
            );
        }
        assert_eq!(back, t);
        assert_ne!(back.truck, TruckSet::Full.params());
    }

    /// Each model's decoder refuses the other's record for its schema id, and the id names the
    /// model it came from.
    #[test]
    fn a_record_of_the_other_model_is_refused_and_named() {
        let car_schema = record_schema();
        let truck_schema = record_schema_of::<TruckVehicle>();
        assert_ne!(car_schema, truck_schema);
        assert_eq!(record_model(car_schema), Some("car-4dof"));
        assert_eq!(record_model(truck_schema), Some("mining-truck-5dof"));
        assert_eq!(record_model(car_schema ^ 1), None);

        let mut buf = [0u8; RECORD_MAX_BYTES];
        let n = encode_record(&truck(), &mut buf).unwrap();
        assert_eq!(
            Vehicle::decode_record(&buf[..n]),
            Err(RecordError::Schema {
                found: truck_schema,
                expected: car_schema
            })
        );
        let n = Vehicle::nominal().encode_record(&mut buf).unwrap();
        assert_eq!(
            decode_record::<TruckVehicle>(&buf[..n]),
            Err(RecordError::Schema {
                found: car_schema,
                expected: truck_schema
            })
        );
    }

    /// A truck value out of its range, a strut that cannot carry its load and a broken rule of
    /// the shared sections are refused naming the field.
    #[test]
    fn a_bad_truck_record_names_the_field() {
        let mut buf = [0u8; RECORD_MAX_BYTES];
        let n = encode_record(&truck(), &mut buf).unwrap();
        let at = |i: usize| RECORD_HEADER_BYTES + 8 * i;
        let with = |i: usize, x: f64| {
            let mut b = buf;
            b[at(i)..at(i) + 8].copy_from_slice(&x.to_le_bytes());
            decode_record::<TruckVehicle>(&b[..n])
        };
        let v0 = TRUCK_FIELDS
            .iter()
            .position(|f| f.name == "hps_v0_m3")
            .unwrap();
        match with(v0, 5.0) {
            Err(RecordError::Invalid(e)) => {
                assert_eq!(e.path(), ("truck", "hps_v0_m3"));
                assert!(matches!(e.problem, Problem::OutOfRange { hi: 0.2, .. }));
            }
            other => panic!("{other:?}"),
        }
        // in range, but a pre-charge the empty-ish truck's load cannot compress: topped out
        let p0 = TRUCK_FIELDS
            .iter()
            .position(|f| f.name == "hps_p0_pa")
            .unwrap();
        match with(p0, 4.9e7) {
            Err(RecordError::Invalid(e)) => {
                assert_eq!(e.path(), ("truck", "hps_v0_m3"));
                assert!(matches!(e.problem, Problem::Inconsistent(r) if r.contains("topped out")));
            }
            other => panic!("{other:?}"),
        }
        // the shared hysteresis rule: zeta_low_off below zeta_low_on
        let off = record_index::<TruckVehicle>("thresholds", "zeta_low_off").unwrap();
        match with(off, 0.0) {
            Err(RecordError::Invalid(e)) => {
                assert_eq!(e.path(), ("thresholds", "zeta_low_off"));
                assert!(matches!(e.problem, Problem::Inconsistent(_)));
            }
            other => panic!("{other:?}"),
        }
    }
}
