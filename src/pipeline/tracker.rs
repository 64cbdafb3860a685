//! Noise tracking of the fused axes: one E-DAVAR per axis, fed with the
//! fused rate quantised to [`LSB_DPS`]. Shared by the QEMU demo and the
//! board firmware.

use super::Output;
use crate::algo::allan::stream::quantise;
use crate::algo::davar::{Davar, DavarConfig, DavarError, DavarStep};
use crate::algo::math::sqrtf;
use crate::link::msg::Noise;

/// Input resolution of the tracker, °/s: ±2048 °/s fits the |w| < 2²⁰
/// integer range, and the step adds (LSB²/12) ≈ 3e-7 (°/s)² of white
/// noise, far below any MEMS gyro's.
pub const LSB_DPS: f32 = 1.0 / 512.0;

/// The segmented E-DAVAR (1 % false alarms per hop) for a window of up to
/// `lambda2` samples, λ1 = λ2/2.
pub const fn config(lambda2: u16) -> DavarConfig {
    DavarConfig::segmented(lambda2 / 2, lambda2)
}

/// E-DAVAR on the three fused axes.
///
/// Allan variances need contiguous samples: an axis whose sample is missing
/// (no fused value, a value that cannot be quantised, or a gap in the
/// sequence numbers from an overrun) restarts its window, counted in
/// [`NoiseTracker::restarts`], rather than splicing across the gap. Each
/// axis remembers the sequence number of its window's first sample, so every
/// estimate is reported with the sequence number it describes.
pub struct NoiseTracker<const CAP: usize, const FRAMES: usize, const T: usize> {
    axes: [Davar<CAP, FRAMES, T, 0>; 3],
    /// Per axis, the sequence number of sample 0 of its E-DAVAR.
    origin: [Option<u32>; 3],
    last_seq: Option<u32>,
    restarts: u32,
}

/// One estimate with the sequence number of the sample it describes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Described<const T: usize> {
    /// Sequence number of the sample at the estimate's time t.
    pub seq: u32,
    /// The surface row (window, score, Allan variances).
    pub step: DavarStep<T>,
}

impl<const CAP: usize, const FRAMES: usize, const T: usize> NoiseTracker<CAP, FRAMES, T> {
    /// One E-DAVAR per axis with `cfg`.
    pub fn new(cfg: DavarConfig) -> Result<Self, DavarError> {
        // Hops 11 samples apart, so the three axes never do their heaviest
        // sample together.
        Ok(Self {
            axes: [
                Davar::new(cfg)?.with_hop_phase(1),
                Davar::new(cfg)?.with_hop_phase(12),
                Davar::new(cfg)?.with_hop_phase(23),
            ],
            origin: [None; 3],
            last_seq: None,
            restarts: 0,
        })
    }

    /// Feed one pipeline output.
    pub fn push<const N: usize>(&mut self, out: &Output<N>) {
        let contiguous = self.last_seq.is_some_and(|s| out.seq == s.wrapping_add(1));
        self.last_seq = Some(out.seq);
        for ((d, f), origin) in self
            .axes
            .iter_mut()
            .zip(out.fused.iter())
            .zip(self.origin.iter_mut())
        {
            if origin.is_some() && !contiguous {
                d.reset();
                *origin = None;
                self.restarts += 1;
            }
            let q = f.map(|f| quantise(f.rate_dps, LSB_DPS));
            match q {
                Some(Ok(q)) if d.push(q).is_ok() => {
                    origin.get_or_insert(out.seq);
                }
                _ => {
                    if origin.is_some() {
                        d.reset();
                        *origin = None;
                        self.restarts += 1;
                    }
                }
            }
        }
    }

    /// The last published surface row of `axis` (0 = x) with the sequence
    /// number it describes: `None` until the axis's window has filled.
    pub fn estimate(&self, axis: usize) -> Option<Described<T>> {
        let step = self.axes.get(axis)?.estimate()?;
        let origin = (*self.origin.get(axis)?)?;
        Some(Described {
            seq: origin.wrapping_add(step.t as u32),
            step,
        })
    }

    /// The last estimate of `axis` as the output link sends it: σ at
    /// τ = 2^`taus[k]` samples with the sequence number it describes.
    /// `None` until the window has filled.
    pub fn noise(&self, axis: usize, taus: [usize; 3]) -> Option<Noise> {
        let d = self.estimate(axis)?;
        Some(Noise {
            axis: axis as u8,
            seq: d.seq,
            len: d.step.len,
            sigma_dps: taus.map(|j| sigma_dps(&d.step, j)),
        })
    }

    /// Window restarts so far (summed over axes).
    pub fn restarts(&self) -> u32 {
        self.restarts
    }
}

/// σ(τ = 2ʲ samples) of a surface row from [`NoiseTracker::estimate`], °/s
/// (NaN for j out of range). Takes the row
/// so that logging several τ converts the sums once.
pub fn sigma_dps<const T: usize>(e: &DavarStep<T>, j: usize) -> f32 {
    e.avar.get(j).map_or(f32::NAN, |&v| sqrtf(v) * LSB_DPS)
}
