//! The degrees of freedom of a frame's τ0 energy, learnt from the data:
//! what the segmentation's χ² model and its threshold take as ν.

use super::SEG;
use crate::algo::math::{i64_to_f32, sqrtf};

/// Memory of the lag-correlation estimates, frames.
const RHO_FRAMES: f32 = 32.0;

/// Memory of the fourth-moment estimates, frames: the tails of a sensor's
/// noise change slowly, and their estimates are noisier than ρ's (ν from
/// them has sd ≈ 3 % over 512 frames on white noise).
const QUAD_FRAMES: f32 = 512.0;

/// Frames before the fourth moments are used at all.
const QUAD_MIN: u32 = 32;

/// ν falls below the Gaussian value only where the fourth-moment one lies
/// this far below it ([`super::Davar::nu`], continuous at the gate): its noise
/// then never moves a Gaussian signal's ν, while heavy tails or sub-LSB
/// rounding (ν_4 at half ν_G or less) get theirs.
const TAIL_GATE: f32 = 0.85;

/// Prior for ν before enough frames are seen: 32 first differences of white
/// noise (lag-1 correlation −½ gives ν = 32²/(32 + 62/4) ≈ 21.6).
pub(super) const NU_WHITE: f32 = 21.6;

/// ν of one frame's τ0 energy (32 squared first differences), from the
/// differences' lag correlations and their squares' covariances, each a
/// running mean over the frames.
#[derive(Clone, Debug)]
pub(super) struct FrameDof {
    /// Running lag-1, lag-2 correlations of the τ0 differences.
    rho: [f32; 2],
    /// Running (over [`QUAD_FRAMES`]) covariances of q at lags 0, 1, 2 and
    /// σ⁴ (the mean q·q₊₃), each frame's in its own scale (the ratios taken
    /// in `nu` weigh frames by σ⁴), and the frames seen.
    cov_q: [f32; 4],
    quad_frames: u32,
}

impl FrameDof {
    /// Nothing learnt: white noise's ν.
    pub(super) fn new() -> Self {
        Self {
            rho: [-0.5, 0.0],
            cov_q: [0.0; 4],
            quad_frames: 0,
        }
    }
    /// Fold the frame's lag sums into the running correlations.
    pub(super) fn learn_lags(&mut self, [s0, s1, s2]: [i64; 3]) {
        if s0 > 0 {
            let s0 = i64_to_f32(s0);
            for (r, s) in self.rho.iter_mut().zip([s1, s2]) {
                *r += (i64_to_f32(s) / s0 - *r) / RHO_FRAMES;
            }
        }
    }
    /// Fold the fourth moments of the τ0 terms `from..=to` of `ring` (a
    /// frame's) into the running covariances of q = d² (ν from them:
    /// [`Self::nu`]), on a sample of the hop of its own. Out of line, like
    /// `refine_part`, so that `push`'s other samples do not carry it.
    #[inline(never)]
    pub(super) fn learn_tails<const CAP: usize>(&mut self, ring: &[i32; CAP], from: u64, to: u64) {
        // (usize indices: the Cortex-M4 does u64 arithmetic in pairs.)
        let (from, count, mask) = (from as usize, (to - from) as usize + 1, CAP - 1);
        let ([mut u0, mut u1, mut u2, mut u3], [mut q1, mut q2, mut q3]) =
            ([0.0f32; 4], [0.0f32; 3]);
        for i in from..from + count {
            let d = (ring[(i + 1) & mask] - ring[i & mask]) as f32;
            let q = d * d;
            u0 += q * q;
            u1 += q * q1;
            u2 += q * q2;
            u3 += q * q3;
            (q1, q2, q3) = (q, q1, q2);
        }
        // Pairs at lag 3 are independent (d = w₁ − w₀ shares no sample
        // with d₊₃, and rate noise is near white at that lag), so their
        // mean is σ⁴ = (E q)², taken inside the frame so that a variance
        // change between frames does not enter; lags 0–2 less σ⁴ are the
        // covariances of q.
        let n = count as u32 as f32;
        if n >= 8.0 {
            let sig4 = u3 / (n - 3.0);
            let c = [
                u0 / n - sig4,
                u1 / (n - 1.0) - sig4,
                u2 / (n - 2.0) - sig4,
                sig4,
            ];
            for (m, c) in self.cov_q.iter_mut().zip(c) {
                *m += (c - *m) / QUAD_FRAMES;
            }
            self.quad_frames = self.quad_frames.saturating_add(1);
        }
    }

    /// ν: the model is on the public [`super::Davar::nu`].
    pub(super) fn nu(&self) -> f32 {
        let [r1, r2] = self.rho;
        let s = SEG as f32;
        let gauss = s * s / (s + 2.0 * (s - 1.0) * r1 * r1 + 2.0 * (s - 2.0) * r2 * r2);
        let [c0, c1, c2, sig4] = self.cov_q;
        let var = s * c0 + 2.0 * (s - 1.0) * c1 + 2.0 * (s - 2.0) * c2;
        if self.quad_frames < QUAD_MIN || !(var > 0.0) || !(sig4 > 0.0) {
            return gauss;
        }
        let r = 2.0 * s * s * sig4 / var / TAIL_GATE / gauss;
        if r >= 1.0 {
            gauss
        } else {
            gauss * r * sqrtf(r)
        }
    }
}
