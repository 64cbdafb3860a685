//! The calibration's drift watch: a chip whose residual against its own
//! calibration lags further than its part's bias can move is drifting, a
//! fault for the health logic, not something to learn.

use super::{CalConfig, RelCal};
use crate::algo::math::at_least;

/// The drift watch (see [`RelCal::drifting`]) sums each chip's residual
/// over the [`EVERY`](super::EVERY) updates between two of its checks; its lag is an
/// exponential mean of those block means with weight 1/2 (a time constant
/// of two blocks, 128 samples at [`LEARN_STRIDE`](super::LEARN_STRIDE) 2).
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

/// Blocks of [`EVERY`](super::EVERY) updates in a row over the limit before a chip is
/// drifting (0.5 s at stride 2): a scale that a turn reveals after a still
/// start (its ridge held it at 1) leaves a residual of |s − 1|·|c| until
/// the regression has it, some 0.3 s; a bias drifting at 0.1 °/s per second
/// leaves a lag that only grows.
pub const LAG_PERSIST: u16 = 8;

impl<const N: usize> RelCal<N> {
    /// The drift watch's residual of the drifting chips with a reading, one
    /// update: left out of learning, each is watched against the
    /// calibration it had (b + s·c) until it is back. (The chips learnt
    /// from have theirs summed in [`RelCal::learn`]'s loop, y − ȳ − s·(c − c̄),
    /// against the calibration as its means stand: the same at a solve,
    /// and the moments' own terms.) A sample fusion rejected (a spike) says
    /// nothing of the bias and is not summed.
    #[cold]
    #[inline(never)]
    pub(super) fn watch_drifting(&mut self, y: &[f32; N], c: f32) {
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
    pub(super) fn judge(&mut self) {
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
    /// its own noise, for [`LAG_PERSIST`] blocks of [`EVERY`](super::EVERY) updates: a
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
}
