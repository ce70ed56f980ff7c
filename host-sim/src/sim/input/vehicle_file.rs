//! Vehicle files (TOML) into a `shimmy_core::vehicle::Vehicle`, and `FILE|SET` on the command
//! line: a named set (`nominal`, `gentle`, `hard`: the plant set with the reference damper,
//! sensors, gains and thresholds) or a file that starts from a named set and sets fields by
//! name, section by section (`docs/vehicle-file.md` lists every field, unit, default, range):
//!
//! ```toml
//! base = "nominal"        # optional, default "nominal"
//! [plant]                 # `[overrides]` is the same section under its older name
//! k_d = 5000.0            # N m/rad
//! [damper]
//! rated_current_a = 2.5   # A
//! [damper_model]          # what the firmware believes about the damper
//! [sensors]
//! [controller]
//! [thresholds]
//! ```
//!
//! A file names its vehicle model with `model` (default `car-4dof`, so every earlier file stays
//! valid). A `model = "mining-truck-5dof"` file (`docs/mining-truck.md`) has `base` =
//! `truck-empty` or `truck-full` (default `truck-full`) and one section, `[truck]`, with the
//! fields of `shimmy_core::vehicles::truck::TRUCK_FIELDS`; the named sets `truck-empty` and `truck-full`
//! work wherever a vehicle is asked for by [`load_model`]. A `model = "trailer-2dof"` file
//! (`docs/trailer.md`) has `base = "trailer"` (the default) and one section, `[trailer]`, with the
//! fields of `shimmy_core::vehicles::trailer::TRAILER_FIELDS`; the named set `trailer` works there too.
//!
//! The parameter files of earlier versions (`base` + `[overrides]`) are vehicle files; the
//! sections they leave out take their defaults. Every value goes through the core's one
//! validation (`Vehicle::set`, then `Vehicle::validate`): a bad file is rejected with a message
//! naming the field, the value and the allowed range; nothing is half-applied.

use crate::model::registry::{
    self, all_set_names, for_each_model, name_of, set_names_of, ModelEntry, ModelTypeVisitor,
    ReferenceModel, Registered, REFERENCE_N,
};
use anyhow::{bail, Context, Result};
use shimmy_core::vehicle::{RecordVehicle, SetError, Vehicle, FIELDS, SECTIONS};
use shimmy_core::vehicles::FieldError;
use std::path::{Path, PathBuf};

pub use crate::model::registry::ModelVehicle;

/// The model of the core's whole vehicle files (the default of the `model` key).
const CAR: &str = <Vehicle as RecordVehicle>::MODEL;

/// A model of the family whose vehicle a vehicle file (or a set name) gives: what a command
/// generic over the model loads `--vehicle` with. Every model of the registry is one.
pub trait FileModel<const N: usize>: Registered<N> {
    /// The vehicle `spec` (a set name or a file, relative to `dir`), or an error naming the
    /// model it has when that is another.
    fn load_vehicle(spec: &str, dir: &Path) -> Result<Self::Vehicle>;
}

impl<M: Registered<N>, const N: usize> FileModel<N> for M {
    fn load_vehicle(spec: &str, dir: &Path) -> Result<M::Vehicle> {
        if M::SECTION.is_none() {
            // The whole-vehicle files' model reads through the core vehicle's own loader.
            let f = M::from_any(load_relative(spec, dir)?.into())
                .map_err(|_| anyhow::anyhow!("a core vehicle file is a {}", CAR))?;
            return M::vehicle(f);
        }
        match M::from_any(load_model_relative(spec, dir)?) {
            Ok(f) => M::vehicle(f),
            Err(other) => bail!(
                "vehicle `{spec}` is a {} model; this run's vehicle is a {} (the simulated and \
                 the believed vehicle are of one model)",
                other.model_name(),
                name_of::<M, N>()
            ),
        }
    }
}

/// The model names a vehicle file's `model` key takes.
pub fn model_names() -> Vec<&'static str> {
    registry::model_names()
}

/// Resolves `spec` (a set name of any model or a vehicle file) to a validated vehicle.
pub fn load_model(spec: &str) -> Result<ModelVehicle> {
    load_model_relative(spec, Path::new(""))
}

/// [`load_model`] with a relative path taken relative to `dir`. Set names win over files of the
/// same name.
pub fn load_model_relative(spec: &str, dir: &Path) -> Result<ModelVehicle> {
    if let Some(v) = registry::named_vehicle(spec) {
        return v;
    }
    let path: PathBuf = if Path::new(spec).is_absolute() {
        PathBuf::from(spec)
    } else {
        dir.join(spec)
    };
    let path = path.as_path();
    if !path.is_file() {
        bail!(
            "vehicle `{spec}`: no such file ({}) and not a named set ({})",
            path.display(),
            all_set_names(", ")
        );
    }
    let text = crate::sim::input::files::read_text(path, crate::sim::input::files::TEXT_LIMIT)
        .context("reading vehicle file")?;
    parse_model(&text).with_context(|| format!("in vehicle file {}", path.display()))
}

/// Parses a vehicle file of any model (its `model` key, default `car-4dof`).
pub fn parse_model(text: &str) -> Result<ModelVehicle> {
    let table: toml::Table = toml::from_str(text)?;
    struct Parse<'a> {
        model: &'a str,
        table: &'a toml::Table,
        text: &'a str,
        out: Option<Result<ModelVehicle>>,
    }
    impl ModelTypeVisitor for Parse<'_> {
        fn visit<M: Registered<N>, const N: usize>(&mut self) {
            if self.out.is_some() || name_of::<M, N>() != self.model {
                return;
            }
            self.out = Some(if M::SECTION.is_none() {
                parse(self.text).map(ModelVehicle::from)
            } else {
                parse_member::<M, N>(self.table).map(M::into_any)
            });
        }
    }
    let mut p = Parse {
        model: model_of(&table)?,
        table: &table,
        text,
        out: None,
    };
    for_each_model(&mut p);
    p.out.unwrap_or_else(|| parse(text).map(ModelVehicle::from))
}

/// The `model` key of a vehicle file, checked (absent: the car).
fn model_of(table: &toml::Table) -> Result<&str> {
    let names = model_names();
    match table.get("model") {
        None => Ok(CAR),
        Some(toml::Value::String(s)) if names.contains(&s.as_str()) => Ok(s.as_str()),
        Some(toml::Value::String(s)) => bail!(
            "field `model`: unknown model `{s}`, allowed: {}",
            names.join(", ")
        ),
        Some(other) => bail!(
            "field `model`: expected a model name ({}), found {}",
            names.join(", "),
            other.type_str()
        ),
    }
}

/// A file of the model `M` whose files have a section of their own: `base` (one of its sets),
/// its section and, when its files take them ([`ModelEntry::SHARED_SECTIONS`]), the shared
/// sections of every model (`[damper]`, `[damper_model]`, `[sensors]`, `[controller]`,
/// `[thresholds]`) over the model's own.
fn parse_member<M: ModelEntry<N>, const N: usize>(table: &toml::Table) -> Result<M::File> {
    let model = name_of::<M, N>();
    let section = M::SECTION.unwrap_or("plant");
    let base = match table.get("base") {
        None => M::DEFAULT_SET,
        Some(toml::Value::String(s)) => s.as_str(),
        Some(other) => bail!(
            "field `base`: expected a set name, found {}",
            other.type_str()
        ),
    };
    let Some(mut t) = M::set(base) else {
        bail!(
            "field `base`: unknown set `{base}` for model {model}, allowed: {}",
            set_names_of::<M, N>()
        );
    };
    let mut parts = if M::SHARED_SECTIONS {
        M::parts_of(&M::assemble(t, None)?).copied()
    } else {
        None
    };
    for (key, value) in table {
        match (key.as_str(), parts.as_mut()) {
            ("model" | "base", _) => continue,
            (k, _) if k == section => {}
            (k, Some(parts)) if k != "plant" && SECTIONS.contains(&k) => {
                for (name, x) in section_numbers(key, value)? {
                    set_field(parts, k, k, name, x)?;
                }
                continue;
            }
            (_, shared) => bail!(
                "field `{key}`: no such section for model {model}, allowed: model, base, {section}{}",
                if shared.is_some() {
                    format!(", {}", SECTIONS[1..].join(", "))
                } else {
                    String::new()
                }
            ),
        }
        for (name, x) in section_numbers(key, value)? {
            match M::set_field(&mut t, name, x) {
                Ok(()) => {}
                Err(FieldError::Unknown) => bail!(
                    "field `{section}.{name}`: no such field, allowed: {}",
                    M::fields()
                        .iter()
                        .map(|f| f.name)
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
                Err(e) => bail!(
                    "{}",
                    e.to_string()
                        .replacen("field `", &format!("field `{section}."), 1)
                ),
            }
        }
    }
    M::check_in_file(&t)?;
    if let Some(parts) = &parts {
        parts.validate()?;
    }
    M::assemble(t, parts)
}

/// The entries of section `key` as numbers (integers read as f64), or an error naming the
/// section or the entry that is not a number.
fn section_numbers<'a>(key: &str, value: &'a toml::Value) -> Result<Vec<(&'a str, f64)>> {
    let Some(entries) = value.as_table() else {
        bail!(
            "field `{key}`: expected a section of numbers, found {}",
            value.type_str()
        );
    };
    entries
        .iter()
        .map(|(name, value)| match value {
            toml::Value::Float(x) => Ok((name.as_str(), *x)),
            toml::Value::Integer(i) => Ok((name.as_str(), *i as f64)),
            other => bail!(
                "field `{key}.{name}`: expected a number, found {}",
                other.type_str()
            ),
        })
        .collect()
}

/// The older name of the `[plant]` section (parameter files).
const PLANT_ALIAS: &str = "overrides";

/// Resolves `spec` (a set name or the path of a vehicle file) to a validated vehicle.
pub fn load(spec: &str) -> Result<Vehicle> {
    load_relative(spec, Path::new(""))
}

/// [`load`] with a relative path taken relative to `dir` (e.g. the folder of the scenario file
/// that names the vehicle). Set names win over files of the same name.
pub fn load_relative(spec: &str, dir: &Path) -> Result<Vehicle> {
    if let Some(v) = <ReferenceModel as ModelEntry<REFERENCE_N>>::named(spec) {
        return v;
    }
    if let Some(model) = registry::model_of_set(spec) {
        bail!("{}", car_only(&format!("vehicle `{spec}`"), model));
    }
    let path: PathBuf = if Path::new(spec).is_absolute() {
        PathBuf::from(spec)
    } else {
        dir.join(spec)
    };
    if !path.is_file() {
        bail!(
            "vehicle `{spec}`: no such file ({}) and not a named set ({})",
            path.display(),
            set_names()
        );
    }
    let text = crate::sim::input::files::read_text(&path, crate::sim::input::files::TEXT_LIMIT)
        .context("reading vehicle file")?;
    parse(&text).with_context(|| format!("in vehicle file {}", path.display()))
}

/// Parses the TOML text of a vehicle file.
pub fn parse(text: &str) -> Result<Vehicle> {
    let mut table: toml::Table = toml::from_str(text)?;
    let model = model_of(&table)?;
    if model != CAR {
        bail!("{}", car_only("this vehicle file", model));
    }
    table.remove("model");
    if table.is_empty() {
        bail!(
            "empty vehicle file: give at least `base` (one of {}) or one section ({})",
            set_names(),
            SECTIONS.join(", ")
        );
    }
    let base = match table.get("base") {
        None => "nominal",
        Some(toml::Value::String(s)) => s.as_str(),
        Some(other) => bail!(
            "field `base`: expected a set name, found {}",
            other.type_str()
        ),
    };
    let Some(plant) = <ReferenceModel as ModelEntry<REFERENCE_N>>::set(base) else {
        bail!(
            "field `base`: unknown set `{base}`, allowed: {}",
            set_names()
        );
    };
    if table.contains_key("plant") && table.contains_key(PLANT_ALIAS) {
        bail!("field `{PLANT_ALIAS}`: the same section as `plant`; give only one of them");
    }
    let mut v = Vehicle::with_plant(plant);
    for (key, value) in &table {
        if key == "base" {
            continue;
        }
        let section = if key == PLANT_ALIAS {
            "plant"
        } else {
            key.as_str()
        };
        if !SECTIONS.contains(&section) {
            bail!(
                "field `{key}`: no such section, allowed: base, {}, {PLANT_ALIAS}",
                SECTIONS.join(", ")
            );
        }
        for (name, x) in section_numbers(key, value)? {
            set_field(&mut v, section, key, name, x)?;
        }
    }
    v.validate()?;
    Ok(v)
}

/// The commands that run a truck vehicle, for messages.
pub const TRUCK_COMMANDS: &str = "params, stability, sensitivity, gas-charge, bifurcation, \
     sweep, margin, faults, run, meter-accuracy, mismatch, report, compare, analyze, device, pil and \
     the demo";

/// The message of a car-only command given another model.
fn car_only(what: &str, model: &str) -> String {
    format!(
        "{what} is a {model} model; this command runs the {} only so far (the truck runs \
         through {TRUCK_COMMANDS}; the trailer through `stability`, `sensitivity`, \
         `sway-damping`, `bifurcation`, `sweep`, `margin`, `faults` and `run`)",
        CAR
    )
}

/// Writes `v` as a vehicle file: every field of every section with its value, so that
/// [`parse`] reads back the same vehicle bit for bit (f64 values print as their shortest
/// round-trip form).
pub fn to_toml(v: &Vehicle) -> String {
    let mut out = String::from(
        "# Vehicle file (docs/vehicle-file.md): every field, as read from a device or written by shimmy-sim.\nbase = \"nominal\"\n",
    );
    push_sections(&mut out, v, &SECTIONS);
    out
}

/// Writes `f`, a vehicle of the model `M`, as a vehicle file: the `model` key (for a model
/// other than the car's whole-vehicle files), every field of the model's section and every
/// field of the shared sections its files take, so that [`parse_model`] reads back the same
/// vehicle bit for bit.
pub fn model_to_toml<M: ModelEntry<N>, const N: usize>(f: &M::File) -> String {
    let mut out = String::from(
        "# Vehicle file (docs/vehicle-file.md): every field, as read from a device or written by shimmy-sim.\n",
    );
    if let Some(section) = M::SECTION {
        out.push_str(&format!(
            "model = \"{}\"\nbase = \"{}\"\n\n[{section}]\n",
            registry::name_of::<M, N>(),
            M::DEFAULT_SET
        ));
        let m = M::model_of(f);
        for field in M::fields() {
            let x = m.field(field.name).unwrap_or(f64::NAN);
            out.push_str(&format!("{} = {x:?}  # {}\n", field.name, field.unit));
        }
    } else {
        out.push_str(&format!("base = \"{}\"\n", M::DEFAULT_SET));
    }
    if let Some(parts) = M::parts_of(f) {
        push_sections(&mut out, parts, registry::shared_sections::<M, N>());
    }
    out
}

/// Every field of `sections` of `v`, a TOML table each.
fn push_sections(out: &mut String, v: &Vehicle, sections: &[&str]) {
    for section in sections {
        out.push_str(&format!("\n[{section}]\n"));
        for f in FIELDS.iter().filter(|f| f.section() == *section) {
            out.push_str(&format!("{} = {:?}  # {}\n", f.name, v.get(f), f.unit()));
        }
    }
}

/// Sets the field `section.name` of `v` to `x` (checked against its range), with an error
/// naming the field as the user wrote it, `shown_as.name` (e.g. `overrides.k_d` under the
/// older section name, `plant.overrides.k_d` in a scenario file).
pub fn set_field(v: &mut Vehicle, section: &str, shown_as: &str, name: &str, x: f64) -> Result<()> {
    match v.set(section, name, x) {
        Ok(()) => Ok(()),
        Err(SetError::UnknownField) => bail!(
            "field `{shown_as}.{name}`: no such field, allowed: {}",
            field_names(section).join(", ")
        ),
        Err(SetError::Invalid(e)) => bail!(
            "{}",
            e.to_string().replacen(
                &format!("field `{section}."),
                &format!("field `{shown_as}."),
                1
            )
        ),
    }
}

/// The fields of `section`, in table order.
pub fn field_names(section: &str) -> Vec<&'static str> {
    FIELDS
        .iter()
        .filter(|f| f.section() == section)
        .map(|f| f.name)
        .collect()
}

/// The named sets, for messages.
pub fn set_names() -> String {
    set_names_of::<ReferenceModel, REFERENCE_N>()
}

/// The field table as Markdown, one table per section (field, unit, default, range, meaning):
/// the body of `docs/vehicle-file.md` between its markers (a test keeps them equal).
pub fn field_table_markdown() -> String {
    let nominal = Vehicle::nominal();
    let mut out = String::new();
    for section in SECTIONS {
        out.push_str(&format!(
            "\n### `[{section}]`\n\n| field | unit | default | allowed | meaning |\n|---|---|---:|---|---|\n"
        ));
        for f in FIELDS.iter().filter(|f| f.section() == section) {
            let allowed = if f.integer {
                format!("{} ..= {}, whole", f.lo, f.hi)
            } else {
                format!("{} ..= {}", f.lo, f.hi)
            };
            out.push_str(&format!(
                "| `{}` | {} | {} | {allowed} | {} |\n",
                f.name,
                f.unit(),
                format_default(nominal.get(f)),
                f.doc
            ));
        }
    }
    out
}

/// Shortest text that reads back to the f32 or f64 default (f32 fields print as e.g. 0.04, not
/// 0.03999999910593033).
fn format_default(x: f64) -> String {
    let as_f32 = x as f32;
    if f64::from(as_f32) == x {
        format!("{as_f32}")
    } else {
        format!("{x}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::family::FamilyVehicle;
    use shimmy_core::vehicles::car::ParamSet;
    use shimmy_core::vehicles::dual_axle::DualAxleSet;
    use shimmy_core::vehicles::trailer::TrailerSet;
    use shimmy_core::vehicles::truck::TruckSet;

    /// `model` picks the model (the car by default), a truck file sets `[truck]` fields by
    /// name, and bad models, sections, fields, values and charges are rejected naming them.
    #[test]
    fn the_model_key_selects_the_vehicle_model() {
        let car = |text: &str| match parse_model(text).unwrap() {
            ModelVehicle::Car(v) => v,
            _ => panic!("a car file read as another model"),
        };
        assert_eq!(
            car("base = \"hard\"\n"),
            car("model = \"car-4dof\"\nbase = \"hard\"\n")
        );
        let ModelVehicle::Truck(FamilyVehicle { model: t, .. }) = parse_model(
            "model = \"mining-truck-5dof\"\nbase = \"truck-empty\"\n[truck]\nhps_v0_m3 = 0.0145\npayload_kg = 100000\n",
        )
        .unwrap() else {
            panic!("a truck file read as a car")
        };
        assert_eq!(
            t,
            TruckSet::Empty
                .params()
                .with_gas_volume(0.0145)
                .with_payload(1e5)
        );
        let err = |text: &str| format!("{:#}", parse_model(text).unwrap_err());
        let e = err("model = \"bus\"\n");
        assert!(
            e.contains("field `model`") && e.contains("car-4dof, mining-truck-5dof"),
            "{e}"
        );
        let e = err("model = \"mining-truck-5dof\"\n[truck]\nhps_v0_m3 = 5.0\n");
        assert!(
            e.contains("field `truck.hps_v0_m3`") && e.contains("0.2"),
            "{e}"
        );
        let e = err("model = \"mining-truck-5dof\"\n[truck]\nk_dd = 5.0\n");
        assert!(e.contains("field `truck.k_dd`: no such field"), "{e}");
        let e = err("model = \"mining-truck-5dof\"\n[plant]\nk_d = 5.0\n");
        assert!(e.contains("field `plant`: no such section"), "{e}");
        let e = err("model = \"mining-truck-5dof\"\n[truck]\nhps_p0_pa = 2.0e7\n");
        assert!(e.contains("topped out"), "{e}");
        // the car-only loader says which model it got
        let e = format!("{:#}", load("truck-full").unwrap_err());
        assert!(
            e.contains("mining-truck-5dof") && e.contains("car-4dof"),
            "{e}"
        );
        assert!(matches!(
            load_model("truck-full").unwrap(),
            ModelVehicle::Truck(_)
        ));
        assert!(matches!(
            load_model("nominal").unwrap(),
            ModelVehicle::Car(_)
        ));
    }

    /// A dual-axle file sets `[dual_axle]` fields by name on its base; bad sections, fields,
    /// values and axle order are rejected naming them.
    #[test]
    fn a_dual_axle_file_reads_its_section() {
        let ModelVehicle::DualAxle(FamilyVehicle { model: t, .. }) = parse_model(
            "model = \"dual-axle-truck-8dof\"\nbase = \"dual-axle\"\n[dual_axle]\nk_t = 2.0e5\nm_f = 80\n",
        )
        .unwrap() else {
            panic!("a dual-axle file read as another model")
        };
        let mut want = DualAxleSet::Rated.params();
        want.k_t = 2.0e5;
        want.m_f = 80.0;
        assert_eq!(t, want);
        let err = |text: &str| format!("{:#}", parse_model(text).unwrap_err());
        let e = err("model = \"dual-axle-truck-8dof\"\n[dual_axle]\nk_t = -1.0\n");
        assert!(
            e.contains("field `dual_axle.k_t`") && e.contains("1000"),
            "{e}"
        );
        let e = err("model = \"dual-axle-truck-8dof\"\n[dual_axle]\nk_tt = 5.0\n");
        assert!(e.contains("field `dual_axle.k_tt`: no such field"), "{e}");
        let e = err("model = \"dual-axle-truck-8dof\"\n[truck]\nk_d = 5.0\n");
        assert!(e.contains("field `truck`: no such section"), "{e}");
        let e = err("model = \"dual-axle-truck-8dof\"\nbase = \"truck-full\"\n");
        assert!(e.contains("field `base`") && e.contains("dual-axle"), "{e}");
        let e = err(
            "model = \"dual-axle-truck-8dof\"\n[dual_axle]\naxle_spacing = 4.9\nwheelbase = 4.0\n",
        );
        assert!(e.contains("field `dual_axle.axle_spacing`"), "{e}");
        assert!(matches!(
            load_model("dual-axle").unwrap(),
            ModelVehicle::DualAxle(_)
        ));
        let e = format!("{:#}", load("dual-axle").unwrap_err());
        assert!(
            e.contains("dual-axle-truck-8dof") && e.contains("car-4dof"),
            "{e}"
        );
    }

    /// A trailer file sets `[trailer]` fields by name over the `trailer` set; bad sections,
    /// fields, values and a tail-heavy centre of gravity are rejected naming them.
    #[test]
    fn a_trailer_file_reads_its_section() {
        let ModelVehicle::Trailer(t) =
            parse_model("model = \"trailer-2dof\"\n[trailer]\nk_y = 7000\nsigma = 0.5\n").unwrap()
        else {
            panic!("a trailer file read as another model")
        };
        let mut want = TrailerSet::Caravan.params();
        want.k_y = 7000.0;
        want.sigma = 0.5;
        assert_eq!(t, want);
        let err = |text: &str| format!("{:#}", parse_model(text).unwrap_err());
        let e = err("model = \"trailer-2dof\"\n[trailer]\nk_y = -1.0\n");
        assert!(
            e.contains("field `trailer.k_y`") && e.contains("100000000"),
            "{e}"
        );
        let e = err("model = \"trailer-2dof\"\n[trailer]\nky = 1.0\n");
        assert!(e.contains("field `trailer.ky`: no such field"), "{e}");
        let e = err("model = \"trailer-2dof\"\n[truck]\nk_y = 1.0\n");
        assert!(e.contains("field `truck`: no such section"), "{e}");
        let e = err("model = \"trailer-2dof\"\nbase = \"truck-full\"\n");
        assert!(e.contains("field `base`") && e.contains("trailer"), "{e}");
        let e = err("model = \"trailer-2dof\"\n[trailer]\na = 7.0\n");
        assert!(e.contains("field `trailer.a`") && e.contains("6.45"), "{e}");
        let e = format!("{:#}", load("trailer").unwrap_err());
        assert!(e.contains("trailer-2dof") && e.contains("car-4dof"), "{e}");
        assert!(matches!(
            load_model("trailer").unwrap(),
            ModelVehicle::Trailer(_)
        ));
    }

    #[test]
    fn a_written_vehicle_file_reads_back_identical() {
        for set in ParamSet::ALL {
            let mut v = Vehicle::from_set(set);
            v.set("plant", "k_d", 4321.5).unwrap();
            let back = parse(&to_toml(&v)).unwrap();
            for f in FIELDS {
                assert_eq!(
                    back.get(f).to_bits(),
                    v.get(f).to_bits(),
                    "{}.{}",
                    f.section(),
                    f.name
                );
            }
        }
    }

    #[test]
    fn named_sets_and_sections() {
        assert_eq!(load("hard").unwrap(), Vehicle::from_set(ParamSet::Hard));
        let v =
            parse("base = \"gentle\"\n[overrides]\nk_d = 5000\n[damper]\nrated_current_a = 2.5\n")
                .unwrap();
        assert_eq!(v.plant.k_d, 5000.0);
        assert_eq!(v.plant.c_sw, 2.0);
        assert_eq!(v.control_params().limits.i_max_a, 2.5);
        let w = parse("[plant]\nk_d = 5000.0\n").unwrap();
        assert_eq!(w.plant.k_d, 5000.0);
        assert_eq!(w.plant.c_sw, 3.0);
    }

    #[test]
    fn the_plant_alias_keeps_the_users_name_in_messages() {
        let e = format!("{:#}", parse("[overrides]\nsigma = -0.6\n").unwrap_err());
        assert!(e.contains("overrides.sigma"), "{e}");
        let e = format!(
            "{:#}",
            parse("[plant]\nk_d = 1.0\n[overrides]\nk_d = 2.0\n").unwrap_err()
        );
        assert!(e.contains("overrides"), "{e}");
    }

    #[test]
    fn docs_table_lists_every_field() {
        let t = field_table_markdown();
        for f in FIELDS {
            assert!(t.contains(&format!("| `{}` |", f.name)), "{}", f.name);
        }
    }

    /// docs/vehicle-file.md carries the generated table between its markers (re-bless with
    /// `SHIMMY_BLESS=1 cargo test -p shimmy-sim --lib vehicle_file`).
    #[test]
    fn docs_vehicle_file_md_is_the_field_table() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/vehicle-file.md");
        let doc = std::fs::read_to_string(&path).unwrap();
        let (begin, end) = (DOC_BEGIN, DOC_END);
        let i = doc.find(begin).expect("begin marker") + begin.len();
        let j = doc.find(end).expect("end marker");
        let want = field_table_markdown();
        if std::env::var("SHIMMY_BLESS").is_ok_and(|v| v == "1") {
            let new = format!("{}{want}\n{}", &doc[..i], &doc[j..]);
            std::fs::write(&path, new).unwrap();
            return;
        }
        assert_eq!(
            doc[i..j].trim(),
            want.trim(),
            "docs/vehicle-file.md is out of date: SHIMMY_BLESS=1 cargo test -p shimmy-sim --lib vehicle_file"
        );
    }

    const DOC_BEGIN: &str = "<!-- generated: shimmy_core::vehicle::FIELDS -->";
    const DOC_END: &str = "<!-- end of generated table -->";
}
