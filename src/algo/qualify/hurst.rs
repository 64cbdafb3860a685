//! Hurst exponent by rescaled range (R/S, seed 002 eq. 11–12, as nolds'
//! `hurst_rs` with `fit='poly', corrected=False, unbiased=False`) and by
//! Lo's modified R/S (eq. 13–14, Andrews lag); the fractional order and
//! fractional differencing of eq. 15–17.

use super::{check_finite, QualifyError, Real};

/// (R/S)_n: the mean over the ⌊N/n⌋ subseries of length n of the range of
/// the cumulative deviations over the population standard deviation.
/// Subseries with zero range are skipped; `None` if all are.
pub fn rs<F: Real>(x: &[F], n: usize) -> Option<F> {
    if n < 2 || x.len() < n {
        return None;
    }
    let (mut acc, mut count) = (F::of(0.0), 0usize);
    for seg in x.chunks_exact(n) {
        let mut s = F::of(0.0);
        for &v in seg {
            s += v;
        }
        let mean = s / F::of(n as f64);
        let (mut c, mut lo, mut hi, mut s2) =
            (F::of(0.0), F::of(f64::MAX), F::of(-f64::MAX), F::of(0.0));
        for &v in seg {
            c += v - mean;
            lo = if c < lo { c } else { lo };
            hi = if c > hi { c } else { hi };
            s2 += (v - mean) * (v - mean);
        }
        let r = hi - lo;
        let sd = (s2 / F::of(n as f64)).sqrt();
        if r != F::of(0.0) && sd > F::of(0.0) {
            acc += r / sd;
            count += 1;
        }
    }
    (count > 0).then(|| acc / F::of(count as f64))
}

/// H by R/S: least-squares slope of ln (R/S)_n on ln n over `ns`.
pub fn hurst_rs<F: Real>(x: &[F], ns: &[usize]) -> Result<F, QualifyError> {
    check_finite(x)?;
    // A constant series has no R/S at any n: `Constant`, as documented
    // (it fell through to `TooShort`).
    if let (true, Some(&x0)) = (x.len() >= 2, x.first()) {
        if x.iter().all(|&v| v == x0) {
            return Err(QualifyError::Constant);
        }
    }
    let (mut sx, mut sy, mut sxx, mut sxy, mut k) = (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for &n in ns {
        if let Some(v) = rs(x, n) {
            let (lx, ly) = (libm::log(n as f64), libm::log(v.f64()));
            sx += lx;
            sy += ly;
            sxx += lx * lx;
            sxy += lx * ly;
            k += 1.0;
        }
    }
    let den = k * sxx - sx * sx;
    if k < 2.0 || !(den > 0.0) {
        return Err(QualifyError::TooShort);
    }
    Ok(F::of((k * sxy - sx * sy) / den))
}

/// Octave window sizes 8, 16, …, N/2 (the default: SEEDS seed 002).
pub fn octave_windows(n: usize, out: &mut [usize; 24]) -> usize {
    let mut c = 0;
    let mut w = 8;
    while 2 * w <= n && c < out.len() {
        out[c] = w;
        c += 1;
        w *= 2;
    }
    c
}

/// Lo's modified R/S over the whole series: Q = R / σ(ρ) with
/// σ²(ρ) = S² + 2 Σ_{j≤ρ} (1 − j/(ρ+1)) γ̂_j and ρ from Andrews' rule; H is
/// read as ln Q / ln N (the literal, single-N reading; SEEDS ambiguity).
/// Returns (H, Q, ρ).
pub fn hurst_mrs<F: Real>(x: &[F]) -> Result<(F, F, usize), QualifyError> {
    check_finite(x)?;
    let n = x.len();
    if n < 8 {
        return Err(QualifyError::TooShort);
    }
    let nf = n as f64;
    let mean = x.iter().map(|v| v.f64()).sum::<f64>() / nf;
    let (mut c, mut lo, mut hi, mut s2) = (0.0f64, f64::MAX, f64::MIN, 0.0f64);
    for &v in x {
        let d = v.f64() - mean;
        c += d;
        lo = lo.min(c);
        hi = hi.max(c);
        s2 += d * d;
    }
    let s2 = s2 / nf;
    if !(s2 > 0.0) {
        return Err(QualifyError::Constant);
    }
    let gamma = |j: usize| {
        let mut g = 0.0;
        for i in j..n {
            g += (x[i].f64() - mean) * (x[i - j].f64() - mean);
        }
        g / nf
    };
    let r1 = gamma(1) / s2;
    let a = libm::fabs(2.0 * r1 / (1.0 - r1 * r1));
    let rho = libm::floor(libm::cbrt(1.5 * nf) * libm::pow(a, 2.0 / 3.0));
    let rho = if rho.is_finite() {
        (rho as usize).min(n / 2)
    } else {
        n / 2
    };
    let mut var = s2;
    for j in 1..=rho {
        var += 2.0 * (1.0 - j as f64 / (rho as f64 + 1.0)) * gamma(j);
    }
    if !(var > 0.0) {
        return Err(QualifyError::Constant);
    }
    let q = (hi - lo) / libm::sqrt(var);
    Ok((F::of(libm::log(q) / libm::log(nf)), F::of(q), rho))
}

/// Convention for the fractional order q from H (SEEDS ambiguity 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Convention {
    /// q = H + 0.5 (the paper: fractional Brownian motion).
    Fbm,
    /// q = H − 0.5 (ARFIMA d of a stationary fGn-like series).
    Fgn,
}

/// The fractional order q for a Hurst exponent.
pub fn frac_order<F: Real>(h: F, c: Convention) -> F {
    match c {
        Convention::Fbm => h + F::of(0.5),
        Convention::Fgn => h - F::of(0.5),
    }
}

/// Binomial weights of (1 − L)^q: h(0) = 1, h(k) = h(k−1)(k − 1 − q)/k.
pub fn frac_weights<F: Real>(q: F, h: &mut [F]) {
    let mut w = F::of(1.0);
    for (k, hk) in h.iter_mut().enumerate() {
        if k > 0 {
            w = w * (F::of(k as f64 - 1.0) - q) / F::of(k as f64);
        }
        *hk = w;
    }
}

/// y(n) = Σ_{k ≤ min(n, L−1)} h(k) x(n − k), truncated at the data start;
/// L = `h.len()` (weights from [`frac_weights`]).
pub fn frac_diff<F: Real>(x: &[F], h: &[F], y: &mut [F]) -> Result<(), QualifyError> {
    if y.len() < x.len() {
        return Err(QualifyError::Buffer);
    }
    if h.is_empty() {
        return Err(QualifyError::Parameter);
    }
    check_finite(x)?;
    check_finite(h)?;
    for n in 0..x.len() {
        let mut s = F::of(0.0);
        for k in 0..=n.min(h.len() - 1) {
            s += h[k] * x[n - k];
        }
        y[n] = s;
    }
    Ok(())
}
