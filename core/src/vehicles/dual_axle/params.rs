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

#[allow(unused_imports)]
use super::*;
use crate::vehicles::fields::{FieldError, FieldTable, ModelField};

use crate::units::G_MPS2;

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

impl DualAxleParams {
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

/// Every field of [`DualAxleParams`], in the order of `docs/dual-axle-truck.md`.
pub const DUAL_AXLE_FIELDS: [ModelField; 32] = {
    const fn f(name: &'static str, unit: &'static str, lo: f64, hi: f64) -> ModelField {
        ModelField::new(name, unit, lo, hi)
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
    /// A field unknown or out of its range.
    #[error(transparent)]
    Field(#[from] FieldError),
    /// The second axle is not between the first and the rear bogie.
    #[error("field `axle_spacing` = {axle_spacing} m must be below `wheelbase` = {wheelbase} m (axle 2 lies between axle 1 and the rear bogie)")]
    AxleOrder {
        /// The axle spacing, m.
        axle_spacing: f64,
        /// The wheelbase, m.
        wheelbase: f64,
    },
}

impl FieldTable for DualAxleParams {
    const FIELDS: &'static [ModelField] = &DUAL_AXLE_FIELDS;

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
}

impl DualAxleParams {
    /// Every field inside its range and the second axle ahead of the rear bogie; the first
    /// offender.
    pub fn validate(&self) -> Result<(), DualAxleFieldError> {
        self.check_ranges()?;
        if self.axle_spacing >= self.wheelbase {
            return Err(DualAxleFieldError::AxleOrder {
                axle_spacing: self.axle_spacing,
                wheelbase: self.wheelbase,
            });
        }
        Ok(())
    }
}
