//! Scalar maths shared by the algorithms.
//!
//! Every function here is correctly rounded or comes from `libm`, which is a
//! pure-Rust implementation, so the host and the Cortex-M4 produce
//! bit-identical results (checked in the QEMU test suite). `micromath` is not
//! used where accuracy matters: its `sqrt(9.0)` returns 3.125.

/// Square root, correctly rounded (IEEE 754). On the Cortex-M4F this is one
/// `vsqrt.f32` instruction; elsewhere it is `libm::sqrtf`. Both are correctly
/// rounded, so they agree bit for bit.
#[inline(always)]
pub fn sqrtf(x: f32) -> f32 {
    #[cfg(all(target_arch = "arm", target_feature = "vfp2"))]
    {
        let r: f32;
        // SAFETY: vsqrt.f32 only reads and writes FPU registers.
        #[allow(unsafe_code)]
        unsafe {
            core::arch::asm!("vsqrt.f32 {r}, {x}", r = out(sreg) r, x = in(sreg) x,
                options(pure, nomem, nostack));
        }
        r
    }
    #[cfg(not(all(target_arch = "arm", target_feature = "vfp2")))]
    {
        libm::sqrtf(x)
    }
}

/// Natural logarithm (libm, < 1 ulp).
#[inline]
pub fn lnf(x: f32) -> f32 {
    libm::logf(x)
}

/// e^x (libm, < 1 ulp).
#[inline]
pub fn expf(x: f32) -> f32 {
    libm::expf(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sqrt_is_exact_where_micromath_is_not() {
        assert_eq!(sqrtf(9.0), 3.0);
        assert_eq!(sqrtf(2.0), core::f32::consts::SQRT_2);
        // The approximation this crate avoids: documented, not used.
        let approx = micromath::F32Ext::sqrt(9.0f32);
        assert!(
            (approx - 3.0).abs() > 0.05,
            "micromath got better: {approx}"
        );
    }
}
