//! The heavy mining dump truck: a 5-DOF front-axle steering model of a ~200-t-class rigid-frame
//! haul truck on hydro-pneumatic struts (`docs/mining-truck.md`; every number's source or
//! reasoning is there).
//!
//! Degrees of freedom `q = [psi_L, psi_R, phi, theta_c, y]`:
//! - `psi_L`, `psi_R`: wheel yaw about the kingpins (positive = steer left), rad;
//! - `phi`: roll (tramp) of the solid front axle on its two struts and tyres, rad;
//! - `theta_c`: the hydraulic steering linkage (cylinder rods, bell crank) referred to the left
//!   kingpin, rad: held to the frame by the oil columns of the closed steering valve (stiffness
//!   `k_h`, damping `c_h`) and tied to the left steering arm by `k_d`;
//! - `y`: the axle's lateral displacement against the frame (Panhard rod, `k_y`), m, positive to
//!   the left: the fifth DOF. The tyres' lateral forces act on the axle itself, which on a
//!   21-t unsprung axle is not rigid against the frame, and its motion feeds back into the slip.
//!
//! State vector (12): `x = [q, dq, a_L, a_R]` with the lagged slip angles `a_i` (tyre force
//! `F_i = C_a a_i`, relaxation length `sigma`):
//! `sigma a_i' = V (psi_i - a_i) + e dpsi_i - h_r dphi - dy`.
//!
//! The hydro-pneumatic strut ([`Hps`]) is a polytropic gas spring: the static load sets the
//! pressure, the pressure the gas volume and stroke, and the stiffness `k = n p A^2 / V` enters
//! the axle's roll stiffness. Load and gas charge therefore move the Hopf window.

#[allow(unused_imports)]
use super::*;
use crate::vehicles::fields::{FieldError, FieldTable, ModelField};

use crate::units::G_MPS2;

/// A hydro-pneumatic strut as a polytropic gas spring: `p V^n = p0 V0^n`, gas volume
/// `V = V0 - A x` at stroke `x` (compression positive from full extension), force `F = p A`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hps {
    /// Initial gas volume at full extension (the charge), m^3.
    pub v0_m3: f64,
    /// Pre-charge pressure at full extension, Pa.
    pub p0_pa: f64,
    /// Piston area, m^2.
    pub area_m2: f64,
    /// Polytropic exponent n (1 isothermal, 1.4 adiabatic nitrogen).
    pub n: f64,
}

/// Why a strut cannot carry a load.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum HpsError {
    /// The load is below the pre-charge force p0 A: the strut stays topped out (no spring).
    #[error("strut load {load_n} N is below the pre-charge force {precharge_n} N (topped out)")]
    ToppedOut {
        /// The static load, N.
        load_n: f64,
        /// p0 A, N.
        precharge_n: f64,
    },
    /// The static stroke leaves less than the strut's minimum gas volume (bottomed out).
    #[error("static gas volume {volume_m3} m^3 is below the strut's minimum {min_m3} m^3 (bottomed out)")]
    BottomedOut {
        /// The static gas volume, m^3.
        volume_m3: f64,
        /// The smallest gas volume the strut allows, m^3.
        min_m3: f64,
    },
}

/// A strut's static operating point under a load.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HpsPoint {
    /// Static gas pressure, Pa.
    pub pressure_pa: f64,
    /// Static gas volume, m^3.
    pub volume_m3: f64,
    /// Static stroke from full extension, m.
    pub stroke_m: f64,
    /// Linear stiffness there, `n p A^2 / V`, N/m.
    pub stiffness_npm: f64,
}

impl Hps {
    /// Smallest gas volume as a fraction of `v0_m3` (the strut's mechanical stop).
    pub const MIN_VOLUME_FRAC: f64 = 0.1;

    /// Gas pressure at stroke `x_m`, Pa (infinite at or beyond zero volume).
    pub fn pressure_pa(&self, x_m: f64) -> f64 {
        let v = self.v0_m3 - self.area_m2 * x_m;
        if v <= 0.0 {
            return f64::INFINITY;
        }
        self.p0_pa * libm::pow(self.v0_m3 / v, self.n)
    }

    /// Strut force at stroke `x_m`, N: the large-stroke nonlinear spring of the simulator.
    pub fn force_n(&self, x_m: f64) -> f64 {
        self.pressure_pa(x_m) * self.area_m2
    }

    /// dF/dx at stroke `x_m`, N/m: the gas law's derivative `n p A^2 / V`.
    pub fn stiffness_npm(&self, x_m: f64) -> f64 {
        let v = self.v0_m3 - self.area_m2 * x_m;
        self.n * self.pressure_pa(x_m) * self.area_m2 * self.area_m2 / v
    }

    /// The static point under the load `load_n`: pressure F/A, volume `V0 (p0/p)^(1/n)`,
    /// stroke `(V0 - V)/A`, stiffness.
    pub fn static_point(&self, load_n: f64) -> Result<HpsPoint, HpsError> {
        let precharge_n = self.p0_pa * self.area_m2;
        // NaN is not above the pre-charge either
        if load_n.partial_cmp(&precharge_n) != Some(core::cmp::Ordering::Greater) {
            return Err(HpsError::ToppedOut {
                load_n,
                precharge_n,
            });
        }
        let p = load_n / self.area_m2;
        let v = self.v0_m3 * libm::pow(self.p0_pa / p, 1.0 / self.n);
        let min_m3 = Self::MIN_VOLUME_FRAC * self.v0_m3;
        if v < min_m3 {
            return Err(HpsError::BottomedOut {
                volume_m3: v,
                min_m3,
            });
        }
        Ok(HpsPoint {
            pressure_pa: p,
            volume_m3: v,
            stroke_m: (self.v0_m3 - v) / self.area_m2,
            stiffness_npm: self.n * p * self.area_m2 * self.area_m2 / v,
        })
    }
}

/// Torsional stiffness at the kingpin of two steering cylinders held by the closed valve: each
/// oil column `beta A_c^2 / V_c` (N/m) on a steering arm `arm_m`, N m/rad.
pub const fn oil_column_stiffness(beta_pa: f64, area_m2: f64, volume_m3: f64, arm_m: f64) -> f64 {
    2.0 * beta_pa * area_m2 * area_m2 / volume_m3 * arm_m * arm_m
}

/// Physical parameters of the truck's front axle and steering (`docs/mining-truck.md`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TruckParams {
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
    /// Steering-arm length l_t (the damper's lever), m.
    pub l_t: f64,
    /// Track-rod stiffness referred to the kingpin K_tr, N m/rad.
    pub k_tr: f64,
    /// Kingpin damping c_k, N m s/rad.
    pub c_k: f64,
    /// Axle roll inertia about the roll centre I_phi, kg m^2.
    pub i_phi: f64,
    /// Unsprung front mass (axle, wheels, struts' lower parts) m_a, kg.
    pub m_axle: f64,
    /// Lateral stiffness of the axle's location against the frame k_y, N/m.
    pub k_y: f64,
    /// Lateral damping of the axle's location c_y, N s/m.
    pub c_y: f64,
    /// Front track (tyre centre to tyre centre) b, m.
    pub track: f64,
    /// Tyre vertical stiffness k_tz, N/m.
    pub k_tz: f64,
    /// Lateral spacing of the two struts s, m.
    pub strut_spacing: f64,
    /// Strut damping (orifices) c_s, N s/m.
    pub c_strut: f64,
    /// The struts' gas spring.
    pub hps: Hps,
    /// Steering-linkage inertia referred to the kingpin J_c, kg m^2.
    pub j_c: f64,
    /// Linkage-to-arm stiffness (rod eyes, brackets) referred to the kingpin k_d, N m/rad.
    pub k_d: f64,
    /// Oil-column stiffness of the steering cylinders to the frame k_h, N m/rad.
    pub k_h: f64,
    /// Steering-linkage damping (valve, seals) c_h, N m s/rad.
    pub c_h: f64,
    /// Front axle load of the empty truck, kg.
    pub front_empty_kg: f64,
    /// Payload carried, kg.
    pub payload_kg: f64,
    /// Share of the payload on the front axle.
    pub payload_front_share: f64,
    /// Tyre-road friction coefficient mu (the simulator's tyre: peak force mu F_z).
    pub mu: f64,
    /// Magic-Formula shape factor C_s of the simulator's tyre.
    pub c_s: f64,
}

/// The truck's derived linear coefficients at its load and gas charge.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TruckOperatingPoint {
    /// Static load per front wheel F_z, N.
    pub f_z: f64,
    /// Cornering stiffness per tyre C_a, N/rad.
    pub c_a: f64,
    /// Static point of each strut.
    pub strut: HpsPoint,
    /// Axle roll stiffness K_phi (tyres + struts), N m/rad.
    pub k_phi: f64,
    /// Axle roll damping (struts) c_phi, N m s/rad.
    pub c_phi: f64,
}

impl TruckParams {
    /// A copy carrying `payload_kg`.
    #[must_use]
    pub fn with_payload(mut self, payload_kg: f64) -> Self {
        self.payload_kg = payload_kg;
        self
    }

    /// A copy with the struts charged to the initial gas volume `v0_m3`.
    #[must_use]
    pub fn with_gas_volume(mut self, v0_m3: f64) -> Self {
        self.hps.v0_m3 = v0_m3;
        self
    }

    /// Static load per front wheel F_z, N.
    pub fn wheel_load_n(&self) -> f64 {
        0.5 * (self.front_empty_kg + self.payload_front_share * self.payload_kg) * G_MPS2
    }

    /// Static load per strut: the wheel load less half the unsprung mass, N.
    pub fn strut_load_n(&self) -> f64 {
        self.wheel_load_n() - 0.5 * self.m_axle * G_MPS2
    }

    /// The linear coefficients at this load and gas charge, or why the struts cannot carry it.
    pub fn operating_point(&self) -> Result<TruckOperatingPoint, HpsError> {
        let f_z = self.wheel_load_n();
        let strut = self.hps.static_point(self.strut_load_n())?;
        let half_track = 0.5 * self.track;
        let half_s = 0.5 * self.strut_spacing;
        Ok(TruckOperatingPoint {
            f_z,
            c_a: self.c_a_per_fz * f_z,
            strut,
            k_phi: 2.0 * self.k_tz * half_track * half_track
                + 2.0 * strut.stiffness_npm * half_s * half_s,
            c_phi: 2.0 * self.c_strut * half_s * half_s,
        })
    }

    /// Spin angular momentum of one wheel I_p V / R at `v_mps`, N m s.
    pub fn spin_momentum(&self, v_mps: f64) -> f64 {
        self.i_p * v_mps / self.r
    }

    /// The operating point, or (struts topped or bottomed out) a zero roll spring from them:
    /// [`LinearModel`](crate::model::LinearModel) is infallible, so callers validate with [`Self::operating_point`] first
    /// (the simulator's nonlinear plant uses the same point).
    pub fn point_or_tyres_only(&self) -> TruckOperatingPoint {
        self.operating_point().unwrap_or_else(|_| {
            let f_z = self.wheel_load_n();
            let half_track = 0.5 * self.track;
            TruckOperatingPoint {
                f_z,
                c_a: self.c_a_per_fz * f_z,
                strut: HpsPoint {
                    pressure_pa: 0.0,
                    volume_m3: 0.0,
                    stroke_m: 0.0,
                    stiffness_npm: 0.0,
                },
                k_phi: 2.0 * self.k_tz * half_track * half_track,
                c_phi: 0.0,
            }
        })
    }
}

/// Every field of [`TruckParams`], in the order of `docs/mining-truck.md`'s model.
pub const TRUCK_FIELDS: [ModelField; 32] = [
    ModelField::new("i_k", "kg m^2", 100.0, 100000.0),
    ModelField::new("i_p", "kg m^2", 0.0, 100000.0),
    ModelField::new("r", "m", 0.3, 2.5),
    ModelField::new("h_r", "m", 0.0, 3.0),
    ModelField::new("sigma", "m", 0.05, 5.0),
    ModelField::new("e", "m", 0.0, 0.5),
    ModelField::new("t_p", "m", 0.0, 0.5),
    ModelField::new("c_a_per_fz", "1/rad", 0.5, 30.0),
    ModelField::new("l_t", "m", 0.05, 2.0),
    ModelField::new("k_tr", "N m/rad", 10000.0, 10000000000.0),
    ModelField::new("c_k", "N m s/rad", 0.0, 1000000.0),
    ModelField::new("i_phi", "kg m^2", 100.0, 10000000.0),
    ModelField::new("m_axle", "kg", 100.0, 100000.0),
    ModelField::new("k_y", "N/m", 10000.0, 10000000000.0),
    ModelField::new("c_y", "N s/m", 0.0, 100000000.0),
    ModelField::new("track", "m", 0.5, 8.0),
    ModelField::new("k_tz", "N/m", 10000.0, 1000000000.0),
    ModelField::new("strut_spacing", "m", 0.2, 8.0),
    ModelField::new("c_strut", "N s/m", 0.0, 100000000.0),
    ModelField::new("hps_v0_m3", "m^3", 0.0001, 0.2),
    ModelField::new("hps_p0_pa", "Pa", 10000.0, 50000000.0),
    ModelField::new("hps_area_m2", "m^2", 0.0001, 1.0),
    ModelField::new("hps_n", "-", 1.0, 1.67),
    ModelField::new("j_c", "kg m^2", 0.01, 100000.0),
    ModelField::new("k_d", "N m/rad", 1000.0, 10000000000.0),
    ModelField::new("k_h", "N m/rad", 0.0, 10000000000.0),
    ModelField::new("c_h", "N m s/rad", 0.0, 10000000.0),
    ModelField::new("front_empty_kg", "kg", 100.0, 500000.0),
    ModelField::new("payload_kg", "kg", 0.0, 1000000.0),
    ModelField::new("payload_front_share", "-", 0.0, 1.0),
    ModelField::new("mu", "-", 0.05, 1.5),
    ModelField::new("c_s", "-", 0.5, 3.0),
];

/// Why a truck parameter set is rejected.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum TruckFieldError {
    /// A field unknown or out of its range.
    #[error(transparent)]
    Field(#[from] FieldError),
    /// The struts cannot carry the load at this charge.
    #[error("the struts cannot carry the load: {0}")]
    Strut(HpsError),
}

impl FieldTable for TruckParams {
    const FIELDS: &'static [ModelField] = &TRUCK_FIELDS;

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
            "i_phi" => &mut self.i_phi,
            "m_axle" => &mut self.m_axle,
            "k_y" => &mut self.k_y,
            "c_y" => &mut self.c_y,
            "track" => &mut self.track,
            "k_tz" => &mut self.k_tz,
            "strut_spacing" => &mut self.strut_spacing,
            "c_strut" => &mut self.c_strut,
            "hps_v0_m3" => &mut self.hps.v0_m3,
            "hps_p0_pa" => &mut self.hps.p0_pa,
            "hps_area_m2" => &mut self.hps.area_m2,
            "hps_n" => &mut self.hps.n,
            "j_c" => &mut self.j_c,
            "k_d" => &mut self.k_d,
            "k_h" => &mut self.k_h,
            "c_h" => &mut self.c_h,
            "front_empty_kg" => &mut self.front_empty_kg,
            "payload_kg" => &mut self.payload_kg,
            "payload_front_share" => &mut self.payload_front_share,
            "mu" => &mut self.mu,
            "c_s" => &mut self.c_s,
            _ => return None,
        })
    }
}

impl TruckParams {
    /// Every field inside its range, and struts that carry the load (neither topped nor
    /// bottomed out); the first offender.
    pub fn validate(&self) -> Result<(), TruckFieldError> {
        self.check_ranges()?;
        self.operating_point()
            .map(|_| ())
            .map_err(TruckFieldError::Strut)
    }
}
