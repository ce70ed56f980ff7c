//! The members of the vehicle-model family in the simulator ([`super::family`]): the car
//! (`PlantParams`, its plant the car's [`Simulator`]) and the mining truck (`TruckParams`, its
//! plant [`TruckPlant`]), and the truck's default shared sections (its damper sized as the
//! car's).

use anyhow::{bail, Result};
use shimmy_core::control::smc::NominalPlant;
use shimmy_core::model::LinearModel;
use shimmy_core::stability::{hopf_crossings, CrossingKind};
use shimmy_core::units::kmh_to_mps;
use shimmy_core::vehicle::Vehicle;
use shimmy_core::vehicles::car::{Param, ParamSet, PlantParams};
use shimmy_core::vehicles::truck::board::TruckVehicle;
use shimmy_core::vehicles::truck::{TruckParams, TruckSet, TRUCK_FIELDS};
use shimmy_core::vehicles::FieldTable;
use shimmy_firmware::monitoring::BoardCalibration;

use super::damper_equiv::damper_equivalent;
use super::family::{param_names, FamilyVehicle, ParamInfo, SimModel, SimPlant};
use super::integrator::IntegrateError;
use super::plant::{idx, Damper, Inputs, Method, Plant, Simulator, STATE_NAMES};
use super::truck_plant::TruckPlant;

impl SimPlant for Simulator {
    fn set_wheel_yaw(&mut self, psi_l_rad: f64, psi_r_rad: f64) {
        let mut x = [0.0; super::plant::N_STATE];
        x[idx::PSI_L] = psi_l_rad;
        x[idx::PSI_R] = psi_r_rad;
        Simulator::set_state(self, x);
    }

    fn set_state(&mut self, x: &[f64]) {
        let mut s = [0.0; super::plant::N_STATE];
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
        let mut s = [0.0; super::plant::N_STATE];
        s.copy_from_slice(x);
        let mut d = [0.0; super::plant::N_STATE];
        self.plant().rhs(&s, inputs, &mut d);
        dx.copy_from_slice(&d);
    }
}

/// The tyre yaw stiffness `(e + t_p) C_a` the scenario files' disturbances are written for (the
/// car's `nominal` set), N m/rad.
pub fn reference_tyre_yaw_stiffness() -> f64 {
    let p = ParamSet::Nominal.params();
    (p.e + p.t_p) * p.c_a
}

impl SimModel<{ shimmy_core::vehicles::car::N_STATES }> for PlantParams {
    type Linear = PlantParams;
    type Plant = Simulator;
    type State = super::plant::State;
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
        Simulator::with_method(
            Plant::new(*self, damper),
            [0.0; super::plant::N_STATE],
            method,
        )
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

impl SimModel<{ shimmy_core::vehicles::truck::N_STATES }> for TruckParams {
    type Linear = TruckParams;
    type Plant = TruckPlant;
    type State = [f64; super::truck_plant::N_SIM];
    type Vehicle = FamilyVehicle<TruckParams>;
    const STEERING: &'static str = "linkage";

    fn family_vehicle(v: &Self::Vehicle) -> FamilyVehicle<Self> {
        *v
    }

    fn parts_mut(v: &mut Self::Vehicle) -> &mut Vehicle {
        &mut v.parts
    }

    fn linear(&self) -> Self {
        *self
    }

    /// The truck has one integrator (Dopri5); it takes `method`'s relative tolerance (1e-7
    /// for the fixed-step methods).
    fn plant(&self, damper: Damper, method: Method) -> TruckPlant {
        let rtol = match method {
            Method::Dopri5 { rtol } | Method::Imex { rtol } | Method::Vern65 { rtol } => rtol,
            Method::Rk4 { .. } | Method::ImexFixed { .. } => 1e-7,
        };
        TruckPlant::new(self, damper, rtol)
    }

    fn rolling_radius_m(&self) -> f64 {
        self.r
    }

    fn steering_arm_m(&self) -> f64 {
        self.l_t
    }

    fn nominal_plant(&self) -> NominalPlant {
        TruckParams::nominal_plant(self)
    }

    fn yaw_torque_scale(&self) -> f64 {
        (self.e + self.t_p) * self.point_or_tyres_only().c_a / reference_tyre_yaw_stiffness()
    }

    fn host_app_model(&self) -> Option<(TruckParams, f32)> {
        let board = TruckVehicle {
            truck: *self,
            parts: truck_parts(),
        };
        Some((*self, board.wheel_order_radius_m()))
    }

    fn params() -> Vec<ParamInfo> {
        TRUCK_FIELDS
            .iter()
            .map(|f| ParamInfo {
                name: f.name,
                unit: f.unit,
            })
            .collect()
    }

    fn param(&self, name: &str) -> Option<f64> {
        self.get(name)
    }

    fn with_param(&self, name: &str, value: f64) -> Result<Self> {
        let mut t = *self;
        match t.set(name, value) {
            Ok(()) => Ok(t),
            Err(shimmy_core::vehicles::FieldError::Unknown) => bail!(
                "parameter `{name}`: no such parameter of {}, allowed: {}",
                TruckParams::NAME,
                param_names::<Self, { shimmy_core::vehicles::truck::N_STATES }>()
            ),
            Err(e) => bail!("{}", e.to_string().replacen("field `", "parameter `", 1)),
        }
    }
}

/// The least viscous track-rod damper coefficient that leaves `m` without a Hopf onset from 1
/// to 150 km/h, N s/m (0 when it has none without a damper; bisection to 0.1 %); `None` when
/// no coefficient up to 1e9 N s/m does.
pub fn least_stabilising_c<M: LinearModel<N>, const N: usize>(m: &M) -> Option<f64> {
    let unstable = |c: f64| {
        hopf_crossings(
            m,
            c,
            kmh_to_mps(1.0),
            kmh_to_mps(150.0),
            kmh_to_mps(0.5),
            1e-3,
        )
        .map_or(true, |cs| cs.iter().any(|x| x.kind == CrossingKind::Onset))
    };
    if !unstable(0.0) {
        return Some(0.0);
    }
    let mut hi = 1.0;
    while unstable(hi) {
        hi *= 2.0;
        if hi > 1e9 {
            return None;
        }
    }
    let mut lo = 0.5 * hi;
    while hi - lo > 1e-3 * hi {
        let mid = 0.5 * (lo + hi);
        if unstable(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(hi)
}

/// The truck's steering damper against the car's, as a factor on every force coefficient of
/// the car's reference damper: the truck's damper is sized as the car's is, so that its
/// energy-equivalent viscous coefficient at the rated current (describing function at the
/// default 0.5 deg, [`damper_equivalent`]) is the same multiple of the least coefficient that
/// closes the Hopf window ([`least_stabilising_c`]) as the car's (the `nominal` car and the
/// loaded truck, `truck-full`, the worst case). The Spencer model's force is linear in its
/// force coefficients (the Bouc-Wen and internal displacements do not change), so the factor is
/// exact at that amplitude; `docs/mining-truck.md` gives the figures.
pub fn truck_damper_scale() -> Result<f64> {
    static SCALE: std::sync::OnceLock<std::result::Result<f64, String>> =
        std::sync::OnceLock::new();
    SCALE
        .get_or_init(|| compute_truck_damper_scale().map_err(|e| format!("{e:#}")))
        .clone()
        .map_err(|e| anyhow::anyhow!(e))
}

fn compute_truck_damper_scale() -> Result<f64> {
    damper_scale_like_the_cars(&TruckSet::Full.params())
}

/// The factor on the car's reference damper that sizes it for `model` as the car's is sized
/// for the `nominal` car: its energy-equivalent viscous coefficient at the rated current
/// (describing function at the default 0.5 deg, [`damper_equivalent`]) the same multiple of
/// the least coefficient that closes `model`'s Hopf window ([`least_stabilising_c`]).
pub fn damper_scale_like_the_cars<M: SimModel<N>, const N: usize>(model: &M) -> Result<f64> {
    let car = Vehicle::from_set(ParamSet::Nominal);
    let sp = car.damper.spencer;
    let rated = sp.u_max;
    let (v0, v1) = (kmh_to_mps(1.0), kmh_to_mps(150.0));
    let amp_deg = super::damper_equiv::REF_WHEEL_YAW_AMPL_RAD.to_degrees();
    let ceq_car = damper_equivalent(&car.plant, &sp, rated, amp_deg, v0, v1)?.c_eq_nspm;
    let ceq_m = damper_equivalent(model, &sp, rated, amp_deg, v0, v1)?.c_eq_nspm;
    let (Some(c_car), Some(c_m)) = (
        least_stabilising_c(&car.plant),
        least_stabilising_c(&model.linear()),
    ) else {
        bail!("damper sizing: no viscous damper closes a Hopf window");
    };
    if c_car <= 0.0 || ceq_m <= 0.0 {
        bail!("damper sizing: the car has no Hopf window to size against");
    }
    Ok((ceq_car / c_car) * c_m / ceq_m)
}

/// The truck's shared sections by default: the car's reference damper, sensors, gains and
/// thresholds with every force coefficient of the damper (the Spencer model's and the firmware's
/// Bingham model's) and the skyhook coefficient scaled by [`truck_damper_scale`]. The coil,
/// its rating and the sensors are the car's (the larger damper has a larger piston and gap,
/// not another coil); the ASMC's gains are angular accelerations of the wheel, its force comes
/// from the nominal plant's 2 I_k / l_t; the warning thresholds are the truck's own
/// ([`TruckParams::warning_thresholds`]).
///
/// The core keeps the factor as
/// [`TRUCK_DAMPER_SCALE`](shimmy_core::vehicles::truck::board::TRUCK_DAMPER_SCALE) (the truck image's
/// compiled-in vehicle is built from it); the test
/// `the_cores_truck_damper_scale_is_the_computed_one` holds the two equal.
pub fn truck_parts() -> Vehicle {
    TruckVehicle::default_parts()
}

/// The car's reference shared sections with every force coefficient of the damper (the
/// Spencer model's and the firmware's Bingham model's) and the skyhook coefficient times `s`.
pub fn car_parts_with_damper_scaled(s: f64) -> Vehicle {
    Vehicle::from_set(ParamSet::Nominal).with_damper_scaled(s)
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

#[cfg(test)]
mod tests {
    use super::*;
    use shimmy_core::vehicles::truck::TruckSet;

    /// The truck's default damper is sized as the car's: at the rated current its c_eq is the
    /// same multiple of the least stabilising coefficient; and, checked on the eigenvalues
    /// (independent of the sizing rule), the loaded truck keeps a Hopf window with the damper
    /// at 0 A and none at the rated current, as the car does.
    #[test]
    fn the_trucks_damper_is_sized_as_the_cars() {
        let car = Vehicle::from_set(ParamSet::Nominal);
        let truck = TruckSet::Full.params();
        let parts = truck_parts();
        let (v0, v1) = (kmh_to_mps(1.0), kmh_to_mps(150.0));
        let deg = crate::model::damper_equiv::REF_WHEEL_YAW_AMPL_RAD.to_degrees();
        let car_2a = damper_equivalent(&car.plant, &car.damper.spencer, 2.0, deg, v0, v1).unwrap();
        let truck_2a = damper_equivalent(&truck, &parts.damper.spencer, 2.0, deg, v0, v1).unwrap();
        let truck_0a = damper_equivalent(&truck, &parts.damper.spencer, 0.0, deg, v0, v1).unwrap();
        let (c_car, c_truck) = (
            least_stabilising_c(&car.plant).unwrap(),
            least_stabilising_c(&truck).unwrap(),
        );
        println!(
            "scale {:.3}; least stabilising c: car {c_car:.1}, truck {c_truck:.1} N s/m; c_eq at \
             2 A: car {:.1}, truck {:.1} N s/m; truck at 0 A {:.1} N s/m",
            truck_damper_scale().unwrap(),
            car_2a.c_eq_nspm,
            truck_2a.c_eq_nspm,
            truck_0a.c_eq_nspm
        );
        // linear in the force factor at a fixed frequency; the describing function's second
        // pass takes the frequency of the mode with the damper in place, which the larger
        // damper moves a little: 1 %
        let (r_truck, r_car) = (truck_2a.c_eq_nspm / c_truck, car_2a.c_eq_nspm / c_car);
        assert!((r_truck / r_car - 1.0).abs() < 0.01, "{r_truck} {r_car}");
        let onsets = |c: f64| {
            hopf_crossings(&truck, c, v0, v1, kmh_to_mps(0.5), 1e-3)
                .unwrap()
                .iter()
                .filter(|x| x.kind == CrossingKind::Onset)
                .count()
        };
        assert!(onsets(truck_0a.c_eq_nspm) > 0);
        assert_eq!(onsets(truck_2a.c_eq_nspm), 0);
        // the firmware's damper model is scaled with the simulator's
        let s = truck_damper_scale().unwrap() as f32;
        assert_eq!(
            parts.damper.model.c_b_ns_per_m_a,
            car.damper.model.c_b_ns_per_m_a * s
        );
        parts.validate().unwrap();
    }

    /// The core's compiled-in factor (the truck image's default vehicle) is the sizing
    /// computed here, within the describing function's accuracy (1e-6 against a ten times finer
    /// grid, `damper_equiv`): a closer check would tie the firmware to the integration grid.
    #[test]
    fn the_cores_truck_damper_scale_is_the_computed_one() {
        use shimmy_core::vehicles::truck::board::TRUCK_DAMPER_SCALE;
        let computed = truck_damper_scale().unwrap();
        assert!(
            (TRUCK_DAMPER_SCALE / computed - 1.0).abs() < 1e-6,
            "core {TRUCK_DAMPER_SCALE:?}, computed {computed:?}: update TRUCK_DAMPER_SCALE"
        );
    }

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

    /// The truck's plant with a viscous damper decays or grows at the rate of the linear
    /// model's shimmy mode with the same damper coefficient (small motion: the nonlinear
    /// elements are their linearisation), and its MR damper's force opposes the stroke rate.
    #[test]
    fn the_trucks_family_plant_follows_its_linear_model_with_a_damper() {
        use shimmy_core::stability::{mode_at, ModeSelect};
        let t = TruckSet::Full.params();
        let v = 30.0 / 3.6;
        let c = 2.0e5;
        let m = mode_at(&t, v, c, ModeSelect::Shimmy).unwrap();
        let mut sim = t.plant(Damper::Viscous(c), Method::default());
        sim.set_wheel_yaw(1e-4, 1e-4);
        let u = Inputs {
            speed_mps: v,
            ..Inputs::default()
        };
        let (settle, dur) = (2.0, 8.0);
        let (mut first, mut last) = (0.0_f64, 0.0_f64);
        let n = (dur / 1e-3) as usize;
        for k in 0..n {
            sim.advance(1e-3, &u).unwrap();
            let tk = (k + 1) as f64 * 1e-3;
            let [l, r] = sim.wheel_yaw_rad();
            let yaw = (0.5 * (l + r)).abs();
            if tk > settle && tk <= settle + 1.0 {
                first = first.max(yaw);
            }
            if tk > dur - 1.0 {
                last = last.max(yaw);
            }
        }
        let growth = (last / first).ln() / (dur - 1.0 - settle);
        assert!(
            (growth - m.re).abs() < 0.1 * m.re.abs().max(0.05),
            "time domain {growth} 1/s, eigenvalue {} 1/s",
            m.re
        );
        // an MR damper at rated current dissipates: its force has the sign of the stroke rate
        let mut mr = t.plant(
            Damper::Mr(shimmy_core::mr_damper::SpencerParams::steering()),
            Method::default(),
        );
        mr.set_wheel_yaw(2e-3, 2e-3);
        let u = Inputs {
            speed_mps: v,
            current_cmd_a: 2.0,
            ..Inputs::default()
        };
        let mut work = 0.0;
        for _ in 0..2000 {
            let x = mr.state();
            let rate = 0.5 * t.l_t * (x[5] + x[6]);
            work += mr.damper_force_n(&u) * rate * 1e-3;
            mr.advance(1e-3, &u).unwrap();
        }
        assert!(work > 0.0, "damper work {work} J");
    }
}
