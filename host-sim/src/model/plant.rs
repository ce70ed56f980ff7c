//! The nonlinear 4-DOF solid-axle steering plant of `docs/plant-model.md` (std, f64):
//! Magic-Formula tyres with first-order lag, gyroscopic coupling, the Spencer MR damper with coil
//! lag (or no damper), driver torque at the steering wheel and forward speed as an input.
//!
//! State (13): the 10 plant states
//! `[psi_L, psi_R, phi, theta_sw, dpsi_L, dpsi_R, dphi, dtheta_sw, a_L, a_R]` followed by the
//! damper's `(u, y, z)` (coil input (V = A), internal displacement in m, Bouc-Wen variable in m).
//! Without a damper the last three states stay at zero.
//!
//! [`Simulator`] integrates it one control period at a time with the inputs held (zero-order
//! hold); [`jacobian_fd`] linearises the right-hand side numerically. Open-loop runs of a
//! scenario live one layer up, in `sim::open_loop`.

use crate::model::integrator::{
    rk4_step, Ark436, ArkFixed, Dopri5, ImexSystem, IntegrateError, StepStats, Vern65,
};
use nalgebra::{DMatrix, SMatrix};
use shimmy_core::mr_damper::{self, SpencerParams, SpencerState};
use shimmy_core::vehicles::car::PlantParams;

/// Number of plant (mechanical + tyre) states.
pub const N_PLANT: usize = 10;
/// Number of simulated states (plant + damper).
pub const N_STATE: usize = 13;
/// Full simulator state.
pub type State = [f64; N_STATE];

/// Indices into [`State`]: the 10 plant states in the core's order (one definition, in
/// `shimmy_core::vehicles::car`), then the damper's internal states.
pub mod idx {
    pub use shimmy_core::vehicles::car::{
        A_L, A_R, DPHI, DPSI_L, DPSI_R, DTHETA_SW, PHI, PSI_L, PSI_R, THETA_SW,
    };
    /// Damper filtered coil input u, V (1 V per A).
    pub const U: usize = shimmy_core::vehicles::car::N_STATES;
    /// Damper internal displacement y, m.
    pub const Y: usize = U + 1;
    /// Damper Bouc-Wen variable z, m.
    pub const Z: usize = U + 2;
}

/// Names and units of the states, for CSV headers.
pub const STATE_NAMES: [&str; N_STATE] = [
    "psi_l_rad",
    "psi_r_rad",
    "phi_rad",
    "theta_sw_rad",
    "dpsi_l_radps",
    "dpsi_r_radps",
    "dphi_radps",
    "dtheta_sw_radps",
    "a_l_rad",
    "a_r_rad",
    "damper_u_v",
    "damper_y_m",
    "damper_z_m",
];

/// The steering damper fitted to the plant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Damper {
    /// No damper: F_d = 0.
    None,
    /// The Spencer modified Bouc-Wen MR damper.
    Mr(SpencerParams),
    /// A linear viscous track-rod damper F_d = c v_d with c in N s/m: exactly the damper of
    /// the linear analysis (`plant::linearise` with the same c), for checks against it.
    Viscous(f64),
}

/// The tyre force law.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TyreLaw {
    /// Magic Formula F = D sin(C_s atan(B a)) (the plant).
    MagicFormula,
    /// F = C_a a (the linearisation's tyre; for checks).
    Linear,
}

/// Inputs held over one control period.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Inputs {
    /// Coil current command, A (= damper input in V-equivalent; clamped to [0, u_max]).
    pub current_cmd_a: f64,
    /// Driver torque at the steering wheel, N m.
    pub driver_torque_nm: f64,
    /// External yaw torques about the kingpins in N m, `[left, right]` (disturbances).
    pub yaw_torque_nm: [f64; 2],
    /// Forward speed V, m/s.
    pub speed_mps: f64,
}

/// Forces at one instant (outputs).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Forces {
    /// Tyre lateral forces in N, `[left, right]`.
    pub tyre_n: [f64; 2],
    /// Damper force (N) along the track rod, positive resisting a positive stroke rate.
    pub damper_n: f64,
}

/// The plant: parameters, damper and tyre law.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plant {
    /// Physical parameters.
    pub params: PlantParams,
    /// Damper model.
    pub damper: Damper,
    /// Tyre force law.
    pub tyre: TyreLaw,
    d_n: f64,
    b_per_rad: f64,
    inv: Reciprocals,
}

/// The reciprocals of the parameters the right-hand side divides by, computed once: a product
/// costs a fraction of a division, and the right-hand side is the integrator's inner loop.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Reciprocals {
    i_k: f64,
    i_phi: f64,
    j_sw: f64,
    i_s: f64,
    sigma: f64,
}

impl Reciprocals {
    fn of(p: &PlantParams) -> Self {
        Self {
            i_k: 1.0 / p.i_k,
            i_phi: 1.0 / p.i_phi,
            j_sw: 1.0 / p.j_sw,
            i_s: 1.0 / p.i_s,
            sigma: 1.0 / p.sigma,
        }
    }
}

impl Plant {
    /// The plant with Magic-Formula tyres.
    pub fn new(params: PlantParams, damper: Damper) -> Self {
        Plant {
            params,
            damper,
            tyre: TyreLaw::MagicFormula,
            d_n: params.tyre_peak_force(),
            b_per_rad: params.tyre_stiffness_factor(),
            inv: Reciprocals::of(&params),
        }
    }

    /// The plant with the reference MR steering damper.
    pub fn with_mr_damper(params: PlantParams) -> Self {
        Self::new(params, Damper::Mr(SpencerParams::steering()))
    }

    /// A copy with another tyre law.
    #[must_use]
    pub fn with_tyre(mut self, tyre: TyreLaw) -> Self {
        self.tyre = tyre;
        self
    }

    /// Tyre lateral force (N) at lagged slip angle `a_rad`.
    #[inline]
    pub fn tyre_force_n(&self, a_rad: f64) -> f64 {
        match self.tyre {
            TyreLaw::MagicFormula => {
                super::tyre::magic_formula_n(self.d_n, self.params.c_s, self.b_per_rad, a_rad)
            }
            TyreLaw::Linear => self.params.c_a * a_rad,
        }
    }

    /// sigma * integral_0^a F(s) ds in J: the elastic energy stored in one tyre's lagged
    /// deformation (see the energy test), by composite Simpson with 256 intervals.
    pub fn tyre_strain_energy_j(&self, a_rad: f64) -> f64 {
        let n = 256;
        let h = a_rad / n as f64;
        let mut s = self.tyre_force_n(0.0) + self.tyre_force_n(a_rad);
        for k in 1..n {
            let w = if k % 2 == 1 { 4.0 } else { 2.0 };
            s += w * self.tyre_force_n(k as f64 * h);
        }
        self.params.sigma * s * h / 3.0
    }

    /// Damper stroke x_d = (l_t/2)(psi_L + psi_R), m and stroke rate, m/s.
    #[inline]
    pub fn damper_stroke(&self, x: &State) -> (f64, f64) {
        let half = 0.5 * self.params.l_t;
        (
            half * (x[idx::PSI_L] + x[idx::PSI_R]),
            half * (x[idx::DPSI_L] + x[idx::DPSI_R]),
        )
    }

    /// Right-hand side dx/dt at state `x` under inputs `u`; returns the forces.
    #[inline]
    pub fn rhs(&self, x: &State, u: &Inputs, dx: &mut State) -> Forces {
        let p = &self.params;
        let v = u.speed_mps;
        let h = p.i_p * v / p.r;
        let (psi_l, psi_r, phi, th) = (x[0], x[1], x[2], x[3]);
        let (dpsi_l, dpsi_r, dphi, dth) = (x[4], x[5], x[6], x[7]);
        let (a_l, a_r) = (x[8], x[9]);
        let f_l = self.tyre_force_n(a_l);
        let f_r = self.tyre_force_n(a_r);
        let f_d = match &self.damper {
            Damper::None => {
                dx[idx::U] = 0.0;
                dx[idx::Y] = 0.0;
                dx[idx::Z] = 0.0;
                0.0
            }
            Damper::Viscous(c) => {
                dx[idx::U] = 0.0;
                dx[idx::Y] = 0.0;
                dx[idx::Z] = 0.0;
                c * self.damper_stroke(x).1
            }
            Damper::Mr(sp) => {
                let (xd, vd) = self.damper_stroke(x);
                let st = SpencerState {
                    u: x[idx::U],
                    y: x[idx::Y],
                    z: x[idx::Z],
                };
                let r = mr_damper::rates(sp, &st, xd, vd, u.current_cmd_a);
                dx[idx::U] = r.du;
                dx[idx::Y] = r.dy;
                dx[idx::Z] = r.dz;
                r.force_n
            }
        };
        let trail = p.e + p.t_p;
        let damper_torque = 0.5 * p.l_t * f_d;
        let inv = &self.inv;
        let k_d_twist = p.k_d * (th * inv.i_s - psi_l);
        let k_tr_twist = p.k_tr * (psi_l - psi_r);
        dx[0] = dpsi_l;
        dx[1] = dpsi_r;
        dx[2] = dphi;
        dx[3] = dth;
        dx[4] = (-p.c_k * dpsi_l - k_tr_twist + k_d_twist - trail * f_l - h * dphi - damper_torque
            + u.yaw_torque_nm[0])
            * inv.i_k;
        dx[5] = (-p.c_k * dpsi_r + k_tr_twist - trail * f_r - h * dphi - damper_torque
            + u.yaw_torque_nm[1])
            * inv.i_k;
        dx[6] = (-p.c_phi * dphi - p.k_phi * phi + p.h_r * (f_l + f_r) + h * (dpsi_l + dpsi_r))
            * inv.i_phi;
        dx[7] = (-p.c_sw * dth - k_d_twist * inv.i_s + u.driver_torque_nm) * inv.j_sw;
        dx[8] = (v * (psi_l - a_l) + p.e * dpsi_l - p.h_r * dphi) * inv.sigma;
        dx[9] = (v * (psi_r - a_r) + p.e * dpsi_r - p.h_r * dphi) * inv.sigma;
        Forces {
            tyre_n: [f_l, f_r],
            damper_n: f_d,
        }
    }

    /// Forces at state `x` under inputs `u`.
    pub fn forces(&self, x: &State, u: &Inputs) -> Forces {
        let mut dx = [0.0; N_STATE];
        self.rhs(x, u, &mut dx)
    }

    /// Mechanical energy in J: kinetic + spring potentials (K_tr, K_d, K_phi).
    pub fn mechanical_energy_j(&self, x: &State) -> f64 {
        let p = &self.params;
        let kin = 0.5
            * (p.i_k * (x[4] * x[4] + x[5] * x[5]) + p.i_phi * x[6] * x[6] + p.j_sw * x[7] * x[7]);
        let tw_tr = x[0] - x[1];
        let tw_d = x[3] / p.i_s - x[0];
        let pot = 0.5 * (p.k_tr * tw_tr * tw_tr + p.k_d * tw_d * tw_d + p.k_phi * x[2] * x[2]);
        kin + pot
    }
}

/// Which integrator [`Simulator`] uses inside a control period.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Method {
    /// Adaptive Dormand-Prince 5(4) with relative tolerance `rtol` (absolute tolerances scaled
    /// per state, see [`default_atol`]).
    Dopri5 {
        /// Relative tolerance.
        rtol: f64,
    },
    /// Adaptive Verner 6(5) ([`Vern65`]) with relative tolerance `rtol` (the same absolute
    /// tolerances as Dopri5): one order higher than Dopri5, so longer steps at the same
    /// tolerance.
    Vern65 {
        /// Relative tolerance.
        rtol: f64,
    },
    /// Classical RK4 with `substeps` equal steps per `advance` call.
    Rk4 {
        /// Steps per call.
        substeps: u32,
    },
    /// Adaptive additive Runge-Kutta ARK4(3)6L\[2\]SA (IMEX, [`Ark436`]) with relative tolerance
    /// `rtol`: the stiff Bouc-Wen variable z of the MR damper goes through the L-stable ESDIRK
    /// tableau (a scalar Newton solve per stage), everything else through the explicit tableau.
    /// The step size is then set by accuracy, not by z's relaxation rate (up to ~2e4 /s when
    /// the damper slides).
    Imex {
        /// Relative tolerance.
        rtol: f64,
    },
    /// The same IMEX pair at a fixed step ([`ArkFixed`]): `substeps` equal steps per `advance`
    /// call (per control period in the closed loop), no error control. Accurate when the
    /// period resolves the slow (explicit) dynamics; z's stiff relaxation is taken by the
    /// L-stable implicit tableau whatever its rate.
    ImexFixed {
        /// Steps per call.
        substeps: u32,
    },
}

impl Method {
    /// The names [`Method::from_name`] accepts, for help texts and errors.
    pub const NAMES: &'static str =
        "dopri5, dopri5:RTOL, vern65, vern65:RTOL, imex:RTOL, imex-fixed, imex-fixed:SUBSTEPS";

    /// Parses `dopri5[:rtol]` or `vern65[:rtol]` (default rtol 1e-7), `imex:rtol` (the adaptive IMEX) or
    /// `imex-fixed[:substeps]` (default 1 step per call); rtol in (0, 1e-2], substeps 1 to 64.
    pub fn from_name(name: &str) -> Result<Self, String> {
        let (kind, arg) = match name.split_once(':') {
            Some((k, a)) => (k, Some(a)),
            None => (name, None),
        };
        let rtol = |a: Option<&str>| -> Result<f64, String> {
            let Some(a) = a else {
                return Ok(1e-7);
            };
            match a.parse::<f64>() {
                Ok(r) if r > 0.0 && r <= 1e-2 => Ok(r),
                _ => Err(format!(
                    "integrator `{name}`: rtol `{a}` must be a number in (0, 1e-2]"
                )),
            }
        };
        match kind {
            "dopri5" => Ok(Method::Dopri5 { rtol: rtol(arg)? }),
            "vern65" => Ok(Method::Vern65 { rtol: rtol(arg)? }),
            "imex" => Ok(Method::Imex { rtol: rtol(arg)? }),
            "imex-fixed" => {
                let substeps = match arg {
                    None => 1,
                    Some(a) => match a.parse::<u32>() {
                        Ok(n) if (1..=64).contains(&n) => n,
                        _ => {
                            return Err(format!(
                            "integrator `{name}`: substeps `{a}` must be an integer from 1 to 64"
                        ))
                        }
                    },
                };
                Ok(Method::ImexFixed { substeps })
            }
            _ => Err(format!(
                "integrator `{name}`: unknown, expected one of {}",
                Self::NAMES
            )),
        }
    }

    /// The relative tolerance of an adaptive method, 1e-7 for the fixed-step ones: what a
    /// plant with a single adaptive integrator takes from any method.
    pub fn rtol(&self) -> f64 {
        match *self {
            Method::Dopri5 { rtol } | Method::Imex { rtol } | Method::Vern65 { rtol } => rtol,
            Method::Rk4 { .. } | Method::ImexFixed { .. } => 1e-7,
        }
    }

    /// The name [`Method::from_name`] parses back.
    pub fn name(&self) -> String {
        match self {
            Method::Dopri5 { rtol } => format!("dopri5:{rtol:e}"),
            Method::Vern65 { rtol } => format!("vern65:{rtol:e}"),
            Method::Imex { rtol } => format!("imex:{rtol:e}"),
            Method::ImexFixed { substeps } => format!("imex-fixed:{substeps}"),
            Method::Rk4 { substeps } => format!("rk4:{substeps}"),
        }
    }
}

impl Default for Method {
    fn default() -> Self {
        Method::Dopri5 { rtol: 1e-7 }
    }
}

/// Absolute tolerances per state for relative tolerance `rtol`: each state's typical scale times
/// `rtol` (angles 1 rad... tiny shimmy amplitudes are 1e-4 rad, so the angle scale is 1e-3 rad;
/// rates 1e-1 rad/s; damper displacements 1e-4 m; coil input 1 V).
pub fn default_atol(rtol: f64) -> State {
    let mut a = [0.0; N_STATE];
    for (i, v) in a.iter_mut().enumerate() {
        let scale = match i {
            0..=3 | 8 | 9 => 1e-3,
            4..=7 => 1e-1,
            idx::U => 1.0,
            _ => 1e-4,
        };
        *v = rtol * scale;
    }
    a
}

/// The plant under held inputs, split for the IMEX stepper: only the Bouc-Wen variable z is
/// implicit. Its stage equation `z = c + h_gamma dz(x, z)` (all other states fixed) is scalar:
/// solved by Newton's method with the analytic derivative.
struct HeldInputs<'a> {
    plant: &'a Plant,
    inputs: &'a Inputs,
    // The previous stage's implicit increment z - c (h gamma dz/dt there): the next stage's
    // Newton iteration starts from c plus it, one iteration closer than from c alone.
    last_increment_m: std::cell::Cell<f64>,
}

impl ImexSystem<N_STATE> for HeldInputs<'_> {
    #[inline]
    fn rhs(&self, y: &State, dy: &mut State) {
        self.plant.rhs(y, self.inputs, dy);
    }

    #[inline]
    fn implicit(&self, i: usize) -> bool {
        i == idx::Z && matches!(self.plant.damper, Damper::Mr(_))
    }

    fn solve_implicit(&self, y: &mut State, h_gamma: f64, diag: &mut State) -> bool {
        let Damper::Mr(sp) = &self.plant.damper else {
            return true;
        };
        let (xd, vd) = self.plant.damper_stroke(y);
        let (alpha, c0, c1) = sp.coefficients(y[idx::U]);
        // rel(z) = v_d - dy/dt = r0 - kappa z (dy/dt is affine in z).
        let kappa = alpha / (c0 + c1);
        let r0 = vd - (c0 * vd + sp.k0 * (xd - y[idx::Y])) / (c0 + c1);
        let c = y[idx::Z];
        let n = sp.n;
        // Newton from the explicit predictor c plus the previous stage's increment. Stop once
        // the update is below 1e-9 m: with quadratic convergence (|g''/2g'| <~ 1e2 /m here) the
        // remaining error is then ~1e-16 m, far below any absolute tolerance on z in use
        // (rtol * 1e-4 m).
        let mut z = c + self.last_increment_m.get();
        for _ in 0..30 {
            let rel = r0 - kappa * z;
            let az = z.abs();
            let (z_n, z_n1) = if n == 2.0 {
                (az * az, az)
            } else {
                (az.powf(n), az.powf(n - 1.0))
            };
            let sgn_rel = if rel > 0.0 {
                1.0
            } else if rel < 0.0 {
                -1.0
            } else {
                0.0
            };
            let f = sp.a_bw * rel - sp.beta * rel * z_n - sp.gamma * rel.abs() * z_n1 * z;
            // d/dz of the above with d rel/dz = -kappa, d|z|^n/dz = n |z|^(n-1) sgn z,
            // d(|z|^(n-1) z)/dz = n |z|^(n-1).
            let df = -kappa * (sp.a_bw - sp.beta * z_n - sp.gamma * sgn_rel * z_n1 * z)
                - sp.beta * rel * n * z_n1 * z.signum()
                - sp.gamma * rel.abs() * n * z_n1;
            let g = z - c - h_gamma * f;
            let dg = 1.0 - h_gamma * df;
            if dg.abs() < 1e-12 || !dg.is_finite() {
                return false;
            }
            let dz = g / dg;
            z -= dz;
            if dz.abs() <= 1e-9 {
                y[idx::Z] = z;
                diag[idx::Z] = dg;
                self.last_increment_m.set(z - c);
                return z.is_finite();
            }
        }
        false
    }
}

/// The plant in time: state, time and an integrator that lives across control periods.
#[derive(Clone, Debug)]
pub struct Simulator {
    plant: Plant,
    x: State,
    t_s: f64,
    method: Method,
    dopri: Dopri5<N_STATE>,
    vern: Vern65<N_STATE>,
    ark: Ark436<N_STATE>,
    ark_fixed: ArkFixed<N_STATE>,
    rk4_evals: u64,
    // Inputs of the last successful Dopri5 period, while the state is untouched since: the
    // derivative at the start of the next period is then the last one of this (FSAL).
    last_inputs: Option<Inputs>,
    // The right-hand side [`Self::forces`] evaluated at the current state, with its inputs:
    // the next `advance` under the same inputs (bit for bit) starts from it instead of
    // evaluating it again (the closed loop asks for the forces every period).
    start_derivative: std::cell::Cell<Option<(Inputs, State)>>,
}

/// Whether two inputs are the same bit for bit (a derivative evaluated under one is then
/// exactly the derivative under the other; `==` would take 0.0 for -0.0).
fn same_bits(a: &Inputs, b: &Inputs) -> bool {
    let bits = |u: &Inputs| {
        [
            u.current_cmd_a,
            u.driver_torque_nm,
            u.yaw_torque_nm[0],
            u.yaw_torque_nm[1],
            u.speed_mps,
        ]
        .map(f64::to_bits)
    };
    // Element by element: `==` on the arrays calls `memcmp`, 1 % of a closed-loop run.
    bits(a).iter().zip(bits(b)).all(|(x, y)| *x == y)
}

impl Simulator {
    /// A simulator at time 0 in state `x0` with the default integrator (Dopri5, rtol 1e-7).
    pub fn new(plant: Plant, x0: State) -> Self {
        Self::with_method(plant, x0, Method::default())
    }

    /// A simulator with a chosen integrator.
    pub fn with_method(plant: Plant, x0: State, method: Method) -> Self {
        let rtol = method.rtol();
        Simulator {
            plant,
            x: x0,
            t_s: 0.0,
            method,
            dopri: Dopri5::new(rtol, default_atol(rtol)),
            vern: Vern65::new(rtol, default_atol(rtol)),
            ark: Ark436::new(rtol, default_atol(rtol)),
            ark_fixed: ArkFixed::new(match method {
                Method::ImexFixed { substeps } => substeps,
                _ => 1,
            }),
            rk4_evals: 0,
            last_inputs: None,
            start_derivative: std::cell::Cell::new(None),
        }
    }

    /// Advances by `dt_s` with `inputs` held constant (zero-order hold).
    pub fn advance(&mut self, dt_s: f64, inputs: &Inputs) -> Result<(), IntegrateError> {
        let plant = self.plant;
        let mut f = |_t: f64, x: &State, dx: &mut State| {
            plant.rhs(x, inputs, dx);
        };
        // The derivative at the current state under these inputs, if `forces` evaluated it.
        let start = self
            .start_derivative
            .take()
            .filter(|(u, _)| same_bits(u, inputs))
            .map(|(_, dx)| dx);
        match self.method {
            Method::Dopri5 { .. } => {
                let mut reuse = self.last_inputs.as_ref() == Some(inputs);
                if let (false, Some(dx)) = (reuse, start) {
                    self.dopri.set_start_derivative(dx);
                    reuse = true;
                }
                self.last_inputs = None;
                self.dopri
                    .integrate_fsal(&mut f, self.t_s, &mut self.x, dt_s, reuse)?;
                self.last_inputs = Some(*inputs);
            }
            Method::Vern65 { .. } => {
                self.vern
                    .integrate(&mut f, self.t_s, &mut self.x, dt_s, start)?;
            }
            Method::Imex { .. } => {
                let sys = HeldInputs {
                    plant: &plant,
                    inputs,
                    last_increment_m: std::cell::Cell::new(0.0),
                };
                self.ark.integrate(&sys, self.t_s, &mut self.x, dt_s)?;
            }
            Method::ImexFixed { .. } => {
                let sys = HeldInputs {
                    plant: &plant,
                    inputs,
                    last_increment_m: std::cell::Cell::new(0.0),
                };
                self.ark_fixed
                    .integrate(&sys, self.t_s, &mut self.x, dt_s, start)?;
            }
            Method::Rk4 { substeps } => {
                let n = substeps.max(1);
                let h = dt_s / f64::from(n);
                for k in 0..n {
                    rk4_step(&mut f, self.t_s + f64::from(k) * h, &mut self.x, h);
                }
                self.rk4_evals += 4 * u64::from(n);
                if !self.x.iter().all(|v| v.is_finite()) {
                    return Err(IntegrateError::NonFinite { t: self.t_s });
                }
            }
        }
        self.t_s += dt_s;
        Ok(())
    }

    /// The plant being simulated.
    pub fn plant(&self) -> &Plant {
        &self.plant
    }

    /// Current state.
    pub fn state(&self) -> &State {
        &self.x
    }

    /// Replaces the state (e.g. to apply a kick).
    pub fn set_state(&mut self, x: State) {
        self.x = x;
        self.last_inputs = None;
        self.start_derivative.set(None);
    }

    /// Simulated time, s.
    pub fn time_s(&self) -> f64 {
        self.t_s
    }

    /// Forces at the current state under `inputs` (the right-hand side evaluated there is kept
    /// for the next [`advance`](Self::advance) under the same inputs).
    pub fn forces(&self, inputs: &Inputs) -> Forces {
        let mut dx = [0.0; N_STATE];
        let f = self.plant.rhs(&self.x, inputs, &mut dx);
        self.start_derivative.set(Some((*inputs, dx)));
        f
    }

    /// Integrator statistics (right-hand-side evaluations so far, steps).
    pub fn stats(&self) -> StepStats {
        let mut s = self.dopri.stats;
        for o in [self.vern.stats, self.ark.stats, self.ark_fixed.stats] {
            s.accepted += o.accepted;
            s.rejected += o.rejected;
            s.evaluations += o.evaluations;
        }
        s.evaluations += self.rk4_evals;
        s
    }
}

/// Finite-difference Jacobian (central differences) of the plant right-hand side with respect to
/// the 10 plant states, about straight running (`x = 0`) at speed `v_mps`, without damper
/// (F_d = 0) and in the tyres' linear region. Column j is `(f(x + h e_j) - f(x - h e_j)) / 2h`
/// with `h = 1e-7` in each state's unit: the Magic Formula is odd, so the central difference
/// has no even-order error and its cubic term contributes O((B h)^2) ~ 1e-12 relative.
pub fn jacobian_fd(params: &PlantParams, v_mps: f64) -> SMatrix<f64, N_PLANT, N_PLANT> {
    let plant = Plant::new(*params, Damper::None);
    let u = Inputs {
        speed_mps: v_mps,
        ..Inputs::default()
    };
    let h = 1e-7;
    let mut jac = SMatrix::<f64, N_PLANT, N_PLANT>::zeros();
    for j in 0..N_PLANT {
        let (mut xp, mut xm) = ([0.0; N_STATE], [0.0; N_STATE]);
        xp[j] = h;
        xm[j] = -h;
        let (mut fp, mut fm) = ([0.0; N_STATE], [0.0; N_STATE]);
        plant.rhs(&xp, &u, &mut fp);
        plant.rhs(&xm, &u, &mut fm);
        for i in 0..N_PLANT {
            jac[(i, j)] = (fp[i] - fm[i]) / (2.0 * h);
        }
    }
    jac
}

/// Eigenvalues (real, imaginary) of a square matrix via nalgebra's real Schur decomposition with
/// a bounded iteration count. `None` if it did not converge.
pub fn eigenvalues(a: &DMatrix<f64>) -> Option<Vec<(f64, f64)>> {
    let schur = nalgebra::linalg::Schur::try_new(a.clone(), 1e-14, 10_000)?;
    let ev = schur.complex_eigenvalues();
    Some(ev.iter().map(|c| (c.re, c.im)).collect())
}

/// Eigenvalues `(re in 1/s, im in rad/s)` of the FD Jacobian at `v_mps`.
pub fn fd_eigenvalues(params: &PlantParams, v_mps: f64) -> Option<Vec<(f64, f64)>> {
    let j = jacobian_fd(params, v_mps);
    eigenvalues(&DMatrix::from_column_slice(N_PLANT, N_PLANT, j.as_slice()))
}

/// The least-damped oscillatory eigenvalue (largest real part among those with imaginary part
/// > 1 rad/s) of the FD Jacobian at `v_mps`: `(re in 1/s, im in rad/s)`.
pub fn least_damped_mode(params: &PlantParams, v_mps: f64) -> Option<(f64, f64)> {
    fd_eigenvalues(params, v_mps)?
        .into_iter()
        .filter(|&(_, im)| im > 1.0)
        .max_by(|a, b| a.0.total_cmp(&b.0))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Entries of the FD Jacobian against the equations of docs/plant-model.md read off by hand
    /// (relative 1e-6: central differences with h = 1e-7).
    #[test]
    fn fd_jacobian_matches_hand_derived_entries() {
        let p = PlantParams::nominal();
        let v = 20.0;
        let j = jacobian_fd(&p, v);
        let h = p.i_p * v / p.r;
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-6 * b.abs().max(1e-6);
        let checks = [
            ((4, 0), -(p.k_tr + p.k_d) / p.i_k),
            ((4, 1), p.k_tr / p.i_k),
            ((4, 3), p.k_d / (p.i_s * p.i_k)),
            ((4, 4), -p.c_k / p.i_k),
            ((4, 6), -h / p.i_k),
            ((4, 8), -(p.e + p.t_p) * p.c_a / p.i_k),
            ((6, 4), h / p.i_phi),
            ((6, 8), p.h_r * p.c_a / p.i_phi),
            ((6, 2), -p.k_phi / p.i_phi),
            ((7, 0), p.k_d / (p.i_s * p.j_sw)),
            ((7, 3), -p.k_d / (p.i_s * p.i_s * p.j_sw)),
            ((8, 0), v / p.sigma),
            ((8, 4), p.e / p.sigma),
            ((8, 6), -p.h_r / p.sigma),
            ((9, 9), -v / p.sigma),
        ];
        for ((r, c), want) in checks {
            assert!(
                close(j[(r, c)], want),
                "J[{r},{c}] = {} vs {want}",
                j[(r, c)]
            );
        }
        assert_eq!(j[(8, 1)], 0.0);
        assert_eq!(j[(5, 3)], 0.0);
    }

    #[test]
    fn magic_formula_saturates_and_is_odd() {
        let plant = Plant::new(PlantParams::nominal(), Damper::None);
        let d = plant.params.tyre_peak_force();
        let f = plant.tyre_force_n(0.5);
        assert!(f < d && f > 0.5 * d);
        assert_eq!(plant.tyre_force_n(-0.3), -plant.tyre_force_n(0.3));
        // Strain energy of the linear tyre is sigma C_a a^2 / 2 (Simpson is exact for it).
        let lin = plant.with_tyre(TyreLaw::Linear);
        let a = 0.01;
        let e = lin.tyre_strain_energy_j(a);
        let want = 0.5 * lin.params.sigma * lin.params.c_a * a * a;
        assert!((e - want).abs() < 1e-12 * want);
    }

    #[test]
    fn damper_acts_through_both_wheels_and_resists_motion() {
        let plant = Plant::with_mr_damper(PlantParams::nominal());
        let mut x = [0.0; N_STATE];
        x[idx::DPSI_L] = 1.0;
        x[idx::DPSI_R] = 1.0;
        x[idx::U] = 1.0;
        let u = Inputs {
            current_cmd_a: 1.0,
            ..Inputs::default()
        };
        let mut dx = [0.0; N_STATE];
        let f = plant.rhs(&x, &u, &mut dx);
        assert!(f.damper_n > 0.0);
        // Same torque on both wheels, opposing the motion.
        let none = Plant::new(PlantParams::nominal(), Damper::None);
        let mut dx0 = [0.0; N_STATE];
        none.rhs(&x, &u, &mut dx0);
        let dl = dx[idx::DPSI_L] - dx0[idx::DPSI_L];
        let dr = dx[idx::DPSI_R] - dx0[idx::DPSI_R];
        assert!(dl < 0.0 && (dl - dr).abs() < 1e-12);
        let want = -0.5 * plant.params.l_t * f.damper_n / plant.params.i_k;
        assert!((dl - want).abs() < 1e-9 * want.abs());
    }

    /// Integrator names round-trip; bad ones are refused naming the part and its range.
    #[test]
    fn integrator_names_parse_and_bad_ones_are_refused() {
        for m in [
            Method::Dopri5 { rtol: 1e-7 },
            Method::Vern65 { rtol: 3e-7 },
            Method::Imex { rtol: 3e-6 },
            Method::ImexFixed { substeps: 2 },
        ] {
            assert_eq!(Method::from_name(&m.name()), Ok(m));
        }
        assert_eq!(Method::from_name("dopri5"), Ok(Method::default()));
        assert_eq!(
            Method::from_name("imex-fixed"),
            Ok(Method::ImexFixed { substeps: 1 })
        );
        for (bad, says) in [
            ("imex-fixed:0", "1 to 64"),
            ("imex-fixed:x", "1 to 64"),
            ("dopri5:0.5", "(0, 1e-2]"),
            ("euler", "unknown"),
        ] {
            let e = Method::from_name(bad).unwrap_err();
            assert!(e.contains(says) && e.contains(bad), "{bad}: {e}");
        }
    }

    /// Reusing the last derivative across periods (same held input) gives bit-identical states
    /// to re-evaluating it, and saves one evaluation per period.
    #[test]
    fn fsal_across_periods_is_exact() {
        let plant = Plant::with_mr_damper(PlantParams::nominal());
        let mut x0 = [0.0; N_STATE];
        x0[idx::PSI_L] = 0.05;
        x0[idx::PSI_R] = 0.05;
        let u = Inputs {
            current_cmd_a: 0.3,
            speed_mps: 15.0,
            ..Inputs::default()
        };
        let m = Method::Dopri5 { rtol: 1e-7 };
        let mut a = Simulator::with_method(plant, x0, m);
        let mut b = Simulator::with_method(plant, x0, m);
        for _ in 0..300 {
            a.advance(1e-3, &u).unwrap();
            b.advance(1e-3, &u).unwrap();
            let x = *b.state();
            b.set_state(x); // forces a fresh derivative
        }
        assert_eq!(a.state(), b.state());
        assert_eq!(a.stats().evaluations + 299, b.stats().evaluations);
    }

    /// The closed loop asks for the forces at the start of each period: the derivative
    /// evaluated for them starts the period's integration, bit-identical to evaluating it
    /// again, one evaluation fewer per period; under other inputs (one bit off) it is not used.
    #[test]
    fn the_forces_derivative_starts_the_period_exactly() {
        let plant = Plant::with_mr_damper(PlantParams::nominal());
        let mut x0 = [0.0; N_STATE];
        x0[idx::PSI_L] = 0.05;
        let input = |k: usize| Inputs {
            current_cmd_a: 0.2 + 0.001 * (k % 7) as f64,
            speed_mps: 15.0,
            ..Inputs::default()
        };
        for m in [
            Method::Dopri5 { rtol: 1e-7 },
            Method::Vern65 { rtol: 1e-7 },
            Method::ImexFixed { substeps: 2 },
        ] {
            let mut plain = Simulator::with_method(plant, x0, m);
            let mut with = Simulator::with_method(plant, x0, m);
            let mut other = Simulator::with_method(plant, x0, m);
            for k in 0..200 {
                let u = input(k);
                plain.advance(1e-3, &u).unwrap();
                assert_eq!(with.forces(&u), plant.forces(with.state(), &u));
                with.advance(1e-3, &u).unwrap();
                let mut v = u;
                v.speed_mps = f64::from_bits(u.speed_mps.to_bits() + 1);
                other.forces(&v);
                other.advance(1e-3, &u).unwrap();
            }
            assert_eq!(plain.state(), with.state(), "{}", m.name());
            assert_eq!(plain.state(), other.state(), "{}", m.name());
            let (a, b, c) = (
                plain.stats().evaluations,
                with.stats().evaluations,
                other.stats().evaluations,
            );
            // Dopri5's first period evaluates anyway (it sizes its first step from it).
            let saved = if matches!(m, Method::Dopri5 { .. }) {
                199
            } else {
                200
            };
            assert_eq!((a - saved, c), (b, a), "{}", m.name());
        }
    }
}
