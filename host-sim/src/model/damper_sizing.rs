//! The reference the other models' dampers and road disturbances are sized against: the
//! reference vehicle (the core's [`Vehicle::nominal`], the car's `nominal` set with the
//! reference damper). A model's default damper is the reference damper scaled so that it closes
//! that model's Hopf window with the same margin as the reference closes its own
//! ([`damper_scale_like_the_cars`]); the scenario files' road torques are scaled by the tyre
//! yaw stiffness ([`reference_tyre_yaw_stiffness`]).

use anyhow::{bail, Result};
use shimmy_core::model::LinearModel;
use shimmy_core::stability::{hopf_crossings, CrossingKind};
use shimmy_core::units::kmh_to_mps;
use shimmy_core::vehicle::Vehicle;

use super::damper_equiv::damper_equivalent;
use super::family::SimModel;

/// The tyre yaw stiffness `(e + t_p) C_a` the scenario files' disturbances are written for (the
/// car's `nominal` set), N m/rad.
pub fn reference_tyre_yaw_stiffness() -> f64 {
    let p = Vehicle::nominal().plant;
    (p.e + p.t_p) * p.c_a
}

/// The least viscous track-rod damper coefficient that leaves `m` without a Hopf onset from 1
/// to 150 km/h, N s/m (0 when it has none without a damper; bisection to 0.1 %); `None` when
/// no coefficient up to 1e9 N s/m does.
pub fn least_stabilising_c<M: LinearModel<N>, const N: usize>(m: &M) -> Option<f64> {
    least_stabilising_c_in(m, (1.0, 150.0))
}

/// [`least_stabilising_c`] over the speeds `kmh` (lowest, highest), km/h.
pub fn least_stabilising_c_in<M: LinearModel<N>, const N: usize>(
    m: &M,
    kmh: (f64, f64),
) -> Option<f64> {
    let unstable = |c: f64| {
        hopf_crossings(
            m,
            c,
            kmh_to_mps(kmh.0),
            kmh_to_mps(kmh.1),
            kmh_to_mps(0.5),
            1e-3,
        )
        .map_or(true, |cs| cs.iter().any(|x| x.kind == CrossingKind::Onset))
    };
    if !unstable(0.0) {
        return Some(0.0);
    }
    let mut hi = 1.0;
    while unstable(hi) {
        hi *= 2.0;
        if hi > 1e9 {
            return None;
        }
    }
    let mut lo = 0.5 * hi;
    while hi - lo > 1e-3 * hi {
        let mid = 0.5 * (lo + hi);
        if unstable(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(hi)
}

/// The factor on the car's reference damper that sizes it for `model` as the car's is sized
/// for the `nominal` car: its energy-equivalent viscous coefficient at the rated current
/// (describing function at the default 0.5 deg, [`damper_equivalent`]) the same multiple of
/// the least coefficient that closes `model`'s Hopf window ([`least_stabilising_c`]), each over
/// its model's sizing speeds ([`SimModel::SIZING_SPEEDS_KMH`]).
pub fn damper_scale_like_the_cars<M: SimModel<N>, const N: usize>(model: &M) -> Result<f64> {
    let car = Vehicle::nominal();
    let sp = car.damper.spencer;
    let rated = sp.u_max;
    let (v0, v1) = (kmh_to_mps(1.0), kmh_to_mps(150.0));
    let amp_deg = super::damper_equiv::REF_WHEEL_YAW_AMPL_RAD.to_degrees();
    let ceq_car = damper_equivalent(&car.plant, &sp, rated, amp_deg, v0, v1)?.c_eq_nspm;
    let kmh = M::SIZING_SPEEDS_KMH;
    let (m0, m1) = (kmh_to_mps(kmh.0), kmh_to_mps(kmh.1));
    let ceq_m = damper_equivalent(model, &sp, rated, amp_deg, m0, m1)?.c_eq_nspm;
    let (Some(c_car), Some(c_m)) = (
        least_stabilising_c(&car.plant),
        least_stabilising_c_in(&model.linear(), kmh),
    ) else {
        bail!("damper sizing: no viscous damper closes a Hopf window");
    };
    if c_car <= 0.0 || ceq_m <= 0.0 {
        bail!("damper sizing: the car has no Hopf window to size against");
    }
    Ok((ceq_car / c_car) * c_m / ceq_m)
}

/// The car's reference shared sections with every force coefficient of the damper (the
/// Spencer model's and the firmware's Bingham model's) and the skyhook coefficient times `s`.
pub fn car_parts_with_damper_scaled(s: f64) -> Vehicle {
    Vehicle::nominal().with_damper_scaled(s)
}
