//! `shimmy-sim params`: print and validate a vehicle (a set name or a vehicle file).

use crate::sim::vehicle_file::{self, ModelVehicle};
use anyhow::Result;
use shimmy_core::vehicle::{Vehicle, FIELDS, SECTIONS};
use shimmy_core::vehicles::truck::TRUCK_FIELDS;
use shimmy_core::vehicles::FieldTable;

/// Prints every field of the vehicle `spec`, section by section, with its unit and allowed range
/// (after validating it); a truck's `[truck]` section first, then the shared sections.
pub fn command(spec: &str) -> Result<()> {
    let v = vehicle_file::load_model(spec)?;
    println!("vehicle `{spec}` (valid, model {})", v.model_name());
    let (v, sections): (Vehicle, &[&str]) = match v {
        ModelVehicle::Car(v) => (v, &SECTIONS),
        ModelVehicle::Truck(t) => {
            println!("[truck]");
            for f in &TRUCK_FIELDS {
                println!(
                    "  {:<22} = {:>14.6} {:<16} ({} ..= {})",
                    f.name,
                    t.model.get(f.name).unwrap_or(f64::NAN),
                    f.unit,
                    f.range.0,
                    f.range.1
                );
            }
            (t.parts, &SECTIONS[1..])
        }
        ModelVehicle::DualAxle(t) => {
            println!("[dual_axle]");
            for f in &shimmy_core::vehicles::dual_axle::DUAL_AXLE_FIELDS {
                println!(
                    "  {:<22} = {:>14.6} {:<16} ({} ..= {})",
                    f.name,
                    t.model.get(f.name).unwrap_or(f64::NAN),
                    f.unit,
                    f.range.0,
                    f.range.1
                );
            }
            (t.parts, &SECTIONS[1..])
        }
        ModelVehicle::Trailer(t) => {
            println!("[trailer]");
            for f in &shimmy_core::vehicles::trailer::TRAILER_FIELDS {
                println!(
                    "  {:<22} = {:>14.6} {:<16} ({} ..= {})",
                    f.name,
                    t.get(f.name).unwrap_or(f64::NAN),
                    f.unit,
                    f.range.0,
                    f.range.1
                );
            }
            return Ok(());
        }
    };
    for section in sections {
        println!("[{section}]");
        for f in FIELDS.iter().filter(|f| f.section() == *section) {
            println!(
                "  {:<22} = {:>14.6} {:<16} ({} ..= {})",
                f.name,
                v.get(f),
                f.unit(),
                f.lo,
                f.hi
            );
        }
    }
    Ok(())
}
