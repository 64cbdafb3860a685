//! One chip's samples brought to the array's common output instants.
//!
//! Each sample arrives with the board instant it describes: its
//! data-ready time on the board's clock ([`super::clock`]) less the chip's
//! signal-path delay. The aligner first takes the moving mean of the last
//! `n` samples (a chip at `n` times the output rate: the mean of `n` has
//! zeros at the output rate and its multiples, so what the chip's filters
//! pass near them does not fold into band; moving, so each new sample
//! gives a new mean and the newest is only (n − 1)/2 samples old), then
//! interpolates linearly between the two means around the instant asked
//! for. A sample repeated by
//! the chip's clock being slow, or skipped by its being fast, is neither:
//! the FIFO gives every sample once, and the instant asked for falls
//! between two of them wherever the chip's phase is.

use super::clock::{since, Instant16};

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

/// The aligner of one chip: the last `CAP` moving means.
#[derive(Clone, Copy, Debug)]
pub struct Aligner<const CAP: usize> {
    ring: [(Instant16, [f32; 3]); CAP],
    len: usize,
    head: usize,
    /// Samples per mean.
    n: usize,
    raw: [(Instant16, [f32; 3]); MAX_MEAN],
    raw_len: usize,
    /// The slot the next raw sample goes to.
    raw_head: usize,
}

impl<const CAP: usize> Aligner<CAP> {
    /// An aligner over moving means of `n` samples (1 for none; at most
    /// [`MAX_MEAN`]).
    pub const fn new(n: u8) -> Self {
        let n = n as usize;
        let n = if n == 0 {
            1
        } else if n > MAX_MEAN {
            MAX_MEAN
        } else {
            n
        };
        Self {
            ring: [(0, [0.0; 3]); CAP],
            len: 0,
            head: 0,
            n,
            raw: [(0, [0.0; 3]); MAX_MEAN],
            raw_len: 0,
            raw_head: 0,
        }
    }

    /// Forget every sample (a gap: an overflow, a restart).
    pub fn clear(&mut self) {
        self.len = 0;
        self.raw_len = 0;
        self.raw_head = 0;
    }

    /// Means held.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether none is held.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// One sample: the rate, and the board instant it describes.
    pub fn push(&mut self, t: Instant16, rate_dps: [f32; 3]) {
        // (Wraps by compare, not `%`: a division and its multiply-back
        // each time, three a push, on the Cortex-M4.)
        let n = self.n.min(MAX_MEAN);
        let i = self.raw_head;
        if let Some(slot) = self.raw.get_mut(i) {
            *slot = (t, rate_dps);
        }
        self.raw_head = if i + 1 >= n { 0 } else { i + 1 };
        if self.raw_len < n {
            self.raw_len += 1;
            if self.raw_len < n {
                return;
            }
        }
        // The mean of the n, at the mean of their instants (taken from the
        // newest, so a wrap between them does no harm). The n instants lie
        // within a few ms of each other: their distances from the newest
        // sum well inside an i32 (an i64 sum and division cost some 100
        // instructions on the Cortex-M4).
        let mut v = [0.0f32; 3];
        let mut dt = 0i32;
        for (ti, ri) in &self.raw[..n] {
            v[0] += ri[0];
            v[1] += ri[1];
            v[2] += ri[2];
            dt = dt.saturating_add(since(*ti, t));
        }
        let mean_t = t.wrapping_add((dt / n as i32) as u32);
        let k = 1.0 / n as f32;
        let j = (self.head + self.len) % CAP;
        self.ring[j] = (mean_t, [v[0] * k, v[1] * k, v[2] * k]);
        if self.len < CAP {
            self.len += 1;
        } else {
            self.head = (self.head + 1) % CAP;
        }
    }

    /// The newest averaged sample's instant.
    pub fn newest(&self) -> Option<Instant16> {
        (self.len > 0).then(|| self.ring[(self.head + self.len - 1) % CAP].0)
    }

    /// The rate at instant `t`: linear between the averaged samples on
    /// either side of it.
    pub fn at(&self, t: Instant16) -> Aligned {
        if self.len == 0 {
            return Aligned::Missing;
        }
        let mut later = self.ring[(self.head + self.len - 1) % CAP];
        if since(t, later.0) > 0 {
            return Aligned::Late;
        }
        for k in (0..self.len - 1).rev() {
            let earlier = self.ring[(self.head + k) % CAP];
            let span = since(later.0, earlier.0);
            let into = since(t, earlier.0);
            if into >= 0 && span > 0 {
                let f = into as f32 / span as f32;
                let mut r = [0.0; 3];
                for a in 0..3 {
                    r[a] = earlier.1[a] + f * (later.1[a] - earlier.1[a]);
                }
                return Aligned::Rate(r);
            }
            later = earlier;
        }
        if since(t, later.0) == 0 {
            return Aligned::Rate(later.1);
        }
        Aligned::Missing
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 1 kHz instant grid in 1/16 µs.
    fn ms(k: u32) -> Instant16 {
        k.wrapping_mul(16_000)
    }

    #[test]
    fn interpolates_between_the_samples_around_the_instant() {
        let mut a = Aligner::<4>::new(1);
        assert_eq!(a.at(ms(0)), Aligned::Missing);
        a.push(ms(10), [1.0, 2.0, 3.0]);
        a.push(ms(11), [3.0, 2.0, -1.0]);
        assert_eq!(a.at(ms(11) + 1), Aligned::Late);
        assert_eq!(a.at(ms(10) - 1), Aligned::Missing);
        let Aligned::Rate(r) = a.at(ms(10) + 4000) else {
            panic!()
        };
        assert_eq!(r, [1.5, 2.0, 2.0]);
        assert_eq!(a.at(ms(10)), Aligned::Rate([1.0, 2.0, 3.0]));
        assert_eq!(a.at(ms(11)), Aligned::Rate([3.0, 2.0, -1.0]));
    }

    #[test]
    fn moving_means_and_the_last_cap() {
        let mut a = Aligner::<3>::new(2);
        // 2 kHz samples of a ramp of 1 °/s per ms: each mean of two is the
        // ramp at their mean instant.
        for k in 0..20u32 {
            a.push(k * 8000, [k as f32 * 0.5, 0.0, 0.0]);
        }
        assert_eq!(a.len(), 3);
        // The newest mean (samples 18, 19) describes 9.25 ms.
        assert_eq!(a.newest(), Some(18 * 8000 + 4000));
        assert_eq!(a.at(18 * 8000 + 4000), Aligned::Rate([9.25, 0.0, 0.0]));
        // Between two means: still the ramp.
        let Aligned::Rate(r) = a.at(17 * 8000 + 6000) else {
            panic!()
        };
        assert!((r[0] - 8.875).abs() < 1e-6);
        assert_eq!(a.at(16 * 8000), Aligned::Missing);
    }

    #[test]
    fn instants_wrap() {
        let mut a = Aligner::<4>::new(1);
        let t0 = u32::MAX - 8000;
        a.push(t0, [0.0; 3]);
        a.push(t0.wrapping_add(16_000), [2.0; 3]);
        assert_eq!(a.at(t0.wrapping_add(8000)), Aligned::Rate([1.0; 3]));
    }
}
