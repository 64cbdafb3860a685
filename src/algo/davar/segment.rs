//! Segmentation of the λ2 span by optimal partitioning (penalised
//! likelihood, dynamic programming, one row per sample) of the frames' τ0
//! energies under a scaled-χ²_ν model, with ν and the tails learnt from
//! the data.

use super::{Davar, EntropyKind, Placement, Threshold, BINS, CELLS};
use crate::algo::stats::chi2_quantile;

impl<const CAP: usize, const FRAMES: usize, const T: usize, const STFT: usize>
    Davar<CAP, FRAMES, T, STFT>
{
    /// The tabulated threshold for `k` frames (every k a window of this
    /// configuration can have is tabulated at construction).
    pub(super) fn threshold_for(&self, k: usize) -> f32 {
        self.thresholds.get(k).copied().unwrap_or(f32::INFINITY)
    }
    /// Threshold for `frames` frames (see [`Threshold`]).
    pub(super) fn quantile_for(&self, frames: usize) -> f32 {
        let p_fa = match self.cfg.threshold {
            Threshold::Fixed(v) => return v,
            Threshold::Auto { p_fa } => p_fa as f64,
        };
        let k = frames.max(2) as f64;
        let b = BINS as f64;
        match (self.cfg.placement, self.cfg.entropy) {
            (Placement::Segmented, _) => {
                // Penalty per change: the χ²₁ likelihood ratio of one split,
                // Bonferroni over the k − 1 splits of a k-frame span.
                chi2_quantile(1.0 - p_fa / (k - 1.0), 1.0).unwrap_or(10.0) as f32
            }
            (Placement::Centred, EntropyKind::Temporal) => {
                // D ≈ χ²_{K−1} / (K ν), ν = 2·BINS (white noise).
                let q = chi2_quantile(1.0 - p_fa, k - 1.0).unwrap_or(k);
                (q / (k * 2.0 * b)) as f32
            }
            (Placement::Centred, EntropyKind::Spectral) => {
                // Deficit ≈ χ²_{B−1}/(B·2K); E = 1 − deficit/ln B, and the
                // paper's rule shrinks on *large* E: use the upper quantile
                // of E, i.e. the lower quantile of the deficit.
                let q = chi2_quantile(p_fa, b - 1.0).unwrap_or(1.0);
                (1.0 - q / (b * 2.0 * k) / libm::log(b)) as f32
            }
        }
    }
    /// Start segmenting the span of frames `first..first + span`: snapshot
    /// the cells' energies and compute the first row.
    pub(super) fn dp_start(&mut self, first: u64) {
        // (span < FRAMES and cells ≤ CELLS by construction; the `min`s let
        // the compiler see it.)
        let (g, k) = (self.dp.group, self.span.min(FRAMES - 1));
        // Prefix sums of the span's τ0 frame energies, kept for
        // `segment_window`; the cells' sums are read off them.
        let s0 = self.sums.slot_of(first).min(FRAMES - 1);
        let run = k.min(FRAMES - s0);
        let mut acc = 0.0f32;
        self.px[0] = 0.0;
        // The span's frames wrap the ring at most once: two plain loops
        // (a chained iterator cost ~1 000 more instructions at λ2 = 4096).
        let (head, tail) = self.px[1..=k].split_at_mut(run.min(k));
        let xs = (
            self.sums.x0.get(s0..s0 + run).unwrap_or(&[]),
            self.sums.x0.get(..k - run).unwrap_or(&[]),
        );
        for (p, &x) in head.iter_mut().zip(xs.0) {
            acc += x;
            *p = acc;
        }
        for (p, &x) in tail.iter_mut().zip(xs.1) {
            acc += x;
            *p = acc;
        }
        for cell in 0..=self.dp.cells.min(CELLS) {
            self.dp.sum[cell] = self.px[(cell * g).min(k)];
        }
        self.dp.first = Some(first);
        self.dp.nu = self.nu();
        self.dp.beta = self.threshold_for(k);
        self.dp.cost[0] = -self.dp.beta;
        self.dp.row = 1;
        self.dp_row();
    }
    /// One row of the optimal partitioning (Jackson et al. 2005): the best
    /// cost of cells 0..j over the start i of its last segment, with the
    /// scaled-χ² (Gamma) segment cost ν·n·ln(mean) and a penalty β per
    /// segment. At most 32 cells per row, one `lnf` per cell.
    pub(super) fn dp_row(&mut self) {
        let j = self.dp.row.min(CELLS);
        let (g, k) = (self.dp.group.max(1), self.span.min(FRAMES - 1));
        let frames = |c: usize| (c * g).min(k);
        let (nu, sj, nj) = (self.dp.nu, self.dp.sum[j], frames(j));
        let (mut best, mut arg) = (f32::INFINITY, 0u8);
        // Segment [i, j) has nf = nj − i·g frames (the last cell may be
        // short, so j's own frame count is nj): walk nf and ln nf down.
        let ln_nf = self.ln_n[..=nj].iter().rev().step_by(g);
        let mut nff = nj as f32;
        let gf = g as f32;
        for (i, ((&si, &ci), &ln_nf)) in self.dp.sum[..j]
            .iter()
            .zip(&self.dp.cost[..j])
            .zip(ln_nf)
            .enumerate()
        {
            // Frame energies of integer samples are 0 or ≥ 1: the floor
            // only guards an all-zero segment.
            let d = sj - si;
            let c = ci + nu * nff * (ln_floored(d) - ln_nf);
            nff -= gf;
            if c < best {
                best = c;
                arg = i as u8;
            }
        }
        self.dp.cost[j] = best + self.dp.beta;
        self.dp.arg[j] = arg;
        self.dp.row = j + 1;
    }
    /// The finished segmentation's segment bounds in frames, backtracked
    /// into `dp.bounds` (0 = b₀ < b₁ < … < b_nb = k); returns nb.
    pub(super) fn backtrack(&mut self) -> usize {
        let (g, k) = (self.dp.group.max(1), self.span.min(FRAMES - 1));
        let cells = self.dp.cells.min(CELLS);
        let bounds = &mut self.dp.bounds;
        let mut nb = 0;
        let mut j = cells;
        while j > 0 && nb < CELLS {
            bounds[nb] = (j * g).min(k) as u16;
            nb += 1;
            j = self.dp.arg.get(j).map_or(0, |&a| a as usize).min(j - 1);
        }
        let nb = nb.min(CELLS);
        bounds[nb] = 0;
        bounds[..=nb].reverse();
        nb
    }
}

/// The segmentation's cost of frames i..j of its span: ν·n·(ln Σx − ln n)
/// over the frame prefix sums `px` (indices from the segmentation are in
/// range; `get` keeps that from being a panic path if it ever were not).
#[inline(always)]
pub(super) fn seg_cost(px: &[f32], ln_n: &[f32], nu: f32, i: usize, j: usize) -> f32 {
    let p = |i: usize| px.get(i).copied().unwrap_or(0.0);
    let nf = j.saturating_sub(i);
    let sum = p(j) - p(i);
    let ln_nf = ln_n.get(nf).copied().unwrap_or(0.0);
    nu * nf as f32 * (ln_floored(sum) - ln_nf)
}

/// Cost of a blurred step over the span's frames l..r (same scale as
/// [`seg_cost`]): the means of [l, c − h) and [c + h, r), joined by a
/// linear transition over [c − h, c + h) taken in chunks of q frames. None
/// where it does not fit in l..r or its mean is not positive.
pub(super) fn transition_cost(
    px: &[f32],
    ln_n: &[f32],
    nu: f32,
    (l, c, r): (usize, usize, usize),
    h: usize,
    q: usize,
) -> Option<f32> {
    let p = |i: usize| px.get(i).copied().unwrap_or(0.0);
    let (a, e) = (c.checked_sub(h)?, c + h);
    if a <= l || e >= r || q == 0 {
        return None;
    }
    let m1 = (p(a) - p(l)) / (a - l) as f32;
    let m2 = (p(r) - p(e)) / (r - e) as f32;
    let mut cost = seg_cost(px, ln_n, nu, l, a) + seg_cost(px, ln_n, nu, e, r);
    let (slope, mut f) = ((m2 - m1) / (2 * h) as f32, a);
    while f < e {
        let g = (f + q).min(e);
        let mu = m1 + slope * (0.5 * (f + g) as f32 - a as f32);
        if !(mu > 0.5) {
            return None;
        }
        cost += nu * ((g - f) as f32 * (ln_fast(mu) - 1.0) + (p(g) - p(f)) / mu);
        f = g;
    }
    Some(cost)
}

/// `ln_fast(max(x, 0.5))`, bit for bit, for x not NaN: the floor taken on
/// the bits as a signed integer (which order as the values do for x ≥ 0,
/// and put every negative x below 0.5). A float compare and select cost
/// the segmentation's inner loop 2 instructions more a cell.
#[inline(always)]
pub(super) fn ln_floored(x: f32) -> f32 {
    const HALF: i32 = 0x3f00_0000; // 0.5f32.to_bits()
    ln_fast(f32::from_bits((x.to_bits() as i32).max(HALF) as u32))
}

/// ln x for normal x ≥ 0.5 to 8e-5 (absolute): the exponent, and a degree-4
/// polynomial in the mantissa − 1 (fitted by iterated weighted least
/// squares, max error measured in `ln_fast_accuracy`). About 12
/// instructions with no division: the segmentation's cells need one each,
/// and an error of 8e-5 × ν·n ≤ 0.06 in a cell's cost is far below the
/// penalty (≈ 13) that decides a change.
#[inline(always)]
pub(super) fn ln_fast(x: f32) -> f32 {
    const C: [f32; 4] = [0.997_450_25, -0.471_311_77, 0.225_708_22, -0.058_771_09];
    let bits = x.to_bits();
    let e = (bits >> 23) as i32 - 127;
    // The mantissa as a float in [1, 2): the bits with the exponent e taken
    // out, (bits & 0x7f_ffff) | 0x3f80_0000 written as one subtraction of
    // the e already at hand (the mask took the Cortex-M4 4 instructions).
    let u = f32::from_bits(bits.wrapping_sub((e as u32) << 23)) - 1.0;
    let p = u * (C[0] + u * (C[1] + u * (C[2] + u * C[3])));
    e as f32 * core::f32::consts::LN_2 + p
}
