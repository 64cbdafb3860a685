//! `gyro allan`: Allan-family deviations of a rate log, their confidence
//! intervals, the IEEE 952 fit and a Kalibr `imu.yaml`.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::ValueEnum;
use gyro_tool::{bulk, dev, edf, fit, plot, screen, short, stream, table, Res};
use indicatif::ProgressBar;

use crate::log_args::LogArgs;

#[derive(clap::Args)]
pub struct Args {
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
    /// Also fit the noise model (IEEE 952's Q, N, B, K, R and up to two
    /// Gauss–Markov processes, with 95 % intervals, a χ² test of the fit
    /// and the tangent readings) to each column's OADEV.
    #[arg(long)]
    fit: bool,
    /// Write a Kalibr imu.yaml from the fits: the gyroscope keys from the
    /// rate columns (the largest over the axes), the accelerometer keys
    /// from `--accel` columns (stated absent without them).
    #[arg(long)]
    kalibr: Option<PathBuf>,
    /// Accelerometer columns, m/s² (repeat), for `--kalibr`.
    #[arg(long = "accel")]
    accel: Vec<String>,
    /// Analyse only each column's longest stretch without steps or motion
    /// (the check runs always and reports what it finds).
    #[arg(long = "static")]
    only_static: bool,
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
    /// What to do where the time column has gaps: `tolerant` computes
    /// OADEV only from the terms no gap falls in (allantools' `gradev`,
    /// from the rates); `join` analyses the samples as if contiguous (the
    /// terms across a gap then mix rates from either side of it).
    #[arg(long, value_enum, default_value = "tolerant")]
    gaps: Gaps,
    /// The columns are phase, not rate: the integrated angle (deg, or rad
    /// with `--unit rads`), one value per sample, as Stable32's phase
    /// files and allantools' `data_type="phase"` are. Not screened (the
    /// screen reads rates).
    #[arg(long)]
    phase: bool,
    /// One pass in bounded memory (taken for `.npy` and `--raw` logs): a
    /// log of any length, its text parsed a block at a time, ADEV, OADEV,
    /// MDEV, TDEV, HDEV, OHDEV and TIE rms on octave, decade or
    /// per-decade factors, the fit. The columns are not screened; a gap
    /// in the time column stops it unless `--gaps join`.
    #[arg(long)]
    stream: bool,
    /// A raw little-endian binary log: f32 or f64, with xK for K values a
    /// row (f64x3); its columns are c1, c2, ….
    #[arg(long)]
    raw: Option<bulk::Raw>,
    /// Memory for the streamed pass's phase, MiB, over all columns: lags
    /// beyond it are read back from a spill file of the phase.
    #[arg(long, default_value_t = 256)]
    memory: usize,
    /// Where the streamed pass's spill file goes (8 bytes a sample; by
    /// default the system's temporary directory).
    #[arg(long)]
    spill_dir: Option<PathBuf>,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum Gaps {
    /// The gap-tolerant OADEV.
    Tolerant,
    /// The samples joined across each gap.
    Join,
}

fn confidence_arg(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v > 0.0 && v < 1.0 => Ok(v),
        _ => Err(format!("{s}: the confidence must be a number in (0, 1)")),
    }
}

#[derive(Clone, Copy, ValueEnum)]
enum OutFormat {
    /// Aligned text.
    Table,
    /// CSV: column, deviation, m, tau_s, value, terms.
    Csv,
    /// JSON: one object per column and deviation, with its points.
    Json,
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

/// One curve of `gyro allan`'s JSON output.
#[derive(serde::Serialize)]
struct CurveOut {
    column: String,
    deviation: dev::Kind,
    unit: &'static str,
    tau0_s: f64,
    samples: usize,
    points: Vec<dev::Point>,
}

/// `gyro allan`: read, compute every deviation of every column, write.
pub fn run(a: Args) -> Res<bool> {
    let Args {
        log,
        columns,
        dev: kinds,
        grid,
        format,
        out: out_file,
        fit: want_fit,
        kalibr,
        accel,
        only_static,
        svg,
        confidence: cf,
        chi2,
        gaps,
        phase,
        stream: want_stream,
        raw,
        memory,
        spill_dir,
    } = a;
    if phase && (only_static || matches!(log.unit, table::Unit::Dph | table::Unit::Lsb)) {
        return Err("--phase takes angles in deg (or rad with --unit rads), and is not screened: no --static".into());
    }
    if want_fit && matches!(format, OutFormat::Csv) {
        return Err("--fit has no place in the CSV of points: use --format json or table (or --kalibr for the Kalibr file)".into());
    }
    let columns = log.columns(&columns);
    let (file, columns, kinds) = (log.file.as_path(), &columns[..], &kinds[..]);
    let (time, tau0, unit, lsb) = (log.time.as_deref(), log.tau0, log.unit, log.lsb_per_dps);
    let started = Instant::now();
    if want_stream || bulk::is_binary(file, raw) {
        if only_static || !accel.is_empty() {
            return Err("--static and --accel read the whole log: not with a streamed (--stream, .npy, --raw) log".into());
        }
        let st = streamed(
            &log,
            columns,
            kinds,
            grid,
            (cf, chi2),
            want_fit || kalibr.is_some(),
            phase,
            gaps,
            (raw, memory, spill_dir),
        )?;
        let out = &st.out;
        emit(
            out,
            file,
            format,
            out_file.as_deref(),
            svg.as_deref(),
            kalibr.as_deref(),
            (&[], &[]),
        )?;
        eprintln!(
            "gyro: {} samples x {} columns in one pass: {:.1} s, {:.0} MB/s of input ({:.0} MB){}; peak memory {}",
            out.samples,
            out.curves.len() / kinds.len().max(1),
            started.elapsed().as_secs_f64(),
            st.bytes as f64 / 1e6 / started.elapsed().as_secs_f64(),
            st.bytes as f64 / 1e6,
            if st.spilled { ", the longer lags read back from the spill" } else { "" },
            peak_mib().map_or("unknown".to_string(), |m| format!("{m:.0} MiB"))
        );
        return Ok(true);
    }
    let s = table::read_layout(
        file,
        columns,
        (time, tau0),
        (unit, lsb),
        false,
        log.layout(),
    )?;
    let read_s = started.elapsed().as_secs_f64();
    for (line, step) in &s.gaps {
        eprintln!(
            "gyro: {}:{line}: gap of {step} s ({:.1} samples)",
            file.display(),
            step / s.tau0
        );
    }
    if !s.gaps.is_empty() && gaps == Gaps::Tolerant {
        if let Some(k) = kinds.iter().find(|k| **k != dev::Kind::Oadev) {
            return Err(format!(
                "{} gap(s) in the time column: only OADEV has a gap-tolerant estimator here, not {}; --dev oadev, or --gaps join to analyse the samples as contiguous",
                s.gaps.len(),
                k.name().to_uppercase()
            )
            .into());
        }
        if want_fit || kalibr.is_some() || only_static {
            return Err(format!(
                "{} gap(s) in the time column: the fit and --static need a log without gaps; cut the log, or --gaps join",
                s.gaps.len()
            )
            .into());
        }
        eprintln!(
            "gyro: {} gap(s): OADEV from only the terms no gap falls in (--gaps join to analyse the samples as contiguous)",
            s.gaps.len()
        );
    }
    let tolerant = !s.gaps.is_empty() && gaps == Gaps::Tolerant;
    if tolerant && phase {
        return Err("a phase log with gaps: not yet gap-tolerant here; --gaps join to analyse it as contiguous".into());
    }
    if !s.gaps.is_empty() && gaps == Gaps::Join {
        eprintln!(
            "gyro: {} gap(s): the samples analysed as contiguous (--gaps join)",
            s.gaps.len()
        );
    }
    let total = (s.rates.len() * kinds.len()) as u64;
    let bar = if s.rates.first().map_or(0, Vec::len) >= 1_000_000 {
        ProgressBar::new(total)
    } else {
        ProgressBar::hidden()
    };
    let mut curves = Vec::new();
    // Each column checked before it is believed (`gyro_tool::screen`): a
    // chip's start-up value is left out; steps and motion are said, and
    // with --static only the longest quiet stretch is analysed.
    let mut used: Vec<&[f64]> = Vec::new();
    // The constant columns: their phase is their offset taken out.
    let mut stuck = vec![false; s.rates.len()];
    // With gaps, each column on its time grid, the missing samples NaN.
    let filled: Vec<Vec<f64>> = if tolerant {
        (0..s.rates.len()).map(|c| s.with_gaps(c)).collect()
    } else {
        Vec::new()
    };
    for (name, rate) in s.names.iter().zip(&s.rates) {
        if tolerant || phase {
            break;
        }
        let sc = screen::screen(rate, s.tau0);
        if let Some(v) = sc.constant {
            eprintln!(
                "gyro: {name}: every sample reads {v}: a constant has no noise (a stuck or saturated sensor, or a setting logged as a rate?); its deviations are 0 and it has no noise model"
            );
            stuck[used.len()] = true;
            used.push(rate);
            continue;
        }
        if sc.no_data_later > 0 {
            return Err(format!(
                "{name}: the start-up value {} recurs at {} samples after the start: a chip that stopped converting; cut the log where it did",
                sc.startup_value.unwrap_or(f64::NAN),
                sc.no_data_later
            )
            .into());
        }
        if sc.startup > 0 {
            eprintln!(
                "gyro: {name}: the first {} samples read {} (a chip's start-up value, not a rate): left out",
                sc.startup,
                sc.startup_value.unwrap_or(f64::NAN)
            );
        }
        let (a, b) = sc.quiet;
        let stretch = format!(
            "{} to {} s",
            short(a as f64 * s.tau0),
            short(b as f64 * s.tau0)
        );
        if sc.spike_count > 0 {
            let at: Vec<String> = sc
                .spikes
                .iter()
                .map(|(i, v)| format!("{v:.4e} at {} s", short(*i as f64 * s.tau0)))
                .collect();
            let more = sc.spike_count - sc.spikes.len();
            eprintln!(
                "gyro: {name}: {} spike(s) (a sample over {} times the noise from both neighbours: a bit error or a shock): {}{}; {}",
                sc.spike_count,
                screen::SPIKE_SIGMAS,
                at.join(", "),
                if more > 0 { format!(" and {more} more") } else { String::new() },
                if only_static {
                    format!("analysed without them from {stretch} (--static)")
                } else {
                    format!("the deviations include them; --static analyses only the longest stretch without ({stretch})")
                }
            );
        }
        if !sc.is_static() {
            let what = if sc.moving {
                "it moves (neighbouring 1 s means differ by over ten times the noise)".to_string()
            } else {
                let at: Vec<String> = sc
                    .steps
                    .iter()
                    .map(|(i, d)| format!("{d:+.3e} at {} s", short(*i as f64 * s.tau0)))
                    .collect();
                format!("{} step(s): {}", sc.steps.len(), at.join(", "))
            };
            eprintln!(
                "gyro: {name}: NOT a static log: {what}; its noise figures mix in the motion. The longest quiet stretch is {stretch} ({} samples){}",
                b - a,
                if only_static { ": analysed alone (--static)" } else { "; --static analyses only it" }
            );
        }
        used.push(if only_static {
            &rate[a..b]
        } else {
            &rate[sc.startup..]
        });
    }
    for (name, y) in s.names.iter().zip(&filled) {
        curves.push(CurveOut {
            column: name.clone(),
            deviation: dev::Kind::Oadev,
            unit: "deg/s",
            tau0_s: s.tau0,
            samples: y.len(),
            points: dev::gap_curve(y, s.tau0, grid, (cf, chi2))?,
        });
        bar.inc(1);
    }
    // Each column's phase, once: the curves and the fit both read it.
    let phases = if phase {
        used = s.rates.iter().map(Vec::as_slice).collect();
        s.rates.clone()
    } else {
        used.iter()
            .zip(&stuck)
            .map(|(rate, &stuck)| {
                // A constant's phase with its offset out is 0, exactly (a
                // running sum of the value would leave its rounding).
                if stuck {
                    Ok(vec![0.0; rate.len() + 1])
                } else {
                    dev::phase_from_rate(rate, s.tau0)
                }
            })
            .collect::<Result<Vec<_>, _>>()?
    };
    for ((name, rate), x) in s.names.iter().zip(&used).zip(&phases) {
        let mut alphas = dev::Alphas::new();
        for &k in kinds {
            let points = dev::curve_with(k, x, s.tau0, grid, (cf, chi2), &mut alphas)?;
            curves.push(CurveOut {
                column: name.clone(),
                deviation: k,
                // TDEV, TTOTDEV, MTIE and TIE rms are in the phase's unit
                // (°); the others in °/s.
                unit: if k.in_phase_unit() { "deg" } else { "deg/s" },
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
        for ((name, x), &stuck) in s.names.iter().zip(&phases).zip(&stuck) {
            if stuck {
                continue;
            }
            match fit::fit_phase(x, s.tau0) {
                Ok(t) => fits.push((name.clone(), t)),
                Err(e @ fit::FitError::TooFewPoints) => eprintln!("gyro: {name}: {e}"),
                Err(e) => return Err(e.into()),
            }
        }
    }
    // The accelerometer columns' fits, for the Kalibr file.
    let mut accel_fits = Vec::new();
    if kalibr.is_some() && !accel.is_empty() {
        // Read as they are (m/s²): no rate unit applies.
        let a = table::read_layout(
            file,
            &accel,
            (time, tau0),
            (table::Unit::Dps, None),
            false,
            log.layout(),
        )?;
        for (name, r) in a.names.iter().zip(&a.rates) {
            let x = dev::phase_from_rate(r, a.tau0)?;
            match fit::fit_phase(&x, a.tau0) {
                Ok(t) => accel_fits.push(t),
                Err(e) => return Err(format!("{name}: {e}").into()),
            }
        }
    }
    let out = Outputs {
        curves,
        fits,
        tau0: s.tau0,
        samples: s.rates.first().map_or(0, Vec::len),
    };
    emit(
        &out,
        file,
        format,
        out_file.as_deref(),
        svg.as_deref(),
        kalibr.as_deref(),
        (&accel, &accel_fits),
    )?;
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

/// What `gyro allan` found, to write.
struct Outputs {
    curves: Vec<CurveOut>,
    fits: Vec<(String, fit::Terms)>,
    tau0: f64,
    samples: usize,
}

/// Write the curves and fits as asked: the Kalibr file, the SVG, the
/// table, CSV or JSON.
fn emit(
    out: &Outputs,
    file: &Path,
    format: OutFormat,
    out_file: Option<&Path>,
    svg: Option<&Path>,
    kalibr: Option<&Path>,
    (accel, accel_fits): (&[String], &[fit::Terms]),
) -> Res<()> {
    if let Some(path) = kalibr {
        let gyro_fits: Vec<fit::Terms> = out
            .fits
            .iter()
            .filter(|(n, _)| !accel.contains(n))
            .map(|(_, t)| t.clone())
            .collect();
        let text = fit::kalibr_yaml(&gyro_fits, accel_fits, short(1.0 / out.tau0), "/imu0")
            .ok_or("no gyro fit for a Kalibr file")?;
        std::fs::write(path, text)?;
    }
    if let Some(path) = svg {
        let cs: Vec<plot::Curve> = out
            .curves
            .iter()
            .map(|c| plot::Curve {
                // A time (angle) deviation: its unit is on its label.
                label: if c.deviation.in_phase_unit() {
                    format!(
                        "{} {} (deg, not deg/s)",
                        c.column,
                        c.deviation.name().to_uppercase()
                    )
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
            out.samples,
            short(out.tau0)
        );
        plot::draw(path, &title, "°/s", &cs, &out.fits)?;
    }
    let mut w: Box<dyn Write> = match out_file {
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
                curves: &'a [CurveOut],
                fits: Vec<FitOut<'a>>,
            }
            let fits = out
                .fits
                .iter()
                .map(|(c, t)| FitOut {
                    column: c,
                    terms: t,
                })
                .collect();
            serde_json::to_writer_pretty(
                &mut w,
                &Out {
                    curves: &out.curves,
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
            for cv in &out.curves {
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
            for cv in &out.curves {
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
                if cv.points.is_empty() {
                    writeln!(
                        w,
                        "  no tau with a value: too few samples{}",
                        if matches!(cv.deviation, dev::Kind::Theobr | dev::Kind::Theoh) {
                            format!(
                                " (TheoBR's bias ratio needs {} phase points)",
                                gyro_tool::kind::THEO_BR_MIN_POINTS
                            )
                        } else {
                            String::new()
                        }
                    )?;
                }
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
            for (name, t) in &out.fits {
                fit::write_table(&mut w, name, t)?;
            }
        }
    }
    Ok(())
}

/// A streamed run's results, and the log's size and whether the phase
/// went to the spill.
struct Streamed {
    out: Outputs,
    bytes: u64,
    spilled: bool,
}

/// `gyro allan --stream`: every column through [`stream::analyse_file`] in
/// one pass over the log.
#[allow(clippy::too_many_arguments)]
fn streamed(
    log: &LogArgs,
    columns: &[String],
    kinds: &[dev::Kind],
    grid: dev::Grid,
    ci: (f64, edf::Chi2),
    fit_too: bool,
    phase: bool,
    gaps: Gaps,
    (raw, memory_mib, spill_dir): (Option<bulk::Raw>, usize, Option<PathBuf>),
) -> Res<Streamed> {
    let job = stream::FileJob {
        path: log.file.clone(),
        columns: columns.to_vec(),
        time: log.time.clone(),
        tau0: log.tau0,
        unit: (log.unit, log.lsb_per_dps),
        layout: log.layout(),
        raw,
        phase,
        join_gaps: gaps == Gaps::Join,
        memory_mib,
    };
    let plan = stream::Plan {
        kinds: kinds.to_vec(),
        grid,
        ci,
        fit: fit_too,
        ring: 0,
        spill_dir,
    };
    if !phase {
        eprintln!(
            "gyro: --stream: the columns are not screened for a start-up value, steps or motion"
        );
    }
    let bar = ProgressBar::hidden();
    let mut progress = |done: u64, size: u64| {
        if size >= 100_000_000 && bar.is_hidden() {
            bar.set_draw_target(indicatif::ProgressDrawTarget::stderr());
            bar.set_length(size);
        }
        bar.set_position(done);
    };
    let stop = std::sync::atomic::AtomicBool::new(false);
    let f = stream::analyse_file(&job, plan, &mut progress, &stop).map_err(|e| {
        // The memory's error names the option it came from.
        match e.downcast_ref::<stream::StreamError>() {
            Some(m @ stream::StreamError::Memory(..)) => format!("--memory: {m}").into(),
            _ => e,
        }
    })?;
    bar.finish_and_clear();
    for (place, step) in &f.gaps {
        eprintln!(
            "gyro: {}:{place}: gap of {step} s ({:.1} samples), joined (--gaps join)",
            log.file.display(),
            step / f.tau0
        );
    }
    if !f.gaps.is_empty() {
        eprintln!(
            "gyro: {} gap(s): the samples analysed as contiguous (--gaps join)",
            f.gaps.len()
        );
    }
    let mut curves = Vec::new();
    let mut fits = Vec::new();
    for (c, name) in f.columns.iter().zip(&f.names) {
        let samples = if phase { c.n } else { c.n - 1 };
        for (kind, points) in &c.curves {
            curves.push(CurveOut {
                column: name.clone(),
                deviation: *kind,
                unit: if kind.in_phase_unit() { "deg" } else { "deg/s" },
                tau0_s: f.tau0,
                samples,
                points: points.clone(),
            });
        }
        if fit_too {
            match fit::fit(&c.fit_points, c.n) {
                Some(t) => fits.push((name.clone(), t)),
                None => eprintln!("gyro: {name}: {}", fit::FitError::TooFewPoints),
            }
        }
    }
    Ok(Streamed {
        out: Outputs {
            curves,
            fits,
            tau0: f.tau0,
            samples: f.samples,
        },
        bytes: f.bytes,
        spilled: f.spilled,
    })
}
