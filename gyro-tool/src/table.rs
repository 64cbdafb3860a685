//! Reading rate logs: comma-, semicolon-, tab- or blank-separated text,
//! with a header line or without one (a Stable32 `.dat` column, a plain
//! export: the columns are then named `c1`, `c2`, …), one column per
//! series (axes, gyros), optionally a time column; units
//! °/s, rad/s, °/h or raw LSB with a scale. Every problem is a typed error
//! with the file and line; gaps and non-monotonic time are found and
//! reported, never skipped silently.

use std::fmt;
use std::path::{Path, PathBuf};

/// Units of the rate columns.
#[derive(Clone, Copy, Debug, PartialEq, clap::ValueEnum)]
pub enum Unit {
    /// Degrees per second.
    Dps,
    /// Radians per second.
    Rads,
    /// Degrees per hour.
    Dph,
    /// Raw counts (give `--lsb-per-dps`).
    Lsb,
}

/// A problem with the input.
#[derive(Debug)]
pub enum TableError {
    /// The file could not be read.
    Io(PathBuf, std::io::Error),
    /// No header line, or an empty file.
    NoHeader(PathBuf),
    /// A named column is not in the header.
    NoColumn(PathBuf, String, Vec<String>),
    /// A field is not a finite number (file, line, column, text).
    Number(PathBuf, usize, String, String),
    /// A line has a different number of fields than the header.
    Fields(PathBuf, usize, usize, usize),
    /// Time goes backwards or repeats (file, line, t before, t).
    Time(PathBuf, usize, f64, f64),
    /// Fewer than 3 samples.
    TooShort(PathBuf, usize),
    /// Unit LSB without a positive scale, or a bad scale.
    Scale,
    /// Neither a sample period nor a time column with two samples.
    NoTau0,
    /// A line could not be read as a record (file, line, why).
    Record(PathBuf, usize, String),
    /// A row of empty fields between rows with values, in a log without a
    /// time column (file, line): a sample missing, which its place alone
    /// cannot skip.
    EmptyRow(PathBuf, usize),
}

impl fmt::Display for TableError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TableError::Io(p, e) => write!(f, "{}: {e}", p.display()),
            TableError::NoHeader(p) => write!(f, "{}: no header line", p.display()),
            TableError::Record(p, l, e) => write!(f, "{}:{l}: {e}", p.display()),
            TableError::EmptyRow(p, l) => write!(
                f,
                "{}:{l}: a row with no value in any column between rows with values: a sample missing, which a log without a time column cannot skip (every later sample would move a period earlier); give the time column, or fill the row",
                p.display()
            ),
            TableError::NoColumn(p, c, have) => {
                write!(
                    f,
                    "{}: no column {c:?} (columns: {})",
                    p.display(),
                    have.join(", ")
                )
            }
            TableError::Number(p, l, c, t) => {
                write!(
                    f,
                    "{}:{l}: column {c:?}: {t:?} is not a finite number",
                    p.display()
                )
            }
            TableError::Fields(p, l, got, want) => {
                write!(
                    f,
                    "{}:{l}: {got} fields, the header has {want}",
                    p.display()
                )
            }
            TableError::Time(p, l, a, b) => write!(
                f,
                "{}:{l}: time {b} does not follow {a} (non-monotonic)",
                p.display()
            ),
            TableError::TooShort(p, n) => {
                write!(f, "{}: {n} samples, at least 3 are needed", p.display())
            }
            TableError::Scale => write!(f, "--unit lsb needs --lsb-per-dps > 0 (finite)"),
            TableError::NoTau0 => write!(f, "give --tau0, or --time with a time column"),
        }
    }
}

impl std::error::Error for TableError {}

/// The series read, in °/s.
#[derive(Debug)]
pub struct Series {
    /// Column names.
    pub names: Vec<String>,
    /// One vector per column, °/s.
    pub rates: Vec<Vec<f64>>,
    /// Sample period, s (given, or the median step of the time column).
    pub tau0: f64,
    /// Gaps found in the time column: (line, step in s) where a step
    /// exceeds 1.5 τ0.
    pub gaps: Vec<(usize, f64)>,
    /// The same gaps by sample: (index of the first sample after the gap,
    /// samples missing: the step in periods, rounded, less one).
    pub gap_samples: Vec<(usize, usize)>,
}

impl Series {
    /// Column `c`'s rates with each gap's missing samples put back as NaN
    /// (the time grid the log should have had).
    pub fn with_gaps(&self, c: usize) -> Vec<f64> {
        let r = &self.rates[c];
        let missing: usize = self.gap_samples.iter().map(|g| g.1).sum();
        let mut out = Vec::with_capacity(r.len() + missing);
        let mut from = 0;
        for &(at, k) in &self.gap_samples {
            out.extend_from_slice(&r[from..at]);
            out.extend(std::iter::repeat_n(f64::NAN, k));
            from = at;
        }
        out.extend_from_slice(&r[from..]);
        out
    }
}

/// The factor that turns a column in `unit` into °/s (the value is
/// multiplied by it).
pub(crate) fn scale_of(unit: Unit, lsb_per_dps: Option<f64>) -> Result<f64, TableError> {
    Ok(match unit {
        Unit::Dps => 1.0,
        Unit::Rads => 180.0 / std::f64::consts::PI,
        Unit::Dph => 1.0 / 3600.0,
        Unit::Lsb => match lsb_per_dps {
            Some(s) if s.is_finite() && s > 0.0 => 1.0 / s,
            _ => return Err(TableError::Scale),
        },
    })
}

/// A text log's separator: the first of comma, semicolon and tab that its
/// first line holds, else blanks.
pub(crate) fn delimiter_of(first_line: &str) -> u8 {
    [b',', b';', b'\t']
        .into_iter()
        .find(|&d| first_line.as_bytes().contains(&d))
        .unwrap_or(b' ')
}

/// Read `path`: the named `columns` (all but the time column when empty),
/// with `time` the time column in s (or `tau0` given).
pub fn read(
    path: &Path,
    columns: &[String],
    time: Option<&str>,
    tau0: Option<f64>,
    unit: Unit,
    lsb_per_dps: Option<f64>,
) -> Result<Series, TableError> {
    read_with(path, columns, time, tau0, (unit, lsb_per_dps), false)
}

/// [`read`], where with `missing` an empty or `nan` cell of a rate column
/// reads as NaN (a chip that did not answer) instead of an error.
pub fn read_with(
    path: &Path,
    columns: &[String],
    time: Option<&str>,
    tau0: Option<f64>,
    units: (Unit, Option<f64>),
    missing: bool,
) -> Result<Series, TableError> {
    read_layout(
        path,
        columns,
        (time, tau0),
        units,
        missing,
        Layout::default(),
    )
}

/// How a text log is laid out, where the detection should be overruled.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Layout {
    /// The separator (`b' '`: runs of blanks); detected when None.
    pub delimiter: Option<u8>,
    /// Whether the first line is a header; detected when None.
    pub header: Option<bool>,
}

/// [`read_with`] with the text's layout given where `layout` says.
pub fn read_layout(
    path: &Path,
    columns: &[String],
    (time, tau0): (Option<&str>, Option<f64>),
    (unit, lsb_per_dps): (Unit, Option<f64>),
    missing: bool,
    layout: Layout,
) -> Result<Series, TableError> {
    let scale = scale_of(unit, lsb_per_dps)?;
    // A robot log: its own stamps (τ0 the median step unless `--tau0`)
    // and units (rad/s, read as °/s); with `missing`, several IMU topics
    // on one grid.
    type RobotRead = fn(&Path, &[String], bool) -> Result<Series, TableError>;
    let robot: Option<RobotRead> = if crate::ros1::is_bag(path) {
        Some(crate::ros1::read)
    } else if crate::ros2::is_bag(path) {
        Some(crate::ros2::read)
    } else if crate::dataflash::is_log(path) {
        Some(crate::dataflash::read)
    } else if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("ulg"))
    {
        Some(crate::ulog::read)
    } else {
        None
    };
    if let Some(read) = robot {
        let mut s = read(path, columns, missing)?;
        if let Some(t) = tau0 {
            s.tau0 = t;
        }
        return Ok(s);
    }
    let p = || path.to_path_buf();
    let open = || {
        std::fs::File::open(path)
            .map(std::io::BufReader::new)
            .map_err(|e| TableError::Io(path.to_path_buf(), e))
    };
    // The separator from the first line ([`delimiter_of`]). With
    // semicolons a decimal comma is read as a point (the European
    // spreadsheet's export).
    let head_line = {
        use std::io::BufRead;
        let mut found = None;
        for l in open()?.lines() {
            let l = l.map_err(|e| TableError::Io(p(), e))?;
            let l = l.trim();
            if !l.is_empty() && !l.starts_with('#') {
                found = Some(l.to_string());
                break;
            }
        }
        found.ok_or_else(|| TableError::NoHeader(p()))?
    };
    let delimiter = layout.delimiter.unwrap_or_else(|| delimiter_of(&head_line));
    // Blank- and tab-separated text may repeat its separator for alignment.
    let comma = matches!(delimiter, b',' | b';');
    let decimal_comma = delimiter == b';';
    // One reader over the whole file, streamed (one reader per line cost
    // 90 % of the time of a 360 000-line log, and holding a 24 h log's text
    // 2 GB): comment lines skipped, fields trimmed, and in whitespace mode
    // the empty fields between repeated blanks dropped.
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .delimiter(delimiter)
        .comment(Some(b'#'))
        .flexible(true)
        .from_reader(open()?);
    // A record that cannot be read (not UTF-8, an I/O error) is an error
    // with its line, never skipped.
    let lines = reader.records().filter_map(|r| {
        let rec = match r {
            Ok(rec) => rec,
            Err(e) => {
                let ln = e.position().map_or(0, |q| q.line() as usize);
                return Some(Err(TableError::Record(p(), ln, e.to_string())));
            }
        };
        let ln = rec.position().map_or(0, |q| q.line() as usize);
        let f: Vec<String> = rec
            .iter()
            .map(|f| {
                let f = f.trim();
                if decimal_comma {
                    f.replace(',', ".")
                } else {
                    f.to_string()
                }
            })
            .filter(|f| comma || !f.is_empty())
            .collect();
        // A line of blanks is no record; separators with nothing between
        // them are a row with no value (kept: see below).
        (!f.iter().all(String::is_empty) || f.len() > 1).then_some(Ok((ln, f)))
    });
    // Rows of empty fields before the header are padding.
    let mut lines = lines.skip_while(|r| matches!(r, Ok((_, f)) if f.iter().all(String::is_empty)));
    let (first_ln, first) = lines.next().ok_or_else(|| TableError::NoHeader(p()))??;
    // A first line of numbers is data: the file has no header.
    let headerless = layout
        .header
        .map_or_else(|| first.iter().all(|f| f.parse::<f64>().is_ok()), |h| !h);
    let header: Vec<String> = if headerless {
        (1..=first.len()).map(|i| format!("c{i}")).collect()
    } else {
        first.clone()
    };
    let lines = headerless
        .then_some(Ok((first_ln, first)))
        .into_iter()
        .chain(lines);

    let find = |c: &str| {
        header
            .iter()
            .position(|h| h == c)
            .ok_or_else(|| TableError::NoColumn(p(), c.to_string(), header.clone()))
    };
    let tcol = time.map(find).transpose()?;
    let cols: Vec<usize> = if columns.is_empty() {
        (0..header.len()).filter(|&i| Some(i) != tcol).collect()
    } else {
        columns.iter().map(|c| find(c)).collect::<Result<_, _>>()?
    };
    let mut rates = vec![Vec::new(); cols.len()];
    let mut times: Vec<(usize, f64)> = Vec::new();
    // Rows of empty fields since the last row with a value: with a time
    // column no record (the stamps show the gap); without one a sample
    // none of whose columns has a value, where another row follows
    // (dropped, every later sample would move a period earlier), and a
    // spreadsheet's padding at the end of the file where none does.
    // (The first such row's line, and how many.)
    let (mut empties, mut seen): (Option<(usize, usize)>, bool) = (None, false);
    for line in lines {
        let (ln, f) = line?;
        if f.iter().all(String::is_empty) {
            if tcol.is_none() && seen {
                empties.get_or_insert((ln, 0)).1 += 1;
            }
            continue;
        }
        if let Some((ln, count)) = empties.take() {
            if !missing {
                return Err(TableError::EmptyRow(p(), ln));
            }
            for r in rates.iter_mut() {
                r.extend(std::iter::repeat_n(f64::NAN, count));
            }
        }
        seen = true;
        if f.len() != header.len() {
            return Err(TableError::Fields(p(), ln, f.len(), header.len()));
        }
        let num = |i: usize| -> Result<f64, TableError> {
            f[i].parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| TableError::Number(p(), ln, header[i].clone(), f[i].clone()))
        };
        if let Some(t) = tcol {
            let v = num(t)?;
            if let Some(&(_, prev)) = times.last() {
                if v <= prev {
                    return Err(TableError::Time(p(), ln, prev, v));
                }
            }
            times.push((ln, v));
        }
        for (r, &c) in rates.iter_mut().zip(&cols) {
            let absent = missing && (f[c].is_empty() || f[c].eq_ignore_ascii_case("nan"));
            r.push(if absent { f64::NAN } else { num(c)? * scale });
        }
    }
    let n = rates.first().map_or(0, Vec::len);
    if n < 3 {
        return Err(TableError::TooShort(p(), n));
    }
    let (tau0, gaps, gap_samples) = match (tau0, times.len()) {
        (Some(t), _) => (t, Vec::new(), Vec::new()),
        (None, k) if k >= 2 => {
            let steps: Vec<f64> = times.windows(2).map(|w| w[1].1 - w[0].1).collect();
            let (med, (gaps, gap_samples)) = gaps_of(&steps);
            let gaps = gaps
                .into_iter()
                .map(|(k, step)| (times[k].0, step))
                .collect();
            (med, gaps, gap_samples)
        }
        _ => return Err(TableError::NoTau0),
    };
    Ok(Series {
        names: cols.iter().map(|&c| header[c].clone()).collect(),
        rates,
        tau0,
        gaps,
        gap_samples,
    })
}

/// Gaps as (index of the sample after each, step in s) and as (that
/// index, samples missing).
type Gaps = (Vec<(usize, f64)>, Vec<(usize, usize)>);

/// The sample period of time steps `steps` (s; their median) and its gaps:
/// the steps over 1.5 periods.
pub(crate) fn gaps_of(steps: &[f64]) -> (f64, Gaps) {
    let mut sorted = steps.to_vec();
    sorted.sort_by(f64::total_cmp);
    let med = sorted[sorted.len() / 2];
    let (mut gaps, mut samples) = (Vec::new(), Vec::new());
    for (k, &d) in steps.iter().enumerate() {
        if d > 1.5 * med {
            gaps.push((k + 1, d));
            samples.push((k + 1, ((d / med).round() as usize).saturating_sub(1).max(1)));
        }
    }
    (med, (gaps, samples))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(name: &str, text: &str) -> PathBuf {
        let p = std::env::temp_dir().join(format!("gyro-table-{}-{name}", std::process::id()));
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn semicolons_tabs_decimal_commas_and_files_without_a_header() {
        for (name, text) in [
            ("tab.tsv", "t\tz\n0\t1.5\n0.01\t2\n0.02\t-1\n"),
            ("semi.csv", "t;z\n0;1,5\n0,01;2\n0,02;-1\n"),
            ("tabs.txt", "t\t\tz\n0\t\t1.5\n0.01\t2\n0.02\t-1\n"),
        ] {
            let s = read(&write(name, text), &[], Some("t"), None, Unit::Dps, None).unwrap();
            assert_eq!(s.names, ["z"], "{name}");
            assert_eq!(s.rates[0], [1.5, 2.0, -1.0], "{name}");
            assert!((s.tau0 - 0.01).abs() < 1e-12, "{name}");
        }
        // A Stable32-style column: every line is data, the first included.
        let col = write("col.dat", "1.5\n2\n-1\n0.25\n");
        let s = read(&col, &[], None, Some(1.0), Unit::Dps, None).unwrap();
        assert_eq!(s.names, ["c1"]);
        assert_eq!(s.rates[0], [1.5, 2.0, -1.0, 0.25]);
        // Two columns without a header, the first a time.
        let two = write("two.txt", "0 1\n0.5 2\n1.0 3\n");
        let s = read(&two, &[], Some("c1"), None, Unit::Dps, None).unwrap();
        assert_eq!(
            (s.names.clone(), s.rates[0].clone()),
            (vec!["c2".to_string()], vec![1.0, 2.0, 3.0])
        );
        assert!((s.tau0 - 0.5).abs() < 1e-12);
    }

    #[test]
    fn the_layout_can_be_overruled() {
        let dps = (Unit::Dps, None);
        // Another separator.
        let p = write("pipe.txt", "x|y\n1|2\n3|4\n5|6\n");
        let l = Layout {
            delimiter: Some(b'|'),
            header: None,
        };
        let s = read_layout(&p, &[], (None, Some(1.0)), dps, false, l).unwrap();
        assert_eq!(
            (s.names.clone(), s.rates[1].clone()),
            (vec!["x".into(), "y".into()], vec![2.0, 4.0, 6.0])
        );
        // A header of numbers (channel numbers) read as a header.
        let p = write("numhead.csv", "1,2\n1.5,2\n3,4\n5,6\n");
        let l = Layout {
            delimiter: None,
            header: Some(true),
        };
        let s = read_layout(&p, &[], (None, Some(1.0)), dps, false, l).unwrap();
        assert_eq!(s.names, ["1", "2"]);
        assert_eq!(s.rates[0], [1.5, 3.0, 5.0]);
        // No header where the detection would take one: the first line's
        // text is then a bad number, with its line.
        let p = write("nohead.csv", "1.5,NA\n3,4\n5,6\n");
        let l = Layout {
            delimiter: None,
            header: Some(false),
        };
        let e = read_layout(&p, &[], (None, Some(1.0)), dps, false, l).unwrap_err();
        assert!(matches!(e, TableError::Number(_, 1, _, _)), "{e}");
    }

    #[test]
    fn csv_and_whitespace_units_time_and_errors() {
        let p = write("a.csv", "t,x,y\n0,1,2\n0.01,1.5,2\n0.02,1,2\n0.05,1,2\n");
        let s = read(&p, &[], Some("t"), None, Unit::Dps, None).unwrap();
        assert_eq!(s.names, ["x", "y"]);
        assert_eq!(s.rates[0], [1.0, 1.5, 1.0, 1.0]);
        assert!((s.tau0 - 0.01).abs() < 1e-12);
        assert_eq!(s.gaps.len(), 1, "{:?}", s.gaps);
        let p = write("b.txt", "# comment\nz   w\n3600 7200\n0 0\n-3600 1\n");
        let s = read(&p, &["z".into()], None, Some(1.0), Unit::Dph, None).unwrap();
        assert_eq!(s.rates[0], [1.0, 0.0, -1.0]);
        let s = read(&p, &["w".into()], None, Some(1.0), Unit::Lsb, Some(2.0)).unwrap();
        assert_eq!(s.rates[0], [3600.0, 0.0, 0.5]);
        assert!(matches!(
            read(&p, &[], None, Some(1.0), Unit::Lsb, None),
            Err(TableError::Scale)
        ));
        let bad = write("c.csv", "t,x\n0,1\n0.01,nan\n");
        let e = read(&bad, &[], Some("t"), None, Unit::Dps, None).unwrap_err();
        assert!(matches!(e, TableError::Number(_, 3, _, _)), "{e}");
        assert!(e.to_string().contains(":3:"), "{e}");
        let back = write("d.csv", "t,x\n0,1\n0.02,1\n0.01,1\n");
        assert!(matches!(
            read(&back, &[], Some("t"), None, Unit::Dps, None),
            Err(TableError::Time(_, 4, _, _))
        ));
        let short = write("e.csv", "t,x\n0,1\n1\n");
        assert!(matches!(
            read(&short, &[], Some("t"), None, Unit::Dps, None),
            Err(TableError::Fields(_, 3, 1, 2))
        ));
        assert!(matches!(
            read(&p, &["q".into()], None, Some(1.0), Unit::Dps, None),
            Err(TableError::NoColumn(..))
        ));
        let missing = std::env::temp_dir().join("gyro-table-no-such-file");
        assert!(matches!(
            read(&missing, &[], None, Some(1.0), Unit::Dps, None),
            Err(TableError::Io(..))
        ));
    }
}
