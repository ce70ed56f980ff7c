//! The mining truck's studies (`docs/mining-truck.md`): the Hopf window as the load and the
//! struts' initial gas volume change, and Gao's question: which gas charges keep the truck free
//! of shimmy at a given load and speed.
//!
//! Both come from the linear model's eigenvalues (`shimmy_core::stability`); the charge bounds
//! are sign changes of the growth rate g(V0) = max Re over the oscillatory eigenvalues at the
//! speed, bracketed on a grid of gas volumes and refined with Brent's method.

use anyhow::{bail, Context, Result};
use shimmy_core::stability::{self, CrossingKind, DEFAULT_TOL_MPS};
use shimmy_core::units::{kmh_to_mps, mps_to_kmh};
use shimmy_core::vehicles::truck::TruckParams;

/// Highest speed the window search looks at, km/h (above the class's top speed of ~60 km/h).
pub const WINDOW_V_MAX_KMH: f64 = 90.0;
/// Lowest speed of the window search, km/h.
pub const WINDOW_V_MIN_KMH: f64 = 1.0;
/// Grid step of the window search, km/h.
pub const WINDOW_STEP_KMH: f64 = 0.5;

/// The first unstable window of one truck.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WindowPoint {
    /// The varied quantity (payload in kg, or gas volume in l).
    pub x: f64,
    /// The struts carry the load (else no window is computed).
    pub feasible: bool,
    /// First onset in the search range, km/h.
    pub onset_kmh: Option<f64>,
    /// The offset above it, km/h (None: unstable to the end of the range).
    pub offset_kmh: Option<f64>,
    /// Frequency at the onset, Hz.
    pub freq_hz: Option<f64>,
}

/// The first Hopf window of `t` in [`WINDOW_V_MIN_KMH`, `WINDOW_V_MAX_KMH`].
pub fn window(t: &TruckParams, x: f64) -> Result<WindowPoint> {
    if t.operating_point().is_err() {
        return Ok(WindowPoint {
            x,
            feasible: false,
            onset_kmh: None,
            offset_kmh: None,
            freq_hz: None,
        });
    }
    let cs = stability::hopf_crossings(
        t,
        0.0,
        kmh_to_mps(WINDOW_V_MIN_KMH),
        kmh_to_mps(WINDOW_V_MAX_KMH),
        kmh_to_mps(WINDOW_STEP_KMH),
        DEFAULT_TOL_MPS,
    )
    .context("Hopf search")?;
    let onset = cs.iter().position(|c| c.kind == CrossingKind::Onset);
    let offset = onset.and_then(|i| {
        cs.iter()
            .skip(i + 1)
            .find(|c| c.kind == CrossingKind::Offset)
    });
    Ok(WindowPoint {
        x,
        feasible: true,
        onset_kmh: onset
            .and_then(|i| cs.get(i))
            .map(|c| mps_to_kmh(c.speed_mps)),
        offset_kmh: offset.map(|c| mps_to_kmh(c.speed_mps)),
        freq_hz: onset.and_then(|i| cs.get(i)).map(|c| c.freq_hz),
    })
}

/// One gas volume of the charge study.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChargeRow {
    /// Initial gas volume, l.
    pub v0_l: f64,
    /// The struts carry the load at this charge.
    pub feasible: bool,
    /// Growth rate of the critical oscillatory mode at the speed, 1/s (< 0: no shimmy).
    pub growth_1ps: f64,
    /// Its frequency, Hz.
    pub freq_hz: f64,
    /// Static stroke of a strut, mm.
    pub stroke_mm: f64,
    /// Strut stiffness at the static point, N/m.
    pub stiffness_npm: f64,
}

/// The answer to "which charges keep the truck free of shimmy at this speed".
#[derive(Clone, Debug, PartialEq)]
pub struct ChargeAnswer {
    /// The speed asked about, km/h.
    pub speed_kmh: f64,
    /// Charge ranges [lo, hi] in l (within the searched range) where straight running is
    /// stable at the speed; `lo` or `hi` at the searched range's end when the range cuts it.
    pub stable_l: Vec<(f64, f64)>,
    /// The grid rows.
    pub rows: Vec<ChargeRow>,
}

impl ChargeAnswer {
    /// The least charge that keeps the truck free of shimmy, l.
    pub fn least_l(&self) -> Option<f64> {
        self.stable_l.first().map(|r| r.0)
    }
}

fn growth(t: &TruckParams, v0_l: f64, v_mps: f64) -> Result<shimmy_core::eigen::Mode> {
    stability::critical_mode_at(&t.with_gas_volume(v0_l * 1e-3), v_mps, 0.0)
        .with_context(|| format!("eigen-solve at V0 = {v0_l} l"))
}

/// Gas volumes from `v0_min_l` to `v0_max_l` in steps of `step_l` at `speed_kmh`: the growth
/// on the grid and every stable range, its ends refined to 1e-4 l. Charges at which the struts
/// top or bottom out count as not stable (they are not a working charge).
pub fn gas_charge(
    t: &TruckParams,
    speed_kmh: f64,
    v0_min_l: f64,
    v0_max_l: f64,
    step_l: f64,
) -> Result<ChargeAnswer> {
    if !(v0_min_l > 0.0 && v0_max_l > v0_min_l && step_l > 0.0) {
        bail!("gas volume range {v0_min_l} .. {v0_max_l} l step {step_l} l: need 0 < min < max and step > 0");
    }
    let v = kmh_to_mps(speed_kmh);
    let n = ((v0_max_l - v0_min_l) / step_l).ceil() as usize;
    let mut rows = Vec::with_capacity(n + 1);
    for i in 0..=n {
        let v0_l = (v0_min_l + i as f64 * step_l).min(v0_max_l);
        let tv = t.with_gas_volume(v0_l * 1e-3);
        let row = match tv.operating_point() {
            Ok(op) => {
                let m = growth(t, v0_l, v)?;
                ChargeRow {
                    v0_l,
                    feasible: true,
                    growth_1ps: m.re,
                    freq_hz: m.freq_hz,
                    stroke_mm: op.strut.stroke_m * 1e3,
                    stiffness_npm: op.strut.stiffness_npm,
                }
            }
            Err(_) => ChargeRow {
                v0_l,
                feasible: false,
                growth_1ps: f64::NAN,
                freq_hz: f64::NAN,
                stroke_mm: f64::NAN,
                stiffness_npm: f64::NAN,
            },
        };
        rows.push(row);
    }
    let stable = |r: &ChargeRow| r.feasible && r.growth_1ps < 0.0;
    // a boundary between two feasible rows is a sign change of the growth: refine it; one
    // between a feasible and an infeasible row stays at the grid (the strut's limit)
    let refine = |a: &ChargeRow, b: &ChargeRow| -> Result<f64> {
        if !(a.feasible && b.feasible) {
            return Ok(if a.feasible { a.v0_l } else { b.v0_l });
        }
        let root = stability::brent(
            |x| growth(t, x, v).map(|m| m.re),
            a.v0_l,
            b.v0_l,
            a.growth_1ps,
            b.growth_1ps,
            1e-4,
            100,
        )?;
        Ok(root.x)
    };
    let mut stable_l = Vec::new();
    let mut start: Option<f64> = rows.first().filter(|r| stable(r)).map(|r| r.v0_l);
    for w in rows.windows(2) {
        let (a, b) = (&w[0], &w[1]);
        match (stable(a), stable(b)) {
            (false, true) => start = Some(refine(a, b)?),
            (true, false) => {
                if let Some(s) = start.take() {
                    stable_l.push((s, refine(a, b)?));
                }
            }
            _ => {}
        }
    }
    if let (Some(s), Some(last)) = (start, rows.last()) {
        stable_l.push((s, last.v0_l));
    }
    Ok(ChargeAnswer {
        speed_kmh,
        stable_l,
        rows,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use shimmy_core::vehicles::truck::TruckSet;

    /// The charge bounds are where the growth changes sign: just inside a stable range the
    /// truck is stable at the speed, just outside it is not (eigenvalues, independent of the
    /// bracketing).
    #[test]
    fn charge_bounds_are_sign_changes_of_the_growth() {
        let t = TruckSet::Full.params();
        let ans = gas_charge(&t, 30.0, 2.0, 100.0, 2.0).unwrap();
        let lo = ans
            .least_l()
            .expect("a charge that stabilises the full truck at 30 km/h");
        let v = kmh_to_mps(30.0);
        assert!(growth(&t, lo + 0.01, v).unwrap().re < 0.0);
        assert!(growth(&t, lo - 0.01, v).unwrap().re > 0.0);
        // the named set's charge (10 l) shimmies at 30 km/h at full load
        assert!(lo > 10.0, "{lo}");
    }
}
