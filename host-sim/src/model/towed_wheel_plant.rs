//! The towed wheel's nonlinear plant (`docs/towed-wheel.md`): the linear model of
//! `shimmy_core::vehicles::towed_wheel` (the contact patch collocated at its Chebyshev points)
//! with the no-sliding condition's geometric terms added as its departure from the
//! linearisation, so that the small-motion limit is the linear model exactly. The patch's
//! particles stick to the road: with the king pin running straight at V,
//! `q_t = (V cos psi - q psi') q_x + V sin psi + (l - x) psi'`, and at the leading edge
//! `q(a)' = -(V cos psi - q(a) psi') q(a) / sigma + V sin psi + (l - a) psi'`. The string's
//! forces and the tyre damping stay linear in the deformation. A friction limit bounds large
//! shimmy: a particle at the sliding deformation
//! ([`TowedWheelParams::sliding_deformation_m`]) that the rolling would deform further slides
//! instead, its deformation held; small motions never reach it.
//!
//! [`TowedWheelPlant`] is the family's plant (`SimModel`: stability, margin, bifurcation,
//! sweep, faults, run) with a steering damper at the lever `l_d` about the king pin (none,
//! viscous, or the MR damper's Spencer model with its coil lag), sized by
//! [`towed_wheel_damper_scale`]. Integrated by the car's adaptive Dopri5 across control
//! periods.

use anyhow::Result;
use nalgebra::SVector;
use shimmy_core::control::smc::NominalPlant;
use shimmy_core::model::{LinearModel, Matrix};
use shimmy_core::mr_damper::{self, SpencerState};
use shimmy_core::vehicle::Vehicle;
use shimmy_core::vehicles::towed_wheel::{
    Patch, TowedWheelParams, TowedWheelSet, DPSI, N_PATCH, N_STATES, PSI, Q0,
};
use shimmy_core::vehicles::FieldTable;

use super::damper_sizing::{
    car_parts_with_damper_scaled, damper_scale_like_the_cars, reference_tyre_yaw_stiffness,
};
use super::family::{FamilyVehicle, ParamInfo, SimModel, SimPlant};
use super::integrator::{Dopri5, IntegrateError};
use super::plant::{Damper, Inputs, Method};

/// The wheel's rolling radius, m: the benchmark's tyre has a 0.08 m contact patch, that of a
/// small pneumatic castor wheel of about 0.1 m radius.
pub const WHEEL_RADIUS_M: f64 = 0.10;

/// States of [`TowedWheelPlant`]: the linear model's, then the MR damper's filtered coil input
/// `u`, internal displacement `y` and Bouc-Wen `z` (as every model's).
pub const N_SIM: usize = N_STATES + 3;
const U: usize = N_STATES;

/// Names of [`TowedWheelPlant`]'s states.
pub fn sim_state_names() -> &'static [&'static str] {
    static NAMES: std::sync::OnceLock<Vec<&'static str>> = std::sync::OnceLock::new();
    NAMES.get_or_init(|| {
        let mut v: Vec<&'static str> = shimmy_core::vehicles::towed_wheel::STATE_NAMES.to_vec();
        v.extend(["u_V", "damper_y_m", "damper_z_m"]);
        v
    })
}

/// The towed wheel as the family's nonlinear plant ([`SimPlant`]): the geometrically exact
/// no-sliding condition on the collocated patch, a steering damper at the king pin, stroke
/// `l_d psi`, its force `F_d` putting the yaw moment `-l_d F_d` on the wheel. The scenario's
/// two kingpin yaw torques (road noise, imbalance, kicks; scaled by
/// [`SimModel::yaw_torque_scale`]) act on the wheel's yaw.
#[derive(Clone, Debug)]
pub struct TowedWheelPlant {
    t: TowedWheelParams,
    damper: Damper,
    d: [[f64; N_PATCH]; N_PATCH],
    q_slide: f64,
    a0: Matrix<N_STATES>,
    da: Matrix<N_STATES>,
    a: Matrix<N_STATES>,
    v_a: f64,
    x: [f64; N_SIM],
    t_s: f64,
    dopri: Dopri5<N_SIM>,
}

impl TowedWheelPlant {
    /// The wheel `t` at rest with `damper`, integrated at relative tolerance `rtol`.
    pub fn new(t: &TowedWheelParams, damper: Damper, rtol: f64) -> Self {
        let mut atol = [0.0; N_SIM];
        for (i, a) in atol.iter_mut().enumerate() {
            // the car's scales: yaw 1e-3 rad, its rate that of a 1 Hz motion, the tyre's
            // deformation the yaw's over the caster, coil 1 V, damper 1e-4 m
            let scale = match i {
                PSI => 1e-3,
                DPSI => 1e-2,
                U => 1.0,
                i if i > U => 1e-4,
                _ => 1e-3 * (t.l + t.a),
            };
            *a = rtol * scale;
        }
        let a0 = t.linearise(0.0, 0.0);
        Self {
            t: *t,
            damper,
            d: Patch::new(t.a).d,
            q_slide: t.sliding_deformation_m(),
            a0,
            da: t.dlinearise_dv(),
            a: a0,
            v_a: 0.0,
            x: [0.0; N_SIM],
            t_s: 0.0,
            dopri: Dopri5::new(rtol, atol),
        }
    }

    /// Right-hand side under held inputs; returns the damper force, N.
    fn rhs(&self, x: &[f64; N_SIM], u: &Inputs, dx: &mut [f64; N_SIM]) -> f64 {
        let xv = SVector::<f64, N_STATES>::from_column_slice(&x[..N_STATES]);
        let lin = self.a * xv;
        dx[..N_STATES].copy_from_slice(lin.as_slice());
        // the no-sliding condition's departure from its linearisation
        let (v, psi, dpsi) = (self.v_a, x[PSI], x[DPSI]);
        let (s, c) = psi.sin_cos();
        let lateral = v * (s - psi);
        for i in 0..N_PATCH {
            let q = x[Q0 + i];
            let transport = v * (c - 1.0) - q * dpsi;
            let slope = if i == 0 {
                -q / self.t.sigma
            } else {
                (0..N_PATCH).map(|j| self.d[i][j] * x[Q0 + j]).sum()
            };
            dx[Q0 + i] += transport * slope + lateral;
            // friction limit: a particle at the sliding deformation that the rolling would
            // deform further slides instead (its deformation held)
            if q.abs() >= self.q_slide && dx[Q0 + i] * q > 0.0 {
                dx[Q0 + i] = 0.0;
            }
        }
        let (xd, vd) = (self.t.l_d * psi, self.t.l_d * dpsi);
        let f_d = match &self.damper {
            Damper::None => {
                dx[U..].fill(0.0);
                0.0
            }
            Damper::Viscous(c) => {
                dx[U..].fill(0.0);
                c * vd
            }
            Damper::Mr(sp) => {
                let st = SpencerState {
                    u: x[U],
                    y: x[U + 1],
                    z: x[U + 2],
                };
                let r = mr_damper::rates(sp, &st, xd, vd, u.current_cmd_a);
                dx[U] = r.du;
                dx[U + 1] = r.dy;
                dx[U + 2] = r.dz;
                r.force_n
            }
        };
        dx[DPSI] += self.t.damper_force_input()[DPSI] * f_d;
        dx[DPSI] += (u.yaw_torque_nm[0] + u.yaw_torque_nm[1]) / self.t.j_a;
        f_d
    }
}

impl SimPlant for TowedWheelPlant {
    /// The wheel yawed by the mean of the two angles (its one yaw), at rest, the tyre
    /// undeformed.
    fn set_wheel_yaw(&mut self, psi_l_rad: f64, psi_r_rad: f64) {
        self.x = [0.0; N_SIM];
        self.x[PSI] = 0.5 * (psi_l_rad + psi_r_rad);
    }

    fn set_state(&mut self, x: &[f64]) {
        self.x.copy_from_slice(x);
    }

    fn advance(&mut self, dt_s: f64, inputs: &Inputs) -> Result<(), IntegrateError> {
        if inputs.speed_mps != self.v_a {
            self.a = self.a0 + self.da * inputs.speed_mps;
            self.v_a = inputs.speed_mps;
        }
        let me = &*self;
        let (t_s, mut x, mut dopri) = (me.t_s, me.x, me.dopri.clone());
        let mut f = |_t: f64, y: &[f64; N_SIM], dy: &mut [f64; N_SIM]| {
            me.rhs(y, inputs, dy);
        };
        dopri.integrate_fsal(&mut f, t_s, &mut x, dt_s, false)?;
        self.dopri = dopri;
        self.x = x;
        self.t_s += dt_s;
        Ok(())
    }

    /// The wheel's yaw on both channels: one wheel, one measurement (the mode meter takes the
    /// mean of the two).
    fn wheel_yaw_rad(&self) -> [f64; 2] {
        [self.x[PSI]; 2]
    }

    /// No steering linkage: the trailing edge's deformation over the caster, the tyre's
    /// visible lag behind the wheel.
    fn steering_angle_rad(&self) -> f64 {
        self.x[Q0 + N_PATCH - 1] / self.t.l.max(self.t.a)
    }

    fn coil_input_a(&self) -> f64 {
        match self.damper {
            Damper::Mr(_) => self.x[U],
            _ => 0.0,
        }
    }

    fn damper_force_n(&self, inputs: &Inputs) -> f64 {
        let mut dx = [0.0; N_SIM];
        self.rhs(&self.x, inputs, &mut dx)
    }

    fn state(&self) -> &[f64] {
        &self.x
    }

    fn state_names(&self) -> &'static [&'static str] {
        sim_state_names()
    }

    fn time_s(&self) -> f64 {
        self.t_s
    }

    fn vector_field(&self, x: &[f64], inputs: &Inputs, dx: &mut [f64]) {
        let mut at_speed = self.clone();
        at_speed.a = self.a0 + self.da * inputs.speed_mps;
        at_speed.v_a = inputs.speed_mps;
        let mut s = [0.0; N_SIM];
        s.copy_from_slice(x);
        let mut ds = [0.0; N_SIM];
        at_speed.rhs(&s, inputs, &mut ds);
        dx.copy_from_slice(&ds);
    }
}

impl SimModel<N_STATES> for TowedWheelParams {
    type Linear = TowedWheelParams;
    type Plant = TowedWheelPlant;
    type State = [f64; N_SIM];
    type Vehicle = FamilyVehicle<TowedWheelParams>;
    const STEERING: &'static str = "tyre q(-a)/l";
    /// 1-60 km/h: the benchmark's window ends at 34 km/h; far above it the tyre damping's
    /// rear-tail term makes the standing-still root cross zero (a static divergence of the
    /// delay equation near 148 km/h, `docs/towed-wheel.md`), where no shimmy mode exists to
    /// size a damper on.
    const SIZING_SPEEDS_KMH: (f64, f64) = (1.0, 60.0);

    fn family_vehicle(v: &Self::Vehicle) -> FamilyVehicle<Self> {
        *v
    }

    fn parts_mut(v: &mut Self::Vehicle) -> &mut Vehicle {
        &mut v.parts
    }

    fn linear(&self) -> Self {
        *self
    }

    fn kick_state(psi_rad: f64) -> [f64; N_SIM] {
        let mut x = [0.0; N_SIM];
        x[PSI] = psi_rad;
        x
    }

    /// One integrator (Dopri5) at `method`'s relative tolerance (1e-7 for the fixed-step
    /// methods).
    fn plant(&self, damper: Damper, method: Method) -> TowedWheelPlant {
        TowedWheelPlant::new(self, damper, method.rtol())
    }

    fn rolling_radius_m(&self) -> f64 {
        WHEEL_RADIUS_M
    }

    /// The damper's lever about the king pin: its stroke `l_d psi` is the family's
    /// `(l_t/2)(psi_L + psi_R)` with both channels at psi.
    fn steering_arm_m(&self) -> f64 {
        self.l_d
    }

    /// The ASMC's model of the yaw about the king pin: force per unit yaw acceleration
    /// `2 I_k / l_t = J_A / l_d` (I_k = J_A / 2, l_t = l_d); the tyre's damping is the
    /// plant's, not the model's (c_k = 0).
    fn nominal_plant(&self) -> NominalPlant {
        NominalPlant {
            i_k_kgm2: (0.5 * self.j_a) as f32,
            c_k_nms_per_rad: 0.0,
            l_t_m: self.l_d as f32,
        }
    }

    fn host_app_model(&self) -> Option<(Self::Linear, f32)> {
        None
    }

    /// The standing tyre's yaw stiffness about the king pin per channel over the car's
    /// `(e + t_p) C_a`: the same road disturbance on a tyre of this stiffness.
    fn yaw_torque_scale(&self) -> f64 {
        0.5 * self.yaw_stiffness_nm_per_rad() / reference_tyre_yaw_stiffness()
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

/// The towed wheel's steering damper against the car's, as a factor on every force
/// coefficient ([`damper_scale_like_the_cars`]: the same multiple of the least stabilising
/// coefficient at the rated current), sized on the benchmark.
pub fn towed_wheel_damper_scale() -> Result<f64> {
    static SCALE: std::sync::OnceLock<std::result::Result<f64, String>> =
        std::sync::OnceLock::new();
    SCALE
        .get_or_init(|| {
            damper_scale_like_the_cars(&TowedWheelSet::Benchmark.params())
                .map_err(|e| format!("{e:#}"))
        })
        .clone()
        .map_err(|e| anyhow::anyhow!(e))
}

/// The towed wheel `t` with its shared sections: the car's reference damper, sensors, gains
/// and thresholds with the damper scaled by [`towed_wheel_damper_scale`].
pub fn towed_wheel_vehicle(t: TowedWheelParams) -> Result<FamilyVehicle<TowedWheelParams>> {
    Ok(FamilyVehicle {
        model: t,
        parts: car_parts_with_damper_scaled(towed_wheel_damper_scale()?),
    })
}

/// The towed wheel in the registry (`super::registry`): its files and sets give its
/// parameters only; it runs with the scaled car damper ([`towed_wheel_vehicle`]).
impl super::registry::ModelEntry<N_STATES> for TowedWheelParams {
    type File = TowedWheelParams;
    const SECTION: Option<&'static str> = Some("towed_wheel");
    const SHARED_SECTIONS: bool = false;
    const DEFAULT_SET: &'static str = TowedWheelSet::Benchmark.name();
    const NO_DRIVER: Option<&'static str> = Some("has no steering for a driver torque");
    /// The damper lever and the friction limit.
    const NO_LINEAR_EFFECT: &'static [&'static str] = &["l_d", "f_z", "mu"];

    fn set_names() -> Vec<&'static str> {
        TowedWheelSet::ALL.iter().map(|s| s.name()).collect()
    }
    fn set(name: &str) -> Option<Self> {
        TowedWheelSet::from_name(name).map(TowedWheelSet::params)
    }
    fn assemble(model: Self, _parts: Option<Vehicle>) -> Result<Self> {
        Ok(model)
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
    ) -> std::result::Result<(), shimmy_core::vehicles::FieldError> {
        FieldTable::set(self, name, value)
    }
    fn check(&self) -> std::result::Result<(), String> {
        self.validate().map_err(|e| e.to_string())
    }
    fn check_in_file(&self) -> Result<()> {
        self.validate().map_err(|e| {
            anyhow::anyhow!(
                "{}",
                e.to_string().replacen("field `", "field `towed_wheel.", 1)
            )
        })
    }
    fn model_of(f: &Self) -> Self {
        *f
    }
    fn model_mut(f: &mut Self) -> &mut Self {
        f
    }
    fn parts_of(_f: &Self) -> Option<&Vehicle> {
        None
    }
    fn parts_of_mut(_f: &mut Self) -> Option<&mut Vehicle> {
        None
    }
    fn vehicle(f: Self) -> Result<FamilyVehicle<TowedWheelParams>> {
        towed_wheel_vehicle(f)
    }
    fn file_of(v: &FamilyVehicle<TowedWheelParams>) -> Self {
        v.model
    }
    fn with_params(
        v: &FamilyVehicle<TowedWheelParams>,
        model: Self,
    ) -> FamilyVehicle<TowedWheelParams> {
        FamilyVehicle { model, ..*v }
    }
}
