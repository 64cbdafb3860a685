//! The array classes of `fusion-eval`: heterogeneous arrays of
//! N = 2…8 chips, common-mode vibration and temperature ramps (all on the
//! algorithms, as the other classes), then faults present at power-up, two
//! of five chips faulty and motion during boot on the whole emulated board
//! (real drivers over the emulated SPI bus, the start-up self-test, the
//! pipeline with its online calibration).

use gyro_array::algo::calib::{CalConfig, RelCal};
use gyro_array::algo::fusion::AxisState;
use gyro_sim::checks::run_board_array_with;
use gyro_sim::noise::{quantise, AxisNoise};
use gyro_sim::{Fault, NoiseParams, RateProfile, Rng};

use super::{mean_zhang_adaptive, method, report, FS, LSB, SAMPLES};

/// One class's result: name, RMS means over the seeds of [oracle, mean,
/// zhang, default], and whether the class is fault-free (then the default
/// is also held to 1.10 × the oracle).
pub type ClassResult = (String, [f64; 4], bool);

/// `N` chips of drawn noise (ARW × 1, 1.5, 2, 3 or 5 the ICM-42688-P's),
/// scale errors in ±`scale_pm`, biases in ±0.3 °/s, and an optional bias
/// slope against a die temperature ramp; `truth(k)` the true rate. The
/// default is the pipeline's path: the relative calibration in front of
/// adaptive fusion, with noise priors (each chip's σ as the start-up noise
/// test measures it, ±3 %). The oracle weights by the true white-noise
/// variances (blind to scale and bias errors). 10 seeds.
#[allow(clippy::too_many_arguments)]
fn class_n<const N: usize>(
    name: &str,
    seed: u64,
    hetero: bool,
    scale_pm: f32,
    temp_slope_pm: f32,
    truth: &dyn Fn(usize) -> f32,
) -> ClassResult {
    let mut res = vec![Vec::new(); 4];
    // The systematic error each reference carries (static bias, its
    // temperature slope, scale error): the oracle's weighted sum of the
    // chips', and the median chip's, which the relative calibration
    // aligns the others with. RMS over time, summed over seeds as squares.
    let mut carried = [0.0f64; 2];
    let mask = ((1u16 << N) - 1) as u8;
    for s in 0..10u64 {
        let mut rng = Rng::new(seed * 1000 + 700 + 17 * N as u64 + s);
        let mut params = [NoiseParams::ICM42688; N];
        let mut slope = [0.0f32; N];
        for (p, sl) in params.iter_mut().zip(slope.iter_mut()) {
            if hetero {
                let k = ((rng.uniform() * 5.0) as usize).min(4);
                p.arw_deg_rt_h *= [1.0, 1.5, 2.0, 3.0, 5.0][k];
            }
            p.scale_error = scale_pm * (2.0 * rng.uniform() - 1.0);
            p.bias_dps = 0.3 * (2.0 * rng.uniform() - 1.0);
            *sl = temp_slope_pm * (2.0 * rng.uniform() - 1.0);
        }
        let sig = params.map(|p| p.white_sigma_dps(FS) as f64);
        let w = sig.map(|s| 1.0 / (s * s));
        let ws: f64 = w.iter().sum();
        let mut noise = [AxisNoise::default(); N];
        let [mean, zhang, adaptive] = mean_zhang_adaptive::<N>();
        let mut st = [AxisState::<N>::default(); 3];
        let mut priors = [None; N];
        for (p, s) in priors.iter_mut().zip(sig) {
            *p = Some((s * (1.0 + 0.03 * (2.0 * rng.uniform() as f64 - 1.0))) as f32);
        }
        st[2].set_noise_priors(priors);
        let mut cal = RelCal::<N>::new(CalConfig::default());
        // What the pipeline tells the calibration from the die temperature
        // it reads: the ramp's rate (40 °C over the run).
        let ramp_c_per_s = if temp_slope_pm > 0.0 {
            40.0 / (SAMPLES as f32 / FS)
        } else {
            0.0
        };
        cal.set_temperature_rate(ramp_c_per_s, (1e6 / FS) as u32);
        let mut sums = [0.0f64; 4];
        for k in 0..SAMPLES {
            let t = truth(k);
            // Die temperature: 20 → 60 °C over the run.
            let temp = 20.0 + 40.0 * k as f32 / SAMPLES as f32;
            let mut y = [0.0f32; N];
            for i in 0..N {
                let v = noise[i].step(&params[i], &mut rng, t, 1.0 / FS) + slope[i] * (temp - 25.0);
                y[i] = quantise(v, LSB) as f32 / LSB;
            }
            let o: f64 = (0..N).map(|i| w[i] * y[i] as f64).sum::<f64>() / ws;
            if temp_slope_pm > 0.0 {
                let mut e: [f64; N] = core::array::from_fn(|i| {
                    (params[i].scale_error * t + params[i].bias_dps + slope[i] * (temp - 25.0))
                        as f64
                });
                carried[0] += ((0..N).map(|i| w[i] * e[i]).sum::<f64>() / ws).powi(2);
                e.sort_by(f64::total_cmp);
                carried[1] += (0.5 * (e[(N - 1) / 2] + e[N / 2])).powi(2);
            }
            sums[0] += (o - t as f64).powi(2);
            let r = mean.fuse(&mut st[0], &y, mask).expect("valid input");
            sums[1] += ((r.rate_dps - t) as f64).powi(2);
            let r = zhang.fuse(&mut st[1], &y, mask).expect("valid input");
            sums[2] += ((r.rate_dps - t) as f64).powi(2);
            let r = cal
                .fuse(&adaptive, &mut st[2], &y, mask)
                .expect("valid input");
            sums[3] += ((r.rate_dps - t) as f64).powi(2);
        }
        for (r, s) in res.iter_mut().zip(sums) {
            r.push((s / SAMPLES as f64).sqrt());
        }
    }
    let out = report(name, ["oracle", "mean", "zhang", "default"], &res);
    if temp_slope_pm > 0.0 {
        let n = (10 * SAMPLES) as f64;
        println!(
            "    (systematic error carried, RMS: the oracle's weighted chips {:.5}, the median chip the calibration aligns with {:.5})",
            (carried[0] / n).sqrt(),
            (carried[1] / n).sqrt()
        );
    }
    (name.to_string(), out, true)
}

/// Heterogeneous arrays N = 2…8 under a 30 °/s, 1 Hz sway with scale
/// errors in ±1 %; common-mode vibration; temperature ramps.
pub fn array_classes(seed: u64) -> Vec<ClassResult> {
    println!("\n(k) heterogeneous arrays, vibration, temperature ramps, 10 seeds x {SAMPLES} samples (RMS mean +- sd)");
    let sway = |k: usize| 30.0 * (2.0 * std::f32::consts::PI * k as f32 / FS).sin();
    let mut out = Vec::new();
    macro_rules! hetero {
        ($($n:literal),*) => {$(
            out.push(class_n::<$n>(
                &format!("(k) N = {}: mixed noise (1-5x), scale errors in +-1 %, 30 deg/s 1 Hz sway", $n),
                seed, true, 0.01, 0.0, &sway,
            ));
        )*};
    }
    hetero!(2, 3, 4, 5, 6, 7, 8);
    let vib = |k: usize| {
        let t = k as f32 / FS;
        20.0 * (2.0 * std::f32::consts::PI * t).sin()
            + 3.0 * (2.0 * std::f32::consts::PI * 180.0 * t).sin()
    };
    out.push(class_n::<4>(
        "(k) common-mode vibration: 3 deg/s at 180 Hz on a 20 deg/s 1 Hz sway, N = 4, scale errors in +-1 %",
        seed,
        false,
        0.01,
        0.0,
        &vib,
    ));
    out.push(class_n::<4>(
        "(k) temperature ramp 20 -> 60 C, bias slopes in +-0.02 deg/s/C, N = 4, 30 deg/s sway",
        seed,
        false,
        0.01,
        0.02,
        &sway,
    ));
    out.push(class_n::<4>(
        "(k) temperature ramp 20 -> 60 C behind the static calibration's bias model (residual slopes in +-0.0005 deg/s/C), N = 4, 30 deg/s sway",
        seed,
        false,
        0.01,
        0.0005,
        &sway,
    ));
    out.push(class_n::<6>(
        "(k) temperature ramp 20 -> 60 C, bias slopes in +-0.02 deg/s/C, N = 6 mixed, 30 deg/s sway",
        seed,
        true,
        0.01,
        0.02,
        &sway,
    ));
    out
}

/// A board-level result: name, worst |fused − truth| where a healthy
/// majority exists, RMS there, and whether the check applies (a healthy
/// majority on some axis).
pub type BoardResult = (String, f64, f64);

/// The whole emulated board (4 ICM-42688-P, an ADXRS453 on z) booting
/// with the faults `faults` present from power-up, under a 20 °/s 1 Hz
/// sway from power-up, through the start-up self-test, then 3000 samples
/// of the pipeline; 10 seeds. On each axis where more chips are healthy
/// than faulty the fused rate is compared with the truth from the first
/// sample (a chip that failed start-up counts as faulty on its axes).
fn board_faults(name: &str, seed: u64, faults: [Fault; 5]) -> BoardResult {
    let mut worst = 0.0f64;
    let (mut se, mut n) = (0.0f64, 0u64);
    let mut held = 0u64;
    for s in 0..10u64 {
        let profile = RateProfile {
            base_dps: [0.0; 3],
            sine_dps: [20.0, 15.0, 20.0],
            sine_hz: 1.0,
            sine_start_s: 0.0,
        };
        let on_axis = |chip: usize, a: usize| chip < 4 || a == 2;
        let bad = |chip: usize| faults[chip] != Fault::None;
        let majority = [0, 1, 2].map(|a| {
            let (mut h, mut f) = (0, 0);
            for c in (0..5).filter(|&c| on_axis(c, a)) {
                if bad(c) {
                    f += 1;
                } else {
                    h += 1;
                }
            }
            h > f
        });
        run_board_array_with(
            profile,
            seed * 1000 + s,
            3000,
            faults,
            Some(20),
            |_, bus, out, _| {
                let truth =
                    gyro_sim::with_bus(bus, |b| b.chips[0].true_rate_dps()).unwrap_or([0.0; 3]);
                for a in 0..3 {
                    if !majority[a] {
                        continue;
                    }
                    match out.fused[a] {
                        Some(f) if !f.fallback => {
                            let e = (f.rate_dps - truth[a]) as f64;
                            worst = worst.max(e.abs());
                            se += e * e;
                            n += 1;
                        }
                        // No output, or a held one: counted, and its error too.
                        Some(f) => {
                            held += 1;
                            worst = worst.max(((f.rate_dps - truth[a]) as f64).abs());
                        }
                        None => held += 1,
                    }
                }
            },
        )
        .expect("the pipeline builds");
    }
    let rms = (se / n.max(1) as f64).sqrt();
    println!("  {name}: worst {worst:.3} deg/s, RMS {rms:.4} deg/s over {n} axis-samples with a healthy majority ({held} held or missing)");
    (name.to_string(), worst, rms)
}

/// Faults present at power-up, one chip and two of five.
pub fn board_fault_classes(seed: u64) -> Vec<BoardResult> {
    println!("\n(l) the emulated board, faults present at power-up, 20 deg/s 1 Hz sway from power-up, 10 seeds x 3000 samples");
    let spikes = Fault::Spikes {
        prob: 0.05,
        magnitude_dps: 200.0,
    };
    let bits = Fault::BitErrors { prob: 0.01 };
    let n = Fault::None;
    let cases: [(&str, [Fault; 5]); 8] = [
        (
            "(l) gyro 1 spikes +-200 deg/s from power-up",
            [n, spikes, n, n, n],
        ),
        (
            "(l) gyro 1 byte bit errors from power-up",
            [n, bits, n, n, n],
        ),
        ("(l) gyro 2 stuck from power-up", [n, n, Fault::Stuck, n, n]),
        (
            "(l) gyro 3 saturated from power-up",
            [n, n, n, Fault::Saturated, n],
        ),
        ("(l) ADXRS453 bit errors from power-up", [n, n, n, n, bits]),
        (
            "(l) two of five: gyro 1 spikes, ADXRS453 bit errors",
            [n, spikes, n, n, bits],
        ),
        (
            "(l) two of five: gyro 0 stuck, gyro 2 spikes",
            [Fault::Stuck, n, spikes, n, n],
        ),
        (
            "(l) two of five: gyro 1 bit errors, gyro 3 spikes",
            [n, bits, n, spikes, n],
        ),
    ];
    cases
        .iter()
        .map(|(name, f)| board_faults(name, seed, *f))
        .collect()
}

/// Motion during boot: the board boots while it sways at 20 °/s on every
/// axis at 0.2, 0.5, 1, 2 and 5 Hz, 10 seeds each: how many healthy chips
/// fail start-up, and the fused RMS error over the first 2 s.
pub fn boot_classes(seed: u64) -> Vec<(String, u32, u32, f64)> {
    println!("\n(m) motion during boot: 20 deg/s sway on every axis, 10 seeds each, start-up self-test then 2000 samples");
    let mut out = Vec::new();
    for hz in [0.2f32, 0.5, 1.0, 2.0, 5.0] {
        let (mut failed, mut chips) = (0u32, 0u32);
        let (mut se, mut n) = (0.0f64, 0u64);
        for s in 0..10u64 {
            let profile = RateProfile {
                base_dps: [0.0; 3],
                sine_dps: [20.0; 3],
                sine_hz: hz,
                sine_start_s: 0.0,
            };
            let f = run_board_array_with(
                profile,
                seed * 1000 + 50 + s,
                2000,
                [Fault::None; 5],
                Some(20),
                |_, bus, out, _| {
                    let truth =
                        gyro_sim::with_bus(bus, |b| b.chips[0].true_rate_dps()).unwrap_or([0.0; 3]);
                    for a in 0..3 {
                        if let Some(f) = out.fused[a] {
                            se += ((f.rate_dps - truth[a]) as f64).powi(2);
                            n += 1;
                        }
                    }
                },
            )
            .expect("the pipeline builds");
            failed += f.count_ones();
            chips += 5;
        }
        let rms = (se / n.max(1) as f64).sqrt();
        let name = format!("(m) boot under a 20 deg/s {hz} Hz sway");
        println!("  {name}: {failed} of {chips} healthy chips failed start-up; fused RMS {rms:.4} deg/s over the first 2 s");
        out.push((name, failed, chips, rms));
    }
    out
}

/// A stuck chip in arrays of N = 2…8 (the default path: relative
/// calibration and adaptive fusion, priors set): chip 0 holds its last
/// reading from 5 s under a 20 °/s 1 Hz sway, 10 seeds. Returns per N the
/// worst number of samples until its weight is 0, and how many samples
/// after that it had weight again while still stuck (summed over seeds).
pub fn stuck_classes(seed: u64) -> Vec<(usize, usize, u32)> {
    println!(
        "\n(n) a chip stuck from 5 s, N = 2..8, 20 deg/s 1 Hz sway, 10 seeds x {SAMPLES} samples"
    );
    let mut out = Vec::new();
    macro_rules! each {
        ($($n:literal),*) => {$( out.push(stuck_n::<$n>(seed)); )*};
    }
    each!(2, 3, 4, 5, 6, 7, 8);
    for (n, worst, back) in &out {
        println!("  N = {n}: out after at most {worst} samples; weight again while stuck: {back} samples");
    }
    out
}

fn stuck_n<const N: usize>(seed: u64) -> (usize, usize, u32) {
    let mask = ((1u16 << N) - 1) as u8;
    let (mut worst, mut back) = (0usize, 0u32);
    for s in 0..10u64 {
        let mut rng = Rng::new(seed * 1000 + 800 + 13 * N as u64 + s);
        let params = [NoiseParams::ICM42688; N];
        let mut noise = [AxisNoise::default(); N];
        let f = method::<N>("adaptive");
        let mut st = AxisState::<N>::default();
        st.set_noise_priors([Some(params[0].white_sigma_dps(FS)); N]);
        let mut cal = RelCal::<N>::new(CalConfig::default());
        let (mut held, mut out_at) = (0.0f32, None);
        for k in 0..SAMPLES {
            let t = 20.0 * (2.0 * std::f32::consts::PI * k as f32 / FS).sin();
            let mut y = [0.0f32; N];
            for i in 0..N {
                y[i] = quantise(noise[i].step(&params[i], &mut rng, t, 1.0 / FS), LSB) as f32 / LSB;
            }
            if k == 5000 {
                held = y[0];
            }
            if k >= 5000 {
                y[0] = held;
            }
            let r = cal.fuse(&f, &mut st, &y, mask).expect("valid input");
            if k >= 5000 {
                match out_at {
                    None if r.weights[0] == 0.0 => out_at = Some(k - 5000),
                    Some(_) if r.weights[0] > 0.0 => back += 1,
                    _ => {}
                }
            }
        }
        worst = worst.max(out_at.unwrap_or(SAMPLES));
    }
    (N, worst, back)
}

/// Seed 001 on the array: each chip a local Kalman
/// filter of rate and bias, fused by the seed's entropy weights or by
/// covariance weights, with the fused rate fed back (`algo::mixture::
/// ChipFilters`), next to the mean, the oracle and the default path; four
/// ICM-42688-P (one 5× noisier in the second case) at rest and under a
/// 30 °/s 1 Hz sway, 10 seeds. Reported, no target: it is the seed's
/// method, measured.
pub fn seed001_classes(seed: u64) -> Vec<(String, [f64; 5])> {
    use gyro_array::algo::mixture::{ChipFilters, ChipWeights};
    println!("\n(o) seed 001 on the array: local rate+bias filters fused by entropy or covariance weights, 10 seeds x {SAMPLES} samples (RMS mean +- sd)");
    let mut out = Vec::new();
    for (noisy, nname) in [(false, "four equal chips"), (true, "chip 3 5x noisier")] {
        for (amp, mname) in [(0.0f32, "at rest"), (30.0, "30 deg/s 1 Hz sway")] {
            let name = format!("(o) {nname}, {mname}");
            let mut res = vec![Vec::new(); 5];
            for s in 0..10u64 {
                let mut rng = Rng::new(seed * 1000 + 600 + s);
                let mut params = [NoiseParams::ICM42688; 4];
                if noisy {
                    params[3].arw_deg_rt_h *= 5.0;
                }
                let sig = params.map(|p| p.white_sigma_dps(FS));
                let w = sig.map(|s| 1.0 / (s as f64 * s as f64));
                let ws: f64 = w.iter().sum();
                let mut noise = [AxisNoise::default(); 4];
                let (mean, adaptive) = (method::<4>("mean"), method::<4>("adaptive"));
                let mut st = [AxisState::<4>::default(); 2];
                st[1].set_noise_priors(sig.map(Some));
                let mut cal = RelCal::<4>::new(CalConfig::default());
                let mut ent =
                    ChipFilters::<4>::new(sig, 6.3, 1e-4, ChipWeights::Entropy).expect("valid");
                let mut cov =
                    ChipFilters::<4>::new(sig, 6.3, 1e-4, ChipWeights::Covariance).expect("valid");
                let mut sums = [0.0f64; 5];
                for k in 0..SAMPLES {
                    let t = amp * (2.0 * std::f32::consts::PI * k as f32 / FS).sin();
                    let y = [0, 1, 2, 3].map(|i| {
                        quantise(noise[i].step(&params[i], &mut rng, t, 1.0 / FS), LSB) as f32 / LSB
                    });
                    let o: f64 = (0..4).map(|i| w[i] * y[i] as f64).sum::<f64>() / ws;
                    sums[0] += (o - t as f64).powi(2);
                    let r = mean.fuse(&mut st[0], &y, 0b1111).expect("valid");
                    sums[1] += ((r.rate_dps - t) as f64).powi(2);
                    let r = cal.fuse(&adaptive, &mut st[1], &y, 0b1111).expect("valid");
                    sums[2] += ((r.rate_dps - t) as f64).powi(2);
                    let e = ent.fuse(&y, 0b1111).map_or(f32::NAN, |v| v.0);
                    sums[3] += ((e - t) as f64).powi(2);
                    let c = cov.fuse(&y, 0b1111).map_or(f32::NAN, |v| v.0);
                    sums[4] += ((c - t) as f64).powi(2);
                }
                for (r, s) in res.iter_mut().zip(sums) {
                    r.push((s / SAMPLES as f64).sqrt());
                }
            }
            let m5 = report(
                &name,
                [
                    "oracle",
                    "mean",
                    "default",
                    "seed 001 entropy",
                    "seed 001 covariance",
                ],
                &res,
            );
            out.push((name, m5));
        }
    }
    out
}
