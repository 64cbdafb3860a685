//! The noise processes of a gyro's rate, each as its Allan variance per
//! unit parameter at averaging factor m and as its power spectral density,
//! for rate samples τ0 apart.
//!
//! Every process is the discrete one a sampled gyro produces, so the
//! Allan variance is exact at every m, not only asymptotically (IEEE Std
//! 952-1997 Annex C gives the continuous limits): quantisation is white
//! noise on the angle, each rate sample the difference of two angle
//! samples; the rate random walk integrates white increments sample by
//! sample; the Gauss–Markov process is the first-order autoregression
//! φ = e^(−τ0/τc); flicker is Kasdin's discrete flicker (by quadrature).
//! The spectra are two-sided on f ∈ [−½, ½] cycles a
//! sample, with ∫S df the variance, so that σ²(m) = ∫ S(f) |H_m(f)|² df
//! with the Allan filter |H_m(f)|² = 2 sin⁴(πfm) / (m sin πf)²
//! (`spectra_integrate_to_the_allan_variances` checks the two agree;
//! `host_tests::noise_classes` generates each process independently).

use std::f64::consts::{LN_2, PI};

/// The power-law terms, in IEEE 952's order and symbols.
pub const POWER_NAMES: [&str; 5] = ["Q", "N", "B", "K", "R"];

/// Number of power-law terms.
pub const POWER: usize = 5;

/// σ²(m) of each power-law term per unit of its squared coefficient:
/// Q² (angle white noise, variance Q²), N² (white rate, N²/τ0 a sample),
/// B² (flicker), K² (rate random walk, increments of K²τ0) and R² (a rate
/// ramp R·t).
pub fn power_avar(m: usize, tau0: f64) -> [f64; POWER] {
    power_avar_at(m as f64, tau0)
}

/// [`power_avar`] at a real averaging factor: the same discrete forms,
/// exact at integer m and continuous in τ between (flicker at the nearest
/// integer m, its curve being flat to within 0.1 % a step there).
pub fn power_avar_at(m: f64, tau0: f64) -> [f64; POWER] {
    let tau = m * tau0;
    [
        // Var(x_{k+2m} − 2x_{k+m} + x_k) / (2τ²) with x white: 6Q²/(2τ²).
        3.0 / (tau * tau),
        1.0 / tau,
        flicker_avar(m.max(1.0).round() as usize),
        // Discrete random walk: K²τ0 (2m² + 1)/(6m) = K²τ/3 + K²τ0²/(6τ).
        tau / 3.0 + tau0 * tau0 / (6.0 * tau),
        tau * tau / 2.0,
    ]
}

/// σ²(m) of flicker of unit coefficient: the discrete flicker of Kasdin
/// and Walter (white noise through (1 − z⁻¹)^(−½), the standard
/// simulation of power-law noise; spectrum 1/(2 sin πf), IEEE 952's
/// B²/(2πf) at low f) through the Allan filter, by quadrature up to m =
/// 4096 (cached); above, IEEE 952's flat level 2 ln 2/π, within 0.1 %.
pub fn flicker_avar(m: usize) -> f64 {
    use std::collections::HashMap;
    use std::sync::{Mutex, OnceLock};
    static CACHE: OnceLock<Mutex<HashMap<usize, f64>>> = OnceLock::new();
    if m > 4096 {
        return 2.0 * LN_2 / PI;
    }
    let cache = CACHE.get_or_init(|| Mutex::new(HashMap::new()));
    if let Some(&v) = cache.lock().ok().and_then(|c| c.get(&m).copied()).as_ref() {
        return v;
    }
    let steps = (16 * m).max(4096);
    let h = 0.5 / steps as f64;
    let v = 2.0
        * (0..steps)
            .map(|i| {
                let f = (i as f64 + 0.5) * h;
                allan_gain(m, f) / (2.0 * (PI * f).sin())
            })
            .sum::<f64>()
        * h;
    if let Ok(mut c) = cache.lock() {
        c.insert(m, v);
    }
    v
}

/// σ²(m) of a stationary first-order Gauss–Markov process of unit
/// variance and correlation time `tau_c`: Var(ȳ) − Cov(ȳ₁, ȳ₂) of
/// adjacent m-sample means of an AR(1) with φ = e^(−τ0/τc),
///
/// m² σ² = m(1+φ)/(1−φ) − 2φ(1−φᵐ)/(1−φ)² − φ(1−φᵐ)²/(1−φ)².
///
/// Where m(1−φ) is small the terms cancel; there the process is a random
/// walk of increments 1−φ² over the m samples (its error O(m(1−φ))).
pub fn gm_avar(m: usize, tau0: f64, tau_c: f64) -> f64 {
    let mf = m as f64;
    let q = -(-tau0 / tau_c).exp_m1(); // 1 − φ, accurate for small τ0/τc
    let phi = 1.0 - q;
    if mf * q < 1e-4 {
        let inc = q * (2.0 - q);
        return inc * (2.0 * mf * mf + 1.0) / (6.0 * mf);
    }
    let qm = -(-mf * tau0 / tau_c).exp_m1(); // 1 − φᵐ
    let s = mf * (1.0 + phi) / q - 2.0 * phi * qm / (q * q) - phi * qm * qm / (q * q);
    (s / (mf * mf)).max(0.0)
}

/// The Allan filter's squared gain |H_m(f)|² at f cycles a sample.
pub fn allan_gain(m: usize, f: f64) -> f64 {
    let mf = m as f64;
    let s = (PI * f).sin();
    let sm = (PI * f * mf).sin();
    let s2 = sm * sm;
    2.0 * s2 * s2 / (mf * mf * s * s)
}

/// The two-sided spectra per unit parameter at f cycles a sample (0 < f
/// ≤ ½): the five power-law terms (the ramp is not random: 0).
pub fn power_psd(f: f64, tau0: f64) -> [f64; POWER] {
    let s = (PI * f).sin();
    [
        4.0 * s * s / (tau0 * tau0),
        1.0 / tau0,
        // Kasdin's discrete flicker (see `flicker_avar`): at low f the
        // one-sided B²/(πF) in Hz of IEEE 952 (σ² = 2 ln 2·h₋₁, h₋₁ =
        // B²/π), per cycle a sample and two-sided.
        1.0 / (2.0 * (PI * f).sin()),
        tau0 / (4.0 * s * s),
        0.0,
    ]
}

/// The spectrum of a unit-variance Gauss–Markov process (AR(1), φ =
/// e^(−τ0/τc)) at f cycles a sample.
pub fn gm_psd(f: f64, tau0: f64, tau_c: f64) -> f64 {
    let q = -(-tau0 / tau_c).exp_m1();
    let phi = 1.0 - q;
    // 1 − 2φ cos 2πf + φ² = (1−φ)² + 4φ sin²(πf).
    let s = (PI * f).sin();
    q * (2.0 - q) / (q * q + 4.0 * phi * s * s)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ∫ S |H_m|² df by the midpoint rule, fine enough for the filter's
    /// oscillation and the spectra's pole at 0.
    fn integrate(m: usize, psd: impl Fn(f64) -> f64) -> f64 {
        let steps = 400_000usize.max(64 * m);
        let h = 0.5 / steps as f64;
        2.0 * (0..steps)
            .map(|i| {
                let f = (i as f64 + 0.5) * h;
                psd(f) * allan_gain(m, f)
            })
            .sum::<f64>()
            * h
    }

    /// Independent of the closed forms: each spectrum integrated through
    /// the Allan filter gives that term's Allan variance (flicker: IEEE
    /// 952's level once m is large).
    #[test]
    fn spectra_integrate_to_the_allan_variances() {
        let tau0 = 0.01;
        for m in [1usize, 2, 3, 7, 40, 300] {
            let closed = power_avar(m, tau0);
            for k in [0usize, 1, 3] {
                let num = integrate(m, |f| power_psd(f, tau0)[k]);
                let rel = num / closed[k] - 1.0;
                assert!(rel.abs() < 2e-4, "term {k} m {m}: {num} vs {}", closed[k]);
            }
            for tau_c in [0.005, 0.03, 1.0, 50.0] {
                let num = integrate(m, |f| gm_psd(f, tau0, tau_c));
                let closed = gm_avar(m, tau0, tau_c);
                let rel = num / closed - 1.0;
                assert!(rel.abs() < 2e-4, "GM {tau_c} m {m}: {num} vs {closed}");
            }
        }
        // Flicker reaches IEEE 952's flat level, and meets it where the
        // quadrature hands over.
        let flat = 2.0 * LN_2 / PI;
        assert!((flicker_avar(4096) / flat - 1.0).abs() < 1e-3);
        assert!((flicker_avar(1) / flat - 1.0).abs() > 0.05);
    }

    /// The Gauss–Markov variance is continuous where its random-walk form
    /// takes over, reaches K² = 2σ²/τc for τ ≪ τc, and equals the
    /// continuous process for τ ≫ τ0.
    #[test]
    fn gauss_markov_limits() {
        let tau0 = 0.01;
        let tau_c = 1000.0;
        // m(1 − φ) = 1e-4 at m = 10 000.
        let below = gm_avar(9_999, tau0, tau_c);
        let above = gm_avar(10_001, tau0, tau_c);
        assert!((above / below - 1.0).abs() < 1e-3, "{below} {above}");
        let rw = gm_avar(100, tau0, tau_c) / ((2.0 / tau_c) * 1.0 / 3.0);
        assert!((rw - 1.0).abs() < 1e-2, "{rw}");
        // The continuous process: σ² (2/T)(1 − (3 − 4e^−T + e^−2T)/(2T)),
        // T = τ/τc (IEEE 952 Annex C).
        let m = 10_000_000usize;
        let t = m as f64 * tau0 / tau_c;
        let cont = (2.0 / t) * (1.0 - (3.0 - 4.0 * (-t).exp() + (-2.0 * t).exp()) / (2.0 * t));
        let far = gm_avar(m, tau0, tau_c) / cont;
        assert!((far - 1.0).abs() < 1e-4, "{far}");
    }
}
