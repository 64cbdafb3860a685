//! The board's fusion on real multi-IMU recordings made by others, judged
//! without a truth (`gyro_tool::assess`): leave-one-out against the plain
//! mean and against fixed inverse-variance weights from the whole log, the
//! weights' spread, and on static logs the Allan ratios. Leave-one-out
//! twice: the firmware fusing the others (`loo`: three chips, weighed
//! equally without priors) and the whole fusion's own weights renormalised
//! over the others (`own`: what the board learns from all four, compared
//! like with like with the fixed weights, which come from all four too).
//!
//! `cargo run -p evaluations --profile host --bin real-eval -- [--dir D] [--no-align]`
//!
//! `D` holds `path_N/IMU_k.csv.gz` as the quadrotor recordings of Hurwitz
//! and Klein do (CC BY 4.0, `host-tests/vectors/real/README.md`): every
//! `path_*` folder is one log, every `IMU_k` one chip, its `Gyr_X/Y/Z`
//! columns the three axes. By default the three flights committed under
//! `host-tests/vectors/real/quadrotor`; `--dir ../shared/real/quadrotor-horizontal`
//! takes all 27. The files of one flight were cut from the raw recordings
//! by row, so chips sit up to four samples apart on some flights: as
//! `gyro replay` does, each chip is shifted by its lag against the first
//! (`gyro_tool::assess::lags` over the three axes, ±8 samples) before
//! fusing, the host's stand-in for the board's time alignment; with
//! `--no-align` the chips are fused as cut.
//!
//! Prints one row per log and axis and the targets' verdicts; exits 1 when
//! a target fails.

use std::path::PathBuf;

use clap::Parser;
use gyro_tool::{assess, replay};
use host_tests::real::{align, load};

#[derive(Parser)]
#[command(name = "real-eval")]
struct Cli {
    /// Folder of `path_*/IMU_k.csv.gz` logs.
    #[arg(long)]
    dir: Option<PathBuf>,
    /// Fuse the chips as cut, without shifting each by its lag.
    #[arg(long)]
    no_align: bool,
}

fn main() {
    gyro_tool::pipe::quiet_on_closed_pipe();
    let cli = Cli::parse();
    let dir = cli.dir.unwrap_or_else(host_tests::real::committed);
    let mut logs = match load(&dir) {
        Ok(l) if !l.is_empty() => l,
        Ok(_) => {
            eprintln!("{}: no path_* logs", dir.display());
            std::process::exit(2);
        }
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2);
        }
    };
    println!(
        "{} logs from {}{}",
        logs.len(),
        dir.display(),
        if cli.no_align {
            ", not aligned"
        } else {
            ", aligned"
        }
    );
    println!(
        "{:<9} {:>2} {:>6} {:>8} {:>8} {:>8} {:>8} {:>8} {:>9}  weights mean (sd)",
        "log", "ax", "n", "loo", "own", "fixedIV", "own/IV", "1>0.9 %", "shared"
    );
    let (mut worst_loo, mut worst_own, mut worst_iv, mut worst_one) =
        (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    let (mut lose, mut lose_own, mut off_iv, mut off_shared, mut rows) = (0, 0, 0, 0, 0);
    let (mut sum_loo, mut sum_own, mut sum_iv) = (0.0, 0.0, 0.0);
    for log in &mut logs {
        if !cli.no_align {
            let lags = align(log);
            println!("{}: lags against IMU_1 {lags:?}", log.name);
        }
        for ax in 0..3 {
            let chips: Vec<Vec<f64>> = log.chips.iter().map(|c| c[ax].clone()).collect();
            let r = match replay::replay(&chips) {
                Ok(r) => r,
                Err(e) => {
                    eprintln!("{} axis {ax}: {e}", log.name);
                    std::process::exit(2);
                }
            };
            let a = match assess::assess(&chips, &r, 1.0 / 120.0) {
                Ok(a) => a,
                Err(e) => {
                    eprintln!("{} axis {ax}: {e}", log.name);
                    std::process::exit(2);
                }
            };
            let (l, own, iv) = (a.loo_ratio(), a.own_ratio(), a.fixed_iv_ratio());
            let w: Vec<String> = a
                .spread
                .iter()
                .map(|s| format!("{:.2}({:.2})", s.mean, s.sd))
                .collect();
            println!(
                "{:<9} {:>2} {:>6} {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>8.2} {:>9}  {}",
                log.name,
                ["x", "y", "z"][ax],
                chips[0].len(),
                l,
                own,
                iv,
                own / iv,
                100.0 * a.one_chip_share,
                if a.shared_error() { "yes" } else { "no" },
                w.join(" ")
            );
            worst_loo = worst_loo.max(l);
            worst_own = worst_own.max(own);
            worst_iv = worst_iv.max(own / iv);
            worst_one = worst_one.max(a.one_chip_share);
            lose += usize::from(l > 1.0);
            lose_own += usize::from(own > 1.0);
            off_iv += usize::from(own > 1.03 * iv);
            off_shared += usize::from(own > 1.03 * iv && a.shared_error());
            rows += 1;
            sum_loo += l;
            sum_own += own;
            sum_iv += iv;
        }
    }
    println!();
    println!(
        "leave-one-out, the fusion of the others / plain mean: mean {:.3}, worst {:.3}; axes above 1.00: {lose} of {rows}",
        sum_loo / rows as f64,
        worst_loo
    );
    println!(
        "leave-one-out, the whole fusion's weights / plain mean: mean {:.3}, worst {:.3}; axes above 1.00: {lose_own} of {rows} (target 0)",
        sum_own / rows as f64,
        worst_own
    );
    println!(
        "fixed inverse-variance weights (the whole log's hat): mean {:.3}; axes where the whole fusion's weights are over 1.03x it: {off_iv} of {rows} (worst {:.3}x), {off_shared} of them where the hat reads a shared error (the fixed weights then give one chip the whole weight)",
        sum_iv / rows as f64,
        worst_iv
    );
    println!(
        "one chip above 0.9 of the weight: worst {:.2} % of the samples (target <= 1 %)",
        100.0 * worst_one
    );
    // The targets this binary can fail: the weights the board learns
    // never worse than the mean; the firmware fusing three chips within
    // 2 % of it (the warm-up's median output, the gate and the
    // calibration move it off the exact mean: docs/fusion.md); never one
    // chip at 0.9. Within 3 % of the fixed weights is printed, not
    // required: measured, not met on every axis.
    let ok = worst_own <= 1.0 && worst_loo <= 1.02 && worst_one <= 0.01;
    println!("targets: {}", if ok { "met" } else { "MISSED" });
    std::process::exit(i32::from(!ok));
}
