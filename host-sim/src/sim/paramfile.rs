//! Parameter sets from the command line: a named set (`nominal`, `gentle`, `hard`) or a TOML
//! file that starts from a named set and overrides fields by name:
//!
//! ```toml
//! base = "nominal"        # optional, default "nominal"
//! [overrides]
//! k_d = 5000.0            # N m/rad
//! c_a = 72000.0           # N/rad
//! ```
//!
//! A bad file is rejected with a message naming the field; nothing is half-applied.

use anyhow::{bail, Context, Result};
use serde::Deserialize;
use shimmy_core::params::{Param, ParamSet, PlantParams};
use std::collections::BTreeMap;
use std::path::Path;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ParamFile {
    base: Option<String>,
    #[serde(default)]
    overrides: BTreeMap<String, f64>,
}

/// Resolves `spec` (a set name or a path to a TOML file) to validated parameters.
pub fn load(spec: &str) -> Result<PlantParams> {
    if let Some(set) = ParamSet::from_name(spec) {
        return Ok(set.params());
    }
    let path = Path::new(spec);
    if !path.exists() {
        bail!(
            "unknown parameter set `{spec}`: use {} or a TOML file",
            set_names()
        );
    }
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {spec}"))?;
    parse(&text).with_context(|| format!("in parameter file {spec}"))
}

/// Parses the TOML text of a parameter file.
pub fn parse(text: &str) -> Result<PlantParams> {
    let file: ParamFile = toml::from_str(text)?;
    let base = file.base.as_deref().unwrap_or("nominal");
    let Some(set) = ParamSet::from_name(base) else {
        bail!(
            "field `base`: unknown set `{base}`, allowed: {}",
            set_names()
        );
    };
    let mut p = set.params();
    for (name, value) in &file.overrides {
        let Some(param) = Param::from_name(name) else {
            let allowed: Vec<&str> = Param::ALL.iter().map(|p| p.name()).collect();
            bail!(
                "field `overrides.{name}`: no such parameter, allowed: {}",
                allowed.join(", ")
            );
        };
        p = p.with(param, *value);
    }
    if let Err((param, value)) = p.validate() {
        bail!(
            "field `overrides.{}` = {value}: must be finite and {} ({})",
            param.name(),
            if value.is_finite() && value == 0.0 {
                "non-zero"
            } else {
                "positive"
            },
            param.unit()
        );
    }
    Ok(p)
}

fn set_names() -> String {
    ParamSet::ALL
        .iter()
        .map(|s| s.name())
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn named_sets_and_overrides() {
        assert_eq!(load("hard").unwrap(), ParamSet::Hard.params());
        let p = parse("base = \"gentle\"\n[overrides]\nk_d = 5000.0\n").unwrap();
        assert_eq!(p.k_d, 5000.0);
        assert_eq!(p.c_sw, 2.0);
    }

    #[test]
    fn bad_files_name_the_field() {
        let e = format!("{:#}", parse("[overrides]\nk_dd = 1.0\n").unwrap_err());
        assert!(e.contains("overrides.k_dd"), "{e}");
        let e = format!("{:#}", parse("[overrides]\nsigma = -0.6\n").unwrap_err());
        assert!(e.contains("overrides.sigma"), "{e}");
        let e = format!("{:#}", parse("base = \"soft\"\n").unwrap_err());
        assert!(e.contains("base"), "{e}");
        let e = format!("{:#}", parse("bsae = \"nominal\"\n").unwrap_err());
        assert!(e.contains("bsae"), "{e}");
        assert!(load("no-such-set").is_err());
    }
}
