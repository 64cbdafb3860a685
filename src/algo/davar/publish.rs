//! A published window: its time, edges and exact sums, and σ² from them.

use crate::algo::math::u128_to_f32;

/// Exact window sums of one published hop.
#[derive(Clone, Copy, Debug)]
pub(super) struct Published<const T: usize> {
    pub(super) t: u64,
    pub(super) start: u64,
    pub(super) end: u64,
    pub(super) acc: [u128; T],
}

impl<const T: usize> Published<T> {
    /// σ² at τ_j = 2^(j·`octaves`) from the window's exact sums (0 where
    /// the window has no term at that τ).
    pub(super) fn avar(&self, j: usize, octaves: u8) -> f32 {
        let p = self;
        let len = p.end - p.start;
        let e = j * octaves as usize;
        let m = 1u64 << e;
        let terms = (len + 1).saturating_sub(2 * m);
        match p.acc.get(j) {
            // In f32 (the board's FPU): the exact integer sum and the term
            // count rounded once each, one division, then the exact power
            // of two 1/(2m²). Within 2 ulp of the f64 quotient (checked by
            // `avar_in_f32_is_within_two_ulp_of_f64`), and a tenth of the
            // soft-f64 cost on the Cortex-M4 (`cargo xtask bench`).
            Some(&acc) if terms > 0 => {
                let inv_2m2 = f32::from_bits((127 - 1 - 2 * e as u32) << 23);
                // (Both conversions equal `as f32`, without the library
                // calls. A window has < 2³² terms.)
                u128_to_f32(acc) / (terms.min(u64::from(u32::MAX)) as u32) as f32 * inv_2m2
            }
            _ => 0.0,
        }
    }
}
