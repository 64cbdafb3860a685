//! The per-sample loop: read every gyro, account for every sample, flag and
//! exclude faulty chips, fuse each axis.
//!
//! Nothing is dropped silently: every sample has a sequence number, every
//! read error and overrun is counted, and every health change is reported in
//! [`Output::health_changed`] for the firmware to log.

pub mod selftest;
pub mod startup;
pub mod tracker;

use crate::algo::fusion::{AxisState, ConfigError, Fused, Fusion, Method};
use crate::drivers::{Gyro, ReadFault};

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
}

/// Pipeline settings.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PipelineConfig {
    /// Samples of identical raw output before a gyro is flagged stuck.
    pub stuck_after: u16,
    /// Consecutive good samples before a flag (other than init) clears.
    pub recover_after: u16,
}

impl Default for PipelineConfig {
    fn default() -> Self {
        Self {
            stuck_after: 16,
            recover_after: 64,
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
}

/// Health of one gyro.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Health {
    /// [`flag`] bits.
    pub flags: u8,
    good_run: u16,
    same_run: u16,
    sat_run: u16,
    last_raw: [i16; 3],
}

/// What one sample produced.
#[derive(Clone, Copy, Debug)]
pub struct Output<const N: usize> {
    /// Sequence number (counts every sample period, including overruns).
    pub seq: u32,
    /// Per-gyro rates, °/s (NaN where not read).
    pub rate_dps: [[f32; 3]; N],
    /// Per axis, the gyros offered to fusion.
    pub offered: [u8; 3],
    /// Per axis, the fused sample.
    pub fused: [Option<Fused<N>>; 3],
    /// Gyros whose health flags changed in this sample.
    pub health_changed: u8,
}

/// The sampling pipeline for `N` gyros.
pub struct Pipeline<const N: usize> {
    cfg: PipelineConfig,
    fusion: Fusion<N>,
    axes: [AxisState<N>; 3],
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
        Ok(Self {
            cfg,
            fusion: Fusion::new(method)?,
            axes: [AxisState::default(); 3],
            seq: 0,
            overruns: 0,
            counters: [GyroCounters::default(); N],
            health: [Health::default(); N],
        })
    }

    /// Mark a gyro whose init or self-test failed; it is never read.
    pub fn mark_init_failed(&mut self, i: usize) {
        if let Some(h) = self.health.get_mut(i) {
            h.flags |= flag::INIT_FAILED;
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
                defmt::warn!(
                    "seq {}: gyro {} health flags now {=u8:#06b}",
                    out.seq,
                    i,
                    self.health[i].flags
                );
            }
        }
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
            offered: [0; 3],
            fused: [None; 3],
            health_changed: 0,
        };
        self.seq = self.seq.wrapping_add(1);
        for (i, g) in gyros.iter_mut().enumerate() {
            let before = self.health[i].flags;
            if before & flag::INIT_FAILED == 0 {
                let r = g.read();
                if let Some(axes) = self.account(i, r) {
                    for (a, off) in out.offered.iter_mut().enumerate() {
                        if axes & (1 << a) != 0 {
                            *off |= 1 << i;
                        }
                    }
                }
                if let Ok(r) = r {
                    out.rate_dps[i] = r.rate_dps;
                }
            }
            if self.health[i].flags != before {
                out.health_changed |= 1 << i;
            }
            let offered_any = out.offered.iter().any(|m| m & (1 << i) != 0);
            if !offered_any {
                self.counters[i].excluded = self.counters[i].excluded.saturating_add(1);
            }
        }
        for a in 0..3 {
            let mut y = [f32::NAN; N];
            for (i, v) in y.iter_mut().enumerate() {
                *v = out.rate_dps[i][a];
            }
            out.fused[a] = self.fusion.fuse(&mut self.axes[a], &y, out.offered[a]).ok();
        }
        out
    }

    /// Update counters and health for gyro `i`; the axes it may offer.
    fn account(&mut self, i: usize, r: Result<crate::drivers::Reading, ReadFault>) -> Option<u8> {
        let c = &mut self.counters[i];
        let h = &mut self.health[i];
        let r = match r {
            Err(e) => {
                c.errors = c.errors.saturating_add(1);
                match e {
                    ReadFault::Parity => c.parity = c.parity.saturating_add(1),
                    ReadFault::ChipFault(_) => c.chip_faults = c.chip_faults.saturating_add(1),
                    _ => {}
                }
                h.flags |= flag::READ_ERROR;
                h.good_run = 0;
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
        if h.good_run >= self.cfg.recover_after {
            h.flags &= flag::INIT_FAILED;
        }
        if h.flags != 0 {
            return None;
        }
        Some(r.axes & !r.saturated)
    }
}
