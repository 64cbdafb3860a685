//! A rate log and how to read it (`allan`, `davar`, `replay`).

use std::path::PathBuf;

use gyro_tool::{dev, table, Res};

/// A rate log and how to read it (shared by `davar` and `replay`).
#[derive(clap::Args)]
pub struct LogArgs {
    /// The log: comma-, semicolon-, tab- or blank-separated text, with a
    /// header line or without one (columns c1, c2, …); or a robot log with
    /// its own stamps: a PX4 ULog (`.ulg`: columns `sensor_gyro.0.x` …), an
    /// ArduPilot dataflash log (`.bin`: `IMU.0.x` …), a ROS 1 bag or a ROS
    /// 2 bag, MCAP or sqlite3 (`/imu/data.x` …).
    pub file: PathBuf,
    /// A robot log's IMU topic (`/imu/data`, `IMU.1`, `sensor_gyro.0`):
    /// its x, y and z, or the axes `-c` names (`-c z`).
    #[arg(long)]
    pub topic: Option<String>,
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
    /// The separator of a text log: comma, semicolon, tab, space (runs of
    /// blanks) or one character; detected from the first line when absent.
    #[arg(long, value_parser = delimiter_arg)]
    pub delimiter: Option<u8>,
    /// The first line is data, not a header (columns c1, c2, …); detected
    /// when absent (a first line of numbers is data).
    #[arg(long)]
    pub no_header: bool,
}

fn delimiter_arg(s: &str) -> Result<u8, String> {
    match s {
        "comma" | "," => Ok(b','),
        "semicolon" | ";" => Ok(b';'),
        "tab" | "\t" => Ok(b'\t'),
        "space" | " " => Ok(b' '),
        _ if s.len() == 1 && s.is_ascii() => Ok(s.as_bytes()[0]),
        _ => Err(format!(
            "{s}: comma, semicolon, tab, space or one ASCII character"
        )),
    }
}

impl LogArgs {
    /// The columns to read: `columns` as given, or with `--topic` the
    /// topic's axes (all three, or those `columns` names as x, y or z).
    pub fn columns(&self, columns: &[String]) -> Vec<String> {
        let Some(t) = &self.topic else {
            return columns.to_vec();
        };
        if columns.is_empty() {
            return ["x", "y", "z"].map(|a| format!("{t}.{a}")).to_vec();
        }
        columns
            .iter()
            .map(|c| match c.as_str() {
                "x" | "y" | "z" => format!("{t}.{c}"),
                _ => c.clone(),
            })
            .collect()
    }

    /// Read `columns` (as [`LogArgs::columns`] makes them); with `missing`,
    /// empty cells are NaN.
    pub fn read(&self, columns: &[String], missing: bool) -> Res<table::Series> {
        let s = table::read_layout(
            &self.file,
            &self.columns(columns),
            (self.time.as_deref(), self.tau0),
            (self.unit, self.lsb_per_dps),
            missing,
            self.layout(),
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

    /// The text's layout as the options overrule it.
    pub fn layout(&self) -> table::Layout {
        table::Layout {
            delimiter: self.delimiter,
            header: self.no_header.then_some(false),
        }
    }

    pub fn name(&self) -> String {
        self.file
            .file_name()
            .map_or("log".into(), |f| f.to_string_lossy().into_owned())
    }
}
