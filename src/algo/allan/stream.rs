//! Streaming overlapping Allan variance at octave τ, in fixed memory, with
//! exact integer arithmetic.
//!
//! Gyro samples are integers (raw counts, or a fused rate quantised with
//! [`quantise`]). For each τ = 2ʲ·τ0 two sliding sums of m = 2ʲ samples are
//! kept, `a` (the newest m) and `b` (the m before); each new sample adds
//! `(a − b)²` to an exact u128 sum. Nothing is ever subtracted from a float,
//! so after 10⁷ (or 10¹⁵) samples the result still equals a from-scratch
//! recompute bit for bit: there is no drift to bound.
//!
//! Range: |sample| < 2²⁰ and m ≤ 2¹⁰ keep |a|, |b| < 2³⁰, |a − b| < 2³¹.

use super::{AdevPoint, AllanError};

/// Largest accepted |sample| (2²⁰ − 1: sums of 2¹⁰ samples then differ by
/// less than 2³¹, so differences and squares stay in one `smull`).
pub const SAMPLE_MAX: i32 = (1 << 20) - 1;

/// Quantise a rate to integer steps of `lsb` (same unit). Saturating input
/// or NaN gives an error rather than a silently clipped sample.
pub fn quantise(rate: f32, lsb: f32) -> Result<i32, AllanError> {
    let q = rate / lsb;
    if !q.is_finite() {
        return Err(AllanError::NonFinite);
    }
    let r = if q >= 0.0 { q + 0.5 } else { q - 0.5 };
    if !(r.abs() <= SAMPLE_MAX as f32) {
        return Err(AllanError::SampleRange);
    }
    Ok(r as i32)
}

/// Streaming OADEV at `T` cluster sizes (octaves m = 1, 2, …, 2^(T−1) by
/// [`StreamAdev::new`], or any list by [`StreamAdev::with_ms`]) with a ring
/// of `RING` samples (a power of two, ≥ 2·max m). RAM: 4·RING + 28·T bytes.
#[derive(Clone, Debug)]
pub struct StreamAdev<const T: usize, const RING: usize> {
    ring: [i32; RING],
    n: u64,
    ms: [u32; T],
    a: [i32; T],
    b: [i32; T],
    acc: [u128; T],
}

impl<const T: usize, const RING: usize> StreamAdev<T, RING> {
    /// Octave τ: m = 2ʲ for j < T. Needs 1 ≤ T ≤ 11 and RING ≥ 2^T.
    pub fn new() -> Result<Self, AllanError> {
        let mut ms = [0u32; T];
        for (j, m) in ms.iter_mut().enumerate() {
            *m = 1u32.checked_shl(j as u32).unwrap_or(0);
        }
        Self::with_ms(ms)
    }

    /// Any list of cluster sizes, 1 ≤ m ≤ 1024 (sums of m samples stay below
    /// 2³⁰), with RING a power of two ≥ 2·max m.
    pub fn with_ms(ms: [u32; T]) -> Result<Self, AllanError> {
        let ok_m = ms.iter().all(|&m| (1..=1024).contains(&m));
        let max = ms.iter().copied().max().unwrap_or(0) as usize;
        if T == 0 || !ok_m || !RING.is_power_of_two() || RING < 2 * max {
            return Err(AllanError::Capacity);
        }
        Ok(Self {
            ring: [0; RING],
            n: 0,
            ms,
            a: [0; T],
            b: [0; T],
            acc: [0; T],
        })
    }

    /// Samples pushed so far.
    pub fn samples(&self) -> u64 {
        self.n
    }

    /// Sample `back` steps before the newest one already stored (0 = the
    /// newest); 0 before the start, so the first sums build up exactly.
    #[inline(always)]
    fn at(&self, back: usize) -> i32 {
        if (back as u64) < self.n {
            self.ring[(self.n as usize).wrapping_sub(1 + back) & (RING - 1)]
        } else {
            0
        }
    }

    /// Add one sample. Out-of-range samples are refused (typed error) and
    /// leave the state unchanged.
    pub fn push(&mut self, w: i32) -> Result<(), AllanError> {
        if !(-SAMPLE_MAX..=SAMPLE_MAX).contains(&w) {
            return Err(AllanError::SampleRange);
        }
        for j in 0..T {
            let m = self.ms[j] as usize;
            // w enters a; the sample m back (counting w) moves from a to b;
            // the one 2m back leaves b. Read before w is stored, so a ring
            // of 2m samples is enough.
            let mid = self.at(m - 1);
            let old = self.at(2 * m - 1);
            self.a[j] += w - mid;
            self.b[j] += mid - old;
            if self.n + 1 >= 2 * m as u64 {
                let d = self.a[j] - self.b[j];
                self.acc[j] += (d as i64 * d as i64) as u64 as u128;
            }
        }
        self.ring[self.n as usize & (RING - 1)] = w;
        self.n += 1;
        Ok(())
    }

    /// The point for the `j`-th cluster size (m = 2ʲ for [`StreamAdev::new`]),
    /// scaled by `lsb` (sample unit → rate unit) with sample period `tau0_s`.
    pub fn point(&self, j: usize, lsb: f64, tau0_s: f64) -> Result<AdevPoint, AllanError> {
        if j >= T {
            return Err(AllanError::Capacity);
        }
        let m = self.ms[j] as u64;
        if self.n < 2 * m {
            return Err(AllanError::TooShort);
        }
        let terms = self.n - 2 * m + 1;
        // The differences of m-sample sums are second differences of the
        // phase in samples; scale to the rate unit.
        let sum_sq = self.acc[j] as f64 * lsb * lsb;
        Ok(AdevPoint::from_sum(
            m as usize, tau0_s, sum_sq, terms, self.n,
        ))
    }
}
