//! Publication: the placed window's sums, spread over three samples, and
//! the estimate a reader sees.

use super::{Davar, Published, SEG};
use crate::algo::math::u128_to_f32;

impl<const CAP: usize, const FRAMES: usize, const T: usize, const STFT: usize>
    Davar<CAP, FRAMES, T, STFT>
{
    /// Publish the window [lo, hi) (frames) of the span starting at frame
    /// `prev`: its estimate describes the span's centre.
    pub(super) fn publish_placed(&mut self, prev: u64, lo: usize, hi: usize) -> u64 {
        let (t, f0, f1) = self.placed_window(prev, lo, hi);
        self.publish(t, f0, f1)
    }
    /// The time and frames [f0, f1) of window [lo, hi) of the span at
    /// `prev`.
    pub(super) fn placed_window(&self, prev: u64, lo: usize, hi: usize) -> (u64, u64, u64) {
        let half = (SEG * self.span / 2) as u64;
        (SEG as u64 * prev + half, prev + lo as u64, prev + hi as u64)
    }
    /// Sum the exact window sums of frames [f0, f1), keep them, return t.
    pub(super) fn publish(&mut self, t: u64, f0: u64, f1: u64) -> u64 {
        self.sums.window_sums(f0, f1, 0..T);
        self.finish_publish(t, f0, f1)
    }
    /// Publish window [f0, f1) at time t from its whole-block sums (all τ
    /// done by `Sums::window_sums`) and the last blocks' prefixes.
    pub(super) fn finish_publish(&mut self, t: u64, f0: u64, f1: u64) -> u64 {
        let acc = self.sums.window_total(f0);
        self.last = Some(Published {
            t,
            start: f0 * SEG as u64,
            end: f1 * SEG as u64,
            acc,
        });
        self.edition = self.edition.wrapping_add(1);
        t
    }
    /// σ² at τ_j = 2^(j·`octaves`) from a published window's exact sums
    /// (0 where the window has no term at that τ).
    pub(super) fn avar_of(p: &Published<T>, j: usize, octaves: u8) -> f32 {
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
                // calls: 300 instructions per link frame that carries an
                // estimate, on the Cortex-M4. A window has < 2³² terms.)
                u128_to_f32(acc) / (terms.min(u64::from(u32::MAX)) as u32) as f32 * inv_2m2
            }
            _ => 0.0,
        }
    }
}
