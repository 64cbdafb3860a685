//! Fusion evaluation harness (seed 004 and ours).
//!
//! `cargo run -p evaluations --profile host --bin fusion-eval -- [SEED]`
//! (a SEED that is not an unsigned integer is an error, not the default)
//!
//! Simulates a 4-gyro array with the emulated ICM-42688-P noise model
//! (ARW, bias instability, rate random walk, 131 LSB/°/s quantisation) at
//! 1 kHz for 20 s per scenario, fuses it with every method and with an
//! oracle that knows each chip's true white-noise variance, and prints mean
//! error, std and RMS error against the true rate.
#![allow(clippy::needless_range_loop)] // scenario indices key the result map too
use clap::Parser;
use gyro_array::algo::fusion::{AxisState, Fusion};
use gyro_sim::checks::methods;
use gyro_sim::noise::{quantise, AxisNoise};
use gyro_sim::{NoiseParams, Rng};

#[path = "fusion_eval/array.rs"]
mod array;
#[path = "fusion_eval/real_like.rs"]
mod real_like;

/// Fusion evaluation over its scenario classes (a)–(m).
#[derive(Parser)]
#[command(name = "fusion-eval")]
struct Cli {
    /// Seed of the scenarios (every class derives its own from it).
    #[arg(default_value_t = 1)]
    seed: u64,
}

const FS: f32 = 1000.0;
const SAMPLES: usize = 20_000;
const LSB: f32 = 131.0;

#[derive(Clone, Copy)]
enum Scenario {
    Equal,
    OneNoisy,
    Spikes,
    Failing,
    Motion(f32),
}

impl Scenario {
    fn name(&self) -> String {
        match self {
            Scenario::Equal => "(a) four equal chips".into(),
            Scenario::OneNoisy => "(b) chip 3 is 5x noisier".into(),
            Scenario::Spikes => "(c) impulsive outliers on chip 1".into(),
            Scenario::Failing => "(d) chip 2 stuck at 5 s, saturated at 10 s".into(),
            Scenario::Motion(r) => format!("(e) Table 1 motion state {r:+} deg/s"),
        }
    }
    fn rate(&self) -> f32 {
        if let Scenario::Motion(r) = self {
            *r
        } else {
            0.0
        }
    }
}

struct Stats {
    n: f64,
    s1: f64,
    s2: f64,
}

impl Stats {
    fn new() -> Self {
        Self {
            n: 0.0,
            s1: 0.0,
            s2: 0.0,
        }
    }
    fn add(&mut self, e: f64) {
        self.n += 1.0;
        self.s1 += e;
        self.s2 += e * e;
    }
    fn mean(&self) -> f64 {
        self.s1 / self.n
    }
    fn std(&self) -> f64 {
        (self.s2 / self.n - self.mean().powi(2)).max(0.0).sqrt()
    }
    fn rms(&self) -> f64 {
        (self.s2 / self.n).sqrt()
    }
}

/// Frames of 4 gyros and the true rate, plus each chip's true white sigma.
fn simulate(sc: Scenario, seed: u64) -> (Vec<[f32; 4]>, f32, [f32; 4]) {
    let mut params = [NoiseParams::ICM42688; 4];
    if let Scenario::OneNoisy = sc {
        params[3].arw_deg_rt_h *= 5.0;
    }
    let mut rng = Rng::new(seed);
    let mut noise = [AxisNoise::default(); 4];
    let truth = sc.rate();
    let mut frames = Vec::with_capacity(SAMPLES);
    let mut stuck = 0.0f32;
    for k in 0..SAMPLES {
        let mut y = [0.0f32; 4];
        for i in 0..4 {
            let mut v = noise[i].step(&params[i], &mut rng, truth, 1.0 / FS);
            if let Scenario::Spikes = sc {
                if i == 1 && rng.uniform() < 0.02 {
                    v += if rng.uniform() < 0.5 { 2.0 } else { -2.0 };
                }
            }
            y[i] = quantise(v, LSB) as f32 / LSB;
        }
        if let Scenario::Failing = sc {
            if k == 5 * FS as usize {
                stuck = y[2];
            }
            if k >= 10 * FS as usize {
                y[2] = i16::MAX as f32 / LSB;
            } else if k >= 5 * FS as usize {
                y[2] = stuck;
            }
        }
        frames.push(y);
    }
    let sig = [0, 1, 2, 3].map(|i| params[i].white_sigma_dps(FS));
    (frames, truth, sig)
}

/// Every method of `checks::methods()` and the pipeline's default path
/// (the online relative calibration, then adaptive fusion) over one
/// realisation of a table class: each one's error statistics and, in (d),
/// the samples from each fault (stuck at 5 s, saturated at 10 s) until the
/// failed chip's weight is 0.
fn run_methods(
    sc: Scenario,
    frames: &[[f32; 4]],
    truth: f32,
) -> Vec<(&'static str, Stats, [Option<usize>; 2])> {
    use gyro_array::algo::calib::{CalConfig, RelCal};
    let mut out = Vec::new();
    let named =
        methods().map(|(name, m)| (name, Fusion::<4>::new(m).expect("valid method"), false));
    let default = ("default", method::<4>("adaptive"), true);
    for (name, f, calibrated) in named.into_iter().chain([default]) {
        let mut st = AxisState::default();
        let mut cal = RelCal::<4>::new(CalConfig::default());
        let mut s = Stats::new();
        let mut first_excluded = [None, None];
        for (k, y) in frames.iter().enumerate() {
            let r = if calibrated {
                cal.fuse(&f, &mut st, y, 0b1111)
            } else {
                f.fuse(&mut st, y, 0b1111)
            }
            .expect("valid input");
            s.add((r.rate_dps - truth) as f64);
            if let Scenario::Failing = sc {
                for (phase, start) in [(0, 5000), (1, 10000)] {
                    if k >= start && first_excluded[phase].is_none() && r.weights[2] == 0.0 {
                        first_excluded[phase] = Some(k - start);
                    }
                }
            }
        }
        out.push((name, s, first_excluded));
    }
    out
}

/// The table classes (a)–(e) again over REALISATIONS runs each, for what a
/// single run cannot settle: the default path against the simple methods
/// and the seed's variant against Zhang. In (d) one run is a draw of luck:
/// the stuck chip holds one noisy sample, and a method that keeps it (Zhang,
/// the seed's) gains or loses by how near the truth that sample fell (its
/// RMS from 5 to 10 s is 0.038–0.066 °/s over seeds 21–40, against 0.044
/// with four live chips). There the simple methods are also run told of the
/// fault (chip 2 masked from 5 s), the reference the default path, which
/// excludes a frozen chip, is held to. Returns per class (name, default,
/// better simple method, seed-scaled, zhang), means over the runs.
fn pooled_classes(scenarios: &[Scenario], seed: u64) -> Vec<(String, f64, f64, f64, f64)> {
    const REALISATIONS: u64 = 10;
    println!("\n(a)-(e) again, {REALISATIONS} realisations x {SAMPLES} samples each (RMS mean +- sd); default = relative calibration + adaptive, the pipeline's path");
    let mut out = Vec::new();
    for (si, sc) in scenarios.iter().enumerate() {
        let mut res = vec![Vec::new(); 6];
        for r in 0..REALISATIONS {
            let (frames, truth, _) = simulate(*sc, seed * 100_000 + 50_000 + si as u64 * 100 + r);
            let runs = run_methods(*sc, &frames, truth);
            let rms = |n: &str| {
                runs.iter()
                    .find(|(name, ..)| *name == n)
                    .map(|(_, s, _)| s.rms())
                    .expect("a method run")
            };
            for (v, x) in res.iter_mut().zip([
                rms("mean"),
                rms("zhang"),
                rms("seed-scaled"),
                rms("default"),
            ]) {
                v.push(x);
            }
            if let Scenario::Failing = sc {
                // Told of the fault: chip 2 out from the sample it froze.
                let [mean, zhang, _] = mean_zhang_adaptive::<4>();
                for (f, v) in [mean, zhang].iter().zip(&mut res[4..]) {
                    let mut st = AxisState::default();
                    let mut s = Stats::new();
                    for (k, y) in frames.iter().enumerate() {
                        let mask = if k >= 5000 { 0b1011 } else { 0b1111 };
                        let r = f.fuse(&mut st, y, mask).expect("valid input");
                        s.add((r.rate_dps - truth) as f64);
                    }
                    v.push(s.rms());
                }
            }
        }
        let labels = ["mean", "zhang", "seed-scaled", "default"];
        let (m, simple) = if let Scenario::Failing = sc {
            let told = [
                "mean",
                "zhang",
                "seed-scaled",
                "default",
                "mean, told the fault",
                "zhang, told the fault",
            ];
            let m = report(&sc.name(), told, &res);
            ([m[0], m[1], m[2], m[3]], m[4].min(m[5]))
        } else {
            let m = report(&sc.name(), labels, &res[..4]);
            (m, m[0].min(m[1]))
        };
        out.push((sc.name(), m[3], simple, m[2], m[1]));
    }
    out
}

/// Mean and sample standard deviation over the seeds.
fn mean_sd(v: &[f64]) -> (f64, f64) {
    let m = v.iter().sum::<f64>() / v.len() as f64;
    let sd = (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt();
    (m, sd)
}

/// The method `name` of `checks::methods()`, for N gyros.
fn method<const N: usize>(name: &str) -> Fusion<N> {
    let m = methods()
        .iter()
        .find(|(n, _)| *n == name)
        .expect("a method of checks::methods")
        .1;
    Fusion::<N>::new(m).expect("valid method")
}

/// Mean, zhang and adaptive, the methods most classes compare.
fn mean_zhang_adaptive<const N: usize>() -> [Fusion<N>; 3] {
    [method("mean"), method("zhang"), method("adaptive")]
}

/// Print a class: `  name:`, then per label the mean ± sd over seeds of
/// its RMS errors `res`; returns the means.
fn report<const K: usize>(name: &str, labels: [&str; K], res: &[Vec<f64>]) -> [f64; K] {
    println!("  {name}:");
    let width = labels
        .iter()
        .map(|l| l.len() + 1)
        .max()
        .unwrap_or(0)
        .max(14);
    let mut out = [0.0; K];
    for ((n, r), o) in labels.iter().zip(res).zip(out.iter_mut()) {
        let (m, sd) = mean_sd(r);
        *o = m;
        println!("    {n:<width$} {m:>10.5} +- {sd:.5}");
    }
    out
}

/// Class (f): a 95 °/s, 2 Hz sway with per-chip scale errors
/// (drawn in ±1 %, and the worst pattern +1/−1/+1/−1 %), 10 seeds × 20 000
/// samples each. Prints mean ± sd of the RMS error of the oracle (true
/// noise, blind to scale errors), the mean, zhang, adaptive, and adaptive
/// behind the online relative calibration (`algo::calib`). Returns per
/// pattern (name, calibrated, oracle, mean) means.
fn scale_class(seed: u64) -> Vec<(String, f64, f64, f64)> {
    use gyro_array::algo::calib::{CalConfig, RelCal};
    let mut out = Vec::new();
    println!("\n(f) 95 deg/s 2 Hz sway, per-chip scale errors, 10 seeds x {SAMPLES} samples (RMS mean +- sd)");
    for pattern in ["drawn in +-1 %", "+1/-1/+1/-1 %"] {
        let names = ["oracle", "mean", "zhang", "adaptive", "adaptive+cal"];
        let mut res = vec![Vec::new(); names.len()];
        for s in 0..10u64 {
            let mut rng = Rng::new(seed * 1000 + 500 + s);
            let mut params = [NoiseParams::ICM42688; 4];
            for (i, p) in params.iter_mut().enumerate() {
                p.scale_error = if pattern.starts_with("drawn") {
                    0.02 * rng.uniform() - 0.01
                } else if i % 2 == 0 {
                    0.01
                } else {
                    -0.01
                };
            }
            let sig = [0, 1, 2, 3].map(|i| params[i].white_sigma_dps(FS) as f64);
            let w: Vec<f64> = sig.iter().map(|s| 1.0 / (s * s)).collect();
            let ws: f64 = w.iter().sum();
            let mut noise = [AxisNoise::default(); 4];
            let fusers = mean_zhang_adaptive::<4>();
            let adaptive = *fusers.last().expect("adaptive");
            let mut states = vec![AxisState::<4>::default(); fusers.len() + 1];
            let mut cal = RelCal::<4>::new(CalConfig::default());
            let mut sums = vec![0.0f64; names.len()];
            for k in 0..SAMPLES {
                let truth = 95.0 * (2.0 * std::f32::consts::PI * 2.0 * k as f32 / FS).sin();
                let y = [0, 1, 2, 3].map(|i| {
                    let v = noise[i].step(&params[i], &mut rng, truth, 1.0 / FS);
                    quantise(v, LSB) as f32 / LSB
                });
                let o: f64 = (0..4).map(|i| w[i] * y[i] as f64).sum::<f64>() / ws;
                sums[0] += (o - truth as f64).powi(2);
                for (j, f) in fusers.iter().enumerate() {
                    let r = f.fuse(&mut states[j], &y, 0b1111).expect("valid input");
                    sums[j + 1] += ((r.rate_dps - truth) as f64).powi(2);
                }
                let last = states.len() - 1;
                let r = cal
                    .fuse(&adaptive, &mut states[last], &y, 0b1111)
                    .expect("valid input");
                sums[4] += ((r.rate_dps - truth) as f64).powi(2);
            }
            for (r, s) in res.iter_mut().zip(&sums) {
                r.push((s / SAMPLES as f64).sqrt());
            }
        }
        let m = report(&format!("scale errors {pattern}"), names, &res);
        out.push((format!("(f) scale errors {pattern}"), m[4], m[0], m[1]));
    }
    out
}

/// One seed of a drift class: four ICM-42688-P under a true rate of `amp`
/// °/s at 1 Hz; from 5 s chip 2's bias ramps at `rate` °/s per s. `fuse`
/// gives per sample the three methods' fused rates and whether the event
/// watched for holds. Returns the time from the drift reaching 3σ of the
/// chip's white noise to the start of the event's last run, s (negative:
/// it began before; infinite: never), and the three methods' RMS errors
/// from 5 s on.
fn drift_seed(
    rng_seed: u64,
    rate: f32,
    amp: f32,
    mut fuse: impl FnMut(&[f32; 4]) -> ([f32; 3], bool),
) -> (f64, [f64; 3]) {
    let mut rng = Rng::new(rng_seed);
    let params = [NoiseParams::ICM42688; 4];
    let sigma = params[2].white_sigma_dps(FS);
    let mut noise = [AxisNoise::default(); 4];
    let mut sums = [0.0f64; 3];
    let (mut reached, mut since) = (None, None::<usize>);
    let start = 5 * FS as usize;
    for k in 0..SAMPLES {
        let t = amp * (2.0 * std::f32::consts::PI * k as f32 / FS).sin();
        let drift = if k >= start {
            rate * (k - start) as f32 / FS
        } else {
            0.0
        };
        if drift >= 3.0 * sigma && reached.is_none() {
            reached = Some(k);
        }
        let y = [0, 1, 2, 3].map(|i| {
            let v =
                noise[i].step(&params[i], &mut rng, t, 1.0 / FS) + if i == 2 { drift } else { 0.0 };
            quantise(v, LSB) as f32 / LSB
        });
        let (rates, event) = fuse(&y);
        if k >= start {
            for (s, r) in sums.iter_mut().zip(rates) {
                *s += ((r - t) as f64).powi(2);
            }
            if event {
                since.get_or_insert(k);
            } else {
                since = None;
            }
        }
    }
    let time = match (reached, since) {
        (Some(r), Some(l)) => (l as f64 - r as f64) / FS as f64,
        _ => f64::INFINITY,
    };
    (time, sums.map(|s| (s / (SAMPLES - start) as f64).sqrt()))
}

/// Class (g): slow bias drift on one chip. Four chips at rest;
/// from 5 s chip 2's bias ramps at `rate` °/s per s. For each of 10 seeds:
/// the time from the drift reaching 3σ of the chip's white noise until
/// adaptive gives it under 5 % of the weight (and keeps it there; 0 if it
/// already had), and the RMS error of mean, zhang and adaptive from 5 s
/// on. Returns (name, worst time in s, adaptive, mean, zhang).
fn drift_class(seed: u64) -> Vec<(String, f64, f64, f64, f64)> {
    let mut out = Vec::new();
    println!("\n(g) slow bias drift on chip 2 from 5 s, 10 seeds x {SAMPLES} samples");
    for rate in [0.02f32, 0.2] {
        let (mut times, mut rms) = (Vec::new(), vec![Vec::new(); 3]);
        for s in 0..10u64 {
            let fusers = mean_zhang_adaptive::<4>();
            let mut states = [AxisState::<4>::default(); 3];
            let (t, r) = drift_seed(seed * 1000 + 700 + s, rate, 0.0, |y| {
                let rs: [_; 3] = core::array::from_fn(|j| {
                    fusers[j]
                        .fuse(&mut states[j], y, 0b1111)
                        .expect("valid input")
                });
                (rs.map(|r| r.rate_dps), rs[2].weights[2] < 0.05)
            });
            times.push(t.max(0.0));
            for (v, x) in rms.iter_mut().zip(r) {
                v.push(x);
            }
        }
        println!(
            "  drift {rate} deg/s per s (3 sigma = {:.3} deg/s):",
            3.0 * NoiseParams::ICM42688.white_sigma_dps(FS)
        );
        out.push(drift_report(
            format!("(g) drift {rate} deg/s per s"),
            "weight < 5 %",
            &times,
            &rms,
            "adaptive",
        ));
    }
    out
}

/// Print a drift class's times from 3σ to `event` (per seed; negative:
/// before) and its RMS errors (mean, zhang, then `last`); (name, worst
/// time, `last`'s RMS, mean's, zhang's).
fn drift_report(
    name: String,
    event: &str,
    times: &[f64],
    rms: &[Vec<f64>],
    last: &str,
) -> (String, f64, f64, f64, f64) {
    let worst = times.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    let (tm, tsd) = mean_sd(times);
    println!("    time from 3 sigma to {event}: {tm:.3} +- {tsd:.3} s, worst {worst:.3} s");
    for (n, r) in ["mean", "zhang", last].iter().zip(rms) {
        let (m, sd) = mean_sd(r);
        println!("    {n:<14} {m:>10.5} +- {sd:.5}");
    }
    (
        name,
        worst,
        mean_sd(&rms[2]).0,
        mean_sd(&rms[0]).0,
        mean_sd(&rms[1]).0,
    )
}

/// Class (g) on the pipeline's default path (the online relative
/// calibration in front of adaptive fusion), at rest and under a 30 °/s,
/// 1 Hz sway: from 5 s chip 2's bias ramps at `rate` °/s per s. Per seed,
/// the time from the drift reaching 3σ of the chip's white noise until
/// the calibration calls it drifting (`RelCal::drifting`, what the
/// pipeline flags) and keeps it so, and the RMS error of mean, zhang and
/// the default from 5 s on. Returns (name, worst time in s, default,
/// mean, zhang).
fn drift_class_calibrated(seed: u64) -> Vec<(String, f64, f64, f64, f64)> {
    use gyro_array::algo::calib::{CalConfig, RelCal};
    let mut out = Vec::new();
    println!("\n(g) slow bias drift on chip 2 from 5 s, the default path (calibration + adaptive), 10 seeds x {SAMPLES} samples");
    for (motion, amp) in [("at rest", 0.0f32), ("30 deg/s 1 Hz sway", 30.0)] {
        for rate in [0.02f32, 0.1, 0.2] {
            let (mut times, mut rms) = (Vec::new(), vec![Vec::new(); 3]);
            for s in 0..10u64 {
                let [mean, zhang, adaptive] = mean_zhang_adaptive::<4>();
                let mut states = [AxisState::<4>::default(); 3];
                let mut cal = RelCal::<4>::new(CalConfig::default());
                let (t, r) = drift_seed(seed * 1000 + 900 + s, rate, amp, |y| {
                    let rs = [
                        mean.fuse(&mut states[0], y, 0b1111),
                        zhang.fuse(&mut states[1], y, 0b1111),
                        cal.fuse(&adaptive, &mut states[2], y, 0b1111),
                    ]
                    .map(|r| r.expect("valid input").rate_dps);
                    (rs, cal.drifting() & (1 << 2) != 0)
                });
                times.push(t);
                for (v, x) in rms.iter_mut().zip(r) {
                    v.push(x);
                }
            }
            let to3 = 3.0 * NoiseParams::ICM42688.white_sigma_dps(FS) / rate;
            println!("  drift {rate} deg/s per s, {motion} (3 sigma {to3:.2} s after it starts):");
            out.push(drift_report(
                format!("(g) drift {rate} deg/s per s, {motion}, default path"),
                "flagged drifting",
                &times,
                &rms,
                "default",
            ));
        }
    }
    out
}

/// Generic 10-seed class over 4 ICM-42688-P: `truth(k)` the true rate,
/// `corrupt(k, rng, y)` changes the readings. RMS mean over seeds of the
/// oracle (true white noise, all chips), mean, zhang and adaptive (+ the
/// online relative calibration when `cal`). Returns the four means.
fn class4(
    name: &str,
    seed: u64,
    scale_pm: f32,
    truth: impl Fn(usize) -> f32,
    mut corrupt: impl FnMut(usize, &mut Rng, &mut [f32; 4]),
) -> ([f64; 4], f64) {
    use gyro_array::algo::calib::{CalConfig, RelCal};
    let mut res = vec![Vec::new(); 4];
    for s in 0..10u64 {
        let mut rng = Rng::new(seed * 1000 + 300 + s);
        let mut params = [NoiseParams::ICM42688; 4];
        for p in params.iter_mut() {
            p.scale_error = scale_pm * (2.0 * rng.uniform() - 1.0);
        }
        let sig = [0, 1, 2, 3].map(|i| params[i].white_sigma_dps(FS) as f64);
        let w = sig.map(|s| 1.0 / (s * s));
        let ws: f64 = w.iter().sum();
        let mut noise = [AxisNoise::default(); 4];
        let fusers = mean_zhang_adaptive::<4>();
        let mut states = vec![AxisState::<4>::default(); 3];
        let mut cal = RelCal::<4>::new(CalConfig::default());
        let mut sums = [0.0f64; 4];
        for k in 0..SAMPLES {
            let t = truth(k);
            let mut y = [0, 1, 2, 3].map(|i| {
                let v = noise[i].step(&params[i], &mut rng, t, 1.0 / FS);
                quantise(v, LSB) as f32 / LSB
            });
            corrupt(k, &mut rng, &mut y);
            let o: f64 = (0..4).map(|i| w[i] * y[i] as f64).sum::<f64>() / ws;
            sums[0] += (o - t as f64).powi(2);
            for j in 0..2 {
                let r = fusers[j]
                    .fuse(&mut states[j], &y, 0b1111)
                    .expect("valid input");
                sums[j + 1] += ((r.rate_dps - t) as f64).powi(2);
            }
            let r = cal
                .fuse(&fusers[2], &mut states[2], &y, 0b1111)
                .expect("valid input");
            sums[3] += ((r.rate_dps - t) as f64).powi(2);
        }
        for (r, s) in res.iter_mut().zip(sums) {
            r.push((s / SAMPLES as f64).sqrt());
        }
    }
    let m = report(name, ["oracle", "mean", "zhang", "adaptive+cal"], &res);
    // The default against the better simple method, paired draw by draw:
    // where each draw has its own scale errors, which no array can observe,
    // a draw's luck (Zhang's weights landing nearer the true scale than the
    // mean) moves the ratio far more than the noise does.
    let better = if m[1] <= m[2] { 1 } else { 2 };
    let d: Vec<f64> = res[3]
        .iter()
        .zip(&res[better])
        .map(|(a, b)| a - b)
        .collect();
    let se = mean_sd(&d).1 / (d.len() as f64).sqrt();
    (m, (1.0 + 2.0 * se / m[better]).max(1.005))
}

/// Class (i): spikes, small (3σ ≈ 0.27 °/s) and large (20 °/s),
/// on one chip and on two (independent, and simultaneous), at 2 % of
/// samples each, at rest and under a 50 °/s 1 Hz sway; and class (j),
/// large motion: sines to 100 °/s at 10 Hz and a vehicle turn (ramp to
/// 100 °/s, hold, back), with per-chip scale errors drawn in ±2 %.
/// Returns (name, [oracle, mean, zhang, adaptive], fault-free, the
/// tolerance of "no worse than the simple methods").
fn more_classes(seed: u64) -> Vec<(String, [f64; 4], bool, f64)> {
    let mut out = Vec::new();
    println!("\n(i) spikes and (j) large motion, 10 seeds x {SAMPLES} samples (RMS mean +- sd)");
    let sway = |k: usize| 50.0 * (2.0 * std::f32::consts::PI * k as f32 / FS).sin();
    for (mag, mname) in [(0.27f32, "3 sigma"), (20.0, "20 deg/s")] {
        for (chips, simultaneous) in [(1usize, false), (2, false), (2, true)] {
            for (moving, tname) in [(false, "at rest"), (true, "50 deg/s sway")] {
                let name = format!(
                    "(i) {mname} spikes on {} chip{}{}, {tname}",
                    chips,
                    if chips > 1 { "s" } else { "" },
                    if simultaneous { " together" } else { "" }
                );
                let r = class4(
                    &name,
                    seed,
                    0.0,
                    |k| if moving { sway(k) } else { 0.0 },
                    |_, rng, y| {
                        let hit = rng.uniform() < 0.02;
                        for c in 0..chips {
                            let on = if simultaneous {
                                hit
                            } else {
                                rng.uniform() < 0.02
                            };
                            if on {
                                y[1 + c] += if rng.uniform() < 0.5 { mag } else { -mag };
                            }
                        }
                    },
                );
                out.push((name, r.0, false, r.1));
            }
        }
    }
    let turn = |k: usize| {
        let t = k as f32 / FS;
        (100.0 * (t - 2.0) / 2.0).clamp(0.0, 100.0) - (100.0 * (t - 12.0) / 2.0).clamp(0.0, 100.0)
    };
    for (name, f) in [
        (
            "(j) 100 deg/s 10 Hz sine, scale errors in +-2 %",
            Box::new(|k: usize| 100.0 * (2.0 * std::f32::consts::PI * 10.0 * k as f32 / FS).sin())
                as Box<dyn Fn(usize) -> f32>,
        ),
        (
            "(j) vehicle turn to 100 deg/s, scale errors in +-2 %",
            Box::new(turn),
        ),
    ] {
        let r = class4(name, seed, 0.02, f, |_, _, _| {});
        out.push((name.to_string(), r.0, true, r.1));
    }
    out
}

/// Class (h): two chips of different noise (an ICM-42688-P and
/// an ADXRS453-like part, σ 5× larger), 10 seeds. Residuals cannot tell two
/// chips apart, so adaptive without priors is the mean; with noise priors
/// (the datasheet σ, or the start-up noise test's) it follows the oracle.
/// Returns (adaptive with priors, oracle, mean, adaptive without).
fn pair_class(seed: u64) -> (f64, f64, f64, f64) {
    println!("\n(h) N = 2: ICM-42688-P + a 5x noisier chip, 10 seeds x {SAMPLES} samples (RMS mean +- sd)");
    let mut res = vec![Vec::new(); 4];
    for s in 0..10u64 {
        let mut rng = Rng::new(seed * 1000 + 900 + s);
        let mut params = [NoiseParams::ICM42688; 2];
        params[1].arw_deg_rt_h *= 5.0;
        let sig = [0, 1].map(|i| params[i].white_sigma_dps(FS));
        let w = sig.map(|s| 1.0 / (s as f64 * s as f64));
        let mut noise = [AxisNoise::default(); 2];
        let f = Fusion::<2>::new(gyro_array::algo::fusion::Method::Adaptive(
            Default::default(),
        ))
        .expect("valid method");
        let mean = Fusion::<2>::new(gyro_array::algo::fusion::Method::Mean).expect("valid method");
        let (mut with, mut without, mut st_mean) = (
            AxisState::<2>::default(),
            AxisState::<2>::default(),
            AxisState::<2>::default(),
        );
        with.set_noise_priors(sig.map(Some));
        let mut sums = [0.0f64; 4];
        for _ in 0..SAMPLES {
            let y = [0, 1].map(|i| {
                let v = noise[i].step(&params[i], &mut rng, 0.0, 1.0 / FS);
                quantise(v, LSB) as f32 / LSB
            });
            let o = (w[0] * y[0] as f64 + w[1] * y[1] as f64) / (w[0] + w[1]);
            let a = f.fuse(&mut with, &y, 0b11).expect("valid").rate_dps as f64;
            let m = mean.fuse(&mut st_mean, &y, 0b11).expect("valid").rate_dps as f64;
            let b = f.fuse(&mut without, &y, 0b11).expect("valid").rate_dps as f64;
            for (s, v) in sums.iter_mut().zip([a, o, m, b]) {
                *s += v * v;
            }
        }
        for (r, s) in res.iter_mut().zip(sums) {
            r.push((s / SAMPLES as f64).sqrt());
        }
    }
    for (n, r) in ["adaptive+priors", "oracle", "mean", "adaptive"]
        .iter()
        .zip(&res)
    {
        let (m, sd) = mean_sd(r);
        println!("    {n:<16} {m:>10.5} +- {sd:.5}");
    }
    (
        mean_sd(&res[0]).0,
        mean_sd(&res[1]).0,
        mean_sd(&res[2]).0,
        mean_sd(&res[3]).0,
    )
}

fn main() {
    gyro_tool::pipe::quiet_on_closed_pipe();
    let seed = Cli::parse().seed;
    println!("fusion-eval: seed {seed}, 4 gyros, {SAMPLES} samples at {FS} Hz per scenario, errors in deg/s");
    let scenarios = [
        Scenario::Equal,
        Scenario::OneNoisy,
        Scenario::Spikes,
        Scenario::Failing,
        Scenario::Motion(95.0),
        Scenario::Motion(-5.0),
        Scenario::Motion(0.0),
    ];
    let mut rms = std::collections::HashMap::new();
    let mut exclusion = Vec::new();
    for (si, sc) in scenarios.iter().enumerate() {
        let (frames, truth, sig) = simulate(*sc, seed * 100 + si as u64);
        println!("\n{}", sc.name());
        println!(
            "{:<14} {:>12} {:>12} {:>12}",
            "method", "mean", "std", "rms err"
        );
        // Oracle: inverse true white-noise variance, all chips.
        let w: Vec<f64> = sig.iter().map(|s| 1.0 / (*s as f64).powi(2)).collect();
        let ws: f64 = w.iter().sum();
        let mut o = Stats::new();
        for y in &frames {
            let x: f64 = (0..4).map(|i| w[i] * y[i] as f64).sum::<f64>() / ws;
            o.add(x - truth as f64);
        }
        println!(
            "{:<14} {:>12.5} {:>12.5} {:>12.5}",
            "oracle",
            o.mean() + truth as f64,
            o.std(),
            o.rms()
        );
        rms.insert((si, "oracle".to_string()), o.rms());
        for (name, s, first_excluded) in run_methods(*sc, &frames, truth) {
            println!(
                "{:<14} {:>12.5} {:>12.5} {:>12.5}",
                name,
                s.mean() + truth as f64,
                s.std(),
                s.rms()
            );
            rms.insert((si, name.to_string()), s.rms());
            if let Scenario::Failing = sc {
                exclusion.push((name, first_excluded));
            }
        }
    }
    let pooled = pooled_classes(&scenarios, seed);
    println!(
        "\n(d) samples from the fault until the failed chip's weight is 0 (stuck, saturated):"
    );
    for (name, e) in &exclusion {
        let f = |v: Option<usize>| v.map_or("never".to_string(), |v| v.to_string());
        println!("  {:<14} {:>6} {:>6}", name, f(e[0]), f(e[1]));
    }
    let motion = scale_class(seed);
    let drift = drift_class(seed);
    let drift_cal = drift_class_calibrated(seed);
    let pair = pair_class(seed);
    let more = more_classes(seed);
    let arrays = array::array_classes(seed);
    let board = array::board_fault_classes(seed);
    let boot = array::boot_classes(seed);
    let stuck = array::stuck_classes(seed);
    let _seed001 = array::seed001_classes(seed);
    let real = real_like::real_like_classes(seed);
    println!("\ntargets:");
    let r = |si: usize, n: &str| rms[&(si, n.to_string())];
    // Per class, the shipped default path's RMS over the better of the
    // simple methods (the mean and Zhang), for the tally in the last line.
    let mut simple: Vec<(String, f64, f64)> = Vec::new();
    let mut all = true;
    let mut target = |what: String, ok: bool| {
        println!("  {} {what}", if ok { "MET    " } else { "NOT MET" });
        all &= ok;
    };
    // The faithful seed method (eq. 3–16) is reported; the seed target is
    // judged on our variant with the running normaliser, which ships next
    // to it. "No worse" allows the RMS's own sampling error, 1/√(2n) = 0.5 %
    // at n = 20 000: the two are then indistinguishable.
    for si in 1..=3 {
        let (f, z) = (r(si, "seed-full"), r(si, "zhang"));
        println!(
            "  {}  {}: faithful seed-full {f:.5} vs zhang {z:.5} (reported, not the shipped variant)",
            if f <= z { "met    " } else { "not met" },
            scenarios[si].name()
        );
    }
    for si in 1..=3 {
        let (s, z, m) = (r(si, "seed-scaled"), r(si, "zhang"), r(si, "mean"));
        let (_, _, _, ps, pz) = &pooled[si];
        println!(
            "  (report) {}: seed-scaled {s:.5} vs zhang {z:.5} in the one run above (ratio {:.4})",
            scenarios[si].name(),
            s / z
        );
        target(
            format!(
                "{}: seed-scaled {ps:.5} <= zhang {pz:.5} over the realisations (ratio {:.4}, tolerance 1.005)",
                scenarios[si].name(),
                ps / pz
            ),
            *ps <= 1.005 * pz,
        );
        target(
            format!("{}: zhang {z:.5} <= mean {m:.5}", scenarios[si].name()),
            z <= m,
        );
    }
    for si in 0..=1 {
        let (a, o) = (r(si, "adaptive"), r(si, "oracle"));
        target(
            format!(
                "{}: adaptive/oracle rms = {:.3} <= 1.15",
                scenarios[si].name(),
                a / o
            ),
            a / o <= 1.15,
        );
    }
    // The table classes, over their realisations; "no worse" allows the
    // RMS's sampling error, as below.
    for (name, default, simple_ref, _, _) in &pooled {
        target(
            format!(
                "{name}: default {default:.5} <= the better of mean and zhang {simple_ref:.5} over the realisations (ratio {:.4}, tolerance 1.005)",
                default / simple_ref
            ),
            *default <= 1.005 * simple_ref,
        );
        simple.push((name.clone(), default / simple_ref, 1.005));
    }
    for (name, cal, oracle, mean) in &motion {
        target(
            format!(
                "{name}: adaptive + relative calibration {cal:.5} <= 1.10 x oracle {oracle:.5}"
            ),
            *cal <= 1.10 * oracle,
        );
        target(
            format!(
                "{name}: adaptive + relative calibration <= mean {mean:.5} (ratio {:.4}, tolerance 1.005)",
                cal / mean
            ),
            *cal <= 1.005 * mean,
        );
        simple.push((name.clone(), cal / mean, 1.005));
    }
    // Sampling error of an RMS over 10 × 20 000 samples: about 1/√(2n)
    // = 0.16 %; "no worse than" allows 0.5 %, or in (i) and (j) twice the
    // paired error over their draws where that is larger (`class4`).
    let arrays_tol = arrays.iter().map(|(n, r, f)| (n.clone(), *r, *f, 1.005));
    for (name, [o, m, z, a], fault_free, tol) in more.iter().cloned().chain(arrays_tol) {
        target(
            format!(
                "{name}: adaptive {a:.5} <= mean {m:.5} and zhang {z:.5} (ratio {:.4}, tolerance {tol:.4})",
                a / m.min(z)
            ),
            a <= tol * m && a <= tol * z,
        );
        simple.push((name.clone(), a / m.min(z), tol));
        if fault_free {
            target(
                format!("{name}: adaptive {a:.5} <= 1.10 x oracle {o:.5}"),
                a <= 1.10 * o,
            );
        }
    }
    let (pa, po, pm, pn) = pair;
    target(
        format!("(h) N = 2 with noise priors: adaptive {pa:.5} <= 1.10 x oracle {po:.5} (mean {pm:.5}, adaptive without priors {pn:.5})"),
        pa <= 1.10 * po,
    );
    for (name, worst, a, m, z) in &drift {
        target(
            format!("{name}: drifting chip under 5 % of the weight within 2 s of reaching 3 sigma (worst {worst:.3} s)"),
            *worst <= 2.0,
        );
        target(
            format!("{name}: adaptive {a:.5} <= mean {m:.5} and zhang {z:.5}"),
            a <= m && a <= z,
        );
    }
    for (name, worst, a, m, z) in &drift_cal {
        // The time target is for drifts of 0.1 °/s per s and more; a slower
        // one is tracked by the calibration (its default RMS is still held
        // to the mean's and Zhang's) and reported.
        if name.contains("drift 0.02 ") {
            println!("  (report) {name}: flagged {worst:.3} s after reaching 3 sigma (worst; inf: not within the run)");
        } else {
            target(
                format!("{name}: drifting chip flagged within 2 s of reaching 3 sigma (worst {worst:+.3} s)"),
                *worst <= 2.0,
            );
        }
        target(
            format!(
                "{name}: default {a:.5} <= mean {m:.5} and zhang {z:.5} (ratio {:.4})",
                a / m.min(*z)
            ),
            a <= m && a <= z,
        );
        simple.push((name.clone(), a / m.min(*z), 1.005));
    }
    for (name, worst, rms) in &board {
        target(
            format!("{name}: fused within 1 deg/s of the truth where a healthy majority exists (worst {worst:.3}, RMS {rms:.4})"),
            *worst <= 1.0,
        );
    }
    for (n, worst, back) in &stuck {
        target(
            format!("(n) N = {n}: stuck chip out within 5 samples ({worst}) and never back while stuck ({back} samples)"),
            *worst <= 5 && *back == 0,
        );
    }
    for (name, failed, chips, _) in &boot {
        target(
            format!("{name}: no healthy chip fails start-up ({failed} of {chips})"),
            *failed == 0,
        );
    }
    // What real arrays show: judged on the truth like the other classes,
    // and as a real log is judged, without it.
    for c in &real {
        target(
            format!(
                "{}: fused {:.5} <= mean {:.5} (ratio {:.4}, tolerance 1.005)",
                c.name,
                c.fused,
                c.mean,
                c.fused / c.mean
            ),
            c.fused <= 1.005 * c.mean,
        );
        simple.push((c.name.clone(), c.fused / c.mean, 1.005));
        // Leave-one-out with the whole fusion's weights over the others:
        // learnt from every chip, as the fixed weights are (the firmware
        // fusing the others has a chip fewer to learn from; printed).
        target(
            format!(
                "{}: leave-one-out, the whole fusion's weights {:.3}x the plain mean's (<= 1.005) and within 3 % of fixed inverse-variance weights' {:.3}x (the firmware fusing the others {:.3}x)",
                c.name, c.own, c.fixed_iv, c.loo
            ),
            c.own <= 1.005 && c.own <= 1.03 * c.fixed_iv,
        );
        target(
            format!(
                "{}: one chip above 0.9 of the weight on {:.2} % of the samples (<= 1 %)",
                c.name,
                100.0 * c.one_chip
            ),
            c.one_chip <= 0.01,
        );
        if let Some((w, lo, hi)) = c.adev {
            target(
                format!(
                    "{}: fused Allan deviation <= 1.02x the plain mean's at tau 1-64 samples (worst {w:.3}); probe within 15 % of the fused rate's ({lo:.3}-{hi:.3})",
                    c.name
                ),
                w <= 1.02 && lo >= 0.85 && hi <= 1.15,
            );
        }
    }
    let (a, o) = (r(2, "adaptive"), r(2, "oracle"));
    target(format!("(c): adaptive {a:.5} < oracle {o:.5}"), a < o);
    if let Some((_, e)) = exclusion.iter().find(|(n, _)| *n == "adaptive") {
        let ok = e.iter().all(|v| v.is_some_and(|v| v <= 10));
        target(
            format!(
                "(d): adaptive excludes the failed chip within 10 samples: {:?}",
                e
            ),
            ok,
        );
    }
    // Losing: beyond the sampling error (the RMS's own, 0.5 %, as the
    // targets; where each draw has its own scale errors, twice the standard
    // error of the paired difference over the draws, if larger).
    let losing: Vec<&(String, f64, f64)> = simple.iter().filter(|(_, q, tol)| q > tol).collect();
    println!(
        "\nthe default path against the better of the mean and Zhang, per class (ratio of RMS; beyond its tolerance loses):"
    );
    for (name, q, tol) in &simple {
        println!(
            "  {q:.4}  {name}{}",
            if *tol > 1.005 {
                format!(" (tolerance {tol:.4})")
            } else {
                String::new()
            }
        );
    }
    println!(
        "\nfusion-eval: {}; {} of {} classes lose to the simple method{}",
        if all {
            "all targets met"
        } else {
            "some targets NOT met"
        },
        losing.len(),
        simple.len(),
        if losing.is_empty() {
            String::new()
        } else {
            format!(
                " ({})",
                losing
                    .iter()
                    .map(|(n, q, _)| format!("{n}: {q:.4}"))
                    .collect::<Vec<_>>()
                    .join("; ")
            )
        }
    );
}
