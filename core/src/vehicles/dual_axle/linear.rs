//! The dual-axle truck as a linear model of the family: states, A(V), inputs, mode shapes, the meter's weights.

#[allow(unused_imports)]
use super::*;

use nalgebra::SVector;

use super::params::DualAxleParams;
use crate::model::{
    wheel_phase_rad, wheel_yaw_shape, ComplexVector, LinearModel, Matrix, ModeShape, ModeShapeInfo,
    UpdatableModel, UpdateParam,
};

/// Number of states of the dual-axle truck's linear model.
pub const N_STATES: usize = 20;
/// Number of mechanical degrees of freedom.
pub const N_DOF: usize = 8;

/// Axle 1 left wheel yaw, rad.
pub const PSI_1L: usize = 0;
/// Axle 1 right wheel yaw, rad.
pub const PSI_1R: usize = 1;
/// Axle 2 left wheel yaw, rad.
pub const PSI_2L: usize = 2;
/// Axle 2 right wheel yaw, rad.
pub const PSI_2R: usize = 3;
/// Axle 1 roll, rad.
pub const PHI_1: usize = 4;
/// Axle 2 roll, rad.
pub const PHI_2: usize = 5;
/// Pitman arm (referred to axle 1's left kingpin), rad.
pub const THETA_G: usize = 6;
/// Mid-shift rocker (referred to axle 2's left kingpin), rad.
pub const THETA_M: usize = 7;
/// First lagged slip angle (axle 1 left); then 1R, 2L, 2R, rad.
pub const A_1L: usize = 16;

/// The wheels as (yaw index, roll index of their axle, slip index, axle 0/1).
pub const WHEELS: [(usize, usize, usize, usize); 4] = [
    (PSI_1L, PHI_1, A_1L, 0),
    (PSI_1R, PHI_1, A_1L + 1, 0),
    (PSI_2L, PHI_2, A_1L + 2, 1),
    (PSI_2R, PHI_2, A_1L + 3, 1),
];

/// Short names of the states, for tables and CSV headers.
pub const STATE_NAMES: [&str; N_STATES] = [
    "psi_1L_rad",
    "psi_1R_rad",
    "psi_2L_rad",
    "psi_2R_rad",
    "phi_1_rad",
    "phi_2_rad",
    "theta_g_rad",
    "theta_m_rad",
    "dpsi_1L_radps",
    "dpsi_1R_radps",
    "dpsi_2L_radps",
    "dpsi_2R_radps",
    "dphi_1_radps",
    "dphi_2_radps",
    "dtheta_g_radps",
    "dtheta_m_radps",
    "a_1L_rad",
    "a_1R_rad",
    "a_2L_rad",
    "a_2R_rad",
];

/// The speeds the meter's weights are computed at: the model's first Hopf onset in this range
/// (0.5 km/h scan, Brent), else the top of the range (no warning to give below it).
const METER_SCAN_MPS: (f64, f64, f64) = (1.0 / 3.6, 150.0 / 3.6, 0.5 / 3.6);

impl DualAxleParams {
    /// The speed the mode meter's weights are taken at ([`Self::meter_weights`]), m/s: the
    /// first Hopf onset of 1-150 km/h, else 150 km/h.
    pub fn meter_reference_speed_mps(&self) -> f64 {
        let (v0, v1, dv) = METER_SCAN_MPS;
        crate::stability::hopf_crossings(self, 0.0, v0, v1, dv, crate::stability::DEFAULT_TOL_MPS)
            .ok()
            .and_then(|cs| {
                cs.iter()
                    .find(|c| c.kind == crate::stability::CrossingKind::Onset)
                    .map(|c| c.speed_mps)
            })
            .unwrap_or(v1)
    }

    /// The weights `[w_1, w_2]` of the signal the mode meter sees,
    /// `y = w_1 (psi_1L + psi_1R) / 2 + w_2 (psi_2L + psi_2R) / 2` (the in-phase yaw of each
    /// axle, all four kingpin encoders): a least-squares modal filter for the shimmy mode at
    /// [`Self::meter_reference_speed_mps`]. Every oscillatory mode's right eigenvector is scaled
    /// to unit modal kinetic energy and reduced to its two in-phase axle yaws `u_k`; the weights
    /// minimise the other modes' share `sum |w . u_k|^2` with the shimmy mode's (phase-aligned)
    /// `w . u_s` fixed to its axle-1 part, so a shimmy reads as axle 1's in-phase yaw (the
    /// amplitude thresholds keep their meaning) while the lightly damped ~15 Hz mode (the axles
    /// yawing against each other) and the tramp mode that axle 1 alone shows next to it cancel.
    /// `[1, 0]` (axle 1 alone) if the eigen-solve fails.
    pub fn meter_weights(&self) -> [f64; 2] {
        self.modal_weights_at(self.meter_reference_speed_mps())
            .unwrap_or([1.0, 0.0])
    }

    fn modal_weights_at(&self, v_mps: f64) -> Option<[f64; 2]> {
        use crate::stability::{select_mode, ModeSelect};
        let a = self.linearise(v_mps, 0.0);
        let vals = crate::eigen::eigenvalues(&a).ok()?;
        let shimmy = select_mode(self, &a, &vals, ModeSelect::Shimmy)
            .ok()?
            .eigenvalue();
        let (mut q, mut u_s) = ([[0.0; 2]; 2], None);
        for l in vals
            .iter()
            .filter(|l| l.im > 0.0 && crate::eigen::is_oscillatory(**l))
        {
            let v = crate::eigen::eigenvector(&a, *l).ok()?;
            let energy: f64 = (0..N_DOF)
                .map(|i| self.inertia(i) * v[N_DOF + i].norm_sqr())
                .sum();
            if energy.is_nan() || energy <= 0.0 {
                continue;
            }
            let s = 1.0 / libm::sqrt(energy);
            let u = [
                (v[PSI_1L] + v[PSI_1R]) * (0.5 * s),
                (v[PSI_2L] + v[PSI_2R]) * (0.5 * s),
            ];
            if (*l - shimmy).norm_sqr() <= 1e-18 * shimmy.norm_sqr() {
                u_s = Some(u);
            } else {
                for (i, row) in q.iter_mut().enumerate() {
                    for (j, qij) in row.iter_mut().enumerate() {
                        *qij += (u[i] * u[j].conj()).re;
                    }
                }
            }
        }
        let u_s = u_s?;
        let n1 = libm::sqrt(u_s[0].norm_sqr());
        if n1.is_nan() || n1 <= 0.0 {
            return None;
        }
        // the shimmy shape rotated so that axle 1's part is real and positive
        let rot = u_s[0].conj() / n1;
        let r = [n1, (u_s[1] * rot).re];
        let det = q[0][0] * q[1][1] - q[0][1] * q[1][0];
        if det.is_nan() || det.abs() <= 1e-12 * (q[0][0] * q[1][1]).abs() {
            return None;
        }
        let c = [
            (q[1][1] * r[0] - q[0][1] * r[1]) / det,
            (q[0][0] * r[1] - q[1][0] * r[0]) / det,
        ];
        let k = n1 / (c[0] * r[0] + c[1] * r[1]);
        let w = [c[0] * k, c[1] * k];
        (w[0].is_finite() && w[1].is_finite()).then_some(w)
    }
}

impl LinearModel<N_STATES> for DualAxleParams {
    const NAME: &'static str = "dual-axle-truck-8dof";
    const STATE_NAMES: [&'static str; N_STATES] = STATE_NAMES;
    const DOF: usize = 8;

    /// Rows 0..8 `q' = dq`; rows 8..16 `M^-1 (-K q - C dq + G a)` (M diagonal); rows 16..20
    /// the tyre lag.
    fn linearise(&self, v_mps: f64, c_damper_nspm: f64) -> Matrix<N_STATES> {
        let op = self.operating_point();
        let k = self.stiffness();
        let h = self.spin_momentum(v_mps);
        let cd = c_damper_nspm * self.l_t * self.l_t / 4.0;
        let lever = self.e + self.t_p;
        let mut a = Matrix::<N_STATES>::zeros();
        for i in 0..N_DOF {
            let inv_m = 1.0 / self.inertia(i);
            a[(i, N_DOF + i)] = 1.0;
            for (j, kij) in k[i].iter().enumerate() {
                a[(N_DOF + i, j)] = -kij * inv_m;
            }
        }
        // damping: kingpins, roll, steering gear, rocker; the damper across axle 1's track rod
        let (ik, iphi) = (1.0 / self.i_k, 1.0 / self.i_phi);
        for w in PSI_1L..=PSI_2R {
            a[(N_DOF + w, N_DOF + w)] = -self.c_k * ik;
        }
        for (i, j) in [
            (PSI_1L, PSI_1L),
            (PSI_1L, PSI_1R),
            (PSI_1R, PSI_1L),
            (PSI_1R, PSI_1R),
        ] {
            a[(N_DOF + i, N_DOF + j)] -= cd * ik;
        }
        a[(N_DOF + PHI_1, N_DOF + PHI_1)] = -op.c_phi * iphi;
        a[(N_DOF + PHI_2, N_DOF + PHI_2)] = -op.c_phi * iphi;
        a[(N_DOF + THETA_G, N_DOF + THETA_G)] = -self.c_g / self.j_g;
        a[(N_DOF + THETA_M, N_DOF + THETA_M)] = -self.c_m / self.j_m;
        // per wheel: gyroscopic pair with its axle's roll (-H dphi in the wheel row, +H dpsi
        // in the roll row), tyre moments and the lag equation
        let inv_sigma = 1.0 / self.sigma;
        for (wheel, roll, slip, axle) in WHEELS {
            let (dw, dr) = (N_DOF + wheel, N_DOF + roll);
            let ca = op.c_a[axle];
            a[(dw, dr)] = -h * ik;
            a[(dr, dw)] = h * iphi;
            a[(dw, slip)] = -lever * ca * ik;
            a[(dr, slip)] = self.h_r * ca * iphi;
            a[(slip, wheel)] = v_mps * inv_sigma;
            a[(slip, slip)] = -v_mps * inv_sigma;
            a[(slip, dw)] = self.e * inv_sigma;
            a[(slip, dr)] = -self.h_r * inv_sigma;
        }
        a
    }

    fn dlinearise_dv(&self) -> Matrix<N_STATES> {
        let dh = self.i_p / self.r;
        let inv_sigma = 1.0 / self.sigma;
        let mut d = Matrix::<N_STATES>::zeros();
        for (wheel, roll, slip, _) in WHEELS {
            d[(N_DOF + wheel, N_DOF + roll)] = -dh / self.i_k;
            d[(N_DOF + roll, N_DOF + wheel)] = dh / self.i_phi;
            d[(slip, wheel)] = inv_sigma;
            d[(slip, slip)] = -inv_sigma;
        }
        d
    }

    /// A steering damper across axle 1's track rod (stroke `l_t (psi_1L + psi_1R) / 2`).
    fn damper_force_input(&self) -> SVector<f64, N_STATES> {
        let mut b = SVector::<f64, N_STATES>::zeros();
        b[N_DOF + PSI_1L] = -(self.l_t / 2.0) / self.i_k;
        b[N_DOF + PSI_1R] = -(self.l_t / 2.0) / self.i_k;
        b
    }

    /// The mode meter's signal: both axles' in-phase wheel yaw weighted by
    /// [`DualAxleParams::meter_weights`] (all four kingpin encoders).
    fn wheel_yaw_output(&self) -> SVector<f64, N_STATES> {
        let [w1, w2] = self.meter_weights();
        let mut c = SVector::<f64, N_STATES>::zeros();
        c[PSI_1L] = 0.5 * w1;
        c[PSI_1R] = 0.5 * w1;
        c[PSI_2L] = 0.5 * w2;
        c[PSI_2R] = 0.5 * w2;
        c
    }

    /// By modal kinetic energy over wheel yaw (four wheels), axle roll (both axles) and the
    /// steering linkage (pitman arm and rocker); in-phase or anti-phase by the wheels of the
    /// axle with the larger yaw energy. The tyre-lag test compares the slip angles with the
    /// displacements.
    fn classify(&self, v: &ComplexVector<N_STATES>) -> ModeShapeInfo {
        let d = |i: usize| v[N_DOF + i].norm_sqr();
        let e_ax = [
            self.i_k * (d(PSI_1L) + d(PSI_1R)),
            self.i_k * (d(PSI_2L) + d(PSI_2R)),
        ];
        let e_wheel = e_ax[0] + e_ax[1];
        let e_phi = self.i_phi * (d(PHI_1) + d(PHI_2));
        let e_c = self.j_g * d(THETA_G) + self.j_m * d(THETA_M);
        let e_tot = e_wheel + e_phi + e_c;
        let frac = |e: f64| if e_tot > 0.0 { e / e_tot } else { 0.0 };
        let (l, r) = if e_ax[0] >= e_ax[1] {
            (PSI_1L, PSI_1R)
        } else {
            (PSI_2L, PSI_2R)
        };
        let wheel2 = v[l].norm_sqr().max(v[r].norm_sqr());
        let disp2 = (0..N_DOF).map(|i| v[i].norm_sqr()).fold(0.0, f64::max);
        let tyre2 = (A_1L..N_STATES)
            .map(|i| v[i].norm_sqr())
            .fold(0.0, f64::max);
        let tyre_ratio = if disp2 > 0.0 {
            libm::sqrt(tyre2 / disp2)
        } else {
            f64::INFINITY
        };
        let steering_wheel_ratio = if wheel2 > 0.0 {
            libm::sqrt(v[THETA_G].norm_sqr().max(v[THETA_M].norm_sqr()) / wheel2)
        } else {
            f64::INFINITY
        };
        let largest = e_wheel.max(e_phi).max(e_c);
        let shape = if tyre_ratio > 3.0 || e_tot == 0.0 {
            ModeShape::TyreLag
        } else if e_wheel >= largest {
            wheel_yaw_shape(v[l], v[r])
        } else if e_phi >= largest {
            ModeShape::Tramp
        } else {
            ModeShape::SteeringWheel
        };
        ModeShapeInfo {
            shape,
            wheel_energy_frac: frac(e_wheel),
            tramp_energy_frac: frac(e_phi),
            steering_wheel_energy_frac: frac(e_c),
            steering_wheel_ratio,
            wheel_phase_rad: wheel_phase_rad(v[l], v[r]),
            tyre_ratio,
        }
    }
}

/// No parameter is updated online yet: this model's identifiability study has not been run, so
/// its margin stays the vehicle file's (corrected by the fusion's measured damping offset).
impl UpdatableModel<N_STATES> for DualAxleParams {
    const UPDATE_PARAMS: &'static [UpdateParam] = &[];

    fn scaled_update_param(&self, _index: usize, _factor: f64) -> Self {
        *self
    }

    fn update_param(&self, _index: usize) -> f64 {
        f64::NAN
    }
}
