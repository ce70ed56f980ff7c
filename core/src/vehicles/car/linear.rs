//! Linearised 4-DOF solid-axle steering plant with tyre lag (`docs/plant-model.md`).
//!
//! State vector (10), indices are the named constants below:
//! `x = [psi_L, psi_R, phi, theta_sw, dpsi_L, dpsi_R, dphi, dtheta_sw, a_L, a_R]`.
//!
//! Sign conventions (as in the reference document):
//! - `psi_L`, `psi_R`: wheel yaw about the kingpins, positive = steer left, rad;
//! - `phi`: axle roll (tramp), positive = left wheel up, rad;
//! - `theta_sw`: steering-wheel angle, positive turns the wheels left through `i_s`, rad;
//! - `a_L`, `a_R`: lagged slip angles, rad; tyre force `F_i = C_a a_i`, N;
//! - `F_d`: damper force along the track rod in N, positive when it resists a positive stroke rate
//!   `v_d = (l_t/2)(dpsi_L + dpsi_R)`; it enters both wheel equations as `-(l_t/2) F_d`;
//! - `T_driver`: driver torque at the steering wheel in N m, positive in the `theta_sw` sense;
//! - gyroscopic coupling `H = I_p V / R`, N m s: `-H dphi` in both wheel equations and
//!   `+H (dpsi_L + dpsi_R)` in the roll equation (a skew-symmetric pair: no net power).
//!
//! The linearisation is exact for the linear-tyre model about straight running; a viscous damper
//! `F_d = c v_d` adds `c l_t^2/4` to the four (psi_L, psi_R) entries of the damping matrix.
//!
//! Everything here is `no_std`, allocation-free and cheap (a few hundred flops).

#[allow(unused_imports)]
use super::*;

use nalgebra::{Complex, SMatrix, SVector};

use crate::float::SolveFloat;
use crate::model::{
    larger, wheel_phase_rad, wheel_yaw_shape, ComplexVector, LinearModel, Matrix, ModeShape,
    ModeShapeInfo, UpdatableModel, UpdateParam,
};
use crate::vehicles::car::{Param, PlantParams};

/// Number of states of the linear model.
pub const N_STATES: usize = 10;
/// Number of mechanical degrees of freedom.
pub const N_DOF: usize = 4;

/// Left wheel yaw angle psi_L, rad.
pub const PSI_L: usize = 0;
/// Right wheel yaw angle psi_R, rad.
pub const PSI_R: usize = 1;
/// Axle roll (tramp) angle phi, rad.
pub const PHI: usize = 2;
/// Steering-wheel angle theta_sw, rad.
pub const THETA_SW: usize = 3;
/// Left wheel yaw rate dpsi_L, rad/s.
pub const DPSI_L: usize = 4;
/// Right wheel yaw rate dpsi_R, rad/s.
pub const DPSI_R: usize = 5;
/// Axle roll rate dphi, rad/s.
pub const DPHI: usize = 6;
/// Steering-wheel rate dtheta_sw, rad/s.
pub const DTHETA_SW: usize = 7;
/// Left lagged slip angle a_L, rad.
pub const A_L: usize = 8;
/// Right lagged slip angle a_R, rad.
pub const A_R: usize = 9;

/// Short names of the states, for tables and CSV headers.
pub const STATE_NAMES: [&str; N_STATES] = [
    "psi_L_rad",
    "psi_R_rad",
    "phi_rad",
    "theta_sw_rad",
    "dpsi_L_radps",
    "dpsi_R_radps",
    "dphi_radps",
    "dtheta_sw_radps",
    "a_L_rad",
    "a_R_rad",
];

/// The second-order mechanical part of the linear model:
/// `M q'' + C q' + K q = G a + b_d F_d + b_t T_driver` with `q = [psi_L, psi_R, phi, theta_sw]`,
/// and the tyre-lag equations `sigma a' = V (S q - a) + E q' ` written out in [`linearise`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SecondOrder {
    /// Mass matrix M = diag(I_k, I_k, I_phi, J_sw), kg m^2.
    pub m: SMatrix<f64, N_DOF, N_DOF>,
    /// Damping matrix C incl. the gyroscopic (skew) part and the viscous damper, N m s/rad.
    pub c: SMatrix<f64, N_DOF, N_DOF>,
    /// Stiffness matrix K (symmetric), N m/rad.
    pub k: SMatrix<f64, N_DOF, N_DOF>,
    /// Generalised tyre forces per unit lagged slip angle, columns (a_L, a_R), N m/rad.
    pub g: SMatrix<f64, N_DOF, 2>,
}

/// Mass, damping (with gyroscopic coupling at speed `v_mps` and a viscous track-rod damper
/// `c_damper_nspm` in N s/m) and stiffness matrices of the mechanical subsystem.
pub fn second_order(p: &PlantParams, v_mps: f64, c_damper_nspm: f64) -> SecondOrder {
    let h = p.spin_momentum(v_mps);
    let cd = c_damper_nspm * p.l_t * p.l_t / 4.0;
    let kd_is = p.k_d / p.i_s;
    let lever = p.e + p.t_p;

    let mut m = SMatrix::<f64, N_DOF, N_DOF>::zeros();
    m[(0, 0)] = p.i_k;
    m[(1, 1)] = p.i_k;
    m[(2, 2)] = p.i_phi;
    m[(3, 3)] = p.j_sw;

    let mut c = SMatrix::<f64, N_DOF, N_DOF>::zeros();
    c[(0, 0)] = p.c_k + cd;
    c[(0, 1)] = cd;
    c[(1, 0)] = cd;
    c[(1, 1)] = p.c_k + cd;
    c[(2, 2)] = p.c_phi;
    c[(3, 3)] = p.c_sw;
    // Gyroscopic: -H dphi in both wheel rows, +H (dpsi_L + dpsi_R) in the roll row.
    c[(0, 2)] = h;
    c[(1, 2)] = h;
    c[(2, 0)] = -h;
    c[(2, 1)] = -h;

    let mut k = SMatrix::<f64, N_DOF, N_DOF>::zeros();
    k[(0, 0)] = p.k_tr + p.k_d;
    k[(0, 1)] = -p.k_tr;
    k[(1, 0)] = -p.k_tr;
    k[(1, 1)] = p.k_tr;
    k[(0, 3)] = -kd_is;
    k[(3, 0)] = -kd_is;
    k[(2, 2)] = p.k_phi;
    k[(3, 3)] = kd_is / p.i_s;

    let mut g = SMatrix::<f64, N_DOF, 2>::zeros();
    g[(0, 0)] = -lever * p.c_a;
    g[(1, 1)] = -lever * p.c_a;
    g[(2, 0)] = p.h_r * p.c_a;
    g[(2, 1)] = p.h_r * p.c_a;

    SecondOrder { m, c, k, g }
}

/// State matrix A(V) of the linear model at forward speed `v_mps` in m/s with a viscous
/// track-rod damper of coefficient `c_damper_nspm`, N s/m (0 = no damper force).
///
/// Rows 0..4 are the kinematic identities `q' = dq`; rows 4..8 are `M^-1 (-K q - C dq + G a)`;
/// rows 8..10 are the tyre lag `sigma a_i' = V (psi_i - a_i) + e dpsi_i - h_r dphi`.
pub fn linearise(
    p: &PlantParams,
    v_mps: f64,
    c_damper_nspm: f64,
) -> SMatrix<f64, N_STATES, N_STATES> {
    let so = second_order(p, v_mps, c_damper_nspm);
    let mut a = SMatrix::<f64, N_STATES, N_STATES>::zeros();
    for i in 0..N_DOF {
        a[(i, N_DOF + i)] = 1.0;
    }
    for i in 0..N_DOF {
        // M is diagonal: row i of M^-1 is 1/M_ii.
        let inv_m = 1.0 / so.m[(i, i)];
        for j in 0..N_DOF {
            a[(N_DOF + i, j)] = -so.k[(i, j)] * inv_m;
            a[(N_DOF + i, N_DOF + j)] = -so.c[(i, j)] * inv_m;
        }
        a[(N_DOF + i, A_L)] = so.g[(i, 0)] * inv_m;
        a[(N_DOF + i, A_R)] = so.g[(i, 1)] * inv_m;
    }
    let inv_sigma = 1.0 / p.sigma;
    for (row, psi, dpsi) in [(A_L, PSI_L, DPSI_L), (A_R, PSI_R, DPSI_R)] {
        a[(row, psi)] = v_mps * inv_sigma;
        a[(row, row)] = -v_mps * inv_sigma;
        a[(row, dpsi)] = p.e * inv_sigma;
        a[(row, DPHI)] = -p.h_r * inv_sigma;
    }
    a
}

/// dA/dV: the derivative of [`linearise`] with respect to the speed (gyroscopic terms and the
/// tyre-lag rows are the only speed-dependent entries; A is affine in V).
pub fn dlinearise_dv(p: &PlantParams) -> SMatrix<f64, N_STATES, N_STATES> {
    let dh = p.i_p / p.r;
    let mut d = SMatrix::<f64, N_STATES, N_STATES>::zeros();
    d[(DPSI_L, DPHI)] = -dh / p.i_k;
    d[(DPSI_R, DPHI)] = -dh / p.i_k;
    d[(DPHI, DPSI_L)] = dh / p.i_phi;
    d[(DPHI, DPSI_R)] = dh / p.i_phi;
    let inv_sigma = 1.0 / p.sigma;
    d[(A_L, PSI_L)] = inv_sigma;
    d[(A_L, A_L)] = -inv_sigma;
    d[(A_R, PSI_R)] = inv_sigma;
    d[(A_R, A_R)] = -inv_sigma;
    d
}

/// Column of dx/dt per unit damper force F_d, N (positive resisting a positive stroke rate).
pub fn damper_force_input(p: &PlantParams) -> SVector<f64, N_STATES> {
    let mut b = SVector::<f64, N_STATES>::zeros();
    b[DPSI_L] = -(p.l_t / 2.0) / p.i_k;
    b[DPSI_R] = -(p.l_t / 2.0) / p.i_k;
    b
}

/// Column of dx/dt per unit driver torque T_driver in N m at the steering wheel.
pub fn driver_torque_input(p: &PlantParams) -> SVector<f64, N_STATES> {
    let mut b = SVector::<f64, N_STATES>::zeros();
    b[DTHETA_SW] = 1.0 / p.j_sw;
    b
}

/// Damper stroke x_d = (l_t/2)(psi_L + psi_R) in m of a state.
pub fn damper_stroke_m(p: &PlantParams, x: &SVector<f64, N_STATES>) -> f64 {
    (p.l_t / 2.0) * (x[PSI_L] + x[PSI_R])
}

/// Damper stroke rate v_d = (l_t/2)(dpsi_L + dpsi_R) in m/s of a state.
pub fn damper_stroke_rate_mps(p: &PlantParams, x: &SVector<f64, N_STATES>) -> f64 {
    (p.l_t / 2.0) * (x[DPSI_L] + x[DPSI_R])
}

/// The car is the family's first member: the free functions above, behind the trait.
impl LinearModel<N_STATES> for PlantParams {
    const NAME: &'static str = "car-4dof";
    const STATE_NAMES: [&'static str; N_STATES] = STATE_NAMES;
    const DOF: usize = 4;

    fn linearise(&self, v_mps: f64, c_damper_nspm: f64) -> Matrix<N_STATES> {
        linearise(self, v_mps, c_damper_nspm)
    }

    fn dlinearise_dv(&self) -> Matrix<N_STATES> {
        dlinearise_dv(self)
    }

    fn damper_force_input(&self) -> SVector<f64, N_STATES> {
        damper_force_input(self)
    }

    fn wheel_yaw_output(&self) -> SVector<f64, N_STATES> {
        // the mode meter's signal: the in-phase yaw of both encoders, (psi_L + psi_R) / 2
        let mut c = SVector::<f64, N_STATES>::zeros();
        c[PSI_L] = 0.5;
        c[PSI_R] = 0.5;
        c
    }

    fn classify(&self, v: &ComplexVector<N_STATES>) -> ModeShapeInfo {
        classify(v, self.i_k, self.i_phi, self.j_sw, self.i_s)
    }

    fn classify_in<T: SolveFloat>(&self, v: &[Complex<T>; N_STATES]) -> ModeShapeInfo {
        classify_in(v, [self.i_k, self.i_phi, self.j_sw, self.i_s])
    }
}

/// The fields behind [`PlantParams::UPDATE_PARAMS`], in its order (its names are taken from
/// here).
const CAR_UPDATE_FIELDS: [Param; 5] = [Param::CA, Param::Sigma, Param::KD, Param::TP, Param::E];

/// The car's updatable parameters: the tyre (cornering stiffness, relaxation length, pneumatic
/// trail), the restoring stiffness of the steering linkage and the caster trail, the ones the
/// shimmy mode's frequency and damping move with. `shimmy-sim identifiability` shows what the
/// data separate: k_d well at every speed, c_a and sigma nearer the onset, t_p and e hardly
/// (they stay near their prior and carry its uncertainty into the onset's sigma). The band is
/// where the diagnosis speaks up (a tyre 25 % softer is under-inflated or worn).
impl UpdatableModel<N_STATES> for PlantParams {
    const UPDATE_PARAMS: &'static [UpdateParam] = &[
        UpdateParam {
            field: CAR_UPDATE_FIELDS[0].name(),
            what: "tyre cornering stiffness",
            prior_sigma_ln: UpdateParam::SERVICE_PRIOR_SIGMA_LN,
            band: (0.75, 1.3),
        },
        UpdateParam {
            field: CAR_UPDATE_FIELDS[1].name(),
            what: "tyre relaxation length",
            prior_sigma_ln: UpdateParam::SERVICE_PRIOR_SIGMA_LN,
            band: (0.75, 1.3),
        },
        UpdateParam {
            field: CAR_UPDATE_FIELDS[2].name(),
            what: "steering linkage stiffness",
            prior_sigma_ln: UpdateParam::SERVICE_PRIOR_SIGMA_LN,
            band: (0.7, 1.3),
        },
        UpdateParam {
            field: CAR_UPDATE_FIELDS[3].name(),
            what: "tyre pneumatic trail",
            prior_sigma_ln: UpdateParam::SERVICE_PRIOR_SIGMA_LN,
            band: (0.75, 1.3),
        },
        UpdateParam {
            field: CAR_UPDATE_FIELDS[4].name(),
            what: "caster trail",
            prior_sigma_ln: UpdateParam::SERVICE_PRIOR_SIGMA_LN,
            band: (0.75, 1.3),
        },
    ];

    fn scaled_update_param(&self, index: usize, factor: f64) -> Self {
        match CAR_UPDATE_FIELDS.get(index) {
            Some(p) => self.scaled(*p, factor),
            None => *self,
        }
    }

    fn update_param(&self, index: usize) -> f64 {
        CAR_UPDATE_FIELDS
            .get(index)
            .map_or(f64::NAN, |p| self.get(*p))
    }
}

/// Classifies the mode with eigenvector `v` (of A) using the modal kinetic energy
/// 0.5 M_jj |dq_j|^2 per degree of freedom (inertias `i_k`, `i_phi`, `j_sw`) and the size of the
/// lagged slip angles relative to the displacements (steering wheel referred through `i_s`).
pub fn classify(
    v: &ComplexVector<N_STATES>,
    i_k: f64,
    i_phi: f64,
    j_sw: f64,
    i_s: f64,
) -> ModeShapeInfo {
    classify_in(&core::array::from_fn(|i| v[i]), [i_k, i_phi, j_sw, i_s])
}

/// [`classify`] in the eigenvector's own precision `T`, with the inertias and the steering
/// ratio `[i_k, i_phi, j_sw, i_s]` (in f64 the same operations as ever).
pub fn classify_in<T: SolveFloat>(v: &[Complex<T>; N_STATES], m: [f64; 4]) -> ModeShapeInfo {
    let t = T::of_f64;
    let [i_k, i_phi, j_sw, i_s] = m.map(t);
    let (zero, inf) = (T::zero(), t(f64::INFINITY));
    let e_wheel = i_k * (v[DPSI_L].norm_sqr() + v[DPSI_R].norm_sqr());
    let e_phi = i_phi * v[DPHI].norm_sqr();
    let e_sw = j_sw * v[DTHETA_SW].norm_sqr();
    let e_tot = e_wheel + e_phi + e_sw;
    let (fw, fp, fs) = if e_tot > zero {
        (e_wheel / e_tot, e_phi / e_tot, e_sw / e_tot)
    } else {
        (zero, zero, zero)
    };
    // magnitudes as the square root of the largest |c|^2 (one sqrt, not a hypot per entry)
    let wheel2 = larger(v[PSI_L].norm_sqr(), v[PSI_R].norm_sqr());
    let wheel_amp = wheel2.sqrt_rounded();
    let disp = larger(
        larger(wheel2, v[PHI].norm_sqr()),
        v[THETA_SW].norm_sqr() / (i_s * i_s),
    )
    .sqrt_rounded();
    let tyre = larger(v[A_L].norm_sqr(), v[A_R].norm_sqr()).sqrt_rounded();
    let tyre_ratio = if disp > zero { tyre / disp } else { inf };
    let steering_wheel_ratio = if wheel_amp > zero {
        v[THETA_SW].norm_sqr().sqrt_rounded() / (i_s * wheel_amp)
    } else {
        inf
    };
    let wheel_phase_rad = wheel_phase_rad(v[PSI_L], v[PSI_R]);
    let shape = if tyre_ratio > t(3.0) || e_tot == zero {
        ModeShape::TyreLag
    } else if fw >= fp && fw >= fs {
        wheel_yaw_shape(v[PSI_L], v[PSI_R])
    } else if fp >= fs {
        ModeShape::Tramp
    } else {
        ModeShape::SteeringWheel
    };
    ModeShapeInfo {
        shape,
        wheel_energy_frac: fw.to_f64(),
        tramp_energy_frac: fp.to_f64(),
        steering_wheel_energy_frac: fs.to_f64(),
        steering_wheel_ratio: steering_wheel_ratio.to_f64(),
        wheel_phase_rad,
        tyre_ratio: tyre_ratio.to_f64(),
    }
}
