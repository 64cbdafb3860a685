//! Allan-family deviations of a log too long to hold, in one pass and
//! bounded memory: ADEV, OADEV, MDEV, TDEV, HDEV, OHDEV and TIE rms at
//! octave, decade or N-per-decade factors, with each factor's noise type
//! and so its EDF and interval, and the points the noise fit takes.
//!
//! Every term of these deviations at factor m is a difference of the phase
//! at t and at lags m, 2m and 3m behind it. The phase comes in chunks of
//! [`CHUNK`] points; a ring holds the last `ring` points, so every lag up
//! to `ring − CHUNK` is read from memory. A longer lag (a 72 h, 1 kHz log
//! reaches lags of 2 × 10⁸) is read back from a spill file of the phase
//! the pass writes behind itself (unlinked on creation; the page cache
//! holds it while it is read, and it is not this process's memory). The
//! ring is the memory bound: 8 bytes a point, whatever the log's length.
//!
//! The phase is built as [`dev::phase_from_rate`] builds it (x₀ = 0,
//! xₖ₊₁ = xₖ + yₖ·τ0), so the terms are the in-memory ones. MDEV, TDEV
//! and HDEV add them in the in-memory order (the same bits); OADEV, OHDEV
//! and TIE rms in independent partial sums (the in-memory OADEV does too,
//! in another grouping), ADEV in order: equal to rounding. The noise type
//! of each factor is the lag-1 autocorrelation test of
//! [`dev::noise_alpha`] on the same decimated phase, from running sums of
//! the series and its first and second differences instead of the stored
//! series.
//!
//! The pass is bound by reading each factor's lagged points, not by where
//! they come from: on 2.6 × 10⁷ samples a ring of 8 MiB (most lags from
//! the spill) took 4.3 s against 4.0 s with 256 MiB (`docs/host.md`).

use std::fs::File;
use std::io::Write;
use std::os::unix::fs::FileExt;
use std::path::PathBuf;

use crate::dev::{self, Grid, Kind, Point};
use crate::edf;

/// Phase points a pass handles at once.
pub const CHUNK: usize = 1 << 14;

/// Independent partial sums of the overlapping kernels.
const LANES: usize = 8;

/// Whether `kind` can be computed in one pass here. TOTDEV reflects the
/// phase about its last point, MTOTDEV, TTOTDEV and HTOTDEV detrend each
/// 3m stretch, Theo1 (and TheoBR and TheoH with it) sums m/2 terms per
/// start, MTIE takes each window's range: none of them is a fixed set of
/// lagged differences.
pub fn streams(kind: Kind) -> bool {
    matches!(
        kind,
        Kind::Adev
            | Kind::Oadev
            | Kind::Mdev
            | Kind::Tdev
            | Kind::Hdev
            | Kind::Ohdev
            | Kind::Tierms
    )
}

/// Why a streamed analysis could not be made.
#[derive(Debug)]
pub enum StreamError {
    /// A deviation that does not stream ([`streams`]).
    Kind(Kind),
    /// Every factor (`--grid all`): a pass per factor, not a stream.
    Grid,
    /// τ0 not a finite positive number.
    Tau0,
    /// Sample (0-based, of the column) not finite.
    NonFinite(u64),
    /// The ring holds fewer than two chunks, or is not a power of two.
    Ring(usize),
    /// The spill file could not be made, written or read.
    Spill(std::io::Error),
    /// Too few samples for any point (phase points).
    TooShort(u64),
    /// The memory (MiB) is less than two chunks a column: the memory, the
    /// columns, the MiB they need.
    Memory(usize, usize, usize),
}

impl std::fmt::Display for StreamError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StreamError::Kind(k) => write!(
                f,
                "{} is not computed in one pass (adev, oadev, mdev, tdev, hdev, ohdev and tierms are): analyse it without --stream",
                k.name().to_uppercase()
            ),
            StreamError::Grid => write!(f, "--grid all is a pass per factor, not a stream: octave, decade or per-decade=N"),
            StreamError::Tau0 => write!(f, "tau0 must be a finite number of seconds > 0"),
            StreamError::NonFinite(i) => write!(f, "sample {i} is not finite"),
            StreamError::Ring(r) => write!(f, "a ring of {r} points: a power of two of at least {} points", 2 * CHUNK),
            StreamError::Spill(e) => write!(f, "the phase spill file: {e}"),
            StreamError::TooShort(n) => write!(f, "{n} phase points: too few for any factor"),
            StreamError::Memory(mib, k, need) => write!(f, "{mib} MiB of memory over {k} columns: at least {need} MiB is needed"),
        }
    }
}

impl std::error::Error for StreamError {}

/// What to compute.
#[derive(Clone, Debug)]
pub struct Plan {
    /// The deviations, on `grid`, with intervals at `ci`.
    pub kinds: Vec<Kind>,
    pub grid: Grid,
    pub ci: (f64, edf::Chi2),
    /// Also OADEV at 8 per decade with 1σ intervals: the fit's points
    /// ([`crate::fit::fit_phase`] takes the same).
    pub fit: bool,
    /// Phase points the ring holds (a power of two ≥ 2·[`CHUNK`]): 8 bytes
    /// each, the pass's memory.
    pub ring: usize,
    /// Where the spill file goes (the system's temporary directory if None).
    pub spill_dir: Option<PathBuf>,
}

/// What one factor needs.
#[derive(Clone, Copy, Debug, Default)]
struct Need {
    oadev: bool,
    adev: bool,
    mdev: bool,
    ohdev: bool,
    hdev: bool,
    tie: bool,
}

impl Need {
    fn of(kind: Kind) -> Need {
        let mut n = Need::default();
        match kind {
            Kind::Oadev => n.oadev = true,
            Kind::Adev => n.adev = true,
            Kind::Mdev | Kind::Tdev => n.mdev = true,
            Kind::Ohdev => n.ohdev = true,
            Kind::Hdev => n.hdev = true,
            Kind::Tierms => n.tie = true,
            _ => {}
        }
        n
    }

    fn or(self, o: Need) -> Need {
        Need {
            oadev: self.oadev || o.oadev,
            adev: self.adev || o.adev,
            mdev: self.mdev || o.mdev,
            ohdev: self.ohdev || o.ohdev,
            hdev: self.hdev || o.hdev,
            tie: self.tie || o.tie,
        }
    }

    /// The longest lag, in factors.
    fn reach(self) -> usize {
        if self.mdev || self.ohdev || self.hdev {
            3
        } else if self.oadev || self.adev {
            2
        } else {
            1
        }
    }
}

/// Running sums of a series for its lag-1 autocorrelation about its mean,
/// shifted by its first value (the phase drifts far from 0; the shift
/// keeps the sums of squares from cancelling).
#[derive(Clone, Copy, Debug, Default)]
struct Acf {
    n: u64,
    shift: f64,
    s1: f64,
    s2: f64,
    s11: f64,
    first: f64,
    last: f64,
}

impl Acf {
    #[inline(always)]
    fn push(&mut self, v: f64) {
        if self.n == 0 {
            self.shift = v;
        }
        let u = v - self.shift;
        if self.n == 0 {
            self.first = u;
        } else {
            self.s11 += self.last * u;
        }
        self.s1 += u;
        self.s2 += u * u;
        self.last = u;
        self.n += 1;
    }

    /// r₁ = Σ(uₖ − ū)(uₖ₊₁ − ū) / Σ(uₖ − ū)², as [`dev::noise_alpha`]
    /// computes it from the stored series; None where the series is
    /// constant.
    fn r1(&self) -> Option<f64> {
        let n = self.n as f64;
        let mean = self.s1 / n;
        let den = self.s2 - n * mean * mean;
        let num = self.s11 - mean * ((self.s1 - self.last) + (self.s1 - self.first))
            + (n - 1.0) * mean * mean;
        (den > 0.0 && den.is_finite()).then_some(num / den)
    }
}

/// One averaging factor's sums.
#[derive(Clone, Debug)]
struct Factor {
    m: usize,
    need: Need,
    oadev: [f64; LANES],
    ohdev: [f64; LANES],
    tie: [f64; LANES],
    adev: f64,
    hdev: f64,
    md_inner: f64,
    md_s: f64,
    /// The decimated phase x[k·m] and its first two differences.
    acf: [Acf; 3],
    z: Option<f64>,
    d1: Option<f64>,
}

impl Factor {
    fn new(m: usize, need: Need) -> Self {
        Factor {
            m,
            need,
            oadev: [0.0; LANES],
            ohdev: [0.0; LANES],
            tie: [0.0; LANES],
            adev: 0.0,
            hdev: 0.0,
            md_inner: 0.0,
            md_s: 0.0,
            acf: [Acf::default(); 3],
            z: None,
            d1: None,
        }
    }

    /// The next points of the decimated phase. (The state in locals for
    /// the loop: at m = 1 this runs for every point.)
    #[inline(always)]
    fn push_decimated<'a>(&mut self, vs: impl Iterator<Item = &'a f64>) {
        let [mut a0, mut a1, mut a2] = self.acf;
        let (mut z, mut d1) = (self.z, self.d1);
        for &v in vs {
            a0.push(v);
            if let Some(z) = z {
                let d = v - z;
                a1.push(d);
                if let Some(p) = d1 {
                    a2.push(d - p);
                }
                d1 = Some(d);
            }
            z = Some(v);
        }
        self.acf = [a0, a1, a2];
        (self.z, self.d1) = (z, d1);
    }

    /// [`dev::noise_alpha`] from the running sums.
    fn alpha(&self) -> Option<i32> {
        if self.acf[0].n < 30 {
            return None;
        }
        for (d, a) in self.acf.iter().enumerate() {
            let r1 = a.r1()?;
            let delta = r1 / (1.0 + r1);
            if delta < 0.25 || d == 2 {
                return Some(2 - (2.0 * delta).round() as i32 - 2 * d as i32);
            }
        }
        None
    }
}

/// The phase behind the pass: the ring, and the spill for longer lags.
struct History {
    /// x[t] at t & mask, and the first CHUNK points again past the end, so
    /// that no view of a chunk's length wraps round.
    ring: Vec<f64>,
    mask: usize,
    /// Lags longer than this come from the spill.
    near: usize,
    spill: Option<File>,
    /// This chunk's stretches of the phase at the far lags: (lag, first
    /// phase index, points).
    far: Vec<(usize, usize, Vec<f64>)>,
}

impl History {
    /// x[a − lag .. b − lag] (a ≥ lag, b − a ≤ [`CHUNK`]).
    fn view(&self, lag: usize, a: usize, b: usize) -> &[f64] {
        let (p, q) = (a - lag, b - lag);
        if lag > self.near {
            let (_, first, v) = self
                .far
                .iter()
                .find(|f| f.0 == lag)
                .expect("every far lag is fetched before the chunk is summed");
            return &v[p - first..q - first];
        }
        // Never wraps: the ring's first chunk is repeated past its end.
        let i = p & self.mask;
        &self.ring[i..i + (q - p)]
    }

    fn write_spill(&mut self, from: usize, to: usize) -> Result<(), StreamError> {
        let Some(f) = &mut self.spill else {
            return Ok(());
        };
        let mut t = from;
        while t < to {
            let i = t & self.mask;
            let len = (to - t).min(self.mask + 1 - i);
            f.write_all(as_bytes(&self.ring[i..i + len]))
                .map_err(StreamError::Spill)?;
            t += len;
        }
        Ok(())
    }
}

/// The spill holds the phase in this machine's own byte order: it is this
/// process's scratch, read back only by it.
fn as_bytes(v: &[f64]) -> &[u8] {
    // SAFETY: f64 has no padding and any byte is a valid u8; the length is
    // the slice's size in bytes and the pointer its own.
    unsafe { std::slice::from_raw_parts(v.as_ptr().cast::<u8>(), std::mem::size_of_val(v)) }
}

/// [`as_bytes`], to read into.
fn as_bytes_mut(v: &mut [f64]) -> &mut [u8] {
    // SAFETY: as for `as_bytes`, and every byte pattern is a valid f64.
    unsafe { std::slice::from_raw_parts_mut(v.as_mut_ptr().cast::<u8>(), std::mem::size_of_val(v)) }
}

/// A one-pass analysis of one series.
pub struct Stream {
    plan: Plan,
    tau0: f64,
    phase_input: bool,
    factors: Vec<Factor>,
    far_lags: Vec<usize>,
    hist: History,
    /// Phase points received, the running phase and the points not yet
    /// summed.
    n: usize,
    acc: f64,
    pending: Vec<f64>,
    /// Samples pushed.
    samples: u64,
}

/// The finished analysis.
#[derive(Clone, Debug)]
pub struct Curves {
    /// Phase points (samples + 1 for rates).
    pub n: usize,
    /// Each asked deviation's points, in the plan's order.
    pub curves: Vec<(Kind, Vec<Point>)>,
    /// OADEV at 8 per decade with 1σ intervals (the plan's `fit`).
    pub fit_points: Vec<Point>,
}

/// The factors of `grid` that can ever be reached (the stream's length is
/// not known ahead).
fn grid_factors(grid: Grid) -> Vec<usize> {
    grid.factors(1 << 48)
}

impl Stream {
    /// A pass over rates (`phase_input` false: °/s, integrated by τ0) or
    /// phase, sampled every `tau0` s.
    pub fn new(plan: Plan, tau0: f64, phase_input: bool) -> Result<Self, StreamError> {
        if let Some(k) = plan.kinds.iter().find(|k| !streams(**k)) {
            return Err(StreamError::Kind(*k));
        }
        if plan.grid == Grid::All {
            return Err(StreamError::Grid);
        }
        if !(tau0.is_finite() && tau0 > 0.0) {
            return Err(StreamError::Tau0);
        }
        if !plan.ring.is_power_of_two() || plan.ring < 2 * CHUNK {
            return Err(StreamError::Ring(plan.ring));
        }
        let mut needs: std::collections::BTreeMap<usize, Need> = Default::default();
        for &k in &plan.kinds {
            for m in grid_factors(plan.grid) {
                let e = needs.entry(m).or_default();
                *e = e.or(Need::of(k));
            }
        }
        if plan.fit {
            for m in grid_factors(Grid::PerDecade(8)) {
                let e = needs.entry(m).or_default();
                *e = e.or(Need::of(Kind::Oadev));
            }
        }
        let factors: Vec<Factor> = needs.into_iter().map(|(m, n)| Factor::new(m, n)).collect();
        let near = plan.ring - CHUNK;
        let mut far_lags: Vec<usize> = factors
            .iter()
            .flat_map(|f| (1..=f.need.reach()).map(move |k| k * f.m))
            .filter(|&l| l > near)
            .collect();
        far_lags.sort_unstable();
        far_lags.dedup();
        let hist = History {
            ring: vec![0.0; plan.ring + CHUNK],
            mask: plan.ring - 1,
            near,
            spill: None,
            far: Vec::new(),
        };
        Ok(Stream {
            plan,
            tau0,
            phase_input,
            factors,
            far_lags,
            hist,
            n: 0,
            acc: 0.0,
            samples: 0,
            pending: Vec::with_capacity(CHUNK),
        })
    }

    /// Phase points taken so far.
    pub fn phase_points(&self) -> usize {
        self.n + self.pending.len()
    }

    /// Whether the phase has gone to the spill file (lags beyond the ring).
    pub fn spilled(&self) -> bool {
        self.hist.spill.is_some()
    }

    /// The next samples.
    pub fn push(&mut self, values: &[f64]) -> Result<(), StreamError> {
        if let Some(k) = values.iter().position(|v| !v.is_finite()) {
            return Err(StreamError::NonFinite(self.samples + k as u64));
        }
        self.samples += values.len() as u64;
        let mut rest = values;
        if !self.phase_input && self.phase_points() == 0 && !rest.is_empty() {
            self.pending.push(0.0);
        }
        while !rest.is_empty() {
            let take = (CHUNK - self.pending.len()).min(rest.len());
            if self.phase_input {
                self.pending.extend_from_slice(&rest[..take]);
            } else {
                for &y in &rest[..take] {
                    self.acc += y * self.tau0;
                    self.pending.push(self.acc);
                }
            }
            rest = &rest[take..];
            if self.pending.len() == CHUNK {
                self.sum_chunk()?;
            }
        }
        Ok(())
    }

    /// Sum the pending phase points' terms.
    fn sum_chunk(&mut self) -> Result<(), StreamError> {
        let (t0, t1) = (self.n, self.n + self.pending.len());
        if t0 == t1 {
            return Ok(());
        }
        let h = &mut self.hist;
        // The spill starts while the ring still holds every point (before
        // the first lag beyond it is needed) and then follows the pass.
        if h.spill.is_none() && t1 > h.near && !self.far_lags.is_empty() {
            let f = match &self.plan.spill_dir {
                Some(d) => tempfile::tempfile_in(d),
                None => tempfile::tempfile(),
            }
            .map_err(StreamError::Spill)?;
            h.spill = Some(f);
            h.write_spill(0, t0)?;
        }
        // (The chunk never wraps: CHUNK divides the ring's length, and
        // every chunk but the last is whole.)
        let i = t0 & h.mask;
        h.ring[i..i + (t1 - t0)].copy_from_slice(&self.pending);
        if i == 0 {
            let r = h.mask + 1;
            h.ring[r..r + (t1 - t0)].copy_from_slice(&self.pending);
        }
        // This chunk's stretches at the far lags, from the spill (their
        // buffers kept from chunk to chunk).
        let reached = self.far_lags.iter().take_while(|&&l| l < t1).count();
        h.far
            .resize_with(reached, || (0, 0, Vec::with_capacity(CHUNK)));
        for (&lag, (l, first, v)) in self.far_lags.iter().zip(h.far.iter_mut()) {
            let f = h
                .spill
                .as_ref()
                .expect("a far lag is reached only past the ring");
            *l = lag;
            *first = t0.max(lag) - lag;
            v.resize(t1 - lag - *first, 0.0);
            f.read_exact_at(as_bytes_mut(v), *first as u64 * 8)
                .map_err(StreamError::Spill)?;
        }
        sum_factors_best(&mut self.factors, h, t0, t1);
        if h.spill.is_some() {
            h.write_spill(t0, t1)?;
        }
        self.n = t1;
        self.pending.clear();
        Ok(())
    }

    /// The curves of every sample pushed.
    pub fn finish(mut self) -> Result<Curves, StreamError> {
        self.sum_chunk()?;
        let n = self.n;
        if n < 3 {
            return Err(StreamError::TooShort(n as u64));
        }
        let tau0 = self.tau0;
        let point = |kind: Kind, f: &Factor| -> Option<Point> {
            let m = f.m;
            if m > kind.max_factor(n) {
                return None;
            }
            let tau = m as f64 * tau0;
            let (var, terms) = match kind {
                Kind::Oadev => {
                    let k = n - 2 * m;
                    (
                        f.oadev.iter().sum::<f64>() / (2.0 * k as f64 * tau * tau),
                        k,
                    )
                }
                Kind::Adev => {
                    let k = (n - 2 * m).div_ceil(m);
                    (f.adev / (2.0 * k as f64 * tau * tau), k)
                }
                Kind::Mdev | Kind::Tdev => {
                    let count = n - 3 * m + 1;
                    let mvar = f.md_s / (2.0 * (m * m) as f64 * count as f64 * tau * tau);
                    if kind == Kind::Tdev {
                        (tau * tau / 3.0 * mvar, count)
                    } else {
                        (mvar, count)
                    }
                }
                Kind::Ohdev => {
                    let k = n - 3 * m;
                    (
                        f.ohdev.iter().sum::<f64>() / (6.0 * k as f64 * tau * tau),
                        k,
                    )
                }
                Kind::Hdev => {
                    let k = (n - 3 * m).div_ceil(m);
                    (f.hdev / (6.0 * k as f64 * tau * tau), k)
                }
                Kind::Tierms => {
                    let k = n - m;
                    (f.tie.iter().sum::<f64>() / k as f64, k)
                }
                _ => return None,
            };
            Some(Point::bare(m, tau0, var.sqrt(), terms, n))
        };
        let curve = |kind: Kind, grid: Grid, ci: (f64, edf::Chi2)| -> Vec<Point> {
            let ms = grid_factors(grid);
            let mut last_alpha = None;
            self.factors
                .iter()
                .filter(|f| ms.binary_search(&f.m).is_ok() && kind.takes_factor(f.m, n))
                .filter_map(|f| point(kind, f).map(|p| (f, p)))
                .map(|(f, p)| dev::with_interval(kind, p, f.alpha(), &mut last_alpha, n, ci))
                .collect()
        };
        let curves = self
            .plan
            .kinds
            .iter()
            .map(|&k| (k, curve(k, self.plan.grid, self.plan.ci)))
            .collect();
        let fit_points = if self.plan.fit {
            curve(
                Kind::Oadev,
                Grid::PerDecade(8),
                (edf::ONE_SIGMA, edf::Chi2::Exact),
            )
        } else {
            Vec::new()
        };
        Ok(Curves {
            n,
            curves,
            fit_points,
        })
    }
}

/// [`sum_factors`], in its AVX2 build where the CPU has AVX2 and FMA: the
/// same operations in the same order (no contraction into fused
/// multiply-adds), so the same bits, with 4 lanes where the baseline has 2.
fn sum_factors_best(factors: &mut [Factor], h: &History, t0: usize, t1: usize) {
    #[cfg(target_arch = "x86_64")]
    if gyro_array::algo::allan::has_avx2_fma() {
        // SAFETY: the CPU has AVX2 and FMA (checked just above), the only
        // requirement of the AVX2 build.
        return unsafe { sum_factors_avx2(factors, h, t0, t1) };
    }
    sum_factors(factors, h, t0, t1)
}

/// [`sum_factors`] compiled for AVX2 and FMA.
///
/// # Safety
///
/// Call it only on a CPU with AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn sum_factors_avx2(factors: &mut [Factor], h: &History, t0: usize, t1: usize) {
    sum_factors(factors, h, t0, t1)
}

/// MDEV chains run side by side: each is a chain of dependent additions
/// (its running inner sum), so one alone waits on each add's latency.
const MDEV_SIDE: usize = 4;

/// Add the terms whose newest point lies in `t0..t1` to every factor.
#[inline(always)]
fn sum_factors(factors: &mut [Factor], h: &History, t0: usize, t1: usize) {
    for f in factors.iter_mut() {
        let m = f.m;
        // The noise type's decimated phase: x[0], x[m], x[2m], …
        let t = t0.div_ceil(m) * m;
        if t < t1 {
            f.push_decimated(h.view(0, t0, t1).iter().skip(t - t0).step_by(m));
        }
        if m >= t1 {
            continue;
        }
        let need = f.need;
        let a = t0.max(2 * m);
        if (need.oadev || need.adev || need.mdev) && a < t1 {
            let (x0, x1, x2) = (h.view(0, a, t1), h.view(m, a, t1), h.view(2 * m, a, t1));
            if need.oadev {
                // Where MDEV slides (t ≥ 3m), its loop adds these terms: it
                // forms them, and the views are read once.
                let end = if need.mdev {
                    (3 * m).clamp(a, t1) - a
                } else {
                    x0.len()
                };
                add_second(&mut f.oadev, &x0[..end], &x1[..end], &x2[..end]);
            }
            if need.adev {
                // The in-memory stride: terms at t ≡ 0 (mod m), in order.
                let mut t = a.div_ceil(m) * m;
                while t < t1 {
                    let i = t - a;
                    let d = x0[i] - 2.0 * x1[i] + x2[i];
                    f.adev += d * d;
                    t += m;
                }
            }
            if need.mdev && a < 3 * m {
                // The first inner sum; the slide below.
                mdev_first(f, a, t1, x0, x1, x2);
            }
        }
        let a = t0.max(3 * m);
        if (need.ohdev || need.hdev) && a < t1 {
            let x = [0, m, 2 * m, 3 * m].map(|l| h.view(l, a, t1));
            if need.ohdev {
                add_third(&mut f.ohdev, x[0], x[1], x[2], x[3]);
            }
            if need.hdev {
                let mut t = a.div_ceil(m) * m;
                while t < t1 {
                    let i = t - a;
                    let d = x[0][i] - 3.0 * x[1][i] + 3.0 * x[2][i] - x[3][i];
                    f.hdev += d * d;
                    t += m;
                }
            }
        }
        let a = t0.max(m);
        if need.tie && a < t1 {
            add_first(&mut f.tie, h.view(0, a, t1), h.view(m, a, t1));
        }
    }
    // MDEV's slide, MDEV_SIDE factors at a time.
    let mut sliding: Vec<&mut Factor> = factors
        .iter_mut()
        .filter(|f| f.need.mdev && t1 > 3 * f.m)
        .collect();
    for group in sliding.chunks_mut(MDEV_SIDE) {
        mdev_slide(group, h, t0, t1);
    }
}

/// MDEV's first inner sum: the second differences ending at 2m .. 3m − 1,
/// added in order as `dev`'s in-memory loop adds them; `x0..x2` start at
/// `a` (≥ 2m).
#[inline(always)]
fn mdev_first(f: &mut Factor, a: usize, t1: usize, x0: &[f64], x1: &[f64], x2: &[f64]) {
    let m = f.m;
    for t in a..t1.min(3 * m) {
        let i = t - a;
        f.md_inner += x0[i] - 2.0 * x1[i] + x2[i];
        if t == 3 * m - 1 {
            f.md_s = f.md_inner * f.md_inner;
        }
    }
}

/// MDEV's inner sum slid by one for each t in `t0..t1` from 3m on, for up
/// to [`MDEV_SIDE`] factors side by side: each factor's additions are
/// `dev`'s in-memory loop's, in its order (the same bits); the side by side
/// only lets one chain's add wait while another's runs.
#[inline(always)]
fn mdev_slide(group: &mut [&mut Factor], h: &History, t0: usize, t1: usize) {
    // Each factor's views from its own start, max(t0, 3m); the common
    // stretch from the latest start, the earlier ones' heads alone first.
    let mut views: [(usize, [&[f64]; 4]); MDEV_SIDE] = [(0, [&[]; 4]); MDEV_SIDE];
    for (f, v) in group.iter().zip(views.iter_mut()) {
        let (m, b) = (f.m, t0.max(3 * f.m));
        *v = (b, [0, m, 2 * m, 3 * m].map(|l| h.view(l, b, t1)));
    }
    let common = views[..group.len()].iter().map(|v| v.0).max().unwrap_or(t1);
    let step = |f: &mut Factor, x: &[&[f64]; 4], i: usize| {
        let new = x[0][i] - 2.0 * x[1][i] + x[2][i];
        // The difference leaving the window ends at t − m.
        let old = x[1][i] - 2.0 * x[2][i] + x[3][i];
        f.md_inner += new - old;
        f.md_s += f.md_inner * f.md_inner;
        if f.need.oadev {
            f.oadev[0] += new * new;
        }
    };
    for (f, (b, x)) in group.iter_mut().zip(&views) {
        for t in *b..common {
            step(f, x, t - b);
        }
    }
    if group.len() == MDEV_SIDE {
        // The chains' state in locals and every view cut to the common
        // stretch's length, so the loop holds no loads of the state and no
        // bounds checks.
        let len = t1 - common;
        let xs: [[&[f64]; 4]; MDEV_SIDE] = std::array::from_fn(|j| {
            let o = common - views[j].0;
            std::array::from_fn(|q| &views[j].1[q][o..o + len])
        });
        let mut inner: [f64; MDEV_SIDE] = std::array::from_fn(|j| group[j].md_inner);
        let mut sum: [f64; MDEV_SIDE] = std::array::from_fn(|j| group[j].md_s);
        // OADEV's terms where the factor has both (0 where it has not).
        let mut oadev = [0.0; MDEV_SIDE];
        for k in 0..len {
            for j in 0..MDEV_SIDE {
                let [x0, x1, x2, x3] = xs[j];
                let new = x0[k] - 2.0 * x1[k] + x2[k];
                let old = x1[k] - 2.0 * x2[k] + x3[k];
                inner[j] += new - old;
                sum[j] += inner[j] * inner[j];
                oadev[j] += new * new;
            }
        }
        for (j, f) in group.iter_mut().enumerate() {
            f.md_inner = inner[j];
            f.md_s = sum[j];
            if f.need.oadev {
                f.oadev[1] += oadev[j];
            }
        }
    } else {
        for (f, (b, x)) in group.iter_mut().zip(&views) {
            for t in common..t1 {
                step(f, x, t - b);
            }
        }
    }
}

/// Lane q adds (x0 − 2·x1 + x2)² of the points q, q + LANES, ….
#[inline(always)]
fn add_second(l: &mut [f64; LANES], x0: &[f64], x1: &[f64], x2: &[f64]) {
    let (c0, c1, c2) = (
        x0.chunks_exact(LANES),
        x1.chunks_exact(LANES),
        x2.chunks_exact(LANES),
    );
    let (r0, r1, r2) = (c0.remainder(), c1.remainder(), c2.remainder());
    for ((a, b), c) in c0.zip(c1).zip(c2) {
        for q in 0..LANES {
            let d = a[q] - 2.0 * b[q] + c[q];
            l[q] += d * d;
        }
    }
    for ((a, b), c) in r0.iter().zip(r1).zip(r2) {
        let d = a - 2.0 * b + c;
        l[0] += d * d;
    }
}

/// Lane q adds (x0 − 3·x1 + 3·x2 − x3)².
#[inline(always)]
fn add_third(l: &mut [f64; LANES], x0: &[f64], x1: &[f64], x2: &[f64], x3: &[f64]) {
    let term = |a: f64, b: f64, c: f64, d: f64| {
        let v = a - 3.0 * b + 3.0 * c - d;
        v * v
    };
    let (c0, c1) = (x0.chunks_exact(LANES), x1.chunks_exact(LANES));
    let (c2, c3) = (x2.chunks_exact(LANES), x3.chunks_exact(LANES));
    let rest = (
        c0.remainder(),
        c1.remainder(),
        c2.remainder(),
        c3.remainder(),
    );
    for (((a, b), c), d) in c0.zip(c1).zip(c2).zip(c3) {
        for (q, lane) in l.iter_mut().enumerate() {
            *lane += term(a[q], b[q], c[q], d[q]);
        }
    }
    for (((a, b), c), d) in rest.0.iter().zip(rest.1).zip(rest.2).zip(rest.3) {
        l[0] += term(*a, *b, *c, *d);
    }
}

/// Lane q adds (x0 − x1)².
#[inline(always)]
fn add_first(l: &mut [f64; LANES], x0: &[f64], x1: &[f64]) {
    let (c0, c1) = (x0.chunks_exact(LANES), x1.chunks_exact(LANES));
    let (r0, r1) = (c0.remainder(), c1.remainder());
    for (a, b) in c0.zip(c1) {
        for q in 0..LANES {
            let d = a[q] - b[q];
            l[q] += d * d;
        }
    }
    for (a, b) in r0.iter().zip(r1) {
        l[0] += (a - b) * (a - b);
    }
}

/// A log file to analyse in one pass ([`analyse_file`]).
#[derive(Clone, Debug)]
pub struct FileJob {
    pub path: PathBuf,
    /// Columns (all but the time column when empty).
    pub columns: Vec<String>,
    /// The time column: τ0 from its first block's median step unless
    /// `tau0`; its gaps are checked.
    pub time: Option<String>,
    pub tau0: Option<f64>,
    pub unit: (crate::table::Unit, Option<f64>),
    pub layout: crate::table::Layout,
    pub raw: Option<crate::bulk::Raw>,
    /// The columns are phase, not rate.
    pub phase: bool,
    /// Analyse the samples across a gap in the time column as contiguous
    /// (else a gap is an error).
    pub join_gaps: bool,
    /// Memory for the columns' rings, MiB.
    pub memory_mib: usize,
}

/// What [`analyse_file`] found.
#[derive(Clone, Debug)]
pub struct FileCurves {
    pub names: Vec<String>,
    pub tau0: f64,
    /// Samples (rows) read.
    pub samples: usize,
    /// The log's size, bytes.
    pub bytes: u64,
    /// Whether the phase went to the spill file.
    pub spilled: bool,
    /// Gaps joined (`join_gaps`): (line or row, step in s).
    pub gaps: Vec<(usize, f64)>,
    /// Each column's curves, in `names`' order.
    pub columns: Vec<Curves>,
}

/// `job`'s log through [`Stream`] in one pass, every column at once, with
/// `plan` (its `ring` set from `job.memory_mib`). `progress` is told the
/// bytes read of the log's size after each block; `stop`, looked at as
/// often, gives up with [`crate::Stopped`].
pub fn analyse_file(
    job: &FileJob,
    mut plan: Plan,
    progress: &mut dyn FnMut(u64, u64),
    stop: &std::sync::atomic::AtomicBool,
) -> crate::Res<FileCurves> {
    let file = job.path.as_path();
    let mut r = crate::bulk::open(
        file,
        &job.columns,
        job.time.as_deref(),
        job.unit,
        job.layout,
        job.raw,
    )?;
    let k = r.names.len();
    // The ring: the largest power of two of points the memory gives each
    // column.
    let per_column = (job.memory_mib << 20) / 8 / k.max(1);
    if per_column < 2 * CHUNK {
        let need = (2 * CHUNK * 8 * k).div_ceil(1 << 20);
        return Err(StreamError::Memory(job.memory_mib, k, need).into());
    }
    plan.ring = 1usize << per_column.ilog2();
    let (mut out, mut times) = (vec![Vec::new(); k], Vec::new());
    let mut got = r.next(&mut out, &mut times)?;
    let tau0 = match job.tau0 {
        Some(t) => t,
        None => tau0_of(&times).ok_or(crate::table::TableError::NoTau0)?,
    };
    let mut streams = (0..k)
        .map(|_| Stream::new(plan.clone(), tau0, job.phase))
        .collect::<Result<Vec<_>, _>>()?;
    let (mut last, mut row, mut gaps) = (None::<f64>, 0usize, Vec::new());
    while got > 0 {
        if stop.load(std::sync::atomic::Ordering::Relaxed) {
            return Err(crate::Stopped.into());
        }
        if r.timed {
            for (i, &t) in times.iter().enumerate() {
                if let Some(prev) = last {
                    let place = r.line(i);
                    if t <= prev {
                        return Err(crate::table::TableError::Time(
                            file.to_path_buf(),
                            place,
                            prev,
                            t,
                        )
                        .into());
                    }
                    if t - prev > 1.5 * tau0 {
                        if !job.join_gaps {
                            return Err(format!(
                                "{}:{place}: gap of {} s ({:.1} samples): a streamed pass takes contiguous samples only; join them (--gaps join) to analyse them as contiguous, or analyse the log in memory (gap-tolerant OADEV)",
                                file.display(),
                                t - prev,
                                (t - prev) / tau0
                            )
                            .into());
                        }
                        gaps.push((place, t - prev));
                    }
                }
                last = Some(t);
            }
        }
        for ((s, col), name) in streams.iter_mut().zip(&out).zip(&r.names) {
            s.push(col).map_err(|e| match e {
                StreamError::NonFinite(i) => format!(
                    "{}: column {name}: sample {} ({}) is not finite: a streamed pass takes finite samples only",
                    file.display(),
                    i,
                    r.place(i as usize - row)
                ),
                e => e.to_string(),
            })?;
        }
        row += got;
        progress(r.bytes_read(), r.size());
        got = r.next(&mut out, &mut times)?;
    }
    let spilled = streams.iter().any(Stream::spilled);
    let columns = streams
        .into_iter()
        .map(Stream::finish)
        .collect::<Result<Vec<_>, _>>()?;
    Ok(FileCurves {
        names: r.names.clone(),
        tau0,
        samples: row,
        bytes: r.size(),
        spilled,
        gaps,
        columns,
    })
}

/// τ0 where only a time column gives it: the median step of the first
/// block ([`crate::bulk::ROWS`] rows; the table reader's rule,
/// [`crate::table::gaps_of`], over what a stream has seen before it starts).
fn tau0_of(times: &[f64]) -> Option<f64> {
    let steps: Vec<f64> = times.windows(2).map(|w| w[1] - w[0]).collect();
    if steps.is_empty() {
        return None;
    }
    Some(crate::table::gaps_of(&steps).0).filter(|t| *t > 0.0 && t.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rates with white, flicker-like and random-walk parts and a bias
    /// (the phase drifts far from 0, as a gyro's does).
    fn rates(n: usize, seed: u64) -> Vec<f64> {
        let mut s = seed;
        let mut u = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        let (mut walk, mut slow) = (0.0, 0.0);
        (0..n)
            .map(|i| {
                walk += 0.002 * u();
                if i % 64 == 0 {
                    slow = 0.3 * u();
                }
                0.7 + u() + slow + walk
            })
            .collect()
    }

    fn plan(kinds: &[Kind], grid: Grid, ring: usize) -> Plan {
        Plan {
            kinds: kinds.to_vec(),
            grid,
            ci: (edf::ONE_SIGMA, edf::Chi2::Exact),
            fit: true,
            ring,
            spill_dir: None,
        }
    }

    const KINDS: [Kind; 7] = [
        Kind::Adev,
        Kind::Oadev,
        Kind::Mdev,
        Kind::Tdev,
        Kind::Hdev,
        Kind::Ohdev,
        Kind::Tierms,
    ];

    /// Every streamed deviation equals the in-memory one (`dev::curve_with`)
    /// with the smallest ring, so that most lags come back from the spill:
    /// MDEV, TDEV and HDEV to the bit (the same additions in the same
    /// order), ADEV, OADEV, OHDEV and TIE rms to 1e-12 (partial sums); the
    /// same noise types, EDFs and intervals; the fit's points too. Fed in
    /// pieces of odd sizes, so chunk edges fall everywhere.
    #[test]
    fn equals_the_in_memory_curves() {
        let tau0 = 0.01;
        let y = rates(150_001, 7);
        let x = dev::phase_from_rate(&y, tau0).unwrap();
        for grid in [Grid::Octave, Grid::Decade, Grid::PerDecade(5)] {
            let mut s = Stream::new(plan(&KINDS, grid, 2 * CHUNK), tau0, false).unwrap();
            let mut at = 0;
            for (k, piece) in [1usize, 7, 16_383, 40_000, 3].iter().cycle().enumerate() {
                let end = (at + piece).min(y.len());
                s.push(&y[at..end]).unwrap();
                at = end;
                if at == y.len() || k > 1000 {
                    break;
                }
            }
            assert!(s.spilled());
            let got = s.finish().unwrap();
            assert_eq!(got.n, x.len());
            for (kind, points) in &got.curves {
                let mut alphas = dev::Alphas::new();
                let ci = (edf::ONE_SIGMA, edf::Chi2::Exact);
                let want = dev::curve_with(*kind, &x, tau0, grid, ci, &mut alphas).unwrap();
                assert_eq!(points.len(), want.len(), "{kind:?} {grid:?}");
                // (ADEV at m = 1 is the overlapping kernel in memory.)
                let exact = matches!(kind, Kind::Mdev | Kind::Tdev | Kind::Hdev);
                for (p, w) in points.iter().zip(&want) {
                    let what = format!("{kind:?} {grid:?} m {}", p.m);
                    assert_eq!((p.m, p.terms, p.alpha), (w.m, w.terms, w.alpha), "{what}");
                    if exact {
                        assert_eq!(p.dev.to_bits(), w.dev.to_bits(), "{what}");
                    } else {
                        assert!(
                            (p.dev / w.dev - 1.0).abs() < 1e-12,
                            "{what}: {} {}",
                            p.dev,
                            w.dev
                        );
                    }
                    let near = |a: Option<f64>, b: Option<f64>| match (a, b) {
                        (Some(a), Some(b)) => (a / b - 1.0).abs() < 1e-9,
                        (a, b) => a.is_none() && b.is_none(),
                    };
                    assert!(
                        near(p.edf, w.edf) && near(p.lo, w.lo) && near(p.hi, w.hi),
                        "{what}"
                    );
                }
            }
            let want = dev::curve(Kind::Oadev, &x, tau0, Grid::PerDecade(8)).unwrap();
            assert_eq!(got.fit_points.len(), want.len());
            for (p, w) in got.fit_points.iter().zip(&want) {
                assert!(
                    (p.dev / w.dev - 1.0).abs() < 1e-12 && p.alpha == w.alpha,
                    "m {}",
                    p.m
                );
            }
        }
    }

    /// Phase input is taken as it is; a ring that holds the whole log
    /// spills nothing; the typed refusals.
    #[test]
    fn phase_input_rings_and_refusals() {
        let tau0 = 1.0;
        let x = dev::phase_from_rate(&rates(5_000, 3), tau0).unwrap();
        let mut s = Stream::new(
            plan(&[Kind::Mdev, Kind::Oadev], Grid::Octave, 1 << 16),
            tau0,
            true,
        )
        .unwrap();
        s.push(&x).unwrap();
        assert!(!s.spilled());
        let got = s.finish().unwrap();
        let want = dev::curve(Kind::Mdev, &x, tau0, Grid::Octave).unwrap();
        let mdev: Vec<u64> = got.curves[0].1.iter().map(|p| p.dev.to_bits()).collect();
        assert_eq!(
            mdev,
            want.iter().map(|p| p.dev.to_bits()).collect::<Vec<_>>()
        );

        let refuse = |kinds: &[Kind], grid, ring, tau0| {
            Stream::new(plan(kinds, grid, ring), tau0, false).err()
        };
        assert!(matches!(
            refuse(&[Kind::Totdev], Grid::Octave, 1 << 16, 1.0),
            Some(StreamError::Kind(Kind::Totdev))
        ));
        assert!(matches!(
            refuse(&[Kind::Oadev], Grid::All, 1 << 16, 1.0),
            Some(StreamError::Grid)
        ));
        assert!(matches!(
            refuse(&[Kind::Oadev], Grid::Octave, 1 << 16, 0.0),
            Some(StreamError::Tau0)
        ));
        assert!(matches!(
            refuse(&[Kind::Oadev], Grid::Octave, 3 << 14, 1.0),
            Some(StreamError::Ring(_))
        ));
        let mut s = Stream::new(plan(&[Kind::Oadev], Grid::Octave, 1 << 16), 1.0, false).unwrap();
        s.push(&[1.0, 2.0]).unwrap();
        assert!(matches!(
            s.push(&[3.0, f64::NAN]),
            Err(StreamError::NonFinite(3))
        ));
        let s = Stream::new(plan(&[Kind::Oadev], Grid::Octave, 1 << 16), 1.0, false).unwrap();
        assert!(matches!(s.finish(), Err(StreamError::TooShort(0))));
    }
}
