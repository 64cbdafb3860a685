use super::*;
use crate::algo::allan::{fill_phase, oavar_phase};
use crate::emu::Rng;

type D = Davar<1024, 33, 8>;

fn white(seed: u64, n: usize, sigma: impl Fn(usize) -> f32) -> Vec<i32> {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|i| (sigma(i) * 100.0 * rng.gaussian()).round() as i32)
        .collect()
}

/// White noise whose σ doubles over samples 2000..3500 of 6000.
fn step_signal(seed: u64) -> Vec<i32> {
    white(seed, 6000, |i| {
        if (2000..3500).contains(&i) {
            2.0
        } else {
            1.0
        }
    })
}

/// The paper's window limits (400, 800), ΔL = 64, temporal entropy.
fn paper_window(p_fa: f32, placement: Placement) -> DavarConfig {
    DavarConfig {
        lambda1: 400,
        lambda2: 800,
        l_init: 800,
        delta_l: 64,
        step: StepMode::Constant,
        entropy: EntropyKind::Temporal,
        threshold: Threshold::Auto { p_fa },
        placement,
    }
}

/// Independent f64 oracle: batch OADEV over the samples [s, e).
fn batch(w: &[i32], s: usize, e: usize, m: usize) -> f64 {
    let y: Vec<f64> = w[s..e].iter().map(|&x| x as f64).collect();
    let mut phase = vec![0.0; y.len() + 1];
    fill_phase(&y, &mut phase).unwrap();
    oavar_phase(&phase, 1.0, m).unwrap().avar
}

fn check_against_batch(cfg: DavarConfig, w: &[i32], every: usize) -> usize {
    let mut d = D::new(cfg).unwrap();
    let mut checked = 0;
    for (i, &x) in w.iter().enumerate() {
        let Some(t) = d.push(x).unwrap() else {
            continue;
        };
        if i % every != 0 {
            continue;
        }
        let st = d.estimate();
        assert_eq!(st.t, t);
        let (s, e) = d.edges(t);
        let (s, e) = (s as usize, e as usize);
        assert_eq!(e - s, st.len as usize);
        for j in 0..8 {
            let want = batch(w, s, e, 1 << j);
            let got = st.avar[j] as f64;
            assert!(
                ((got - want) / want).abs() < 1e-6,
                "t={t} L={} m={}: {got} vs {want}",
                st.len,
                1 << j
            );
        }
        checked += 1;
    }
    checked
}

#[test]
fn fixed_window_equals_batch_oadev() {
    let w = white(1, 3000, |_| 1.0);
    assert!(check_against_batch(DavarConfig::fixed(400), &w, 97) > 20);
}

#[test]
fn adaptive_window_stays_exact_while_it_moves() {
    // A variance step makes the window shrink and grow; every estimate must
    // still equal the batch OADEV over exactly its window.
    let w = step_signal(2);
    let cfg = paper_window(0.05, Placement::Centred);
    assert!(check_against_batch(cfg, &w, 61) > 50);
    // ...and it did move.
    let mut d = D::new(cfg).unwrap();
    let (mut lo, mut hi) = (u16::MAX, 0);
    for &x in &w {
        if d.push(x).unwrap().is_some() {
            lo = lo.min(d.len());
            hi = hi.max(d.len());
        }
    }
    assert!(lo == 400 && hi == 800, "{lo}..{hi}");
}

#[test]
fn auto_threshold_false_alarm_rate() {
    // Stationary white noise: the temporal score exceeds D0 at about p_fa
    // of the hops (the χ² approximation is second order; allow 0.4–2.5×).
    for p_fa in [0.05f32, 0.2] {
        let cfg = DavarConfig {
            lambda1: 512,
            lambda2: 512,
            l_init: 512,
            delta_l: 2,
            step: StepMode::Constant,
            entropy: EntropyKind::Temporal,
            threshold: Threshold::Auto { p_fa },
            placement: Placement::Centred,
        };
        let mut d = D::new(cfg).unwrap();
        let (th, mut hits, mut hops) = (d.calibrate(512), 0, 0);
        let w = white(3, 200_000, |_| 1.0);
        for (i, &x) in w.iter().enumerate() {
            if let Some(t) = d.push(x).unwrap() {
                // Fixed windows do not adapt; score the window directly.
                if t % (SEG as u64 * 16) == 0 && i > 0 {
                    d.cfg.lambda1 = 510;
                    d.adapt(t);
                    d.cfg.lambda1 = 512;
                    d.len = 512;
                    hits += (d.entropy > th) as u32;
                    hops += 1;
                }
            }
        }
        let rate = hits as f32 / hops as f32;
        assert!(
            rate > 0.4 * p_fa && rate < 2.5 * p_fa,
            "p_fa={p_fa}: measured {rate} over {hops} hops"
        );
    }
}

#[test]
fn bad_settings_are_typed() {
    let ok = DavarConfig {
        lambda1: 400,
        lambda2: 800,
        l_init: 800,
        delta_l: 32,
        step: StepMode::Constant,
        entropy: EntropyKind::Spectral,
        threshold: Threshold::Fixed(0.2),
        placement: Placement::Centred,
    };
    assert!(D::new(ok).is_ok());
    let bad = |f: fn(&mut DavarConfig)| {
        let mut c = ok;
        f(&mut c);
        D::new(c).err()
    };
    assert_eq!(bad(|c| c.lambda1 = 900), Some(DavarError::Lambda));
    assert_eq!(bad(|c| c.l_init = 100), Some(DavarError::Lambda));
    assert_eq!(
        bad(|c| {
            c.lambda2 = 2048;
            c.l_init = 2048
        }),
        Some(DavarError::Capacity)
    );
    assert_eq!(bad(|c| c.lambda1 = 200), Some(DavarError::Capacity));
    assert_eq!(bad(|c| c.delta_l = 0), Some(DavarError::DeltaL));
    assert_eq!(
        bad(|c| c.threshold = Threshold::Fixed(f32::NAN)),
        Some(DavarError::Threshold)
    );
    assert_eq!(
        bad(|c| c.threshold = Threshold::Auto { p_fa: 1.0 }),
        Some(DavarError::Threshold)
    );
    let mut d = D::new(ok).unwrap();
    assert_eq!(d.push(1 << 21), Err(AllanError::SampleRange));
    assert_eq!(d.push(0), Ok(None));
}

#[test]
fn change_aware_window_is_exact_and_avoids_the_change() {
    let w = step_signal(4);
    let cfg = paper_window(0.01, Placement::ChangeAware);
    assert!(check_against_batch(cfg, &w, 53) > 50);
    // Windows must not reach more than 64 samples (two frames of location
    // error) across a change on both sides; count the exceptions.
    let mut d = D::new(cfg).unwrap();
    let (mut bad, mut total) = (0, 0);
    for &x in &w {
        if let Some(t) = d.push(x).unwrap() {
            let (s, e) = d.edges(t);
            for c in [2000u64, 3500] {
                if t.abs_diff(c) < 400 {
                    total += 1;
                    bad += (s + 64 < c && c + 64 < e) as u32;
                }
            }
        }
    }
    assert!(
        bad * 20 < total,
        "{bad} of {total} windows straddle a change"
    );
    let mut c = cfg;
    c.lambda1 = 500;
    assert_eq!(D::new(c).err(), Some(DavarError::Lambda));
}

#[test]
fn ring_of_exactly_lambda2_stays_exact() {
    let mut rng = Rng::new(5);
    let w: Vec<i32> = (0..3000)
        .map(|i| {
            let sine = if i >= 2000 {
                10240.0 * (2.0 * core::f32::consts::PI * 0.5 * (i - 2000) as f32 / 1000.0).sin()
            } else {
                0.0
            };
            (5120.0 + sine + 23.0 * rng.gaussian()).round() as i32
        })
        .collect();
    let cfg = DavarConfig {
        lambda1: 256,
        lambda2: 512,
        l_init: 512,
        delta_l: 32,
        step: StepMode::Constant,
        entropy: EntropyKind::Temporal,
        threshold: Threshold::Auto { p_fa: 0.01 },
        placement: Placement::ChangeAware,
    };
    let mut d = Davar::<512, 17, 7>::new(cfg).unwrap();
    for (i, &x) in w.iter().enumerate() {
        if let Some(t) = d.push(x).unwrap() {
            if i % 37 == 0 {
                let st = d.estimate();
                let (s, e) = d.edges(t);
                let want = batch(&w, s as usize, e as usize, 1);
                let got = st.avar[0] as f64;
                assert!(
                    ((got - want) / want).abs() < 1e-5,
                    "i={i} t={t} {got} vs {want}"
                );
            }
        }
    }
}
