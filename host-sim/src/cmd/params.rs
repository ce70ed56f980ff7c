//! `shimmy-sim params`: print and validate a parameter set (a name or a TOML file).

use crate::sim::paramfile;
use anyhow::Result;
use shimmy_core::params::Param;

/// Prints every parameter of the set `spec` with its unit (after validating it).
pub fn command(spec: &str) -> Result<()> {
    let p = paramfile::load(spec)?;
    println!("parameter set `{spec}` (valid)");
    for q in Param::ALL {
        println!("  {:<6} = {:>14.6} {}", q.name(), p.get(q), q.unit());
    }
    Ok(())
}
