//! `shimmy-sim params`: print and validate a vehicle (a set name or a vehicle file).

use crate::model::registry::{self, ModelVisitor, Registered};
use crate::sim::input::vehicle_file;
use anyhow::Result;
use shimmy_core::vehicle::{Vehicle, FIELDS, SECTIONS};

/// Prints every field of the vehicle `spec`, section by section, with its unit and allowed range
/// (after validating it); a truck's `[truck]` section first, then the shared sections.
pub fn command(spec: &str) -> Result<()> {
    let v = vehicle_file::load_model(spec)?;
    println!("vehicle `{spec}` (valid, model {})", v.model_name());
    struct Own;
    impl ModelVisitor for Own {
        type Output = Option<(Vehicle, &'static [&'static str])>;
        /// The model's own section (if its files have one), then its shared sections, if any.
        fn visit<M: Registered<N>, const N: usize>(self, f: M::File) -> Self::Output {
            let Some(section) = M::SECTION else {
                return M::parts_of(&f).map(|v| (*v, &SECTIONS[..]));
            };
            println!("[{section}]");
            let t = M::model_of(&f);
            for f in M::fields() {
                println!(
                    "  {:<22} = {:>14.6} {:<16} ({} ..= {})",
                    f.name,
                    t.field(f.name).unwrap_or(f64::NAN),
                    f.unit,
                    f.range.0,
                    f.range.1
                );
            }
            M::parts_of(&f).map(|v| (*v, &SECTIONS[1..]))
        }
    }
    let Some((v, sections)) = registry::with_model(v, Own) else {
        return Ok(());
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
