//! The covariance of overlapping Allan variance estimates at several τ,
//! for a Gaussian noise of known spectrum.
//!
//! The estimate at factor m is the mean of M = n − 2m squares z_k² of the
//! rate filtered by the Allan filter (z_k = (ȳ_{k+m} − ȳ_k)/√2). For a
//! Gaussian process Cov(z², w²) = 2 Cov(z, w)², so over long records
//! (Percival & Walden, *Wavelet Methods for Time Series Analysis*, §8.3,
//! for the wavelet variance; the same argument holds for any filter)
//!
//! Cov(σ̂²(m_i), σ̂²(m_j)) ≈ (2/√(M_i M_j)) ∫ S(f)² |H_i(f)|² |H_j(f)|² df,
//!
//! by Parseval over the cross-covariance of the two filtered sequences.
//! Neighbouring τ on a grid of 8 a decade share most of their data (for
//! white rate noise the estimates at m and 2m correlate by 0.55), which a
//! fit weighted point by point takes as independent evidence.

use super::model::{allan_gain, gm_psd, power_psd, POWER};
use std::f64::consts::PI;

/// A noise spectrum: the power-law terms' squared coefficients and the
/// Gauss–Markov processes' (variance, τc), at rate samples τ0 apart.
#[derive(Clone, Debug)]
pub struct Spectrum {
    pub power: [f64; POWER],
    pub gm: Vec<(f64, f64)>,
    pub tau0: f64,
}

impl Spectrum {
    /// S(f) at f cycles a sample (0 < f ≤ ½).
    pub fn at(&self, f: f64) -> f64 {
        let p = power_psd(f, self.tau0);
        let mut s: f64 = (0..POWER).map(|k| self.power[k] * p[k]).sum();
        for &(var, tau_c) in &self.gm {
            s += var * gm_psd(f, self.tau0, tau_c);
        }
        s
    }
}

/// Up to this m the integral runs over a grid that resolves both filters
/// everywhere; above it the region where both oscillate fast is averaged.
const FULL_M: usize = 4096;
/// Beyond F/m cycles a sample a filter oscillates fast against the
/// spectrum's envelope.
const F: f64 = 16.0;

/// The mean of sin⁴(a x) sin⁴(b x) over x where both oscillate fast:
/// with sin⁴ = 3/8 − ½ cos 2u + ⅛ cos 4u, only products of equal
/// frequency (k a = l b) survive.
fn joint_mean(mi: usize, mj: usize) -> f64 {
    let a = [0.0, -0.5, 0.125];
    let mut s = 0.375 * 0.375;
    for k in 1..3usize {
        for l in 1..3usize {
            if k * mi == l * mj {
                s += 0.5 * a[k] * a[l];
            }
        }
    }
    s
}

/// ∫₀^½ S² |H_i|² |H_j|² df for m_i ≤ m_j.
///
/// Each filter oscillates with period 1/m in f; where f is well above
/// F/m, the oscillation is fast against the rest of the integrand and is
/// replaced by its mean. Below that the integrand is summed on a grid of
/// 16 points an oscillation of the faster filter.
fn pair_integral(spec: &Spectrum, mi: usize, mj: usize) -> f64 {
    let midpoint = |lo: f64, hi: f64, steps: usize, g: &dyn Fn(f64) -> f64| -> f64 {
        let h = (hi - lo) / steps as f64;
        (0..steps)
            .map(|k| g(lo + (k as f64 + 0.5) * h))
            .sum::<f64>()
            * h
    };
    // Midpoint on a log grid of `per` points a decade.
    let log_grid = |lo: f64, hi: f64, per: f64, g: &dyn Fn(f64) -> f64| -> f64 {
        if hi <= lo {
            return 0.0;
        }
        let n = ((per * (hi / lo).log10()).ceil() as usize).max(16);
        let (la, lb) = (lo.ln(), hi.ln());
        let h = (lb - la) / n as f64;
        (0..n)
            .map(|k| {
                let f = (la + (k as f64 + 0.5) * h).exp();
                g(f) * f
            })
            .sum::<f64>()
            * h
    };
    let (mfi, mfj) = (mi as f64, mj as f64);
    let s2 = |f: f64| {
        let s = spec.at(f);
        s * s
    };
    let exact = |f: f64| s2(f) * allan_gain(mi, f) * allan_gain(mj, f);
    // |H_m|² with sin⁴(πfm) replaced by its mean 3/8.
    let mean_gain = |m: f64, f: f64| {
        let sn = (PI * f).sin();
        0.75 / (m * m * sn * sn)
    };
    let (fi, fj) = (F / mfi, F / mfj);
    if mj <= FULL_M {
        let steps = ((0.5 * 16.0 * mfj).ceil() as usize).max(256);
        return midpoint(0.0, 0.5, steps, &exact);
    }
    if mj <= 4 * mi {
        // Close factors: both exact up to F/m_i, then both averaged
        // together (their frequencies can coincide: m_j = 2m_i).
        let steps = ((fi * 16.0 * mfj).ceil() as usize).max(256);
        let c = 4.0 * joint_mean(mi, mj) / (mfi * mfi * mfj * mfj);
        let both = |f: f64| {
            let sn = (PI * f).sin();
            s2(f) * c / (sn * sn * sn * sn)
        };
        return midpoint(0.0, fi, steps, &exact) + log_grid(fi, 0.5, 64.0, &both);
    }
    // Far apart: exact below F/m_j; the faster filter averaged up to F/m_i
    // (no frequency of the slower can meet it: m_j > 4m_i); both above.
    let low = midpoint(0.0, fj, 256, &exact);
    let mid_g = |f: f64| s2(f) * allan_gain(mi, f) * mean_gain(mfj, f);
    // The slower filter's oscillation (period 1/m_i) is resolved by 16
    // points at F/m_i with 600 points a decade (a step of ln 10/600 of f).
    let mid = log_grid(fj, fi.min(0.5), 600.0, &mid_g);
    let high_g = |f: f64| s2(f) * mean_gain(mfi, f) * mean_gain(mfj, f);
    low + mid + log_grid(fi.min(0.5), 0.5, 64.0, &high_g)
}

/// The covariance matrix of the overlapping Allan variances at factors
/// `ms` of `n` phase points under `spec`.
pub fn avar_cov(spec: &Spectrum, ms: &[usize], n: usize) -> Vec<Vec<f64>> {
    let p = ms.len();
    let mut c = vec![vec![0.0; p]; p];
    let terms = |m: usize| (n.saturating_sub(2 * m)).max(1) as f64;
    for i in 0..p {
        for j in i..p {
            let (a, b) = if ms[i] <= ms[j] {
                (ms[i], ms[j])
            } else {
                (ms[j], ms[i])
            };
            let v = 2.0 * 2.0 * pair_integral(spec, a, b) / (terms(a) * terms(b)).sqrt();
            c[i][j] = v;
            c[j][i] = v;
        }
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    fn white(tau0: f64) -> Spectrum {
        Spectrum {
            power: [0.0, 1.0, 0.0, 0.0, 0.0],
            gm: vec![],
            tau0,
        }
    }

    /// For white rate noise the variance matches the EDF of SP 1065's
    /// white-FM formula, (3(N−1)/2m − 2(N−2)/N)·4m²/(4m²+5), to 5 % at
    /// m ≥ 4 where that formula holds.
    #[test]
    fn variance_of_white_noise_matches_the_edf() {
        let n = 100_000usize;
        let tau0 = 1.0;
        let spec = white(tau0);
        for m in [4usize, 16, 100, 1000, 5000] {
            let c = avar_cov(&spec, &[m], n);
            let avar = 1.0 / m as f64;
            let edf = 2.0 * avar * avar / c[0][0];
            let nf = n as f64;
            let mf = m as f64;
            let sp1065 = (3.0 * (nf - 1.0) / (2.0 * mf) - 2.0 * (nf - 2.0) / nf) * 4.0 * mf * mf
                / (4.0 * mf * mf + 5.0);
            assert!(
                (edf / sp1065 - 1.0).abs() < 0.05,
                "m {m}: {edf} vs {sp1065}"
            );
        }
    }

    /// A Monte Carlo oracle for the correlation between τ: white noise at
    /// m and 2m correlate by about 0.55, and the averaged high-frequency
    /// region (m above FULL_M) gives the same variance as the full grid.
    #[test]
    fn correlation_of_white_noise() {
        let spec = white(1.0);
        let n = 1_000_000;
        let c = avar_cov(&spec, &[100, 200, 1600], n);
        let r = c[0][1] / (c[0][0] * c[1][1]).sqrt();
        assert!((0.45..0.65).contains(&r), "{r}");
        let r16 = c[0][2] / (c[0][0] * c[2][2]).sqrt();
        assert!(r16 < 0.05, "{r16}");
        // m = 5000 averaged against its full grid.
        let full = {
            let steps = 16 * 5000 / 2;
            let h = 0.5 / steps as f64;
            (0..steps)
                .map(|k| {
                    let f = (k as f64 + 0.5) * h;
                    let g = allan_gain(5000, f);
                    g * g
                })
                .sum::<f64>()
                * h
        };
        let split = pair_integral(&spec, 5000, 5000);
        assert!((split / full - 1.0).abs() < 0.01, "{split} vs {full}");
        // Pairs of large factors, near and far, against the full grid; on
        // a spectrum of white noise and a random walk.
        let mixed = Spectrum {
            power: [0.0, 1.0, 0.0, 1e-4, 0.0],
            gm: vec![(0.5, 300.0)],
            tau0: 1.0,
        };
        for (a, b) in [
            (5000usize, 7000usize),
            (5000, 10_000),
            (5000, 30_000),
            (100, 60_000),
        ] {
            let steps = 16 * b / 2;
            let h = 0.5 / steps as f64;
            let full: f64 = (0..steps)
                .map(|k| {
                    let f = (k as f64 + 0.5) * h;
                    let s = mixed.at(f);
                    s * s * allan_gain(a, f) * allan_gain(b, f)
                })
                .sum::<f64>()
                * h;
            let split = pair_integral(&mixed, a, b);
            assert!(
                (split / full - 1.0).abs() < 0.02,
                "{a} {b}: {split} vs {full}"
            );
        }
    }

    /// Monte Carlo: 400 records of white noise, the sample covariance of
    /// the estimates at m = 8 and 16 against the formula (within its
    /// sampling error).
    #[test]
    fn covariance_matches_monte_carlo() {
        let (n, runs) = (20_000usize, 400);
        let ms = [8usize, 16];
        let mut rng = gyro_sim::Rng::new(5);
        let mut est = vec![[0.0f64; 2]; runs];
        for e in est.iter_mut() {
            let mut x = vec![0.0f64; n];
            for k in 1..n {
                x[k] = x[k - 1] + f64::from(rng.gaussian());
            }
            for (slot, &m) in e.iter_mut().zip(&ms) {
                let terms = n - 2 * m;
                let s: f64 = (0..terms)
                    .map(|k| {
                        let d = x[k + 2 * m] - 2.0 * x[k + m] + x[k];
                        d * d
                    })
                    .sum();
                *slot = s / (2.0 * (m * m) as f64 * terms as f64);
            }
        }
        let mean = |k: usize| est.iter().map(|e| e[k]).sum::<f64>() / runs as f64;
        let (m0, m1) = (mean(0), mean(1));
        let cov = |a: usize, b: usize, ma: f64, mb: f64| {
            est.iter().map(|e| (e[a] - ma) * (e[b] - mb)).sum::<f64>() / (runs - 1) as f64
        };
        let c = avar_cov(&white(1.0), &ms, n);
        let v0 = cov(0, 0, m0, m0);
        let v01 = cov(0, 1, m0, m1);
        // A sample variance of 400 is within 15 % at 2 sd.
        assert!((v0 / c[0][0] - 1.0).abs() < 0.15, "{v0} vs {}", c[0][0]);
        let r_mc = v01 / (v0 * cov(1, 1, m1, m1)).sqrt();
        let r = c[0][1] / (c[0][0] * c[1][1]).sqrt();
        assert!((r_mc - r).abs() < 0.1, "{r_mc} vs {r}");
    }
}
