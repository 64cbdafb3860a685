//! The per-sample loop: read every gyro, account for every sample, flag and
//! exclude faulty chips, restart lost ones, fuse each axis.
//!
//! Nothing is dropped silently: every sample has a sequence number, every
//! read error and overrun is counted, and every health change is reported in
//! [`Output::health_changed`] for the firmware to log.
//!
//! Recovery: a gyro that failed at start-up or reports a reset of its own
//! (ICM-42688-P RESET_DONE, ADXRS453 POR) is restarted through
//! [`Gyro::restart`], a few SPI transactions per sample while the others
//! keep sampling; one that reads but stays bad (errors, stuck, saturated)
//! for `restart_after` samples in a row is restarted too. A failed attempt
//! is retried after a back-off that doubles from `backoff_min` to
//! `backoff_max` samples (for a bad-reading gyro, the back-off also
//! lengthens the bad run that triggers the next restart) and resets once
//! the gyro is healthy again. A restarted gyro rejoins fusion after
//! `stuck_after` good samples (its configuration was just verified), any
//! other flagged one after `recover_after`.

pub mod align;
pub mod clock;
mod health;
pub mod selftest;
pub mod stamps;
pub mod startup;
pub mod timed;
pub mod tracker;

use crate::algo::calib::{CalConfig, RelCal};
use crate::algo::fusion::{AxisState, ConfigError, FuseError, Fused, Fusion, Method};
use crate::algo::math::at_least;
use crate::algo::static_cal::{CalError, CalRecord, ChipCal};
use crate::drivers::{Gyro, ReadFault, Reading};
pub use health::{flag, GyroCounters, Health, Recovery};

/// Pipeline settings.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PipelineConfig {
    /// Samples of identical raw output before a gyro is flagged stuck.
    pub stuck_after: u16,
    /// Consecutive good samples before a flag (other than init) clears.
    pub recover_after: u16,
    /// Samples a gyro may stay excluded before it is restarted.
    pub restart_after: u16,
    /// Sample period, µs (turns the drivers' restart waits into samples).
    pub sample_us: u32,
    /// Back-off before the first retry of a failed restart, samples.
    pub backoff_min: u32,
    /// Longest back-off, samples.
    pub backoff_max: u32,
    /// Every this many samples one gyro (in turn) has its configuration
    /// read back, at sample [`CHECK_AT`] of the period, and (calibrated)
    /// its die temperature read, at [`TEMP_AT`] (0: never).
    pub check_every: u32,
}

/// The sample (mod `check_every`, 64 by default) of each configuration
/// read-back, and of each temperature read. A read-back costs the
/// firmware about 900 instructions (its bus time aside), as much as a
/// calibration solve, and is on the frame's path: both take samples where
/// no solve falls (`calib::SOLVE_SLOTS`), ≡ 27 and ≡ 6 (mod 32).
pub const CHECK_AT: u32 = 27;
/// See [`CHECK_AT`].
pub const TEMP_AT: u32 = 38;

/// A gyro's restart runs its steps (a reset; the configuration and its
/// read-back, some 30 SPI transactions for an ICM-42688-P) only on samples
/// ≡ [`RESTART_AT`] (mod [`RESTART_EVERY`]), where the E-DAVARs' frames
/// cost least and no solve, read-back or temperature read falls: the
/// configuration step is the costliest of the loop's rare steps (some 200
/// instructions off fault scenario B's worst sample, `cargo xtask
/// bench-loop`). Each step waits up to 3 samples more: a chip is back in
/// fusion 73 samples after an ICM-42688-P reset, 125 after an ADXRS453
/// reset, 189 after a late power-up (`checks::recovery_comes_back`).
pub const RESTART_EVERY: u32 = 4;
/// See [`RESTART_EVERY`].
pub const RESTART_AT: u32 = 1;

/// Samples from boot during which a healthy gyro that has not read yet
/// and is still finding its clock (`ReadFault::Acquiring`) keeps fusion
/// from a pair or a single chip, as one that lost its clock after good
/// reads does. The timed chips' clock trackers start from two captures
/// 20 ms apart, so at boot they all acquire within some 20 samples; the
/// bound keeps a chip that never acquires from holding the others back
/// for good.
pub const ACQUIRE_AT_BOOT: u32 = 100;

impl PipelineConfig {
    /// The default [`Self::check_every`].
    pub const DEFAULT_CHECK_EVERY: u32 = 64;
}

impl Default for PipelineConfig {
    fn default() -> Self {
        Self {
            stuck_after: 16,
            recover_after: 64,
            restart_after: 100,
            sample_us: 1000,
            backoff_min: 25,
            backoff_max: 1000,
            check_every: Self::DEFAULT_CHECK_EVERY,
        }
    }
}

/// What one sample produced.
#[derive(Clone, Copy, Debug)]
pub struct Output<const N: usize> {
    /// Sequence number (counts every sample period, including overruns).
    pub seq: u32,
    /// Per-gyro rates, °/s (NaN where not read).
    pub rate_dps: [[f32; 3]; N],
    /// Per gyro, how long before the read its rate was true, µs
    /// ([`Gyro::delay_us`]; 0 where not read).
    pub delay_us: [u32; N],
    /// Per axis, the gyros offered to fusion.
    pub offered: [u8; 3],
    /// Per axis, the fused sample.
    pub fused: [Option<Fused<N>>; 3],
    /// Per axis, the array's noise probe (`fusion::noise_probe`) over the
    /// inputs fusion saw: noise with the fused rate's variance and none of
    /// the platform's motion, for the noise tracker. `None` where fewer
    /// than two gyros were used.
    pub noise_probe_dps: [Option<f32>; 3],
    /// Gyros whose health flags changed in this sample.
    pub health_changed: u8,
}

impl<const N: usize> Output<N> {
    /// Per axis, how long before the read the fused rate was true, µs: the
    /// fusion weights' mean of the chips' delays (for a slow signal, a
    /// weighted mean of delayed copies is that copy delayed by the mean).
    /// 0 where the axis has no fused value.
    pub fn age_us(&self) -> [u16; 3] {
        let mut age = [0u16; 3];
        // Every chip on one stated instant (the timed board): the weighted
        // mean is that delay, and only a held output (all weights 0) is
        // not.
        let first = self.delay_us.first().copied().unwrap_or(0);
        let uniform = self.delay_us.iter().all(|&d| d == first);
        for (a, f) in self.fused.iter().enumerate() {
            let Some(f) = f else { continue };
            if uniform && !(f.fallback && f.weights.iter().all(|&w| w == 0.0)) {
                age[a] = first.min(u32::from(u16::MAX)) as u16;
                continue;
            }
            // The weights sum to 1 (or are all 0: a held output, age 0).
            let mut d = 0.5f32;
            for (w, us) in f.weights.iter().zip(self.delay_us.iter()) {
                d += *w * *us as f32;
            }
            age[a] = d.min(u16::MAX as f32) as u16;
        }
        age
    }
}

/// One axis's calibration and fusion ([`RelCal::fuse_deferred`]), out of
/// line. Inlined into the board's loop (one function of ~55 KB with the
/// drivers, the tracker and the link), its register allocation moved with
/// any change in fusion, by ±100 instructions a sample (`cargo xtask
/// bench-loop`); out of line the loop's mean is also 10–30 lower.
/// (`fuse_probed` itself stays inlinable, for callers that fuse alone, as
/// the fusion bench does.)
#[inline(never)]
fn fuse_axis<const N: usize>(
    cal: &mut RelCal<N>,
    fusion: &Fusion<N>,
    st: &mut AxisState<N>,
    y: &[f32; N],
    offered: u8,
) -> Result<(Fused<N>, Option<f32>), FuseError> {
    cal.fuse_deferred(fusion, st, y, offered)
}

/// The sampling pipeline for `N` gyros.
pub struct Pipeline<const N: usize> {
    cfg: PipelineConfig,
    fusion: Fusion<N>,
    axes: [AxisState<N>; 3],
    /// Online relative calibration per axis, applied before fusion.
    cal: [RelCal<N>; 3],
    /// Static calibration per chip (mounting, scale, misalignment, bias
    /// and its temperature slope), applied to every reading when a valid
    /// record was given.
    static_cal: [ChipCal; N],
    calibrated: bool,
    /// Last die temperature per chip, °C (read while calibrated), and the
    /// sample it was read on.
    temps: [Option<f32>; N],
    /// How each gyro's start-up went.
    start: [crate::link::msg::Start; N],
    temp_seq: [u32; N],
    /// The fastest die temperature change lately, °C/s (the calibration's
    /// drift allowance follows it).
    temp_rate: f32,
    /// The chips flagged [`flag::CAL_DRIFT`] and [`flag::CAL_BOUNDS`].
    cal_flagged: (u8, u8),
    seq: u32,
    overruns: u32,
    counters: [GyroCounters; N],
    health: [Health; N],
}

impl<const N: usize> Pipeline<N> {
    /// A pipeline with the given fusion method.
    pub fn new(cfg: PipelineConfig, method: Method) -> Result<Self, ConfigError> {
        if cfg.stuck_after < 2 || cfg.recover_after == 0 {
            return Err(ConfigError::Parameter);
        }
        if cfg.sample_us == 0 || cfg.backoff_min == 0 || cfg.backoff_max < cfg.backoff_min {
            return Err(ConfigError::Parameter);
        }
        let h = Health::new(cfg);
        Ok(Self {
            cfg,
            fusion: Fusion::new(method)?,
            axes: core::array::from_fn(AxisState::for_axis),
            cal: core::array::from_fn(|a| RelCal::for_axis(CalConfig::board(), a)),
            static_cal: [ChipCal::IDENTITY; N],
            calibrated: false,
            temps: [None; N],
            start: [crate::link::msg::Start::Unknown; N],
            temp_seq: [0; N],
            temp_rate: 0.0,
            cal_flagged: (0, 0),
            seq: 0,
            overruns: 0,
            counters: [GyroCounters::default(); N],
            health: [h; N],
        })
    }

    /// How gyro `i`'s start-up went (the start-up says; a gyro marked
    /// failed reads `InitFailed` unless its self-test was what failed).
    pub fn set_start(&mut self, i: usize, s: crate::link::msg::Start) {
        if let Some(slot) = self.start.get_mut(i) {
            *slot = s;
        }
    }

    /// How each gyro's start-up went.
    pub fn starts(&self) -> &[crate::link::msg::Start; N] {
        &self.start
    }

    /// Mark a gyro whose init or self-test failed: it is not read, and is
    /// restarted after the first back-off.
    pub fn mark_init_failed(&mut self, i: usize) {
        use crate::link::msg::Start;
        if let Some(s) = self.start.get_mut(i) {
            if *s != Start::SelfTestFailed {
                *s = Start::InitFailed;
            }
        }
        let (seq, backoff) = (self.seq, self.cfg.backoff_min);
        if let Some(h) = self.health.get_mut(i) {
            h.flags |= flag::INIT_FAILED;
            h.recovery = Recovery::Waiting {
                at: seq.wrapping_add(backoff),
            };
        }
    }

    /// Record `missed` sample periods that passed without a sample. They
    /// consume sequence numbers, so gaps are visible downstream.
    pub fn note_overrun(&mut self, missed: u32) {
        self.overruns = self.overruns.saturating_add(missed);
        self.seq = self.seq.wrapping_add(missed);
    }

    /// Sample periods missed so far.
    pub fn overruns(&self) -> u32 {
        self.overruns
    }

    /// Counters of gyro `i`.
    pub fn counters(&self) -> &[GyroCounters; N] {
        &self.counters
    }

    /// Health of every gyro.
    pub fn health(&self) -> &[Health; N] {
        &self.health
    }

    /// Log (defmt) the new health flags of every gyro whose health changed
    /// in `out`, as the firmware must.
    #[cfg(feature = "defmt")]
    pub fn log_health_changes(&self, out: &Output<N>) {
        for i in 0..N {
            if out.health_changed & (1 << i) != 0 {
                let c = self.counters[i];
                defmt::warn!(
                    "seq {}: gyro {} health flags now {=u8:#07b} ({}; resets {}, restarts {}, restarted {})",
                    out.seq,
                    i,
                    self.health[i].flags,
                    self.health[i].recovery,
                    c.resets,
                    c.restarts,
                    c.restarted
                );
            }
        }
    }

    /// Use the static calibration `rec` (as read from storage). A missing
    /// or invalid record, or one for another number of chips, leaves the
    /// pipeline uncalibrated ([`Pipeline::calibrated`] false, sent on the
    /// link) and returns why.
    pub fn set_calibration(&mut self, rec: Result<&CalRecord, CalError>) -> Result<(), CalError> {
        let rec = rec.inspect_err(|_| self.calibrated = false)?;
        if rec.chips.len() != N {
            self.calibrated = false;
            return Err(CalError::Chips);
        }
        for (d, c) in self.static_cal.iter_mut().zip(rec.chips.iter()) {
            *d = *c;
        }
        self.calibrated = true;
        Ok(())
    }

    /// Board-axis rates of gyro `i`'s reading `r`: the static calibration
    /// applied when one is in use, the chip's own axes otherwise.
    pub fn board_rates(&self, i: usize, r: &Reading) -> [f32; 3] {
        match (self.calibrated, self.static_cal.get(i)) {
            (true, Some(c)) => c.apply(r.rate_dps, r.axes, self.temps.get(i).copied().flatten()),
            _ => r.rate_dps,
        }
    }

    /// The static calibration per gyro, when one is in use.
    pub fn static_calibration(&self) -> Option<&[ChipCal; N]> {
        self.calibrated.then_some(&self.static_cal)
    }

    /// Prior noise σ per gyro, °/s (the start-up noise test's, or the
    /// datasheet's), for every axis: fusion needs them when only two gyros
    /// are left on an axis ([`crate::algo::fusion::AxisState::set_noise_priors`]).
    pub fn set_noise_priors(&mut self, sigma_dps: [Option<f32>; N]) {
        for st in self.axes.iter_mut() {
            st.set_noise_priors(sigma_dps);
        }
    }

    /// Per axis (bit a), fusion reads an error its chips share
    /// ([`crate::algo::fusion::AxisState::shared_error`]): the noise probe
    /// and the E-DAVAR on it cover only the part they do not share.
    pub fn shared_errors(&self) -> u8 {
        let mut m = 0u8;
        for (a, st) in self.axes.iter().enumerate() {
            m |= u8::from(st.shared_error()) << a;
        }
        m
    }

    /// Whether a static calibration record is in use.
    pub fn calibrated(&self) -> bool {
        self.calibrated
    }

    /// Last die temperature read from each chip, °C (read only while
    /// calibrated: one chip in turn, every `check_every` samples).
    pub fn temperatures(&self) -> &[Option<f32>; N] {
        &self.temps
    }

    /// Switch the fusion method. Its noise model and the frozen-chip
    /// state start again; the relative calibration is kept. On error
    /// nothing changes.
    pub fn set_method(&mut self, method: Method) -> Result<(), ConfigError> {
        let fusion = Fusion::new(method)?;
        self.finish();
        self.fusion = fusion;
        self.axes = core::array::from_fn(AxisState::for_axis);
        Ok(())
    }

    /// The fusion settings.
    pub fn fusion(&self) -> &Fusion<N> {
        &self.fusion
    }

    /// One sample: read every gyro, update health, fuse, and let the
    /// calibration learn from it.
    pub fn step(&mut self, gyros: &mut [&mut dyn Gyro; N]) -> Output<N> {
        let out = self.read_and_fuse(gyros);
        self.finish();
        out
    }

    /// [`Pipeline::step`] up to its output: what the calibration learns
    /// from the sample waits for [`Pipeline::finish`] (some 300
    /// instructions a sample on the Cortex-M4, a solve or a drift verdict
    /// more on their samples), which the board runs once the sample's
    /// frame is on the wire. The next `read_and_fuse` finishes first if it
    /// was not, so every sample is learnt from, in order.
    pub fn read_and_fuse(&mut self, gyros: &mut [&mut dyn Gyro; N]) -> Output<N> {
        self.finish();
        let mut out = Output {
            seq: self.seq,
            rate_dps: [[f32::NAN; 3]; N],
            delay_us: [0; N],
            offered: [0; 3],
            fused: [None; 3],
            noise_probe_dps: [None; 3],
            health_changed: 0,
        };
        self.seq = self.seq.wrapping_add(1);
        let seq = out.seq;
        // The gyro (in turn) whose configuration is read back this
        // sample, and the one whose temperature is read: decided once a
        // sample, not once a gyro.
        let every = self.cfg.check_every;
        let (mut check, mut temp) = (usize::MAX, usize::MAX);
        if let (Some(round), Some(phase)) = (seq.checked_div(every), seq.checked_rem(every)) {
            let turn = round as usize % N;
            if phase == CHECK_AT % every {
                check = turn;
            }
            if self.calibrated && phase == TEMP_AT % every {
                temp = turn;
            }
        }
        // The calibration's drift verdicts of the last sample (here, not
        // after this sample's fusion, so that `out` is built where it is
        // returned: flagged after it, the loop copied it, 64 instructions a
        // sample on the Cortex-M4).
        let drifting = self.cal.iter().fold(0u8, |m, c| m | c.drifting());
        let bounds = self.cal.iter().fold(0u8, |m, c| m | c.out_of_bounds());
        if (drifting, bounds) != self.cal_flagged {
            self.cal_flagged = (drifting, bounds);
            for (i, h) in self.health.iter_mut().enumerate() {
                let before = h.flags;
                h.flags &= !flag::CALIBRATION;
                if drifting & (1 << i) != 0 {
                    h.flags |= flag::CAL_DRIFT;
                }
                if bounds & (1 << i) != 0 {
                    h.flags |= flag::CAL_BOUNDS;
                }
                if h.flags != before {
                    out.health_changed |= 1 << i;
                }
            }
        }
        // Healthy chips finding their clocks again after a gap.
        let mut acquiring = 0u8;
        for (i, g) in gyros.iter_mut().enumerate() {
            let before = self.health[i].flags;
            let mut offered_any = false;
            if self.health[i].recovery != Recovery::Running {
                self.counters[i].not_read = self.counters[i].not_read.saturating_add(1);
                let cfg = self.cfg;
                if self.health[i].recover(&mut self.counters[i], cfg, &mut **g, seq) {
                    // The chip's calibration is its part's: kept, unless it
                    // is outside the bounds (`RelCal::resume`). Fusion
                    // trusted it only while it agreed with the others, so a
                    // fault that corrupted its range is not in it.
                    for cal in self.cal.iter_mut() {
                        cal.resume(i);
                    }
                }
            } else {
                let due = i == check;
                // One gyro in turn also has its configuration read back.
                let r = if due {
                    g.check_config().and_then(|()| g.read())
                } else {
                    g.read()
                };
                // (Good before, so the gap is a shared one: a chip whose
                // own errors keep breaking its stream does not hold the
                // others back. At boot every chip acquires at once and the
                // first ready may be one frozen from power-up that the
                // stuck check cannot know yet: until it has read, and for
                // at most `ACQUIRE_AT_BOOT` samples, a chip still finding
                // its clock holds the others back too.)
                let h = &self.health[i];
                let waited = h.good_run > 0 || self.counters[i].reads == 0 && seq < ACQUIRE_AT_BOOT;
                if matches!(r, Err(ReadFault::Acquiring)) && h.flags == 0 && waited {
                    acquiring |= 1 << i;
                }
                let (cfg, seq) = (self.cfg, self.seq);
                if let Some(axes) = self.health[i].account(&mut self.counters[i], cfg, seq, r) {
                    offered_any = axes != 0;
                    for (a, off) in out.offered.iter_mut().enumerate() {
                        *off |= ((axes >> a) & 1) << i;
                    }
                }
                if let Ok(r) = r {
                    out.rate_dps[i] = self.board_rates(i, &r);
                    out.delay_us[i] = g.delay_us();
                }
                // The die temperature, for the bias model: one gyro in
                // turn, between configuration checks.
                if i == temp {
                    if let Ok(t) = g.temperature_c() {
                        self.temp_change(i, t, seq);
                    }
                }
            }
            if self.health[i].flags != before {
                out.health_changed |= 1 << i;
                let frozen = flag::STUCK | flag::SATURATED;
                if self.health[i].flags & frozen & !before != 0 {
                    for cal in self.cal.iter_mut() {
                        cal.drop_frozen(i);
                    }
                }
            }
            if !offered_any {
                self.counters[i].excluded = self.counters[i].excluded.saturating_add(1);
            }
        }
        for a in 0..3 {
            // A pair cannot outvote a faulty member; while a healthy chip is
            // only finding its clock again (back within a few reads), a
            // pair is not fused.
            if acquiring != 0 && out.offered[a].count_ones() < 3 {
                out.offered[a] = 0;
            }
            let mut y = [f32::NAN; N];
            for (i, v) in y.iter_mut().enumerate() {
                *v = out.rate_dps[i][a];
            }
            // Fusion sees the chips with their relative scale and bias
            // taken out (`algo::calib`); the calibration then learns from
            // the raw readings of the chips fusion used.
            let r = fuse_axis(
                &mut self.cal[a],
                &self.fusion,
                &mut self.axes[a],
                &y,
                out.offered[a],
            );
            (out.fused[a], out.noise_probe_dps[a]) = match r {
                Ok((f, p)) => (Some(f), p),
                Err(_) => (None, None),
            };
        }
        out
    }

    /// The calibration's learning from the last sample fused, if it has
    /// not been done (see [`Pipeline::read_and_fuse`]).
    pub fn finish(&mut self) {
        for (cal, st) in self.cal.iter_mut().zip(self.axes.iter_mut()) {
            cal.finish(st);
        }
    }

    /// What the board's loop runs once a sample's frame is on the wire,
    /// for the sample `probe` was taken of: the calibration's learning
    /// ([`Pipeline::finish`]) and the noise tracker's E-DAVARs.
    pub fn after_frame<const CAP: usize, const FRAMES: usize, const T: usize>(
        &mut self,
        noise: &mut tracker::NoiseTracker<CAP, FRAMES, T>,
        probe: tracker::Probe,
    ) {
        self.finish();
        noise.push_probe(probe);
    }

    /// A new die temperature `t` of gyro `i` on sample `seq`: kept for the
    /// bias model, and its rate of change sets how far the calibration
    /// lets a chip's bias move before it calls the chip drifting, and how
    /// fast it follows (`RelCal::set_temperature_rate`).
    fn temp_change(&mut self, i: usize, t: f32, seq: u32) {
        if let (Some(Some(t0)), Some(&s0)) = (self.temps.get(i), self.temp_seq.get(i)) {
            let dt_s = seq.wrapping_sub(s0) as f32 * self.cfg.sample_us as f32 * 1e-6;
            if dt_s > 0.0 {
                // The fastest chip's rate, decaying by a quarter a reading.
                let r = (t - t0).abs() / dt_s;
                self.temp_rate = at_least(r, 0.75 * self.temp_rate);
                for c in self.cal.iter_mut() {
                    c.set_temperature_rate(self.temp_rate, self.cfg.sample_us);
                }
            }
        }
        if let (Some(slot), Some(s)) = (self.temps.get_mut(i), self.temp_seq.get_mut(i)) {
            (*slot, *s) = (Some(t), seq);
        }
    }

    /// The online relative calibration of each axis (x, y, z).
    pub fn calibration(&self) -> &[RelCal<N>; 3] {
        &self.cal
    }
}
