//! The trailer's nonlinear plant (`docs/trailer.md`): the linear model of `shimmy_core::trailer`
//! with the tyres' saturation added as its departure from the linearisation, so that the
//! small-motion limit is the linear model exactly: the Magic-Formula force
//! `F = D sin(C_s atan(B alpha))` of the lagged slip (`D = mu F_z`, `B = C_a / (C_s D)`: slope
//! C_a at 0, saturating at D) in place of `C_a alpha` in both equations of motion. In
//! [`TrailerSim`] (the studies' plant) the sway damper is the linear viscous one of the model
//! (coefficient `c_damper_nspm`); [`TrailerPlant`] is the family's plant (`SimModel`: margin,
//! bifurcation, sweep, faults, run) with the MR damper at the hitch, sized by
//! [`trailer_damper_scale`].
//!
//! Fixed-step RK4 at 2 ms: the fastest pole, the tyre lag's `-V / sigma`, is at most
//! 70 / 0.4 = 175 1/s at the top speed of the named set, 0.35 per step (RK4's real-axis limit
//! is 2.8).

use anyhow::Result;
use nalgebra::SVector;
use shimmy_core::control::smc::NominalPlant;
use shimmy_core::model::{LinearModel, Matrix};
use shimmy_core::mr_damper::{self, SpencerState};
use shimmy_core::vehicle::Vehicle;
use shimmy_core::vehicles::trailer::{
    TrailerParams, TrailerSet, ALPHA, DPSI, DY, N_STATES, PSI, Y,
};
use shimmy_core::vehicles::FieldTable;

use super::damper_sizing::{
    car_parts_with_damper_scaled, damper_scale_like_the_cars, reference_tyre_yaw_stiffness,
};
use super::family::{FamilyVehicle, ParamInfo, SimModel, SimPlant};
use super::integrator::{rk4_step, Dopri5, IntegrateError};
use super::plant::{Damper, Inputs, Method};

/// Integration step, s.
pub const DT_S: f64 = 2e-3;

/// The trailer at a forward speed (changeable between steps) with a viscous sway damper.
pub struct TrailerSim {
    t: TrailerParams,
    c_damper_nspm: f64,
    v_mps: f64,
    a: Matrix<N_STATES>,
    /// Generalised-force input column: dx/dt per unit yaw moment on the trailer, N m.
    yaw_moment_input: SVector<f64, N_STATES>,
    /// Time, s.
    pub time_s: f64,
    /// State (the linear model's order).
    pub x: [f64; N_STATES],
}

impl TrailerSim {
    /// A simulation of `t` at `v_mps` with a sway damper `c_damper_nspm` from the state `x0`.
    pub fn new(t: &TrailerParams, v_mps: f64, c_damper_nspm: f64, x0: [f64; N_STATES]) -> Self {
        let mut yaw_moment_input = SVector::<f64, N_STATES>::zeros();
        // M^-1 [0, 1]: the damper column per unit moment (its lever is l_d)
        let b = t.damper_force_input();
        yaw_moment_input[DY] = -b[DY] / t.l_d;
        yaw_moment_input[DPSI] = -b[DPSI] / t.l_d;
        Self {
            t: *t,
            c_damper_nspm,
            v_mps,
            a: t.linearise(v_mps, c_damper_nspm),
            yaw_moment_input,
            time_s: 0.0,
            x: x0,
        }
    }

    /// The forward speed, m/s.
    pub fn speed_mps(&self) -> f64 {
        self.v_mps
    }

    /// Sets the forward speed (the state matrix is relinearised; A is affine in V).
    pub fn set_speed(&mut self, v_mps: f64) {
        if v_mps != self.v_mps {
            self.v_mps = v_mps;
            self.a = self.t.linearise(v_mps, self.c_damper_nspm);
        }
    }

    /// The axle's lateral force at lagged slip `alpha`, N.
    pub fn tyre_force_n(&self, alpha: f64) -> f64 {
        tyre_force_n(&self.t, alpha)
    }

    fn rhs(&self, x: &[f64; N_STATES], yaw_moment_nm: f64, dx: &mut [f64; N_STATES]) {
        let xv = SVector::<f64, N_STATES>::from_column_slice(x);
        let lin = self.a * xv + self.yaw_moment_input * yaw_moment_nm;
        dx.copy_from_slice(lin.as_slice());
        add_tyre_saturation(&self.t, x, dx);
    }

    /// One step of [`DT_S`] with the external yaw moment `yaw_moment_nm` on the trailer (road,
    /// wind), held over the step.
    pub fn step(&mut self, yaw_moment_nm: f64) {
        let mut f =
            |_t: f64, y: &[f64; N_STATES], dy: &mut [f64; N_STATES]| self.rhs(y, yaw_moment_nm, dy);
        let mut x = self.x;
        rk4_step(&mut f, self.time_s, &mut x, DT_S);
        self.x = x;
        self.time_s += DT_S;
    }

    /// Advances by `duration_s` in steps of [`DT_S`] without external forces, calling
    /// `each(time, state)` after every step.
    pub fn run(&mut self, duration_s: f64, mut each: impl FnMut(f64, &[f64; N_STATES])) {
        let n = (duration_s / DT_S).round() as usize;
        for _ in 0..n {
            self.step(0.0);
            each(self.time_s, &self.x);
        }
    }
}

/// The axle's Magic-Formula lateral force at lagged slip `alpha`, N.
fn tyre_force_n(t: &TrailerParams, alpha: f64) -> f64 {
    let d = t.mu * t.axle_load_n();
    let b = t.cornering_stiffness() / (t.c_s * d);
    super::tyre::magic_formula_n(d, t.c_s, b, alpha)
}

/// Adds a lateral force `f_n` at the axle (to the left) to `dx`: the generalised force
/// `f [1, -l]` through `M^-1` (the tyre's path in the linear model).
fn add_axle_force(t: &TrailerParams, f_n: f64, dx: &mut [f64]) {
    let (m, iz, a) = (t.m, t.i_z, t.a);
    let b = t.l - a;
    dx[DY] += f_n * (iz - m * a * b) / (m * iz);
    dx[DPSI] -= f_n * b / iz;
}

/// The tyres' saturation: the Magic-Formula force minus the linear `C_a alpha` already in A.
fn add_tyre_saturation(t: &TrailerParams, x: &[f64], dx: &mut [f64]) {
    let extra = tyre_force_n(t, x[ALPHA]) - t.cornering_stiffness() * x[ALPHA];
    add_axle_force(t, extra, dx);
}

/// Growth rate of the yaw envelope, 1/s: the log ratio of the largest |psi| in the last and
/// the first `window_s` after `settle_s` (the hitch-lateral mode decayed), over their distance
/// in time.
pub fn envelope_growth_1ps(
    t: &TrailerParams,
    v_mps: f64,
    c_damper_nspm: f64,
    psi0_rad: f64,
    settle_s: f64,
    duration_s: f64,
    window_s: f64,
) -> f64 {
    let mut sim = TrailerSim::new(t, v_mps, c_damper_nspm, yaw_start(psi0_rad));
    let (mut first, mut last) = (0.0_f64, 0.0_f64);
    let (w0, w1) = (settle_s + window_s, duration_s - window_s);
    sim.run(duration_s, |time, x| {
        let yaw = x[PSI].abs();
        if time > settle_s && time <= w0 {
            first = first.max(yaw);
        }
        if time > w1 {
            last = last.max(yaw);
        }
    });
    (last / first).ln() / (w1 - settle_s)
}

/// The largest |psi| over the last `window_s` of a `duration_s` run from the yaw `psi0_rad`,
/// rad: the limit-cycle amplitude when the run has settled on one.
pub fn final_yaw_amplitude_rad(
    t: &TrailerParams,
    v_mps: f64,
    c_damper_nspm: f64,
    psi0_rad: f64,
    duration_s: f64,
    window_s: f64,
) -> f64 {
    let mut sim = TrailerSim::new(t, v_mps, c_damper_nspm, yaw_start(psi0_rad));
    let mut amp = 0.0_f64;
    sim.run(duration_s, |time, x| {
        if time > duration_s - window_s {
            amp = amp.max(x[PSI].abs());
        }
    });
    amp
}

/// A yaw start, rad (the hitch on the tow path, at rest).
pub fn yaw_start(psi_rad: f64) -> [f64; N_STATES] {
    let mut x = [0.0; N_STATES];
    x[PSI] = psi_rad;
    x
}

/// Loaded rolling radius of the caravan's wheels, m: a 195/70 R14 tyre (the common touring
/// caravan size) has a 0.635 m diameter, about 0.30 m loaded. The trailer's wheel order (its
/// imbalance) is that wheel's rotation: 7 to 15 Hz from 50 to 100 km/h, far above the
/// 0.64 Hz sway.
pub const WHEEL_RADIUS_M: f64 = 0.30;

/// States of [`TrailerPlant`]: the linear model's 5, then the MR damper's filtered coil input
/// `u`, internal displacement `y` and Bouc-Wen `z` (as the car's and the trucks').
pub const N_SIM: usize = N_STATES + 3;
const U: usize = N_STATES;

/// Names of [`TrailerPlant`]'s states.
pub const SIM_STATE_NAMES: [&str; N_SIM] = [
    "y_m",
    "psi_rad",
    "dy_mps",
    "dpsi_radps",
    "alpha_rad",
    "u_V",
    "damper_y_m",
    "damper_z_m",
];

/// The trailer as the family's nonlinear plant ([`SimPlant`]): the model of [`TrailerSim`]
/// (saturating tyres) with a sway damper at the hitch (none, viscous, or the MR damper's
/// Spencer model with its coil lag), stroke `l_d psi`, its force `F_d` putting the yaw moment
/// `-l_d F_d` on the trailer (the linear model's input column). The scenario's two kingpin yaw
/// torques (road noise, imbalance, kicks; scaled by [`SimModel::yaw_torque_scale`]) are the
/// yaw moment about the hitch of a lateral force at the axle, `F = -(M_L + M_R) / l`: the
/// road's slip disturbance acts through the tyres as the tyre force does. Integrated by the
/// car's adaptive Dopri5 across control periods (the Bouc-Wen variable is stiff).
#[derive(Clone, Debug)]
pub struct TrailerPlant {
    t: TrailerParams,
    damper: Damper,
    a0: Matrix<N_STATES>,
    da: Matrix<N_STATES>,
    a: Matrix<N_STATES>,
    v_a: f64,
    x: [f64; N_SIM],
    t_s: f64,
    dopri: Dopri5<N_SIM>,
}

impl TrailerPlant {
    /// The trailer `t` at rest with `damper`, integrated at relative tolerance `rtol`.
    pub fn new(t: &TrailerParams, damper: Damper, rtol: f64) -> Self {
        let mut atol = [0.0; N_SIM];
        for (i, a) in atol.iter_mut().enumerate() {
            // the car's scales: angles 1e-3 rad (the hitch's displacement as the yaw it makes,
            // y / l), coil 1 V, damper 1e-4 m; rates those of a 1 Hz motion
            let scale = match i {
                Y => 1e-3 * t.l,
                PSI | ALPHA => 1e-3,
                DY => 1e-2 * t.l,
                DPSI => 1e-2,
                U => 1.0,
                _ => 1e-4,
            };
            *a = rtol * scale;
        }
        let a0 = t.linearise(0.0, 0.0);
        Self {
            t: *t,
            damper,
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
        add_tyre_saturation(&self.t, &x[..N_STATES], &mut dx[..N_STATES]);
        let (xd, vd) = (self.t.l_d * x[PSI], self.t.l_d * x[DPSI]);
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
        let b = self.t.damper_force_input();
        dx[DY] += b[DY] * f_d;
        dx[DPSI] += b[DPSI] * f_d;
        let yaw_moment = u.yaw_torque_nm[0] + u.yaw_torque_nm[1];
        add_axle_force(&self.t, -yaw_moment / self.t.l, &mut dx[..N_STATES]);
        f_d
    }
}

impl SimPlant for TrailerPlant {
    /// The trailer yawed by the mean of the two angles (its one measured yaw), at rest.
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

    /// The hitch angle on both channels: the sensor at the hitch is the trailer's one yaw
    /// measurement (the mode meter takes the mean of the two).
    fn wheel_yaw_rad(&self) -> [f64; 2] {
        [self.x[PSI]; 2]
    }

    /// The hitch's lateral displacement as the yaw it makes over the drawbar, `y / l`.
    fn steering_angle_rad(&self) -> f64 {
        self.x[Y] / self.t.l
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
        &SIM_STATE_NAMES
    }

    fn time_s(&self) -> f64 {
        self.t_s
    }

    fn vector_field(&self, x: &[f64], inputs: &Inputs, dx: &mut [f64]) {
        let mut at_speed = self.clone();
        at_speed.a = self.a0 + self.da * inputs.speed_mps;
        let mut s = [0.0; N_SIM];
        s.copy_from_slice(x);
        let mut ds = [0.0; N_SIM];
        at_speed.rhs(&s, inputs, &mut ds);
        dx.copy_from_slice(&ds);
    }
}

impl SimModel<N_STATES> for TrailerParams {
    type Linear = TrailerParams;
    type Plant = TrailerPlant;
    type State = [f64; N_SIM];
    type Vehicle = FamilyVehicle<TrailerParams>;
    const STEERING: &'static str = "hitch y/l";

    fn family_vehicle(v: &Self::Vehicle) -> FamilyVehicle<Self> {
        *v
    }

    fn parts_mut(v: &mut Self::Vehicle) -> &mut Vehicle {
        &mut v.parts
    }

    fn linear(&self) -> Self {
        *self
    }

    /// The trailer's yaw is its second state (the first is the hitch's lateral displacement).
    fn kick_state(psi_rad: f64) -> [f64; N_SIM] {
        let mut x = [0.0; N_SIM];
        x[PSI] = psi_rad;
        x
    }

    /// One integrator (Dopri5) at `method`'s relative tolerance (1e-7 for the fixed-step
    /// methods).
    fn plant(&self, damper: Damper, method: Method) -> TrailerPlant {
        let rtol = method.rtol();
        TrailerPlant::new(self, damper, rtol)
    }

    fn rolling_radius_m(&self) -> f64 {
        WHEEL_RADIUS_M
    }

    /// The damper's lever at the hitch: its stroke `l_d psi` is the family's
    /// `(l_t/2)(psi_L + psi_R)` with both channels at psi.
    fn steering_arm_m(&self) -> f64 {
        self.l_d
    }

    /// The ASMC's model of the yaw about the hitch: force per unit yaw acceleration
    /// `2 I_k / l_t = I_hitch / l_d` (I_k = I_hitch / 2, l_t = l_d); the yaw has no damping of
    /// its own (c_k = 0: the hitch's lateral damping acts on y).
    fn nominal_plant(&self) -> NominalPlant {
        NominalPlant {
            i_k_kgm2: (0.5 * self.i_hitch()) as f32,
            c_k_nms_per_rad: 0.0,
            l_t_m: self.l_d as f32,
        }
    }

    fn host_app_model(&self) -> Option<(Self::Linear, f32)> {
        None
    }

    /// The tyres' yaw stiffness about the hitch per wheel, `l C_a / 2`, over the car's
    /// `(e + t_p) C_a`: the same slip disturbance on each of the two tyres.
    fn yaw_torque_scale(&self) -> f64 {
        0.5 * self.l * self.cornering_stiffness() / reference_tyre_yaw_stiffness()
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

/// The trailer's sway damper against the car's steering damper, as a factor on every force
/// coefficient ([`damper_scale_like_the_cars`]: the same multiple of the least stabilising
/// coefficient at the rated current), sized on the named caravan.
pub fn trailer_damper_scale() -> Result<f64> {
    static SCALE: std::sync::OnceLock<std::result::Result<f64, String>> =
        std::sync::OnceLock::new();
    SCALE
        .get_or_init(|| {
            damper_scale_like_the_cars(&TrailerSet::Caravan.params()).map_err(|e| format!("{e:#}"))
        })
        .clone()
        .map_err(|e| anyhow::anyhow!(e))
}

/// The trailer's shared sections: the car's reference damper, sensors, gains and thresholds
/// with the damper's force coefficients scaled by [`trailer_damper_scale`]
/// ([`car_parts_with_damper_scaled`], as the mining truck's).
pub fn trailer_parts() -> Result<Vehicle> {
    Ok(car_parts_with_damper_scaled(trailer_damper_scale()?))
}

/// The trailer `t` with its shared sections ([`trailer_parts`]).
pub fn trailer_vehicle(t: TrailerParams) -> Result<FamilyVehicle<TrailerParams>> {
    Ok(FamilyVehicle {
        model: t,
        parts: trailer_parts()?,
    })
}

/// The trailer in the registry (`super::registry`): its files and sets give its parameters only
/// (no MR damper configured); it runs with [`trailer_parts`] ([`trailer_vehicle`]).
impl super::registry::ModelEntry<N_STATES> for TrailerParams {
    type File = TrailerParams;
    const SECTION: Option<&'static str> = Some("trailer");
    const SHARED_SECTIONS: bool = false;
    const DEFAULT_SET: &'static str = TrailerSet::Caravan.name();
    const MR_DAMPER: bool = false;
    const NO_DRIVER: Option<&'static str> = Some("has no steering for a driver torque");
    /// The simulator tyre's friction and shape and the damper lever.
    const NO_LINEAR_EFFECT: &'static [&'static str] = &["mu", "c_s", "l_d"];

    fn set_names() -> Vec<&'static str> {
        TrailerSet::ALL.iter().map(|s| s.name()).collect()
    }
    fn set(name: &str) -> Option<Self> {
        TrailerSet::from_name(name).map(TrailerSet::params)
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
                e.to_string().replacen("field `", "field `trailer.", 1)
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
    fn vehicle(f: Self) -> Result<FamilyVehicle<TrailerParams>> {
        trailer_vehicle(f)
    }
    fn file_of(v: &FamilyVehicle<TrailerParams>) -> Self {
        v.model
    }
    fn with_params(v: &FamilyVehicle<TrailerParams>, model: Self) -> FamilyVehicle<TrailerParams> {
        FamilyVehicle { model, ..*v }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use shimmy_core::stability::{self, CrossingKind, DEFAULT_TOL_MPS};
    use shimmy_core::vehicles::trailer::TrailerSet;

    /// The family's plant linearises to the core's linear model: its finite-difference
    /// Jacobian at rest with a viscous sway damper is A(V, c) (the damper's states do not
    /// enter), at a speed below, at and above the onset; the disturbances' yaw torques enter as
    /// the yaw moment of a lateral force at the axle (`-l F`, the tyre's path).
    #[test]
    fn the_family_plant_linearises_to_the_core_model() {
        let t = TrailerSet::Caravan.params();
        let c = t.damper_of_zeta(0.05);
        let plant = TrailerPlant::new(&t, Damper::Viscous(c), 1e-7);
        for v in [20.0, 28.05, 35.0] {
            let mut p = plant.clone();
            p.a = p.a0 + p.da * v;
            let u = Inputs {
                speed_mps: v,
                ..Inputs::default()
            };
            let a = t.linearise(v, c);
            let h = 1e-7;
            for j in 0..N_STATES {
                let (mut xp, mut xm) = ([0.0; N_SIM], [0.0; N_SIM]);
                xp[j] = h;
                xm[j] = -h;
                let (mut fp, mut fm) = ([0.0; N_SIM], [0.0; N_SIM]);
                p.rhs(&xp, &u, &mut fp);
                p.rhs(&xm, &u, &mut fm);
                for i in 0..N_STATES {
                    let d = (fp[i] - fm[i]) / (2.0 * h);
                    let scale = a.column(j).amax().max(1e-12);
                    assert!(
                        (d - a[(i, j)]).abs() < 1e-6 * scale,
                        "V {v}: A[{i},{j}] = {} vs finite difference {d}",
                        a[(i, j)]
                    );
                }
            }
            // a yaw torque pair: the moment about the hitch of the force at the axle
            let tq = Inputs {
                yaw_torque_nm: [30.0, 20.0],
                ..u
            };
            let mut f = [0.0; N_SIM];
            p.rhs(&[0.0; N_SIM], &tq, &mut f);
            let force = -50.0 / t.l;
            // M^-1 [F, -l F] written out: M^-1 = [[I_h, m a], [m a, m]] / (m I_z)
            let want_dpsi = (t.m * t.a * force - t.m * t.l * force) / (t.m * t.i_z);
            assert!(
                (f[DPSI] - want_dpsi).abs() < 1e-12 * want_dpsi.abs(),
                "{f:?}"
            );
            let want_dy = (t.i_hitch() * force - t.m * t.a * t.l * force) / (t.m * t.i_z);
            assert!((f[DY] - want_dy).abs() < 1e-12 * want_dy.abs(), "{f:?}");
        }
    }

    /// The MR damper at the hitch at its rated current dissipates: its force has the sign of
    /// the stroke rate `l_d psi'` over a swaying run; and at 0 A it dissipates less.
    #[test]
    fn the_mr_sway_damper_dissipates_more_at_the_rated_current() {
        let t = TrailerSet::Caravan.params();
        let parts = trailer_parts().unwrap();
        let work = |current: f64| {
            let mut p = t.plant(Damper::Mr(parts.damper.spencer), Method::default());
            p.set_wheel_yaw(2e-2, 2e-2);
            let u = Inputs {
                speed_mps: 25.0,
                current_cmd_a: current,
                ..Inputs::default()
            };
            let mut w = 0.0;
            for _ in 0..3000 {
                let rate = t.l_d * p.state()[DPSI];
                w += p.damper_force_n(&u) * rate * 1e-3;
                p.advance(1e-3, &u).unwrap();
            }
            w
        };
        let (w0, w2) = (work(0.0), work(parts.damper.spencer.u_max));
        let s = trailer_damper_scale().unwrap();
        let deg = super::super::damper_equiv::REF_WHEEL_YAW_AMPL_RAD.to_degrees();
        let car =
            shimmy_core::vehicle::Vehicle::from_set(shimmy_core::vehicles::car::ParamSet::Nominal);
        // the car's damper on the trailer (the sizing's first pass), then times the scale: the
        // Spencer force is linear in the force coefficients
        let ceq = |i| {
            super::super::damper_equiv::damper_equivalent(
                &t,
                &car.damper.spencer,
                i,
                deg,
                1.0 / 3.6,
                150.0 / 3.6,
            )
            .unwrap()
            .c_eq_nspm
                * s
        };
        let c_least = super::super::damper_sizing::least_stabilising_c(&t).unwrap();
        println!(
            "scale {s:.3}; least stabilising c {c_least:.0} N s/m; c_eq of the scaled damper at \
             0 A {:.0}, at 2 A {:.0} N s/m; damper work over 3 s: 0 A {w0:.3} J, rated {w2:.3} J",
            ceq(0.0),
            ceq(2.0)
        );
        assert!(w2 > 0.0 && w2 > w0, "{w0} {w2}");
    }

    /// The tyre has the linear model's slope at 0 and saturates at mu F_z.
    #[test]
    fn the_tyre_linearises_to_the_model_and_saturates() {
        let t = TrailerSet::Caravan.params();
        let sim = TrailerSim::new(&t, 20.0, 0.0, [0.0; N_STATES]);
        let h = 1e-7;
        let slope = (sim.tyre_force_n(h) - sim.tyre_force_n(-h)) / (2.0 * h);
        let ca = t.cornering_stiffness();
        assert!((slope - ca).abs() < 1e-6 * ca);
        let peak = (1..200)
            .map(|i| sim.tyre_force_n(f64::from(i) * 0.005))
            .fold(0.0, f64::max);
        assert!(
            (peak - t.mu * t.axle_load_n()).abs() < 1e-3 * peak,
            "{peak}"
        );
    }

    /// The Hopf speed in the time domain: from a 0.1 deg yaw start the nonlinear plant's yaw
    /// envelope grows 3 km/h above the eigenvalue onset and decays 3 km/h below it, at the
    /// eigenvalues' rate (10 % + 2e-3 1/s), damper off and with a sway damper of zeta 0.05.
    #[test]
    fn hopf_speed_matches_the_time_domain_onset() {
        let t = TrailerSet::Caravan.params();
        for c in [0.0, t.damper_of_zeta(0.05)] {
            let cs = stability::hopf_crossings(&t, c, 1.0, 70.0, 0.5, DEFAULT_TOL_MPS).unwrap();
            let onset = cs
                .iter()
                .find(|x| x.kind == CrossingKind::Onset)
                .unwrap()
                .speed_mps;
            for dv_kmh in [-3.0, 3.0] {
                let v = onset + dv_kmh / 3.6;
                let g = envelope_growth_1ps(&t, v, c, 0.1_f64.to_radians(), 10.0, 70.0, 6.0);
                let re = stability::critical_mode_at(&t, v, c).unwrap().re;
                println!(
                    "damper {c:.0} N s/m: onset {:.3} km/h, at {:.3} km/h: envelope {g:.5} 1/s, \
                     eigenvalue {re:.5} 1/s",
                    onset * 3.6,
                    v * 3.6
                );
                assert_eq!(g > 0.0, dv_kmh > 0.0, "{dv_kmh} km/h from the onset: {g}");
                assert!(
                    (g - re).abs() < 0.1 * re.abs() + 2e-3,
                    "envelope {g} vs {re}"
                );
            }
        }
    }

    /// Above the onset the tyres' saturation stops the growth on a limit cycle (the same one
    /// from a small and a large start); below it both starts decay (no coexisting cycle there).
    #[test]
    fn sway_settles_on_one_limit_cycle_above_the_onset() {
        let t = TrailerSet::Caravan.params();
        let onset = stability::hopf_crossings(&t, 0.0, 1.0, 70.0, 0.5, DEFAULT_TOL_MPS).unwrap()[0]
            .speed_mps;
        let above = onset + 10.0 / 3.6;
        let small = final_yaw_amplitude_rad(&t, above, 0.0, 0.5_f64.to_radians(), 200.0, 20.0);
        let large = final_yaw_amplitude_rad(&t, above, 0.0, 8.0_f64.to_radians(), 200.0, 20.0);
        println!(
            "limit cycle at {:.1} km/h: {:.3} deg (small start), {:.3} deg (large start)",
            above * 3.6,
            small.to_degrees(),
            large.to_degrees()
        );
        assert!(small.to_degrees() > 1.0, "{small}");
        assert!((small - large).abs() < 1e-3 * small, "{small} vs {large}");
        let below = onset - 5.0 / 3.6;
        let big = final_yaw_amplitude_rad(&t, below, 0.0, 8.0_f64.to_radians(), 200.0, 20.0);
        assert!(big < 0.05_f64.to_radians(), "{}", big.to_degrees());
    }
}
