//! The segmented placement: the λ2 span segmented by optimal partitioning
//! (penalised likelihood, dynamic programming, one row per sample) of the
//! frames' τ0 energies under a scaled-χ²_ν model, its change points
//! refined to the frame, and the window the segment that holds t, widened
//! to λ1, or symmetric about t where the change next to it is gradual.

use core::cell::Cell;

use super::dof::NU_WHITE;
use super::shape::{hinge_over_step_from, line_over_step_from, line_sums, ratio_gap, slope_z2};
use super::sums::ahead;
use super::{
    cell_group, stale, CELLS, FAR_Z2, GRADUAL, HINGE_MAX_GAIN, HINGE_SLACK, LAG, REFINE_PARTS, SEG,
    SLOPE_Z2, STRONG,
};

/// Optimal partitioning of one span (Segmented placement), computed one
/// row per sample over the hop after the span completed.
#[derive(Clone, Debug)]
#[repr(C)]
pub(super) struct Segmentation<const FRAMES: usize> {
    /// Frames in the span (λ2 rounded down), the shortest window in
    /// frames, and λ1 in samples.
    span: usize,
    min_frames: usize,
    lambda1: usize,
    /// First frame of the span being segmented, if any.
    pub(super) first: Option<u64>,
    /// First frame of the span to segment next (noted at the hop, started
    /// [`START_AT`] samples later).
    pub(super) next_first: Option<u64>,
    /// The window placed at [`PLACE_AT`] (span's first frame, window
    /// frames), published at [`PUBLISH_AT`].
    pub(super) placed: Option<(u64, usize, usize)>,
    /// The refinement under way from [`REFINE_AT`] (span's first frame,
    /// the count of `bounds` less one, the next change to refine).
    refined: Option<(u64, usize, usize)>,
    /// The segment bounds of the segmentation being refined (or placed),
    /// in place (never copied: 33 bounds at most).
    bounds: [u16; CELLS + 1],
    /// Frames per cell and cells.
    group: usize,
    pub(super) cells: usize,
    /// Prefix sums of the cells' τ0 energies.
    sum: [f32; CELLS + 1],
    /// Optimal cost of cells 0..j and the start of its last segment.
    cost: [f32; CELLS + 1],
    arg: [u8; CELLS + 1],
    /// Next row to compute (1..=cells; cells + 1 when done).
    pub(super) row: usize,
    nu: f32,
    beta: f32,
    /// Stamps of the last [`LAG`] segmentations (their first frames, as
    /// u16; the first `recent_len` of them valid, the next written at
    /// `recent_at`): their changes are the blocks whose `marks` carry one
    /// of them.
    recent: [u16; LAG],
    recent_len: u8,
    recent_at: usize,
    /// Per block, the stamp (first frame, as u16) of the last
    /// segmentation that put a change at it (`marks`), or within a frame of
    /// it (`marks_near`); a stale stamp from the time the block completed
    /// otherwise ([`stale`]). Whether one of the last [`LAG`]
    /// segmentations had a change within a frame of c is then one read,
    /// however many changes each placed.
    marks: [u16; FRAMES],
    marks_near: [u16; FRAMES],
    /// Prefix sums of x0 over the span being segmented.
    px: [f32; FRAMES],
    /// ln n for n = 0..FRAMES (ln 0 unused).
    ln_n: [f32; FRAMES],
    /// The last window's gain over one segment (its score).
    gain: f32,
}

impl<const FRAMES: usize> Segmentation<FRAMES> {
    /// An idle segmentation of spans of `span` frames, with a shortest
    /// window of `min_frames` frames (λ1 = `lambda1` samples).
    pub(super) fn new(span: usize, min_frames: usize, lambda1: usize) -> Self {
        let group = cell_group(span, min_frames);
        let mut s = Self {
            span,
            min_frames,
            lambda1,
            first: None,
            next_first: None,
            placed: None,
            refined: None,
            bounds: [0; CELLS + 1],
            group,
            cells: span.div_ceil(group),
            sum: [0.0; CELLS + 1],
            cost: [0.0; CELLS + 1],
            arg: [0; CELLS + 1],
            row: 0,
            nu: NU_WHITE,
            beta: 0.0,
            recent: [0; LAG],
            recent_len: 0,
            recent_at: 0,
            marks: [stale(0); FRAMES],
            marks_near: [stale(0); FRAMES],
            px: [0.0; FRAMES],
            ln_n: [0.0; FRAMES],
            gain: 0.0,
        };
        for (i, v) in s.ln_n.iter_mut().enumerate().skip(1) {
            *v = ln_fast(i as f32);
        }
        s
    }
    /// Forget every span (after a gap in the input).
    pub(super) fn reset(&mut self) {
        self.first = None;
        self.next_first = None;
        self.placed = None;
        self.refined = None;
        self.row = 0;
        // (The valid stamps are the first `recent_len`: start at 0.)
        (self.recent_len, self.recent_at) = (0, 0);
        // (Every block a later segmentation reads completes after this and
        // is made stale then; cleared here all the same.)
        self.marks = [stale(0); FRAMES];
        self.marks_near = [stale(0); FRAMES];
    }
    /// Block `block` (in slot `slot`) has just completed: no segmentation
    /// has put a change at it yet.
    #[inline(always)]
    pub(super) fn block_completed(&mut self, block: u64, slot: usize) {
        if let (Some(m), Some(n)) = (self.marks.get_mut(slot), self.marks_near.get_mut(slot)) {
            (*m, *n) = (stale(block), stale(block));
        }
    }
    /// The last window's score: what the segmentation gained over one
    /// segment, and the penalty per change it was weighed against.
    pub(super) fn score(&self) -> (f32, f32) {
        (self.gain, self.beta)
    }
    /// Start segmenting the span of frames `first..first + span` (its
    /// first block in slot `s0` of the τ0 energies `x0`) with ν `nu` and
    /// the penalty `beta` per change: snapshot the cells' energies and
    /// compute the first row.
    pub(super) fn start(&mut self, first: u64, s0: usize, x0: &[f32; FRAMES], nu: f32, beta: f32) {
        // (span < FRAMES and cells ≤ CELLS by construction; the `min`s let
        // the compiler see it.)
        let (g, k) = (self.group, self.span.min(FRAMES - 1));
        // Prefix sums of the span's τ0 frame energies, kept for
        // [`Self::window`]; the cells' sums are read off them.
        let s0 = s0.min(FRAMES - 1);
        let run = k.min(FRAMES - s0);
        let mut acc = 0.0f32;
        self.px[0] = 0.0;
        // The span's frames wrap the ring at most once: two plain loops.
        let (head, tail) = self.px[1..=k].split_at_mut(run.min(k));
        let xs = (
            x0.get(s0..s0 + run).unwrap_or(&[]),
            x0.get(..k - run).unwrap_or(&[]),
        );
        for (p, &x) in head.iter_mut().zip(xs.0) {
            acc += x;
            *p = acc;
        }
        for (p, &x) in tail.iter_mut().zip(xs.1) {
            acc += x;
            *p = acc;
        }
        for cell in 0..=self.cells.min(CELLS) {
            self.sum[cell] = self.px[(cell * g).min(k)];
        }
        self.first = Some(first);
        self.nu = nu;
        self.beta = beta;
        self.cost[0] = -self.beta;
        self.row = 1;
        self.next_row();
    }
    /// One row of the optimal partitioning (Jackson et al. 2005): the best
    /// cost of cells 0..j over the start i of its last segment, with the
    /// scaled-χ² (Gamma) segment cost ν·n·ln(mean) and a penalty β per
    /// segment. At most 32 cells per row, one `lnf` per cell.
    pub(super) fn next_row(&mut self) {
        let j = self.row.min(CELLS);
        let (g, k) = (self.group.max(1), self.span.min(FRAMES - 1));
        let frames = |c: usize| (c * g).min(k);
        let (nu, sj, nj) = (self.nu, self.sum[j], frames(j));
        let (mut best, mut arg) = (f32::INFINITY, 0u8);
        // Segment [i, j) has nf = nj − i·g frames (the last cell may be
        // short, so j's own frame count is nj): walk nf and ln nf down.
        let ln_nf = self.ln_n[..=nj].iter().rev().step_by(g);
        let mut nff = nj as f32;
        let gf = g as f32;
        for (i, ((&si, &ci), &ln_nf)) in self.sum[..j]
            .iter()
            .zip(&self.cost[..j])
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
        self.cost[j] = best + self.beta;
        self.arg[j] = arg;
        self.row = j + 1;
    }
    /// The finished segmentation's segment bounds in frames, backtracked
    /// into `dp.bounds` (0 = b₀ < b₁ < … < b_nb = k); returns nb.
    pub(super) fn backtrack(&mut self) -> usize {
        let (g, k) = (self.group.max(1), self.span.min(FRAMES - 1));
        let cells = self.cells.min(CELLS);
        let bounds = &mut self.bounds;
        let mut nb = 0;
        let mut j = cells;
        while j > 0 && nb < CELLS {
            bounds[nb] = (j * g).min(k) as u16;
            nb += 1;
            j = self.arg.get(j).map_or(0, |&a| a as usize).min(j - 1);
        }
        let nb = nb.min(CELLS);
        bounds[nb] = 0;
        bounds[..=nb].reverse();
        nb
    }
    /// Part `part` (of [`REFINE_PARTS`]) of the refinement: its share of
    /// the changes, in order; `s0` is the slot of the span's first block.
    /// Out of line, so that `push`'s other samples do not carry it.
    #[inline(never)]
    pub(super) fn refine_part(&mut self, part: usize, s0: usize) {
        let (Some(prev), Some(_)) = (self.first, self.next_first) else {
            return;
        };
        while self.row <= self.cells {
            self.next_row();
        }
        let (nb, next) = self.refining(prev);
        let to = (1 + nb.saturating_sub(1) * (part + 1) / REFINE_PARTS)
            .min(nb)
            .max(next);
        self.refine(nb, next..to, s0);
        self.refined = Some((prev, nb, to));
    }
    /// The refinement of the span at `first` so far (the count of
    /// `dp.bounds` less one, the next change to refine), or its start.
    pub(super) fn refining(&mut self, first: u64) -> (usize, usize) {
        match self.refined {
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
    pub(super) fn refine(&mut self, nb: usize, which: core::ops::Range<usize>, s0: usize) {
        let g = self.group.max(1);
        if g <= 1 {
            return;
        }
        // The changes the last segmentation placed: the span's blocks
        // that carry its stamp.
        let last = (self.recent_len > 0).then(|| self.recent[(self.recent_at + LAG - 1) % LAG]);
        let s0 = s0.min(FRAMES - 1);
        // Over the span's frame prefix sums (from [`Self::start`]).
        let (px, ln_n, nu) = (&self.px, &self.ln_n, self.nu);
        let bounds = &mut self.bounds;
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
    /// The finished segmentation's segment that holds t, widened to λ1;
    /// returns the window [lo, hi) in frames of the span at `first`, whose
    /// first block is in slot `s0`.
    pub(super) fn window(&mut self, first: u64, s0: usize) -> (usize, usize) {
        // The bounds refined from REFINE_AT (the rest, if any, now).
        let (nb, next) = self.refining(first);
        self.refined = None;
        self.refine(nb, next..nb, s0);
        let bounds = &self.bounds;
        let k = self.span.min(FRAMES - 1);
        let ft = k / 2; // frame that starts at (or holds) t
                        // The span's frame prefix sums (from [`Self::start`]): every mean below
                        // is taken over frames. Indices come from the segmentation and are
                        // in range; `get` keeps that from being a panic path if it ever
                        // were not.
        let (px, ln_n) = (&self.px, &self.ln_n);
        let p = |i: usize| px.get(i).copied().unwrap_or(0.0);
        let nu = self.nu;
        let cost = |i: usize, j: usize| seg_cost(px, ln_n, nu, i, j);
        let bd = |b: &[u16; CELLS + 1], i: usize| b.get(i).copied().unwrap_or(0) as usize;
        // Keep the changes that one of the last LAG segmentations had too,
        // or strong ones, and then stamp this hop's (its stamp over the
        // oldest's).
        let s0 = s0.min(FRAMES - 1);
        // The block c frames into the span (c ≤ k < FRAMES).
        let slot = |c: usize| ahead::<FRAMES>(s0, c);
        // The recent stamps; where fewer than LAG segmentations ran since
        // the start, this one's own stamp, which no block carries yet.
        let stamp = first as u16;
        let n_recent = usize::from(self.recent_len);
        let recent: [u16; LAG] =
            core::array::from_fn(|j| if j < n_recent { self.recent[j] } else { stamp });
        let near = &self.marks_near;
        let strong = STRONG * self.beta;
        // This hop's changes with their neighbours (l, c, r), as slices
        // (no checked read per bound).
        let changes = bounds.get(..=nb).unwrap_or(&[]);
        let (mut kept, mut nk) = ([0u16; CELLS + 1], 1);
        for w in changes.windows(3) {
            let &[l, c, r] = w else { continue };
            let (l, c, r) = (usize::from(l), usize::from(c), usize::from(r));
            // Seen: a recent segmentation had a change within a frame of c
            // (the latest that had one did, then). Else its likelihood gain
            // against merging its two segments must be strong.
            let seen = near.get(slot(c)).is_some_and(|m| recent.contains(m));
            if seen || cost(l, r) - cost(l, c) - cost(c, r) > strong {
                if let Some(kc) = kept.get_mut(nk) {
                    *kc = c as u16;
                }
                nk += 1;
            }
        }
        for &c in changes.get(1..nb).unwrap_or(&[]) {
            let c = usize::from(c);
            if let Some(m) = self.marks.get_mut(slot(c)) {
                *m = stamp;
            }
            for q in [c - 1, c, c + 1] {
                if let Some(m) = self.marks_near.get_mut(slot(q)) {
                    *m = stamp;
                }
            }
        }
        let at = self.recent_at % LAG;
        self.recent[at] = stamp;
        self.recent_len = (self.recent_len + 1).min(LAG as u8);
        self.recent_at = (at + 1) % LAG;
        let nb = nk.min(CELLS);
        kept[nb] = k as u16;
        let b = |i: usize| bd(&kept, i);
        let mean =
            |i: usize| (p(b(i + 1)) - p(b(i))) / (b(i + 1).saturating_sub(b(i))).max(1) as f32;
        let mut s = 0;
        while s + 1 < nb && b(s + 1) <= ft {
            s += 1;
        }
        // Score: what the segmentation gained over one segment (> 0 iff a
        // change was placed), against the penalty per change.
        self.gain = (cost(0, k) - self.cost[self.cells.min(CELLS)]).max(0.0);
        // A monotone run of segments through t's (levels rising or falling
        // segment after segment) is a gradual change cut into stairs, not
        // steps: there a window symmetric about t is unbiased to first
        // order and a one-sided segment is not. Use the widest symmetric
        // window inside the run.
        let dir = |i: usize| (mean(i + 1) - mean(i)).signum();
        // A change next to t's segment is gradual (a ramp cut into a step,
        // or a false alarm), not a step, when its two segments together
        // span at least 2λ1 and
        // - one line through both explains their energies better than the
        //   step does ([`line_over_step`]), or as well less the penalty for
        //   the step's location where the change gains less than GRADUAL·β;
        // - where the change is alone in the span, two lines joined at
        //   their best knot explain the energies as well as the step does,
        //   less HINGE_SLACK·β ([`hinge_over_step`]): a level that starts
        //   to slope, which the step's free location fits as well as one
        //   line does; or
        // - a blurred step fits them better than the sharp one: the two
        //   levels joined by a linear transition over 2h frames centred on
        //   the change, h ≥ λ1 (so a one-sided window of λ1 inside the
        //   transition would be biased by its slope).
        // Such a change does not bound the window: t gets a window
        // symmetric about it, which a linear change leaves unbiased. (Each
        // side tests one change, so the sample's cost stays bounded.)
        let (beta, min_frames, q) = (self.beta, self.min_frames, self.group.max(1));
        let lambda1 = self.lambda1;
        // (Asked only of a change next to t's segment.)
        let seg_slope = if nb > 1 {
            slope_z2(px, nu, (b(s), b(s + 1)))
        } else {
            None
        };
        // Whether the hinge test is what read a change as gradual; whether
        // it read a change far from t so (the window then stops there).
        let hinged = Cell::new(false);
        let inside = Cell::new(false);
        let gradual = |i: usize| {
            let (l, c, r) = (b(i - 1), b(i), b(i + 1));
            // t's own segment rising (or falling) toward or away from the
            // change as the change goes: a ramp cut into stairs, whose
            // stairs are not flat.
            if let Some((z2, up)) = seg_slope {
                if z2 > SLOPE_Z2 && up == (mean(i) > mean(i - 1)) {
                    return true;
                }
            }
            // At least 2λ1 samples, not frames rounded up: at λ1 = λ2/2
            // only a change alone in the span passes, and at the paper's
            // 400/800 (12.5 frames a side) a rounded count would let none
            // pass, and a ×4 ramp over λ2 would read 1.23× the best fixed
            // window (`davar-eval --sweep`).
            if (r - l) * SEG < 2 * lambda1 {
                return false;
            }
            let sums = line_sums(px, l, r);
            let d = line_over_step_from(px, nu, (l, c, r), sums);
            if d > 0.0 {
                return true;
            }
            // The step's cost and its gain over one segment, each made at
            // most once (three logarithms).
            let (mut step, mut gain) = (None, None);
            let mut gain_of = |step: &mut Option<f32>| {
                *gain.get_or_insert_with(|| {
                    cost(l, r) - *step.get_or_insert_with(|| cost(l, c) + cost(c, r))
                })
            };
            if d > -beta && gain_of(&mut step) < GRADUAL * beta {
                return true;
            }
            // Near t: within 3λ1/4 or λ2/8 of it, whichever is farther,
            // and inside the span's middle half (farther, the segment that
            // holds t is most of a one-sided window's length on either
            // side of t, and the few frames beyond the change let a steep
            // line mimic the step; at the board's λ1 = λ2/2 the middle
            // half is the nearer bound, λ1/2). λ2/8 where λ1 is short
            // against λ2: a ramp over λ2 at 128/2048 is cut where the noise
            // puts it, up to λ2/4 from where it bends. With the rounded
            // 2⌈λ1/32⌉ frames, as the line test had them: at 400/800 the
            // joined lines come within β/2 of the paper's ×3 steps (gains
            // 3–6β, deficits 0–0.5β on 25 frames), and reading those as
            // gradual takes its experiment from 0.70 to 0.77–0.88. And not
            // strong (the second-order form holds near equal levels and
            // understates a large step's edge).
            // Farther from t, where t's segment slopes the change's way,
            // the same test reads a ramp whose bend the step stands for:
            // there the segment, one-sided about t, would take the slope's
            // bias, and the window is symmetric about t and stops at the
            // change instead (unbiased on the ramp; on a step misread only
            // shorter, with no step inside).
            let near = c.abs_diff(ft) * 4 <= (3 * min_frames).max(k / 2).min(k);
            let sloping =
                || seg_slope.is_some_and(|(z2, up)| z2 > FAR_Z2 && up == (mean(i) > mean(i - 1)));
            if nb == 2
                && r - l >= 2 * min_frames
                && (near || sloping())
                && gain_of(&mut step) < HINGE_MAX_GAIN * beta
                && hinge_over_step_from(px, nu, (l, c, r), sums) > -HINGE_SLACK * beta
            {
                if near {
                    hinged.set(true);
                    return true;
                }
                inside.set(true);
            }
            let mut h = min_frames.max(1);
            while c > l + h && c + h < r {
                let st = *step.get_or_insert_with(|| cost(l, c) + cost(c, r));
                if transition_cost(px, ln_n, nu, (l, c, r), h, q).is_some_and(|v| v < st) {
                    return true;
                }
                h *= 2;
            }
            false
        };
        let r0 = s - usize::from(s > 0 && gradual(s));
        let left_inside = inside.replace(false);
        let r1 = s + usize::from(s + 1 < nb && gradual(s + 1));
        let right_inside = inside.get();
        let run = s > 0 && s + 1 < nb && dir(s - 1) == dir(s);
        if run || r0 < s || r1 > s || left_inside || right_inside {
            let (mut r0, mut r1) = (r0, r1);
            if run {
                let d = dir(s);
                (r0, r1) = (r0.min(s - 1), r1.max(s + 1));
                while r0 > 0 && dir(r0 - 1) == d {
                    r0 -= 1;
                }
                while r1 + 1 < nb && dir(r1) == d {
                    r1 += 1;
                }
            }
            let odd = k % 2;
            let (run_lo, run_hi) = (b(r0), b(r1 + 1));
            let mut h = ft
                .saturating_sub(run_lo)
                .min(run_hi.saturating_sub(ft + odd));
            if hinged.get() {
                h = h.min(hinge_half(self.min_frames, k));
            }
            if left_inside && r0 == s {
                h = h.min(ft.saturating_sub(b(s)));
            }
            if right_inside && r1 == s {
                h = h.min(b(s + 1).saturating_sub(ft + odd));
            }
            if 2 * h + odd < self.min_frames {
                h = self.min_frames.saturating_sub(odd).div_ceil(2).min(ft);
            }
            return (ft - h, (ft + odd + h).min(k));
        }
        let (mut lo, mut hi) = (b(s), b(s + 1).max(b(s) + 1));
        // Widen to λ1, one frame at a time, toward the neighbour whose
        // energy is closer (in ratio) to the segment's mean. Each side's
        // gap is computed once per frame it reaches, the frames' energies
        // walked outward over the prefix sums as slices.
        let seg_mean = mean(s);
        let gap = |w: &[f32]| match *w {
            [a, b] => ratio_gap(b - a, seg_mean),
            _ => f32::INFINITY,
        };
        // Frames lo − 1, lo − 2, …, 0 and hi, hi + 1, …, k − 1.
        let mut lefts = px.get(..=lo).unwrap_or(&[]).windows(2).rev().map(gap);
        let mut rights = px.get(hi..=k).unwrap_or(&[]).windows(2).map(gap);
        let (mut left, mut right) = (lefts.next(), rights.next());
        while hi - lo < self.min_frames.min(k) {
            let to_left = match (left, right) {
                (Some(l), Some(r)) => l <= r,
                (l, _) => l.is_some(),
            };
            if to_left {
                lo -= 1;
                left = lefts.next();
            } else {
                hi += 1;
                right = rights.next();
            }
        }
        (lo, hi)
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

/// Half the symmetric window, in frames, that a change the hinge test
/// reads as gradual leaves t: the window is half the span, and at least
/// λ1. A ×2
/// step and a level that starts to slope gain alike; with the change δ
/// from t the share of a window of 2h beyond a step it missed is
/// (h − δ)/2h, so the shorter window costs a missed step less and a ramp
/// more. At λ1 = λ2/4 this is 2λ1, as tuned there (`--first-seed 55555
/// --seeds 60`: ×2 at 256/1024 0.844, with the whole span 0.913); at
/// λ1 = λ2/2 it is λ1 (with the whole span a ramp over λ1 at 512/1024
/// reads 1.074× the best fixed window and ×2 steps 0.908; with λ1 ≤ 1.00
/// and 0.841); at 128/2048 λ2/2 (with 2λ1 the ramp over λ2 reads 1.16: a
/// window of 256 is too noisy against the bias it avoids).
pub(super) fn hinge_half(min_frames: usize, span: usize) -> usize {
    (min_frames / 2).max(span / 4)
}
