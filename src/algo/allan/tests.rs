use super::stream::{quantise, StreamAdev};
use super::*;
use crate::algo::stats::chi2_quantile;

#[allow(clippy::excessive_precision, clippy::unreadable_literal)]
mod vectors {
    include!("../../../host-tests/vectors/allan.in");
}

/// NBS14 1000-point set (NIST SP 1065 §12.3): Park–Miller from 1234567890,
/// y = n / (2³¹ − 1), the seed itself being the first point.
fn nbs14_1000() -> Vec<f64> {
    let mut n: u64 = 1_234_567_890;
    let mut y = Vec::with_capacity(1000);
    for _ in 0..1000 {
        y.push(n as f64 / 2_147_483_647.0);
        n = (16_807 * n) % 2_147_483_647;
    }
    y
}

/// The same series as make_allan_vectors.py builds.
fn wrw_series(n: usize) -> Vec<f64> {
    let mut x: u64 = 1_234_567_890;
    let mut next = || {
        let v = x as f64 / 2_147_483_647.0;
        x = (16_807 * x) % 2_147_483_647;
        v
    };
    let mut rw = 0.0;
    (0..n)
        .map(|_| {
            let u = next();
            let v = next();
            rw += v - 0.5;
            (u - 0.5) + 0.01 * rw
        })
        .collect()
}

fn rel(a: f64, b: f64) -> f64 {
    ((a - b) / b).abs()
}

#[test]
fn nbs14_matches_sp1065_to_7_digits() {
    // SP 1065 Table 31 (1000-point NBS14), τ = 1, 10, 100.
    const ADEV: [f64; 3] = [2.922319e-01, 9.965736e-02, 3.897804e-02];
    const OADEV: [f64; 3] = [2.922319e-01, 9.159953e-02, 3.241343e-02];
    let y = nbs14_1000();
    let mut phase = vec![0.0; y.len() + 1];
    fill_phase(&y, &mut phase).unwrap();
    for (i, m) in [1, 10, 100].into_iter().enumerate() {
        let a = avar_phase(&phase, 1.0, m).unwrap().adev();
        let o = oavar_phase(&phase, 1.0, m).unwrap().adev();
        assert_eq!(format!("{a:.6e}"), format!("{:.6e}", ADEV[i]), "ADEV m={m}");
        assert_eq!(
            format!("{o:.6e}"),
            format!("{:.6e}", OADEV[i]),
            "OADEV m={m}"
        );
    }
}

#[test]
fn oadev_matches_allantools() {
    let y = wrw_series(10_000);
    let mut phase = vec![0.0; y.len() + 1];
    for &(m, dev, terms) in vectors::OADEV_WRW {
        let p = oavar(&y, 1.0, m, &mut phase).unwrap();
        assert_eq!(p.terms, terms, "m={m}");
        assert!(rel(p.adev(), dev) < 1e-11, "m={m}: {} vs {dev}", p.adev());
    }
    let ms: Vec<usize> = octave_ms(y.len()).collect();
    assert_eq!(ms.len(), vectors::OADEV_WRW.len());
}

#[test]
fn edf_and_intervals_match_allantools() {
    for &(alpha, n_phase, m, want) in vectors::EDF {
        let noise = match alpha {
            2 => NoiseType::WhitePm,
            1 => NoiseType::FlickerPm,
            0 => NoiseType::WhiteFm,
            -1 => NoiseType::FlickerFm,
            _ => NoiseType::RandomWalkFm,
        };
        let got = edf(noise, n_phase, m).unwrap();
        assert!(
            rel(got, want) < 1e-12,
            "alpha={alpha} m={m}: {got} vs {want}"
        );
    }
    for &(dev, e, ci, lo, hi) in vectors::CI {
        let p = 0.5 * (1.0 - ci);
        let l = dev * (e / chi2_quantile(1.0 - p, e).unwrap()).sqrt();
        let h = dev * (e / chi2_quantile(p, e).unwrap()).sqrt();
        assert!(
            rel(l, lo) < 1e-9 && rel(h, hi) < 1e-9,
            "{l} {h} vs {lo} {hi}"
        );
    }
}

#[test]
fn interval_brackets_the_estimate() {
    let y = wrw_series(4000);
    let mut phase = vec![0.0; y.len() + 1];
    let p = oavar(&y, 1.0, 4, &mut phase).unwrap();
    let (lo, hi) = p.interval(NoiseType::WhiteFm, 0.683).unwrap();
    assert!(lo < p.adev() && p.adev() < hi);
    // EDF ≈ 1.5·N/m for white FM: the 1σ half-width is ≈ 1/√(2·edf).
    let half = 0.5 * (hi - lo) / p.adev();
    let e = edf(NoiseType::WhiteFm, 4001, 4).unwrap();
    assert!((half - (0.5 / e).sqrt()).abs() < 0.1 * half, "{half}");
}

#[test]
fn bad_input_is_typed() {
    let mut phase = [0.0; 8];
    assert_eq!(
        oavar(&[1.0; 7], 1.0, 0, &mut phase),
        Err(AllanError::BadTau)
    );
    assert_eq!(
        oavar(&[1.0; 7], 1.0, 4, &mut phase),
        Err(AllanError::TooShort)
    );
    assert_eq!(
        oavar(&[1.0; 8], 1.0, 1, &mut phase),
        Err(AllanError::Scratch)
    );
    assert_eq!(
        oavar(&[1.0, f64::NAN, 1.0], 1.0, 1, &mut phase),
        Err(AllanError::NonFinite)
    );
    assert_eq!(
        oavar(&[1.0; 7], -1.0, 1, &mut phase),
        Err(AllanError::BadTau)
    );
    assert!(StreamAdev::<4, 8>::new().is_err());
    assert!(StreamAdev::<4, 24>::new().is_err());
    let mut s = StreamAdev::<2, 4>::new().unwrap();
    assert_eq!(s.push(SAMPLE_MAX_PLUS), Err(AllanError::SampleRange));
    assert_eq!(s.samples(), 0);
    assert_eq!(s.point(1, 1.0, 1.0), Err(AllanError::TooShort));
    assert_eq!(quantise(f32::NAN, 0.01), Err(AllanError::NonFinite));
    assert_eq!(quantise(1e9, 0.01), Err(AllanError::SampleRange));
    assert_eq!(quantise(-0.016, 0.01), Ok(-2));
}

const SAMPLE_MAX_PLUS: i32 = stream::SAMPLE_MAX + 1;

/// Exact from-scratch recompute with i128 prefix sums.
fn exact_avar(w: &[i32], m: usize) -> f64 {
    let mut s = vec![0i128; w.len() + 1];
    for (i, &x) in w.iter().enumerate() {
        s[i + 1] = s[i] + x as i128;
    }
    let mut acc: u128 = 0;
    let terms = w.len() + 1 - 2 * m;
    for k in 0..terms {
        let d = s[k + 2 * m] - 2 * s[k + m] + s[k];
        acc += (d * d) as u128;
    }
    acc as f64 / (2.0 * (m * m) as f64 * terms as f64)
}

#[test]
fn streaming_equals_exact_recompute_after_1e7_samples() {
    const N: usize = 10_000_000;
    let mut rng = gyro_sim::Rng::new(3);
    let mut s = StreamAdev::<10, 1024>::new().unwrap();
    let mut w = Vec::with_capacity(N);
    // Biased, noisy, with a random walk: the worst case for float sums.
    let mut rw = 0.0f32;
    for _ in 0..N {
        rw += 0.01 * rng.gaussian();
        let x = quantise(95.0 + 0.2 * rng.gaussian() + rw, 1.0 / 1024.0).unwrap();
        s.push(x).unwrap();
        w.push(x);
    }
    let wf: Vec<f64> = w.iter().map(|&x| x as f64 / 1024.0).collect();
    let mut phase = vec![0.0; N + 1];
    fill_phase(&wf, &mut phase).unwrap();
    for j in 0..10 {
        let m = 1 << j;
        let p = s.point(j, 1.0 / 1024.0, 1.0).unwrap();
        let exact = exact_avar(&w, m) / (1024.0 * 1024.0);
        assert_eq!(p.avar, exact, "m={m}: streaming must equal the exact sum");
        let batch = oavar_phase(&phase, 1.0, m).unwrap();
        assert!(rel(p.avar, batch.avar) < 1e-9, "m={m}");
        assert_eq!(p.terms, batch.terms);
    }
}

#[test]
fn noise_terms_recover_arw_and_rrw() {
    // White rate noise σ = 0.1 °/s at 100 Hz gives N = 0.1·√0.01 °/√s
    // = 0.6 °/√h; a rate random walk of 1e-4 °/s per √s is
    // K = 1e-4·3600·60 = 21.6 °/h/√h.
    let mut rng = gyro_sim::Rng::new(9);
    let tau0: f64 = 0.01;
    let n = 2_000_000;
    let mut rw = 0.0f64;
    let y: Vec<f64> = (0..n)
        .map(|_| {
            rw += 1e-4 * tau0.sqrt() * rng.gaussian() as f64;
            0.1 * rng.gaussian() as f64 + rw
        })
        .collect();
    let mut phase = vec![0.0; n + 1];
    fill_phase(&y, &mut phase).unwrap();
    let pts: Vec<AdevPoint> = octave_ms(n)
        .map(|m| oavar_phase(&phase, tau0, m).unwrap())
        .collect();
    let mut t = [None; 5];
    noise_terms(&pts, &mut t);
    let arw = t[1].unwrap();
    assert!(arw.visible && rel(arw.value, 0.6) < 0.05, "{arw:?}");
    // K is read at the long-τ end, from few independent terms: the
    // minimum over noisy points reads low, so only the order is checked.
    let rrw = t[3].unwrap();
    assert!(rel(rrw.value, 21.6) < 0.5, "{rrw:?}");
    assert_eq!(TermKind::AngleRandomWalk.unit(), "deg/sqrt(h)");
    // White noise alone has no visible bias instability floor.
    assert!(t[0].is_some_and(|q| !q.visible));
}

#[test]
fn noise_terms_recover_the_emulated_icm42688() {
    // 4 h at 100 Hz of the chip model: N and B must come back; K is below
    // the bias-instability hump at every reliable τ, so it must be reported
    // as an upper bound that is still above the true value.
    let p = gyro_sim::NoiseParams::ICM42688;
    let mut rng = gyro_sim::Rng::new(2024);
    let mut ax = gyro_sim::noise::AxisNoise::default();
    let n = 4 * 3600 * 100;
    let y: Vec<f64> = (0..n)
        .map(|_| ax.step(&p, &mut rng, 0.0, 0.01) as f64)
        .collect();
    let mut phase = vec![0.0; n + 1];
    let mut pts = [AdevPoint::default(); 40];
    let c = oavar_octave(&y, 0.01, &mut phase, &mut pts).unwrap();
    let mut t = [None; 5];
    noise_terms(&pts[..c], &mut t);
    let (arw, bi, rrw) = (t[1].unwrap(), t[2].unwrap(), t[3].unwrap());
    assert!(
        arw.visible && rel(arw.value, p.arw_deg_rt_h as f64) < 0.03,
        "{arw:?}"
    );
    assert!(
        bi.visible && rel(bi.value, p.bias_instability_deg_h as f64) < 0.1,
        "{bi:?}"
    );
    assert!(
        !rrw.visible && rrw.value > p.rrw_deg_h_rt_h as f64,
        "{rrw:?}"
    );
    // The one-sweep octave curve equals the per-τ one.
    for q in &pts[..c] {
        let single = oavar_phase(&phase, 0.01, q.m as usize).unwrap();
        assert!(rel(q.avar, single.avar) < 1e-12);
    }
}

#[test]
fn streaming_arbitrary_tau_list_matches_batch() {
    let mut rng = gyro_sim::Rng::new(8);
    let ms = [1u32, 3, 10, 100, 333, 1000];
    let mut s = StreamAdev::<6, 2048>::with_ms(ms).unwrap();
    let w: Vec<i32> = (0..50_000)
        .map(|_| (300.0 * rng.gaussian()) as i32 - 7000)
        .collect();
    for &x in &w {
        s.push(x).unwrap();
    }
    let wf: Vec<f64> = w.iter().map(|&x| x as f64).collect();
    let mut phase = vec![0.0; wf.len() + 1];
    fill_phase(&wf, &mut phase).unwrap();
    for (j, &m) in ms.iter().enumerate() {
        let p = s.point(j, 1.0, 1.0).unwrap();
        assert_eq!(p.avar, exact_avar(&w, m as usize), "m={m}");
        let b = oavar_phase(&phase, 1.0, m as usize).unwrap();
        assert!(rel(p.avar, b.avar) < 1e-10, "m={m}");
    }
    assert!(StreamAdev::<2, 1024>::with_ms([3, 1025]).is_err());
    assert!(StreamAdev::<2, 1024>::with_ms([0, 4]).is_err());
    assert!(StreamAdev::<2, 512>::with_ms([3, 300]).is_err());
}

#[test]
fn huge_cluster_sizes_and_stray_indices_are_errors_not_panics() {
    // Reproducers from fuzzing: 2m overflowed for m ≥ 2⁶³, and local_slope
    // indexed past the end.
    let phase = [0.0; 5];
    for m in [1usize << 63, usize::MAX, 3] {
        assert_eq!(oavar_phase(&phase, 1.0, m), Err(AllanError::TooShort));
        assert_eq!(avar_phase(&phase, 1.0, m), Err(AllanError::TooShort));
    }
    assert_eq!(edf(NoiseType::WhiteFm, 5, 1 << 63), None);
    assert_eq!(edf(NoiseType::WhiteFm, 0, 1), None);
    assert_eq!(octave_ms(usize::MAX).count(), usize::BITS as usize - 1);
    let p = oavar_phase(&[0.0, 1.0, 3.0, 2.0, 5.0], 1.0, 1).unwrap();
    assert_eq!(local_slope(&[p, p], 5), None);
    assert_eq!(local_slope(&[p, p], usize::MAX), None);
    assert_eq!(local_slope(&[], 0), None);
}

/// The AVX2 + FMA builds of the OADEV kernel give the plain build's bits
/// (the host tool and `allan-speed` take them where the CPU has both).
#[cfg(target_arch = "x86_64")]
#[test]
#[allow(unsafe_code)]
fn avx2_build_gives_the_same_bits() {
    if !has_avx2_fma() {
        return;
    }
    let mut rng = gyro_sim::Rng::new(5);
    let mut rw = 0.0f64;
    let y: Vec<f64> = (0..20_011)
        .map(|_| {
            rw += 1e-3 * rng.gaussian() as f64;
            95.0 + 0.1 * rng.gaussian() as f64 + rw
        })
        .collect();
    let mut phase = vec![0.0; y.len() + 1];
    fill_phase(&y, &mut phase).unwrap();
    for m in (1..10_000).step_by(37).chain([1, 2, 3, 7, 8, 9, 10_005]) {
        let plain = oavar_phase(&phase, 0.01, m);
        // SAFETY: the CPU has AVX2 and FMA (checked above).
        let fast = unsafe { oavar_phase_avx2(&phase, 0.01, m) };
        assert_eq!(
            plain.map(|p| p.avar.to_bits()),
            fast.map(|p| p.avar.to_bits()),
            "m={m}"
        );
        let (from, to) = (m / 3, phase.len().saturating_sub(2 * m + 5));
        let plain = second_diff_sum(&phase, m, from, to);
        // SAFETY: as above.
        let fast = unsafe { second_diff_sum_avx2(&phase, m, from, to) };
        assert_eq!(plain.to_bits(), fast.to_bits(), "m={m}");
    }
    // The octave sweep: both of its groups of τ (2¹⁴ > 20 011 / 2 holds
    // octaves 0..=13, the near group 0..10).
    let (mut plain, mut fast) = ([AdevPoint::default(); 24], [AdevPoint::default(); 24]);
    let k = oavar_octave_phase(&phase, 0.01, &mut plain);
    // SAFETY: as above.
    assert_eq!(
        unsafe { oavar_octave_phase_avx2(&phase, 0.01, &mut fast) },
        k
    );
    assert!(k > 10);
    for (p, f) in plain.iter().zip(&fast).take(k) {
        assert_eq!(p.avar.to_bits(), f.avar.to_bits(), "m={}", p.m);
    }
    // Out of range: nothing, in both builds.
    assert_eq!(second_diff_sum(&phase, 20_000, 0, 10), 0.0);
    // SAFETY: as above.
    assert_eq!(
        unsafe { second_diff_sum_avx2(&phase, usize::MAX, 0, 10) },
        0.0
    );
}

/// The grouped kernel gives each factor the one-factor kernel's sum bit
/// for bit: random-walk phase, lengths around the lane and block edges,
/// groups of 1 to GROUP factors up to the longest that fits.
#[test]
#[allow(unsafe_code)]
fn grouped_sums_are_the_one_factor_sums() {
    let mut rng = gyro_sim::Rng::new(5);
    for n in [3usize, 17, 40, 513, 1030, 1100, 3001] {
        let mut x = vec![0.0f64; n];
        for i in 1..n {
            x[i] = x[i - 1] + f64::from(rng.gaussian()) * 1e-3;
        }
        let top = (n - 1) / 2;
        for g in 1..=GROUP {
            let mut m0 = 1;
            while m0 + g - 1 <= top {
                let mut sums = [f64::NAN; GROUP];
                second_diff_sums(&x, m0, &mut sums[..g]);
                #[cfg(target_arch = "x86_64")]
                let mut wide = [f64::NAN; GROUP];
                #[cfg(target_arch = "x86_64")]
                if has_avx2_fma() {
                    // SAFETY: the CPU has AVX2 and FMA.
                    unsafe { second_diff_sums_avx2(&x, m0, &mut wide[..g]) };
                    for (w, s) in wide[..g].iter().zip(&sums[..g]) {
                        assert_eq!(w.to_bits(), s.to_bits());
                    }
                }
                for (k, s) in sums[..g].iter().enumerate() {
                    let m = m0 + k;
                    let one = second_diff_sum(&x, m, 0, n - 2 * m);
                    assert_eq!(
                        s.to_bits(),
                        one.to_bits(),
                        "n {n} m {m} group {g} from {m0}"
                    );
                }
                m0 += if m0 < 40 { 1 } else { 37 };
            }
        }
    }
}

/// The kernels' fused multiply-add is libm's on the board and std's on the
/// host: both round a·b + c once, so the sums are the same bits in both.
#[test]
fn libm_fma_is_std_mul_add() {
    let mut rng = gyro_sim::Rng::new(11);
    for _ in 0..100_000 {
        let d = 1e3 * rng.gaussian() as f64 + rng.gaussian() as f64 * 1e-9;
        let acc = 1e6 * f64::from(rng.uniform()) + 1e-7 * rng.gaussian() as f64;
        assert_eq!(libm::fma(d, d, acc).to_bits(), d.mul_add(d, acc).to_bits());
    }
}
