//! Robustness and property tests of the fusion stage.
use super::adaptive::{adaptive_active, HUBER_C2, HUBER_KAPPA};
use super::frozen::frozen_check;
use super::gate::consensus_gate;
use super::*;
use gyro_sim::Rng;

/// Every method in the reading we ship (supports clamped at 0).
fn all_methods() -> [Method; 7] {
    let full = SupportConfig {
        denominator: Denominator::MSquaredMinus1,
        clamp_negative: true,
        grubbs: Some(GrubbsConfig::default()),
        memory: Some(MemoryConfig::default()),
        normaliser: Normaliser::Instant,
    };
    [
        Method::Mean,
        Method::Zhang,
        Method::SupportDegree(SupportConfig {
            clamp_negative: true,
            ..SupportConfig::SUPPORT
        }),
        Method::SupportDegree(SupportConfig {
            clamp_negative: true,
            grubbs: Some(GrubbsConfig::default()),
            ..SupportConfig::SUPPORT
        }),
        Method::SupportDegree(full),
        Method::SupportDegree(SupportConfig {
            clamp_negative: true,
            grubbs: Some(GrubbsConfig::default()),
            normaliser: Normaliser::Running {
                k: 11.0,
                alpha: 1.0 / 64.0,
            },
            ..SupportConfig::SUPPORT
        }),
        Method::Adaptive(AdaptiveConfig::default()),
    ]
}

#[test]
fn bad_inputs_never_panic_and_are_rejected() {
    for m in all_methods() {
        let f = Fusion::<4>::new(m).unwrap();
        let mut st = AxisState::default();
        let y = [1.0, f32::NAN, f32::INFINITY, 1.5];
        let r = f.fuse(&mut st, &y, 0b1111).unwrap();
        assert_eq!(r.rejected & 0b0110, 0b0110, "{m:?}");
        assert!(
            r.rate_dps >= 1.0 && r.rate_dps <= 1.5,
            "{m:?}: {}",
            r.rate_dps
        );
        assert_eq!(r.weights[1], 0.0);
        let none = f.fuse(&mut st, &[f32::NAN; 4], 0b1111);
        assert_eq!(none, Err(FuseError::NoValidInput));
        assert_eq!(f.fuse(&mut st, &[1.0; 4], 0), Err(FuseError::NoValidInput));
        // Huge finite values are no rates, and their sums must not overflow
        // to ±inf.
        let huge = f.fuse(&mut st, &[3e38, 3e38, -3e38, 2.0], 0b1111).unwrap();
        assert_eq!(huge.rate_dps, 2.0, "{m:?}");
        assert_eq!(huge.rejected & 0b0111, 0b0111);
        assert_eq!(
            f.fuse(&mut st, &[3e38, 3e38, -3e38, 3e38], 0b1111),
            Err(FuseError::NoValidInput)
        );
    }
}

#[test]
fn all_equal_inputs_give_that_value() {
    // The seed's normaliser is 0/0 here; we define d* = 0.
    for m in all_methods() {
        let f = Fusion::<4>::new(m).unwrap();
        let mut st = AxisState::default();
        for _ in 0..50 {
            let r = f.fuse(&mut st, &[-5.0; 4], 0b1111).unwrap();
            assert_eq!(r.rate_dps, -5.0, "{m:?}");
            let ws: f32 = r.weights.iter().sum();
            assert!((ws - 1.0).abs() < 1e-5, "{m:?}: weights {:?}", r.weights);
        }
    }
}

#[test]
fn one_and_two_gyros_are_defined() {
    for m in all_methods() {
        let f1 = Fusion::<1>::new(m).unwrap();
        let mut s1 = AxisState::default();
        assert_eq!(f1.fuse(&mut s1, &[2.5], 1).unwrap().rate_dps, 2.5);
        let f2 = Fusion::<2>::new(m).unwrap();
        let mut s2 = AxisState::default();
        let r = f2.fuse(&mut s2, &[1.0, 3.0], 0b11).unwrap();
        // Grubbs is undefined for two values, so nothing can be rejected and
        // both gyros are symmetric: the fused value is their mean.
        assert!((r.rate_dps - 2.0).abs() < 1e-6, "{m:?}: {}", r.rate_dps);
    }
}

#[test]
fn zero_weight_sum_falls_back_to_mean() {
    // Zhang's supports underflow to 0 for gyros 20 °/s apart.
    let f = Fusion::<3>::new(Method::Zhang).unwrap();
    let mut st = AxisState::default();
    let r = f.fuse(&mut st, &[0.0, 20.0, 40.0], 0b111).unwrap();
    assert!(r.fallback);
    assert_eq!(r.rate_dps, 20.0);
    // The literal seed method: three values with negative total support.
    let f = Fusion::<3>::new(Method::SupportDegree(SupportConfig {
        clamp_negative: true,
        ..SupportConfig::SUPPORT
    }))
    .unwrap();
    let r = f.fuse(&mut st, &[0.0, 0.0, 100.0], 0b111).unwrap();
    assert!(r.rate_dps.abs() < 1e-6, "{}", r.rate_dps);
}

#[test]
fn all_disagreeing_gyros_still_give_a_bounded_answer() {
    for m in all_methods() {
        let f = Fusion::<4>::new(m).unwrap();
        let mut st = AxisState::default();
        let mut rng = Rng::new(3);
        for k in 0..200 {
            let y = if k < 100 {
                [
                    rng.gaussian() * 0.1,
                    rng.gaussian() * 0.1,
                    rng.gaussian() * 0.1,
                    rng.gaussian() * 0.1,
                ]
            } else {
                [-100.0, -10.0, 10.0, 100.0]
            };
            let r = f.fuse(&mut st, &y, 0b1111).unwrap();
            let lo = y.iter().cloned().fold(f32::INFINITY, f32::min);
            let hi = y.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
            assert!(r.rate_dps >= lo && r.rate_dps <= hi, "{m:?}");
        }
    }
}

/// The literal eq. 5 gives negative supports to a far outlier, whose weight
/// then pushes the fused value away from it, outside the inputs' range. This
/// is why the shipped reading clamps supports at 0.
#[test]
fn literal_seed_weights_can_leave_the_input_range() {
    let f = Fusion::<4>::new(Method::SupportDegree(SupportConfig::SUPPORT)).unwrap();
    let mut st = AxisState::default();
    let r = f.fuse(&mut st, &[0.0, 0.01, -0.01, 10.0], 0b1111).unwrap();
    assert!(r.weights[3] < 0.0, "{:?}", r.weights);
    assert!(r.rate_dps < -0.01, "{}", r.rate_dps);
    let f = Fusion::<4>::new(Method::SupportDegree(SupportConfig {
        clamp_negative: true,
        ..SupportConfig::SUPPORT
    }))
    .unwrap();
    let r = f.fuse(&mut st, &[0.0, 0.01, -0.01, 10.0], 0b1111).unwrap();
    assert_eq!(r.weights[3], 0.0);
    assert!(r.rate_dps.abs() <= 0.01);
}

#[test]
fn bad_configurations_are_typed_errors() {
    let g = |alpha| {
        Method::SupportDegree(SupportConfig {
            grubbs: Some(GrubbsConfig {
                alpha,
                ..Default::default()
            }),
            ..SupportConfig::SUPPORT
        })
    };
    assert_eq!(Fusion::<4>::new(g(0.0)).err(), Some(ConfigError::Alpha));
    assert_eq!(
        Fusion::<4>::new(g(f32::NAN)).err(),
        Some(ConfigError::Alpha)
    );
    let mem = |len| {
        Method::SupportDegree(SupportConfig {
            memory: Some(MemoryConfig {
                len,
                ..Default::default()
            }),
            ..SupportConfig::SUPPORT
        })
    };
    assert_eq!(Fusion::<4>::new(mem(0)).err(), Some(ConfigError::MemoryLen));
    assert_eq!(
        Fusion::<4>::new(mem(17)).err(),
        Some(ConfigError::MemoryLen)
    );
    assert_eq!(
        Fusion::<9>::new(Method::Mean).err(),
        Some(ConfigError::ArraySize)
    );
    let ad = Method::Adaptive(AdaptiveConfig {
        alpha: 1.5,
        ..Default::default()
    });
    assert_eq!(Fusion::<4>::new(ad).err(), Some(ConfigError::Parameter));
}

#[test]
fn grubbs_table_covers_every_array_size() {
    let f = Fusion::<8>::new(Method::SupportDegree(SupportConfig {
        grubbs: Some(GrubbsConfig::default()),
        ..SupportConfig::SUPPORT
    }))
    .unwrap();
    assert_eq!(f.grubbs_critical(2), 0.0);
    for n in 3..=8 {
        assert!(
            f.grubbs_critical(n) > 1.0
                && f.grubbs_critical(n) < (n as f32 - 1.0) / (n as f32).sqrt() + 1e-6
        );
    }
    assert!((f.grubbs_critical(4) - 1.4812).abs() < 1e-4);
}

/// Property: the fused value lies within the range of the accepted inputs,
/// is invariant under permutation of the gyros, and constant input gives the
/// constant back. 2000 random cases per method, with outliers.
#[test]
fn properties_range_permutation_constant() {
    let mut rng = Rng::new(11);
    for m in all_methods() {
        let f = Fusion::<5>::new(m).unwrap();
        for case in 0..2000 {
            let mut y = [0.0f32; 5];
            let base = (rng.uniform() - 0.5) * 200.0;
            for v in y.iter_mut() {
                *v = base + rng.gaussian() * (0.01 + rng.uniform());
                if rng.uniform() < 0.1 {
                    *v += (rng.uniform() - 0.5) * 1000.0;
                }
            }
            // A stateless first sample, so permuted runs see the same history.
            let mut st = AxisState::default();
            let r = f.fuse(&mut st, &y, 0b11111).unwrap();
            let acc: Vec<f32> = (0..5)
                .filter(|i| r.weights[*i] > 0.0)
                .map(|i| y[i])
                .collect();
            let lo = acc.iter().cloned().fold(f32::INFINITY, f32::min);
            let hi = acc.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
            let tol = 1e-5 * hi.abs().max(lo.abs()).max(1.0);
            assert!(
                r.rate_dps >= lo - tol && r.rate_dps <= hi + tol,
                "{m:?} case {case}: {} not in [{lo}, {hi}]",
                r.rate_dps
            );
            // Permutation: rotate and reverse.
            let mut p = y;
            p.rotate_left(case % 5);
            p.reverse();
            let mut st2 = AxisState::default();
            let rp = f.fuse(&mut st2, &p, 0b11111).unwrap();
            assert!(
                (rp.rate_dps - r.rate_dps).abs() <= 1e-4 * r.rate_dps.abs().max(1.0),
                "{m:?} case {case}: {} vs {}",
                rp.rate_dps,
                r.rate_dps
            );
            // Constant input.
            let mut st3 = AxisState::default();
            assert_eq!(
                f.fuse(&mut st3, &[base; 5], 0b11111).unwrap().rate_dps,
                base,
                "{m:?}"
            );
        }
    }
}

#[test]
fn adaptive_learns_noise_and_rejects_outliers_and_frozen_outputs() {
    let f = Fusion::<4>::new(Method::Adaptive(AdaptiveConfig::default())).unwrap();
    let mut st = AxisState::default();
    let mut rng = Rng::new(5);
    let sig = [0.1f32, 0.1, 0.1, 0.5];
    // The estimate is unbiased: its time average is within 5 %, and any
    // single reading within 40 % (EWMA over 64 samples).
    let mut acc = [0.0f64; 4];
    for k in 0..20_000 {
        let y = [0, 1, 2, 3].map(|i| sig[i] * rng.gaussian());
        f.fuse(&mut st, &y, 0b1111).unwrap();
        let s = st.sigma_dps(&AdaptiveConfig::default());
        if k >= 1000 {
            for i in 0..4 {
                acc[i] += (s[i] * s[i]) as f64 / 19_000.0;
                assert!(
                    (s[i] / sig[i] - 1.0).abs() < 0.4,
                    "sigma {i} at {k}: {} vs {}",
                    s[i],
                    sig[i]
                );
            }
        }
    }
    for i in 0..4 {
        let s = acc[i].sqrt() as f32;
        assert!(
            (s / sig[i] - 1.0).abs() < 0.05,
            "mean sigma {i}: {s} vs {}",
            sig[i]
        );
    }
    // A spike is gated.
    let r = f.fuse(&mut st, &[0.0, 0.05, -0.05, 30.0], 0b1111).unwrap();
    assert_eq!(r.rejected, 0b1000);
    // A frozen gyro is excluded after 4 identical samples.
    let mut rejected_at = None;
    for k in 0..10 {
        let y = [
            0.1 * rng.gaussian(),
            0.1 * rng.gaussian(),
            0.1 * rng.gaussian(),
            0.02,
        ];
        let r = f.fuse(&mut st, &y, 0b1111).unwrap();
        if r.rejected & 0b1000 != 0 && rejected_at.is_none() {
            rejected_at = Some(k);
        }
    }
    assert_eq!(rejected_at, Some(3));
}

#[test]
fn running_normaliser_settings_are_checked() {
    let m = |k, alpha| {
        Method::SupportDegree(SupportConfig {
            normaliser: Normaliser::Running { k, alpha },
            ..SupportConfig::SUPPORT
        })
    };
    assert!(Fusion::<4>::new(m(11.0, 0.01)).is_ok());
    for (k, a) in [(0.0, 0.01), (f32::NAN, 0.01), (11.0, 0.0), (11.0, 1.0)] {
        assert_eq!(
            Fusion::<4>::new(m(k, a)).err(),
            Some(ConfigError::Parameter),
            "{k} {a}"
        );
    }
}

/// A stuck chip among N = 2…8 quantised healthy chips (131 LSB/°/s,
/// σ = 0.09 °/s: a healthy chip repeats its value on about 2.4 % of samples)
/// is out of adaptive fusion within 5 samples of sticking and never back
/// while stuck, over 20 000 samples.
fn stuck_stays_out<const N: usize>() -> (Option<usize>, usize) {
    let f = Fusion::<N>::new(Method::Adaptive(AdaptiveConfig::default())).unwrap();
    let mut st = AxisState::<N>::default();
    let mut rng = Rng::new(N as u64);
    let q = |v: f32| (v * 131.0).round() / 131.0;
    let (start, n) = (200, 20_000);
    let mut stuck = 0.0;
    let (mut out_at, mut readmitted) = (None, 0);
    for k in 0..n {
        let mut y = [0.0f32; N];
        for v in y.iter_mut() {
            *v = q(3.0 + 0.09 * rng.gaussian());
        }
        if k == start {
            stuck = y[0];
        }
        if k >= start {
            y[0] = stuck;
        }
        let r = f.fuse(&mut st, &y, ((1u16 << N) - 1) as u8).unwrap();
        if k >= start {
            let used = r.weights[0] > 0.0;
            match (used, out_at) {
                (false, None) => out_at = Some(k - start),
                (true, Some(_)) => readmitted += 1,
                _ => {}
            }
        }
    }
    (out_at, readmitted)
}

#[test]
fn a_stuck_chip_is_out_within_5_samples_and_stays_out_for_n_2_to_8() {
    let r = [
        stuck_stays_out::<2>(),
        stuck_stays_out::<3>(),
        stuck_stays_out::<4>(),
        stuck_stays_out::<5>(),
        stuck_stays_out::<6>(),
        stuck_stays_out::<7>(),
        stuck_stays_out::<8>(),
    ];
    for (i, (out_at, readmitted)) in r.iter().enumerate() {
        assert!(out_at.is_some_and(|k| k <= 5), "N = {}: {r:?}", i + 2);
        assert_eq!(*readmitted, 0, "N = {}: {r:?}", i + 2);
    }
}

/// The fault campaign's last failure mode (seed 8856 of 10 000): four
/// gyros active, one faulty chip moved 1 °/s by a bit error lands beside a
/// noisy but honest one (an ADXRS453, σ five times the others), so the
/// median of four falls between two pairs and the first gate keeps the
/// wrong pair. The consensus gate keeps the quiet majority instead.
#[test]
fn two_chips_agreeing_by_chance_do_not_outvote_the_quiet_majority() {
    let f = Fusion::<4>::new(Method::Adaptive(AdaptiveConfig::default())).unwrap();
    let mut st = AxisState::default();
    let mut rng = Rng::new(11);
    // Chips 0, 1, 2 alike; chip 3 the noisy ADXRS453-like part.
    let sig = [0.05f32, 0.05, 0.05, 0.5];
    for _ in 0..5000 {
        let y = [0, 1, 2, 3].map(|i| 3.0 + sig[i] * rng.gaussian());
        f.fuse(&mut st, &y, 0b1111).unwrap();
    }
    // Chip 2 garbled to 1.99; chip 3's noise puts it at 1.97: the middle
    // two are chips 2 and 1, the median lands half-way and every quiet
    // chip is off it; dropping the most outlying (chip 0) and gating again
    // about the new median (chip 2) keeps chips 2 and 3.
    let r = f.fuse(&mut st, &[3.03, 3.0, 1.99, 1.97], 0b1111).unwrap();
    assert!((r.rate_dps - 3.0).abs() < 0.1, "{r:?}");
    assert_eq!(r.rejected & 0b0011, 0, "{r:?}");
    assert_ne!(r.rejected & 0b0100, 0, "{r:?}");
}

/// The consensus gate as written before it shared each pair's square:
/// gate every active gyro about each active gyro's value in turn; most
/// gyros wins, then the least weighted spread about the set's weighted
/// mean.
fn consensus_by_reference<const N: usize>(
    y: &[f32; N],
    v: &[f32; N],
    active: u8,
    first: u8,
    k2: f32,
    v_med: f32,
) -> (u8, bool) {
    let spread = |set: u8| {
        let members: Vec<usize> = (0..N).filter(|&i| has(set, i)).collect();
        let sw: f32 = members.iter().map(|&i| 1.0 / v[i]).sum();
        let swy: f32 = members.iter().map(|&i| 1.0 / v[i] * y[i]).sum();
        let mean = swy / sw;
        members
            .iter()
            .map(|&i| 1.0 / v[i] * (y[i] - mean) * (y[i] - mean))
            .sum::<f32>()
    };
    let (mut best, mut best_n, mut best_s) = (first, first.count_ones(), spread(first));
    for j in (0..N).filter(|&j| has(active, j)) {
        let set = (0..N)
            .filter(|&i| has(active, i) && (y[i] - y[j]).powi(2) <= k2 * (v[i] + v_med))
            .fold(0u8, |s, i| s | 1 << i);
        let (n, s) = (set.count_ones(), spread(set));
        if n >= 2 && (n > best_n || (n == best_n && s < best_s)) {
            (best, best_n, best_s) = (set, n, s);
        }
    }
    (best, 2 * best_n <= active.count_ones())
}

/// The fault campaign's case at seed 777972: five gyros, two quiet chips
/// corrupted to a wrong range (read far off and agreeing by chance), the
/// noisy ADXRS453 near the quiet pair but within the wide gate of both.
/// Both sets count three; the one that fits its members keeps the quiet
/// pair.
#[test]
fn a_noisy_chip_between_two_pairs_sides_with_the_one_it_is_near() {
    let y = [-0.22f32, -2.09, -0.30, -2.15, -0.175];
    // The corrupted chips' noise model still says quiet (frozen while
    // they were gated out), so their total weight is the larger.
    let v = [0.0025f32, 0.0020, 0.0025, 0.0020, 0.25];
    let w = v.map(|v| 1.0 / v);
    let (set, split) = consensus_gate(&y, &v, &w, 0b11111, 0b10101, 16.0, 0.002);
    assert_eq!((set, split), (0b10101, false));
}

proptest::proptest! {
    /// The shipped consensus gate (each pair's square once, weights only
    /// for a tie) picks the same set as gating about each gyro in turn,
    /// on values clustered so that every kind of split occurs.
    #[test]
    fn consensus_gate_picks_what_gating_about_each_gyro_picks(
        y in proptest::array::uniform5(proptest::prop_oneof![-2.0f32..2.0, 9.0f32..10.0, 0.0f32..0.3]),
        v in proptest::array::uniform5(0.001f32..1.0),
        active in 0u8..32,
        first in 0u8..32,
        v_med in 0.0f32..0.5,
    ) {
        let first = first & active;
        let k2 = 9.0;
        let w = core::array::from_fn(|i| if has(active, i) { 1.0 / v[i] } else { 0.0 });
        proptest::prop_assert_eq!(
            consensus_gate(&y, &v, &w, active, first, k2, v_med),
            consensus_by_reference(&y, &v, active, first, k2, v_med)
        );
    }
}

/// κ makes the capped squared residual an unbiased variance estimate for
/// Gaussian noise: E[κ·min(z², c²)] = 1, by Monte Carlo (10⁶ draws).
#[test]
fn huber_kappa_is_the_gaussian_consistency_factor() {
    let mut rng = Rng::new(3);
    let mut acc = 0.0f64;
    let n = 1_000_000;
    for _ in 0..n {
        let z = rng.gaussian() as f64;
        acc += (z * z).min(HUBER_C2 as f64);
    }
    let e = acc / n as f64;
    assert!((e * HUBER_KAPPA as f64 - 1.0).abs() < 0.005, "E = {e}");
}

/// A chip spiking ±200 °/s in 5 % of its samples, from power-up, beside
/// three quiet ones: its noise estimate stays bounded, so the spikes stay
/// outside the gate and the fused rate never moves by more than 0.3 °/s.
/// (With the cap at the gate the estimate grew until the spikes fitted
/// inside it.)
#[test]
fn a_chip_spiking_at_5_percent_never_widens_its_own_gate() {
    let f = Fusion::<4>::new(Method::Adaptive(AdaptiveConfig::default())).unwrap();
    let mut st = AxisState::default();
    let mut rng = Rng::new(17);
    let mut worst = 0.0f32;
    for k in 0..20_000 {
        let mut y = [0usize, 1, 2, 3].map(|_| 0.1 * rng.gaussian());
        if rng.uniform() < 0.05 {
            y[3] += if rng.uniform() < 0.5 { 200.0 } else { -200.0 };
        }
        let r = f.fuse(&mut st, &y, 0b1111).unwrap();
        if k > 100 {
            worst = worst.max(r.rate_dps.abs());
        }
    }
    let s = st.sigma_dps(&AdaptiveConfig::default());
    assert!(worst < 0.3, "worst fused {worst}, sigma {s:?}");
    assert!(s[3] < 5.0, "sigma of the spiking chip {}", s[3]);
}

/// A chip spiking ±20 °/s on 2 % of its samples keeps its noise estimate:
/// the gate leaves the spikes out, and what the gate leaves out does not
/// teach the estimate. Its clean samples keep a quarter of the weight
/// (no less than 3 % under it, and the pairs' slow means read within
/// 5 % over it, 0.259 measured; with the spikes Huber-capped into the
/// estimate it was 0.226), and its σ estimate stays within 10 % of the
/// others'.
#[test]
fn gated_spikes_do_not_inflate_the_noise_estimate() {
    let f = Fusion::<4>::new(Method::Adaptive(AdaptiveConfig::default())).unwrap();
    let mut st = AxisState::default();
    let mut rng = Rng::new(23);
    let (mut w, mut n) = (0.0f64, 0.0f64);
    for k in 0..20_000 {
        let mut y = [0usize, 1, 2, 3].map(|_| 0.09 * rng.gaussian());
        let spike = rng.uniform() < 0.02;
        if spike {
            y[1] += if rng.uniform() < 0.5 { 20.0 } else { -20.0 };
        }
        let r = f.fuse(&mut st, &y, 0b1111).unwrap();
        if k > 1000 && !spike {
            w += f64::from(r.weights[1]);
            n += 1.0;
        }
    }
    let w = w / n;
    assert!(
        (-0.03..0.05).contains(&(w / 0.25 - 1.0)),
        "clean weight of the spiking chip {w}"
    );
    let s = st.sigma_dps(&AdaptiveConfig::default());
    let others = (s[0] + s[2] + s[3]) / 3.0;
    assert!((s[1] / others - 1.0).abs() < 0.1, "{s:?}");
}

/// Two chips with priors: what the priors explain is split in their
/// proportion, the excess equally. At rest (no excess) a 5× noisier chip
/// gets about 1/26 of the weight; on a 30 °/s, 1 Hz sway with scale errors
/// of +1 % and −1 % (an excess the priors cannot explain, and cannot pin on
/// either chip) the split moves towards equal, near the optimum for those
/// errors, and the fused error is no worse than the mean's.
#[test]
fn a_pair_splits_the_unexplained_disagreement_equally() {
    let run = |moving: bool| {
        let f = Fusion::<2>::new(Method::Adaptive(AdaptiveConfig::default())).unwrap();
        let mut st = AxisState::<2>::default();
        st.set_noise_priors([Some(0.09), Some(0.45)]);
        let mut rng = Rng::new(5);
        let (mut w1, mut se, mut se_mean) = (0.0f64, 0.0f64, 0.0f64);
        for k in 0..20_000 {
            let t = if moving {
                30.0 * libm::sinf(2.0 * core::f32::consts::PI * k as f32 * 1e-3)
            } else {
                0.0
            };
            let y = [
                1.01 * t + 0.09 * rng.gaussian(),
                0.99 * t + 0.45 * rng.gaussian(),
            ];
            let r = f.fuse(&mut st, &y, 0b11).unwrap();
            if k >= 5000 {
                w1 += f64::from(r.weights[1]);
                se += f64::from(r.rate_dps - t).powi(2);
                se_mean += f64::from(0.5 * (y[0] + y[1]) - t).powi(2);
            }
        }
        (w1 / 15_000.0, (se / se_mean).sqrt())
    };
    let (w_still, _) = run(false);
    assert!(
        (w_still - 1.0 / 26.0).abs() < 0.01,
        "weight at rest {w_still}"
    );
    let (w_moving, ratio) = run(true);
    // Optimal for these errors (each chip's scale error adds (0.01·r)² of
    // variance, 0.045 (°/s)² over the sway): 1/(σ² + 0.045), 0.18 for the
    // noisier chip. The priors' proportion alone would give it 0.04.
    assert!(
        (0.12..0.3).contains(&w_moving),
        "weight of the noisier chip under motion {w_moving}"
    );
    assert!(ratio <= 1.0, "fused / mean RMS {ratio}");
}

/// Two of four chips spiking the same way on the same sample: no majority,
/// so the output holds its last value, flagged, instead of following the
/// pair (which the noise model also finds the quieter one: it was
/// followed, 1.1 °/s RMS against 0.06 now in `fusion-eval` class (i)).
#[test]
fn two_of_four_chips_wrong_together_give_a_held_flagged_output() {
    let f = Fusion::<4>::new(Method::Adaptive(AdaptiveConfig::default())).unwrap();
    let mut st = AxisState::default();
    let mut rng = Rng::new(21);
    let mut last = 0.0;
    for _ in 0..3000 {
        let y = [0usize, 1, 2, 3].map(|_| 1.0 + 0.09 * rng.gaussian());
        last = f.fuse(&mut st, &y, 0b1111).unwrap().rate_dps;
    }
    let r = f.fuse(&mut st, &[1.02, 21.0, 21.05, 0.97], 0b1111).unwrap();
    assert_eq!(r.rate_dps, last, "{r:?}");
    assert!(r.fallback && r.used() == 0, "{r:?}");
    // With a majority (three against one) nothing is held.
    let r = f.fuse(&mut st, &[1.02, 21.0, 1.05, 0.97], 0b1111).unwrap();
    assert!(!r.fallback && (r.rate_dps - 1.0).abs() < 0.1, "{r:?}");
}

/// `used` is w > 0: zeros of both signs, NaN and negative weights are out;
/// subnormal and infinite positive weights are in.
#[test]
fn used_is_the_positive_weights() {
    let odd = [
        0.0f32,
        -0.0,
        f32::MIN_POSITIVE / 2.0,
        -f32::MIN_POSITIVE / 2.0,
        1.0,
        -1.0,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NAN,
        -f32::NAN,
        f32::MAX,
    ];
    for &a in &odd {
        for &b in &odd {
            let f = Fused::<2> {
                rate_dps: 0.0,
                weights: [a, b],
                rejected: 0,
                fallback: false,
            };
            let want = u8::from(a > 0.0) | u8::from(b > 0.0) << 1;
            assert_eq!(f.used(), want, "{a} {b}");
        }
    }
}

/// The adaptive method through [`adaptive_active`] with every mask a
/// runtime value: the reference for the constant-set copies.
fn adaptive_reference<const N: usize>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    valid: u8,
    out: &mut Fused<N>,
) -> bool {
    if valid == 0 {
        return false;
    }
    let active = frozen_check(c, st, y, valid);
    if active == 0 {
        out.rejected |= valid;
        return false;
    }
    put(
        adaptive_active(c, st, y, valid, active, valid, (false, false), None, out),
        out,
    )
}

/// Every constant-set copy of the adaptive method (the jump table's sets,
/// the sets left while a frozen chip votes, one gyro gated out of the
/// board's healthy sets) gives the general path's bits: outputs and
/// states, over random sets of five, spikes, one or two chips stuck at
/// once, warm-up and rejoins.
#[test]
fn constant_set_copies_give_the_general_paths_bits() {
    let c = AdaptiveConfig::default();
    let mut rng = Rng::new(11);
    let mut rejected = 0u32;
    let mut frozen = 0u32;
    let mut pairs = 0u32;
    for _ in 0..100 {
        let (mut a, mut b) = (AxisState::<5>::default(), AxisState::<5>::default());
        let mut valid = 0b11111u8;
        let mut stuck: Option<(u8, [f32; 5], u32)> = None;
        for _ in 0..600 {
            if rng.uniform() < 0.01 {
                // A new set: mostly the board's, sometimes any.
                valid = if rng.uniform() < 0.5 {
                    [0b11111, 0b01111][(rng.uniform() * 2.0) as usize % 2]
                } else {
                    (rng.uniform() * 32.0) as u8 & 0b11111
                };
            }
            let mut y = [0.0f32; 5];
            for (i, v) in y.iter_mut().enumerate() {
                *v = 3.0 + [0.1, 0.1, 0.1, 0.1, 0.5][i] * rng.gaussian();
                if rng.uniform() < 0.03 {
                    *v += 20.0 * rng.gaussian();
                }
            }
            if stuck.is_none() && rng.uniform() < 0.01 {
                // One chip, or (half the time) two together: then the
                // gyros fused while they are frozen can be a pair.
                let i = (rng.uniform() * 5.0) as usize % 5;
                let j = (i + 1 + (rng.uniform() * 4.0) as usize % 4) % 5;
                let m = (1u8 << i) | if rng.uniform() < 0.5 { 1u8 << j } else { 0 };
                stuck = Some((m, y, 30));
            }
            if let Some((m, v, left)) = stuck {
                for i in 0..5 {
                    y[i] = if m & (1 << i) != 0 { v[i] } else { y[i] };
                }
                stuck = (left > 1).then_some((m, v, left - 1));
                pairs += u32::from((valid & !m).count_ones() == 2 && valid & m != 0);
            }
            let blank = Fused {
                rate_dps: f32::NAN,
                weights: [0.0; 5],
                rejected: 0,
                fallback: false,
            };
            let (mut oa, mut ob) = (blank, blank);
            let ra = adaptive(&c, &mut a, &y, valid, &mut oa);
            let rb = adaptive_reference(&c, &mut b, &y, valid, &mut ob);
            assert_eq!(ra, rb);
            assert_eq!(format!("{oa:?}"), format!("{ob:?}"), "valid {valid:#07b}");
            assert_eq!(format!("{a:?}"), format!("{b:?}"), "valid {valid:#07b}");
            rejected += u32::from(ob.rejected != 0);
            frozen += u32::from(b.frozen.iter().any(|&f| f >= 3));
        }
    }
    // The test must reach the paths it is about.
    assert!(
        rejected > 1000 && frozen > 1000 && pairs > 300,
        "rejected {rejected}, frozen {frozen}, pairs left beside stuck chips {pairs}"
    );
}

/// What fusion makes of `y` with weights `w` (summing to 1): Σwᵢyᵢ.
fn fused_with<const N: usize>(y: &[f32; N], w: &[f32; N]) -> Fused<N> {
    Fused {
        rate_dps: y
            .iter()
            .zip(w)
            .filter(|(_, &w)| w > 0.0)
            .map(|(y, w)| y * w)
            .sum(),
        weights: *w,
        rejected: 0,
        fallback: false,
    }
}

#[test]
fn noise_probe_cancels_motion_and_keeps_the_fused_variance() {
    // Five gyros of unequal noise, inverse-variance weights, a platform
    // rate of up to ±100 °/s that every chip sees: the probe does not move
    // with the rate, and its variance is the fused error's, 1/Σσ⁻².
    let sigma = [0.05f32, 0.08, 0.1, 0.12, 0.2];
    let inv: f32 = sigma.iter().map(|s| 1.0 / (s * s)).sum();
    let w = sigma.map(|s| 1.0 / (s * s) / inv);
    let probe = |y: &[f32; 5]| noise_probe(y, &fused_with(y, &w));
    let mut rng = Rng::new(3);
    let (mut sum2, mut fused2, n) = (0.0f64, 0.0f64, 200_000);
    for k in 0..n {
        let rate = 100.0 * libm::sinf(k as f32 * 0.01);
        let noise = sigma.map(|s| s * rng.gaussian());
        let y: [f32; 5] = core::array::from_fn(|i| rate + noise[i]);
        let p = probe(&y).unwrap();
        let still = probe(&noise).unwrap();
        assert!((p - still).abs() < 1e-4, "the rate leaks: {p} vs {still}");
        sum2 += (p as f64).powi(2);
        fused2 += (w.iter().zip(&noise).map(|(w, e)| w * e).sum::<f32>() as f64).powi(2);
    }
    let (var, want) = (sum2 / n as f64, 1.0 / inv as f64);
    assert!((var / want - 1.0).abs() < 0.02, "{var} vs {want}");
    assert!((fused2 / n as f64 / want - 1.0).abs() < 0.02);
    // Two gyros: half their difference; one gyro, or none: no probe.
    let two = |y: [f32; 3], w: [f32; 3]| noise_probe(&y, &fused_with(&y, &w));
    assert_eq!(two([1.0, 3.0, 0.0], [0.5, 0.5, 0.0]), Some(-1.0));
    assert_eq!(two([1.0, 3.0, 5.0], [1.0, 0.0, 0.0]), None);
    assert_eq!(two([1.0, f32::NAN, 0.0], [0.5, 0.5, 0.0]), None);
}

#[test]
fn every_methods_probe_cancels_motion() {
    // `noise_probe` takes the fused rate for Σwᵢyᵢ. It is that, or in the
    // adaptive method's warm-up the voters' median; either moves one for
    // one with a rate common to every chip, so the probe does not. Two
    // fusions, one fed a ±100 °/s motion plus noise and one the noise
    // alone (outliers and a chip dropped from the offered set, and so
    // warm-ups, in both), give the same probe to rounding.
    for m in all_methods() {
        let f = Fusion::<5>::new(m).unwrap();
        let (mut moving, mut still) = (AxisState::default(), AxisState::default());
        let mut rng = Rng::new(11);
        let mut probes = 0;
        // The seed's memory and running-spread weights see each rate
        // through a small ε: the rounding of a 100 °/s value moves them by
        // 0.1–0.3 % (measured; the others by 7e-6).
        let tol = match m {
            Method::SupportDegree(c)
                if c.memory.is_some() || c.normaliser != Normaliser::Instant =>
            {
                5e-3
            }
            _ => 1e-4,
        };
        for k in 0..20_000u32 {
            let rate = 100.0 * libm::sinf(k as f32 * 0.003);
            let mut e: [f32; 5] = core::array::from_fn(|_| 0.1 * rng.gaussian());
            if k % 97 == 0 {
                e[1] += 30.0;
            }
            let y = e.map(|e| rate + e);
            let offered = if k % 1000 < 100 { 0b10111 } else { 0b11111 };
            let (a, b) = (
                f.fuse(&mut moving, &y, offered),
                f.fuse(&mut still, &e, offered),
            );
            let (Ok(a), Ok(b)) = (a, b) else {
                assert_eq!(a.is_ok(), b.is_ok(), "{m:?} at {k}");
                continue;
            };
            assert!((a.weights.iter().sum::<f32>() - 1.0).abs() < 1e-5 || a.weights == [0.0; 5]);
            let (pa, pb) = (noise_probe(&y, &a), noise_probe(&e, &b));
            assert_eq!(pa.is_some(), pb.is_some(), "{m:?} at {k}");
            if let (Some(pa), Some(pb)) = (pa, pb) {
                let rel = (pa - pb).abs() / (1.0 + pb.abs());
                assert!(rel < tol, "{m:?} at {k}: {pa} moving, {pb} still");
                probes += 1;
            }
        }
        assert!(probes > 19_000, "{m:?}: {probes} probes");
    }
}

/// The timed fault campaign's case at seed 786741: three gyros, one read
/// far off (a corrupted range) and gated out; then the third drops a
/// sample and the off one is left with a good one. The pair disagree and
/// fusion used only the good one last sample: it stays alone, where the
/// pair's weighted mean was 108 °/s off.
#[test]
fn of_two_that_disagree_the_one_in_the_consensus_stays() {
    let f = Fusion::<3>::new(Method::Adaptive(AdaptiveConfig::default())).unwrap();
    let mut st = AxisState::default();
    let mut rng = Rng::new(5);
    for _ in 0..3000 {
        let y = [0, 1, 2].map(|_| -15.0 + 0.05 * rng.gaussian());
        f.fuse(&mut st, &y, 0b111).unwrap();
    }
    let r = f.fuse(&mut st, &[-240.0, -15.02, -14.98], 0b111).unwrap();
    assert!((r.rate_dps + 15.0).abs() < 0.1, "{r:?}");
    assert_ne!(r.rejected & 0b001, 0, "{r:?}");
    // Chip 2 drops out: chips 0 and 1 alone.
    let r = f.fuse(&mut st, &[-241.0, -15.01, f32::NAN], 0b011).unwrap();
    assert!((r.rate_dps + 15.0).abs() < 0.1, "{r:?}");
    assert_ne!(r.rejected & 0b001, 0, "{r:?}");
    // Both back in agreement: both fused again.
    let r = f.fuse(&mut st, &[-15.0, -15.01, f32::NAN], 0b011).unwrap();
    assert!((r.rate_dps + 15.0).abs() < 0.1, "{r:?}");
    assert_eq!(r.rejected, 0, "{r:?}");
}
