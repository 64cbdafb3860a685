//! Dynamic Allan variance (DAVAR: Galleani and Tavella, 2003; Galleani,
//! 2009) and its adaptive window (E-DAVAR: Tan, Wang and Zhu, "Entropy of
//! information based dynamic Allan variance algorithm with adaptive
//! window length", Electronics Optics & Control 24(9), 2017), streaming in
//! fixed memory with a bounded cost for every single sample.
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
//! around a change or first fills.
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
//!   λ2 = 1024 a worst sample of about 2 000 instructions).
//!
//! # Reading of the paper (Tan, Wang and Zhu, 2017)
//! - Ambiguity 8 (where t sits in its window): the estimate for t uses a
//!   window around t (Fig. 2 reacts ~300 s early, which only a centred
//!   window does). Streaming, this means a latency of about λ2/2.
//! - λ1, λ2 are rounded to whole frames: λ2 down (the memory bound), λ1 up
//!   (the shortest window), but never above λ2's rounding.
//! - Eq. 4's step: [`StepMode`]. Thresholds: [`Threshold`].
//!
//! # Types, a file each
//! This one holds the estimator ([`Davar`]): its per-sample schedule
//! ([`Davar::push`]), the thresholds, and what it publishes. Each part it
//! holds owns its state: `sums::Sums` the samples and the exact streaming
//! sums; `dof::FrameDof` a frame's ν, learnt from the data;
//! `segmented::Segmentation` the segmented placement (the span's optimal
//! partitioning, its changes refined, the window chosen), with the tests
//! that tell a step from a gradual change in `shape`; `centred::Centred`
//! the paper's centred placement; `publish::Published` a published
//! window's sums and σ². The knobs are in `settings`.

mod centred;
mod dof;
mod publish;
mod segmented;
mod settings;
mod shape;
mod sums;

pub use settings::*;

use centred::Centred;
use dof::FrameDof;
use publish::Published;
use segmented::Segmentation;
use sums::Sums;

use crate::algo::allan::stream::SAMPLE_MAX;
use crate::algo::allan::AllanError;
use crate::algo::stats::chi2_quantile;

/// Frame (block, STFT hop) length, samples.
pub const SEG: usize = 32;

/// Frequency bins used per STFT frame (1..=15).
pub const BINS: usize = SEG / 2 - 1;

/// A change bounds a window only if one of the LAG segmentations before put
/// one at the same place (± one frame), or it is strong: a step stays where
/// it is, while a one-off false alarm does not come back. (Ramps, whose
/// changes move with the span, are told apart by a line, in
/// `Segmentation::window`.)
const LAG: usize = 2;

/// A change whose likelihood gain exceeds STRONG × β bounds a window
/// without waiting for confirmation.
const STRONG: f32 = 3.0;

/// A change gaining less than GRADUAL·β may be read as gradual
/// (`Segmentation::window`).
const GRADUAL: f32 = 2.0;

/// A change alone in the span is gradual where two lines joined at their
/// best knot explain the frames' energies as well as the step, less this
/// × β. Both choose a location from the data; the joined lines then come
/// within β/2 of the step in nearly every ramp span, and of a ×2 step's in
/// 0.61 (test `on_a_ramp_the_best_step_ties_with_a_line_and_not_with_joined_lines`).
/// At β/4 the board-λ ramp loses to the fixed window (`davar-eval
/// --first-seed 9001`: 1.024), so the weak steps pay instead.
const HINGE_SLACK: f32 = 0.5;

/// …and gains less than this × β: the second-order form holds near equal
/// levels and understates a large step's edge (`davar-eval
/// --other-lambdas`: ×3 at 256/1024 0.746 here, 0.788 at 8β; at 4β the
/// board-λ ramp at seed 9001 loses, 1.034).
const HINGE_MAX_GAIN: f32 = 6.0;

/// t's segment is a stair of a ramp, not the level of a step, where its
/// energies' slope has z² above this (and runs with the change).
const SLOPE_Z2: f32 = 9.0;

/// A lone change farther from t than the hinge test looks, which joined
/// lines fit as well as the step, is a ramp's bend where t's segment's
/// slope runs its way with z² above this (`Segmentation::window`). Weak
/// evidence on purpose: the window it gives is symmetric about t and
/// stops at the change, so a step misread costs a shorter window, never
/// the step inside it. On a flat level a z² above 1 the change's way
/// comes one time in six; on a ×2 ramp over λ2 at 128/2048 a segment of
/// two thirds of λ2 read 2.5–4 (`davar-eval --sweep`).
const FAR_Z2: f32 = 1.0;

/// Most cells of the segmentation (frames are grouped beyond this, so a
/// hop's work does not grow with λ2).
const CELLS: usize = 32;

/// The hop's samples that run the segmentation's rows: one row on each,
/// two where a span has more cells than this. A span is cut into this
/// many cells, or into cells of one frame per 6 of λ1 where that makes
/// more (up to [`CELLS`]): a change every λ1 or less must still fall
/// between cells (at λ 256/1024, cells of two frames missed changes every
/// 200 samples in whole spans, 1.08× the best fixed window, and cells of
/// one frame find them, 0.96×), and at the board's λ1 = λ2/2 sixteen
/// cells already are λ1/8.
const ROW_SAMPLES: usize = 16;

/// Frames per cell of a span of `span` frames whose shortest window is
/// `min_frames`: see [`ROW_SAMPLES`].
fn cell_group(span: usize, min_frames: usize) -> usize {
    let coarse = span.div_ceil(ROW_SAMPLES).max(1);
    (min_frames / 6).clamp(1, coarse).max(span.div_ceil(CELLS))
}

/// The mark of a block that no segmentation has put a change at since it
/// completed: a stamp half the u16 range from its own frame number. A
/// segmentation's stamp is its first frame, within FRAMES of any block it
/// reads (< 2¹⁵ by construction), so no recent stamp can equal it until
/// the block's slot is reused and made stale again.
const fn stale(block: u64) -> u16 {
    (block as u16).wrapping_add(0x8000)
}

/// Segmented placement: samples after the hop at which the last span's
/// window is placed, then published, then the next span's segmentation
/// starts, one on each sample. Past the τ terms (samples 1..T of the hop)
/// and the last segmentation's rows (which run on the samples after its
/// start: ROW_SAMPLES of them, from START_AT + 1 around to the next hop's
/// sample 5, or 7 where they make way for the τ terms). The changes are
/// refined to the frame on the `REFINE_PARTS` samples before (from
/// `REFINE_AT`, a share on each): with many changes found (a chip gated in
/// and out of a fused axis) refining costs some 1 100 instructions, more
/// than one sample of the board's loop can take beside the placement.
const PLACE_AT: usize = 17;

/// The sample of the hop that learns the noise's tails (~630
/// instructions), once the span has filled: after the τ terms (T ≤ 11)
/// and before the refinement, where no segmentation row runs; in one
/// piece, as a split costs more than it spreads.
const TAILS_AT: usize = 12;

const REFINE_PARTS: usize = 4;

const REFINE_AT: usize = PLACE_AT - REFINE_PARTS;

const PUBLISH_AT: usize = PLACE_AT + 1;

/// Samples the publication's window sums are spread over.
const PUB_PARTS: usize = 3;

const START_AT: usize = PUBLISH_AT + PUB_PARTS;

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
    /// Allan variance at τ_j = 2^(j·`tau_octaves`)·τ0 in (sample unit)²;
    /// multiply by lsb².
    pub avar: [f32; T],
    /// Octaves between consecutive τ ([`DavarConfig::tau_octaves`]).
    pub tau_octaves: u8,
}

impl<const T: usize> DavarStep<T> {
    /// The Allan variance at τ = 2^`e` samples, if that is one of the row's
    /// τ.
    pub fn avar_at(&self, e: usize) -> Option<f32> {
        self.avar.get(tau_index(self.tau_octaves, e, T)?).copied()
    }
}

/// The index j of τ = 2^`e` samples among `count` τ spaced `octaves` apart
/// (τ_j = 2^(j·octaves)), if it is one of them.
fn tau_index(octaves: u8, e: usize, count: usize) -> Option<usize> {
    let oct = usize::from(octaves.max(1));
    (e.is_multiple_of(oct) && e / oct < count).then_some(e / oct)
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
    /// Sample of the 32-sample hop on which the hop's work is done (1..=31).
    hop_phase: u8,
    /// Frames in the span (λ2 rounded down) and the shortest window.
    span: usize,
    min_frames: usize,
    /// ν of a frame's τ0 energy, learnt from the data.
    dof: FrameDof,
    /// Threshold per frame count (Centred: K frames in the window;
    /// Segmented: a segment of K frames).
    thresholds: [f32; FRAMES],
    last: Option<Published<T>>,
    /// Times `last` has changed (published or cleared), wrapping: what a
    /// reader keeping something made of it compares.
    edition: u32,
    /// The centred placement's state.
    centred: Centred<FRAMES, STFT>,
    /// The segmented placement's state.
    seg: Segmentation<FRAMES>,
    /// The samples and the exact sums of their Allan terms.
    sums: Sums<CAP, FRAMES, T>,
}

impl<const CAP: usize, const FRAMES: usize, const T: usize, const STFT: usize>
    Davar<CAP, FRAMES, T, STFT>
{
    /// Whether the segmentation's rows make way for the τ terms (samples
    /// 1..T of the hop): where the rows left after the hop (those past the
    /// `SEG − START_AT − 1` samples before it) still end before
    /// `TAILS_AT`. The last rows are the costliest (a row weighs every
    /// earlier cell), some 800 instructions on the Cortex-M4, as much as
    /// one τ's 32 new terms: with three τ (the board's) the hop's samples
    /// 1–2 cost 1 600 with both, where samples 6–11 had nothing to do.
    const ROWS_YIELD: bool = T + ROW_SAMPLES - (SEG - START_AT - 1) < TAILS_AT;

    /// The tabulated threshold for `k` frames (every k a window of this
    /// configuration can have is tabulated at construction).
    pub(super) fn threshold_for(&self, k: usize) -> f32 {
        self.thresholds.get(k).copied().unwrap_or(f32::INFINITY)
    }
    /// Threshold for `frames` frames (see [`Threshold`]).
    pub(super) fn quantile_for(&self, frames: usize) -> f32 {
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
        // oldest sample of a term 2·τ_max + 32 samples back; τ ≤ 2¹⁰ keeps
        // every sum exact (see the module's head).
        let top = (T.max(1) - 1) * cfg.tau_octaves as usize;
        if T == 0 || cfg.tau_octaves == 0 || top > 10 {
            return Err(DavarError::Capacity);
        }
        let term_span = 2usize << top;
        if term_span > min_frames * SEG || term_span + SEG + 1 > CAP {
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
            sums: Sums::new(cfg.tau_octaves),
            hop_phase: 1,
            span,
            min_frames,
            dof: FrameDof::new(),
            thresholds: [0.0; FRAMES],
            last: None,
            edition: 0,
            centred: Centred::new(span, min_frames, cfg.l_init),
            seg: Segmentation::new(span, min_frames, l1),
        };
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
        Ok(d)
    }

    /// Forget every sample (after a gap in the input), keeping the settings
    /// and the tabulated thresholds.
    pub fn reset(&mut self) {
        self.sums.reset();
        self.centred.reset(self.cfg.l_init);
        self.dof = FrameDof::new();
        self.last = None;
        self.edition = self.edition.wrapping_add(1);
        self.seg.reset();
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
    /// `FrameDof::learn_tails` measures (lags 0–2, σ⁴ from lag 3), and
    /// ν₄ = 2·32²σ⁴/Var x. Heavy tails (Student's t with 5 dof: Var q =
    /// 20σ⁴ and lag-1 Cov 8σ⁴ against 8 and 2, so ν₄ = 7.2) or rounding
    /// below half an LSB (σ = 0.3 LSB: ν₄ ≈ 6) make it far smaller, and a
    /// threshold set with the Gaussian ν then sees changes everywhere
    /// (9.7 % and 36 % of windows shortened on stationary input).
    ///
    /// With r = ν₄/(0.85·ν_G) (`TAIL_GATE`: ν₄ is the noisier, and on
    /// Gaussian frames r ≥ 1 and ν stays ν_G), ν = ν_G·r^1.5 below the
    /// gate. The power is for the tails themselves: Var q rests on the
    /// eighth moment's tail, and its running estimate falls short the more
    /// the heavier the tail, so the measured ν₄ reads high (t with 5 dof:
    /// 9.4 for the true 7.2; the power gives 7.9). With ν₄ as measured,
    /// 2.4 % of the windows on that noise are short and the estimate loses
    /// to λ2 (`davar-eval --first-seed 55555 --seeds 60 --only heavy`:
    /// 1.015); with the power 0.8 % and 1.005.
    pub fn nu(&self) -> f32 {
        self.dof.nu()
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
        self.sums.push(w);
        let n = self.sums.n;
        let centred_adaptive =
            self.cfg.placement == Placement::Centred && self.min_frames < self.span;
        // The work of a hop is spread over its 32 samples (rel 0 is the
        // hop): phase 0 the STFT of the finished frame (centred windows),
        // rel j the new Allan terms of τ_j (τ0 at the hop), every other
        // sample one row of the segmentation.
        let phase = (n % SEG as u64) as usize;
        let hop_phase = self.hop_phase as usize;
        // Samples since the hop.
        let rel = (phase + SEG - hop_phase) % SEG;
        if phase == 0 && centred_adaptive {
            self.centred.store_frame(&self.sums);
        }
        let terms = (1..T).contains(&rel);
        if terms {
            self.sums.add_terms(rel);
        }
        if rel == TAILS_AT {
            if let Some((from, to)) = self.sums.tail_terms.take() {
                self.dof.learn_tails(self.sums.ring(), from, to);
            }
        }
        if rel != 0 {
            let segmented = self.cfg.placement == Placement::Segmented;
            if segmented && (REFINE_AT..PLACE_AT).contains(&rel) {
                let s0 = self.seg.first.map_or(0, |f| self.sums.slot_of(f));
                self.seg.refine_part(rel - REFINE_AT, s0);
            } else if segmented && rel == PLACE_AT {
                // The last segmentation's window (its rows finished long
                // ago; `while` only guards the invariant).
                if let (Some(prev), Some(_)) = (self.seg.first, self.seg.next_first) {
                    while self.seg.row <= self.seg.cells {
                        self.seg.next_row();
                    }
                    let (lo, hi) = self.seg.window(prev, self.sums.slot_of(prev));
                    self.seg.placed = Some((prev, lo, hi));
                }
            } else if segmented && (PUBLISH_AT..START_AT).contains(&rel) {
                // The window sums, a third of the τ on each of three
                // samples; the estimate is out on the last.
                let part = rel - PUBLISH_AT;
                let taus = T * part / PUB_PARTS..T * (part + 1) / PUB_PARTS;
                if let Some((prev, lo, hi)) = self.seg.placed {
                    let (t, f0, f1) = self.placed_window(prev, lo, hi);
                    self.sums.window_sums(f0, f1, taus);
                    if part + 1 == PUB_PARTS {
                        self.seg.placed = None;
                        return Ok(Some(self.finish_publish(t, f0, f1)));
                    }
                }
            } else if segmented && rel == START_AT {
                if let Some(first) = self.seg.next_first.take() {
                    let beta = self.threshold_for(self.span.min(FRAMES - 1));
                    let s0 = self.sums.slot_of(first);
                    self.seg
                        .start(first, s0, &self.sums.x0, self.dof.nu(), beta);
                }
            } else if self.seg.row >= 1
                && self.seg.row <= self.seg.cells
                && !(terms && Self::ROWS_YIELD)
            {
                self.seg.next_row();
                if self.seg.cells > ROW_SAMPLES && self.seg.row <= self.seg.cells {
                    self.seg.next_row();
                }
            }
            return Ok(None);
        }
        // The hop, at least one sample after a frame boundary: the τ0
        // terms of the last frame end on its first sample.
        let seg = &mut self.seg;
        self.sums
            .add_tau0(|block, slot| seg.block_completed(block, slot));
        if n < (self.span * SEG + hop_phase) as u64 {
            // (The tails are learnt once the span has filled: during the
            // fill their samples would meet the first, from-scratch terms
            // of the long τ.)
            self.sums.tail_terms = None;
            return Ok(None);
        }
        let c = n / SEG as u64; // frames 0..c are complete
        self.dof.learn_lags(core::mem::take(&mut self.sums.lag));
        let first = c - self.span as u64;
        let done = match self.cfg.placement {
            // The window placed at the last hop is published now: by then
            // the terms of every τ up to its end have been added.
            Placement::Centred => {
                let done = self
                    .centred
                    .pending
                    .map(|(prev, lo, hi)| self.publish_placed(prev, lo, hi));
                let s0 = self.sums.slot_of(first);
                let (lo, hi) =
                    self.centred
                        .place(first, s0, centred_adaptive, &self.cfg, &self.thresholds);
                self.centred.pending = Some((first, lo, hi));
                done
            }
            Placement::Segmented => {
                // The hop only notes the new span: the last span's window
                // is placed and published PUBLISH_AT samples later and the
                // new segmentation starts on the sample after, so no
                // sample carries all three.
                self.seg.next_first = Some(first);
                None
            }
        };
        Ok(done)
    }

    /// Publish the window [lo, hi) (frames) of the span starting at frame
    /// `prev`: its estimate describes the span's centre.
    pub(super) fn publish_placed(&mut self, prev: u64, lo: usize, hi: usize) -> u64 {
        let (t, f0, f1) = self.placed_window(prev, lo, hi);
        self.publish(t, f0, f1)
    }
    /// The time and frames [f0, f1) of window [lo, hi) of the span at
    /// `prev`.
    pub(super) fn placed_window(&self, prev: u64, lo: usize, hi: usize) -> (u64, u64, u64) {
        let half = (SEG * self.span / 2) as u64;
        (SEG as u64 * prev + half, prev + lo as u64, prev + hi as u64)
    }
    /// Sum the exact window sums of frames [f0, f1), keep them, return t.
    pub(super) fn publish(&mut self, t: u64, f0: u64, f1: u64) -> u64 {
        self.sums.window_sums(f0, f1, 0..T);
        self.finish_publish(t, f0, f1)
    }
    /// Publish window [f0, f1) at time t from its whole-block sums (all τ
    /// done by `Sums::window_sums`) and the last blocks' prefixes.
    pub(super) fn finish_publish(&mut self, t: u64, f0: u64, f1: u64) -> u64 {
        let acc = self.sums.window_total(f0);
        self.last = Some(Published {
            t,
            start: f0 * SEG as u64,
            end: f1 * SEG as u64,
            acc,
        });
        self.edition = self.edition.wrapping_add(1);
        t
    }
    /// The last sample pushed, if any since the start or a reset.
    pub fn last_sample(&self) -> Option<i32> {
        let n = self.sums.n.checked_sub(1)?;
        self.sums.ring().get(n as usize & (CAP - 1)).copied()
    }

    /// The last published row of the t–τ–σ surface; `None` until the span
    /// has filled. The u128 → float conversions happen here, on demand.
    pub fn estimate(&self) -> Option<DavarStep<T>> {
        let p = self.last.as_ref()?;
        let len = p.end - p.start;
        let mut avar = [0.0f32; T];
        for (j, v) in avar.iter_mut().enumerate() {
            *v = p.avar(j, self.cfg.tau_octaves);
        }
        let (score, threshold) = match self.cfg.placement {
            Placement::Segmented => self.seg.score(),
            // (Before the entropy rule has scored a window, or where it
            // never does: no score, against the whole span's threshold.)
            Placement::Centred => self
                .centred
                .score
                .unwrap_or((0.0, self.threshold_for(self.span))),
        };
        Some(DavarStep {
            t: p.t,
            start: p.start,
            end: p.end,
            len: len as u16,
            score,
            threshold,
            avar,
            tau_octaves: self.cfg.tau_octaves,
        })
    }

    /// The index j of τ = 2^`e` samples among this estimator's τ
    /// (τ_j = 2^(j·octaves)), if it is one of them.
    pub fn tau_index(&self, e: usize) -> Option<usize> {
        tau_index(self.cfg.tau_octaves, e, T)
    }

    /// The last estimate's time `t` and window length: what
    /// [`Davar::estimate`] reports, without converting its sums (some 300
    /// instructions per τ on a Cortex-M4).
    pub fn estimate_window(&self) -> Option<(u64, u16)> {
        self.last.map(|p| (p.t, (p.end - p.start) as u16))
    }

    /// A count that moves whenever the last estimate changes (published or
    /// cleared by a reset): equal counts, the same estimate.
    pub fn estimate_edition(&self) -> u32 {
        self.edition
    }

    /// The last estimate's window [start, end), in sample indices.
    pub fn estimate_span(&self) -> Option<(u64, u64)> {
        self.last.map(|p| (p.start, p.end))
    }

    /// One τ (2ʲ samples) of [`Davar::estimate`]: `None` before the first
    /// estimate or for j ≥ T.
    pub fn estimate_avar(&self, j: usize) -> Option<f32> {
        // By reference: the published row is T u128 sums.
        let p = self.last.as_ref()?;
        (j < T).then(|| p.avar(j, self.cfg.tau_octaves))
    }
}

#[cfg(test)]
mod tests;
