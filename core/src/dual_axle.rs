//! The dual-front-axle heavy truck: an 8-DOF model of the two steered front axles of an 8x4
//! truck, linked by a mid-shift transmission (`docs/dual-axle-truck.md`; every number's source
//! or reasoning is there). After Wei et al., "Shimmy of a heavy truck with dual front axles"
//! (Shock and Vibration 2015, article 839801): both steered axles, the linkage between them,
//! tyre lateral dynamics and dry friction at the kingpins (the friction lives in the nonlinear
//! simulator, `host-sim/src/model/dual_axle_plant.rs`; this linear model is friction-free).
//!
//! Degrees of freedom `q = [psi_1L, psi_1R, psi_2L, psi_2R, phi_1, phi_2, theta_g, theta_m]`:
//! - `psi_ij`: yaw of wheel j (left, right) of axle i (1 front, 2 second) about its kingpin,
//!   rad, positive = steer left;
//! - `phi_i`: roll (tramp) of axle i on its leaf springs and tyres, rad;
//! - `theta_g`: the steering gear's pitman arm, referred to axle 1's left kingpin, rad: held to
//!   the frame by the power-steering gear (`k_g`, `c_g`), tied to axle 1's steering arm by the
//!   first drag link (`k_d1`);
//! - `theta_m`: the mid-shift rocker, referred to axle 2's left kingpin, rad: driven from the
//!   pitman arm by the steering transition rod (`k_t`, through the axles' steer ratio `n_2`),
//!   tied to axle 2's steering arm by the second drag link (`k_d2`).
//!
//! State vector (20): `x = [q, dq, a_1L, a_1R, a_2L, a_2R]` with the lagged slip angles
//! (`F_ij = C_a,i a_ij`, relaxation length `sigma`):
//! `sigma a_ij' = V (psi_ij - a_ij) + e dpsi_ij - h_r dphi_i`.

use nalgebra::SVector;

use crate::model::{
    ComplexVector, LinearModel, Matrix, ModeShape, ModeShapeInfo, UpdatableModel, UpdateParam,
};
use crate::plant::{wheel_phase_rad, wheel_yaw_shape};
use crate::truck::G_MPS2;

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

/// Physical parameters of the two steered front axles (`docs/dual-axle-truck.md`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DualAxleParams {
    /// Wheel-assembly yaw inertia about the kingpin I_k, kg m^2.
    pub i_k: f64,
    /// Wheel spin inertia I_p, kg m^2.
    pub i_p: f64,
    /// Loaded rolling radius R, m.
    pub r: f64,
    /// Roll-centre height above the ground h_r, m.
    pub h_r: f64,
    /// Tyre relaxation length sigma, m.
    pub sigma: f64,
    /// Caster (mechanical) trail e, m.
    pub e: f64,
    /// Pneumatic trail t_p, m.
    pub t_p: f64,
    /// Cornering stiffness per unit wheel load C_a / F_z, 1/rad.
    pub c_a_per_fz: f64,
    /// Steering-arm length l_t (the lever of a steering damper on axle 1), m.
    pub l_t: f64,
    /// Tie-rod stiffness of each axle referred to the kingpin k_tr, N m/rad.
    pub k_tr: f64,
    /// Viscous kingpin damping (grease, seals) c_k, N m s/rad.
    pub c_k: f64,
    /// First drag link (pitman arm to axle 1) k_d1, N m/rad.
    pub k_d1: f64,
    /// Second drag link (mid-shift rocker to axle 2) k_d2, N m/rad.
    pub k_d2: f64,
    /// Steering transition rod (pitman arm to mid-shift rocker) k_t, N m/rad (axle 2's side).
    pub k_t: f64,
    /// Power-steering gear's hold of the pitman arm against the frame k_g, N m/rad.
    pub k_g: f64,
    /// Steering-gear damping (valve, servo) c_g, N m s/rad.
    pub c_g: f64,
    /// Pitman arm, sector shaft and steering column inertia J_g, kg m^2 (axle 1's side).
    pub j_g: f64,
    /// Mid-shift rocker and rods inertia J_m, kg m^2 (axle 2's side).
    pub j_m: f64,
    /// Mid-shift rocker bearing damping c_m, N m s/rad.
    pub c_m: f64,
    /// Axle 1 to the rear bogie's centre L, m.
    pub wheelbase: f64,
    /// Axle 1 to axle 2 s_12, m.
    pub axle_spacing: f64,
    /// Axle roll inertia about the roll centre I_phi (each axle), kg m^2.
    pub i_phi: f64,
    /// Track (tyre centre to tyre centre) b, m.
    pub track: f64,
    /// Tyre vertical stiffness k_tz, N/m.
    pub k_tz: f64,
    /// Leaf-spring rate per side k_s, N/m.
    pub k_spring: f64,
    /// Lateral spacing of the two leaf springs s, m.
    pub spring_spacing: f64,
    /// Shock-absorber damping per side (at the springs) c_s, N s/m.
    pub c_shock: f64,
    /// Static load of axle 1, kg.
    pub axle_load_1_kg: f64,
    /// Static load of axle 2, kg.
    pub axle_load_2_kg: f64,
    /// Dry (Coulomb) friction torque at each kingpin M_f, N m (the nonlinear simulator only).
    pub m_f: f64,
    /// Tyre-road friction coefficient mu (the simulator's tyre: peak force mu F_z).
    pub mu: f64,
    /// Magic-Formula shape factor C_s of the simulator's tyre.
    pub c_s: f64,
}

/// The derived linear coefficients.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DualAxleOperatingPoint {
    /// Static load per wheel of axle 1 and 2, N.
    pub f_z: [f64; 2],
    /// Cornering stiffness per tyre of axle 1 and 2, N/rad.
    pub c_a: [f64; 2],
    /// Roll stiffness of each axle (tyres + springs), N m/rad.
    pub k_phi: f64,
    /// Roll damping of each axle (shock absorbers), N m s/rad.
    pub c_phi: f64,
    /// Axle 2's steer angle per unit axle-1 steer angle (rigid linkage): `(L - s_12) / L`.
    pub n_2: f64,
}

/// The named parameter sets of the dual-axle truck.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DualAxleSet {
    /// The reference 8x4 truck at its rated front-axle loads.
    Rated,
    /// The same truck without kingpin dry friction (`m_f` = 0): the simulator's plant is then
    /// the linear model's plus the tyres' saturation (the margin runs' friction-free case).
    Frictionless,
}

impl DualAxleSet {
    /// Every named set.
    pub const ALL: [DualAxleSet; 2] = [DualAxleSet::Rated, DualAxleSet::Frictionless];

    /// The set's name (vehicle files, command lines).
    pub const fn name(self) -> &'static str {
        match self {
            DualAxleSet::Rated => "dual-axle",
            DualAxleSet::Frictionless => "dual-axle-frictionless",
        }
    }

    /// Looks a set up by name.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.name() == name)
    }

    /// The set's parameters.
    pub fn params(self) -> DualAxleParams {
        match self {
            DualAxleSet::Rated => DualAxleParams::reference(),
            DualAxleSet::Frictionless => DualAxleParams {
                m_f: 0.0,
                ..DualAxleParams::reference()
            },
        }
    }
}

impl DualAxleParams {
    /// The reference truck: an 8x4 tipper class on 315/80R22.5 steer tyres, each front axle at
    /// 8 t; every value explained in `docs/dual-axle-truck.md`.
    pub fn reference() -> Self {
        // wheel: tyre (60 kg, radius of gyration 0.43 m), steel rim (33 kg, 0.26 m), hub, drum
        // and brake (110 kg, 0.18 m)
        let parts = [(60.0, 0.43), (33.0, 0.26), (110.0, 0.18)];
        let i_p: f64 = parts.iter().map(|(m, rg)| m * rg * rg).sum();
        let m_wheel: f64 = parts.iter().map(|(m, _)| m).sum();
        // yaw about a diameter: half the polar inertia, the width term (0.32 m section) and
        // the kingpin offset at the wheel centre (0.15 m) by the parallel-axis theorem
        let (width, offset) = (0.32, 0.15);
        let i_k = 0.5 * i_p + m_wheel * width * width / 12.0 + m_wheel * offset * offset;
        let track = 2.05;
        let (m_beam, beam_len) = (350.0, 2.0);
        let i_phi = 2.0 * m_wheel * (0.5 * track) * (0.5 * track)
            + 2.0 * 0.5 * i_p
            + m_beam * beam_len * beam_len / 12.0;
        let r = 0.50;
        let caster_rad = 3.0_f64.to_radians();
        // rods: axial stiffness (tube and two ball joints) on 0.25 m arms
        let arm = 0.25;
        Self {
            i_k,
            i_p,
            r,
            h_r: r,
            sigma: 0.6,
            e: r * libm::tan(caster_rad),
            t_p: 0.05,
            c_a_per_fz: 7.0,
            l_t: arm,
            k_tr: 8.0e6 * arm * arm,
            c_k: 50.0,
            k_d1: 1.0e7 * arm * arm,
            k_d2: 1.0e7 * arm * arm,
            k_t: 4.8e6 * arm * arm,
            k_g: 4.0e5,
            c_g: 500.0,
            j_g: 15.0,
            j_m: 3.0,
            c_m: 20.0,
            wheelbase: 5.8,
            axle_spacing: 1.9,
            i_phi,
            track,
            k_tz: 1.0e6,
            k_spring: 3.0e5,
            spring_spacing: 0.9,
            c_shock: 2.0e4,
            axle_load_1_kg: 8000.0,
            axle_load_2_kg: 8000.0,
            m_f: 40.0,
            mu: 0.8,
            c_s: 1.3,
        }
    }

    /// The linear coefficients: wheel loads, cornering stiffnesses, roll stiffness and
    /// damping, the second axle's steer ratio.
    pub fn operating_point(&self) -> DualAxleOperatingPoint {
        let f_z = [
            0.5 * self.axle_load_1_kg * G_MPS2,
            0.5 * self.axle_load_2_kg * G_MPS2,
        ];
        let (half_b, half_s) = (0.5 * self.track, 0.5 * self.spring_spacing);
        DualAxleOperatingPoint {
            f_z,
            c_a: [self.c_a_per_fz * f_z[0], self.c_a_per_fz * f_z[1]],
            k_phi: 2.0 * self.k_tz * half_b * half_b + 2.0 * self.k_spring * half_s * half_s,
            c_phi: 2.0 * self.c_shock * half_s * half_s,
            n_2: (self.wheelbase - self.axle_spacing) / self.wheelbase,
        }
    }

    /// Spin angular momentum of one wheel I_p V / R at `v_mps`, N m s.
    pub fn spin_momentum(&self, v_mps: f64) -> f64 {
        self.i_p * v_mps / self.r
    }

    /// The mechanical inertia of DOF `i` (the diagonal mass matrix).
    pub fn inertia(&self, i: usize) -> f64 {
        match i {
            PSI_1L..=PSI_2R => self.i_k,
            PHI_1 | PHI_2 => self.i_phi,
            THETA_G => self.j_g,
            _ => self.j_m,
        }
    }

    /// The stiffness matrix K (N_DOF x N_DOF, symmetric): tie rods, drag links, transition rod
    /// through the steer ratio, steering gear, roll.
    pub fn stiffness(&self) -> [[f64; N_DOF]; N_DOF] {
        let op = self.operating_point();
        let mut k = [[0.0; N_DOF]; N_DOF];
        // a spring of stiffness s on the stretch r_i q_i - r_j q_j
        let mut spring = |i: usize, j: usize, s: f64, ri: f64, rj: f64| {
            k[i][i] += s * ri * ri;
            k[j][j] += s * rj * rj;
            k[i][j] -= s * ri * rj;
            k[j][i] -= s * ri * rj;
        };
        spring(PSI_1L, PSI_1R, self.k_tr, 1.0, 1.0);
        spring(PSI_2L, PSI_2R, self.k_tr, 1.0, 1.0);
        spring(PSI_1L, THETA_G, self.k_d1, 1.0, 1.0);
        spring(PSI_2L, THETA_M, self.k_d2, 1.0, 1.0);
        spring(THETA_M, THETA_G, self.k_t, 1.0, op.n_2);
        k[THETA_G][THETA_G] += self.k_g;
        k[PHI_1][PHI_1] += op.k_phi;
        k[PHI_2][PHI_2] += op.k_phi;
        k
    }
}

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

/// One field of the dual-axle truck's parameters in a vehicle file: name, unit, plausible
/// range (both ends included).
pub type DualAxleField = crate::truck::TruckField;

/// Every field of [`DualAxleParams`], in the order of `docs/dual-axle-truck.md`.
pub const DUAL_AXLE_FIELDS: [DualAxleField; 32] = {
    const fn f(name: &'static str, unit: &'static str, lo: f64, hi: f64) -> DualAxleField {
        DualAxleField {
            name,
            unit,
            range: (lo, hi),
        }
    }
    [
        f("i_k", "kg m^2", 1.0, 1000.0),
        f("i_p", "kg m^2", 0.0, 1000.0),
        f("r", "m", 0.2, 1.5),
        f("h_r", "m", 0.0, 2.0),
        f("sigma", "m", 0.05, 3.0),
        f("e", "m", 0.0, 0.3),
        f("t_p", "m", 0.0, 0.3),
        f("c_a_per_fz", "1/rad", 0.5, 30.0),
        f("l_t", "m", 0.05, 1.0),
        f("k_tr", "N m/rad", 1000.0, 1.0e9),
        f("c_k", "N m s/rad", 0.0, 1.0e5),
        f("k_d1", "N m/rad", 1000.0, 1.0e9),
        f("k_d2", "N m/rad", 1000.0, 1.0e9),
        f("k_t", "N m/rad", 1000.0, 1.0e9),
        f("k_g", "N m/rad", 0.0, 1.0e9),
        f("c_g", "N m s/rad", 0.0, 1.0e6),
        f("j_g", "kg m^2", 0.01, 1000.0),
        f("j_m", "kg m^2", 0.01, 1000.0),
        f("c_m", "N m s/rad", 0.0, 1.0e6),
        f("wheelbase", "m", 1.0, 15.0),
        f("axle_spacing", "m", 0.5, 5.0),
        f("i_phi", "kg m^2", 10.0, 100000.0),
        f("track", "m", 0.5, 4.0),
        f("k_tz", "N/m", 10000.0, 1.0e8),
        f("k_spring", "N/m", 0.0, 1.0e8),
        f("spring_spacing", "m", 0.1, 4.0),
        f("c_shock", "N s/m", 0.0, 1.0e7),
        f("axle_load_1_kg", "kg", 100.0, 30000.0),
        f("axle_load_2_kg", "kg", 100.0, 30000.0),
        f("m_f", "N m", 0.0, 5000.0),
        f("mu", "-", 0.05, 1.5),
        f("c_s", "-", 0.5, 3.0),
    ]
};

/// Why a dual-axle parameter set is rejected.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum DualAxleFieldError {
    /// No field of that name.
    #[error("no dual-axle field of that name")]
    Unknown,
    /// A value outside its field's plausible range (or not finite).
    #[error("field `{name}` = {value} {unit} is outside {lo} ..= {hi} {unit}")]
    OutOfRange {
        /// The field.
        name: &'static str,
        /// The value given.
        value: f64,
        /// Lower end of the range.
        lo: f64,
        /// Upper end of the range.
        hi: f64,
        /// The field's unit.
        unit: &'static str,
    },
    /// The second axle is not between the first and the rear bogie.
    #[error("field `axle_spacing` = {axle_spacing} m must be below `wheelbase` = {wheelbase} m (axle 2 lies between axle 1 and the rear bogie)")]
    AxleOrder {
        /// The axle spacing, m.
        axle_spacing: f64,
        /// The wheelbase, m.
        wheelbase: f64,
    },
}

impl DualAxleParams {
    fn field_mut(&mut self, name: &str) -> Option<&mut f64> {
        Some(match name {
            "i_k" => &mut self.i_k,
            "i_p" => &mut self.i_p,
            "r" => &mut self.r,
            "h_r" => &mut self.h_r,
            "sigma" => &mut self.sigma,
            "e" => &mut self.e,
            "t_p" => &mut self.t_p,
            "c_a_per_fz" => &mut self.c_a_per_fz,
            "l_t" => &mut self.l_t,
            "k_tr" => &mut self.k_tr,
            "c_k" => &mut self.c_k,
            "k_d1" => &mut self.k_d1,
            "k_d2" => &mut self.k_d2,
            "k_t" => &mut self.k_t,
            "k_g" => &mut self.k_g,
            "c_g" => &mut self.c_g,
            "j_g" => &mut self.j_g,
            "j_m" => &mut self.j_m,
            "c_m" => &mut self.c_m,
            "wheelbase" => &mut self.wheelbase,
            "axle_spacing" => &mut self.axle_spacing,
            "i_phi" => &mut self.i_phi,
            "track" => &mut self.track,
            "k_tz" => &mut self.k_tz,
            "k_spring" => &mut self.k_spring,
            "spring_spacing" => &mut self.spring_spacing,
            "c_shock" => &mut self.c_shock,
            "axle_load_1_kg" => &mut self.axle_load_1_kg,
            "axle_load_2_kg" => &mut self.axle_load_2_kg,
            "m_f" => &mut self.m_f,
            "mu" => &mut self.mu,
            "c_s" => &mut self.c_s,
            _ => return None,
        })
    }

    /// The value of the field `name`.
    pub fn get(&self, name: &str) -> Option<f64> {
        let mut copy = *self;
        copy.field_mut(name).map(|v| *v)
    }

    /// Sets the field `name` to `value` if it is inside the field's range.
    pub fn set(&mut self, name: &str, value: f64) -> Result<(), DualAxleFieldError> {
        let field = DUAL_AXLE_FIELDS
            .iter()
            .find(|f| f.name == name)
            .ok_or(DualAxleFieldError::Unknown)?;
        check(field, value)?;
        *self.field_mut(name).ok_or(DualAxleFieldError::Unknown)? = value;
        Ok(())
    }

    /// Every field inside its range and the second axle ahead of the rear bogie; the first
    /// offender.
    pub fn validate(&self) -> Result<(), DualAxleFieldError> {
        for f in &DUAL_AXLE_FIELDS {
            check(f, self.get(f.name).ok_or(DualAxleFieldError::Unknown)?)?;
        }
        if self.axle_spacing >= self.wheelbase {
            return Err(DualAxleFieldError::AxleOrder {
                axle_spacing: self.axle_spacing,
                wheelbase: self.wheelbase,
            });
        }
        Ok(())
    }
}

fn check(f: &DualAxleField, value: f64) -> Result<(), DualAxleFieldError> {
    let (lo, hi) = f.range;
    if (lo..=hi).contains(&value) {
        Ok(())
    } else {
        Err(DualAxleFieldError::OutOfRange {
            name: f.name,
            value,
            lo,
            hi,
            unit: f.unit,
        })
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stability::{self, CrossingKind};

    #[test]
    fn a_is_affine_in_speed_with_the_stated_derivative() {
        let t = DualAxleSet::Rated.params();
        let a0 = t.linearise(3.0, 2.0e3);
        let a1 = t.linearise(17.0, 2.0e3);
        let err = (a1 - a0 - t.dlinearise_dv() * 14.0).amax();
        assert!(err < 1e-9 * a0.amax(), "{err}");
    }

    /// Stiffness symmetric, gyroscopic part skew, a rigid linkage (every rod infinitely stiff
    /// against the gear) steering axle 2 at n_2 times axle 1: the transition rod's term
    /// carries the steer ratio.
    #[test]
    fn structure_matches_the_equations() {
        let t = DualAxleSet::Rated.params();
        let a = t.linearise(12.0, 0.0);
        for i in 0..N_DOF {
            for j in 0..N_DOF {
                let kij = -a[(N_DOF + i, j)] * t.inertia(i);
                let kji = -a[(N_DOF + j, i)] * t.inertia(j);
                assert!((kij - kji).abs() <= 1e-9 * kij.abs().max(1.0), "K {i}{j}");
            }
        }
        let h = t.spin_momentum(12.0);
        for (w, r, _, _) in WHEELS {
            assert!((-a[(N_DOF + w, N_DOF + r)] * t.i_k - h).abs() < 1e-9 * h);
            assert!((a[(N_DOF + r, N_DOF + w)] * t.i_phi - h).abs() < 1e-9 * h);
        }
        // the kinematic steer pattern (every wheel of axle 1 at 1, of axle 2 at n_2, the
        // pitman arm at 1, the rocker at n_2) stretches no rod: only the gear's spring holds it
        let n2 = t.operating_point().n_2;
        let q = [1.0, 1.0, n2, n2, 0.0, 0.0, 1.0, n2];
        let k = t.stiffness();
        for (i, row) in k.iter().enumerate() {
            let f: f64 = row.iter().zip(q).map(|(kij, qj)| kij * qj).sum();
            let want = if i == THETA_G { t.k_g } else { 0.0 };
            assert!((f - want).abs() < 1e-6 * t.k_g, "row {i}: {f}");
        }
    }

    /// Every field is in the table, reads back what was set, and a value out of range or a
    /// second axle behind the bogie is rejected naming the field.
    #[test]
    fn the_field_table_covers_every_field_and_checks_ranges() {
        let mut t = DualAxleSet::Rated.params();
        t.validate().unwrap();
        for f in &DUAL_AXLE_FIELDS {
            let v = t.get(f.name).unwrap();
            assert!((f.range.0..=f.range.1).contains(&v), "{} = {v}", f.name);
            let mid = 0.5 * (f.range.0 + f.range.1);
            let mut u = t;
            u.set(f.name, mid).unwrap();
            assert_eq!(u.get(f.name), Some(mid), "{}", f.name);
            assert!(u != t || v == mid, "{} sets nothing", f.name);
        }
        let e = t.set("k_t", -1.0).unwrap_err();
        assert!(
            matches!(e, DualAxleFieldError::OutOfRange { name: "k_t", .. }),
            "{e}"
        );
        assert_eq!(t.set("no_such", 1.0), Err(DualAxleFieldError::Unknown));
        t.set("axle_spacing", 4.0).unwrap();
        t.set("wheelbase", 3.0).unwrap();
        assert!(matches!(
            t.validate(),
            Err(DualAxleFieldError::AxleOrder { .. })
        ));
    }

    /// The named set has a shimmy onset of the in-phase wheel-yaw mode in the truck's speed
    /// range, and the paper's directions hold in the linear model: a stiffer transition rod,
    /// a smaller pneumatic trail or caster trail raise it.
    #[test]
    fn the_onset_moves_in_the_papers_directions() {
        let onset = |t: &DualAxleParams| {
            stability::hopf_crossings(t, 0.0, 1.0, 40.0, 0.5, 1e-7)
                .unwrap()
                .iter()
                .find(|c| c.kind == CrossingKind::Onset)
                .map(|c| (c.speed_mps, c.shape))
        };
        let t = DualAxleSet::Rated.params();
        let (v0, shape) = onset(&t).expect("an onset");
        assert_eq!(shape, ModeShape::InPhaseWheelYaw);
        assert!(v0 > 5.0 && v0 < 30.0, "{v0}");
        for (name, f) in [("k_t", 1.2), ("t_p", 0.8), ("e", 0.8)] {
            let mut u = t;
            u.set(name, t.get(name).unwrap() * f).unwrap();
            let (v, _) = onset(&u).expect("an onset");
            assert!(v > v0 + 0.1, "{name} x{f}: {v} vs {v0}");
        }
    }
}

#[cfg(test)]
mod meter_signal_tests {
    use super::*;

    /// The shimmy mode's gain (per unit modal energy) in a signal with weights `w` on the
    /// axles' in-phase yaw, and each oscillatory mode's gain relative to it, at the meter's
    /// reference speed: (frequency Hz, share).
    fn shares(t: &DualAxleParams, w: [f64; 2]) -> (f64, heapless::Vec<(f64, f64), 10>) {
        let v = t.meter_reference_speed_mps();
        let a = t.linearise(v, 0.0);
        let vals = crate::eigen::eigenvalues(&a).unwrap();
        let shimmy =
            crate::stability::select_mode(t, &a, &vals, crate::stability::ModeSelect::Shimmy)
                .unwrap()
                .eigenvalue();
        let gain = |l: nalgebra::Complex<f64>| {
            let x = crate::eigen::eigenvector(&a, l).unwrap();
            let e: f64 = (0..N_DOF)
                .map(|i| t.inertia(i) * x[N_DOF + i].norm_sqr())
                .sum();
            ((x[PSI_1L] + x[PSI_1R]) * (0.5 * w[0]) + (x[PSI_2L] + x[PSI_2R]) * (0.5 * w[1])).norm()
                / libm::sqrt(e)
        };
        let g_s = gain(shimmy);
        let mut out = heapless::Vec::new();
        for l in vals
            .iter()
            .filter(|l| l.im > 0.0 && crate::eigen::is_oscillatory(**l))
        {
            out.push((l.im / (2.0 * core::f64::consts::PI), gain(*l) / g_s))
                .unwrap();
        }
        (g_s, out)
    }

    /// The meter's weights come from the model's mode shapes: on the named set the lightly
    /// damped ~15 Hz mode (the axles yawing against each other, as large as the shimmy on
    /// axle 1 alone) falls below a tenth of the shimmy's share, no other mode gains more than
    /// 0.02 of share over axle 1 alone (the 93-Hz linkage mode gains 0.018, outside the meter's
    /// band), a shimmy reads as axle 1's in-phase yaw, and the output row is the weights.
    #[test]
    fn the_weights_isolate_the_shimmy_mode() {
        let t = DualAxleSet::Rated.params();
        let w = t.meter_weights();
        assert!(w[0] > 0.0 && w[1] > 0.0, "{w:?}");
        let ((g_w, with), (g_1, alone)) = (shares(&t, w), shares(&t, [1.0, 0.0]));
        // |w . u_s| = |u_s1| up to the shape's small imaginary part (the weights are real)
        assert!((g_w / g_1 - 1.0).abs() < 0.01, "{g_w} vs {g_1}");
        let near15 = |s: &[(f64, f64)]| {
            s.iter()
                .find(|(f, _)| (13.0..17.0).contains(f))
                .map(|p| p.1)
                .unwrap()
        };
        std::println!(
            "weights {w:?} at {:.2} km/h; shares (Hz, modal filter, axle 1 alone): {:?}",
            t.meter_reference_speed_mps() * 3.6,
            with.iter()
                .zip(alone.iter())
                .map(|(a, b)| (a.0, a.1, b.1))
                .collect::<heapless::Vec<_, 10>>()
        );
        assert!(near15(&alone) > 0.8, "{alone:?}");
        assert!(near15(&with) < 0.1, "{with:?}");
        for ((f, g), (_, g1)) in with.iter().zip(alone.iter()) {
            assert!(*g <= g1 + 0.02, "{f} Hz: {g} vs axle 1 alone {g1}");
        }
        let c = t.wheel_yaw_output();
        assert_eq!(
            [c[PSI_1L], c[PSI_1R], c[PSI_2L], c[PSI_2R]],
            [0.5 * w[0], 0.5 * w[0], 0.5 * w[1], 0.5 * w[1]]
        );
        assert_eq!(c.iter().filter(|x| **x != 0.0).count(), 4);
        // the weights follow the model: a softer transition rod changes the shapes and them
        let mut soft = t;
        soft.k_t *= 0.5;
        let ws = soft.meter_weights();
        assert!((ws[1] - w[1]).abs() > 1e-3, "{ws:?} vs {w:?}");
    }
}

#[cfg(test)]
mod tracker_tests {
    use super::*;
    use crate::eigen::SolveFloat;
    use crate::estimator::model_margin::{ModelMarginConfig, ModelMarginTracker};
    use crate::stability::{self, CrossingKind};

    /// The model-margin tracker runs on the dual-axle truck (20 states) in both precisions:
    /// its onset above the current speed is the scan's Hopf crossing.
    #[test]
    fn the_tracker_finds_the_onset() {
        fn check<T: SolveFloat>() {
            let t = DualAxleSet::Rated.params();
            let scan = stability::hopf_crossings(&t, 0.0, 1.0, 40.0, 0.5, 1e-7).unwrap();
            let onset = scan.iter().find(|c| c.kind == CrossingKind::Onset).unwrap();
            let mut tr = ModelMarginTracker::<T, DualAxleParams, N_STATES>::in_precision(
                t,
                ModelMarginConfig::default(),
            );
            let p = (0..400u16)
                .find_map(|k| tr.step(f64::from(k) * 1e-3, 8.0, 0.0))
                .expect("a cycle completes");
            let above = p.above.expect("an onset above 8 m/s");
            assert_eq!(above.kind, CrossingKind::Onset);
            assert!(
                (above.speed_mps - onset.speed_mps).abs() < 2e-3,
                "{}: {} vs {}",
                T::NAME,
                above.speed_mps,
                onset.speed_mps
            );
            assert!(p.shimmy_found, "{}", T::NAME);
        }
        check::<f64>();
        check::<f32>();
    }
}
