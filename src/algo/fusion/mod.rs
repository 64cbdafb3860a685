//! Per-sample fusion of N gyros into one virtual gyro (one axis at a time).
//!
//! Methods (seed 004: Zhou, Yao and Shen, "An information fusion
//! algorithm of gyro array based on support degree and memory weighting",
//! Electronics Optics & Control 26(12), 2019):
//! - [`Method::Mean`]: the baseline.
//! - [`Method::Zhang`]: support `exp(−(yi−yj)²)` (Zhang 2012, eq. 2), eq. 9.
//! - [`Method::SupportDegree`]: normalised distance and log support (eq. 3–9),
//!   optionally Grubbs rejection of abnormal supports (eq. 10–12) and
//!   limited-memory weighting (eq. 13–16). Every ambiguity is a knob.
//! - [`Method::Adaptive`] (ours, the default): per-gyro noise variance from
//!   the slow mean squares of the pairs' differences (the N-cornered hat),
//!   weights that tend to equal where the evidence is weak, median gating,
//!   a drift watch and frozen-output rejection.
//!
//! Settings ([`Fusion`]) are immutable and shared by the three axes; the
//! per-axis running state is [`AxisState`]. Capacity is the const `N ≤ 8`;
//! gyro sets are bit masks (bit i = gyro i).
//!
//! Files: this one holds the interface ([`Fusion::fuse`], [`Fused`],
//! [`AxisState`], the noise probe) and the weighted mean every method ends
//! in; `settings` the methods and their knobs; `support` Zhang's and the
//! seed's support-degree methods; `adaptive` ours, with the constant-set
//! dispatch; `gate` its warm-up, median and consensus gates; `frozen` the
//! stuck-output check; `median` the sorting networks behind the gates.

mod adaptive;
mod frozen;
mod gate;
mod median;
mod settings;
mod support;

pub use settings::*;

use adaptive::adaptive;
pub(crate) use median::median;

use crate::algo::math::{at_least, sqrtf};
use crate::algo::stats::grubbs_critical;

/// Largest array supported (masks are `u8`).
pub const MAX_GYROS: usize = 8;

/// Longest memory window for eq. 13–16.
pub const MAX_MEMORY: usize = 16;

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
    /// The last output, held when the gyros split with no majority, and
    /// the gyros it used (weight > 0).
    last_out: f32,
    last_used: u8,
    /// With exactly two gyros and priors: which two, and the learnt power
    /// of their difference, (°/s)².
    pair: u8,
    pair_power: f32,
    /// Per pair i < j, the slow mean of (yᵢ − yⱼ)², (°/s)²: Var(yᵢ − yⱼ)
    /// = σᵢ² + σⱼ² for independent errors, the N-cornered hat's input
    /// (`adaptive::attribute`).
    pd: [[f32; N]; N],
    /// Per gyro, samples it learnt on, counted up to
    /// 1/[`adaptive::NOISE_ALPHA`]: the growing window of its pairs and
    /// of its drift watch's means before their slow factors take over.
    n_pair: [u16; N],
    /// The set `var` was last attributed over.
    solved: u8,
    /// Per gyro, the variance the median gate judges it by: its own share
    /// of the disagreement, even where the weights are kept equal
    /// (`adaptive::attribute`), so that a chip that sees more vibration
    /// than the others is not gated for it.
    gvar: [f32; N],
    /// Per gyro, its own noise variance as the hat attributes it (no
    /// shrinkage, no shared part): what [`AxisState::sigma_dps`] reports.
    own: [f32; N],
    /// Per gyro, the fast (`AdaptiveConfig::alpha`) and the slow
    /// ([`adaptive::NOISE_ALPHA`]) mean of its distance from the median,
    /// and the slow mean of its square: the drift watch (`adaptive::rise`).
    mf: [f32; N],
    ms: [f32; N],
    es: [f32; N],
    /// Per gyro, the quick mean ([`adaptive::GATE_ALPHA`]) of its squared
    /// distance from the median: the gate's floor in a burst.
    ef: [f32; N],
    /// What the last attribution over four or more gyros found: 0 none
    /// yet, 1 independent errors, 2 an error some chips share.
    four: u8,
    /// Offset of the sample count at which the attribution is solved
    /// ([`AxisState::for_axis`]).
    slot: u32,
    /// The last fused sample's learning, if not yet done
    /// ([`AxisState::learn_pending`]).
    pend: Option<adaptive::PendLearn<N>>,
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
            last_used: 0,
            pair: 0,
            pair_power: 0.0,
            pd: [[0.0; N]; N],
            n_pair: [0; N],
            solved: 0,
            gvar: [0.0; N],
            own: [0.0; N],
            mf: [0.0; N],
            ms: [0.0; N],
            es: [0.0; N],
            ef: [0.0; N],
            four: 0,
            slot: 0,
            pend: None,
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
                self.n_pair[i] = 0;
                self.var[i] = 0.0;
                self.gvar[i] = 0.0;
                self.own[i] = 0.0;
                self.mf[i] = 0.0;
                self.ms[i] = 0.0;
                self.es[i] = 0.0;
                self.ef[i] = 0.0;
            }
        }
        self.warm &= !mask;
        self.solved = 0;
    }

    /// The state of board axis `axis` (0 = x) of three: its attribution is
    /// solved on other samples than the other two axes' (solved together,
    /// the three cost the board's loop's worst sample some 1 800
    /// instructions on the Cortex-M4, `cargo xtask bench-loop`).
    pub fn for_axis(axis: usize) -> Self {
        Self {
            slot: (axis as u32 % 3) * 5,
            ..Self::default()
        }
    }

    /// What the last fused sample teaches the adaptive method's noise
    /// model (its pairs, the drift watch's means, the attribution), if it
    /// has not been learnt yet: [`Fusion::fuse`] runs it first, so a
    /// caller that never calls this sees every sample learnt in order; the
    /// board's loop calls it (through `RelCal::finish`) once the frame is
    /// sent, which takes it off the frame's path.
    #[inline]
    pub fn learn_pending(&mut self) {
        if let Some(p) = self.pend.take() {
            adaptive::learn(self, &p);
        }
    }

    /// The last attribution over four or more gyros read a variance below
    /// zero: some chips share an error (two on one arm of a vibrating
    /// frame, a common vibration). The noise probe, a combination whose
    /// coefficients sum to 0, cannot see what the chips share, so its
    /// figure then is the part of the fused error the chips do not share.
    pub fn shared_error(&self) -> bool {
        self.four == 2
    }

    /// The adaptive method's noise variance estimate of gyro `i`, its own
    /// share of the disagreement, (°/s)² (0 before any update or out of
    /// range).
    pub fn noise_var(&self, i: usize) -> f32 {
        self.own.get(i).copied().unwrap_or(0.0)
    }

    /// Current noise standard deviation estimates of the adaptive method,
    /// °/s (NaN before any update).
    pub fn sigma_dps(&self, cfg: &AdaptiveConfig) -> [f32; N] {
        let mut s = [f32::NAN; N];
        for i in 0..N {
            if self.n_upd[i] > 0 {
                s[i] = sqrtf(at_least(self.own[i], cfg.var_floor));
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
            Method::SupportDegree(c) => {
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
        if let Method::SupportDegree(SupportConfig {
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
        st.learn_pending();
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
            Method::SupportDegree(c) => self.seed(c, st, y, valid, &mut out),
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

/// Largest |rate| fusion accepts, °/s: far beyond any gyro's range (the
/// ICM-42688-P saturates at 2000 °/s), small enough that no sum or square
/// of a few of them overflows f32. NaN fails the comparison too.
pub const RATE_LIMIT_DPS: f32 = 1.0e6;

#[cfg(test)]
mod tests;
