//! `gyro`: the host side of the gyro board's output link.
//!
//! - `gyro record --from SRC -o FILE`: save the byte stream (the recording
//!   is the wire format itself, so nothing is lost), with a live view.
//! - `gyro watch --from SRC`: the live view alone.
//! - `--send OP` (record, watch): commands to the board, acknowledged in
//!   the stream: `status`, `divider=N`, `status-every=N`,
//!   `mode=fused|raw`, `method=mean|zhang|adaptive`,
//!   `compensation=off|frame|MICROSECONDS` (the delay compensation: off,
//!   to the frame's last byte, or to a horizon after the sample's time).
//! - `gyro check FILE`: integrity of a recording (no corrupt frame, no
//!   gap), optionally against the firmware's own count and CRC-32.
//! - `gyro decode FILE --what samples|noise|raw|status -o CSV`.
//! - `gyro analyse FILE`: Allan deviation of each fused axis and the
//!   E-DAVAR estimates the board sent.
//! - `gyro pointing FILE [--truth CSV] [--svg OUT]`: the recording through
//!   the reference stabilisation loop: the pointing error it adds to the
//!   ideal gyro's per axis, split into delay and noise (and, against a
//!   reference, calibration and faults).
//!
//! SRC is `serial:PATH[@BAUD]`, `tcp:HOST:PORT`, `unix:PATH`, `file:PATH`
//! or `-`. Protocol: `docs/link.md`.

use gyro_tool::{
    analyse, dev, edf, fit, plot, pointing, read_recording, replay, short, source, summary,
    surface, table, Res,
};

use std::io::{Read, Write};
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use clap::{Parser, Subcommand, ValueEnum};
use gyro_array::link::msg::{Command, Compensation, Frame, FusionMethod, Mode, Op, Reject};
use gyro_array::link::wire::{encode, Decoded, Decoder, MAX_FRAME};
use indicatif::{ProgressBar, ProgressStyle};

use source::Source;
use summary::{status_line, Summary};

#[derive(Parser)]
#[command(
    name = "gyro",
    version,
    about = "Record, watch, check and analyse the gyro board's output link"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Save the link's bytes to a file, with a live view.
    Record {
        #[command(flatten)]
        link: LinkArgs,
        /// The recording (the raw wire bytes).
        #[arg(short, long)]
        out: PathBuf,
    },
    /// Show the link live.
    Watch {
        #[command(flatten)]
        link: LinkArgs,
    },
    /// Check a recording: no corrupt frame, no gap in the link or sample
    /// sequence numbers; exit 1 otherwise.
    Check {
        /// The recording.
        file: PathBuf,
        /// Expect exactly this many sample frames.
        #[arg(long)]
        samples: Option<u64>,
        /// Expect at least this many sample frames.
        #[arg(long)]
        min_samples: Option<u64>,
        /// Expect this CRC-32 of the fused rates (the firmware's log).
        #[arg(long, value_parser = parse_hex)]
        fused_crc32: Option<u32>,
        /// Expect these acknowledgements, in order (ok, corrupt, too-long,
        /// version, malformed, out-of-range, refused), comma-separated.
        #[arg(long, value_delimiter = ',')]
        acks: Option<Vec<AckKind>>,
    },
    /// Export one kind of frame from a recording as CSV.
    Decode {
        /// The recording.
        file: PathBuf,
        /// Which frames.
        #[arg(long, value_enum, default_value = "samples")]
        what: What,
        /// The CSV file (standard output if absent).
        #[arg(short, long)]
        out: Option<PathBuf>,
    },
    /// Allan deviation of each fused axis, and the board's E-DAVAR
    /// estimates, from a recording.
    Analyse {
        /// The recording.
        file: PathBuf,
    },
    /// A recording through the reference stabilisation loop: the pointing
    /// error its stated delay and its noise leave, per axis.
    Pointing {
        /// The recording.
        file: PathBuf,
        /// The true rate on the board's clock (CSV: t_us,x_dps,y_dps,z_dps;
        /// an emulated run's, `pointing-eval --write`): the error then
        /// splits into delay, calibration, noise and faults.
        #[arg(long)]
        truth: Option<PathBuf>,
        /// Draw the motion and the pointing error of the axis that moved
        /// most as SVG.
        #[arg(long)]
        svg: Option<PathBuf>,
    },
    /// Allan-family deviations of a rate log: CSV or whitespace text with
    /// a header line, one column per series.
    Allan {
        #[command(flatten)]
        log: LogArgs,
        /// Columns to analyse (repeat; default: every column but the time
        /// column).
        #[arg(long = "column", short = 'c')]
        columns: Vec<String>,
        /// Deviations, comma-separated.
        #[arg(long, value_enum, value_delimiter = ',', default_value = "oadev")]
        dev: Vec<dev::Kind>,
        /// Averaging factors: all, octave, decade or per-decade=N.
        #[arg(long, default_value = "octave")]
        grid: dev::Grid,
        /// Output format.
        #[arg(long, value_enum, default_value = "table")]
        format: OutFormat,
        /// Write here instead of standard output.
        #[arg(short, long)]
        out: Option<PathBuf>,
        /// Also fit the IEEE 952 noise model (Q, N, B, K, R with standard
        /// errors, next to the tangent readings) to each column's OADEV.
        #[arg(long)]
        fit: bool,
        /// Write a Kalibr imu.yaml (gyroscope_noise_density,
        /// gyroscope_random_walk) from the first column's fit.
        #[arg(long)]
        kalibr: Option<PathBuf>,
        /// Draw the curves (and the fits) as SVG.
        #[arg(long)]
        svg: Option<PathBuf>,
        /// Confidence of the intervals (default 1σ, 0.6827: Stable32's
        /// "0.683").
        #[arg(long, default_value_t = edf::ONE_SIGMA, value_parser = confidence_arg)]
        confidence: f64,
        /// χ² quantiles of the intervals: exact, or as Stable32 computes
        /// them (an approximation beyond EDF 100, to reproduce its tables).
        #[arg(long, value_enum, default_value = "exact")]
        chi2: edf::Chi2,
    },
    /// Write a rate log of an emulated chip at rest (`emu::noise`), one
    /// axis: the analysis tools' test input, of any length.
    Emulate {
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
    },
    /// The E-DAVAR t–τ–σ surface of one column of a rate log (the board's
    /// segmented window), with σ(τ0) and the window over time.
    Davar {
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
    },
    /// Replay the board's fusion over a multi-gyro log: one column per
    /// chip, the same axis (at most 8).
    Replay {
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
    },
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum EmuChip {
    Icm42688,
    Adxrs453,
}

/// A rate log and how to read it (shared by `davar` and `replay`).
#[derive(clap::Args)]
struct LogArgs {
    /// The log: CSV or whitespace text with a header line.
    file: PathBuf,
    /// The time column, s: τ0 is its median step, and gaps (steps over
    /// 1.5 τ0) and non-monotonic times are reported.
    #[arg(long, required_unless_present = "tau0", conflicts_with = "tau0")]
    time: Option<String>,
    /// Sample period, s (finite, in (0, 1e6]).
    #[arg(long, value_parser = dev::tau0_arg)]
    tau0: Option<f64>,
    /// Unit of the rate columns.
    #[arg(long, value_enum, default_value = "dps")]
    unit: table::Unit,
    /// Counts per °/s, with `--unit lsb`.
    #[arg(long)]
    lsb_per_dps: Option<f64>,
}

impl LogArgs {
    /// Read `columns`; with `missing`, empty cells are NaN.
    fn read(&self, columns: &[String], missing: bool) -> Res<table::Series> {
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

    fn name(&self) -> String {
        self.file
            .file_name()
            .map_or("log".into(), |f| f.to_string_lossy().into_owned())
    }
}

fn confidence_arg(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v > 0.0 && v < 1.0 => Ok(v),
        _ => Err(format!("{s}: the confidence must be a number in (0, 1)")),
    }
}

#[derive(clap::Args)]
struct LinkArgs {
    /// serial:PATH[@BAUD], tcp:HOST:PORT, unix:PATH, file:PATH or -.
    #[arg(long)]
    from: Source,
    /// Commands to send once connected (repeatable).
    #[arg(long = "send", value_parser = parse_op)]
    send: Vec<Op>,
    /// Stop after this many seconds (default: at the end of the stream).
    #[arg(long)]
    seconds: Option<f64>,
    /// How long to keep trying to connect to a socket, seconds.
    #[arg(long, default_value_t = 30.0)]
    connect_timeout: f64,
    /// No live view.
    #[arg(short, long)]
    quiet: bool,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum What {
    Samples,
    Noise,
    Raw,
    Status,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum AckKind {
    Ok,
    Corrupt,
    TooLong,
    Version,
    Malformed,
    OutOfRange,
    Refused,
}

impl AckKind {
    fn of(r: Result<(), Reject>) -> Self {
        match r {
            Ok(()) => AckKind::Ok,
            Err(Reject::Corrupt) => AckKind::Corrupt,
            Err(Reject::TooLong) => AckKind::TooLong,
            Err(Reject::Version) => AckKind::Version,
            Err(Reject::Malformed) => AckKind::Malformed,
            Err(Reject::OutOfRange) => AckKind::OutOfRange,
            Err(Reject::Refused) => AckKind::Refused,
        }
    }
}

fn parse_hex(s: &str) -> Result<u32, String> {
    u32::from_str_radix(s.trim_start_matches("0x"), 16).map_err(|e| format!("{s:?}: {e}"))
}

fn parse_op(s: &str) -> Result<Op, String> {
    let (k, v) = s.split_once('=').unwrap_or((s, ""));
    let num = |v: &str| v.parse::<u32>().map_err(|e| format!("{s:?}: {e}"));
    Ok(match (k, v) {
        ("status", "") => Op::RequestStatus,
        // Out-of-range values are sent as they are: the board rejects them.
        ("divider", v) => Op::SetDivider(u16::try_from(num(v)?).unwrap_or(u16::MAX)),
        ("status-every", v) => Op::SetStatusEvery(num(v)?),
        ("mode", "fused") => Op::SetMode(Mode::Fused),
        ("mode", "raw") => Op::SetMode(Mode::Raw),
        ("method", "mean") => Op::SetMethod(FusionMethod::Mean),
        ("method", "zhang") => Op::SetMethod(FusionMethod::Zhang),
        ("method", "adaptive") => Op::SetMethod(FusionMethod::Adaptive),
        ("compensation", "off") => Op::SetCompensation(Compensation::Off),
        ("compensation", "frame") => Op::SetCompensation(Compensation::ToFrame),
        ("compensation", v) => {
            Op::SetCompensation(Compensation::Horizon(u16::try_from(num(v)?).unwrap_or(u16::MAX)))
        }
        _ => {
            return Err(format!(
                "{s:?}: expected status, divider=N, status-every=N, mode=fused|raw, method=mean|zhang|adaptive or compensation=off|frame|MICROSECONDS"
            ))
        }
    })
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let r = match cli.cmd {
        Cmd::Record { link, out } => stream(&link, Some(out)),
        Cmd::Watch { link } => stream(&link, None),
        Cmd::Check {
            file,
            samples,
            min_samples,
            fused_crc32,
            acks,
        } => check(&file, (samples, min_samples), fused_crc32, acks),
        Cmd::Decode { file, what, out } => decode(&file, what, out),
        Cmd::Analyse { file } => analyse::run(&file),
        Cmd::Pointing { file, truth, svg } => pointing::run(&file, truth.as_ref(), svg.as_ref()),
        Cmd::Allan {
            log,
            columns,
            dev,
            grid,
            format,
            out,
            fit,
            kalibr,
            svg,
            confidence,
            chi2,
        } => allan(
            &log.file,
            &columns,
            log.time.as_deref(),
            log.tau0,
            (log.unit, log.lsb_per_dps),
            &dev,
            grid,
            format,
            out,
            (fit, kalibr, svg),
            (confidence, chi2),
        ),
        Cmd::Emulate {
            chip,
            hours,
            hz,
            seed,
            flicker,
            rrw,
            out,
        } => emulate(chip, hours, hz, seed, flicker, rrw, &out),
        Cmd::Davar {
            log,
            column,
            lambda2,
            svg,
            csv,
        } => davar(&log, &column, lambda2, &svg, csv.as_deref()),
        Cmd::Replay {
            log,
            columns,
            truth,
            svg,
            csv,
        } => replay_log(&log, &columns, truth.as_deref(), &svg, csv.as_deref()),
    };
    match r {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::FAILURE,
        Err(e) => {
            eprintln!("gyro: {e}");
            ExitCode::from(2)
        }
    }
}

/// Output formats of `gyro allan`.
#[derive(Clone, Copy, ValueEnum)]
enum OutFormat {
    /// Aligned text.
    Table,
    /// CSV: column, deviation, m, tau_s, value, terms.
    Csv,
    /// JSON: one object per column and deviation, with its points.
    Json,
}

/// `gyro emulate`: a log of an emulated chip at rest.
fn emulate(
    chip: EmuChip,
    hours: f64,
    hz: f64,
    seed: u64,
    flicker: bool,
    rrw: Option<f32>,
    out: &std::path::Path,
) -> Res<bool> {
    use gyro_array::emu::noise::AxisNoise;
    use gyro_array::emu::{NoiseParams, Rng};
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

/// Peak resident memory of this process, MiB (Linux; None elsewhere).
fn peak_mib() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let kb: f64 = s
        .lines()
        .find(|l| l.starts_with("VmHWM:"))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()?;
    Some(kb / 1024.0)
}

/// `gyro davar`: the E-DAVAR surface of one column.
fn davar(
    log: &LogArgs,
    column: &str,
    l2: surface::Lambda2,
    svg: &std::path::Path,
    csv_out: Option<&std::path::Path>,
) -> Res<bool> {
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
    surface::draw(svg, &log.name(), "°/s", &rows, lambda2, s.tau0)?;
    Ok(true)
}

/// `gyro replay`: the board's fusion over a multi-gyro log.
fn replay_log(
    log: &LogArgs,
    columns: &[String],
    truth: Option<&str>,
    svg: &std::path::Path,
    csv_out: Option<&std::path::Path>,
) -> Res<bool> {
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
    let r = replay::replay(&s.rates)?;
    let n = r.fused.len();
    let valid = r.fused.iter().filter(|v| v.is_finite()).count();
    println!(
        "{} chips, {n} samples at tau0 = {} s: fused on {valid} samples",
        s.rates.len(),
        short(s.tau0)
    );
    for (c, name) in s.names.iter().enumerate() {
        let err = truth_col.as_ref().map(|t| {
            let e: Vec<f64> = (0..n)
                .filter(|&i| r.weights[i][c] > 0.0)
                .map(|i| s.rates[c][i] - t[i])
                .collect();
            (e.iter().map(|e| e * e).sum::<f64>() / e.len().max(1) as f64).sqrt()
        });
        println!(
            "  {name}: answered {} samples, in the fusion {}{}",
            r.offered[c],
            r.used[c],
            err.map_or(String::new(), |e| format!(", error RMS while in {e:.4}"))
        );
    }
    if let Some(t) = &truth_col {
        let e: Vec<f64> = (0..n)
            .filter(|&i| r.fused[i].is_finite())
            .map(|i| r.fused[i] - t[i])
            .collect();
        let rms = (e.iter().map(|e| e * e).sum::<f64>() / e.len().max(1) as f64).sqrt();
        let max = e.iter().fold(0.0f64, |m, e| m.max(e.abs()));
        println!("  fused: error RMS {rms:.4}, max {max:.4}");
    }
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

/// One curve of `gyro allan`'s JSON output.
#[derive(serde::Serialize)]
struct CurveOut<'a> {
    column: &'a str,
    deviation: dev::Kind,
    unit: &'static str,
    tau0_s: f64,
    samples: usize,
    points: Vec<dev::Point>,
}

/// `gyro allan`: read, compute every deviation of every column, write.
#[allow(clippy::too_many_arguments)]
fn allan(
    file: &std::path::Path,
    columns: &[String],
    time: Option<&str>,
    tau0: Option<f64>,
    (unit, lsb): (table::Unit, Option<f64>),
    kinds: &[dev::Kind],
    grid: dev::Grid,
    format: OutFormat,
    out: Option<PathBuf>,
    (want_fit, kalibr, svg): (bool, Option<PathBuf>, Option<PathBuf>),
    (cf, chi2): (f64, edf::Chi2),
) -> Res<bool> {
    let started = Instant::now();
    let s = table::read(file, columns, time, tau0, unit, lsb)?;
    let read_s = started.elapsed().as_secs_f64();
    for (line, step) in &s.gaps {
        eprintln!(
            "gyro: {}:{line}: gap of {step} s ({:.1} samples)",
            file.display(),
            step / s.tau0
        );
    }
    let total = (s.rates.len() * kinds.len()) as u64;
    let bar = if s.rates.first().map_or(0, Vec::len) >= 1_000_000 {
        ProgressBar::new(total)
    } else {
        ProgressBar::hidden()
    };
    let mut curves = Vec::new();
    // Each column's phase, once: the curves and the fit both read it.
    let phases = s
        .rates
        .iter()
        .map(|rate| dev::phase_from_rate(rate, s.tau0))
        .collect::<Result<Vec<_>, _>>()?;
    for ((name, rate), x) in s.names.iter().zip(&s.rates).zip(&phases) {
        let mut alphas = dev::Alphas::new();
        for &k in kinds {
            let points = dev::curve_with(k, x, s.tau0, grid, (cf, chi2), &mut alphas)?;
            curves.push(CurveOut {
                column: name,
                deviation: k,
                // TDEV is in the phase's unit (°); the others in °/s.
                unit: if k == dev::Kind::Tdev { "deg" } else { "deg/s" },
                tau0_s: s.tau0,
                samples: rate.len(),
                points,
            });
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    // The noise model per column, on its OADEV at 8 points per decade.
    let mut fits = Vec::new();
    if want_fit || kalibr.is_some() {
        for (name, x) in s.names.iter().zip(&phases) {
            match fit::fit_phase(x, s.tau0) {
                Ok(t) => fits.push((name.clone(), t)),
                Err(e @ fit::FitError::TooFewPoints) => eprintln!("gyro: {name}: {e}"),
                Err(e) => return Err(e.into()),
            }
        }
    }
    if let Some(path) = &kalibr {
        let Some((_, t)) = fits.first() else {
            return Err("no fit for a Kalibr file".into());
        };
        std::fs::write(path, fit::kalibr_yaml(t, short(1.0 / s.tau0), "/imu0"))?;
    }
    if let Some(path) = &svg {
        let cs: Vec<plot::Curve> = curves
            .iter()
            .map(|c| plot::Curve {
                // TDEV is a time (angle) deviation: its unit is on its label.
                label: if c.deviation == dev::Kind::Tdev {
                    format!("{} TDEV (deg, not deg/s)", c.column)
                } else {
                    format!("{} {}", c.column, c.deviation.name().to_uppercase())
                },
                points: &c.points,
            })
            .collect();
        let title = format!(
            "{}: {} samples at τ0 = {} s",
            file.file_name()
                .map_or("log".into(), |f| f.to_string_lossy()),
            s.rates.first().map_or(0, Vec::len),
            short(s.tau0)
        );
        plot::draw(path, &title, "°/s", &cs, &fits)?;
    }
    let mut w: Box<dyn Write> = match &out {
        Some(p) => Box::new(std::io::BufWriter::new(std::fs::File::create(p)?)),
        None => Box::new(std::io::stdout().lock()),
    };
    match format {
        OutFormat::Json => {
            #[derive(serde::Serialize)]
            struct FitOut<'a> {
                column: &'a str,
                /// Q deg, N deg/s*sqrt(s), B deg/s, K deg/s/sqrt(s), R deg/s^2.
                terms: &'a fit::Terms,
            }
            #[derive(serde::Serialize)]
            struct Out<'a> {
                curves: &'a [CurveOut<'a>],
                fits: Vec<FitOut<'a>>,
            }
            let fits = fits
                .iter()
                .map(|(c, t)| FitOut {
                    column: c,
                    terms: t,
                })
                .collect();
            serde_json::to_writer_pretty(
                &mut w,
                &Out {
                    curves: &curves,
                    fits,
                },
            )?;
            writeln!(w)?;
        }
        OutFormat::Csv => {
            let mut c = csv::Writer::from_writer(w);
            c.write_record([
                "column",
                "deviation",
                "m",
                "tau_s",
                "value",
                "unit",
                "terms",
                "alpha",
                "few_clusters",
                "edf",
                "lo",
                "hi",
            ])?;
            for cv in &curves {
                for p in &cv.points {
                    c.write_record([
                        cv.column.to_string(),
                        cv.deviation.name().to_string(),
                        p.m.to_string(),
                        format!("{:e}", p.tau),
                        format!("{:e}", p.dev),
                        cv.unit.to_string(),
                        p.terms.to_string(),
                        p.alpha.map_or(String::new(), |a| a.to_string()),
                        p.few_clusters.to_string(),
                        p.edf.map_or(String::new(), |e| format!("{e:e}")),
                        p.lo.map_or(String::new(), |v| format!("{v:e}")),
                        p.hi.map_or(String::new(), |v| format!("{v:e}")),
                    ])?;
                }
            }
            c.flush()?;
        }
        OutFormat::Table => {
            for cv in &curves {
                writeln!(
                    w,
                    "{} {} ({}), {} samples at tau0 = {} s",
                    cv.column,
                    cv.deviation.name().to_uppercase(),
                    cv.unit,
                    cv.samples,
                    short(cv.tau0_s)
                )?;
                writeln!(
                    w,
                    "{:>10} {:>14} {:>14} {:>14} {:>14} {:>12} {:>9} {:>6}",
                    "m", "tau (s)", "min", "deviation", "max", "edf", "terms", "alpha"
                )?;
                let opt = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.6e}"));
                for p in &cv.points {
                    writeln!(
                        w,
                        "{:>10} {:>14.6e} {:>14} {:>14.6e} {:>14} {:>12} {:>9} {:>6}{}",
                        p.m,
                        p.tau,
                        opt(p.lo),
                        p.dev,
                        opt(p.hi),
                        p.edf.map_or("-".to_string(), |e| format!("{e:.4}")),
                        p.terms,
                        p.alpha.map_or("-".to_string(), |a| a.to_string()),
                        if p.few_clusters { "  few clusters" } else { "" }
                    )?;
                }
            }
            // The terms in the units gyro datasheets use.
            let units = [
                ("Q", 1.0, "deg"),
                ("N", 60.0, "deg/sqrt(h)"),
                ("B", 3600.0, "deg/h"),
                ("K", 3600.0 * 60.0, "deg/h/sqrt(h)"),
                ("R", 3600.0 * 3600.0, "deg/h^2"),
            ];
            for (name, t) in &fits {
                writeln!(
                    w,
                    "{name}: IEEE 952 model, weighted least squares over {} OADEV points",
                    t.points
                )?;
                writeln!(
                    w,
                    "{:>4} {:>14} {:>12} {:>16}  unit",
                    "term", "fit", "+- sd", "IEEE 952 tangent"
                )?;
                for (i, (n, k, u)) in units.iter().enumerate() {
                    writeln!(
                        w,
                        "{n:>4} {:>14.6e} {:>12.3e} {:>16.6e}  {u}{}",
                        t.value[i] * k,
                        t.sd[i] * k,
                        t.tangent[i] * k,
                        if t.visible[i] { "  visible" } else { "" }
                    )?;
                }
            }
        }
    }
    // What the run cost: the check of a long log's handling.
    eprintln!(
        "gyro: {} samples x {} columns: read in {read_s:.1} s, analysed in {:.1} s in all; peak memory {}",
        s.rates.first().map_or(0, Vec::len),
        s.rates.len(),
        started.elapsed().as_secs_f64(),
        peak_mib().map_or("unknown".to_string(), |m| format!("{m:.0} MiB"))
    );
    Ok(true)
}

/// `record` and `watch`.
fn stream(args: &LinkArgs, out: Option<PathBuf>) -> Res<bool> {
    let wait = Duration::from_secs_f64(args.connect_timeout.max(0.0));
    let mut conn = source::open(&args.from, wait)?;
    let mut file = match &out {
        Some(p) => Some(std::fs::File::create(p).map_err(|e| format!("{}: {e}", p.display()))?),
        None => None,
    };
    // Commands go out once the board is heard from (a UART drops what
    // arrives before it is enabled), all in one write.
    let mut commands = Vec::new();
    for (id, op) in args.send.iter().enumerate() {
        let mut buf = [0u8; MAX_FRAME];
        let id = u8::try_from(id).map_err(|_| "at most 256 commands")?;
        let n = encode(u32::from(id), &Command { id, op: *op }, &mut buf)
            .map_err(|e| format!("{e:?}"))?;
        commands.extend_from_slice(&buf[..n]);
    }
    if !commands.is_empty() && conn.writer.is_none() {
        return Err("--send needs a serial port or a socket".into());
    }
    let bar = if args.quiet {
        ProgressBar::hidden()
    } else {
        let b = ProgressBar::new_spinner();
        b.set_style(ProgressStyle::with_template(
            "{spinner} {elapsed} {bytes} {msg}",
        )?);
        b
    };
    let deadline = args
        .seconds
        .map(|s| Instant::now() + Duration::from_secs_f64(s.max(0.0)));
    let mut dec = Decoder::<MAX_FRAME>::new();
    let mut sum = Summary::default();
    let mut buf = [0u8; 4096];
    let mut last_view = Instant::now();
    loop {
        if deadline.is_some_and(|d| Instant::now() >= d) {
            break;
        }
        let n = match conn.reader.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e.into()),
        };
        if let Some(f) = file.as_mut() {
            f.write_all(&buf[..n])?;
        }
        bar.inc(n as u64);
        for &b in &buf[..n] {
            if let Some(r) = dec.feed::<Frame>(b) {
                if let Ok(Decoded {
                    body: Frame::Status(st),
                    ..
                }) = &r
                {
                    bar.println(status_line(st));
                }
                if let Ok(Decoded {
                    body: Frame::Ack(a),
                    ..
                }) = &r
                {
                    bar.println(format!("ack: command {:?} -> {:?}", a.id, a.result));
                }
                sum.add(&r);
                if r.is_ok() && !commands.is_empty() {
                    if let Some(w) = conn.writer.as_mut() {
                        w.write_all(&commands)?;
                        w.flush()?;
                    }
                    commands.clear();
                }
            }
        }
        if last_view.elapsed() > Duration::from_millis(100) {
            last_view = Instant::now();
            let st = dec.stats();
            let rate = sum
                .last_sample
                .as_ref()
                .map(|s| {
                    format!(
                        "seq {} rate {:+8.3} {:+8.3} {:+8.3} dps",
                        s.seq, s.rate_dps[0], s.rate_dps[1], s.rate_dps[2]
                    )
                })
                .unwrap_or_default();
            bar.set_message(format!(
                "{} frames, {} corrupt, {} missing | {rate}",
                st.frames, st.corrupt, sum.link_missing
            ));
        }
    }
    bar.finish_and_clear();
    if let Some(f) = file.as_mut() {
        f.flush()?;
    }
    eprint!("{}", sum.report(&dec.stats()));
    Ok(true)
}

fn check(
    file: &std::path::Path,
    (samples, min_samples): (Option<u64>, Option<u64>),
    crc: Option<u32>,
    acks: Option<Vec<AckKind>>,
) -> Res<bool> {
    let (frames, dec) = read_recording(file)?;
    let mut sum = Summary::default();
    for r in &frames {
        sum.add(r);
    }
    let st = dec.stats();
    print!("{}", sum.report(&st));
    let mut fails = Vec::new();
    if st.frames == 0 {
        fails.push("no frame".to_string());
    }
    if st.corrupt + st.too_long + st.version + st.malformed > 0 || st.bytes_dropped > 0 {
        fails.push("frames failed to decode".into());
    }
    if sum.link_missing > 0 || sum.link_restarts > 0 {
        fails.push("gaps in the link sequence numbers".into());
    }
    if sum.sample_gaps > 0 {
        fails.push("gaps in the sample sequence numbers".into());
    }
    if let Some(n) = samples {
        if sum.samples != n {
            fails.push(format!("{} sample frames, expected {n}", sum.samples));
        }
    }
    if let Some(n) = min_samples {
        if sum.samples < n {
            fails.push(format!(
                "{} sample frames, expected at least {n}",
                sum.samples
            ));
        }
    }
    if let Some(c) = crc {
        if sum.fused_crc32() != c {
            fails.push(format!(
                "fused-rate CRC-32 {:#010x}, the firmware's {c:#010x}",
                sum.fused_crc32()
            ));
        }
    }
    if let Some(want) = acks {
        let got: Vec<AckKind> = sum.acks.iter().map(|a| AckKind::of(a.result)).collect();
        let ids_ok = sum
            .acks
            .iter()
            .enumerate()
            .all(|(i, a)| a.id == Some(i as u8));
        if got != want || !ids_ok {
            fails.push(format!(
                "acknowledgements {got:?}, expected {want:?} for ids 0.."
            ));
        }
    }
    for f in &fails {
        println!("FAIL: {f}");
    }
    if fails.is_empty() {
        println!("check: PASS");
    }
    Ok(fails.is_empty())
}

/// The first three CSV columns of a sample or raw frame.
fn lead(link_seq: u32, seq: u32, t_us: u64) -> Vec<String> {
    vec![link_seq.to_string(), seq.to_string(), t_us.to_string()]
}

fn decode(file: &std::path::Path, what: What, out: Option<PathBuf>) -> Res<bool> {
    let (frames, dec) = read_recording(file)?;
    let sink: Box<dyn Write> = match &out {
        Some(p) => Box::new(std::fs::File::create(p).map_err(|e| format!("{}: {e}", p.display()))?),
        None => Box::new(std::io::stdout().lock()),
    };
    let mut w = csv::Writer::from_writer(sink);
    let mut header_done = false;
    for d in frames.iter().flatten() {
        match (&d.body, what) {
            (Frame::Sample(s), What::Samples) => {
                if !header_done {
                    let mut h: Vec<String> = [
                        "link_seq",
                        "seq",
                        "t_us",
                        "age_x_us",
                        "age_y_us",
                        "age_z_us",
                        "predicted_us",
                        "x_dps",
                        "y_dps",
                        "z_dps",
                        "valid",
                        "degraded",
                        "used_x",
                        "used_y",
                        "used_z",
                    ]
                    .map(String::from)
                    .to_vec();
                    h.extend((0..s.health.len()).map(|i| format!("flags_{i}")));
                    w.write_record(&h)?;
                    header_done = true;
                }
                let mut r = lead(d.link_seq, s.seq, s.t_us);
                r.extend(s.age_us.iter().map(|v| v.to_string()));
                r.push(s.predicted_us.map_or(String::new(), |v| v.to_string()));
                r.extend(s.rate_dps.iter().map(|v| v.to_string()));
                r.extend([s.valid, s.degraded].iter().map(|v| v.to_string()));
                r.extend(s.used.iter().map(|v| v.to_string()));
                r.extend(s.health.iter().map(|v| v.to_string()));
                w.write_record(&r)?;
            }
            (Frame::Sample(s), What::Noise) => {
                let Some(n) = s.noise else { continue };
                if !header_done {
                    w.write_record([
                        "frame_seq",
                        "axis",
                        "describes_seq",
                        "window",
                        "bridged",
                        "sigma0_dps",
                        "sigma1_dps",
                        "sigma2_dps",
                    ])?;
                    header_done = true;
                }
                let mut r = vec![
                    s.seq.to_string(),
                    n.axis.to_string(),
                    n.seq.to_string(),
                    n.len.to_string(),
                    n.bridged.to_string(),
                ];
                r.extend(n.sigma_dps.iter().map(|v| v.to_string()));
                w.write_record(&r)?;
            }
            (Frame::Raw(s), What::Raw) => {
                if !header_done {
                    let mut h = vec!["link_seq".to_string(), "seq".into(), "t_us".into()];
                    h.extend((0..s.age_us.len()).map(|i| format!("g{i}_age_us")));
                    for i in 0..s.rate_dps.len() {
                        h.extend(["x", "y", "z"].map(|a| format!("g{i}_{a}_dps")));
                    }
                    h.extend((0..s.health.len()).map(|i| format!("flags_{i}")));
                    w.write_record(&h)?;
                    header_done = true;
                }
                let mut r = lead(d.link_seq, s.seq, s.t_us);
                r.extend(s.age_us.iter().map(|v| v.to_string()));
                for g in &s.rate_dps {
                    r.extend(g.iter().map(|v| v.to_string()));
                }
                r.extend(s.health.iter().map(|v| v.to_string()));
                w.write_record(&r)?;
            }
            (Frame::Status(s), What::Status) => {
                if !header_done {
                    let mut h: Vec<String> = [
                        "seq",
                        "t_us",
                        "mode",
                        "method",
                        "divider",
                        "overruns",
                        "sent",
                        "dropped",
                        "accepted",
                        "rejected",
                        "stack_peak",
                    ]
                    .map(String::from)
                    .to_vec();
                    // The online relative calibration and the clock of
                    // every gyro.
                    for i in 0..s.gyros.len() {
                        for q in ["scale_ppm", "bias_mdps"] {
                            h.extend(["x", "y", "z"].map(|a| format!("g{i}_{q}_{a}")));
                        }
                        h.extend(["clock", "clock_ppm", "late"].map(|q| format!("g{i}_{q}")));
                    }
                    w.write_record(&h)?;
                    header_done = true;
                }
                let mut r = vec![
                    s.seq.to_string(),
                    s.t_us.to_string(),
                    format!("{:?}", s.settings.mode),
                    format!("{:?}", s.settings.method),
                    s.settings.divider.to_string(),
                    s.overruns.to_string(),
                    s.link.sent.to_string(),
                    s.link.dropped.to_string(),
                    s.link.accepted.to_string(),
                    s.link.rejected.to_string(),
                    s.stack_peak.to_string(),
                ];
                for g in &s.gyros {
                    r.extend(g.scale_ppm.iter().map(|v| v.to_string()));
                    r.extend(g.bias_mdps.iter().map(|v| v.to_string()));
                    r.extend([
                        format!("{:?}", g.clock),
                        g.clock_ppm.to_string(),
                        g.late.to_string(),
                    ]);
                }
                w.write_record(&r)?;
            }
            _ => {}
        }
    }
    w.flush()?;
    let st = dec.stats();
    if st.frames != frames.len() as u64 {
        eprintln!(
            "gyro: {} of {} frames did not decode ({} bytes dropped)",
            frames.len() as u64 - st.frames,
            frames.len(),
            st.bytes_dropped
        );
    }
    Ok(true)
}
