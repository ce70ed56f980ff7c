//! f32 sine, cosine and tangent in f32 on the FPU, for |x| <= 200 (NaN beyond): within 2 ulps
//! of the exact value for sine and cosine and 3.5 for the tangent (measured against f64 in the
//! tests below: 1.82, 1.92 and 3.16 at worst; 97.6 % of the sines are libm's bits).
//!
//! libm's f32 functions compute in f64 (soft-float calls on the M4F: 1.6 KB of flash for these
//! three in that form, 1.0 KB in this one, `cargo xtask size`) and reduce an argument beyond
//! 2^28 pi/2 with `rem_pio2_large` (Payne-Hanek with a table of 2/pi, 2.5 KB more) that no
//! caller needs: the estimator's arguments are wrapped phases (|x| <= pi), design angles below
//! 2 pi and tan(pi f / fs) with f < fs / 2. Here the reduction is Cody-Waite with pi/2 in three parts, each product with
//! the quadrant number exact below 128 quadrants, and the kernels are msun's polynomials
//! evaluated in f32. Host and target run the same f32 operations, so they compute the same
//! bits (the conformance digests, `docs/architecture.md`).
//!
//! The kernels' coefficients and the split of pi/2 are FreeBSD's msun (`k_sinf.c`, `k_cosf.c`,
//! `k_tanf.c`, `e_rem_pio2f.c`; Copyright (C) 1993, 2004 by Sun Microsystems, Inc.: "Permission
//! to use, copy, modify, and distribute this software is freely granted, provided that this
//! notice is preserved."), as in the `libm` crate.

// The kernels' coefficients as msun writes them (more digits than an f32 holds).
#![allow(clippy::excessive_precision)]

use core::f32::consts::{FRAC_2_PI, FRAC_PI_4};

/// Largest |x| reduced: 127 quadrants (200 / (pi/2) = 127.3), where n * PIO2_1 and
/// n * PIO2_2 are still exact.
const LIMIT: f32 = 200.0;
/// pi/2 in three parts (msun's float `pio2_1`, `pio2_2`, `pio2_2t`): 17 and 14 significant
/// bits, then the rest.
const PIO2_1: f32 = f32::from_bits(0x3fc9_0f80);
const PIO2_2: f32 = f32::from_bits(0x3735_4400);
const PIO2_2T: f32 = f32::from_bits(0x2e85_a308);
/// 1.5 * 2^23: adding and subtracting it rounds an f32 below 2^22 to an integer.
const TOINT: f32 = 1.5 / f32::EPSILON;

/// The bits of |x|, which order like the magnitudes (NaN above infinity above every finite
/// value).
fn magnitude_bits(x: f32) -> u32 {
    x.to_bits() & 0x7fff_ffff
}

/// (n, y) with x = n pi/2 + y, |y| ~<= pi/4; `None` beyond [`LIMIT`] (and for NaN, infinity).
fn reduce(x: f32) -> Option<(i32, f32)> {
    let ax = magnitude_bits(x);
    if ax <= FRAC_PI_4.to_bits() {
        return Some((0, x));
    }
    if ax > LIMIT.to_bits() {
        return None;
    }
    let n = (x * FRAC_2_PI + TOINT) - TOINT;
    // x - n PIO2_1 is exact (Sterbenz), as are both products; the error is the last two
    // subtractions' rounding.
    Some((n as i32, ((x - n * PIO2_1) - n * PIO2_2) - n * PIO2_2T))
}

/// sin(x) on |x| <= pi/4 (msun: |sin(x)/x - s(x)| < 2**-37.5).
fn k_sinf(x: f32) -> f32 {
    const S1: f32 = -0.166_666_666_416_265_235_595;
    const S2: f32 = 0.008_333_329_385_889_463_175_6;
    const S3: f32 = -0.000_198_393_348_360_966_317_347;
    const S4: f32 = 0.000_002_718_311_493_989_821_906_4;
    let z = x * x;
    let w = z * z;
    let r = S3 + z * S4;
    let s = z * x;
    (x + s * (S1 + z * S2)) + s * w * r
}

/// cos(x) on |x| <= pi/4 (msun: |cos(x) - c(x)| < 2**-34.1).
fn k_cosf(x: f32) -> f32 {
    const C0: f32 = -0.499_999_997_251_031_003_120;
    const C1: f32 = 0.041_666_623_323_739_063_189_4;
    const C2: f32 = -0.001_388_676_377_460_992_946_92;
    const C3: f32 = 0.000_024_390_448_796_277_409_065_4;
    let z = x * x;
    let w = z * z;
    let r = C2 + z * C3;
    ((1.0 + z * C0) + w * C1) + (w * z) * r
}

/// tan(x) on |x| <= pi/4 (-1/tan(x) when `odd`; msun: |tan(x)/x - t(x)| < 2**-25.5).
fn k_tanf(x: f32, odd: bool) -> f32 {
    const T: [f32; 6] = [
        0.333_331_395_030_791_399_758,
        0.133_392_002_712_976_742_718,
        0.053_381_237_844_567_039_352_3,
        0.024_528_318_116_654_727_887_3,
        0.002_974_357_433_599_673_049_27,
        0.009_465_647_849_436_731_667_28,
    ];
    let z = x * x;
    let mut r = T[4] + z * T[5];
    let t = T[2] + z * T[3];
    let w = z * z;
    let s = z * x;
    let u = T[0] + z * T[1];
    r = (x + s * u) + (s * w) * (t + w * r);
    if odd {
        -1. / r
    } else {
        r
    }
}

/// |x| < 2^-12 (and 0): sin and tan are x, cos is 1, each correctly rounded.
fn tiny(x: f32) -> bool {
    magnitude_bits(x) < 0x3980_0000
}

/// sin(x) for |x| <= 200 (within 2 ulps), NaN beyond.
pub fn sinf(x: f32) -> f32 {
    if tiny(x) {
        return x;
    }
    match reduce(x) {
        Some((n, y)) => match n & 3 {
            0 => k_sinf(y),
            1 => k_cosf(y),
            2 => -k_sinf(y),
            _ => -k_cosf(y),
        },
        None => f32::NAN,
    }
}

/// cos(x) for |x| <= 200 (within 2 ulps), NaN beyond.
pub fn cosf(x: f32) -> f32 {
    if tiny(x) {
        return 1.0;
    }
    match reduce(x) {
        Some((n, y)) => match n & 3 {
            0 => k_cosf(y),
            1 => -k_sinf(y),
            2 => -k_cosf(y),
            _ => k_sinf(y),
        },
        None => f32::NAN,
    }
}

/// tan(x) for |x| <= 200 (within 3.5 ulps), NaN beyond.
pub fn tanf(x: f32) -> f32 {
    if tiny(x) {
        return x;
    }
    match reduce(x) {
        Some((n, y)) => k_tanf(y, n & 1 != 0),
        None => f32::NAN,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Error of `got` in units in the last place of the correctly rounded `exact`.
    fn ulps(got: f32, exact: f64) -> f64 {
        let rounded = exact as f32;
        let ulp = f32::from_bits(rounded.to_bits() + 1) - rounded;
        (f64::from(got) - exact).abs() / f64::from(ulp.abs())
    }

    /// Against f64 libm (the exact value to ~1e-16 relative) on both signs of ~2.2 M
    /// arguments: every binade up to the limit (a prime stride through the bit patterns) and
    /// every bit pattern next to the branch limits and near multiples of pi/2.
    #[test]
    fn within_two_ulps_of_the_exact_value() {
        let limit_bits = LIMIT.to_bits();
        let branch = [0x3980_0000u32, FRAC_PI_4.to_bits(), limit_bits];
        let near_multiples =
            (1..=127).map(|k| (f64::from(k) * core::f64::consts::FRAC_PI_2) as f32);
        let near = branch
            .into_iter()
            .chain(near_multiples.map(f32::to_bits))
            .flat_map(|l| l.saturating_sub(64)..(l + 64).min(limit_bits + 1));
        let (mut worst, mut checked, mut same_as_libm) = ([0.0f64; 3], 0u32, 0u32);
        for bits in (0..=limit_bits).step_by(997).chain(near) {
            for x in [f32::from_bits(bits), -f32::from_bits(bits)] {
                let x64 = f64::from(x);
                let got = [sinf(x), cosf(x), tanf(x)];
                let exact = [libm::sin(x64), libm::cos(x64), libm::tan(x64)];
                for k in 0..3 {
                    worst[k] = worst[k].max(ulps(got[k], exact[k]));
                }
                same_as_libm += u32::from(got[0].to_bits() == libm::sinf(x).to_bits());
                checked += 1;
            }
        }
        assert!(checked > 2_000_000, "{checked}");
        eprintln!("worst {worst:?} ulps, {same_as_libm} of {checked} sines libm's bits");
        assert!(
            worst[0] <= 2.0 && worst[1] <= 2.0,
            "sin, cos: {worst:?} ulps"
        );
        assert!(worst[2] <= 3.5, "tan: {worst:?} ulps");
        // libm's f32 sine is correctly rounded nearly everywhere: most results agree exactly
        assert!(
            f64::from(same_as_libm) > 0.9 * f64::from(checked),
            "{same_as_libm} of {checked}"
        );
    }

    /// Beyond the limit, and for NaN and infinity: NaN.
    #[test]
    fn beyond_the_limit_and_non_finite_arguments_give_nan() {
        let past = f32::from_bits(LIMIT.to_bits() + 1);
        for x in [
            past,
            -past,
            1e9,
            -3e38,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ] {
            assert!(
                sinf(x).is_nan() && cosf(x).is_nan() && tanf(x).is_nan(),
                "{x}"
            );
        }
        assert!((sinf(LIMIT) - libm::sinf(LIMIT)).abs() <= 1e-6);
    }
}
