//! One chip's samples brought to the array's common output instants.
//!
//! The aligner works in the chip's own time: each sample is kept with its
//! FIFO timestamp, raw (in the chip's counts), and the instant a read asks
//! for is put on the chip's clock and into counts once ([`super::clock::ChipClock::chip_instant`]), not each
//! sample on the board's. The chip's signal-path delay is a fixed time on
//! its own clock, so it is added there, exactly, whatever the clock's rate.
//!
//! It first takes the moving mean of the last `n` samples (a chip at `n`
//! times the output rate: the mean of `n` has zeros at the output rate and
//! its multiples, so what the chip's filters pass near them does not fold
//! into band; moving, so each new sample gives a new mean and the newest is
//! only (n − 1)/2 samples old), then interpolates linearly between the two
//! means around the instant asked for. The means are integer sums of the
//! raw LSB, worked out for the means a read looks at; only the two it
//! interpolates between become °/s. A sample repeated by the chip's clock being slow, or
//! skipped by its being fast, is neither: the FIFO gives every sample
//! once, and the instant asked for falls between two of them wherever the
//! chip's phase is.

use super::clock::since;

/// What [`Aligner::at`] found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Aligned {
    /// The rate at the instant, °/s per axis.
    Rate([f32; 3]),
    /// The instant is newer than the newest averaged sample: the chip is
    /// late (its delay is longer than the array's), not faulty.
    Late,
    /// The instant is older than the oldest sample kept, or there is
    /// none.
    Missing,
}

/// Raw samples a moving mean can span.
pub const MAX_MEAN: usize = 8;

/// The aligner of one chip: its last `CAP` samples, raw, each with its
/// stamp (the chip's time in any linear unit: the board keeps the FIFO's
/// counts). The moving means are worked out when a read asks for an
/// instant, for the two it falls between: a push is a store, and a chip
/// gives two or more samples for each read.
#[derive(Clone, Copy, Debug)]
pub struct Aligner<const CAP: usize> {
    ring: [(u32, [i16; 3]); CAP],
    len: usize,
    head: usize,
    /// Samples per mean.
    n: usize,
}

/// One moving mean: its instant (1/16 of the stamps' unit) and the sum of its raw
/// samples.
type Mean = (u32, [i32; 3]);

/// A moving mean's window: the wrapping sum of its stamps and the sum of
/// its raw samples.
type Window = (u32, [i32; 3]);

impl<const CAP: usize> Aligner<CAP> {
    /// The ring wraps by mask.
    const POW2: () = assert!(
        CAP.is_power_of_two(),
        "an aligner's capacity is a power of two"
    );

    /// An aligner over moving means of `n` samples (1 for none; at most
    /// [`MAX_MEAN`], and fewer than `CAP`).
    pub const fn new(n: u8) -> Self {
        let () = Self::POW2;
        let n = n as usize;
        let n = if n == 0 {
            1
        } else if n > MAX_MEAN {
            MAX_MEAN
        } else {
            n
        };
        Self {
            ring: [(0, [0; 3]); CAP],
            len: 0,
            head: 0,
            n: if n < CAP { n } else { CAP - 1 },
        }
    }

    /// Forget every sample (a gap: an overflow, a restart).
    pub fn clear(&mut self) {
        self.len = 0;
        self.head = 0;
    }

    /// Means held.
    pub fn len(&self) -> usize {
        (self.len + 1).saturating_sub(self.n)
    }

    /// Whether none is held.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// One sample: its stamp (the chip's time) and its raw value.
    pub fn push(&mut self, stamp_us: u32, raw: [i16; 3]) {
        let () = Self::POW2;
        // (Wraps by mask, CAP a power of two: no division, and no bounds
        // check on the store.)
        if let Some(slot) = self.ring.get_mut((self.head + self.len) & (CAP - 1)) {
            *slot = (stamp_us, raw);
        }
        if self.len < CAP {
            self.len += 1;
        } else {
            self.head = (self.head + 1) & (CAP - 1);
        }
    }

    /// Sample `i` held (0 the oldest): its stamp and raw value.
    #[inline(always)]
    fn sample(&self, i: usize) -> (u32, [i16; 3]) {
        self.ring[(self.head + i) % CAP]
    }

    /// The window of the moving mean ending at sample `k` (0 the oldest
    /// held; `k ≥ n − 1`): the wrapping sum of its stamps and the sum of its
    /// raw samples (exact in integers).
    fn window(&self, k: usize) -> Window {
        let (mut stamps, mut sum) = (0u32, [0i32; 3]);
        for i in 0..self.n {
            let (ti, ri) = self.sample(k - i);
            stamps = stamps.wrapping_add(ti);
            for a in 0..3 {
                sum[a] += i32::from(ri[a]);
            }
        }
        (stamps, sum)
    }

    /// The window ending at sample `k − 1` from the one ending at `k`: one
    /// sample out, one in (the walk back through the means costs a
    /// subtraction and an addition a step, not a sum of `n`).
    fn slide_back(&self, k: usize, (stamps, sum): Window) -> Window {
        let ((t_out, r_out), (t_in, r_in)) = (self.sample(k), self.sample(k - self.n));
        let mut s = sum;
        for a in 0..3 {
            s[a] += i32::from(r_in[a]) - i32::from(r_out[a]);
        }
        (stamps.wrapping_sub(t_out).wrapping_add(t_in), s)
    }

    /// The moving mean ending at sample `k`, from its window: at the mean
    /// of its stamps, taken from the newest (`n·t − Σtᵢ` wraps to the small
    /// true distance whatever the stamps' own wrap; their distances are a
    /// few ms), as the sum of its raw samples.
    fn mean_of(&self, k: usize, (stamps, sum): Window) -> Mean {
        let n = self.n as u32;
        let t = self.sample(k).0;
        let behind = t.wrapping_mul(n).wrapping_sub(stamps);
        (
            // (n ≥ 1: a window holds its sample.)
            t.wrapping_mul(16)
                .wrapping_sub(behind.wrapping_mul(16).checked_div(n).unwrap_or(0)),
            sum,
        )
    }

    fn mean(&self, k: usize) -> Mean {
        self.mean_of(k, self.window(k))
    }

    /// The newest mean's instant, 1/16 of the stamps' unit.
    pub fn newest(&self) -> Option<u32> {
        (self.len >= self.n).then(|| self.mean(self.len - 1).0)
    }

    /// The rate at chip instant `t` (1/16 of the stamps' unit): linear
    /// between the means on either side of it, °/s at `dps_per_lsb`.
    pub fn at(&self, t: u32, dps_per_lsb: f32) -> Aligned {
        let n = self.n;
        if self.len < n {
            return Aligned::Missing;
        }
        let k = dps_per_lsb / n as f32;
        let dps = |s: [i32; 3]| s.map(|v| v as f32 * k);
        let mut win = self.window(self.len - 1);
        let mut later = self.mean_of(self.len - 1, win);
        if since(t, later.0) > 0 {
            return Aligned::Late;
        }
        for j in (n - 1..self.len - 1).rev() {
            win = self.slide_back(j + 1, win);
            let earlier = self.mean_of(j, win);
            let span = since(later.0, earlier.0);
            let into = since(t, earlier.0);
            if into >= 0 && span > 0 {
                let f = into as f32 / span as f32;
                let (e, l) = (dps(earlier.1), dps(later.1));
                let mut r = [0.0; 3];
                for a in 0..3 {
                    r[a] = e[a] + f * (l[a] - e[a]);
                }
                return Aligned::Rate(r);
            }
            later = earlier;
        }
        if since(t, later.0) == 0 {
            return Aligned::Rate(dps(later.1));
        }
        Aligned::Missing
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_between_the_samples_around_the_instant() {
        let mut a = Aligner::<4>::new(1);
        assert_eq!(a.at(0, 1.0), Aligned::Missing);
        // 1 kHz samples, chip µs; instants asked in 1/16 µs.
        a.push(10_000, [2, 4, 6]);
        a.push(11_000, [6, 4, -2]);
        assert_eq!(a.at(11_000 * 16 + 1, 0.5), Aligned::Late);
        assert_eq!(a.at(10_000 * 16 - 1, 0.5), Aligned::Missing);
        let Aligned::Rate(r) = a.at(10_000 * 16 + 4000, 0.5) else {
            panic!()
        };
        assert_eq!(r, [1.5, 2.0, 2.0]);
        assert_eq!(a.at(10_000 * 16, 0.5), Aligned::Rate([1.0, 2.0, 3.0]));
        assert_eq!(a.at(11_000 * 16, 0.5), Aligned::Rate([3.0, 2.0, -1.0]));
    }

    #[test]
    fn moving_means_and_the_last_cap() {
        let mut a = Aligner::<4>::new(2);
        // 2 kHz samples of a ramp of 1 LSB per 500 µs: each mean of two
        // is the ramp at their mean instant.
        for k in 0..20u32 {
            a.push(k * 500, [k as i16, 0, 0]);
        }
        assert_eq!(a.len(), 3);
        // The newest mean (samples 18, 19) describes 9.25 ms.
        assert_eq!(a.newest(), Some(9_250 * 16));
        assert_eq!(a.at(9_250 * 16, 1.0), Aligned::Rate([18.5, 0.0, 0.0]));
        // Between two means: still the ramp.
        let Aligned::Rate(r) = a.at(8_875 * 16, 1.0) else {
            panic!()
        };
        assert!((r[0] - 17.75).abs() < 1e-5, "{r:?}");
        assert_eq!(a.at(8_000 * 16, 1.0), Aligned::Missing);
    }

    #[test]
    fn sliding_back_gives_each_window_as_summed() {
        // Ring wrapped, stamps across the u32 wrap, three means of three.
        let mut a = Aligner::<8>::new(3);
        let s0 = u32::MAX - 2_000;
        for k in 0..13u32 {
            a.push(
                s0.wrapping_add(k * 250),
                [k as i16 * 7 - 40, -(k as i16), 3],
            );
        }
        let mut win = a.window(a.len - 1);
        for k in (a.n..a.len).rev() {
            win = a.slide_back(k, win);
            assert_eq!(win, a.window(k - 1), "window ending at {}", k - 1);
            // The instant as the distances back from the newest stamp, each
            // taken on its own (no sum of wrapped stamps).
            let t = a.sample(k - 1).0;
            let behind: u32 = (1..a.n)
                .map(|i| t.wrapping_sub(a.sample(k - 1 - i).0))
                .sum();
            let mean_t = t.wrapping_mul(16).wrapping_sub(behind * 16 / a.n as u32);
            assert_eq!(a.mean_of(k - 1, win).0, mean_t, "instant of {}", k - 1);
        }
    }

    #[test]
    fn stamps_wrap() {
        let mut a = Aligner::<8>::new(2);
        let s0 = u32::MAX - 700;
        for k in 0..4u32 {
            a.push(s0.wrapping_add(k * 500), [k as i16 * 2; 3]);
        }
        // Means at s0 + 250, + 750, + 1250 (the last two past the wrap).
        let t = s0.wrapping_add(1_000).wrapping_mul(16);
        assert_eq!(a.at(t, 1.0), Aligned::Rate([4.0; 3]));
    }
}
