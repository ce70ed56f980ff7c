//! The named sets of the towed wheel.

#[allow(unused_imports)]
use super::*;

use super::params::TowedWheelParams;

/// The named towed-wheel parameter sets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TowedWheelSet {
    /// The benchmark's test rig (Takács, Orosz & Stépán 2009, Table 1) at twice the patch's
    /// half length as caster.
    Benchmark,
}

impl TowedWheelSet {
    /// Every named set.
    pub const ALL: [TowedWheelSet; 1] = [TowedWheelSet::Benchmark];

    /// The set's name (vehicle files, command lines).
    pub const fn name(self) -> &'static str {
        match self {
            TowedWheelSet::Benchmark => "towed-wheel",
        }
    }

    /// Looks a set up by name.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.name() == name)
    }

    /// The set's parameters.
    pub fn params(self) -> TowedWheelParams {
        match self {
            TowedWheelSet::Benchmark => TowedWheelParams::benchmark(),
        }
    }
}

/// The rig's measured natural frequency of the standing wheel, rad/s (Table 1).
pub const BENCHMARK_OMEGA_N_RADPS: f64 = 15.29;

impl TowedWheelParams {
    /// The benchmark rig: the tyre of Table 1 (`a`, `sigma`, `k`, `b`), the caster `l = 2a`
    /// (dimensionless `L = 2`, inside the chart's shimmy region) and the yaw inertia that gives
    /// the rig's measured natural frequency 15.29 rad/s at that caster; the damper lever is
    /// the caster's; the friction limit (100 N on the wheel, mu 0.8: the patch slides at
    /// 6.7 mm of deformation) is chosen, the paper's load not being available.
    pub fn benchmark() -> Self {
        let mut p = Self {
            a: 0.04,
            sigma: 0.072,
            k: 53_506.0,
            b: 140.0,
            l: 0.08,
            j_a: 1.0,
            l_d: 0.08,
            f_z: 100.0,
            mu: 0.8,
        };
        p.j_a = p.inertia_for_frequency(BENCHMARK_OMEGA_N_RADPS);
        p
    }
}
