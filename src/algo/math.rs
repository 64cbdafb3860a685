//! Scalar maths shared by the algorithms.
//!
//! Every function here is correctly rounded, comes from `libm` (pure Rust),
//! or is plain f32 arithmetic written here, so the host and the Cortex-M4
//! produce bit-identical results (checked in the QEMU test suite).
//! `micromath` is not used where accuracy matters: its `sqrt(9.0)` returns
//! 3.125. The accuracy of [`lnf`] is measured against f64 in the tests.

/// `v.max(lo)` without libm's `fmaxf` (`f32::max` is a function call on
/// the Cortex-M4); NaN gives `lo`, as `max` does.
#[inline(always)]
pub fn at_least(v: f32, lo: f32) -> f32 {
    if v > lo {
        v
    } else {
        lo
    }
}

/// `v.max(lo).min(hi)` without libm's `fmaxf` and `fminf` (`f32::max` and
/// `f32::min` are function calls on the Cortex-M4: 230 instructions a turn
/// in the online calibration's solve); NaN gives `lo`, as `max` does.
#[inline(always)]
pub fn bound(v: f32, lo: f32, hi: f32) -> f32 {
    let v = at_least(v, lo);
    if v < hi {
        v
    } else {
        hi
    }
}

/// Square root, correctly rounded (IEEE 754). On the Cortex-M4F this is one
/// `vsqrt.f32` instruction; elsewhere it is `libm::sqrtf`. Both are correctly
/// rounded, so they agree bit for bit.
///
/// The FPU is told by the hard-float ABI (`eabihf`: every such ARM target
/// has VFP, and VSQRT.F32 is in every VFP). A `target_feature = "vfp2"`
/// test is never true on stable Rust (ARM's features are not reported to
/// `cfg`), and would leave the board on libm's software square root.
#[inline(always)]
pub fn sqrtf(x: f32) -> f32 {
    #[cfg(all(target_arch = "arm", target_abi = "eabihf"))]
    {
        // (The `sreg` operand class needs the double-precision `vfp2`
        // feature, which the Cortex-M4F lacks: go through a core register
        // and s15, declared clobbered.)
        let r: u32;
        // SAFETY: the three instructions only move between a core register
        // and s15 (declared clobbered) and take the root; no memory, no
        // stack, no flags.
        #[allow(unsafe_code)]
        unsafe {
            core::arch::asm!(
                "vmov s15, {x}",
                "vsqrt.f32 s15, s15",
                "vmov {r}, s15",
                x = in(reg) x.to_bits(),
                r = lateout(reg) r,
                out("s15") _,
                options(pure, nomem, nostack),
            );
        }
        f32::from_bits(r)
    }
    #[cfg(not(all(target_arch = "arm", target_abi = "eabihf")))]
    {
        libm::sqrtf(x)
    }
}

/// Natural logarithm, within 2 ulp over every positive normal and
/// subnormal f32 (test `lnf_is_within_2_ulp_of_f64`); ln 0 = −∞, ln ∞ = ∞,
/// negative or NaN gives NaN.
///
/// x = 2ᵉ·m with m in [√½, √2), s = (m − 1)/(m + 1), and
/// ln m = 2s(1 + s²/3 + s⁴/5 + s⁶/7 + s⁸/9) (|s| ≤ 0.1716, so the next term
/// is below 2⁻²⁹); e·ln 2 is added in two parts. About 25 instructions on the
/// Cortex-M4F, against about 46 for `libm::logf` (one division, no table).
#[inline]
pub fn lnf(x: f32) -> f32 {
    const LN2_HI: f32 = 0.693_145_75; // 12 significant bits: e·LN2_HI is exact
    const LN2_LO: f32 = 1.428_606_8e-6;
    let bits = x.to_bits();
    // Positive normal finite numbers are 0x0080_0000..=0x7f7f_ffff: one
    // unsigned compare sends zero, subnormals, ∞, NaN and negatives aside.
    if bits.wrapping_sub(0x0080_0000) >= 0x7f00_0000 {
        return lnf_special(x);
    }
    // m in [√½, √2): take one off the exponent when the mantissa is above
    // √2's (0x3504f3), all in integers.
    let mant = bits & 0x007f_ffff;
    let up = (mant > 0x0035_04f3) as u32;
    let e = (bits >> 23) as i32 - 127 + up as i32;
    let m = f32::from_bits(mant | (0x3f80_0000 - (up << 23)));
    let s = (m - 1.0) / (m + 1.0);
    let z = s * s;
    let p = z * (1.0 / 3.0 + z * (1.0 / 5.0 + z * (1.0 / 7.0 + z * (1.0 / 9.0))));
    let ef = e as f32;
    ef * LN2_HI + (ef * LN2_LO + (2.0 * s + 2.0 * s * p))
}

/// [`lnf`] off the fast path: zero, subnormals, ∞, NaN, negatives.
#[cold]
#[inline(never)]
fn lnf_special(x: f32) -> f32 {
    if x == 0.0 {
        f32::NEG_INFINITY
    } else if x == f32::INFINITY {
        x
    } else if x > 0.0 {
        // Subnormal: ln(x·2²³) − 23·ln 2, with x·2²³ normal.
        lnf(x * 8_388_608.0) - 23.0 * core::f32::consts::LN_2
    } else {
        f32::NAN
    }
}

/// e^x (libm, < 1 ulp).
#[inline]
pub fn expf(x: f32) -> f32 {
    libm::expf(x)
}

/// u64 → f32 as two 32-bit conversions (a u64 conversion is a library
/// call on the Cortex-M4). Rounds twice, so it can differ from `as f32` in
/// the last bit; the same on every target.
#[inline(always)]
pub fn u64_to_f32(x: u64) -> f32 {
    (x >> 32) as u32 as f32 * 4_294_967_296.0 + x as u32 as f32
}

/// i64 → f32 as a signed high half and a signed low half (an i64
/// conversion is a library call on the Cortex-M4): exact rounding for
/// |v| < 2³¹, where the high half is 0, and two roundings above. (The lag
/// sums were once split as a signed high and an *unsigned* low half: a
/// small negative sum then became −2³² + (2³² − |v|) with the low half
/// rounded to a multiple of 256 first, so every |v| < 128 read as 0 and a
/// white signal of a few LSB looked uncorrelated, ν 32 for 21.6.)
#[inline(always)]
pub fn i64_to_f32(v: i64) -> f32 {
    let hi = v.wrapping_add(1 << 31) >> 32;
    let lo = v.wrapping_sub(hi << 32) as i32;
    hi as i32 as f32 * 4_294_967_296.0 + lo as f32
}

/// u128 → f32, correctly rounded: equal to `as f32`, which is a library
/// call on the Cortex-M4 (≈ 65 instructions), with one 32-bit hardware
/// conversion instead. The top 32 significant bits, with a sticky bit for
/// any below them, round to 24 as the whole number does (the rounding
/// bit is bit 7); scaling by 2ˢ is exact. Checked against `as f32` by
/// `u128_to_f32_is_as_f32`.
#[inline(always)]
pub fn u128_to_f32(x: u128) -> f32 {
    let (hi, lo) = ((x >> 64) as u64, x as u64);
    if hi == 0 {
        if lo >> 32 == 0 {
            return lo as u32 as f32;
        }
        let s = 32 - lo.leading_zeros();
        let top = (lo >> s) as u32 | u32::from(lo << (64 - s) != 0);
        return top as f32 * f32::from_bits((127 + s) << 23);
    }
    let s = 96 - x.leading_zeros();
    let top = (x >> s) as u32 | u32::from(x << (128 - s) != 0);
    top as f32 * f32::from_bits((127 + s) << 23)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Distance in units in the last place between an f32 and the f64 truth.
    fn ulps(got: f32, want: f64) -> f64 {
        let w = want as f32;
        let ulp = (f32::from_bits(w.abs().to_bits() + 1) - w.abs()) as f64;
        (got as f64 - want).abs() / ulp
    }

    #[test]
    fn lnf_is_within_2_ulp_of_f64() {
        // Every 97th f32 bit pattern from the smallest subnormal to the
        // largest finite, plus a dense sweep around 1 (where ln → 0).
        let mut worst = (0.0f64, 0.0f32);
        let mut check = |x: f32| {
            let want = (x as f64).ln();
            let got = lnf(x);
            let u = if want == 0.0 {
                (got as f64).abs() / f32::EPSILON as f64
            } else {
                ulps(got, want)
            };
            if u > worst.0 {
                worst = (u, x);
            }
        };
        let mut b = 1u32;
        while b < 0x7f80_0000 {
            check(f32::from_bits(b));
            b += 97;
        }
        for i in -100_000..100_000 {
            check(1.0 + i as f32 * 1e-6);
        }
        println!("lnf: worst {} ulp at x = {:e}", worst.0, worst.1);
        assert!(worst.0 <= 2.0, "worst {} ulp at x = {:e}", worst.0, worst.1);
        assert_eq!(lnf(0.0), f32::NEG_INFINITY);
        assert_eq!(lnf(f32::INFINITY), f32::INFINITY);
        assert!(lnf(-1.0).is_nan() && lnf(f32::NAN).is_nan());
        assert_eq!(lnf(1.0), 0.0);
    }

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
