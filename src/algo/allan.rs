//! Overlapping Allan variance of rate data (IEEE Std 952
//! Annex C, NIST SP 1065 §5.2.4), its confidence intervals, and the IEEE 952
//! noise terms read from the curve.
//!
//! - [`oavar`]: batch, f64, over a slice: the host and log-analysis path.
//! - [`stream`]: fixed-capacity streaming over integer samples with exact
//!   integer sums, for the board.
//! - [`edf`] / [`AdevPoint::interval`]: equivalent degrees of freedom
//!   (SP 1065 Table 5, "simple" formulas) and χ² confidence intervals.
//! - [`noise_terms`]: angle random walk, bias instability, rate random walk,
//!   quantisation and rate ramp, each with its unit.

pub mod stream;

use crate::algo::stats::chi2_quantile;

/// Why an Allan variance could not be computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AllanError {
    /// Cluster size m = 0, or τ0 not finite and positive.
    BadTau,
    /// Fewer than 2m samples: no term exists for this τ (documented
    /// skip: callers list the τ they could not compute).
    TooShort,
    /// A sample is NaN or infinite.
    NonFinite,
    /// The phase scratch buffer is shorter than the data plus one.
    Scratch,
    /// An integer sample has |w| ≥ 2²⁰ (streaming path; sums must stay
    /// exact in i32/u64).
    SampleRange,
    /// A capacity, size or setting does not fit the const bounds.
    Capacity,
}

/// One point of an Allan deviation curve.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AdevPoint {
    /// Cluster size m (τ = m·τ0).
    pub m: u32,
    /// τ, seconds.
    pub tau_s: f64,
    /// Allan variance, (input unit)², e.g. (°/s)².
    pub avar: f64,
    /// Number of terms summed (N − 2m + 1 for N rate samples).
    pub terms: u64,
    /// Number of rate samples the point was computed from.
    pub samples: u64,
}

impl AdevPoint {
    /// The point for cluster size `m` from the sum of squared second
    /// differences of the phase (in rate units × samples): σ² =
    /// Σd² / (2 m² · terms). Every path (batch, octave sweep, streaming)
    /// builds its points here.
    pub fn from_sum(m: usize, tau0_s: f64, sum_sq: f64, terms: u64, samples: u64) -> Self {
        let mf = m as f64;
        Self {
            m: m as u32,
            tau_s: mf * tau0_s,
            avar: sum_sq / (2.0 * mf * mf * terms as f64),
            terms,
            samples,
        }
    }

    /// At least 10 clusters of m samples went into the point (N ≥ 10·m).
    /// Beyond that a point rests on a handful of independent differences.
    pub fn reliable(&self) -> bool {
        self.samples >= 10 * self.m as u64
    }

    /// Allan deviation, input unit (e.g. °/s).
    pub fn adev(&self) -> f64 {
        libm::sqrt(self.avar)
    }

    /// Two-sided confidence interval of the deviation at `confidence`
    /// (e.g. 0.683), from the EDF for the given noise type: `(lo, hi)`.
    pub fn interval(&self, noise: NoiseType, confidence: f64) -> Option<(f64, f64)> {
        let e = edf(noise, self.samples + 1, self.m as u64)?;
        let p = 0.5 * (1.0 - confidence);
        let lo = chi2_quantile(1.0 - p, e)?;
        let hi = chi2_quantile(p, e)?;
        Some((
            libm::sqrt(self.avar * e / lo),
            libm::sqrt(self.avar * e / hi),
        ))
    }
}

/// Power-law noise type of the rate data, by the exponent α of its
/// spectrum S_y(f) ∝ f^α (SP 1065 §4). Gyro names in brackets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum NoiseType {
    /// α = 2, white phase (angle quantisation).
    WhitePm,
    /// α = 1, flicker phase.
    FlickerPm,
    /// α = 0, white frequency (angle random walk).
    WhiteFm,
    /// α = −1, flicker frequency (bias instability).
    FlickerFm,
    /// α = −2, random-walk frequency (rate random walk).
    RandomWalkFm,
}

impl NoiseType {
    /// Dominant noise type from the local log–log slope μ of σ(τ)
    /// (σ ∝ τ^μ: −1 for PM, −½ white FM, 0 flicker FM, +½ RWFM).
    pub fn from_adev_slope(mu: f64) -> Self {
        if mu < -0.75 {
            NoiseType::WhitePm
        } else if mu < -0.25 {
            NoiseType::WhiteFm
        } else if mu < 0.25 {
            NoiseType::FlickerFm
        } else {
            NoiseType::RandomWalkFm
        }
    }
}

/// Equivalent degrees of freedom of the overlapping AVAR, SP 1065 Table 5
/// ("simple" formulas, after Howe, Allan and Barnes), with `n_phase` phase
/// points (rate samples + 1) and cluster size `m`. `None` if undefined.
pub fn edf(noise: NoiseType, n_phase: u64, m: u64) -> Option<f64> {
    let n = n_phase as f64;
    let m_f = m as f64;
    if m == 0 || n_phase < 4 || (n_phase - 1) / 2 < m {
        return None;
    }
    let e = match noise {
        NoiseType::WhitePm => (n + 1.0) * (n - 2.0 * m_f) / (2.0 * (n - m_f)),
        NoiseType::FlickerPm => libm::exp(libm::sqrt(
            libm::log((n - 1.0) / (2.0 * m_f)) * libm::log((2.0 * m_f + 1.0) * (n - 1.0) / 4.0),
        )),
        NoiseType::WhiteFm => {
            (3.0 * (n - 1.0) / (2.0 * m_f) - 2.0 * (n - 2.0) / n) * 4.0 * m_f * m_f
                / (4.0 * m_f * m_f + 5.0)
        }
        NoiseType::FlickerFm => {
            if m == 1 {
                2.0 * (n - 2.0) / (2.3 * n - 4.9)
            } else {
                5.0 * n * n / (4.0 * m_f * (n + 3.0 * m_f))
            }
        }
        NoiseType::RandomWalkFm => {
            (n - 2.0) / m_f * ((n - 1.0) * (n - 1.0) - 3.0 * m_f * (n - 1.0) + 4.0 * m_f * m_f)
                / ((n - 3.0) * (n - 3.0))
        }
    };
    (e.is_finite() && e > 0.0).then_some(e)
}

/// Overlapping Allan variance of `rate` at cluster size `m` (τ = m·τ0), f64.
///
/// The mean rate is removed first (it cancels in every term), then the
/// angle θ is accumulated into `phase` (length ≥ `rate.len() + 1`) and
/// `σ² = Σ (θ[k+2m] − 2θ[k+m] + θ[k])² / (2 m² τ0² (N − 2m + 1))`.
/// Removing the mean keeps θ small, so the second difference keeps its
/// digits even at large bias and 10⁷ samples.
pub fn oavar(
    rate: &[f64],
    tau0_s: f64,
    m: usize,
    phase: &mut [f64],
) -> Result<AdevPoint, AllanError> {
    fill_phase(rate, phase)?;
    oavar_phase(&phase[..rate.len() + 1], tau0_s, m)
}

/// Overlapping AVAR of `rate` at every octave τ that fits, into `out`
/// (one sweep, see [`oavar_octave_phase`]); `phase` is scratch of
/// `rate.len() + 1`. Returns the number of points.
pub fn oavar_octave(
    rate: &[f64],
    tau0_s: f64,
    phase: &mut [f64],
    out: &mut [AdevPoint],
) -> Result<usize, AllanError> {
    fill_phase(rate, phase)?;
    Ok(oavar_octave_phase(&phase[..rate.len() + 1], tau0_s, out))
}

/// Phase (angle in units of rate·τ0, mean rate removed) of `rate` into
/// `phase[..=rate.len()]`.
///
/// The mean is summed in independent lanes (vectorised; one chain of
/// dependent additions waits ~4 cycles per sample on a host core, and
/// two such passes were 0.03 s of the 0.13 s for 10⁷ samples). The
/// running sum stays one chain: running sums side by side, each from the
/// sum of the parts before it, met with a jump of 2e-3 where the parts
/// meet (the quantised test data rounds the same way for millions of
/// additions), and the OADEV moved by 8e-9. Non-finite data, or data so
/// large that its sum overflows, is refused.
pub fn fill_phase(rate: &[f64], phase: &mut [f64]) -> Result<(), AllanError> {
    let n = rate.len();
    let Some(phase) = phase.get_mut(..n + 1) else {
        return Err(AllanError::Scratch);
    };
    let total = lane_sum(rate);
    if !total.is_finite() {
        return Err(AllanError::NonFinite);
    }
    let mean = total / n.max(1) as f64;
    let mut x = 0.0;
    phase[0] = 0.0;
    for (p, &w) in phase[1..].iter_mut().zip(rate) {
        x += w - mean;
        *p = x;
    }
    Ok(())
}

/// Σ `x` in [`LANES`] independent partial sums (vectorised, no chain).
fn lane_sum(x: &[f64]) -> f64 {
    let mut l = [0.0f64; LANES];
    let c = x.chunks_exact(LANES);
    let r = c.remainder();
    for a in c {
        for q in 0..LANES {
            l[q] += a[q];
        }
    }
    l.iter().sum::<f64>() + r.iter().sum::<f64>()
}

/// Overlapping AVAR from phase filled by [`fill_phase`] (θ in rate units ×
/// samples; `phase.len()` = rate samples + 1).
pub fn oavar_phase(phase: &[f64], tau0_s: f64, m: usize) -> Result<AdevPoint, AllanError> {
    oavar_phase_inline(phase, tau0_s, m)
}

/// Whether this CPU runs the `_avx2` builds of the kernels below (AVX2 and
/// FMA), which give the plain builds' bits faster (host builds).
#[cfg(all(target_arch = "x86_64", any(test, feature = "std")))]
pub fn has_avx2_fma() -> bool {
    std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
}

/// [`oavar_phase`] compiled for AVX2 and FMA (x86-64 hosts; call it only
/// where `has_avx2_fma` holds). The same operations in the same order, so
/// the same bits: checked by a test. Each term is formed and added to its
/// lane by fused multiply-adds (`fma`, in every build: one rounding, the
/// same in the scalar build's call as in the instruction). Every-τ sweeps
/// are bound by arithmetic: 10⁵ samples at every τ took 0.51 s instead of
/// 0.70 on `allan-speed`'s host with AVX2, and the grouped kernel, fused,
/// 0.265 s instead of 0.36 on an EPYC.
///
/// # Safety
///
/// Call it only on a CPU with AVX2 and FMA (calling it is `unsafe` for
/// that).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
pub fn oavar_phase_avx2(phase: &[f64], tau0_s: f64, m: usize) -> Result<AdevPoint, AllanError> {
    oavar_phase_inline(phase, tau0_s, m)
}

#[inline(always)]
fn oavar_phase_inline(phase: &[f64], tau0_s: f64, m: usize) -> Result<AdevPoint, AllanError> {
    let n = check_cluster(phase, tau0_s, m)?;
    let terms = phase.len() - 2 * m;
    let s = second_diff_inline(phase, m, 0, terms);
    Ok(AdevPoint::from_sum(m, tau0_s, s, terms as u64, n as u64))
}

/// Σ (θ[i + 2m] − 2θ[i + m] + θ\[i\])² over i in `from..to`: the kernel of
/// every overlapping Allan-type sum (the host tool's OADEV and TOTDEV use
/// it). 0 for an empty range or one that does not fit in `phase`.
pub fn second_diff_sum(phase: &[f64], m: usize, from: usize, to: usize) -> f64 {
    second_diff_inline(phase, m, from, to)
}

/// [`second_diff_sum`] compiled for AVX2 and FMA (see [`oavar_phase_avx2`]).
///
/// # Safety
///
/// Call it only on a CPU with AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
pub fn second_diff_sum_avx2(phase: &[f64], m: usize, from: usize, to: usize) -> f64 {
    second_diff_inline(phase, m, from, to)
}

#[inline(always)]
fn second_diff_inline(phase: &[f64], m: usize, from: usize, to: usize) -> f64 {
    let len = to.saturating_sub(from);
    let end = m.checked_mul(2).and_then(|m2| to.checked_add(m2));
    if len == 0 || end.is_none_or(|e| e > phase.len()) {
        return 0.0;
    }
    let l = second_diff_sq::<true, LANES>(
        &phase[from..to],
        &phase[from + m..to + m],
        &phase[from + 2 * m..to + 2 * m],
    );
    l.iter().sum()
}

/// One chunk of terms into a factor's lanes: lane q adds
/// (c[q] − 2·b[q] + a[q])².
#[inline(always)]
fn add_terms(l: &mut [f64; LANES], a: &[f64], b: &[f64], c: &[f64]) {
    let (a, b, c) = (&a[..LANES], &b[..LANES], &c[..LANES]);
    for q in 0..LANES {
        let d = second_diff(a[q], b[q], c[q]);
        l[q] = fma(d, d, l[q]);
    }
}

/// Factors of [`second_diff_sums`] that share their loads of θ\[i\].
const SHARE: usize = 4;

/// Factors one pass of [`second_diff_sums`] takes at most.
pub const GROUP: usize = 16;
/// Terms of each factor a block of [`second_diff_sums`] sums before the
/// next factor: a multiple of [`LANES`], its three stretches of the phase
/// (12 KiB) within a core's L1 cache.
const GROUP_BLOCK: usize = 512;

/// [`second_diff_sum`] from 0 over every term (i + 2m < len) for the
/// consecutive factors m0, m0 + 1, … (`sums.len()` of them, at most
/// [`GROUP`]; each must have a term): the same sums, bit for bit. Each
/// factor's lanes add its terms in the order the one-factor kernel does
/// (lane q the terms q, q + LANES, … and the remainder in lane 0), but
/// the factors take turns block by block, so the three stretches of the
/// phase a block reads come from the L1 cache for all of them: one factor
/// at a time streams the whole series from the outer caches each time,
/// and the sum is bound by their bandwidth (every τ of 10⁵ points).
pub fn second_diff_sums(phase: &[f64], m0: usize, sums: &mut [f64]) {
    second_diff_sums_inline(phase, m0, sums);
}

/// [`second_diff_sums`] compiled for AVX2 and FMA (see [`oavar_phase_avx2`]).
///
/// # Safety
///
/// Call it only on a CPU with AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
pub fn second_diff_sums_avx2(phase: &[f64], m0: usize, sums: &mut [f64]) {
    second_diff_sums_inline(phase, m0, sums);
}

#[inline(always)]
fn second_diff_sums_inline(phase: &[f64], m0: usize, sums: &mut [f64]) {
    let n = phase.len();
    let g_n = sums.len().min(GROUP);
    // Each factor's term count and the part of it in whole lanes.
    let span = |g: usize| n.saturating_sub(2 * (m0 + g));
    let mut lanes = [[0.0f64; LANES]; GROUP];
    let whole = |g: usize| span(g) - span(g) % LANES;
    let longest = whole(0);
    let mut b = 0;
    while b < longest {
        let e = (b + GROUP_BLOCK).min(longest);
        // Factors in SHAREs that all run to the block's end share each
        // chunk's load of θ[i]: two loads a term instead of three.
        let mut g = 0;
        while g + SHARE <= g_n && whole(g + SHARE - 1) >= e {
            let x0 = &phase[b..e];
            let m = m0 + g;
            let far = |k: usize| &phase[b + k..e + k];
            let x1: [&[f64]; SHARE] = core::array::from_fn(|s| far(m + s));
            let x2: [&[f64]; SHARE] = core::array::from_fn(|s| far(2 * (m + s)));
            let mut acc: [[f64; LANES]; SHARE] = core::array::from_fn(|s| lanes[g + s]);
            // (Every stretch is e − b long.)
            let mut j = 0;
            while j + LANES <= x0.len() {
                let a = &x0[j..j + LANES];
                for s in 0..SHARE {
                    add_terms(&mut acc[s], a, &x1[s][j..j + LANES], &x2[s][j..j + LANES]);
                }
                j += LANES;
            }
            lanes[g..g + SHARE].copy_from_slice(&acc);
            g += SHARE;
        }
        for (g, l) in lanes.iter_mut().enumerate().take(g_n).skip(g) {
            let end = e.min(whole(g));
            if end <= b {
                break;
            }
            let m = m0 + g;
            let (Some(x0), Some(x1), Some(x2)) = (
                phase.get(b..end),
                phase.get(b + m..end + m),
                phase.get(b + 2 * m..end + 2 * m),
            ) else {
                break;
            };
            let c0 = x0.chunks_exact(LANES);
            let c1 = x1.chunks_exact(LANES);
            let c2 = x2.chunks_exact(LANES);
            for ((a, bb), c) in c0.zip(c1).zip(c2) {
                for q in 0..LANES {
                    let d = second_diff(a[q], bb[q], c[q]);
                    l[q] = fma(d, d, l[q]);
                }
            }
        }
        b = e;
    }
    for (g, (l, out)) in lanes.iter_mut().zip(sums.iter_mut()).enumerate().take(g_n) {
        let m = m0 + g;
        for i in whole(g)..span(g) {
            let d = second_diff(phase[i], phase[i + m], phase[i + 2 * m]);
            l[0] = fma(d, d, l[0]);
        }
        *out = l.iter().sum();
    }
}

/// Check m and τ0 against phase data; the number of rate samples.
fn check_cluster(phase: &[f64], tau0_s: f64, m: usize) -> Result<usize, AllanError> {
    if m == 0 || !(tau0_s > 0.0) || !tau0_s.is_finite() {
        return Err(AllanError::BadTau);
    }
    let n = phase.len().saturating_sub(1);
    // n / 2 < m, not n < 2m: 2m overflows for m ≥ 2⁶³ (found by fuzzing).
    if n / 2 < m {
        return Err(AllanError::TooShort);
    }
    Ok(n)
}

/// Overlapping AVAR at every octave m = 1, 2, 4, … that fits, in one
/// sweep over `phase` (from [`fill_phase`]); writes `out[j]` for m = 2ʲ and
/// returns how many were written. Same sums as [`oavar_phase`], up to the
/// order of additions and its fused multiply-adds.
pub fn oavar_octave_phase(phase: &[f64], tau0_s: f64, out: &mut [AdevPoint]) -> usize {
    let mut sums = OctaveSums::new(phase.len());
    sums.add_range(phase, 0, phase.len());
    sums.finish(tau0_s, out)
}

/// [`oavar_octave_phase`] compiled for AVX2 and FMA (see [`oavar_phase_avx2`]):
/// the same bits.
///
/// # Safety
///
/// Call it only on a CPU with AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
pub fn oavar_octave_phase_avx2(phase: &[f64], tau0_s: f64, out: &mut [AdevPoint]) -> usize {
    let mut sums = OctaveSums::new(phase.len());
    sums.add_range_inline(phase, 0, phase.len());
    sums.finish(tau0_s, out)
}

/// Partial sums of the octave OADEV sweep. Split the term index range
/// among threads (host) with [`OctaveSums::add_range`], [`OctaveSums::merge`]
/// the parts, then [`OctaveSums::finish`].
///
/// The sweep goes block by block and, inside a block, τ by τ: τ j reads θ
/// at offsets 0, m and 2m, and τ j + 1 reads 0, 2m and 4m, so two of its
/// three streams are still in cache. Memory is read about once for all τ
/// whose offsets fit in the cache, instead of once per τ. Short blocks
/// (64 points) keep the streams advancing together, as the hardware
/// prefetchers follow them: on 10⁷ points (`allan-speed`'s host) the sweep
/// took 0.069 s with 64, 0.072 with 128, 0.084 with 512 and 0.098 with
/// 2048. The τ of m < 2¹⁰ go in one sweep and the longer in a second:
/// on a 2-core Xeon (AVX2) 0.107 s against 0.129–0.157 for all ~24 τ in
/// one, where more streams run at once than the prefetchers track.
#[derive(Clone, Debug)]
pub struct OctaveSums {
    phase_len: usize,
    count: usize,
    acc: [[f64; OCT_LANES]; OctaveSums::MAX_J],
}

impl OctaveSums {
    const MAX_J: usize = 48;
    const BLOCK: usize = 64;
    /// The τ are swept in tiers, m = 2ʲ for j in TIERS[i]..TIERS[i + 1]:
    /// 24 streams in one sweep are more than the prefetchers follow. The
    /// first tier's streams lie within 16 KiB (L1), the second's within
    /// 1 MiB (L2), so each of them reads memory about once.
    const TIERS: [usize; 4] = [0, 10, 16, Self::MAX_J];

    /// Sums for phase data of `phase_len` points (rate samples + 1).
    pub fn new(phase_len: usize) -> Self {
        let n = phase_len.saturating_sub(1);
        Self {
            phase_len,
            count: octave_ms(n).count().min(Self::MAX_J),
            acc: [[0.0; OCT_LANES]; Self::MAX_J],
        }
    }

    /// Add the terms with index k in `from..to` (clipped to each τ's count).
    /// `phase` must be the whole series (`phase_len` points).
    pub fn add_range(&mut self, phase: &[f64], from: usize, to: usize) {
        self.add_range_inline(phase, from, to);
    }

    /// [`OctaveSums::add_range`], inlined into its caller's build (the
    /// AVX2 one of [`oavar_octave_phase_avx2`]).
    #[inline(always)]
    fn add_range_inline(&mut self, phase: &[f64], from: usize, to: usize) {
        if phase.len() != self.phase_len {
            return;
        }
        let n = phase.len();
        // The sums in a local copy: summed in place in `self`, the sweep
        // took 0.087 s instead of 0.070 (the same loop; likely the stores
        // falsely aliasing the loads).
        let mut local = self.acc;
        let count = self.count;
        for w in Self::TIERS.windows(2) {
            let (j0, j1) = (w[0].min(count), w[1].min(count));
            let acc = &mut local[j0..j1];
            let mut k0 = from;
            while k0 < to {
                let k1 = (k0 + Self::BLOCK).min(to);
                for (j, a) in acc.iter_mut().enumerate() {
                    let m = 1usize << (j0 + j);
                    let terms = n - 2 * m;
                    if k0 >= terms {
                        break;
                    }
                    let len = k1.min(terms) - k0;
                    let l = second_diff_sq::<false, OCT_LANES>(
                        &phase[k0..k0 + len],
                        &phase[k0 + m..k0 + m + len],
                        &phase[k0 + 2 * m..k0 + 2 * m + len],
                    );
                    for q in 0..OCT_LANES {
                        a[q] += l[q];
                    }
                }
                k0 = k1;
            }
        }
        self.acc = local;
    }

    /// Add another part's sums (same `phase_len`).
    pub fn merge(&mut self, other: &OctaveSums) {
        for (a, b) in self.acc.iter_mut().zip(other.acc.iter()) {
            for q in 0..OCT_LANES {
                a[q] += b[q];
            }
        }
    }

    /// Write the curve (`out[j]` for m = 2ʲ); returns the number of points.
    pub fn finish(&self, tau0_s: f64, out: &mut [AdevPoint]) -> usize {
        if !(tau0_s > 0.0) || !tau0_s.is_finite() {
            return 0;
        }
        let count = self.count.min(out.len());
        let n = self.phase_len.saturating_sub(1);
        for (j, (o, a)) in out.iter_mut().zip(self.acc.iter()).take(count).enumerate() {
            let m = 1usize << j;
            let terms = (self.phase_len - 2 * m) as u64;
            *o = AdevPoint::from_sum(m, tau0_s, a.iter().sum::<f64>(), terms, n as u64);
        }
        count
    }
}

/// a·b + c with one rounding: std's `mul_add` on the host, which the
/// builds for AVX2 and FMA vectorise; libm's (the same correctly rounded
/// result) on the board, which does not run these kernels.
#[inline(always)]
fn fma(a: f64, b: f64, c: f64) -> f64 {
    #[cfg(any(test, feature = "std"))]
    return a.mul_add(b, c);
    #[cfg(not(any(test, feature = "std")))]
    return libm::fma(a, b, c);
}

/// The phase's second difference θ₂ − 2θ₁ + θ₀, every kernel's term, as
/// (θ₀ + θ₂) − 2θ₁ in one fused multiply-add: three operations a term where
/// the written-out form took four, which the every-τ sweeps, bound by
/// arithmetic, feel (10⁵ points at every τ from Python: 0.265 s against
/// 0.305, alternated builds). Its rounding is that of one addition and one
/// fused step, as small as the written-out form's.
#[inline(always)]
fn second_diff(x0: f64, x1: f64, x2: f64) -> f64 {
    fma(-2.0, x1, x0 + x2)
}

/// Independent partial sums (lanes) of the second-difference kernel.
const LANES: usize = 8;
/// Independent partial sums of the octave sweep: in its 64-term blocks each
/// of 8 lanes was a chain of 8 dependent adds, and 16 read 7–15 % faster
/// from Python (10⁷ points, six alternated pairs of builds).
const OCT_LANES: usize = 16;

/// Σ (x2 − 2·x1 + x0)² over equal-length slices, in L partial sums. Exact
/// chunks and independent lanes let the compiler use SIMD without
/// reassociating anything itself (the result is deterministic). FUSED adds
/// each square by `fma` (the one-factor and grouped kernels, bound by
/// arithmetic); the octave sweep keeps the multiply and the add (fused,
/// its short chains read 0.080 s against 0.072 for 10⁷ points from Python).
#[inline(always)]
fn second_diff_sq<const FUSED: bool, const L: usize>(
    x0: &[f64],
    x1: &[f64],
    x2: &[f64],
) -> [f64; L] {
    let mut l = [0.0f64; L];
    let add = |acc: f64, d: f64| if FUSED { fma(d, d, acc) } else { acc + d * d };
    let c0 = x0.chunks_exact(L);
    let c1 = x1.chunks_exact(L);
    let c2 = x2.chunks_exact(L);
    let (r0, r1, r2) = (c0.remainder(), c1.remainder(), c2.remainder());
    for ((a, b), c) in c0.zip(c1).zip(c2) {
        for q in 0..L {
            let d = second_diff(a[q], b[q], c[q]);
            l[q] = add(l[q], d);
        }
    }
    for ((a, b), c) in r0.iter().zip(r1).zip(r2) {
        let d = second_diff(*a, *b, *c);
        l[0] = add(l[0], d);
    }
    l
}

/// Non-overlapping Allan variance (SP 1065 eq. 6), for the published
/// NBS14 check. Same phase input as [`oavar_phase`].
pub fn avar_phase(phase: &[f64], tau0_s: f64, m: usize) -> Result<AdevPoint, AllanError> {
    let n = check_cluster(phase, tau0_s, m)?;
    let mut s = 0.0;
    let mut terms = 0u64;
    let mut k = 0;
    while k + 2 * m < phase.len() {
        let d = second_diff(phase[k], phase[k + m], phase[k + 2 * m]);
        s += d * d;
        terms += 1;
        k += m;
    }
    Ok(AdevPoint::from_sum(m, tau0_s, s, terms, n as u64))
}

/// Octave cluster sizes 1, 2, 4, … with at least one term for `n` samples.
pub fn octave_ms(n: usize) -> impl Iterator<Item = usize> {
    (0..usize::BITS)
        .map(|j| 1usize << j)
        .take_while(move |&m| n / 2 >= m)
}

/// Which IEEE 952 term a [`NoiseTerm`] is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TermKind {
    /// Quantisation noise Q, σ = √3·Q/τ; unit arc-seconds (″).
    Quantisation,
    /// Angle random walk N, σ = N/√τ; unit °/√h.
    AngleRandomWalk,
    /// Bias instability B, flat floor σ = 0.664·B; unit °/h.
    BiasInstability,
    /// Rate random walk K, σ = K·√(τ/3); unit °/h/√h.
    RateRandomWalk,
    /// Rate ramp R, σ = R·τ/√2; unit °/h².
    RateRamp,
}

impl TermKind {
    /// Unit of the reported value.
    pub fn unit(self) -> &'static str {
        match self {
            TermKind::Quantisation => "arcsec",
            TermKind::AngleRandomWalk => "deg/sqrt(h)",
            TermKind::BiasInstability => "deg/h",
            TermKind::RateRandomWalk => "deg/h/sqrt(h)",
            TermKind::RateRamp => "deg/h^2",
        }
    }

    /// Log–log slope of σ(τ) where this term dominates.
    pub fn slope(self) -> f64 {
        match self {
            TermKind::Quantisation => -1.0,
            TermKind::AngleRandomWalk => -0.5,
            TermKind::BiasInstability => 0.0,
            TermKind::RateRandomWalk => 0.5,
            TermKind::RateRamp => 1.0,
        }
    }

    /// The term's value (in [`TermKind::unit`]) if it alone made σ at τ
    /// (σ in °/s, τ in s). Over the curve the smallest of these bounds the
    /// term from above: every other term only adds variance.
    fn alone_at(self, sigma_dps: f64, tau_s: f64) -> f64 {
        match self {
            TermKind::Quantisation => sigma_dps * tau_s / libm::sqrt(3.0) * 3600.0,
            TermKind::AngleRandomWalk => sigma_dps * libm::sqrt(tau_s) * 60.0,
            TermKind::BiasInstability => sigma_dps / 0.664 * 3600.0,
            TermKind::RateRandomWalk => sigma_dps * libm::sqrt(3.0 / tau_s) * 3600.0 * 60.0,
            TermKind::RateRamp => sigma_dps * libm::sqrt(2.0) / tau_s * 3600.0 * 3600.0,
        }
    }
}

/// One IEEE 952 noise term read from an ADEV curve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NoiseTerm {
    /// Which term.
    pub kind: TermKind,
    /// Value in `kind.unit()`.
    pub value: f64,
    /// τ (s) where it was read.
    pub tau_s: f64,
    /// True when the curve's local slope there matches the term's slope
    /// (within ±0.15), so the term is *visible*; otherwise `value` is only
    /// an upper bound.
    pub visible: bool,
}

/// IEEE 952 terms from an ADEV curve in °/s (points sorted by τ).
///
/// Each term is read where its own asymptote touches the curve from below
/// (the minimum over τ of the value that term alone would need), and is
/// marked visible only if the local log–log slope there is the term's.
/// This is the standard graphical reading, made mechanical; it needs no
/// fit and never reports a term larger than the curve allows. Points from
/// fewer than 10 clusters ([`AdevPoint::reliable`]) are skipped: their
/// scatter would make the minimum read low.
pub fn noise_terms(points: &[AdevPoint], out: &mut [Option<NoiseTerm>; 5]) {
    const KINDS: [TermKind; 5] = [
        TermKind::Quantisation,
        TermKind::AngleRandomWalk,
        TermKind::BiasInstability,
        TermKind::RateRandomWalk,
        TermKind::RateRamp,
    ];
    for (slot, kind) in out.iter_mut().zip(KINDS) {
        *slot = None;
        let mut best: Option<(usize, f64)> = None;
        for (i, p) in points.iter().enumerate() {
            if !p.reliable() {
                continue;
            }
            let v = kind.alone_at(p.adev(), p.tau_s);
            if v.is_finite() && best.is_none_or(|(_, b)| v < b) {
                best = Some((i, v));
            }
        }
        let Some((i, value)) = best else { continue };
        let slope = local_slope(points, i);
        *slot = Some(NoiseTerm {
            kind,
            value,
            tau_s: points[i].tau_s,
            visible: slope.is_some_and(|s| libm::fabs(s - kind.slope()) <= 0.15),
        });
    }
}

/// Log–log slope of σ(τ) around point `i` (central where possible).
pub fn local_slope(points: &[AdevPoint], i: usize) -> Option<f64> {
    let a = i.saturating_sub(1);
    let b = i.saturating_add(1).min(points.len().checked_sub(1)?);
    // i past the end (a ≥ b) has no neighbours (fuzzing reaches it).
    if a >= b {
        return None;
    }
    let (pa, pb) = (*points.get(a)?, *points.get(b)?);
    let s =
        (libm::log(pb.adev()) - libm::log(pa.adev())) / (libm::log(pb.tau_s) - libm::log(pa.tau_s));
    s.is_finite().then_some(s)
}

#[cfg(test)]
mod tests;
