//! Trend tests and removal (seed 003): the reverse-arrangement test
//! (eq. 2–4) and least-squares polynomial detrending.

use super::{check_finite, QualifyError, Real};

/// Result of the reverse-arrangement test.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Arrangement {
    /// Number of segments M.
    pub segments: usize,
    /// A = #{i < j : y_j > y_i} over the segment means (the paper's count;
    /// ties count ½).
    pub a: f64,
    /// λ = (A − M(M−1)/4) / √(M(2M+5)(M−1)/72).
    pub lambda: f64,
}

impl Arrangement {
    /// |λ| ≤ 2: no trend at the 5 % level, as the paper reads it.
    pub fn stationary(&self) -> bool {
        self.lambda.abs() <= 2.0
    }
}

/// Reverse-arrangement test on the means of `segments` equal segments
/// (the last ⌊N mod M⌋ samples are dropped). `means` needs M entries.
pub fn reverse_arrangement<F: Real>(
    x: &[F],
    segments: usize,
    means: &mut [F],
) -> Result<Arrangement, QualifyError> {
    if segments < 3 {
        return Err(QualifyError::Parameter);
    }
    if means.len() < segments {
        return Err(QualifyError::Buffer);
    }
    let len = x.len() / segments;
    if len == 0 {
        return Err(QualifyError::TooShort);
    }
    check_finite(x)?;
    for (m, seg) in means.iter_mut().zip(x.chunks_exact(len)) {
        let mut s = F::of(0.0);
        for &v in seg {
            s += v;
        }
        *m = s / F::of(len as f64);
    }
    let y = &means[..segments];
    let mut a = 0.0f64;
    for i in 0..segments {
        for j in i + 1..segments {
            if y[j] > y[i] {
                a += 1.0;
            } else if y[j] == y[i] {
                a += 0.5;
            }
        }
    }
    let m = segments as f64;
    let mu = m * (m - 1.0) / 4.0;
    let var = m * (2.0 * m + 5.0) * (m - 1.0) / 72.0;
    Ok(Arrangement {
        segments,
        a,
        lambda: (a - mu) / libm::sqrt(var),
    })
}

/// Remove the least-squares polynomial of `degree` (0..=3) in place
/// (t scaled to [−1, 1], normal equations solved by Gaussian elimination
/// with partial pivoting, in f64). Returns the coefficients (in scaled t).
pub fn detrend_poly<F: Real>(x: &mut [F], degree: usize) -> Result<[f64; 4], QualifyError> {
    if degree > 3 {
        return Err(QualifyError::Parameter);
    }
    let n = x.len();
    if n <= degree {
        return Err(QualifyError::TooShort);
    }
    check_finite(x)?;
    let d = degree + 1;
    let t = |i: usize| {
        if n == 1 {
            0.0
        } else {
            2.0 * i as f64 / (n - 1) as f64 - 1.0
        }
    };
    let mut a = [[0.0f64; 5]; 4];
    for i in 0..n {
        let ti = t(i);
        let mut pw = [1.0f64; 7];
        for k in 1..7 {
            pw[k] = pw[k - 1] * ti;
        }
        for r in 0..d {
            for c in 0..d {
                a[r][c] += pw[r + c];
            }
            a[r][d] += pw[r] * x[i].f64();
        }
    }
    for col in 0..d {
        let piv = (col..d)
            .max_by(|&p, &q| libm::fabs(a[p][col]).total_cmp(&libm::fabs(a[q][col])))
            .unwrap_or(col);
        a.swap(col, piv);
        if !(libm::fabs(a[col][col]) > 1e-300) {
            return Err(QualifyError::Constant);
        }
        for r in 0..d {
            if r != col {
                let f = a[r][col] / a[col][col];
                for c in col..=d {
                    a[r][c] -= f * a[col][c];
                }
            }
        }
    }
    let mut coef = [0.0f64; 4];
    for r in 0..d {
        coef[r] = a[r][d] / a[r][r];
    }
    for (i, v) in x.iter_mut().enumerate() {
        let ti = t(i);
        let mut p = 0.0;
        for k in (0..d).rev() {
            p = p * ti + coef[k];
        }
        *v -= F::of(p);
    }
    Ok(coef)
}
