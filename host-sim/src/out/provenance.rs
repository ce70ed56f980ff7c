//! Where a report comes from, so a reviewer can reproduce it: the tool's version and git
//! describe at build time (`build.rs`; it says so when the build had no git), the command line,
//! the SHA-256 of every input file (vehicle file, log, mapping, scenario files) and of the
//! resolved vehicle's byte record, and the seeds. Written as a Markdown table into every report
//! and as an object into its JSON summary.

use crate::model::registry::{self, ModelVisitor, Registered};
use crate::sim::input::vehicle_file::ModelVehicle;
use anyhow::{Context, Result};
use serde_json::{json, Value};
use sha2::{Digest, Sha256};
use shimmy_core::vehicle::{Vehicle, RECORD_MAX_BYTES};
use std::path::Path;

/// The build's `git describe --always --dirty --tags` (or why there is none).
pub const GIT: &str = env!("SHIMMY_GIT");

/// One input of a run.
#[derive(Clone, Debug, PartialEq)]
pub struct Input {
    /// What it is (e.g. `vehicle`, `log`).
    pub role: String,
    /// Its file (or the built-in set's name).
    pub source: String,
    /// SHA-256 of its content, hex.
    pub sha256: String,
}

/// The provenance of one report.
#[derive(Clone, Debug, PartialEq)]
pub struct Provenance {
    /// `shimmy-sim <version>`.
    pub tool: String,
    /// [`GIT`].
    pub git: String,
    /// The command line as typed (arguments with spaces quoted).
    pub command_line: String,
    /// Input files and vehicles.
    pub inputs: Vec<Input>,
    /// Named seeds.
    pub seeds: Vec<(String, u64)>,
}

/// SHA-256 of `bytes`, lower-case hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// SHA-256 of a vehicle's byte record (the same bytes the flash store and host link carry).
pub fn vehicle_record_sha256(v: &Vehicle) -> Result<String> {
    let mut buf = [0u8; RECORD_MAX_BYTES];
    let n = v.encode_record(&mut buf).context("vehicle record")?;
    Ok(sha256_hex(buf.get(..n).unwrap_or(&buf)))
}

fn quote(arg: &str) -> String {
    if !arg.is_empty()
        && arg
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c))
    {
        arg.to_string()
    } else {
        format!("'{}'", arg.replace('\'', r"'\''"))
    }
}

impl Provenance {
    /// The provenance of a command given `args` (program name first).
    pub fn new<I: IntoIterator<Item = String>>(args: I) -> Self {
        let args: Vec<String> = args.into_iter().collect();
        Self {
            tool: format!("shimmy-sim {}", env!("CARGO_PKG_VERSION")),
            git: GIT.to_string(),
            command_line: args.iter().map(|a| quote(a)).collect::<Vec<_>>().join(" "),
            inputs: Vec::new(),
            seeds: Vec::new(),
        }
    }

    /// The provenance of this process's command line.
    pub fn of_this_process() -> Self {
        Self::new(std::env::args())
    }

    /// Adds a file input (its content hashed).
    pub fn file(mut self, role: &str, path: &Path) -> Result<Self> {
        let bytes =
            crate::sim::input::files::read_bytes(path, crate::sim::input::files::DATA_LIMIT)?;
        self.inputs.push(Input {
            role: role.to_string(),
            source: path.display().to_string(),
            sha256: sha256_hex(&bytes),
        });
        Ok(self)
    }

    /// Adds a vehicle given as on the command line (`spec`: a set name or a file) and resolved
    /// to `v`: the file's content hash (for a file) and the record hash of what was used.
    pub fn vehicle(mut self, role: &str, spec: &str, v: &Vehicle) -> Result<Self> {
        if registry::model_of_set(spec).is_none() {
            self = self.file(&format!("{role} file"), Path::new(spec))?;
        }
        self.inputs.push(Input {
            role: format!("{role} record"),
            source: if registry::model_of_set(spec).is_some() {
                format!("built-in set `{spec}`")
            } else {
                format!("resolved from {spec}")
            },
            sha256: vehicle_record_sha256(v)?,
        });
        Ok(self)
    }

    /// [`Self::vehicle`] for a vehicle of any model: another model's record is the SHA-256 of
    /// its parameters (model and shared sections) as the simulator holds them.
    pub fn model_vehicle(mut self, role: &str, spec: &str, v: &ModelVehicle) -> Result<Self> {
        /// A whole core vehicle (its record), or the record text of another model's vehicle
        /// and whether `spec` is one of its sets.
        struct Record<'a>(&'a str);
        impl ModelVisitor for Record<'_> {
            type Output = std::result::Result<Vehicle, (String, bool)>;
            fn visit<M: Registered<N>, const N: usize>(self, f: M::File) -> Self::Output {
                match (M::SECTION, M::parts_of(&f)) {
                    (None, Some(whole)) => Ok(*whole),
                    _ => Err((format!("{f:?}"), M::set(self.0).is_some())),
                }
            }
        }
        let (record, named) = match registry::with_model(v.clone(), Record(spec)) {
            Ok(car) => return self.vehicle(role, spec, &car),
            Err(r) => r,
        };
        if !named {
            self = self.file(&format!("{role} file"), Path::new(spec))?;
        }
        self.inputs.push(Input {
            role: format!("{role} record"),
            source: if named {
                format!("built-in set `{spec}`")
            } else {
                format!("resolved from {spec}")
            },
            sha256: sha256_hex(record.as_bytes()),
        });
        Ok(self)
    }

    /// Adds a named seed.
    #[must_use]
    pub fn seed(mut self, name: &str, seed: u64) -> Self {
        self.seeds.push((name.to_string(), seed));
        self
    }

    /// A `## Provenance` section (a Markdown table).
    pub fn markdown(&self) -> String {
        let cell = |s: &str| s.replace('|', "\\|");
        let mut s = String::from("## Provenance\n\n| item | value |\n|---|---|\n");
        s += &format!("| tool | {} |\n", cell(&self.tool));
        s += &format!("| git (at build) | `{}` |\n", cell(&self.git));
        s += &format!("| command line | `{}` |\n", cell(&self.command_line));
        for i in &self.inputs {
            s += &format!(
                "| {} | {} (sha256 `{}`) |\n",
                cell(&i.role),
                cell(&i.source),
                i.sha256
            );
        }
        for (name, seed) in &self.seeds {
            s += &format!("| seed: {} | {seed} |\n", cell(name));
        }
        s
    }

    /// The provenance as a JSON object.
    pub fn json(&self) -> Value {
        json!({
            "tool": self.tool,
            "git": self.git,
            "command_line": self.command_line,
            "inputs": self.inputs.iter().map(|i| json!({
                "role": i.role, "source": i.source, "sha256": i.sha256,
            })).collect::<Vec<_>>(),
            "seeds": self.seeds.iter().map(|(n, s)| json!({"name": n, "seed": s})).collect::<Vec<_>>(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use shimmy_core::vehicles::car::ParamSet;

    #[test]
    fn hashes_quoting_and_the_vehicle() {
        // FIPS 180-2 test vector.
        assert_eq!(
            sha256_hex(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        let p = Provenance::new(
            ["shimmy-sim", "analyze", "my log.csv", "--out", "o"].map(String::from),
        )
        .vehicle("vehicle", "nominal", &Vehicle::nominal())
        .unwrap()
        .seed("road noise", 7);
        assert_eq!(p.command_line, "shimmy-sim analyze 'my log.csv' --out o");
        assert!(!p.git.is_empty());
        let md = p.markdown();
        assert!(
            md.contains("| vehicle record | built-in set `nominal` (sha256 `"),
            "{md}"
        );
        assert!(md.contains("| seed: road noise | 7 |"));
        // Another vehicle has another record hash.
        let hard = Vehicle::from_set(ParamSet::Hard);
        assert_ne!(
            vehicle_record_sha256(&hard).unwrap(),
            vehicle_record_sha256(&Vehicle::nominal()).unwrap()
        );
        assert_eq!(p.json()["seeds"][0]["seed"], 7);
    }
}
