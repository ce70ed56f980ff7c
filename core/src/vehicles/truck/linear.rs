//! The mining truck as a linear model of the family: states, A(V), inputs, mode shapes.

#[allow(unused_imports)]
use super::*;

use nalgebra::SVector;

use super::params::TruckParams;
use crate::model::{
    wheel_phase_rad, wheel_yaw_shape, ComplexVector, LinearModel, Matrix, ModeShape, ModeShapeInfo,
    UpdatableModel, UpdateParam,
};
use crate::vehicles::fields::FieldTable;

/// Number of states of the truck's linear model.
pub const N_STATES: usize = 12;
/// Number of mechanical degrees of freedom.
pub const N_DOF: usize = 5;

/// Left wheel yaw psi_L, rad.
pub const PSI_L: usize = 0;
/// Right wheel yaw psi_R, rad.
pub const PSI_R: usize = 1;
/// Axle roll phi, rad.
pub const PHI: usize = 2;
/// Steering-linkage angle theta_c (referred to the left kingpin), rad.
pub const THETA_C: usize = 3;
/// Axle lateral displacement y, m.
pub const Y: usize = 4;
/// Left wheel yaw rate, rad/s.
pub const DPSI_L: usize = 5;
/// Right wheel yaw rate, rad/s.
pub const DPSI_R: usize = 6;
/// Axle roll rate, rad/s.
pub const DPHI: usize = 7;
/// Steering-linkage rate, rad/s.
pub const DTHETA_C: usize = 8;
/// Axle lateral velocity, m/s.
pub const DY: usize = 9;
/// Left lagged slip angle, rad.
pub const A_L: usize = 10;
/// Right lagged slip angle, rad.
pub const A_R: usize = 11;

/// Short names of the states, for tables and CSV headers.
pub const STATE_NAMES: [&str; N_STATES] = [
    "psi_L_rad",
    "psi_R_rad",
    "phi_rad",
    "theta_c_rad",
    "y_m",
    "dpsi_L_radps",
    "dpsi_R_radps",
    "dphi_radps",
    "dtheta_c_radps",
    "dy_mps",
    "a_L_rad",
    "a_R_rad",
];

impl LinearModel<N_STATES> for TruckParams {
    const NAME: &'static str = "mining-truck-5dof";
    const STATE_NAMES: [&'static str; N_STATES] = STATE_NAMES;
    const DOF: usize = 5;

    /// The loaded truck's shimmy is at ~3 Hz, half the car's ~6 Hz: below the car meter's
    /// 3 Hz band edge. Measured (`shimmy-sim meter-accuracy --vehicle truck-full
    /// --meter-time-scale 1` against the default 2, `docs/mining-truck.md`).
    fn meter_time_scale(&self) -> u16 {
        2
    }

    /// Rows 0..5 `q' = dq`; rows 5..10 `M^-1 (-K q - C dq + G a)`; rows 10..12 the tyre lag.
    fn linearise(&self, v_mps: f64, c_damper_nspm: f64) -> Matrix<N_STATES> {
        let op = self.point_or_tyres_only();
        let h = self.spin_momentum(v_mps);
        let cd = c_damper_nspm * self.l_t * self.l_t / 4.0;
        let lever = self.e + self.t_p;
        // entry by entry (the nonzeros of M^-1 K, M^-1 C, M^-1 G): soft-float f64 on the M4,
        // so no full 5 x 5 products
        let (ik, iphi, jc, ma) = (
            1.0 / self.i_k,
            1.0 / self.i_phi,
            1.0 / self.j_c,
            1.0 / self.m_axle,
        );
        let mut a = Matrix::<N_STATES>::zeros();
        for i in 0..N_DOF {
            a[(i, N_DOF + i)] = 1.0;
        }
        // stiffness: tie rod, linkage, oil columns, roll, lateral
        a[(DPSI_L, PSI_L)] = -(self.k_tr + self.k_d) * ik;
        a[(DPSI_L, PSI_R)] = self.k_tr * ik;
        a[(DPSI_L, THETA_C)] = self.k_d * ik;
        a[(DPSI_R, PSI_L)] = self.k_tr * ik;
        a[(DPSI_R, PSI_R)] = -self.k_tr * ik;
        a[(DTHETA_C, PSI_L)] = self.k_d * jc;
        a[(DTHETA_C, THETA_C)] = -(self.k_d + self.k_h) * jc;
        a[(DPHI, PHI)] = -op.k_phi * iphi;
        a[(DY, Y)] = -self.k_y * ma;
        // damping: kingpins with the track-rod damper, roll, linkage, lateral; gyroscopic
        // -H dphi in both wheel rows, +H (dpsi_L + dpsi_R) in the roll row
        a[(DPSI_L, DPSI_L)] = -(self.c_k + cd) * ik;
        a[(DPSI_L, DPSI_R)] = -cd * ik;
        a[(DPSI_R, DPSI_L)] = -cd * ik;
        a[(DPSI_R, DPSI_R)] = -(self.c_k + cd) * ik;
        a[(DPSI_L, DPHI)] = -h * ik;
        a[(DPSI_R, DPHI)] = -h * ik;
        a[(DPHI, DPSI_L)] = h * iphi;
        a[(DPHI, DPSI_R)] = h * iphi;
        a[(DPHI, DPHI)] = -op.c_phi * iphi;
        a[(DTHETA_C, DTHETA_C)] = -self.c_h * jc;
        a[(DY, DY)] = -self.c_y * ma;
        // generalised tyre forces per unit lagged slip: yaw moment -(e + t_p) C_a on its wheel,
        // roll moment h_r C_a, lateral force C_a on the axle
        let inv_sigma = 1.0 / self.sigma;
        for (slip, wheel, dpsi) in [(A_L, PSI_L, DPSI_L), (A_R, PSI_R, DPSI_R)] {
            a[(dpsi, slip)] = -lever * op.c_a * ik;
            a[(DPHI, slip)] = self.h_r * op.c_a * iphi;
            a[(DY, slip)] = op.c_a * ma;
            // tyre lag: sigma a' = V (psi - a) + e dpsi - h_r dphi - dy
            a[(slip, wheel)] = v_mps * inv_sigma;
            a[(slip, slip)] = -v_mps * inv_sigma;
            a[(slip, dpsi)] = self.e * inv_sigma;
            a[(slip, DPHI)] = -self.h_r * inv_sigma;
            a[(slip, DY)] = -inv_sigma;
        }
        a
    }

    fn dlinearise_dv(&self) -> Matrix<N_STATES> {
        let dh = self.i_p / self.r;
        let mut d = Matrix::<N_STATES>::zeros();
        d[(DPSI_L, DPHI)] = -dh / self.i_k;
        d[(DPSI_R, DPHI)] = -dh / self.i_k;
        d[(DPHI, DPSI_L)] = dh / self.i_phi;
        d[(DPHI, DPSI_R)] = dh / self.i_phi;
        let inv_sigma = 1.0 / self.sigma;
        d[(A_L, PSI_L)] = inv_sigma;
        d[(A_L, A_L)] = -inv_sigma;
        d[(A_R, PSI_R)] = inv_sigma;
        d[(A_R, A_R)] = -inv_sigma;
        d
    }

    fn damper_force_input(&self) -> SVector<f64, N_STATES> {
        let mut b = SVector::<f64, N_STATES>::zeros();
        b[DPSI_L] = -(self.l_t / 2.0) / self.i_k;
        b[DPSI_R] = -(self.l_t / 2.0) / self.i_k;
        b
    }

    fn wheel_yaw_output(&self) -> SVector<f64, N_STATES> {
        let mut c = SVector::<f64, N_STATES>::zeros();
        c[PSI_L] = 0.5;
        c[PSI_R] = 0.5;
        c
    }

    /// By modal kinetic energy over wheel yaw, axle roll, steering linkage and axle lateral
    /// motion; the tyre-lag test compares the slip angles with the displacements (the lateral
    /// one over the relaxation length, the slip it makes).
    fn classify(&self, v: &ComplexVector<N_STATES>) -> ModeShapeInfo {
        let e_wheel = self.i_k * (v[DPSI_L].norm_sqr() + v[DPSI_R].norm_sqr());
        let e_phi = self.i_phi * v[DPHI].norm_sqr();
        let e_c = self.j_c * v[DTHETA_C].norm_sqr();
        let e_y = self.m_axle * v[DY].norm_sqr();
        let e_tot = e_wheel + e_phi + e_c + e_y;
        let frac = |e: f64| if e_tot > 0.0 { e / e_tot } else { 0.0 };
        let wheel2 = v[PSI_L].norm_sqr().max(v[PSI_R].norm_sqr());
        let disp2 = wheel2
            .max(v[PHI].norm_sqr())
            .max(v[THETA_C].norm_sqr())
            .max(v[Y].norm_sqr() / (self.sigma * self.sigma));
        let tyre = crate::sqrt::sqrt(v[A_L].norm_sqr().max(v[A_R].norm_sqr()));
        let tyre_ratio = if disp2 > 0.0 {
            tyre / crate::sqrt::sqrt(disp2)
        } else {
            f64::INFINITY
        };
        let steering_wheel_ratio = if wheel2 > 0.0 {
            crate::sqrt::sqrt(v[THETA_C].norm_sqr() / wheel2)
        } else {
            f64::INFINITY
        };
        let largest = e_wheel.max(e_phi).max(e_c).max(e_y);
        let shape = if tyre_ratio > 3.0 || e_tot == 0.0 {
            ModeShape::TyreLag
        } else if e_wheel >= largest {
            wheel_yaw_shape(v[PSI_L], v[PSI_R])
        } else if e_phi >= largest {
            ModeShape::Tramp
        } else if e_c >= largest {
            ModeShape::SteeringWheel
        } else {
            ModeShape::AxleLateral
        };
        ModeShapeInfo {
            shape,
            wheel_energy_frac: frac(e_wheel),
            tramp_energy_frac: frac(e_phi),
            steering_wheel_energy_frac: frac(e_c),
            steering_wheel_ratio,
            wheel_phase_rad: wheel_phase_rad(v[PSI_L], v[PSI_R]),
            tyre_ratio,
        }
    }
}

/// The truck's updatable parameters: the tyre (cornering coefficient, relaxation length,
/// pneumatic trail) and the hydrostatic steering linkage (stiffness and damping), the ones its
/// shimmy mode moves with (`shimmy-sim identifiability --vehicle truck-full`). The band is
/// where the diagnosis speaks up.
impl UpdatableModel<N_STATES> for TruckParams {
    const UPDATE_PARAMS: &'static [UpdateParam] = &[
        UpdateParam {
            field: "c_a_per_fz",
            what: "tyre cornering coefficient",
            prior_sigma_ln: UpdateParam::SERVICE_PRIOR_SIGMA_LN,
            band: (0.75, 1.3),
        },
        UpdateParam {
            field: "sigma",
            what: "tyre relaxation length",
            prior_sigma_ln: UpdateParam::SERVICE_PRIOR_SIGMA_LN,
            band: (0.75, 1.3),
        },
        UpdateParam {
            field: "c_h",
            what: "steering linkage damping",
            prior_sigma_ln: UpdateParam::SERVICE_PRIOR_SIGMA_LN,
            band: (0.6, 1.5),
        },
        UpdateParam {
            field: "k_h",
            what: "steering linkage stiffness",
            prior_sigma_ln: UpdateParam::SERVICE_PRIOR_SIGMA_LN,
            band: (0.7, 1.3),
        },
        UpdateParam {
            field: "t_p",
            what: "tyre pneumatic trail",
            prior_sigma_ln: UpdateParam::SERVICE_PRIOR_SIGMA_LN,
            band: (0.75, 1.3),
        },
    ];

    fn scaled_update_param(&self, index: usize, factor: f64) -> Self {
        let mut out = *self;
        if let Some(v) = Self::UPDATE_PARAMS
            .get(index)
            .and_then(|u| out.field_mut(u.field))
        {
            *v *= factor;
        }
        out
    }

    fn update_param(&self, index: usize) -> f64 {
        Self::UPDATE_PARAMS
            .get(index)
            .and_then(|u| self.get(u.field))
            .unwrap_or(f64::NAN)
    }
}
