//! Frequency-stability deviations in f64 from phase (time-error) data, as
//! NIST SP 1065 defines them and Stable32 computes them: Allan (ADEV),
//! overlapping Allan (OADEV), modified Allan (MDEV), time (TDEV), Hadamard
//! (HDEV), overlapping Hadamard (OHDEV) and total (TOTDEV); and the τ grids
//! (all, octave, decade, N per decade). Rates (°/s) become phase (°) by a
//! cumulative sum times τ0 ([`phase_from_rate`]); a deviation of such
//! phase is then in the rate's unit.
//!
//! Every function checks its input and returns a typed [`DevError`].
//! Checked against Stable32's tables for PHASE.DAT (`tests/stable32`).

use std::fmt;

use gyro_array::algo::allan;

/// Overlapping Allan variance of `rate` at every octave τ that fits, by
/// the firmware's exact sweep (`allan::oavar_octave`): the quick curve
/// `gyro analyse` and `gyro replay` print.
pub fn octave_oavar(rate: &[f64], tau0: f64) -> Result<Vec<allan::AdevPoint>, allan::AllanError> {
    let mut phase = vec![0.0; rate.len() + 1];
    let mut out = vec![allan::AdevPoint::from_sum(1, tau0, 0.0, 1, 1); 64];
    let n = allan::oavar_octave(rate, tau0, &mut phase, &mut out)?;
    out.truncate(n);
    Ok(out)
}

/// Why a deviation could not be computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DevError {
    /// τ0 is not a finite positive number.
    Tau0,
    /// A sample is NaN or infinite (its index).
    NonFinite(usize),
    /// Too few samples for this averaging factor.
    TooShort,
    /// The averaging factor is 0.
    Factor,
    /// The deviation at this factor came out infinite or NaN from finite
    /// input: values or a τ0 beyond what f64 carries through the sums
    /// (samples near ±1e308, a τ0 of 1e-300).
    Overflow(usize),
    /// TheoBR's bias ratio over more phase points than it is computed for
    /// (the limit): its Theo1 terms grow as N³.
    TooLong(usize),
}

impl fmt::Display for DevError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DevError::Tau0 => write!(f, "tau0 must be a finite number of seconds > 0"),
            DevError::NonFinite(i) => write!(f, "sample {i} is not finite"),
            DevError::TooShort => write!(f, "too few samples for this tau"),
            DevError::Factor => write!(f, "the averaging factor must be at least 1"),
            DevError::Overflow(m) => write!(
                f,
                "the deviation at factor {m} is not finite: the values or tau0 are beyond what f64 carries through the sums"
            ),
            DevError::TooLong(max) => write!(
                f,
                "TheoBR and TheoH are computed for at most {max} phase points (their bias ratio's Theo1 terms grow as N³): average the rates in blocks first"
            ),
        }
    }
}

impl std::error::Error for DevError {}

pub use crate::kind::Kind;

/// A sample period given on a command line (`gyro allan --tau0`,
/// `allan-report`): a finite number of seconds in (0, 1e6].
pub fn tau0_arg(s: &str) -> Result<f64, String> {
    let v: f64 = s
        .parse()
        .map_err(|_| format!("{s:?} is not a number of seconds"))?;
    if v.is_finite() && v > 0.0 && v <= 1e6 {
        Ok(v)
    } else {
        Err(format!("{s}: the sample period must be in (0, 1e6] s"))
    }
}

/// One point of a deviation curve.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Point {
    /// Averaging factor m (τ = m·τ0).
    pub m: usize,
    /// τ, s.
    pub tau: f64,
    /// The deviation.
    pub dev: f64,
    /// Number of terms summed (Stable32's "#").
    pub terms: usize,
    /// Noise type α at this τ by the lag-1 autocorrelation
    /// ([`noise_alpha`]; None with fewer than 30 decimated points).
    pub alpha: Option<i32>,
    /// Fewer than [`MIN_CLUSTERS`] clusters of m samples: a point to read
    /// with care (few degrees of freedom).
    pub few_clusters: bool,
    /// Equivalent degrees of freedom ([`crate::edf::of`]: Greenhall's
    /// algorithm, SP 1065 Table 7 for TOTDEV) for `alpha`, or where that
    /// is None the α identified at the nearest shorter τ.
    pub edf: Option<f64>,
    /// The confidence interval's bounds at [`curve_with`]'s confidence.
    pub lo: Option<f64>,
    pub hi: Option<f64>,
}

impl Point {
    /// The point at factor `m` of `n` phase points, before the noise type,
    /// EDF and interval are known.
    pub(crate) fn bare(m: usize, tau0: f64, dev: f64, terms: usize, n: usize) -> Self {
        Point {
            m,
            tau: m as f64 * tau0,
            dev,
            terms,
            alpha: None,
            few_clusters: n / m < MIN_CLUSTERS,
            edf: None,
            lo: None,
            hi: None,
        }
    }
}

/// See [`Point::few_clusters`].
pub const MIN_CLUSTERS: usize = 16;

/// Phase from rate samples: x₀ = 0, x_{k+1} = x_k + y_k·τ0.
pub fn phase_from_rate(rate: &[f64], tau0: f64) -> Result<Vec<f64>, DevError> {
    check(rate, tau0)?;
    let mut x = Vec::with_capacity(rate.len() + 1);
    let mut acc = 0.0;
    x.push(0.0);
    for &y in rate {
        acc += y * tau0;
        x.push(acc);
    }
    Ok(x)
}

/// `tau0` a finite positive period and every sample of `x` finite.
pub fn check(x: &[f64], tau0: f64) -> Result<(), DevError> {
    check_tau0(tau0)?;
    match x.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(DevError::NonFinite(i)),
        None => Ok(()),
    }
}

fn check_tau0(tau0: f64) -> Result<(), DevError> {
    if tau0.is_finite() && tau0 > 0.0 {
        Ok(())
    } else {
        Err(DevError::Tau0)
    }
}

/// Deviation `kind` of phase `x` (sample period `tau0`, s) at averaging
/// factor `m`.
#[cfg_attr(not(test), allow(dead_code))]
pub fn deviation(kind: Kind, x: &[f64], tau0: f64, m: usize) -> Result<Point, DevError> {
    check(x, tau0)?;
    deviation_checked(kind, x, tau0, m)
}

/// [`deviation`] at each of `factors`, the phase checked once (None where
/// a factor has too few samples). OADEV at factors that are all powers of
/// two comes from one sweep over the phase for every octave
/// (`allan::oavar_octave_phase`: the same terms, summed in another order).
pub fn deviations(
    kind: Kind,
    x: &[f64],
    tau0: f64,
    factors: &[usize],
) -> Result<Vec<Option<Point>>, DevError> {
    check(x, tau0)?;
    deviations_of_finite(kind, x, tau0, factors)
}

/// [`deviations`] of phase the caller has made sure is finite (as one
/// built by a running sum that ended finite), without the pass that
/// checks it; a bad `tau0` is still an error.
pub fn deviations_of_finite(
    kind: Kind,
    x: &[f64],
    tau0: f64,
    factors: &[usize],
) -> Result<Vec<Option<Point>>, DevError> {
    let out = deviations_unchecked(kind, x, tau0, factors)?;
    match out.iter().flatten().find(|p| !p.dev.is_finite()) {
        Some(p) => Err(DevError::Overflow(p.m)),
        None => Ok(out),
    }
}

fn deviations_unchecked(
    kind: Kind,
    x: &[f64],
    tau0: f64,
    factors: &[usize],
) -> Result<Vec<Option<Point>>, DevError> {
    check_tau0(tau0)?;
    if kind == Kind::Oadev && factors.len() > 1 && factors.iter().all(|m| m.is_power_of_two()) {
        let mut out = vec![allan::AdevPoint::from_sum(1, tau0, 0.0, 1, 1); 64];
        let k = octave_sweep(x, tau0, &mut out);
        let swept: Vec<&allan::AdevPoint> = out.iter().take(k).collect();
        return Ok(factors
            .iter()
            .map(|&m| {
                // (The sweep's variance is of the phase as given, per
                // sample: τ0² times the rate's.)
                swept
                    .iter()
                    .find(|p| p.m as usize == m)
                    .map(|p| Point::bare(m, tau0, p.adev() / tau0, p.terms as usize, x.len()))
            })
            .collect());
    }
    let mut ratio = None;
    let mut one = |m: usize| match deviation_in(kind, x, tau0, m, &mut ratio) {
        Ok(p) => Ok(Some(p)),
        Err(DevError::TooShort) => Ok(None),
        Err(e) => Err(e),
    };
    if kind != Kind::Oadev {
        return factors.iter().map(|&m| one(m)).collect();
    }
    // OADEV at runs of consecutive factors (every τ): up to
    // `allan::GROUP` at once through the grouped kernel, the same sums as
    // one factor at a time.
    let n = x.len();
    let fits = |m: usize| m > 0 && n > 2 * m;
    let mut out = Vec::with_capacity(factors.len());
    let mut k = 0;
    while let Some(&m0) = factors.get(k) {
        if !fits(m0) {
            out.push(one(m0)?);
            k += 1;
            continue;
        }
        let mut g = 1;
        while g < allan::GROUP && factors.get(k + g) == Some(&(m0 + g)) && fits(m0 + g) {
            g += 1;
        }
        let mut sums = [0.0; allan::GROUP];
        second_diff_sums(x, m0, &mut sums[..g]);
        for (j, s) in sums[..g].iter().enumerate() {
            let m = m0 + j;
            let (span, tau) = (n - 2 * m, m as f64 * tau0);
            let var = s / (2.0 * span as f64 * tau * tau);
            out.push(Some(Point::bare(m, tau0, var.sqrt(), span, n)));
        }
        k += g;
    }
    Ok(out)
}

/// [`allan::second_diff_sums`], in its AVX2 build where the CPU has AVX2
/// (the same bits).
fn second_diff_sums(x: &[f64], m0: usize, sums: &mut [f64]) {
    #[cfg(target_arch = "x86_64")]
    if allan::has_avx2_fma() {
        // SAFETY: the CPU has AVX2 and FMA (checked just above), the only
        // requirements of the AVX2 build.
        return unsafe { allan::second_diff_sums_avx2(x, m0, sums) };
    }
    allan::second_diff_sums(x, m0, sums)
}

/// The octave sweep (`allan::oavar_octave_phase`), in its AVX2 build where
/// the CPU has AVX2 (the same bits).
fn octave_sweep(x: &[f64], tau0: f64, out: &mut [allan::AdevPoint]) -> usize {
    #[cfg(target_arch = "x86_64")]
    if allan::has_avx2_fma() {
        // SAFETY: the CPU has AVX2 and FMA (checked just above), the only
        // requirements of the AVX2 build.
        return unsafe { allan::oavar_octave_phase_avx2(x, tau0, out) };
    }
    allan::oavar_octave_phase(x, tau0, out)
}

/// Σ over i of (x[i + 2m] − 2x[i + m] + x[i])² for i in `from..to` by
/// `stride`. Stride 1 (OADEV, TOTDEV) is the library's kernel
/// (`gyro_array::algo::allan::second_diff_sum`), in its AVX2 build where
/// the CPU has AVX2: the same bits, faster where the sum is bound by
/// arithmetic (every τ).
fn second_diff_sum(x: &[f64], m: usize, from: usize, to: usize, stride: usize) -> f64 {
    if to <= from {
        return 0.0;
    }
    if stride == 1 {
        #[cfg(target_arch = "x86_64")]
        if allan::has_avx2_fma() {
            // SAFETY: the CPU has AVX2 and FMA (checked just above), the only
            // requirements of the AVX2 build.
            return unsafe { allan::second_diff_sum_avx2(x, m, from, to) };
        }
        return allan::second_diff_sum(x, m, from, to);
    }
    let (a, b, c) = (
        &x[from..to],
        &x[from + m..to + m],
        &x[from + 2 * m..to + 2 * m],
    );
    a.iter()
        .zip(b)
        .zip(c)
        .step_by(stride)
        .map(|((p, q), r)| (r - 2.0 * q + p) * (r - 2.0 * q + p))
        .sum()
}

/// [`deviation`] of phase already checked finite.
fn deviation_checked(kind: Kind, x: &[f64], tau0: f64, m: usize) -> Result<Point, DevError> {
    if m == 0 {
        return Err(DevError::Factor);
    }
    let n = x.len();
    let tau = m as f64 * tau0;
    let (var, terms) = match kind {
        Kind::Adev | Kind::Oadev => {
            let stride = if kind == Kind::Adev { m } else { 1 };
            if n < 2 * m + 1 {
                return Err(DevError::TooShort);
            }
            let span = n - 2 * m; // terms with stride 1
            let k = span.div_ceil(stride);
            let s = second_diff_sum(x, m, 0, span, stride);
            (s / (2.0 * k as f64 * tau * tau), k)
        }
        Kind::Mdev | Kind::Tdev => {
            if n < 3 * m + 1 {
                return Err(DevError::TooShort);
            }
            // Inner sums of m second differences, slid by one.
            let d2 = |i: usize| x[i + 2 * m] - 2.0 * x[i + m] + x[i];
            let mut inner: f64 = (0..m).map(d2).sum();
            let count = n - 3 * m + 1;
            let mut s = inner * inner;
            for j in 1..count {
                inner += d2(j + m - 1) - d2(j - 1);
                s += inner * inner;
            }
            let mvar = s / (2.0 * (m * m) as f64 * count as f64 * tau * tau);
            if kind == Kind::Tdev {
                (tau * tau / 3.0 * mvar, count)
            } else {
                (mvar, count)
            }
        }
        Kind::Hdev | Kind::Ohdev => {
            let stride = if kind == Kind::Hdev { m } else { 1 };
            if n < 3 * m + 1 {
                return Err(DevError::TooShort);
            }
            let (mut s, mut k) = (0.0, 0usize);
            let mut i = 0;
            while i + 3 * m < n {
                let d = x[i + 3 * m] - 3.0 * x[i + 2 * m] + 3.0 * x[i + m] - x[i];
                s += d * d;
                k += 1;
                i += stride;
            }
            (s / (6.0 * k as f64 * tau * tau), k)
        }
        Kind::Totdev => {
            // SP 1065 eq. 25: extend x by reflection about both ends,
            // x*(1 − j) = 2x(1) − x(1 + j), x*(N + j) = 2x(N) − x(N − j),
            // then sum the N − 2 second differences centred on 2..N−1.
            // (Reflection reaches every m < n; the curves stop at
            // `max_factor`, as Stable32 does.)
            if n < 3 || m > n - 1 {
                return Err(DevError::TooShort);
            }
            let at = |i: isize| -> f64 {
                let last = n as isize - 1;
                if i < 0 {
                    2.0 * x[0] - x[(-i) as usize]
                } else if i > last {
                    2.0 * x[n - 1] - x[(2 * last - i) as usize]
                } else {
                    x[i as usize]
                }
            };
            let mi = m as isize;
            // The centres i in 1..n − 1 whose three points are all inside
            // (m ≤ i ≤ n − 1 − m) in one vectorised sweep; the reflected
            // ones at both ends point by point.
            let (lo, hi) = (m.max(1), (n - 1).saturating_sub(m).max(m.max(1)));
            let mut s = if hi > lo {
                second_diff_sum(x, m, lo - m, hi - m, 1)
            } else {
                0.0
            };
            for i in (1..(n as isize - 1)).filter(|&i| (i as usize) < lo || (i as usize) >= hi) {
                let d = at(i - mi) - 2.0 * at(i) + at(i + mi);
                s += d * d;
            }
            (s / (2.0 * tau * tau * (n - 2) as f64), n - 2)
        }
        Kind::Mtotdev | Kind::Ttotdev => {
            if m > n / 3 {
                return Err(DevError::TooShort);
            }
            let (s, k) = total_sums(x, m);
            // SP 1065 eq. 27: over 2τ² the mean square of the second
            // differences of m-point means (the sums are of m-point sums:
            // hence m²).
            let mvar = s / (2.0 * (m * m) as f64 * tau * tau * k as f64);
            if kind == Kind::Ttotdev {
                (tau * tau / 3.0 * mvar, k)
            } else {
                (mvar, k)
            }
        }
        Kind::Htotdev if m == 1 => return deviation_checked(Kind::Ohdev, x, tau0, 1),
        Kind::Htotdev => {
            if n < 2 || m > (n - 1) / 3 {
                return Err(DevError::TooShort);
            }
            let y: Vec<f64> = x.windows(2).map(|w| (w[1] - w[0]) / tau0).collect();
            let (s, k) = total_sums(&y, m);
            // SP 1065 eq. 29: ⟨(ȳ₁ − 2ȳ₂ + ȳ₃)²⟩ / 6 over m-point means.
            (s / (6.0 * (m * m) as f64 * k as f64), k)
        }
        Kind::Mtie => {
            if n < m + 2 {
                return Err(DevError::TooShort);
            }
            (mtie(x, m + 1).powi(2), n - m)
        }
        Kind::Theo1 => {
            // Odd factors have no value (the batch and curves skip them).
            if !m.is_multiple_of(2) || m >= n {
                return Err(DevError::TooShort);
            }
            // SP 1065 eq. 30: for each start i, the m/2 weighted squares of
            // (x[i] − x[i − d + m/2] + x[i + m] − x[i + d + m/2]).
            let h = m / 2;
            let mut s = 0.0;
            for i in 0..n - m {
                for d in 0..h {
                    let v = x[i] - x[i + h - d] + x[i + m] - x[i + h + d];
                    s += v * v / (h - d) as f64;
                }
            }
            (s / (0.75 * (n - m) as f64 * tau * tau), (n - m) * h)
        }
        Kind::Tierms => {
            if n < m + 2 {
                return Err(DevError::TooShort);
            }
            let k = n - m;
            let s: f64 = x[m..].iter().zip(x).map(|(b, a)| (b - a) * (b - a)).sum();
            (s / k as f64, k)
        }
        Kind::Theobr | Kind::Theoh => return theo_point(kind, x, tau0, m, &mut None),
    };
    Ok(Point::bare(m, tau0, var.sqrt(), terms, n))
}

/// [`deviation_checked`] over one series' factors in turn, TheoBR's bias
/// ratio computed once for all of them (`ratio`, None before).
fn deviation_in(
    kind: Kind,
    x: &[f64],
    tau0: f64,
    m: usize,
    ratio: &mut Option<f64>,
) -> Result<Point, DevError> {
    match kind {
        Kind::Theobr | Kind::Theoh => theo_point(kind, x, tau0, m, ratio),
        _ => deviation_checked(kind, x, tau0, m),
    }
}

/// The most phase points TheoBR and TheoH are computed for: the bias
/// ratio sums Theo1 at some N/30 factors up to 0.13 N, about N³/900 terms
/// (9·10⁹ here, seconds), where Theo1 at one factor is N m/2.
pub const THEO_BR_MAX_POINTS: usize = 20_000;

/// TheoBR's bias ratio over phase `x` (SP 1065 eq. 31): the mean over
/// i = 0 ..= k, k = ⌊0.1 N/3 − 3⌋, of OAVAR at factor 9 + 3i over Theo1
/// at 12 + 4i, the two at the same averaging time (Theo1's is 0.75 m τ0;
/// τ0 cancels). A pair whose Theo1 is 0 (a phase with no second
/// differences there) is left out of the mean; none at all reads 1.
fn theo_br_ratio(x: &[f64]) -> Result<f64, DevError> {
    let n = x.len();
    if n > THEO_BR_MAX_POINTS {
        return Err(DevError::TooLong(THEO_BR_MAX_POINTS));
    }
    let k = (0.1 * n as f64 / 3.0 - 3.0).floor();
    if k < 0.0 {
        return Err(DevError::TooShort);
    }
    let (mut sum, mut pairs) = (0.0, 0usize);
    for i in 0..=k as usize {
        let a = deviation_checked(Kind::Oadev, x, 1.0, 9 + 3 * i)?.dev;
        let t = deviation_checked(Kind::Theo1, x, 1.0, 12 + 4 * i)?.dev;
        if t > 0.0 {
            sum += (a * a) / (t * t);
            pairs += 1;
        }
    }
    Ok(if pairs == 0 { 1.0 } else { sum / pairs as f64 })
}

/// TheoBR at Theo1's factor `m` (reported as Theo1 is), or TheoH at
/// factor `m` (its averaging time m τ0: OADEV up to a tenth of the record,
/// beyond it TheoBR at Theo1's 4m/3), the bias ratio taken from `ratio` or
/// computed into it.
fn theo_point(
    kind: Kind,
    x: &[f64],
    tau0: f64,
    m: usize,
    ratio: &mut Option<f64>,
) -> Result<Point, DevError> {
    let n = x.len();
    if kind == Kind::Theoh && crate::kind::theoh_is_oadev(m, n) {
        return deviation_checked(Kind::Oadev, x, tau0, m);
    }
    let f = match kind {
        Kind::Theoh if m.is_multiple_of(3) => 4 * m / 3,
        Kind::Theoh => return Err(DevError::TooShort),
        _ => m,
    };
    let p = deviation_checked(Kind::Theo1, x, tau0, f)?;
    let r = match *ratio {
        Some(r) => r,
        None => {
            let r = theo_br_ratio(x)?;
            *ratio = Some(r);
            r
        }
    };
    Ok(Point::bare(m, tau0, p.dev * r.sqrt(), p.terms, n))
}

/// Gap-tolerant overlapping Allan deviation at factor `m` of phase `x`
/// whose missing points are NaN (allantools' `gradev`): the overlapping
/// second differences whose three points are all present, their mean
/// square over 2τ². `terms` counts those; too short where none is.
pub fn gradev(x: &[f64], tau0: f64, m: usize) -> Result<Point, DevError> {
    check_tau0(tau0)?;
    if m == 0 {
        return Err(DevError::Factor);
    }
    if let Some(i) = x.iter().position(|v| v.is_infinite()) {
        return Err(DevError::NonFinite(i));
    }
    let n = x.len();
    let (mut s, mut k) = (0.0, 0usize);
    for i in 0..n.saturating_sub(2 * m) {
        let d = x[i + 2 * m] - 2.0 * x[i + m] + x[i];
        if d.is_finite() {
            s += d * d;
            k += 1;
        }
    }
    gap_point(s, k, m, tau0, n)
}

/// [`gradev`] of a rate series `y` whose missing samples are NaN: a term
/// counts where none of the 2m rates it spans is missing (the phase
/// across a missing rate is unknown, so no second difference reaches over
/// one). With nothing missing, OADEV's terms.
pub fn gradev_rate(y: &[f64], tau0: f64, m: usize) -> Result<Point, DevError> {
    check_tau0(tau0)?;
    if m == 0 {
        return Err(DevError::Factor);
    }
    if let Some(i) = y.iter().position(|v| v.is_infinite()) {
        return Err(DevError::NonFinite(i));
    }
    // Running sums with the missing samples as 0, and their count.
    let mut sum = Vec::with_capacity(y.len() + 1);
    let mut gaps = Vec::with_capacity(y.len() + 1);
    let (mut a, mut g) = (0.0, 0usize);
    sum.push(a);
    gaps.push(g);
    for v in y {
        if v.is_nan() {
            g += 1;
        } else {
            a += v;
        }
        sum.push(a);
        gaps.push(g);
    }
    let n = y.len();
    let (mut s, mut k) = (0.0, 0usize);
    for i in 0..(n + 1).saturating_sub(2 * m) {
        if gaps[i + 2 * m] != gaps[i] {
            continue;
        }
        let d = tau0 * ((sum[i + 2 * m] - sum[i + m]) - (sum[i + m] - sum[i]));
        s += d * d;
        k += 1;
    }
    gap_point(s, k, m, tau0, n + 1)
}

fn gap_point(s: f64, k: usize, m: usize, tau0: f64, n: usize) -> Result<Point, DevError> {
    if k == 0 {
        return Err(DevError::TooShort);
    }
    let tau = m as f64 * tau0;
    let dev = (s / (2.0 * k as f64)).sqrt() / tau;
    if !dev.is_finite() {
        return Err(DevError::Overflow(m));
    }
    Ok(Point::bare(m, tau0, dev, k, n))
}

/// The total estimators' sums (SP 1065 eqs. 27 and 29; Howe 1999): for
/// each stretch of 3m points of `s` (N − 3m + 1 of them), its linear
/// trend taken out (the slope between the means of its first and last
/// halves), extended to 9m points by even reflection at both ends; then the
/// mean over the 6m positions of (S₁ − 2S₂ + S₃)², the Sᵢ three adjacent
/// m-point sums. Returns the sum of those means over the stretches, and
/// their number.
fn total_sums(s: &[f64], m: usize) -> (f64, usize) {
    let w = 3 * m;
    let stretches = s.len() + 1 - w;
    // The halves' means are over ⌊3m/2⌋ points each, their centres
    // ⌈3m/2⌉ apart (one more than ⌊3m/2⌋ for odd 3m).
    let half = w / 2;
    let apart = w.div_ceil(2) as f64;
    let mut ext = vec![0.0; 9 * m + 1];
    let mut total = 0.0;
    for i in 0..stretches {
        let xs = &s[i..i + w];
        let mean1 = xs[..half].iter().sum::<f64>() / half as f64;
        let mean2 = xs[w - half..].iter().sum::<f64>() / half as f64;
        let slope = (mean2 - mean1) / apart;
        // Running sums of the extended stretch: reversed, as is, reversed.
        let at = |k: usize| {
            let j = if k < w {
                w - 1 - k
            } else if k < 2 * w {
                k - w
            } else {
                3 * w - 1 - k
            };
            xs[j] - slope * j as f64
        };
        for k in 0..9 * m {
            ext[k + 1] = ext[k] + at(k);
        }
        let mut sq = 0.0;
        for j in 0..6 * m {
            let s1 = ext[j + m] - ext[j];
            let s2 = ext[j + 2 * m] - ext[j + m];
            let s3 = ext[j + 3 * m] - ext[j + 2 * m];
            let d = s1 - 2.0 * s2 + s3;
            sq += d * d;
        }
        total += sq / (6 * m) as f64;
    }
    (total, stretches)
}

/// The largest max − min of `x` over any `window` consecutive points
/// (monotone queues of the window's candidates: O(n)).
fn mtie(x: &[f64], window: usize) -> f64 {
    use std::collections::VecDeque;
    let (mut hi, mut lo): (VecDeque<usize>, VecDeque<usize>) = (VecDeque::new(), VecDeque::new());
    let mut worst: f64 = 0.0;
    for (i, &v) in x.iter().enumerate() {
        while hi.back().is_some_and(|&j| x[j] <= v) {
            hi.pop_back();
        }
        hi.push_back(i);
        while lo.back().is_some_and(|&j| x[j] >= v) {
            lo.pop_back();
        }
        lo.push_back(i);
        if i + 1 >= window {
            let start = i + 1 - window;
            while hi.front().is_some_and(|&j| j < start) {
                hi.pop_front();
            }
            while lo.front().is_some_and(|&j| j < start) {
                lo.pop_front();
            }
            if let (Some(&a), Some(&b)) = (hi.front(), lo.front()) {
                worst = worst.max(x[a] - x[b]);
            }
        }
    }
    worst
}

/// Which averaging factors.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Grid {
    /// Every m from 1.
    All,
    /// 1, 2, 4, 8, …
    Octave,
    /// 1, 2, 4 per decade (1, 2, 4, 10, 20, 40, …), as Stable32's decade.
    Decade,
    /// N per decade, log-spaced and rounded, without repeats.
    PerDecade(u32),
}

impl std::str::FromStr for Grid {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "all" => Ok(Grid::All),
            "octave" => Ok(Grid::Octave),
            "decade" => Ok(Grid::Decade),
            _ => match s.strip_prefix("per-decade=").map(str::parse::<u32>) {
                Some(Ok(n)) if (1..=1000).contains(&n) => Ok(Grid::PerDecade(n)),
                _ => Err(format!(
                    "{s:?}: expected all, octave, decade or per-decade=N (N in 1..=1000)"
                )),
            },
        }
    }
}

impl Grid {
    /// The factors up to `max`.
    pub fn factors(self, max: usize) -> Vec<usize> {
        let mut out = Vec::new();
        match self {
            Grid::All => out.extend(1..=max),
            Grid::Octave => {
                let mut m = 1usize;
                while m <= max {
                    out.push(m);
                    m = match m.checked_mul(2) {
                        Some(v) => v,
                        None => break,
                    };
                }
            }
            Grid::Decade => {
                let mut d = 1usize;
                'outer: loop {
                    for k in [1, 2, 4] {
                        let Some(m) = d.checked_mul(k) else {
                            break 'outer;
                        };
                        if m > max {
                            break 'outer;
                        }
                        out.push(m);
                    }
                    d = match d.checked_mul(10) {
                        Some(v) => v,
                        None => break,
                    };
                }
            }
            Grid::PerDecade(n) => {
                let mut i = 0u32;
                loop {
                    let m = 10f64.powf(i as f64 / n as f64).round() as usize;
                    if m > max {
                        break;
                    }
                    if out.last() != Some(&m) {
                        out.push(m);
                    }
                    i += 1;
                }
            }
        }
        out
    }
}

/// The deviation over a grid (factors past the data's reach are left out),
/// with 1σ intervals (confidence 0.683, exact χ²).
pub fn curve(kind: Kind, x: &[f64], tau0: f64, grid: Grid) -> Result<Vec<Point>, DevError> {
    let mut alphas = Alphas::new();
    let ci = (crate::edf::ONE_SIGMA, crate::edf::Chi2::Exact);
    curve_with(kind, x, tau0, grid, ci, &mut alphas)
}

/// The noise types already identified for one phase series, by factor m
/// (the curves of several deviations share them).
pub type Alphas = std::collections::HashMap<usize, Option<i32>>;

/// [`curve`] with intervals at confidence `cf` and χ² quantiles by
/// `chi2`. A point whose noise type cannot be identified (fewer than 30
/// decimated points) takes the last identified at a shorter τ for its EDF,
/// as the slope of the curve changes slowly there; none before the first.
pub fn curve_with(
    kind: Kind,
    x: &[f64],
    tau0: f64,
    grid: Grid,
    (cf, chi2): (f64, crate::edf::Chi2),
    alphas: &mut Alphas,
) -> Result<Vec<Point>, DevError> {
    let n = x.len();
    let max = kind.max_factor(n);
    let mut factors: Vec<usize> = grid
        .factors(max)
        .into_iter()
        .map(|m| kind.snap_factor(m, n))
        .filter(|&m| kind.takes_factor(m, n))
        .collect();
    factors.dedup();
    curve_at(kind, x, tau0, &factors, (cf, chi2), alphas)
}

/// The gap-tolerant OADEV curve ([`gradev_rate`]) of rates `y` whose
/// missing samples are NaN, on `grid`, with the factors that have terms.
/// Each point's noise type is identified on the longest stretch without a
/// gap (where it has the 30 decimated points the test needs), and its EDF
/// is Greenhall's for OADEV over as many phase points as the terms span
/// (terms + 2m): the gaps' share of the record taken out, their
/// fragmentation not modelled.
pub fn gap_curve(
    y: &[f64],
    tau0: f64,
    grid: Grid,
    (cf, chi2): (f64, crate::edf::Chi2),
) -> Result<Vec<Point>, DevError> {
    check_tau0(tau0)?;
    // The longest stretch without a missing sample, as phase.
    let (mut best, mut start) = ((0, 0), 0);
    for (i, v) in y.iter().chain([&f64::NAN]).enumerate() {
        if v.is_nan() {
            if i - start > best.1 - best.0 {
                best = (start, i);
            }
            start = i + 1;
        }
    }
    let longest = phase_from_rate(&y[best.0..best.1], tau0).unwrap_or_default();
    let mut last_alpha = None;
    let mut out = Vec::new();
    for m in grid.factors(Kind::Oadev.max_factor(y.len() + 1)) {
        let p = match gradev_rate(y, tau0, m) {
            Ok(p) => p,
            Err(DevError::TooShort) => continue,
            Err(e) => return Err(e),
        };
        let alpha = noise_alpha(&longest, m);
        last_alpha = alpha.or(last_alpha);
        let edf =
            last_alpha.and_then(|a| crate::edf::of(Kind::Oadev, a.max(-2), m, p.terms + 2 * m));
        let ci = edf.and_then(|e| crate::edf::interval_with(p.dev, e, cf, chi2));
        out.push(Point {
            alpha,
            edf,
            lo: ci.map(|c| c.0),
            hi: ci.map(|c| c.1),
            ..p
        });
    }
    Ok(out)
}

/// [`curve_with`] at the averaging factors `factors` (each must reach: a
/// factor with too few samples is an error).
pub fn curve_at(
    kind: Kind,
    x: &[f64],
    tau0: f64,
    factors: &[usize],
    (cf, chi2): (f64, crate::edf::Chi2),
    alphas: &mut Alphas,
) -> Result<Vec<Point>, DevError> {
    check(x, tau0)?;
    let mut last_alpha = None;
    let mut ratio = None;
    let points: Vec<Point> = factors
        .iter()
        .map(|&m| {
            deviation_in(kind, x, tau0, m, &mut ratio).map(|p| {
                let alpha = *alphas.entry(m).or_insert_with(|| noise_alpha(x, m));
                with_interval(kind, p, alpha, &mut last_alpha, x.len(), (cf, chi2))
            })
        })
        .collect::<Result<_, _>>()?;
    match points.iter().find(|p| !p.dev.is_finite()) {
        Some(p) => Err(DevError::Overflow(p.m)),
        None => Ok(points),
    }
}

/// Point `p` of deviation `kind` over `n` phase points with its noise type
/// `alpha` (identified at its factor), EDF and interval at confidence `cf`.
/// A point whose noise type is None takes `last_alpha`, the one identified
/// at the nearest shorter τ, which this updates (the curve's points go in
/// order of τ).
pub fn with_interval(
    kind: Kind,
    p: Point,
    alpha: Option<i32>,
    last_alpha: &mut Option<i32>,
    n: usize,
    (cf, chi2): (f64, crate::edf::Chi2),
) -> Point {
    *last_alpha = alpha.or(*last_alpha);
    // The Allan family converges for α > −3 and its EDF tables stop at
    // random-walk FM: a steeper identification (drift at the longest τ) is
    // read as −2 there; Hadamard's go to −4.
    let floor = if matches!(kind, Kind::Hdev | Kind::Ohdev | Kind::Htotdev) {
        -4
    } else {
        -2
    };
    let edf = last_alpha.and_then(|a| crate::edf::of(kind, a.max(floor), p.m, n));
    let ci = edf.and_then(|e| crate::edf::interval_with(p.dev, e, cf, chi2));
    Point {
        alpha,
        edf,
        lo: ci.map(|c| c.0),
        hi: ci.map(|c| c.1),
        ..p
    }
}

/// Power-law noise type α (frequency PSD ∝ f^α: 2 white PM, 1 flicker PM,
/// 0 white FM, −1 flicker FM, −2 random-walk FM) of phase `x` at averaging
/// factor `m`, by the lag-1 autocorrelation method (Riley & Greenhall
/// 2004): decimate the phase by m, difference it d times until
/// δ = r₁/(1 + r₁) < 0.25 (d ≤ 2 for the Allan family), then
/// α = 2 − round(2δ) − 2d. None with fewer than 30 decimated points (the
/// method needs them; Stable32 switches to another test there).
pub fn noise_alpha(x: &[f64], m: usize) -> Option<i32> {
    if m == 0 {
        return None;
    }
    let mut z: Vec<f64> = x.iter().step_by(m).copied().collect();
    if z.len() < 30 || z.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let dmax = 2;
    let mut d = 0;
    loop {
        let n = z.len() as f64;
        let mean = z.iter().sum::<f64>() / n;
        let (mut num, mut den) = (0.0, 0.0);
        for w in z.windows(2) {
            num += (w[0] - mean) * (w[1] - mean);
        }
        for v in &z {
            den += (v - mean) * (v - mean);
        }
        if den <= 0.0 || !den.is_finite() {
            return None;
        }
        let r1 = num / den;
        let delta = r1 / (1.0 + r1);
        if delta < 0.25 || d >= dmax {
            return Some(2 - (2.0 * delta).round() as i32 - 2 * d);
        }
        z = z.windows(2).map(|w| w[1] - w[0]).collect();
        d += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// OADEV at every τ (the grouped kernel) is each τ's own point, bit
    /// for bit, with gaps in the factors, factors too long for the data
    /// and a factor of 0 refused as one at a time refuses it.
    #[test]
    fn every_tau_in_groups_is_each_tau_alone() {
        let mut x = vec![0.0f64; 1201];
        let mut v = 0.1f64;
        for i in 1..x.len() {
            v = (v * 3.9 * (1.0 - v)).clamp(1e-6, 1.0 - 1e-6);
            x[i] = x[i - 1] + v - 0.5;
        }
        let mut ms: Vec<usize> = (1..=700).collect();
        ms.retain(|m| m % 97 != 0);
        let got = deviations_of_finite(Kind::Oadev, &x, 0.01, &ms).unwrap();
        assert_eq!(got.len(), ms.len());
        for (p, &m) in got.iter().zip(&ms) {
            match deviation_checked(Kind::Oadev, &x, 0.01, m) {
                Ok(want) => assert_eq!(
                    p.map(|p| p.dev.to_bits()),
                    Some(want.dev.to_bits()),
                    "m {m}"
                ),
                Err(DevError::TooShort) => assert_eq!(*p, None, "m {m}"),
                Err(e) => panic!("m {m}: {e}"),
            }
            if let Some(p) = p {
                assert_eq!(Some(*p), deviation_checked(Kind::Oadev, &x, 0.01, m).ok());
            }
        }
        assert!(deviations_of_finite(Kind::Oadev, &x, 0.01, &[3, 0, 4]).is_err());
    }

    /// The lines of `text` that are neither comments nor blank.
    fn data_lines(text: &str) -> impl Iterator<Item = &str> {
        text.lines()
            .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
    }

    /// One number per data line.
    fn values(text: &str) -> Vec<f64> {
        data_lines(text)
            .map(|l| l.trim().parse().unwrap())
            .collect()
    }

    /// The allantools oracle's phase record (`tests/make_allantools_vectors.py`).
    fn oracle_phase() -> Vec<f64> {
        values(
            include_str!("../tests/vectors/allantools_phase.csv")
                .split_once('\n')
                .unwrap()
                .1,
        )
    }

    /// An oracle file's rows: kind, m, deviation, terms.
    fn oracle_rows(csv: &str) -> Vec<(&str, usize, f64, usize)> {
        csv.lines()
            .skip(1)
            .map(|l| {
                let f: Vec<&str> = l.split(',').collect();
                (
                    f[0],
                    f[1].parse().unwrap(),
                    f[2].parse().unwrap(),
                    f[3].parse().unwrap(),
                )
            })
            .collect()
    }

    fn phase_dat() -> Vec<f64> {
        values(include_str!("../tests/stable32/PHASE.DAT"))
    }

    /// (AF, #, alpha, sigma) rows of a Stable32 table.
    fn table(text: &str) -> Vec<(usize, usize, i32, f64)> {
        data_lines(text)
            .map(|l| {
                let f: Vec<&str> = l.split_whitespace().collect();
                (
                    f[0].parse().unwrap(),
                    f[2].parse().unwrap(),
                    f[3].parse().unwrap(),
                    f[5].parse().unwrap(),
                )
            })
            .collect()
    }

    /// Stable32's MTIE, TIE rms and Theo1 (at white FM, where it needs no
    /// bias correction) tables for PHASE.DAT (no
    /// interval columns): every value to the five digits it prints and its
    /// term counts (Theo1's "#" counts the m/2 inner terms of each start).
    #[test]
    fn mtie_tierms_and_theo1_match_stable32_on_phase_dat() {
        let x = phase_dat();
        let mut checked = 0;
        for (kind, text, col) in [
            (
                Kind::Mtie,
                include_str!("../tests/stable32/phase_dat_mtie.txt"),
                3,
            ),
            (
                Kind::Tierms,
                include_str!("../tests/stable32/phase_dat_tierms.txt"),
                3,
            ),
            (
                Kind::Theo1,
                include_str!("../tests/stable32/phase_dat_theo1_alpha0.txt"),
                5,
            ),
        ] {
            for l in data_lines(text) {
                let f: Vec<&str> = l.split_whitespace().collect();
                let m: usize = f[0].parse().unwrap();
                // (Theo1's counts printed as 1.0050e+05: to five digits.)
                let terms: f64 = f[2].parse().unwrap();
                let want: f64 = f[col].parse().unwrap();
                let p = deviation(kind, &x, 1.0, m).unwrap();
                let half = 0.5e-4 * 10f64.powi(want.log10().floor() as i32);
                assert!(
                    (p.dev - want).abs() <= half * 1.001,
                    "{kind:?} m {m}: {} against {want}",
                    p.dev
                );
                let unit = 10f64.powi(terms.log10().floor() as i32 - 4);
                assert!(
                    (p.terms as f64 - terms).abs() <= 0.5 * unit,
                    "{kind:?} m {m}: {} terms",
                    p.terms
                );
                checked += 1;
            }
        }
        assert_eq!(checked, 9 + 139 + 181);
    }

    /// Every value of Stable32's tables for PHASE.DAT, to the five digits
    /// it prints (half a unit of the last digit), and its term counts.
    #[test]
    fn every_deviation_matches_stable32_on_phase_dat() {
        let x = phase_dat();
        assert_eq!(x.len(), 1001);
        let mut checked = 0;
        for (kind, text) in [
            (
                Kind::Adev,
                include_str!("../tests/stable32/phase_dat_adev.txt"),
            ),
            (
                Kind::Oadev,
                include_str!("../tests/stable32/phase_dat_oadev.txt"),
            ),
            (
                Kind::Mdev,
                include_str!("../tests/stable32/phase_dat_mdev.txt"),
            ),
            (
                Kind::Tdev,
                include_str!("../tests/stable32/phase_dat_tdev.txt"),
            ),
            (
                Kind::Hdev,
                include_str!("../tests/stable32/phase_dat_hdev.txt"),
            ),
            (
                Kind::Ohdev,
                include_str!("../tests/stable32/phase_dat_ohdev.txt"),
            ),
            (
                Kind::Totdev,
                include_str!("../tests/stable32/phase_dat_totdev.txt"),
            ),
        ] {
            for (af, terms, _, sigma) in table(text) {
                let p = deviation(kind, &x, 1.0, af).unwrap();
                // Printed as d.dddde±xx: half a unit of the fourth decimal
                // of the mantissa, plus 1e-7 relative for a value that sits
                // on a rounding edge (summation order: TDEV at AF 47 is
                // 0.788355013, printed 7.8835e-01).
                let exp = sigma.abs().log10().floor();
                let half = 0.5e-4 * 10f64.powf(exp);
                assert!(
                    (p.dev - sigma).abs() <= half + 1e-7 * sigma.abs(),
                    "{} AF {af}: {} vs Stable32 {sigma}",
                    kind.name(),
                    p.dev
                );
                // Stable32's count for TOTDEV is the data's, N − 2 here.
                if kind != Kind::Totdev {
                    assert_eq!(p.terms, terms, "{} AF {af}: terms", kind.name());
                }
                checked += 1;
            }
        }
        println!("{checked} Stable32 values matched");
        assert!(checked > 900, "{checked}");
    }

    #[test]
    fn grids_and_errors() {
        assert_eq!(Grid::Octave.factors(10), [1, 2, 4, 8]);
        assert_eq!(Grid::Decade.factors(100), [1, 2, 4, 10, 20, 40, 100]);
        assert_eq!(Grid::PerDecade(3).factors(10), [1, 2, 5, 10]);
        assert_eq!(Grid::All.factors(3), [1, 2, 3]);
        assert!("per-decade=0".parse::<Grid>().is_err());
        assert!("weekly".parse::<Grid>().is_err());
        let x = [0.0, 1.0, f64::NAN, 2.0];
        assert_eq!(
            deviation(Kind::Oadev, &x, 1.0, 1),
            Err(DevError::NonFinite(2))
        );
        assert_eq!(
            deviation(Kind::Oadev, &[0.0; 4], 0.0, 1),
            Err(DevError::Tau0)
        );
        assert_eq!(
            deviation(Kind::Oadev, &[0.0; 4], f64::NAN, 1),
            Err(DevError::Tau0)
        );
        assert_eq!(
            deviation(Kind::Oadev, &[0.0; 4], 1.0, 0),
            Err(DevError::Factor)
        );
        assert_eq!(
            deviation(Kind::Mdev, &[0.0; 6], 1.0, 2),
            Err(DevError::TooShort)
        );
        let c = curve(Kind::Oadev, &[0.0; 100], 1.0, Grid::Octave).unwrap();
        assert_eq!(c.len(), 6); // 1..32 (max factor 49)
    }

    /// The lag-1 autocorrelation noise identification against Stable32's
    /// on real data: a GPS receiver's 1PPS against an H-maser (241 218
    /// points) and PHASE.DAT, at every octave factor with ≥ 30 decimated
    /// points.
    #[test]
    fn noise_type_matches_stable32_on_gps_and_phase_dat() {
        use std::io::Read;
        let mut gz = Vec::new();
        flate2::read::GzDecoder::new(
            &include_bytes!("../tests/stable32/gps_1pps_phase_data.txt.gz")[..],
        )
        .read_to_end(&mut gz)
        .unwrap();
        let gps = values(&String::from_utf8(gz).unwrap());
        assert_eq!(gps.len(), 241_218);
        let pd = phase_dat();
        let (mut same, mut all) = (0, 0);
        for (x, text) in [
            (&gps, include_str!("../tests/stable32/gps_oadev_octave.txt")),
            (
                &pd,
                include_str!("../tests/stable32/phase_dat_oadev_octave.txt"),
            ),
        ] {
            for (af, _, want, _) in table(text) {
                if let Some(got) = noise_alpha(x, af) {
                    println!("AF {af}: alpha {got}, Stable32 {want}");
                    all += 1;
                    same += (got == want) as u32;
                }
            }
        }
        println!("{same} of {all} noise types as Stable32");
        assert_eq!(same, all);
    }

    /// Every deviation against allantools 2024.06 on a generated record
    /// (white PM, white FM and random-walk FM; `tests/vectors`, made by
    /// `tests/make_allantools_vectors.py`): factors 1–40 and octaves to
    /// 2048, values to 1e-9 relative and the same term counts (TOTDEV's
    /// count aside: allantools reports N − 2 as Stable32 does).
    #[test]
    fn every_deviation_matches_allantools() {
        let x = oracle_phase();
        assert_eq!(x.len(), 4000);
        let (mut worst, mut checked) = (0.0f64, 0);
        for (name, m, want, n) in oracle_rows(include_str!("../tests/vectors/allantools_devs.csv"))
        {
            let kind = Kind::from_name(name).unwrap();
            let p = deviation(kind, &x, 1.0, m).unwrap();
            worst = worst.max(((p.dev - want) / want).abs());
            if kind != Kind::Totdev {
                assert_eq!(p.terms, n, "{kind:?} m {m}");
            }
            checked += 1;
        }
        assert_eq!(checked, 315);
        assert!(worst < 1e-9, "worst {worst:e}");
    }

    /// The total estimators, MTIE and TIE rms against allantools 2024.6 on
    /// the same phase (`tests/make_allantools_vectors.py`): every value to
    /// 1e-9 relative, the same number of terms.
    #[test]
    fn the_total_family_and_tie_match_allantools() {
        let x = oracle_phase();
        let (mut worst, mut checked) = (0.0f64, 0);
        for (name, m, want, n) in
            oracle_rows(include_str!("../tests/vectors/allantools_family.csv"))
        {
            let kind = Kind::from_name(name).unwrap();
            let p = deviation(kind, &x, 1.0, m).unwrap();
            worst = worst.max(((p.dev - want) / want).abs());
            assert!(
                ((p.dev - want) / want).abs() < 1e-9,
                "{kind:?} m {m}: {} against {want}",
                p.dev
            );
            assert_eq!(p.terms, n, "{kind:?} m {m}");
            checked += 1;
        }
        assert_eq!(checked, 95);
        assert!(worst < 1e-9, "worst {worst:e}");
    }

    /// Theo1 against allantools 2024.6 (`allantools_theo1.csv`): 26 even
    /// factors to 1e-9 relative, the same term counts; odd factors have no
    /// value, and curves skip them.
    #[test]
    fn theo1_matches_allantools() {
        let x = oracle_phase();
        let mut checked = 0;
        for (_, m, want, n) in oracle_rows(include_str!("../tests/vectors/allantools_theo1.csv")) {
            let p = deviation(Kind::Theo1, &x, 1.0, m).unwrap();
            assert!(
                ((p.dev - want) / want).abs() < 1e-9,
                "m {m}: {} against {want}",
                p.dev
            );
            assert_eq!(p.terms, n, "m {m}");
            checked += 1;
        }
        assert_eq!(checked, 26);
        assert!(matches!(
            deviation(Kind::Theo1, &x, 1.0, 3),
            Err(DevError::TooShort)
        ));
        let mut alphas = Alphas::new();
        let c = curve_with(
            Kind::Theo1,
            &x,
            1.0,
            Grid::Octave,
            (0.68, crate::edf::Chi2::Exact),
            &mut alphas,
        )
        .unwrap();
        assert!(
            c.iter().all(|p| p.m % 2 == 0) && c.len() == 11,
            "{:?}",
            c.iter().map(|p| p.m).collect::<Vec<_>>()
        );
    }

    /// TheoBR and TheoH against allantools 2024.6's own Theo1 and OADEV
    /// combined by SP 1065 eqs. 31–32 (`allantools_theobr.csv`, from
    /// `tests/make_theobr_vectors.py`; allantools has neither): the bias
    /// ratio, 23 TheoBR and 51 TheoH points to 1e-9 relative, the same
    /// term counts; TheoH's factors beyond a tenth of the record only at
    /// multiples of 3, curves skipping the others; too long a record is a
    /// typed error, not minutes of work.
    #[test]
    fn theobr_and_theoh_match_allantools_theo1_and_oadev() {
        let x = oracle_phase();
        let mut checked = 0;
        let mut worst = 0.0f64;
        for (name, m, want, n) in
            oracle_rows(include_str!("../tests/vectors/allantools_theobr.csv"))
        {
            let l = format!("{name} {m}");
            let got = match name {
                "ratio" => {
                    let r = theo_br_ratio(&x).unwrap();
                    worst = worst.max(((r - want) / want).abs());
                    checked += 1;
                    continue;
                }
                "theobr" => deviation(Kind::Theobr, &x, 1.0, m).unwrap(),
                "theoh" => deviation(Kind::Theoh, &x, 1.0, m).unwrap(),
                k => panic!("{k}"),
            };
            worst = worst.max(((got.dev - want) / want).abs());
            assert!(((got.dev - want) / want).abs() < 1e-9, "{l}: {}", got.dev);
            assert_eq!(got.terms, n, "{l}");
            assert_eq!(got.tau, m as f64, "{l}");
            checked += 1;
        }
        assert_eq!(checked, 1 + 23 + 51);
        assert!(worst < 1e-9, "worst {worst:e}");
        // Beyond a tenth of the record TheoH has values at multiples of 3
        // only; below it every factor (OADEV's).
        assert!(matches!(
            deviation(Kind::Theoh, &x, 1.0, 401),
            Err(DevError::TooShort)
        ));
        let c = curve(Kind::Theoh, &x, 1.0, Grid::PerDecade(10)).unwrap();
        assert!(c.iter().all(|p| p.m * 10 <= 3999 || p.m % 3 == 0));
        assert!(c.iter().any(|p| p.m * 10 > 3999));
        // The batch shares the ratio: the same values one at a time.
        let ms = [10, 64, 3996];
        let batch = deviations(Kind::Theobr, &x, 1.0, &ms).unwrap();
        for (m, p) in ms.iter().zip(batch) {
            assert_eq!(
                p.unwrap().dev,
                deviation(Kind::Theobr, &x, 1.0, *m).unwrap().dev
            );
        }
        let long = vec![0.0; THEO_BR_MAX_POINTS + 1];
        assert_eq!(
            deviation(Kind::Theobr, &long, 1.0, 10),
            Err(DevError::TooLong(THEO_BR_MAX_POINTS))
        );
        // Under 90 points there is no pair for the ratio.
        assert_eq!(
            deviation(Kind::Theobr, &x[..89], 1.0, 10),
            Err(DevError::TooShort)
        );
    }

    /// The gap-tolerant OADEV against allantools' `gradev` on the same
    /// phase with 421 points cut out (`tests/make_gradev_vectors.py`): 45
    /// values to 1e-9 relative, the same term counts. With nothing missing
    /// it is OADEV, from phase and from rate alike; from rate, a term counts
    /// exactly where none of its rates is missing (checked term by term).
    #[test]
    fn gradev_matches_allantools_on_a_holed_record() {
        let mut x = oracle_phase();
        let whole = x.clone();
        for i in (500..520).chain([1700]).chain(2500..2900) {
            x[i] = f64::NAN;
        }
        let mut checked = 0;
        for l in include_str!("../tests/vectors/allantools_gradev.csv")
            .lines()
            .skip(1)
        {
            let f: Vec<&str> = l.split(',').collect();
            let (m, want, n): (usize, f64, usize) = (
                f[0].parse().unwrap(),
                f[1].parse().unwrap(),
                f[2].parse().unwrap(),
            );
            let p = gradev(&x, 1.0, m).unwrap();
            assert!(
                ((p.dev - want) / want).abs() < 1e-9,
                "m {m}: {} against {want}",
                p.dev
            );
            assert_eq!(p.terms, n, "m {m}");
            checked += 1;
        }
        assert_eq!(checked, 45);
        // Nothing missing: OADEV's value and terms, from phase and from rate.
        let y: Vec<f64> = whole.windows(2).map(|w| (w[1] - w[0]) / 0.5).collect();
        for m in [1, 3, 64] {
            let o = deviation(Kind::Oadev, &whole, 0.5, m).unwrap();
            for g in [
                gradev(&whole, 0.5, m).unwrap(),
                gradev_rate(&y, 0.5, m).unwrap(),
            ] {
                assert_eq!(g.terms, o.terms);
                assert!(((g.dev - o.dev) / o.dev).abs() < 1e-9, "m {m}");
            }
        }
        // Rates missing: the terms whose 2m rates are all there, by brute force.
        let mut yh = y.clone();
        for i in (100..103).chain([2000]).chain(3000..3010) {
            yh[i] = f64::NAN;
        }
        for m in [1, 2, 5, 40] {
            let (mut s, mut k) = (0.0, 0);
            for i in 0..=yh.len() - 2 * m {
                let w = &yh[i..i + 2 * m];
                if w.iter().any(|v| v.is_nan()) {
                    continue;
                }
                let d = 0.5 * (w[m..].iter().sum::<f64>() - w[..m].iter().sum::<f64>());
                s += d * d;
                k += 1;
            }
            let want = (s / (2.0 * k as f64)).sqrt() / (m as f64 * 0.5);
            let g = gradev_rate(&yh, 0.5, m).unwrap();
            assert_eq!(g.terms, k, "m {m}");
            assert!(((g.dev - want) / want).abs() < 1e-9, "m {m}");
        }
    }

    /// The batch (one check, OADEV's octaves in one sweep) gives what the
    /// factor-by-factor [`deviation`] does: the same terms, the deviation
    /// to 1e-12 relative; a factor out of reach is None.
    #[test]
    fn the_batch_is_the_single_factor_path() {
        let x = phase_dat();
        for kind in [Kind::Oadev, Kind::Adev, Kind::Totdev] {
            for factors in [
                vec![1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024],
                vec![3, 7, 500],
            ] {
                let batch = deviations(kind, &x, 1.0, &factors).unwrap();
                for (m, b) in factors.iter().zip(&batch) {
                    match (deviation(kind, &x, 1.0, *m), b) {
                        (Ok(p), Some(q)) => {
                            assert_eq!(p.terms, q.terms, "{kind:?} {m}");
                            assert!((p.dev - q.dev).abs() <= 1e-12 * p.dev, "{kind:?} {m}");
                        }
                        (Err(DevError::TooShort), None) => {}
                        (p, q) => panic!("{kind:?} {m}: {p:?} {q:?}"),
                    }
                }
            }
        }
        assert_eq!(
            deviations(Kind::Oadev, &[0.0, f64::NAN], 1.0, &[1]),
            Err(DevError::NonFinite(1))
        );
    }
}
