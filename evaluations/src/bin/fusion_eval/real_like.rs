//! The classes of `fusion-eval` built from what real arrays show and the
//! project's other classes do not: chips that see their own vibration (a
//! flexing frame, each chip's own resonance), turn-on offsets up to
//! ±5 °/s, unequal noise, scale differences of a few per cent and timing
//! skew between chips. Each runs the firmware's default path as `gyro
//! replay` does (`gyro_tool::replay`: relative calibration, then adaptive
//! fusion) and is judged twice: against the truth it was made from, and
//! without it, as a real log is (`gyro_tool::assess`: leave-one-out, the
//! weights' spread, and on the static rig the Allan ratios and the noise
//! probe).

use gyro_sim::Rng;
use gyro_tool::{assess, replay};

/// One class's result over its seeds.
pub struct RealLike {
    pub name: String,
    /// RMS error against the truth (each series' mean out: the relative
    /// calibration aligns the chips with their average, whose offset no
    /// array can see): fused, plain mean, weights by the true noise.
    pub fused: f64,
    pub mean: f64,
    pub oracle: f64,
    /// Leave-one-out over the plain mean's: the firmware fusing the
    /// others, the whole fusion's weights renormalised over the others
    /// (`assess::LooChip::own`), and fixed inverse-variance weights (root
    /// of summed squares over seeds).
    pub loo: f64,
    pub own: f64,
    pub fixed_iv: f64,
    /// Worst share of samples with one chip above 0.9 of the weight.
    pub one_chip: f64,
    /// On the static rig: the worst fused / plain mean Allan deviation at
    /// τ = 1…64 samples, and the probe / fused range.
    pub adev: Option<(f64, f64, f64)>,
}

/// A resonance at a frequency drawn in 0.1–0.3 cycles per sample, of RMS
/// `amp`: an AR(2) driven by white noise, pole radius 0.97 (a quality
/// factor of about 10 at 150 Hz of 1 kHz), scaled to its RMS over the run.
fn resonance(rng: &mut Rng, n: usize, amp: f64) -> Vec<f64> {
    let f = u(rng, 0.1, 0.3);
    let r = 0.97f64;
    let (a1, a2) = (2.0 * r * (2.0 * std::f64::consts::PI * f).cos(), -r * r);
    let (mut x1, mut x2) = (0.0, 0.0);
    let mut out: Vec<f64> = (0..n + 200)
        .map(|_| {
            let x = a1 * x1 + a2 * x2 + f64::from(rng.gaussian());
            (x2, x1) = (x1, x);
            x
        })
        .skip(200)
        .collect();
    let rms = (out.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
    for v in &mut out {
        *v *= amp / rms;
    }
    out
}

fn u(rng: &mut Rng, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * f64::from(rng.uniform())
}

/// Truth-free and truth-based figures of one log.
struct One {
    fused: f64,
    mean: f64,
    oracle: f64,
    loo: [f64; 4],
    one_chip: f64,
    adev: Option<(f64, f64, f64)>,
}

fn judge(chips: &[Vec<f64>], truth: &[f64], sigma: &[f64], tau0: f64) -> One {
    let k = chips.len();
    let n = truth.len();
    let r = replay::replay(chips).expect("a replayable log");
    let a = assess::assess(chips, &r, tau0).expect("assessed");
    let mean: Vec<f64> = (0..n)
        .map(|i| chips.iter().map(|c| c[i]).sum::<f64>() / k as f64)
        .collect();
    let w: Vec<f64> = sigma.iter().map(|s| 1.0 / (s * s)).collect();
    let ws: f64 = w.iter().sum();
    let oracle: Vec<f64> = (0..n)
        .map(|i| chips.iter().zip(&w).map(|(c, w)| w * c[i]).sum::<f64>() / ws)
        .collect();
    let sq = |f: &dyn Fn(&assess::LooChip) -> f64| a.loo.iter().map(|c| f(c).powi(2)).sum::<f64>();
    let adev = (!a.static_points.is_empty()).then(|| {
        let worst = a
            .static_points
            .iter()
            .map(|p| p.fused_over_mean)
            .fold(0.0, f64::max);
        let lo = a
            .static_points
            .iter()
            .map(|p| p.probe_over_fused)
            .fold(f64::MAX, f64::min);
        let hi = a
            .static_points
            .iter()
            .map(|p| p.probe_over_fused)
            .fold(0.0, f64::max);
        (worst, lo, hi)
    });
    One {
        fused: assess::rms_demeaned(&r.fused, truth),
        mean: assess::rms_demeaned(&mean, truth),
        oracle: assess::rms_demeaned(&oracle, truth),
        loo: [
            sq(&|c| c.fused),
            sq(&|c| c.mean),
            sq(&|c| c.fixed_iv),
            sq(&|c| c.own),
        ],
        one_chip: a.one_chip_share,
        adev,
    }
}

fn pool(name: String, ones: &[One]) -> RealLike {
    let m = ones.len() as f64;
    let avg = |f: &dyn Fn(&One) -> f64| ones.iter().map(f).sum::<f64>() / m;
    let sum = |j: usize| ones.iter().map(|o| o.loo[j]).sum::<f64>();
    let adev = ones
        .iter()
        .filter_map(|o| o.adev)
        .fold(None, |acc, (w, lo, hi)| {
            Some(match acc {
                None => (w, lo, hi),
                Some((aw, alo, ahi)) => (f64::max(aw, w), f64::min(alo, lo), f64::max(ahi, hi)),
            })
        });
    RealLike {
        name,
        fused: avg(&|o| o.fused),
        mean: avg(&|o| o.mean),
        oracle: avg(&|o| o.oracle),
        loo: (sum(0) / sum(1)).sqrt(),
        fixed_iv: (sum(2) / sum(1)).sqrt(),
        own: (sum(3) / sum(1)).sqrt(),
        one_chip: ones.iter().map(|o| o.one_chip).fold(0.0, f64::max),
        adev,
    }
}

/// A static rig of `K` chips at 120 Hz for 120 s (the held-out rig's
/// shape): turn-on offsets in ±5 °/s, white noise 1–3× 0.05 °/s (a
/// consumer MEMS part at 120 Hz), each bias wandering as a random walk.
fn static_rig(seed: u64, k: usize) -> RealLike {
    let n = 14_400;
    let ones: Vec<One> = (0..5u64)
        .map(|s| {
            let mut rng = Rng::new(seed * 7919 + 31 * k as u64 + s);
            let sigma: Vec<f64> = (0..k).map(|_| 0.05 * u(&mut rng, 1.0, 3.0)).collect();
            let truth = vec![0.004; n];
            let chips: Vec<Vec<f64>> = sigma
                .iter()
                .map(|&sg| {
                    let b0 = u(&mut rng, -5.0, 5.0);
                    let mut walk = 0.0;
                    (0..n)
                        .map(|i| {
                            walk += 2e-4 * f64::from(rng.gaussian());
                            truth[i] + b0 + walk + sg * f64::from(rng.gaussian())
                        })
                        .collect()
                })
                .collect();
            if let Some(d) = std::env::var_os("DUMP") {
                let mut w = String::from("t");
                for c in 0..k {
                    w += &format!(",c{}", c + 1);
                }
                w += "\n";
                for i in 0..n {
                    w += &format!("{}", i as f64 / 120.0);
                    for c in &chips {
                        w += &format!(",{}", c[i]);
                    }
                    w += "\n";
                }
                std::fs::write(
                    std::path::Path::new(&d).join(format!("static{k}_{s}.csv")),
                    w,
                )
                .unwrap();
            }
            judge(&chips, &truth, &sigma, 1.0 / 120.0)
        })
        .collect();
    pool(
        format!("(r) static rig, {k} chips at 120 Hz: offsets in +-5 deg/s, noise 1-3x"),
        &ones,
    )
}

/// How the chips' vibration is shared.
#[derive(Clone, Copy)]
enum Frame {
    /// Each chip its own resonance, 2–4 °/s.
    Own,
    /// Two arms: chips 0 and 1 share one arm's resonance, 2 and 3 the
    /// other's (3 °/s), plus 1 °/s of each chip's own.
    Flexing,
    /// Each its own, one chip on a loose mount at 3× the others'.
    Loose,
}

/// Four chips at 1 kHz on a vehicle: a 30 °/s 1 Hz sway and a turn to
/// 100 °/s, each chip's offset in ±5 °/s, scale error in ±3 %, white noise
/// 1–3× the ICM-42688-P's, its vibration as `frame`, and a timing skew in
/// 0–300 µs (the motion it sees is that long late). The truth is the
/// common motion.
fn vehicle(seed: u64, frame: Frame, name: &str) -> RealLike {
    let (n, fs) = (20_000usize, 1000.0f64);
    let k = 4;
    let motion = |t: f64| {
        let turn = if (5.0..15.0).contains(&t) {
            100.0 * (std::f64::consts::PI * (t - 5.0) / 10.0).sin()
        } else {
            0.0
        };
        30.0 * (2.0 * std::f64::consts::PI * t).sin() + turn
    };
    let ones: Vec<One> = (0..5u64)
        .map(|s| {
            let mut rng = Rng::new(seed * 104_729 + 977 * frame as u64 + s);
            let truth: Vec<f64> = (0..n).map(|i| motion(i as f64 / fs)).collect();
            let arms = [resonance(&mut rng, n, 3.0), resonance(&mut rng, n, 3.0)];
            let mut sigma = Vec::new();
            let chips: Vec<Vec<f64>> = (0..k)
                .map(|c| {
                    let white = 0.089 * u(&mut rng, 1.0, 3.0);
                    let (b0, scale) = (u(&mut rng, -5.0, 5.0), 1.0 + u(&mut rng, -0.03, 0.03));
                    let skew = u(&mut rng, 0.0, 300e-6);
                    let own_amp = match frame {
                        Frame::Own => u(&mut rng, 2.0, 4.0),
                        Frame::Flexing => 1.0,
                        Frame::Loose => {
                            if c == 0 {
                                9.0
                            } else {
                                3.0
                            }
                        }
                    };
                    let own = resonance(&mut rng, n, own_amp);
                    let shared = match frame {
                        Frame::Flexing => Some(&arms[c / 2]),
                        _ => None,
                    };
                    let var = white * white
                        + own_amp * own_amp
                        + if shared.is_some() { 9.0 } else { 0.0 };
                    sigma.push(var.sqrt());
                    (0..n)
                        .map(|i| {
                            let t = i as f64 / fs - skew;
                            scale * motion(t)
                                + b0
                                + own[i]
                                + shared.map_or(0.0, |a| a[i])
                                + white * f64::from(rng.gaussian())
                        })
                        .collect()
                })
                .collect();
            judge(&chips, &truth, &sigma, 1.0 / fs)
        })
        .collect();
    pool(name.to_string(), &ones)
}

/// Every class of this file, printed as it runs.
pub fn real_like_classes(seed: u64) -> Vec<RealLike> {
    println!(
        "\n(r)-(u) what real arrays show: 5 seeds each, the default path as gyro replay runs it"
    );
    let out = vec![
        static_rig(seed, 8),
        static_rig(seed, 4),
        vehicle(
            seed,
            Frame::Own,
            "(s) vehicle, 4 chips: own vibration 2-4 deg/s, offsets +-5, scale +-3 %, skew 0-300 us",
        ),
        vehicle(
            seed,
            Frame::Flexing,
            "(t) flexing frame, 4 chips: two arms' vibration shared by pairs, offsets, scale, skew",
        ),
        vehicle(
            seed,
            Frame::Loose,
            "(u) one chip on a loose mount (3x the others' vibration), offsets, scale, skew",
        ),
    ];
    for c in &out {
        println!("  {}", c.name);
        println!(
            "    truth RMS: fused {:.5}, mean {:.5}, true-noise weights {:.5}; leave-one-out {:.3}x the mean (the whole fusion's weights {:.3}x, fixed weights {:.3}x); one chip > 0.9 on {:.2} %{}",
            c.fused,
            c.mean,
            c.oracle,
            c.loo,
            c.own,
            c.fixed_iv,
            100.0 * c.one_chip,
            c.adev.map_or(String::new(), |(w, lo, hi)| format!(
                "; Allan fused / mean worst {w:.3} at tau 1-64, probe / fused {lo:.3}-{hi:.3}"
            ))
        );
    }
    out
}
