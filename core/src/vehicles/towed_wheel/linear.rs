//! The towed wheel as a linear model of the family: the contact patch's memory by Chebyshev
//! collocation, states, A(V), inputs, mode shapes.
//!
//! The linearised no-sliding condition in the patch is the transport equation
//! `q_t = V q_x + V psi + (l - x) psi'`: the deformation travels backwards through the patch
//! at V, entering at the leading edge `x = a`, where the string outside the patch makes
//! `q_x = -q / sigma`, so `q(a)' = -(V / sigma) q(a) + V psi + (l - a) psi'`. The patch is
//! collocated at the `N_PATCH` Chebyshev points `x_j = a cos(j pi / (N_PATCH - 1))` (j = 0 the
//! leading edge): spectral accuracy for the delay's smooth solutions, where an upwind grid's
//! numerical diffusion would damp the memory that drives the shimmy.
//!
//! The king pin's yaw balance `J_A psi'' = M_A + M_b - c l_d^2 psi'`:
//! - the string's moment about the pin, `M_A = k int (x - l) q dx + k sigma [(a + sigma - l)
//!   q(a) - (a + sigma + l) q(-a)]` (the patch by Clenshaw-Curtis quadrature on the same
//!   points, the two exponential tails in closed form);
//! - the tyre damping `b` on each particle's deformation rate as it travels: in the patch
//!   `V psi + (l - x) psi'`, on the front tail the leading edge's, on the rear tail
//!   `q(-a)' - (V / sigma) q(-a)`, with the same lever arms;
//! - a steering damper of coefficient c at the lever `l_d`.
//!
//! Every entry is affine in V, as the family's trait requires. The characteristic function of
//! the undiscretised delay equation (Takács, Orosz & Stépán 2009, Eq. 31) checks the
//! collocation in `tests.rs`.

#[allow(unused_imports)]
use super::*;

use nalgebra::SVector;

use super::params::TowedWheelParams;
use crate::model::{
    ComplexVector, LinearModel, Matrix, ModeShape, ModeShapeInfo, UpdatableModel, UpdateParam,
};

/// Collocation points on the contact patch: 14 keep the critical roots within 1e-4 of the
/// delay equation's over the benchmark's speeds (`tests.rs`).
pub const N_PATCH: usize = 14;
/// Number of states of the towed wheel's linear model: the yaw, its rate and the patch.
pub const N_STATES: usize = 2 + N_PATCH;

/// Wheel yaw psi, rad.
pub const PSI: usize = 0;
/// Wheel yaw rate, rad/s.
pub const DPSI: usize = 1;
/// The first patch state: the deformation at the leading edge, m; the patch's point j is the
/// state `Q0 + j`, the trailing edge the last.
pub const Q0: usize = 2;
/// The trailing edge's state.
pub const Q_TRAIL: usize = Q0 + N_PATCH - 1;

/// Names of the patch's states, as many as a collocation may use.
const PATCH_NAMES: [&str; 32] = [
    "q00_m", "q01_m", "q02_m", "q03_m", "q04_m", "q05_m", "q06_m", "q07_m", "q08_m", "q09_m",
    "q10_m", "q11_m", "q12_m", "q13_m", "q14_m", "q15_m", "q16_m", "q17_m", "q18_m", "q19_m",
    "q20_m", "q21_m", "q22_m", "q23_m", "q24_m", "q25_m", "q26_m", "q27_m", "q28_m", "q29_m",
    "q30_m", "q31_m",
];

/// Short names of the states, for tables and CSV headers.
pub const STATE_NAMES: [&str; N_STATES] = {
    let mut n = ["psi_rad"; N_STATES];
    n[DPSI] = "dpsi_radps";
    let mut j = 0;
    while j < N_PATCH {
        n[Q0 + j] = PATCH_NAMES[j];
        j += 1;
    }
    n
};

/// The collocation on the patch `[-a, a]`: points (j = 0 the leading edge), differentiation
/// matrix and quadrature weights.
pub struct Patch {
    /// The points x_j, m.
    pub x: [f64; N_PATCH],
    /// `d/dx` at the points: `(q_x)_i = sum_j d[i][j] q_j`, 1/m.
    pub d: [[f64; N_PATCH]; N_PATCH],
    /// Clenshaw-Curtis weights: `int q dx = sum_j w_j q_j`, m.
    pub w: [f64; N_PATCH],
}

impl Patch {
    /// The Chebyshev-Gauss-Lobatto collocation of `[-a, a]` (Trefethen, "Spectral Methods in
    /// MATLAB", `cheb` and `clencurt`).
    pub fn new(a: f64) -> Self {
        const N: usize = N_PATCH - 1;
        let pi = core::f64::consts::PI;
        let mut x = [0.0; N_PATCH];
        for (j, xj) in x.iter_mut().enumerate() {
            *xj = libm::cos(pi * j as f64 / N as f64);
        }
        let c = |i: usize| {
            let end = if i == 0 || i == N { 2.0 } else { 1.0 };
            if i.is_multiple_of(2) {
                end
            } else {
                -end
            }
        };
        let mut d = [[0.0; N_PATCH]; N_PATCH];
        for i in 0..N_PATCH {
            let mut diag = 0.0;
            for j in 0..N_PATCH {
                if i != j {
                    d[i][j] = c(i) / c(j) / (x[i] - x[j]);
                    diag -= d[i][j];
                }
            }
            d[i][i] = diag;
        }
        let mut w = [0.0; N_PATCH];
        for (j, wj) in w.iter_mut().enumerate() {
            let theta = pi * j as f64 / N as f64;
            let mut s = 1.0;
            for k in 1..=N / 2 {
                let bk = if 2 * k == N { 1.0 } else { 2.0 };
                s -= bk * libm::cos(2.0 * k as f64 * theta) / (4.0 * (k * k) as f64 - 1.0);
            }
            let cj = if j == 0 || j == N { 1.0 } else { 2.0 };
            *wj = cj * s / N as f64 * a;
        }
        for xj in x.iter_mut() {
            *xj *= a;
        }
        for row in d.iter_mut() {
            for dij in row.iter_mut() {
                *dij /= a;
            }
        }
        Self { x, d, w }
    }
}

impl TowedWheelParams {
    /// A(V) = `a0 + V a1` with the steering damper's coefficient `c_damper_nspm`: the
    /// speed-free part and the speed's coefficient.
    fn parts(&self, c_damper_nspm: f64) -> (Matrix<N_STATES>, Matrix<N_STATES>) {
        let (a, s, l, k, b) = (self.a, self.sigma, self.l, self.k, self.b);
        let p = Patch::new(a);
        let mut a0 = Matrix::<N_STATES>::zeros();
        let mut a1 = Matrix::<N_STATES>::zeros();
        a0[(PSI, DPSI)] = 1.0;
        // the patch: q_j' = V (q_x)_j + V psi + (l - x_j) psi'; the leading edge's row from
        // the string outside
        for i in 0..N_PATCH {
            let r = Q0 + i;
            a1[(r, PSI)] = 1.0;
            a0[(r, DPSI)] = l - p.x[i];
            if i == 0 {
                a1[(r, r)] = -1.0 / s;
            } else {
                for j in 0..N_PATCH {
                    a1[(r, Q0 + j)] = p.d[i][j];
                }
            }
        }
        // the yaw balance, M / J_A
        let inv_j = 1.0 / self.j_a;
        let front = s * (a + s - l);
        let rear = s * (a + s + l);
        for j in 0..N_PATCH {
            a0[(DPSI, Q0 + j)] += k * p.w[j] * (p.x[j] - l) * inv_j;
        }
        a0[(DPSI, Q0)] += k * front * inv_j;
        a0[(DPSI, Q_TRAIL)] -= k * rear * inv_j;
        // damping in the patch: b int (x - l)(V psi + (l - x) psi') dx
        a1[(DPSI, PSI)] += -2.0 * a * l * b * inv_j;
        a0[(DPSI, DPSI)] += -(2.0 * a * a * a / 3.0 + 2.0 * a * l * l) * b * inv_j;
        // front tail: the leading edge's rate V psi + (l - a) psi'
        a1[(DPSI, PSI)] += b * front * inv_j;
        a0[(DPSI, DPSI)] += b * front * (l - a) * inv_j;
        // rear tail: q(-a)' - (V / sigma) q(-a), with q(-a)' from the patch's last row
        a1[(DPSI, PSI)] -= b * rear * inv_j;
        a0[(DPSI, DPSI)] -= b * rear * (l + a) * inv_j;
        for j in 0..N_PATCH {
            a1[(DPSI, Q0 + j)] -= b * rear * p.d[N_PATCH - 1][j] * inv_j;
        }
        a1[(DPSI, Q_TRAIL)] += b * rear / s * inv_j;
        a0[(DPSI, DPSI)] -= c_damper_nspm * self.l_d * self.l_d * inv_j;
        (a0, a1)
    }
}

impl LinearModel<N_STATES> for TowedWheelParams {
    const NAME: &'static str = "towed-wheel-string";
    const STATE_NAMES: [&'static str; N_STATES] = STATE_NAMES;
    const DOF: usize = 1;

    fn linearise(&self, v_mps: f64, c_damper_nspm: f64) -> Matrix<N_STATES> {
        let (a0, a1) = self.parts(c_damper_nspm);
        a0 + a1 * v_mps
    }

    fn dlinearise_dv(&self) -> Matrix<N_STATES> {
        self.parts(0.0).1
    }

    /// The damper's force at the lever `l_d`: the yaw moment `-l_d F_d`.
    fn damper_force_input(&self) -> SVector<f64, N_STATES> {
        let mut b = SVector::<f64, N_STATES>::zeros();
        b[DPSI] = -self.l_d / self.j_a;
        b
    }

    /// The wheel's yaw about the king pin.
    fn wheel_yaw_output(&self) -> SVector<f64, N_STATES> {
        let mut c = SVector::<f64, N_STATES>::zeros();
        c[PSI] = 1.0;
        c
    }

    /// 3: the benchmark's shimmy (1-3 Hz) is about three times slower than the car's ~6 Hz;
    /// the meter's 3-20 Hz band becomes 1-6.7 Hz and its memories three times longer in
    /// seconds, the same in shimmy cycles.
    fn meter_time_scale(&self) -> u16 {
        3
    }

    /// [`ModeShape::InPhaseWheelYaw`] (the one wheel's shimmy) unless the tyre's deformation
    /// exceeds three times the lateral motion the yaw makes over the tyre's reach
    /// `(l + a + sigma) |psi|`: then [`ModeShape::TyreLag`] (the patch's own transport
    /// modes). The wheel has all the kinetic energy (the string is massless).
    fn classify(&self, v: &ComplexVector<N_STATES>) -> ModeShapeInfo {
        let psi = libm::sqrt(v[PSI].norm_sqr());
        let q = (Q0..N_STATES).fold(0.0_f64, |m, i| m.max(libm::sqrt(v[i].norm_sqr())));
        let reach = (self.l + self.a + self.sigma) * psi;
        let tyre_ratio = if reach > 0.0 {
            q / reach
        } else {
            f64::INFINITY
        };
        let shape = if tyre_ratio > 3.0 {
            ModeShape::TyreLag
        } else {
            ModeShape::InPhaseWheelYaw
        };
        ModeShapeInfo {
            shape,
            wheel_energy_frac: 1.0,
            tramp_energy_frac: 0.0,
            steering_wheel_energy_frac: 0.0,
            steering_wheel_ratio: 0.0,
            wheel_phase_rad: 0.0,
            tyre_ratio,
        }
    }
}

/// No parameter is updated online: this model's identifiability study has not been run, so
/// its margin stays the vehicle file's (corrected by the fusion's measured damping offset).
impl UpdatableModel<N_STATES> for TowedWheelParams {
    const UPDATE_PARAMS: &'static [UpdateParam] = &[];

    fn scaled_update_param(&self, _index: usize, _factor: f64) -> Self {
        *self
    }

    fn update_param(&self, _index: usize) -> f64 {
        f64::NAN
    }
}
