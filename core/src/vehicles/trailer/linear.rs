//! The trailer as a linear model of the family: states, A(V), inputs, mode shapes.

#[allow(unused_imports)]
use super::*;

use nalgebra::SVector;

use super::params::TrailerParams;
use crate::model::{
    ComplexVector, LinearModel, Matrix, ModeShape, ModeShapeInfo, UpdatableModel, UpdateParam,
};

/// Number of states of the trailer's linear model.
pub const N_STATES: usize = 5;
/// Number of mechanical degrees of freedom.
pub const N_DOF: usize = 2;

/// Hitch lateral displacement y, m.
pub const Y: usize = 0;
/// Trailer yaw (hitch angle) psi, rad.
pub const PSI: usize = 1;
/// Hitch lateral velocity, m/s.
pub const DY: usize = 2;
/// Trailer yaw rate, rad/s.
pub const DPSI: usize = 3;
/// Lagged slip angle of the axle, rad.
pub const ALPHA: usize = 4;

/// Short names of the states, for tables and CSV headers.
pub const STATE_NAMES: [&str; N_STATES] = ["y_m", "psi_rad", "dy_mps", "dpsi_radps", "alpha_rad"];

impl LinearModel<N_STATES> for TrailerParams {
    const NAME: &'static str = "trailer-2dof";
    const STATE_NAMES: [&'static str; N_STATES] = STATE_NAMES;
    const DOF: usize = 2;

    /// `M q'' + D q' + K q = G alpha + b F_d` with `M = [[m, -m a], [-m a, I_z + m a^2]]`
    /// (the centre of gravity's lateral position is `y - a psi`), `K = diag(k_y, 0)`,
    /// `D = diag(c_y, c l_d^2)`, `G = C_a [1, -l]`; `M^-1 = [[I_h, m a], [m a, m]] / (m I_z)`
    /// written out entry by entry; the last row is the tyre lag.
    fn linearise(&self, v_mps: f64, c_damper_nspm: f64) -> Matrix<N_STATES> {
        let ct = c_damper_nspm * self.l_d * self.l_d;
        let ca = self.cornering_stiffness();
        let b = self.l - self.a;
        let (m, iz, a) = (self.m, self.i_z, self.a);
        // M^-1 entries
        let m00 = self.i_hitch() / (m * iz);
        let m01 = a / iz;
        let m11 = 1.0 / iz;
        let mut x = Matrix::<N_STATES>::zeros();
        x[(Y, DY)] = 1.0;
        x[(PSI, DPSI)] = 1.0;
        // generalised forces: Q_y = -k_y y - c_y y' + C_a alpha, Q_psi = -c_t psi' - l C_a alpha
        x[(DY, Y)] = -self.k_y * m00;
        x[(DY, DY)] = -self.c_y * m00;
        x[(DY, DPSI)] = -ct * m01;
        x[(DY, ALPHA)] = ca * (iz - m * a * b) / (m * iz);
        x[(DPSI, Y)] = -self.k_y * m01;
        x[(DPSI, DY)] = -self.c_y * m01;
        x[(DPSI, DPSI)] = -ct * m11;
        x[(DPSI, ALPHA)] = -ca * b / iz;
        // tyre lag: sigma alpha' = V (psi - alpha) - y' + l psi'
        let inv_sigma = 1.0 / self.sigma;
        x[(ALPHA, PSI)] = v_mps * inv_sigma;
        x[(ALPHA, ALPHA)] = -v_mps * inv_sigma;
        x[(ALPHA, DY)] = -inv_sigma;
        x[(ALPHA, DPSI)] = self.l * inv_sigma;
        x
    }

    fn dlinearise_dv(&self) -> Matrix<N_STATES> {
        let mut d = Matrix::<N_STATES>::zeros();
        d[(ALPHA, PSI)] = 1.0 / self.sigma;
        d[(ALPHA, ALPHA)] = -1.0 / self.sigma;
        d
    }

    /// The yaw moment `-l_d F_d` through `M^-1`.
    fn damper_force_input(&self) -> SVector<f64, N_STATES> {
        let mut b = SVector::<f64, N_STATES>::zeros();
        b[DY] = -self.l_d * self.a / self.i_z;
        b[DPSI] = -self.l_d / self.i_z;
        b
    }

    /// The trailer yaw, which is the hitch angle here (the tow vehicle does not yaw).
    fn wheel_yaw_output(&self) -> SVector<f64, N_STATES> {
        let mut c = SVector::<f64, N_STATES>::zeros();
        c[PSI] = 1.0;
        c
    }

    /// 10: the sway at its onset (0.64 Hz for the caravan) is ten times slower than the car's
    /// ~6 Hz shimmy; the car's 3-20 Hz band becomes 0.3-2 Hz, the decimation 100 (a 10 Hz
    /// meter rate) and its memories ten times longer in seconds, the same in sway cycles.
    fn meter_time_scale(&self) -> u16 {
        10
    }

    /// By the modal kinetic energy of yaw about the hitch (`I_h |psi'|^2`) against the hitch's
    /// lateral motion (`m |y'|^2`): [`ModeShape::Sway`] when yaw has the larger share,
    /// [`ModeShape::HitchLateral`] otherwise; [`ModeShape::TyreLag`] when the slip angle
    /// exceeds three times the largest displacement (psi, or y over l, the yaw it makes).
    /// Fields of the family's [`ModeShapeInfo`]: `wheel_energy_frac` is the yaw share (the
    /// measured motion), `steering_wheel_energy_frac` the hitch-lateral share,
    /// `steering_wheel_ratio` `|y| / (l |psi|)`, `wheel_phase_rad` the phase of y against psi;
    /// tramp does not exist (0).
    fn classify(&self, v: &ComplexVector<N_STATES>) -> ModeShapeInfo {
        let e_yaw = self.i_hitch() * v[DPSI].norm_sqr();
        let e_hitch = self.m * v[DY].norm_sqr();
        let e_tot = e_yaw + e_hitch;
        let frac = |e: f64| if e_tot > 0.0 { e / e_tot } else { 0.0 };
        let psi = libm::sqrt(v[PSI].norm_sqr());
        let y_over_l = libm::sqrt(v[Y].norm_sqr()) / self.l;
        let disp = psi.max(y_over_l);
        let tyre = libm::sqrt(v[ALPHA].norm_sqr());
        let tyre_ratio = if disp > 0.0 {
            tyre / disp
        } else {
            f64::INFINITY
        };
        let shape = if tyre_ratio > 3.0 || e_tot == 0.0 {
            ModeShape::TyreLag
        } else if e_yaw >= e_hitch {
            ModeShape::Sway
        } else {
            ModeShape::HitchLateral
        };
        let ratio = if psi > 0.0 {
            y_over_l / psi
        } else {
            f64::INFINITY
        };
        let phase = if psi > 0.0 {
            let r = v[Y] / v[PSI];
            libm::atan2(r.im, r.re)
        } else {
            0.0
        };
        ModeShapeInfo {
            shape,
            wheel_energy_frac: frac(e_yaw),
            tramp_energy_frac: 0.0,
            steering_wheel_energy_frac: frac(e_hitch),
            steering_wheel_ratio: ratio,
            wheel_phase_rad: phase,
            tyre_ratio,
        }
    }
}

/// No parameter is updated online yet: this model's identifiability study has not been run, so
/// its margin stays the vehicle file's (corrected by the fusion's measured damping offset).
impl UpdatableModel<N_STATES> for TrailerParams {
    const UPDATE_PARAMS: &'static [UpdateParam] = &[];

    fn scaled_update_param(&self, _index: usize, _factor: f64) -> Self {
        *self
    }

    fn update_param(&self, _index: usize) -> f64 {
        f64::NAN
    }
}
