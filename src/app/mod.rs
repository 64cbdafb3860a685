//! The per-sample schedule, written once: what the sample task does at
//! each tick, and what the background does with what it hands on. The
//! board's RTIC 2 tasks (`src/bin/board_f405.rs`) and the QEMU demo's loop
//! (`src/bin/qemu_demo.rs`) both run these functions; what differs between
//! them is only how the pieces are shared (RTIC's priority-ceiling locks,
//! or plain `&mut` through [`rtic_core::Exclusive`] where one loop owns
//! everything).
//!
//! The split: the **sample task** reads the array at the stated instant,
//! fuses, queues the frame, and lets the calibration learn from the
//! sample (deterministic: every sample, in order, before the next); the
//! **background** feeds the E-DAVARs, builds status frames and applies
//! commands. The sample task never waits for the E-DAVARs: their newest
//! estimates reach it as a [`NoiseSnapshot`] the background leaves after
//! each update, so a frame carries the estimate published so far.

use rtic_core::prelude::*;
use rtic_core::Mutex;

use crate::drivers::Gyro;
use crate::link::port::{ChipTime, NoiseSnapshot, Port};
use crate::pipeline::tracker::{NoiseTracker, Probe};
use crate::pipeline::{Output, Pipeline};

/// The board's time for its samples: one µs counter (TIM5 on the board,
/// the emulated bus's timer in QEMU) read at each tick, extended to 64
/// bits, and the periods that passed without a sample.
#[derive(Clone, Copy, Debug)]
pub struct SampleClock {
    last_us: u32,
    t_us: u64,
    period_us: u32,
}

impl SampleClock {
    /// Started at `now_us`, ticking every `period_us` of the counter.
    pub fn new(now_us: u32, period_us: u32) -> Self {
        Self {
            last_us: now_us,
            t_us: u64::from(now_us),
            period_us: period_us.max(1),
        }
    }

    /// The tick read at `now_us`: its 64-bit µs and the periods missed
    /// since the last (a tick more than half a period late counts one).
    pub fn tick(&mut self, now_us: u32) -> (u64, u32) {
        let elapsed = now_us.wrapping_sub(self.last_us);
        self.last_us = now_us;
        self.t_us = self.t_us.wrapping_add(u64::from(elapsed));
        let periods = elapsed.saturating_add(self.period_us / 2) / self.period_us;
        (self.t_us, periods.saturating_sub(1))
    }

    /// The counter's µs a sample period.
    pub fn period_us(&self) -> u32 {
        self.period_us
    }
}

/// Where frames go: the port, and what moves its queued bytes on (the
/// board's UART queue and interrupt; nothing where the loop drains the
/// port itself).
pub trait Link<const TX: usize> {
    /// The port.
    fn port(&mut self) -> &mut Port<TX>;
    /// Bytes were queued on the port.
    fn flush(&mut self);
}

impl<const TX: usize> Link<TX> for Port<TX> {
    fn port(&mut self) -> &mut Port<TX> {
        self
    }
    fn flush(&mut self) {}
}

/// What the sample task hands the background, in sample order.
#[derive(Clone, Copy, Debug)]
pub enum Job<const N: usize> {
    /// A sample's noise probe for the E-DAVARs.
    Sample(Probe),
    /// A status frame is due with sample `seq` read at `t_us`; the chips'
    /// clocks as the sample task's timed reads see them.
    Status {
        /// The sample's sequence number.
        seq: u32,
        /// Its time, µs.
        t_us: u64,
        /// Each chip's clock.
        clocks: [ChipTime; N],
    },
}

/// What one tick produced.
#[derive(Clone, Copy, Debug)]
pub struct Sampled<const N: usize> {
    /// The fused sample.
    pub out: Output<N>,
    /// Whether its frame was queued (the divider may skip it).
    pub sent: bool,
    /// Whether a status frame is due with it.
    pub status_due: bool,
}

/// The sample task's work at a tick read at `t_us`, `missed` periods after
/// the last: the chips read through `gyros` (already set to the tick's
/// instant), fused, the frame queued with the newest noise estimate, the
/// calibration's learning. The pipeline and the link are held for all of
/// it: everything else that takes them runs below this task. `queued`
/// runs the moment the frame is queued (where a measurement of the
/// response reads its clock).
pub fn sample<const N: usize, const TX: usize, L: Link<TX>>(
    pipe: &mut impl Mutex<T = Pipeline<N>>,
    link: &mut impl Mutex<T = L>,
    noise: &mut impl Mutex<T = NoiseSnapshot>,
    gyros: &mut [&mut dyn Gyro; N],
    t_us: u64,
    missed: u32,
    queued: impl FnOnce(),
) -> Sampled<N> {
    let estimates = noise.lock(|n| *n);
    (pipe, link).lock(|pipe, link| {
        if missed > 0 {
            pipe.note_overrun(missed);
        }
        let out = pipe.read_and_fuse(gyros);
        // The frame first: the antenna waits for it.
        let port = link.port();
        let before = port.counters().sent;
        port.publish(&out, t_us, pipe, &estimates);
        let sent = port.counters().sent != before;
        let status_due = port.status_due(out.seq);
        link.flush();
        queued();
        // The calibration learns from every sample, in order.
        pipe.finish();
        Sampled {
            out,
            sent,
            status_due,
        }
    })
}

/// The background's own state: the E-DAVARs and what its status frames
/// say of the board.
pub struct Background<'a, const CAP: usize, const FRAMES: usize, const T: usize> {
    /// The noise tracker (one E-DAVAR per fused axis).
    pub tracker: &'a mut NoiseTracker<CAP, FRAMES, T>,
    /// The τ of the link's noise records, as octaves: τ = 2ʲ samples.
    pub taus: [usize; 3],
    /// The sample period, µs, the status frames state.
    pub sample_us: u32,
}

impl<const CAP: usize, const FRAMES: usize, const T: usize> Background<'_, CAP, FRAMES, T> {
    /// One job from the sample task. `stack_peak` is what a status frame
    /// states of the stack.
    pub fn run<const N: usize, const TX: usize, L: Link<TX>>(
        &mut self,
        job: Job<N>,
        pipe: &mut impl Mutex<T = Pipeline<N>>,
        link: &mut impl Mutex<T = L>,
        noise: &mut impl Mutex<T = NoiseSnapshot>,
        stack_peak: u32,
    ) {
        match job {
            Job::Sample(probe) => {
                self.tracker.push_probe(probe);
                let snap = NoiseSnapshot::of(&self.tracker.at_taus(self.taus));
                noise.lock(|n| *n = snap);
            }
            Job::Status { seq, t_us, clocks } => {
                // The status frame states them in samples.
                let taus = self.taus.map(|j| 1u16.checked_shl(j as u32).unwrap_or(0));
                let sample_us = self.sample_us;
                (pipe, link).lock(|pipe, link| {
                    let port = link.port();
                    let st = port.status(pipe, seq, t_us, taus, sample_us, stack_peak, &clocks);
                    port.send(&st);
                    link.flush();
                });
            }
        }
    }
}

/// Apply the commands waiting in `rx` (bounded by the port), their
/// acknowledgements queued.
pub fn receive<const N: usize, const TX: usize, L: Link<TX>, R>(
    rx: &mut R,
    pipe: &mut impl Mutex<T = Pipeline<N>>,
    link: &mut impl Mutex<T = L>,
) where
    R: embedded_hal_nb::serial::Read<u8>,
{
    (pipe, link).lock(|pipe, link| {
        link.port().receive(rx, pipe);
        link.flush();
    });
}

/// The jobs of a tick: the probe always, a status frame when due.
pub fn jobs<const N: usize>(
    s: &Sampled<N>,
    t_us: u64,
    clocks: impl FnOnce() -> [ChipTime; N],
) -> (Job<N>, Option<Job<N>>) {
    (
        Job::Sample(Probe::from(&s.out)),
        s.status_due.then(|| Job::Status {
            seq: s.out.seq,
            t_us,
            clocks: clocks(),
        }),
    )
}
