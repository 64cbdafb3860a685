//! `gyro emulate`: a rate log of an emulated chip at rest.

use std::io::Write;
use std::path::PathBuf;

use clap::ValueEnum;
use gyro_tool::Res;
use indicatif::ProgressBar;

#[derive(clap::Args)]
pub struct Args {
    /// The chip's noise model.
    #[arg(long, value_enum, default_value = "icm42688")]
    chip: EmuChip,
    /// Length, hours.
    #[arg(long, default_value_t = 1.0)]
    hours: f64,
    /// Sample rate, Hz.
    #[arg(long, default_value_t = 100.0)]
    hz: f64,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Flicker bias instability (a flat Allan floor) instead of the
    /// default Gauss–Markov one.
    #[arg(long)]
    flicker: bool,
    /// Rate random walk K, °/h/√h (default: the chip's).
    #[arg(long)]
    rrw: Option<f32>,
    /// The log (one column, `z`, in °/s; τ0 = 1/hz).
    #[arg(short, long)]
    out: PathBuf,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum EmuChip {
    Icm42688,
    Adxrs453,
}

/// `gyro emulate`: a log of an emulated chip at rest.
pub fn run(a: Args) -> Res<bool> {
    let Args {
        chip,
        hours,
        hz,
        seed,
        flicker,
        rrw,
        out,
    } = a;
    let out = out.as_path();
    use gyro_sim::noise::AxisNoise;
    use gyro_sim::{NoiseParams, Rng};
    if !(hours > 0.0 && hours <= 1000.0 && hz > 0.0 && hz <= 1e5) {
        return Err("hours must be in (0, 1000] and hz in (0, 1e5]".into());
    }
    let mut p = match chip {
        EmuChip::Icm42688 => NoiseParams::ICM42688,
        EmuChip::Adxrs453 => NoiseParams::ADXRS453,
    };
    if flicker {
        p.bias_tau_s = 0.0;
    }
    if let Some(k) = rrw {
        if !(k >= 0.0 && k.is_finite()) {
            return Err("--rrw must be a finite K >= 0".into());
        }
        p.rrw_deg_h_rt_h = k;
    }
    let n = (hours * 3600.0 * hz).round() as u64;
    if n < 3 {
        // Fewer than any deviation needs: no file, rather than one that
        // every analysis refuses.
        return Err(
            format!("{hours} h at {hz} Hz is {n} samples; the analyses need at least 3").into(),
        );
    }
    let dt = (1.0 / hz) as f32;
    let mut rng = Rng::new(seed);
    let mut axis = AxisNoise::default();
    let mut w = std::io::BufWriter::new(std::fs::File::create(out)?);
    writeln!(
        w,
        "# gyro emulate: {chip:?} at rest, {hours} h at {hz} Hz, seed {seed}, N {} deg/rt h, B {} deg/h ({}), K {} deg/h/rt h",
        p.arw_deg_rt_h,
        p.bias_instability_deg_h,
        if flicker { "flicker" } else { "Gauss-Markov" },
        p.rrw_deg_h_rt_h
    )?;
    writeln!(w, "z")?;
    let bar = if n >= 10_000_000 {
        ProgressBar::new(n)
    } else {
        ProgressBar::hidden()
    };
    for i in 0..n {
        writeln!(w, "{}", axis.step(&p, &mut rng, 0.0, dt))?;
        if i % 1_000_000 == 0 {
            bar.set_position(i);
        }
    }
    bar.finish_and_clear();
    w.flush()?;
    eprintln!(
        "gyro: wrote {n} samples to {} (tau0 = {} s)",
        out.display(),
        1.0 / hz
    );
    Ok(true)
}
