//! Noise tracking of the fused axes: one E-DAVAR per axis, fed with the
//! array's noise probe (`Output::noise_probe_dps`) quantised to
//! [`LSB_DPS`]: noise with the fused rate's variance and none of the
//! platform's motion. Fed the fused rate itself, the tracker measured the
//! vehicle: a 20 °/s, 1 Hz sway read σ(τ0) 0.082 °/s for 0.051 on the
//! still axes, and at τ = 64 samples the sway was nearly all of it.
//! Shared by the QEMU demo and the board firmware.

use super::Output;
use crate::algo::allan::stream::quantise;
use crate::algo::davar::{Davar, DavarConfig, DavarError, DavarStep, SEG};
use crate::algo::math::sqrtf;

/// Input resolution of the tracker, °/s: ±2048 °/s fits the |w| < 2²⁰
/// integer range, and the step adds (LSB²/12) ≈ 3e-7 (°/s)² of white
/// noise, far below any MEMS gyro's.
pub const LSB_DPS: f32 = 1.0 / 512.0;

/// The segmented E-DAVAR (1 % false alarms per hop) for a window of up to
/// `lambda2` samples, λ1 = λ2/2.
pub const fn config(lambda2: u16) -> DavarConfig {
    DavarConfig::segmented(lambda2 / 2, lambda2)
}

/// The τ (2ʲ samples, j = 0, 4, 8: 1, 16 and 256 ms at 1 kHz) of the link
/// record a new tracker makes ready ([`NoiseTracker::set_view`]).
pub const VIEW_TAUS: [usize; 3] = [0, 4, 8];

/// [`config`] summing the link's three τ alone (every fourth octave, a
/// tracker with `T` = 3): what the board runs. The link's records are the
/// every-octave tracker's bit for bit, and the sums of the six τ nobody
/// reads are not made (some 250 instructions a sample and 3.9 KB of RAM
/// an axis, `cargo xtask bench`).
pub const fn link_config(lambda2: u16) -> DavarConfig {
    config(lambda2).with_tau_octaves(VIEW_TAUS[1] as u8)
}

/// The three axes' hop phases. Each axis's heavy samples are the τ terms
/// after its hop and the segmentation's last rows (samples 1–7 of its
/// hop) and the placement, publication and segmentation start (17–21);
/// apart, the three axes' heavy samples do not meet, so the background's
/// job stays near one axis's worst (the three axes' worst sample at
/// [8, 17, 30] is 2 266 instructions, `cargo xtask bench`; hopping
/// together, their heaviest samples would add up) and a probe waits in
/// its channel behind one short job. The
/// values were chosen when the E-DAVARs shared the sample's loop with the
/// calibration's solves and the read-backs; any three phases apart serve
/// the background.
pub const HOP_PHASES: [u8; 3] = [8, 17, 30];

/// Write one axis's E-DAVAR to `dst`; not inlined, so that each axis's
/// temporaries reuse one frame.
#[inline(never)]
#[allow(unsafe_code)]
fn build_axis<const CAP: usize, const FRAMES: usize, const T: usize>(
    dst: *mut Davar<CAP, FRAMES, T, 0>,
    cfg: DavarConfig,
    phase: u8,
) -> Result<(), DavarError> {
    let d = Davar::new(cfg)?;
    // SAFETY: the caller passes a pointer valid for writes of one Davar;
    // once written it is initialised and may be borrowed.
    unsafe {
        dst.write(d);
        (*dst).set_hop_phase(phase);
    }
    Ok(())
}

/// A missing noise-probe sample is bridged (the last one held) at most once
/// per this many samples of the axis's window, in the long run.
pub const BRIDGE_EVERY: u16 = 128;
/// Bridges saved up over a quiet stretch, for a burst (fallbacks come in
/// clusters while two chips misbehave at once).
pub const BRIDGE_BURST: u16 = 4;
/// How far before `bridge_at` a bridge is allowed: BRIDGE_BURST − 1 periods.
const BRIDGE_SAVED: u32 = (BRIDGE_BURST as u32 - 1) * BRIDGE_EVERY as u32;
/// Bridged samples remembered per axis (their sequence numbers), to count
/// those inside an estimate's window. The ring holds the newest, so it
/// must hold every bridge from the start of a window read now: a window is
/// at most CAP samples and closes at most [`HELD_LAG`] samples before its
/// estimate is last read. The credit allows at most BRIDGE_BURST +
/// ⌈n / BRIDGE_EVERY⌉ bridges in n samples, so 40 cover a capacity of up
/// to 4 480 samples (checked at construction).
const HELD_MEMORY: usize = 40;
/// Samples from a window's end to the last read of its estimate, at most:
/// the span ends on the last whole frame before the hop (≤ 2 frames back
/// by the time the hop's work is done), and the estimate is replaced a
/// frame later; one frame more of margin (the board's sample task reads a
/// copy made when the estimate is published, never later).
const HELD_LAG: usize = 4 * SEG;

/// E-DAVAR on the three fused axes.
///
/// Allan variances need contiguous samples. An axis whose noise probe is
/// missing on a sample (fusion fell back: no majority to vouch for any
/// chip) holds its last value for it: one sample in [`BRIDGE_EVERY`] in the
/// long run, up to [`BRIDGE_BURST`] saved up (so at most 12 in a window of
/// 1024; none in the window's first [`BRIDGE_EVERY`]), counted in
/// [`NoiseTracker::bridged`], and per estimate, those inside its window, in
/// [`Described::bridged`] and the link's noise record. A held sample takes one first difference out
/// and doubles the next: for white noise σ²(τ0) of a window of n samples
/// reads about 1/n low per held sample in it, so at most 1.2 % at
/// λ2 = 1024, and 0.8 % with one sample in 130 missing
/// (`a_bridged_gap_keeps_the_estimate`). Restarting on each one lost 1.1 s
/// of noise figures per fallback: scenario E of `cargo xtask bench-loop`,
/// where two chips spike at once, restarted 22 times; now 4, with 22
/// samples bridged.
/// Beyond that budget, or on a value that cannot be quantised, or a gap in
/// the sequence numbers from an overrun, the axis restarts its window,
/// counted in [`NoiseTracker::restarts`], rather than splicing across the
/// gap. Each axis remembers the sequence number of its window's first
/// sample, so every estimate is reported with the sequence number it
/// describes.
pub struct NoiseTracker<const CAP: usize, const FRAMES: usize, const T: usize> {
    axes: [Davar<CAP, FRAMES, T, 0>; 3],
    /// Per axis, the sequence number of sample 0 of its E-DAVAR.
    origin: [Option<u32>; 3],
    last_seq: Option<u32>,
    restarts: u32,
    /// Per axis, when its bridging credit is all spent (a generic cell
    /// rate algorithm's theoretical arrival time): a bridge is allowed
    /// from BRIDGE_BURST − 1 periods before it, and moves it a period on.
    bridge_at: [u32; 3],
    bridged: u32,
    /// Per axis, the sequence numbers of its window's bridged samples (a
    /// ring), and how many since its window started.
    held: [[u32; HELD_MEMORY]; 3],
    held_count: [u32; 3],
    /// The link record's τ ([`VIEW_TAUS`] unless set).
    view: [usize; 3],
    /// Per axis, its newest estimate as the link sends it at `view`, and
    /// the estimate's edition (`Davar::estimate_edition`) it was made
    /// from: made in the idle time the sample it is published on, so the
    /// frame that carries it only copies it (the sums' conversions, the
    /// square roots and the bridged count cost some 250 instructions).
    ready: [(u32, Option<AxisNoise>); 3],
}

/// One estimate with the sequence number of the sample it describes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Described<const T: usize> {
    /// Sequence number of the sample at the estimate's time t.
    pub seq: u32,
    /// Samples of the window that were bridged ([`NoiseTracker`]).
    pub bridged: u8,
    /// The surface row (window, score, Allan variances).
    pub step: DavarStep<T>,
}

impl<const CAP: usize, const FRAMES: usize, const T: usize> NoiseTracker<CAP, FRAMES, T> {
    /// Every window's bridged samples fit in [`HELD_MEMORY`].
    const HELD_FIT: () = assert!(
        BRIDGE_BURST as usize + (CAP + HELD_LAG).div_ceil(BRIDGE_EVERY as usize) <= HELD_MEMORY,
        "a window could hold more bridged samples than the tracker remembers"
    );

    /// One E-DAVAR per axis with `cfg`.
    pub fn new(cfg: DavarConfig) -> Result<Self, DavarError> {
        let () = Self::HELD_FIT;
        Ok(Self {
            axes: [
                Davar::new(cfg)?.with_hop_phase(HOP_PHASES[0]),
                Davar::new(cfg)?.with_hop_phase(HOP_PHASES[1]),
                Davar::new(cfg)?.with_hop_phase(HOP_PHASES[2]),
            ],
            origin: [None; 3],
            last_seq: None,
            restarts: 0,
            bridge_at: [0; 3],
            bridged: 0,
            held: [[0; HELD_MEMORY]; 3],
            held_count: [0; 3],
            view: VIEW_TAUS,
            ready: [(0, None); 3],
        })
    }

    /// Build the tracker in place in `slot` (a firmware static), one axis
    /// at a time: the stack holds one axis under construction (≈ 7 KB for
    /// the board's λ2 = 1024 and three τ, 11 KB at nine) instead of the whole tracker twice, as returning it
    /// by value does (66 KB on the board, measured from the frame size).
    /// On error `slot` stays uninitialised.
    #[allow(unsafe_code)]
    pub fn init_in(
        slot: &mut core::mem::MaybeUninit<Self>,
        cfg: DavarConfig,
    ) -> Result<&mut Self, DavarError> {
        let () = Self::HELD_FIT;
        let p = slot.as_mut_ptr();
        // SAFETY: `p` is valid for writes of `Self` (from the MaybeUninit);
        // `axes` is an array of 3. Fields are written through raw pointers,
        // never read before they are written.
        let axes = unsafe { core::ptr::addr_of_mut!((*p).axes).cast::<Davar<CAP, FRAMES, T, 0>>() };
        for (i, phase) in HOP_PHASES.into_iter().enumerate() {
            // SAFETY: i < 3, inside `axes`.
            build_axis(unsafe { axes.add(i) }, cfg, phase)?;
        }
        // SAFETY: as above; after these writes every field is initialised.
        unsafe {
            core::ptr::addr_of_mut!((*p).origin).write([None; 3]);
            core::ptr::addr_of_mut!((*p).last_seq).write(None);
            core::ptr::addr_of_mut!((*p).restarts).write(0);
            core::ptr::addr_of_mut!((*p).bridge_at).write([0; 3]);
            core::ptr::addr_of_mut!((*p).bridged).write(0);
            core::ptr::addr_of_mut!((*p).held).write([[0; HELD_MEMORY]; 3]);
            core::ptr::addr_of_mut!((*p).held_count).write([0; 3]);
            core::ptr::addr_of_mut!((*p).view).write(VIEW_TAUS);
            core::ptr::addr_of_mut!((*p).ready).write([(0, None); 3]);
            Ok(slot.assume_init_mut())
        }
    }

    /// Feed one pipeline output.
    pub fn push<const N: usize>(&mut self, out: &Output<N>) {
        self.push_probe(Probe::from(out));
    }

    /// Feed what the tracker takes of one pipeline output (kept by the
    /// board loop until its sample frame is on the wire).
    pub fn push_probe(&mut self, out: Probe) {
        let contiguous = self.last_seq.is_some_and(|s| out.seq == s.wrapping_add(1));
        self.last_seq = Some(out.seq);
        // (By index: a `zip` of the axes with the probes cost some 70
        // instructions an axis in iterator state on the Cortex-M4.)
        for a in 0..3 {
            let (Some(d), Some(&p), Some(origin), Some(bridge_at)) = (
                self.axes.get_mut(a),
                out.noise_probe_dps.get(a),
                self.origin.get_mut(a),
                self.bridge_at.get_mut(a),
            ) else {
                continue;
            };
            if origin.is_some() && !contiguous {
                d.reset();
                *origin = None;
                self.restarts += 1;
            }
            let q = match p {
                Some(p) => Some(quantise(p, LSB_DPS)),
                // Bridged: the window's last sample again, within the
                // credit (wrapping comparisons: the sequence numbers wrap).
                None if origin.is_some()
                    && out.seq.wrapping_sub(bridge_at.wrapping_sub(BRIDGE_SAVED)) as i32 >= 0 =>
                {
                    let spent = (out.seq.wrapping_sub(*bridge_at) as i32) < 0;
                    *bridge_at = if spent { *bridge_at } else { out.seq };
                    *bridge_at = bridge_at.wrapping_add(u32::from(BRIDGE_EVERY));
                    self.bridged += 1;
                    if let (Some(ring), Some(n)) =
                        (self.held.get_mut(a), self.held_count.get_mut(a))
                    {
                        if let Some(slot) = ring.get_mut(*n as usize % HELD_MEMORY) {
                            *slot = out.seq;
                        }
                        *n = n.saturating_add(1);
                    }
                    d.last_sample().map(Ok)
                }
                None => None,
            };
            match q {
                // A window starts on the sequence numbers' 32-sample grid
                // (up to 31 samples late), so every axis's frames, and its
                // heavy samples with them, keep their phases against the
                // calibration's solves (`calib::SOLVE_SLOTS`) after any
                // restart.
                Some(Ok(_)) if origin.is_none() && !out.seq.is_multiple_of(SEG as u32) => {}
                Some(Ok(q)) if d.push(q).is_ok() => {
                    if origin.is_none() {
                        *origin = Some(out.seq);
                        if let Some(n) = self.held_count.get_mut(a) {
                            *n = 0;
                        }
                        // Credit starts empty: the first bridge a period on.
                        *bridge_at = out.seq.wrapping_add(BRIDGE_SAVED + u32::from(BRIDGE_EVERY));
                    }
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
        for a in 0..3 {
            self.make_ready(a);
        }
    }

    /// Remake `axis`'s link record if its estimate has changed since.
    fn make_ready(&mut self, axis: usize) {
        let edition = self.axes.get(axis).map(|d| d.estimate_edition());
        if self.ready.get(axis).map(|r| r.0) != edition {
            self.remake(axis);
        }
    }

    /// Make `axis`'s link record at the view's τ from its estimate now.
    fn remake(&mut self, axis: usize) {
        let Some(edition) = self.axes.get(axis).map(|d| d.estimate_edition()) else {
            return;
        };
        let record = self.record(axis, self.view);
        if let Some(r) = self.ready.get_mut(axis) {
            *r = (edition, record);
        }
    }

    /// The τ (2ʲ samples) the link record made ready after each estimate
    /// has; a view at other τ ([`Self::at_taus`]) makes its own on demand.
    pub fn set_view(&mut self, taus: [usize; 3]) {
        self.view = taus;
        for a in 0..3 {
            self.remake(a);
        }
    }

    /// `axis`'s newest estimate as the link sends it, σ at τ = 2^`taus[k]`.
    fn record(&self, axis: usize, taus: [usize; 3]) -> Option<AxisNoise> {
        let d = self.axes.get(axis)?;
        let (t, len) = d.estimate_window()?;
        let origin = (*self.origin.get(axis)?)?;
        Some(AxisNoise {
            seq: origin.wrapping_add(t as u32),
            len,
            bridged: self.bridged_in(axis, origin, d.estimate_span()?),
            sigma_dps: taus.map(|e| {
                d.tau_index(e)
                    .and_then(|j| d.estimate_avar(j))
                    .map_or(f32::NAN, |v| sqrtf(v) * LSB_DPS)
            }),
        })
    }

    /// The last published surface row of `axis` (0 = x) with the sequence
    /// number it describes: `None` until the axis's window has filled.
    pub fn estimate(&self, axis: usize) -> Option<Described<T>> {
        let step = self.axes.get(axis)?.estimate()?;
        let origin = (*self.origin.get(axis)?)?;
        Some(Described {
            seq: origin.wrapping_add(step.t as u32),
            bridged: self.bridged_in(axis, origin, (step.start, step.end)),
            step,
        })
    }

    /// How many of `axis`'s bridged samples lie in its window [start,
    /// end) (sample indices from `origin`).
    fn bridged_in(&self, axis: usize, origin: u32, (start, end): (u64, u64)) -> u8 {
        let (Some(ring), Some(&n)) = (self.held.get(axis), self.held_count.get(axis)) else {
            return 0;
        };
        let first = origin.wrapping_add(start as u32);
        let len = end.saturating_sub(start) as u32;
        let kept = ring.get(..(n as usize).min(HELD_MEMORY)).unwrap_or(&[]);
        let inside = kept
            .iter()
            .filter(|&&s| s.wrapping_sub(first) < len)
            .count();
        inside.min(usize::from(u8::MAX)) as u8
    }

    /// The link's view of the tracker: σ at τ = 2^`taus[k]` samples.
    pub fn at_taus(&self, taus: [usize; 3]) -> NoiseView<'_, CAP, FRAMES, T> {
        NoiseView {
            tracker: self,
            taus,
        }
    }

    /// Window restarts so far (summed over axes).
    pub fn restarts(&self) -> u32 {
        self.restarts
    }

    /// Missing samples bridged so far (summed over axes).
    pub fn bridged(&self) -> u32 {
        self.bridged
    }
}

/// What the tracker takes of a sample: its sequence number and each axis's
/// noise probe ([`Output::noise_probe_dps`]). The board keeps it, not the
/// whole output, for the idle time after the sample's frame has gone out:
/// the antenna waits for the frame, not for the E-DAVARs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Probe {
    /// The sample's sequence number.
    pub seq: u32,
    /// Per axis, the noise probe (`None`: fewer than two gyros fused).
    pub noise_probe_dps: [Option<f32>; 3],
}

impl<const N: usize> From<&Output<N>> for Probe {
    fn from(out: &Output<N>) -> Self {
        Self {
            seq: out.seq,
            noise_probe_dps: out.noise_probe_dps,
        }
    }
}

/// The tracker as the output link reads it ([`NoiseTracker::at_taus`];
/// `link::port` makes its frames' noise record of it).
pub struct NoiseView<'a, const CAP: usize, const FRAMES: usize, const T: usize> {
    tracker: &'a NoiseTracker<CAP, FRAMES, T>,
    taus: [usize; 3],
}

/// An axis's newest estimate, as the link sends it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisNoise {
    /// Sequence number of the sample it describes.
    pub seq: u32,
    /// Window length, samples.
    pub len: u16,
    /// Missing samples of the window bridged by holding the one before.
    pub bridged: u8,
    /// σ at the view's three τ, °/s (NaN where out of range).
    pub sigma_dps: [f32; 3],
}

impl<const CAP: usize, const FRAMES: usize, const T: usize> NoiseView<'_, CAP, FRAMES, T> {
    /// Sequence number of the sample the axis's newest estimate describes
    /// (cheap: the link asks every sample).
    pub fn described(&self, axis: usize) -> Option<u32> {
        let (t, _) = self.tracker.axes.get(axis)?.estimate_window()?;
        let origin = (*self.tracker.origin.get(axis)?)?;
        Some(origin.wrapping_add(t as u32))
    }

    /// The axis's newest estimate: the record made ready when it was
    /// published where this view's τ are the tracker's
    /// ([`NoiseTracker::set_view`]), else made now.
    pub fn newest(&self, axis: usize) -> Option<AxisNoise> {
        let t = self.tracker;
        let edition = t.axes.get(axis)?.estimate_edition();
        // (Element by element: `==` on the arrays is a call to memcmp,
        // some 85 instructions on the Cortex-M4.)
        let (a, v) = (self.taus, t.view);
        let same_view = (a[0] ^ v[0]) | (a[1] ^ v[1]) | (a[2] ^ v[2]) == 0;
        match t.ready.get(axis) {
            Some(&(e, record)) if e == edition && same_view => record,
            _ => t.record(axis, self.taus),
        }
    }
}

/// σ(τ = 2ʲ samples) of a surface row from [`NoiseTracker::estimate`], °/s
/// (NaN where the row has no such τ). Takes the row
/// so that logging several τ converts the sums once.
pub fn sigma_dps<const T: usize>(e: &DavarStep<T>, j: usize) -> f32 {
    e.avar_at(j).map_or(f32::NAN, |v| sqrtf(v) * LSB_DPS)
}

#[cfg(test)]
mod tests {
    use super::*;
    use gyro_sim::Rng;

    /// White noise on three axes, the same on each: x whole, y missing one
    /// sample in 130 (within the budget), z one in 10 (beyond it). y keeps
    /// its window and its σ²(τ0) stays within 1/BRIDGE_EVERY (and half
    /// that again for the estimate's own spread) of x's; z restarts.
    #[test]
    fn a_bridged_gap_keeps_the_estimate() {
        let mut t = NoiseTracker::<1024, 35, 9>::new(config(1024)).unwrap();
        let mut rng = Rng::new(5);
        let (mut sum, mut n) = ([0.0f64; 2], 0);
        let mut last = None;
        for k in 0..40_000u32 {
            let p = 0.01 * rng.gaussian();
            let out = Output::<1> {
                seq: k,
                rate_dps: [[0.0; 3]],
                delay_us: [0],
                offered: [0; 3],
                fused: [None; 3],
                noise_probe_dps: [
                    Some(p),
                    (k % 130 != 77).then_some(p),
                    (k % 10 != 7).then_some(p),
                ],
                health_changed: 0,
            };
            t.push(&out);
            if let (Some(x), Some(y)) = (t.estimate(0), t.estimate(1)) {
                if last != Some(x.seq) && x.seq == y.seq {
                    last = Some(x.seq);
                    sum[0] += f64::from(x.step.avar[0]);
                    sum[1] += f64::from(y.step.avar[0]);
                    n += 1;
                }
            }
        }
        assert!(n > 1000, "{n} estimates in common");
        let ratio = sum[1] / sum[0];
        let bound = 1.0 / f64::from(BRIDGE_EVERY);
        assert!(
            ratio < 1.0 && ratio > 1.0 - 1.5 * bound,
            "sigma2(tau0) ratio {ratio}"
        );
        assert!(t.bridged() >= 280, "{} bridged", t.bridged());
        println!(
            "ratio {ratio}, {} bridged, {} restarts",
            t.bridged(),
            t.restarts()
        );
        assert!(
            t.restarts() > 100,
            "z beyond the budget restarts: {}",
            t.restarts()
        );
        assert!(t.estimate(1).is_some(), "y kept its window");
    }

    /// Every estimate, and the link's noise record, counts the bridged
    /// samples inside its own window: checked against the samples seen
    /// bridged as they were pushed (one missing in 130 on y, none on x),
    /// across the sequence numbers' wrap.
    #[test]
    fn estimates_count_the_bridged_samples_in_their_window() {
        let mut t = NoiseTracker::<1024, 35, 9>::new(config(1024)).unwrap();
        let mut rng = Rng::new(7);
        let first = 0xFFFF_E000u32; // on the 32-sample grid, 8192 before the wrap
        let mut held = Vec::new();
        let (mut checked, mut with_held, mut last) = (0, 0, None);
        for k in 0..20_000u32 {
            let seq = first.wrapping_add(k);
            let p = 0.01 * rng.gaussian();
            let out = Output::<1> {
                seq,
                rate_dps: [[0.0; 3]],
                delay_us: [0],
                offered: [0; 3],
                fused: [None; 3],
                noise_probe_dps: [Some(p), (k % 130 != 77).then_some(p), Some(p)],
                health_changed: 0,
            };
            let before = t.bridged();
            t.push(&out);
            if t.bridged() > before {
                held.push(seq);
            }
            let Some(y) = t.estimate(1) else { continue };
            if last == Some(y.seq) {
                continue;
            }
            last = Some(y.seq);
            let start = y.seq.wrapping_sub((y.step.t - y.step.start) as u32);
            let len = (y.step.end - y.step.start) as u32;
            let want = held
                .iter()
                .filter(|&&s| s.wrapping_sub(start) < len)
                .count();
            assert_eq!(usize::from(y.bridged), want, "estimate for seq {}", y.seq);
            let link = t.at_taus([0, 4, 8]).newest(1).unwrap();
            assert_eq!((link.seq, link.bridged), (y.seq, y.bridged));
            assert_eq!(t.estimate(0).map(|x| x.bridged), Some(0));
            checked += 1;
            with_held += usize::from(y.bridged > 0);
        }
        assert!(held.len() > 100, "{} bridged", held.len());
        assert!(
            checked > 300 && with_held * 10 > checked * 9,
            "{with_held} of {checked}"
        );
    }

    /// The record made ready as each estimate is published is the one
    /// the link would make on demand, through bridges, restarts and a
    /// change of view; a view at other τ makes its own.
    #[test]
    fn the_ready_record_is_the_one_made_on_demand() {
        let mut t = NoiseTracker::<1024, 35, 9>::new(config(1024)).unwrap();
        let mut rng = Rng::new(11);
        let (mut compared, mut changed, mut last) = (0, 0, [None; 3]);
        for k in 0..30_000u32 {
            if k == 15_000 {
                t.set_view([1, 2, 3]);
            }
            let p = 0.01 * rng.gaussian() * if k > 9_000 { 2.0 } else { 1.0 };
            // y bridges one in 130; z loses a run of 40 at 12 000 (a
            // restart); every axis skips sample 20 000 (a gap).
            let z_gap = (12_000..12_040).contains(&k);
            if k == 20_000 {
                continue;
            }
            t.push_probe(Probe {
                seq: k,
                noise_probe_dps: [Some(p), (k % 130 != 77).then_some(p), (!z_gap).then_some(p)],
            });
            let view = t.view;
            for a in 0..3 {
                // The record is the current estimate's, so the link copies it.
                assert_eq!(
                    t.ready[a].0,
                    t.axes[a].estimate_edition(),
                    "axis {a} at {k}"
                );
                let ready = t.at_taus(view).newest(a);
                assert_eq!(ready, t.record(a, view), "axis {a} at {k}");
                compared += usize::from(ready.is_some());
                if ready.map(|r| r.seq) != last[a] {
                    changed += 1;
                    last[a] = ready.map(|r| r.seq);
                }
                let other = [view[0], view[1], 5];
                assert_eq!(t.at_taus(other).newest(a), t.record(a, other));
            }
        }
        assert!(
            t.restarts() >= 4 && t.bridged() > 100,
            "{} {}",
            t.restarts(),
            t.bridged()
        );
        assert!(compared > 60_000 && changed > 2_000, "{compared} {changed}");
    }

    /// The board's tracker, summing the link's three τ alone, sends the
    /// every-octave tracker's records bit for bit, through a variance
    /// step, bridges and a restart.
    #[test]
    fn the_link_taus_alone_give_the_same_records() {
        let mut all = NoiseTracker::<1024, 35, 9>::new(config(1024)).unwrap();
        let mut three = NoiseTracker::<1024, 35, 3>::new(link_config(1024)).unwrap();
        let mut rng = Rng::new(12);
        let mut compared = 0;
        for k in 0..20_000u32 {
            let p = 0.01 * rng.gaussian() * if k > 9_000 { 2.0 } else { 1.0 };
            let probe = Probe {
                seq: k,
                noise_probe_dps: [
                    Some(p),
                    (k % 130 != 77).then_some(p),
                    (!(12_000..12_040).contains(&k)).then_some(p),
                ],
            };
            all.push_probe(probe);
            three.push_probe(probe);
            for a in 0..3 {
                let (x, y) = (
                    all.at_taus(VIEW_TAUS).newest(a),
                    three.at_taus(VIEW_TAUS).newest(a),
                );
                assert_eq!(
                    x.map(|r| (r.seq, r.len, r.bridged, r.sigma_dps.map(f32::to_bits))),
                    y.map(|r| (r.seq, r.len, r.bridged, r.sigma_dps.map(f32::to_bits))),
                    "axis {a} at {k}"
                );
                compared += usize::from(x.is_some());
                let (e, f) = (all.estimate(a), three.estimate(a));
                for j in VIEW_TAUS {
                    assert_eq!(
                        e.map(|e| sigma_dps(&e.step, j).to_bits()),
                        f.map(|f| sigma_dps(&f.step, j).to_bits())
                    );
                }
            }
            // A τ the three-τ tracker does not sum is NaN, not another's.
            if let Some(f) = three.estimate(0) {
                assert!(sigma_dps(&f.step, 2).is_nan());
            }
        }
        assert!(compared > 40_000, "{compared}");
    }

    /// After a quiet stretch an axis bridges a burst of BRIDGE_BURST
    /// missing samples, and restarts on the next; across the sequence
    /// numbers' wrap.
    #[test]
    fn a_burst_is_bridged_then_the_window_restarts() {
        let mut t = NoiseTracker::<1024, 35, 9>::new(config(1024)).unwrap();
        let mut rng = Rng::new(6);
        let first = 0xFFFF_FC00u32; // on the 32-sample grid, 1024 before the wrap
        for k in 0..3000u32 {
            let p = 0.01 * rng.gaussian();
            let gap = (2000..2006).contains(&k);
            let out = Output::<1> {
                seq: first.wrapping_add(k),
                rate_dps: [[0.0; 3]],
                delay_us: [0],
                offered: [0; 3],
                fused: [None; 3],
                noise_probe_dps: [(!gap).then_some(p), Some(p), Some(p)],
                health_changed: 0,
            };
            t.push(&out);
            if k == 2003 {
                assert_eq!((t.bridged(), t.restarts()), (4, 0));
            }
        }
        assert_eq!(t.bridged(), u32::from(BRIDGE_BURST));
        assert_eq!(t.restarts(), 1);
    }
}
