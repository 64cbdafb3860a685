//! `gyro replay`: the board's fusion over a multi-gyro rate log.

use std::path::PathBuf;

use gyro_tool::{assess, replay, short, Res};

use crate::log_args::LogArgs;

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    log: LogArgs,
    /// The chips' columns (default: every column but the time column
    /// and --truth).
    #[arg(long = "column", short = 'c')]
    columns: Vec<String>,
    /// A reference rate column, if the log has one: errors are printed
    /// against it.
    #[arg(long)]
    truth: Option<String>,
    /// The picture.
    #[arg(long)]
    svg: PathBuf,
    /// Also the fused rate and each chip's weight per sample, as CSV.
    #[arg(long)]
    csv: Option<PathBuf>,
    /// Fuse the chips as logged. By default each chip is first shifted by
    /// its lag against the first chip (cross-correlation of the rates'
    /// changes, up to 8 samples, taken only where the motion says so), as
    /// the board puts its chips on one time grid: a log cut by rows can
    /// hold chips a few samples apart.
    #[arg(long)]
    no_align: bool,
}

/// `gyro replay`: the board's fusion over a multi-gyro log.
pub fn run(a: Args) -> Res<bool> {
    let Args {
        log,
        columns,
        truth,
        svg,
        csv,
        no_align,
    } = a;
    let (columns, truth, svg, csv_out) = (
        &columns[..],
        truth.as_deref(),
        svg.as_path(),
        csv.as_deref(),
    );
    let mut s = log.read(columns, true)?;
    // The reference: out of the chips' columns if it is among them (no -c
    // given), else read on its own.
    let truth_col = match truth {
        Some(t) => Some(match s.names.iter().position(|n| n == t) {
            Some(i) => {
                s.names.remove(i);
                s.rates.remove(i)
            }
            None => log.read(&[t.to_string()], false)?.rates.remove(0),
        }),
        None => None,
    };
    if let Some((t, col)) = truth.zip(truth_col.as_ref()) {
        replay::check_rates(&format!("reference {t}"), col)?;
    }
    if !no_align {
        let lags = assess::lags(&[&s.rates[..]]);
        if lags.iter().any(|&l| l != 0) {
            println!(
                "aligned: each chip's lag against {}, in samples: {lags:?} (--no-align: fuse as logged)",
                s.names[0]
            );
            s.rates = assess::shifted(&s.rates, &lags);
        }
    }
    let r = replay::replay(&s.rates)?;
    let n = r.fused.len();
    let valid = r.fused.iter().filter(|v| v.is_finite()).count();
    println!(
        "{} chips, {n} samples at tau0 = {} s: fused on {valid} samples",
        s.rates.len(),
        short(s.tau0)
    );
    for (c, name) in s.names.iter().enumerate() {
        // Against the reference where it has a value (an empty cell:
        // none), while the chip is in the fusion.
        let err = truth_col.as_ref().map(|t| {
            rms(&(0..n)
                .filter(|&i| r.weights[i][c] > 0.0 && t[i].is_finite())
                .map(|i| s.rates[c][i] - t[i])
                .collect::<Vec<f64>>())
        });
        println!(
            "  {name}: answered {} samples, in the fusion {}{}",
            r.offered[c],
            r.used[c],
            match err {
                None => String::new(),
                Some(None) if r.used[c] == 0 => String::new(),
                Some(None) => ", error RMS while in: no sample with the reference".to_string(),
                Some(Some(e)) => format!(", error RMS while in {e:.4}"),
            }
        );
    }
    if let Some(t) = &truth_col {
        let e: Vec<f64> = (0..n)
            .filter(|&i| r.fused[i].is_finite() && t[i].is_finite())
            .map(|i| r.fused[i] - t[i])
            .collect();
        match rms(&e) {
            Some(rms) => {
                let max = e.iter().fold(0.0f64, |m, e| m.max(e.abs()));
                println!(
                    "  fused: error RMS {rms:.4}, max {max:.4} (over {} samples)",
                    e.len()
                );
            }
            None => println!("  fused: no fused sample with the reference"),
        }
    }
    print_assessment(&assess::assess(&s.rates, &r, s.tau0)?, &s.names, &r.offered);
    // The fused gyro's noise, free of the motion: the probe's Allan
    // deviation (and, with a reference, the fused error's beside it).
    let (len, probe) = replay::longest_run_adev(&r.probe, s.tau0);
    if probe.is_empty() {
        println!("  noise probe: fewer than 16 contiguous samples with two chips fused");
    } else {
        let oracle = truth_col.as_ref().map(|t| {
            let e: Vec<f64> = r.fused.iter().zip(t).map(|(f, t)| f - t).collect();
            replay::longest_run_adev(&e, s.tau0).1
        });
        println!(
            "  noise probe (the fused noise without the motion), Allan deviation over {len} contiguous samples:"
        );
        if r.shared > 0 {
            println!(
                "  (on {:.1} % of the samples the chips share an error, which the probe cannot see: there it gives the part they do not share)",
                100.0 * r.shared as f64 / n.max(1) as f64
            );
        }
        println!(
            "  {:>12} {:>14}{}",
            "tau_s",
            "probe",
            if oracle.is_some() {
                "   fused error (from the reference)"
            } else {
                ""
            }
        );
        for (j, (tau, sd)) in probe.iter().enumerate() {
            let o = oracle
                .as_ref()
                .and_then(|o| o.get(j))
                .map_or(String::new(), |(_, o)| format!(" {o:>14.6e}"));
            println!("  {tau:>12.4} {sd:>14.6e}{o}");
        }
    }
    if let Some(p) = csv_out {
        let mut w = csv::Writer::from_path(p)?;
        let mut head = vec!["t_s".to_string(), "fused".into(), "noise_probe".into()];
        head.extend(s.names.iter().map(|n| format!("w_{n}")));
        w.write_record(&head)?;
        for i in 0..n {
            let mut rec = vec![
                short(i as f64 * s.tau0).to_string(),
                r.fused[i].to_string(),
                r.probe[i].to_string(),
            ];
            rec.extend((0..s.names.len()).map(|c| r.weights[i][c].to_string()));
            w.write_record(&rec)?;
        }
        w.flush()?;
    }
    replay::draw(svg, &log.name(), &s.names, &s.rates, &r, s.tau0)?;
    Ok(true)
}

/// The truth-free measure: leave-one-out, the weights' spread and, on a
/// static log, the Allan deviations' ratios.
fn print_assessment(a: &assess::Assessment, names: &[String], offered: &[usize]) {
    // Leave-one-out needs samples where the chip left out and two others
    // answered together: none, and every figure would read NaN.
    let judged = a.loo.iter().any(|l| l.fused.is_finite());
    if !a.loo.is_empty() && !judged {
        println!(
            "  leave-one-out: no sample where the chip left out and another answered together"
        );
    }
    if judged {
        println!(
            "  leave-one-out (RMS against the chip left out, means out): the fusion of the others / the whole fusion's weights over the others / plain mean / fixed inverse-variance:"
        );
        for (c, l) in a.loo.iter().enumerate() {
            println!(
                "    {:<10} {:>12.6} {:>12.6} {:>12.6} {:>12.6}   hat variance {:.4e}",
                names[c], l.fused, l.own, l.mean, l.fixed_iv, a.hat[c]
            );
        }
        println!(
            "    over the chips, against the plain mean: the fusion of the others {:.3}x, the whole fusion's weights {:.3}x, fixed inverse-variance {:.3}x{}",
            a.loo_ratio(),
            a.own_ratio(),
            a.fixed_iv_ratio(),
            if a.shared_error() {
                " (the hat reads a variance below 0: some chips share an error)"
            } else {
                ""
            }
        );
    }
    println!("  weights (mean, sd over the samples a chip answered; samples at weight 0):");
    for (c, w) in a.spread.iter().enumerate() {
        if offered.get(c) == Some(&0) {
            println!("    {:<10} never answered", names[c]);
            continue;
        }
        println!(
            "    {:<10} {:.3} ± {:.3}   {}",
            names[c], w.mean, w.sd, w.zero
        );
    }
    println!(
        "    one chip above 0.9 on {:.2} % of the samples with three or more fused",
        100.0 * a.one_chip_share
    );
    if a.is_static {
        println!("  static log: Allan deviation, fused / plain mean and probe / fused:");
        for p in &a.static_points {
            println!(
                "    tau = {:>3} samples  {:.3}  {:.3}",
                p.m, p.fused_over_mean, p.probe_over_fused
            );
        }
    } else if judged {
        println!("  not static (the chips' mean moves more than their noise): no Allan ratios");
    } else {
        // The static test compares the motion with the chips' noise, which
        // only chips answering together show.
        println!(
            "  static or not, untold (no samples where chips answered together): no Allan ratios"
        );
    }
}

/// The root mean square of `e`; None when it is empty.
fn rms(e: &[f64]) -> Option<f64> {
    (!e.is_empty()).then(|| (e.iter().map(|e| e * e).sum::<f64>() / e.len() as f64).sqrt())
}
