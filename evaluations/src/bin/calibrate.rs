//! The static calibration procedure on the emulated board
//! (`host_tests::calibration`): rate table and thermal runs through the
//! real drivers and pipeline, the record they give, and its errors
//! against the emulator's true constants.
//!
//! `cargo run -p evaluations --profile host --bin calibrate -- [--hold N] [--seed S] [--out FILE]`
//!
//! Exits 1 unless every chip's scale and misalignment are recovered to
//! 0.05 % and its bias to 0.01 °/s.

use std::process::ExitCode;

use clap::Parser;
use host_tests::calibration::{calibrate, errors};

#[derive(Parser)]
#[command(about = "Calibrate the emulated board and check the constants recovered")]
struct Args {
    /// Samples held per run (1 kHz).
    #[arg(long, default_value_t = 10_000)]
    hold: u32,
    /// Noise seed of the emulated chips.
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// Write the record (the bytes the board keeps in flash) here.
    #[arg(long)]
    out: Option<std::path::PathBuf>,
}

fn main() -> ExitCode {
    gyro_tool::pipe::quiet_on_closed_pipe();
    let args = Args::parse();
    let Some(rec) = calibrate(args.hold.max(100), args.seed) else {
        eprintln!("calibrate: a chip's matrix is singular");
        return ExitCode::from(2);
    };
    let e = errors(&rec);
    println!("chip  scale+misalignment left  bias error (°/s)  slope error (°/s/°C)");
    for i in 0..5 {
        println!(
            "{i}     {:>10.2e}               {:>10.2e}        {:>10.2e}",
            e.scale[i], e.bias_dps[i], e.tc[i]
        );
    }
    let (s, b) = (
        e.scale.iter().cloned().fold(0.0, f64::max),
        e.bias_dps.iter().cloned().fold(0.0, f64::max),
    );
    let ok = s <= 5e-4 && b <= 0.01;
    println!(
        "worst: scale {:.4} % (target 0.05 %), bias {:.4} °/s (target 0.01): {}",
        s * 100.0,
        b,
        if ok { "MET" } else { "NOT MET" }
    );
    if let Some(path) = args.out {
        let mut buf = [0u8; gyro_array::algo::static_cal::MAX_LEN];
        let n = match rec.encode(&mut buf) {
            Ok(n) => n,
            Err(e) => {
                eprintln!("calibrate: {e:?}");
                return ExitCode::from(2);
            }
        };
        if let Err(e) = std::fs::write(&path, &buf[..n]) {
            eprintln!("calibrate: {}: {e}", path.display());
            return ExitCode::from(2);
        }
        println!("record ({n} bytes) written to {}", path.display());
    }
    if ok {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}
