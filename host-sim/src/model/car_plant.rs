//! The 4-DOF car (`car-4dof`, `shimmy_core::vehicles::car`) in the simulator: its nonlinear
//! plant ([`Simulator`], `super::plant`) as a member of the family (`super::family`), in the
//! registry (`super::registry`), the studies (`super::study`) and on the board
//! (`super::board`, the firmware's default image).

use anyhow::{bail, Result};
use shimmy_core::control::smc::NominalPlant;
use shimmy_core::model::LinearModel;
use shimmy_core::vehicle::Vehicle;
use shimmy_core::vehicles::car::{Param, ParamSet, PlantParams};
use shimmy_firmware::monitoring::BoardCalibration;

use super::family::{param_names, FamilyVehicle, ParamInfo, SimModel, SimPlant};
use super::integrator::IntegrateError;
use super::plant::{idx, Damper, Inputs, Method, Plant, Simulator, State, N_STATE, STATE_NAMES};

impl SimPlant for Simulator {
    fn set_wheel_yaw(&mut self, psi_l_rad: f64, psi_r_rad: f64) {
        let mut x = [0.0; N_STATE];
        x[idx::PSI_L] = psi_l_rad;
        x[idx::PSI_R] = psi_r_rad;
        Simulator::set_state(self, x);
    }

    fn set_state(&mut self, x: &[f64]) {
        let mut s = [0.0; N_STATE];
        s.copy_from_slice(x);
        Simulator::set_state(self, s);
    }

    fn advance(&mut self, dt_s: f64, inputs: &Inputs) -> Result<(), IntegrateError> {
        Simulator::advance(self, dt_s, inputs)
    }

    fn wheel_yaw_rad(&self) -> [f64; 2] {
        let x = Simulator::state(self);
        [x[idx::PSI_L], x[idx::PSI_R]]
    }

    fn steering_angle_rad(&self) -> f64 {
        Simulator::state(self)[idx::THETA_SW]
    }

    fn coil_input_a(&self) -> f64 {
        match self.plant().damper {
            Damper::Mr(_) => Simulator::state(self)[idx::U],
            _ => 0.0,
        }
    }

    fn damper_force_n(&self, inputs: &Inputs) -> f64 {
        self.forces(inputs).damper_n
    }

    fn state(&self) -> &[f64] {
        Simulator::state(self)
    }

    fn state_names(&self) -> &'static [&'static str] {
        &STATE_NAMES
    }

    fn time_s(&self) -> f64 {
        Simulator::time_s(self)
    }

    fn vector_field(&self, x: &[f64], inputs: &Inputs, dx: &mut [f64]) {
        let mut s = [0.0; N_STATE];
        s.copy_from_slice(x);
        let mut d = [0.0; N_STATE];
        self.plant().rhs(&s, inputs, &mut d);
        dx.copy_from_slice(&d);
    }
}

impl SimModel<{ shimmy_core::vehicles::car::N_STATES }> for PlantParams {
    type Linear = PlantParams;
    type Plant = Simulator;
    type State = State;
    type Vehicle = Vehicle;
    const STEERING: &'static str = "wheel";

    fn family_vehicle(v: &Vehicle) -> FamilyVehicle<Self> {
        FamilyVehicle::car(*v)
    }

    fn parts_mut(v: &mut Vehicle) -> &mut Vehicle {
        v
    }

    fn linear(&self) -> Self {
        *self
    }

    fn plant(&self, damper: Damper, method: Method) -> Simulator {
        Simulator::with_method(Plant::new(*self, damper), [0.0; N_STATE], method)
    }

    fn rolling_radius_m(&self) -> f64 {
        self.r
    }

    fn steering_arm_m(&self) -> f64 {
        self.l_t
    }

    fn nominal_plant(&self) -> NominalPlant {
        NominalPlant::from_params(self)
    }

    fn host_app_model(&self) -> Option<(PlantParams, f32)> {
        Some((*self, Vehicle::with_plant(*self).wheel_order_radius_m()))
    }

    fn yaw_torque_scale(&self) -> f64 {
        1.0
    }

    fn params() -> Vec<ParamInfo> {
        Param::ALL
            .iter()
            .map(|p| ParamInfo {
                name: p.name(),
                unit: p.unit(),
            })
            .collect()
    }

    fn param(&self, name: &str) -> Option<f64> {
        Param::from_name(name).map(|p| self.get(p))
    }

    fn with_param(&self, name: &str, value: f64) -> Result<Self> {
        match Param::from_name(name) {
            Some(p) => Ok(self.with(p, value)),
            None => bail!(
                "parameter `{name}`: no such parameter of {}, allowed: {}",
                PlantParams::NAME,
                param_names::<Self, { shimmy_core::vehicles::car::N_STATES }>()
            ),
        }
    }
}

/// The car in the registry (`super::registry`): its vehicle is the core's whole [`Vehicle`],
/// its files the core's vehicle files (the `[plant]` section and the shared ones).
impl super::registry::ModelEntry<{ shimmy_core::vehicles::car::N_STATES }> for PlantParams {
    type File = Vehicle;
    const SECTION: Option<&'static str> = None;
    const SHARED_SECTIONS: bool = true;
    const DEFAULT_SET: &'static str = ParamSet::Nominal.name();

    fn set_names() -> Vec<&'static str> {
        ParamSet::ALL.iter().map(|s| s.name()).collect()
    }
    fn set(name: &str) -> Option<Self> {
        ParamSet::from_name(name).map(ParamSet::params)
    }
    fn named(name: &str) -> Option<Result<Vehicle>> {
        ParamSet::from_name(name).map(|s| Ok(Vehicle::from_set(s)))
    }
    fn assemble(model: Self, parts: Option<Vehicle>) -> Result<Vehicle> {
        Ok(Vehicle {
            plant: model,
            ..parts.unwrap_or_else(Vehicle::nominal)
        })
    }
    fn fields() -> &'static [shimmy_core::vehicles::ModelField] {
        &[]
    }
    fn field(&self, _name: &str) -> Option<f64> {
        None
    }
    fn set_field(
        &mut self,
        _name: &str,
        _value: f64,
    ) -> std::result::Result<(), shimmy_core::vehicles::FieldError> {
        Err(shimmy_core::vehicles::FieldError::Unknown)
    }
    fn check(&self) -> std::result::Result<(), String> {
        self.validate()
            .map_err(|(p, x)| format!("field `{}`: {x} is out of range", p.name()))
    }
    fn model_of(f: &Vehicle) -> Self {
        f.plant
    }
    fn model_mut(f: &mut Vehicle) -> &mut Self {
        &mut f.plant
    }
    fn parts_of(f: &Vehicle) -> Option<&Vehicle> {
        Some(f)
    }
    fn parts_of_mut(f: &mut Vehicle) -> Option<&mut Vehicle> {
        Some(f)
    }
    fn vehicle(f: Vehicle) -> Result<Vehicle> {
        Ok(f)
    }
    fn file_of(v: &Vehicle) -> Vehicle {
        *v
    }
    fn with_params(v: &Vehicle, model: Self) -> Vehicle {
        Vehicle { plant: model, ..*v }
    }
}

/// The car in the studies (`super::study`).
impl super::study::StudyModel<{ shimmy_core::vehicles::car::N_STATES }> for PlantParams {
    const DRIVER_TORQUE: bool = true;
    const SCENARIO_DIR: &'static str = "";

    fn single_variants(&self, f: f64) -> Result<Vec<(&'static str, Self)>> {
        let groups: [(&str, &[Param]); 6] = [
            ("C_a", &[Param::CA]),
            ("sigma", &[Param::Sigma]),
            ("K_d", &[Param::KD]),
            ("e", &[Param::E]),
            ("t_p", &[Param::TP]),
            ("load (F_z, C_a)", &[Param::FZ, Param::CA]),
        ];
        Ok(groups
            .iter()
            .map(|&(name, ps)| (name, ps.iter().fold(*self, |p, &q| p.scaled(q, f))))
            .collect())
    }

    fn other_plants() -> Vec<(String, Self)> {
        [ParamSet::Hard, ParamSet::Gentle]
            .iter()
            .map(|s| (format!("`{}` plant", s.name()), s.params()))
            .collect()
    }

    fn robustness_variants(&self) -> Result<Vec<(String, Self)>> {
        let mut v = vec![("hard".to_string(), self.scaled(Param::KD, 0.5))];
        for q in [Param::CA, Param::Sigma, Param::E] {
            for f in [0.8, 1.2] {
                v.push((
                    format!("{}{:+.0}%", q.name(), (f - 1.0) * 100.0),
                    self.scaled(q, f),
                ));
            }
        }
        Ok(v)
    }

    fn meter_speeds_kmh() -> (&'static [f64], &'static [f64]) {
        (
            &[10.0, 20.0, 90.0, 105.0, 120.0],
            &[10.0, 40.0, 60.0, 90.0, 120.0],
        )
    }
}

/// The car's firmware image (the default build): its stored vehicle is the core's whole
/// [`Vehicle`]; its simulated device drives the demo's ramp with its pothole to 120 km/h.
impl super::board::BoardModel<{ shimmy_core::vehicles::car::N_STATES }> for PlantParams {
    type Board = Vehicle;
    const PIL_ELF: &'static str = "target/xtask/shimmy-firmware.pil.elf";
    const DEVICE_TOP_KMH: f64 = 120.0;
    const DEVICE_POTHOLE: bool = true;
    fn board_vehicle(v: &FamilyVehicle<Self>) -> Vehicle {
        Vehicle {
            plant: v.model,
            ..v.parts
        }
    }
    fn from_board(b: &Vehicle) -> Vehicle {
        *b
    }
}

impl FamilyVehicle<PlantParams> {
    /// The car `v`: its plant is the model.
    pub fn car(v: Vehicle) -> Self {
        Self {
            model: v.plant,
            parts: v,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The family's car plant is the car's simulator unchanged: the same state after the same
    /// inputs, bit for bit, as `Simulator` driven directly.
    #[test]
    fn the_cars_family_plant_is_its_simulator() {
        let p = ParamSet::Nominal.params();
        let mut a = p.plant(
            Damper::Mr(shimmy_core::mr_damper::SpencerParams::steering()),
            Method::default(),
        );
        a.set_wheel_yaw(0.01, 0.01);
        let mut b = Simulator::new(
            Plant::with_mr_damper(p),
            crate::model::disturbance::initial_yaw(0.01),
        );
        let u = Inputs {
            current_cmd_a: 0.5,
            speed_mps: 15.0,
            ..Inputs::default()
        };
        for _ in 0..200 {
            SimPlant::advance(&mut a, 1e-3, &u).unwrap();
            b.advance(1e-3, &u).unwrap();
        }
        assert_eq!(SimPlant::state(&a), &b.state()[..]);
        assert_eq!(a.damper_force_n(&u), b.forces(&u).damper_n);
    }
}
