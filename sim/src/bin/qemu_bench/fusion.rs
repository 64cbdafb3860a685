//! Every fusion method on N = 4, per fused 3-axis sample, and the
//! calibration in front of it.

use super::*;

/// Instructions per fused 3-axis sample of every fusion method (N = 4).
/// Not inlined: its frames stay out of main's stack.
#[inline(never)]
pub(super) fn bench_fusion(t: &Ticks, ipt: f32, rng: &mut Rng) -> bool {
    // Frames: 4 gyros × 3 axes, noise plus occasional spikes on gyro 1.
    let mut frames = [[[0.0f32; 4]; 3]; FRAMES];
    for f in frames.iter_mut() {
        for (a, axis) in f.iter_mut().enumerate() {
            for (i, y) in axis.iter_mut().enumerate() {
                *y = [95.0, -5.0, 0.0][a] + [0.1, 0.1, 0.1, 0.5][i] * rng.gaussian();
            }
            if rng.uniform() < 0.05 {
                axis[1] += 10.0;
            }
        }
    }

    // Loop overhead: the same loop (`per_frame`'s) with the call replaced.
    let overhead = ticks_of(t, &frames, |f| {
        for axis in f.iter() {
            black_box(axis);
        }
    });

    let mut ok = true;
    for (name, m) in methods() {
        let Ok(fusion) = Fusion::<4>::new(m) else {
            exit(false)
        };
        let mut st = [AxisState::<4>::default(); 3];
        // Warmed up first (memory windows, noise estimates).
        let per_sample = per_frame(t, ipt, overhead, &frames, true, |f| {
            for (a, axis) in f.iter().enumerate() {
                let _ = black_box(fusion.fuse(&mut st[a], black_box(axis), 0b1111));
            }
        });
        defmt::info!(
            "bench fusion {=str}: {=u32} instructions per 3-axis sample (N = 4)",
            name,
            per_sample as u32
        );
        ok &= per_sample > 0.0;
    }

    // The adaptive fusion with five gyros, all in or some out (as after a
    // fault): the general mask costs more than the constant one.
    let mut frames5 = [[[0.0f32; 5]; 3]; 200];
    for f in frames5.iter_mut() {
        for (a, axis) in f.iter_mut().enumerate() {
            for (i, y) in axis.iter_mut().enumerate() {
                *y = [95.0, -5.0, 0.0][a] + [0.1, 0.1, 0.1, 0.1, 0.5][i] * rng.gaussian();
            }
        }
    }
    let overhead5 = ticks_of(t, &frames5, |f| {
        for axis in f.iter() {
            black_box(axis);
        }
    });
    for (name, mask) in [
        ("all five", 0b11111u8),
        ("four of five", 0b01111),
        ("three of five", 0b00111),
    ] {
        let Ok(fusion) = Fusion::<5>::new(Method::Adaptive(Default::default())) else {
            exit(false)
        };
        let mut st = [AxisState::<5>::default(); 3];
        let mut step = |f: &[[f32; 5]; 3]| {
            for (a, axis) in f.iter().enumerate() {
                let _ = black_box(fusion.fuse(&mut st[a], black_box(axis), mask));
            }
        };
        // Noise estimates warmed up over three passes (the last in
        // `per_frame`), the fourth timed.
        for _ in 0..2 {
            frames5.iter().for_each(&mut step);
        }
        let per_sample = per_frame(t, ipt, overhead5, &frames5, true, step);
        defmt::info!(
            "bench fusion adaptive, N = 5, {=str} offered: {=u32} instructions per 3-axis sample",
            name,
            per_sample as u32
        );
        ok &= per_sample > 0.0;
    }

    // The default path of the pipeline: relative calibration, adaptive
    // fusion, calibration update (as `Pipeline::step` runs them; the noise
    // probe it adds is timed on its own below).
    let Ok(fusion) = Fusion::<4>::new(Method::Adaptive(Default::default())) else {
        exit(false)
    };
    let mut st = [AxisState::<4>::default(); 3];
    let mut cal = [RelCal::<4>::new(CalConfig::default()); 3];
    let step = |st: &mut [AxisState<4>; 3], cal: &mut [RelCal<4>; 3], f: &[[f32; 4]; 3]| {
        for (a, axis) in f.iter().enumerate() {
            let y = black_box(axis);
            let _ = black_box(cal[a].fuse(&fusion, &mut st[a], y, 0b1111));
        }
    };
    let per_sample = per_frame(t, ipt, overhead, &frames, true, |f| {
        step(&mut st, &mut cal, f)
    });
    defmt::info!(
        "bench fusion adaptive + online relative calibration: {=u32} instructions per 3-axis sample (N = 4)",
        per_sample as u32
    );
    ok &= per_sample > 0.0;

    // The static calibration in front (`Pipeline::board_rates`: each chip's
    // 3×3 matrix, bias and bias-temperature slope), timed alone and then
    // with the rest: calibration, online calibration and fusion.
    use gyro_array::algo::static_cal::ChipCal;
    let cal_of = |i: usize| ChipCal {
        m: [
            [1.01, 0.002 * i as f32, -0.001],
            [0.0015, -0.995, 0.002],
            [0.001, -0.002, 1.004],
        ],
        bias_dps: [0.1, -0.2, 0.05],
        bias_tc_dps_per_c: [0.001, -0.002, 0.0005],
        t_ref_c: 25.0,
    };
    let chips = [cal_of(0), cal_of(1), cal_of(2), cal_of(3)];
    let temps = [Some(31.5f32), Some(30.0), Some(29.0), Some(32.0)];
    let apply = |f: &[[f32; 4]; 3]| {
        let mut out = [[0.0f32; 4]; 3];
        for (i, (c, tc)) in chips.iter().zip(temps).enumerate() {
            let b = black_box(c).apply([f[0][i], f[1][i], f[2][i]], 0b111, tc);
            for (a, v) in b.into_iter().enumerate() {
                out[a][i] = v;
            }
        }
        out
    };
    let st_i = per_frame(t, ipt, overhead, &frames, false, |f| {
        black_box(apply(black_box(f)));
    });
    let all = per_frame(t, ipt, overhead, &frames, false, |f| {
        let c = apply(black_box(f));
        step(&mut st, &mut cal, &c);
    });
    defmt::info!(
        "bench fusion default path (static calibration + online relative calibration + adaptive fusion): {=u32} instructions per 3-axis sample (N = 4; static calibration alone {=u32}, target <= 2500)",
        all as u32,
        st_i as u32
    );
    ok &= all > 0.0;
    // The noise probe the pipeline takes from each fused axis for its
    // tracker, on the fused outputs of the frames (timed alone: a second
    // caller of `fuse_probed` here changed its inlining into `fuse` and
    // the path above by +270).
    let fused: [[Option<gyro_array::algo::fusion::Fused<4>>; 3]; FRAMES] = {
        let mut st = [AxisState::<4>::default(); 3];
        core::array::from_fn(|k| {
            core::array::from_fn(|a| fusion.fuse(&mut st[a], &frames[k][a], 0b1111).ok())
        })
    };
    let mut k = 0usize;
    let probe = per_frame(t, ipt, overhead, &frames, false, |f| {
        for (a, axis) in f.iter().enumerate() {
            if let Some(r) = &fused[k % FRAMES][a] {
                black_box(noise_probe(black_box(axis), black_box(r)));
            }
        }
        k += 1;
    });
    defmt::info!(
        "bench fusion noise probe (the pipeline's tracker input, on top of the default path): {=u32} instructions per 3-axis sample (N = 4)",
        probe as u32
    );
    ok &= probe > 0.0;

    // Seed 001 on the array: a local rate+bias Kalman filter per chip,
    // fused by entropy or covariance weights, the fused rate fed back.
    use gyro_array::algo::mixture::{ChipFilters, ChipWeights};
    for (name, weights) in [
        ("entropy", ChipWeights::Entropy),
        ("covariance", ChipWeights::Covariance),
    ] {
        let Ok(cf) = ChipFilters::<4>::new([0.1, 0.1, 0.1, 0.5], 6.3, 1e-4, weights) else {
            exit(false)
        };
        let mut cfs = [cf; 3];
        let per = per_frame(t, ipt, overhead, &frames, true, |f| {
            for (a, axis) in f.iter().enumerate() {
                black_box(cfs[a].fuse(black_box(axis), 0b1111));
            }
        });
        defmt::info!(
            "bench fusion seed 001 local filters ({=str} weights): {=u32} instructions per 3-axis sample (N = 4)",
            name,
            per as u32
        );
        ok &= per > 0.0;
    }

    ok
}
