//! Oracles: nolds, PyWavelets, scikit-image, scipy and statsmodels vectors
//! (`host-tests/vectors/qualify.in`, made by `make_qualify_vectors.py`),
//! plus independent f64 references written here.
use super::ar::{burg, select_order, yule_walker};
use super::hurst::{frac_diff, frac_order, frac_weights, hurst_mrs, hurst_rs, rs, Convention};
use super::moments::skew_kurtosis;
use super::trend::{detrend_poly, reverse_arrangement};
use super::wavelet::{bayes_shrink, wavedec, waverec, Layout, DB4, DB5};
use super::*;

#[allow(clippy::excessive_precision, clippy::unreadable_literal)]
mod v {
    include!("../../../host-tests/vectors/qualify.in");
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(1e-300)
}

/// Park–Miller as the script: the first value is one step after the seed.
fn park_miller(seed: u64, n: usize) -> Vec<f64> {
    let mut x = seed;
    (0..n)
        .map(|_| {
            x = (16_807 * x) % 2_147_483_647;
            x as f64 / 2_147_483_647.0
        })
        .collect()
}

fn fixed() -> Vec<f64> {
    (0..256u64).map(|i| ((i * i * 7) % 101) as f64).collect()
}

#[test]
fn rs_statistic_matches_nolds_exactly() {
    let x = fixed();
    for (k, n) in [4, 8, 16, 32, 64].into_iter().enumerate() {
        let got = rs(&x, n).unwrap();
        assert!(
            rel(got, v::RS_FIXED[k]) < 1e-13,
            "n={n}: {got} vs {}",
            v::RS_FIXED[k]
        );
    }
    let h = hurst_rs(&x, &[4, 8, 16, 32, 64]).unwrap();
    assert!(rel(h, v::H_RS_FIXED) < 1e-12, "{h}");
}

/// fGn by Hosking's method, as the script (Box–Muller on Park–Miller).
fn fgn(h: f64, n: usize, seed: u64) -> Vec<f64> {
    let u = park_miller(seed, 2 * n);
    let mut g = (0..n).map(|i| {
        (-2.0 * u[2 * i].ln()).sqrt() * (2.0 * core::f64::consts::PI * u[2 * i + 1]).cos()
    });
    let (mut x, mut phi, mut prev) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    gyro_sim::noise::fgn_hosking(h, || g.next().unwrap_or(0.0), &mut x, &mut phi, &mut prev);
    x
}

#[test]
fn hurst_rs_on_fgn_matches_nolds() {
    let ns: Vec<usize> = (3..=10).map(|j| 1 << j).collect();
    for (k, h) in [0.6, 0.7, 0.8].into_iter().enumerate() {
        let x = fgn(h, 2048, 1_234_567 + (100.0 * h).round() as u64);
        let got = hurst_rs(&x, &ns).unwrap();
        assert!(
            (got - v::H_RS_FGN[k]).abs() < 1e-9,
            "H={h}: ours {got}, nolds {}",
            v::H_RS_FGN[k]
        );
        // And it estimates H (R/S is biased at N = 2048; ±0.1).
        assert!((got - h).abs() < 0.1, "H={h}: {got}");
        // The f32 board path agrees within 1e-3.
        let x32: Vec<f32> = x.iter().map(|&v| v as f32).collect();
        let h32 = hurst_rs(&x32, &ns).unwrap();
        assert!((h32 as f64 - got).abs() < 1e-3, "{h32} vs {got}");
    }
}

#[test]
fn modified_rs_matches_an_f64_reference() {
    let x = fgn(0.75, 2048, 99);
    let (h, q, rho) = hurst_mrs(&x).unwrap();
    // Reference written out from eq. 13–14 with the Andrews rule.
    let n = x.len() as f64;
    let m = x.iter().sum::<f64>() / n;
    let d: Vec<f64> = x.iter().map(|v| v - m).collect();
    let mut c = 0.0;
    let (mut lo, mut hi) = (f64::MAX, f64::MIN);
    for v in &d {
        c += v;
        lo = lo.min(c);
        hi = hi.max(c);
    }
    let g = |j: usize| d[j..].iter().zip(&d).map(|(a, b)| a * b).sum::<f64>() / n;
    let r1 = g(1) / g(0);
    let rho_ref = ((1.5 * n).powf(1.0 / 3.0) * (2.0 * r1 / (1.0 - r1 * r1)).abs().powf(2.0 / 3.0))
        .floor() as usize;
    assert_eq!(rho, rho_ref);
    let mut var = g(0);
    for j in 1..=rho_ref {
        var += 2.0 * (1.0 - j as f64 / (rho_ref as f64 + 1.0)) * g(j);
    }
    let q_ref = (hi - lo) / var.sqrt();
    assert!(rel(q, q_ref) < 1e-12 && rel(h, q_ref.ln() / n.ln()) < 1e-12);
}

#[test]
fn fractional_difference_weights_are_exact() {
    let mut h = [0.0f64; 17];
    frac_weights(1.2483, &mut h);
    for (k, (&a, &b)) in h.iter().zip(v::FD_W_12483).enumerate() {
        assert!(
            rel(a, b) < 1e-12 || (a - b).abs() < 1e-15,
            "k={k}: {a} vs {b}"
        );
    }
    // SEEDS analyst check: 1, −1.2483, 0.1550, 0.0388, 0.0170, 0.0094.
    for (a, b) in h.iter().zip([1.0, -1.2483, 0.1550, 0.0388, 0.0170, 0.0094]) {
        assert!((a - b).abs() < 6e-5, "{a} vs {b}");
    }
    assert_eq!(frac_order(0.7483, Convention::Fbm), 1.2483);
    assert!((frac_order(0.7483, Convention::Fgn) - 0.2483f64).abs() < 1e-15);
    // q = 1: the first difference.
    let mut w = [0.0f64; 4];
    frac_weights(1.0, &mut w);
    assert_eq!(w, [1.0, -1.0, 0.0, 0.0]);
    let mut y = [0.0; 4];
    frac_diff(&[1.0, 4.0, 9.0, 16.0], &w, &mut y).unwrap();
    assert_eq!(y, [1.0, 3.0, 5.0, 7.0]);
}

fn check_wavelet(w: &super::wavelet::Wavelet, lens: &[usize], coeffs: &[f64], bayes: &[f64]) {
    let x = v::WAVE_SIGNAL;
    let mut c = vec![0.0; 400];
    let mut scratch = vec![0.0; 700];
    let lay = wavedec(w, x, 5, &mut c, &mut scratch).unwrap();
    assert_eq!(lay.lens(), lens);
    let scale = coeffs.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for (i, (&a, &b)) in c[..lay.total()].iter().zip(coeffs).enumerate() {
        assert!(
            (a - b).abs() <= 1e-5 * scale.max(b.abs()) * 1e-5 + 1e-12,
            "coeff {i}: {a} vs {b}"
        );
    }
    // Perfect reconstruction.
    let mut out = vec![0.0; 300];
    waverec(w, &c, &lay, &mut out, &mut scratch).unwrap();
    for (a, b) in out.iter().zip(x) {
        assert!((a - b).abs() < 1e-12);
    }
    // BayesShrink against scikit-image: 1e-6 of the peak.
    let mut tmp = vec![0.0; 200];
    bayes_shrink(&mut c, &lay, &mut tmp).unwrap();
    waverec(w, &c, &lay, &mut out, &mut scratch).unwrap();
    let peak = bayes.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for (i, (&a, &b)) in out.iter().zip(bayes).enumerate() {
        assert!((a - b).abs() <= 1e-6 * peak, "sample {i}: {a} vs {b}");
    }
}

#[test]
fn db4_and_db5_match_pywavelets_and_skimage() {
    check_wavelet(&DB4, v::DB4_LENS, v::DB4_COEFFS, v::DB4_BAYES);
    check_wavelet(&DB5, v::DB5_LENS, v::DB5_COEFFS, v::DB5_BAYES);
}

#[test]
fn moments_match_scipy() {
    let m: Vec<f64> = (0..500u64)
        .map(|i| ((i * i * 7) % 101 + (i % 13) * (i % 13)) as f64)
        .collect();
    let (s, k) = skew_kurtosis(&m).unwrap();
    assert!(
        rel(s, v::SKEW) < 1e-12 && rel(k, v::KURT) < 1e-12,
        "{s} {k}"
    );
    assert_eq!(skew_kurtosis(&[2.0f64; 10]), Err(QualifyError::Constant));
    assert_eq!(skew_kurtosis::<f64>(&[]), Err(QualifyError::TooShort));
    assert_eq!(
        skew_kurtosis(&[1.0, f64::NAN]),
        Err(QualifyError::NonFinite)
    );
}

fn ar_series() -> Vec<f64> {
    let u = park_miller(777, 4000);
    let mut x = vec![0.0; 4000];
    for t in 0..4000 {
        let mut v = u[t] - 0.5;
        if t >= 1 {
            v += 0.6 * x[t - 1];
        }
        if t >= 2 {
            v -= 0.3 * x[t - 2];
        }
        x[t] = v;
    }
    x
}

#[test]
fn ar_fits_match_statsmodels() {
    let x = ar_series();
    let yw = yule_walker(&x, 4).unwrap();
    for i in 0..4 {
        assert!(rel(yw.phi[i], v::YW_PHI[i]) < 1e-10, "yw {i}");
    }
    assert!(rel(yw.sigma2.sqrt(), v::YW_SIGMA) < 1e-10);
    let mut s = vec![0.0; 8000];
    let b = burg(&x, 4, &mut s).unwrap();
    for i in 0..4 {
        assert!(
            rel(b.phi[i], v::BURG_PHI[i]) < 1e-9,
            "burg {i}: {} vs {}",
            b.phi[i],
            v::BURG_PHI[i]
        );
    }
    assert!(
        rel(b.sigma2, v::BURG_SIGMA2) < 1e-9,
        "{} vs {}",
        b.sigma2,
        v::BURG_SIGMA2
    );
    // AIC over 1..=8 picks order 2 or 3 (it overfits by one now and then)
    // and recovers φ1 = 0.6, φ2 = −0.3.
    let best = select_order(&x, 8, &mut s).unwrap();
    assert!((2..=3).contains(&best.order), "{}", best.order);
    assert!((best.phi[0] - 0.6).abs() < 0.05 && (best.phi[1] + 0.3).abs() < 0.05);
    assert_eq!(yule_walker(&x, 0).err(), Some(QualifyError::Parameter));
    assert_eq!(
        yule_walker(&[1.0, 2.0], 4).err(),
        Some(QualifyError::TooShort)
    );
    assert_eq!(
        yule_walker(&[3.0; 50], 2).err(),
        Some(QualifyError::Constant)
    );
}

#[test]
fn reverse_arrangement_counts_and_detects_a_trend() {
    // Brute-force reference for λ on white noise and on a ramp.
    let u = park_miller(5, 4000);
    let mut means = [0.0; 64];
    let flat: Vec<f64> = u.iter().map(|v| v - 0.5).collect();
    let r = reverse_arrangement(&flat, 40, &mut means).unwrap();
    assert!(r.stationary(), "{r:?}");
    let ramp: Vec<f64> = flat
        .iter()
        .enumerate()
        .map(|(i, v)| v + i as f64 * 2e-4)
        .collect();
    let r = reverse_arrangement(&ramp, 40, &mut means).unwrap();
    assert!(!r.stationary() && r.lambda > 2.0, "{r:?}");
    // Strictly increasing means: A = M(M−1)/2, λ = √(9M(M−1)/(2(2M+5))).
    let inc: Vec<f64> = (0..100).map(|i| i as f64).collect();
    let r = reverse_arrangement(&inc, 10, &mut means).unwrap();
    assert_eq!(r.a, 45.0);
    assert!(rel(r.lambda, (9.0f64 * 10.0 * 9.0 / (2.0 * 25.0)).sqrt()) < 1e-12);
    assert_eq!(
        reverse_arrangement(&inc, 2, &mut means).err(),
        Some(QualifyError::Parameter)
    );
    assert_eq!(
        reverse_arrangement(&inc[..5], 10, &mut means).err(),
        Some(QualifyError::TooShort)
    );
}

#[test]
fn polynomial_detrend_removes_a_cubic_exactly() {
    let mut x: Vec<f64> = (0..200)
        .map(|i| {
            let t = i as f64;
            3.0 + 0.5 * t - 0.01 * t * t + 1e-5 * t * t * t
        })
        .collect();
    detrend_poly(&mut x, 3).unwrap();
    assert!(x.iter().all(|v| v.abs() < 1e-9), "{:?}", &x[..4]);
    assert_eq!(
        detrend_poly(&mut [1.0f64, 2.0], 3).err(),
        Some(QualifyError::TooShort)
    );
}

#[test]
fn wavelet_bad_input_is_typed() {
    let mut c = [0.0f64; 64];
    let mut s = [0.0f64; 128];
    assert_eq!(
        wavedec(&DB5, &[1.0; 4], 5, &mut c, &mut s).err(),
        Some(QualifyError::TooShort)
    );
    assert_eq!(
        wavedec(&DB5, &[1.0; 40], 0, &mut c, &mut s).err(),
        Some(QualifyError::Parameter)
    );
    assert_eq!(
        wavedec(&DB5, &[f64::NAN; 40], 2, &mut c, &mut s).err(),
        Some(QualifyError::NonFinite)
    );
    assert_eq!(
        wavedec(&DB5, &[1.0; 40], 2, &mut c[..10], &mut s).err(),
        Some(QualifyError::Buffer)
    );
    // A constant signal: every band dies, the approximation keeps it.
    let x = [2.5f64; 64];
    let mut c = [0.0f64; 128];
    let mut s = [0.0f64; 256];
    let lay = wavedec(&DB4, &x, 2, &mut c, &mut s).unwrap();
    let mut tmp = [0.0f64; 64];
    let sh = bayes_shrink(&mut c, &lay, &mut tmp).unwrap();
    assert!(sh.sigma.abs() < 1e-12);
    let mut out = [0.0f64; 64];
    waverec(&DB4, &c, &lay, &mut out, &mut s).unwrap();
    assert!(out.iter().all(|v| (v - 2.5).abs() < 1e-9));
    let _ = Layout::new(64, 8, 2).unwrap();
    // Short buffers for reconstruction and shrinkage are typed errors, and
    // a layout of another length cannot be forged (private fields): one
    // for 1000 samples on 128 coefficients is refused, not indexed.
    assert_eq!(
        waverec(&DB4, &c, &lay, &mut out[..10], &mut s),
        Err(QualifyError::Buffer)
    );
    assert_eq!(
        waverec(&DB4, &c, &lay, &mut out, &mut s[..10]),
        Err(QualifyError::Buffer)
    );
    assert_eq!(
        bayes_shrink(&mut c, &lay, &mut tmp[..3]),
        Err(QualifyError::Buffer)
    );
    let big = Layout::new(1000, 8, 2).unwrap();
    assert_eq!(
        bayes_shrink(&mut c, &big, &mut tmp),
        Err(QualifyError::Buffer)
    );
    assert_eq!(
        waverec(&DB4, &c, &big, &mut out, &mut s),
        Err(QualifyError::Buffer)
    );
    assert!(big.band(99).is_empty());
}

/// EMD of `x` with the default settings: the rows (IMFs, then the
/// residue), and the decomposition's summary.
fn run_emd(x: &[f64]) -> (Vec<f64>, super::emd::Decomposition) {
    use super::emd::{emd, work_len, EmdConfig};
    let n = x.len();
    let cfg = EmdConfig::default();
    let mut out = vec![0.0; (cfg.max_imfs + 1) * n];
    let mut work = vec![0.0; work_len(n)];
    let mut idx = vec![0u32; n];
    let d = emd(x, &cfg, &mut out, &mut work, &mut idx).unwrap();
    (out, d)
}

#[test]
fn emd_matches_pyemd() {
    let x = v::EMD_SIGNAL;
    let n = x.len();
    let (out, d) = run_emd(x);
    let rows = d.imfs + d.residue as usize;
    println!(
        "ours: {} IMFs + residue {} (sifts {:?}); PyEMD rows {}",
        d.imfs,
        d.residue,
        &d.sifts[..d.imfs],
        v::EMD_ROWS
    );
    assert_eq!(rows, v::EMD_ROWS, "row count");
    for r in 0..rows {
        let a = &out[r * n..(r + 1) * n];
        let b = &v::EMD_OUT[r * n..(r + 1) * n];
        let corr = corr(a, b);
        println!("row {r}: correlation {corr:.6}");
        assert!(corr >= 0.99, "row {r}: correlation {corr}");
    }
    // The rows add back up to the signal.
    for i in 0..n {
        let s: f64 = (0..rows).map(|r| out[r * n + i]).sum();
        assert!((s - x[i]).abs() < 1e-9);
    }
}

#[test]
fn emd_edge_cases_are_defined() {
    use super::emd::{emd, masm, trend_start, work_len, EmdConfig};
    let cfg = EmdConfig::default();
    let n = 200;
    let mut out = vec![0.0; (cfg.max_imfs + 1) * n];
    let mut work = vec![0.0; work_len(n)];
    let mut idx = vec![0u32; n];
    // Monotone: no IMF, the signal is the residue.
    let ramp: Vec<f64> = (0..n).map(|i| i as f64 * 0.1).collect();
    let d = emd(&ramp, &cfg, &mut out, &mut work, &mut idx).unwrap();
    assert_eq!((d.imfs, d.residue), (0, true));
    assert_eq!(&out[..n], &ramp[..]);
    // All zero: nothing at all.
    let d = emd(&vec![0.0; n], &cfg, &mut out, &mut work, &mut idx).unwrap();
    assert_eq!((d.imfs, d.residue), (0, false));
    assert_eq!(
        emd(&[1.0, 2.0], &cfg, &mut out, &mut work, &mut idx).err(),
        Some(QualifyError::TooShort)
    );
    let mut bad = ramp.clone();
    bad[3] = f64::NAN;
    assert_eq!(
        emd(&bad, &cfg, &mut out, &mut work, &mut idx).err(),
        Some(QualifyError::NonFinite)
    );
    assert_eq!(
        emd(&ramp, &cfg, &mut out[..10], &mut work, &mut idx).err(),
        Some(QualifyError::Buffer)
    );
    // MASM of zero-mean modes is ~0; a trend mode shows up.
    let x: Vec<f64> = (0..n).map(|i| (i as f64 * 0.7).sin()).collect();
    let mut modes = x.clone();
    modes.extend((0..n).map(|i| 1.0 + i as f64 * 0.01));
    let mut acc = vec![0.0; n];
    let mut h = [0.0; 2];
    masm(&modes, n, 2, &mut acc, &mut h).unwrap();
    assert!(h[0].abs() < 0.05 && h[1].abs() > 0.5, "{h:?}");
    // Short buffers are typed errors (they panicked before).
    assert_eq!(
        masm(&modes, n, 3, &mut acc, &mut [0.0; 3]),
        Err(QualifyError::Buffer)
    );
    assert_eq!(
        masm(&modes, n, 2, &mut acc[..n - 1], &mut h),
        Err(QualifyError::Buffer)
    );
    assert_eq!(
        masm(&modes, n, 2, &mut acc, &mut h[..1]),
        Err(QualifyError::Buffer)
    );
    assert_eq!(
        masm(&modes, 0, 2, &mut acc, &mut h),
        Err(QualifyError::TooShort)
    );
    assert_eq!(trend_start(&h, 0.2), Some(2));
}

#[test]
fn pipelines_run_and_refuse_bad_settings() {
    use super::pipeline::{detrend_wavelet, prewhiten, Estimator, PrewhitenConfig};
    let x = fgn(0.8, 1024, 7);
    let cfg = PrewhitenConfig {
        estimator: Estimator::Rs,
        convention: Convention::Fgn,
        filter_len: 1024,
        wavelet: DB5,
        levels: 5,
    };
    let mut out = vec![0.0; 1024];
    let mut s = vec![0.0; 6 * 1024 + 64];
    let r = prewhiten(&x, &cfg, &mut out, &mut s).unwrap();
    assert!(r.q > 0.0 && r.q < 0.5 && r.std[2] < r.std[1], "{r:?}");
    let bad = PrewhitenConfig {
        filter_len: 0,
        ..cfg
    };
    assert_eq!(
        prewhiten(&x, &bad, &mut out, &mut s).err(),
        Some(QualifyError::Parameter)
    );
    assert_eq!(
        prewhiten(&[1.0; 1024], &cfg, &mut out, &mut s).err(),
        Some(QualifyError::Constant)
    );
    // A wavelet trend of a ramp plus a tone takes the ramp.
    let mut y: Vec<f64> = (0..1024)
        .map(|i| i as f64 * 0.01 + (i as f64 * 0.9).sin())
        .collect();
    let mut trend = vec![0.0; 1024];
    let mut s2 = vec![0.0; 4 * 1024 + 1024];
    detrend_wavelet(&mut y, &DB4, 6, &mut trend, &mut s2).unwrap();
    let mid = trend[512];
    assert!((mid - 5.12).abs() < 0.2, "{mid}");
}

/// The error-path sweep: every public qualify function, fed NaN, ±inf, empty
/// and too-short input and buffers shorter than documented, returns a
/// typed error or finite output, and never panics. Each case names the
/// error it must give (`tested` counts the cases, so none is skipped).
#[test]
fn bad_input_sweep_gives_typed_errors_and_no_nan() {
    use super::emd::{emd, masm, trend_start, work_len, EmdConfig};
    use super::moments::mean_var;
    use super::pipeline::{detrend_emd, detrend_wavelet, prewhiten, Estimator, PrewhitenConfig};
    use super::wavelet::{dwt, dwt_len, idwt};
    use QualifyError::*;
    let n = 256;
    let good: Vec<f64> = park_miller(11, n).iter().map(|v| v - 0.5).collect();
    let mut tested = 0;
    let mut expect = |what: &str, got: Result<(), QualifyError>, want: QualifyError| {
        assert_eq!(got, Err(want), "{what}");
        tested += 1;
    };
    for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        let mut x = good.clone();
        x[n / 2] = bad;
        let x = &x[..];
        expect("mean_var", mean_var(x).map(|_| ()), NonFinite);
        expect("skew_kurtosis", skew_kurtosis(x).map(|_| ()), NonFinite);
        let mut means = [0.0; 16];
        expect(
            "reverse_arrangement",
            reverse_arrangement(x, 16, &mut means).map(|_| ()),
            NonFinite,
        );
        let mut y = x.to_vec();
        expect(
            "detrend_poly",
            detrend_poly(&mut y, 2).map(|_| ()),
            NonFinite,
        );
        expect("yule_walker", yule_walker(x, 4).map(|_| ()), NonFinite);
        let mut sc = vec![0.0; 2 * n];
        expect("burg", burg(x, 4, &mut sc).map(|_| ()), NonFinite);
        expect(
            "select_order",
            select_order(x, 4, &mut sc).map(|_| ()),
            NonFinite,
        );
        expect("hurst_rs", hurst_rs(x, &[8, 16, 32]).map(|_| ()), NonFinite);
        expect("hurst_mrs", hurst_mrs(x).map(|_| ()), NonFinite);
        let mut h = vec![0.0; 16];
        frac_weights(0.3, &mut h);
        let mut out = vec![0.0; n];
        expect("frac_diff x", frac_diff(x, &h, &mut out), NonFinite);
        let mut hb = h.clone();
        hb[3] = bad;
        expect(
            "frac_diff weights",
            frac_diff(&good, &hb, &mut out),
            NonFinite,
        );
        let m = dwt_len(n, DB4.len());
        let (mut a, mut d) = (vec![0.0; m], vec![0.0; m]);
        expect("dwt", dwt(&DB4, x, &mut a, &mut d), NonFinite);
        dwt(&DB4, &good, &mut a, &mut d).unwrap();
        let mut ab = a.clone();
        ab[2] = bad;
        let mut rec = vec![0.0; 2 * m + 2];
        expect("idwt", idwt(&DB4, &ab, &d, &mut rec).map(|_| ()), NonFinite);
        let lay = Layout::new(n, DB4.len(), 3).unwrap();
        let mut c = vec![0.0; lay.total()];
        let mut scratch = vec![0.0; 2 * (n + DB4.len() + 2)];
        expect(
            "wavedec",
            wavedec(&DB4, x, 3, &mut c, &mut scratch).map(|_| ()),
            NonFinite,
        );
        let lay = wavedec(&DB4, &good, 3, &mut c, &mut scratch).unwrap();
        let mut cb = c.clone();
        cb[lay.band(1).start] = bad;
        let mut rec = vec![0.0; n];
        expect(
            "waverec",
            waverec(&DB4, &cb, &lay, &mut rec, &mut scratch),
            NonFinite,
        );
        let mut tmp = vec![0.0; n];
        expect(
            "bayes_shrink",
            bayes_shrink(&mut cb, &lay, &mut tmp).map(|_| ()),
            NonFinite,
        );
        let cfg = EmdConfig::default();
        let mut rows = vec![0.0; (cfg.max_imfs + 1) * n];
        let mut work = vec![0.0; work_len(n) + n];
        let mut idx = vec![0u32; n];
        expect(
            "emd",
            emd(x, &cfg, &mut rows, &mut work[..work_len(n)], &mut idx).map(|_| ()),
            NonFinite,
        );
        let mut imfs = good.repeat(2);
        imfs[n + 3] = bad;
        let (mut acc, mut hm) = (vec![0.0; n], vec![0.0; 2]);
        expect("masm", masm(&imfs, n, 2, &mut acc, &mut hm), NonFinite);
        let pcfg = PrewhitenConfig {
            estimator: Estimator::Rs,
            convention: Convention::Fbm,
            filter_len: 32,
            wavelet: DB4,
            levels: 3,
        };
        let mut big = vec![0.0; 3 * n + 2 * (n + 16) + 32];
        expect(
            "prewhiten",
            prewhiten(x, &pcfg, &mut out, &mut big).map(|_| ()),
            NonFinite,
        );
        let mut y = x.to_vec();
        let mut trend = vec![0.0; n];
        let mut sc2 = vec![0.0; n + 8 * 3 * DB4.len() + 2 * (n + DB4.len() + 2)];
        expect(
            "detrend_wavelet",
            detrend_wavelet(&mut y, &DB4, 3, &mut trend, &mut sc2),
            NonFinite,
        );
        let mut det = vec![0.0; n];
        expect(
            "detrend_emd",
            detrend_emd(x, &cfg, 0.2, &mut det, &mut rows, &mut work, &mut idx).map(|_| ()),
            NonFinite,
        );
        // A NaN threshold input to trend_start is not an error: NaN never
        // exceeds the threshold, so no trend is found.
        assert_eq!(
            trend_start(&[bad, 0.1], 0.2),
            if bad.is_nan() { None } else { Some(1) }
        );
    }
    // Empty and too short.
    let e: &[f64] = &[];
    expect("mean_var empty", mean_var(e).map(|_| ()), TooShort);
    expect(
        "skew_kurtosis empty",
        skew_kurtosis(e).map(|_| ()),
        TooShort,
    );
    expect(
        "hurst_mrs short",
        hurst_mrs(&good[..4]).map(|_| ()),
        TooShort,
    );
    let mut a = [0.0; 8];
    let mut d = [0.0; 8];
    expect("dwt empty", dwt(&DB4, e, &mut a, &mut d), TooShort);
    let cfg = EmdConfig::default();
    let (mut rows, mut work, mut idx) = (vec![0.0; 64], vec![0.0; 64], vec![0u32; 3]);
    expect(
        "emd short",
        emd(&good[..3], &cfg, &mut rows, &mut work, &mut idx).map(|_| ()),
        TooShort,
    );
    // Constant input.
    let flat = vec![1.5; n];
    expect(
        "hurst_rs constant",
        hurst_rs(&flat, &[8, 16, 32]).map(|_| ()),
        Constant,
    );
    expect(
        "skew_kurtosis constant",
        skew_kurtosis(&flat).map(|_| ()),
        Constant,
    );
    expect(
        "yule_walker constant",
        yule_walker(&flat, 3).map(|_| ()),
        Constant,
    );
    // Buffers shorter than documented.
    let mut out = vec![0.0; n - 1];
    let h = [1.0, -0.5];
    expect("frac_diff short y", frac_diff(&good, &h, &mut out), Buffer);
    let mut small = [0.0; 4];
    expect("dwt short a", dwt(&DB4, &good, &mut small, &mut d), Buffer);
    let lay = Layout::new(n, DB4.len(), 3).unwrap();
    let mut c = vec![0.0; lay.total() - 1];
    let mut scratch = vec![0.0; 2 * (n + DB4.len() + 2)];
    expect(
        "wavedec short coeffs",
        wavedec(&DB4, &good, 3, &mut c, &mut scratch).map(|_| ()),
        Buffer,
    );
    let mut c = vec![0.0; lay.total()];
    let mut tmp = vec![0.0; 3];
    expect(
        "bayes_shrink short tmp",
        bayes_shrink(&mut c, &lay, &mut tmp).map(|_| ()),
        Buffer,
    );
    let (mut acc, mut hm) = (vec![0.0; n], vec![0.0; 1]);
    expect("masm short h", masm(&good, n, 2, &mut acc, &mut hm), Buffer);
    let mut sc = vec![0.0; n];
    expect(
        "burg short scratch",
        burg(&good, 4, &mut sc).map(|_| ()),
        Buffer,
    );
    assert_eq!(tested, 3 * 21 + 14, "cases");
}

#[allow(clippy::excessive_precision, clippy::unreadable_literal)]
mod vc {
    include!("../../../host-tests/vectors/qualify_classes.in");
}

/// Correlation of two equal-length rows.
fn corr(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (p, q) in a.iter().zip(b) {
        sab += (p - ma) * (q - mb);
        saa += (p - ma) * (p - ma);
        sbb += (q - mb) * (q - mb);
    }
    if saa == 0.0 && sbb == 0.0 {
        return 1.0;
    }
    sab / (saa * sbb).sqrt()
}

/// EMD against PyEMD 1.10 on a chirp, tones, white noise, a
/// random walk, quantised AR(1) counts and an integer staircase (plateaus
/// of 2–7 samples): the same number of rows, and every row correlated
/// ≥ 0.999 with PyEMD's.
#[test]
fn emd_matches_pyemd_on_every_signal_class() {
    let cases: [(&str, &[f64], usize, &[f64]); 6] = [
        (
            "chirp",
            vc::EMD_CHIRP_X,
            vc::EMD_CHIRP_ROWS,
            vc::EMD_CHIRP_OUT,
        ),
        (
            "tones",
            vc::EMD_TONES_X,
            vc::EMD_TONES_ROWS,
            vc::EMD_TONES_OUT,
        ),
        (
            "noise",
            vc::EMD_NOISE_X,
            vc::EMD_NOISE_ROWS,
            vc::EMD_NOISE_OUT,
        ),
        ("walk", vc::EMD_WALK_X, vc::EMD_WALK_ROWS, vc::EMD_WALK_OUT),
        (
            "quantised AR(1)",
            vc::EMD_ARQ_X,
            vc::EMD_ARQ_ROWS,
            vc::EMD_ARQ_OUT,
        ),
        (
            "integer stairs",
            vc::EMD_STAIRS_X,
            vc::EMD_STAIRS_ROWS,
            vc::EMD_STAIRS_OUT,
        ),
    ];
    let mut worst = 1.0f64;
    for (name, x, rows_py, out_py) in cases {
        let n = x.len();
        let (out, d) = run_emd(x);
        let rows = d.imfs + d.residue as usize;
        let cs: Vec<f64> = (0..rows.min(rows_py))
            .map(|r| corr(&out[r * n..(r + 1) * n], &out_py[r * n..(r + 1) * n]))
            .collect();
        println!(
            "{name}: ours {rows} rows (sifts {:?}), PyEMD {rows_py}; correlations {cs:.5?}",
            &d.sifts[..d.imfs]
        );
        assert_eq!(rows, rows_py, "{name}: row count");
        for (r, c) in cs.iter().enumerate() {
            worst = worst.min(*c);
            assert!(*c >= 0.999, "{name}, row {r}: correlation {c}");
        }
    }
    println!("smallest correlation: {worst:.6}");
}

/// BayesShrink against scikit-image on a still gyro's integer
/// counts and on a record zero-padded to a power of two (exact zeros in the
/// finest band), db4 and db5, 5 levels: within 1e-6 of the peak.
#[test]
fn bayes_shrink_matches_skimage_on_quantised_and_padded_records() {
    let cases: [(&str, &[f64], &super::wavelet::Wavelet, &[f64]); 4] = [
        ("still db4", vc::BAYES_STILL_X, &DB4, vc::BAYES_STILL_DB4),
        ("still db5", vc::BAYES_STILL_X, &DB5, vc::BAYES_STILL_DB5),
        ("padded db4", vc::BAYES_PADDED_X, &DB4, vc::BAYES_PADDED_DB4),
        ("padded db5", vc::BAYES_PADDED_X, &DB5, vc::BAYES_PADDED_DB5),
    ];
    for (name, x, w, want) in cases {
        let n = x.len();
        let lay = Layout::new(n, w.len(), 5).unwrap();
        let mut c = vec![0.0; lay.total()];
        let mut scratch = vec![0.0; 2 * (n + w.len() + 2)];
        wavedec(w, x, 5, &mut c, &mut scratch).unwrap();
        let mut tmp = vec![0.0; n];
        bayes_shrink(&mut c, &lay, &mut tmp).unwrap();
        let mut out = vec![0.0; n];
        waverec(w, &c, &lay, &mut out, &mut scratch).unwrap();
        let peak = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let err = out
            .iter()
            .zip(want)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        println!("{name}: max error {:.3e} of the peak", err / peak);
        assert!(err <= 1e-6 * peak, "{name}: {err} (peak {peak})");
    }
}
