//! Sliding-mode laws for the MR steering damper: ordinary SMC with a boundary layer and the
//! adaptive SMC (ASMC) with sigma-modification, dead zone, bounds and anti-windup.
//!
//! # Nominal model (what the controller knows)
//!
//! Adding the two wheel equations of the reference plant, the in-phase wheel yaw
//! psi = (psi_L + psi_R)/2 obeys
//!
//! ```text
//! I_k psi'' = -c_k psi' - (l_t/2) F_d + tau_u,
//! ```
//!
//! where the track-rod terms cancel (they act on psi_L - psi_R) and everything the firmware does
//! not know well or cannot measure is lumped into tau_u: tyre aligning and lateral-force moments
//! -(e + t_p)(F_L + F_R)/2 (speed, load and road dependent), the drag-link torque
//! K_d (theta_sw/i_s - psi_L)/2 (the most uncertain parameter), and the gyroscopic torque
//! -H phi'. So the controller uses only I_k, c_k and l_t from [`crate::vehicles::car::PlantParams`]
//! (their nominal values, [`NominalPlant`]): the geometry l_t is known exactly, I_k within a few
//! per cent, c_k is small; tau_u is the matched disturbance that the switching gain must cover.
//! The damper stroke rate is v_d = l_t psi'.
//!
//! # SMC
//!
//! Sliding variable on the shimmy-band signals (see [`super::conditioning`]):
//! s = psi_hp' + lambda psi_hp. On s = 0 the shimmy-band yaw decays as exp(-lambda t).
//! s' = psi'' + lambda psi' = (-c_k psi' - (l_t/2) F_d + tau_u)/I_k + lambda psi'.
//! Requiring s' = -K sat(s/phi) for tau_u = 0 gives the desired damper force
//!
//! ```text
//! F_des = (2 I_k / l_t) [ (lambda - c_k/I_k) psi_hp' + K sat(s/phi) ],
//! ```
//!
//! an equivalent-control part (a viscous force on the shimmy-band rate) plus the switching part;
//! sat is the boundary layer of width phi that removes chattering. Outside the layer
//! s s' <= -(K - |tau_u|/I_k)|s| when the damper delivers F_des, so K > sup|tau_u|/I_k + eta
//! makes the layer attractive in finite time.
//!
//! # ASMC
//!
//! The bound on tau_u is not known and a large fixed K spends current when nothing happens, so
//! K adapts:
//!
//! ```text
//! K' = gamma (|s| - s_dz)_+ [growth, frozen while the actuator is saturated or semi-actively
//!      clipped, or below the speed gate] - sigma (K - K_min) [leakage],
//! K projected onto [K_min, K_max].
//! ```
//!
//! The dead zone s_dz sits above the noise floor of s (+-1 LSB noise on each 14-bit encoder
//! through the observer gives 0.026 rad/s rms, measured in the tests), so sensor noise alone
//! never pumps K up. The same dead zone is a **quiet zone** for the force: the ASMC force is
//! multiplied by [`quiet_weight`] (0 for |s| <= s_dz, 1 from 2 s_dz on), so that the viscous
//! equivalent-control part does not hold ~0.2 A on the coil to damp sensor noise; the leakage
//! (sigma-modification) pulls K back to K_min when shimmy has stopped, which is what keeps the
//! current low when the road is quiet; the growth term raises K within tens of milliseconds once
//! |s| grows.
//!
//! (Inside the quiet zone |s| < 2 s_dz the force is reduced, which is covered by the
//! ultimate bound below: the argument only makes claims outside |s| <= 2 s_dz.)
//!
//! **Stability argument.** Let K* be an (unknown) gain with |tau_u|/I_k <= K* - eta, eta > 0, and
//! V = s^2/2 + (K - K*)^2/(2 gamma). Outside the boundary layer and the dead zone, while the
//! damper delivers F_des (not clipped, not saturated):
//!
//! ```text
//! V' = s (tau_u/I_k - K sgn s) + (K - K*)(|s| - s_dz - (sigma/gamma)(K - K_min))
//!    <= -eta |s| - (K - K*) s_dz - (sigma/gamma)(K - K*)(K - K_min)
//!    <= -eta |s| - (sigma/(2 gamma)) (K - K*)^2 + (sigma/(2 gamma)) (K* - K_min)^2 + K* s_dz,
//! ```
//!
//! using -(K - K*)(K - K_min) <= -(K - K*)^2/2 + (K* - K_min)^2/2 and K >= 0. V' < 0 outside
//! the compact set
//!
//! ```text
//! { eta |s| + (sigma/(2 gamma))(K - K*)^2 <= (sigma/(2 gamma))(K* - K_min)^2 + K* s_dz },
//! ```
//!
//! so (s, K) are **uniformly ultimately bounded**: s ends up in a band whose width
//! grows with sigma (leakage) and s_dz (dead zone); without leakage (sigma = 0) this would be
//! s -> layer, but then K could only grow (drift under noise and disturbances: the reason for
//! sigma). The projection onto [K_min, K_max] only removes terms of the right sign (standard
//! projection argument), and it bounds K independently of the argument.
//!
//! **With the semi-active constraint** the damper cannot deliver F_des when F_des v_d <= 0 (it
//! then gives its passive 0 A force, which still resists motion) or when F_des exceeds the
//! force at I_max. During those intervals the s-part of V' has an extra bounded term
//! s (l_t/(2 I_k))(F_des - F_real) and the argument above does not hold; what does hold is
//! (i) K stays bounded (growth frozen, leakage and projection only: no wind-up, K does not
//! climb to K_max because of force the damper cannot make), and (ii) the damper never injects
//! energy: F_real v_d >= 0 always, so the controlled damper removes at least as much energy from
//! the in-phase mode as the passive damper at the minimum current. The guarantee is therefore UUB
//! whenever the damper authority suffices (|tau_u| within what the clipped, saturated force can
//! counter over a cycle), and "never worse than passive at 0 A" otherwise. The closed-loop tests
//! check both on a stand-in plant; the 4-DOF comparison is in the simulator.

// NaN must take the "no" branch of these comparisons, hence `!(x > 0.0)` style.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

/// Nominal plant data the controllers use (f32 copies of the nominal parameter set).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NominalPlant {
    /// Wheel-assembly yaw inertia about the kingpin I_k, kg m^2.
    pub i_k_kgm2: f32,
    /// Kingpin damping c_k, N m s/rad.
    pub c_k_nms_per_rad: f32,
    /// Steering-arm length l_t, m.
    pub l_t_m: f32,
}

impl NominalPlant {
    /// Takes I_k, c_k and l_t from a plant parameter set.
    pub const fn from_params(p: &crate::vehicles::car::PlantParams) -> Self {
        NominalPlant {
            i_k_kgm2: p.i_k as f32,
            c_k_nms_per_rad: p.c_k as f32,
            l_t_m: p.l_t as f32,
        }
    }

    /// Force at the damper per unit of sliding acceleration: 2 I_k / l_t [N/(rad/s^2)].
    #[inline]
    pub fn force_per_accel(&self) -> f32 {
        2.0 * self.i_k_kgm2 / self.l_t_m
    }
}

impl NominalPlant {
    /// The nominal parameter set's I_k, c_k and l_t.
    pub const DEFAULT: Self =
        NominalPlant::from_params(&crate::vehicles::car::PlantParams::nominal());
}

impl Default for NominalPlant {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Gains of the sliding surface and the fixed-gain SMC.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SmcParams {
    /// Sliding-surface slope lambda, 1/s.
    pub lambda_per_s: f32,
    /// Boundary-layer half width phi, rad/s.
    pub phi_radps: f32,
    /// Fixed switching gain K of the ordinary SMC, rad/s^2.
    pub k_radps2: f32,
}

impl SmcParams {
    /// lambda = 6 1/s keeps the equivalent-control viscous part, (2/l_t^2)(lambda I_k - c_k)
    /// = 1.0e3 N s/m on the stroke, inside what the damper gives at 2 A, so the law is not
    /// saturated by its linear part alone; phi = 0.1 rad/s is a quarter of the rate of a
    /// 0.01 rad, 6 Hz shimmy; K = 8 rad/s^2 is a switching force of 2 I_k K / l_t = 370 N.
    pub const DEFAULT: Self = SmcParams {
        lambda_per_s: 6.0,
        phi_radps: 0.1,
        k_radps2: 8.0,
    };
}

impl Default for SmcParams {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Gains of the adaptation law.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AsmcParams {
    /// Adaptation rate gamma [rad/s^2 per (rad/s) per s].
    pub gamma: f32,
    /// Leakage sigma, 1/s.
    pub sigma_per_s: f32,
    /// Dead zone on |s|, rad/s (above the noise floor of s).
    pub dead_zone_radps: f32,
    /// Lower bound (and leakage target) of K, rad/s^2.
    pub k_min_radps2: f32,
    /// Upper bound of K, rad/s^2.
    pub k_max_radps2: f32,
    /// K at start-up and after reset, rad/s^2.
    pub k_init_radps2: f32,
    /// Freeze the growth term while the actuator is saturated or clipped (anti-windup). Off
    /// only to show that it is needed.
    pub anti_windup: bool,
}

impl AsmcParams {
    /// gamma = 300: |s| = 0.4 rad/s (a 0.01 rad, 6 Hz shimmy) raises K by 8 rad/s^2 in 0.07 s;
    /// sigma = 0.5 1/s: K returns to K_min within a few seconds of quiet; dead zone 0.04 rad/s
    /// (1.5x the rms noise of s with +-1 LSB encoder noise); K_max = 30 rad/s^2 (1.4 kN, beyond
    /// the damper's force at 2 A, so the bound is never what limits the force).
    /// gamma and the dead zone were tuned in the 4-DOF closed loop (`shimmy-sim compare`, the
    /// 14-bit encoder model with 0.5 LSB rms noise): with the former 100 / 0.06 the quiet zone
    /// left the last 10 % of a decay to the 0 A damper and ASMC settled 0.15-0.6 s later than
    /// fixed-gain SMC; with 300 / 0.04 it settles within 5 % of SMC at ~10 % of its coil energy,
    /// and still spends 0.2 J in a 10 s slalom with road noise (K_min > 0 would triple chattering).
    pub const DEFAULT: Self = AsmcParams {
        gamma: 300.0,
        sigma_per_s: 0.5,
        dead_zone_radps: 0.04,
        k_min_radps2: 0.0,
        k_max_radps2: 30.0,
        k_init_radps2: 0.0,
        anti_windup: true,
    };
}

impl Default for AsmcParams {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// sat(x) = x clipped to [-1, 1] (NaN -> 0).
#[inline]
pub fn sat(x: f32) -> f32 {
    if x > 1.0 {
        1.0
    } else if x < -1.0 {
        -1.0
    } else if !x.is_nan() {
        x
    } else {
        0.0
    }
}

/// Sliding variable s = rate + lambda psi, rad/s.
#[inline]
pub fn sliding_surface(psi_hp_rad: f32, rate_hp_radps: f32, lambda_per_s: f32) -> f32 {
    rate_hp_radps + lambda_per_s * psi_hp_rad
}

/// Desired damper force of the SMC law, N (positive resists a positive stroke rate).
#[inline]
pub fn smc_force_n(
    nom: &NominalPlant,
    smc: &SmcParams,
    s_radps: f32,
    rate_hp_radps: f32,
    k_radps2: f32,
) -> f32 {
    let lam_eff = smc.lambda_per_s - nom.c_k_nms_per_rad / nom.i_k_kgm2;
    nom.force_per_accel() * (lam_eff * rate_hp_radps + k_radps2 * sat(s_radps / smc.phi_radps))
}

/// Quiet-zone weight of the ASMC force: 0 for |s| <= s_dz, rising linearly to 1 at 2 s_dz.
/// Inside the noise floor the law's viscous part would otherwise keep ~0.2 A on the coil just to
/// damp sensor noise. A zero or NaN dead zone gives 1 (no quiet zone).
#[inline]
pub fn quiet_weight(s_radps: f32, dead_zone_radps: f32) -> f32 {
    if !(dead_zone_radps > 0.0) {
        return 1.0;
    }
    let w = (libm::fabsf(s_radps) - dead_zone_radps) / dead_zone_radps;
    if w >= 1.0 {
        1.0
    } else if w > 0.0 {
        w
    } else {
        0.0
    }
}

/// The adaptive gain with its update law.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdaptiveGain {
    k: f32,
}

impl AdaptiveGain {
    /// Starts at `p.k_init_radps2` (projected onto the bounds).
    pub fn new(p: &AsmcParams) -> Self {
        AdaptiveGain {
            // max/min instead of clamp: no panic on NaN bounds (panic-free check).
            k: p.k_init_radps2
                .max(p.k_min_radps2)
                .min(p.k_max_radps2.max(p.k_min_radps2)),
        }
    }

    /// Current gain, rad/s^2.
    #[inline]
    pub fn get(&self) -> f32 {
        self.k
    }

    /// One explicit-Euler step of the law over `dt_s`. `freeze` stops the growth term
    /// (anti-windup). Returns whether the growth term was active.
    #[inline]
    pub fn update(&mut self, p: &AsmcParams, s_radps: f32, dt_s: f32, freeze: bool) -> bool {
        let excess = libm::fabsf(s_radps) - p.dead_zone_radps;
        let grow = !freeze && excess > 0.0;
        let growth = if grow { p.gamma * excess } else { 0.0 };
        let k = self.k + dt_s * (growth - p.sigma_per_s * (self.k - p.k_min_radps2));
        let hi = if p.k_max_radps2 > p.k_min_radps2 {
            p.k_max_radps2
        } else {
            p.k_min_radps2
        };
        // Projection onto [K_min, K_max]; a NaN step leaves K unchanged.
        self.k = if k >= p.k_min_radps2 {
            if k > hi {
                hi
            } else {
                k
            }
        } else if k < p.k_min_radps2 {
            p.k_min_radps2
        } else {
            self.k
        };
        grow
    }

    /// Back to the initial gain.
    pub fn reset(&mut self, p: &AsmcParams) {
        *self = AdaptiveGain::new(p);
    }
}
