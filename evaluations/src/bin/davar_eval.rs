//! E-DAVAR evaluation over scenario classes and the paper's
//! experiment (seed 000: Tan, Wang and Zhu, 2017, its simulation).
//!
//! `cargo run -p evaluations --profile host --bin davar-eval -- [--seeds N] [--first-seed S] [--csv PATH] [--other-lambdas] [--lsb S] [--only NAME] [--p-fa P] [--sweep [--hops PATH]]`
//!
//! Every class is run over N seeds (20 by default). The error is the RMS of
//! σ²(τ0) against the true local Allan variance at τ0, over the times every
//! method has an estimate for ([λ2/2, n − λ2/2) of the class's λ2). Each
//! estimate describes its own time t (one per 32-sample hop); a time between
//! hops is scored with the nearest estimate. Methods: fixed windows of λ1, λ2
//! and their midpoint; the paper's E-DAVAR (centred, spectral entropy,
//! E0 = 0.2, ΔL = 64); the centred window with our temporal entropy and an
//! automatic threshold; and the default, the segmented window. Where the
//! class has steps, an oracle that knows the true change points (same
//! window limits, f64 from the samples) shows what any detector could
//! reach; on every class a second oracle picks, at each t, the length of
//! the window centred on t with the least expected error given the true
//! σ² profile: what any bias–variance choice of a centred window (ICI,
//! Lepski) could reach. On the slow ramps it is the fixed λ2 window
//! (0.996 and 1.000 of it over 2000 and 8000 samples): there no window
//! within λ1…λ2 beats λ2 by the 8 % the target asks. Two soft-placement
//! rows (f64, not shipped: [`soft_average`]) average the windows of every
//! single-change model by its posterior odds instead of choosing one.
//!
//! Targets ([`target`]): never worse than the best fixed window (ratio
//! ≤ 1.00 within the sampling error, two standard errors of the mean
//! per-seed ratio) on every class; ≤ 0.95 on ×1.5 steps; ≤ 0.70 on the
//! paper's experiment; the ×2–×4 steps and the changes every 300–400
//! samples no worse than the figures [`TODAY`] records (within the same
//! sampling error); and the window shortened on ≤ 5 % of the hops on
//! stationary input. The RMS carries its seed-to-seed sd; the ratio's sd
//! is that of the per-seed ratios.
//!
//! The paper experiment's window-length trace (seed 1) is written to
//! `target/davar-trace.csv`.

use gyro_array::algo::davar::{
    Davar, DavarConfig, EntropyKind, Placement, StepMode, Threshold, SEG,
};
use gyro_sim::Rng;
use std::fmt::Write as _;
use std::process::ExitCode;

type D = Davar<2048, 67, 8>;
/// Integer resolution of the generated signals, in units of the classes'
/// base σ (1/1024 unless `--lsb`).
static LSB: std::sync::OnceLock<f64> = std::sync::OnceLock::new();
fn lsb() -> f64 {
    *LSB.get_or_init(|| 1.0 / 1024.0)
}

/// What rounding to the LSB adds to σ²_A(τ0): a uniform error of variance
/// LSB²/12 in each sample, independent of the next (the signals move by
/// many LSB a sample), so ½E[(e₁ − e₀)²] = LSB²/12.
fn rounding() -> f64 {
    lsb() * lsb() / 12.0
}

#[derive(Clone, Copy)]
enum Kind {
    Step,
    Ramp,
    Repeated,
    Stationary,
    Paper,
}

/// A signal and its true σ²(τ0) per sample.
type Signal = (Vec<i32>, Vec<f64>);

/// A scenario class: a generator of signals by seed.
struct Class {
    name: String,
    kind: Kind,
    lambda: (u16, u16),
    n: usize,
    gen: Box<dyn Fn(u64) -> Signal>,
    /// True change points, where the class has steps (for the oracle).
    changes: Option<Vec<usize>>,
}

/// White noise with variance v(t): truth σ²_A(τ0) = (v(t) + v(t+1))/2.
fn white_class(n: usize, v: impl Fn(usize) -> f64 + 'static) -> impl Fn(u64) -> Signal {
    move |seed| {
        let mut rng = Rng::new(seed);
        let w = (0..n)
            .map(|t| (v(t).sqrt() * rng.gaussian() as f64 / lsb()).round() as i32)
            .collect();
        let truth = (0..n)
            .map(|t| 0.5 * (v(t) + v(t + 1)) + rounding())
            .collect();
        (w, truth)
    }
}

/// Stationary white noise of unit variance with heavy tails: Student's t
/// with `dof` (> 4) degrees of freedom, z/√(χ²/dof) scaled by
/// √((dof − 2)/dof). Its squares vary more than a Gaussian's (kurtosis
/// 3 + 6/(dof − 4)), so a threshold that assumes Gaussian frames sees
/// changes in it.
fn student_class(n: usize, dof: u32) -> impl Fn(u64) -> Signal {
    move |seed| {
        let mut rng = Rng::new(seed);
        let k = dof as f64;
        let w = (0..n)
            .map(|_| {
                let z = rng.gaussian() as f64;
                let chi2: f64 = (0..dof).map(|_| (rng.gaussian() as f64).powi(2)).sum();
                (z / (chi2 / k).sqrt() * ((k - 2.0) / k).sqrt() / lsb()).round() as i32
            })
            .collect();
        (w, vec![1.0 + rounding(); n])
    }
}

/// Stationary sum of white noise (variance `white`) and AR(1) components
/// (coefficient φ, innovation variance q): truth σ²_A(τ0) = ½E[(y₁ − y₀)²]
/// = white + Σ q/(1 + φ) (each AR(1) has variance q/(1 − φ²) and lag-1
/// covariance φ times that). φ → 1 makes a random walk over the record.
fn coloured_class(n: usize, white: f64, ar: Vec<(f64, f64)>) -> impl Fn(u64) -> Signal {
    let truth_v = white + ar.iter().map(|&(phi, q)| q / (1.0 + phi)).sum::<f64>();
    move |seed| {
        let mut rng = Rng::new(seed);
        let mut state: Vec<f64> = ar
            .iter()
            .map(|&(phi, q)| {
                // Stationary start, except for a random walk (from 0).
                let s = if phi < 0.999 {
                    (q / (1.0 - phi * phi)).sqrt()
                } else {
                    0.0
                };
                s * rng.gaussian() as f64
            })
            .collect();
        let w = (0..n)
            .map(|_| {
                let mut y = white.sqrt() * rng.gaussian() as f64;
                for (x, &(phi, q)) in state.iter_mut().zip(ar.iter()) {
                    *x = phi * *x + q.sqrt() * rng.gaussian() as f64;
                    y += *x;
                }
                (y / lsb()).round() as i32
            })
            .collect();
        (w, vec![truth_v + rounding(); n])
    }
}

/// White noise whose variance steps from 1 to `r` at sample 4000 of 8000.
fn step_class(r: f64, l1: u16, l2: u16) -> Class {
    let n = 8000;
    Class {
        name: format!("step ×{r}, λ {l1}/{l2}"),
        kind: Kind::Step,
        lambda: (l1, l2),
        n,
        gen: Box::new(white_class(n, move |t| if t < 4000 { 1.0 } else { r })),
        changes: Some(vec![4000]),
    }
}

/// White noise whose variance ramps from 1 to 3 over `len` samples from
/// sample 4000, with 4000 steady samples after.
fn ramp_class(len: usize, l1: u16, l2: u16) -> Class {
    ramp_to(3.0, len, l1, l2)
}

/// White noise whose variance ramps from 1 to `r` over `len` samples from
/// sample 4000, with 4000 steady samples after.
fn ramp_to(r: f64, len: usize, l1: u16, l2: u16) -> Class {
    let n = 4000 + len + 4000;
    Class {
        name: format!("ramp 1→{r} over {len}, λ {l1}/{l2}"),
        kind: Kind::Ramp,
        lambda: (l1, l2),
        n,
        gen: Box::new(white_class(n, move |t| {
            1.0 + (r - 1.0) * ((t as f64 - 4000.0) / len as f64).clamp(0.0, 1.0)
        })),
        changes: None,
    }
}

/// The λ pairs the sweep runs (`--sweep`): the paper's 400/800, the
/// board's 512/1024, and pairs on either side of them.
const SWEEP_LAMBDAS: [(u16, u16); 5] = [
    (200, 1000),
    (256, 1024),
    (400, 800),
    (512, 1024),
    (128, 2048),
];

/// `--sweep`: every ramp and step class at every λ pair of
/// [`SWEEP_LAMBDAS`]; the default against the best fixed window of λ1,
/// the midpoint and λ2, per seed; the worst class per pair.
fn sweep(args: &Args) -> ExitCode {
    let first = args.first_seed.unwrap_or_else(|| {
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(1, |d| d.as_secs() % 1_000_000)
    });
    let seeds = args.seeds;
    println!("E-DAVAR λ sweep: seeds {first}..{}, default ÷ best fixed window of λ1, midpoint, λ2 (mean of per-seed ratios over the mean; ± two standard errors)", first + seeds);
    let mut all_ok = true;
    let mut all_hops = String::from("class,seed,t,window,err2_default,err2_lambda2\n");
    for &(l1, l2) in &SWEEP_LAMBDAS {
        let mut classes = Vec::new();
        for r in [1.5, 2.0, 4.0] {
            for len in [l1 as usize, l2 as usize, 4 * l2 as usize] {
                classes.push(ramp_to(r, len, l1, l2));
            }
        }
        for r in [1.5, 2.0, 4.0, 0.5, 0.25] {
            classes.push(step_class(r, l1, l2));
        }
        classes.retain(|c| {
            args.only
                .as_ref()
                .is_none_or(|o| c.name.contains(o.as_str()))
        });
        if classes.is_empty() {
            continue;
        }
        let ms = methods(l1, l2, args.p_fa);
        // The three fixed windows and the default (the last).
        let picks = [0, 1, 2, ms.len() - 1];
        let mut worst: Option<(String, f64, f64)> = None;
        let mut steps = Vec::new();
        let mut hop_rows = String::new();
        println!(
            "
λ {l1}/{l2}"
        );
        for class in &classes {
            let (a, b) = (l2 as usize / 2 + SEG, class.n - l2 as usize / 2 - SEG);
            let mut errs = vec![Vec::new(); picks.len()];
            let mut short = 0.0;
            for seed in first..first + seeds {
                let (w, truth) = (class.gen)(seed * 7919 + class.n as u64);
                for (k, &i) in picks.iter().enumerate() {
                    let r = run(ms[i].1, &w);
                    errs[k].push(rms(&r, &truth, a, b));
                    if args.hops.is_some() && k == picks.len() - 1 {
                        let fixed = run(ms[2].1, &w);
                        for (h, f) in r.hops.iter().zip(&fixed.hops) {
                            if (a..b).contains(&h.0) {
                                let tv = truth[h.0];
                                let _ = writeln!(
                                    hop_rows,
                                    "{},{seed},{},{},{:e},{:e}",
                                    class.name.replace(',', ";"),
                                    h.0 as i64 - 4000,
                                    h.2,
                                    (h.1 - tv).powi(2),
                                    (f.1 - tv).powi(2)
                                );
                            }
                        }
                    }
                    if k == picks.len() - 1 {
                        let full = (l2 as usize / SEG * SEG) as u16;
                        short += r.hops.iter().filter(|h| h.2 < full).count() as f64
                            / r.hops.len() as f64
                            / seeds as f64;
                    }
                }
            }
            let best = (0..3)
                .min_by(|&x, &y| mean_sd(&errs[x]).0.total_cmp(&mean_sd(&errs[y]).0))
                .unwrap_or(0);
            let ratio = mean_sd(&errs[3]).0 / mean_sd(&errs[best]).0;
            let per_seed: Vec<f64> = errs[3]
                .iter()
                .zip(&errs[best])
                .map(|(x, y)| x / y)
                .collect();
            let se2 = 2.0 * mean_sd(&per_seed).1 / (per_seed.len() as f64).sqrt();
            let harm = ratio > 1.0 + se2;
            println!(
                "  {:<34} best {:<11} {ratio:>7.4} ± {se2:.4}  shortened {:>5.1} % {}",
                class.name,
                ms[picks[best]].0,
                100.0 * short,
                if harm { " ABOVE 1" } else { "" }
            );
            all_ok &= !harm;
            if worst.as_ref().is_none_or(|w| ratio - se2 > w.1 - w.2) {
                worst = Some((class.name.clone(), ratio, se2));
            }
            if matches!(class.kind, Kind::Step) {
                steps.push((class.name.clone(), ratio, se2));
            }
        }
        if let Some((name, r, se2)) = worst {
            println!("  worst: {name}: {r:.4} ± {se2:.4}");
        }
        all_hops.push_str(&hop_rows);
        // Where a short window has room to gain: ×2 ≤ 0.87, ×4 ≤ 0.70.
        if l2 >= 4 * l1 {
            for (name, r, _) in &steps {
                let goal = if name.starts_with("step ×2,") {
                    Some(0.87)
                } else if name.starts_with("step ×4,") {
                    Some(0.70)
                } else {
                    None
                };
                if let Some(g) = goal {
                    let met = *r <= g;
                    all_ok &= met;
                    println!(
                        "  target {name} ≤ {g}: {r:.4} {}",
                        if met { "met" } else { "NOT met" }
                    );
                }
            }
        }
    }
    if let Some(path) = &args.hops {
        match std::fs::write(path, &all_hops) {
            Ok(()) => println!("\nevery scored hop written to {path}"),
            Err(e) => eprintln!("davar-eval: cannot write {path}: {e}"),
        }
    }
    println!(
        "
λ sweep: {}",
        if all_ok {
            "no class above the best fixed window, step targets met"
        } else {
            "targets NOT all met"
        }
    );
    if all_ok {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}

/// Ramps and steps at other λ than the standard classes (`--other-lambdas`).
fn other_lambdas() -> Vec<Class> {
    let mut v = Vec::new();
    for &(len, l1, l2) in &[
        (2000usize, 512u16, 1024u16),
        (4000, 512, 1024),
        (1000, 256, 1024),
        (500, 256, 512),
        (300, 256, 512),
    ] {
        v.push(ramp_class(len, l1, l2));
    }
    for &(r, l1, l2) in &[
        (1.5f64, 512u16, 1024u16),
        (2.0, 512, 1024),
        (4.0, 512, 1024),
        (0.5, 512, 1024),
        (0.25, 512, 1024),
        (2.0, 256, 512),
        (3.0, 256, 1024),
        (8.0, 256, 1024),
    ] {
        v.push(step_class(r, l1, l2));
    }
    v
}

fn classes() -> Vec<Class> {
    let mut v = Vec::new();
    for &(l1, l2) in &[(256u16, 1024u16), (400, 800)] {
        for &r in &[1.5f64, 2.0, 4.0] {
            v.push(step_class(r, l1, l2));
        }
    }
    // The last at the board's λ (λ1 = λ2/2, forced by its 9 τ).
    for &(len, l1) in &[(500usize, 256u16), (2000, 256), (8000, 256), (1000, 512)] {
        v.push(ramp_class(len, l1, 1024));
    }
    for &(l1, l2, every) in &[
        (400u16, 800u16, 300usize),
        (512, 1024, 400),
        (256, 1024, 200),
    ] {
        let n = 12000;
        v.push(Class {
            name: format!("steps 1/3 every {every}, λ {l1}/{l2}"),
            kind: Kind::Repeated,
            lambda: (l1, l2),
            n,
            gen: Box::new(white_class(
                n,
                move |t| if (t / every) % 2 == 0 { 1.0 } else { 3.0 },
            )),
            changes: Some((1..n / every + 1).map(|i| i * every).collect()),
        });
    }
    let n = 40000;
    v.push(Class {
        name: "stationary white".into(),
        kind: Kind::Stationary,
        lambda: (256, 1024),
        n,
        gen: Box::new(white_class(n, |_| 1.0)),
        changes: Some(vec![]),
    });
    // Flicker: AR(1) components one per octave of time constant, equal
    // variance per octave (a 1/f spectrum from 2 to 4096 samples).
    let flicker: Vec<(f64, f64)> = (1..=12)
        .map(|k| {
            let phi = 1.0 - 1.0 / (1u32 << k) as f64;
            (phi, 0.25 * (1.0 - phi * phi))
        })
        .collect();
    v.push(Class {
        name: "stationary flicker + white".into(),
        kind: Kind::Stationary,
        lambda: (256, 1024),
        n,
        gen: Box::new(coloured_class(n, 0.3, flicker)),
        changes: Some(vec![]),
    });
    v.push(Class {
        name: "stationary random walk + white".into(),
        kind: Kind::Stationary,
        lambda: (256, 1024),
        n,
        gen: Box::new(coloured_class(n, 0.3, vec![(1.0 - 1e-9, 0.7)])),
        changes: Some(vec![]),
    });
    v.push(Class {
        name: "stationary heavy-tailed white (Student t, 5 dof)".into(),
        kind: Kind::Stationary,
        lambda: (256, 1024),
        n,
        gen: Box::new(student_class(n, 5)),
        changes: Some(vec![]),
    });
    v.push(Class {
        name: "paper: 6000 s, σ² 1/3/1, λ 400/800".into(),
        kind: Kind::Paper,
        lambda: (400, 800),
        n: 6000,
        gen: Box::new(white_class(6000, |t| {
            if (1500..4500).contains(&t) {
                3.0
            } else {
                1.0
            }
        })),
        changes: Some(vec![1500, 4500]),
    });
    v
}

fn methods(l1: u16, l2: u16, p_fa: Option<f32>) -> Vec<(String, DavarConfig)> {
    let mid = ((l1 as u32 + l2 as u32) / 2) as u16;
    let centred = |entropy, threshold| DavarConfig {
        lambda1: l1,
        lambda2: l2,
        l_init: l2,
        delta_l: 64,
        step: StepMode::Constant,
        entropy,
        threshold,
        placement: Placement::Centred,
        tau_octaves: 1,
    };
    vec![
        (format!("fixed {l1}"), DavarConfig::fixed(l1)),
        (format!("fixed {mid}"), DavarConfig::fixed(mid)),
        (format!("fixed {l2}"), DavarConfig::fixed(l2)),
        (
            "paper (spectral, E0=0.2)".into(),
            centred(EntropyKind::Spectral, Threshold::Fixed(0.2)),
        ),
        (
            "centred temporal, auto".into(),
            centred(EntropyKind::Temporal, Threshold::Auto { p_fa: 0.01 }),
        ),
        match p_fa {
            None => ("segmented (default)".into(), DavarConfig::segmented(l1, l2)),
            Some(p) => (
                format!("segmented, p_fa {p}"),
                DavarConfig {
                    threshold: Threshold::Auto { p_fa: p },
                    ..DavarConfig::segmented(l1, l2)
                },
            ),
        },
    ]
}

/// Penalties of the soft-placement reference rows, in units of the
/// segmentation's β.
const SOFT_SCALES: [f64; 2] = [1.0, 1.5];

/// The default's ratio on the classes whose target is "no worse than
/// today" (20 seeds from seed 1, the defaults of this tool), as it stood
/// when the no-harm targets were set.
const TODAY: [(&str, f64); 6] = [
    ("step ×2, λ 256/1024", 0.836),
    ("step ×2, λ 400/800", 0.847),
    ("step ×4, λ 256/1024", 0.710),
    ("step ×4, λ 400/800", 0.604),
    ("steps 1/3 every 300, λ 400/800", 0.891),
    ("steps 1/3 every 400, λ 512/1024", 0.816),
];

/// A class's target for the default's ratio to the best fixed window, and
/// its wording; the sampling error is added where the target is "no
/// worse" than a reference.
fn target(class: &Class) -> (f64, bool, String) {
    if let Some(&(_, t)) = TODAY.iter().find(|(n, _)| *n == class.name) {
        return (t, true, format!("no worse than today's {t:.3}"));
    }
    match class.kind {
        Kind::Paper => (0.70, false, "≤ 0.70".into()),
        Kind::Step if class.name.starts_with("step ×1.5,") => (0.95, false, "≤ 0.95".into()),
        _ => (1.00, true, "≤ 1.00 (no harm)".into()),
    }
}

/// Estimates of one run: per published hop, (t, σ²(τ0), window length).
struct Run {
    hops: Vec<(usize, f64, u16)>,
}

fn run(cfg: DavarConfig, w: &[i32]) -> Run {
    match D::new(cfg) {
        Ok(d) => run_on(d, w),
        // λ1 < 256 cannot hold τ = 128's terms: seven octaves there (only
        // σ²(τ0) is scored).
        Err(gyro_array::algo::davar::DavarError::Capacity) => {
            run_on(Davar::<2048, 67, 7>::new(cfg).expect("valid config"), w)
        }
        Err(e) => panic!("configuration refused: {e:?}"),
    }
}

fn run_on<const C: usize, const F: usize, const T: usize>(mut d: Davar<C, F, T>, w: &[i32]) -> Run {
    let mut hops = Vec::new();
    for &x in w {
        if d.push(x).expect("in range").is_some() {
            let s = d.estimate().expect("published");
            hops.push((s.t as usize, s.avar[0] as f64 * lsb() * lsb(), s.len));
        }
    }
    Run { hops }
}

/// σ²(τ0) of the samples [s, e), in f64 straight from them (the oracles).
fn avar_tau0(w: &[i32], s: usize, e: usize) -> f64 {
    let d2: f64 = (s..e - 1)
        .map(|i| {
            let d = (w[i + 1] - w[i]) as f64;
            d * d
        })
        .sum();
    0.5 * d2 / (e - s - 1) as f64 * lsb() * lsb()
}

/// The oracle: at each hop time of `like`, the window is the true segment
/// that holds t inside the λ2 span (frame-aligned as the estimator's), or
/// the λ1 window nearest to it when the segment is shorter; σ²(τ0) is
/// computed in f64 straight from the samples. What a perfect change
/// detector would get with the same window limits.
fn oracle(like: &Run, w: &[i32], changes: &[usize], l1: u16, l2: u16) -> Run {
    let seg = SEG;
    let k = l2 as usize / seg * seg; // span, samples
    let min = (l1 as usize).div_ceil(seg).min(k / seg) * seg;
    let hops = like
        .hops
        .iter()
        .map(|&(t, _, _)| {
            let (lo, hi) = (t - k / 2, t - k / 2 + k);
            let s = changes
                .iter()
                .filter(|&&c| c <= t)
                .max()
                .map_or(lo, |&c| c.max(lo));
            let e = changes
                .iter()
                .filter(|&&c| c > t)
                .min()
                .map_or(hi, |&c| c.min(hi));
            let (mut s, mut e) = (s, e);
            if e - s < min {
                // Centre the λ1 window on the segment, inside the span.
                let mid = (s + e) / 2;
                s = mid.saturating_sub(min / 2).clamp(lo, hi - min);
                e = s + min;
            }
            (t, avar_tau0(w, s, e), (e - s) as u16)
        })
        .collect();
    Run { hops }
}

/// The centred oracle: at each hop time of `like`, the window centred on
/// t (whole frames, λ1 ≤ L ≤ λ2) whose expected squared error is least
/// given the true σ²(τ0) profile: the bias² of the window's mean truth
/// against the truth at t, plus the variance 3·mean(truth²)/L of a mean of
/// squared first differences (lag-1 correlation of the squares ¼, white
/// noise). σ²(τ0) is then computed from the samples, as in [`oracle`].
/// What any selector of a centred window's length could reach (it cannot
/// know the bias better than the truth does): a bound for gradual changes.
fn oracle_centred(like: &Run, w: &[i32], truth: &[f64], l1: u16, l2: u16) -> Run {
    let seg = SEG;
    let k = l2 as usize / seg; // span, frames
    let min = (l1 as usize).div_ceil(seg).min(k);
    let hops = like
        .hops
        .iter()
        .map(|&(t, _, _)| {
            let mut best = (f64::INFINITY, t, t);
            // Lengths of the span's parity, so the window is centred on t.
            for f in (min..=k).filter(|f| (k - f).is_multiple_of(2)) {
                let (s, e) = (t - f * seg / 2, t + f * seg / 2);
                let span = &truth[s..e - 1];
                let n = span.len() as f64;
                let mean = span.iter().sum::<f64>() / n;
                let mean_sq = span.iter().map(|v| v * v).sum::<f64>() / n;
                let mse = (mean - truth[t]).powi(2) + 3.0 * mean_sq / n;
                if mse < best.0 {
                    best = (mse, s, e);
                }
            }
            let (_, s, e) = best;
            (t, avar_tau0(w, s, e), (e - s) as u16)
        })
        .collect();
    Run { hops }
}

/// Soft placement (f64 reference, not shipped): at each hop time of
/// `like`, instead of choosing one window, average the estimates of the
/// models "no change in the span" (the whole λ2 span) and "one change at
/// frame c" (t's side of c, widened to λ1), each weighted by its posterior
/// odds exp((D_c − β')/2), where D_c is the change's Gamma deviance over
/// the span's τ0 frame energies (the segmentation's cost, ν from the
/// span's lag correlations) and β' = `scale` × the segmentation's
/// penalty β. A weak step then moves the estimate part of the way instead
/// of all or nothing; the price is that stationary noise always moves it
/// a little. What it reaches shows where the detection limit leaves a
/// window chooser (docs/davar.md).
fn soft_average(like: &Run, w: &[i32], l1: u16, l2: u16, scale: f64) -> Run {
    let k = l2 as usize / SEG; // span, frames
    let k = k / 2 * 2;
    let min = (l1 as usize).div_ceil(SEG).min(k);
    let beta = scale
        * gyro_array::algo::stats::chi2_quantile(1.0 - 0.01 / (k as f64 - 1.0), 1.0)
            .unwrap_or(10.0);
    let hops = like
        .hops
        .iter()
        .map(|&(t, _, _)| {
            let s0 = t - k * SEG / 2;
            let d = |i: usize| (w[i + 1] - w[i]) as f64;
            // Frame energies (first differences starting in each frame).
            let x: Vec<f64> = (0..k)
                .map(|f| {
                    (s0 + f * SEG..s0 + (f + 1) * SEG)
                        .map(|i| d(i) * d(i))
                        .sum()
                })
                .collect();
            // ν from the span's lag-1 and lag-2 correlations of d.
            let lag =
                |h: usize| -> f64 { (s0..s0 + k * SEG - h).map(|i| d(i) * d(i + h)).sum::<f64>() };
            let (r0, r1, r2) = (lag(0).max(1.0), lag(1), lag(2));
            let (p1, p2) = (r1 / r0, r2 / r0);
            let nu = 1024.0 / (32.0 + 62.0 * p1 * p1 + 60.0 * p2 * p2);
            let cost = |sum: f64, n: usize| nu * n as f64 * (sum.max(1.0) / n as f64).ln();
            let total: f64 = x.iter().sum();
            let c0 = cost(total, k);
            let win = |a: usize, b: usize| avar_tau0(w, s0 + a * SEG, s0 + b * SEG);
            let (mut num, mut den) = (win(0, k), 1.0);
            let mut left = 0.0;
            for c in 1..k {
                left += x[c - 1];
                let dev = c0 - cost(left, c) - cost(total - left, k - c);
                let odds = ((dev - beta) / 2.0).exp();
                let (a, b) = if k / 2 < c {
                    (0, c.max(min))
                } else {
                    (c.min(k - min), k)
                };
                num += odds * win(a, b);
                den += odds;
            }
            (t, num / den, k as u16)
        })
        .collect();
    Run { hops }
}

/// RMS error over [a, b), each t scored with the nearest hop.
fn rms(r: &Run, truth: &[f64], a: usize, b: usize) -> f64 {
    let mut se = 0.0;
    let mut i = 0;
    for (t, &tv) in truth.iter().enumerate().take(b).skip(a) {
        while i + 1 < r.hops.len() && r.hops[i + 1].0.abs_diff(t) <= r.hops[i].0.abs_diff(t) {
            i += 1;
        }
        let e = r.hops[i].1 - tv;
        se += e * e;
    }
    (se / (b - a) as f64).sqrt()
}

/// One oracle's row: its RMS (mean ± sd over seeds) and its ratio to the
/// best fixed window's (with the sd of the per-seed ratios).
fn oracle_row(name: &str, errs: &[f64], best: &[f64]) {
    let (m, sd) = mean_sd(errs);
    let ratios: Vec<f64> = errs.iter().zip(best).map(|(x, y)| x / y).collect();
    let (_, rs) = mean_sd(&ratios);
    println!(
        "  {name:<26} {m:>9.4} ± {sd:<6.4} {:>8.3} ± {rs:<5.3}",
        m / mean_sd(best).0
    );
}

fn mean_sd(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let s = (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0).max(1.0)).sqrt();
    (m, s)
}

/// E-DAVAR over the scenario classes and the paper's experiment.
#[derive(clap::Parser)]
#[command(name = "davar-eval")]
struct Args {
    /// Seeds per class (at least 2: the tables print seed-to-seed sd).
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u64).range(2..))]
    seeds: u64,
    /// First seed of each class's run (seeds S..S+N; the trace is of S; default 1, or the clock with `--sweep`).
    #[arg(long)]
    first_seed: Option<u64>,
    /// Where the paper experiment's window trace goes (default
    /// target/davar-trace.csv).
    #[arg(long)]
    csv: Option<String>,
    /// Run the classes at other λ instead (ramps and steps at the board's
    /// 512/1024, at 256/512 and 256/1024): a check away from the standard
    /// own classes.
    #[arg(long)]
    other_lambdas: bool,
    /// Quantisation step of the generated signals in units of the
    /// classes' base σ (default 1/1024). `--lsb 1` runs every class at about
    /// one LSB of noise, as a raw log of a gyro at a wide range reads: the
    /// rounding is then a good part of each frame's energy, and the truth
    /// carries its LSB²/12.
    #[arg(long, value_parser = host_tests::args::positive)]
    lsb: Option<f64>,
    /// The λ sweep instead of the classes: ramps from 1 to ×1.5, ×2 and ×4
    /// over λ1, λ2 and 4λ2 samples and steps of ×1.5, ×2, ×4, ×0.5 and
    /// ×0.25 at λ 200/1000, 256/1024, 400/800, 512/1024 and 128/2048, on a
    /// seed block taken from the clock unless `--first-seed` is given;
    /// prints the worst class per λ pair.
    #[arg(long)]
    sweep: bool,
    /// Run only the classes whose name holds this text (as printed, e.g.
    /// `"ramp 1→3 over 1000"` or `"every 200"`).
    #[arg(long)]
    only: Option<String>,
    /// The segmentation's false-alarm probability per hop in place of the
    /// default's 1 % (its threshold β follows): the detector's operating
    /// curve, weak changes found against stationary windows shortened.
    #[arg(long, value_parser = probability)]
    p_fa: Option<f32>,
    /// With `--sweep`: every scored hop of the default and of the fixed λ2
    /// window as CSV rows (class, seed, t from the change's start, the
    /// default's window, its squared error and λ2's): where a class's
    /// ratio comes from.
    #[arg(long)]
    hops: Option<String>,
}

fn probability(s: &str) -> Result<f32, String> {
    match s.parse::<f32>() {
        Ok(v) if v > 0.0 && v < 1.0 => Ok(v),
        _ => Err(format!("{s}: not a probability in (0, 1)")),
    }
}

fn main() -> ExitCode {
    gyro_tool::pipe::quiet_on_closed_pipe();
    let args = <Args as clap::Parser>::parse();
    if let Some(l) = args.lsb {
        let _ = LSB.set(l);
    }
    if args.sweep {
        return sweep(&args);
    }
    let seeds = args.seeds;
    println!(
        "E-DAVAR classes: RMS error of σ²(τ0) against the true local value, {seeds} seeds each \
         (mean ± sd); ratio = method ÷ best fixed window, per seed"
    );
    let mut all_met = true;
    let (mut losing, mut n_classes) = (Vec::<String>::new(), 0usize);
    let mut trace = String::from("method,t,window_len,avar_tau1,truth\n");
    for class in if args.other_lambdas {
        other_lambdas()
    } else {
        classes()
    }
    .into_iter()
    .filter(|c| {
        args.only
            .as_ref()
            .is_none_or(|o| c.name.contains(o.as_str()))
    }) {
        let (l1, l2) = class.lambda;
        let ms = methods(l1, l2, args.p_fa);
        let (a, b) = (l2 as usize / 2 + SEG, class.n - l2 as usize / 2 - SEG);
        // errs[method][seed], short[method] (fraction of hops shortened).
        let mut errs = vec![Vec::new(); ms.len()];
        let mut short = vec![0.0f64; ms.len()];
        let mut oracle_errs = Vec::new();
        let mut centred_errs = Vec::new();
        let mut soft_errs = [Vec::new(), Vec::new()];
        let first_seed = args.first_seed.unwrap_or(1);
        for seed in first_seed..first_seed + seeds {
            let (w, truth) = (class.gen)(seed * 7919 + class.n as u64);
            for (i, (name, cfg)) in ms.iter().enumerate() {
                let r = run(*cfg, &w);
                errs[i].push(rms(&r, &truth, a, b));
                if let (Some(ch), true) = (&class.changes, i == ms.len() - 1) {
                    oracle_errs.push(rms(&oracle(&r, &w, ch, l1, l2), &truth, a, b));
                }
                if i == ms.len() - 1 {
                    let c = oracle_centred(&r, &w, &truth, l1, l2);
                    centred_errs.push(rms(&c, &truth, a, b));
                    for (e, scale) in soft_errs.iter_mut().zip(SOFT_SCALES) {
                        e.push(rms(&soft_average(&r, &w, l1, l2, scale), &truth, a, b));
                    }
                }
                let full = (l2 as usize / SEG * SEG) as u16;
                short[i] += r.hops.iter().filter(|h| h.2 < full).count() as f64
                    / r.hops.len() as f64
                    / seeds as f64;
                if seed == first_seed && matches!(class.kind, Kind::Paper) {
                    for &(t, v, len) in &r.hops {
                        let _ = writeln!(trace, "{name},{t},{len},{v},{}", truth[t]);
                    }
                }
            }
        }
        // Best fixed window: the lowest mean RMS of the three.
        let best = (0..3)
            .min_by(|&x, &y| mean_sd(&errs[x]).0.total_cmp(&mean_sd(&errs[y]).0))
            .unwrap_or(0);
        println!("\n{}  (best fixed: {})", class.name, ms[best].0);
        println!(
            "  {:<26} {:>18} {:>16} {:>10}",
            "method", "RMS σ²(τ0)", "÷ best fixed", "shortened"
        );
        for (i, (name, _)) in ms.iter().enumerate() {
            let (m, s) = mean_sd(&errs[i]);
            let ratios: Vec<f64> = errs[i]
                .iter()
                .zip(&errs[best])
                .map(|(x, y)| x / y)
                .collect();
            let (rm, rs) = mean_sd(&ratios);
            println!(
                "  {name:<26} {m:>9.4} ± {s:<6.4} {:>8.3} ± {rs:<5.3} {:>9.1} %",
                m / mean_sd(&errs[best]).0,
                100.0 * short[i]
            );
            let _ = rm;
        }
        if !oracle_errs.is_empty() {
            oracle_row("(oracle: true changes)", &oracle_errs, &errs[best]);
        }
        oracle_row("(oracle: centred length)", &centred_errs, &errs[best]);
        for (e, scale) in soft_errs.iter().zip(SOFT_SCALES) {
            oracle_row(&format!("(soft average, β' = {scale}β)"), e, &errs[best]);
        }
        let d = ms.len() - 1;
        let ratio = mean_sd(&errs[d]).0 / mean_sd(&errs[best]).0;
        // Against the simple method a user could have picked (the best
        // fixed window): a loss beyond the sampling error, two standard
        // errors of the mean per-seed ratio.
        let per_seed: Vec<f64> = errs[d]
            .iter()
            .zip(&errs[best])
            .map(|(x, y)| x / y)
            .collect();
        let se = mean_sd(&per_seed).1 / (per_seed.len().max(1) as f64).sqrt();
        let loses = ratio > 1.0 + 2.0 * se;
        if loses {
            losing.push(format!("{}: {ratio:.4}", class.name));
        }
        let (goal, with_error, what) = target(&class);
        let met = ratio <= goal + if with_error { 2.0 * se } else { 0.0 };
        all_met &= met;
        n_classes += 1;
        print!(
            "  target: default {what} × best fixed: {ratio:.4} {}; against the best fixed window {} (its sampling error ±{:.4})",
            if met { "met" } else { "NOT met" },
            if loses { "LOSES" } else { "no worse" },
            2.0 * se
        );
        if matches!(class.kind, Kind::Stationary) {
            let ok = short[d] <= 0.05;
            all_met &= ok;
            print!(
                "; shortened ≤ 5 %: {:.1} % {}",
                100.0 * short[d],
                if ok { "met" } else { "NOT met" }
            );
        }
        println!();
    }
    let path = args.csv.unwrap_or_else(|| {
        concat!(env!("CARGO_MANIFEST_DIR"), "/../target/davar-trace.csv").to_string()
    });
    match std::fs::write(&path, trace) {
        Ok(()) => println!(
            "\npaper experiment, seed {}: window trace written to {path}",
            args.first_seed.unwrap_or(1)
        ),
        Err(e) => eprintln!("davar-eval: cannot write {path}: {e}"),
    }
    println!(
        "all davar-eval targets: {}; {} of {n_classes} classes lose to the best fixed window beyond their sampling error{}",
        if all_met { "met" } else { "NOT all met" },
        losing.len(),
        if losing.is_empty() {
            String::new()
        } else {
            format!(" ({})", losing.join("; "))
        }
    );
    ExitCode::SUCCESS
}
