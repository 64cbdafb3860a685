//! Mean, variance and the normality moments of seed 003 eq. 8 (population
//! moments: ideal skewness 0, kurtosis 3; as scipy's `skew` and
//! `kurtosis(fisher=False)`).

use super::{check_finite, QualifyError, Real};

/// Mean and population variance (two passes, about the mean).
pub fn mean_var<F: Real>(x: &[F]) -> Result<(F, F), QualifyError> {
    if x.is_empty() {
        return Err(QualifyError::TooShort);
    }
    check_finite(x)?;
    let n = F::of(x.len() as f64);
    let mut s = F::of(0.0);
    for &v in x {
        s += v;
    }
    let mean = s / n;
    let mut s2 = F::of(0.0);
    for &v in x {
        s2 += (v - mean) * (v - mean);
    }
    Ok((mean, s2 / n))
}

/// Skewness ξ = m3 / m2^(3/2) and kurtosis υ = m4 / m2² (population).
pub fn skew_kurtosis<F: Real>(x: &[F]) -> Result<(F, F), QualifyError> {
    let (mean, var) = mean_var(x)?;
    if !(var > F::of(0.0)) {
        return Err(QualifyError::Constant);
    }
    let n = F::of(x.len() as f64);
    let (mut m3, mut m4) = (F::of(0.0), F::of(0.0));
    for &v in x {
        let d = v - mean;
        let d2 = d * d;
        m3 += d2 * d;
        m4 += d2 * d2;
    }
    let (m3, m4) = (m3 / n, m4 / n);
    Ok((m3 / (var * var.sqrt()), m4 / (var * var)))
}
