//! The named sets of the dual-axle truck.

#[allow(unused_imports)]
use super::*;

use super::params::DualAxleParams;

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
}
