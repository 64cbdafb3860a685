//! Long logs read a block at a time, for [`crate::stream`]: text parsed
//! straight into the columns asked for (no table of every field), and
//! binary files (`.npy`, raw little-endian f32 or f64) read through a
//! memory map whose pages are let go behind the reader, so neither holds
//! more than a block of the log.
//!
//! The text follows [`crate::table`]'s rules (the separator from the first
//! line, a header unless the first line is numbers, `#` comments, decimal
//! commas with semicolons, the same typed errors with the line), so a log
//! reads the same values either way (`tests`).

use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};

use memmap2::{Advice, Mmap, UncheckedAdvice};

use crate::table::{self, Layout, TableError, Unit};

/// Rows a call to [`Reader::next`] reads at most.
pub const ROWS: usize = 1 << 14;

/// A raw binary log's element type and row width (`--raw f32`, `f64x3`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Raw {
    pub f32: bool,
    pub width: usize,
}

impl std::str::FromStr for Raw {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let (ty, w) = s.split_once('x').unwrap_or((s, "1"));
        let f32 = match ty {
            "f32" => true,
            "f64" => false,
            _ => {
                return Err(format!(
                    "{s}: f32 or f64, with xK for K values a row (f64x3)"
                ))
            }
        };
        match w.parse::<usize>() {
            Ok(width) if (1..=4096).contains(&width) => Ok(Raw { f32, width }),
            _ => Err(format!("{s}: the row width after x is 1 to 4096")),
        }
    }
}

/// The columns of a log, read a block at a time.
pub struct Reader {
    /// The columns read, by name.
    pub names: Vec<String>,
    /// Whether a time column is read (each block's stamps in `times`).
    pub timed: bool,
    inner: Inner,
}

enum Inner {
    Text(Box<Text>),
    Binary(Binary),
}

/// Whether `path` is a binary log [`open`] reads by memory map.
pub fn is_binary(path: &Path, raw: Option<Raw>) -> bool {
    raw.is_some()
        || path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("npy"))
}

/// Open `path`'s `columns` (every column but the time column when empty;
/// `c1`, `c2`, … in a binary log or a text without a header) in `unit`.
pub fn open(
    path: &Path,
    columns: &[String],
    time: Option<&str>,
    (unit, lsb_per_dps): (Unit, Option<f64>),
    layout: Layout,
    raw: Option<Raw>,
) -> Result<Reader, TableError> {
    let scale = table::scale_of(unit, lsb_per_dps)?;
    if is_binary(path, raw) {
        let b = Binary::open(path, raw, scale)?;
        let header: Vec<String> = (1..=b.width).map(|i| format!("c{i}")).collect();
        let tcol = time.map(|t| find(path, &header, t)).transpose()?;
        let cols = pick(path, &header, columns, tcol)?;
        return Ok(Reader {
            names: cols.iter().map(|&c| header[c].clone()).collect(),
            timed: tcol.is_some(),
            inner: Inner::Binary(Binary { cols, tcol, ..b }),
        });
    }
    let t = Text::open(path, columns, time, scale, layout)?;
    Ok(Reader {
        names: t.cols.iter().map(|&c| t.header[c].clone()).collect(),
        timed: t.tcol.is_some(),
        inner: Inner::Text(Box::new(t)),
    })
}

fn find(path: &Path, header: &[String], c: &str) -> Result<usize, TableError> {
    header
        .iter()
        .position(|h| h == c)
        .ok_or_else(|| TableError::NoColumn(path.to_path_buf(), c.to_string(), header.to_vec()))
}

fn pick(
    path: &Path,
    header: &[String],
    columns: &[String],
    tcol: Option<usize>,
) -> Result<Vec<usize>, TableError> {
    if columns.is_empty() {
        Ok((0..header.len()).filter(|&i| Some(i) != tcol).collect())
    } else {
        columns.iter().map(|c| find(path, header, c)).collect()
    }
}

impl Reader {
    /// Up to [`ROWS`] more rows: each column's values into `out` (cleared
    /// first), the stamps into `times` where the log is timed. 0 at the end.
    pub fn next(
        &mut self,
        out: &mut [Vec<f64>],
        times: &mut Vec<f64>,
    ) -> Result<usize, TableError> {
        for o in out.iter_mut() {
            o.clear();
        }
        times.clear();
        match &mut self.inner {
            Inner::Text(t) => t.next(out, times),
            Inner::Binary(b) => Ok(b.next(out, times)),
        }
    }

    /// Where the last row read came from, for a message: "line L" of a text
    /// log, "row R" of a binary one.
    pub fn place(&self, row_in_block: usize) -> String {
        let what = match self.inner {
            Inner::Text(_) => "line",
            Inner::Binary(_) => "row",
        };
        format!("{what} {}", self.line(row_in_block))
    }

    /// The line (text) or 1-based row (binary) of row `row_in_block` of
    /// the last block.
    pub fn line(&self, row_in_block: usize) -> usize {
        match &self.inner {
            Inner::Text(t) => t.lines.get(row_in_block).copied().unwrap_or(0),
            Inner::Binary(b) => b.pos - b.last + row_in_block + 1,
        }
    }

    /// Bytes of the log read so far (of its size: [`Reader::size`]).
    pub fn bytes_read(&self) -> u64 {
        match &self.inner {
            Inner::Text(t) => t.consumed,
            Inner::Binary(b) => (b.offset + b.pos * b.width * b.elem) as u64,
        }
    }

    /// The log's size, bytes.
    pub fn size(&self) -> u64 {
        match &self.inner {
            Inner::Text(t) => t.size,
            Inner::Binary(b) => b.map.len() as u64,
        }
    }
}

/// A text log, parsed a block at a time.
struct Text {
    path: PathBuf,
    file: File,
    size: u64,
    buf: Vec<u8>,
    /// Unparsed bytes: buf[at..end].
    at: usize,
    end: usize,
    eof: bool,
    line: usize,
    consumed: u64,
    delimiter: u8,
    blanks: bool,
    decimal_comma: bool,
    header: Vec<String>,
    cols: Vec<usize>,
    tcol: Option<usize>,
    scale: f64,
    /// The line of each row of the last block.
    lines: Vec<usize>,
    /// A first line of data held back by the header's detection.
    first: Option<(usize, Vec<u8>)>,
    field: Vec<u8>,
    /// A row was read (rows of empty fields before it are padding).
    seen: bool,
    /// The first row of empty fields since the last row: a sample none of
    /// whose columns has a value where another row follows (the table
    /// reader's rule), padding if none does.
    empty_at: Option<usize>,
}

const BLOCK: usize = 1 << 22;

impl Text {
    fn open(
        path: &Path,
        columns: &[String],
        time: Option<&str>,
        scale: f64,
        layout: Layout,
    ) -> Result<Text, TableError> {
        let io = |e| TableError::Io(path.to_path_buf(), e);
        let file = File::open(path).map_err(io)?;
        let size = file.metadata().map_err(io)?.len();
        let mut t = Text {
            path: path.to_path_buf(),
            file,
            size,
            buf: vec![0; BLOCK],
            at: 0,
            end: 0,
            eof: false,
            line: 0,
            consumed: 0,
            delimiter: b',',
            blanks: false,
            decimal_comma: false,
            header: Vec::new(),
            cols: Vec::new(),
            tcol: None,
            scale,
            lines: Vec::new(),
            first: None,
            field: Vec::new(),
            seen: false,
            empty_at: None,
        };
        let (ln, first) = loop {
            match t.next_line()? {
                None => return Err(TableError::NoHeader(t.path.clone())),
                Some((ln, l)) => {
                    let l = l.trim_ascii();
                    if !l.is_empty() && !l.starts_with(b"#") {
                        break (ln, l.to_vec());
                    }
                }
            }
        };
        let text = std::str::from_utf8(&first)
            .map_err(|e| TableError::Record(t.path.clone(), ln, e.to_string()))?;
        t.delimiter = layout
            .delimiter
            .unwrap_or_else(|| table::delimiter_of(text));
        t.blanks = !matches!(t.delimiter, b',' | b';');
        t.decimal_comma = t.delimiter == b';';
        let fields = t.split(&first, ln)?;
        let headerless = layout
            .header
            .map_or_else(|| fields.iter().all(|f| f.parse::<f64>().is_ok()), |h| !h);
        t.header = if headerless {
            (1..=fields.len()).map(|i| format!("c{i}")).collect()
        } else {
            fields
        };
        if headerless {
            t.first = Some((ln, first));
        }
        t.tcol = time.map(|c| find(path, &t.header, c)).transpose()?;
        t.cols = pick(path, &t.header, columns, t.tcol)?;
        Ok(t)
    }

    /// The next line (without its end), with its number.
    fn next_line(&mut self) -> Result<Option<(usize, &[u8])>, TableError> {
        Ok(self.next_range()?.map(|(ln, a, b)| (ln, &self.buf[a..b])))
    }

    /// The next line as its number and its place in `buf`.
    fn next_range(&mut self) -> Result<Option<(usize, usize, usize)>, TableError> {
        loop {
            if let Some(k) = memchr::memchr(b'\n', &self.buf[self.at..self.end]) {
                let (a, mut b) = (self.at, self.at + k);
                self.at = b + 1;
                self.line += 1;
                self.consumed += (k + 1) as u64;
                if b > a && self.buf[b - 1] == b'\r' {
                    b -= 1;
                }
                return Ok(Some((self.line, a, b)));
            }
            if self.eof {
                if self.at == self.end {
                    return Ok(None);
                }
                let (a, b) = (self.at, self.end);
                self.at = b;
                self.line += 1;
                self.consumed += (b - a) as u64;
                return Ok(Some((self.line, a, b)));
            }
            // Keep the partial line, read more behind it.
            self.buf.copy_within(self.at..self.end, 0);
            self.end -= self.at;
            self.at = 0;
            if self.end == self.buf.len() {
                self.buf.resize(self.buf.len() * 2, 0);
            }
            let got = self
                .file
                .read(&mut self.buf[self.end..])
                .map_err(|e| TableError::Io(self.path.clone(), e))?;
            self.eof = got == 0;
            self.end += got;
        }
    }

    /// A line's fields as text (for the header).
    fn split(&self, line: &[u8], ln: usize) -> Result<Vec<String>, TableError> {
        let text = std::str::from_utf8(line)
            .map_err(|e| TableError::Record(self.path.clone(), ln, e.to_string()))?;
        Ok(text
            .split(self.delimiter as char)
            .map(|f| unquote(f.trim()).to_string())
            .filter(|f| !self.blanks || !f.is_empty())
            .map(|f| {
                if self.decimal_comma {
                    f.replace(',', ".")
                } else {
                    f
                }
            })
            .collect())
    }

    fn next(&mut self, out: &mut [Vec<f64>], times: &mut Vec<f64>) -> Result<usize, TableError> {
        self.lines.clear();
        let mut rows = 0;
        // The column each field goes to, by field index.
        let mut slot: Vec<Option<usize>> = vec![None; self.header.len()];
        for (k, &c) in self.cols.iter().enumerate() {
            slot[c] = Some(k);
        }
        let mut vals = vec![0.0; self.cols.len()];
        while rows < ROWS {
            let held = self.first.take();
            let (ln, range) = match &held {
                Some((ln, _)) => (*ln, (0, 0)),
                None => match self.next_range()? {
                    Some((ln, a, b)) => (ln, (a, b)),
                    None => break,
                },
            };
            let line = match &held {
                Some((_, l)) => &l[..],
                None => &self.buf[range.0..range.1],
            };
            let row = Row {
                path: &self.path,
                header: &self.header,
                delimiter: self.delimiter,
                blanks: self.blanks,
                decimal_comma: self.decimal_comma,
                scale: self.scale,
                tcol: self.tcol,
                slot: &slot,
            };
            let t = match row.parse(line, ln, &mut vals, &mut self.field)? {
                Parsed::NoRecord => continue,
                Parsed::Empty => {
                    if self.seen && self.tcol.is_none() && self.empty_at.is_none() {
                        self.empty_at = Some(ln);
                    }
                    continue;
                }
                Parsed::Row(t) => t,
            };
            if let Some(at) = self.empty_at.take() {
                // A sample with no value between two that have them: not
                // dropped (every later sample would move a period earlier).
                return Err(TableError::EmptyRow(self.path.clone(), at));
            }
            self.seen = true;
            for (o, v) in out.iter_mut().zip(&vals) {
                o.push(*v);
            }
            if let Some(t) = t {
                times.push(t);
            }
            self.lines.push(ln);
            rows += 1;
        }
        Ok(rows)
    }
}

/// What one line of a text log is.
enum Parsed {
    /// A blank line, a comment, blanks only.
    NoRecord,
    /// Separators with nothing between them.
    Empty,
    /// A row: its stamp, if the log has a time column.
    Row(Option<f64>),
}

/// How a text log's rows are read.
struct Row<'a> {
    path: &'a Path,
    header: &'a [String],
    delimiter: u8,
    blanks: bool,
    decimal_comma: bool,
    scale: f64,
    tcol: Option<usize>,
    slot: &'a [Option<usize>],
}

impl Row<'_> {
    /// The wanted columns of `line` into `vals` (in °/s), and its stamp;
    /// or that the line is no record (blank, a comment, blanks only), or
    /// a row of empty fields between separators.
    fn parse(
        &self,
        line: &[u8],
        ln: usize,
        vals: &mut [f64],
        field: &mut Vec<u8>,
    ) -> Result<Parsed, TableError> {
        let l = line.trim_ascii();
        let fields = || {
            l.split(|&b| b == self.delimiter)
                .map(|f| unquote_bytes(f.trim_ascii()))
        };
        if l.is_empty() || l.starts_with(b"#") {
            return Ok(Parsed::NoRecord);
        }
        if fields().all(<[u8]>::is_empty) {
            return Ok(if self.blanks || fields().count() < 2 {
                Parsed::NoRecord
            } else {
                Parsed::Empty
            });
        }
        let (mut nf, mut t) = (0, None);
        for f in fields() {
            if self.blanks && f.is_empty() {
                continue;
            }
            let want = self.slot.get(nf).copied().flatten();
            if want.is_some() || Some(nf) == self.tcol {
                let v = self.number(f, ln, nf, field)?;
                if let Some(k) = want {
                    vals[k] = v * self.scale;
                }
                if Some(nf) == self.tcol {
                    t = Some(v);
                }
            }
            nf += 1;
        }
        if nf != self.header.len() {
            return Err(TableError::Fields(
                self.path.to_path_buf(),
                ln,
                nf,
                self.header.len(),
            ));
        }
        Ok(Parsed::Row(t))
    }

    fn number(
        &self,
        f: &[u8],
        ln: usize,
        col: usize,
        field: &mut Vec<u8>,
    ) -> Result<f64, TableError> {
        let bytes: &[u8] = if self.decimal_comma && f.contains(&b',') {
            field.clear();
            field.extend(f.iter().map(|&b| if b == b',' { b'.' } else { b }));
            field
        } else {
            f
        };
        std::str::from_utf8(bytes)
            .ok()
            .and_then(|s| s.parse::<f64>().ok())
            .filter(|v| v.is_finite())
            .ok_or_else(|| {
                TableError::Number(
                    self.path.to_path_buf(),
                    ln,
                    self.header[col].clone(),
                    String::from_utf8_lossy(bytes).into_owned(),
                )
            })
    }
}

/// A field without the double quotes a spreadsheet may put round it (the
/// table reader's CSV parser drops them).
fn unquote(f: &str) -> &str {
    f.strip_prefix('"')
        .and_then(|g| g.strip_suffix('"'))
        .unwrap_or(f)
}

fn unquote_bytes(f: &[u8]) -> &[u8] {
    f.strip_prefix(b"\"")
        .and_then(|g| g.strip_suffix(b"\""))
        .unwrap_or(f)
}

/// A binary log through a memory map.
struct Binary {
    map: Mmap,
    offset: usize,
    elem: usize,
    f32: bool,
    width: usize,
    rows: usize,
    pos: usize,
    /// Rows in the last block.
    last: usize,
    /// Bytes before which the map's pages have been let go.
    released: usize,
    cols: Vec<usize>,
    tcol: Option<usize>,
    scale: f64,
}

/// Pages let go a few MiB at a time.
const RELEASE: usize = 1 << 24;

impl Binary {
    fn open(path: &Path, raw: Option<Raw>, scale: f64) -> Result<Binary, TableError> {
        let p = || path.to_path_buf();
        let file = File::open(path).map_err(|e| TableError::Io(p(), e))?;
        // SAFETY: the map is read only. A file changed by another process
        // while it is read gives wrong numbers, not unsoundness in this
        // process's own memory beyond what any reader of a changing file
        // sees; the log is the user's own, not written during analysis.
        let map = unsafe { Mmap::map(&file) }.map_err(|e| TableError::Io(p(), e))?;
        let _ = map.advise(Advice::Sequential);
        let (offset, f32, width) = match raw {
            Some(r) => (0, r.f32, r.width),
            None => npy_header(&map).map_err(|why| TableError::Record(p(), 1, why))?,
        };
        let elem = if f32 { 4 } else { 8 };
        let body = map.len() - offset;
        if body % (elem * width) != 0 {
            return Err(TableError::Record(
                p(),
                1,
                format!(
                    "{body} bytes of data are not whole rows of {width} {}",
                    if f32 { "f32" } else { "f64" }
                ),
            ));
        }
        Ok(Binary {
            rows: body / (elem * width),
            map,
            offset,
            elem,
            f32,
            width,
            pos: 0,
            last: 0,
            released: 0,
            cols: Vec::new(),
            tcol: None,
            scale,
        })
    }

    /// Column `c` of rows `from..from + take` into `out`, each value times
    /// `scale`.
    fn column(&self, c: usize, from: usize, take: usize, scale: f64, out: &mut Vec<f64>) {
        let row = self.width * self.elem;
        let start = self.offset + from * row + c * self.elem;
        let bytes = &self.map[start..start + (take - 1) * row + self.elem];
        if self.f32 {
            out.extend(
                bytes
                    .chunks(row)
                    .map(|b| f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])) * scale),
            );
        } else {
            out.extend(bytes.chunks(row).map(|b| {
                f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]) * scale
            }));
        }
    }

    fn next(&mut self, out: &mut [Vec<f64>], times: &mut Vec<f64>) -> usize {
        let take = ROWS.min(self.rows - self.pos);
        if take == 0 {
            return 0;
        }
        for (o, &c) in out.iter_mut().zip(&self.cols) {
            self.column(c, self.pos, take, self.scale, o);
        }
        if let Some(c) = self.tcol {
            self.column(c, self.pos, take, 1.0, times);
        }
        self.pos += take;
        self.last = take;
        // The pages behind the reader: let go, so the map does not grow
        // into the whole file's size in this process's memory.
        let done = self.offset + self.pos * self.width * self.elem;
        let page = 4096;
        let upto = done / page * page;
        if upto >= self.released + RELEASE {
            // SAFETY: the map is read only and nothing reads behind `upto`
            // again; a page let go would be read back from the file.
            let _ = unsafe {
                self.map.unchecked_advise_range(
                    UncheckedAdvice::DontNeed,
                    self.released,
                    upto - self.released,
                )
            };
            self.released = upto;
        }
        take
    }
}

/// A `.npy` file's data offset, element type and row width: little-endian
/// f4 or f8, C order, shape (N,) or (N, K) (NumPy's format, version 1–3).
fn npy_header(b: &[u8]) -> Result<(usize, bool, usize), String> {
    if b.len() < 10 || &b[..6] != b"\x93NUMPY" {
        return Err("not a .npy file (no \\x93NUMPY magic)".into());
    }
    let (len, start) = match b[6] {
        1 => (u16::from_le_bytes([b[8], b[9]]) as usize, 10),
        2 | 3 if b.len() >= 12 => (u32::from_le_bytes([b[8], b[9], b[10], b[11]]) as usize, 12),
        v => return Err(format!(".npy version {v}: 1, 2 or 3 are read")),
    };
    let h = b
        .get(start..start + len)
        .and_then(|h| std::str::from_utf8(h).ok())
        .ok_or(".npy header cut short or not text")?;
    let value = |key: &str| -> Option<&str> {
        let i = h.find(&format!("'{key}'"))? + key.len() + 2;
        let rest = h[i..].trim_start().strip_prefix(':')?.trim_start();
        let end = if rest.starts_with('(') {
            rest.find(')')? + 1
        } else {
            rest.find([',', '}']).unwrap_or(rest.len())
        };
        Some(rest[..end].trim())
    };
    let f32 = match value("descr") {
        Some("'<f4'") => true,
        Some("'<f8'") => false,
        d => {
            return Err(format!(
                ".npy dtype {}: little-endian f4 or f8 are read",
                d.unwrap_or("?")
            ))
        }
    };
    if value("fortran_order") != Some("False") {
        return Err(".npy in Fortran order: save it in C order (np.ascontiguousarray)".into());
    }
    let shape = value("shape").ok_or(".npy header without a shape")?;
    let dims: Vec<usize> = shape
        .trim_matches(|c| c == '(' || c == ')')
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.parse::<usize>()
                .map_err(|_| format!(".npy shape {shape}"))
        })
        .collect::<Result<_, _>>()?;
    let width = match dims[..] {
        [_] => 1,
        [_, k] if k > 0 => k,
        _ => return Err(format!(".npy shape {shape}: (N,) or (N, K) is read")),
    };
    Ok((start + len, f32, width))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(name: &str, bytes: &[u8]) -> PathBuf {
        let p = std::env::temp_dir().join(format!("gyro-bulk-{}-{name}", std::process::id()));
        std::fs::write(&p, bytes).unwrap();
        p
    }

    fn all(r: &mut Reader) -> (Vec<Vec<f64>>, Vec<f64>) {
        let k = r.names.len();
        let (mut cols, mut ts) = (vec![Vec::new(); k], Vec::new());
        let (mut out, mut t) = (vec![Vec::new(); k], Vec::new());
        while r.next(&mut out, &mut t).unwrap() > 0 {
            for (c, o) in cols.iter_mut().zip(&out) {
                c.extend_from_slice(o);
            }
            ts.extend_from_slice(&t);
        }
        (cols, ts)
    }

    /// The block reader reads what the table reader reads, over every
    /// layout the table's tests use (separators, decimal commas, comments,
    /// blank lines, CRLF, no header, units).
    #[test]
    fn text_reads_as_the_table_does() {
        let dps = (Unit::Dps, None);
        for (name, text, time) in [
            (
                "a.csv",
                "t,x,y\n0,1,2\n0.01,1.5,2\n\n# note\n0.02,1,2\r\n0.03,1,2e-3",
                Some("t"),
            ),
            ("b.tsv", "t\tz\n0\t1.5\n0.01\t2\n0.02\t-1\n", Some("t")),
            (
                "q.csv",
                "\"t\",\"x\"\n\"0\",\"1.5\"\n0.01,2\n0.02,-1\n",
                Some("t"),
            ),
            ("c.csv", "t;z\n0;1,5\n0,01;2\n0,02;-1\n", Some("t")),
            ("d.dat", "1.5\n2.25\n-3\n4\n", None),
            ("e.txt", "  1.0   2.0\n  3.0   4.0\n5 6\n", None),
        ] {
            let p = write(name, text.as_bytes());
            let want =
                table::read_layout(&p, &[], (time, Some(0.01)), dps, false, Layout::default())
                    .unwrap();
            let mut r = open(&p, &[], time, dps, Layout::default(), None).unwrap();
            assert_eq!(r.names, want.names, "{name}");
            let (cols, _) = all(&mut r);
            assert_eq!(cols, want.rates, "{name}");
            let _ = std::fs::remove_file(p);
        }
        // Units and a wrong field count or number, with their lines.
        let p = write("f.csv", b"x\n1\n2\n3\n");
        let mut r = open(&p, &[], None, (Unit::Dph, None), Layout::default(), None).unwrap();
        let per_hour = 1.0 / 3600.0;
        assert_eq!(
            all(&mut r).0,
            vec![vec![per_hour, 2.0 * per_hour, 3.0 * per_hour]]
        );
        let p = write("g.csv", b"x,y\n1,2\n3\n");
        let mut r = open(&p, &[], None, dps, Layout::default(), None).unwrap();
        let e = r.next(&mut [vec![], vec![]], &mut vec![]).unwrap_err();
        assert!(matches!(e, TableError::Fields(_, 3, 1, 2)), "{e}");
        let p = write("h.csv", b"x\n1\nnan\n");
        let mut r = open(&p, &[], None, dps, Layout::default(), None).unwrap();
        let e = r.next(&mut [vec![]], &mut vec![]).unwrap_err();
        assert!(matches!(e, TableError::Number(_, 3, _, _)), "{e}");
        assert!(matches!(
            open(&p, &["z".into()], None, dps, Layout::default(), None),
            Err(TableError::NoColumn(..))
        ));
    }

    /// A `.npy` file as NumPy writes it (version 1.0 header, padded to 64
    /// bytes, shape (N, 3) of f4), and a raw f64 file.
    #[test]
    fn npy_and_raw() {
        let header = "{'descr': '<f4', 'fortran_order': False, 'shape': (4, 3), }";
        let mut h = header.to_string();
        while !(10 + h.len() + 1).is_multiple_of(64) {
            h.push(' ');
        }
        h.push('\n');
        let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
        bytes.extend_from_slice(&(h.len() as u16).to_le_bytes());
        bytes.extend_from_slice(h.as_bytes());
        for i in 0..12 {
            bytes.extend_from_slice(&(i as f32 * 0.5).to_le_bytes());
        }
        let p = write("a.npy", &bytes);
        let dps = (Unit::Dps, None);
        let mut r = open(&p, &["c2".into()], None, dps, Layout::default(), None).unwrap();
        assert_eq!(all(&mut r).0, vec![vec![0.5, 2.0, 3.5, 5.0]]);
        let mut r = open(&p, &[], Some("c1"), dps, Layout::default(), None).unwrap();
        let (cols, ts) = all(&mut r);
        assert_eq!(r.names, ["c2", "c3"]);
        assert_eq!(cols[1], vec![1.0, 2.5, 4.0, 5.5]);
        assert_eq!(ts, vec![0.0, 1.5, 3.0, 4.5]);
        // Cut short: not whole rows.
        let q = write("b.npy", &bytes[..bytes.len() - 2]);
        assert!(open(&q, &[], None, dps, Layout::default(), None).is_err());
        let raw: Vec<u8> = [1.0f64, -2.0, 3.0]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let q = write("c.bin", &raw);
        let mut r = open(
            &q,
            &[],
            None,
            dps,
            Layout::default(),
            Some("f64".parse().unwrap()),
        )
        .unwrap();
        assert_eq!(all(&mut r).0, vec![vec![1.0, -2.0, 3.0]]);
        assert!("f16".parse::<Raw>().is_err() && "f32x0".parse::<Raw>().is_err());
    }
}
