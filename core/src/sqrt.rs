//! Square roots on the FPU where the target has one.
//!
//! libm's `sqrtf` is a correctly rounded software routine, about 60 instructions on the
//! Cortex-M4F; the M4F's `VSQRT.F32` is one instruction. IEEE 754 requires the square root to
//! be correctly rounded, so both give the same bits and the host and the target stay
//! bit-identical (the conformance digests, `docs/architecture.md`). f64 has no FPU path on the
//! M4 (single-precision FPU): there it is a digit-by-digit integer square root (fdlibm's
//! method, ~0.2 KB), where libm's table-driven one is ~0.7 KB of flash with its table (`cargo
//! xtask size`); the host keeps libm's. Both are correctly rounded: the same bits (a test).

/// Correctly rounded square root of an f32 (`VSQRT.F32` on hard-float ARM, libm elsewhere).
#[inline]
pub fn sqrtf(x: f32) -> f32 {
    #[cfg(all(target_arch = "arm", target_abi = "eabihf"))]
    {
        let y: u32;
        // rustc gives the FPU's register class only to double-precision (`vfp2`) targets, and
        // the M4F's FPU is single precision: the operands pass through core registers, and s0
        // is saved and restored around its use.
        // SAFETY: the sequence reads and writes only the registers named here and restores s0
        // and the stack pointer.
        unsafe {
            core::arch::asm!(
                "vpush {{s0}}",
                "vmov s0, {x}",
                "vsqrt.f32 s0, s0",
                "vmov {y}, s0",
                "vpop {{s0}}",
                x = in(reg) x.to_bits(),
                y = lateout(reg) y,
                options(pure, nomem, preserves_flags)
            );
        }
        f32::from_bits(y)
    }
    #[cfg(not(all(target_arch = "arm", target_abi = "eabihf")))]
    {
        libm::sqrtf(x)
    }
}

/// Correctly rounded square root of an f64 (digit by digit on hard-float ARM, libm elsewhere).
#[inline]
pub fn sqrt(x: f64) -> f64 {
    #[cfg(all(target_arch = "arm", target_abi = "eabihf"))]
    {
        sqrt_by_digits(x)
    }
    #[cfg(not(all(target_arch = "arm", target_abi = "eabihf")))]
    {
        libm::sqrt(x)
    }
}

/// The f64 square root digit by digit (fdlibm's `e_sqrt.c` in one 64-bit word): 54 bits of
/// the root of the scaled significand, then round to nearest on the 54th (the root is never
/// exactly halfway). Slower than libm's (54 iterations), little where it is used: a mode's
/// natural frequency, +1,280 instructions in the worst warm model cycle (`cargo xtask bench`).
#[cfg_attr(not(all(target_arch = "arm", target_abi = "eabihf")), allow(dead_code))]
#[inline(never)] // one copy for every caller
fn sqrt_by_digits(x: f64) -> f64 {
    let bits = x.to_bits();
    // NaN, +-0, +inf are their own roots; other negatives have none.
    if x.is_nan() || x == 0.0 || x == f64::INFINITY {
        return x;
    }
    if bits >> 63 != 0 {
        return f64::NAN;
    }
    let (mut exp, mut m) = ((bits >> 52) as i32, bits & ((1 << 52) - 1));
    if exp == 0 {
        // subnormal: normalise the significand
        let shift = m.leading_zeros() - 11;
        m <<= shift;
        exp = 1 - shift as i32;
    } else {
        m |= 1 << 52;
    }
    exp -= 1023;
    // an even exponent halves exactly; the significand takes the odd one's factor 2
    if exp & 1 != 0 {
        m <<= 1;
    }
    let mut rem = m << 1;
    let (mut root, mut s, mut bit) = (0u64, 0u64, 1u64 << 53);
    while bit != 0 {
        let t = s + bit;
        if t <= rem {
            s = t + bit;
            rem -= t;
            root += bit;
        }
        rem <<= 1;
        bit >>= 1;
    }
    // root has 54 bits: the result's 53 and a rounding bit
    let mantissa = (root >> 1) + (root & 1);
    f64::from_bits(mantissa + (((exp >> 1) + 1022) as u64) * (1 << 52))
}

/// The correctly rounded square root of the numeric kernels' float types (the eigenvalue
/// solver is generic over f32 and f64).
pub trait Sqrt: Copy {
    /// The square root, correctly rounded.
    fn sqrt_rounded(self) -> Self;
}

impl Sqrt for f32 {
    #[inline]
    fn sqrt_rounded(self) -> Self {
        sqrtf(self)
    }
}

impl Sqrt for f64 {
    #[inline]
    fn sqrt_rounded(self) -> Self {
        sqrt(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The target's digit-by-digit f64 root is libm's bit for bit: 2 M pseudo-random bit
    /// patterns (every exponent, subnormals included), the squares of random f64 (exact
    /// roots), each one ulp off (the closest cases to rounding), and the special values.
    #[test]
    fn the_f64_square_root_by_digits_is_libms() {
        let same = |x: f64| {
            let (a, b) = (sqrt_by_digits(x), libm::sqrt(x));
            assert!(
                a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                "{x:e}: {a:e} vs {b:e}"
            );
        };
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        for _ in 0..2_000_000 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            same(f64::from_bits(state >> 1));
            let r = f64::from_bits((state >> 12) | 0x3ff0_0000_0000_0000); // [1, 2)
            let sq = r * r;
            for x in [
                sq,
                f64::from_bits(sq.to_bits() + 1),
                f64::from_bits(sq.to_bits() - 1),
            ] {
                same(x);
                same(x * 1e-300);
            }
        }
        for x in [
            0.0,
            -0.0,
            -1.0,
            5e-324,
            f64::MIN_POSITIVE,
            f64::MAX,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            2.0,
            4.0,
            0.25,
        ] {
            same(x);
        }
    }

    #[test]
    fn the_square_root_is_libms_bit_for_bit() {
        // Powers of two, their neighbours, subnormals, the largest float and random-ish bits.
        let mut bits: u32 = 0x3f80_0000;
        for k in 0..100_000u32 {
            bits = bits.wrapping_mul(1_664_525).wrapping_add(1_013_904_223 ^ k);
            let x = f32::from_bits(bits & 0x7fff_ffff);
            let (a, b) = (sqrtf(x), libm::sqrtf(x));
            assert!(
                a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                "{x:e}"
            );
        }
        for x in [
            0.0f32,
            -0.0,
            1e-45,
            f32::MIN_POSITIVE,
            f32::MAX,
            f32::INFINITY,
        ] {
            assert_eq!(sqrtf(x).to_bits(), libm::sqrtf(x).to_bits(), "{x:e}");
        }
        assert!(sqrtf(-1.0).is_nan());
    }
}
