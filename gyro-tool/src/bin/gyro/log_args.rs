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
    /// Read `columns`; with `missing`, empty cells are NaN.
    pub fn read(&self, columns: &[String], missing: bool) -> Res<table::Series> {
        let s = table::read_layout(
            &self.file,
            columns,
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
