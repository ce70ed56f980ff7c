//! The Magic-Formula lateral force that every simulated plant's tyres share.

/// `D sin(C atan(B a))` in N: peak `d` (N), shape `c`, stiffness factor `b` (per unit of `a`),
/// at lagged slip `a`.
///
/// Through the `libm` crate rather than the platform's `f64::sin`/`atan`: glibc saves and
/// restores the rounding mode on every call, and the two calls were 20-29 % of a closed-loop
/// run (`perf` on `cargo bench -p shimmy-sim --bench plant -- closed_loop`). Both are within
/// an ulp of each other (`tests::agrees_with_the_platform_functions`).
#[inline]
pub fn magic_formula_n(d: f64, c: f64, b: f64, a: f64) -> f64 {
    d * libm::sin(c * libm::atan(b * a))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn agrees_with_the_platform_functions() {
        // Slips from the linear region through the peak to deep sliding, both signs.
        let (d, c, b) = (4_000.0, 1.3507, 11.0);
        for k in -2_000..=2_000 {
            let a = f64::from(k) * 5e-4;
            let platform = d * (c * (b * a).atan()).sin();
            let ours = magic_formula_n(d, c, b, a);
            assert!(
                (ours - platform).abs() <= 4.0 * f64::EPSILON * platform.abs(),
                "slip {a}: {ours} vs {platform}"
            );
        }
        assert_eq!(magic_formula_n(d, c, b, 0.0), 0.0);
    }
}
