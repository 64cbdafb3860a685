//! The streaming sums: each sample completes one Allan term per τ, whose
//! square is added, exactly, to its 32-term block; a window is whole
//! blocks plus one block prefix per τ.

use super::SEG;
use crate::algo::allan::stream::SAMPLE_MAX;
use crate::algo::math::u64_to_f32;

/// The exact streaming sums of one axis: the last `CAP` samples, each
/// Allan term's square added to its 32-term block (`FRAMES` blocks, `T`
/// τ), the τ0 blocks' energies and lag sums that the segmentation and ν
/// read, and the whole-block sums of the last published window.
// (In this order, the small state first and the ring last, so that what
// the hop's schedule touches lies within the Cortex-M4's 4 KB load offset
// of the struct's base: no address to build for each field.)
#[derive(Clone, Debug)]
#[repr(C)]
pub(super) struct Sums<const CAP: usize, const FRAMES: usize, const T: usize> {
    /// Octaves between consecutive τ.
    octaves: u8,
    /// Samples pushed since the start or a reset.
    pub(super) n: u64,
    /// Slot of block n/32 (kept incrementally: a u64 `%` by a FRAMES that
    /// is not a power of two is a library call on the Cortex-M4).
    cur_slot: usize,
    /// Per τ, the next term to add to the blocks, and the sums of the term
    /// before it: b = Σ w[k..k+m), a = Σ w[k+m..k+2m).
    next: [u64; T],
    a: [i32; T],
    b: [i32; T],
    /// Per τ, the sums of its first term (b over samples 0..m, a over
    /// m..2m), kept as the samples arrive from a running sum read at
    /// each power of two, so that the first term is not summed from
    /// scratch: 2m samples on one sample of the loop.
    first_a: [i32; T],
    first_b: [i32; T],
    /// Σ of the samples so far (wrapping: a difference of two of them is
    /// exact), while the first terms are being gathered.
    prefix: i32,
    /// Σd², Σd·d₋₁, Σd·d₋₂ of the τ0 differences d since ν last took
    /// them (exact), and the last two d.
    pub(super) lag: [i64; 3],
    dprev: [i32; 2],
    /// The τ0 terms (d) of the last whole frame, for ν's tails.
    pub(super) tail_terms: Option<(u64, u64)>,
    /// The last published window's first block, and per τ the end of its
    /// whole blocks and their sum (for the next window's update).
    win_f0: Option<u64>,
    win_q: [u64; T],
    win_sum: [u128; T],
    /// Per block (terms starting in it) and τ: Σd² as low word + carry,
    /// and the prefix a window ending in this block needs.
    lo: [[u64; FRAMES]; T],
    hi: [[u8; FRAMES]; T],
    pre: [[u64; FRAMES]; T],
    /// τ0 block sums as f32, once complete (the segmentation's input).
    pub(super) x0: [f32; FRAMES],
    /// The last `CAP` samples (sample i at `i & (CAP − 1)`), last: see
    /// `Davar`'s field order.
    ring: [i32; CAP],
}

/// Slot of block `block`.
#[inline(always)]
pub(super) fn slot<const FRAMES: usize>(block: u64) -> usize {
    (block % FRAMES as u64) as usize
}

/// The slot `c` blocks after slot `s0` (c < FRAMES: one wrap at most).
#[inline(always)]
pub(super) fn ahead<const FRAMES: usize>(s0: usize, c: usize) -> usize {
    let s = s0 + c;
    if s >= FRAMES {
        s - FRAMES
    } else {
        s
    }
}

impl<const CAP: usize, const FRAMES: usize, const T: usize> Sums<CAP, FRAMES, T> {
    /// Empty sums for τ spaced `octaves` apart.
    pub(super) fn new(octaves: u8) -> Self {
        Self {
            octaves,
            ring: [0; CAP],
            n: 0,
            cur_slot: 0,
            next: [0; T],
            a: [0; T],
            b: [0; T],
            first_a: [0; T],
            first_b: [0; T],
            prefix: 0,
            lo: [[0; FRAMES]; T],
            hi: [[0; FRAMES]; T],
            pre: [[0; FRAMES]; T],
            x0: [0.0; FRAMES],
            lag: [0; 3],
            dprev: [0; 2],
            tail_terms: None,
            win_f0: None,
            win_q: [0; T],
            win_sum: [0; T],
        }
    }
    /// Forget every sample. (The blocks, first terms and energies are
    /// written again before they are read.)
    pub(super) fn reset(&mut self) {
        self.n = 0;
        self.cur_slot = 0;
        self.next = [0; T];
        self.a = [0; T];
        self.b = [0; T];
        self.prefix = 0;
        self.lag = [0; 3];
        self.dprev = [0; 2];
        self.tail_terms = None;
        self.win_f0 = None;
    }
    /// Take sample `w` (|w| ≤ [`SAMPLE_MAX`], checked by the caller) into
    /// the ring; its terms are added at the hop ([`Self::add_terms`]).
    #[inline(always)]
    pub(super) fn push(&mut self, w: i32) {
        let n = self.n;
        self.ring[n as usize & (CAP - 1)] = w;
        self.n = n + 1;
        if n < self.term_span() {
            self.gather_first_terms(w);
        }
        if self.n.is_multiple_of(SEG as u64) {
            self.cur_slot = Self::next(self.cur_slot);
        }
    }
    /// The last `CAP` samples, sample i at `i & (CAP − 1)`.
    #[inline(always)]
    pub(super) fn ring(&self) -> &[i32; CAP] {
        &self.ring
    }
    #[inline(always)]
    pub(super) fn w(&self, i: u64) -> i32 {
        self.ring[i as usize & (CAP - 1)]
    }
    /// Slot of block n/32 − back (back < FRAMES).
    #[inline(always)]
    pub(super) fn back_slot(&self, back: usize) -> usize {
        if self.cur_slot >= back {
            self.cur_slot - back
        } else {
            self.cur_slot + FRAMES - back
        }
    }
    /// Slot of an older block f (within FRAMES of the newest).
    #[inline(always)]
    pub(super) fn slot_of(&self, f: u64) -> usize {
        self.back_slot((self.n / SEG as u64 - f) as usize)
    }
    /// The next slot after `s`.
    #[inline(always)]
    pub(super) fn next(s: usize) -> usize {
        if s + 1 == FRAMES {
            0
        } else {
            s + 1
        }
    }
    /// τ_j in samples: 2^(j·octaves).
    #[inline(always)]
    pub(super) fn tau(&self, j: usize) -> u64 {
        1u64 << (j * self.octaves as usize)
    }
    /// Samples the longest τ's first term spans: 2·τ_{T−1}.
    #[inline(always)]
    pub(super) fn term_span(&self) -> u64 {
        2 * self.tau(T - 1)
    }
    /// After sample `w` (the `n`th, from 1): at n = τ_j the first term's b
    /// of τ_j is the running sum, and at n = 2τ_j its a the sum since
    /// n = τ_j. Runs for the first 2·τ_{T−1} samples after a start.
    #[inline]
    pub(super) fn gather_first_terms(&mut self, w: i32) {
        self.prefix = self.prefix.wrapping_add(w);
        let n = self.n;
        if n.is_power_of_two() {
            let i = n.trailing_zeros() as usize;
            let oct = self.octaves as usize;
            if i.is_multiple_of(oct) {
                if let Some(b) = i.checked_div(oct).and_then(|k| self.first_b.get_mut(k)) {
                    *b = self.prefix;
                }
            }
            if let Some(j) = i
                .checked_sub(1)
                .filter(|e| e.is_multiple_of(oct))
                .and_then(|e| e.checked_div(oct))
            {
                if let (Some(a), Some(&b)) = (self.first_a.get_mut(j), self.first_b.get(j)) {
                    *a = self.prefix.wrapping_sub(b);
                }
            }
        }
    }
    /// Add every Allan term completed since the last hop to its block, per
    /// τ in one tight loop (sliding sums in registers, about 10
    /// instructions a term on the Cortex-M4).
    /// Term k of τ = m uses samples [k, k + 2m); `next[j]` is the next term
    /// to add and `a`, `b` hold the sums of the term before it (τ > τ0:
    /// τ0's terms need no sums, [`Self::add_tau0`]).
    pub(super) fn add_terms(&mut self, j: usize) {
        let n = self.n;
        if j == 0 || j >= T {
            return;
        }
        {
            let m = self.tau(j);
            if n < 2 * m {
                return;
            }
            let last = n - 2 * m; // newest complete term
            let mut k = self.next[j];
            if k > last {
                return;
            }
            let (mu, m2) = (m as usize, 2 * m as usize);
            let (mut a, mut b) = (self.a[j], self.b[j]);
            let pre_off = (SEG - m2 % SEG) % SEG;
            while k <= last {
                let block = k / SEG as u64;
                let off = (k % SEG as u64) as usize;
                let end = last.min(block * SEG as u64 + SEG as u64 - 1);
                // (Slots are < FRAMES by construction; the `min` lets the
                // compiler see it, so no index here can panic.)
                let slot = self.slot_of(block).min(FRAMES - 1);
                let (mut lo, mut hi) = if off == 0 {
                    (0u64, 0u8)
                } else {
                    (self.lo[j][slot], self.hi[j][slot])
                };
                let mut from = k;
                if k == 0 {
                    // First term: its sums, gathered as the samples came.
                    (a, b) = (self.first_a[j], self.first_b[j]);
                    (lo, hi) = add_sq(lo, hi, a - b);
                    if pre_off == 0 {
                        self.pre[j][slot] = lo;
                    }
                    from = 1;
                }
                // Terms from..=end, the prefix recorded on the way.
                let pre_k = block * SEG as u64 + pre_off as u64;
                if from <= end {
                    let i = (from as usize).wrapping_sub(1);
                    let slide = if carry_free(mu) {
                        Self::slide::<false>
                    } else {
                        Self::slide::<true>
                    };
                    if (from..=end).contains(&pre_k) {
                        let n1 = (pre_k - from) as usize + 1;
                        let i2;
                        (i2, a, b, lo, hi) = slide(&self.ring, i, n1, mu, a, b, lo, hi);
                        self.pre[j][slot] = lo;
                        (_, a, b, lo, hi) =
                            slide(&self.ring, i2, (end - pre_k) as usize, mu, a, b, lo, hi);
                    } else {
                        (_, a, b, lo, hi) =
                            slide(&self.ring, i, (end - from) as usize + 1, mu, a, b, lo, hi);
                    }
                }
                self.lo[j][slot] = lo;
                self.hi[j][slot] = hi;
                k = end + 1;
            }
            self.next[j] = k;
            (self.a[j], self.b[j]) = (a, b);
        }
    }
    /// The terms of τ0 = 1 sample since the last hop: the squared first
    /// differences d_k = w[k + 1] − w[k], in the same pass as the lag
    /// sums of d that ν is learnt from (`FrameDof::learn_lags`), which
    /// need the same d: one pass over the hop's samples. `completed`
    /// hears of each block whose terms are now all in (its number and
    /// slot).
    pub(super) fn add_tau0(&mut self, mut completed: impl FnMut(u64, usize)) {
        let Some(last) = self.n.checked_sub(2) else {
            return; // no complete term yet
        };
        let mut k = self.next[0];
        if k > last {
            return;
        }
        let mask = CAP - 1;
        let ([mut s0, mut s1, mut s2], [mut p1, mut p2]) = (self.lag, self.dprev);
        // The prefix kept for window sums ends with the block's term at
        // offset SEG − 2 (the last whose two samples are in the block).
        const PRE_OFF: u64 = SEG as u64 - 2;
        while k <= last {
            let block = k / SEG as u64;
            let end = last.min(block * SEG as u64 + SEG as u64 - 1);
            // (Slots are < FRAMES by construction; the `min` lets the
            // compiler see it.)
            let slot = self.slot_of(block).min(FRAMES - 1);
            // |d| ≤ 2·SAMPLE_MAX: a block's 32 squares fit the u64
            // (`carry_free(1)`), so its carry byte is left as it is.
            let mut lo = if k.is_multiple_of(SEG as u64) {
                self.hi[0][slot] = 0;
                0u64
            } else {
                self.lo[0][slot]
            };
            let pre_k = block * SEG as u64 + PRE_OFF;
            let mut from = k as usize;
            // The block's terms in at most two runs, split after the
            // prefix's term; each run in contiguous stretches of the ring.
            for stop in [pre_k.min(end), end] {
                let stop = stop as usize;
                while from <= stop {
                    let i0 = from & mask;
                    let run = (stop + 1 - from).min(CAP - 1 - i0);
                    if run == 0 {
                        // The pair wraps the ring: w[CAP − 1], w[0].
                        let d = self.ring[0] - self.ring[CAP - 1];
                        lo = lo.wrapping_add((d as i64 * d as i64) as u64);
                        s0 += d as i64 * d as i64;
                        s1 += d as i64 * p1 as i64;
                        s2 += d as i64 * p2 as i64;
                        (p1, p2) = (d, p1);
                        from += 1;
                        continue;
                    }
                    let xs = self.ring.get(i0..=i0 + run).unwrap_or(&[]);
                    for w in xs.windows(2) {
                        let d = w[1] - w[0];
                        let q = d as i64 * d as i64;
                        lo = lo.wrapping_add(q as u64);
                        s0 += q;
                        s1 += d as i64 * p1 as i64;
                        s2 += d as i64 * p2 as i64;
                        (p1, p2) = (d, p1);
                    }
                    from += run;
                }
                if stop as u64 == pre_k && k <= pre_k {
                    self.pre[0][slot] = lo;
                }
            }
            self.lo[0][slot] = lo;
            if end % SEG as u64 == SEG as u64 - 1 {
                self.x0[slot] = u64_to_f32(lo);
                completed(block, slot);
            }
            k = end + 1;
        }
        self.next[0] = k;
        (self.lag, self.dprev) = ([s0, s1, s2], [p1, p2]);
        // The tails take the last whole frame's terms, whatever the hop's
        // phase (so that staggered axes learn the same).
        let end = (last + 1) / SEG as u64 * SEG as u64;
        self.tail_terms = end.checked_sub(SEG as u64).map(|f| (f, end - 1));
    }
    /// `count` terms of τ = m: slide the sums from the term starting at
    /// i + 1 − 1 = i to the next (samples i, i + m, i + 2m), add each d².
    /// The per-term hot loop: everything in registers.
    ///
    /// Without `CARRY` the squares are summed in the u64 alone: the caller
    /// has checked that a whole 32-term block cannot overflow it (see
    /// [`carry_free`]), and the carry test per term (two more adds and a
    /// spilled register) goes.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub(super) fn slide<const CARRY: bool>(
        ring: &[i32; CAP],
        mut i: usize,
        count: usize,
        m: usize,
        mut a: i32,
        mut b: i32,
        mut lo: u64,
        mut hi: u8,
    ) -> (usize, i32, i32, u64, u8) {
        let mask = CAP - 1;
        let mut left = count;
        // In runs where none of the three samples wraps around the ring:
        // plain slices, so the loop walks three pointers with no mask per
        // read (about 12 instructions a term on the Cortex-M4).
        while left > 0 {
            let (i0, i1, i2) = (
                i & mask,
                i.wrapping_add(m) & mask,
                i.wrapping_add(2 * m) & mask,
            );
            let run = left.min(CAP - i0).min(CAP - i1).min(CAP - i2);
            let s0 = ring.get(i0..i0 + run).unwrap_or(&[]);
            let s1 = ring.get(i1..i1 + run).unwrap_or(&[]);
            let s2 = ring.get(i2..i2 + run).unwrap_or(&[]);
            for ((x0, x1), x2) in s0.iter().zip(s1).zip(s2) {
                b += x1 - x0;
                a += x2 - x1;
                if CARRY {
                    (lo, hi) = add_sq(lo, hi, a - b);
                } else {
                    let d = (a - b) as i64;
                    lo = lo.wrapping_add((d * d) as u64);
                }
            }
            i = i.wrapping_add(run);
            left -= run;
        }
        (i, a, b, lo, hi)
    }
    /// Slot of block `b`, from f0's slot `s_f0` (blocks within FRAMES of
    /// f0 either way).
    pub(super) fn slot_near(f0: u64, s_f0: usize, b: u64) -> usize {
        if b >= f0 {
            let d = (b - f0) as usize; // < FRAMES: b is in or next to the window
            if s_f0 + d >= FRAMES {
                s_f0 + d - FRAMES
            } else {
                s_f0 + d
            }
        } else {
            let d = (f0 - b) as usize;
            if s_f0 >= d {
                s_f0 - d
            } else {
                s_f0 + FRAMES - d
            }
        }
    }
    /// The whole-block sums of window [f0, f1) for the τ in `taus`, kept in
    /// `win_q`/`win_sum`; the board spreads the τ over `PUB_PARTS` samples. Until
    /// the publication ([`Self::window_total`]) the last window (`win_f0`) stays the base
    /// of the update, for every τ alike.
    pub(super) fn window_sums(&mut self, f0: u64, f1: u64, taus: core::ops::Range<usize>) {
        let e = f1 * SEG as u64;
        let s_f0 = self.slot_of(f0).min(FRAMES - 1);
        let slot = |b: u64| Self::slot_near(f0, s_f0, b);
        let old_f0 = self.win_f0;
        for j in taus.start..taus.end.min(T) {
            let m = self.tau(j);
            // Terms k ∈ [s, e − 2m]: whole blocks f0..q, then q's prefix.
            let q = (e - 2 * m) / SEG as u64;
            // The whole blocks: from the last window's by the blocks that
            // entered and left (exact integers, so nothing drifts), or
            // from scratch when that is shorter.
            let full = match old_f0 {
                Some(of0) if f0.abs_diff(of0) + q.abs_diff(self.win_q[j]) < q - f0 => {
                    let (oq, mut v) = (self.win_q[j], self.win_sum[j]);
                    if q > oq {
                        v += self.block_sum(j, slot(oq), q - oq);
                    } else {
                        v -= self.block_sum(j, slot(q), oq - q);
                    }
                    if f0 > of0 {
                        v -= self.block_sum(j, slot(of0), f0 - of0);
                    } else {
                        v += self.block_sum(j, s_f0, of0 - f0);
                    }
                    v
                }
                _ => self.block_sum(j, s_f0, q - f0),
            };
            self.win_q[j] = q;
            self.win_sum[j] = full;
        }
    }
    /// The exact sums of window [f0, ·) for every τ, from the whole-block
    /// sums [`Self::window_sums`] left and the last blocks' prefixes; the
    /// window is the base of the next one's update from now on.
    pub(super) fn window_total(&mut self, f0: u64) -> [u128; T] {
        let s_f0 = self.slot_of(f0).min(FRAMES - 1);
        let mut acc = [0u128; T];
        for (j, a) in acc.iter_mut().enumerate() {
            let q = self.win_q[j];
            *a =
                self.win_sum[j] + self.pre[j][Self::slot_near(f0, s_f0, q).min(FRAMES - 1)] as u128;
        }
        self.win_f0 = Some(f0);
        acc
    }
    /// Σ of `count` blocks of τ j from slot `s0` on, exactly. They wrap at
    /// most once: two contiguous runs. Low words with their carries
    /// counted, high parts apart: 32-bit-friendly sums, no u128 add per
    /// block.
    pub(super) fn block_sum(&self, j: usize, s0: usize, count: u64) -> u128 {
        let (Some(lo_j), Some(hi_j)) = (self.lo.get(j), self.hi.get(j)) else {
            return 0;
        };
        let count = (count as usize).min(FRAMES);
        let s0 = s0.min(FRAMES - 1);
        let first_run = count.min(FRAMES - s0);
        let run = |r: core::ops::Range<usize>| {
            lo_j.get(r.clone())
                .unwrap_or(&[])
                .iter()
                .zip(hi_j.get(r).unwrap_or(&[]))
        };
        let (mut lo, mut hi) = (0u64, 0u32);
        // Two plain loops rather than a chained iterator (whose every step
        // asks which half it is in). Where the blocks carry nothing
        // ([`carry_free`]) their high parts are 0 and are not read.
        let free = carry_free(self.tau(j) as usize);
        for r in [s0..s0 + first_run, 0..count - first_run] {
            if free {
                for l in lo_j.get(r).unwrap_or(&[]) {
                    let (v, c) = lo.overflowing_add(*l);
                    lo = v;
                    hi += c as u32;
                }
            } else {
                for (l, h) in run(r) {
                    let (v, c) = lo.overflowing_add(*l);
                    lo = v;
                    hi += c as u32 + *h as u32;
                }
            }
        }
        ((hi as u128) << 64) | lo as u128
    }
}

/// Whether a whole block of τ = m terms sums in a u64 without a carry:
/// |d| ≤ 2m·[`SAMPLE_MAX`], so 32 terms stay below 32·(2m·S)². True up to
/// m = 256 (τ up to 2⁸ samples: the board's tracker and the default
/// configurations); beyond, the carry byte is kept term by term.
#[inline(always)]
pub(super) const fn carry_free(m: usize) -> bool {
    let bound = 2 * m as u128 * SAMPLE_MAX as u128;
    SEG as u128 * bound * bound <= u64::MAX as u128
}

/// lo + hi·2⁶⁴ += d², exactly (a 32-term block of d² < 2⁶² needs 3 carry
/// bits at most).
#[inline(always)]
pub(super) fn add_sq(lo: u64, hi: u8, d: i32) -> (u64, u8) {
    let (v, c) = lo.overflowing_add((d as i64 * d as i64) as u64);
    (v, hi + c as u8)
}
