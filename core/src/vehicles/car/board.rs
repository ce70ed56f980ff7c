//! The car on the board: its stored record is the whole [`Vehicle`] (its plant is the model,
//! with the sections every model shares), and the board configures the car from it.

use crate::control::smc::NominalPlant;
use crate::vehicle::{
    decode_record, encode_record, record_schema_of, BoardVehicle, RecordError, RecordVehicle,
    Vehicle, VehicleError, FIELDS,
};

use super::PlantParams;

impl RecordVehicle for Vehicle {
    const MODEL: &'static str =
        <PlantParams as crate::model::LinearModel<{ crate::vehicles::car::N_STATES }>>::NAME;

    fn values() -> usize {
        FIELDS.len()
    }

    fn describe(i: usize) -> Option<(&'static str, &'static str, &'static str)> {
        FIELDS.get(i).map(|f| (f.section(), f.name, f.unit()))
    }

    fn record_base() -> Self {
        Vehicle::nominal()
    }

    fn read_value(&mut self, i: usize) -> f64 {
        FIELDS.get(i).map_or(f64::NAN, |f| (f.slot)(self).read())
    }

    fn write_value(&mut self, i: usize, x: f64) -> Result<(), VehicleError> {
        // The decoder writes only `i < values()`; nothing lies beyond.
        if let Some(field) = FIELDS.get(i) {
            field.check(x)?;
            (field.slot)(self).write(x);
        }
        Ok(())
    }

    fn check_all(&self) -> Result<(), VehicleError> {
        self.validate()
    }
}

/// The schema id of [`FIELDS`] (the car's record): FNV-1a over every field's section, name and
/// unit, in table order. A record written under another table (a field added, removed, renamed,
/// moved or given another unit, or another model's) carries another id and is refused instead
/// of misread.
pub fn record_schema() -> u32 {
    record_schema_of::<Vehicle>()
}

impl BoardVehicle<{ crate::vehicles::car::N_STATES }> for Vehicle {
    type Model = PlantParams;

    fn compiled_in() -> Self {
        Vehicle::nominal()
    }

    fn model(&self) -> PlantParams {
        self.plant
    }

    fn parts(&self) -> &Vehicle {
        self
    }

    fn nominal_plant(&self) -> NominalPlant {
        NominalPlant::from_params(&self.plant)
    }
}

impl Vehicle {
    /// Writes the vehicle as a car record ([`encode_record`]).
    pub fn encode_record(&self, out: &mut [u8]) -> Result<usize, RecordError> {
        encode_record(self, out)
    }

    /// Reads a car record ([`decode_record`]): the schema must be [`record_schema`].
    pub fn decode_record(bytes: &[u8]) -> Result<Vehicle, RecordError> {
        decode_record(bytes)
    }
}
