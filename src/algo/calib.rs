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

/// [`RelCal::fuse`] learns on one sample in `LEARN_STRIDE`.
pub const LEARN_STRIDE: u32 = 2;

/// Update counts (mod [`EVERY`]) of the three axes' scheduled solves.
/// The pipeline counts samples from 0 and each axis learns on every other
/// one (x and z on even samples, y on odd), so x solves on samples ≡ 10
/// (mod 64), y on ≡ 59 and z on ≡ 62: samples ≡ 10, 27 and 30 (mod 32),
/// where the E-DAVARs, whose frames are on the same 32-sample grid
/// (`pipeline::tracker`), cost least (1 558, 1 540 and 1 662 instructions
/// for the three axes against up to 2 630; `cargo xtask bench`'s whole
/// loop); a solve on the tracker's segmentation start makes the loop's
/// worst sample.
pub const SOLVE_SLOTS: [u32; 3] = [6, 30, 0];

/// The drift watch (see [`RelCal::drifting`]) sums each chip's residual
/// over the [`EVERY`] updates between two of its checks; its lag is an
/// exponential mean of those block means with weight 1/2 (a time constant
/// of two blocks, 128 samples at [`LEARN_STRIDE`] 2).
pub const LAG_BLOCK_WEIGHT: f32 = 0.5;

/// The weight per block of the residual's mean square (the watch's noise
/// level), 1/32 (about 2 s).
pub const LAG_VAR_WEIGHT: f32 = 1.0 / 32.0;

/// Standard deviations of the fast mean's own noise a lag must exceed.
pub const LAG_SIGMAS: f32 = 6.0;

/// The lag, °/s, that a part's bias moving as fast as it physically can
/// leaves behind the calibration at a steady die temperature: the
/// calibration follows a bias ramp of rate r at r/α = 4.1 s behind
/// (α = 1/4096 a sample), and the ICM-42688-P's zero-rate output moves
/// ±0.005 °/s/°C (datasheet, ZRO variation over temperature): at 1 °C/s, a
/// fast warm-up, 0.02 °/s. The die temperature's own rate raises it
/// ([`RelCal::set_temperature_rate`]).
pub const LAG_FLOOR_DPS: f32 = 0.02;

/// A bound on how fast a part's zero-rate output moves with its die
/// temperature, °/s per °C: ten times the ICM-42688-P's typical ±0.005
/// (datasheet, ZRO variation over temperature, for which no maximum is
/// given), so that no part within its type is called drifting while its
/// die warms; at a steady temperature only [`LAG_FLOOR_DPS`] is allowed.
pub const ZRO_TEMPCO_BOUND_DPS_PER_C: f32 = 0.05;

/// The lag that two parts' biases moving apart as fast as
/// [`ZRO_TEMPCO_BOUND_DPS_PER_C`] allows, with the die temperature
/// changing at `temp_rate_c_per_s`, leave behind a calibration of `cfg`'s
/// time constant at `sample_us`: 2 · bound · rate · τ (τ = 1/α samples; a
/// calibration [`tracking`] k times faster leaves 1/k of it).
pub fn drift_allowance(cfg: &CalConfig, temp_rate_c_per_s: f32, sample_us: u32) -> f32 {
    let tau_s = sample_us as f32 * 1e-6 / at_least(cfg.alpha, 1e-6);
    2.0 * ZRO_TEMPCO_BOUND_DPS_PER_C * temp_rate_c_per_s.abs() * tau_s
}

/// The most [`RelCal::set_temperature_rate`] speeds the calibration up.
pub const MAX_TRACK: f32 = 8.0;

/// How many times faster than α the calibration follows while the die
/// temperature changes at `c_per_s`: 1 at a steady temperature, twice at
/// 0.25 °C/s, [`MAX_TRACK`] from 1.75 °C/s.
pub fn tracking(c_per_s: f32) -> f32 {
    let k = 1.0 + c_per_s.abs() / 0.25;
    if k < MAX_TRACK {
        k
    } else {
        MAX_TRACK
    }
}

/// Blocks of [`EVERY`] updates in a row over the limit before a chip is
/// drifting (0.5 s at stride 2): a scale that a turn reveals after a still
/// start (its ridge held it at 1) leaves a residual of |s − 1|·|c| until
/// the regression has it, some 0.3 s; a bias drifting at 0.1 °/s per second
/// leaves a lag that only grows.
pub const LAG_PERSIST: u16 = 8;

use crate::algo::fusion::{median, noise_probe, AxisState, FuseError, Fused, Fusion};
use crate::algo::math::{at_least, bound};

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
    /// Bound on |b|, °/s.
    pub max_bias_dps: f32,
}

impl Default for CalConfig {
    fn default() -> Self {
        Self {
            alpha: 1.0 / 4096.0,
            ridge_dps2: 1.0,
            max_scale: 0.05,
            max_bias_dps: 2.0,
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
    /// Chips started but not yet [`WARM`].
    warming: u8,
    /// Which sample of [`LEARN_STRIDE`] [`RelCal::fuse`] is on.
    phase: u8,
    /// The update count's offset for solving (see [`RelCal::for_axis`]).
    slot: u32,
    /// The last [`RelCal::fuse`] solved for the estimates.
    solved: bool,
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
    /// Chips whose lag stayed over its limit (see [`RelCal::drifting`]).
    drifting: u8,
    /// The lag a part's bias may leave, °/s (see [`LAG_FLOOR_DPS`]).
    allowance: f32,
    /// How many times faster than α the moments follow (see
    /// [`RelCal::set_temperature_rate`]).
    track: f32,
}

impl<const N: usize> RelCal<N> {
    /// A calibration with no estimate yet (every chip as read).
    pub fn new(cfg: CalConfig) -> Self {
        Self {
            cfg,
            mean_c: [0.0; N],
            mean_y: [0.0; N],
            var_c: [0.0; N],
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
            warming: 0,
            phase: 0,
            slot: 0,
            solved: false,
            warm_parity: 0,
            last_raw: [f32::NAN; N],
            grow: (1.0 / cfg.alpha.max(1e-6)) as u32,
            lag: [0.0; N],
            lag_ms: [0.0; N],
            blk_sum: [0.0; N],
            blk_sq: [0.0; N],
            blk_n: [0; N],
            over: [0; N],
            drifting: 0,
            allowance: LAG_FLOOR_DPS,
            track: 1.0,
        }
    }

    /// The calibration of board axis `axis` (0 = x) of three, with its work
    /// spread against the other two: x and z learn on even samples, y on
    /// odd ones; each solves at its [`SOLVE_SLOTS`], and when a chip has
    /// just warmed up x on even update counts, z on odd ones (which may
    /// wait one update). Started together, the three learnt and solved on
    /// the same samples: in the board's loop those samples cost 1 100 more
    /// (learning) and 1 000 more (solving) than the others (`cargo xtask
    /// bench`).
    pub fn for_axis(cfg: CalConfig, axis: usize) -> Self {
        let mut c = Self::new(cfg);
        c.phase = (axis % LEARN_STRIDE as usize) as u8;
        c.slot = SOLVE_SLOTS.get(axis).copied().unwrap_or(0);
        c.warm_parity = u32::from(axis == 2);
        c
    }

    /// Whether the last [`RelCal::fuse`] solved for the estimates (about
    /// 400 instructions on the Cortex-M4, N = 5): the pipeline reports such
    /// samples as busy.
    pub fn solved(&self) -> bool {
        self.solved
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
        // The calibration learns on every other sample: what it tracks
        // moves over seconds, and the consensus and moments of every
        // sample cost 330 instructions per axis on the Cortex-M4. Its
        // schedule counts samples, fused or not, so that its solves stay
        // on the samples [`RelCal::for_axis`] chose for them.
        let learn_now = self.phase == 0;
        self.phase = (self.phase + 1) % LEARN_STRIDE as u8;
        self.solved = false;
        let seen = self.correct(y);
        let r = match fusion.fuse(st, &seen, offered & !self.drifting) {
            Ok(r) => r,
            Err(e) => {
                if learn_now {
                    self.tick = self.tick.wrapping_add(1);
                }
                return Err(e);
            }
        };
        if learn_now {
            self.learn(y, r.used(), LEARN_STRIDE);
        }
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
        Ok((r, noise_probe(&seen, &r)))
    }

    /// Forget the noise estimates of the chips whose correction has just
    /// started to apply (see [`RelCal::fuse`]). Rare, so out of line: kept
    /// inside `fuse` it cost 100 instructions per sample on the Cortex-M4.
    #[cold]
    #[inline(never)]
    fn forget_fresh(&mut self, st: &mut AxisState<N>) {
        let mut forget = false;
        for i in 0..N {
            forget |= self.fresh & (1 << i) != 0 && self.removed_ms(i) > 0.5 * st.noise_var(i);
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
        let mut finite = 0u8;
        for (i, v) in y.iter().enumerate() {
            finite |= u8::from(v.is_finite()) << i;
        }
        self.learn(y, used & finite, 1);
    }

    /// [`RelCal::update`] for an update that stands for `stride` samples
    /// (the forgetting and the growing window count samples, not updates).
    /// `used` must hold only chips whose `y` is finite: fusion's used
    /// chips are (it takes no value beyond `fusion::RATE_LIMIT_DPS`, and
    /// the correction it saw them through is bounded), and `update` checks
    /// its own. (Checking fusion's again cost the default fusion path 43
    /// instructions a 3-axis sample.)
    fn learn(&mut self, y: &[f32; N], used: u8, stride: u32) {
        // Every update counts, learnt from or not: solves keep their
        // samples.
        self.tick = self.tick.wrapping_add(1);
        // A drifting chip is a fault, not something to learn.
        let mask = used & ((1u16 << N) - 1) as u8 & !self.drifting;
        if mask.count_ones() < 3 {
            return;
        }
        let c = median(y, mask);
        if self.drifting != 0 {
            self.watch_drifting(y, c);
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
        }
        // The estimates move with the 1/α time constant: solving for them
        // every `EVERY` samples halves the cost and changes nothing.
        let t = self.tick.wrapping_sub(self.slot);
        let warm_turn = self.warming != 0 && t % 2 == self.warm_parity && self.newly_warm();
        if t.is_multiple_of(EVERY) || warm_turn {
            self.solved = true;
            self.solve(y, mask);
        } else if t % EVERY == EVERY / 2 {
            self.judge();
        } else if t.wrapping_add(1).is_multiple_of(EVERY) {
            // The readings the next solve compares with (kept only then).
            self.last_raw = *y;
        }
    }

    /// The drift watch's residual of the drifting chips with a reading, one
    /// update: left out of learning, each is watched against the
    /// calibration it had (b + s·c) until it is back. (The chips learnt
    /// from have theirs summed in [`RelCal::learn`]'s loop, y − ȳ − s·(c − c̄),
    /// against the calibration as its means stand: the same at a solve,
    /// and the moments' own terms.) A sample fusion rejected (a spike) says
    /// nothing of the bias and is not summed.
    #[cold]
    #[inline(never)]
    fn watch_drifting(&mut self, y: &[f32; N], c: f32) {
        for i in 0..N {
            if self.drifting & (1 << i) == 0 || !y[i].is_finite() {
                continue;
            }
            let e = y[i] - (self.bias[i] + self.scale[i] * c);
            self.blk_sum[i] += e;
            self.blk_n[i] = self.blk_n[i].saturating_add(1);
        }
    }

    /// One block of the drift watch: each chip's lag (the exponential mean
    /// of its block means) against its limit, |lag| > allowance + K·σ_lag
    /// with σ_lag² = ms / (3·block) (a block mean's variance, through an
    /// exponential mean of weight 1/2), without a square root. The noise
    /// level is the residual's whole mean square on used samples: a chip
    /// that is only noisier (spikes of either sign) raises its own bar,
    /// and a drift's lag, in it too, lowers the watch's reach by at most
    /// √2. At most a minority of the chips is drifting: the residuals are
    /// against their median.
    #[cold]
    #[inline(never)]
    fn judge(&mut self) {
        let allow = self.allowance;
        let most = self.applied.count_ones().div_ceil(2);
        for i in 0..N {
            let bit = 1u8 << i;
            let n = self.blk_n[i];
            let (sum, sq) = (self.blk_sum[i], self.blk_sq[i]);
            (self.blk_sum[i], self.blk_sq[i], self.blk_n[i]) = (0.0, 0.0, 0);
            if n == 0 {
                continue;
            }
            // (A drifting chip's updates sum no squares: its noise level
            // stays what it was.)
            if self.drifting & bit == 0 {
                self.lag_ms[i] += LAG_VAR_WEIGHT * (sq / f32::from(n) - self.lag_ms[i]);
            }
            let lag = self.lag[i] + LAG_BLOCK_WEIGHT * (sum / f32::from(n) - self.lag[i]);
            self.lag[i] = lag;
            let k2 = LAG_SIGMAS * LAG_SIGMAS / (3.0 * f32::from(n));
            let ex = lag.abs() - allow;
            if ex > 0.0 && ex * ex > k2 * self.lag_ms[i] {
                self.over[i] = self.over[i].saturating_add(1);
                if self.over[i] >= LAG_PERSIST && (self.drifting | bit).count_ones() < most {
                    self.drifting |= bit;
                }
            } else {
                self.over[i] = 0;
                if ex <= 0.0 {
                    // Back within what its part's bias can do.
                    self.drifting &= !bit;
                }
            }
        }
    }

    /// Chips whose residual against their calibration has stayed further
    /// from zero than their part's bias can move it ([`LAG_FLOOR_DPS`],
    /// raised by [`RelCal::set_temperature_rate`]) plus [`LAG_SIGMAS`] of
    /// its own noise, for [`LAG_PERSIST`] blocks of [`EVERY`] updates: a
    /// chip failing slowly
    /// (its bias drifting far faster than temperature moves a part's),
    /// which the calibration would otherwise follow and fusion keep. Such
    /// a chip is left out of fusion ([`RelCal::fuse`]) and of the
    /// calibration's learning until its residual is back within the
    /// allowance; the pipeline flags it (`pipeline::flag::CAL_DRIFT`).
    pub fn drifting(&self) -> u8 {
        self.drifting
    }

    /// The die temperature's rate of change, °C/s (the fastest chip's,
    /// as the pipeline reads it), at `sample_us` a sample. While the die
    /// warms or cools the parts' biases move with it, each at its own
    /// slope, so the moments follow up to [`MAX_TRACK`] times faster
    /// ([`tracking`]: without it, a 20 → 60 °C ramp in 20 s with slopes in
    /// ±0.02 °/s/°C left four equal chips 4.7 % worse than their plain
    /// mean, `fusion-eval` (k); 8× faster, 0.1 %), and the drift watch
    /// allows the lag that two parts' biases moving apart as fast as
    /// [`ZRO_TEMPCO_BOUND_DPS_PER_C`] leave behind that faster calibration
    /// ([`drift_allowance`], at least [`LAG_FLOOR_DPS`]).
    pub fn set_temperature_rate(&mut self, c_per_s: f32, sample_us: u32) {
        self.track = tracking(c_per_s);
        let dps = drift_allowance(&self.cfg, c_per_s, sample_us) / self.track;
        self.allowance = at_least(dps, LAG_FLOOR_DPS);
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
            // Outside the bounds it is a fault (a wrong range, a chip
            // going bad), not a calibration: such a chip is read as is and
            // kept out of the common reference.
            let inside = (s - 1.0).abs() <= m && b.abs() <= self.cfg.max_bias_dps;
            if inside {
                self.wild &= !(1 << i);
            } else {
                self.wild |= 1 << i;
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
        let (mut ms, mut mb, mut n) = (0.0f32, 0.0f32, 0.0f32);
        for i in 0..N {
            if warm(i) {
                ms += self.scale[i];
                mb += self.bias[i];
                n += 1.0;
            }
        }
        if n > 0.0 {
            let (ms, mb) = (ms / n, mb / n);
            let mut applied = 0u8;
            for i in 0..N {
                if used & (1 << i) == 0 {
                    applied |= self.applied & (1 << i);
                    continue;
                }
                if warm(i) {
                    applied |= 1 << i;
                    self.inv_scale[i] = ms / self.scale[i];
                    self.applied_bias[i] = self.bias[i] - mb * self.scale[i] / ms;
                } else {
                    (self.applied_bias[i], self.inv_scale[i]) = (0.0, 1.0);
                }
            }
            self.fresh |= applied & !self.applied;
            self.applied = applied;
        }
    }

    /// Mean square of what the correction removes from chip `i`'s readings,
    /// `E[(y − (y − b)/s)²]` over the consensus's recent mean and variance,
    /// (°/s)².
    fn removed_ms(&self, i: usize) -> f32 {
        let (k, b) = (
            1.0 - self.inv_scale[i],
            self.applied_bias[i] * self.inv_scale[i],
        );
        let m = self.mean_c[i];
        k * k * (self.var_c[i] + m * m) + 2.0 * k * b * m + b * b
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
        if (self.wild | self.drifting) & bit != 0 || self.applied & bit == 0 {
            self.reset(i);
            return;
        }
        self.n[i] = self.n[i].min(RESUME_SAMPLES);
    }

    /// Forget chip `i` (after a restart): it is read as is until it has
    /// [`WARM`] updates again.
    pub fn reset(&mut self, i: usize) {
        if i < N {
            self.started &= !(1 << i);
            self.wild &= !(1 << i);
            self.n[i] = 1;
            (self.mean_c[i], self.mean_y[i], self.var_c[i], self.cov[i]) = (0.0, 0.0, 0.0, 0.0);
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

    /// Current scale estimates `s_i` against the median chip (1: as read).
    pub fn scale(&self) -> [f32; N] {
        self.scale
    }

    /// Current bias estimates `b_i` against the median chip, °/s.
    pub fn bias(&self) -> [f32; N] {
        self.bias
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emu::Rng;

    /// Four chips with scale errors of +1/−1/+1.5/−2 % and biases on a
    /// 95 °/s, 2 Hz sway: after 10 s the corrected chips agree with each
    /// other to within their noise, the estimates are within 0.1 % of the
    /// true relative scale, and a still board leaves the scales at 1.
    #[test]
    fn scale_and_bias_are_learnt_under_motion_and_left_alone_when_still() {
        let scale = [1.01f32, 0.99, 1.015, 0.98];
        let bias = [0.2f32, -0.1, 0.0, 0.3];
        let mut rng = Rng::new(3);
        let mut cal = RelCal::<4>::new(CalConfig::default());
        let mut spread = 0.0f64;
        let n = 20_000;
        for k in 0..n {
            let w = 95.0 * libm::sinf(2.0 * core::f32::consts::PI * 2.0 * k as f32 * 1e-3);
            let y = [0, 1, 2, 3].map(|i| scale[i] * w + bias[i] + 0.09 * rng.gaussian());
            let c = cal.correct(&y);
            if k >= n - 5000 {
                let m = c.iter().sum::<f32>() / 4.0;
                spread += c.iter().map(|v| ((v - m) as f64).powi(2)).sum::<f64>() / 3.0;
            }
            cal.update(&y, 0b1111);
        }
        let spread = (spread / 5000.0).sqrt();
        assert!(spread < 0.12, "spread {spread}");
        // Relative to the median chip's scale (the mean of 1.01 and 0.99).
        let s = cal.scale();
        for i in 0..4 {
            assert!((s[i] - scale[i]).abs() < 1e-3, "{s:?}");
        }
        let mut still = RelCal::<4>::new(CalConfig::default());
        for _ in 0..20_000 {
            let y = [0, 1, 2, 3].map(|i| scale[i] * 5.0 + bias[i] + 0.09 * rng.gaussian());
            still.update(&y, 0b1111);
        }
        assert!(
            still.scale().iter().all(|s| (s - 1.0).abs() < 0.01),
            "{:?}",
            still.scale()
        );
    }

    /// A chip reading NaN or ±∞ teaches the calibration nothing, whether
    /// the caller says it was used (`update`) or fusion decides (`fuse`):
    /// the estimates stay finite and the same as without the bad chip's
    /// samples, which are the only difference between the two runs.
    #[test]
    fn non_finite_readings_are_not_learnt() {
        use crate::algo::fusion::{AdaptiveConfig, AxisState, Fusion, Method};
        let f = Fusion::<4>::new(Method::Adaptive(AdaptiveConfig::default())).unwrap();
        let mut rng = Rng::new(9);
        let (mut a, mut b) = (
            RelCal::<4>::new(CalConfig::default()),
            RelCal::<4>::new(CalConfig::default()),
        );
        let (mut c, mut d) = (a, b);
        let (mut sc, mut sd) = (AxisState::<4>::default(), AxisState::<4>::default());
        for k in 0..6000 {
            let w = 80.0 * libm::sinf(k as f32 * 0.01);
            let y = [1.01f32, 0.99, 1.0, 1.02].map(|s| s * w + 0.05 * rng.gaussian());
            let bad = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY][k % 3];
            let mut z = y;
            z[3] = if k % 7 == 0 { bad } else { y[3] };
            // update: the caller marks all four used; the bad samples of
            // chip 3 are the same as leaving it out of `used`.
            a.update(&z, 0b1111);
            b.update(&y, if k % 7 == 0 { 0b0111 } else { 0b1111 });
            // fuse: fusion rejects the bad value itself.
            let _ = c.fuse(&f, &mut sc, &z, 0b1111);
            let _ = d.fuse(&f, &mut sd, &y, if k % 7 == 0 { 0b0111 } else { 0b1111 });
        }
        for (x, y) in [(&a, &b), (&c, &d)] {
            assert!(x.scale().iter().chain(&x.bias()).all(|v| v.is_finite()));
            assert_eq!(x.scale(), y.scale());
            assert_eq!(x.bias(), y.bias());
        }
        // Against the average chip (scale 1.005).
        assert!(
            (a.scale()[3] - 1.02 / 1.005).abs() < 2e-3,
            "{:?}",
            a.scale()
        );
    }

    /// Under a 100 °/s, 10 Hz motion with scale errors of ±2 %, fusion
    /// first learns the uncorrected disagreement (about 2 °/s) as noise.
    /// Once the correction applies, those estimates are forgotten and
    /// learnt again: 1000 samples later every σ estimate is within 30 % of
    /// the true 0.09 °/s (left to decay at 1/256 per sample, they would
    /// still be several times too large), and the fused error is at the
    /// noise level.
    #[test]
    fn noise_learnt_before_the_correction_is_forgotten() {
        use crate::algo::fusion::{AdaptiveConfig, AxisState, Fusion, Method};
        let cfg = AdaptiveConfig::default();
        let f = Fusion::<4>::new(Method::Adaptive(cfg)).unwrap();
        let mut st = AxisState::<4>::default();
        let scale = [1.02f32, 0.98, 1.015, 0.985];
        let mut rng = Rng::new(11);
        let mut cal = RelCal::<4>::new(CalConfig::default());
        let mut se = 0.0f64;
        let mut peak = 0.0f32;
        for k in 0..1000 {
            let w = 100.0 * libm::sinf(2.0 * core::f32::consts::PI * 10.0 * k as f32 * 1e-3);
            let y = [0, 1, 2, 3].map(|i| scale[i] * w + 0.09 * rng.gaussian());
            let r = cal.fuse(&f, &mut st, &y, 0b1111).unwrap();
            if k == 30 {
                peak = st.sigma_dps(&cfg).iter().fold(0.0, |m, s| m.max(*s));
            }
            if k >= 500 {
                // Against the chips' mean scale (what the calibration keeps).
                se += ((r.rate_dps - w * 1.0) as f64).powi(2);
            }
        }
        assert!(
            peak > 0.5,
            "the uncorrected disagreement was learnt: {peak}"
        );
        let s = st.sigma_dps(&cfg);
        assert!(s.iter().all(|s| (s / 0.09 - 1.0).abs() < 0.3), "{s:?}");
        let rms = (se / 500.0).sqrt();
        assert!(rms < 0.07, "fused rms {rms}");
    }
    /// A chip fusion no longer uses (stuck) keeps its correction while the
    /// others' estimates move: its corrected reading stays frozen, so
    /// fusion's frozen-output check keeps it out.
    #[test]
    fn an_unused_chip_keeps_its_correction() {
        let scale = [1.01f32, 0.99, 1.015, 0.98];
        let mut rng = Rng::new(9);
        let mut cal = RelCal::<4>::new(CalConfig::default());
        let w = |k: usize| 30.0 * libm::sinf(2.0 * core::f32::consts::PI * k as f32 * 1e-3);
        for k in 0..3000 {
            let y = [0, 1, 2, 3].map(|i| scale[i] * w(k) + 0.09 * rng.gaussian());
            cal.update(&y, 0b1111);
        }
        let held = 7.5f32;
        let first = cal.correct(&[held, 0.0, 0.0, 0.0])[0];
        for k in 3000..6000 {
            let mut y = [0, 1, 2, 3]
                .map(|i| scale[i] * w(k) * (1.0 + 2e-3 * i as f32) + 0.09 * rng.gaussian());
            y[0] = held;
            cal.update(&y, 0b1110);
            assert_eq!(cal.correct(&y)[0], first, "sample {k}");
        }
    }
    /// A chip that sticks is out of fusion within 5 samples whatever the
    /// phase of the calibration's re-solve (every offset of its 64-sample
    /// cycle tried): a repeated raw reading keeps its corrected value.
    #[test]
    fn a_stuck_chip_is_out_quickly_at_every_solve_phase() {
        use crate::algo::fusion::{AdaptiveConfig, AxisState, Fusion, Method};
        let f = Fusion::<3>::new(Method::Adaptive(AdaptiveConfig::default())).unwrap();
        let scale = [1.01f32, 0.99, 1.005];
        let mut worst = 0;
        for offset in 0..64 {
            let mut st = AxisState::<3>::default();
            st.set_noise_priors([Some(0.09); 3]);
            let mut cal = RelCal::<3>::new(CalConfig::default());
            let mut rng = Rng::new(100 + offset as u64);
            let stick = 3000 + offset;
            let mut held = 0.0f32;
            let mut out_after = None;
            for k in 0..stick + 20 {
                let w = 20.0 * libm::sinf(2.0 * core::f32::consts::PI * k as f32 * 1e-3);
                // Quantised as the ICM-42688-P's 131 LSB/°/s.
                let mut y = [0, 1, 2]
                    .map(|i| libm::roundf((scale[i] * w + 0.09 * rng.gaussian()) * 131.0) / 131.0);
                if k == stick {
                    held = y[0];
                }
                if k >= stick {
                    y[0] = held;
                }
                let r = cal.fuse(&f, &mut st, &y, 0b111).unwrap();
                if k >= stick && out_after.is_none() && r.weights[0] == 0.0 {
                    out_after = Some(k - stick);
                }
            }
            assert!(
                out_after.is_some_and(|n| n <= 5),
                "offset {offset}: {out_after:?}"
            );
            worst = worst.max(out_after.unwrap_or(99));
        }
        println!("stuck chip out after at most {worst} samples");
    }

    /// The drift watch on the pipeline's path (`fuse`, adaptive fusion),
    /// four chips, `scale` errors, a true rate `w(k)` (1 kHz), and chip 2's
    /// bias ramping at `drift` °/s per s from 5 s: the first sample from
    /// which chip 2 is drifting to the end (none: never), and whether any
    /// other chip ever was; the last fused weight of chip 2.
    fn watch_run(
        scale: [f32; 4],
        drift: f32,
        temp_rate: f32,
        w: impl Fn(usize) -> f32,
    ) -> (Option<usize>, bool, f32) {
        use crate::algo::fusion::{AdaptiveConfig, AxisState, Fusion, Method};
        let f = Fusion::<4>::new(Method::Adaptive(AdaptiveConfig::default())).unwrap();
        let mut st = AxisState::<4>::default();
        let mut cal = RelCal::<4>::new(CalConfig::default());
        cal.set_temperature_rate(temp_rate, 1000);
        let mut rng = Rng::new(21);
        let (mut since, mut others, mut weight) = (None, false, 0.0);
        for k in 0..15_000 {
            let d = if k >= 5000 {
                drift * (k - 5000) as f32 * 1e-3
            } else {
                0.0
            };
            let y = [0, 1, 2, 3].map(|i| {
                let v = scale[i] * w(k) + 0.06 * rng.gaussian() + if i == 2 { d } else { 0.0 };
                libm::roundf(v * 131.0) / 131.0
            });
            let r = cal.fuse(&f, &mut st, &y, 0b1111).unwrap();
            weight = r.weights[2];
            if cal.drifting() & 0b100 != 0 {
                since.get_or_insert(k);
            } else {
                since = None;
            }
            others |= cal.drifting() & !0b100 != 0;
        }
        (since, others, weight)
    }

    /// A chip drifting at 0.1 °/s per second from 5 s (its 0.18 °/s, 3σ of
    /// its noise, at 6.8 s) is called drifting within 2 s of reaching 3σ,
    /// stays so, and leaves fusion; no other chip is, at rest or under a
    /// sway with scale errors.
    #[test]
    fn a_drifting_chip_is_caught_and_left_out() {
        let sway = |k: usize| 30.0 * libm::sinf(2.0 * core::f32::consts::PI * k as f32 * 1e-3);
        for (scale, w) in [
            ([1.0f32; 4], &(|_| 0.0f32) as &dyn Fn(usize) -> f32),
            ([1.01, 0.99, 1.005, 0.985], &sway),
        ] {
            let (since, others, weight) = watch_run(scale, 0.1, 0.0, w);
            assert!(since.is_some_and(|k| k < 8800), "{since:?}");
            println!("drifting from sample {since:?}");
            assert!(!others);
            assert_eq!(weight, 0.0);
        }
    }

    /// No chip is called drifting when none drifts: a scale error of 2 %
    /// that a 100 °/s turn reveals after 5 s on a still board (the ridge
    /// held the scale at 1), and a chip drifting at 0.1 °/s per second while
    /// the die temperature moves fast enough to allow it.
    #[test]
    fn a_revealed_scale_or_a_warming_die_is_no_drift() {
        let turn = |k: usize| {
            if k < 5000 {
                0.0
            } else {
                100.0f32.min((k - 5000) as f32 * 0.2)
            }
        };
        let (since, others, _) = watch_run([1.0, 1.02, 0.99, 0.98], 0.0, 0.0, turn);
        assert!(since.is_none() && !others, "{since:?} {others}");
        let (since, others, _) = watch_run([1.0; 4], 0.1, 2.0, |_| 0.0);
        assert!(since.is_none() && !others, "{since:?} {others}");
    }
}
