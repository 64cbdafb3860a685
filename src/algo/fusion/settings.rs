//! The fusion methods and their settings: every ambiguity of the seed
//! (Zhou, Yao and Shen, 2019) is a knob here.

/// Denominator of the normalised distance, eq. 4 (SEEDS ambiguity 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Denominator {
    /// `m² − 1`, as printed.
    MSquaredMinus1,
    /// `m(m − 1)`, the number of ordered pairs: d* is then distance over
    /// mean pairwise distance.
    OrderedPairs,
}

/// Standard deviation used by the Grubbs statistic, eq. 11.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StdKind {
    /// 1/N, as printed in eq. 11.
    Population,
    /// 1/(N − 1), textbook Grubbs.
    Sample,
}

/// Grubbs settings (eq. 10–12).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GrubbsConfig {
    /// Significance level α (0.05 by default).
    pub alpha: f32,
    /// Two-sided critical value (α/2N) rather than one-sided (α/N).
    pub two_sided: bool,
    /// Include the diagonal `s_ii = 1` in each row, so N = m (our reading of
    /// the undefined N; the alternative is N = m − 1).
    pub include_diagonal: bool,
    /// Which standard deviation eq. 11 uses.
    pub std: StdKind,
}

impl Default for GrubbsConfig {
    fn default() -> Self {
        Self {
            alpha: 0.05,
            two_sided: true,
            include_diagonal: true,
            std: StdKind::Population,
        }
    }
}

/// Limited-memory weighting (eq. 13–16) settings.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MemoryConfig {
    /// Memory length M (8 by default): epochs u = k−M+1 ..= k.
    pub len: usize,
    /// Lag of the current epoch: `t = k − u + lag0`. 1 is our reading (the
    /// printed `t = k − u` divides by zero at the current epoch, so with 0 the
    /// current epoch is skipped).
    pub lag0: u8,
    /// Guard ε added to `(r − r̄)²` in eq. 14 (not in the paper).
    pub eps: f32,
}

impl Default for MemoryConfig {
    fn default() -> Self {
        Self {
            len: 8,
            lag0: 1,
            eps: 1e-3,
        }
    }
}

/// The scale d_ij is divided by in the support function (eq. 4–5).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Normaliser {
    /// Eq. 4: this sample's mean pairwise distance. Scale-free: the
    /// supports, and so the weights, stay just as random however well the
    /// chips agree (measured in `fusion-eval`).
    Instant,
    /// Ours: `k` times a running (EWMA factor `alpha`) estimate of the
    /// array's spread, the median absolute deviation from the median (one
    /// faulty gyro cannot inflate it). Healthy chips then sit near d* = 0
    /// and get near-equal weights, while a gyro `1.72·k` spreads away
    /// (d* = e − 1) gets no support at all.
    Running {
        /// Multiple of the running spread.
        k: f32,
        /// EWMA factor of the spread.
        alpha: f32,
    },
}

/// Seed 004's support-degree method (Zhou, Yao and Shen, 2019) and its
/// readings of the paper.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SupportConfig {
    /// Eq. 4 denominator.
    pub denominator: Denominator,
    /// Clamp total supports `r_i` at 0. Eq. 5 gives negative supports for
    /// `d* > e − 1`, which makes a far outlier pull the fused value *away*
    /// from itself with a negative weight. `false` is the literal paper.
    pub clamp_negative: bool,
    /// Grubbs rejection (eq. 10–12), if enabled.
    pub grubbs: Option<GrubbsConfig>,
    /// Memory weighting (eq. 13–16), if enabled.
    pub memory: Option<MemoryConfig>,
    /// Scale of the normalised distance.
    pub normaliser: Normaliser,
}

impl SupportConfig {
    /// Eq. 3–9 only, literal.
    pub const SUPPORT: Self = Self {
        denominator: Denominator::MSquaredMinus1,
        clamp_negative: false,
        grubbs: None,
        memory: None,
        normaliser: Normaliser::Instant,
    };
}

/// Our adaptive method's settings.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AdaptiveConfig {
    /// EWMA factor of the quick means once warmed up: the squared
    /// residual of two gyros (the pairs of three or more learn at
    /// `adaptive::NOISE_ALPHA`, 1/4096) and the drift watch's fast mean
    /// (1/256: a time constant of 0.26 s at 1 kHz. As the residuals'
    /// factor, 1/64 made the weights' own estimation noise cost 1.0 % RMS
    /// against the oracle on four equal chips).
    pub alpha: f32,
    /// Samples averaged plainly before the EWMA takes over (≥ 1).
    pub warmup: u16,
    /// Gate: a gyro further than `gate_k` residual sigmas from the median is
    /// rejected for this sample.
    pub gate_k: f32,
    /// Floor of each noise variance, (°/s)² (quantisation: LSB²/12).
    pub var_floor: f32,
    /// Consecutive bit-identical outputs after which a gyro counts as frozen.
    pub frozen_after: u8,
}

impl Default for AdaptiveConfig {
    fn default() -> Self {
        Self {
            alpha: 1.0 / 256.0,
            warmup: 32,
            gate_k: 5.0,
            var_floor: 1e-6,
            frozen_after: 4,
        }
    }
}

/// Fusion method.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Method {
    /// Arithmetic mean of the valid inputs.
    Mean,
    /// Support `exp(−(yi − yj)²)` with y in °/s.
    Zhang,
    /// Support degree with Grubbs rejection and memory weighting (seed
    /// 004, eq. 3–16 as configured).
    SupportDegree(SupportConfig),
    /// Inverse-variance weighting with online noise estimates.
    Adaptive(AdaptiveConfig),
}

/// Errors found when a configuration is built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigError {
    /// N must be 1..=8.
    ArraySize,
    /// α must lie in (0, 1).
    Alpha,
    /// Memory length must be 1..=16.
    MemoryLen,
    /// A factor or threshold is out of range (non-finite, ≤ 0, α ≥ 1).
    Parameter,
}
