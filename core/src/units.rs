//! Unit conversions and physical constants shared by every model.

/// Standard gravity, m/s^2.
pub const G_MPS2: f64 = 9.80665;

/// km/h -> m/s.
pub fn kmh_to_mps(v_kmh: f64) -> f64 {
    v_kmh / 3.6
}

/// m/s -> km/h.
pub fn mps_to_kmh(v_mps: f64) -> f64 {
    v_mps * 3.6
}
