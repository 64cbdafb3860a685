//! Allan deviation report of a recorded rate log: octave OADEV with 68 %
//! confidence intervals (EDF for the noise type read from the local
//! slope) and the IEEE Std 952 noise terms with their units.
//!
//! `cargo run -p evaluations --profile host --bin allan-report -- FILE TAU0_S`
//! or `-- --demo`
//!
//! FILE holds one rate sample (°/s) per line; TAU0_S, the sample period in
//! seconds, is required with it (finite, > 0, ≤ 1e6). `--demo` runs the
//! report on 4 h at 100 Hz of the emulated ICM-42688-P noise model and
//! compares the terms it reads with the model's settings; it never runs in
//! place of a FILE whose TAU0 is missing (that is a usage error).

use gyro_array::algo::allan::{edf, local_slope, noise_terms, oavar_octave, AdevPoint, NoiseType};
use gyro_sim::noise::AxisNoise;
use gyro_sim::{NoiseParams, Rng};

/// Allan deviation report of a rate log.
#[derive(clap::Parser)]
#[command(name = "allan-report")]
struct Cli {
    /// One rate sample (°/s) per line; `#` comments and blank lines skipped.
    #[arg(required_unless_present = "demo", requires = "tau0")]
    file: Option<String>,
    /// Sample period, seconds.
    #[arg(value_parser = gyro_tool::dev::tau0_arg, requires = "file")]
    tau0: Option<f64>,
    /// Report on the emulated ICM-42688-P instead of a file.
    #[arg(long, conflicts_with_all = ["file", "tau0"])]
    demo: bool,
}

fn main() {
    gyro_tool::pipe::quiet_on_closed_pipe();
    let cli = <Cli as clap::Parser>::parse();
    let (rate, tau0, model) = match (cli.file.as_ref(), cli.tau0) {
        (Some(path), Some(tau0)) => {
            let text = std::fs::read_to_string(path).unwrap_or_else(|e| {
                eprintln!("allan-report: {path}: {e}");
                std::process::exit(2)
            });
            let mut rate = Vec::new();
            for (i, l) in text.lines().enumerate() {
                let l = l.trim();
                if l.is_empty() || l.starts_with('#') {
                    continue;
                }
                match l.parse::<f64>() {
                    Ok(v) if v.is_finite() => rate.push(v),
                    _ => {
                        eprintln!("allan-report: {path}:{}: not a finite number: {l:?}", i + 1);
                        std::process::exit(2)
                    }
                }
            }
            (rate, tau0, None)
        }
        _ => {
            let p = NoiseParams::ICM42688;
            let fs = 100.0f32;
            let n = (4.0 * 3600.0 * fs) as usize;
            let mut rng = Rng::new(2024);
            let mut ax = AxisNoise::default();
            let rate = (0..n)
                .map(|_| ax.step(&p, &mut rng, 0.0, 1.0 / fs) as f64)
                .collect();
            (rate, 1.0 / fs as f64, Some(p))
        }
    };
    if rate.len() < 3 {
        eprintln!("allan-report: need at least 3 samples");
        std::process::exit(2);
    }
    let mut phase = vec![0.0; rate.len() + 1];
    let mut pts = [AdevPoint::default(); 64];
    let count = oavar_octave(&rate, tau0, &mut phase, &mut pts).expect("finite, checked above");
    let pts = &pts[..count];
    println!(
        "{} samples at tau0 = {tau0} s ({:.2} h)",
        rate.len(),
        rate.len() as f64 * tau0 / 3600.0
    );
    println!(
        "{:>12} {:>13} {:>13} {:>13} {:>8} {:>12}",
        "tau (s)", "ADEV (deg/s)", "68% lo", "68% hi", "EDF", "noise"
    );
    for (i, p) in pts.iter().enumerate() {
        let noise = local_slope(pts, i).map_or(NoiseType::WhiteFm, NoiseType::from_adev_slope);
        let e = edf(noise, p.samples + 1, p.m as u64).unwrap_or(f64::NAN);
        let (lo, hi) = p.interval(noise, 0.683).unwrap_or((f64::NAN, f64::NAN));
        println!(
            "{:>12.4} {:>13.6e} {:>13.6e} {:>13.6e} {:>8.1} {:>12}{}",
            p.tau_s,
            p.adev(),
            lo,
            hi,
            e,
            format!("{noise:?}"),
            if p.reliable() {
                ""
            } else {
                "  (< 10 clusters: not used for terms)"
            }
        );
    }
    let mut terms = [None; 5];
    noise_terms(pts, &mut terms);
    println!("IEEE Std 952 terms (read where each asymptote touches the curve):");
    for t in terms.iter().flatten() {
        println!(
            "  {:<17} {:>12.4} {:<14} at tau = {:>9.2} s  {}",
            format!("{:?}", t.kind),
            t.value,
            t.kind.unit(),
            t.tau_s,
            if t.visible {
                "visible"
            } else {
                "not visible: upper bound only"
            }
        );
    }
    // The host's noise model fit (`gyro allan --fit`, the Python package):
    // the tangent readings above are bounds the board can compute; this is
    // the estimate with intervals and a test of the model.
    let x = gyro_tool::dev::phase_from_rate(&rate, tau0).expect("finite, checked above");
    match gyro_tool::fit::fit_phase(&x, tau0) {
        Ok(t) => {
            let mut out = std::io::stdout().lock();
            gyro_tool::fit::write_table(&mut out, "noise model fit (gyro allan --fit)", &t)
                .expect("stdout");
        }
        Err(e) => println!("noise model fit: {e}"),
    }
    if let Some(p) = model {
        println!(
            "model settings: N = {} deg/sqrt(h), B = {} deg/h, K = {} deg/h/sqrt(h)",
            p.arw_deg_rt_h, p.bias_instability_deg_h, p.rrw_deg_h_rt_h
        );
    }
}
