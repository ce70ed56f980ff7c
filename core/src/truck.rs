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

use nalgebra::SVector;

use crate::estimator::monitor::MonitorParams;
use crate::estimator::pipeline::PipelineParams;
use crate::model::{
    ComplexVector, LinearModel, Matrix, ModeShape, ModeShapeInfo, UpdatableModel, UpdateParam,
};
use crate::plant::{wheel_phase_rad, wheel_yaw_shape};

/// Standard gravity, m/s^2.
pub const G_MPS2: f64 = 9.80665;

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

/// The named truck parameter sets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TruckSet {
    /// No payload.
    Empty,
    /// Rated payload.
    Full,
}

impl TruckSet {
    /// Every named set.
    pub const ALL: [TruckSet; 2] = [TruckSet::Empty, TruckSet::Full];

    /// The set's name (vehicle files, command lines).
    pub const fn name(self) -> &'static str {
        match self {
            TruckSet::Empty => "truck-empty",
            TruckSet::Full => "truck-full",
        }
    }

    /// Looks a set up by name.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.name() == name)
    }

    /// The set's parameters.
    pub fn params(self) -> TruckParams {
        let t = TruckParams::reference();
        match self {
            TruckSet::Empty => t.with_payload(0.0),
            TruckSet::Full => t.with_payload(TruckParams::RATED_PAYLOAD_KG),
        }
    }
}

impl TruckParams {
    /// Rated payload of the truck class, kg (`docs/mining-truck.md`).
    pub const RATED_PAYLOAD_KG: f64 = 227_000.0;
    /// Empty operating mass, kg.
    pub const EMPTY_MASS_KG: f64 = 160_000.0;
    /// Front-axle share of the empty mass.
    pub const FRONT_SHARE_EMPTY: f64 = 0.47;
    /// Front-axle share of the loaded (gross) mass.
    pub const FRONT_SHARE_LOADED: f64 = 0.33;

    /// The reference truck (rated payload), every value explained in `docs/mining-truck.md`.
    pub fn reference() -> Self {
        let gross = Self::EMPTY_MASS_KG + Self::RATED_PAYLOAD_KG;
        let front_empty = Self::FRONT_SHARE_EMPTY * Self::EMPTY_MASS_KG;
        let front_loaded = Self::FRONT_SHARE_LOADED * gross;
        // tyre 40.00R57 (~4.0 t) and rim/hub (~2.5 t): a ring of mass m_t at radius r_g
        let (m_tyre, r_gyr_tyre) = (4_000.0, 1.45);
        let (m_rim, r_gyr_rim) = (2_500.0, 0.75);
        let i_p = m_tyre * r_gyr_tyre * r_gyr_tyre + m_rim * r_gyr_rim * r_gyr_rim;
        let m_wheel = m_tyre + m_rim;
        // yaw about a diameter: half the ring's polar inertia plus the width term, then the
        // kingpin offset (scrub) by the parallel-axis theorem
        let (width, scrub) = (1.1, 0.5);
        let i_k = 0.5 * i_p + m_wheel * width * width / 12.0 + m_wheel * scrub * scrub;
        let track = 5.3;
        let m_beam = 8_000.0;
        let beam_len = 4.0;
        let i_phi = 2.0 * m_wheel * (0.5 * track) * (0.5 * track)
            + 2.0 * 0.5 * i_p
            + m_beam * beam_len * beam_len / 12.0;
        let r = 1.72;
        let caster_rad = 4.0_f64.to_radians();
        Self {
            i_k,
            i_p,
            r,
            h_r: r,
            sigma: 0.9,
            e: r * libm::tan(caster_rad),
            t_p: 0.16,
            c_a_per_fz: 5.0,
            l_t: 0.8,
            // tie rod: 4e8 N/m axial on the 0.8 m arm
            k_tr: 4.0e8 * 0.8 * 0.8,
            c_k: 2.0e3,
            i_phi,
            m_axle: 2.0 * m_wheel + m_beam,
            k_y: 3.0e7,
            c_y: 5.0e4,
            track,
            k_tz: 2.5e6,
            strut_spacing: 4.4,
            c_strut: 1.5e5,
            hps: Hps {
                v0_m3: 0.010,
                p0_pa: 2.0e6,
                area_m2: 0.0855,
                n: 1.4,
            },
            j_c: 600.0,
            k_d: 5.0e7,
            // two 180 mm cylinders, 12 l of oil and hose each, hose-dominated bulk modulus
            k_h: oil_column_stiffness(1.5e8, 0.0254, 0.012, 0.6),
            c_h: 2.0e4,
            front_empty_kg: front_empty,
            payload_kg: Self::RATED_PAYLOAD_KG,
            payload_front_share: (front_loaded - front_empty) / Self::RATED_PAYLOAD_KG,
            mu: 0.6,
            c_s: 1.3,
        }
    }

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
    /// [`LinearModel`] is infallible, so callers validate with [`Self::operating_point`] first
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

/// One field of the truck's parameters in a vehicle file: name, unit, plausible range (both
/// ends included: wide enough for any heavy truck's front axle, narrow enough to reject a typo
/// by orders of magnitude).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TruckField {
    /// Field name (`[truck]` section of a vehicle file; the strut's with an `hps_` prefix).
    pub name: &'static str,
    /// SI unit.
    pub unit: &'static str,
    /// Plausible range (lo, hi).
    pub range: (f64, f64),
}

/// Every field of [`TruckParams`], in the order of `docs/mining-truck.md`'s model.
pub const TRUCK_FIELDS: [TruckField; 32] = [
    TruckField {
        name: "i_k",
        unit: "kg m^2",
        range: (100.0, 100000.0),
    },
    TruckField {
        name: "i_p",
        unit: "kg m^2",
        range: (0.0, 100000.0),
    },
    TruckField {
        name: "r",
        unit: "m",
        range: (0.3, 2.5),
    },
    TruckField {
        name: "h_r",
        unit: "m",
        range: (0.0, 3.0),
    },
    TruckField {
        name: "sigma",
        unit: "m",
        range: (0.05, 5.0),
    },
    TruckField {
        name: "e",
        unit: "m",
        range: (0.0, 0.5),
    },
    TruckField {
        name: "t_p",
        unit: "m",
        range: (0.0, 0.5),
    },
    TruckField {
        name: "c_a_per_fz",
        unit: "1/rad",
        range: (0.5, 30.0),
    },
    TruckField {
        name: "l_t",
        unit: "m",
        range: (0.05, 2.0),
    },
    TruckField {
        name: "k_tr",
        unit: "N m/rad",
        range: (10000.0, 10000000000.0),
    },
    TruckField {
        name: "c_k",
        unit: "N m s/rad",
        range: (0.0, 1000000.0),
    },
    TruckField {
        name: "i_phi",
        unit: "kg m^2",
        range: (100.0, 10000000.0),
    },
    TruckField {
        name: "m_axle",
        unit: "kg",
        range: (100.0, 100000.0),
    },
    TruckField {
        name: "k_y",
        unit: "N/m",
        range: (10000.0, 10000000000.0),
    },
    TruckField {
        name: "c_y",
        unit: "N s/m",
        range: (0.0, 100000000.0),
    },
    TruckField {
        name: "track",
        unit: "m",
        range: (0.5, 8.0),
    },
    TruckField {
        name: "k_tz",
        unit: "N/m",
        range: (10000.0, 1000000000.0),
    },
    TruckField {
        name: "strut_spacing",
        unit: "m",
        range: (0.2, 8.0),
    },
    TruckField {
        name: "c_strut",
        unit: "N s/m",
        range: (0.0, 100000000.0),
    },
    TruckField {
        name: "hps_v0_m3",
        unit: "m^3",
        range: (0.0001, 0.2),
    },
    TruckField {
        name: "hps_p0_pa",
        unit: "Pa",
        range: (10000.0, 50000000.0),
    },
    TruckField {
        name: "hps_area_m2",
        unit: "m^2",
        range: (0.0001, 1.0),
    },
    TruckField {
        name: "hps_n",
        unit: "-",
        range: (1.0, 1.67),
    },
    TruckField {
        name: "j_c",
        unit: "kg m^2",
        range: (0.01, 100000.0),
    },
    TruckField {
        name: "k_d",
        unit: "N m/rad",
        range: (1000.0, 10000000000.0),
    },
    TruckField {
        name: "k_h",
        unit: "N m/rad",
        range: (0.0, 10000000000.0),
    },
    TruckField {
        name: "c_h",
        unit: "N m s/rad",
        range: (0.0, 10000000.0),
    },
    TruckField {
        name: "front_empty_kg",
        unit: "kg",
        range: (100.0, 500000.0),
    },
    TruckField {
        name: "payload_kg",
        unit: "kg",
        range: (0.0, 1000000.0),
    },
    TruckField {
        name: "payload_front_share",
        unit: "-",
        range: (0.0, 1.0),
    },
    TruckField {
        name: "mu",
        unit: "-",
        range: (0.05, 1.5),
    },
    TruckField {
        name: "c_s",
        unit: "-",
        range: (0.5, 3.0),
    },
];

/// Why a truck parameter set is rejected.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum TruckFieldError {
    /// No field of that name.
    #[error("no truck field of that name")]
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
    /// The struts cannot carry the load at this charge.
    #[error("the struts cannot carry the load: {0}")]
    Strut(HpsError),
}

impl TruckParams {
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

    /// The value of the field `name`.
    pub fn get(&self, name: &str) -> Option<f64> {
        let mut copy = *self;
        copy.field_mut(name).map(|v| *v)
    }

    /// Sets the field `name` to `value` if it is inside the field's range.
    pub fn set(&mut self, name: &str, value: f64) -> Result<(), TruckFieldError> {
        let field = TRUCK_FIELDS
            .iter()
            .find(|f| f.name == name)
            .ok_or(TruckFieldError::Unknown)?;
        check(field, value)?;
        *self.field_mut(name).ok_or(TruckFieldError::Unknown)? = value;
        Ok(())
    }

    /// Every field inside its range, and struts that carry the load (neither topped nor
    /// bottomed out); the first offender.
    pub fn validate(&self) -> Result<(), TruckFieldError> {
        for f in &TRUCK_FIELDS {
            check(f, self.get(f.name).ok_or(TruckFieldError::Unknown)?)?;
        }
        self.operating_point()
            .map(|_| ())
            .map_err(TruckFieldError::Strut)
    }
}

fn check(f: &TruckField, value: f64) -> Result<(), TruckFieldError> {
    let (lo, hi) = f.range;
    if (lo..=hi).contains(&value) {
        Ok(())
    } else {
        Err(TruckFieldError::OutOfRange {
            name: f.name,
            value,
            lo,
            hi,
            unit: f.unit,
        })
    }
}

impl TruckParams {
    /// The controller's nominal plant: the wheel assembly's yaw inertia I_k and kingpin
    /// damping c_k, and the steering arm l_t (the ASMC's model).
    pub fn nominal_plant(&self) -> crate::control::smc::NominalPlant {
        crate::control::smc::NominalPlant {
            i_k_kgm2: self.i_k as f32,
            c_k_nms_per_rad: self.c_k as f32,
            l_t_m: self.l_t as f32,
        }
    }

    /// The truck vehicle's warning thresholds by default (its `[thresholds]` section): the
    /// car's ([`PipelineParams::tuned_monitor`]) with the data path's MarginLow damping
    /// thresholds lowered for the truck's lightly damped mode (zeta 0.0098 at 70 % of the
    /// loaded truck's onset, where the car's `zeta_low_on` 0.005 flickers: 24-42 false
    /// warnings per hour on the data-only arm, 0 with these) and the speed-margin thresholds
    /// lowered (the truck's 70 % point is only 7 km/h from its onset), chosen by `shimmy-sim
    /// mismatch --vehicle truck-full` (`docs/mining-truck.md`, "Warning thresholds").
    pub fn warning_thresholds() -> MonitorParams {
        MonitorParams {
            zeta_low_on: -0.005,
            zeta_low_off: 0.005,
            dv_low_on_mps: 1.2,
            dv_low_off_mps: 1.4,
            dv_crit_on_mps: 0.6,
            dv_crit_off_mps: 0.9,
            ..PipelineParams::tuned_monitor()
        }
    }
}

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
/// shimmy mode moves with (`shimmy-sim identifiability --vehicle truck-full`). Priors of
/// +-15 % (one sigma); the band is where the diagnosis speaks up.
impl UpdatableModel<N_STATES> for TruckParams {
    const UPDATE_PARAMS: &'static [UpdateParam] = &[
        UpdateParam {
            field: "c_a_per_fz",
            what: "tyre cornering coefficient",
            prior_sigma_ln: 0.15,
            band: (0.75, 1.3),
        },
        UpdateParam {
            field: "sigma",
            what: "tyre relaxation length",
            prior_sigma_ln: 0.15,
            band: (0.75, 1.3),
        },
        UpdateParam {
            field: "c_h",
            what: "steering linkage damping",
            prior_sigma_ln: 0.15,
            band: (0.6, 1.5),
        },
        UpdateParam {
            field: "k_h",
            what: "steering linkage stiffness",
            prior_sigma_ln: 0.15,
            band: (0.7, 1.3),
        },
        UpdateParam {
            field: "t_p",
            what: "tyre pneumatic trail",
            prior_sigma_ln: 0.15,
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stability::{self, CrossingKind};

    /// The strut's stiffness is the derivative of its force: central differences of the gas
    /// law at small and large strokes (where the spring stiffens several-fold).
    #[test]
    fn hps_stiffness_is_the_derivative_of_the_gas_force() {
        let hps = TruckSet::Full.params().hps;
        let x_max = (1.0 - 2.0 * Hps::MIN_VOLUME_FRAC) * hps.v0_m3 / hps.area_m2;
        let h = 1e-6;
        for i in 0..=20 {
            let x = x_max * f64::from(i) / 20.0;
            let fd = (hps.force_n(x + h) - hps.force_n(x - h)) / (2.0 * h);
            let k = hps.stiffness_npm(x);
            assert!((fd - k).abs() < 1e-6 * k, "x {x}: fd {fd} analytic {k}");
        }
        // large-stroke nonlinearity: at 80 % of the gas volume compressed, over 9x the
        // initial stiffness (n = 1.4: (1/0.2)^2.4 = 47)
        assert!(hps.stiffness_npm(x_max) > 9.0 * hps.stiffness_npm(0.0));
    }

    /// The static point carries the load (F(x_s) = load) and its stiffness is F'(x_s); loads
    /// below the pre-charge or past the stop are errors naming the limit.
    #[test]
    fn hps_static_point_carries_the_load() {
        let t = TruckSet::Full.params();
        let load = t.strut_load_n();
        let sp = t.hps.static_point(load).unwrap();
        assert!((t.hps.force_n(sp.stroke_m) - load).abs() < 1e-9 * load);
        assert!(
            (t.hps.stiffness_npm(sp.stroke_m) - sp.stiffness_npm).abs() < 1e-9 * sp.stiffness_npm
        );
        assert!(matches!(
            t.hps.static_point(0.5 * t.hps.p0_pa * t.hps.area_m2),
            Err(HpsError::ToppedOut { .. })
        ));
        assert!(matches!(
            t.hps.static_point(1e4 * load),
            Err(HpsError::BottomedOut { .. })
        ));
        // more gas, softer strut; more load, stiffer
        let soft = t
            .with_gas_volume(2.0 * t.hps.v0_m3)
            .operating_point()
            .unwrap();
        let base = t.operating_point().unwrap();
        let empty = TruckSet::Empty.params().operating_point().unwrap();
        assert!(soft.strut.stiffness_npm < base.strut.stiffness_npm);
        assert!(empty.strut.stiffness_npm < base.strut.stiffness_npm);
    }

    /// Every field is in the table, reads back what was set, and a value out of range or a
    /// charge the struts cannot carry is rejected naming the field.
    #[test]
    fn the_field_table_covers_every_field_and_checks_ranges() {
        let mut t = TruckSet::Full.params();
        t.validate().unwrap();
        for f in &TRUCK_FIELDS {
            let v = t.get(f.name).unwrap();
            let mid = 0.5 * (f.range.0 + f.range.1);
            let mut u = t;
            u.set(f.name, mid).unwrap();
            assert_eq!(u.get(f.name), Some(mid), "{}", f.name);
            assert!(u != t || v == mid, "{} sets nothing", f.name);
        }
        let e = t.set("hps_v0_m3", 5.0).unwrap_err();
        assert!(
            matches!(
                e,
                TruckFieldError::OutOfRange {
                    name: "hps_v0_m3",
                    ..
                }
            ),
            "{e}"
        );
        assert_eq!(t.set("no_such", 1.0), Err(TruckFieldError::Unknown));
        t.set("hps_p0_pa", 2.0e7).unwrap();
        assert!(matches!(
            t.validate(),
            Err(TruckFieldError::Strut(HpsError::ToppedOut { .. }))
        ));
    }

    #[test]
    fn a_is_affine_in_speed_with_the_stated_derivative() {
        let t = TruckSet::Full.params();
        let a0 = t.linearise(3.0, 2.0e4);
        let a1 = t.linearise(11.0, 2.0e4);
        let err = (a1 - a0 - t.dlinearise_dv() * 8.0).amax();
        assert!(err < 1e-9 * a0.amax(), "{err}");
    }

    /// Stiffness symmetric, gyroscopic part skew, tyre rows as the slip kinematics: checked on
    /// the second-order form recovered from A.
    #[test]
    fn structure_matches_the_equations() {
        let t = TruckSet::Full.params();
        let a = t.linearise(8.0, 0.0);
        let m = [t.i_k, t.i_k, t.i_phi, t.j_c, t.m_axle];
        for i in 0..N_DOF {
            for j in 0..N_DOF {
                let kij = -a[(N_DOF + i, j)] * m[i];
                let kji = -a[(N_DOF + j, i)] * m[j];
                assert!((kij - kji).abs() <= 1e-9 * kij.abs().max(1.0), "K {i}{j}");
            }
        }
        let h = t.spin_momentum(8.0);
        assert!((-a[(DPSI_L, DPHI)] * t.i_k - h).abs() < 1e-9 * h);
        assert!((-a[(DPHI, DPSI_L)] * t.i_phi + h).abs() < 1e-9 * h);
        assert_eq!(a[(A_L, DY)], -1.0 / t.sigma);
    }

    /// Full load has a shimmy onset in the haul-road speed range, of the in-phase wheel-yaw
    /// mode; the empty truck's is higher or absent; more gas moves the full truck's onset up.
    #[test]
    fn full_load_has_an_onset_that_more_gas_raises() {
        let onset = |t: &TruckParams| {
            stability::hopf_crossings(t, 0.0, 0.5, 25.0, 0.25, 1e-6)
                .unwrap()
                .iter()
                .find(|c| c.kind == CrossingKind::Onset)
                .map(|c| (c.speed_mps, c.shape))
        };
        let full = TruckSet::Full.params();
        let (v_full, shape) = onset(&full).expect("full load has an onset");
        assert_eq!(shape, ModeShape::InPhaseWheelYaw);
        assert!(v_full > 2.0 && v_full < 16.7, "{v_full}");
        let (v_more_gas, _) = onset(&full.with_gas_volume(3.0 * full.hps.v0_m3)).unwrap();
        assert!(v_more_gas > v_full + 0.5, "{v_more_gas} vs {v_full}");
        if let Some((v_empty, _)) = onset(&TruckSet::Empty.params()) {
            assert!(v_empty > v_full, "{v_empty} vs {v_full}");
        }
    }
}

#[cfg(test)]
mod tracker_tests {
    use super::*;
    use crate::eigen::{self, SolveFloat};
    use crate::estimator::model_margin::{ModelMarginConfig, ModelMarginTracker};
    use crate::model::LinearModel;
    use crate::stability::{self, CrossingKind};

    /// The model-margin tracker runs on the truck (12 states) in both precisions: its onset
    /// above the current speed is the scan's Hopf crossing.
    #[test]
    fn the_tracker_finds_the_trucks_onset() {
        fn check<T: SolveFloat>() {
            let t = TruckSet::Full.params();
            let scan = stability::hopf_crossings(&t, 0.0, 0.5, 25.0, 0.25, 1e-7).unwrap();
            let onset = scan.iter().find(|c| c.kind == CrossingKind::Onset).unwrap();
            let mut tr = ModelMarginTracker::<T, TruckParams, N_STATES>::in_precision(
                t,
                ModelMarginConfig::default(),
            );
            let p = (0..200u16)
                .find_map(|k| tr.step(f64::from(k) * 1e-3, 2.0, 0.0))
                .expect("a cycle completes");
            let above = p.above.expect("an onset above 2 m/s");
            assert_eq!(above.kind, CrossingKind::Onset);
            // The crossing is as exact as the solver's Re s near it allows: the tolerance plus
            // the speed that the worst error of T's Re s (against f64, sampled within 1 mm/s of
            // the onset) amounts to at the f64 slope. In f32 that is ~1e-4 1/s at 0.08 1/s per
            // m/s, ~1e-3 m/s; in f64 nothing.
            let re = |v: f64| {
                let vals = eigen::eigenvalues_of::<T, N_STATES>(&t.linearise(v, 0.0)).unwrap();
                eigen::critical_oscillatory_mode(&vals).unwrap().re
            };
            let re64 = |v: f64| {
                let vals = eigen::eigenvalues_of::<f64, N_STATES>(&t.linearise(v, 0.0)).unwrap();
                eigen::critical_oscillatory_mode(&vals).unwrap().re
            };
            let slope = (re64(onset.speed_mps + 1e-3) - re64(onset.speed_mps - 1e-3)) / 2e-3;
            let noise = (-10..=10)
                .map(|k| onset.speed_mps + f64::from(k) * 1e-4)
                .map(|v| (re(v) - re64(v)).abs())
                .fold(0.0, f64::max);
            let tol = 2e-4 + 2.0 * noise / slope.abs();
            assert!(
                (above.speed_mps - onset.speed_mps).abs() < tol,
                "{}: {} vs {} (tolerance {tol:e} m/s)",
                T::NAME,
                above.speed_mps,
                onset.speed_mps
            );
            assert!(p.shimmy_found && p.slope_valid, "{}", T::NAME);
            assert_eq!(p.margin().v_crit_onset_mps, Some(above.speed_mps));
        }
        check::<f64>();
        check::<f32>();
    }
}
