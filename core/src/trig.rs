//! f32 sine, cosine and tangent with the bits of libm's `sinf`, `cosf` and `tanf` for every
//! argument below 2^28 pi/2 (4.2e8 rad) in magnitude, without libm's reduction of huge
//! arguments.
//!
//! libm's f32 functions reduce an argument beyond 2^28 pi/2 with `rem_pio2_large` (Payne-Hanek
//! with a table of 2/pi), 2.5 KB of the firmware image (`cargo xtask size`) that no caller
//! needs: the estimator's arguments are wrapped phases (|x| <= pi), design angles below 2 pi and
//! tan(pi f / fs) with f < fs / 2. These are the same kernels, the same reductions (the small
//! multiples of pi/2 up to 9 pi/4, then the 25 + 53-bit pi/2 of the medium range) and the same
//! operations in f64, so host and target compute libm's bits (tested against libm over the
//! whole range here). Beyond the range the result is NaN, not an inaccurate number.
//!
//! The kernels and the reduction are FreeBSD's msun (`k_sinf.c`, `k_cosf.c`, `k_tanf.c`,
//! `e_rem_pio2f.c`, `s_sinf.c`, `s_cosf.c`, `s_tanf.c`; Copyright (C) 1993, 2004 by Sun
//! Microsystems, Inc.: "Permission to use, copy, modify, and distribute this software is
//! freely granted, provided that this notice is preserved."), as in the `libm` crate.

// The kernels' coefficients as msun writes them (more digits than an f64 holds; they round to
// msun's f64 values, which the test against libm checks bit for bit).
#![allow(clippy::excessive_precision)]

use core::f64::consts::{FRAC_2_PI, FRAC_PI_2};

/// Largest |x| bit pattern of the medium range (|x| ~< 2^28 pi/2).
const MEDIUM_END: u32 = 0x4dc9_0fdb;
/// First 25 bits of pi/2 (0x3FF921FB, 0x50000000).
const PIO2_1: f64 = 1.570_796_310_901_641_845_70;
/// pi/2 - PIO2_1 (0x3E5110b4, 0x611A6263).
const PIO2_1T: f64 = 1.589_325_477_352_819_669_16e-8;
const TOINT: f64 = 1.5 / f64::EPSILON;

/// (n, y) with x = n pi/2 + y, |y| ~<= pi/4, as libm reduces it; `None` for |x| of 2^28 pi/2
/// and more (and NaN, infinity).
fn reduce(x: f32) -> Option<(i32, f64)> {
    let x64 = x as f64;
    let ix = x.to_bits() & 0x7fff_ffff;
    // |x| ~<= pi/4, 3 pi/4, 5 pi/4, 7 pi/4, 9 pi/4: x minus that small multiple of pi/2
    let (k, c) = match ix {
        0..=0x3f49_0fda => (0, 0.0),
        0x3f49_0fdb..=0x4016_cbe3 => (1, FRAC_PI_2),
        0x4016_cbe4..=0x407b_53d1 => (2, 2.0 * FRAC_PI_2),
        0x407b_53d2..=0x40af_eddf => (3, 3.0 * FRAC_PI_2),
        0x40af_ede0..=0x40e2_31d5 => (4, 4.0 * FRAC_PI_2),
        0x40e2_31d6..MEDIUM_END => {
            // 2/pi rounded to f64 is msun's invpio2 (0x3FE45F30, 0x6DC9C883)
            let f_n = (x64 * FRAC_2_PI + TOINT) - TOINT;
            return Some((f_n as i32, x64 - f_n * PIO2_1 - f_n * PIO2_1T));
        }
        _ => return None,
    };
    Some(if x.is_sign_negative() {
        (-k, x64 + c)
    } else {
        (k, x64 - c)
    })
}

/// |sin(x)/x - s(x)| < 2**-37.5 on |x| <= pi/4.
fn k_sinf(x: f64) -> f32 {
    const S1: f64 = -0.166_666_666_416_265_235_595;
    const S2: f64 = 0.008_333_329_385_889_463_175_6;
    const S3: f64 = -0.000_198_393_348_360_966_317_347;
    const S4: f64 = 0.000_002_718_311_493_989_821_906_4;
    let z = x * x;
    let w = z * z;
    let r = S3 + z * S4;
    let s = z * x;
    ((x + s * (S1 + z * S2)) + s * w * r) as f32
}

/// |cos(x) - c(x)| < 2**-34.1 on |x| <= pi/4.
fn k_cosf(x: f64) -> f32 {
    const C0: f64 = -0.499_999_997_251_031_003_120;
    const C1: f64 = 0.041_666_623_323_739_063_189_4;
    const C2: f64 = -0.001_388_676_377_460_992_946_92;
    const C3: f64 = 0.000_024_390_448_796_277_409_065_4;
    let z = x * x;
    let w = z * z;
    let r = C2 + z * C3;
    (((1.0 + z * C0) + w * C1) + (w * z) * r) as f32
}

/// tan(x) on |x| <= pi/4 (-1/tan(x) when `odd`); |tan(x)/x - t(x)| < 2**-25.5.
fn k_tanf(x: f64, odd: bool) -> f32 {
    const T: [f64; 6] = [
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
    (if odd { -1. / r } else { r }) as f32
}

/// |x| < 2^-12 (and 0): libm returns x for sin and tan, 1 for cos.
fn tiny(x: f32) -> bool {
    x.to_bits() & 0x7fff_ffff < 0x3980_0000
}

/// sin(x): libm's `sinf` for |x| < 2^28 pi/2, NaN beyond.
pub fn sinf(x: f32) -> f32 {
    if tiny(x) {
        return x;
    }
    match reduce(x) {
        Some((n, y)) => match n & 3 {
            0 => k_sinf(y),
            1 => k_cosf(y),
            2 => k_sinf(-y),
            _ => -k_cosf(y),
        },
        None => f32::NAN,
    }
}

/// cos(x): libm's `cosf` for |x| < 2^28 pi/2, NaN beyond.
pub fn cosf(x: f32) -> f32 {
    if tiny(x) {
        return 1.0;
    }
    match reduce(x) {
        Some((n, y)) => match n & 3 {
            0 => k_cosf(y),
            1 => k_sinf(-y),
            2 => -k_cosf(y),
            _ => k_sinf(y),
        },
        None => f32::NAN,
    }
}

/// tan(x): libm's `tanf` for |x| < 2^28 pi/2, NaN beyond.
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

    fn same(a: f32, b: f32) -> bool {
        a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
    }

    /// Bit for bit libm's functions on both signs of ~1.3 M arguments spread over every
    /// binade up to the end of the medium range (a prime stride through the bit patterns), and
    /// on every bit pattern next to the branch limits.
    #[test]
    fn the_bits_of_libm_below_the_huge_range() {
        let limits = [
            0x3980_0000u32,
            0x3f49_0fda,
            0x4016_cbe3,
            0x407b_53d1,
            0x40af_eddf,
            0x40e2_31d5,
            MEDIUM_END,
        ];
        let near = limits
            .iter()
            .flat_map(|&l| l.saturating_sub(64)..(l + 64).min(MEDIUM_END));
        let mut checked = 0u32;
        for bits in (0..MEDIUM_END).step_by(997).chain(near) {
            for x in [f32::from_bits(bits), -f32::from_bits(bits)] {
                assert!(same(sinf(x), libm::sinf(x)), "sin({x:e})");
                assert!(same(cosf(x), libm::cosf(x)), "cos({x:e})");
                assert!(same(tanf(x), libm::tanf(x)), "tan({x:e})");
                checked += 1;
            }
        }
        assert!(checked > 2_600_000, "{checked}");
    }

    /// Beyond the medium range, and for NaN and infinity: NaN (libm reduces huge arguments
    /// with a table this module does not link).
    #[test]
    fn huge_and_non_finite_arguments_give_nan() {
        for x in [
            f32::from_bits(MEDIUM_END),
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
        // just below the end: libm's value
        let x = f32::from_bits(MEDIUM_END - 1);
        assert_eq!(sinf(x).to_bits(), libm::sinf(x).to_bits());
    }
}
