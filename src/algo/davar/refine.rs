//! Refinement of the segmentation's change points, and the tests that
//! tell a step from a gradual change (a line over the step, t's own
//! slope).

use super::segment::seg_cost;
use super::sums::ahead;
use super::{Davar, CELLS, LAG, REFINE_PARTS};
use crate::algo::math::at_least;

impl<const CAP: usize, const FRAMES: usize, const T: usize, const STFT: usize>
    Davar<CAP, FRAMES, T, STFT>
{
    /// Part `part` (of [`REFINE_PARTS`]) of the refinement: its share of
    /// the changes, in order. Out of line: inlined in `push`, it cost every
    /// sample 33 instructions.
    #[inline(never)]
    pub(super) fn refine_part(&mut self, part: usize) {
        let (Some(prev), Some(_)) = (self.dp.first, self.dp.next_first) else {
            return;
        };
        while self.dp.row <= self.dp.cells {
            self.dp_row();
        }
        let (nb, next) = self.refining(prev);
        let to = (1 + nb.saturating_sub(1) * (part + 1) / REFINE_PARTS)
            .min(nb)
            .max(next);
        self.refine(nb, next..to);
        self.dp.refined = Some((prev, nb, to));
    }
    /// The refinement of the span at `first` so far (the count of
    /// `dp.bounds` less one, the next change to refine), or its start.
    pub(super) fn refining(&mut self, first: u64) -> (usize, usize) {
        match self.dp.refined {
            Some((f, nb, next)) if f == first => (nb, next),
            _ => (self.backtrack(), 1),
        }
    }
    /// Refine changes `which` (in order) of `dp.bounds` (nb segments) to the
    /// frame: the cells group g frames, and each change moves to the best
    /// split of its two segments within ± (g − 1) frames (every frame for
    /// g < 4; else, near a change the last segmentation placed, that frame
    /// and the two beside it, and otherwise every other frame and then the
    /// two beside the best).
    #[inline(never)]
    pub(super) fn refine(&mut self, nb: usize, which: core::ops::Range<usize>) {
        let g = self.dp.group.max(1);
        if g <= 1 {
            return;
        }
        // The changes the last segmentation placed: the span's blocks
        // that carry its stamp.
        let first = self.dp.first.unwrap_or(0);
        let last =
            (self.dp.recent_len > 0).then(|| self.dp.recent[(self.dp.recent_at + LAG - 1) % LAG]);
        let s0 = self.sums.slot_of(first).min(FRAMES - 1);
        // Over the span's frame prefix sums (from `dp_start`).
        let (px, ln_n, nu) = (&self.px, &self.ln_n, self.dp.nu);
        let bounds = &mut self.dp.bounds;
        let cost = |i: usize, j: usize| seg_cost(px, ln_n, nu, i, j);
        let bd = |b: &[u16; CELLS + 1], i: usize| b.get(i).copied().unwrap_or(0) as usize;
        let marks = &self.marks;
        let placed_last =
            |q: usize| last.is_some_and(|l| marks.get(ahead::<FRAMES>(s0, q)) == Some(&l));
        for i in which.start.max(1)..which.end.min(nb) {
            let (l, c, r) = (bd(bounds, i - 1), bd(bounds, i), bd(bounds, i + 1));
            let (lo, hi) = (c.saturating_sub(g - 1).max(l + 1), (c + g).min(r));
            let split = |q: usize| (cost(l, q) + cost(q, r), q);
            let keep = |best: (f32, usize), q: usize| {
                let v = split(q);
                if v.0 < best.0 {
                    v
                } else {
                    best
                }
            };
            // The best of `best` and the frames on either side of it.
            let beside = |best: (f32, usize)| {
                [best.1.wrapping_sub(1), best.1 + 1]
                    .into_iter()
                    .filter(|q| (lo..hi).contains(q))
                    .fold(best, keep)
            };
            let near = || (lo..hi).find(|&q| placed_last(q));
            let best = if g < 4 {
                (lo..hi).filter(|&q| q != c).fold(split(c), keep)
            } else if let Some(p) = near() {
                // The last segmentation refined a change within reach: a
                // step's split moves little from one hop to the next, so
                // look there and beside it (3 costs for 2g − 1).
                beside(split(p))
            } else {
                // Every other frame from c, then the two beside the best:
                // g + 1 costs for 2g − 1 (λ2 ≥ 2048 only; the split's cost
                // is smooth at that scale).
                beside(
                    (lo..hi)
                        .filter(|&q| q != c && q.abs_diff(c) % 2 == 0)
                        .fold(split(c), keep),
                )
            };
            if let Some(b) = bounds.get_mut(i) {
                *b = best.1 as u16;
            }
        }
    }
}

/// How much better one line explains the frame energies of l..r than the
/// step at c does, in cost units: (SS_line − SS_step)·ν/(2m²), the sums of
/// squares the least-squares line and the two segment means explain,
/// scaled by the variance 2m²/ν of a frame energy at the pooled mean m.
/// That is the second-order form of the difference of their Gamma
/// deviances, from the prefix sums alone: r − l additions and no
/// logarithm, so the board's placement sample can afford it. −∞ where it
/// does not apply.
#[cfg(test)]
pub(super) fn line_over_step(px: &[f32], nu: f32, (l, c, r): (usize, usize, usize)) -> f32 {
    line_over_step_from(px, nu, (l, c, r), line_sums(px, l, r))
}

/// `line_over_step` with [`line_sums`] over l..r already made.
pub(super) fn line_over_step_from(
    px: &[f32],
    nu: f32,
    (l, c, r): (usize, usize, usize),
    (m, sfc, sxx): (f32, f32, f32),
) -> f32 {
    if c <= l || r <= c || r < l + 3 || !(m > 0.5) {
        return f32::NEG_INFINITY;
    }
    (sfc * sfc / sxx - step_ss(px, (l, c, r))) * nu / (2.0 * m * m)
}

/// The sum of squares about the mean of l..r that the two segment means
/// of l..c and c..r explain (l < c < r), from the prefix sums.
fn step_ss(px: &[f32], (l, c, r): (usize, usize, usize)) -> f32 {
    let p = |i: usize| px.get(i).copied().unwrap_or(0.0);
    let (n, n1, n2) = ((r - l) as f32, (c - l) as f32, (r - c) as f32);
    let d = (p(c) - p(l)) / n1 - (p(r) - p(c)) / n2;
    n1 * n2 / n * d * d
}

/// How much better two lines joined at the best knot explain the frame
/// energies of l..r than the step at c does, in the cost units of
/// `line_over_step` (the same second-order form of the Gamma deviances,
/// from the prefix sums). A hinge (a level that starts to slope, or a
/// slope that levels off) is a gradual change that one line through both
/// segments fits poorly, so the step at c wins the line test and bounds
/// the window, one-sided on the slope; joined lines fit it. The knot is
/// free (every other frame boundary with two frames on either side), not the
/// step's c: on a ramp the segmentation puts c where the noise makes the
/// step look best, often far from where the slope starts, and lines forced
/// to join there fall short of a step that chose its place. A sharp step
/// is explained about three quarters by joined lines wherever their knot
/// falls (one knot cannot both rise and level off), so a step shows as a
/// deficit of about a quarter of its gain. −∞ where it does not apply.
#[cfg(test)]
pub(super) fn hinge_over_step(px: &[f32], nu: f32, (l, c, r): (usize, usize, usize)) -> f32 {
    hinge_over_step_from(px, nu, (l, c, r), line_sums(px, l, r))
}

/// `hinge_over_step` with [`line_sums`] over l..r already made. One walk
/// from r down to l: for a knot at κ the regressors are the frame index
/// and w = f − κ + ½ on the frames f ≥ κ (0 before), whose sums are
/// closed forms in the count on the right, and whose product with the
/// energies follows from the previous knot's (R₁(κ) = R₁(κ+1) + R₀(κ+1),
/// R₀ the energy from κ on, R₁ = Σ (f − κ)·x_f): O(1) a knot, no
/// second pass.
pub(super) fn hinge_over_step_from(
    px: &[f32],
    nu: f32,
    (l, c, r): (usize, usize, usize),
    (m, sfc, sxx): (f32, f32, f32),
) -> f32 {
    let p = |i: usize| px.get(i).copied().unwrap_or(0.0);
    if c < l + 2 || r < c + 2 || !(m > 0.5) {
        return f32::NEG_INFINITY;
    }
    let n = (r - l) as f32;
    // The explained sum of squares of (f, w) about their means is the
    // line's, sfc²/sxx, plus w's part orthogonal to f: (cwe − b·sfc)² over
    // cww − cxw²/sxx, b = cxw/sxx. (The 2 × 2 form gᵀA⁻¹g of the same
    // cancels to a few digits where w is nearly f.) Knot r − 1 starts the
    // running sums; every other knot from r − 2 down to l + 2 is scored
    // (a knot a frame off changes the explained sum little, and the
    // scan's cost on the board's placement sample halves).
    let (pr, slope, half_m) = (p(r), sfc / sxx, 0.5 * m);
    let (mut r0, mut r1, mut mr, mut best) = (pr - p(r - 1), 0.0f32, 1.0f32, 0.0f32);
    for (i, &pk) in px.get(l + 2..r - 1).unwrap_or(&[]).iter().rev().enumerate() {
        r1 += r0;
        r0 = pr - pk;
        mr += 1.0;
        if i % 2 == 1 {
            continue;
        }
        let (nl, m2) = (n - mr, mr * mr);
        let sww = mr * (4.0 * m2 - 1.0) * (1.0 / 12.0);
        let cxw = sww + 0.25 * (nl - mr) * m2;
        let e = r1 + 0.5 * r0 - half_m * m2 - cxw * slope;
        // 144 (sxx·cww − cxw²), factored: positive with two frames a side.
        let q = mr * nl;
        let det = q * (4.0 * q * q - 3.0 * q - m2 - nl * nl + 1.0);
        best = best.max(e * e / det);
    }
    let hinge = sfc * slope + 144.0 * sxx * best;
    (hinge - step_ss(px, (l, c, r))) * nu / (2.0 * m * m)
}

/// The slope of the frames' energies over l..r, squared, over its own
/// variance under the scaled-χ²_ν model at their mean (a z²), and whether
/// it rises. None where fewer than 4 frames or a mean not positive.
pub(super) fn slope_z2(px: &[f32], nu: f32, (l, r): (usize, usize)) -> Option<(f32, bool)> {
    if r < l + 4 {
        return None;
    }
    let (m, sfc, sxx) = line_sums(px, l, r);
    if !(m > 0.0) {
        return None;
    }
    Some((sfc * sfc / sxx * nu / (2.0 * m * m), sfc > 0.0))
}

/// Over the frames l..r (r > l) of the prefix sums `px`: their mean
/// energy, Σ (f − f̄)·x_f and Σ (f − f̄)², the sums of a least-squares line.
pub(super) fn line_sums(px: &[f32], l: usize, r: usize) -> (f32, f32, f32) {
    let p = |i: usize| px.get(i).copied().unwrap_or(0.0);
    let n = (r - l) as f32;
    let s = p(r) - p(l);
    // Σ (f − l)·x_f = n·P(r) − Σ_{j = l+1..=r} P(j) (P the prefix sums;
    // P(l) cancels), then about the centre l + (n − 1)/2.
    // (Four running sums: fewer instructions than one at λ2 = 4096.)
    let w = px.get(l + 1..=r).unwrap_or(&[]);
    let mut quads = w.chunks_exact(4);
    let mut acc = [0.0f32; 4];
    for q in &mut quads {
        for (a, &v) in acc.iter_mut().zip(q) {
            *a += v;
        }
    }
    let sp = (acc[0] + acc[1]) + (acc[2] + acc[3]) + quads.remainder().iter().sum::<f32>();
    let sfc = n * p(r) - sp - 0.5 * (n - 1.0) * s;
    (s / n, sfc, n * (n * n - 1.0) / 12.0)
}

/// |ln(a/b)| without a logarithm: max(a, b)/min(a, b) orders the same way.
pub(super) fn ratio_gap(a: f32, b: f32) -> f32 {
    let (a, b) = (
        at_least(a, f32::MIN_POSITIVE),
        at_least(b, f32::MIN_POSITIVE),
    );
    if a > b {
        a / b
    } else {
        b / a
    }
}
