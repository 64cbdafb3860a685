//! The two whole procedures of the seeds, in caller-provided buffers:
//! pre-whitening (seed 002: estimate H, choose q, difference, denoise) and
//! detrending by a wavelet approximation or by EMD + MASM (seed 003).

use super::emd::{emd, masm, trend_start, work_len, Decomposition, EmdConfig};
use super::hurst::{
    frac_diff, frac_order, frac_weights, hurst_mrs, hurst_rs, octave_windows, Convention,
};
use super::moments::mean_var;
use super::wavelet::{bayes_shrink, wavedec, waverec, Wavelet, MAX_LEVELS};
use super::{QualifyError, Real};

/// Which Hurst estimate sets q.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Estimator {
    /// R/S regression over octave windows.
    Rs,
    /// Lo's modified R/S, ln Q / ln N (the paper's choice).
    ModifiedRs,
}

/// Pre-whitening settings (the paper: modified R/S, q = H + 0.5, db5, 5
/// levels, the full-length filter).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PrewhitenConfig {
    /// Hurst estimator.
    pub estimator: Estimator,
    /// q from H.
    pub convention: Convention,
    /// Fractional-difference filter length (≤ N; the paper's is unknown).
    pub filter_len: usize,
    /// Wavelet and levels of the BayesShrink stage.
    pub wavelet: Wavelet,
    /// Decomposition levels.
    pub levels: usize,
}

/// What pre-whitening did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prewhitened<F> {
    /// Hurst exponent used.
    pub hurst: F,
    /// Fractional order q.
    pub q: F,
    /// Standard deviations: input, differenced, denoised.
    pub std: [F; 3],
}

/// Estimate H, difference with q, BayesShrink-denoise into `out`.
/// `scratch` needs `3n + 2(n + 16) + filter_len` samples.
pub fn prewhiten<F: Real>(
    x: &[F],
    cfg: &PrewhitenConfig,
    out: &mut [F],
    scratch: &mut [F],
) -> Result<Prewhitened<F>, QualifyError> {
    let n = x.len();
    if cfg.filter_len == 0 || cfg.filter_len > n || cfg.levels == 0 || cfg.levels > MAX_LEVELS {
        return Err(QualifyError::Parameter);
    }
    if out.len() < n || scratch.len() < 3 * n + 2 * (n + 16) + cfg.filter_len {
        return Err(QualifyError::Buffer);
    }
    let (_, v_in) = mean_var(x)?;
    if !(v_in > F::of(0.0)) {
        return Err(QualifyError::Constant);
    }
    let hurst = match cfg.estimator {
        Estimator::Rs => {
            let mut ws = [0usize; 24];
            let k = octave_windows(n, &mut ws);
            hurst_rs(x, &ws[..k])?
        }
        Estimator::ModifiedRs => hurst_mrs(x)?.0,
    };
    let q = frac_order(hurst, cfg.convention);
    let (h, rest) = scratch.split_at_mut(cfg.filter_len);
    let (f, rest) = rest.split_at_mut(n);
    let (c, rest) = rest.split_at_mut(2 * n);
    frac_weights(q, h);
    frac_diff(x, h, f)?;
    let (_, v_f) = mean_var(f)?;
    let lay = wavedec(&cfg.wavelet, f, cfg.levels, c, rest)?;
    bayes_shrink(c, &lay, out)?;
    waverec(&cfg.wavelet, c, &lay, out, rest)?;
    let (_, v_out) = mean_var(&out[..n])?;
    Ok(Prewhitened {
        hurst,
        q,
        std: [v_in.sqrt(), v_f.sqrt(), v_out.sqrt()],
    })
}

/// Wavelet trend (seed 003's comparison method): the level-`levels`
/// approximation; `x` becomes x − trend, `trend` gets the trend.
/// `scratch` needs 2n + 2(n + F + 2) + 64·levels samples.
pub fn detrend_wavelet<F: Real>(
    x: &mut [F],
    w: &Wavelet,
    levels: usize,
    trend: &mut [F],
    scratch: &mut [F],
) -> Result<(), QualifyError> {
    let n = x.len();
    let need = n + 8 * levels * w.len();
    if scratch.len() < need + 2 * (n + w.len() + 2) || trend.len() < n {
        return Err(QualifyError::Buffer);
    }
    let (c, rest) = scratch.split_at_mut(need);
    let lay = wavedec(w, x, levels, c, rest)?;
    for b in 1..=lay.levels() {
        for v in &mut c[lay.band(b)] {
            *v = F::of(0.0);
        }
    }
    waverec(w, c, &lay, trend, rest)?;
    for (v, t) in x.iter_mut().zip(trend.iter()) {
        *v -= *t;
    }
    Ok(())
}

/// EMD detrending with MASM (eq. 5–7): the detrended series is the sum of
/// the modes before the first one whose |h_m| exceeds `threshold`.
/// `rows` needs (max_imfs + 1)·n, `work` [`work_len`] + n, `idx` n.
/// Returns (the decomposition, the trend's first mode m, 1-based).
pub fn detrend_emd<F: Real>(
    x: &[F],
    cfg: &EmdConfig,
    threshold: f64,
    detrended: &mut [F],
    rows: &mut [F],
    work: &mut [F],
    idx: &mut [u32],
) -> Result<(Decomposition, usize), QualifyError> {
    let n = x.len();
    if detrended.len() < n || work.len() < work_len(n) + n {
        return Err(QualifyError::Buffer);
    }
    let (w, acc) = work.split_at_mut(work_len(n));
    let d = emd(x, cfg, rows, w, idx)?;
    let mut h = [F::of(0.0); 17];
    let count = (d.imfs + d.residue as usize).min(h.len());
    masm(rows, n, count, acc, &mut h)?;
    let m = trend_start(&h[..count], threshold).unwrap_or(count + 1);
    for v in detrended[..n].iter_mut() {
        *v = F::of(0.0);
    }
    for r in 0..(m - 1).min(count) {
        for (a, v) in detrended.iter_mut().zip(&rows[r * n..(r + 1) * n]) {
            *a += *v;
        }
    }
    Ok((d, m))
}
