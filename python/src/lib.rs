//! `shimmy_sim` for Python (PyO3; on PyPI `shimmy-sim`: `shimmy` is another project's name there): the simulator's library functions with NumPy arrays in and out.
//!
//! - `Vehicle`: load and validate a vehicle of any model (a named set or a vehicle file, the
//!   same loader as `shimmy-sim --vehicle`), read and set the fields of its model's table by
//!   `section.name` through the validation of a vehicle file, the car's plant parameters as a
//!   dict (the names of `host-sim/reference/plant_scipy.py`).
//! - `hopf_window`: the Hopf crossings of the linearised plant of any model (`shimmy-sim
//!   stability`).
//! - `eigen_sweep`: least-damped / critical mode at given speeds, as arrays, any model.
//! - `run_scenario` / `run_scenario_toml`: one closed-loop scenario run (`shimmy-sim run`), its
//!   trace and mode-meter rows as arrays and its metrics.
//! - `analyze`: the mode meter, fusion and monitor on a measured log (`shimmy-sim analyze`,
//!   `shimmy_sim::sim::analyze`), its rows as arrays, events and summary.
//!
//! Every error of the Rust side (a bad field, a value out of range, a failed run) is a
//! `ValueError` carrying the full message, which names the field and the allowed range. Long
//! computations release the GIL, so a thread pool (or Dask/Ray workers) can run them in parallel.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::Context as _;
use numpy::{IntoPyArray, PyArray1};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use shimmy_core::estimator::monitor::Level;
use shimmy_core::model::LinearModel;
use shimmy_core::stability::{self, HopfCrossing, ModeSelect, DEFAULT_TOL_MPS};
use shimmy_core::units::{kmh_to_mps, mps_to_kmh};
use shimmy_core::vehicle::{self as core_vehicle, FIELDS};
use shimmy_core::vehicles::car::{Param, PlantParams};
use shimmy_core::vehicles::{FieldError, ModelField};
use shimmy_sim::cmd::reference_bench::spencer_fields;
use shimmy_sim::cmd::stability::{REF_AMPLITUDE_DEG, STEP_KMH};
use shimmy_sim::model::damper_equiv::damper_equivalent;
use shimmy_sim::model::family::SimModel;
use shimmy_sim::model::hopf_type::{hopf_type_at, HopfType, HopfTypeError};
use shimmy_sim::model::plant::Damper;
use shimmy_sim::model::registry::{self, ModelVisitor, Registered};
use shimmy_sim::sim::analyze::{self as sim_analyze, Analysis, AnalysisRow, AnalyzeOptions};
use shimmy_sim::sim::input::arg_range::{self, SPEED_KMH};
use shimmy_sim::sim::input::log_file::{self, MappingChanges};
use shimmy_sim::sim::input::vehicle_file::ModelVehicle;
use shimmy_sim::sim::run::closed_loop::{LoopResult, RunMetrics};
use shimmy_sim::sim::run::scenario::ScenarioSpec;
use shimmy_sim::sim::{
    input::vehicle_file,
    run::{scenario, scenario_file},
};

/// The Rust error as a Python `ValueError` with the whole context chain.
fn value_error(e: impl Into<anyhow::Error>) -> PyErr {
    PyValueError::new_err(format!("{:#}", e.into()))
}

/// A validated vehicle of any model of the family (`docs/vehicle-file.md`): the car's whole
/// vehicle, or another model's parameters with the shared sections it has.
#[pyclass(module = "shimmy_sim", from_py_object)]
#[derive(Clone)]
struct Vehicle {
    inner: ModelVehicle,
}

#[pymethods]
impl Vehicle {
    /// A named set of any model (`nominal`, `gentle`, `hard`, `truck-full`, `truck-empty`,
    /// `dual-axle`, `trailer`, ...) or the path of a vehicle file (TOML, its `model` key).
    #[new]
    #[pyo3(signature = (spec = "nominal"))]
    fn new(spec: &str) -> PyResult<Self> {
        vehicle_file::load_model(spec)
            .map(|inner| Self { inner })
            .map_err(value_error)
    }

    /// A vehicle from the TOML text of a vehicle file of any model.
    #[staticmethod]
    fn from_toml(text: &str) -> PyResult<Self> {
        vehicle_file::parse_model(text)
            .map(|inner| Self { inner })
            .map_err(value_error)
    }

    /// The model's name (`car-4dof`, `mining-truck-5dof`, `dual-axle-truck-8dof`,
    /// `trailer-2dof`).
    #[getter]
    fn model(&self) -> &'static str {
        self.inner.model_name()
    }

    /// The value of `field` (`"plant.k_d"`, `"truck.k_d"`), in the unit of the field table.
    fn get(&self, field: &str) -> PyResult<f64> {
        let (section, name) = split_field(&self.inner, field)?;
        let v = &self.inner;
        if model_section(v) == Some(section) {
            return v.model_field(name).ok_or_else(|| {
                PyValueError::new_err(format!(
                    "field `{section}.{name}`: no such field, allowed in `{section}`: {}",
                    field_list(v)
                ))
            });
        }
        if shared_sections(v).contains(&section) {
            let parts = parts(v).ok_or_else(|| no_section(v, section))?;
            return core_vehicle::find_field(section, name)
                .map(|f| parts.get(f))
                .ok_or_else(|| unknown_field(section, name));
        }
        Err(no_section(v, section))
    }

    /// Sets `field` (`"plant.k_d"`, `"truck.k_d"`) to `value`; the field's range and the whole
    /// vehicle are checked (as in a vehicle file), and on an error nothing changes.
    fn set(&mut self, field: &str, value: f64) -> PyResult<()> {
        let (section, name) = split_field(&self.inner, field)?;
        let shared = shared_sections(&self.inner).contains(&section);
        let own = model_section(&self.inner) == Some(section);
        // the messages of the vehicle file's reader (`vehicle_file::parse_model`)
        let v = &self.inner;
        let r = if own {
            model_set(v, section, name, value)
        } else if let (true, Some(mut parts)) = (shared, parts(v)) {
            set_shared(&mut parts, section, name, value)
                .map(|()| v.with_parts(parts).expect("a vehicle with shared sections"))
        } else {
            return Err(no_section(v, section));
        };
        self.inner = r.map_err(value_error)?;
        Ok(())
    }

    /// A copy with the fields of `changes` (`{"plant.k_d": 5000.0, ...}`) set.
    fn with_fields(&self, changes: BTreeMap<String, f64>) -> PyResult<Self> {
        let mut out = self.clone();
        for (field, value) in changes {
            out.set(&field, value)?;
        }
        Ok(out)
    }

    /// Every field of the vehicle's model as `{"section.name": value}` (the model's own
    /// section, then the shared sections its vehicle files take).
    fn fields(&self) -> BTreeMap<String, f64> {
        let mut out = model_fields(&self.inner);
        if let Some(parts) = parts(&self.inner) {
            let sections = shared_sections(&self.inner);
            out.extend(
                FIELDS
                    .iter()
                    .filter(|f| sections.contains(&f.section()))
                    .map(|f| (format!("{}.{}", f.section(), f.name), parts.get(f))),
            );
        }
        out
    }

    /// The car's plant parameters by their names in `shimmy_core::vehicles::car` (and in
    /// `host-sim/reference/plant_scipy.py`), SI units; the car only (another model's are its
    /// section of [`Vehicle::fields`]).
    fn plant(&self) -> PyResult<BTreeMap<&'static str, f64>> {
        let v = self.car("plant()")?;
        Ok(Param::ALL
            .into_iter()
            .map(|q| (q.name(), v.plant.get(q)))
            .collect())
    }

    /// The MR damper (Spencer model, scaled to the steering damper) by the names of the
    /// reference's `[damper]` section (`host-sim/reference/plant_scipy.py`); a model without
    /// an MR damper (the trailer) is refused.
    fn damper(&self) -> PyResult<BTreeMap<&'static str, f64>> {
        let parts = self.damped("damper()")?;
        Ok(spencer_fields(&parts.damper.spencer).into_iter().collect())
    }

    /// The coil rating (largest allowed current), A; a model without an MR damper (the
    /// trailer) is refused.
    #[getter]
    fn rated_current_a(&self) -> PyResult<f64> {
        Ok(f64::from(self.damped("rated_current_a")?.rated_current_a()))
    }

    fn __repr__(&self) -> String {
        match &self.inner {
            ModelVehicle::Car(v) => format!(
                "Vehicle(model={}, k_d={} N m/rad, c_a={} N/rad, rated_current_a={} A)",
                self.model(),
                v.plant.k_d,
                v.plant.c_a,
                v.rated_current_a()
            ),
            other => format!("Vehicle(model={})", other.model_name()),
        }
    }

    fn __eq__(&self, other: &Self) -> bool {
        self.inner == other.inner
    }
}

impl Vehicle {
    /// The car's vehicle, or a `ValueError` naming this vehicle's model for `what`, a
    /// function of the car only.
    fn car(&self, what: &str) -> PyResult<&core_vehicle::Vehicle> {
        match &self.inner {
            ModelVehicle::Car(v) => Ok(v),
            other => Err(PyValueError::new_err(format!(
                "{what}: the vehicle is a {} model; supported for the {} model only",
                other.model_name(),
                PlantParams::NAME
            ))),
        }
    }

    /// The shared sections of a model with an MR damper, or a `ValueError` for `what`.
    fn damped(&self, what: &str) -> PyResult<core_vehicle::Vehicle> {
        parts(&self.inner).ok_or_else(|| {
            PyValueError::new_err(format!(
                "{what}: the {} model has no MR damper; supported for {}",
                self.inner.model_name(),
                registry::and_list(&registry::damped_models())
            ))
        })
    }
}

/// The model's own section of the field table (the car has none: its plant is `[plant]`).
fn model_section(v: &ModelVehicle) -> Option<&'static str> {
    v.section()
}

/// The shared sections a vehicle file of the model sets (the car: all; the truck: all but
/// `plant`, which is its `[truck]`; the dual-axle truck and the trailer: none, their files
/// take their own section only).
fn shared_sections(v: &ModelVehicle) -> &'static [&'static str] {
    v.shared_sections()
}

/// The shared sections (damper, sensors, gains, thresholds) of a model with an MR damper.
fn parts(v: &ModelVehicle) -> Option<core_vehicle::Vehicle> {
    v.parts()
}

/// Every section a field of the model's vehicle may name.
fn sections_of(v: &ModelVehicle) -> Vec<&'static str> {
    model_section(v)
        .into_iter()
        .chain(shared_sections(v).iter().copied())
        .collect()
}

fn no_section(v: &ModelVehicle, section: &str) -> PyErr {
    PyValueError::new_err(format!(
        "section `{section}`: no such section for model {}, allowed: {}",
        v.model_name(),
        sections_of(v).join(", ")
    ))
}

/// `v` with the field `name` of its model's own section set, then the whole checked as a
/// vehicle file checks it.
fn model_set(v: &ModelVehicle, section: &str, name: &str, x: f64) -> anyhow::Result<ModelVehicle> {
    match v.with_model_field(name, x) {
        Ok(r) => r,
        Err(FieldError::Unknown) => anyhow::bail!(
            "field `{section}.{name}`: no such field, allowed in `{section}`: {}",
            field_list(v)
        ),
        Err(e) => Err(prefixed(e, section)),
    }
}

/// Sets a field of the shared sections through the core's validation; on an error `v` is
/// unchanged.
fn set_shared(
    v: &mut core_vehicle::Vehicle,
    section: &str,
    name: &str,
    x: f64,
) -> anyhow::Result<()> {
    let mut u = *v;
    vehicle_file::set_field(&mut u, section, section, name, x)?;
    u.validate()?;
    *v = u;
    Ok(())
}

/// A model's field error with the field named as `section.name`.
fn prefixed(e: impl std::fmt::Display, section: &str) -> anyhow::Error {
    anyhow::anyhow!(
        "{}",
        e.to_string()
            .replacen("field `", &format!("field `{section}."), 1)
    )
}

fn field_list(v: &ModelVehicle) -> String {
    v.model_fields()
        .iter()
        .map(|f| f.name)
        .collect::<Vec<_>>()
        .join(", ")
}

/// A model's own section as `{"section.name": value}`.
fn model_fields(v: &ModelVehicle) -> BTreeMap<String, f64> {
    let Some(section) = v.section() else {
        return BTreeMap::new();
    };
    v.model_fields()
        .iter()
        .filter_map(|f| Some((format!("{section}.{}", f.name), v.model_field(f.name)?)))
        .collect()
}

fn split_field<'a>(v: &ModelVehicle, field: &'a str) -> PyResult<(&'a str, &'a str)> {
    field.split_once('.').ok_or_else(|| {
        PyValueError::new_err(format!(
            "field `{field}`: expected `section.name`, sections of model {}: {}",
            v.model_name(),
            sections_of(v).join(", ")
        ))
    })
}

fn unknown_field(section: &str, name: &str) -> PyErr {
    PyValueError::new_err(format!(
        "field `{section}.{name}`: no such field, allowed in `{section}`: {}",
        vehicle_file::field_names(section).join(", ")
    ))
}

/// The field table of `vehicle`'s model (default: the car's), the fields [`Vehicle::fields`]
/// lists: one dict per field (section, name, unit, lo, hi, integer, doc; a model's own section
/// has no doc: None).
#[pyfunction]
#[pyo3(signature = (vehicle = None))]
fn field_table<'py>(
    py: Python<'py>,
    vehicle: Option<&Vehicle>,
) -> PyResult<Vec<Bound<'py, PyDict>>> {
    let car = ModelVehicle::from(core_vehicle::Vehicle::nominal());
    let v = vehicle.map_or(&car, |v| &v.inner);
    let own: &[ModelField] = v.model_fields();
    let mut rows = Vec::new();
    for f in own {
        let d = PyDict::new(py);
        d.set_item("section", model_section(v))?;
        d.set_item("name", f.name)?;
        d.set_item("unit", f.unit)?;
        d.set_item("lo", f.range.0)?;
        d.set_item("hi", f.range.1)?;
        d.set_item("integer", false)?;
        d.set_item("doc", py.None())?;
        rows.push(d);
    }
    let shared = shared_sections(v);
    for f in FIELDS.iter().filter(|f| shared.contains(&f.section())) {
        let d = PyDict::new(py);
        d.set_item("section", f.section())?;
        d.set_item("name", f.name)?;
        d.set_item("unit", f.unit())?;
        d.set_item("lo", f.lo)?;
        d.set_item("hi", f.hi)?;
        d.set_item("integer", f.integer)?;
        d.set_item("doc", f.doc)?;
        rows.push(d);
    }
    Ok(rows)
}

/// [`crossings_on`] on the vehicle's model (`shimmy-sim stability`'s dispatch: the registry).
struct Crossings {
    model: &'static str,
    current_a: Option<f64>,
    ref_amplitude_deg: f64,
    v_min_kmh: f64,
    v_max_kmh: f64,
    step_kmh: f64,
}

impl ModelVisitor for Crossings {
    type Output = anyhow::Result<Vec<(HopfCrossing, Result<HopfType, HopfTypeError>)>>;
    fn visit<M: Registered<N>, const N: usize>(self, f: M::File) -> Self::Output {
        crossings_on(
            &M::model_of(&f),
            M::parts_of(&f),
            self.model,
            self.current_a,
            self.ref_amplitude_deg,
            self.v_min_kmh,
            self.v_max_kmh,
            self.step_kmh,
        )
    }
}

/// [`sweep_on`] on the vehicle's model.
struct Sweep<'a> {
    model: &'static str,
    speeds_kmh: &'a [f64],
    current_a: Option<f64>,
    ref_amplitude_deg: f64,
}

impl ModelVisitor for Sweep<'_> {
    type Output = anyhow::Result<BTreeMap<&'static str, Vec<f64>>>;
    fn visit<M: Registered<N>, const N: usize>(self, f: M::File) -> Self::Output {
        sweep_on(
            &M::model_of(&f),
            M::parts_of(&f),
            self.model,
            self.speeds_kmh,
            self.current_a,
            self.ref_amplitude_deg,
        )
    }
}

/// Equivalent viscous damper coefficient in N s/m: 0 without a current, else the MR damper's
/// describing-function value at `current_a` on the model `m` (as `shimmy-sim stability
/// --damper-current-a`); a model without an MR damper refuses a current.
fn damper_c<M: SimModel<N>, const N: usize>(
    m: &M,
    parts: Option<&core_vehicle::Vehicle>,
    model: &str,
    current_a: Option<f64>,
    ref_amplitude_deg: f64,
    v_min_kmh: f64,
    v_max_kmh: f64,
) -> anyhow::Result<f64> {
    REF_AMPLITUDE_DEG.check("ref_amplitude_deg", ref_amplitude_deg)?;
    let Some(i) = current_a else { return Ok(0.0) };
    let Some(parts) = parts else {
        anyhow::bail!(
            "damper_current_a: the {model} model has no MR damper configured; leave it out"
        )
    };
    arg_range::check_current("damper_current_a", i, parts)?;
    let d = damper_equivalent(
        m,
        &parts.damper.spencer,
        i,
        ref_amplitude_deg,
        kmh_to_mps(v_min_kmh),
        kmh_to_mps(v_max_kmh),
    )?;
    Ok(d.c_eq_nspm)
}

/// The Hopf crossings of the model `m` (`shimmy-sim stability`'s search on its linear model).
#[allow(clippy::too_many_arguments)]
fn crossings_on<M: SimModel<N>, const N: usize>(
    m: &M,
    parts: Option<&core_vehicle::Vehicle>,
    model: &str,
    current_a: Option<f64>,
    ref_amplitude_deg: f64,
    v_min_kmh: f64,
    v_max_kmh: f64,
    step_kmh: f64,
) -> anyhow::Result<Vec<(HopfCrossing, Result<HopfType, HopfTypeError>)>> {
    let c = damper_c(
        m,
        parts,
        model,
        current_a,
        ref_amplitude_deg,
        v_min_kmh,
        v_max_kmh,
    )?;
    let crossings = stability::hopf_crossings(
        &m.linear(),
        c,
        kmh_to_mps(v_min_kmh),
        kmh_to_mps(v_max_kmh),
        kmh_to_mps(step_kmh),
        DEFAULT_TOL_MPS,
    )?;
    // The nonlinear plant behind the crossing: with a coil current the MR damper is in it.
    let damper = match (current_a, parts) {
        (Some(_), Some(p)) => Damper::Mr(p.damper.spencer),
        _ => Damper::None,
    };
    Ok(crossings
        .iter()
        .map(|x| (*x, hopf_type_at(m, damper, x.speed_mps, x.freq_hz)))
        .collect())
}

/// The Hopf crossings of straight running in [v_min_kmh, v_max_kmh], for a vehicle of any
/// model: a list of dicts (speed_kmh, kind "onset"/"offset", freq_hz, shape, converged; the
/// Hopf type of `shimmy-sim stability`: hopf_type "supercritical", "subcritical", "degenerate",
/// "non-smooth" or "failed" with the reason in hopf_note, l1, cycle_amp_deg_1kmh), by
/// increasing speed. With `damper_current_a` the MR damper enters as its equivalent viscous
/// damper (not for the trailer, which has none).
#[pyfunction]
#[pyo3(signature = (vehicle, damper_current_a = None, v_min_kmh = 5.0, v_max_kmh = 150.0, step_kmh = 1.0, ref_amplitude_deg = 0.5))]
fn hopf_window<'py>(
    py: Python<'py>,
    vehicle: &Vehicle,
    damper_current_a: Option<f64>,
    v_min_kmh: f64,
    v_max_kmh: f64,
    step_kmh: f64,
    ref_amplitude_deg: f64,
) -> PyResult<Vec<Bound<'py, PyDict>>> {
    let v = &vehicle.inner;
    let model = v.model_name();
    let crossings = py
        .detach(|| -> anyhow::Result<_> {
            SPEED_KMH.check("v_min_kmh", v_min_kmh)?;
            SPEED_KMH.check("v_max_kmh", v_max_kmh)?;
            STEP_KMH.check("step_kmh", step_kmh)?;
            anyhow::ensure!(
                v_max_kmh > v_min_kmh,
                "v_min_kmh {v_min_kmh} must be below v_max_kmh {v_max_kmh}"
            );
            registry::with_model(
                v.clone(),
                Crossings {
                    model,
                    current_a: damper_current_a,
                    ref_amplitude_deg,
                    v_min_kmh,
                    v_max_kmh,
                    step_kmh,
                },
            )
        })
        .map_err(value_error)?;
    crossings
        .iter()
        .map(|(x, h)| {
            let d = PyDict::new(py);
            d.set_item("speed_kmh", mps_to_kmh(x.speed_mps))?;
            d.set_item("kind", x.kind.name())?;
            d.set_item("freq_hz", x.freq_hz)?;
            d.set_item("shape", x.shape.name())?;
            d.set_item("converged", x.converged)?;
            // The Hopf type as `shimmy-sim stability` gives it (NaN where there is none).
            let (kind, l1, amp_deg) = match h {
                Ok(h) => {
                    let amp = h.cycle_1kmh().1.map_or(f64::NAN, f64::to_degrees);
                    (h.criticality().name(), h.lyapunov.l1, amp)
                }
                Err(e) => (e.label(), f64::NAN, f64::NAN),
            };
            d.set_item("hopf_type", kind)?;
            d.set_item("hopf_note", h.as_ref().err().map(ToString::to_string))?;
            d.set_item("l1", l1)?;
            d.set_item("cycle_amp_deg_1kmh", amp_deg)?;
            Ok(d)
        })
        .collect()
}

/// The columns of [`eigen_sweep`] on the model `m`.
fn sweep_on<M: SimModel<N>, const N: usize>(
    m: &M,
    parts: Option<&core_vehicle::Vehicle>,
    model: &str,
    speeds_kmh: &[f64],
    current_a: Option<f64>,
    ref_amplitude_deg: f64,
) -> anyhow::Result<BTreeMap<&'static str, Vec<f64>>> {
    let lo = speeds_kmh.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = speeds_kmh.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let c = damper_c(
        m,
        parts,
        model,
        current_a,
        ref_amplitude_deg,
        lo,
        hi.max(lo + 1.0),
    )?;
    let p = &m.linear();
    let mut cols: BTreeMap<&'static str, Vec<f64>> = BTreeMap::new();
    for &s in speeds_kmh {
        let v_mps = kmh_to_mps(s);
        let m = stability::mode_summary(p, v_mps, c)?;
        let shimmy = stability::mode_at(p, v_mps, c, ModeSelect::Shimmy).ok();
        for (name, x) in [
            ("speed_kmh", s),
            ("max_re", m.max_re),
            ("critical_re", m.critical.re),
            ("critical_freq_hz", m.critical.freq_hz),
            ("critical_zeta", m.critical.zeta),
            ("least_damped_zeta", m.least_damped.zeta),
            ("least_damped_freq_hz", m.least_damped.freq_hz),
            ("shimmy_zeta", shimmy.map_or(f64::NAN, |m| m.zeta)),
            ("shimmy_freq_hz", shimmy.map_or(f64::NAN, |m| m.freq_hz)),
        ] {
            cols.entry(name).or_default().push(x);
        }
    }
    Ok(cols)
}

/// Modes of the linearised plant of a vehicle of any model at each speed of `speeds_kmh` (a
/// sequence or array): a dict of arrays `speed_kmh`, `max_re` (1/s, over all eigenvalues),
/// `critical_re`, `critical_freq_hz`, `critical_zeta` (the oscillatory mode with the largest
/// real part), `least_damped_zeta`, `least_damped_freq_hz`, `shimmy_zeta`, `shimmy_freq_hz`
/// (the least-damped in-phase wheel-yaw mode, NaN where there is none).
#[pyfunction]
#[pyo3(signature = (vehicle, speeds_kmh, damper_current_a = None, ref_amplitude_deg = 0.5))]
fn eigen_sweep<'py>(
    py: Python<'py>,
    vehicle: &Vehicle,
    speeds_kmh: Vec<f64>,
    damper_current_a: Option<f64>,
    ref_amplitude_deg: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let v = &vehicle.inner;
    let model = v.model_name();
    let columns = py
        .detach(|| -> anyhow::Result<BTreeMap<&'static str, Vec<f64>>> {
            anyhow::ensure!(
                !speeds_kmh.is_empty(),
                "speeds_kmh: give at least one speed"
            );
            for &s in &speeds_kmh {
                SPEED_KMH.check("speeds_kmh", s)?;
            }
            registry::with_model(
                v.clone(),
                Sweep {
                    model,
                    speeds_kmh: &speeds_kmh,
                    current_a: damper_current_a,
                    ref_amplitude_deg,
                },
            )
        })
        .map_err(value_error)?;
    let out = PyDict::new(py);
    for (name, col) in columns {
        out.set_item(name, col.into_pyarray(py))?;
    }
    Ok(out)
}

/// Runs the scenario file at `path` (`host-sim/scenarios/*.toml`, as `shimmy-sim run`); see
/// [`run_result`] for what it returns. `sensor_noise = False` runs the sensor models without
/// their random noise (quantisation and delays stay): a run an outside co-simulation can
/// reproduce sample for sample.
#[pyfunction]
#[pyo3(signature = (path, sensor_noise = true))]
fn run_scenario<'py>(
    py: Python<'py>,
    path: PathBuf,
    sensor_noise: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let run = py
        .detach(|| scenario_file::load(&path).and_then(|spec| run_spec(spec, sensor_noise)))
        .map_err(value_error)?;
    run_result(py, &run)
}

/// Runs a scenario given as TOML text (relative vehicle paths are taken relative to
/// `base_dir`); the rest as [`run_scenario`].
#[pyfunction]
#[pyo3(signature = (text, name = "scenario", base_dir = ".", sensor_noise = true))]
fn run_scenario_toml<'py>(
    py: Python<'py>,
    text: &str,
    name: &str,
    base_dir: &str,
    sensor_noise: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let run = py
        .detach(|| {
            scenario_file::parse_in(text, name, Path::new(base_dir))
                .and_then(|s| run_spec(s, sensor_noise))
        })
        .map_err(value_error)?;
    run_result(py, &run)
}

/// One finished scenario run.
struct Run {
    result: LoopResult,
    metrics: RunMetrics,
    trace_dt_s: f64,
}

fn run_spec(mut spec: ScenarioSpec, sensor_noise: bool) -> anyhow::Result<Run> {
    if !sensor_noise {
        spec.sensors.encoder_noise_rad = 0.0;
        spec.sensors.speed_noise_mps = 0.0;
        spec.sensors.current_noise_a = 0.0;
    }
    let (cfg, result) = scenario::run(&spec)?;
    let metrics = result.metrics(&cfg, spec.t_dist_s);
    Ok(Run {
        result,
        metrics,
        trace_dt_s: cfg.dt_s * cfg.record_every as f64,
    })
}

/// A run as a dict: `trace` (dict of arrays at the trace rate: t_s, psi_l_rad, psi_r_rad,
/// theta_sw_rad, speed_mps, driver_torque_nm, current_cmd_a, coil_a, damper_force_n, s_radps,
/// gain_radps2, flags, zeta, freq_hz), `meter` (dict of arrays at 100 Hz: t_s, speed_mps,
/// zeta_slow, sigma_zeta_slow, zeta_fast, freq_hz, amplitude_rad, valid), `trace_dt_s`,
/// `metrics` (dict: peak_yaw_rad, rms_yaw_rad, settle_s or None, peak_sw_rad, rms_current_a,
/// peak_current_a, energy_j, chatter_a, rms_force_n, shimmy_s, amp_end_rad, amp_max_rad,
/// invalid_commands), `sim_s` and `wall_s`.
fn run_result<'py>(py: Python<'py>, run: &Run) -> PyResult<Bound<'py, PyDict>> {
    let r = &run.result;
    fn column<'py, T: numpy::Element, R>(
        py: Python<'py>,
        rows: &[R],
        f: impl Fn(&R) -> T,
    ) -> Bound<'py, PyArray1<T>> {
        rows.iter().map(f).collect::<Vec<T>>().into_pyarray(py)
    }
    let t = &r.trace;
    let trace = PyDict::new(py);
    trace.set_item("t_s", column(py, t, |x| x.t_s))?;
    trace.set_item("psi_l_rad", column(py, t, |x| x.psi_l_rad))?;
    trace.set_item("psi_r_rad", column(py, t, |x| x.psi_r_rad))?;
    trace.set_item("theta_sw_rad", column(py, t, |x| x.theta_sw_rad))?;
    trace.set_item("speed_mps", column(py, t, |x| x.speed_mps))?;
    trace.set_item("driver_torque_nm", column(py, t, |x| x.driver_torque_nm))?;
    trace.set_item("current_cmd_a", column(py, t, |x| x.current_cmd_a))?;
    trace.set_item("coil_a", column(py, t, |x| x.coil_a))?;
    trace.set_item("damper_force_n", column(py, t, |x| x.damper_force_n))?;
    trace.set_item("s_radps", column(py, t, |x| x.s_radps))?;
    trace.set_item("gain_radps2", column(py, t, |x| x.gain_radps2))?;
    trace.set_item("flags", column(py, t, |x| x.flags))?;
    trace.set_item("zeta", column(py, t, |x| x.zeta))?;
    trace.set_item("freq_hz", column(py, t, |x| x.freq_hz))?;
    let m = &r.meter;
    let meter = PyDict::new(py);
    meter.set_item("t_s", column(py, m, |x| x.t_s))?;
    meter.set_item("speed_mps", column(py, m, |x| x.speed_mps))?;
    meter.set_item("zeta_slow", column(py, m, |x| x.zeta_slow))?;
    meter.set_item("sigma_zeta_slow", column(py, m, |x| x.sigma_zeta_slow))?;
    meter.set_item("zeta_fast", column(py, m, |x| x.zeta_fast))?;
    meter.set_item("freq_hz", column(py, m, |x| x.freq_hz))?;
    meter.set_item("amplitude_rad", column(py, m, |x| x.amplitude_rad))?;
    meter.set_item("valid", column(py, m, |x| x.valid))?;
    let out = PyDict::new(py);
    out.set_item("trace", trace)?;
    out.set_item("meter", meter)?;
    out.set_item("trace_dt_s", run.trace_dt_s)?;
    let k = &run.metrics;
    let metrics = PyDict::new(py);
    metrics.set_item("peak_yaw_rad", k.peak_yaw_rad)?;
    metrics.set_item("rms_yaw_rad", k.rms_yaw_rad)?;
    metrics.set_item("settle_s", k.settle_s)?;
    metrics.set_item("peak_sw_rad", k.peak_sw_rad)?;
    metrics.set_item("rms_current_a", k.rms_current_a)?;
    metrics.set_item("peak_current_a", k.peak_current_a)?;
    metrics.set_item("energy_j", k.energy_j)?;
    metrics.set_item("chatter_a", k.chatter_a)?;
    metrics.set_item("rms_force_n", k.rms_force_n)?;
    metrics.set_item("shimmy_s", k.shimmy_s)?;
    metrics.set_item("amp_end_rad", k.amp_end_rad)?;
    metrics.set_item("amp_max_rad", k.amp_max_rad)?;
    metrics.set_item("invalid_commands", r.faults.invalid_commands)?;
    out.set_item("metrics", metrics)?;
    out.set_item("sim_s", r.sim_s)?;
    out.set_item("wall_s", r.wall_s)?;
    Ok(out)
}

/// Runs `shimmy-sim analyze` on the log file `log` (CSV): the mapping file `mapping` (TOML, as
/// `--mapping`) with the keyword options on top (the command's `--time-column`, `--rate-hz`,
/// `--yaw-column`, `--yaw-left`/`--yaw-right`, `--yaw-unit`, `--yaw-gain`, `--speed-column`,
/// `--speed-unit`, `--time-unit`, `--delimiter`), `model = False` for `--data-only`. Returns
/// `rows` (dict of arrays at 100 Hz: t_s, speed_mps, zeta_slow, sigma_zeta_slow, freq_slow_hz,
/// slow_valid, zeta_fast, sigma_zeta_fast, freq_fast_hz, fast_valid, amplitude_rad, zeta_model,
/// speed_margin_mps, time_to_critical_s, model_consistent, level 0..3), `events` (list of
/// dicts), `summary` (dict; its `not_judged` says why the log cannot be judged when the meter
/// estimated nothing in it, else None) and `rejected_samples`.
#[pyfunction]
#[pyo3(signature = (log, vehicle = None, mapping = None, model = true, max_gap_ms = 20.0,
    delimiter = None, time_column = None, time_unit = None, rate_hz = None, yaw_column = None,
    yaw_left = None, yaw_right = None, yaw_unit = None, yaw_gain = None, speed_column = None,
    speed_unit = None))]
#[allow(clippy::too_many_arguments)]
fn analyze<'py>(
    py: Python<'py>,
    log: PathBuf,
    vehicle: Option<&Vehicle>,
    mapping: Option<PathBuf>,
    model: bool,
    max_gap_ms: f64,
    delimiter: Option<String>,
    time_column: Option<String>,
    time_unit: Option<String>,
    rate_hz: Option<f64>,
    yaw_column: Option<String>,
    yaw_left: Option<String>,
    yaw_right: Option<String>,
    yaw_unit: Option<String>,
    yaw_gain: Option<f64>,
    speed_column: Option<String>,
    speed_unit: Option<String>,
) -> PyResult<Bound<'py, PyDict>> {
    // any model the analysis takes (the car, the truck); it names the others it refuses
    let vehicle = vehicle.map_or_else(
        || ModelVehicle::from(core_vehicle::Vehicle::nominal()),
        |v| v.inner.clone(),
    );
    let changes = MappingChanges {
        delimiter,
        time_column,
        time_unit,
        rate_hz,
        yaw_column,
        yaw_left,
        yaw_right,
        yaw_unit,
        yaw_gain,
        speed_column,
        speed_unit,
    };
    let result = py
        .detach(|| -> anyhow::Result<Analysis> {
            let file = match &mapping {
                Some(p) => MappingChanges::load(p)?,
                None => MappingChanges::default(),
            };
            let map = file.then(&changes).mapping()?;
            let samples = log_file::load(&log, &map)?;
            let opts = AnalyzeOptions {
                vehicle,
                model,
                max_gap_s: max_gap_ms * 1e-3,
            };
            sim_analyze::analyze(&samples.samples, &opts)
                .with_context(|| format!("analysing {}", log.display()))
        })
        .map_err(value_error)?;
    let level = |l: Level| match l {
        Level::Normal => 0_i32,
        Level::MarginLow => 1,
        Level::ApproachingCritical => 2,
        Level::ShimmyPresent => 3,
    };
    fn column<'py, T: numpy::Element>(
        py: Python<'py>,
        rows: &[AnalysisRow],
        f: impl Fn(&AnalysisRow) -> T,
    ) -> Bound<'py, PyArray1<T>> {
        rows.iter().map(f).collect::<Vec<T>>().into_pyarray(py)
    }
    let r = &result.rows;
    let rows = PyDict::new(py);
    rows.set_item("t_s", column(py, r, |x| x.t_s))?;
    rows.set_item("speed_mps", column(py, r, |x| x.speed_mps))?;
    rows.set_item("zeta_slow", column(py, r, |x| x.zeta_slow))?;
    rows.set_item("sigma_zeta_slow", column(py, r, |x| x.sigma_zeta_slow))?;
    rows.set_item("freq_slow_hz", column(py, r, |x| x.freq_slow_hz))?;
    rows.set_item("slow_valid", column(py, r, |x| x.slow_valid))?;
    rows.set_item("zeta_fast", column(py, r, |x| x.zeta_fast))?;
    rows.set_item("sigma_zeta_fast", column(py, r, |x| x.sigma_zeta_fast))?;
    rows.set_item("freq_fast_hz", column(py, r, |x| x.freq_fast_hz))?;
    rows.set_item("fast_valid", column(py, r, |x| x.fast_valid))?;
    rows.set_item("amplitude_rad", column(py, r, |x| x.amplitude_rad))?;
    rows.set_item("zeta_model", column(py, r, |x| x.zeta_model))?;
    rows.set_item("speed_margin_mps", column(py, r, |x| x.speed_margin_mps))?;
    rows.set_item(
        "time_to_critical_s",
        column(py, r, |x| x.time_to_critical_s),
    )?;
    rows.set_item("model_consistent", column(py, r, |x| x.model_consistent))?;
    rows.set_item("level", column(py, r, |x| level(x.level)))?;
    let events = result
        .events
        .iter()
        .map(|e| {
            let d = PyDict::new(py);
            d.set_item("start_s", e.start_s)?;
            d.set_item("speed_mps", e.speed_mps)?;
            d.set_item("freq_hz", e.freq_hz)?;
            d.set_item("peak_amplitude_rad", e.peak_amplitude_rad)?;
            d.set_item("worst_level", level(e.worst))?;
            d.set_item("duration_s", e.duration_s)?;
            d.set_item("open", e.open)?;
            Ok(d)
        })
        .collect::<PyResult<Vec<_>>>()?;
    let s = result.summary();
    let summary = PyDict::new(py);
    summary.set_item("duration_s", s.duration_s)?;
    summary.set_item("valid_fraction", s.valid_fraction)?;
    summary.set_item("zeta_slow_min", s.zeta_slow_min)?;
    summary.set_item("zeta_slow_median", s.zeta_slow_median)?;
    summary.set_item("sigma_slow_median", s.sigma_slow_median)?;
    summary.set_item("freq_slow_median_hz", s.freq_slow_median_hz)?;
    summary.set_item("max_level", level(s.max_level))?;
    summary.set_item("episodes", s.episodes)?;
    summary.set_item("not_judged", result.not_judged())?;
    let out = PyDict::new(py);
    out.set_item("rows", rows)?;
    out.set_item("events", events)?;
    out.set_item("summary", summary)?;
    out.set_item("rejected_samples", result.rejected_samples)?;
    Ok(out)
}

/// The Python module `shimmy_sim` (the Rust function has another name: `shimmy_sim` is the
/// simulator crate's).
#[pymodule(name = "shimmy_sim")]
fn python_module(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<Vehicle>()?;
    m.add_function(wrap_pyfunction!(field_table, m)?)?;
    m.add_function(wrap_pyfunction!(hopf_window, m)?)?;
    m.add_function(wrap_pyfunction!(eigen_sweep, m)?)?;
    m.add_function(wrap_pyfunction!(run_scenario, m)?)?;
    m.add_function(wrap_pyfunction!(run_scenario_toml, m)?)?;
    m.add_function(wrap_pyfunction!(analyze, m)?)?;
    Ok(())
}
