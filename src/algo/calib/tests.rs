use super::*;
use gyro_sim::Rng;

/// Four chips with scale errors of +1/−1/+1.5/−2 % and biases on a
/// 95 °/s, 2 Hz sway: after 10 s the corrected chips agree with each
/// other to within their noise, the estimates are within 0.1 % of the
/// true relative scale, and a still board leaves the scales at 1.
#[test]
fn scale_and_bias_are_learnt_under_motion_and_left_alone_when_still() {
    let scale = [1.01f32, 0.99, 1.015, 0.98];
    let bias = [0.2f32, -0.1, 0.0, 0.3];
    let mut rng = Rng::new(3);
    let mut cal = RelCal::<4>::new(CalConfig::default());
    let mut spread = 0.0f64;
    let n = 20_000;
    for k in 0..n {
        let w = 95.0 * libm::sinf(2.0 * core::f32::consts::PI * 2.0 * k as f32 * 1e-3);
        let y = [0, 1, 2, 3].map(|i| scale[i] * w + bias[i] + 0.09 * rng.gaussian());
        let c = cal.correct(&y);
        if k >= n - 5000 {
            let m = c.iter().sum::<f32>() / 4.0;
            spread += c.iter().map(|v| ((v - m) as f64).powi(2)).sum::<f64>() / 3.0;
        }
        cal.update(&y, 0b1111);
    }
    let spread = (spread / 5000.0).sqrt();
    assert!(spread < 0.12, "spread {spread}");
    // Relative to the median chip's scale (the mean of 1.01 and 0.99).
    let s = cal.scale();
    for i in 0..4 {
        assert!((s[i] - scale[i]).abs() < 1e-3, "{s:?}");
    }
    let mut still = RelCal::<4>::new(CalConfig::default());
    for _ in 0..20_000 {
        let y = [0, 1, 2, 3].map(|i| scale[i] * 5.0 + bias[i] + 0.09 * rng.gaussian());
        still.update(&y, 0b1111);
    }
    assert!(
        still.scale().iter().all(|s| (s - 1.0).abs() < 0.01),
        "{:?}",
        still.scale()
    );
}

/// A chip reading NaN or ±∞ teaches the calibration nothing, whether
/// the caller says it was used (`update`) or fusion decides (`fuse`):
/// the estimates stay finite and the same as without the bad chip's
/// samples, which are the only difference between the two runs.
#[test]
fn non_finite_readings_are_not_learnt() {
    use crate::algo::fusion::{AdaptiveConfig, AxisState, Fusion, Method};
    let f = Fusion::<4>::new(Method::Adaptive(AdaptiveConfig::default())).unwrap();
    let mut rng = Rng::new(9);
    let (mut a, mut b) = (
        RelCal::<4>::new(CalConfig::default()),
        RelCal::<4>::new(CalConfig::default()),
    );
    let (mut c, mut d) = (a, b);
    let (mut sc, mut sd) = (AxisState::<4>::default(), AxisState::<4>::default());
    for k in 0..6000 {
        let w = 80.0 * libm::sinf(k as f32 * 0.01);
        let y = [1.01f32, 0.99, 1.0, 1.02].map(|s| s * w + 0.05 * rng.gaussian());
        let bad = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY][k % 3];
        let mut z = y;
        z[3] = if k % 7 == 0 { bad } else { y[3] };
        // update: the caller marks all four used; the bad samples of
        // chip 3 are the same as leaving it out of `used`.
        a.update(&z, 0b1111);
        b.update(&y, if k % 7 == 0 { 0b0111 } else { 0b1111 });
        // fuse: fusion rejects the bad value itself.
        let _ = c.fuse(&f, &mut sc, &z, 0b1111);
        let _ = d.fuse(&f, &mut sd, &y, if k % 7 == 0 { 0b0111 } else { 0b1111 });
    }
    for (x, y) in [(&a, &b), (&c, &d)] {
        assert!(x.scale().iter().chain(&x.bias()).all(|v| v.is_finite()));
        assert_eq!(x.scale(), y.scale());
        assert_eq!(x.bias(), y.bias());
    }
    // Against the average chip (scale 1.005).
    assert!(
        (a.scale()[3] - 1.02 / 1.005).abs() < 2e-3,
        "{:?}",
        a.scale()
    );
}

/// Under a 100 °/s, 10 Hz motion with scale errors of ±2 %, fusion
/// first learns the uncorrected disagreement (about 2 °/s) as noise.
/// Once the correction applies, those estimates are forgotten and
/// learnt again: 1000 samples later every σ estimate is within 30 % of
/// the true 0.09 °/s (left to decay at 1/256 per sample, they would
/// still be several times too large), and the fused error is at the
/// noise level.
#[test]
fn noise_learnt_before_the_correction_is_forgotten() {
    use crate::algo::fusion::{AdaptiveConfig, AxisState, Fusion, Method};
    let cfg = AdaptiveConfig::default();
    let f = Fusion::<4>::new(Method::Adaptive(cfg)).unwrap();
    let mut st = AxisState::<4>::default();
    let scale = [1.02f32, 0.98, 1.015, 0.985];
    let mut rng = Rng::new(11);
    let mut cal = RelCal::<4>::new(CalConfig::default());
    let mut se = 0.0f64;
    let mut peak = 0.0f32;
    for k in 0..1000 {
        let w = 100.0 * libm::sinf(2.0 * core::f32::consts::PI * 10.0 * k as f32 * 1e-3);
        let y = [0, 1, 2, 3].map(|i| scale[i] * w + 0.09 * rng.gaussian());
        let r = cal.fuse(&f, &mut st, &y, 0b1111).unwrap();
        if k == 30 {
            peak = st.sigma_dps(&cfg).iter().fold(0.0, |m, s| m.max(*s));
        }
        if k >= 500 {
            // Against the chips' mean scale (what the calibration keeps).
            se += ((r.rate_dps - w * 1.0) as f64).powi(2);
        }
    }
    assert!(
        peak > 0.5,
        "the uncorrected disagreement was learnt: {peak}"
    );
    let s = st.sigma_dps(&cfg);
    assert!(s.iter().all(|s| (s / 0.09 - 1.0).abs() < 0.3), "{s:?}");
    let rms = (se / 500.0).sqrt();
    assert!(rms < 0.07, "fused rms {rms}");
}
/// A chip fusion no longer uses (stuck) keeps its correction while the
/// others' estimates move: its corrected reading stays frozen, so
/// fusion's frozen-output check keeps it out.
#[test]
fn an_unused_chip_keeps_its_correction() {
    let scale = [1.01f32, 0.99, 1.015, 0.98];
    let mut rng = Rng::new(9);
    let mut cal = RelCal::<4>::new(CalConfig::default());
    let w = |k: usize| 30.0 * libm::sinf(2.0 * core::f32::consts::PI * k as f32 * 1e-3);
    for k in 0..3000 {
        let y = [0, 1, 2, 3].map(|i| scale[i] * w(k) + 0.09 * rng.gaussian());
        cal.update(&y, 0b1111);
    }
    let held = 7.5f32;
    let first = cal.correct(&[held, 0.0, 0.0, 0.0])[0];
    for k in 3000..6000 {
        let mut y =
            [0, 1, 2, 3].map(|i| scale[i] * w(k) * (1.0 + 2e-3 * i as f32) + 0.09 * rng.gaussian());
        y[0] = held;
        cal.update(&y, 0b1110);
        assert_eq!(cal.correct(&y)[0], first, "sample {k}");
    }
}
/// A chip that sticks is out of fusion within 5 samples whatever the
/// phase of the calibration's re-solve (every offset of its 64-sample
/// cycle tried): a repeated raw reading keeps its corrected value.
#[test]
fn a_stuck_chip_is_out_quickly_at_every_solve_phase() {
    use crate::algo::fusion::{AdaptiveConfig, AxisState, Fusion, Method};
    let f = Fusion::<3>::new(Method::Adaptive(AdaptiveConfig::default())).unwrap();
    let scale = [1.01f32, 0.99, 1.005];
    let mut worst = 0;
    for offset in 0..64 {
        let mut st = AxisState::<3>::default();
        st.set_noise_priors([Some(0.09); 3]);
        let mut cal = RelCal::<3>::new(CalConfig::default());
        let mut rng = Rng::new(100 + offset as u64);
        let stick = 3000 + offset;
        let mut held = 0.0f32;
        let mut out_after = None;
        for k in 0..stick + 20 {
            let w = 20.0 * libm::sinf(2.0 * core::f32::consts::PI * k as f32 * 1e-3);
            // Quantised as the ICM-42688-P's 131 LSB/°/s.
            let mut y = [0, 1, 2]
                .map(|i| libm::roundf((scale[i] * w + 0.09 * rng.gaussian()) * 131.0) / 131.0);
            if k == stick {
                held = y[0];
            }
            if k >= stick {
                y[0] = held;
            }
            let r = cal.fuse(&f, &mut st, &y, 0b111).unwrap();
            if k >= stick && out_after.is_none() && r.weights[0] == 0.0 {
                out_after = Some(k - stick);
            }
        }
        assert!(
            out_after.is_some_and(|n| n <= 5),
            "offset {offset}: {out_after:?}"
        );
        worst = worst.max(out_after.unwrap_or(99));
    }
    println!("stuck chip out after at most {worst} samples");
}

/// The drift watch on the pipeline's path (`fuse`, adaptive fusion),
/// four chips, `scale` errors, a true rate `w(k)` (1 kHz), and chip 2's
/// bias ramping at `drift` °/s per s from 5 s: the first sample from
/// which chip 2 is drifting to the end (none: never), and whether any
/// other chip ever was; the last fused weight of chip 2.
fn watch_run(
    scale: [f32; 4],
    drift: f32,
    temp_rate: f32,
    w: impl Fn(usize) -> f32,
) -> (Option<usize>, bool, f32) {
    use crate::algo::fusion::{AdaptiveConfig, AxisState, Fusion, Method};
    let f = Fusion::<4>::new(Method::Adaptive(AdaptiveConfig::default())).unwrap();
    let mut st = AxisState::<4>::default();
    let mut cal = RelCal::<4>::new(CalConfig::default());
    cal.set_temperature_rate(temp_rate, 1000);
    let mut rng = Rng::new(21);
    let (mut since, mut others, mut weight) = (None, false, 0.0);
    for k in 0..15_000 {
        let d = if k >= 5000 {
            drift * (k - 5000) as f32 * 1e-3
        } else {
            0.0
        };
        let y = [0, 1, 2, 3].map(|i| {
            let v = scale[i] * w(k) + 0.06 * rng.gaussian() + if i == 2 { d } else { 0.0 };
            libm::roundf(v * 131.0) / 131.0
        });
        let r = cal.fuse(&f, &mut st, &y, 0b1111).unwrap();
        weight = r.weights[2];
        if cal.drifting() & 0b100 != 0 {
            since.get_or_insert(k);
        } else {
            since = None;
        }
        others |= cal.drifting() & !0b100 != 0;
    }
    (since, others, weight)
}

/// A chip drifting at 0.1 °/s per second from 5 s (its 0.18 °/s, 3σ of
/// its noise, at 6.8 s) is called drifting within 2 s of reaching 3σ,
/// stays so, and leaves fusion; no other chip is, at rest or under a
/// sway with scale errors.
#[test]
fn a_drifting_chip_is_caught_and_left_out() {
    let sway = |k: usize| 30.0 * libm::sinf(2.0 * core::f32::consts::PI * k as f32 * 1e-3);
    for (scale, w) in [
        ([1.0f32; 4], &(|_| 0.0f32) as &dyn Fn(usize) -> f32),
        ([1.01, 0.99, 1.005, 0.985], &sway),
    ] {
        let (since, others, weight) = watch_run(scale, 0.1, 0.0, w);
        assert!(since.is_some_and(|k| k < 8800), "{since:?}");
        println!("drifting from sample {since:?}");
        assert!(!others);
        assert_eq!(weight, 0.0);
    }
}

/// No chip is called drifting when none drifts: a scale error of 2 %
/// that a 100 °/s turn reveals after 5 s on a still board (the ridge
/// held the scale at 1), and a chip drifting at 0.1 °/s per second while
/// the die temperature moves fast enough to allow it.
#[test]
fn a_revealed_scale_or_a_warming_die_is_no_drift() {
    let turn = |k: usize| {
        if k < 5000 {
            0.0
        } else {
            100.0f32.min((k - 5000) as f32 * 0.2)
        }
    };
    let (since, others, _) = watch_run([1.0, 1.02, 0.99, 0.98], 0.0, 0.0, turn);
    assert!(since.is_none() && !others, "{since:?} {others}");
    let (since, others, _) = watch_run([1.0; 4], 0.1, 2.0, |_| 0.0);
    assert!(since.is_none() && !others, "{since:?} {others}");
}

/// Fusing first and learning after (the board's loop: the frame goes out
/// between the two) is the same calibration, the same fusion and the same
/// noise probe, bit for bit, as doing both at once: on a sway with scale
/// errors, a chip drifting 0.1 °/s per second and, for a while, a chip
/// fusion refuses (all four stuck on one value is no consensus).
#[test]
fn learning_after_the_frame_is_learning_at_once() {
    use crate::algo::fusion::{AdaptiveConfig, AxisState, Fusion, Method};
    let f = Fusion::<4>::new(Method::Adaptive(AdaptiveConfig::default())).unwrap();
    let scale = [1.01f32, 0.99, 1.015, 0.98];
    let mut rng = Rng::new(21);
    let (mut at_once, mut after) = (
        RelCal::<4>::new(CalConfig::default()),
        RelCal::<4>::new(CalConfig::default()),
    );
    let (mut sa, mut sb) = (AxisState::<4>::default(), AxisState::<4>::default());
    for k in 0..12_000u32 {
        let t = k as f32 * 1e-3;
        let w = 95.0 * libm::sinf(2.0 * core::f32::consts::PI * 2.0 * t);
        let mut y = [0, 1, 2, 3].map(|i| scale[i] * w + 0.09 * rng.gaussian());
        y[2] += 0.1 * (t - 6.0).max(0.0);
        let offered = if (3000..3040).contains(&k) {
            0b0011
        } else {
            0b1111
        };
        let a = at_once.fuse_probed(&f, &mut sa, &y, offered);
        let b = after.fuse_deferred(&f, &mut sb, &y, offered);
        assert_eq!(
            a.map(|(r, p)| (r.rate_dps.to_bits(), p.map(f32::to_bits))),
            b.map(|(r, p)| (r.rate_dps.to_bits(), p.map(f32::to_bits))),
            "sample {k}"
        );
        after.finish(&mut sb);
        assert_eq!(at_once.scale(), after.scale(), "sample {k}");
        assert_eq!(at_once.bias(), after.bias(), "sample {k}");
        assert_eq!(at_once.drifting(), after.drifting(), "sample {k}");
    }
    assert_ne!(at_once.drifting(), 0, "the drifting chip is flagged");
}

/// Five chips at rest on 1.8 °/s, one read at 16× its range (26 °/s off,
/// as a corrupted GYRO_FS_SEL reads): fusion's warm-up gate leaves it out,
/// the young watch judges its offset beyond the bound within a block or
/// two, and from then on it is out of bounds and never fused (weight 0,
/// not in `used`), while the others' fused rate stays on the truth.
/// Without the watch it passed fusion's gate on a noise estimate its own
/// offset had made, and the fused rate went 1.1 °/s off (the fault
/// campaign, seed 255).
#[test]
fn a_chip_far_off_at_power_up_is_out_of_bounds_and_not_fused() {
    use crate::algo::fusion::{AdaptiveConfig, AxisState, Fusion, Method};
    let f = Fusion::<5>::new(Method::Adaptive(AdaptiveConfig::default())).unwrap();
    let mut cal = RelCal::<5>::new(CalConfig::board());
    let mut st = AxisState::<5>::default();
    let mut rng = Rng::new(255);
    let truth = -1.8f32;
    let mut flagged_at = None;
    let mut worst = 0.0f32;
    for k in 0..3000 {
        let mut y = [0.0f32; 5];
        for (i, v) in y.iter_mut().enumerate() {
            let sigma = if i == 4 { 0.45 } else { 0.09 };
            *v = truth + sigma * rng.gaussian();
        }
        y[2] = 16.0 * truth + 0.09 * rng.gaussian();
        let r = cal.fuse(&f, &mut st, &y, 0b11111).expect("fused");
        if cal.out_of_bounds() & 0b100 != 0 && flagged_at.is_none() {
            flagged_at = Some(k);
        }
        if let Some(at) = flagged_at {
            if k > at {
                assert_eq!(r.weights[2], 0.0, "sample {k}");
                assert_eq!(r.used() & 0b100, 0, "sample {k}");
                worst = worst.max((r.rate_dps - truth).abs());
            }
        }
    }
    let at = flagged_at.expect("the chip 26 deg/s off is flagged");
    assert!(at < 40, "flagged at sample {at}");
    assert_eq!(cal.out_of_bounds(), 0b100, "only that chip");
    assert!(worst < 0.5, "fused off the truth by {worst}");
}

/// The board's reference leaves out a chip whose offset is out of line
/// with an array that agrees (a chip 6 °/s off, inside the bias bound: a
/// chip read at 16× at −0.4 °/s looks like that): every chip's correction,
/// and the fused rate, stays on the others' average. With the generic
/// settings (unknown parts, whose offsets spread widely) it is averaged
/// in, as the plain mean of the chips would.
#[test]
fn the_boards_reference_leaves_out_a_chip_out_of_line() {
    let run = |cfg: CalConfig| {
        let mut cal = RelCal::<4>::new(cfg);
        let mut rng = Rng::new(8214);
        let mut c = [0.0f32; 4];
        for _ in 0..4000 {
            let mut y = [0.0f32; 4];
            for v in y.iter_mut() {
                *v = -0.39 + 0.07 * rng.gaussian();
            }
            y[3] -= 5.9;
            c = cal.correct(&y);
            cal.update(&y, 0b1111);
        }
        c.iter().take(3).sum::<f32>() / 3.0
    };
    let board = run(CalConfig::board());
    assert!((board + 0.39).abs() < 0.1, "board: the others read {board}");
    let generic = run(CalConfig::default());
    assert!(
        (generic + 0.39 + 5.9 / 4.0).abs() < 0.15,
        "generic: the others read {generic}"
    );
}

/// Two chips of four frozen from power-up (at 0 while the board turns at
/// 14 °/s): until the stuck check flags them, the healthy pair's early
/// biases are taken against a median they pull halfway. Dropped when they
/// are found frozen, the pair starts again against the chips left and is
/// read as it is (two chips teach nothing); kept, it would sit 7 °/s off.
#[test]
fn chips_found_frozen_during_the_warm_up_take_what_was_learnt_against_them() {
    let mut rng = Rng::new(9);
    let mut kept = RelCal::<4>::new(CalConfig::default());
    let mut dropped = RelCal::<4>::new(CalConfig::default());
    let read = |rng: &mut Rng| {
        [
            0.0,
            0.0,
            14.0 + 0.05 * rng.gaussian(),
            14.0 + 0.05 * rng.gaussian(),
        ]
    };
    for _ in 0..20 {
        let y = read(&mut rng);
        kept.update(&y, 0b1111);
        dropped.update(&y, 0b1111);
    }
    dropped.drop_frozen(0);
    dropped.drop_frozen(1);
    for _ in 0..500 {
        let y = read(&mut rng);
        kept.update(&y, 0b1100);
        dropped.update(&y, 0b1100);
    }
    let y = [0.0, 0.0, 14.0, 14.0];
    let (k, d) = (kept.correct(&y), dropped.correct(&y));
    assert!(
        (d[2] - 14.0).abs() < 0.01 && (d[3] - 14.0).abs() < 0.01,
        "{d:?}"
    );
    assert!((k[2] - 14.0).abs() > 3.0, "the case this guards: {k:?}");
    // Once every chip is warm, a chip found frozen changes no other's.
    let mut warm = RelCal::<4>::new(CalConfig::default());
    for _ in 0..2000 {
        let y = [0, 1, 2, 3].map(|i| 14.0 + 0.1 * i as f32 + 0.05 * rng.gaussian());
        warm.update(&y, 0b1111);
    }
    let before = warm.correct(&y);
    warm.drop_frozen(0);
    assert_eq!(warm.correct(&y), before);
}
