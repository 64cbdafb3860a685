//! Dynamic Allan variance (DAVAR, Galleani–Tavella, SEEDS.md §0.2) and its
//! entropy-adaptive window (E-DAVAR, seed 000), streaming in fixed memory.
//!
//! # Reading of the paper (SEEDS.md seed 000, ambiguities 1–8)
//! - The estimate for time `t` uses the window of `L(t)` samples centred at
//!   `t` (ambiguity 8: Fig. 2 reacts ~300 s early, which only a centred
//!   window does). Streaming, this means a fixed latency of λ2/2 samples:
//!   when sample `n` arrives, the estimate for `t = n − λ2/2` is produced.
//! - The window slides by one sample; L changes once per STFT hop (every
//!   [`SEG`] samples) by the clipped rule of eq. 4 ("tentative, then
//!   clip"), with a constant or proportional step ([`StepMode`]).
//! - τ grid: octaves m = 1, 2, …, 2^(T−1); 2^T ≤ λ1 so that every τ exists
//!   in every window.
//! - STFT: rectangular frames of [`SEG`] = 32 samples aligned to the sample
//!   count, FFT by microfft; DC (the frame mean) and Nyquist are dropped, so
//!   bins 1..=15 remain. Only frames wholly inside the window count.
//!
//! # Entropies ([`EntropyKind`])
//! - `Spectral` (faithful, eq. 1–3): p over the 15 frequency bins of the
//!   window's summed STFT power, entropy normalised by ln 15. The paper
//!   shrinks the window when E > E0. For white noise p is flat whatever the
//!   variance, so this hardly reacts to a variance step (SEEDS ambiguity 2);
//!   `davar-eval` measures it.
//! - `Temporal` (ours): p over the K frames of the window by frame energy
//!   (the time marginal of the same STFT). A variance step makes frame
//!   energies uneven, so the entropy *drops*; the score fed to eq. 4 is the
//!   deficit D = ln K − E ≥ 0, and the window shrinks when D > D0.
//!
//! # Automatic threshold ([`Threshold::Auto`])
//! Under stationary white noise each frame energy is σ²·χ²_ν/ν with ν = 30
//! (15 complex bins), and to second order D ≈ Σ(x_k − 1)²/(2K) with
//! x_k = K·p_k, i.e. D ≈ χ²_{K−1}/(K·ν). D0 is its (1 − p_fa) quantile, so
//! a stationary window triggers a shrink with probability ≈ p_fa. For the
//! spectral entropy the roles of time and frequency swap (B = 15 bins, each
//! a sum of K frames: ν = 2K), and E0 is the matching quantile of E on the
//! side the paper's rule uses (E > E0 shrinks). The thresholds depend on K,
//! so they are recomputed whenever the window length changes.
//!
//! Sums are exact integers, as in [`crate::algo::allan::stream`]: moving a
//! window edge adds or removes one exact term per τ, and no drift exists.
//! Frame sums for the entropies are f32 and are recomputed from the stored
//! frames at every hop, so they cannot drift either.

use crate::algo::allan::stream::SAMPLE_MAX;
use crate::algo::allan::AllanError;
use crate::algo::math::lnf;
use crate::algo::stats::chi2_quantile;

/// STFT frame length (samples).
pub const SEG: usize = 32;
/// Frequency bins used per frame (1..=15).
pub const BINS: usize = SEG / 2 - 1;

/// Which entropy drives the window.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EntropyKind {
    /// Paper eq. 1–3 over frequency bins, normalised by ln(bins).
    Spectral,
    /// Ours: over the frames' energies (time marginal); score = deficit.
    Temporal,
}

/// Step of eq. 4 (SEEDS: the printed rule is garbled).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StepMode {
    /// `L − sgn(E − E0)·ΔL`.
    Constant,
    /// `L − clamp((E − E0)/E0, −1, 1)·ΔL`: faster the further E is from E0.
    Proportional,
}

/// How the window sits around its time t.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Placement {
    /// Centred on t, length L(t) from eq. 4 (the paper).
    Centred,
    /// Ours: the temporal-entropy deficit over the whole λ2 span around t
    /// detects a change; the frame-energy split that maximises the
    /// two-segment likelihood locates it (to one frame), and the window is
    /// the longest one inside the span that does not straddle it (length
    /// λ2/2..λ2). With no change detected the window is the full λ2.
    /// Needs λ1 ≤ λ2/2.
    ChangeAware,
}

/// Where the threshold E0 (or D0) comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Threshold {
    /// A fixed value (the paper: 0.2, chosen by hand from past data).
    Fixed(f32),
    /// Calibrated from the stationary distribution for this window and
    /// frame size, at false-alarm probability `p_fa` per hop.
    Auto {
        /// Probability that a stationary window shrinks at one hop.
        p_fa: f32,
    },
}

/// DAVAR / E-DAVAR settings.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DavarConfig {
    /// Shortest window λ1, samples.
    pub lambda1: u16,
    /// Longest window λ2, samples (also the latency ×2).
    pub lambda2: u16,
    /// Initial window length.
    pub l_init: u16,
    /// Length step ΔL per hop, samples (even; 0 is refused). Unused when
    /// λ1 = λ2, which is plain fixed-window DAVAR.
    pub delta_l: u16,
    /// Step rule.
    pub step: StepMode,
    /// Entropy driving the window.
    pub entropy: EntropyKind,
    /// Threshold E0 / D0.
    pub threshold: Threshold,
    /// Window placement.
    pub placement: Placement,
}

impl DavarConfig {
    /// Fixed-window DAVAR of `len` samples.
    pub const fn fixed(len: u16) -> Self {
        Self {
            lambda1: len,
            lambda2: len,
            l_init: len,
            delta_l: 2,
            step: StepMode::Constant,
            entropy: EntropyKind::Temporal,
            threshold: Threshold::Auto { p_fa: 0.01 },
            placement: Placement::Centred,
        }
    }
}

/// Error building a DAVAR.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DavarError {
    /// λ1 > λ2, l_init outside [λ1, λ2], or λ1 > λ2/2 with
    /// [`Placement::ChangeAware`].
    Lambda,
    /// λ2 over the capacity `CAP`, or λ1 below 2^T (the largest τ), or a
    /// capacity that is not a power of two.
    Capacity,
    /// ΔL = 0 (or odd) on an adaptive window.
    DeltaL,
    /// Threshold not finite, or p_fa outside (0, 1).
    Threshold,
}

/// One output step: the t–τ–σ surface is the sequence of these.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DavarStep<const T: usize> {
    /// Sample index of the window centre (the estimate's time).
    pub t: u64,
    /// Window length L(t), samples.
    pub len: u16,
    /// Last entropy (normalised spectral E, or temporal deficit D).
    pub entropy: f32,
    /// Threshold in force (E0 or D0).
    pub threshold: f32,
    /// Allan variance at τ = 2ʲ·τ0 in (sample unit)²; multiply by lsb².
    pub avar: [f32; T],
}

/// d² exactly: |d| < 2³¹ because |w| < 2²⁰ and m ≤ 2¹⁰ (one `smull`).
#[inline(always)]
fn sq(d: i32) -> u128 {
    (d as i64 * d as i64) as u64 as u128
}

/// Sample i of a ring of CAP (a power of two) samples. A free function so
/// that closures can borrow the ring alone while the sums are updated.
#[inline(always)]
fn ring_at<const CAP: usize>(ring: &[i32; CAP], i: u64) -> i32 {
    ring[i as usize & (CAP - 1)]
}

/// How the sums of the term starting at k, b = Σ w[k..k+m) and
/// a = Σ w[k+m..k+2m), change when the term moves to k + 1: (Δb, Δa).
/// Both window edges move terms this way (the head's term starts at
/// its position − 2m, the tail's at its position).
#[inline(always)]
fn shift(w: impl Fn(u64) -> i32, k: u64, m: u64) -> (i32, i32) {
    let (x0, x1, x2) = (w(k), w(k + m), w(k + 2 * m));
    (x1 - x0, x2 - x1)
}

/// Edge of the window: the sliding sums of the term that starts (tail) or
/// ends (head) there, per τ.
#[derive(Clone, Copy, Debug)]
struct Edge<const T: usize> {
    pos: u64,
    a: [i32; T],
    b: [i32; T],
}

/// Fixed-capacity DAVAR / E-DAVAR for one axis. `CAP` (power of two ≥ λ2)
/// samples of ring, `FRAMES` (≥ CAP/SEG + 1) stored STFT frames, `T` octave
/// τ. RAM ≈ 4·CAP + 64·FRAMES + 40·T bytes.
#[derive(Clone, Debug)]
pub struct Davar<const CAP: usize, const FRAMES: usize, const T: usize> {
    cfg: DavarConfig,
    ring: [i32; CAP],
    n: u64,
    /// Power of bins 1..=15 of each stored frame (frame f in slot f % FRAMES).
    frames: [[f32; BINS]; FRAMES],
    /// Each frame's energy e (bins 1..=15) and e·ln e, kept when the frame
    /// is stored, so a hop's temporal entropy is K additions and one ln.
    energy: [f32; FRAMES],
    eloge: [f32; FRAMES],
    head: Edge<T>,
    tail: Edge<T>,
    acc: [u128; T],
    len: u16,
    entropy: f32,
    threshold: f32,
    started: bool,
    /// Time of the current window.
    t: u64,
    /// Change located at the last hop (ChangeAware).
    change: Option<u64>,
    /// Threshold for each frame count 0..FRAMES, computed once: the χ²
    /// quantile is soft-float f64 work that must stay out of the hot path.
    thresholds: [f32; FRAMES],
}

impl<const CAP: usize, const FRAMES: usize, const T: usize> Davar<CAP, FRAMES, T> {
    /// Check the settings against the capacities.
    pub fn new(cfg: DavarConfig) -> Result<Self, DavarError> {
        let (l1, l2) = (cfg.lambda1 as usize, cfg.lambda2 as usize);
        if l1 > l2 || !(l1..=l2).contains(&(cfg.l_init as usize)) {
            return Err(DavarError::Lambda);
        }
        if cfg.placement == Placement::ChangeAware && 2 * l1 > l2 {
            return Err(DavarError::Lambda);
        }
        if !CAP.is_power_of_two() || l2 > CAP || FRAMES * SEG < CAP + SEG || T == 0 {
            return Err(DavarError::Capacity);
        }
        if T > 11 || (1usize << T) > l1 {
            return Err(DavarError::Capacity);
        }
        if l1 < l2 && (cfg.delta_l == 0 || cfg.delta_l % 2 == 1) {
            return Err(DavarError::DeltaL);
        }
        match cfg.threshold {
            Threshold::Fixed(v) if !v.is_finite() => return Err(DavarError::Threshold),
            Threshold::Auto { p_fa } if !(p_fa > 0.0 && p_fa < 1.0) => {
                return Err(DavarError::Threshold)
            }
            _ => {}
        }
        let edge = Edge {
            pos: 0,
            a: [0; T],
            b: [0; T],
        };
        let mut d = Self {
            cfg,
            ring: [0; CAP],
            n: 0,
            frames: [[0.0; BINS]; FRAMES],
            energy: [0.0; FRAMES],
            eloge: [0.0; FRAMES],
            head: edge,
            tail: edge,
            acc: [0; T],
            len: cfg.l_init & !1,
            entropy: f32::NAN,
            threshold: f32::NAN,
            started: false,
            t: 0,
            change: None,
            thresholds: [0.0; FRAMES],
        };
        for k in d.tabulated() {
            d.thresholds[k] = d.quantile_for(k);
        }
        d.threshold = d.calibrate(d.len);
        Ok(d)
    }

    /// The settings.
    pub fn config(&self) -> &DavarConfig {
        &self.cfg
    }

    /// Current window length.
    pub fn len(&self) -> u16 {
        self.len
    }

    /// Always false: a window is never empty (for clippy's `len` rule).
    pub fn is_empty(&self) -> bool {
        false
    }

    #[inline(always)]
    fn w(&self, i: u64) -> i32 {
        ring_at(&self.ring, i)
    }

    /// Threshold for a window of `len` samples (see the module docs).
    fn calibrate(&self, len: u16) -> f32 {
        self.calibrate_frames(len as usize / SEG)
    }

    /// Threshold for `frames` STFT frames (table lookup).
    fn calibrate_frames(&self, frames: usize) -> f32 {
        let f = frames.min(FRAMES - 1);
        if self.tabulated().contains(&f) {
            self.thresholds[f]
        } else {
            self.quantile_for(f)
        }
    }

    /// Frame counts a window of λ1..=λ2 samples can hold (one frame is lost
    /// to alignment at most): only these thresholds are tabulated, so the
    /// soft-float χ² quantiles at start-up are the ones that can be used.
    fn tabulated(&self) -> core::ops::RangeInclusive<usize> {
        let lo = (self.cfg.lambda1 as usize / SEG).saturating_sub(1);
        let hi = (self.cfg.lambda2 as usize / SEG + 1).min(FRAMES - 1);
        lo..=hi
    }

    /// Threshold for `frames` STFT frames, computed.
    fn quantile_for(&self, frames: usize) -> f32 {
        let p_fa = match self.cfg.threshold {
            Threshold::Fixed(v) => return v,
            Threshold::Auto { p_fa } => p_fa as f64,
        };
        let k = frames.max(2) as f64;
        let b = BINS as f64;
        match self.cfg.entropy {
            EntropyKind::Temporal => {
                // D ≈ χ²_{K−1} / (K ν), ν = 2·BINS.
                let q = chi2_quantile(1.0 - p_fa, k - 1.0).unwrap_or(k);
                (q / (k * 2.0 * b)) as f32
            }
            EntropyKind::Spectral => {
                // Deficit ≈ χ²_{B−1}/(B·2K); E = 1 − deficit/ln B, and the
                // paper's rule shrinks on *large* E: use the upper quantile
                // of E, i.e. the lower quantile of the deficit.
                let q = chi2_quantile(p_fa, b - 1.0).unwrap_or(1.0);
                (1.0 - q / (b * 2.0 * k) / libm::log(b)) as f32
            }
        }
    }

    /// Add one sample (integer, |w| < 2²⁰; quantise rates with
    /// [`crate::algo::allan::stream::quantise`]). Once λ2 samples have
    /// arrived, returns the time t (sample index) of the window now centred
    /// λ2/2 samples back; [`Davar::estimate`] then gives its values. A
    /// refused sample leaves the state unchanged.
    pub fn push(&mut self, w: i32) -> Result<Option<u64>, AllanError> {
        if !(-SAMPLE_MAX..=SAMPLE_MAX).contains(&w) {
            return Err(AllanError::SampleRange);
        }
        // Fast path, the common case: no hop at this sample and both edges
        // slide by one. One fused pass per τ, before the sample is stored.
        let half2 = self.cfg.lambda2 as u64 / 2;
        if self.started {
            let t = self.n + 1 - half2;
            let hop = t.is_multiple_of(SEG as u64) && self.cfg.lambda1 < self.cfg.lambda2;
            let (s, e) = self.edges(t);
            let frame_done = (self.n + 1).is_multiple_of(SEG as u64);
            if !hop && s == self.tail.pos + 1 && e == self.head.pos + 1 {
                self.slide(w);
                self.ring[self.n as usize & (CAP - 1)] = w;
                self.n += 1;
                if frame_done {
                    self.store_frame();
                }
                self.t = t;
                return Ok(Some(t));
            }
        }
        // No window reaches before n + 1 − λ2 after this sample: move the
        // tail there first, while the sample the new one evicts (when
        // CAP = λ2) is still in the ring.
        if self.started {
            let floor = self.n + 1 - self.cfg.lambda2 as u64;
            if self.tail.pos < floor {
                self.move_tail(floor);
            }
        }
        self.ring[self.n as usize & (CAP - 1)] = w;
        self.n += 1;
        if self.n.is_multiple_of(SEG as u64) {
            self.store_frame();
        }
        if self.n < 2 * half2 {
            return Ok(None);
        }
        let t = self.n - half2;
        self.t = t;
        if !self.started {
            if self.cfg.placement == Placement::ChangeAware {
                self.len = self.cfg.lambda2;
            }
            self.start(t);
        } else {
            if t.is_multiple_of(SEG as u64) && self.cfg.lambda1 < self.cfg.lambda2 {
                match self.cfg.placement {
                    Placement::Centred => self.adapt(t),
                    Placement::ChangeAware => self.locate(t),
                }
            }
            let (s, e) = self.edges(t);
            self.len = (e - s) as u16;
            self.move_head(e);
            self.move_tail(s);
        }
        Ok(Some(t))
    }

    /// Window [s, e) for time t.
    fn edges(&self, t: u64) -> (u64, u64) {
        let half2 = self.cfg.lambda2 as u64 / 2;
        match (self.cfg.placement, self.change) {
            (Placement::Centred, _) => (t - self.len as u64 / 2, t + self.len as u64 / 2),
            (Placement::ChangeAware, None) => (t - half2, t + half2),
            (Placement::ChangeAware, Some(c)) if c <= t => (c.max(t - half2), t + half2),
            (Placement::ChangeAware, Some(c)) => (t - half2, c.min(t + half2)),
        }
    }

    /// ChangeAware: detect and locate one change in the λ2 span around t.
    fn locate(&mut self, t: u64) {
        let half2 = self.cfg.lambda2 as u64 / 2;
        let f_lo = (t - half2).div_ceil(SEG as u64);
        let f_hi = (t + half2) / SEG as u64;
        let k = f_hi.saturating_sub(f_lo) as usize;
        if k < 4 {
            return;
        }
        let Some(deficit) = self.deficit(f_lo, f_hi) else {
            self.change = None;
            return;
        };
        self.entropy = deficit;
        // A change is a fixed instant. Once it is within λ2/4 of t it was
        // located from a span with at least a quarter on its near side, so
        // keep it until it leaves the span: re-locating would only jitter
        // it by a split stride and make both edges jump back and forth.
        if let Some(c) = self.change {
            if c.abs_diff(t) <= half2 / 2 {
                self.threshold = self.calibrate_frames(k);
                return;
            }
        }
        self.threshold = self.calibrate_frames(k);
        if !(deficit > self.threshold) {
            self.change = None;
            return;
        }
        let mut en = [0.0f32; FRAMES];
        let mut tot = 0.0f32;
        for (i, s) in Self::slots(f_lo, f_hi).enumerate() {
            en[i] = self.energy[s];
            tot += en[i];
        }
        // Two-segment scale model: minimise j·ln(mean_left) +
        // (k − j)·ln(mean_right) over the split j (one ln per side). Splits
        // are tried every `stride` frames, at most SPLITS of them, so a hop
        // costs the same at any λ2; the location error stays ≤ λ2/SPLITS.
        const SPLITS: usize = 32;
        let stride = k.div_ceil(SPLITS);
        let (mut best, mut best_j, mut left) = (f32::INFINITY, 0, 0.0f32);
        let mut j0 = 0;
        for j in (stride..k).step_by(stride) {
            for &e in &en[j0..j] {
                left += e;
            }
            j0 = j;
            let right = tot - left;
            if !(left > 0.0 && right > 0.0) {
                continue;
            }
            let (jf, rf) = (j as f32, (k - j) as f32);
            let cost = jf * lnf(left / jf) + rf * lnf(right / rf);
            if cost < best {
                best = cost;
                best_j = j;
            }
        }
        self.change = (best_j > 0).then_some((f_lo + best_j as u64) * SEG as u64);
    }

    /// The current window's step of the t–τ–σ surface (computed on demand:
    /// the u128 → float conversions are not part of the per-sample cost).
    pub fn estimate(&self) -> DavarStep<T> {
        let t = self.t;
        let mut avar = [0.0f32; T];
        for j in 0..T {
            let m = 1u64 << j;
            let terms = (self.head.pos - self.tail.pos + 1).saturating_sub(2 * m);
            if terms > 0 {
                let mf = m as f64;
                avar[j] = (self.acc[j] as f64 / (2.0 * mf * mf * terms as f64)) as f32;
            }
        }
        DavarStep {
            t,
            len: self.len,
            entropy: self.entropy,
            threshold: self.threshold,
            avar,
        }
    }

    /// Build the first window, centred on `t`, from scratch.
    fn start(&mut self, t: u64) {
        let half = self.len as u64 / 2;
        let s = t - half;
        self.tail.pos = s;
        self.head.pos = s;
        // Head sums for the (empty) window ending at s: the 2m samples
        // before s may not exist (s can be 0), so start both edges at s with
        // zero sums and let the head sweep forward; terms are only added
        // once the head has 2m samples inside the window.
        self.head.a = [0; T];
        self.head.b = [0; T];
        self.tail.a = [0; T];
        self.tail.b = [0; T];
        self.acc = [0; T];
        // Tail sums of the term starting at s: b = w[s..s+m), a = w[s+m..s+2m).
        for j in 0..T {
            let m = 1u64 << j;
            for i in 0..m {
                self.tail.b[j] += self.w(s + i);
                self.tail.a[j] += self.w(s + m + i);
            }
        }
        let mut pos = s;
        while pos < t + half {
            pos += 1;
            // Head at pos: the window is [s, pos); sums over the last 2m
            // samples inside it (samples before s count as 0 here, and the
            // term is only used when pos − 2m ≥ s).
            for j in 0..T {
                let m = 1u64 << j;
                let x = self.w(pos - 1);
                let mid = if pos > s + m { self.w(pos - 1 - m) } else { 0 };
                let old = if pos > s + 2 * m {
                    self.w(pos - 1 - 2 * m)
                } else {
                    0
                };
                self.head.a[j] += x - mid;
                self.head.b[j] += mid - old;
                if pos >= s + 2 * m {
                    let d = self.head.a[j] - self.head.b[j];
                    self.acc[j] += sq(d);
                }
            }
        }
        self.head.pos = pos;
        self.started = true;
    }

    /// Slide both edges by one sample while `w` (not yet stored) arrives:
    /// per τ, the term ending at the new head is added and the term starting
    /// at the old tail removed, as one signed delta on the exact sum.
    fn slide(&mut self, w: i32) {
        let n = self.n;
        let (e, s) = (self.head.pos, self.tail.pos);
        // The same term moves as [`shift`], written out: this is the
        // per-sample hot path, the samples at e and s are shared by every
        // τ, and only index n (the arriving sample) needs a test.
        let r = |d: &Self, i: u64| if i == n { w } else { d.w(i) };
        let xh = r(self, e);
        let x0 = self.w(s);
        for j in 0..T {
            let m = 1u64 << j;
            let (mid, old) = (self.w(e - m), self.w(e - 2 * m));
            self.head.a[j] += xh - mid;
            self.head.b[j] += mid - old;
            let dh = self.head.a[j] - self.head.b[j];
            let dt = self.tail.a[j] - self.tail.b[j];
            let (x1, x2) = (self.w(s + m), r(self, s + 2 * m));
            self.tail.b[j] += x1 - x0;
            self.tail.a[j] += x2 - x1;
            // |d| < 2³¹, so d² < 2⁶² and the delta fits an i64; the sum is
            // non-negative, so the wrapping add is exact.
            let delta = (dh as i64 * dh as i64) - (dt as i64 * dt as i64);
            self.acc[j] = self.acc[j].wrapping_add(delta as i128 as u128);
        }
        self.head.pos = e + 1;
        self.tail.pos = s + 1;
    }

    /// Move the head (exclusive end) to `to`, adding or removing the terms
    /// that end there. τ is the outer loop so that each τ's sums and exact
    /// total stay in registers across a long jump.
    fn move_head(&mut self, to: u64) {
        let from = self.head.pos;
        let ring = &self.ring;
        let w = |i: u64| ring_at(ring, i);
        for j in 0..T {
            let m = 1u64 << j;
            let (mut a, mut b, mut acc) = (self.head.a[j], self.head.b[j], self.acc[j]);
            let mut e = from;
            while e < to {
                let (db, da) = shift(w, e - 2 * m, m);
                a += da;
                b += db;
                acc += sq(a - b);
                e += 1;
            }
            while e > to {
                e -= 1;
                acc -= sq(a - b);
                let (db, da) = shift(w, e - 2 * m, m);
                a -= da;
                b -= db;
            }
            (self.head.a[j], self.head.b[j], self.acc[j]) = (a, b, acc);
        }
        self.head.pos = to;
    }

    /// Move the tail (first sample) to `to`, removing or adding the terms
    /// that start there (τ outer, as in [`Davar::move_head`]).
    fn move_tail(&mut self, to: u64) {
        let from = self.tail.pos;
        let ring = &self.ring;
        let w = |i: u64| ring_at(ring, i);
        for j in 0..T {
            let m = 1u64 << j;
            let (mut a, mut b, mut acc) = (self.tail.a[j], self.tail.b[j], self.acc[j]);
            let mut s = from;
            while s < to {
                acc -= sq(a - b);
                let (db, da) = shift(w, s, m);
                b += db;
                a += da;
                s += 1;
            }
            while s > to {
                s -= 1;
                let (db, da) = shift(w, s, m);
                b -= db;
                a -= da;
                acc += sq(a - b);
            }
            (self.tail.a[j], self.tail.b[j], self.acc[j]) = (a, b, acc);
        }
        self.tail.pos = to;
    }

    /// FFT of the frame that just completed; keep the power of bins 1..=15.
    fn store_frame(&mut self) {
        let mut x = [0.0f32; SEG];
        let first = self.n - SEG as u64;
        for (i, v) in x.iter_mut().enumerate() {
            *v = self.w(first + i as u64) as f32;
        }
        let spec = microfft::real::rfft_32(&mut x);
        let slot = (first / SEG as u64) as usize % FRAMES;
        let mut e = 0.0f32;
        for (p, c) in self.frames[slot].iter_mut().zip(spec[1..].iter()) {
            *p = c.re * c.re + c.im * c.im;
            e += *p;
        }
        self.energy[slot] = e;
        self.eloge[slot] = if e > 0.0 { e * lnf(e) } else { 0.0 };
    }

    /// Slots of frames `f_lo..f_hi` (contiguous, wrapping): one u64
    /// division per hop instead of one per frame.
    fn slots(f_lo: u64, f_hi: u64) -> impl Iterator<Item = usize> {
        let first = (f_lo % FRAMES as u64) as usize;
        (0..(f_hi - f_lo) as usize).map(move |i| {
            let s = first + i;
            if s >= FRAMES {
                s - FRAMES
            } else {
                s
            }
        })
    }

    /// Temporal entropy deficit D = ln K − H over frames `f_lo..f_hi`, with
    /// H = ln Σe − Σ(e ln e)/Σe; `None` if the frames hold no energy.
    fn deficit(&self, f_lo: u64, f_hi: u64) -> Option<f32> {
        let (mut tot, mut sum_eloge) = (0.0f32, 0.0f32);
        for s in Self::slots(f_lo, f_hi) {
            tot += self.energy[s];
            sum_eloge += self.eloge[s];
        }
        if !(tot > 0.0) {
            return None;
        }
        let h = lnf(tot) - sum_eloge / tot;
        Some(lnf((f_hi - f_lo) as f32) - h)
    }

    /// Entropy of the window [t − L/2, t + L/2) and the eq. 4 update.
    fn adapt(&mut self, t: u64) {
        let half = self.len as u64 / 2;
        let (s, e) = (t - half, t + half);
        let f_lo = s.div_ceil(SEG as u64);
        let f_hi = e / SEG as u64; // exclusive
        let k = f_hi.saturating_sub(f_lo) as usize;
        if k < 2 {
            return;
        }
        let score = match self.cfg.entropy {
            EntropyKind::Temporal => match self.deficit(f_lo, f_hi) {
                Some(d) => d,
                None => return,
            },
            EntropyKind::Spectral => {
                let mut bins = [0.0f32; BINS];
                for f in Self::slots(f_lo, f_hi) {
                    for (b, p) in bins.iter_mut().zip(self.frames[f].iter()) {
                        *b += p;
                    }
                }
                let tot: f32 = bins.iter().sum();
                if !(tot > 0.0) {
                    return;
                }
                let mut h = 0.0f32;
                for &p in &bins {
                    if p > 0.0 {
                        let q = p / tot;
                        h -= q * lnf(q);
                    }
                }
                h / lnf(BINS as f32)
            }
        };
        self.entropy = score;
        let th = self.threshold;
        let dl = self.cfg.delta_l as f32;
        let step = match self.cfg.step {
            StepMode::Constant => {
                if score > th {
                    dl
                } else if score < th {
                    -dl
                } else {
                    0.0
                }
            }
            StepMode::Proportional => {
                let r = if th != 0.0 {
                    (score - th) / th.abs()
                } else {
                    0.0
                };
                r.clamp(-1.0, 1.0) * dl
            }
        };
        // Even lengths keep the window centred on a whole sample.
        let tentative = (self.len as f32 - step) as i32 & !1;
        let new_len = tentative.clamp(self.cfg.lambda1 as i32, self.cfg.lambda2 as i32) as u16 & !1;
        if new_len != self.len {
            self.len = new_len;
            self.threshold = self.calibrate(new_len);
        }
    }
}

#[cfg(test)]
mod tests;
