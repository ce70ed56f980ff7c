//! `shimmy-sim params`: print and validate a vehicle (a set name or a vehicle file).

use crate::sim::vehicle_file;
use anyhow::Result;
use shimmy_core::vehicle::{FIELDS, SECTIONS};

/// Prints every field of the vehicle `spec`, section by section, with its unit and allowed range
/// (after validating it).
pub fn command(spec: &str) -> Result<()> {
    let v = vehicle_file::load(spec)?;
    println!("vehicle `{spec}` (valid)");
    for section in SECTIONS {
        println!("[{section}]");
        for f in FIELDS.iter().filter(|f| f.section == section) {
            println!(
                "  {:<22} = {:>14.6} {:<16} ({} ..= {})",
                f.name,
                v.get(f),
                f.unit,
                f.lo,
                f.hi
            );
        }
    }
    Ok(())
}
