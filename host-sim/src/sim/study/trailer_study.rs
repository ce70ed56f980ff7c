//! The trailer's studies (`docs/trailer.md`): the sway damper a trailer needs at a speed, and
//! Diboll & Hagen's dimensionless map of the damping ratio needed over the Strouhal number
//! `s omega / V` with the energy term `mu G z / V^2` as parameter.
//!
//! Both come from the linear model's eigenvalues (`shimmy_core::stability`): the damper needed
//! is the least coefficient whose smallest damping ratio over the oscillatory modes reaches the
//! target, bracketed on a grid of coefficients and refined with Brent's method.

use anyhow::{Context, Result};
use shimmy_core::eigen::EigenError;
use shimmy_core::stability;
use shimmy_core::vehicles::trailer::TrailerParams;

/// Largest damping ratio of the sway damper searched ([`TrailerParams::damper_zeta`]).
pub const ZETA_DAMPER_MAX: f64 = 2.0;
/// Grid of the bracketing search over the damper coefficient (points from 0 to the maximum).
const C_GRID: usize = 80;
/// Relative tolerance of the damper coefficient.
const C_TOL_REL: f64 = 1e-7;

/// The smallest damping ratio over the oscillatory modes of `t` at `v_mps` with the sway
/// damper `c_nspm`.
pub fn least_zeta(t: &TrailerParams, v_mps: f64, c_nspm: f64) -> Result<f64, EigenError> {
    Ok(stability::mode_at(t, v_mps, c_nspm, stability::ModeSelect::LeastDamped)?.zeta)
}

/// The least sway-damper coefficient, N s/m, that brings every oscillatory mode of `t` at
/// `v_mps` to a damping ratio of at least `zeta_target` (0: the critical damper, the least
/// that keeps it stable); `Some(0.0)` when the trailer needs none, `None` when no damper up to
/// a damping ratio of [`ZETA_DAMPER_MAX`] does.
pub fn damper_needed(t: &TrailerParams, v_mps: f64, zeta_target: f64) -> Result<Option<f64>> {
    let f = |c: f64| least_zeta(t, v_mps, c).map(|z| z - zeta_target);
    let mut c_prev = 0.0;
    let mut f_prev = f(0.0).context("eigen-solve without damper")?;
    if f_prev >= 0.0 {
        return Ok(Some(0.0));
    }
    let c_max = t.damper_of_zeta(ZETA_DAMPER_MAX);
    for i in 1..=C_GRID {
        let c = c_max * i as f64 / C_GRID as f64;
        let fc = f(c).with_context(|| format!("eigen-solve at damper {c} N s/m"))?;
        if fc >= 0.0 {
            let root = stability::brent(f, c_prev, c, f_prev, fc, C_TOL_REL * c, 200)
                .context("refining the damper coefficient")?;
            // the bracket's stable end: the coefficient that meets the target
            return Ok(Some(root.hi));
        }
        c_prev = c;
        f_prev = fc;
    }
    Ok(None)
}

/// One point of Diboll & Hagen's map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DhPoint {
    /// The energy term mu G z / V^2 of the curve.
    pub energy_term: f64,
    /// Strouhal number s omega / V.
    pub strouhal: f64,
    /// Speed of the point, m/s (from the energy term).
    pub v_mps: f64,
    /// Hitch stiffness of the point, N/m (from the Strouhal number).
    pub k_y_npm: f64,
    /// The sway damper needed for stability, N s/m (None: none up to [`ZETA_DAMPER_MAX`]).
    pub c_needed_nspm: Option<f64>,
    /// Its damping ratio ([`TrailerParams::damper_zeta`] of the point's trailer).
    pub zeta_needed: Option<f64>,
}

/// The trailer `t` moved to the Strouhal number `strouhal` and the energy term `energy` by
/// speed and hitch stiffness alone (every other dimensionless ratio kept, the hitch's lateral
/// damping ratio `c_y / (2 sqrt(k_y m))` too), and that speed.
pub fn similar_point(t: &TrailerParams, strouhal: f64, energy: f64) -> (TrailerParams, f64) {
    let v = (t.c_a_per_fz * shimmy_core::units::G_MPS2 * t.a / energy).sqrt();
    let zeta_y = t.c_y / (2.0 * (t.k_y * t.m).sqrt());
    let mut p = *t;
    let omega = strouhal * v / t.l;
    p.k_y = t.m * omega * omega;
    p.c_y = zeta_y * 2.0 * (p.k_y * p.m).sqrt();
    (p, v)
}

/// Diboll & Hagen's map for `t`: for each energy term, the damping ratio needed for stability
/// at each Strouhal number.
pub fn dh_map(t: &TrailerParams, energy_terms: &[f64], strouhals: &[f64]) -> Result<Vec<DhPoint>> {
    let mut out = Vec::with_capacity(energy_terms.len() * strouhals.len());
    for &e in energy_terms {
        for &s in strouhals {
            let (p, v) = similar_point(t, s, e);
            let c = damper_needed(&p, v, 0.0)?;
            out.push(DhPoint {
                energy_term: e,
                strouhal: s,
                v_mps: v,
                k_y_npm: p.k_y,
                c_needed_nspm: c,
                zeta_needed: c.map(|c| p.damper_zeta(c)),
            });
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use shimmy_core::stability::CrossingKind;
    use shimmy_core::vehicles::trailer::TrailerSet;

    /// The critical damper at a speed is the damper whose Hopf onset is that speed, and 1 %
    /// less leaves the trailer unstable there; below the undamped onset none is needed.
    #[test]
    fn the_critical_damper_puts_the_onset_at_the_speed() {
        let t = TrailerSet::Caravan.params();
        let v0 = stability::hopf_crossings(&t, 0.0, 1.0, 70.0, 0.5, 1e-7).unwrap()[0].speed_mps;
        assert_eq!(damper_needed(&t, v0 - 1.0, 0.0).unwrap(), Some(0.0));
        for v in [v0 + 3.0, v0 + 10.0] {
            let c = damper_needed(&t, v, 0.0)
                .unwrap()
                .expect("a damper that stabilises");
            let on = stability::hopf_crossings(&t, c, 1.0, 70.0, 0.5, 1e-7)
                .unwrap()
                .iter()
                .find(|x| x.kind == CrossingKind::Onset)
                .unwrap()
                .speed_mps;
            assert!((on - v).abs() < 1e-4 * v, "damper {c}: onset {on} vs {v}");
            assert!(stability::critical_mode_at(&t, v, 0.99 * c).unwrap().re > 0.0);
            // a damping-ratio target needs more
            let c5 = damper_needed(&t, v, 0.05).unwrap().unwrap();
            assert!(c5 > c);
            assert!((least_zeta(&t, v, c5).unwrap() - 0.05).abs() < 1e-6);
        }
    }

    /// The shape Diboll & Hagen report: "as higher values of s omega / V and mu G z / V^2 are
    /// reached (for example, lower velocity), less damping is needed". Along the trailer's own
    /// path (both groups rise as the speed falls) the damping needed falls; on each curve of
    /// the map it falls with s omega / V beyond the curve's peak (a stiffer hitch) and reaches
    /// zero; the peak is lower at a higher energy term. (At a very soft hitch the need falls
    /// again, `docs/trailer.md`.)
    #[test]
    fn less_damping_is_needed_at_higher_strouhal_and_energy_term() {
        let t = TrailerSet::Caravan.params();
        let mut last = f64::INFINITY;
        for kmh in [180.0, 160.0, 140.0, 120.0, 105.0] {
            let c = damper_needed(&t, kmh / 3.6, 0.0).unwrap().unwrap();
            assert!(c > 0.0 && c < last, "{kmh} km/h: {c} after {last}");
            last = c;
        }
        let energy = [0.25, 0.36];
        let st = [0.1, 0.15, 0.2, 0.25, 0.3, 0.4];
        let map = dh_map(&t, &energy, &st).unwrap();
        let z = |e: usize, s: usize| map[e * st.len() + s].zeta_needed.unwrap();
        let mut peaks = Vec::new();
        for (e, energy_term) in energy.iter().enumerate() {
            let peak = (0..st.len())
                .max_by(|&a, &b| z(e, a).total_cmp(&z(e, b)))
                .unwrap();
            assert!(peak < st.len() - 2 && z(e, peak) > 0.0, "{map:?}");
            for s in peak + 1..st.len() {
                assert!(z(e, s) <= z(e, s - 1), "energy {energy_term}: {map:?}");
            }
            assert_eq!(z(e, st.len() - 1), 0.0, "{map:?}");
            peaks.push(z(e, peak));
        }
        assert!(peaks[1] < peaks[0], "{peaks:?}");
        // every point is the trailer at its groups
        for p in &map {
            let (q, v) = similar_point(&t, p.strouhal, p.energy_term);
            assert!((q.strouhal(v) - p.strouhal).abs() < 1e-12);
            assert!((q.energy_term(v) - p.energy_term).abs() < 1e-12);
        }
    }
}
