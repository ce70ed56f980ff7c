//! Square roots on the FPU where the target has one.
//!
//! libm's `sqrtf` is a correctly rounded software routine, about 60 instructions on the
//! Cortex-M4F; the M4F's `VSQRT.F32` is one instruction. IEEE 754 requires the square root to
//! be correctly rounded, so both give the same bits and the host and the target stay
//! bit-identical (the conformance digests, `docs/architecture.md`). f64 has no FPU path on the
//! M4 (single-precision FPU): it stays libm's.

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
        libm::sqrt(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
