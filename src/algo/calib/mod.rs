//! Online relative calibration of an array axis.
//!
//! MEMS gyros differ in scale factor by up to a few per cent. On a board
//! turning at 100 °/s, 1 % is 1 °/s of disagreement between chips, ten times
//! their white noise: a fusion that weights chips by how well they agree
//! reads it as noise and keeps the wrong chips. While the platform moves,
//! each chip is regressed against the array's consensus, the median of
//! this sample's raw readings of the chips fusion trusts (the previous
//! fused rate would lag by 1 °/s per ms at 100 °/s and 2 Hz), with
//! exponential forgetting; the estimate applies from the next sample:
//!
//! `y_i ≈ b_i + s_i · c`, `s_i = (cov(c, y_i) + ρ) / (var(c) + ρ)`,
//! `b_i = ȳ_i − s_i · c̄`,
//!
//! and the corrected reading `(y_i − b_i) / s_i` goes to fusion. The ridge
//! `ρ` (in (°/s)²) pulls `s_i` to 1 when the platform is still, where the
//! scale is unobservable; `s_i` and `b_i` are bounded (a chip outside the
//! bounds is a fault for the health checks, not a calibration). The
//! calibration is relative: it aligns the chips with the median chip and
//! cannot see an error common to all of them (that is the job of the
//! factory calibration).
//!
//! Cost: a median of N and a few multiply-adds per chip per sample; the
//! estimates are solved every 16 samples (`cargo xtask bench` prints it).

mod drift;
#[cfg(test)]
mod tests;

pub use drift::{
    drift_allowance, tracking, LAG_BLOCK_WEIGHT, LAG_FLOOR_DPS, LAG_PERSIST, LAG_SIGMAS,
    LAG_VAR_WEIGHT, MAX_TRACK, ZRO_TEMPCO_BOUND_DPS_PER_C,
};

/// Updates a chip needs before its correction applies (32 ms at 1 kHz).
/// Under motion 32 samples already pin the scale to 10⁻³ (the ridge keeps
/// it at 1 on a still board); with 256, fusion ran the first quarter second
/// on uncorrected chips, which cost 0.8 % of the RMS error over 20 s of a
/// 95 °/s sway with scale errors in ±1 % (`fusion-eval`, class (f)).
pub const WARM: u32 = 32;

/// Samples the growing window restarts from when a chip comes back from
/// a restart with its calibration kept ([`RelCal::resume`]): a time
/// constant of 1 024 samples (1 s at 1 kHz), a quarter of the default 1/α.
pub const RESUME_SAMPLES: u32 = 1024;

/// The estimates are solved every `EVERY` updates (the moments every one).
pub const EVERY: u32 = 32;

/// While a chip warms up, its bias-only correction is solved every
/// `EARLY_EVERY` updates.
pub const EARLY_EVERY: u32 = 4;

/// Robust standard deviations of the chips' biases beyond which a chip
/// is left out of the common reference ([`RelCal::estimate`]).
pub const REF_MADS: f32 = 3.0;

/// Updates per block of [`RelCal::watch_young`].
pub const YOUNG_BLOCK: u32 = 8;

/// [`RelCal::fuse`] learns on one sample in `LEARN_STRIDE`.
pub const LEARN_STRIDE: u32 = 2;

/// Update counts (mod [`EVERY`]) of the three axes' scheduled solves.
/// The pipeline counts samples from 0 and each axis learns on every other
/// one (x and z on even samples, y on odd), so x solves on samples ≡ 10
/// (mod 64), y on ≡ 59 and z on ≡ 62: three different samples, so that
/// the sample task (which learns after each frame is queued, `app`) never
/// runs two solves at once, nor one beside a configuration read-back
/// (`pipeline::CHECK_AT`).
pub const SOLVE_SLOTS: [u32; 3] = [6, 30, 0];

use crate::algo::fusion::{median, noise_probe, AxisState, FuseError, Fused, Fusion};

use crate::algo::math::{at_least, bound};

/// The chips whose reading in `y` is finite (bit i = chip i).
fn finite_mask<const N: usize>(y: &[f32; N]) -> u8 {
    let mut finite = 0u8;
    for (i, v) in y.iter().enumerate() {
        finite |= u8::from(v.is_finite()) << i;
    }
    finite
}

/// Settings of [`RelCal`].
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CalConfig {
    /// Forgetting factor per sample (time constant 1/α samples).
    pub alpha: f32,
    /// Ridge ρ, (°/s)²: the motion variance at which the scale estimate is
    /// half data, half prior.
    pub ridge_dps2: f32,
    /// Bound on |s − 1|.
    pub max_scale: f32,
    /// Bound on |b| against the median chip, °/s: ±10, two chips at the
    /// ±5 °/s that MEMS gyros of a real array show at turn-on (an
    /// eight-chip static rig spans −3 to +3 °/s; the ICM-42688-P's
    /// datasheet states ±0.5 °/s after board-level calibration, so its
    /// parts sit well inside). With ±2 the chips beyond it were read as
    /// they are, their offsets counted as noise, and fusion gave them
    /// almost no weight.
    pub max_bias_dps: f32,
    /// A chip whose bias sits further than this (or [`REF_MADS`] robust
    /// standard deviations of the chips' biases, if more) from the median
    /// chip's is left out of the common reference, °/s
    /// ([`RelCal::estimate`]). For parts whose datasheet bounds their
    /// offset ([`CalConfig::board`]); infinite, the default, for chips
    /// nobody here has described: at rest a chip at 16× its range cannot
    /// be told from a large offset, and a real array's offsets spread over
    /// ±3–5 °/s, where leaving the outer chips out of the reference cost a
    /// static four-chip rig 3 % against the plain mean (`fusion-eval`
    /// (r)) and stepped its fused rate as the verdicts changed.
    pub ref_floor_dps: f32,
}

impl Default for CalConfig {
    fn default() -> Self {
        Self {
            alpha: 1.0 / 4096.0,
            ridge_dps2: 1.0,
            max_scale: 0.05,
            max_bias_dps: 10.0,
            ref_floor_dps: f32::INFINITY,
        }
    }
}

impl CalConfig {
    /// The board's chips (four ICM-42688-P, one ADXRS453): the reference
    /// leaves out a chip 1 °/s or more off the others' median bias, twice
    /// the ICM-42688-P's ±0.5 °/s zero-rate offset after board-level
    /// calibration (datasheet, gyroscope specifications; the ADXRS453's
    /// null accuracy is ±0.4 °/s at 25 °C).
    pub fn board() -> Self {
        Self {
            ref_floor_dps: 1.0,
            ..Self::default()
        }
    }
}

/// Running relative calibration of one axis of `N` chips.
#[derive(Clone, Copy, Debug)]
pub struct RelCal<const N: usize> {
    cfg: CalConfig,
    /// Per chip: forgetting means of the consensus and of the chip, and
    /// the consensus's variance and covariance with the chip.
    mean_c: [f32; N],
    mean_y: [f32; N],
    var_c: [f32; N],
    cov: [f32; N],
    /// The chip's own variance (with `cov` and `var_c`, the regression's
    /// residual: how sure the scale and bias are, [`RelCal::estimate`]).
    var_y: [f32; N],
    started: u8,
    /// Updates since creation (for the estimate's decimation).
    tick: u32,
    /// Chips whose estimate is outside the bounds.
    wild: u8,
    /// Updates per chip (for the growing window).
    n: [u32; N],
    /// Estimates against the median chip: scale and bias.
    scale: [f32; N],
    bias: [f32; N],
    /// Applied correction (against the average chip): bias, 1/scale.
    applied_bias: [f32; N],
    inv_scale: [f32; N],
    /// Chips whose correction is applied, and those whose correction has
    /// just started to apply (their noise estimates are then forgotten).
    applied: u8,
    fresh: u8,
    /// Per chip, what its correction changed when it started to apply
    /// ([`RelCal::change_ms`]).
    fresh_ms: [f32; N],
    /// Chips started but not yet [`WARM`].
    warming: u8,
    /// Which sample of [`LEARN_STRIDE`] [`RelCal::fuse`] is on.
    phase: u8,
    /// The update count's offset for solving (see [`RelCal::for_axis`]).
    slot: u32,
    /// The last fusion's learning, not yet done (see
    /// [`RelCal::fuse_deferred`]), and the raw readings it learns from.
    pending: Pending,
    /// (Kept beside `pending`, not in it: in the enum the copy was a
    /// `memcpy` call, some 30 instructions an axis, on the Cortex-M4.)
    kept: [f32; N],
    /// Parity of the update counts on which a chip that has just warmed
    /// up is solved for.
    warm_parity: u32,
    /// The raw readings of the update before the next solve.
    last_raw: [f32; N],
    /// Samples of the growing window: 1/α (bounded), as an integer.
    grow: u32,
    /// Per chip, the fast mean of the residual y − (b + s·c) against the
    /// calibration, °/s, and the residual's mean square, (°/s)².
    lag: [f32; N],
    lag_ms: [f32; N],
    /// Per chip, this block's sums of the residual and of its square (the
    /// square on learnt updates only), and their count.
    blk_sum: [f32; N],
    blk_sq: [f32; N],
    blk_n: [u8; N],
    /// Per chip, blocks in a row with the lag over its limit.
    over: [u16; N],
    /// Chips outside the bounds a part can have, beyond their estimates'
    /// noise (see [`RelCal::out_of_bounds`]).
    gross: u8,
    /// [`RelCal::watch_young`]'s block sums, sums of squares and counts.
    young_sum: [f32; N],
    young_sq: [f32; N],
    young_n: [u8; N],
    /// Chips whose lag stayed over its limit (see [`RelCal::drifting`]).
    drifting: u8,
    /// The lag a part's bias may leave, °/s (see [`LAG_FLOOR_DPS`]).
    allowance: f32,
    /// How many times faster than α the moments follow (see
    /// [`RelCal::set_temperature_rate`]).
    track: f32,
}

/// What [`RelCal::finish`] has still to do for the last sample fused.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Pending {
    None,
    /// A learning sample fusion refused: counted, nothing learnt.
    Tick,
    /// A learning sample (its raw readings in `RelCal::kept`), the chips
    /// fusion used and those offered to it.
    Learn(u8, u8),
}

impl<const N: usize> RelCal<N> {
    /// A calibration with no estimate yet (every chip as read).
    pub fn new(cfg: CalConfig) -> Self {
        Self {
            cfg,
            mean_c: [0.0; N],
            mean_y: [0.0; N],
            var_c: [0.0; N],
            var_y: [0.0; N],
            cov: [0.0; N],
            started: 0,
            tick: 0,
            wild: 0,
            n: [1; N],
            scale: [1.0; N],
            bias: [0.0; N],
            applied_bias: [0.0; N],
            inv_scale: [1.0; N],
            applied: 0,
            fresh: 0,
            fresh_ms: [0.0; N],
            warming: 0,
            phase: 0,
            slot: 0,
            pending: Pending::None,
            kept: [0.0; N],
            warm_parity: 0,
            last_raw: [f32::NAN; N],
            grow: (1.0 / cfg.alpha.max(1e-6)) as u32,
            lag: [0.0; N],
            lag_ms: [0.0; N],
            blk_sum: [0.0; N],
            blk_sq: [0.0; N],
            blk_n: [0; N],
            over: [0; N],
            gross: 0,
            young_sum: [0.0; N],
            young_sq: [0.0; N],
            young_n: [0; N],
            drifting: 0,
            allowance: LAG_FLOOR_DPS,
            track: 1.0,
        }
    }

    /// The calibration of board axis `axis` (0 = x) of three, with its work
    /// spread against the other two: x and z learn on even samples, y on
    /// odd ones; each solves at its [`SOLVE_SLOTS`], and when a chip has
    /// just warmed up x on even update counts, z on odd ones (which may
    /// wait one update): no sample of the board's loop learns or solves
    /// for all three axes (a learn costs it some 1 100 instructions, a
    /// solve 1 000: `cargo xtask bench`).
    pub fn for_axis(cfg: CalConfig, axis: usize) -> Self {
        let mut c = Self::new(cfg);
        c.phase = (axis % LEARN_STRIDE as usize) as u8;
        c.slot = SOLVE_SLOTS.get(axis).copied().unwrap_or(0);
        c.warm_parity = u32::from(axis == 2);
        c
    }

    /// The corrected readings `(y − b) / s` of every chip.
    #[inline]
    pub fn correct(&self, y: &[f32; N]) -> [f32; N] {
        let mut out = *y;
        for i in 0..N {
            out[i] = (y[i] - self.applied_bias[i]) * self.inv_scale[i];
        }
        out
    }

    /// One calibrated fused sample, in the pipeline's order: fuse the
    /// corrected readings, then learn from the raw `y` of the gyros fusion
    /// used.
    #[inline]
    pub fn fuse(
        &mut self,
        fusion: &Fusion<N>,
        st: &mut AxisState<N>,
        y: &[f32; N],
        offered: u8,
    ) -> Result<Fused<N>, FuseError> {
        self.fuse_probed(fusion, st, y, offered).map(|(f, _)| f)
    }

    /// [`RelCal::fuse`], and the array's noise probe
    /// ([`crate::algo::fusion::noise_probe`]) over the corrected readings
    /// fusion saw, with its weights.
    #[inline]
    pub fn fuse_probed(
        &mut self,
        fusion: &Fusion<N>,
        st: &mut AxisState<N>,
        y: &[f32; N],
        offered: u8,
    ) -> Result<(Fused<N>, Option<f32>), FuseError> {
        let r = self.fuse_deferred(fusion, st, y, offered);
        self.finish(st);
        r
    }

    /// [`RelCal::fuse_probed`] up to the fused value and the probe; what
    /// the calibration learns from the sample (its moments, a solve, a
    /// drift verdict, fusion's noise estimates forgotten for a chip whose
    /// correction starts) waits for [`RelCal::finish`], which must run
    /// before the next fusion (a second `fuse_deferred` runs it first).
    /// The board's loop fuses, sends the frame, then finishes: the same
    /// state in the same order, off the frame's path.
    #[inline]
    pub fn fuse_deferred(
        &mut self,
        fusion: &Fusion<N>,
        st: &mut AxisState<N>,
        y: &[f32; N],
        offered: u8,
    ) -> Result<(Fused<N>, Option<f32>), FuseError> {
        self.finish(st);
        // The calibration learns on every other sample: what it tracks
        // moves over seconds, and the consensus and moments of every
        // sample cost 330 instructions per axis on the Cortex-M4. Its
        // schedule counts samples, fused or not, so that its solves stay
        // on the samples [`RelCal::for_axis`] chose for them.
        let learn_now = self.phase == 0;
        self.phase = (self.phase + 1) % LEARN_STRIDE as u8;
        let seen = self.correct(y);
        // A drifting chip and one outside its part's bounds are faults:
        // not fused. (Fused, a chip 26 °/s off its range, read as is,
        // taught fusion's noise model a variance that took its offset in,
        // and the gate, judging it by that, never left it out.)
        let r = match fusion.fuse(st, &seen, offered & !(self.drifting | self.gross)) {
            Ok(r) => r,
            Err(e) => {
                if learn_now {
                    self.pending = Pending::Tick;
                }
                return Err(e);
            }
        };
        if learn_now {
            self.kept = *y;
            self.pending = Pending::Learn(r.used(), offered);
        }
        Ok((r, noise_probe(&seen, &r)))
    }

    /// Learn from the last sample fused by [`RelCal::fuse_deferred`] (if
    /// it has not yet): `st` is the axis state it was fused with.
    #[inline]
    pub fn finish(&mut self, st: &mut AxisState<N>) {
        // Fusion's own learning first: the calibration's reads what it
        // learnt (`forget_fresh` weighs its change against the noise).
        st.learn_pending();
        if self.pending == Pending::None {
            return;
        }
        self.learn_pending(st);
    }

    /// [`RelCal::finish`] with something to learn: out of line, so that
    /// the check alone is what the fusion's path pays.
    #[inline(never)]
    fn learn_pending(&mut self, st: &mut AxisState<N>) {
        let used = match core::mem::replace(&mut self.pending, Pending::None) {
            Pending::None => return,
            // Unfused: the update is counted, nothing learnt.
            Pending::Tick => {
                self.tick = self.tick.wrapping_add(1);
                return;
            }
            Pending::Learn(used, offered) => (used, offered),
        };
        let y = self.kept;
        self.learn(&y, used.0, used.1 & finite_mask(&y), LEARN_STRIDE);
        // A chip whose correction starts now was judged by fusion on its
        // uncorrected readings: its rate-proportional disagreement sits in
        // its noise estimate. Where what the correction removes is a large
        // part of that estimate, the estimate is forgotten (learnt again
        // from the next sample, as at power-up) rather than left to decay:
        // at 100 °/s, 10 Hz and ±2 % scale errors, decaying cost 0.5 % of
        // the RMS error over 20 s. Where it is small (a still board, small
        // biases) the estimate is kept: a new warm-up has its own cost (no
        // noise model to settle a two-against-two split).
        if self.fresh != 0 {
            self.forget_fresh(st);
        }
    }

    /// Forget the noise estimates of the chips whose correction has just
    /// started to apply (see [`RelCal::fuse`]). Rare, so out of line: kept
    /// inside `fuse` it cost 100 instructions per sample on the Cortex-M4.
    #[cold]
    #[inline(never)]
    fn forget_fresh(&mut self, st: &mut AxisState<N>) {
        let mut forget = false;
        for i in 0..N {
            forget |= self.fresh & (1 << i) != 0 && self.fresh_ms[i] > 0.5 * st.noise_var(i);
        }
        // All of them or none: keeping some inflated estimates beside
        // fresh ones would weight the chips by when they were learnt.
        if forget {
            st.forget_noise(self.fresh);
        }
        self.fresh = 0;
    }

    /// A chip has just become warm (its correction then applies from the
    /// next sample, not from the next scheduled solve). Out of line: only
    /// while some chip is warming up.
    #[cold]
    #[inline(never)]
    fn newly_warm(&mut self) -> bool {
        let mut done = 0u8;
        for i in 0..N {
            if self.warming & (1 << i) != 0 && self.n[i] > WARM {
                done |= 1 << i;
            }
        }
        self.warming &= !done;
        done != 0
    }

    /// Learn from this sample's raw readings `y`, on the chips in `used`
    /// (those fusion trusted: faulty chips must not teach the consensus).
    /// Needs at least three chips in `used`; otherwise nothing changes.
    pub fn update(&mut self, y: &[f32; N], used: u8) {
        let finite = finite_mask(y);
        self.learn(y, used & finite, used & finite, 1);
    }

    /// [`RelCal::update`] for an update that stands for `stride` samples
    /// (the forgetting and the growing window count samples, not updates).
    /// `used` must hold only chips whose `y` is finite: fusion's used
    /// chips are (it takes no value beyond `fusion::RATE_LIMIT_DPS`, and
    /// the correction it saw them through is bounded), and `update` checks
    /// its own. (Checking fusion's again cost the default fusion path 43
    /// instructions a 3-axis sample.)
    fn learn(&mut self, y: &[f32; N], used: u8, voters: u8, stride: u32) {
        // Every update counts, learnt from or not: solves keep their
        // samples.
        self.tick = self.tick.wrapping_add(1);
        // A drifting chip is a fault, not something to learn.
        let mut mask = used & ((1u16 << N) - 1) as u8 & !self.drifting;
        if mask.count_ones() < 3 {
            return;
        }
        // A chip outside its bounds is not fused but still learnt from:
        // its moments are what says it is back within them.
        if self.gross != 0 {
            mask |= self.gross & finite_mask(y) & !self.drifting;
        }
        // The consensus: the median of the raw readings of every chip
        // offered (a faulty minority cannot move a median). Over the chips
        // fusion used this sample only, it jumped by half the offsets
        // between chips whenever the gate left a different chip out (with
        // turn-on offsets of a few °/s, 1.9 °/s at rest), which read as
        // motion and pulled every scale to its bound.
        let voters = voters & ((1u16 << N) - 1) as u8 & !(self.drifting | self.gross);
        let c = median(
            y,
            if voters.count_ones() >= 3 {
                voters
            } else {
                mask
            },
        );
        if self.drifting != 0 {
            self.watch_drifting(y, c);
        }
        // A chip warming up that fusion leaves out (its warm-up gate leaves
        // out a chip far off the others) is not learnt from, so the offset
        // of every chip warming up is watched apart, on every sample it
        // offers ([`RelCal::watch_young`]).
        let young = (!self.started | self.warming) & voters & !self.gross;
        if young != 0 {
            self.watch_young(y, c, young);
        }
        // (Bounded: α = 0 must not count samples until n overflows.)
        let grow = self.grow;
        let step = stride as f32;
        let fixed = self.cfg.alpha * self.track * step;
        for i in 0..N {
            if mask & (1 << i) == 0 {
                continue;
            }
            if self.started & (1 << i) == 0 {
                self.started |= 1 << i;
                self.warming |= 1 << i;
                self.n[i] = stride;
                self.mean_c[i] = c;
                self.mean_y[i] = y[i];
                continue;
            }
            // A growing window until it reaches 1/α samples: the first
            // estimate after a start or a restart is ready in a second
            // rather than a time constant.
            let a = if self.n[i] < grow {
                self.n[i] = self.n[i].saturating_add(stride);
                at_least(step / self.n[i] as f32, fixed)
            } else {
                fixed
            };
            let dc = c - self.mean_c[i];
            let dy = y[i] - self.mean_y[i];
            // The drift watch's residual against the calibration,
            // y − (b + s·c) with b = ȳ − s·c̄ (see [`RelCal::judge`]).
            if self.applied & (1 << i) != 0 {
                let e = dy - self.scale[i] * dc;
                self.blk_sum[i] += e;
                self.blk_sq[i] += e * e;
                self.blk_n[i] = self.blk_n[i].saturating_add(1);
            }
            self.mean_c[i] += a * dc;
            self.mean_y[i] += a * dy;
            self.var_c[i] = (1.0 - a) * (self.var_c[i] + a * dc * dc);
            self.cov[i] = (1.0 - a) * (self.cov[i] + a * dc * dy);
            self.var_y[i] = (1.0 - a) * (self.var_y[i] + a * dy * dy);
        }
        // The estimates move with the 1/α time constant: solving for them
        // every `EVERY` samples halves the cost and changes nothing.
        let t = self.tick.wrapping_sub(self.slot);
        let warm_turn = self.warming != 0 && t % 2 == self.warm_parity && self.newly_warm();
        // While a chip warms up its bias-only correction is solved every
        // [`EARLY_EVERY`] updates: a start-up offset is out of the fused
        // rate within a few samples, not after the first scheduled solve.
        let early = self.warming != 0 && (t < EARLY_EVERY || t.is_multiple_of(EARLY_EVERY));
        if t.is_multiple_of(EVERY) || warm_turn || early {
            self.solve(y, mask);
        } else if t % EVERY == EVERY / 2 {
            self.judge();
        } else if t.wrapping_add(1).is_multiple_of(EVERY) {
            // The readings the next solve compares with (kept only then).
            self.last_raw = *y;
        }
    }

    /// Solve for the estimates (see [`RelCal::estimate`]). A chip whose
    /// reading repeats since the update before keeps its correction too
    /// (as one fusion does not use): a frozen output must stay frozen
    /// through the correction, or fusion's frozen check starts over (a
    /// stuck chip was out after 6 samples, not 3, when a solve fell just
    /// after it stuck: `fusion-eval` (n), seed 3). Out of line: it runs
    /// once per `EVERY` updates.
    #[cold]
    #[inline(never)]
    fn solve(&mut self, y: &[f32; N], used: u8) {
        let mut held = 0u8;
        for i in 0..N {
            held |= u8::from(y[i].to_bits() == self.last_raw[i].to_bits()) << i;
        }
        self.estimate(used & !held);
    }

    /// Scale and bias of every started chip from the moments, then the
    /// correction (against the average chip).
    ///
    /// A chip outside `used` (not trusted by fusion on this sample) keeps
    /// the correction it has: a stuck chip's corrected reading must stay
    /// frozen for fusion to see it frozen. Re-solved with the others, its
    /// correction moved with the array's mean scale, and a stuck chip was
    /// readmitted for ~13 samples per 15 s on a sway (`fusion-eval`, (n)).
    fn estimate(&mut self, used: u8) {
        for i in 0..N {
            if self.started & (1 << i) == 0 {
                continue;
            }
            let r = self.cfg.ridge_dps2;
            let m = self.cfg.max_scale;
            let s = (self.cov[i] + r) / (self.var_c[i] + r);
            let b = self.mean_y[i] - s * self.mean_c[i];
            // Outside the bounds it is no calibration (a wrong range, a
            // chip going bad): such a chip is read as is and kept out of
            // the common reference.
            // Before it is warm only its offset is judged: a few dozen
            // samples at rest say nothing of a scale (with a burst of
            // spikes in the consensus they read 0.04).
            let inside = if self.n[i] > WARM {
                (s - 1.0).abs() <= m && b.abs() <= self.cfg.max_bias_dps
            } else {
                (self.mean_y[i] - self.mean_c[i]).abs() <= self.cfg.max_bias_dps
            };
            if inside {
                self.wild &= !(1 << i);
            } else {
                self.wild |= 1 << i;
            }
            // (Until it is warm, a chip's verdict is [`RelCal::watch_young`]'s.)
            if self.n[i] > WARM {
                if self.is_gross(i, b) {
                    self.gross |= 1 << i;
                } else {
                    self.gross &= !(1 << i);
                }
            }
            // `bound`, not clamp: clamp panics on a bad bound.
            self.scale[i] = bound(s, 1.0 - m, 1.0 + m);
            let bb = self.cfg.max_bias_dps;
            self.bias[i] = bound(b, -bb, bb);
        }
        // Align to the average chip, not the median one: the corrected
        // chips then share the mean scale and bias of the array, as an
        // average of uncalibrated chips would (the median chip alone
        // carries a larger common error).
        // Only chips with `WARM` updates are corrected: a few dozen
        // samples give a scale estimate that is worse than none.
        let warm = |i: usize| self.n[i] > WARM && self.wild & (1 << i) == 0;
        // A chip still warming up is corrected for its bias alone (its
        // offset from the consensus, scale 1): a bias is pinned in a few
        // samples where a scale needs motion. Uncorrected, a turn-on
        // offset of a few °/s sat in the fused rate until the chip warmed
        // up, and the step when it was taken out (and the warm-up's median
        // output before it) raised a static eight-chip rig's fused Allan
        // deviation 1.4–1.9× the plain mean's at τ = 16–64 samples.
        let early =
            |i: usize| self.started & (1 << i) != 0 && !warm(i) && self.wild & (1 << i) == 0;
        // The reference: the average of every corrected chip, warm or
        // early. Over the warm chips alone it jumped by a quarter of an
        // offset (1 °/s) while one chip of four was still early, and the
        // fused rate with it.
        // Each weighed by its updates up to [`WARM`]: a chip a few updates
        // into its warm-up counts little, so that a chip garbling bits
        // from power-up, corrected from its first updates, cannot move
        // every chip's correction with a few samples of garbage (2 °/s at
        // equal weights, `fusion-eval` (l), seed 55555), and a chip that
        // turns warm changes nothing.
        let inref = self.reference_set(&warm, &early);
        let (mut ms, mut mb, mut n) = (0.0f32, 0.0f32, 0.0f32);
        for i in 0..N {
            let k = self.n[i].min(WARM) as f32;
            if inref & (1 << i) == 0 {
                continue;
            }
            if warm(i) {
                ms += k * self.scale[i];
                mb += k * self.bias[i];
                n += k;
            } else if early(i) {
                ms += k;
                mb += k * (self.mean_y[i] - self.mean_c[i]);
                n += k;
            }
        }
        if !(n > 0.0) {
            return;
        }
        let (ms, mb) = (ms / n, mb / n);
        let mut applied = 0u8;
        for i in 0..N {
            if used & (1 << i) == 0 {
                applied |= self.applied & (1 << i);
                continue;
            }
            if warm(i) {
                applied |= 1 << i;
                let (kb, ko) = (self.applied_bias[i], self.inv_scale[i]);
                self.inv_scale[i] = ms / self.scale[i];
                self.applied_bias[i] = self.bias[i] - mb * self.scale[i] / ms;
                if self.applied & (1 << i) == 0 {
                    self.fresh_ms[i] = self.change_ms(i, kb, ko);
                }
            } else if early(i) {
                let b = self.mean_y[i] - self.mean_c[i];
                self.inv_scale[i] = 1.0;
                self.applied_bias[i] = b - mb / ms;
            } else {
                (self.applied_bias[i], self.inv_scale[i]) = (0.0, 1.0);
            }
        }
        self.fresh |= applied & !self.applied;
        self.applied = applied;
    }

    /// The chips that make the common reference: every warm or early chip
    /// but those whose bias (an early chip's offset) sits further from
    /// the median chip's than [`REF_MADS`] robust standard deviations of
    /// the chips' biases (1.4826 · MAD), and at least
    /// [`CalConfig::ref_floor_dps`]: one chip out of line with an array
    /// that agrees. A chip read at 16×
    /// its range (a corrupted configuration, at −0.4 °/s it reads −6)
    /// passes the part's bounds as a 6 °/s offset; in the average it moved
    /// every chip's correction, and the fused rate, by 1.4 °/s until the
    /// configuration check restarted it.
    fn reference_set(&self, warm: &impl Fn(usize) -> bool, early: &impl Fn(usize) -> bool) -> u8 {
        let mut b = [0.0f32; N];
        let mut set = 0u8;
        for i in 0..N {
            if warm(i) {
                b[i] = self.bias[i];
                set |= 1 << i;
            } else if early(i) {
                b[i] = self.mean_y[i] - self.mean_c[i];
                set |= 1 << i;
            }
        }
        if set.count_ones() < 3 || !self.cfg.ref_floor_dps.is_finite() {
            return set;
        }
        let med = median(&b, set);
        let mut dev = [0.0f32; N];
        for i in 0..N {
            dev[i] = (b[i] - med).abs();
        }
        let lim = at_least(
            REF_MADS * 1.4826 * median(&dev, set),
            self.cfg.ref_floor_dps,
        );
        for i in 0..N {
            if dev[i] > lim {
                set &= !(1 << i);
            }
        }
        set
    }

    /// The offset from the consensus `c` of the chips in `young` (warming
    /// up, offered), each sample's clipped at twice the
    /// bias bound so that a spike counts as no more than an offset at it,
    /// over blocks of [`YOUNG_BLOCK`] samples: a block's mean beyond the
    /// bound by 3 of its standard errors makes the chip a fault ([`RelCal::out_of_bounds`]), learnt
    /// from from then on, so that its own moments judge it once warm.
    /// Unwatched, a chip read at 16× its range (26 °/s off at rest) sat out
    /// fusion's warm-up, and then passed fusion's gate on a noise estimate
    /// its own offset had made (its pairs learnt, capped, while it warmed
    /// up), at a weight of 0.0006, while its pairs' noise in the hat gave a
    /// noisy chip 0.7 of the weight and the fused rate was 1.1 °/s off.
    /// A spike, clipped, moves a block's mean by at most 2.5 °/s; a
    /// manoeuvre on a real flight (chips a sample apart, each with its own
    /// vibration) moved one to 11.9 °/s, with a standard error of its own. Out of line: only while a chip warms up left
    /// out.
    #[cold]
    #[inline(never)]
    fn watch_young(&mut self, y: &[f32; N], c: f32, young: u8) {
        let mb = self.cfg.max_bias_dps;
        for i in 0..N {
            if young & (1 << i) == 0 || !y[i].is_finite() {
                continue;
            }
            let d = bound(y[i] - c, -2.0 * mb, 2.0 * mb);
            self.young_sum[i] += d;
            self.young_sq[i] += d * d;
            self.young_n[i] += 1;
            if u32::from(self.young_n[i]) >= YOUNG_BLOCK {
                let n = f32::from(self.young_n[i]);
                let m = self.young_sum[i] / n;
                // Beyond the bound by 3 standard errors of the block's mean.
                let e = m.abs() - mb;
                let var = at_least(self.young_sq[i] / n - m * m, 0.0);
                if e > 0.0 && e * e > 9.0 * var / n {
                    self.gross |= 1 << i;
                }
                (self.young_sum[i], self.young_sq[i], self.young_n[i]) = (0.0, 0.0, 0);
            }
        }
    }

    /// Whether chip `i`, with bias `b` against the median chip, is a fault
    /// to leave out of fusion ([`RelCal::out_of_bounds`]): its bias beyond
    /// the part's bound by more than 3 standard errors of the estimate.
    /// (Its scale is not judged: on the real quadrotor flights each chip's
    /// own vibration, in the consensus too, biases the regression's scale
    /// to 0.85–0.95 in a manoeuvre, 0.1–0.6 in a hover and 1.48 where the
    /// median of chips a sample apart smooths the motion, and the reverse
    /// regression with it; with those chips left out the fusion of three
    /// lost 35 % to the mean. A bracket of both regressions beyond 1.7
    /// left out two chips spiking together at rest, whose spikes moved the
    /// median by half (`fusion-eval` (i): 0.156 against 0.105 °/s). A chip
    /// at a wrong range in motion is the configuration check's.)
    fn is_gross(&self, i: usize, b: f32) -> bool {
        let (_, se_b2) = self.standard_errors(i);
        let eb = b.abs() - self.cfg.max_bias_dps;
        eb > 0.0 && eb * eb > 9.0 * se_b2
    }

    /// Squared standard errors of chip `i`'s scale and bias estimates:
    /// the regression's residual variance over the updates it has
    /// (counted as half its samples, the learning stride, and at most the
    /// window), through the motion (plus the ridge) for the scale, and for
    /// the bias the residual's own plus the scale's error at the mean rate.
    /// Out of line: solves only.
    #[inline(never)]
    fn standard_errors(&self, i: usize) -> (f32, f32) {
        let r = self.cfg.ridge_dps2;
        // (No chip i: nothing is known of it.)
        let (Some(&var_y), Some(&cov), Some(&var_c), Some(&count), Some(&m)) = (
            self.var_y.get(i),
            self.cov.get(i),
            self.var_c.get(i),
            self.n.get(i),
            self.mean_c.get(i),
        ) else {
            return (f32::INFINITY, f32::INFINITY);
        };
        let resid = at_least(var_y - cov * cov / at_least(var_c, f32::MIN_POSITIVE), 0.0);
        let n = at_least(count.min(self.grow) as f32 / LEARN_STRIDE as f32, 1.0);
        let se_s2 = resid / (n * (var_c + r));
        (se_s2, resid / n + se_s2 * m * m)
    }

    /// Mean square of what chip `i`'s correction changes against the one
    /// it had, (bias `kb`, factor `ko`): E[((y − b)k − (y − kb)ko)²] over
    /// the consensus's recent mean and variance, (°/s)². A chip already
    /// corrected for its bias while warming up changes little when its
    /// scale starts to apply on a still board, and keeps its noise model.
    fn change_ms(&self, i: usize, kb: f32, ko: f32) -> f32 {
        let dk = self.inv_scale[i] - ko;
        let db = self.applied_bias[i] * self.inv_scale[i] - kb * ko;
        let m = self.mean_c[i];
        dk * dk * (self.var_c[i] + m * m) - 2.0 * dk * db * m + db * db
    }

    /// Chip `i` is back from a restart: a chip's scale and bias are its
    /// part's, not its configuration's, so a calibration inside the bounds
    /// is kept and applied from the first sample; its moments learn on with
    /// the growing window put back to [`RESUME_SAMPLES`], so that what a
    /// power cycle moved (the turn-on bias repeatability) is relearnt in
    /// about a second rather than the 1/α time constant. Started afresh
    /// (from identity, [`WARM`] updates before it applies), the bias of a
    /// chip back from a fault took some 10 s to come back and the fused
    /// rate carried it meanwhile (`pointing-eval`, docs/pointing.md). A
    /// calibration outside the bounds, or not yet applied, is no
    /// calibration, and a drifting chip's was following its fault: the chip
    /// starts afresh ([`RelCal::reset`]).
    pub fn resume(&mut self, i: usize) {
        if i >= N {
            return;
        }
        let bit = 1u8 << i;
        if (self.wild | self.gross | self.drifting) & bit != 0 || self.applied & bit == 0 {
            self.reset(i);
            return;
        }
        self.n[i] = self.n[i].min(RESUME_SAMPLES);
    }

    /// Chip `i` was found frozen (stuck or saturated) while some chip was
    /// still warming up: each warming chip's early bias was taken against a
    /// median the frozen chip was part of (two chips frozen from power-up
    /// pull a four-chip median halfway, and the healthy pair kept a common
    /// correction of 2–4 °/s, learning nothing more with two chips left:
    /// the timed fault campaign, seeds 2598, 2664 and 4750). So the frozen
    /// chip and every chip still warming start their warm-up again against
    /// the chips left. Once every chip is warm, nothing changes: a median
    /// of warm chips is not moved by one frozen minority within the
    /// 20 samples the stuck check takes.
    pub fn drop_frozen(&mut self, i: usize) {
        if self.warming == 0 || i >= N {
            return;
        }
        let warming = self.warming;
        self.reset(i);
        for j in 0..N {
            if warming & (1 << j) != 0 {
                self.reset(j);
            }
        }
    }

    /// Forget chip `i` (after a restart): it is read as is until it has
    /// [`WARM`] updates again.
    pub fn reset(&mut self, i: usize) {
        if i < N {
            self.started &= !(1 << i);
            self.wild &= !(1 << i);
            self.gross &= !(1 << i);
            (self.young_sum[i], self.young_sq[i], self.young_n[i]) = (0.0, 0.0, 0);
            self.n[i] = 1;
            (self.mean_c[i], self.mean_y[i], self.var_c[i], self.cov[i]) = (0.0, 0.0, 0.0, 0.0);
            self.var_y[i] = 0.0;
            (self.scale[i], self.bias[i]) = (1.0, 0.0);
            (self.applied_bias[i], self.inv_scale[i]) = (0.0, 1.0);
            self.applied &= !(1 << i);
            self.fresh &= !(1 << i);
            self.warming &= !(1 << i);
            (self.lag[i], self.lag_ms[i], self.over[i]) = (0.0, 0.0, 0);
            (self.blk_sum[i], self.blk_sq[i], self.blk_n[i]) = (0.0, 0.0, 0);
            self.drifting &= !(1 << i);
        }
    }

    /// Chips whose scale or bias against the median chip is outside the
    /// bounds a part can have (`CalConfig::max_scale`, `max_bias_dps`;
    /// before a chip is warm, its offset alone): a wrong range or a chip
    /// gone bad. Such a chip is read as is, left out of fusion and of the
    /// common reference, and still learnt from, so that it rejoins when
    /// its moments are back inside (or when a restart starts its
    /// calibration over, [`RelCal::resume`]); the pipeline flags it
    /// (`pipeline::flag::CAL_BOUNDS`).
    pub fn out_of_bounds(&self) -> u8 {
        self.gross
    }

    /// Current scale estimates `s_i` against the median chip (1: as read).
    pub fn scale(&self) -> [f32; N] {
        self.scale
    }

    /// Current bias estimates `b_i` against the median chip, °/s.
    pub fn bias(&self) -> [f32; N] {
        self.bias
    }
}
