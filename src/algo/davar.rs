//! Dynamic Allan variance (DAVAR, Galleani–Tavella, SEEDS.md §0.2) and its
//! adaptive window (E-DAVAR, seed 000), streaming in fixed memory with a
//! bounded cost for every single sample.
//!
//! # Time grid and cost
//! The window moves in whole frames of [`SEG`] = 32 samples: every 32
//! samples (one *hop*) a window is placed and one estimate is published,
//! carrying the time `t` it describes and its edges. Between hops nothing
//! new is known about the window length (the paper's rule also changes L
//! once per STFT hop), and at λ ≥ 256 a 32-sample step of the centre is
//! below the estimate's own resolution.
//!
//! Each arriving sample completes one Allan term per τ (the one that ends
//! there); its square is added, exactly, to the sum of the 32-term *block*
//! its start belongs to. A window [s, e) with frame-aligned edges is then
//! whole blocks plus one block prefix per τ (kept as the prefix's terms
//! arrive), so placing a window anywhere in the span costs T × (blocks)
//! integer additions, however far its edges jump. The worst sample is the
//! hop's, and it is bounded: there is no catch-up when the window flips
//! around a change or first fills (the old sliding design cost up to
//! 500 000 instructions there).
//!
//! Sums are exact integers: |w| < 2²⁰ and m ≤ 2¹⁰ give |d| < 2³¹, d² < 2⁶²,
//! so one term fits a u64, a 32-term block a u64 plus a 3-bit carry, and a
//! window sum a u128. Nothing is subtracted, so nothing can drift.
//!
//! # Placements
//! - [`Placement::Centred`] (the paper, eq. 1–4): the window is centred on
//!   t, its length L moves by ΔL per hop by the entropy rule of eq. 4.
//!   Entropies ([`EntropyKind`]): `Spectral` (faithful, eq. 1–3, over the
//!   STFT bins 1..=15 of the window, normalised by ln 15) or `Temporal`
//!   (ours: over the frames' energies; score = deficit D = ln K − E).
//! - [`Placement::Segmented`] (ours, the default): the λ2 span around t is
//!   segmented by optimal partitioning (penalised likelihood, dynamic
//!   programming) of the frames' τ0 energies (the per-block sums of squared
//!   first differences, whose mean is 62·σ²(τ0) in any noise type) under a
//!   scaled-χ²_ν model, and the window is the segment that holds t, widened
//!   to λ1 where it is shorter. Several changes per span are found; ν is
//!   measured from the data (see [`Davar::nu`]), so coloured noise does not
//!   raise false alarms the way a white-noise threshold does. The
//!   partitioning runs one row per sample after it starts, and the hop's
//!   own work is spread too: the hop notes the new span, the last span's
//!   window is placed `PLACE_AT` = 17 samples later, its window sums are
//!   computed over the next three samples (a third of the τ each) and
//!   published on the last, and the new segmentation starts on the one
//!   after, so these estimates come one hop and 20 samples later (at
//!   λ2 = 1024 the worst sample went from 6 920 to 3 880 instructions
//!   with one publication sample, and to 2 066 with three).
//!
//! # Reading of the paper (SEEDS.md seed 000)
//! - Ambiguity 8 (where t sits in its window): the estimate for t uses a
//!   window around t (Fig. 2 reacts ~300 s early, which only a centred
//!   window does). Streaming, this means a latency of about λ2/2.
//! - λ1, λ2 are rounded to whole frames: λ2 down (the memory bound), λ1 up
//!   (the shortest window), but never above λ2's rounding.
//! - Eq. 4's step: [`StepMode`]. Thresholds: [`Threshold`].

use crate::algo::allan::stream::SAMPLE_MAX;
use crate::algo::allan::AllanError;
use crate::algo::math::{at_least, lnf};
use crate::algo::stats::chi2_quantile;

/// Frame (block, STFT hop) length, samples.
pub const SEG: usize = 32;
/// Frequency bins used per STFT frame (1..=15).
pub const BINS: usize = SEG / 2 - 1;
/// A change bounds a window only if one of the LAG segmentations before put
/// one at the same place (± one frame), or it is strong: a step stays where
/// it is, while a one-off false alarm does not come back. (Requiring the
/// same place exactly 4 hops earlier, which also filtered the changes a
/// variance ramp produces, moving with the span, missed weak steps: the
/// ramps are now told apart by a line, in `segment_window`.)
const LAG: usize = 2;
/// A change whose likelihood gain exceeds STRONG × β bounds a window
/// without waiting for confirmation.
const STRONG: f32 = 3.0;
/// A change gaining less than GRADUAL·β may be read as gradual
/// ([`Davar::segment_window`]).
const GRADUAL: f32 = 2.0;
/// t's segment is a stair of a ramp, not the level of a step, where its
/// energies' slope has z² above this (and runs with the change).
const SLOPE_Z2: f32 = 9.0;
/// Most cells of the segmentation (frames are grouped beyond this, so a
/// hop's work does not grow with λ2).
const CELLS: usize = 16;
/// Segmented placement: samples after the hop at which the last span's
/// window is placed, then published, then the next span's segmentation
/// starts, one on each sample. Past the τ terms (samples 1..T of the hop)
/// and the last segmentation's rows (which run on the samples after its
/// start: CELLS of them, from START_AT + 1 around to the next hop's
/// sample 4). The changes are refined to the frame on the
/// `REFINE_PARTS` samples before (from `REFINE_AT`, a share of them on
/// each): with many changes found (a chip gated in and out of a fused
/// axis) refining and placing together cost 1 100 instructions more than
/// with none, on one sample of the board's loop, which then went over its
/// 10 000; in two parts, one of them still left 17 to spare.
const PLACE_AT: usize = 17;
/// The sample of the hop that learns the noise's tails (~630
/// instructions), once the span has filled: after the τ terms (T ≤ 11)
/// and before the refinement, where no segmentation row runs. (Spread over
/// four samples it cost 30 a sample more in all, and moving it to samples
/// 8–11 moved the board's three-axis peak, not lowered it.)
const TAILS_AT: usize = 12;
const REFINE_PARTS: usize = 4;
const REFINE_AT: usize = PLACE_AT - REFINE_PARTS;
const PUBLISH_AT: usize = PLACE_AT + 1;
/// Samples the publication's window sums are spread over.
const PUB_PARTS: usize = 3;
const START_AT: usize = PUBLISH_AT + PUB_PARTS;
/// Memory of the lag-correlation estimates, frames.
const RHO_FRAMES: f32 = 32.0;
/// Memory of the fourth-moment estimates, frames: the tails of a sensor's
/// noise change slowly, and their estimates are noisier than ρ's (ν from
/// them has sd ≈ 3 % over 512 frames on white noise).
const QUAD_FRAMES: f32 = 512.0;
/// Frames before the fourth moments are used at all.
const QUAD_MIN: u32 = 32;
/// ν falls to the fourth-moment value only where that lies this far below
/// the Gaussian one (as ν_4 / [`TAIL_GATE`], so it moves continuously):
/// its noise then never moves a Gaussian signal's ν, while heavy tails or
/// sub-LSB rounding (ν_4 at half ν_G or less) get theirs.
const TAIL_GATE: f32 = 0.85;
/// Prior for ν before enough frames are seen: 32 first differences of white
/// noise (lag-1 correlation −½ gives ν = 32²/(32 + 62/4) ≈ 21.6).
const NU_WHITE: f32 = 21.6;

/// Which entropy drives the centred window (eq. 1–4).
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

/// How the window is placed around its time t.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Placement {
    /// Centred on t, length L(t) from eq. 4 (the paper).
    Centred,
    /// Ours: the segment of the λ2 span that holds t (optimal partitioning
    /// of the frames' τ0 energies), at least λ1 long.
    Segmented,
}

/// Where the threshold comes from.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Threshold {
    /// A fixed value: E0 or D0 for [`Placement::Centred`] (the paper: 0.2),
    /// the likelihood-ratio threshold for [`Placement::Segmented`].
    Fixed(f32),
    /// Calibrated at false-alarm probability `p_fa` per hop on stationary
    /// input: for Centred from the χ² law of the entropy under white noise;
    /// for Segmented, Bonferroni over the splits of a χ²₁ likelihood ratio.
    Auto {
        /// Probability that a stationary window shrinks at one hop.
        p_fa: f32,
    },
}

/// DAVAR / E-DAVAR settings.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DavarConfig {
    /// Shortest window λ1, samples (rounded up to frames).
    pub lambda1: u16,
    /// Longest window λ2, samples (rounded down to frames; latency ≈ λ2/2).
    pub lambda2: u16,
    /// Initial window length (Centred).
    pub l_init: u16,
    /// Length step ΔL per hop, samples (Centred; even, > 0 when λ1 < λ2).
    pub delta_l: u16,
    /// Step rule (Centred).
    pub step: StepMode,
    /// Entropy driving the window (Centred).
    pub entropy: EntropyKind,
    /// Threshold.
    pub threshold: Threshold,
    /// Window placement.
    pub placement: Placement,
}

impl DavarConfig {
    /// Fixed-window DAVAR of `len` samples (rounded down to frames).
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

    /// Our adaptive window: segmented placement between `lambda1` and
    /// `lambda2`, false-alarm probability 1 % per hop.
    pub const fn segmented(lambda1: u16, lambda2: u16) -> Self {
        Self {
            lambda1,
            lambda2,
            l_init: lambda2,
            delta_l: 2,
            step: StepMode::Constant,
            entropy: EntropyKind::Temporal,
            threshold: Threshold::Auto { p_fa: 0.01 },
            placement: Placement::Segmented,
        }
    }
}

/// Error building a DAVAR.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DavarError {
    /// λ1 > λ2, l_init outside [λ1, λ2], or λ2 shorter than two frames.
    Lambda,
    /// λ2 over the capacity `CAP`, `FRAMES` < CAP/32 + 3 (or ≥ 2¹⁵), `STFT` < FRAMES
    /// for an adaptive centred window,
    /// λ1 below 2^T (the largest τ's term span), CAP < 2^T + 33, T outside
    /// 1..=11, or CAP not a power of two.
    Capacity,
    /// ΔL = 0 (or odd) on an adaptive centred window.
    DeltaL,
    /// Threshold not finite, or p_fa outside (0, 1).
    Threshold,
}

/// One published row of the t–τ–σ surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DavarStep<const T: usize> {
    /// Sample index of the time this estimate describes.
    pub t: u64,
    /// Window [start, end) in sample indices; `t` lies inside it.
    pub start: u64,
    /// End of the window (exclusive).
    pub end: u64,
    /// Window length, samples.
    pub len: u16,
    /// Score of the last hop: entropy E or deficit D (Centred), or the
    /// likelihood ratio ν·LR of the best split of the span (Segmented).
    /// Always finite (0 before a score exists).
    pub score: f32,
    /// Threshold the score was compared with.
    pub threshold: f32,
    /// Allan variance at τ = 2ʲ·τ0 in (sample unit)²; multiply by lsb².
    pub avar: [f32; T],
}

/// Exact window sums of one published hop.
#[derive(Clone, Copy, Debug)]
struct Published<const T: usize> {
    t: u64,
    start: u64,
    end: u64,
    acc: [u128; T],
}

/// Fixed-capacity DAVAR / E-DAVAR for one axis: `CAP` (power of two ≥ λ2)
/// samples of ring, `FRAMES` (≥ CAP/32 + 3) blocks, `T` octave τ, and
/// `STFT` frames of spectrum (FRAMES for an adaptive centred window, which
/// needs them; 0 is enough for the segmented one).
/// RAM ≈ 4·CAP + FRAMES·(17·T + 8) + 68·STFT bytes.
#[derive(Clone, Debug)]
pub struct Davar<const CAP: usize, const FRAMES: usize, const T: usize, const STFT: usize = FRAMES>
{
    cfg: DavarConfig,
    ring: [i32; CAP],
    n: u64,
    /// Sample of the 32-sample hop on which the hop's work is done (1..=31).
    hop_phase: u8,
    /// Slot of block n/32 (kept incrementally: a u64 `%` by a FRAMES that
    /// is not a power of two is a library call on the Cortex-M4).
    cur_slot: usize,
    /// Per τ, the next term to add to the blocks, and the sums of the term
    /// before it: b = Σ w[k..k+m), a = Σ w[k+m..k+2m).
    next: [u64; T],
    a: [i32; T],
    b: [i32; T],
    /// Per τ, the sums of its first term (b over samples 0..m, a over
    /// m..2m), kept as the samples arrive from a running sum read at
    /// each power of two, so that the first term is not summed from
    /// scratch: 2m samples on one sample of the loop (some 7 000
    /// instructions for τ = 1024 after a restart; `cargo xtask
    /// bench-loop`'s scenario E made its worst sample with τ = 256).
    first_a: [i32; T],
    first_b: [i32; T],
    /// Σ of the samples so far (wrapping: a difference of two of them is
    /// exact), while the first terms are being gathered.
    prefix: i32,
    /// Per block (terms starting in it) and τ: Σd² as low word + carry,
    /// and the prefix a window ending in this block needs.
    lo: [[u64; FRAMES]; T],
    /// τ0 block sums as f32, once complete (the segmentation's input).
    x0: [f32; FRAMES],
    /// Per block, the stamp (first frame, as u16) of the last
    /// segmentation that put a change at it (`marks`), or within a frame of
    /// it (`marks_near`); a stale stamp from the time the block completed
    /// otherwise ([`stale`]). Whether one of the last [`LAG`]
    /// segmentations had a change within a frame of c is then one read:
    /// a list per segmentation, walked beside each change, cost ~700
    /// instructions on one sample with fifteen changes (`cargo xtask
    /// bench-loop`, scenario I, after two stuck chips came back).
    marks: [u16; FRAMES],
    marks_near: [u16; FRAMES],
    /// Prefix sums of x0 over the span being segmented.
    px: [f32; FRAMES],
    hi: [[u8; FRAMES]; T],
    pre: [[u64; FRAMES]; T],
    /// STFT power of bins 1..=15 per frame, its energy and e·ln e
    /// (Centred windows only).
    frames: [[f32; BINS]; STFT],
    energy: [f32; STFT],
    eloge: [f32; STFT],
    /// Frames in the span (λ2 rounded down) and the shortest window.
    span: usize,
    min_frames: usize,
    /// Centred: current length in samples (eq. 4 state).
    len: u16,
    score: f32,
    threshold: f32,
    /// Σd², Σd·d₋₁, Σd·d₋₂ of the τ0 differences d over the current frame
    /// (exact), the last two d, and the running lag-1, lag-2 correlations.
    lag: [i64; 3],
    dprev: [i32; 2],
    rho: [f32; 2],
    /// The τ0 terms (d) of the last frame, for [`Davar::learn_tails`].
    tail_terms: Option<(u64, u64)>,
    /// Running (over [`QUAD_FRAMES`]) covariances of q at lags 0, 1, 2 and
    /// σ⁴ (the mean q·q₊₃), each frame's in its own scale (the ratios taken
    /// in `nu` weigh frames by σ⁴), and the frames seen.
    cov_q: [f32; 4],
    quad_frames: u32,
    /// Threshold per frame count (Centred: K frames in the window;
    /// Segmented: a segment of K frames).
    thresholds: [f32; FRAMES],
    last: Option<Published<T>>,
    /// The last published window's first block, and per τ the end of its
    /// whole blocks and their sum (for the next window's update).
    win_f0: Option<u64>,
    win_q: [u64; T],
    win_sum: [u128; T],
    /// Centred: the window placed at the last hop (span's first frame and
    /// window frames), published at the next.
    pending: Option<(u64, usize, usize)>,
    /// ln n for n = 0..FRAMES (ln 0 unused).
    ln_n: [f32; FRAMES],
    dp: Segmentation,
}

/// Optimal partitioning of one span (Segmented placement), computed one
/// row per sample over the hop after the span completed.
#[derive(Clone, Debug)]
struct Segmentation {
    /// First frame of the span being segmented, if any.
    first: Option<u64>,
    /// First frame of the span to segment next (noted at the hop, started
    /// [`START_AT`] samples later).
    next_first: Option<u64>,
    /// The window placed at [`PLACE_AT`] (span's first frame, window
    /// frames), published at [`PUBLISH_AT`].
    placed: Option<(u64, usize, usize)>,
    /// The segment bounds being refined from [`REFINE_AT`] (span's first
    /// frame, bounds, their count less one, the next change to refine).
    refined: Option<(u64, [u16; CELLS + 1], usize, usize)>,
    /// Frames per cell and cells.
    group: usize,
    cells: usize,
    /// Prefix sums of the cells' τ0 energies.
    sum: [f32; CELLS + 1],
    /// Optimal cost of cells 0..j and the start of its last segment.
    cost: [f32; CELLS + 1],
    arg: [u8; CELLS + 1],
    /// Next row to compute (1..=cells; cells + 1 when done).
    row: usize,
    nu: f32,
    beta: f32,
    /// Stamps of the last [`LAG`] segmentations (their first frames, as
    /// u16; the first `recent_len` of them valid, the next written at
    /// `recent_at`): their changes are the blocks whose `marks` carry one
    /// of them.
    recent: [u16; LAG],
    recent_len: u8,
    recent_at: usize,
}

impl<const CAP: usize, const FRAMES: usize, const T: usize, const STFT: usize>
    Davar<CAP, FRAMES, T, STFT>
{
    /// Check the settings against the capacities.
    pub fn new(cfg: DavarConfig) -> Result<Self, DavarError> {
        let (l1, l2) = (cfg.lambda1 as usize, cfg.lambda2 as usize);
        if l1 > l2 || !(l1..=l2).contains(&(cfg.l_init as usize)) || l2 < 2 * SEG {
            return Err(DavarError::Lambda);
        }
        // Windows are published one hop after their span (the terms and the
        // segmentation are computed meanwhile), and the blocks that left
        // since the last window are subtracted from its sums: two more
        // blocks than the span.
        // (FRAMES < 2¹⁵ keeps the blocks' change stamps apart: [`stale`].)
        if !CAP.is_power_of_two() || l2 > CAP || FRAMES < CAP / SEG + 3 || FRAMES >= 1 << 15 {
            return Err(DavarError::Capacity);
        }
        let span = l2 / SEG;
        let min_frames = l1.div_ceil(SEG).min(span);
        // Terms are added once per hop, so the ring must still hold the
        // oldest sample of a term 2^T + 32 samples back.
        if T == 0 || T > 11 || (1usize << T) > min_frames * SEG || (1usize << T) + SEG + 1 > CAP {
            return Err(DavarError::Capacity);
        }
        let centred_adaptive = cfg.placement == Placement::Centred && min_frames < span;
        if centred_adaptive && (cfg.delta_l == 0 || cfg.delta_l % 2 == 1) {
            return Err(DavarError::DeltaL);
        }
        if centred_adaptive && STFT < FRAMES {
            return Err(DavarError::Capacity);
        }
        match cfg.threshold {
            Threshold::Fixed(v) if !v.is_finite() => return Err(DavarError::Threshold),
            Threshold::Auto { p_fa } if !(p_fa > 0.0 && p_fa < 1.0) => {
                return Err(DavarError::Threshold)
            }
            _ => {}
        }
        let mut d = Self {
            cfg,
            ring: [0; CAP],
            n: 0,
            hop_phase: 1,
            cur_slot: 0,
            next: [0; T],
            a: [0; T],
            b: [0; T],
            first_a: [0; T],
            first_b: [0; T],
            prefix: 0,
            lo: [[0; FRAMES]; T],
            x0: [0.0; FRAMES],
            marks: [stale(0); FRAMES],
            marks_near: [stale(0); FRAMES],
            px: [0.0; FRAMES],
            hi: [[0; FRAMES]; T],
            pre: [[0; FRAMES]; T],
            frames: [[0.0; BINS]; STFT],
            energy: [0.0; STFT],
            eloge: [0.0; STFT],
            span,
            min_frames,
            len: cfg.l_init,
            score: 0.0,
            threshold: 0.0,
            lag: [0; 3],
            dprev: [0; 2],
            rho: [-0.5, 0.0],
            tail_terms: None,
            cov_q: [0.0; 4],
            quad_frames: 0,
            thresholds: [0.0; FRAMES],
            last: None,
            win_f0: None,
            win_q: [0; T],
            win_sum: [0; T],
            pending: None,
            ln_n: [0.0; FRAMES],
            dp: Segmentation {
                first: None,
                next_first: None,
                placed: None,
                refined: None,
                group: span.div_ceil(CELLS).max(1),
                cells: span.div_ceil(span.div_ceil(CELLS).max(1)),
                sum: [0.0; CELLS + 1],
                cost: [0.0; CELLS + 1],
                arg: [0; CELLS + 1],
                row: 0,
                nu: NU_WHITE,
                beta: 0.0,
                recent: [0; LAG],
                recent_len: 0,
                recent_at: 0,
            },
        };
        for (i, v) in d.ln_n.iter_mut().enumerate().skip(1) {
            *v = ln_fast(i as f32);
        }
        // Soft-float χ² quantiles, once: only the frame counts that can
        // occur are tabulated.
        let lo = match cfg.placement {
            Placement::Centred => min_frames.saturating_sub(1),
            Placement::Segmented => 2,
        };
        for k in lo..=span {
            let q = d.quantile_for(k);
            if let Some(t) = d.thresholds.get_mut(k) {
                *t = q;
            }
        }
        d.threshold = d.threshold_for(span);
        Ok(d)
    }

    /// Forget every sample (after a gap in the input), keeping the settings
    /// and the tabulated thresholds.
    pub fn reset(&mut self) {
        self.n = 0;
        self.cur_slot = 0;
        self.next = [0; T];
        self.a = [0; T];
        self.b = [0; T];
        self.prefix = 0;
        self.len = self.cfg.l_init;
        self.score = 0.0;
        self.threshold = self.threshold_for(self.span);
        self.lag = [0; 3];
        self.dprev = [0; 2];
        self.rho = [-0.5, 0.0];
        self.tail_terms = None;
        self.cov_q = [0.0; 4];
        self.quad_frames = 0;
        self.last = None;
        self.win_f0 = None;
        self.pending = None;
        self.dp.first = None;
        self.dp.next_first = None;
        self.dp.placed = None;
        self.dp.refined = None;
        self.dp.row = 0;
        // (The valid stamps are the first `recent_len`: start at 0.)
        (self.dp.recent_len, self.dp.recent_at) = (0, 0);
        // (Every block a later segmentation reads completes after this and
        // is made stale then; cleared here all the same.)
        self.marks = [stale(0); FRAMES];
        self.marks_near = [stale(0); FRAMES];
    }

    /// The tabulated threshold for `k` frames (every k a window of this
    /// configuration can have is tabulated at construction).
    fn threshold_for(&self, k: usize) -> f32 {
        self.thresholds.get(k).copied().unwrap_or(f32::INFINITY)
    }

    /// The settings.
    pub fn config(&self) -> &DavarConfig {
        &self.cfg
    }

    /// Length of the window last published (samples), or of the span
    /// before the first one.
    pub fn len(&self) -> u16 {
        self.last
            .map_or((self.span * SEG) as u16, |p| (p.end - p.start) as u16)
    }

    /// Always false: a window is never empty (for clippy's `len` rule).
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Samples between an estimate's time and the sample that published it
    /// (the price of a window around t): λ2/2 and one hop, the time the
    /// terms and the segmentation take to compute (segmented: and the
    /// samples by which its publication follows the hop, up to the last
    /// of its `PUB_PARTS`).
    pub fn latency(&self) -> u64 {
        let publish = match self.cfg.placement {
            Placement::Segmented => (START_AT - 1) as u64,
            Placement::Centred => 0,
        };
        (SEG * self.span).div_ceil(2) as u64 + self.hop_phase as u64 + SEG as u64 + publish
    }

    /// Do the hop's work `phase` samples (1..=31, clamped) after each frame
    /// boundary instead of 1: several E-DAVARs fed the same samples (the
    /// three fused axes) then do their heaviest samples at different
    /// times. Estimates come `phase − 1` samples later. Set before the
    /// first sample.
    pub fn with_hop_phase(mut self, phase: u8) -> Self {
        self.set_hop_phase(phase);
        self
    }

    /// [`Davar::with_hop_phase`] in place.
    pub fn set_hop_phase(&mut self, phase: u8) {
        self.hop_phase = phase.clamp(1, SEG as u8 - 1);
    }

    /// Effective degrees of freedom of one frame's τ0 energy x = Σd² over
    /// 32 first differences d: for Gaussian d, ν = 2E\[x\]²/Var x =
    /// 32²/Σ_h (32 − |h|)ρ_h² ≈ 32²/(32 + 62ρ₁² + 60ρ₂²), with the lag
    /// correlations ρ₁, ρ₂ of d measured inside each frame, so a variance
    /// change, however frequent, does not bias them. White noise: ρ₁ = −½,
    /// ν = 21.6 (the prior); random walk: ρ = 0, ν = 32; quantisation of
    /// an angle (blue rate noise): ρ₁ = −⅔, ρ₂ = ⅙, ν ≈ 16.7.
    ///
    /// That form holds for Gaussian d only. In general Var x =
    /// Σ_h (32 − |h|)·Cov(q, q₊ₕ) over the squares q = d², which
    /// `learn_tails` measures (lags 0–2, σ⁴ from lag 3), and
    /// ν₄ = 2·32²σ⁴/Var x. Heavy tails (Student's t with 5 dof: ν₄ ≈ 12)
    /// or rounding below half an LSB (σ = 0.3 LSB: ν₄ ≈ 6) make it far
    /// smaller, and a threshold set with the Gaussian ν then sees changes
    /// everywhere (9.7 % and 36 % of windows shortened on stationary
    /// input). ν is the smaller of the two, ν₄ taken as ν₄/0.85
    /// (`TAIL_GATE`): ν₄ is the noisier, and on Gaussian frames it then
    /// never moves ν.
    pub fn nu(&self) -> f32 {
        let [r1, r2] = self.rho;
        let s = SEG as f32;
        let gauss = s * s / (s + 2.0 * (s - 1.0) * r1 * r1 + 2.0 * (s - 2.0) * r2 * r2);
        let [c0, c1, c2, sig4] = self.cov_q;
        let var = s * c0 + 2.0 * (s - 1.0) * c1 + 2.0 * (s - 2.0) * c2;
        if self.quad_frames < QUAD_MIN || !(var > 0.0) || !(sig4 > 0.0) {
            return gauss;
        }
        gauss.min(2.0 * s * s * sig4 / var / TAIL_GATE)
    }

    #[inline(always)]
    fn w(&self, i: u64) -> i32 {
        self.ring[i as usize & (CAP - 1)]
    }

    #[inline(always)]
    fn slot(block: u64) -> usize {
        (block % FRAMES as u64) as usize
    }

    /// Slot of block n/32 − back (back < FRAMES).
    #[inline(always)]
    fn back_slot(&self, back: usize) -> usize {
        if self.cur_slot >= back {
            self.cur_slot - back
        } else {
            self.cur_slot + FRAMES - back
        }
    }

    /// Slot of an older block f (within FRAMES of the newest).
    #[inline(always)]
    fn slot_of(&self, f: u64) -> usize {
        self.back_slot((self.n / SEG as u64 - f) as usize)
    }

    /// The slot `c` blocks after slot `s0` (c < FRAMES: one wrap at most).
    #[inline(always)]
    fn ahead(s0: usize, c: usize) -> usize {
        let s = s0 + c;
        if s >= FRAMES {
            s - FRAMES
        } else {
            s
        }
    }

    /// The next slot after `s`.
    #[inline(always)]
    fn next(s: usize) -> usize {
        if s + 1 == FRAMES {
            0
        } else {
            s + 1
        }
    }

    /// Threshold for `frames` frames (see [`Threshold`]).
    fn quantile_for(&self, frames: usize) -> f32 {
        let p_fa = match self.cfg.threshold {
            Threshold::Fixed(v) => return v,
            Threshold::Auto { p_fa } => p_fa as f64,
        };
        let k = frames.max(2) as f64;
        let b = BINS as f64;
        match (self.cfg.placement, self.cfg.entropy) {
            (Placement::Segmented, _) => {
                // Penalty per change: the χ²₁ likelihood ratio of one split,
                // Bonferroni over the k − 1 splits of a k-frame span.
                chi2_quantile(1.0 - p_fa / (k - 1.0), 1.0).unwrap_or(10.0) as f32
            }
            (Placement::Centred, EntropyKind::Temporal) => {
                // D ≈ χ²_{K−1} / (K ν), ν = 2·BINS (white noise).
                let q = chi2_quantile(1.0 - p_fa, k - 1.0).unwrap_or(k);
                (q / (k * 2.0 * b)) as f32
            }
            (Placement::Centred, EntropyKind::Spectral) => {
                // Deficit ≈ χ²_{B−1}/(B·2K); E = 1 − deficit/ln B, and the
                // paper's rule shrinks on *large* E: use the upper quantile
                // of E, i.e. the lower quantile of the deficit.
                let q = chi2_quantile(p_fa, b - 1.0).unwrap_or(1.0);
                (1.0 - q / (b * 2.0 * k) / libm::log(b)) as f32
            }
        }
    }

    /// Add one sample (integer, |w| < 2²⁰; quantise rates with
    /// [`crate::algo::allan::stream::quantise`]). Once per hop, from the
    /// moment the span is full, a new estimate is published and its time t
    /// returned ([`Davar::estimate`] gives it). A refused sample leaves the
    /// state unchanged.
    pub fn push(&mut self, w: i32) -> Result<Option<u64>, AllanError> {
        if !(-SAMPLE_MAX..=SAMPLE_MAX).contains(&w) {
            return Err(AllanError::SampleRange);
        }
        let n = self.n;
        self.ring[n as usize & (CAP - 1)] = w;
        self.n = n + 1;
        if n >> T == 0 {
            self.gather_first_terms(w);
        }
        let n = self.n;
        if n.is_multiple_of(SEG as u64) {
            self.cur_slot = Self::next(self.cur_slot);
        }
        let centred_adaptive =
            self.cfg.placement == Placement::Centred && self.min_frames < self.span;
        // The work of a hop is spread over its 32 samples (1 is the hop):
        // phase 0 the STFT of the finished frame (centred windows), phase
        // 1 + j the new Allan terms of τ = 2ʲ (τ0 at the hop, the others on
        // the next samples), every other sample one row of the
        // segmentation.
        let phase = (n % SEG as u64) as usize;
        let hop_phase = self.hop_phase as usize;
        // Samples since the hop: the terms of τ = 2ʲ come j samples after it.
        let rel = (phase + SEG - hop_phase) % SEG;
        if phase == 0 && centred_adaptive {
            self.store_frame();
        }
        if (1..T).contains(&rel) {
            self.add_terms(rel);
        }
        if rel == TAILS_AT {
            self.learn_tails();
        }
        if rel != 0 {
            let segmented = self.cfg.placement == Placement::Segmented;
            if segmented && (REFINE_AT..PLACE_AT).contains(&rel) {
                self.refine_part(rel - REFINE_AT);
            } else if segmented && rel == PLACE_AT {
                // The last segmentation's window (its rows finished long
                // ago; `while` only guards the invariant).
                if let (Some(prev), Some(_)) = (self.dp.first, self.dp.next_first) {
                    while self.dp.row <= self.dp.cells {
                        self.dp_row();
                    }
                    let (lo, hi) = self.segment_window(prev);
                    self.dp.placed = Some((prev, lo, hi));
                }
            } else if segmented && (PUBLISH_AT..START_AT).contains(&rel) {
                // The window sums, a third of the τ on each of three
                // samples; the estimate is out on the last.
                let part = rel - PUBLISH_AT;
                let taus = T * part / PUB_PARTS..T * (part + 1) / PUB_PARTS;
                if let Some((prev, lo, hi)) = self.dp.placed {
                    let (t, f0, f1) = self.placed_window(prev, lo, hi);
                    self.window_sums(f0, f1, taus);
                    if part + 1 == PUB_PARTS {
                        self.dp.placed = None;
                        return Ok(Some(self.finish_publish(t, f0, f1)));
                    }
                }
            } else if segmented && rel == START_AT {
                if let Some(first) = self.dp.next_first.take() {
                    self.dp_start(first);
                }
            } else if self.dp.row >= 1 && self.dp.row <= self.dp.cells {
                self.dp_row();
            }
            return Ok(None);
        }
        // The hop, at least one sample after a frame boundary: the τ0
        // terms of the last frame end on its first sample.
        self.add_terms(0);
        if n < (self.span * SEG + hop_phase) as u64 {
            // (The tails are learnt once the span has filled: during the
            // fill their samples would meet the first, from-scratch terms
            // of the long τ.)
            self.tail_terms = None;
            return Ok(None);
        }
        let c = n / SEG as u64; // frames 0..c are complete
        self.learn_nu();
        let first = c - self.span as u64;
        let done = match self.cfg.placement {
            // The window placed at the last hop is published now: by then
            // the terms of every τ up to its end have been added.
            Placement::Centred => {
                let done = self
                    .pending
                    .map(|(prev, lo, hi)| self.publish_placed(prev, lo, hi));
                let (lo, hi) = self.centred(first, centred_adaptive);
                self.pending = Some((first, lo, hi));
                done
            }
            Placement::Segmented => {
                // The hop only notes the new span: the last span's window
                // is placed and published PUBLISH_AT samples later and the
                // new segmentation starts on the sample after, so no
                // sample carries all three (5 650 instructions on one
                // sample at λ2 = 1024 when they did).
                self.dp.next_first = Some(first);
                None
            }
        };
        Ok(done)
    }

    /// The last sample pushed, if any since the start or a reset.
    pub fn last_sample(&self) -> Option<i32> {
        let n = self.n.checked_sub(1)?;
        self.ring.get(n as usize & (CAP - 1)).copied()
    }

    /// After sample `w` (the `n`th, from 1): at n = 2ʲ the first term's b
    /// of τ = 2ʲ is the running sum, and a of τ = 2ʲ⁻¹ the sum since
    /// n = 2ʲ⁻¹. Runs for the first 2^T samples after a start.
    #[inline]
    fn gather_first_terms(&mut self, w: i32) {
        self.prefix = self.prefix.wrapping_add(w);
        let n = self.n;
        if n.is_power_of_two() {
            let i = n.trailing_zeros() as usize;
            if let Some(b) = self.first_b.get_mut(i) {
                *b = self.prefix;
            }
            if let Some(j) = i.checked_sub(1) {
                if let (Some(a), Some(&b)) = (self.first_a.get_mut(j), self.first_b.get(j)) {
                    *a = self.prefix.wrapping_sub(b);
                }
            }
        }
    }

    /// Add every Allan term completed since the last hop to its block, per
    /// τ in one tight loop (sliding sums in registers): ~10 instructions a
    /// term, where doing it sample by sample cost ~60 (state reloads).
    /// Term k of τ = m uses samples [k, k + 2m); `next[j]` is the next term
    /// to add and `a`, `b` hold the sums of the term before it.
    fn add_terms(&mut self, j: usize) {
        let n = self.n;
        if j >= T {
            return;
        }
        {
            let m = 1u64 << j;
            if n < 2 * m {
                return;
            }
            let last = n - 2 * m; // newest complete term
            let mut k = self.next[j];
            if k > last {
                return;
            }
            let (mu, m2) = (m as usize, 2 * m as usize);
            let (mut a, mut b) = (self.a[j], self.b[j]);
            let first_k = k;
            let pre_off = (SEG - m2 % SEG) % SEG;
            while k <= last {
                let block = k / SEG as u64;
                let off = (k % SEG as u64) as usize;
                let end = last.min(block * SEG as u64 + SEG as u64 - 1);
                // (Slots are < FRAMES by construction; the `min` lets the
                // compiler see it, so no index here can panic.)
                let slot = self.slot_of(block).min(FRAMES - 1);
                let (mut lo, mut hi) = if off == 0 {
                    (0u64, 0u8)
                } else {
                    (self.lo[j][slot], self.hi[j][slot])
                };
                let mut from = k;
                if k == 0 {
                    // First term: its sums, gathered as the samples came.
                    (a, b) = (self.first_a[j], self.first_b[j]);
                    (lo, hi) = add_sq(lo, hi, a - b);
                    if pre_off == 0 {
                        self.pre[j][slot] = lo;
                    }
                    from = 1;
                }
                // Terms from..=end, the prefix recorded on the way.
                let pre_k = block * SEG as u64 + pre_off as u64;
                if from <= end {
                    let i = (from as usize).wrapping_sub(1);
                    let slide = if carry_free(mu) {
                        Self::slide::<false>
                    } else {
                        Self::slide::<true>
                    };
                    if (from..=end).contains(&pre_k) {
                        let n1 = (pre_k - from) as usize + 1;
                        let i2;
                        (i2, a, b, lo, hi) = slide(&self.ring, i, n1, mu, a, b, lo, hi);
                        self.pre[j][slot] = lo;
                        (_, a, b, lo, hi) =
                            slide(&self.ring, i2, (end - pre_k) as usize, mu, a, b, lo, hi);
                    } else {
                        (_, a, b, lo, hi) =
                            slide(&self.ring, i, (end - from) as usize + 1, mu, a, b, lo, hi);
                    }
                }
                self.lo[j][slot] = lo;
                self.hi[j][slot] = hi;
                if j == 0 && end % SEG as u64 == SEG as u64 - 1 {
                    self.x0[slot] = u64_to_f32(lo);
                    self.marks[slot] = stale(block);
                    self.marks_near[slot] = stale(block);
                }
                k = end + 1;
            }
            self.next[j] = k;
            (self.a[j], self.b[j]) = (a, b);
            if j == 0 {
                // τ0 lag sums for ν: d = w[i + 1] − w[i] (|d| < 2²¹, so the
                // products fit).
                let mask = CAP - 1;
                let ([mut s0, mut s1, mut s2], [mut p1, mut p2]) = (self.lag, self.dprev);
                for i in first_k as usize..=last as usize {
                    let d = self.ring[(i + 1) & mask] - self.ring[i & mask];
                    s0 += d as i64 * d as i64;
                    s1 += d as i64 * p1 as i64;
                    s2 += d as i64 * p2 as i64;
                    (p1, p2) = (d, p1);
                }
                (self.lag, self.dprev) = ([s0, s1, s2], [p1, p2]);
                // The tails take the last whole frame's terms, whatever
                // the hop's phase (so that staggered axes learn the same).
                let end = (last + 1) / SEG as u64 * SEG as u64;
                self.tail_terms = end.checked_sub(SEG as u64).map(|f| (f, end - 1));
            }
        }
    }

    /// `count` terms of τ = m: slide the sums from the term starting at
    /// i + 1 − 1 = i to the next (samples i, i + m, i + 2m), add each d².
    /// The per-term hot loop: everything in registers.
    ///
    /// Without `CARRY` the squares are summed in the u64 alone: the caller
    /// has checked that a whole 32-term block cannot overflow it (see
    /// [`carry_free`]), and the carry test per term (two more adds and a
    /// spilled register) goes.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn slide<const CARRY: bool>(
        ring: &[i32; CAP],
        mut i: usize,
        count: usize,
        m: usize,
        mut a: i32,
        mut b: i32,
        mut lo: u64,
        mut hi: u8,
    ) -> (usize, i32, i32, u64, u8) {
        let mask = CAP - 1;
        let mut left = count;
        // In runs where none of the three samples wraps around the ring:
        // plain slices, so the loop walks three pointers (about 12
        // instructions a term on the Cortex-M4 instead of 22 with a mask
        // per read).
        while left > 0 {
            let (i0, i1, i2) = (
                i & mask,
                i.wrapping_add(m) & mask,
                i.wrapping_add(2 * m) & mask,
            );
            let run = left.min(CAP - i0).min(CAP - i1).min(CAP - i2);
            let s0 = ring.get(i0..i0 + run).unwrap_or(&[]);
            let s1 = ring.get(i1..i1 + run).unwrap_or(&[]);
            let s2 = ring.get(i2..i2 + run).unwrap_or(&[]);
            for ((x0, x1), x2) in s0.iter().zip(s1).zip(s2) {
                b += x1 - x0;
                a += x2 - x1;
                if CARRY {
                    (lo, hi) = add_sq(lo, hi, a - b);
                } else {
                    let d = (a - b) as i64;
                    lo = lo.wrapping_add((d * d) as u64);
                }
            }
            i = i.wrapping_add(run);
            left -= run;
        }
        (i, a, b, lo, hi)
    }

    /// Fold the frame's lag sums into the running correlations.
    fn learn_nu(&mut self) {
        let [s0, s1, s2] = self.lag;
        self.lag = [0; 3];
        if s0 > 0 {
            let s0 = i64_to_f32(s0);
            for (r, s) in self.rho.iter_mut().zip([s1, s2]) {
                *r += (i64_to_f32(s) / s0 - *r) / RHO_FRAMES;
            }
        }
    }

    /// Fold the last frame's fourth moments into the running covariances
    /// of q = d² (ν from them: [`Davar::nu`]), on a sample of the hop of
    /// its own. Out of line, like `refine_part`: inlined in `push`, it cost
    /// every sample ~30 instructions.
    #[inline(never)]
    fn learn_tails(&mut self) {
        let Some((from, to)) = self.tail_terms.take() else {
            return;
        };
        // (usize indices: a u64 loop cost twice the instructions.)
        let (from, count, mask) = (from as usize, (to - from) as usize + 1, CAP - 1);
        let ([mut u0, mut u1, mut u2, mut u3], [mut q1, mut q2, mut q3]) =
            ([0.0f32; 4], [0.0f32; 3]);
        for i in from..from + count {
            let d = (self.ring[(i + 1) & mask] - self.ring[i & mask]) as f32;
            let q = d * d;
            u0 += q * q;
            u1 += q * q1;
            u2 += q * q2;
            u3 += q * q3;
            (q1, q2, q3) = (q, q1, q2);
        }
        // Pairs at lag 3 are independent (d = w₁ − w₀ shares no sample
        // with d₊₃, and rate noise is near white at that lag), so their
        // mean is σ⁴ = (E q)², taken inside the frame so that a variance
        // change between frames does not enter; lags 0–2 less σ⁴ are the
        // covariances of q.
        let n = count as u32 as f32;
        if n >= 8.0 {
            let sig4 = u3 / (n - 3.0);
            let c = [
                u0 / n - sig4,
                u1 / (n - 1.0) - sig4,
                u2 / (n - 2.0) - sig4,
                sig4,
            ];
            for (m, c) in self.cov_q.iter_mut().zip(c) {
                *m += (c - *m) / QUAD_FRAMES;
            }
            self.quad_frames = self.quad_frames.saturating_add(1);
        }
    }

    /// Publish the window [lo, hi) (frames) of the span starting at frame
    /// `prev`: its estimate describes the span's centre.
    fn publish_placed(&mut self, prev: u64, lo: usize, hi: usize) -> u64 {
        let (t, f0, f1) = self.placed_window(prev, lo, hi);
        self.publish(t, f0, f1)
    }

    /// The time and frames [f0, f1) of window [lo, hi) of the span at
    /// `prev`.
    fn placed_window(&self, prev: u64, lo: usize, hi: usize) -> (u64, u64, u64) {
        let half = (SEG * self.span / 2) as u64;
        (SEG as u64 * prev + half, prev + lo as u64, prev + hi as u64)
    }

    /// Sum the exact window sums of frames [f0, f1), keep them, return t.
    fn publish(&mut self, t: u64, f0: u64, f1: u64) -> u64 {
        self.window_sums(f0, f1, 0..T);
        self.finish_publish(t, f0, f1)
    }

    /// Slot of block `b`, from f0's slot `s_f0` (blocks within FRAMES of
    /// f0 either way).
    fn slot_near(f0: u64, s_f0: usize, b: u64) -> usize {
        if b >= f0 {
            let d = (b - f0) as usize; // < FRAMES: b is in or next to the window
            if s_f0 + d >= FRAMES {
                s_f0 + d - FRAMES
            } else {
                s_f0 + d
            }
        } else {
            let d = (f0 - b) as usize;
            if s_f0 >= d {
                s_f0 - d
            } else {
                s_f0 + FRAMES - d
            }
        }
    }

    /// The whole-block sums of window [f0, f1) for the τ in `taus`, kept in
    /// `win_q`/`win_sum`; the board spreads the τ over `PUB_PARTS` samples. Until
    /// [`Self::finish_publish`] the last window (`win_f0`) stays the base
    /// of the update, for every τ alike.
    fn window_sums(&mut self, f0: u64, f1: u64, taus: core::ops::Range<usize>) {
        let e = f1 * SEG as u64;
        let s_f0 = self.slot_of(f0).min(FRAMES - 1);
        let slot = |b: u64| Self::slot_near(f0, s_f0, b);
        let old_f0 = self.win_f0;
        for j in taus.start..taus.end.min(T) {
            let m = 1u64 << j;
            // Terms k ∈ [s, e − 2m]: whole blocks f0..q, then q's prefix.
            let q = (e - 2 * m) / SEG as u64;
            // The whole blocks: from the last window's by the blocks that
            // entered and left (exact integers, so nothing drifts), or
            // from scratch when that is shorter.
            let full = match old_f0 {
                Some(of0) if f0.abs_diff(of0) + q.abs_diff(self.win_q[j]) < q - f0 => {
                    let (oq, mut v) = (self.win_q[j], self.win_sum[j]);
                    if q > oq {
                        v += self.block_sum(j, slot(oq), q - oq);
                    } else {
                        v -= self.block_sum(j, slot(q), oq - q);
                    }
                    if f0 > of0 {
                        v -= self.block_sum(j, slot(of0), f0 - of0);
                    } else {
                        v += self.block_sum(j, s_f0, of0 - f0);
                    }
                    v
                }
                _ => self.block_sum(j, s_f0, q - f0),
            };
            self.win_q[j] = q;
            self.win_sum[j] = full;
        }
    }

    /// Publish window [f0, f1) at time t from its whole-block sums (all τ
    /// done by [`Self::window_sums`]) and the last blocks' prefixes.
    fn finish_publish(&mut self, t: u64, f0: u64, f1: u64) -> u64 {
        let s_f0 = self.slot_of(f0).min(FRAMES - 1);
        let mut acc = [0u128; T];
        for (j, a) in acc.iter_mut().enumerate() {
            let q = self.win_q[j];
            *a =
                self.win_sum[j] + self.pre[j][Self::slot_near(f0, s_f0, q).min(FRAMES - 1)] as u128;
        }
        self.win_f0 = Some(f0);
        self.last = Some(Published {
            t,
            start: f0 * SEG as u64,
            end: f1 * SEG as u64,
            acc,
        });
        t
    }

    /// Σ of `count` blocks of τ j from slot `s0` on, exactly. They wrap at
    /// most once: two contiguous runs. Low words with their carries
    /// counted, high parts apart: 32-bit-friendly sums, no u128 add per
    /// block.
    fn block_sum(&self, j: usize, s0: usize, count: u64) -> u128 {
        let (Some(lo_j), Some(hi_j)) = (self.lo.get(j), self.hi.get(j)) else {
            return 0;
        };
        let count = (count as usize).min(FRAMES);
        let s0 = s0.min(FRAMES - 1);
        let first_run = count.min(FRAMES - s0);
        let run = |r: core::ops::Range<usize>| {
            lo_j.get(r.clone())
                .unwrap_or(&[])
                .iter()
                .zip(hi_j.get(r).unwrap_or(&[]))
        };
        let (mut lo, mut hi) = (0u64, 0u32);
        // Two plain loops rather than a chained iterator (whose every step
        // asks which half it is in). Where the blocks carry nothing
        // ([`carry_free`]) their high parts are 0 and are not read.
        let free = carry_free(1 << j);
        for r in [s0..s0 + first_run, 0..count - first_run] {
            if free {
                for l in lo_j.get(r).unwrap_or(&[]) {
                    let (v, c) = lo.overflowing_add(*l);
                    lo = v;
                    hi += c as u32;
                }
            } else {
                for (l, h) in run(r) {
                    let (v, c) = lo.overflowing_add(*l);
                    lo = v;
                    hi += c as u32 + *h as u32;
                }
            }
        }
        ((hi as u128) << 64) | lo as u128
    }

    /// The last published row of the t–τ–σ surface; `None` until the span
    /// has filled. The u128 → float conversions happen here, on demand.
    pub fn estimate(&self) -> Option<DavarStep<T>> {
        let p = self.last.as_ref()?;
        let len = p.end - p.start;
        let mut avar = [0.0f32; T];
        for (j, v) in avar.iter_mut().enumerate() {
            *v = Self::avar_of(p, j);
        }
        Some(DavarStep {
            t: p.t,
            start: p.start,
            end: p.end,
            len: len as u16,
            score: self.score,
            threshold: self.threshold,
            avar,
        })
    }

    /// The last estimate's time `t` and window length: what
    /// [`Davar::estimate`] reports, without converting its sums (some 300
    /// instructions per τ on a Cortex-M4).
    pub fn estimate_window(&self) -> Option<(u64, u16)> {
        self.last.map(|p| (p.t, (p.end - p.start) as u16))
    }

    /// The last estimate's window [start, end), in sample indices.
    pub fn estimate_span(&self) -> Option<(u64, u64)> {
        self.last.map(|p| (p.start, p.end))
    }

    /// One τ (2ʲ samples) of [`Davar::estimate`]: `None` before the first
    /// estimate or for j ≥ T.
    pub fn estimate_avar(&self, j: usize) -> Option<f32> {
        // By reference: a copy of the published row (its u128 sums) cost
        // some 170 instructions a call on the Cortex-M4.
        let p = self.last.as_ref()?;
        (j < T).then(|| Self::avar_of(p, j))
    }

    /// σ² at τ = 2ʲ from a published window's exact sums (0 where the
    /// window has no term at that τ).
    fn avar_of(p: &Published<T>, j: usize) -> f32 {
        let len = p.end - p.start;
        let m = 1u64 << j;
        let terms = (len + 1).saturating_sub(2 * m);
        match p.acc.get(j) {
            // In f32 (the board's FPU): the exact integer sum and the term
            // count rounded once each, one division, then the exact power
            // of two 1/(2m²). Within 2 ulp of the f64 quotient (checked by
            // `avar_in_f32_is_within_two_ulp_of_f64`), and a tenth of the
            // soft-f64 cost on the Cortex-M4 (`cargo xtask bench`).
            Some(&acc) if terms > 0 => {
                let inv_2m2 = f32::from_bits((127 - 1 - 2 * j as u32) << 23);
                // (Both conversions equal `as f32`, without the library
                // calls: 300 instructions per link frame that carries an
                // estimate, on the Cortex-M4. A window has < 2³² terms.)
                u128_to_f32(acc) / (terms.min(u64::from(u32::MAX)) as u32) as f32 * inv_2m2
            }
            _ => 0.0,
        }
    }

    /// Start segmenting the span of frames `first..first + span`: snapshot
    /// the cells' energies and compute the first row.
    fn dp_start(&mut self, first: u64) {
        // (span < FRAMES and cells ≤ CELLS by construction; the `min`s let
        // the compiler see it.)
        let (g, k) = (self.dp.group, self.span.min(FRAMES - 1));
        // Prefix sums of the span's τ0 frame energies, kept for
        // `segment_window`; the cells' sums are read off them.
        let s0 = self.slot_of(first).min(FRAMES - 1);
        let run = k.min(FRAMES - s0);
        let mut acc = 0.0f32;
        self.px[0] = 0.0;
        // The span's frames wrap the ring at most once: two plain loops
        // (a chained iterator cost ~1 000 more instructions at λ2 = 4096).
        let (head, tail) = self.px[1..=k].split_at_mut(run.min(k));
        let xs = (
            self.x0.get(s0..s0 + run).unwrap_or(&[]),
            self.x0.get(..k - run).unwrap_or(&[]),
        );
        for (p, &x) in head.iter_mut().zip(xs.0) {
            acc += x;
            *p = acc;
        }
        for (p, &x) in tail.iter_mut().zip(xs.1) {
            acc += x;
            *p = acc;
        }
        for cell in 0..=self.dp.cells.min(CELLS) {
            self.dp.sum[cell] = self.px[(cell * g).min(k)];
        }
        self.dp.first = Some(first);
        self.dp.nu = self.nu();
        self.dp.beta = self.threshold_for(k);
        self.dp.cost[0] = -self.dp.beta;
        self.dp.row = 1;
        self.dp_row();
    }

    /// One row of the optimal partitioning (Jackson et al. 2005): the best
    /// cost of cells 0..j over the start i of its last segment, with the
    /// scaled-χ² (Gamma) segment cost ν·n·ln(mean) and a penalty β per
    /// segment. At most 32 cells per row, one `lnf` per cell.
    fn dp_row(&mut self) {
        let j = self.dp.row.min(CELLS);
        let (g, k) = (self.dp.group.max(1), self.span.min(FRAMES - 1));
        let frames = |c: usize| (c * g).min(k);
        let (nu, sj, nj) = (self.dp.nu, self.dp.sum[j], frames(j));
        let (mut best, mut arg) = (f32::INFINITY, 0u8);
        // Segment [i, j) has nf = nj − i·g frames (the last cell may be
        // short, so j's own frame count is nj): walk nf and ln nf down.
        let ln_nf = self.ln_n[..=nj].iter().rev().step_by(g);
        let mut nff = nj as f32;
        let gf = g as f32;
        for (i, ((&si, &ci), &ln_nf)) in self.dp.sum[..j]
            .iter()
            .zip(&self.dp.cost[..j])
            .zip(ln_nf)
            .enumerate()
        {
            // Frame energies of integer samples are 0 or ≥ 1: the floor
            // only guards an all-zero segment.
            let d = sj - si;
            let c = ci + nu * nff * (ln_floored(d) - ln_nf);
            nff -= gf;
            if c < best {
                best = c;
                arg = i as u8;
            }
        }
        self.dp.cost[j] = best + self.dp.beta;
        self.dp.arg[j] = arg;
        self.dp.row = j + 1;
    }

    /// Part `part` (of [`REFINE_PARTS`]) of the refinement: its share of
    /// the changes, in order. Out of line: inlined in `push`, it cost every
    /// sample 33 instructions.
    #[inline(never)]
    fn refine_part(&mut self, part: usize) {
        let (Some(prev), Some(_)) = (self.dp.first, self.dp.next_first) else {
            return;
        };
        while self.dp.row <= self.dp.cells {
            self.dp_row();
        }
        let (mut bounds, nb, next) = self.refining(prev);
        let to = (1 + nb.saturating_sub(1) * (part + 1) / REFINE_PARTS)
            .min(nb)
            .max(next);
        self.refine(&mut bounds, nb, next..to);
        self.dp.refined = Some((prev, bounds, nb, to));
    }

    /// The refinement of the span at `first` so far (bounds, their count
    /// less one, the next change to refine), or its start.
    fn refining(&self, first: u64) -> ([u16; CELLS + 1], usize, usize) {
        match self.dp.refined {
            Some((f, b, nb, next)) if f == first => (b, nb, next),
            _ => {
                let (b, nb) = self.backtrack();
                (b, nb, 1)
            }
        }
    }

    /// The finished segmentation's segment bounds in frames, backtracked
    /// (0 = b₀ < b₁ < … < b_nb = k), and nb.
    fn backtrack(&self) -> ([u16; CELLS + 1], usize) {
        let (g, k) = (self.dp.group.max(1), self.span.min(FRAMES - 1));
        let cells = self.dp.cells.min(CELLS);
        let mut bounds = [0u16; CELLS + 1];
        let mut nb = 0;
        let mut j = cells;
        while j > 0 && nb < CELLS {
            bounds[nb] = (j * g).min(k) as u16;
            nb += 1;
            j = self.dp.arg.get(j).map_or(0, |&a| a as usize).min(j - 1);
        }
        let nb = nb.min(CELLS);
        bounds[nb] = 0;
        bounds[..=nb].reverse();
        (bounds, nb)
    }

    /// Refine changes `which` (in order) of `bounds` (nb segments) to the
    /// frame: the cells group g frames, and each change moves to the best
    /// split of its two segments within ± (g − 1) frames (every frame for
    /// g < 4; else, near a change the last segmentation placed, that frame
    /// and the two beside it, and otherwise every other frame and then the
    /// two beside the best).
    #[inline(never)]
    fn refine(&self, bounds: &mut [u16; CELLS + 1], nb: usize, which: core::ops::Range<usize>) {
        let g = self.dp.group.max(1);
        if g <= 1 {
            return;
        }
        // Over the span's frame prefix sums (from `dp_start`).
        let (px, ln_n, nu) = (&self.px, &self.ln_n, self.dp.nu);
        let cost = |i: usize, j: usize| seg_cost(px, ln_n, nu, i, j);
        let bd = |b: &[u16; CELLS + 1], i: usize| b.get(i).copied().unwrap_or(0) as usize;
        // The changes the last segmentation placed: the span's blocks
        // that carry its stamp.
        let first = self.dp.first.unwrap_or(0);
        let last =
            (self.dp.recent_len > 0).then(|| self.dp.recent[(self.dp.recent_at + LAG - 1) % LAG]);
        let s0 = self.slot_of(first).min(FRAMES - 1);
        let marks = &self.marks;
        let placed_last =
            |q: usize| last.is_some_and(|l| marks.get(Self::ahead(s0, q)) == Some(&l));
        for i in which.start.max(1)..which.end.min(nb) {
            let (l, c, r) = (bd(bounds, i - 1), bd(bounds, i), bd(bounds, i + 1));
            let (lo, hi) = (c.saturating_sub(g - 1).max(l + 1), (c + g).min(r));
            let split = |q: usize| (cost(l, q) + cost(q, r), q);
            let keep = |best: (f32, usize), q: usize| {
                let v = split(q);
                if v.0 < best.0 {
                    v
                } else {
                    best
                }
            };
            // The best of `best` and the frames on either side of it.
            let beside = |best: (f32, usize)| {
                [best.1.wrapping_sub(1), best.1 + 1]
                    .into_iter()
                    .filter(|q| (lo..hi).contains(q))
                    .fold(best, keep)
            };
            let near = || (lo..hi).find(|&q| placed_last(q));
            let best = if g < 4 {
                (lo..hi).filter(|&q| q != c).fold(split(c), keep)
            } else if let Some(p) = near() {
                // The last segmentation refined a change within reach: a
                // step's split moves little from one hop to the next, so
                // look there and beside it (3 costs for 2g − 1).
                beside(split(p))
            } else {
                // Every other frame from c, then the two beside the best:
                // g + 1 costs for 2g − 1 (λ2 ≥ 2048 only; the split's cost
                // is smooth at that scale).
                beside(
                    (lo..hi)
                        .filter(|&q| q != c && q.abs_diff(c) % 2 == 0)
                        .fold(split(c), keep),
                )
            };
            if let Some(b) = bounds.get_mut(i) {
                *b = best.1 as u16;
            }
        }
    }

    /// The finished segmentation's segment that holds t, widened to λ1;
    /// returns the window [lo, hi) in frames of the span at `first`.
    fn segment_window(&mut self, first: u64) -> (usize, usize) {
        // The bounds refined from REFINE_AT (the rest, if any, now).
        let (mut bounds, nb, next) = self.refining(first);
        self.dp.refined = None;
        self.refine(&mut bounds, nb, next..nb);
        let k = self.span.min(FRAMES - 1);
        let ft = k / 2; // frame that starts at (or holds) t
                        // The span's frame prefix sums (from `dp_start`): every mean below
                        // is taken over frames. Indices come from the segmentation and are
                        // in range; `get` keeps that from being a panic path if it ever
                        // were not.
        let (px, ln_n) = (&self.px, &self.ln_n);
        let p = |i: usize| px.get(i).copied().unwrap_or(0.0);
        let nu = self.dp.nu;
        let cost = |i: usize, j: usize| seg_cost(px, ln_n, nu, i, j);
        let bd = |b: &[u16; CELLS + 1], i: usize| b.get(i).copied().unwrap_or(0) as usize;
        // Keep the changes that one of the last LAG segmentations had too,
        // or strong ones, and then stamp this hop's (its stamp over the
        // oldest's).
        let s0 = self.slot_of(first).min(FRAMES - 1);
        // The block c frames into the span (c ≤ k < FRAMES).
        let slot = |c: usize| Self::ahead(s0, c);
        // The recent stamps; where fewer than LAG segmentations ran since
        // the start, this one's own stamp, which no block carries yet.
        let stamp = first as u16;
        let n_recent = usize::from(self.dp.recent_len);
        let recent: [u16; LAG] = core::array::from_fn(|j| {
            if j < n_recent {
                self.dp.recent[j]
            } else {
                stamp
            }
        });
        let near = &self.marks_near;
        let strong = STRONG * self.dp.beta;
        // This hop's changes with their neighbours (l, c, r), as slices:
        // reading the bounds one by one through checked reads cost ~250
        // instructions with fifteen changes.
        let changes = bounds.get(..=nb).unwrap_or(&[]);
        let (mut kept, mut nk) = ([0u16; CELLS + 1], 1);
        for w in changes.windows(3) {
            let &[l, c, r] = w else { continue };
            let (l, c, r) = (usize::from(l), usize::from(c), usize::from(r));
            // Seen: a recent segmentation had a change within a frame of c
            // (the latest that had one did, then). Else its likelihood gain
            // against merging its two segments must be strong.
            let seen = near.get(slot(c)).is_some_and(|m| recent.contains(m));
            if seen || cost(l, r) - cost(l, c) - cost(c, r) > strong {
                if let Some(kc) = kept.get_mut(nk) {
                    *kc = c as u16;
                }
                nk += 1;
            }
        }
        for &c in changes.get(1..nb).unwrap_or(&[]) {
            let c = usize::from(c);
            if let Some(m) = self.marks.get_mut(slot(c)) {
                *m = stamp;
            }
            for q in [c - 1, c, c + 1] {
                if let Some(m) = self.marks_near.get_mut(slot(q)) {
                    *m = stamp;
                }
            }
        }
        let at = self.dp.recent_at % LAG;
        self.dp.recent[at] = stamp;
        self.dp.recent_len = (self.dp.recent_len + 1).min(LAG as u8);
        self.dp.recent_at = (at + 1) % LAG;
        let nb = nk.min(CELLS);
        kept[nb] = k as u16;
        let b = |i: usize| bd(&kept, i);
        let mean =
            |i: usize| (p(b(i + 1)) - p(b(i))) / (b(i + 1).saturating_sub(b(i))).max(1) as f32;
        let mut s = 0;
        while s + 1 < nb && b(s + 1) <= ft {
            s += 1;
        }
        // Score: what the segmentation gained over one segment (> 0 iff a
        // change was placed), against the penalty per change.
        self.score = (cost(0, k) - self.dp.cost[self.dp.cells.min(CELLS)]).max(0.0);
        self.threshold = self.dp.beta;
        // A monotone run of segments through t's (levels rising or falling
        // segment after segment) is a gradual change cut into stairs, not
        // steps: there a window symmetric about t is unbiased to first
        // order and a one-sided segment is not. Use the widest symmetric
        // window inside the run.
        let dir = |i: usize| (mean(i + 1) - mean(i)).signum();
        // A change next to t's segment is gradual (a ramp cut into a step,
        // or a false alarm), not a step, when its two segments together
        // span at least 2λ1 and
        // - one line through both explains their energies better than the
        //   step does ([`line_over_step`]), or as well less the penalty for
        //   the step's location where the change gains less than GRADUAL·β;
        //   or
        // - a blurred step fits them better than the sharp one: the two
        //   levels joined by a linear transition over 2h frames centred on
        //   the change, h ≥ λ1 (so a one-sided window of λ1 inside the
        //   transition would be biased by its slope).
        // Such a change does not bound the window: t gets a window
        // symmetric about it, which a linear change leaves unbiased. (Each
        // side tests one change, so the sample's cost stays bounded.)
        let (beta, min_frames, q) = (self.dp.beta, self.min_frames, self.dp.group.max(1));
        // (Asked only of a change next to t's segment.)
        let seg_slope = if nb > 1 {
            slope_z2(px, nu, (b(s), b(s + 1)))
        } else {
            None
        };
        let gradual = |i: usize| {
            let (l, c, r) = (b(i - 1), b(i), b(i + 1));
            // t's own segment rising (or falling) toward or away from the
            // change as the change goes: a ramp cut into stairs, whose
            // stairs are not flat.
            if let Some((z2, up)) = seg_slope {
                if z2 > SLOPE_Z2 && up == (mean(i) > mean(i - 1)) {
                    return true;
                }
            }
            // (At the board's λ1 = λ2/2 only a change alone in the span
            // passes.)
            if r - l < 2 * min_frames {
                return false;
            }
            let step = || cost(l, c) + cost(c, r);
            let line = || {
                let d = line_over_step(px, nu, (l, c, r));
                d > 0.0 || (d > -beta && cost(l, r) - step() < GRADUAL * beta)
            };
            let blurred = || {
                let mut h = min_frames.max(1);
                while c > l + h && c + h < r {
                    if transition_cost(px, ln_n, nu, (l, c, r), h, q).is_some_and(|v| v < step()) {
                        return true;
                    }
                    h *= 2;
                }
                false
            };
            line() || blurred()
        };
        let r0 = s - usize::from(s > 0 && gradual(s));
        let r1 = s + usize::from(s + 1 < nb && gradual(s + 1));
        let run = s > 0 && s + 1 < nb && dir(s - 1) == dir(s);
        if run || r0 < s || r1 > s {
            let (mut r0, mut r1) = (r0, r1);
            if run {
                let d = dir(s);
                (r0, r1) = (r0.min(s - 1), r1.max(s + 1));
                while r0 > 0 && dir(r0 - 1) == d {
                    r0 -= 1;
                }
                while r1 + 1 < nb && dir(r1) == d {
                    r1 += 1;
                }
            }
            let odd = k % 2;
            let (run_lo, run_hi) = (b(r0), b(r1 + 1));
            let mut h = ft
                .saturating_sub(run_lo)
                .min(run_hi.saturating_sub(ft + odd));
            if 2 * h + odd < self.min_frames {
                h = self.min_frames.saturating_sub(odd).div_ceil(2).min(ft);
            }
            return (ft - h, (ft + odd + h).min(k));
        }
        let (mut lo, mut hi) = (b(s), b(s + 1).max(b(s) + 1));
        // Widen to λ1, one frame at a time, toward the neighbour whose
        // energy is closer (in ratio) to the segment's mean. Each side's
        // gap is computed once per frame it reaches, the frames' energies
        // walked outward over the prefix sums as slices: recomputing both
        // sides' gaps on every step, through checked reads, made an axis's
        // placement ~1 000 instructions dearer when t's segment was a few
        // frames long (`cargo xtask bench-loop`, scenario F, after two
        // chips power-cycled).
        let seg_mean = mean(s);
        let gap = |w: &[f32]| match *w {
            [a, b] => ratio_gap(b - a, seg_mean),
            _ => f32::INFINITY,
        };
        // Frames lo − 1, lo − 2, …, 0 and hi, hi + 1, …, k − 1.
        let mut lefts = px.get(..=lo).unwrap_or(&[]).windows(2).rev().map(gap);
        let mut rights = px.get(hi..=k).unwrap_or(&[]).windows(2).map(gap);
        let (mut left, mut right) = (lefts.next(), rights.next());
        while hi - lo < self.min_frames.min(k) {
            let to_left = match (left, right) {
                (Some(l), Some(r)) => l <= r,
                (l, _) => l.is_some(),
            };
            if to_left {
                lo -= 1;
                left = lefts.next();
            } else {
                hi += 1;
                right = rights.next();
            }
        }
        (lo, hi)
    }

    /// Centred placement: eq. 4 (when adaptive), then the window of the
    /// current length around t, in frames of the span.
    fn centred(&mut self, first: u64, adaptive: bool) -> (usize, usize) {
        let (k, min_frames) = (self.span, self.min_frames);
        let frames_of = move |len: u16| -> usize {
            // Whole frames of the span's parity, so the window is centred.
            let mut f = (len as usize / SEG).max(min_frames).min(k);
            if (k - f) % 2 == 1 {
                f = if f < k { f + 1 } else { f - 1 };
            }
            f
        };
        if adaptive {
            let f = frames_of(self.len);
            let lo = first + ((k - f) / 2) as u64;
            self.adapt(lo, lo + f as u64);
        }
        let f = frames_of(self.len);
        ((k - f) / 2, (k + f) / 2)
    }

    /// FFT of the frame that just completed; keep the power of bins 1..=15.
    fn store_frame(&mut self) {
        let mut x = [0.0f32; SEG];
        let first = self.n - SEG as u64;
        for (i, v) in x.iter_mut().enumerate() {
            *v = self.w(first + i as u64) as f32;
        }
        let spec = microfft::real::rfft_32(&mut x);
        let slot = Self::slot(first / SEG as u64);
        let (Some(frame), Some(energy), Some(eloge)) = (
            self.frames.get_mut(slot),
            self.energy.get_mut(slot),
            self.eloge.get_mut(slot),
        ) else {
            return; // STFT < FRAMES is refused for windows that need it
        };
        let mut e = 0.0f32;
        for (p, c) in frame.iter_mut().zip(spec[1..].iter()) {
            *p = c.re * c.re + c.im * c.im;
            e += *p;
        }
        *energy = e;
        *eloge = if e > 0.0 { e * lnf(e) } else { 0.0 };
    }

    /// Entropy of frames [f_lo, f_hi) and the eq. 4 update of the length.
    fn adapt(&mut self, f_lo: u64, f_hi: u64) {
        let k = (f_hi - f_lo) as usize;
        if k < 2 {
            return;
        }
        let s0 = self.slot_of(f_lo);
        let slots = (0..k).map(move |i| {
            if s0 + i >= FRAMES {
                s0 + i - FRAMES
            } else {
                s0 + i
            }
        });
        let score = match self.cfg.entropy {
            EntropyKind::Temporal => {
                let (mut tot, mut sum_eloge) = (0.0f32, 0.0f32);
                for s in slots {
                    tot += self.energy.get(s).copied().unwrap_or(0.0);
                    sum_eloge += self.eloge.get(s).copied().unwrap_or(0.0);
                }
                if !(tot > 0.0) {
                    return;
                }
                // D = ln K − H, H = ln Σe − Σ(e ln e)/Σe.
                lnf(k as f32) - (lnf(tot) - sum_eloge / tot)
            }
            EntropyKind::Spectral => {
                let mut bins = [0.0f32; BINS];
                for f in slots.filter_map(|s| self.frames.get(s)) {
                    for (b, p) in bins.iter_mut().zip(f.iter()) {
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
        let th = self.thresholds[k.min(FRAMES - 1)];
        self.score = score;
        self.threshold = th;
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
        let tentative = (self.len as f32 - step) as i32 & !1;
        // (max then min: `clamp` asserts λ1 ≤ λ2, which `new` checked.)
        self.len = tentative
            .max(self.cfg.lambda1 as i32)
            .min(self.cfg.lambda2 as i32) as u16;
    }
}

/// The segmentation's cost of frames i..j of its span: ν·n·(ln Σx − ln n)
/// over the frame prefix sums `px` (indices from the segmentation are in
/// range; `get` keeps that from being a panic path if it ever were not).
#[inline(always)]
fn seg_cost(px: &[f32], ln_n: &[f32], nu: f32, i: usize, j: usize) -> f32 {
    let p = |i: usize| px.get(i).copied().unwrap_or(0.0);
    let nf = j.saturating_sub(i);
    let sum = p(j) - p(i);
    let ln_nf = ln_n.get(nf).copied().unwrap_or(0.0);
    nu * nf as f32 * (ln_floored(sum) - ln_nf)
}

/// How much better one line explains the frame energies of l..r than the
/// step at c does, in cost units: (SS_line − SS_step)·ν/(2m²), the sums of
/// squares the least-squares line and the two segment means explain,
/// scaled by the variance 2m²/ν of a frame energy at the pooled mean m.
/// That is the second-order form of the difference of their Gamma
/// deviances, from the prefix sums alone: r − l additions and no
/// logarithm, so the board's placement sample can afford it. −∞ where it
/// does not apply.
fn line_over_step(px: &[f32], nu: f32, (l, c, r): (usize, usize, usize)) -> f32 {
    let p = |i: usize| px.get(i).copied().unwrap_or(0.0);
    if c <= l || r <= c || r < l + 3 {
        return f32::NEG_INFINITY;
    }
    let (n, n1, n2) = ((r - l) as f32, (c - l) as f32, (r - c) as f32);
    let (m, sfc, sxx) = line_sums(px, l, r);
    if !(m > 0.5) {
        return f32::NEG_INFINITY;
    }
    let d = (p(c) - p(l)) / n1 - (p(r) - p(c)) / n2;
    (sfc * sfc / sxx - n1 * n2 / n * d * d) * nu / (2.0 * m * m)
}

/// The slope of the frames' energies over l..r, squared, over its own
/// variance under the scaled-χ²_ν model at their mean (a z²), and whether
/// it rises. None where fewer than 4 frames or a mean not positive.
fn slope_z2(px: &[f32], nu: f32, (l, r): (usize, usize)) -> Option<(f32, bool)> {
    if r < l + 4 {
        return None;
    }
    let (m, sfc, sxx) = line_sums(px, l, r);
    if !(m > 0.0) {
        return None;
    }
    Some((sfc * sfc / sxx * nu / (2.0 * m * m), sfc > 0.0))
}

/// Over the frames l..r (r > l) of the prefix sums `px`: their mean
/// energy, Σ (f − f̄)·x_f and Σ (f − f̄)², the sums of a least-squares line.
fn line_sums(px: &[f32], l: usize, r: usize) -> (f32, f32, f32) {
    let p = |i: usize| px.get(i).copied().unwrap_or(0.0);
    let n = (r - l) as f32;
    let s = p(r) - p(l);
    // Σ (f − l)·x_f = n·P(r) − Σ_{j = l+1..=r} P(j) (P the prefix sums;
    // P(l) cancels), then about the centre l + (n − 1)/2.
    // (Four running sums: fewer instructions than one at λ2 = 4096.)
    let w = px.get(l + 1..=r).unwrap_or(&[]);
    let mut quads = w.chunks_exact(4);
    let mut acc = [0.0f32; 4];
    for q in &mut quads {
        for (a, &v) in acc.iter_mut().zip(q) {
            *a += v;
        }
    }
    let sp = (acc[0] + acc[1]) + (acc[2] + acc[3]) + quads.remainder().iter().sum::<f32>();
    let sfc = n * p(r) - sp - 0.5 * (n - 1.0) * s;
    (s / n, sfc, n * (n * n - 1.0) / 12.0)
}

/// Cost of a blurred step over the span's frames l..r (same scale as
/// [`seg_cost`]): the means of [l, c − h) and [c + h, r), joined by a
/// linear transition over [c − h, c + h) taken in chunks of q frames. None
/// where it does not fit in l..r or its mean is not positive.
fn transition_cost(
    px: &[f32],
    ln_n: &[f32],
    nu: f32,
    (l, c, r): (usize, usize, usize),
    h: usize,
    q: usize,
) -> Option<f32> {
    let p = |i: usize| px.get(i).copied().unwrap_or(0.0);
    let (a, e) = (c.checked_sub(h)?, c + h);
    if a <= l || e >= r || q == 0 {
        return None;
    }
    let m1 = (p(a) - p(l)) / (a - l) as f32;
    let m2 = (p(r) - p(e)) / (r - e) as f32;
    let mut cost = seg_cost(px, ln_n, nu, l, a) + seg_cost(px, ln_n, nu, e, r);
    let (slope, mut f) = ((m2 - m1) / (2 * h) as f32, a);
    while f < e {
        let g = (f + q).min(e);
        let mu = m1 + slope * (0.5 * (f + g) as f32 - a as f32);
        if !(mu > 0.5) {
            return None;
        }
        cost += nu * ((g - f) as f32 * (ln_fast(mu) - 1.0) + (p(g) - p(f)) / mu);
        f = g;
    }
    Some(cost)
}

/// `ln_fast(max(x, 0.5))`, bit for bit, for x not NaN: the floor taken on
/// the bits as a signed integer (which order as the values do for x ≥ 0,
/// and put every negative x below 0.5). A float compare and select cost
/// the segmentation's inner loop 2 instructions more a cell.
#[inline(always)]
fn ln_floored(x: f32) -> f32 {
    const HALF: i32 = 0x3f00_0000; // 0.5f32.to_bits()
    ln_fast(f32::from_bits((x.to_bits() as i32).max(HALF) as u32))
}

/// ln x for normal x ≥ 0.5 to 8e-5 (absolute): the exponent, and a degree-4
/// polynomial in the mantissa − 1 (fitted by iterated weighted least
/// squares, max error measured in `ln_fast_accuracy`). About 12
/// instructions with no division: the segmentation's cells need one each,
/// and an error of 8e-5 × ν·n ≤ 0.06 in a cell's cost is far below the
/// penalty (≈ 13) that decides a change.
#[inline(always)]
fn ln_fast(x: f32) -> f32 {
    const C: [f32; 4] = [0.997_450_25, -0.471_311_77, 0.225_708_22, -0.058_771_09];
    let bits = x.to_bits();
    let e = (bits >> 23) as i32 - 127;
    // The mantissa as a float in [1, 2): the bits with the exponent e taken
    // out, (bits & 0x7f_ffff) | 0x3f80_0000 written as one subtraction of
    // the e already at hand (the mask took the Cortex-M4 4 instructions).
    let u = f32::from_bits(bits.wrapping_sub((e as u32) << 23)) - 1.0;
    let p = u * (C[0] + u * (C[1] + u * (C[2] + u * C[3])));
    e as f32 * core::f32::consts::LN_2 + p
}

/// u64 → f32 as two 32-bit conversions (a u64 conversion is a library
/// call on the Cortex-M4). Rounds twice, so it can differ from `as f32` in
/// the last bit; the same on every target.
#[inline(always)]
fn u64_to_f32(x: u64) -> f32 {
    (x >> 32) as u32 as f32 * 4_294_967_296.0 + x as u32 as f32
}

/// i64 → f32 as a signed high half and a signed low half (an i64
/// conversion is a library call on the Cortex-M4): exact rounding for
/// |v| < 2³¹, where the high half is 0, and two roundings above. (The lag
/// sums were once split as a signed high and an *unsigned* low half: a
/// small negative sum then became −2³² + (2³² − |v|) with the low half
/// rounded to a multiple of 256 first, so every |v| < 128 read as 0 and a
/// white signal of a few LSB looked uncorrelated, ν 32 for 21.6.)
#[inline(always)]
fn i64_to_f32(v: i64) -> f32 {
    let hi = v.wrapping_add(1 << 31) >> 32;
    let lo = v.wrapping_sub(hi << 32) as i32;
    hi as i32 as f32 * 4_294_967_296.0 + lo as f32
}

/// u128 → f32, correctly rounded: equal to `as f32`, which is a library
/// call on the Cortex-M4 (≈ 65 instructions), with one 32-bit hardware
/// conversion instead. The top 32 significant bits, with a sticky bit for
/// any below them, round to 24 as the whole number does (the rounding
/// bit is bit 7); scaling by 2ˢ is exact. Checked against `as f32` by
/// `u128_to_f32_is_as_f32`.
#[inline(always)]
pub(crate) fn u128_to_f32(x: u128) -> f32 {
    let (hi, lo) = ((x >> 64) as u64, x as u64);
    if hi == 0 {
        if lo >> 32 == 0 {
            return lo as u32 as f32;
        }
        let s = 32 - lo.leading_zeros();
        let top = (lo >> s) as u32 | u32::from(lo << (64 - s) != 0);
        return top as f32 * f32::from_bits((127 + s) << 23);
    }
    let s = 96 - x.leading_zeros();
    let top = (x >> s) as u32 | u32::from(x << (128 - s) != 0);
    top as f32 * f32::from_bits((127 + s) << 23)
}

/// Whether a whole block of τ = m terms sums in a u64 without a carry:
/// |d| ≤ 2m·[`SAMPLE_MAX`], so 32 terms stay below 32·(2m·S)². True up to
/// m = 256 (τ up to 2⁸ samples: the board's tracker and the default
/// configurations); beyond, the carry byte is kept term by term.
#[inline(always)]
const fn carry_free(m: usize) -> bool {
    let bound = 2 * m as u128 * SAMPLE_MAX as u128;
    SEG as u128 * bound * bound <= u64::MAX as u128
}

/// lo + hi·2⁶⁴ += d², exactly (a 32-term block of d² < 2⁶² needs 3 carry
/// bits at most).
#[inline(always)]
fn add_sq(lo: u64, hi: u8, d: i32) -> (u64, u8) {
    let (v, c) = lo.overflowing_add((d as i64 * d as i64) as u64);
    (v, hi + c as u8)
}

/// The mark of a block that no segmentation has put a change at since it
/// completed: a stamp half the u16 range from its own frame number. A
/// segmentation's stamp is its first frame, within FRAMES of any block it
/// reads (< 2¹⁵ by construction), so no recent stamp can equal it until
/// the block's slot is reused and made stale again.
const fn stale(block: u64) -> u16 {
    (block as u16).wrapping_add(0x8000)
}

/// |ln(a/b)| without a logarithm: max(a, b)/min(a, b) orders the same way.
fn ratio_gap(a: f32, b: f32) -> f32 {
    let (a, b) = (
        at_least(a, f32::MIN_POSITIVE),
        at_least(b, f32::MIN_POSITIVE),
    );
    if a > b {
        a / b
    } else {
        b / a
    }
}

#[cfg(test)]
mod tests;
