//! The E-DAVAR's settings: the placement, the entropy and step rules of
//! eq. 1–4 and the change threshold, each reading of the paper a knob.

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
    /// Octaves between consecutive τ: τ_j = 2^(j·tau_octaves) samples, j
    /// below the estimator's `T`. 1 gives every octave; the board, whose
    /// link reads σ at 1, 16 and 256 samples alone, sums those three (4)
    /// and no τ that nothing reads.
    pub tau_octaves: u8,
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
            tau_octaves: 1,
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
            tau_octaves: 1,
        }
    }

    /// The same settings with τ_j = 2^(j·`octaves`) samples.
    pub const fn with_tau_octaves(mut self, octaves: u8) -> Self {
        self.tau_octaves = octaves;
        self
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
    /// λ1 below the largest τ's term span (2·τ_{T−1}), CAP below that
    /// span + 33, a τ over 2¹⁰ samples, T = 0, τ octaves 0, or CAP not a
    /// power of two.
    Capacity,
    /// ΔL = 0 (or odd) on an adaptive centred window.
    DeltaL,
    /// Threshold not finite, or p_fa outside (0, 1).
    Threshold,
}
