//! Placing the window: the segment that holds t, widened to λ1
//! ([`Placement::Segmented`]), or centred on t with the entropy rule of
//! eq. 1–4 ([`Placement::Centred`]).

use super::refine::{hinge_over_step_from, line_over_step_from, line_sums, ratio_gap, slope_z2};
use super::segment::{seg_cost, transition_cost};
use super::sums::{ahead, slot};
use super::{
    Davar, EntropyKind, StepMode, BINS, CELLS, GRADUAL, HINGE_MAX_GAIN, HINGE_SLACK, LAG, SEG,
    SLOPE_Z2, STRONG,
};
use crate::algo::math::lnf;
use core::cell::Cell;

impl<const CAP: usize, const FRAMES: usize, const T: usize, const STFT: usize>
    Davar<CAP, FRAMES, T, STFT>
{
    /// The finished segmentation's segment that holds t, widened to λ1;
    /// returns the window [lo, hi) in frames of the span at `first`.
    pub(super) fn segment_window(&mut self, first: u64) -> (usize, usize) {
        // The bounds refined from REFINE_AT (the rest, if any, now).
        let (nb, next) = self.refining(first);
        self.dp.refined = None;
        self.refine(nb, next..nb);
        let bounds = &self.dp.bounds;
        let k = self.span.min(FRAMES - 1);
        let ft = k / 2; // frame that starts at (or holds) t
                        // The span's frame prefix sums (from `dp_start`): every mean below
                        // is taken over frames. Indices come from the segmentation and are
                        // in range; `get` keeps that from being a panic path if it ever
                        // were not.
        let (px, ln_n) = (&self.px, &self.ln_n);
        let p = |i: usize| px.get(i).copied().unwrap_or(0.0);
        let nu = self.dp.nu;
        let cost = |i: usize, j: usize| seg_cost(px, ln_n, nu, i, j);
        let bd = |b: &[u16; CELLS + 1], i: usize| b.get(i).copied().unwrap_or(0) as usize;
        // Keep the changes that one of the last LAG segmentations had too,
        // or strong ones, and then stamp this hop's (its stamp over the
        // oldest's).
        let s0 = self.sums.slot_of(first).min(FRAMES - 1);
        // The block c frames into the span (c ≤ k < FRAMES).
        let slot = |c: usize| ahead::<FRAMES>(s0, c);
        // The recent stamps; where fewer than LAG segmentations ran since
        // the start, this one's own stamp, which no block carries yet.
        let stamp = first as u16;
        let n_recent = usize::from(self.dp.recent_len);
        let recent: [u16; LAG] = core::array::from_fn(|j| {
            if j < n_recent {
                self.dp.recent[j]
            } else {
                stamp
            }
        });
        let near = &self.marks_near;
        let strong = STRONG * self.dp.beta;
        // This hop's changes with their neighbours (l, c, r), as slices:
        // reading the bounds one by one through checked reads cost ~250
        // instructions with fifteen changes.
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
        let at = self.dp.recent_at % LAG;
        self.dp.recent[at] = stamp;
        self.dp.recent_len = (self.dp.recent_len + 1).min(LAG as u8);
        self.dp.recent_at = (at + 1) % LAG;
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
        self.score = (cost(0, k) - self.dp.cost[self.dp.cells.min(CELLS)]).max(0.0);
        self.threshold = self.dp.beta;
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
        let (beta, min_frames, q) = (self.dp.beta, self.min_frames, self.dp.group.max(1));
        let lambda1 = usize::from(self.cfg.lambda1);
        // (Asked only of a change next to t's segment.)
        let seg_slope = if nb > 1 {
            slope_z2(px, nu, (b(s), b(s + 1)))
        } else {
            None
        };
        // Whether the hinge test is what read a change as gradual.
        let hinged = Cell::new(false);
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
            if nb == 2
                && r - l >= 2 * min_frames
                && c.abs_diff(ft) * 4 <= (3 * min_frames).max(k / 2).min(k)
                && gain_of(&mut step) < HINGE_MAX_GAIN * beta
                && hinge_over_step_from(px, nu, (l, c, r), sums) > -HINGE_SLACK * beta
            {
                hinged.set(true);
                return true;
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
        let r1 = s + usize::from(s + 1 < nb && gradual(s + 1));
        let run = s > 0 && s + 1 < nb && dir(s - 1) == dir(s);
        if run || r0 < s || r1 > s {
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
            if 2 * h + odd < self.min_frames {
                h = self.min_frames.saturating_sub(odd).div_ceil(2).min(ft);
            }
            return (ft - h, (ft + odd + h).min(k));
        }
        let (mut lo, mut hi) = (b(s), b(s + 1).max(b(s) + 1));
        // Widen to λ1, one frame at a time, toward the neighbour whose
        // energy is closer (in ratio) to the segment's mean. Each side's
        // gap is computed once per frame it reaches, the frames' energies
        // walked outward over the prefix sums as slices (both sides' gaps
        // recomputed at every step cost some 1 000 instructions more where
        // t's segment is a few frames long).
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
    /// Centred placement: eq. 4 (when adaptive), then the window of the
    /// current length around t, in frames of the span.
    pub(super) fn centred(&mut self, first: u64, adaptive: bool) -> (usize, usize) {
        let (k, min_frames) = (self.span, self.min_frames);
        let frames_of = move |len: u16| -> usize {
            // Whole frames of the span's parity, so the window is centred.
            let mut f = (len as usize / SEG).max(min_frames).min(k);
            if (k - f) % 2 == 1 {
                f = if f < k { f + 1 } else { f - 1 };
            }
            f
        };
        if adaptive {
            let f = frames_of(self.len);
            let lo = first + ((k - f) / 2) as u64;
            self.adapt(lo, lo + f as u64);
        }
        let f = frames_of(self.len);
        ((k - f) / 2, (k + f) / 2)
    }
    /// FFT of the frame that just completed; keep the power of bins 1..=15.
    pub(super) fn store_frame(&mut self) {
        let mut x = [0.0f32; SEG];
        let first = self.sums.n - SEG as u64;
        for (i, v) in x.iter_mut().enumerate() {
            *v = self.sums.w(first + i as u64) as f32;
        }
        let spec = microfft::real::rfft_32(&mut x);
        let slot = slot::<FRAMES>(first / SEG as u64);
        let (Some(frame), Some(energy), Some(eloge)) = (
            self.frames.get_mut(slot),
            self.energy.get_mut(slot),
            self.eloge.get_mut(slot),
        ) else {
            return; // STFT < FRAMES is refused for windows that need it
        };
        let mut e = 0.0f32;
        for (p, c) in frame.iter_mut().zip(spec[1..].iter()) {
            *p = c.re * c.re + c.im * c.im;
            e += *p;
        }
        *energy = e;
        *eloge = if e > 0.0 { e * lnf(e) } else { 0.0 };
    }
    /// Entropy of frames [f_lo, f_hi) and the eq. 4 update of the length.
    pub(super) fn adapt(&mut self, f_lo: u64, f_hi: u64) {
        let k = (f_hi - f_lo) as usize;
        if k < 2 {
            return;
        }
        let s0 = self.sums.slot_of(f_lo);
        let slots = (0..k).map(move |i| {
            if s0 + i >= FRAMES {
                s0 + i - FRAMES
            } else {
                s0 + i
            }
        });
        let score = match self.cfg.entropy {
            EntropyKind::Temporal => {
                let (mut tot, mut sum_eloge) = (0.0f32, 0.0f32);
                for s in slots {
                    tot += self.energy.get(s).copied().unwrap_or(0.0);
                    sum_eloge += self.eloge.get(s).copied().unwrap_or(0.0);
                }
                if !(tot > 0.0) {
                    return;
                }
                // D = ln K − H, H = ln Σe − Σ(e ln e)/Σe.
                lnf(k as f32) - (lnf(tot) - sum_eloge / tot)
            }
            EntropyKind::Spectral => {
                let mut bins = [0.0f32; BINS];
                for f in slots.filter_map(|s| self.frames.get(s)) {
                    for (b, p) in bins.iter_mut().zip(f.iter()) {
                        *b += p;
                    }
                }
                let tot: f32 = bins.iter().sum();
                if !(tot > 0.0) {
                    return;
                }
                let mut h = 0.0f32;
                for &p in &bins {
                    if p > 0.0 {
                        let q = p / tot;
                        h -= q * lnf(q);
                    }
                }
                h / lnf(BINS as f32)
            }
        };
        let th = self.thresholds[k.min(FRAMES - 1)];
        self.score = score;
        self.threshold = th;
        let dl = self.cfg.delta_l as f32;
        let step = match self.cfg.step {
            StepMode::Constant => {
                if score > th {
                    dl
                } else if score < th {
                    -dl
                } else {
                    0.0
                }
            }
            StepMode::Proportional => {
                let r = if th != 0.0 {
                    (score - th) / th.abs()
                } else {
                    0.0
                };
                r.clamp(-1.0, 1.0) * dl
            }
        };
        let tentative = (self.len as f32 - step) as i32 & !1;
        // (max then min: `clamp` asserts λ1 ≤ λ2, which `new` checked.)
        self.len = tentative
            .max(self.cfg.lambda1 as i32)
            .min(self.cfg.lambda2 as i32) as u16;
    }
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
