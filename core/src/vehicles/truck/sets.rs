//! The named sets of the mining truck.

#[allow(unused_imports)]
use super::*;

use super::params::oil_column_stiffness;
use super::params::{Hps, TruckParams};

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
}
