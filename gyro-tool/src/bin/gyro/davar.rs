//! `gyro davar`: the E-DAVAR surface of one column of a rate log.

use std::path::PathBuf;

use gyro_tool::{short, surface, Res};

use crate::log_args::LogArgs;

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    log: LogArgs,
    /// The column.
    #[arg(long = "column", short = 'c')]
    column: String,
    /// The longest window λ2, samples (λ1 = λ2/2).
    #[arg(long, value_enum, default_value = "1024")]
    lambda2: surface::Lambda2,
    /// The picture.
    #[arg(long)]
    svg: PathBuf,
    /// Also the rows as CSV (t, window, σ per τ).
    #[arg(long)]
    csv: Option<PathBuf>,
}

/// `gyro davar`: the E-DAVAR surface of one column.
pub fn run(a: Args) -> Res<bool> {
    let Args {
        log,
        column,
        lambda2: l2,
        svg,
        csv: csv_out,
    } = a;
    let s = log.read(&[column.to_string()], false)?;
    let rate = s.rates.first().ok_or("no column")?;
    let (rows, lsb, lambda2) = surface::surface(rate, s.tau0, l2)?;
    let shortened = rows
        .iter()
        .filter(|r| ((r.end_s - r.start_s) / s.tau0).round() < f64::from(lambda2) - 32.0)
        .count();
    println!(
        "{column}: {} samples at tau0 = {} s, E-DAVAR lambda2 = {lambda2}: {} estimates, window shortened in {shortened}; quantisation step {lsb:e} (adds {:.1e} to sigma^2(tau0))",
        rate.len(),
        short(s.tau0),
        rows.len(),
        lsb * lsb / 6.0
    );
    let clipped = surface::clipped(rate, lsb);
    if clipped > 0 {
        println!(
            "{column}: {clipped} samples beyond the E-DAVAR's range at that step were clipped to +-{:e} (a saturating sensor's reading)",
            lsb * gyro_array::algo::allan::stream::SAMPLE_MAX as f64
        );
    }
    if let Some(p) = csv_out {
        let mut w = csv::Writer::from_path(p)?;
        let taus = rows.first().map_or(0, |r| r.adev.len());
        let mut head = vec!["t_s".to_string(), "start_s".into(), "end_s".into()];
        head.extend((0..taus).map(|j| format!("adev_tau{}", short(s.tau0 * f64::from(1u32 << j)))));
        w.write_record(&head)?;
        for r in &rows {
            let mut rec = vec![
                short(r.t_s).to_string(),
                short(r.start_s).to_string(),
                short(r.end_s).to_string(),
            ];
            rec.extend(r.adev.iter().map(|v| format!("{v:e}")));
            w.write_record(&rec)?;
        }
        w.flush()?;
    }
    surface::draw(&svg, &log.name(), "°/s", &rows, lambda2, s.tau0)?;
    Ok(true)
}
