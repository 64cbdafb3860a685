//! A rate log and how to read it (`allan`, `davar`, `replay`).

use std::path::PathBuf;

use gyro_tool::{dev, table, Res};

/// A rate log and how to read it (shared by `davar` and `replay`).
#[derive(clap::Args)]
pub struct LogArgs {
    /// The log: comma-, semicolon-, tab- or blank-separated text, with a
    /// header line or without one (columns c1, c2, …); or a PX4 ULog
    /// (`.ulg`: its gyro topics, columns `sensor_gyro.0.x` …, its own
    /// stamps).
    pub file: PathBuf,
    /// The time column, s: τ0 is its median step, and gaps (steps over
    /// 1.5 τ0) and non-monotonic times are reported (a text log needs this
    /// or `--tau0`).
    #[arg(long, conflicts_with = "tau0")]
    pub time: Option<String>,
    /// Sample period, s (finite, in (0, 1e6]).
    #[arg(long, value_parser = dev::tau0_arg)]
    pub tau0: Option<f64>,
    /// Unit of the rate columns.
    #[arg(long, value_enum, default_value = "dps")]
    pub unit: table::Unit,
    /// Counts per °/s, with `--unit lsb`.
    #[arg(long)]
    pub lsb_per_dps: Option<f64>,
}

impl LogArgs {
    /// Read `columns`; with `missing`, empty cells are NaN.
    pub fn read(&self, columns: &[String], missing: bool) -> Res<table::Series> {
        let s = table::read_with(
            &self.file,
            columns,
            self.time.as_deref(),
            self.tau0,
            (self.unit, self.lsb_per_dps),
            missing,
        )?;
        for (line, step) in &s.gaps {
            eprintln!(
                "gyro: {}:{line}: gap of {step} s ({:.1} samples)",
                self.file.display(),
                step / s.tau0
            );
        }
        Ok(s)
    }

    pub fn name(&self) -> String {
        self.file
            .file_name()
            .map_or("log".into(), |f| f.to_string_lossy().into_owned())
    }
}
