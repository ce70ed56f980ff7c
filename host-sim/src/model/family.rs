//! The vehicle-model family in the simulator: what a command needs of a vehicle model, so that
//! it is written once for every model (`/docs/architecture.md`, "Vehicle models").
//!
//! The core's [`LinearModel`] is the linear side (A(V), dA/dV, the damper's input column, the
//! wheel-yaw output, the mode shapes: eigenvalues, Hopf crossings, sensitivities and the
//! model-margin tracker run on it). [`SimModel`] adds the simulator's side: the nonlinear plant
//! ([`SimPlant`]: stepped one control period at a time with the MR damper's coil current, the
//! speed and the disturbances' kingpin yaw torques as held [`Inputs`], the measured wheel yaw
//! angles out; its right-hand side at held inputs for `super::hopf_type`, with
//! [`SimModel::non_smooth`] saying when it has no third derivatives), the wheel's rolling radius (the mode meter's wheel order), the damper's lever,
//! what the controller's model needs (I_k, c_k, l_t) and the parameters by name (sweeps).
//!
//! Members: each model implements [`LinearModel`] in its core folder and [`SimModel`] in its
//! plant file (the car's `super::plant`, the mining truck's `super::truck_plant`, ...); `bifurcation`, `sweep` (eigenvalue maps), `margin` and the closed loop
//! are generic over `M: SimModel<N>`; a command dispatches on the vehicle file's model
//! (`sim::vehicle_file::ModelVehicle`).

use anyhow::Result;
use shimmy_core::control::smc::NominalPlant;
use shimmy_core::control::ControlParams;
use shimmy_core::estimator::pipeline::PipelineParams;
use shimmy_core::model::{LinearModel, UpdatableModel};
use shimmy_core::supervisor::params::SupervisorParams;
use shimmy_core::vehicle::Vehicle;
use shimmy_core::vehicles::{FieldError, FieldTable};

use super::integrator::IntegrateError;
use super::plant::{Damper, Inputs, Method};

/// A vehicle model as the simulator runs it; `N` is the state count of its linear model.
pub trait SimModel<const N: usize>: Copy + Send + Sync + std::fmt::Debug + 'static {
    /// The core's linear model (eigenvalues, Hopf crossings, the model-margin tracker).
    type Linear: UpdatableModel<N> + Copy + Send + Sync + std::fmt::Debug + 'static;
    /// The nonlinear plant in time.
    type Plant: SimPlant + Clone + Send;

    /// The linear model of this vehicle.
    fn linear(&self) -> Self::Linear;

    /// The simulated state (the plant's and the damper's), e.g. `[f64; 13]` for the car: the
    /// closed loop's initial state (all zero by default; a kick sets the wheel yaw angles,
    /// which are the first two entries of every model).
    type State: AsRef<[f64]> + AsMut<[f64]> + Copy + Default + std::fmt::Debug + Send + Sync;
    /// The whole vehicle of this model as a vehicle file gives it (the car: the core's
    /// [`Vehicle`]; another model: [`FamilyVehicle`]).
    type Vehicle: Copy + std::fmt::Debug + PartialEq + Send + Sync;

    /// What the steering DOF of [`SimPlant::steering_angle_rad`] is, after "steering" in
    /// tables (the car: `wheel`; the truck: `linkage`).
    const STEERING: &'static str;

    /// The state at rest with the measured yaw at `psi_rad` (a kick): both wheel yaw angles,
    /// the first two states, unless the model says otherwise (the trailer's one yaw is not
    /// first).
    fn kick_state(psi_rad: f64) -> Self::State {
        let mut x = Self::State::default();
        x.as_mut()[0] = psi_rad;
        x.as_mut()[1] = psi_rad;
        x
    }

    /// The vehicle as the model's parameters and the shared sections.
    fn family_vehicle(v: &Self::Vehicle) -> FamilyVehicle<Self>;

    /// The shared sections of `v` (damper, sensors, gains, thresholds), to set fields in.
    fn parts_mut(v: &mut Self::Vehicle) -> &mut Vehicle;

    /// The nonlinear plant at rest with `damper` on the track rod, integrated by `method`
    /// (a model may have one integrator only and take `method`'s tolerance); the parameters
    /// are a validated vehicle's.
    fn plant(&self, damper: Damper, method: Method) -> Self::Plant;

    /// Loaded rolling radius, m (the wheel order of the mode meter, the imbalance).
    fn rolling_radius_m(&self) -> f64;

    /// Steering-arm length l_t, m: the damper's stroke is `(l_t/2)(psi_L + psi_R)`.
    fn steering_arm_m(&self) -> f64;

    /// The controller's nominal plant (I_k, c_k, l_t: the ASMC's model).
    fn nominal_plant(&self) -> NominalPlant;

    /// The linear model the host build of the firmware's application (`shimmy_firmware::pil::
    /// HostApp`) runs its model task on and the rolling radius its meter's wheel order takes
    /// (`shimmy_firmware::monitoring::BoardCalibration`), if the firmware is built for this
    /// model (the car; the mining truck, cargo feature `model-truck`). `None`: no board image
    /// for this model, so no margin report in the closed loop (the margin-scheduled
    /// controller is not available).
    fn host_app_model(&self) -> Option<(Self::Linear, f32)>;

    /// Factor on the kingpin yaw torques of a scenario's disturbances (road noise, imbalance,
    /// potholes, kicks), which scenario files give for the car: the road acts through the
    /// tyre's lateral force at its trail, so the factor is the ratio of this model's tyre yaw
    /// stiffness `(e + t_p) C_a` to that of the car's `nominal` set (the same slip disturbance;
    /// 1 for the car).
    fn yaw_torque_scale(&self) -> f64;

    /// The parameters a sweep can vary (with [`Self::param`], [`Self::with_param`]): name and
    /// unit.
    fn params() -> Vec<ParamInfo>;

    /// The value of the parameter `name`, if there is one.
    fn param(&self, name: &str) -> Option<f64>;

    /// A copy with the parameter `name` set to `value`, or an error naming it and its range.
    fn with_param(&self, name: &str, value: f64) -> Result<Self>;

    /// The speeds its damper is sized over (lowest, highest), km/h: the road vehicles' 1-150.
    const SIZING_SPEEDS_KMH: (f64, f64) = (1.0, 150.0);

    /// What keeps the plant's right-hand side with `damper` from being three times
    /// differentiable at straight running, if anything (the Hopf type needs its third
    /// derivatives, `super::hopf_type`): by default the MR damper (the Bouc-Wen `|z|` terms).
    fn non_smooth(&self, damper: &Damper) -> Option<&'static str> {
        matches!(damper, Damper::Mr(_)).then_some("MR damper: Bouc-Wen |z|")
    }
}

/// A parameter of a model by name, for axes and tables.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ParamInfo {
    /// Field name (as in the vehicle file).
    pub name: &'static str,
    /// SI unit (`-` for none).
    pub unit: &'static str,
}

/// The names of `M`'s parameters, comma separated (for messages).
pub fn param_names<M: SimModel<N>, const N: usize>() -> String {
    M::params()
        .iter()
        .map(|p| p.name)
        .collect::<Vec<_>>()
        .join(", ")
}

/// The parameters of a model whose sweepable parameters are its field table
/// ([`SimModel::params`] of the truck, the trailer, the dual-axle truck).
pub fn table_params<M: FieldTable>() -> Vec<ParamInfo> {
    M::FIELDS
        .iter()
        .map(|f| ParamInfo {
            name: f.name,
            unit: f.unit,
        })
        .collect()
}

/// `m` with its field-table parameter `name` set to `value` ([`SimModel::with_param`] of such
/// a model): an unknown name is refused with the model's parameters, a value out of range
/// with the field's allowed range.
pub fn with_table_param<M: SimModel<N> + FieldTable, const N: usize>(
    m: &M,
    name: &str,
    value: f64,
) -> Result<M> {
    let mut t = *m;
    match t.set(name, value) {
        Ok(()) => Ok(t),
        Err(FieldError::Unknown) => anyhow::bail!(
            "parameter `{name}`: no such parameter of {}, allowed: {}",
            <M::Linear as LinearModel<N>>::NAME,
            param_names::<M, N>()
        ),
        Err(e) => anyhow::bail!("{}", e.to_string().replacen("field `", "parameter `", 1)),
    }
}

/// The state of `M` at rest with its measured yaw at `psi_rad` (both wheels in phase:
/// [`SimModel::kick_state`]).
pub fn yaw_state<M: SimModel<N>, const N: usize>(psi_rad: f64) -> M::State {
    M::kick_state(psi_rad)
}

/// A vehicle's nonlinear plant, one control period at a time (inputs held).
pub trait SimPlant {
    /// Puts the plant at rest with the wheels at yaw `psi_l_rad`, `psi_r_rad` (a kick).
    fn set_wheel_yaw(&mut self, psi_l_rad: f64, psi_r_rad: f64);
    /// Replaces the whole state (the model's [`SimModel::State`] as a slice).
    fn set_state(&mut self, x: &[f64]);
    /// Advances by `dt_s` with `inputs` held (zero-order hold).
    fn advance(&mut self, dt_s: f64, inputs: &Inputs) -> Result<(), IntegrateError>;
    /// The wheel yaw angles `[psi_L, psi_R]`, rad: what the encoders measure.
    fn wheel_yaw_rad(&self) -> [f64; 2];
    /// The `[psi_L, psi_R]` pair the mode meter is fed (it reads their mean): the model's
    /// measured output row ([`LinearModel::wheel_yaw_output`]) applied to the state, as a pair
    /// of equal angles where that row is not one axle's two wheels. By default the wheel yaw
    /// angles themselves ([`Self::wheel_yaw_rad`]).
    fn meter_yaw_rad(&self) -> [f64; 2] {
        self.wheel_yaw_rad()
    }
    /// The steering angle of the model's steering DOF (the car: the steering wheel; the
    /// truck: the hydraulic linkage at the kingpin), rad.
    fn steering_angle_rad(&self) -> f64;
    /// The damper's filtered coil input (1 V per A), A; 0 without an MR damper.
    fn coil_input_a(&self) -> f64;
    /// The damper force at the current state under `inputs`, N.
    fn damper_force_n(&self, inputs: &Inputs) -> f64;
    /// The whole simulated state (model order, the damper's states last).
    fn state(&self) -> &[f64];
    /// Names of [`Self::state`]'s entries, for CSV headers.
    fn state_names(&self) -> &'static [&'static str];
    /// Simulated time, s.
    fn time_s(&self) -> f64;
    /// The right-hand side dx/dt at the whole state `x` ([`Self::state`]'s order) under
    /// `inputs` held: what [`Self::advance`] integrates (the plant's own state is not used).
    fn vector_field(&self, x: &[f64], inputs: &Inputs, dx: &mut [f64]);
}

/// A vehicle of the model `M`: the model's parameters and the sections every model shares, in
/// a core [`Vehicle`] (the damper and the firmware's model of it, the sensors, the controller's
/// gains, the warning thresholds and the fusion). For a model other than the car the
/// `parts.plant` is not used: the controller's nominal plant comes from the model
/// ([`SimModel::nominal_plant`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FamilyVehicle<M> {
    /// The vehicle model's parameters.
    pub model: M,
    /// The damper, sensors, gains and thresholds.
    pub parts: Vehicle,
}

impl<M> FamilyVehicle<M> {
    /// The controller's parameters: [`Vehicle::control_params`] with the model's nominal plant.
    pub fn control_params<const N: usize>(&self) -> ControlParams
    where
        M: SimModel<N>,
    {
        self.parts.control_params_with(self.model.nominal_plant())
    }

    /// The supervisor's thresholds ([`Vehicle::supervisor_params_for`] on the model).
    pub fn supervisor_params<const N: usize>(&self) -> SupervisorParams
    where
        M: SimModel<N>,
    {
        self.parts.supervisor_params_for(&self.model.linear())
    }

    /// The margin pipeline's parameters ([`Vehicle::pipeline_params`]; its model is
    /// [`Self::model`]), the mode meter slowed to the model's mode
    /// ([`LinearModel::meter_time_scale`]).
    pub fn pipeline_params<const N: usize>(&self) -> PipelineParams
    where
        M: SimModel<N>,
    {
        self.parts.pipeline_params_for(&self.model.linear())
    }
}

/// The linear onset speed of `p` without damper by a 0.5 km/h scan + Brent (independent of the
/// pipeline's incremental search).
pub fn onset_kmh<M: LinearModel<N>, const N: usize>(p: &M) -> Option<f64> {
    shimmy_core::stability::hopf_crossings(
        p,
        0.0,
        shimmy_core::units::kmh_to_mps(1.0),
        shimmy_core::units::kmh_to_mps(150.0),
        shimmy_core::units::kmh_to_mps(0.5),
        shimmy_core::stability::DEFAULT_TOL_MPS,
    )
    .ok()?
    .iter()
    .find(|c| c.kind == shimmy_core::stability::CrossingKind::Onset)
    .map(|c| shimmy_core::units::mps_to_kmh(c.speed_mps))
}
