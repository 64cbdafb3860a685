//! Noise tracking of the fused axes: one E-DAVAR per axis, fed with the
//! fused rate quantised to [`LSB_DPS`]. Shared by the QEMU demo and the
//! board firmware.

use super::Output;
use crate::algo::allan::stream::quantise;
use crate::algo::davar::{
    Davar, DavarConfig, DavarError, DavarStep, EntropyKind, Placement, StepMode, Threshold,
};
use crate::algo::math::sqrtf;

/// Input resolution of the tracker, °/s: ±2048 °/s fits the |w| < 2²⁰
/// integer range, and the step adds (LSB²/12) ≈ 3e-7 (°/s)² of white
/// noise, far below any MEMS gyro's.
pub const LSB_DPS: f32 = 1.0 / 512.0;

/// The change-aware E-DAVAR (temporal entropy, automatic threshold) for a
/// window of up to `lambda2` samples, λ1 = λ2/2.
pub const fn config(lambda2: u16) -> DavarConfig {
    DavarConfig {
        lambda1: lambda2 / 2,
        lambda2,
        l_init: lambda2,
        delta_l: lambda2 / 16,
        step: StepMode::Constant,
        entropy: EntropyKind::Temporal,
        threshold: Threshold::Auto { p_fa: 0.01 },
        placement: Placement::ChangeAware,
    }
}

/// E-DAVAR on the three fused axes.
pub struct NoiseTracker<const CAP: usize, const FRAMES: usize, const T: usize> {
    axes: [Davar<CAP, FRAMES, T>; 3],
    skipped: u32,
}

impl<const CAP: usize, const FRAMES: usize, const T: usize> NoiseTracker<CAP, FRAMES, T> {
    /// One E-DAVAR per axis with `cfg`.
    pub fn new(cfg: DavarConfig) -> Result<Self, DavarError> {
        Ok(Self {
            axes: [Davar::new(cfg)?, Davar::new(cfg)?, Davar::new(cfg)?],
            skipped: 0,
        })
    }

    /// Feed one pipeline output. An axis without a fused value, or one that
    /// cannot be quantised (non-finite, beyond ±2048 °/s), is a documented
    /// skip: it is counted and that axis's window simply does not advance.
    pub fn push<const N: usize>(&mut self, out: &Output<N>) {
        for (d, f) in self.axes.iter_mut().zip(out.fused.iter()) {
            match f.map(|f| quantise(f.rate_dps, LSB_DPS)) {
                Some(Ok(q)) if d.push(q).is_ok() => {}
                _ => self.skipped += 1,
            }
        }
    }

    /// The current surface row of `axis` (0 = x).
    pub fn estimate(&self, axis: usize) -> Option<DavarStep<T>> {
        self.axes.get(axis).map(Davar::estimate)
    }

    /// Axis-samples skipped so far.
    pub fn skipped(&self) -> u32 {
        self.skipped
    }
}

/// σ(τ = 2ʲ samples) of a surface row from [`NoiseTracker::estimate`], °/s
/// (0 before the window has filled, NaN for j out of range). Takes the row
/// so that logging several τ converts the sums once.
pub fn sigma_dps<const T: usize>(e: &DavarStep<T>, j: usize) -> f32 {
    e.avar.get(j).map_or(f32::NAN, |&v| sqrtf(v) * LSB_DPS)
}
