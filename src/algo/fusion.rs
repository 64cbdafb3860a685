//! Per-sample fusion of N gyros into one virtual gyro (one axis at a time).
//!
//! Methods (SEEDS.md "Seed 004"):
//! - [`Method::Mean`]: the baseline.
//! - [`Method::Zhang`]: support `exp(−(yi−yj)²)` (Zhang 2012, eq. 2), eq. 9.
//! - [`Method::Seed`]: normalised distance and log support (eq. 3–9),
//!   optionally Grubbs rejection of abnormal supports (eq. 10–12) and
//!   limited-memory weighting (eq. 13–16). Every ambiguity is a knob.
//! - [`Method::Adaptive`] (ours, the default): per-gyro noise variance from
//!   leave-one-out residuals, inverse-variance weights, median gating and
//!   frozen-output rejection.
//!
//! Settings ([`Fusion`]) are immutable and shared by the three axes; the
//! per-axis running state is [`AxisState`]. Capacity is the const `N ≤ 8`;
//! gyro sets are bit masks (bit i = gyro i).

use crate::algo::math::{at_least, expf, lnf, sqrtf};
use crate::algo::stats::grubbs_critical;

/// Largest array supported (masks are `u8`).
pub const MAX_GYROS: usize = 8;
/// Longest memory window for eq. 13–16.
pub const MAX_MEMORY: usize = 16;

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

/// The seed's method and its readings.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SeedConfig {
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

impl SeedConfig {
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
    /// EWMA factor of the squared residuals once warmed up (1/256: a
    /// time constant of 0.26 s at 1 kHz. With 1/64 the weights' own
    /// estimation noise cost 1.0 % RMS against the oracle on four equal
    /// chips, and made `adaptive` 0.8–1.2 % worse than the mean with small
    /// spikes; with 1/256, 0.3 %, and no worse: `fusion-eval`).
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
    /// The seed's support method (eq. 3–16 as configured).
    Seed(SeedConfig),
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

/// Why no fused value came out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FuseError {
    /// No input was valid and finite.
    NoValidInput,
}

/// One fused sample of one axis.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Fused<const N: usize> {
    /// The fused rate, °/s.
    pub rate_dps: f32,
    /// Normalised weights (sum 1 over the used gyros, 0 elsewhere; all 0
    /// when the gyros split with no majority and the last output is held,
    /// `fallback` set).
    pub weights: [f32; N],
    /// Gyros that were offered but rejected this sample (non-finite input,
    /// Grubbs-isolated, gated, frozen).
    pub rejected: u8,
    /// Why the method fell back to the plain mean, if it did.
    pub fallback: bool,
}

/// The array's noise probe: Σ cᵢyᵢ over the gyros the fused value used,
/// with coefficients that sum to 0, so a rate common to every chip (the
/// platform's motion: sway, a 100 °/s turn) cancels, while the noise left
/// has the fused rate's variance. cᵢ = k(sᵢ − δ)wᵢ, with signs sᵢ = ±1
/// alternating over the used gyros in index order, δ = Σsᵢwᵢ (so Σcᵢ = 0,
/// the weights summing to 1), and k = 1/√Σ(sᵢ − δ)²wᵢ. For independent
/// noises of variance σᵢ² and inverse-variance weights
/// wᵢ = σᵢ⁻²/Σσⱼ⁻² (the adaptive fusion's),
/// Var Σcᵢnᵢ = k²Σ(sᵢ − δ)²wᵢ/Σσⱼ⁻² = 1/Σσⱼ⁻², the fused error's variance
/// exactly; at longer τ it holds as far as the chips share one noise
/// shape (c² differs from w² chip by chip: with five equal weights three
/// chips get 0.67× and two 1.5×, the least spread any Σcᵢ = 0 allows).
/// What all chips share (a common vibration error) is not seen.
///
/// `fused` must be what fusion made of `y`: its weights sum to 1 and its
/// rate is Σwᵢyᵢ, which the probe reuses. (In the adaptive method's
/// warm-up the rate is the voters' median instead; it too moves one for
/// one with a rate common to every chip, so the motion still cancels:
/// test `every_methods_probe_cancels_motion`.) `None` with fewer than two
/// used gyros (no combination is free of the motion) or a non-finite
/// input among them.
pub fn noise_probe<const N: usize>(y: &[f32; N], fused: &Fused<N>) -> Option<f32> {
    // One pass, no coefficients kept: with D = Σsᵢwᵢ = δ and
    // S = Σsᵢwᵢyᵢ, Σcᵢyᵢ = k(S − δ·Σwᵢyᵢ) = k(S − δ·rate), and
    // Σ(sᵢ − δ)²wᵢ = 1 − 2δD + δ² = 1 − δ², so k = 1/√(1 − δ²). (Summing
    // Σwᵢ and Σwᵢyᵢ here as well cost 30 instructions a 3-axis sample on
    // the Cortex-M4. A cached set of coefficients cost less on most
    // samples but ~100 an axis on each change of the used set, which in a
    // fault comes on all three axes at once: the board loop's worst
    // sample.)
    let (mut d, mut sy, mut s, mut n) = (0.0f32, 0.0f32, 1.0f32, 0u32);
    for (&yi, &w) in y.iter().zip(&fused.weights) {
        if w > 0.0 {
            let sw = s * w;
            d += sw;
            sy += sw * yi;
            s = -s;
            n += 1;
        }
    }
    let p = (sy - d * fused.rate_dps) / sqrtf(1.0 - d * d);
    (n >= 2 && p.is_finite()).then_some(p)
}

impl<const N: usize> Fused<N> {
    /// The gyros that went into the fused rate (weight above 0).
    #[inline]
    pub fn used(&self) -> u8 {
        let mut m = 0u8;
        for (i, w) in self.weights.iter().enumerate() {
            // (A compare on the bits, (1..=0x7f80_0000).contains(bits),
            // measured 29 instructions more per 3-axis sample in the
            // default fusion path: kept as a float compare.)
            m |= ((*w > 0.0) as u8) << i;
        }
        m
    }
}

/// Immutable fusion settings; one value drives all axes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fusion<const N: usize> {
    method: Method,
    /// T(n, α) for n = 0..=N (0 where undefined).
    grubbs_t: [f32; MAX_GYROS + 1],
    /// 1/t² of eq. 14 for each memory lag (0 where t = 0: skipped).
    inv_t2: [f32; MAX_MEMORY],
}

/// Running state of one axis.
#[derive(Clone, Copy, Debug)]
pub struct AxisState<const N: usize> {
    k: u32,
    // Memory weighting: ring of r_i(u) and of 1/((r_i(u) − r̄_i(u))² + ε).
    /// r_i(u) / ((r_i(u) − r̄_i(u))² + ε) per epoch u (eq. 14 without t²).
    ring: [[f32; N]; MAX_MEMORY],
    head: usize,
    rbar: [f32; N],
    /// Running spread for [`Normaliser::Running`].
    spread: f32,
    // Adaptive: noise variance estimates, last input, frozen counters.
    var: [f32; N],
    last: [f32; N],
    frozen: [u8; N],
    /// Noise updates counted up to `warmup` (then frozen: not needed).
    n_upd: [u16; N],
    /// Gyros whose noise estimate has had `warmup` updates (n_upd ≥ warmup),
    /// kept as a mask so the per-sample "all warm" test is one AND.
    warm: u8,
    /// Prior noise variances ((°/s)², 0 = none): how two gyros share the
    /// variance of their difference ([`AxisState::set_noise_priors`]).
    prior: [f32; N],
    /// The last output, held when the gyros split with no majority.
    last_out: f32,
    /// With exactly two gyros and priors: which two, and the learnt power
    /// of their difference, (°/s)².
    pair: u8,
    pair_power: f32,
}

impl<const N: usize> Default for AxisState<N> {
    fn default() -> Self {
        Self {
            k: 0,
            ring: [[0.0; N]; MAX_MEMORY],
            head: 0,
            rbar: [0.0; N],
            spread: 0.0,
            var: [0.0; N],
            last: [f32::NAN; N],
            frozen: [0; N],
            n_upd: [0; N],
            warm: 0,
            prior: [0.0; N],
            last_out: f32::NAN,
            pair: 0,
            pair_power: 0.0,
        }
    }
}

impl<const N: usize> AxisState<N> {
    /// Prior noise σ per gyro, °/s (from the datasheet or the start-up
    /// noise test; `None` or non-finite: no prior). With exactly two good
    /// gyros the residuals only tell the sum of their variances, not how
    /// it splits (both estimates get the same update, and the method falls
    /// back to the mean): the split then follows the priors.
    pub fn set_noise_priors(&mut self, sigma_dps: [Option<f32>; N]) {
        for (p, s) in self.prior.iter_mut().zip(sigma_dps) {
            *p = match s {
                Some(s) if s.is_finite() && s > 0.0 => s * s,
                _ => 0.0,
            };
        }
    }

    /// Forget the noise estimates of the gyros in `mask`: they learn again
    /// from the next sample, as at power-up (warm-up gate, plain average,
    /// then the EWMA). For residuals that were measured against readings
    /// that have since been corrected ([`crate::algo::calib::RelCal`]):
    /// a scale error of 1 % at 100 °/s reads as 1 °/s of noise, which an
    /// EWMA of 1/256 would take a thousand samples to forget.
    pub fn forget_noise(&mut self, mask: u8) {
        if mask == 0 {
            return;
        }
        for i in 0..N {
            if mask & (1 << i) != 0 {
                self.n_upd[i] = 0;
                self.var[i] = 0.0;
            }
        }
        self.warm &= !mask;
    }

    /// The adaptive method's raw noise variance estimate of gyro `i`,
    /// (°/s)² (0 before any update or out of range).
    pub fn noise_var(&self, i: usize) -> f32 {
        self.var.get(i).copied().unwrap_or(0.0)
    }

    /// Current noise standard deviation estimates of the adaptive method,
    /// °/s (NaN before any update).
    pub fn sigma_dps(&self, cfg: &AdaptiveConfig) -> [f32; N] {
        let mut s = [f32::NAN; N];
        for i in 0..N {
            if self.n_upd[i] > 0 {
                s[i] = sqrtf(at_least(self.var[i], cfg.var_floor));
            }
        }
        s
    }
}

/// Gyro `i` is in set `m`. Loops test this over `0..N` rather than
/// iterate a filtered range: for small N the compiler unrolls them, which
/// made the adaptive method 2.2× cheaper on the Cortex-M4.
#[inline(always)]
fn has(m: u8, i: usize) -> bool {
    m & (1 << i) != 0
}

/// Call `f(i, j)` for every pair i < j of gyros in `m`, in order.
#[inline(always)]
fn each_pair<const N: usize>(m: u8, mut f: impl FnMut(usize, usize)) {
    for i in 0..N {
        if !has(m, i) {
            continue;
        }
        for j in (i + 1)..N {
            if has(m, j) {
                f(i, j);
            }
        }
    }
}

/// First masked value: the reference the sums are taken about, so that
/// constant input comes back exactly and large rates lose no precision.
fn first<const N: usize>(y: &[f32; N], m: u8) -> f32 {
    y.get(m.trailing_zeros() as usize).copied().unwrap_or(0.0)
}

fn mean_of<const N: usize>(y: &[f32; N], m: u8) -> (f32, [f32; N]) {
    let n = m.count_ones() as f32;
    let y0 = first(y, m);
    let mut w = [0.0; N];
    let mut s = 0.0;
    // Select-style lane loops (no `continue`): one basic block per body, so
    // LLVM unrolls them for the Cortex-M; adding +0.0 leaves sums exact.
    for i in 0..N {
        let on = has(m, i);
        s += if on { y[i] - y0 } else { 0.0 };
        w[i] = if on { 1.0 / n } else { 0.0 };
    }
    (y0 + s / n, w)
}

/// Weighted average with weights `r` on mask `m`; `None` if Σr ≤ 0.
fn weighted<const N: usize>(y: &[f32; N], r: &[f32; N], m: u8) -> Option<(f32, [f32; N])> {
    let y0 = first(y, m);
    let mut sr = 0.0;
    let mut sy = 0.0;
    for i in 0..N {
        let on = has(m, i);
        sr += if on { r[i] } else { 0.0 };
        sy += if on { r[i] * (y[i] - y0) } else { 0.0 };
    }
    // One compare pair instead of a compare plus an is_finite bit test:
    // false for NaN, ≤ 0 and +∞ alike.
    if !(sr > 0.0 && sr < f32::INFINITY) {
        return None;
    }
    let mut w = [0.0; N];
    for i in 0..N {
        w[i] = if has(m, i) { r[i] / sr } else { 0.0 };
    }
    let x = y0 + sy / sr;
    x.is_finite().then_some((x, w))
}

impl<const N: usize> Fusion<N> {
    /// Check the settings and precompute the Grubbs critical values.
    pub fn new(method: Method) -> Result<Self, ConfigError> {
        if N == 0 || N > MAX_GYROS {
            return Err(ConfigError::ArraySize);
        }
        let mut grubbs_t = [0.0f32; MAX_GYROS + 1];
        match method {
            Method::Seed(c) => {
                if let Some(g) = c.grubbs {
                    if !(g.alpha > 0.0 && g.alpha < 1.0) {
                        return Err(ConfigError::Alpha);
                    }
                    for (n, t) in grubbs_t.iter_mut().enumerate() {
                        *t = grubbs_critical(n, g.alpha as f64, g.two_sided).unwrap_or(0.0) as f32;
                    }
                }
                if let Normaliser::Running { k, alpha } = c.normaliser {
                    if !(k > 0.0 && k.is_finite() && alpha > 0.0 && alpha < 1.0) {
                        return Err(ConfigError::Parameter);
                    }
                }
                if let Some(m) = c.memory {
                    if m.len == 0 || m.len > MAX_MEMORY {
                        return Err(ConfigError::MemoryLen);
                    }
                    if !(m.eps > 0.0 && m.eps.is_finite()) {
                        return Err(ConfigError::Parameter);
                    }
                }
            }
            Method::Adaptive(a) => {
                let ok = a.alpha > 0.0
                    && a.alpha < 1.0
                    && a.gate_k > 0.0
                    && a.gate_k.is_finite()
                    && a.var_floor > 0.0
                    && a.var_floor.is_finite()
                    && a.frozen_after >= 2
                    && a.warmup >= 1;
                if !ok {
                    return Err(ConfigError::Parameter);
                }
            }
            Method::Mean | Method::Zhang => {}
        }
        let mut inv_t2 = [0.0f32; MAX_MEMORY];
        if let Method::Seed(SeedConfig {
            memory: Some(mc), ..
        }) = method
        {
            for (lag, v) in inv_t2.iter_mut().enumerate() {
                let t = (lag + mc.lag0 as usize) as f32;
                *v = if t == 0.0 { 0.0 } else { 1.0 / (t * t) };
            }
        }
        Ok(Self {
            method,
            grubbs_t,
            inv_t2,
        })
    }

    /// The configured method.
    pub fn method(&self) -> Method {
        self.method
    }

    /// Grubbs critical value used for `n` values (0 where undefined).
    pub fn grubbs_critical(&self, n: usize) -> f32 {
        self.grubbs_t.get(n).copied().unwrap_or(0.0)
    }

    /// Fuse one axis. `offered` marks the gyros the pipeline considers
    /// healthy; non-finite values among them are rejected here.
    pub fn fuse(
        &self,
        st: &mut AxisState<N>,
        y: &[f32; N],
        offered: u8,
    ) -> Result<Fused<N>, FuseError> {
        let offered = offered & full::<N>();
        // Finite and within a physical range: a value of 10⁶ °/s is no rate
        // (a garbled frame, a bad scale), and sums of a few near f32::MAX
        // overflowed to ±inf (found by fuzzing). Branch-free: every gyro is
        // usually offered.
        let mut valid = 0u8;
        for (i, v) in y.iter().enumerate() {
            valid |= u8::from(v.abs() <= RATE_LIMIT_DPS) << i;
        }
        let valid = valid & offered;
        let mut out = Fused {
            rate_dps: f32::NAN,
            weights: [0.0; N],
            rejected: offered & !valid,
            fallback: false,
        };
        st.k = st.k.saturating_add(1);
        // (By reference: matched by value, the settings were copied to the
        // stack on every call, 10 instructions a 3-axis sample with N = 5.)
        let res = match &self.method {
            Method::Mean => (valid != 0).then(|| mean_of(y, valid)),
            Method::Zhang => self.zhang(y, valid, &mut out),
            Method::Seed(c) => self.seed(c, st, y, valid, &mut out),
            Method::Adaptive(c) => {
                return if adaptive(c, st, y, valid, &mut out) {
                    Ok(out)
                } else {
                    Err(FuseError::NoValidInput)
                };
            }
        };
        match res {
            Some((x, w)) => {
                out.rate_dps = x;
                out.weights = w;
                Ok(out)
            }
            None => Err(FuseError::NoValidInput),
        }
    }

    fn zhang(&self, y: &[f32; N], m: u8, out: &mut Fused<N>) -> Option<(f32, [f32; N])> {
        if m == 0 {
            return None;
        }
        let mut r = [0.0f32; N];
        each_pair::<N>(m, |i, j| {
            let d = y[i] - y[j];
            let s = expf(-d * d);
            r[i] += s;
            r[j] += s;
        });
        if m.count_ones() == 1 {
            return Some(mean_of(y, m));
        }
        weighted(y, &r, m).or_else(|| {
            out.fallback = true;
            Some(mean_of(y, m))
        })
    }

    fn seed(
        &self,
        c: &SeedConfig,
        st: &mut AxisState<N>,
        y: &[f32; N],
        m: u8,
        out: &mut Fused<N>,
    ) -> Option<(f32, [f32; N])> {
        // Inlined twice: for all gyros (a constant mask, so the mask tests
        // fold away and the loops unroll) and for the general mask.
        if m == full::<N>() {
            self.seed_masked(c, st, y, full::<N>(), out)
        } else {
            self.seed_masked(c, st, y, m, out)
        }
    }

    #[inline(always)]
    fn seed_masked(
        &self,
        c: &SeedConfig,
        st: &mut AxisState<N>,
        y: &[f32; N],
        m: u8,
        out: &mut Fused<N>,
    ) -> Option<(f32, [f32; N])> {
        let n = m.count_ones() as usize;
        if n == 0 {
            return None;
        }
        if n == 1 {
            return Some(mean_of(y, m));
        }
        // Eq. 3–4: distances and their normaliser over ordered pairs.
        let mut d = [[0.0f32; N]; N];
        let mut sum = 0.0;
        each_pair::<N>(m, |i, j| {
            let dij = (y[i] - y[j]).abs();
            d[i][j] = dij;
            d[j][i] = dij;
            sum += 2.0 * dij;
        });
        let nf = n as f32;
        let denom = match c.denominator {
            Denominator::MSquaredMinus1 => nf * nf - 1.0,
            Denominator::OrderedPairs => nf * (nf - 1.0),
        };
        let scale = match c.normaliser {
            Normaliser::Instant => sum / denom,
            Normaliser::Running { k, alpha } => {
                let mad = mad(y, m);
                st.spread = if st.spread > 0.0 {
                    st.spread + alpha * (mad - st.spread)
                } else {
                    mad
                };
                k * st.spread
            }
        };
        // Eq. 5–6: support matrix. All-equal inputs give 0/0 in eq. 4; we
        // take d* = 0 (full support), which is the limit for equal values.
        let mut s = [[1.0f32; N]; N];
        if scale > 0.0 && scale.is_finite() {
            let inv = 1.0 / scale;
            each_pair::<N>(m, |i, j| {
                let v = 1.0 - lnf(1.0 + d[i][j] * inv);
                s[i][j] = v;
                s[j][i] = v;
            });
        }
        // Eq. 10–12: Grubbs on each row; zeroing breaks symmetry, as printed.
        if let Some(g) = c.grubbs {
            let nrow = if g.include_diagonal { n } else { n - 1 };
            let t = self.grubbs_t[nrow.min(MAX_GYROS)];
            if t > 0.0 {
                // The diagonal choice as a const, so the row tests fold.
                if g.include_diagonal {
                    grubbs_rows::<N, true>(&mut s, m, nrow, t * t, g.std);
                } else {
                    grubbs_rows::<N, false>(&mut s, m, nrow, t * t, g.std);
                }
            }
        }
        // Eq. 7: total support.
        let mut r = [0.0f32; N];
        for i in 0..N {
            if !has(m, i) {
                continue;
            }
            for j in 0..N {
                if !has(m, j) || j == i {
                    continue;
                }
                r[i] += s[i][j];
            }
            if c.clamp_negative && r[i] < 0.0 {
                r[i] = 0.0;
            }
        }
        for i in 0..N {
            if !has(m, i) {
                continue;
            }
            if r[i] <= 0.0 && c.clamp_negative {
                out.rejected |= 1 << i;
            }
        }
        // Eq. 13–16: limited memory.
        let r = match c.memory {
            Some(mc) => memory_weights(&mc, &self.inv_t2, st, &r, m),
            None => r,
        };
        weighted(y, &r, m).or_else(|| {
            out.fallback = true;
            Some(mean_of(y, m))
        })
    }
}

/// Grubbs rejection (eq. 10–12) on every row of the support matrix: an
/// element whose statistic |s_ij − s̄_i|/σ_i reaches T is set to 0. `DIAG`:
/// the row includes s_ii = 1 (then it has `nrow` = n elements).
#[inline(always)]
fn grubbs_rows<const N: usize, const DIAG: bool>(
    s: &mut [[f32; N]; N],
    m: u8,
    nrow: usize,
    t2: f32,
    std: StdKind,
) {
    let dof = match std {
        StdKind::Population => nrow as f32,
        StdKind::Sample => nrow as f32 - 1.0,
    };
    for i in 0..N {
        if !has(m, i) {
            continue;
        }
        let inrow = |j: usize| has(m, j) && (DIAG || j != i);
        let (mut s1, mut s2) = (0.0f32, 0.0f32);
        for j in 0..N {
            s1 += if inrow(j) { s[i][j] } else { 0.0 };
        }
        let mean = s1 / nrow as f32;
        for j in 0..N {
            let e = s[i][j] - mean;
            s2 += if inrow(j) { e * e } else { 0.0 };
        }
        let var = s2 / dof;
        if !(var > 0.0) {
            continue;
        }
        // T_ij ≥ T  ⇔  (s_ij − s̄)² ≥ T²·σ² (no division, no sqrt). Both
        // sides are non-negative and finite, so their bit patterns order
        // like the values: an integer compare replaces `vcmp` + `vmrs`.
        let thr = (t2 * var).to_bits();
        for j in 0..N {
            let e = s[i][j] - mean;
            let out = inrow(j) && (e * e).to_bits() >= thr;
            s[i][j] = if out { 0.0 } else { s[i][j] };
        }
    }
}

/// Eq. 13–16 with our consistent indexing: `R_i(k) = Σ_u r_i(u)·∂_i(u;k)`
/// over the last `len` epochs, `∂ = 1 / (t² ((r_i(u) − r̄_i(u))² + ε))`,
/// `t = k − u + lag0`; r̄ is the running mean since start (eq. 13). μ and
/// 1/k cancel in eq. 16 and are left out.
fn memory_weights<const N: usize>(
    mc: &MemoryConfig,
    inv_t2: &[f32; MAX_MEMORY],
    st: &mut AxisState<N>,
    r: &[f32; N],
    m: u8,
) -> [f32; N] {
    let kf = st.k as f32;
    st.head = (st.head + 1) % MAX_MEMORY;
    for i in 0..N {
        let on = has(m, i);
        st.rbar[i] = if on {
            st.rbar[i] + (r[i] - st.rbar[i]) / kf
        } else {
            st.rbar[i]
        };
        let dev = r[i] - st.rbar[i];
        let ri = if on { r[i] } else { 0.0 };
        // Kept as one product: (r·∂′)·(1/t²) rounds exactly as r·∂′·(1/t²).
        st.ring[st.head][i] = ri * (1.0 / (dev * dev + mc.eps));
    }
    let mut big_r = [0.0f32; N];
    let len = mc.len.min(st.k as usize);
    // A skipped lag (t = 0) has 1/t² = 0 in the table: adding r·0 = ±0
    // leaves the sums unchanged, so no branch is needed.
    for (lag, &it2) in inv_t2.iter().enumerate().take(len) {
        let u = (st.head + MAX_MEMORY - lag) % MAX_MEMORY;
        for i in 0..N {
            big_r[i] += st.ring[u][i] * it2;
        }
    }
    big_r
}

/// Median of the masked values: an odd–even transposition sort (N rounds,
/// fully unrolled for the const N) of order-preserving integer keys, with
/// gyros outside `m` keyed last. On the Cortex-M4 integer compare-exchanges
/// are far cheaper than float compares (`vcmp` + `vmrs`) or an insertion
/// sort's data-dependent loops; three or four gyros (every set after a
/// chip or two fails) take a short network on their gathered keys
/// instead. NaN when `m` is empty. Also the consensus of the online
/// calibration and of the self-test.
pub(crate) fn median<const N: usize>(y: &[f32; N], m: u8) -> f32 {
    median_of(y, m)
}

/// [`median`], inlined: the adaptive method's constant sets fold it.
#[inline(always)]
fn median_of<const N: usize>(y: &[f32; N], m: u8) -> f32 {
    // Sign-magnitude to two's complement: an involution on the bits.
    let key = |b: i32| b ^ (((b >> 31) as u32) >> 1) as i32;
    let mut k = [i32::MAX; N];
    for i in 0..N {
        k[i] = if has(m, i) {
            key(y[i].to_bits() as i32)
        } else {
            i32::MAX
        };
    }
    let (lo, hi) = middle_keys(k, m);
    let f = |j: i32| f32::from_bits(key(j) as u32);
    if one_middle(m) {
        f(lo)
    } else {
        0.5 * (f(lo) + f(hi))
    }
}

/// The two middle keys of the keys `k` of the gyros in `m` (the others
/// keyed `i32::MAX`), sorted: the same one twice where there is one middle
/// ([`one_middle`]). Three or four gyros (every set after a chip or two
/// fails) take a short network on their gathered keys (4 and 6 min/max);
/// the others the odd–even transposition sort.
#[inline(always)]
fn middle_keys<const N: usize>(mut k: [i32; N], m: u8) -> (i32, i32) {
    let n = m.count_ones();
    if n == 3 {
        let [a, b, c, _] = four(&k, m);
        let mid = a.min(b).max(a.max(b).min(c));
        return (mid, mid);
    }
    if n == 4 {
        // The middle pair is (max of the two minima, min of the two maxima).
        let [a, b, c, d] = four(&k, m);
        let (a, b) = (a.min(b), a.max(b));
        let (c, d) = (c.min(d), c.max(d));
        return (a.max(c), b.min(d));
    }
    for round in 0..N {
        let mut i = round % 2;
        while i + 1 < N {
            let (a, b) = (k[i], k[i + 1]);
            k[i] = a.min(b);
            k[i + 1] = a.max(b);
            i += 2;
        }
    }
    let n = n as usize;
    let at = |j: usize| k.get(j).copied().unwrap_or(0);
    (at(n.saturating_sub(1) / 2), at(n / 2))
}

/// Whether the gyros in `m` have one middle value (an odd count, or none).
#[inline(always)]
fn one_middle(m: u8) -> bool {
    let n = m.count_ones();
    n % 2 == 1 || n == 0
}

/// The median for the adaptive gate: with an odd count the middle value;
/// with an even count the inverse-variance weighted mean of the middle two
/// (the plain mean of them let a noisy but honest gyro, an ADXRS453 among
/// ICM-42688-Ps, drag the reference off every quiet gyro once a third one
/// was wild: the fault campaign's last failures). Same sorting as
/// [`median`], with each gyro's index in the key's three low bits, so the
/// middle two are known; the values returned are the exact inputs.
#[inline(always)]
fn gate_median<const N: usize>(y: &[f32; N], v: &[f32; N], m: u8) -> f32 {
    let key = |b: i32| b ^ (((b >> 31) as u32) >> 1) as i32;
    let mut k = [i32::MAX; N];
    for i in 0..N {
        k[i] = if has(m, i) {
            (key(y[i].to_bits() as i32) & !7) | (i as i32 & 7)
        } else {
            i32::MAX
        };
    }
    // (Indices are < N; `% N` lets the compiler see it: no bounds checks.)
    let pick = |lo: i32, hi: i32| {
        let (a, b) = ((lo & 7) as usize % N, (hi & 7) as usize % N);
        let (ya, yb, va, vb) = (y[a], y[b], v[a], v[b]);
        // (ya/va + yb/vb) / (1/va + 1/vb), without the divisions.
        (ya * vb + yb * va) / (va + vb)
    };
    let (lo, hi) = middle_keys(k, m);
    if one_middle(m) {
        y[(lo & 7) as usize % N]
    } else {
        pick(lo, hi)
    }
}

/// The keys of the (up to) four gyros in `m`, in order; `i32::MAX` after
/// them. With `m` a constant (the adaptive method's constant sets) the
/// gather folds to four loads.
#[inline(always)]
fn four<const N: usize>(k: &[i32; N], m: u8) -> [i32; 4] {
    if N == 4 && m == full::<N>() {
        // All four (the online calibration's usual consensus with four
        // gyros, a runtime mask): no gather.
        let at = |j: usize| k.get(j).copied().unwrap_or(i32::MAX);
        return [at(0), at(1), at(2), at(3)];
    }
    let mut g = [i32::MAX; 4];
    let mut j = 0usize;
    for i in 0..N {
        if has(m, i) {
            if let Some(s) = g.get_mut(j) {
                *s = k[i];
            }
            j += 1;
        }
    }
    g
}

/// Median absolute deviation from the median over the masked values.
fn mad<const N: usize>(y: &[f32; N], m: u8) -> f32 {
    let med = median(y, m);
    let mut dev = [0.0f32; N];
    for i in 0..N {
        dev[i] = (y[i] - med).abs();
    }
    median(&dev, m)
}

/// All N gyros.
#[inline(always)]
fn full<const N: usize>() -> u8 {
    ((1u16 << N) - 1) as u8
}

/// Store a fused value and its weights in `out`; whether there was one.
/// The adaptive method's out-of-line parts return through `out` rather
/// than by value: merging their results by value cost copies of them in
/// the inlined path (40 instructions per 3-axis sample with N = 4).
#[inline(always)]
fn put<const N: usize>(r: Option<(f32, [f32; N])>, out: &mut Fused<N>) -> bool {
    match r {
        Some((x, w)) => {
            out.rate_dps = x;
            out.weights = w;
            true
        }
        None => false,
    }
}

/// The adaptive method over `valid`, into `out`; false if nothing fused.
fn adaptive<const N: usize>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    valid: u8,
    out: &mut Fused<N>,
) -> bool {
    if valid == 0 {
        return false;
    }
    // Sets of three or more gyros run with a constant mask when N ≤ 5 (16
    // sets for the board's five, 5 for four, 1 for three), and all gyros
    // do for larger N. With the mask a constant, every phase's mask tests
    // fold away and its lane loops shrink to the gyros in the set. Before,
    // only all gyros and (N = 5) all but the last had that, and after a
    // chip failed every axis ran the general mask: three of five cost
    // 3 101 instructions per 3-axis sample on the Cortex-M4, against 1 991
    // for the constant four of five (`cargo xtask bench`). Sets of one or
    // two have no gate and take the general path. Same arithmetic in the
    // same order either way.
    // With fewer than five gyros, all of them (the usual case) is inlined
    // here: out of line, the call cost 60 more per 3-axis sample with N = 4,
    // over the default path's 2 500. With five, inlining it made the other
    // sets' calls dearer (four of five 2 011 -> 2 687).
    if N < 5 && valid == full::<N>() {
        adaptive_const(c, st, y, full::<N>(), out)
    } else {
        adaptive_dispatch(c, st, y, valid, out)
    }
}

/// [`adaptive`] for the sets not inlined there: the jump table.
#[inline(never)]
fn adaptive_dispatch<const N: usize>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    valid: u8,
    out: &mut Fused<N>,
) -> bool {
    macro_rules! dispatch {
        ($($m:literal)*) => {
            match valid {
                $( $m if N <= 5 && ($m as u32) >> N == 0 => adaptive_set::<N, $m>(c, st, y, out), )*
                _ if N > 5 && valid == full::<N>() => adaptive_set::<N, 0>(c, st, y, out),
                _ => adaptive_general(c, st, y, valid, out),
            }
        };
    }
    dispatch!(7 11 13 14 15 19 21 22 23 25 26 27 28 29 30 31)
}

/// [`adaptive`] with the constant set `M` valid (0: all N gyros): one copy
/// per set, its phases inlined with the mask folded in.
#[inline(never)]
fn adaptive_set<const N: usize, const M: u8>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    out: &mut Fused<N>,
) -> bool {
    adaptive_const(c, st, y, if M == 0 { full::<N>() } else { M }, out)
}

/// [`adaptive`] with the set `m` valid, inlined for a constant `m`.
#[inline(always)]
fn adaptive_const<const N: usize>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    m: u8,
    out: &mut Fused<N>,
) -> bool {
    let active = frozen_check(c, st, y, m);
    if active == m {
        put(
            adaptive_active(c, st, y, m, m, m, (true, true), None, out),
            out,
        )
    } else if active != 0 {
        // A frozen chip votes but is not fused: the gate is over the
        // voters, the constant `m`, so it is taken here, folded, and passed
        // on (with the general mask it cost 270 more per 3-axis sample in
        // the 12 samples after a chip sticks).
        let all_warm = active & !st.warm == 0;
        let v = floored(st, c);
        let g = first_gate(c, y, &v, m, m.count_ones(), all_warm);
        adaptive_frozen(c, st, y, m, active, Some((g, v)), out)
    } else {
        adaptive_frozen(c, st, y, m, active, None, out)
    }
}

/// Each gyro's noise variance, floored: the weights' and the gate's.
#[inline(always)]
fn floored<const N: usize>(st: &AxisState<N>, c: &AdaptiveConfig) -> [f32; N] {
    let mut v = [0.0f32; N];
    for i in 0..N {
        v[i] = at_least(st.var[i], c.var_floor);
    }
    v
}

/// [`adaptive`] for any set.
#[inline(never)]
fn adaptive_general<const N: usize>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    valid: u8,
    out: &mut Fused<N>,
) -> bool {
    let active = frozen_check(c, st, y, valid);
    adaptive_frozen(c, st, y, valid, active, None, out)
}

/// The rest of [`adaptive`] once the frozen check has left `active` of
/// `valid`. Frozen candidates are not fused but still vote in the median
/// gate: a healthy chip that repeats a quantised value four times (it
/// happens) must not leave a faulty one ungated for want of a quorum
/// (fault campaign, seed 7 783 687: three gyros on x, one rescaled, one
/// repeating; the rescaled one was fused). A chip that sticks is frozen
/// here for the 12 samples until the pipeline flags it stuck, on every
/// axis: the gyros left to fuse run with a constant mask too (the gate,
/// over the voters, with the general one), which took 1 750 instructions
/// off each of those samples.
#[inline(never)]
fn adaptive_frozen<const N: usize>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    valid: u8,
    active: u8,
    gate: Option<(Gate, [f32; N])>,
    out: &mut Fused<N>,
) -> bool {
    if active == 0 {
        out.rejected |= valid;
        return false;
    }
    macro_rules! dispatch {
        ($($m:literal)*) => {
            match active {
                $( $m if N <= 5 && ($m as u32) >> N == 0 => adaptive_fused_set::<N, $m>(c, st, y, valid, gate, out), )*
                _ => put(adaptive_active(c, st, y, valid, active, valid, (false, false), gate, out), out),
            }
        };
    }
    // (Pairs among the first four too: two ICM-42688-Ps left on x or y
    // while two others that stuck together are not yet flagged. Through
    // the general path those samples cost 300 more, and made the loop's
    // worst sample in `cargo xtask bench-loop`'s scenario F.)
    dispatch!(3 5 6 9 10 12 7 11 13 14 15 19 21 22 23 25 26 27 28 29 30)
}

/// [`adaptive_frozen`] fusing the constant set `M` of `valid`.
#[inline(never)]
fn adaptive_fused_set<const N: usize, const M: u8>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    valid: u8,
    gate: Option<(Gate, [f32; N])>,
    out: &mut Fused<N>,
) -> bool {
    put(
        adaptive_active(c, st, y, valid, M, valid, (false, true), gate, out),
        out,
    )
}

/// Frozen outputs: bit-identical for `frozen_after` samples while some
/// other gyro moves. A stuck chip is caught before it drifts away. Returns
/// the gyros of `valid` that are not frozen. Lane loops here and below are
/// select-style (see `mean_of`).
#[inline(always)]
fn frozen_check<const N: usize>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    valid: u8,
) -> u8 {
    // A gyro is frozen when its own run of repeats is long enough and some
    // other gyro has moved since it froze (its run is longer than the
    // shortest). Asking only "did another gyro move on this sample" let a
    // stuck chip back in whenever a healthy one repeated a quantised value
    // (2.4 % of samples with N = 2). Candidates are rare: the comparison
    // runs out of line.
    let mut candidates = 0u8;
    for i in 0..N {
        let on = has(valid, i);
        let same = y[i].to_bits() == st.last[i].to_bits();
        let f = st.frozen[i];
        let f = match (on, same) {
            (false, _) => f,
            (true, true) => f.saturating_add(1),
            (true, false) => 0,
        };
        st.frozen[i] = f;
        candidates |= ((on && f.saturating_add(1) >= c.frozen_after) as u8) << i;
        st.last[i] = if on { y[i] } else { st.last[i] };
    }
    if candidates == 0 {
        valid
    } else {
        drop_frozen(st, valid, candidates)
    }
}

/// The gyros of `valid` left after dropping the `candidates` whose run of
/// repeats is longer than the shortest among `valid`. Select-style: it
/// runs on every sample while a chip that stuck is caught here but not
/// yet flagged by the pipeline, and with branches it cost 330
/// instructions per 3-axis sample then (`cargo xtask bench`, whole loop).
/// Out of line: inlined, it cost the all-in path 16 more.
#[cold]
#[inline(never)]
fn drop_frozen<const N: usize>(st: &AxisState<N>, valid: u8, candidates: u8) -> u8 {
    let mut shortest = u8::MAX;
    for i in 0..N {
        let f = if has(valid, i) { st.frozen[i] } else { u8::MAX };
        shortest = shortest.min(f);
    }
    let mut longer = 0u8;
    for i in 0..N {
        longer |= u8::from(st.frozen[i] > shortest) << i;
    }
    valid & !(candidates & longer)
}

/// The median gate left fewer than two gyros. With an even count the
/// median is the mean of the middle two, so one wild value plus one noisy
/// but honest one (an ADXRS453 among ICM-42688-Ps) can pull it off every
/// quiet gyro: drop the most outlying value and gate again about the new
/// median.
fn regate_without_worst<const N: usize>(
    y: &[f32; N],
    v: &[f32; N],
    active: u8,
    med: f32,
    k2: f32,
    v_med: f32,
) -> u8 {
    let mut worst = (0.0f32, 0usize);
    for i in 0..N {
        let e = y[i] - med;
        let z = if has(active, i) {
            e * e / (v[i] + v_med)
        } else {
            0.0
        };
        if z > worst.0 {
            worst = (z, i);
        }
    }
    let rest = active & !(1u8 << (worst.1 & 7));
    if rest & rest.wrapping_sub(1) == 0 {
        // One gyro left (two were active: a pair fused while others that
        // stuck are not yet flagged): it is within the gate about its own
        // value. Through the median's sort and the gate this cost a 3-axis
        // sample 100 more (`cargo xtask bench-loop`, scenario F).
        return rest;
    }
    let med = gate_median(y, v, rest);
    let mut good = rest;
    for i in 0..N {
        let e = y[i] - med;
        let off = e * e > k2 * (v[i] + v_med);
        good &= !(((has(rest, i) && off) as u8) << i);
    }
    good
}

/// The first gate kept fewer than two gyros or left two or more out
/// (rare, so out of line): [`regate_without_worst`] for the first, then
/// [`consensus_gate`] if two or more are out. Also says whether the gyros
/// split with no majority.
#[cold]
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn regate<const N: usize>(
    y: &[f32; N],
    v: &[f32; N],
    w: &[f32; N],
    active: u8,
    mut good: u8,
    med: f32,
    k2: f32,
    v_med: f32,
) -> (u8, bool) {
    if good & good.wrapping_sub(1) == 0 {
        good = regate_without_worst(y, v, active, med, k2, v_med);
    }
    let off = active & !good;
    if off & off.wrapping_sub(1) != 0 {
        return consensus_gate(y, v, w, active, good, k2, v_med);
    }
    (good, false)
}

/// The gate rejected two or more gyros. With an even count the median
/// sits between the middle two, and when two chips agree by chance with a
/// faulty one (a bit error that moved a chip by 1 °/s, beside a noisy but
/// honest ADXRS453) the gate can keep the wrong pair and reject the quiet
/// majority: the fault campaign's last two failures in 10 000 runs. So
/// take every active gyro's value in turn as the reference, gate the
/// others about it as about the median (residual variance vᵢ + v_med: a
/// reference's own variance must not widen the gate, or a chip the noise
/// model already distrusts would vouch for everybody), and keep the
/// consistent set of largest total inverse variance; the first gate's
/// choice stands unless another set has more gyros or, as many, outweighs
/// it. Returns the set, and whether it is no majority of the active gyros
/// (a split: two against two). Two rejections are rare (two faulty chips
/// at once), so this is out of line.
#[cold]
#[inline(never)]
fn consensus_gate<const N: usize>(
    y: &[f32; N],
    v: &[f32; N],
    w: &[f32; N],
    active: u8,
    first: u8,
    k2: f32,
    v_med: f32,
) -> (u8, bool) {
    // Each gyro's gate (its residual variance times k²), then, for every
    // pair once, whether each is within the other's: the same sets as
    // gating all gyros about each reference in turn, with half the
    // squares. It was 800 instructions a 3-axis sample at the whole loop's
    // worst sample (fault scenario D: two chips spiking on one axis).
    let mut lim = [0.0f32; N];
    for i in 0..N {
        lim[i] = k2 * (v[i] + v_med);
    }
    let mut agree = [0u8; N];
    for j in 0..N {
        agree[j] |= u8::from(0.0 <= lim[j]) << j;
        for i in 0..j {
            let e = y[i] - y[j];
            let e2 = e * e;
            agree[j] |= u8::from(e2 <= lim[i]) << i;
            agree[i] |= u8::from(e2 <= lim[j]) << j;
        }
    }
    // The set's total inverse variance, from the caller's weights (1/vᵢ
    // over the active gyros: every set here is within them).
    let weight = |set: u8| -> f32 {
        let mut s = 0.0;
        for i in 0..N {
            s += if has(set, i) { w[i] } else { 0.0 };
        }
        s
    };
    // Majority logic first (more gyros agreeing wins), weight second: the
    // weights are only summed for a tie.
    let (mut best, mut best_n, mut best_w) = (first, first.count_ones(), None);
    for j in 0..N {
        let set = agree[j] & active;
        let n = set.count_ones();
        if !has(active, j) || n < 2 || n < best_n {
            continue;
        }
        if n > best_n {
            (best, best_n, best_w) = (set, n, None);
            continue;
        }
        let bw = *best_w.get_or_insert_with(|| weight(best));
        let w = weight(set);
        if w > bw {
            (best, best_w) = (set, Some(w));
        }
    }
    // Split: the largest consistent set is not a majority of the gyros.
    (best, 2 * best_n <= active.count_ones())
}

/// Sum of the priors of the two gyros in `good`, or 0 unless both have one.
fn pair_prior_sum<const N: usize>(prior: &[f32; N], good: u8) -> f32 {
    let mut sum = 0.0;
    for i in 0..N {
        if has(good, i) {
            if !(prior[i] > 0.0) {
                return 0.0;
            }
            sum += prior[i];
        }
    }
    sum
}

/// With two gyros, the power of their difference up to this multiple of
/// the priors' sum is shared in the priors' proportion (4 standard
/// deviations of its EWMA estimate); only what exceeds it is split equally.
const PAIR_SLACK: f32 = 1.25;

/// Sum of the noise variances of the gyros in `good`.
fn pair_var_sum<const N: usize>(var: &[f32; N], good: u8) -> f32 {
    let mut sum = 0.0;
    for i in 0..N {
        if has(good, i) {
            sum += var[i];
        }
    }
    sum
}

/// Huber's c² for the noise update (c = 2).
const HUBER_C2: f32 = 4.0;
/// 1 / E[min(z², c²)] for z ~ N(0, 1) and c = 2: 1 / (P(|z| < 2) − 4φ(2)
/// + 4·P(|z| > 2)) = 1 / 0.920 537 (checked by `huber_kappa_is_the_gaussian_consistency_factor`).
const HUBER_KAPPA: f32 = 1.086_322_5;

/// Largest |rate| fusion accepts, °/s: far beyond any gyro's range (the
/// ICM-42688-P saturates at 2000 °/s), small enough that no sum or square
/// of a few of them overflows f32. NaN fails the comparison too.
pub const RATE_LIMIT_DPS: f32 = 1.0e6;

/// Gate of the warm-up (robust sigmas from the median): wide, because a
/// MAD of three to five values is a rough scale.
const WARM_GATE: f32 = 6.0;

/// Warming up (the first `warmup` samples, or a gyro that just joined): no
/// noise model yet, so gate on the spread itself. A value more than
/// [`WARM_GATE`] robust sigmas (1.4826 · MAD about the median) from the
/// median is left out, so a chip that spikes or garbles frames from
/// power-up is not averaged in. Also returns the limit squared, which caps
/// what one sample adds to a warming chip's noise estimate. Out of line:
/// it runs for a few dozen samples after start-up or a rejoin.
#[cold]
#[inline(never)]
fn warm_up_gate<const N: usize>(
    c: &AdaptiveConfig,
    y: &[f32; N],
    active: u8,
    med: f32,
) -> (u8, f32) {
    let mut dev = [0.0f32; N];
    for i in 0..N {
        dev[i] = (y[i] - med).abs();
    }
    let lim = WARM_GATE * (1.4826 * median(&dev, active)).max(sqrtf(c.var_floor));
    let mut good = active;
    for i in 0..N {
        good &= !(((has(active, i) && dev[i] > lim) as u8) << i);
    }
    (good, lim * lim)
}

/// The first gate's result: the voters' median, those off it, and the
/// typical variance term.
type Gate = (f32, u8, f32);

/// [`first_gate`] for any voters, out of line.
#[inline(never)]
fn first_gate_any<const N: usize>(
    c: &AdaptiveConfig,
    y: &[f32; N],
    v: &[f32; N],
    voters: u8,
    n: u32,
    all_warm: bool,
) -> Gate {
    first_gate(c, y, v, voters, n, all_warm)
}

/// The median of `voters` (`n` of them) and, once all are warm and there
/// are three or more, the voters off it and the typical variance term of
/// the gate (0 and 0 otherwise).
#[inline(always)]
fn first_gate<const N: usize>(
    c: &AdaptiveConfig,
    y: &[f32; N],
    v: &[f32; N],
    voters: u8,
    n: u32,
    all_warm: bool,
) -> Gate {
    let med = if all_warm {
        gate_median(y, v, voters)
    } else {
        median_of(y, voters)
    };
    if !(n >= 3 && all_warm) {
        return (med, 0, 0.0);
    }
    // The typical variance: the mean of the active gyros' without the
    // largest. The plain mean let one very noisy or spiking gyro widen
    // the gate for all (the fault campaign found a second faulty chip
    // getting through that way); a median of the variances did as well
    // at ~60 more instructions per 3-axis sample.
    let (mut vsum, mut vmax) = (0.0f32, 0.0f32);
    for i in 0..N {
        let vi = if has(voters, i) { v[i] } else { 0.0 };
        vsum += vi;
        vmax = if vi > vmax { vi } else { vmax };
    }
    let nm1 = n as f32 - 1.0;
    let k2 = c.gate_k * c.gate_k;
    // vbar / (n − 1), with vbar = (vsum − vmax) / (n − 1).
    let v_med = (vsum - vmax) / (nm1 * nm1);
    let mut offm = 0u8;
    for i in 0..N {
        let e = y[i] - med;
        let off = has(voters, i) && e * e > k2 * (v[i] + v_med);
        offm |= (off as u8) << i;
    }
    (med, offm, v_med)
}

/// Weights, median gate, noise update and the fused value over `active`;
/// the gate's median and quorum are over `voters` (⊇ `active`).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn adaptive_active<const N: usize>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    valid: u8,
    active: u8,
    voters: u8,
    (fast_gate, fast_fuse): (bool, bool),
    gate: Option<(Gate, [f32; N])>,
    out: &mut Fused<N>,
) -> Option<(f32, [f32; N])> {
    let n = voters.count_ones();
    // Current weights: inverse variance once warmed up, equal before.
    let all_warm = active & !st.warm == 0;
    let v = match gate {
        Some((_, v)) => v,
        None => floored(st, c),
    };
    let mut w = [0.0f32; N];
    for i in 0..N {
        let wi = if all_warm { 1.0 / v[i] } else { 1.0 };
        w[i] = if has(active, i) { wi } else { 0.0 };
    }
    // Median gate (needs 3 gyros to tell which one is off): the residual
    // y_i − median has variance about σ_i² + (typical σ²)/(n − 1). With
    // `fast_gate`, the voters are `active` and it is a constant; `gate`,
    // the caller took it.
    let (med, offm, v_med) = match gate {
        Some((g, _)) => g,
        None if fast_gate => first_gate(c, y, &v, active, n, all_warm),
        None => first_gate_any(c, y, &v, voters, n, all_warm),
    };
    let k2 = c.gate_k * c.gate_k;
    let mut good = active;
    let mut warm_cap = f32::INFINITY;
    if n >= 3 && all_warm {
        good = active & !offm;
        // Voters that agree with the median: the fused ones and any frozen
        // candidate (a healthy chip repeating a value still vouches).
        let mut support = voters & !offm;
        // Fewer than two agree, or two or more fused gyros out (one AND
        // each, no popcount): rare, out of line.
        let out_active = active & offm;
        if support & support.wrapping_sub(1) == 0 || out_active & out_active.wrapping_sub(1) != 0 {
            let split;
            (good, split) = regate(y, &v, &w, active, good, med, k2, v_med);
            support = good | (voters & !active & !offm);
            if split {
                // No majority agrees (two chips against two): nothing
                // tells which pair is right. Hold the last output, flagged
                // as degraded, rather than follow either pair (the pair
                // that is wrong together also looks quieter to the noise
                // model, and was followed).
                out.fallback = true;
                out.rejected |= valid & !good;
                // No gyro is used (weights 0): nothing learns from a
                // sample nobody can vouch for (the online calibration
                // learns from the gyros fusion used).
                let held = st.last_out;
                if held.is_finite() {
                    return Some((held, [0.0; N]));
                }
            }
        }
        if good == 0 || support & support.wrapping_sub(1) == 0 {
            // Still fewer than two: everybody disagrees, nothing to single
            // out; fall back.
            good = active;
            out.fallback = true;
        }
    } else if n >= 3 {
        (good, warm_cap) = warm_up_gate(c, y, voters, med);
        good &= active;
        if good & good.wrapping_sub(1) == 0 {
            good = active;
            out.fallback = true;
        }
    }
    out.rejected |= valid & !good;
    // With `fast_fuse`, `active` is the caller's constant set: inlined for
    // it when the gate kept every gyro, out of line otherwise (N ≥ 5).
    let warm = (all_warm, warm_cap);
    let one_out = (active & !good).is_power_of_two();
    let r = if fast_fuse && good == active {
        update_and_fuse(c, st, y, active, active, warm, med, &v, &w, out)
    } else if N < 5 && fast_fuse {
        // A gyro gated out of a constant set, with fewer than five: inlined
        // too (a call cost 47 more per 3-axis sample with N = 4, where the
        // bench's spiking gyro is gated out of 5 % of the axes).
        update_and_fuse(c, st, y, active, good, warm, med, &v, &w, out)
    } else if fast_fuse && N == 5 && one_out && active == 31 {
        // One gyro gated out of the board's healthy sets (all five on z,
        // the four ICM-42688-Ps on x and y), out of line: a chip that
        // glitches on all three axes at once cost 740 more per 3-axis
        // sample through the general path.
        without_one::<N, 31>(c, st, y, good, warm, med, &v, &w, out)
    } else if fast_fuse && N == 5 && one_out && active == 15 {
        without_one::<N, 15>(c, st, y, good, warm, med, &v, &w, out)
    } else {
        update_and_fuse_general(c, st, y, active, good, warm, med, &v, &w, out)
    };
    // Warming up (the first samples after power-up or a rejoin), the
    // output is the median of the voters: equal weights over what a rough
    // MAD gate let through can still carry a second faulty chip (fault
    // campaign, seed 7 780 514: one chip stuck, one garbling bytes, and
    // the noisy ADXRS453 widening the MAD). The noise model still learns
    // from the gated set; the weights reported are its equal weights.
    let r = if !all_warm && n >= 3 {
        r.map(|(_, wts)| (med, wts))
    } else {
        r
    };
    if let Some((x, _)) = r {
        st.last_out = x;
    }
    r
}

/// [`update_and_fuse`] over the constant set `M` with one gyro, `M` less
/// `good`, gated out: one copy per gyro, `good` a constant too.
#[allow(clippy::too_many_arguments)]
#[inline(never)]
fn without_one<const N: usize, const M: u8>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    good: u8,
    warm: (bool, f32),
    med: f32,
    v: &[f32; N],
    w: &[f32; N],
    out: &mut Fused<N>,
) -> Option<(f32, [f32; N])> {
    macro_rules! without {
        ($($b:literal)*) => {
            match M & !good {
                $( $b if M & $b != 0 => update_and_fuse(c, st, y, M, M & !$b, warm, med, v, w, out), )*
                _ => update_and_fuse(c, st, y, M, good, warm, med, v, w, out),
            }
        };
    }
    without!(1 2 4 8 16)
}

/// [`update_and_fuse`] for any sets, out of line.
#[allow(clippy::too_many_arguments)]
#[inline(never)]
fn update_and_fuse_general<const N: usize>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    active: u8,
    good: u8,
    warm: (bool, f32),
    med: f32,
    v: &[f32; N],
    w: &[f32; N],
    out: &mut Fused<N>,
) -> Option<(f32, [f32; N])> {
    update_and_fuse(c, st, y, active, good, warm, med, v, w, out)
}

/// Noise update and inverse-variance fusion over `good` (⊆ `active`).
///
/// Each gyro is compared with the weighted mean of the *other* good gyros,
/// x₋ᵢ, whose variance V₋ᵢ = 1/Σ_{j≠i} w_j is known from the current
/// estimates, so E[(y_i − x₋ᵢ)²] − V₋ᵢ = σ_i². Sums are taken about the
/// median to keep precision at high rates.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn update_and_fuse<const N: usize>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    active: u8,
    good: u8,
    (all_warm, warm_cap): (bool, f32),
    med: f32,
    v: &[f32; N],
    w: &[f32; N],
    out: &mut Fused<N>,
) -> Option<(f32, [f32; N])> {
    let (mut sw, mut swy) = (0.0f32, 0.0f32);
    for i in 0..N {
        let on = has(good, i);
        sw += if on { w[i] } else { 0.0 };
        swy += if on { w[i] * (y[i] - med) } else { 0.0 };
    }
    // Exactly two good gyros with priors for both: the variance of their
    // difference is shared in proportion to the priors.
    let rest = good & good.wrapping_sub(1);
    let pair_prior = if rest != 0 && rest & rest.wrapping_sub(1) == 0 {
        pair_prior_sum(&st.prior, good)
    } else {
        0.0
    };
    // At least two good gyros (one AND, no popcount).
    if good & good.wrapping_sub(1) != 0 {
        for i in 0..N {
            let inside = has(good, i);
            let wo = if inside { sw - w[i] } else { sw };
            let wyo = if inside {
                swy - w[i] * (y[i] - med)
            } else {
                swy
            };
            if !has(active, i) || !(wo > 0.0) {
                continue;
            }
            let was_warm = has(st.warm, i);
            // A warm chip the gate left out this sample teaches its noise
            // estimate nothing: its error is an outlier's, and the
            // estimate is what the gate judges it by. Capped by Huber
            // instead, 20 °/s spikes on 2 % of a chip's samples raised its
            // variance 11 % and cost its clean samples a tenth of their
            // weight (0.5 % of the RMS error, worse than zhang). A chip
            // whose noise really grows still teaches it through the
            // samples inside the gate (Huber below), and one the gate
            // always leaves out is out of the fusion anyway.
            if was_warm && !inside {
                continue;
            }
            let e = (y[i] - med) - wyo / wo;
            let v_others = if all_warm { 1.0 / wo } else { 0.0 };
            let mut e2 = e * e;
            // Warming up, one sample adds at most the warm-up gate's limit
            // squared: a chip that spikes from power-up does not start with
            // its spikes in its variance, and one that is plainly wrong
            // still warms up (with a large variance) instead of holding the
            // axis in warm-up.
            if !was_warm && e2 > warm_cap {
                e2 = warm_cap;
            }
            // Huber's scale estimate once warm: e² capped at c²·(its expected
            // value) with c = 2, times κ = 1/E[min(z², 4)] = 1.0864 so that
            // Gaussian noise is estimated without bias. With the cap at the
            // gate (c = 5), outliers at more than 1/(κc²) ≈ 4 % of samples
            // (a chip spiking at 5 %) made the estimate grow without bound
            // until the spikes fitted inside the gate (fault campaign, seed
            // 7 783 523); with c = 2 it stays bounded up to 23 %.
            if was_warm {
                let cap = HUBER_C2 * (v[i] + v_others);
                e2 = if e2 > cap { cap } else { e2 } * HUBER_KAPPA;
            }
            // Plain average until `warmup` updates, then the EWMA; the count
            // stops once warm (it is only needed until then).
            let a = if was_warm {
                c.alpha
            } else {
                st.n_upd[i] += 1;
                st.warm |= ((st.n_upd[i] >= c.warmup) as u8) << i;
                1.0 / st.n_upd[i] as f32
            };
            if pair_prior > 0.0 && has(good, i) {
                // Two chips: the power of their difference is learnt once
                // (on the lower index), and each chip's variance is its
                // prior's share of the part the priors explain plus half of
                // any excess. What the priors do not explain (scale errors
                // under motion, a drift) cannot be pinned on either chip,
                // and scale errors that are alike in size are best averaged
                // equally: split in proportion to the priors instead, it
                // left the pair 1.08× the mean on a 30 °/s sway with scale
                // errors in ±1 % (`fusion-eval` class (k), seed 2).
                if i as u32 == good.trailing_zeros() {
                    if st.pair != good {
                        st.pair = good;
                        st.pair_power = pair_var_sum(&st.var, good);
                    }
                    st.pair_power += a * (e2 - st.pair_power);
                }
                // (Only the excess beyond PAIR_SLACK × the priors' sum is
                // split equally: the learnt power itself fluctuates by
                // ~6 % (χ²₁ through an EWMA of 1/256), and splitting those
                // fluctuations equally gave a 5× noisier chip 1/20 of the
                // weight instead of 1/26.)
                let (p, knee) = (st.pair_power, PAIR_SLACK * pair_prior);
                st.var[i] = st.prior[i] * (p.min(knee) / pair_prior) + 0.5 * (p - knee).max(0.0);
                continue;
            }
            st.var[i] += a * (e2 - v_others - st.var[i]);
        }
    }
    if pair_prior == 0.0 {
        st.pair = 0;
    }
    // Inverse-variance weights over the good set.
    weighted(y, w, good).or_else(|| {
        out.fallback = true;
        Some(mean_of(y, good))
    })
}

#[cfg(test)]
mod tests;
