//! The centred placement (`Placement::Centred`, the paper's eq. 1–4): a
//! window of the current length around t, the length moved by the entropy
//! rule over the window's frames.

use super::sums::{ahead, slot, Sums};
use super::{DavarConfig, EntropyKind, StepMode, BINS, SEG};
use crate::algo::math::lnf;

/// The centred placement's state: each frame's STFT power (bins 1..=15),
/// energy and e·ln e (`STFT` frames, one per block), and the window's
/// length.
#[derive(Clone, Debug)]
pub(super) struct Centred<const FRAMES: usize, const STFT: usize> {
    /// Frames in the span (λ2 rounded down) and the shortest window.
    span: usize,
    min_frames: usize,
    frames: [[f32; BINS]; STFT],
    energy: [f32; STFT],
    eloge: [f32; STFT],
    /// Current length in samples (eq. 4's state).
    len: u16,
    /// The last entropy score and the threshold it was compared with.
    pub(super) score: Option<(f32, f32)>,
    /// The window placed at the last hop (span's first frame and window
    /// frames), published at the next.
    pub(super) pending: Option<(u64, usize, usize)>,
}

impl<const FRAMES: usize, const STFT: usize> Centred<FRAMES, STFT> {
    /// Windows of `l_init` samples to start, in spans of `span` frames and
    /// no shorter than `min_frames`.
    pub(super) fn new(span: usize, min_frames: usize, l_init: u16) -> Self {
        Self {
            span,
            min_frames,
            frames: [[0.0; BINS]; STFT],
            energy: [0.0; STFT],
            eloge: [0.0; STFT],
            len: l_init,
            score: None,
            pending: None,
        }
    }
    /// Forget the windows (after a gap in the input); the frames' spectra
    /// are written again before they are read.
    pub(super) fn reset(&mut self, l_init: u16) {
        self.len = l_init;
        self.score = None;
        self.pending = None;
    }
    /// Centred placement: eq. 4 (when adaptive), then the window of the
    /// current length around t, in frames of the span.
    pub(super) fn place(
        &mut self,
        first: u64,
        s0: usize,
        adaptive: bool,
        cfg: &DavarConfig,
        thresholds: &[f32; FRAMES],
    ) -> (usize, usize) {
        let (k, min_frames) = (self.span, self.min_frames);
        let frames_of = move |len: u16| -> usize {
            // Whole frames of the span's parity, so the window is centred.
            let mut f = (len as usize / SEG).max(min_frames).min(k);
            if (k - f) % 2 == 1 {
                f = if f < k { f + 1 } else { f - 1 };
            }
            f
        };
        if adaptive {
            let f = frames_of(self.len);
            let lo = first + ((k - f) / 2) as u64;
            let s_lo = ahead::<FRAMES>(s0, (k - f) / 2);
            self.adapt(lo, lo + f as u64, s_lo, cfg, thresholds);
        }
        let f = frames_of(self.len);
        ((k - f) / 2, (k + f) / 2)
    }
    /// FFT of the frame that just completed (the last 32 samples of
    /// `sums`); keep the power of bins 1..=15.
    pub(super) fn store_frame<const CAP: usize, const T: usize>(
        &mut self,
        sums: &Sums<CAP, FRAMES, T>,
    ) {
        let mut x = [0.0f32; SEG];
        let first = sums.n - SEG as u64;
        for (i, v) in x.iter_mut().enumerate() {
            *v = sums.w(first + i as u64) as f32;
        }
        let spec = microfft::real::rfft_32(&mut x);
        let slot = slot::<FRAMES>(first / SEG as u64);
        let (Some(frame), Some(energy), Some(eloge)) = (
            self.frames.get_mut(slot),
            self.energy.get_mut(slot),
            self.eloge.get_mut(slot),
        ) else {
            return; // STFT < FRAMES is refused for windows that need it
        };
        let mut e = 0.0f32;
        for (p, c) in frame.iter_mut().zip(spec[1..].iter()) {
            *p = c.re * c.re + c.im * c.im;
            e += *p;
        }
        *energy = e;
        *eloge = if e > 0.0 { e * lnf(e) } else { 0.0 };
    }
    /// Entropy of frames [f_lo, f_hi) (the first in slot `s0`) and the
    /// eq. 4 update of the length.
    fn adapt(
        &mut self,
        f_lo: u64,
        f_hi: u64,
        s0: usize,
        cfg: &DavarConfig,
        thresholds: &[f32; FRAMES],
    ) {
        let k = (f_hi - f_lo) as usize;
        if k < 2 {
            return;
        }
        let slots = (0..k).map(move |i| {
            if s0 + i >= FRAMES {
                s0 + i - FRAMES
            } else {
                s0 + i
            }
        });
        let score = match cfg.entropy {
            EntropyKind::Temporal => {
                let (mut tot, mut sum_eloge) = (0.0f32, 0.0f32);
                for s in slots {
                    tot += self.energy.get(s).copied().unwrap_or(0.0);
                    sum_eloge += self.eloge.get(s).copied().unwrap_or(0.0);
                }
                if !(tot > 0.0) {
                    return;
                }
                // D = ln K − H, H = ln Σe − Σ(e ln e)/Σe.
                lnf(k as f32) - (lnf(tot) - sum_eloge / tot)
            }
            EntropyKind::Spectral => {
                let mut bins = [0.0f32; BINS];
                for f in slots.filter_map(|s| self.frames.get(s)) {
                    for (b, p) in bins.iter_mut().zip(f.iter()) {
                        *b += p;
                    }
                }
                let tot: f32 = bins.iter().sum();
                if !(tot > 0.0) {
                    return;
                }
                let mut h = 0.0f32;
                for &p in &bins {
                    if p > 0.0 {
                        let q = p / tot;
                        h -= q * lnf(q);
                    }
                }
                h / lnf(BINS as f32)
            }
        };
        let th = thresholds[k.min(FRAMES - 1)];
        self.score = Some((score, th));
        let dl = cfg.delta_l as f32;
        let step = match cfg.step {
            StepMode::Constant => {
                if score > th {
                    dl
                } else if score < th {
                    -dl
                } else {
                    0.0
                }
            }
            StepMode::Proportional => {
                let r = if th != 0.0 {
                    (score - th) / th.abs()
                } else {
                    0.0
                };
                r.clamp(-1.0, 1.0) * dl
            }
        };
        let tentative = (self.len as f32 - step) as i32 & !1;
        // (max then min: `clamp` asserts λ1 ≤ λ2, which `new` checked.)
        self.len = tentative.max(cfg.lambda1 as i32).min(cfg.lambda2 as i32) as u16;
    }
}
