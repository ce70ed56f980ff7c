//! The mining truck's nonlinear plant (`docs/mining-truck.md`): the linear model of
//! `shimmy_core::vehicles::truck` plus its two nonlinear elements, each added as its departure from its
//! linearisation so that the small-motion limit is the linear model exactly:
//!
//! - the tyres: Magic-Formula force `F = D sin(C_s atan(B a))` of the lagged slip (`D = mu F_z`,
//!   `B = C_a / (C_s D)`: slope C_a at 0, saturating at D) in place of `C_a a`, in the yaw, roll
//!   and lateral equations;
//! - the struts: the polytropic gas springs `Hps::force_n` at the strokes `x_s +- (s/2) phi`
//!   (left strut compressed by positive roll) in place of their linear roll stiffness: the
//!   large-stroke stiffening of the gas.
//!
//! Fixed-step RK4 at 1 ms (the stiffest mode, the linkage at ~46 Hz, is far inside its
//! stability limit).

use nalgebra::SVector;
use shimmy_core::model::{LinearModel, Matrix};
use shimmy_core::mr_damper::{self, SpencerState};
use shimmy_core::vehicles::truck::{
    TruckOperatingPoint, TruckParams, TruckSet, A_L, A_R, DPHI, DPSI_L, DPSI_R, DY, N_STATES, PHI,
    PSI_L, PSI_R, THETA_C, Y,
};

use anyhow::Result;
use shimmy_core::control::smc::NominalPlant;
use shimmy_core::vehicle::Vehicle;
use shimmy_core::vehicles::truck::board::TruckVehicle;
use shimmy_core::vehicles::FieldTable;

use shimmy_firmware::monitoring::BoardCalibration;

use super::damper_sizing::reference_tyre_yaw_stiffness;
use super::family::{FamilyVehicle, ParamInfo, SimModel, SimPlant};
use super::integrator::{rk4_step, Dopri5, IntegrateError};
use super::plant::{Damper, Inputs, Method};

/// Integration step, s.
pub const DT_S: f64 = 1e-3;

/// The truck at a constant speed, damper off.
pub struct TruckSim {
    t: TruckParams,
    op: TruckOperatingPoint,
    a: Matrix<N_STATES>,
    /// Time, s.
    pub time_s: f64,
    /// State (the linear model's order).
    pub x: [f64; N_STATES],
}

impl TruckSim {
    /// A simulation of `t` at `v_mps` from the state `x0`; fails when the struts cannot carry
    /// the load.
    pub fn new(
        t: &TruckParams,
        v_mps: f64,
        x0: [f64; N_STATES],
    ) -> Result<Self, shimmy_core::vehicles::truck::HpsError> {
        Ok(Self {
            t: *t,
            op: t.operating_point()?,
            a: t.linearise(v_mps, 0.0),
            time_s: 0.0,
            x: x0,
        })
    }

    /// The tyre's lateral force at lagged slip `a`, N.
    pub fn tyre_force_n(&self, a: f64) -> f64 {
        tyre_force_n(&self.t, &self.op, a)
    }

    /// The struts' roll moment on the axle at roll `phi`, N m (restoring), from the gas law.
    pub fn strut_roll_moment_nm(&self, phi: f64) -> f64 {
        strut_roll_moment_nm(&self.t, &self.op, phi)
    }

    fn rhs(&self, x: &[f64; N_STATES], dx: &mut [f64; N_STATES]) {
        let xv = SVector::<f64, N_STATES>::from_column_slice(x);
        let lin = self.a * xv;
        dx.copy_from_slice(lin.as_slice());
        add_nonlinear(&self.t, &self.op, x, dx);
    }

    /// Advances by `duration_s` in steps of [`DT_S`], calling `each(time, state)` after every
    /// step.
    pub fn run(&mut self, duration_s: f64, mut each: impl FnMut(f64, &[f64; N_STATES])) {
        let n = (duration_s / DT_S).round() as usize;
        for _ in 0..n {
            let mut f = |_t: f64, y: &[f64; N_STATES], dy: &mut [f64; N_STATES]| self.rhs(y, dy);
            let mut x = self.x;
            rk4_step(&mut f, self.time_s, &mut x, DT_S);
            self.x = x;
            self.time_s += DT_S;
            each(self.time_s, &self.x);
        }
    }
}

/// The tyre's lateral force at lagged slip `a`, N: the Magic Formula with slope C_a at 0.
fn tyre_force_n(t: &TruckParams, op: &TruckOperatingPoint, a: f64) -> f64 {
    let d = t.mu * op.f_z;
    let b = op.c_a / (t.c_s * d);
    super::tyre::magic_formula_n(d, t.c_s, b, a)
}

/// The struts' roll moment on the axle at roll `phi`, N m (restoring), from the gas law.
fn strut_roll_moment_nm(t: &TruckParams, op: &TruckOperatingPoint, phi: f64) -> f64 {
    let half_s = 0.5 * t.strut_spacing;
    let x_s = op.strut.stroke_m;
    let (f_l, f_r) = (
        t.hps.force_n(x_s + half_s * phi),
        t.hps.force_n(x_s - half_s * phi),
    );
    -half_s * (f_l - f_r)
}

/// Adds the two nonlinear elements to `dx` (which holds the linear model's `A x`): each as its
/// departure from its linearisation.
fn add_nonlinear(t: &TruckParams, op: &TruckOperatingPoint, x: &[f64], dx: &mut [f64]) {
    let lever = t.e + t.t_p;
    // tyres: nonlinear force minus the linear C_a a already in A
    for (slip, wheel) in [(A_L, DPSI_L), (A_R, DPSI_R)] {
        let extra = tyre_force_n(t, op, x[slip]) - op.c_a * x[slip];
        dx[wheel] -= lever * extra / t.i_k;
        dx[DPHI] += t.h_r * extra / t.i_phi;
        dx[DY] += extra / t.m_axle;
    }
    // struts: the gas law's moment minus the linear strut part of K_phi in A
    let half_s = 0.5 * t.strut_spacing;
    let linear_struts = -2.0 * op.strut.stiffness_npm * half_s * half_s * x[PHI];
    dx[DPHI] += (strut_roll_moment_nm(t, op, x[PHI]) - linear_struts) / t.i_phi;
}

/// States of [`TruckPlant`]: the linear model's 12, then the MR damper's `(u, y, z)` as in the
/// car's plant (`crate::model::plant::idx::U`).
pub const N_SIM: usize = N_STATES + 3;
/// Damper filtered coil input u, V (1 V per A).
pub const U: usize = N_STATES;
/// Damper internal displacement y, m.
pub const DAMPER_Y: usize = N_STATES + 1;
/// Damper Bouc-Wen variable z, m.
pub const DAMPER_Z: usize = N_STATES + 2;

/// Names of the [`TruckPlant`] states, for CSV headers.
pub const SIM_STATE_NAMES: [&str; N_SIM] = [
    "psi_l_rad",
    "psi_r_rad",
    "phi_rad",
    "theta_c_rad",
    "y_m",
    "dpsi_l_radps",
    "dpsi_r_radps",
    "dphi_radps",
    "dtheta_c_radps",
    "dy_mps",
    "a_l_rad",
    "a_r_rad",
    "damper_u_v",
    "damper_y_m",
    "damper_z_m",
];

/// The truck with its steering damper in the simulator's loop: the nonlinear truck of
/// [`TruckSim`] with the speed, the coil current and external kingpin yaw torques as held
/// inputs ([`Inputs`]) and a damper on the track rod (none, the Spencer MR damper with its coil
/// lag, or a viscous one), integrated by the car's adaptive Dopri5 across control periods (the
/// Bouc-Wen variable is stiff). The damper acts as in the linear model's input column:
/// stroke `x_d = (l_t/2)(psi_L + psi_R)`, moment `-(l_t/2) F_d` on each wheel. The driver
/// torque is not used: a hydrostatic steering has no mechanical path from the steering wheel
/// to the linkage (the closed valve holds it, `docs/mining-truck.md`).
#[derive(Clone, Debug)]
pub struct TruckPlant {
    dynamics: Dynamics,
    a0: Matrix<N_STATES>,
    da: Matrix<N_STATES>,
    v_a: f64,
    x: [f64; N_SIM],
    t_s: f64,
    dopri: Dopri5<N_SIM>,
    last_inputs: Option<Inputs>,
}

impl TruckPlant {
    /// The truck `t` at rest with `damper`, integrated at relative tolerance `rtol`, at the
    /// operating point of its linear model (`TruckParams::point_or_tyres_only`: a vehicle file's
    /// truck is validated, its struts carry the load).
    pub fn new(t: &TruckParams, damper: Damper, rtol: f64) -> Self {
        let mut atol = [0.0; N_SIM];
        for (i, a) in atol.iter_mut().enumerate() {
            // the car's scales (`plant::default_atol`); the axle's lateral motion in m on the
            // scale of its slip contribution (sigma x 1e-3 rad)
            let scale = match i {
                PSI_L..=THETA_C | A_L | A_R => 1e-3,
                Y => 1e-3 * t.sigma,
                DPSI_L..=DY => 1e-1,
                U => 1.0,
                _ => 1e-4,
            };
            *a = rtol * scale;
        }
        Self {
            dynamics: Dynamics {
                t: *t,
                op: t.point_or_tyres_only(),
                damper,
                a: t.linearise(0.0, 0.0),
            },
            a0: t.linearise(0.0, 0.0),
            da: t.dlinearise_dv(),
            v_a: 0.0,
            x: [0.0; N_SIM],
            t_s: 0.0,
            dopri: Dopri5::new(rtol, atol),
            last_inputs: None,
        }
    }

    /// The parameters.
    pub fn params(&self) -> &TruckParams {
        &self.dynamics.t
    }
}

/// The right-hand side's parts of a [`TruckPlant`] (apart from the integrator's state).
#[derive(Clone, Debug)]
struct Dynamics {
    t: TruckParams,
    op: TruckOperatingPoint,
    damper: Damper,
    /// A(V) at the speed of the current period.
    a: Matrix<N_STATES>,
}

impl Dynamics {
    /// Damper stroke (m) and stroke rate (m/s).
    fn stroke(&self, x: &[f64; N_SIM]) -> (f64, f64) {
        let half = 0.5 * self.t.l_t;
        (half * (x[PSI_L] + x[PSI_R]), half * (x[DPSI_L] + x[DPSI_R]))
    }

    /// Right-hand side under held inputs; returns the damper force, N.
    fn rhs(&self, x: &[f64; N_SIM], u: &Inputs, dx: &mut [f64; N_SIM]) -> f64 {
        let xv = SVector::<f64, N_STATES>::from_column_slice(&x[..N_STATES]);
        let lin = self.a * xv;
        dx[..N_STATES].copy_from_slice(lin.as_slice());
        add_nonlinear(&self.t, &self.op, &x[..N_STATES], &mut dx[..N_STATES]);
        let f_d = match &self.damper {
            Damper::None => {
                dx[U..].fill(0.0);
                0.0
            }
            Damper::Viscous(c) => {
                dx[U..].fill(0.0);
                c * self.stroke(x).1
            }
            Damper::Mr(sp) => {
                let (xd, vd) = self.stroke(x);
                let st = SpencerState {
                    u: x[U],
                    y: x[DAMPER_Y],
                    z: x[DAMPER_Z],
                };
                let r = mr_damper::rates(sp, &st, xd, vd, u.current_cmd_a);
                dx[U] = r.du;
                dx[DAMPER_Y] = r.dy;
                dx[DAMPER_Z] = r.dz;
                r.force_n
            }
        };
        let half_lt = 0.5 * self.t.l_t;
        for (i, wheel) in [DPSI_L, DPSI_R].into_iter().enumerate() {
            dx[wheel] += (u.yaw_torque_nm[i] - half_lt * f_d) / self.t.i_k;
        }
        f_d
    }
}

impl SimPlant for TruckPlant {
    fn set_wheel_yaw(&mut self, psi_l_rad: f64, psi_r_rad: f64) {
        self.x = [0.0; N_SIM];
        self.x[PSI_L] = psi_l_rad;
        self.x[PSI_R] = psi_r_rad;
        self.last_inputs = None;
    }

    fn set_state(&mut self, x: &[f64]) {
        self.x.copy_from_slice(x);
        self.last_inputs = None;
    }

    fn advance(&mut self, dt_s: f64, inputs: &Inputs) -> Result<(), IntegrateError> {
        if inputs.speed_mps != self.v_a {
            self.dynamics.a = self.a0 + self.da * inputs.speed_mps;
            self.v_a = inputs.speed_mps;
            self.last_inputs = None;
        }
        let reuse = self.last_inputs.as_ref() == Some(inputs);
        self.last_inputs = None;
        let d = &self.dynamics;
        let mut f = |_t: f64, y: &[f64; N_SIM], dy: &mut [f64; N_SIM]| {
            d.rhs(y, inputs, dy);
        };
        self.dopri
            .integrate_fsal(&mut f, self.t_s, &mut self.x, dt_s, reuse)?;
        self.t_s += dt_s;
        self.last_inputs = Some(*inputs);
        Ok(())
    }

    fn wheel_yaw_rad(&self) -> [f64; 2] {
        [self.x[PSI_L], self.x[PSI_R]]
    }

    fn steering_angle_rad(&self) -> f64 {
        self.x[THETA_C]
    }

    fn coil_input_a(&self) -> f64 {
        match self.dynamics.damper {
            Damper::Mr(_) => self.x[U],
            _ => 0.0,
        }
    }

    fn damper_force_n(&self, inputs: &Inputs) -> f64 {
        let mut dx = [0.0; N_SIM];
        self.dynamics.rhs(&self.x, inputs, &mut dx)
    }

    fn state(&self) -> &[f64] {
        &self.x
    }

    fn state_names(&self) -> &'static [&'static str] {
        &SIM_STATE_NAMES
    }

    fn time_s(&self) -> f64 {
        self.t_s
    }

    fn vector_field(&self, x: &[f64], inputs: &Inputs, dx: &mut [f64]) {
        let mut d = self.dynamics.clone();
        d.a = self.a0 + self.da * inputs.speed_mps;
        let mut s = [0.0; N_SIM];
        s.copy_from_slice(x);
        let mut ds = [0.0; N_SIM];
        d.rhs(&s, inputs, &mut ds);
        dx.copy_from_slice(&ds);
    }
}

/// Growth rate of the wheel-yaw envelope, 1/s: the log ratio of the largest |psi_L + psi_R|/2
/// in the last and the first `window_s` after `settle_s` (fast modes decayed), over their
/// distance in time.
pub fn envelope_growth_1ps(
    t: &TruckParams,
    v_mps: f64,
    x0: [f64; N_STATES],
    settle_s: f64,
    duration_s: f64,
    window_s: f64,
) -> Result<f64, shimmy_core::vehicles::truck::HpsError> {
    let mut sim = TruckSim::new(t, v_mps, x0)?;
    let (mut first, mut last) = (0.0_f64, 0.0_f64);
    let (w0, w1) = (settle_s + window_s, duration_s - window_s);
    sim.run(duration_s, |time, x| {
        let yaw = (0.5 * (x[0] + x[1])).abs();
        if time > settle_s && time <= w0 {
            first = first.max(yaw);
        }
        if time > w1 {
            last = last.max(yaw);
        }
    });
    Ok((last / first).ln() / (w1 - settle_s))
}

/// A small in-phase wheel-yaw start, rad (both wheels).
pub fn yaw_start(psi_rad: f64) -> [f64; N_STATES] {
    let mut x = [0.0; N_STATES];
    x[0] = psi_rad;
    x[1] = psi_rad;
    x
}

/// The truck in the studies (`super::study`).
impl super::study::StudyModel<N_STATES> for TruckParams {
    const DRIVER_TORQUE: bool = false;
    const SCENARIO_DIR: &'static str = "truck";

    /// The fields the loaded truck's onset moves most with (`shimmy-sim sensitivity --vehicle
    /// truck-full`: I_k, C_a/F_z, c_h, k_h, t_p) and the car's tyre fields sigma and e; the
    /// load is the payload (the cornering coefficient C_a/F_z stays, as for the car's load).
    fn single_variants(&self, f: f64) -> anyhow::Result<Vec<(&'static str, Self)>> {
        [
            ("C_a/F_z", "c_a_per_fz"),
            ("sigma", "sigma"),
            ("I_k", "i_k"),
            ("c_h", "c_h"),
            ("k_h", "k_h"),
            ("e", "e"),
            ("t_p", "t_p"),
            ("payload", "payload_kg"),
        ]
        .iter()
        .map(|&(label, name)| Ok((label, super::study::scaled(self, name, f)?)))
        .collect()
    }

    fn other_plants() -> Vec<(String, Self)> {
        Vec::new()
    }

    /// The analogue of the car's `hard` set (half the restoring stiffness K_d): half the
    /// linkage's damping c_h, the truck's least-damped path; and +-20 % on C_a/F_z, sigma, e.
    fn robustness_variants(&self) -> anyhow::Result<Vec<(String, Self)>> {
        let mut v = vec![(
            "c_h-50%".to_string(),
            super::study::scaled(self, "c_h", 0.5)?,
        )];
        for name in ["c_a_per_fz", "sigma", "e"] {
            for f in [0.8, 1.2] {
                v.push((
                    format!("{name}{:+.0}%", (f - 1.0) * 100.0),
                    super::study::scaled(self, name, f)?,
                ));
            }
        }
        Ok(v)
    }

    /// Off: below the loaded truck's onset (23.51 km/h); on: through its window.
    fn meter_speeds_kmh() -> (&'static [f64], &'static [f64]) {
        (&[8.0, 12.0, 16.0, 20.0], &[10.0, 30.0, 50.0])
    }
}

/// The mining truck in the registry (`super::registry`): its files have the `[truck]` section
/// and the shared ones; its shared sections default to the truck's (`TruckVehicle::default_parts`).
impl super::registry::ModelEntry<N_STATES> for TruckParams {
    type File = super::family::FamilyVehicle<TruckParams>;
    const SECTION: Option<&'static str> = Some("truck");
    const SHARED_SECTIONS: bool = true;
    const DEFAULT_SET: &'static str = TruckSet::Full.name();
    const NO_DRIVER: Option<&'static str> =
        Some("steers hydrostatically, no driver torque reaches its linkage");
    /// The simulator tyre's friction and shape and the damper lever.
    const NO_LINEAR_EFFECT: &'static [&'static str] = &["mu", "c_s", "l_t"];

    fn set_names() -> Vec<&'static str> {
        TruckSet::ALL.iter().map(|s| s.name()).collect()
    }
    fn set(name: &str) -> Option<Self> {
        TruckSet::from_name(name).map(TruckSet::params)
    }
    fn assemble(
        model: Self,
        parts: Option<shimmy_core::vehicle::Vehicle>,
    ) -> anyhow::Result<Self::File> {
        Ok(super::family::FamilyVehicle {
            model,
            parts: parts
                .unwrap_or_else(shimmy_core::vehicles::truck::board::TruckVehicle::default_parts),
        })
    }
    fn fields() -> &'static [shimmy_core::vehicles::ModelField] {
        <Self as FieldTable>::FIELDS
    }
    fn field(&self, name: &str) -> Option<f64> {
        FieldTable::get(self, name)
    }
    fn set_field(
        &mut self,
        name: &str,
        value: f64,
    ) -> Result<(), shimmy_core::vehicles::FieldError> {
        FieldTable::set(self, name, value)
    }
    fn check(&self) -> Result<(), String> {
        self.validate().map_err(|e| e.to_string())
    }
    fn check_in_file(&self) -> anyhow::Result<()> {
        self.validate().map_err(|e| anyhow::anyhow!("truck: {e}"))
    }
    fn model_of(f: &Self::File) -> Self {
        f.model
    }
    fn model_mut(f: &mut Self::File) -> &mut Self {
        &mut f.model
    }
    fn parts_of(f: &Self::File) -> Option<&shimmy_core::vehicle::Vehicle> {
        Some(&f.parts)
    }
    fn parts_of_mut(f: &mut Self::File) -> Option<&mut shimmy_core::vehicle::Vehicle> {
        Some(&mut f.parts)
    }
    fn vehicle(f: Self::File) -> anyhow::Result<Self::File> {
        Ok(f)
    }
    fn file_of(v: &Self::File) -> Self::File {
        *v
    }
    fn with_params(v: &Self::File, model: Self) -> Self::File {
        super::family::FamilyVehicle { model, ..*v }
    }
}

impl SimModel<{ N_STATES }> for TruckParams {
    type Linear = TruckParams;
    type Plant = TruckPlant;
    type State = [f64; N_SIM];
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
        let rtol = method.rtol();
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
            parts: TruckVehicle::default_parts(),
        };
        Some((*self, board.wheel_order_radius_m()))
    }

    fn params() -> Vec<ParamInfo> {
        super::family::table_params::<Self>()
    }

    fn param(&self, name: &str) -> Option<f64> {
        FieldTable::get(self, name)
    }

    fn with_param(&self, name: &str, value: f64) -> Result<Self> {
        super::family::with_table_param::<Self, N_STATES>(self, name, value)
    }
}

/// The truck's firmware image (cargo feature `model-truck`): its stored vehicle is the core's
/// [`TruckVehicle`]; its simulated device drives road noise and the wheels' imbalance through
/// the loaded truck's onset (23.5 km/h) towards the truck class's top speed (~64 km/h,
/// `docs/mining-truck.md`).
impl super::board::BoardModel<N_STATES> for TruckParams {
    type Board = TruckVehicle;
    const PIL_ELF: &'static str = "target/xtask/shimmy-firmware.pil+model-truck.elf";
    const DEVICE_TOP_KMH: f64 = 50.0;
    const DEVICE_POTHOLE: bool = false;
    fn board_vehicle(v: &FamilyVehicle<Self>) -> TruckVehicle {
        TruckVehicle {
            truck: v.model,
            parts: v.parts,
        }
    }
    fn from_board(b: &TruckVehicle) -> FamilyVehicle<Self> {
        FamilyVehicle {
            model: b.truck,
            parts: b.parts,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::damper_equiv::damper_equivalent;
    use crate::model::damper_sizing::{damper_scale_like_the_cars, least_stabilising_c};
    use shimmy_core::stability::{hopf_crossings, CrossingKind};
    use shimmy_core::units::kmh_to_mps;
    use shimmy_core::vehicles::truck::TruckSet;

    /// The truck's steering damper against the car's, as a factor on every force coefficient of
    /// the car's reference damper: the truck's damper is sized as the car's is, so that its
    /// energy-equivalent viscous coefficient at the rated current (describing function at the
    /// default 0.5 deg, [`damper_equivalent`]) is the same multiple of the least coefficient that
    /// closes the Hopf window ([`least_stabilising_c`]) as the car's (the `nominal` car and the
    /// loaded truck, `truck-full`, the worst case). The Spencer model's force is linear in its
    /// force coefficients (the Bouc-Wen and internal displacements do not change), so the factor is
    /// exact at that amplitude; `docs/mining-truck.md` gives the figures.
    fn truck_damper_scale() -> Result<f64> {
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

    /// Both nonlinear elements have the linear model's slope at 0 and depart from it at large
    /// motion in the physical direction (the tyre saturates, the gas stiffens).
    #[test]
    fn the_nonlinear_elements_linearise_to_the_model() {
        let t = TruckSet::Full.params();
        let sim = TruckSim::new(&t, 8.0, [0.0; N_STATES]).unwrap();
        let h = 1e-7;
        let slope = (sim.tyre_force_n(h) - sim.tyre_force_n(-h)) / (2.0 * h);
        assert!((slope - sim.op.c_a).abs() < 1e-6 * sim.op.c_a);
        assert!(sim.tyre_force_n(0.3) < 0.5 * sim.op.c_a * 0.3);
        let half_s = 0.5 * t.strut_spacing;
        let k_lin = 2.0 * sim.op.strut.stiffness_npm * half_s * half_s;
        let m_slope = -(sim.strut_roll_moment_nm(h) - sim.strut_roll_moment_nm(-h)) / (2.0 * h);
        assert!((m_slope - k_lin).abs() < 1e-5 * k_lin, "{m_slope} {k_lin}");
        assert_eq!(sim.strut_roll_moment_nm(0.0), 0.0);
        // 2 deg of roll: the gas spring's moment exceeds the linear one
        let phi = 2.0_f64.to_radians();
        assert!(-sim.strut_roll_moment_nm(phi) > 1.001 * k_lin * phi);
    }

    /// The truck's default damper is sized as the car's: at the rated current its c_eq is the
    /// same multiple of the least stabilising coefficient; and, checked on the eigenvalues
    /// (independent of the sizing rule), the loaded truck keeps a Hopf window with the damper
    /// at 0 A and none at the rated current, as the car does.
    #[test]
    fn the_trucks_damper_is_sized_as_the_cars() {
        let car = Vehicle::nominal();
        let truck = TruckSet::Full.params();
        let parts = TruckVehicle::default_parts();
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
