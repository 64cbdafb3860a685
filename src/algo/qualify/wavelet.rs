//! Discrete wavelet transform with Daubechies db4 / db5, symmetric
//! boundary extension (PyWavelets' default `mode='symmetric'`), multilevel
//! decomposition and reconstruction, and BayesShrink soft thresholding
//! (seed 002 eq. 18–20; as scikit-image's `denoise_wavelet`).
//!
//! Conventions follow PyWavelets so that results can be compared 1:1:
//! level j gives ⌊(n + F − 1)/2⌋ coefficients from n, coefficient k is
//! Σ_j dec\[j\]·x̃\[2k + 1 − j\] with x̃ the half-sample symmetric extension,
//! and reconstruction is the "valid" upsampling convolution (2n − F + 2
//! samples), trimmed by one when lengths differ.

use super::{check_finite, QualifyError, Real};

/// A Daubechies wavelet (PyWavelets filter values).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Wavelet {
    /// Decomposition low-pass filter.
    pub dec_lo: &'static [f64],
}

/// db4 (8 taps).
pub const DB4: Wavelet = Wavelet {
    dec_lo: &[
        -0.010_597_401_785_069_032,
        0.032_883_011_666_885_2,
        0.030_841_381_835_560_764,
        -0.187_034_811_719_093_09,
        -0.027_983_769_416_859_854,
        0.630_880_767_929_858_9,
        0.714_846_570_552_915_7,
        0.230_377_813_308_896_5,
    ],
};

/// db5 (10 taps).
pub const DB5: Wavelet = Wavelet {
    dec_lo: &[
        0.003_335_725_285_473_771_2,
        -0.012_580_751_999_081_999,
        -0.006_241_490_212_798_274,
        0.077_571_493_840_045_72,
        -0.032_244_869_584_638_375,
        -0.242_294_887_066_382_03,
        0.138_428_145_901_320_74,
        0.724_308_528_437_772_9,
        0.603_829_269_797_189_6,
        0.160_102_397_974_192_93,
    ],
};

/// Longest filter supported and most levels.
const MAX_TAPS: usize = 10;
/// Most decomposition levels.
pub const MAX_LEVELS: usize = 12;

impl Wavelet {
    /// Filter length F.
    pub fn len(&self) -> usize {
        self.dec_lo.len()
    }

    /// Never empty (for clippy's `len` rule).
    pub fn is_empty(&self) -> bool {
        false
    }

    /// The four filters: dec_lo, dec_hi, rec_lo, rec_hi
    /// (rec_lo = reversed dec_lo, dec_hi[k] = (−1)^(k+1)·rec_lo[k],
    /// rec_hi = reversed dec_hi).
    fn filters<F: Real>(&self) -> [[F; MAX_TAPS]; 4] {
        let n = self.len();
        let mut f = [[F::of(0.0); MAX_TAPS]; 4];
        for k in 0..n {
            let rec_lo = self.dec_lo[n - 1 - k];
            let dec_hi = if k % 2 == 0 { -rec_lo } else { rec_lo };
            f[0][k] = F::of(self.dec_lo[k]);
            f[1][k] = F::of(dec_hi);
            f[2][k] = F::of(rec_lo);
        }
        for k in 0..n {
            f[3][k] = f[1][n - 1 - k];
        }
        f
    }
}

/// Coefficient count at one level from `n` samples.
pub fn dwt_len(n: usize, taps: usize) -> usize {
    (n + taps - 1) / 2
}

/// Half-sample symmetric index into 0..n (reflects as often as needed).
fn sym(mut i: isize, n: usize) -> usize {
    let n = n as isize;
    loop {
        if i < 0 {
            i = -i - 1;
        } else if i >= n {
            i = 2 * n - 1 - i;
        } else {
            return i as usize;
        }
    }
}

/// One level: approximation `a` and detail `d` (each `dwt_len` long).
pub fn dwt<F: Real>(w: &Wavelet, x: &[F], a: &mut [F], d: &mut [F]) -> Result<(), QualifyError> {
    let taps = w.len();
    let n = x.len();
    let out = dwt_len(n, taps);
    if n == 0 {
        return Err(QualifyError::TooShort);
    }
    if a.len() < out || d.len() < out {
        return Err(QualifyError::Buffer);
    }
    check_finite(x)?;
    let f = w.filters::<F>();
    for k in 0..out {
        let (mut sa, mut sd) = (F::of(0.0), F::of(0.0));
        for j in 0..taps {
            let v = x[sym(2 * k as isize + 1 - j as isize, n)];
            sa += f[0][j] * v;
            sd += f[1][j] * v;
        }
        a[k] = sa;
        d[k] = sd;
    }
    Ok(())
}

/// One inverse level: `out` gets 2n − F + 2 samples from n coefficients.
pub fn idwt<F: Real>(w: &Wavelet, a: &[F], d: &[F], out: &mut [F]) -> Result<usize, QualifyError> {
    let taps = w.len();
    let n = a.len();
    if d.len() != n || n < taps / 2 {
        return Err(QualifyError::TooShort);
    }
    let len = 2 * n + 2 - taps;
    check_finite(a)?;
    check_finite(d)?;
    if out.len() < len {
        return Err(QualifyError::Buffer);
    }
    let f = w.filters::<F>();
    let half = taps / 2;
    // (Pairs of `out`, so that no index of it can panic.)
    let pairs = out
        .get_mut(..len)
        .ok_or(QualifyError::Buffer)?
        .chunks_exact_mut(2);
    for (pair, i) in pairs.zip(half - 1..n) {
        let (mut even, mut odd) = (F::of(0.0), F::of(0.0));
        for j in 0..half {
            // (i − j is in 0..n; `get` keeps that from being a panic path.)
            let (av, dv) = (
                a.get(i - j).copied().unwrap_or(F::of(0.0)),
                d.get(i - j).copied().unwrap_or(F::of(0.0)),
            );
            even += f[2][2 * j] * av + f[3][2 * j] * dv;
            odd += f[2][2 * j + 1] * av + f[3][2 * j + 1] * dv;
        }
        if let [e, o] = pair {
            (*e, *o) = (even, odd);
        }
    }
    Ok(len)
}

/// Where each band of a multilevel decomposition sits in its buffer, in
/// PyWavelets order: cA_J, cD_J, …, cD_1. Only [`Layout::new`] builds one
/// (the fields are private), so its lengths always agree with each other:
/// a hand-made, inconsistent layout made `waverec` and `bayes_shrink`
/// panic before.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    levels: usize,
    lens: [usize; MAX_LEVELS + 1],
    n: usize,
}

impl Layout {
    /// Lengths of a `levels`-level decomposition of `n` samples.
    pub fn new(n: usize, taps: usize, levels: usize) -> Result<Self, QualifyError> {
        if levels == 0 || levels > MAX_LEVELS {
            return Err(QualifyError::Parameter);
        }
        let mut lens = [0; MAX_LEVELS + 1];
        let mut m = n;
        for j in 0..levels {
            if m < taps / 2 {
                return Err(QualifyError::TooShort);
            }
            m = dwt_len(m, taps);
            lens[levels - j] = m; // cD_(j+1)
        }
        lens[0] = m;
        Ok(Self { levels, lens, n })
    }

    /// Levels J.
    pub fn levels(&self) -> usize {
        self.levels
    }

    /// Band lengths, cA_J first (`levels + 1` of them).
    pub fn lens(&self) -> &[usize] {
        self.lens.get(..=self.levels).unwrap_or(&[])
    }

    /// Original signal length.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Total coefficient count.
    pub fn total(&self) -> usize {
        self.lens().iter().sum()
    }

    /// Range of band `b` (0 = cA_J, 1 = cD_J, …, J = cD_1); empty past J.
    pub fn band(&self, b: usize) -> core::ops::Range<usize> {
        let lens = self.lens();
        let start: usize = lens.iter().take(b).sum();
        start..start + lens.get(b).copied().unwrap_or(0)
    }
}

/// Multilevel decomposition into `coeffs` (≥ `Layout::total`), with a
/// scratch of ≥ 2·(n + F) samples.
pub fn wavedec<F: Real>(
    w: &Wavelet,
    x: &[F],
    levels: usize,
    coeffs: &mut [F],
    scratch: &mut [F],
) -> Result<Layout, QualifyError> {
    check_finite(x)?;
    let lay = Layout::new(x.len(), w.len(), levels)?;
    let half = x.len() + w.len();
    if coeffs.len() < lay.total() || scratch.len() < 2 * half {
        return Err(QualifyError::Buffer);
    }
    let (cur, next) = scratch.split_at_mut(half);
    part_mut(cur, ..x.len())?.copy_from_slice(x);
    let mut m = x.len();
    for j in 0..levels {
        let band = lay.band(levels - j);
        let out = band.len();
        dwt(
            w,
            part(cur, ..m)?,
            part_mut(next, ..out)?,
            part_mut(coeffs, band)?,
        )?;
        part_mut(cur, ..out)?.copy_from_slice(part(next, ..out)?);
        m = out;
    }
    let a = part(cur, ..m)?;
    part_mut(coeffs, lay.band(0))?.copy_from_slice(a);
    Ok(lay)
}

/// Multilevel reconstruction of `lay.n` samples into `out`, with a scratch
/// of ≥ 2·(n + F) samples.
pub fn waverec<F: Real>(
    w: &Wavelet,
    coeffs: &[F],
    lay: &Layout,
    out: &mut [F],
    scratch: &mut [F],
) -> Result<(), QualifyError> {
    let half = lay.n + w.len() + 2;
    if out.len() < lay.n || scratch.len() < 2 * half || coeffs.len() < lay.total() {
        return Err(QualifyError::Buffer);
    }
    check_finite(part(coeffs, ..lay.total())?)?;
    let (cur, next) = scratch.split_at_mut(half);
    let mut m = lay.lens[0];
    part_mut(cur, ..m)?.copy_from_slice(part(coeffs, lay.band(0))?);
    for b in 1..=lay.levels {
        let d = part(coeffs, lay.band(b))?;
        if m == d.len() + 1 {
            m -= 1; // PyWavelets trims the approximation
        }
        if m != d.len() {
            return Err(QualifyError::Parameter);
        }
        let len = idwt(w, part(cur, ..m)?, d, next)?;
        part_mut(cur, ..len)?.copy_from_slice(part(next, ..len)?);
        m = len;
    }
    if m < lay.n {
        return Err(QualifyError::Parameter);
    }
    part_mut(out, ..lay.n)?.copy_from_slice(part(cur, ..lay.n)?);
    Ok(())
}

/// `s[r]`, or a `Buffer` error instead of a panic.
fn part<F, R: core::slice::SliceIndex<[F], Output = [F]>>(
    s: &[F],
    r: R,
) -> Result<&[F], QualifyError> {
    s.get(r).ok_or(QualifyError::Buffer)
}

/// `&mut s[r]`, or a `Buffer` error instead of a panic.
fn part_mut<F, R: core::slice::SliceIndex<[F], Output = [F]>>(
    s: &mut [F],
    r: R,
) -> Result<&mut [F], QualifyError> {
    s.get_mut(r).ok_or(QualifyError::Buffer)
}

/// Median of |v|, in place (heap sort: O(n log n) whatever the data, no
/// recursion, so long host logs and board blocks alike stay bounded).
fn median_abs<F: Real>(v: &mut [F]) -> F {
    for x in v.iter_mut() {
        *x = x.abs();
    }
    let n = v.len();
    if n == 0 {
        return F::of(0.0);
    }
    let sift = |t: &mut [F], mut root: usize, end: usize| {
        let end = end.min(t.len());
        loop {
            let mut child = 2 * root + 1;
            if child >= end {
                break;
            }
            if child + 1 < end && t[child] < t[child + 1] {
                child += 1;
            }
            if root < child && t[root] < t[child] {
                t.swap(root, child);
                root = child;
            } else {
                break;
            }
        }
    };
    for start in (0..n / 2).rev() {
        sift(v, start, n);
    }
    for end in (1..n).rev() {
        // v.swap(0, end) without its bounds panic.
        if let Some((first, rest)) = v.split_first_mut() {
            if let Some(e) = rest.get_mut(end - 1) {
                core::mem::swap(first, e);
            }
        }
        sift(v, 0, end);
    }
    let mid = |i: usize| v.get(i).copied().unwrap_or(F::of(0.0));
    if n % 2 == 1 {
        mid(n / 2)
    } else {
        (mid(n / 2 - 1) + mid(n / 2)) / F::of(2.0)
    }
}

/// What BayesShrink did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shrink<F> {
    /// Noise σ_z = median(|cD_1|)/0.6745.
    pub sigma: F,
    /// Threshold per band (index as [`Layout::band`]; 0 for cA_J, kept).
    pub thresholds: [F; MAX_LEVELS + 1],
}

/// BayesShrink soft thresholding of the detail bands in place: per band,
/// T = σ_z² / √max(mean(d²) − σ_z², ε) with ε = 2.2e-16 (a band with no
/// signal is killed), as scikit-image. `tmp` needs the length of cD_1.
pub fn bayes_shrink<F: Real>(
    coeffs: &mut [F],
    lay: &Layout,
    tmp: &mut [F],
) -> Result<Shrink<F>, QualifyError> {
    let finest = lay.band(lay.levels);
    if tmp.len() < finest.len() || coeffs.len() < lay.total() {
        return Err(QualifyError::Buffer);
    }
    // A NaN would sort anywhere in the median and zero its band.
    check_finite(part(coeffs, ..lay.total())?)?;
    // σ from the finest band's non-zero coefficients only, as
    // scikit-image's `estimate_sigma` (quantised or zero-padded records
    // have runs of exact zeros there, which pulled the median down: 1 % and
    // 20 % of the peak off scikit-image). None non-zero: σ = 0, nothing is
    // shrunk. scipy.stats.norm.ppf(0.75):
    let mut k = 0;
    for &c in part(coeffs, finest)? {
        if c != F::of(0.0) {
            if let Some(t) = tmp.get_mut(k) {
                *t = c;
                k += 1;
            }
        }
    }
    let sigma = median_abs(tmp.get_mut(..k).unwrap_or(&mut [])) / F::of(0.674_489_750_196_081_7);
    let var = sigma * sigma;
    let mut thresholds = [F::of(0.0); MAX_LEVELS + 1];
    for b in 1..=lay.levels {
        let band = part_mut(coeffs, lay.band(b))?;
        let mut s2 = F::of(0.0);
        for &c in band.iter() {
            s2 += c * c;
        }
        let dvar = s2 / F::of(band.len() as f64);
        let excess = dvar - var;
        let eps = F::of(f64::EPSILON);
        let t = var / (if excess > eps { excess } else { eps }).sqrt();
        for c in band.iter_mut() {
            let a = c.abs() - t;
            let mag = if a > F::of(0.0) { a } else { F::of(0.0) };
            *c = if *c < F::of(0.0) { -mag } else { mag };
        }
        thresholds[b] = t;
    }
    Ok(Shrink { sigma, thresholds })
}
