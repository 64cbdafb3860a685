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
pub mod selftest;
pub mod startup;
pub mod timed;
pub mod tracker;

use crate::algo::calib::{CalConfig, RelCal};
use crate::algo::fusion::{AxisState, ConfigError, FuseError, Fused, Fusion, Method};
use crate::algo::math::at_least;
use crate::algo::mounting::{CalError, CalRecord, ChipCal};
use crate::drivers::{Gyro, ReadFault, Reading, Restart};

/// Health flags of one gyro (bit set = problem).
pub mod flag {
    /// The driver's init or self-test failed; the gyro is never read.
    pub const INIT_FAILED: u8 = 1 << 0;
    /// A read failed (bus, parity, chip fault); cleared after
    /// `recover_after` good reads. A chip that garbles frames is suspect, so
    /// its frames that do pass the checks are not used until then either.
    pub const READ_ERROR: u8 = 1 << 1;
    /// Raw output bit-identical for `stuck_after` samples.
    pub const STUCK: u8 = 1 << 2;
    /// At the end of its range for `stuck_after` samples.
    pub const SATURATED: u8 = 1 << 3;
    /// Being restarted (not read until the restart is done).
    pub const RESTARTING: u8 = 1 << 4;
    /// Its reading has moved away from its calibration faster than its
    /// part's bias can (`algo::calib::RelCal::drifting`, on any axis): a
    /// chip failing slowly. Read and watched, not fused, not learnt from;
    /// cleared when it is back within its part's allowance.
    pub const CAL_DRIFT: u8 = 1 << 5;
}

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
/// firmware about 900 instructions (its bus time aside); every 50 samples
/// it fell in turn on each phase of the E-DAVARs' 32-sample frames and the
/// calibration's solves, and made the loop's worst sample (9 941, on a
/// frame with an estimate; `cargo xtask bench`). On the shared 64-sample
/// schedule (`calib::SOLVE_SLOTS`, `pipeline::tracker`) both take samples
/// where the E-DAVARs cost least and no solve falls: ≡ 27 and ≡ 6 (mod 32).
pub const CHECK_AT: u32 = 27;
/// See [`CHECK_AT`].
pub const TEMP_AT: u32 = 38;

/// A gyro's restart runs its steps (a reset; the configuration and its
/// read-back, some 30 SPI transactions for an ICM-42688-P) only on samples
/// ≡ [`RESTART_AT`] (mod [`RESTART_EVERY`]), where the E-DAVARs' frames
/// cost least and no solve, read-back or temperature read falls. Run when
/// due, the configuration step made the loop's costliest sample: fault
/// scenario B's worst went 9 913 → 9 730 instructions with the slots
/// (`cargo xtask bench-loop`, exact). Each step waits up to 3 samples
/// more: back in fusion after an ICM-42688-P reset 64 → 73 samples, an
/// ADXRS453 reset 119 → 125, a late power-up 166 → 189
/// (`checks::recovery_comes_back`).
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

impl Default for PipelineConfig {
    fn default() -> Self {
        Self {
            stuck_after: 16,
            recover_after: 64,
            restart_after: 100,
            sample_us: 1000,
            backoff_min: 25,
            backoff_max: 1000,
            check_every: 64,
        }
    }
}

/// Counters of one gyro since start.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct GyroCounters {
    /// Successful reads.
    pub reads: u32,
    /// Failed reads of any kind.
    pub errors: u32,
    /// Of those, parity failures.
    pub parity: u32,
    /// Of those, chip-reported faults.
    pub chip_faults: u32,
    /// Axis samples at the end of the range.
    pub saturated: u32,
    /// Samples in which the gyro was excluded from fusion.
    pub excluded: u32,
    /// Resets the chip reported by itself.
    pub resets: u32,
    /// Configuration read-backs that differed (corrupted registers).
    pub config_errors: u32,
    /// Restart attempts.
    pub restarts: u32,
    /// Restarts that completed (the chip configured and sampling again).
    pub restarted: u32,
    /// Samples in which the gyro was not read because it was being
    /// restarted or waiting for its next attempt.
    pub not_read: u32,
    /// Samples in which the gyro had nothing yet for the instant asked for
    /// ([`ReadFault::Late`], [`ReadFault::Acquiring`]): not a fault. Every
    /// sample is one of `reads`, `errors`, `not_read` or `late`.
    pub late: u32,
}

impl Health {
    /// The back-off before the next retry if the attempt under way (or
    /// the next one) fails, samples.
    pub fn backoff(&self) -> u32 {
        self.backoff
    }
}

/// Where a gyro is in its recovery.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Recovery {
    /// Read every sample.
    #[default]
    Running,
    /// A restart is due at sequence number `at`.
    Waiting {
        /// When.
        at: u32,
    },
    /// Restart step `step` is due at sequence number `at`.
    Restarting {
        /// The driver's next step.
        step: u8,
        /// When.
        at: u32,
    },
}

/// Health of one gyro.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Health {
    /// [`flag`] bits.
    pub flags: u8,
    /// Recovery state.
    pub recovery: Recovery,
    good_run: u16,
    same_run: u16,
    sat_run: u16,
    bad_run: u32,
    /// Good samples needed before the flags clear.
    need: u16,
    /// Back-off before the next retry, samples.
    backoff: u32,
    last_raw: [i16; 3],
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
    /// This sample ran periodic heavy work (a calibration solve, a
    /// configuration read-back, a temperature read): work that can wait,
    /// such as the link's E-DAVAR estimate, waits a sample. A solve for a
    /// chip that had just warmed up again after bit errors, on a frame with
    /// an estimate, made the loop's worst sample (10 030 instructions,
    /// `cargo xtask bench`, fault scenario B).
    pub busy: bool,
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

/// One axis's calibration and fusion ([`RelCal::fuse_probed`]), out of
/// line. Inlined into the board's loop (one function of ~55 KB with the
/// drivers, the tracker and the link), its register allocation moved with
/// any change in fusion, by ±100 instructions a sample (`cargo xtask
/// bench-loop`); out of line the loop's mean is also 10–30 lower.
/// (`fuse_probed` itself stays inlinable: called alone, as in the fusion
/// bench, out of line it cost 90 more per axis.)
#[inline(never)]
fn fuse_axis<const N: usize>(
    cal: &mut RelCal<N>,
    fusion: &Fusion<N>,
    st: &mut AxisState<N>,
    y: &[f32; N],
    offered: u8,
) -> Result<(Fused<N>, Option<f32>), FuseError> {
    cal.fuse_probed(fusion, st, y, offered)
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
    temp_seq: [u32; N],
    /// The fastest die temperature change lately, °C/s (the calibration's
    /// drift allowance follows it).
    temp_rate: f32,
    /// The chips flagged [`flag::CAL_DRIFT`].
    drift_flagged: u8,
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
        let h = Health {
            need: cfg.recover_after,
            backoff: cfg.backoff_min,
            ..Health::default()
        };
        Ok(Self {
            cfg,
            fusion: Fusion::new(method)?,
            axes: [AxisState::default(); 3],
            cal: core::array::from_fn(|a| RelCal::for_axis(CalConfig::default(), a)),
            static_cal: [ChipCal::IDENTITY; N],
            calibrated: false,
            temps: [None; N],
            temp_seq: [0; N],
            temp_rate: 0.0,
            drift_flagged: 0,
            seq: 0,
            overruns: 0,
            counters: [GyroCounters::default(); N],
            health: [h; N],
        })
    }

    /// Mark a gyro whose init or self-test failed: it is not read, and is
    /// restarted after the first back-off.
    pub fn mark_init_failed(&mut self, i: usize) {
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
        self.fusion = Fusion::new(method)?;
        self.axes = [AxisState::default(); 3];
        Ok(())
    }

    /// The fusion settings.
    pub fn fusion(&self) -> &Fusion<N> {
        &self.fusion
    }

    /// One sample: read every gyro, update health, fuse.
    pub fn step(&mut self, gyros: &mut [&mut dyn Gyro; N]) -> Output<N> {
        let mut out = Output {
            seq: self.seq,
            rate_dps: [[f32::NAN; 3]; N],
            delay_us: [0; N],
            offered: [0; 3],
            fused: [None; 3],
            noise_probe_dps: [None; 3],
            health_changed: 0,
            busy: false,
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
        if drifting != self.drift_flagged {
            self.drift_flagged = drifting;
            for (i, h) in self.health.iter_mut().enumerate() {
                let before = h.flags;
                if drifting & (1 << i) != 0 {
                    h.flags |= flag::CAL_DRIFT;
                } else {
                    h.flags &= !flag::CAL_DRIFT;
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
                self.recover(i, &mut **g, seq);
            } else {
                let due = i == check;
                // One gyro in turn also has its configuration read back.
                out.busy |= due;
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
                if let Some(axes) = self.account(i, r) {
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
                    out.busy = true;
                    if let Ok(t) = g.temperature_c() {
                        self.temp_change(i, t, seq);
                    }
                }
            }
            if self.health[i].flags != before {
                out.health_changed |= 1 << i;
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
            out.busy |= self.cal[a].solved();
        }
        out
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

    /// Drive gyro `i`'s restart: start it when due, run the step the
    /// driver asked for when its wait is over.
    fn recover(&mut self, i: usize, g: &mut dyn Gyro, seq: u32) {
        let cfg = self.cfg;
        let (Some(h), Some(c)) = (self.health.get_mut(i), self.counters.get_mut(i)) else {
            return;
        };
        if seq % RESTART_EVERY != RESTART_AT {
            return;
        }
        let due = |at: u32| (seq.wrapping_sub(at) as i32) >= 0;
        let step = match h.recovery {
            Recovery::Running => return,
            Recovery::Waiting { at } if due(at) => {
                c.restarts = c.restarts.saturating_add(1);
                h.flags |= flag::RESTARTING;
                0
            }
            Recovery::Restarting { step, at } if due(at) => step,
            _ => return,
        };
        match g.restart(step) {
            Ok(Restart::Again { step, wait_us }) => {
                // (sample_us > 0 is checked in `new`; `max` shows it.)
                let wait = wait_us.div_ceil(cfg.sample_us.max(1));
                h.recovery = Recovery::Restarting {
                    step,
                    at: seq.wrapping_add(wait.max(1)),
                };
            }
            Ok(Restart::Done) => {
                c.restarted = c.restarted.saturating_add(1);
                h.recovery = Recovery::Running;
                // The chip's calibration is its part's: kept, unless it is
                // outside the bounds (`RelCal::resume`). Fusion trusted it
                // only while it agreed with the others, so a fault that
                // corrupted its range is not in it.
                for cal in self.cal.iter_mut() {
                    cal.resume(i);
                }
                // Configured and verified just now: it rejoins after a run
                // as long as the stuck check needs, not recover_after.
                h.flags = flag::READ_ERROR | (h.flags & flag::CAL_DRIFT);
                h.need = cfg.stuck_after;
                h.good_run = 0;
                h.bad_run = 0;
            }
            Err(_) => {
                h.recovery = Recovery::Waiting {
                    at: seq.wrapping_add(h.backoff),
                };
                h.backoff = h.backoff.saturating_mul(2).min(cfg.backoff_max);
            }
        }
    }

    /// Update counters and health for gyro `i`; the axes it may offer.
    fn account(&mut self, i: usize, r: Result<crate::drivers::Reading, ReadFault>) -> Option<u8> {
        let cfg = self.cfg;
        let seq = self.seq;
        let c = &mut self.counters[i];
        let h = &mut self.health[i];
        let r = match r {
            Err(ReadFault::Late | ReadFault::Acquiring) => {
                c.late = c.late.saturating_add(1);
                return None;
            }
            Err(e) => {
                c.errors = c.errors.saturating_add(1);
                match e {
                    ReadFault::Parity => c.parity = c.parity.saturating_add(1),
                    ReadFault::ChipFault(_) => c.chip_faults = c.chip_faults.saturating_add(1),
                    ReadFault::Reset => c.resets = c.resets.saturating_add(1),
                    ReadFault::Config => c.config_errors = c.config_errors.saturating_add(1),
                    _ => {}
                }
                h.flags |= flag::READ_ERROR;
                h.good_run = 0;
                if matches!(e, ReadFault::Reset | ReadFault::Config) {
                    // Its configuration is gone: restart it now.
                    h.recovery = Recovery::Waiting { at: seq };
                } else {
                    Self::maybe_restart(h, cfg, seq);
                }
                return None;
            }
            Ok(r) => r,
        };
        c.reads = c.reads.saturating_add(1);
        if r.saturated != 0 {
            c.saturated = c.saturated.saturating_add(1);
            h.sat_run = h.sat_run.saturating_add(1);
        } else {
            h.sat_run = 0;
        }
        if r.raw == h.last_raw {
            h.same_run = h.same_run.saturating_add(1);
        } else {
            h.same_run = 0;
        }
        h.last_raw = r.raw;
        if h.same_run.saturating_add(1) >= self.cfg.stuck_after {
            h.flags |= flag::STUCK;
        }
        if h.sat_run >= self.cfg.stuck_after {
            h.flags |= flag::SATURATED;
        }
        let good = r.saturated == 0 && h.same_run.saturating_add(1) < self.cfg.stuck_after;
        h.good_run = if good {
            h.good_run.saturating_add(1)
        } else {
            0
        };
        if h.good_run >= h.need {
            // (The calibration's verdict is its own to clear.)
            h.flags &= flag::CAL_DRIFT;
            h.need = self.cfg.recover_after;
        }
        if h.flags != 0 {
            // A good sample of a flagged gyro is on its way back: only a
            // run of bad ones leads to a restart.
            if good {
                h.bad_run = 0;
            } else {
                Self::maybe_restart(h, cfg, seq);
            }
            return None;
        }
        // Healthy: the next loss starts from the shortest back-off.
        h.bad_run = 0;
        h.backoff = cfg.backoff_min;
        Some(r.axes & !r.saturated)
    }

    /// A bad sample of a gyro that is still read: after `restart_after`
    /// bad samples in a row (or the current back-off, if longer), restart
    /// it now, and double the back-off for the next time. It stays read
    /// until then, so one that comes good on its own is never restarted.
    fn maybe_restart(h: &mut Health, cfg: PipelineConfig, seq: u32) {
        h.bad_run = h.bad_run.saturating_add(1);
        if h.bad_run >= (cfg.restart_after as u32).max(h.backoff) {
            h.bad_run = 0;
            h.recovery = Recovery::Waiting { at: seq };
            h.backoff = h.backoff.saturating_mul(2).min(cfg.backoff_max);
        }
    }
}
