//! Each gyro's health: its flags, counters and restart state, what a
//! read's result does to them, and the restart with its back-off. The
//! pipeline holds one [`Health`] and one [`GyroCounters`] a gyro and
//! hands each read to [`Health::account`].

use super::{PipelineConfig, RESTART_AT, RESTART_EVERY};
use crate::drivers::{Gyro, ReadFault, Restart};

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
    /// Its scale or bias against the median chip is outside what its part
    /// can have (`algo::calib::RelCal::out_of_bounds`, on any axis): a
    /// wrong range, a chip gone bad. Read and learnt from, not fused;
    /// cleared when its calibration is back inside the bounds or starts
    /// over after a restart.
    pub const CAL_BOUNDS: u8 = 1 << 6;
    /// The calibration's verdicts, which only the calibration clears.
    pub const CALIBRATION: u8 = CAL_DRIFT | CAL_BOUNDS;
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
    /// A healthy gyro under `cfg`: its first recovery needs
    /// `recover_after` good samples, its first back-off is the shortest.
    pub(super) fn new(cfg: PipelineConfig) -> Self {
        Self {
            need: cfg.recover_after,
            backoff: cfg.backoff_min,
            ..Self::default()
        }
    }

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
    pub(super) good_run: u16,
    same_run: u16,
    sat_run: u16,
    bad_run: u32,
    /// Good samples needed before the flags clear.
    need: u16,
    /// Back-off before the next retry, samples.
    backoff: u32,
    last_raw: [i16; 3],
}

impl Health {
    /// Drive the gyro `g`'s restart at sample `seq`: start it when due, run
    /// the step the driver asked for when its wait is over. True when the
    /// restart has just completed (the chip configured and sampling
    /// again).
    pub(super) fn recover(
        &mut self,
        c: &mut GyroCounters,
        cfg: PipelineConfig,
        g: &mut dyn Gyro,
        seq: u32,
    ) -> bool {
        let h = self;
        if seq % RESTART_EVERY != RESTART_AT {
            return false;
        }
        let due = |at: u32| (seq.wrapping_sub(at) as i32) >= 0;
        let step = match h.recovery {
            Recovery::Running => return false,
            Recovery::Waiting { at } if due(at) => {
                c.restarts = c.restarts.saturating_add(1);
                h.flags |= flag::RESTARTING;
                0
            }
            Recovery::Restarting { step, at } if due(at) => step,
            _ => return false,
        };
        match g.restart(step) {
            Ok(Restart::Again { step, wait_us }) => {
                // (sample_us > 0 is checked in `new`; `max` shows it.)
                let wait = wait_us.div_ceil(cfg.sample_us.max(1));
                h.recovery = Recovery::Restarting {
                    step,
                    at: seq.wrapping_add(wait.max(1)),
                };
                false
            }
            Ok(Restart::Done) => {
                c.restarted = c.restarted.saturating_add(1);
                h.recovery = Recovery::Running;
                // Configured and verified just now: it rejoins after a run
                // as long as the stuck check needs, not recover_after.
                h.flags = flag::READ_ERROR | (h.flags & flag::CALIBRATION);
                h.need = cfg.stuck_after;
                h.good_run = 0;
                h.bad_run = 0;
                true
            }
            Err(_) => {
                h.recovery = Recovery::Waiting {
                    at: seq.wrapping_add(h.backoff),
                };
                h.backoff = h.backoff.saturating_mul(2).min(cfg.backoff_max);
                false
            }
        }
    }

    /// The gyro's read `r` at sample `seq` into its health and counters
    /// `c`; the axes it may offer.
    pub(super) fn account(
        &mut self,
        c: &mut GyroCounters,
        cfg: PipelineConfig,
        seq: u32,
        r: Result<crate::drivers::Reading, ReadFault>,
    ) -> Option<u8> {
        let h = self;
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
        if h.same_run.saturating_add(1) >= cfg.stuck_after {
            h.flags |= flag::STUCK;
        }
        if h.sat_run >= cfg.stuck_after {
            h.flags |= flag::SATURATED;
        }
        let good = r.saturated == 0 && h.same_run.saturating_add(1) < cfg.stuck_after;
        h.good_run = if good {
            h.good_run.saturating_add(1)
        } else {
            0
        };
        if h.good_run >= h.need {
            // (The calibration's verdict is its own to clear.)
            h.flags &= flag::CALIBRATION;
            h.need = cfg.recover_after;
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
