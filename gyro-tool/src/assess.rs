//! A truth-free measure of a fusion on a real multi-gyro log: nobody knows
//! the true rate, but each chip is an independent witness of the others.
//!
//! - **Leave-one-out.** For each chip, the others are fused (the firmware's
//!   path, [`crate::replay::replay`]) and compared with it, each series'
//!   mean taken out (a constant offset between chips cannot be told from a
//!   bias without a truth). With independent chip errors,
//!   E[(x₋ᵢ − yᵢ)²] = Var x₋ᵢ + σᵢ², so over the chips the fusion with the
//!   smaller sum has the smaller fused error. Beside it the same for the
//!   plain mean of the others and for fixed inverse-variance weights with
//!   each chip's noise estimated from the whole log (the N-cornered hat:
//!   least squares of Var(yᵢ − yⱼ) = σᵢ² + σⱼ² over every pair), what
//!   knowing the chips' noise in advance is worth. Those fixed weights
//!   come from every chip, the one left out too; so does the fourth
//!   figure, the whole fusion's own weights sample by sample, renormalised
//!   over the others: the two compare like with like (what the board
//!   learns from all its chips against what knowing their noise in advance
//!   gives), where the fusion of the others alone has one chip fewer to
//!   learn from (three chips cannot tell a noisier chip from two that
//!   share an error, and are weighed equally).
//! - **The weights' spread**: each chip's mean weight and its standard
//!   deviation over the samples it was offered, and the share of samples
//!   with three or more chips fused where one chip holds over 0.9.
//! - **On a static log**, the fused rate's Allan deviation against the
//!   plain mean's, and the noise probe's against the fused rate's (on a
//!   static log the fused rate is its own noise).
//!
//! The hat's variances come out negative where chips share an error (two
//! chips on one arm of a frame that vibrates): then no second-moment
//! method can say which chip is noisier, and the hat says so
//! ([`Assessment::shared_error`]).

use crate::replay::{replay, Replay, MAX_CHIPS};
use crate::Res;

/// Leave-one-out of one chip.
#[derive(Clone, Copy, Debug)]
pub struct LooChip {
    /// RMS of (fusion of the others − this chip), means out.
    pub fused: f64,
    /// The same for the plain mean of the others.
    pub mean: f64,
    /// The same for fixed inverse-variance weights (the whole log's hat).
    pub fixed_iv: f64,
    /// The same for the whole fusion's own weights, renormalised over the
    /// others ([`renormalised`]): the weights learnt with every chip, as
    /// the fixed weights' hat is.
    pub own: f64,
}

/// One chip's weight over the log.
#[derive(Clone, Copy, Debug)]
pub struct Spread {
    /// Mean weight over the samples the chip answered.
    pub mean: f64,
    /// Its standard deviation over those samples.
    pub sd: f64,
    /// Samples it answered but fusion gave it weight 0.
    pub zero: usize,
}

/// On a static log: at τ = 2^j samples, the fused rate's Allan deviation
/// over the plain mean's, and the probe's over the fused rate's.
#[derive(Clone, Copy, Debug)]
pub struct StaticPoint {
    pub m: usize,
    pub fused_over_mean: f64,
    pub probe_over_fused: f64,
}

/// The truth-free measure of one log.
#[derive(Clone, Debug)]
pub struct Assessment {
    /// Per chip (empty with fewer than three chips: two leave one alone).
    pub loo: Vec<LooChip>,
    /// Each chip's noise variance from the whole log's N-cornered hat.
    pub hat: Vec<f64>,
    /// Per chip.
    pub spread: Vec<Spread>,
    /// Share of the samples with three or more chips fused where one
    /// chip's weight is above 0.9.
    pub one_chip_share: f64,
    /// Whether the log reads as static ([`is_static`]).
    pub is_static: bool,
    /// With a static log, τ = 1, 2, 4 … 64 samples.
    pub static_points: Vec<StaticPoint>,
}

impl Assessment {
    /// √(Σ over chips of the leave-one-out mean square) of the fusion over
    /// the plain mean's.
    pub fn loo_ratio(&self) -> f64 {
        ratio(&self.loo, |c| c.fused)
    }
    /// The same for the fixed inverse-variance weights.
    pub fn fixed_iv_ratio(&self) -> f64 {
        ratio(&self.loo, |c| c.fixed_iv)
    }
    /// The same for the whole fusion's own weights.
    pub fn own_ratio(&self) -> f64 {
        ratio(&self.loo, |c| c.own)
    }
    /// The hat has a variance below zero: some chips share an error, and
    /// no fusion that weighs by second moments can attribute it.
    pub fn shared_error(&self) -> bool {
        self.hat.iter().any(|&v| v < 0.0)
    }
}

fn ratio(loo: &[LooChip], f: impl Fn(&LooChip) -> f64) -> f64 {
    let a: f64 = loo.iter().map(|c| f(c).powi(2)).sum();
    let b: f64 = loo.iter().map(|c| c.mean.powi(2)).sum();
    (a / b).sqrt()
}

/// RMS of `a − b` with each one's mean taken out, over the samples where
/// both are finite (NaN if none).
pub fn rms_demeaned(a: &[f64], b: &[f64]) -> f64 {
    let pairs: Vec<(f64, f64)> = a
        .iter()
        .zip(b)
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .map(|(&x, &y)| (x, y))
        .collect();
    let n = pairs.len() as f64;
    if pairs.is_empty() {
        return f64::NAN;
    }
    let (ma, mb) = pairs
        .iter()
        .fold((0.0, 0.0), |(s, t), (x, y)| (s + x / n, t + y / n));
    (pairs
        .iter()
        .map(|(x, y)| ((x - ma) - (y - mb)).powi(2))
        .sum::<f64>()
        / n)
        .sqrt()
}

/// The N-cornered hat: each chip's noise variance from the variances of
/// the pairwise differences (over the samples both answered), by least
/// squares of Var(yᵢ − yⱼ) = σᵢ² + σⱼ². With every pair present the
/// solution is closed: with Rᵢ = Σⱼ Dᵢⱼ and S = ΣRᵢ / (2(N − 1)),
/// σᵢ² = (Rᵢ − S)/(N − 2). Needs three chips.
pub fn hat(chips: &[Vec<f64>]) -> Vec<f64> {
    let k = chips.len();
    if k < 3 {
        return vec![f64::NAN; k];
    }
    let mut r = vec![0.0; k];
    for i in 0..k {
        for j in i + 1..k {
            let d = rms_demeaned(&chips[i], &chips[j]).powi(2);
            r[i] += d;
            r[j] += d;
        }
    }
    let s = r.iter().sum::<f64>() / (2.0 * (k as f64 - 1.0));
    r.iter().map(|ri| (ri - s) / (k as f64 - 2.0)).collect()
}

/// A log reads as static when the plain mean of the chips, its own mean
/// taken out, moves no more than its noise explains: its RMS at most
/// three times what the hat's variances give for the mean (√Σσᵢ² / N),
/// plus 0.05 °/s for a bias that wanders. A vehicle's motion, even a
/// slow sway, is many times that.
pub fn is_static(chips: &[Vec<f64>], hat: &[f64]) -> bool {
    let k = chips.len();
    let n = chips[0].len();
    let mean: Vec<f64> = (0..n)
        .map(|i| chips.iter().map(|c| c[i]).sum::<f64>() / k as f64)
        .collect();
    let zero = vec![0.0; n];
    let rms = rms_demeaned(&mean, &zero);
    let noise = (hat.iter().map(|v| v.max(0.0)).sum::<f64>()).sqrt() / k as f64;
    rms.is_finite() && noise.is_finite() && rms <= 3.0 * noise + 0.05
}

/// The weighted mean of the (value, weight) pairs whose value is finite
/// and weight above 0 (NaN if none).
fn weighted_mean(pairs: impl Iterator<Item = (f64, f64)>) -> f64 {
    let (mut s, mut sw) = (0.0, 0.0);
    for (v, w) in pairs {
        if v.is_finite() && w > 0.0 {
            s += w * v;
            sw += w;
        }
    }
    if sw > 0.0 {
        s / sw
    } else {
        f64::NAN
    }
}

/// Fuse `chips` with fixed weights `w` (renormalised over the finite
/// ones each sample).
fn fixed(chips: &[&Vec<f64>], w: &[f64]) -> Vec<f64> {
    (0..chips[0].len())
        .map(|i| weighted_mean(chips.iter().zip(w).map(|(c, &wc)| (c[i], wc))))
        .collect()
}

/// Each sample, the chips but `skip` weighted by the whole fusion's own
/// weights `w` renormalised over them, each chip's mean (`means`) taken out
/// first, the stand-in for the calibration's offsets: how well the weights
/// the fusion learnt from every chip predict the one left out.
fn renormalised(
    chips: &[Vec<f64>],
    means: &[f64],
    w: &[[f32; MAX_CHIPS]],
    skip: usize,
) -> Vec<f64> {
    (0..chips[0].len())
        .map(|i| {
            weighted_mean(
                chips
                    .iter()
                    .enumerate()
                    .filter(|&(c, _)| c != skip)
                    .map(|(c, chip)| (chip[i] - means[c], f64::from(w[i][c]))),
            )
        })
        .collect()
}

/// Measure the replay `r` of `chips` (sampled every `tau0` s) without a
/// truth: leave-one-out runs the firmware's fusion once per chip.
pub fn assess(chips: &[Vec<f64>], r: &Replay, tau0: f64) -> Res<Assessment> {
    let k = chips.len();
    let n = chips[0].len();
    let hat = hat(chips);
    // Fixed weights: the hat's variances, floored at a millionth of the
    // largest (a chip the hat reads as noiseless takes the weight).
    let top = hat.iter().fold(0.0f64, |m, &v| m.max(v));
    let iv: Vec<f64> = hat
        .iter()
        .map(|&v| 1.0 / v.max(top * 1e-6).max(f64::MIN_POSITIVE))
        .collect();
    let mut loo = Vec::new();
    // Each chip's mean over its finite samples, for `renormalised`.
    let means: Vec<f64> = chips
        .iter()
        .map(|c| {
            let f: Vec<f64> = c.iter().copied().filter(|v| v.is_finite()).collect();
            f.iter().sum::<f64>() / f.len().max(1) as f64
        })
        .collect();
    if k >= 3 {
        for i in 0..k {
            let others: Vec<Vec<f64>> = (0..k)
                .filter(|&j| j != i)
                .map(|j| chips[j].clone())
                .collect();
            let refs: Vec<&Vec<f64>> = others.iter().collect();
            let fused = replay(&others)?.fused;
            let ones = vec![1.0; k - 1];
            let w: Vec<f64> = (0..k).filter(|&j| j != i).map(|j| iv[j]).collect();
            loo.push(LooChip {
                fused: rms_demeaned(&fused, &chips[i]),
                mean: rms_demeaned(&fixed(&refs, &ones), &chips[i]),
                fixed_iv: rms_demeaned(&fixed(&refs, &w), &chips[i]),
                own: rms_demeaned(&renormalised(chips, &means, &r.weights, i), &chips[i]),
            });
        }
    }
    let spread = (0..k)
        .map(|c| {
            let ws: Vec<f64> = (0..n)
                .filter(|&i| chips[c][i].is_finite())
                .map(|i| f64::from(r.weights[i][c]))
                .collect();
            let m = ws.len().max(1) as f64;
            let mean = ws.iter().sum::<f64>() / m;
            let sd = (ws.iter().map(|w| (w - mean).powi(2)).sum::<f64>() / m).sqrt();
            Spread {
                mean,
                sd,
                zero: ws.iter().filter(|&&w| w == 0.0).count(),
            }
        })
        .collect();
    let (mut three, mut one) = (0usize, 0usize);
    for w in &r.weights {
        if w.iter().filter(|&&x| x > 0.0).count() >= 3 {
            three += 1;
            one += usize::from(w.iter().any(|&x| x > 0.9));
        }
    }
    let is_static = k >= 3 && is_static(chips, &hat);
    let mut static_points = Vec::new();
    if is_static {
        let ones = vec![1.0; k];
        let mean = fixed(&chips.iter().collect::<Vec<_>>(), &ones);
        let (_, f) = crate::replay::longest_run_adev(&r.fused, tau0);
        let (_, m) = crate::replay::longest_run_adev(&mean, tau0);
        let (_, p) = crate::replay::longest_run_adev(&r.probe, tau0);
        for j in 0..7.min(f.len()).min(m.len()).min(p.len()) {
            static_points.push(StaticPoint {
                m: 1 << j,
                fused_over_mean: f[j].1 / m[j].1,
                probe_over_fused: p[j].1 / f[j].1,
            });
        }
    }
    Ok(Assessment {
        loo,
        hat,
        spread,
        one_chip_share: one as f64 / three.max(1) as f64,
        is_static,
        static_points,
    })
}

/// Most samples [`lags`] looks either side.
pub const MAX_LAG: usize = 8;

/// Each chip's lag against the first, in samples (chip `c` at sample
/// `i + lag` saw what the first chip saw at `i`), from the cross-
/// correlation of the rates (means out) summed over `axes` (one
/// slice of chips per axis, same lengths). A lag is taken only where the
/// common motion says so: the peak correlation at least 0.3, and what it
/// leaves unexplained (1 − ρ) at most 0.8 of what lag 0 leaves; otherwise
/// 0 (a static log is noise about its mean, and any peak is chance).
///
/// Why: the board puts its chips on one time grid (their FIFO stamps and
/// the clock tracker); a log cut by rows does not, and on a turning
/// vehicle one sample of skew between chips reads as a disagreement of
/// the rate's change per sample, which the gate then takes for a fault
/// (the quadrotor flights' chips sit up to four samples apart).
pub fn lags(axes: &[&[Vec<f64>]]) -> Vec<i64> {
    let k = axes.first().map_or(0, |a| a.len());
    // Each rate less its mean (NaN as 0): the motion itself, not its
    // change per sample, whose vibration near the Nyquist frequency
    // correlates at the wrong lag.
    let diff = |x: &[f64]| -> Vec<f64> {
        let fin = x.iter().filter(|v| v.is_finite());
        let n = fin.clone().count().max(1) as f64;
        let m = fin.sum::<f64>() / n;
        x.iter()
            .map(|v| if v.is_finite() { v - m } else { 0.0 })
            .collect()
    };
    let d: Vec<Vec<Vec<f64>>> = axes
        .iter()
        .map(|chips| chips.iter().map(|c| diff(c)).collect())
        .collect();
    let corr = |c: usize, lag: i64| -> f64 {
        let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
        for ax in &d {
            let (a, b) = (&ax[0], &ax[c]);
            let n = a.len().min(b.len()) as i64;
            let m = MAX_LAG as i64;
            for i in m..(n - m) {
                let (x, y) = (a[i as usize], b[(i + lag) as usize]);
                sab += x * y;
                saa += x * x;
                sbb += y * y;
            }
        }
        let den = (saa * sbb).sqrt();
        if den > 0.0 {
            sab / den
        } else {
            0.0
        }
    };
    let m = MAX_LAG as i64;
    (0..k)
        .map(|c| {
            if c == 0 || d[0][c].len() <= 2 * MAX_LAG + 16 {
                return 0;
            }
            let rho: Vec<f64> = (-m..=m).map(|l| corr(c, l)).collect();
            let (best, peak) = (-m..=m)
                .zip(rho.iter().copied())
                .fold((0, f64::MIN), |b, x| if x.1 > b.1 { x } else { b });
            let at_zero = rho[MAX_LAG];
            if peak >= 0.3 && 1.0 - peak <= 0.8 * (1.0 - at_zero) {
                best
            } else {
                0
            }
        })
        .collect()
}

/// `chips` with each shifted by its lag: chip `c`'s sample `i + lag`
/// becomes its sample `i`; where that falls outside the log, NaN (no
/// answer).
pub fn shifted(chips: &[Vec<f64>], lags: &[i64]) -> Vec<Vec<f64>> {
    chips
        .iter()
        .zip(lags)
        .map(|(c, &l)| {
            (0..c.len() as i64)
                .map(|i| {
                    let j = i + l;
                    if (0..c.len() as i64).contains(&j) {
                        c[j as usize]
                    } else {
                        f64::NAN
                    }
                })
                .collect()
        })
        .collect()
}
