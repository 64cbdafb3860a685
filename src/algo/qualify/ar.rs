//! AR(p) modelling (seed 003 eq. 1): Yule–Walker (biased autocovariance,
//! Levinson–Durbin; statsmodels `yule_walker(method='mle')`), Burg
//! (statsmodels `burg`) and order selection by AIC.

use super::{check_finite, QualifyError, Real};

/// Highest AR order supported.
pub const MAX_ORDER: usize = 32;

/// A fitted AR(p) model: x_t = Σ φ_i x_(t−i) + ε_t (on the demeaned series).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ArModel<F> {
    /// Order p.
    pub order: usize,
    /// φ_1..φ_p (the rest 0).
    pub phi: [F; MAX_ORDER],
    /// Innovation variance σ_ε².
    pub sigma2: F,
}

impl<F: Real> ArModel<F> {
    /// AIC = n·ln σ² + 2p, for `n` samples.
    pub fn aic(&self, n: usize) -> F {
        F::of(n as f64) * self.sigma2.ln() + F::of(2.0 * self.order as f64)
    }
}

fn check<F: Real>(x: &[F], p: usize) -> Result<F, QualifyError> {
    if p == 0 || p > MAX_ORDER {
        return Err(QualifyError::Parameter);
    }
    if x.len() <= p + 1 {
        return Err(QualifyError::TooShort);
    }
    check_finite(x)?;
    let mut s = F::of(0.0);
    for &v in x {
        s += v;
    }
    Ok(s / F::of(x.len() as f64))
}

/// Reflection coefficients to AR coefficients (Levinson step by step).
fn levinson_from_reflection<F: Real>(k: &[F], phi: &mut [F; MAX_ORDER]) {
    let mut tmp = [F::of(0.0); MAX_ORDER];
    for (m, &km) in k.iter().enumerate() {
        tmp[..m].copy_from_slice(&phi[..m]);
        for j in 0..m {
            phi[j] = tmp[j] - km * tmp[m - 1 - j];
        }
        phi[m] = km;
    }
}

/// Yule–Walker with the biased (1/n) autocovariance of the demeaned
/// series, solved by Levinson–Durbin.
pub fn yule_walker<F: Real>(x: &[F], p: usize) -> Result<ArModel<F>, QualifyError> {
    let mean = check(x, p)?;
    let n = x.len();
    let mut r = [F::of(0.0); MAX_ORDER + 1];
    for (k, rk) in r.iter_mut().enumerate().take(p + 1) {
        let mut s = F::of(0.0);
        for t in k..n {
            s += (x[t] - mean) * (x[t - k] - mean);
        }
        *rk = s / F::of(n as f64);
    }
    if !(r[0] > F::of(0.0)) {
        return Err(QualifyError::Constant);
    }
    let mut phi = [F::of(0.0); MAX_ORDER];
    let mut tmp = [F::of(0.0); MAX_ORDER];
    let mut e = r[0];
    for m in 0..p {
        let mut acc = r[m + 1];
        for j in 0..m {
            acc -= phi[j] * r[m - j];
        }
        let k = acc / e;
        tmp[..m].copy_from_slice(&phi[..m]);
        for j in 0..m {
            phi[j] = tmp[j] - k * tmp[m - 1 - j];
        }
        phi[m] = k;
        e *= F::of(1.0) - k * k;
    }
    let mut s2 = r[0];
    for i in 0..p {
        s2 -= phi[i] * r[i + 1];
    }
    Ok(ArModel {
        order: p,
        phi,
        sigma2: s2,
    })
}

/// Burg's method (Brockwell & Davis): forward/backward prediction errors
/// in `scratch` (≥ 2n), σ² = (1 − k_p²)·D_p / (2(n − p)).
pub fn burg<F: Real>(x: &[F], p: usize, scratch: &mut [F]) -> Result<ArModel<F>, QualifyError> {
    let mean = check(x, p)?;
    let n = x.len();
    if scratch.len() < 2 * n {
        return Err(QualifyError::Buffer);
    }
    let (f, b) = scratch.split_at_mut(n);
    for t in 0..n {
        f[t] = x[t] - mean;
        b[t] = x[t] - mean;
    }
    let mut k = [F::of(0.0); MAX_ORDER];
    let mut den = F::of(0.0);
    for m in 1..=p {
        let (mut num, mut d) = (F::of(0.0), F::of(0.0));
        // t = m..n: f[t] against b[t − 1].
        for (&ft, &bt1) in f.iter().skip(m).zip(b.iter().skip(m - 1)) {
            num += ft * bt1;
            d += ft * ft + bt1 * bt1;
        }
        if !(d > F::of(0.0)) {
            return Err(QualifyError::Constant);
        }
        let km = F::of(2.0) * num / d;
        // Update from the end so b[t − 1] is still the old value.
        for t in (m..n).rev() {
            let (Some(&ft), Some(&bt1)) = (f.get(t), b.get(t - 1)) else {
                continue;
            };
            if let Some(fo) = f.get_mut(t) {
                *fo = ft - km * bt1;
            }
            if let Some(bo) = b.get_mut(t) {
                *bo = bt1 - km * ft;
            }
        }
        // (`check` bounds p by MAX_ORDER; `get` lets the compiler see it.)
        *k.get_mut(m - 1).ok_or(QualifyError::Parameter)? = km;
        den = d;
    }
    let mut phi = [F::of(0.0); MAX_ORDER];
    let ks = k.get(..p).ok_or(QualifyError::Parameter)?;
    levinson_from_reflection(ks, &mut phi);
    let kp = *ks.last().ok_or(QualifyError::Parameter)?;
    let sigma2 = (F::of(1.0) - kp * kp) * den / F::of(2.0 * (n - p) as f64);
    Ok(ArModel {
        order: p,
        phi,
        sigma2,
    })
}

/// The Burg model of order 1..=`max_p` with the lowest AIC.
pub fn select_order<F: Real>(
    x: &[F],
    max_p: usize,
    scratch: &mut [F],
) -> Result<ArModel<F>, QualifyError> {
    let mut best: Option<ArModel<F>> = None;
    for p in 1..=max_p.min(MAX_ORDER) {
        let m = burg(x, p, scratch)?;
        if best.is_none_or(|b| m.aic(x.len()) < b.aic(x.len())) {
            best = Some(m);
        }
    }
    best.ok_or(QualifyError::Parameter)
}
