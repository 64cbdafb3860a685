//! The per-sample schedule, written once: what the sample task does at
//! each tick, and what the background does with what it hands on. The
//! board's RTIC 2 tasks (`src/bin/board_f405.rs`) and the QEMU demo's loop
//! (`sim/src/bin/qemu_demo.rs`) both run these functions; what differs between
//! them is only how the pieces are shared (RTIC's priority-ceiling locks,
//! or plain `&mut` through [`rtic_core::Exclusive`] where one loop owns
//! everything).
//!
//! The split: the **sample task** reads the array at the stated instant,
//! fuses, queues the frame, lets the calibration learn from the sample
//! (deterministic: every sample, in order, before the next) and, when one
//! is due, queues a status frame behind it; the **background** feeds the
//! E-DAVARs and applies commands. The sample task never waits for the
//! E-DAVARs: their newest estimates reach it as a [`NoiseSnapshot`] the
//! background leaves after each update, so a frame carries the estimate
//! published so far. The status frame is the sample task's because it
//! reads the pipeline and the port: built in the background, it would hold
//! both against the next sample.

use rtic_core::prelude::*;
use rtic_core::Mutex;

use crate::algo::static_cal::CalRecord;
use crate::drivers::icm42688::ClockInput;
use crate::drivers::Gyro;
use crate::link::msg::{
    ClockSource, FifoAnomalies, FusionMethod, GyroStatus, Noise, Reject, Start,
};
use crate::link::port::{
    Array, ChipTime, FramePath, NoiseSnapshot, NoiseSource, Port, SampleOut, StoreRequest,
};
use crate::link::ring::TxQueue;
use crate::pipeline::timed::{array_instant, board_delay_us, tracking, TimedIcm};
use crate::pipeline::tracker::{NoiseTracker, NoiseView, Probe};
use crate::pipeline::{Output, Pipeline};
use crate::store::Store;

/// The board's frame path, as the delay compensation allows for it: the
/// SPI transfers of its reads at its 4 kHz FIFO sampling
/// (`pipeline::timed::board_spi_us`: 110 µs) and a budget of 10 000
/// instructions from the reads to the frame queued, at the STM32F405's
/// 168 MHz (60 µs; `cargo xtask bench-loop` counts the path). A board on
/// its fallback clock says so with its own `core_hz`.
pub const BOARD_FRAME_PATH: FramePath = FramePath {
    spi_us: 110,
    instructions: 10_000,
    core_hz: 168_000_000,
};

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

/// Where frames go: the port, and what sends its queued bytes (the
/// board's UART interrupt, woken; nothing where the loop drains the port
/// itself).
pub trait Link {
    /// The port's transmit queue.
    type Queue: TxQueue;
    /// The port.
    fn port(&mut self) -> &mut Port<Self::Queue>;
    /// Bytes were queued on the port.
    fn flush(&mut self);
}

impl<Q: TxQueue> Link for Port<Q> {
    type Queue = Q;
    fn port(&mut self) -> &mut Port<Q> {
        self
    }
    fn flush(&mut self) {}
}

/// The pipeline's output as its frame states it.
impl<const N: usize> SampleOut for Output<N> {
    fn seq(&self) -> u32 {
        self.seq
    }
    fn fused(&self, axis: usize) -> Option<(f32, bool, u8)> {
        self.fused
            .get(axis)
            .copied()
            .flatten()
            .map(|f| (f.rate_dps, f.fallback, f.used()))
    }
    fn age_us(&self) -> [u16; 3] {
        Output::age_us(self)
    }
    fn gyro_rates(&self) -> &[[f32; 3]] {
        &self.rate_dps
    }
    fn gyro_delays_us(&self) -> &[u32] {
        &self.delay_us
    }
}

/// The pipeline's noise tracker, each axis's newest estimate as a frame's
/// noise record.
impl<const CAP: usize, const FRAMES: usize, const T: usize> NoiseSource
    for NoiseView<'_, CAP, FRAMES, T>
{
    fn described(&self, axis: usize) -> Option<u32> {
        NoiseView::described(self, axis)
    }

    fn noise(&self, axis: usize) -> Option<Noise> {
        self.newest(axis).map(|n| Noise {
            axis: axis as u8,
            seq: n.seq,
            len: n.len,
            bridged: n.bridged,
            sigma_dps: n.sigma_dps,
        })
    }
}

/// [`ChipTime`] of a timed chip.
pub fn timed_clock<SPI, C>(t: &TimedIcm<SPI, C>) -> ChipTime
where
    SPI: embedded_hal::spi::SpiDevice,
    C: crate::drivers::SampleCapture,
{
    let src = match t.clock_input() {
        ClockInput::ClkIn => ClockSource::ClkIn,
        ClockInput::Internal => ClockSource::Own,
    };
    let ppm = if tracking(t.clock()) {
        t.clock().error_ppm() as i32
    } else {
        0
    };
    let c = &t.counters;
    ChipTime {
        source: src,
        ppm,
        fifo: FifoAnomalies {
            overflows: c.overflows,
            bad: c.bad_fifo,
            cuts: c.cuts,
            resent: c.resent,
        },
    }
}

/// The pipeline as the link's port states it (`link::port::Array`): the
/// link knows the array only through this.
impl<const N: usize> Array for Pipeline<N> {
    #[inline]
    fn flags(&self, i: usize) -> u8 {
        self.health().get(i).map_or(0, |h| h.flags)
    }

    #[inline]
    fn gyros(&self) -> usize {
        N
    }

    fn gyro_status(&self, i: usize) -> GyroStatus {
        let c = self.counters().get(i).copied().unwrap_or_default();
        let cal = self.calibration();
        // (Saturating float-to-int casts; NaN gives 0.)
        let scale_ppm = cal.each_ref().map(|a| {
            let s = a.scale().get(i).copied().unwrap_or(1.0);
            ((s - 1.0) * 1e6) as i32
        });
        let bias_mdps = cal.each_ref().map(|a| {
            let b = a.bias().get(i).copied().unwrap_or(0.0);
            (b * 1e3) as i16
        });
        GyroStatus {
            flags: self.flags(i),
            reads: c.reads,
            errors: c.errors,
            excluded: c.excluded,
            restarts: c.restarts,
            restarted: c.restarted,
            scale_ppm,
            bias_mdps,
            clock: ClockSource::Polled,
            clock_ppm: 0,
            late: c.late,
            fifo: FifoAnomalies::default(),
        }
    }

    #[inline]
    fn shared_errors(&self) -> u8 {
        Pipeline::shared_errors(self)
    }

    #[inline]
    fn calibrated(&self) -> bool {
        Pipeline::calibrated(self)
    }

    fn overruns(&self) -> u32 {
        Pipeline::overruns(self)
    }

    fn start(&self, i: usize) -> (Start, Option<f32>) {
        (
            self.starts().get(i).copied().unwrap_or_default(),
            self.temperatures().get(i).copied().flatten(),
        )
    }

    fn set_method(&mut self, method: FusionMethod) -> Result<(), Reject> {
        Pipeline::set_method(self, method.method()).map_err(|_| Reject::Refused)
    }
}

/// What the sample task hands the background, in sample order: a
/// sample's noise probe for the E-DAVARs.
pub type Job = Probe;

/// What one tick produced.
#[derive(Clone, Copy, Debug)]
pub struct Sampled<const N: usize> {
    /// The fused sample.
    pub out: Output<N>,
    /// Whether its frame was queued (the divider may skip it).
    pub sent: bool,
    /// Whether a status frame was queued behind it.
    pub status_sent: bool,
}

/// What a status frame states beyond the pipeline and the port.
#[derive(Clone, Copy, Debug)]
pub struct StatusFacts<const N: usize> {
    /// Each chip's clock, as the sample task's timed reads see it.
    pub clocks: [ChipTime; N],
    /// The stack's deepest use so far, bytes.
    pub stack_peak: u32,
}

/// What the board's status frames say of the schedule.
#[derive(Clone, Copy, Debug)]
pub struct StatusView {
    /// The τ of the link's noise records, as octaves: τ = 2ʲ samples.
    pub taus: [usize; 3],
    /// The sample period, µs.
    pub sample_us: u32,
}

impl StatusView {
    /// The τ as the status frame states them, in samples.
    fn taus_in_samples(&self) -> [u16; 3] {
        self.taus.map(|j| 1u16.checked_shl(j as u32).unwrap_or(0))
    }
}

/// The sample task's work at a tick read at `t_us` (the low 32 bits the
/// captures' µs count at the read), `missed` periods after the last: the
/// chips aimed at the tick's one instant (behind the read by the board's
/// stated delay for the path trim in force) and read through `gyros`, fused, the frame queued with the newest noise estimate, the
/// calibration's learning, and a status frame when one is due (its facts
/// from `facts`). The pipeline and the link are held for all of it:
/// everything else that takes them (commands) runs below this task.
/// `queued` runs the moment the sample's frame is queued (where a
/// measurement of the response reads its clock).
#[allow(clippy::too_many_arguments)]
pub fn sample<const N: usize, L: Link>(
    pipe: &mut impl Mutex<T = Pipeline<N>>,
    link: &mut impl Mutex<T = L>,
    noise: &mut impl Mutex<T = NoiseSnapshot>,
    gyros: &mut [&mut dyn Gyro; N],
    (t_us, missed): (u64, u32),
    view: &StatusView,
    queued: impl FnOnce(),
    facts: impl FnOnce() -> StatusFacts<N>,
) -> Sampled<N> {
    (pipe, link).lock(|pipe, link| {
        if missed > 0 {
            pipe.note_overrun(missed);
        }
        let trim = link.port().settings().path_trim_us;
        let behind = board_delay_us(trim);
        let at = array_instant(t_us as u32, behind);
        for g in gyros.iter_mut() {
            g.aim(at, behind, trim);
        }
        let out = pipe.read_and_fuse(gyros);
        // The frame first: the antenna waits for it.
        let port = link.port();
        let before = port.counters().sent;
        // The estimates read where they lie, not copied: the background
        // that writes them runs below this task, so the lock costs nothing
        // here.
        noise.lock(|estimates| port.publish(&out, t_us, pipe, estimates));
        let sent = port.counters().sent != before;
        link.flush();
        queued();
        // The calibration learns from every sample, in order.
        pipe.finish();
        let port = link.port();
        let status_sent = port.status_due(out.seq) && {
            let f = facts();
            let st = port.status(
                pipe,
                out.seq,
                t_us,
                view.taus_in_samples(),
                view.sample_us,
                f.stack_peak,
                &f.clocks,
            );
            let ok = port.send(&st);
            link.flush();
            ok
        };
        // The board and its chips, half way between status frames.
        let port = link.port();
        if port.info_due(out.seq) {
            let info = port.info(pipe, gyros);
            port.send(&info);
            link.flush();
        }
        Sampled {
            out,
            sent,
            status_sent,
        }
    })
}

/// The background's own state: the E-DAVARs.
pub struct Background<'a, const CAP: usize, const FRAMES: usize, const T: usize> {
    /// The noise tracker (one E-DAVAR per fused axis).
    pub tracker: &'a mut NoiseTracker<CAP, FRAMES, T>,
    /// The τ of the link's noise records, as octaves: τ = 2ʲ samples.
    pub taus: [usize; 3],
}

impl<const CAP: usize, const FRAMES: usize, const T: usize> Background<'_, CAP, FRAMES, T> {
    /// One sample's probe into the E-DAVARs, and their newest estimates
    /// left for the sample task.
    pub fn run(&mut self, probe: Job, noise: &mut impl Mutex<T = NoiseSnapshot>) {
        self.tracker.push_probe(probe);
        let snap = NoiseSnapshot::of(&self.tracker.at_taus(self.taus));
        noise.lock(|n| *n = snap);
    }
}

/// Apply the commands waiting in `rx` (bounded by the port), their
/// acknowledgements queued.
pub fn receive<const N: usize, L: Link, R>(
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

/// Carry out the store command waiting on the port, if any (a save or a
/// factory reset), and queue its acknowledgement. Run in the background:
/// the link is held only to take the request and to answer it, not while
/// the flash is written (which stalls the core anyway, `crate::store`).
/// `calibration`: the record in use, saved beside the settings.
pub fn store<L: Link, F>(
    store: &mut Store<F>,
    calibration: Option<&CalRecord>,
    link: &mut impl Mutex<T = L>,
) where
    F: embedded_storage_async::nor_flash::MultiwriteNorFlash,
{
    let Some(request) = link.lock(|l| l.port().store_request()) else {
        return;
    };
    let result = match request {
        StoreRequest::Save(s) => store.save(&s, calibration),
        StoreRequest::Clear => store.clear(),
    };
    let state = store.state();
    link.lock(|l| {
        l.port()
            .store_done(result.map_err(|_| Reject::Storage), state);
        l.flush();
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::link::port::RingPort;

    #[test]
    fn the_boards_frame_path_allows_for_its_spi_reads_and_its_budget() {
        use crate::drivers::icm42688::{board_fifo, ClockInput};
        // The SPI transfers of the board's reads, rounded up to the µs,
        // and the 10 000-instruction budget at 168 MHz.
        let spi = crate::pipeline::timed::board_spi_us(&board_fifo(ClockInput::ClkIn));
        let p = BOARD_FRAME_PATH;
        assert!(
            p.spi_us as f32 >= spi && (p.spi_us as f32) < spi + 1.0,
            "{p:?}: {spi}"
        );
        let want = spi + 10_000.0 / 168.0;
        let got = p.us() as f32;
        assert!(got >= want && got < want + 2.0, "{got} against {want}");
    }

    #[test]
    fn the_sample_clock_extends_its_counter_and_counts_missed_periods() {
        // Started just before the 32-bit µs counter wraps.
        let mut c = SampleClock::new(u32::MAX - 1500, 1000);
        assert_eq!(c.tick(u32::MAX - 500), (u64::from(u32::MAX) - 500, 0));
        // Across the wrap: the 64-bit time goes on.
        assert_eq!(c.tick(499), (u64::from(u32::MAX) + 500, 0));
        // 0.4 period late is the same tick; 2.6 periods on is two missed.
        assert_eq!(c.tick(1899).1, 0);
        assert_eq!(c.tick(4499).1, 2);
        assert_eq!(c.period_us(), 1000);
    }

    use crate::drivers::{ReadFault, Reading, Restart};
    use crate::link::msg::{Frame, Settings};
    use crate::link::wire::{Decoder, MAX_FRAME};
    use gyro_sim::Rng;
    use rtic_core::Exclusive;

    /// A gyro reading a still board's noise.
    struct Still(Rng);

    impl Gyro for Still {
        fn read(&mut self) -> Result<Reading, ReadFault> {
            let mut r = [0.0f32; 3];
            for v in r.iter_mut() {
                *v = 0.05 * self.0.gaussian();
            }
            Ok(Reading {
                // Counts at the ICM-42688-P's ±250 °/s (131 LSB per °/s):
                // a reading whose counts never change is a stuck chip.
                raw: r.map(|v| (v * 131.0) as i16),
                rate_dps: r,
                axes: 0b111,
                saturated: 0,
            })
        }
        fn restart(&mut self, _: u8) -> Result<Restart, ReadFault> {
            Ok(Restart::Done)
        }
    }

    struct Sink(std::vec::Vec<u8>);

    impl embedded_hal_nb::serial::ErrorType for Sink {
        type Error = core::convert::Infallible;
    }

    impl embedded_hal_nb::serial::Write<u8> for Sink {
        fn write(&mut self, b: u8) -> embedded_hal_nb::nb::Result<(), Self::Error> {
            self.0.push(b);
            Ok(())
        }
        fn flush(&mut self) -> embedded_hal_nb::nb::Result<(), Self::Error> {
            Ok(())
        }
    }

    /// The schedule as one loop runs it, on four still chips: every sample
    /// a frame, a status frame right behind the sample's that makes it
    /// due, missed periods counted and left as gaps, the E-DAVARs' records
    /// reaching the frames through the background's copy.
    #[test]
    fn the_schedule_sends_each_sample_then_its_status_and_counts_what_it_missed() {
        use crate::algo::fusion::{AdaptiveConfig, Method};
        use crate::pipeline::PipelineConfig;
        let mut pipe = Pipeline::<4>::new(
            PipelineConfig::default(),
            Method::Adaptive(AdaptiveConfig::default()),
        )
        .unwrap();
        let mut port = RingPort::<2048>::new(Settings::default(), crate::app::BOARD_FRAME_PATH);
        let mut noise = NoiseSnapshot::default();
        let mut tracker =
            NoiseTracker::<1024, 35, 3>::new(crate::pipeline::tracker::link_config(1024)).unwrap();
        let mut bg = Background {
            tracker: &mut tracker,
            taus: crate::pipeline::tracker::VIEW_TAUS,
        };
        let view = StatusView {
            taus: crate::pipeline::tracker::VIEW_TAUS,
            sample_us: 1000,
        };
        let mut chips: [Still; 4] = core::array::from_fn(|i| Still(Rng::new(i as u64 + 1)));
        let mut clock = SampleClock::new(0, 1000);
        let mut wire = Sink(std::vec::Vec::new());
        let mut queued = 0;
        for n in 1..=3000u32 {
            // Sample 1500 comes three periods after 1499: two missed.
            let now = if n >= 1500 { (n + 2) * 1000 } else { n * 1000 };
            let (t_us, missed) = clock.tick(now);
            let [a, b, c, d] = &mut chips;
            let mut gyros: [&mut dyn Gyro; 4] = [a, b, c, d];
            let s = sample(
                &mut Exclusive(&mut pipe),
                &mut Exclusive(&mut port),
                &mut Exclusive(&mut noise),
                &mut gyros,
                (t_us, missed),
                &view,
                || queued += 1,
                || StatusFacts {
                    clocks: [ChipTime::default(); 4],
                    stack_peak: 0,
                },
            );
            assert!(s.sent);
            port.drain(&mut wire);
            bg.run(Probe::from(&s.out), &mut Exclusive(&mut noise));
        }
        assert_eq!(queued, 3000);
        assert_eq!(pipe.overruns(), 2);
        let mut dec = Decoder::<MAX_FRAME>::new();
        let frames: std::vec::Vec<Frame> = wire
            .0
            .iter()
            .filter_map(|&b| dec.feed::<Frame>(b))
            .map(|r| r.unwrap().body)
            .collect();
        let mut last_seq = None;
        let (mut statuses, mut infos, mut with_noise) = (0, 0, 0);
        for (k, f) in frames.iter().enumerate() {
            match f {
                Frame::Sample(s) => {
                    // Each a millisecond after the last, but across the
                    // two missed periods, whose sequence numbers are gaps.
                    if let Some(q) = last_seq {
                        assert_eq!(s.seq - q, if s.seq == 1501 { 3 } else { 1 }, "{}", s.seq);
                    }
                    last_seq = Some(s.seq);
                    with_noise += usize::from(s.noise.is_some());
                }
                Frame::Status(st) => {
                    statuses += 1;
                    // Right behind the sample frame that made it due.
                    match frames.get(k.wrapping_sub(1)) {
                        Some(Frame::Sample(s)) => assert_eq!(s.seq, st.seq),
                        other => panic!("a status frame after {other:?}"),
                    }
                    assert_eq!(st.seq % 1000, 0);
                    assert_eq!(st.noise_tau, [1, 16, 256]);
                }
                Frame::Info(i) => {
                    infos += 1;
                    // Half way between status frames, behind its sample.
                    match frames.get(k.wrapping_sub(1)) {
                        Some(Frame::Sample(s)) => assert_eq!(s.seq % 1000, 500),
                        other => panic!("an info frame after {other:?}"),
                    }
                    assert_eq!(i.chips.len(), 4);
                }
                other => panic!("{other:?}"),
            }
        }
        // With sequence numbers 0, 1000, 2000 and 3000; info frames with
        // 500 and 2500 (1500 was missed).
        assert_eq!(statuses, 4);
        assert_eq!(infos, 2);
        // The E-DAVARs publish once their window has filled, and their
        // records reach the frames.
        assert!(with_noise > 10, "{with_noise}");
    }

    /// The controller's side of a 6 Mbaud UART: at most `per_ms` bytes a
    /// sample period each way.
    struct Wire {
        out: Sink,
        room: usize,
    }

    impl embedded_hal_nb::serial::ErrorType for Wire {
        type Error = core::convert::Infallible;
    }

    impl embedded_hal_nb::serial::Write<u8> for Wire {
        fn write(&mut self, b: u8) -> embedded_hal_nb::nb::Result<(), Self::Error> {
            if self.room == 0 {
                return Err(embedded_hal_nb::nb::Error::WouldBlock);
            }
            self.room -= 1;
            self.out.0.push(b);
            Ok(())
        }
        fn flush(&mut self) -> embedded_hal_nb::nb::Result<(), Self::Error> {
            Ok(())
        }
    }

    /// Bytes from the controller, as the receive interrupt queues them.
    struct Rx(std::collections::VecDeque<u8>);

    impl embedded_hal_nb::serial::ErrorType for Rx {
        type Error = core::convert::Infallible;
    }

    impl embedded_hal_nb::serial::Read<u8> for Rx {
        fn read(&mut self) -> embedded_hal_nb::nb::Result<u8, Self::Error> {
            self.0
                .pop_front()
                .ok_or(embedded_hal_nb::nb::Error::WouldBlock)
        }
    }

    /// A controller flooding the link at the UART's full rate (600 bytes a
    /// millisecond at 6 Mbaud) with status requests back to back, with
    /// noise, with runs of frame delimiters, or a mix, while the board
    /// sends at the same rate: every sample frame still leaves, in order,
    /// none dropped, and the transmit queue's backlog stays bounded (the
    /// receive path takes a bounded number of bytes a call, and status
    /// requests coalesce into one status frame a sample).
    #[test]
    fn a_flooded_link_loses_no_sample_frame() {
        use crate::algo::fusion::{AdaptiveConfig, Method};
        use crate::link::msg::{Command, Op};
        use crate::link::wire::encode;
        use crate::pipeline::PipelineConfig;
        const PER_MS: usize = 600;
        let request = {
            let mut buf = [0u8; MAX_FRAME];
            let n = encode(
                0,
                &Command {
                    id: 9,
                    op: Op::RequestStatus,
                },
                &mut buf,
            )
            .unwrap();
            buf[..n].to_vec()
        };
        for flood in 0..4u8 {
            let mut pipe = Pipeline::<4>::new(
                PipelineConfig::default(),
                Method::Adaptive(AdaptiveConfig::default()),
            )
            .unwrap();
            let mut port = RingPort::<2048>::new(Settings::default(), crate::app::BOARD_FRAME_PATH);
            let mut noise = NoiseSnapshot::default();
            let view = StatusView {
                taus: crate::pipeline::tracker::VIEW_TAUS,
                sample_us: 1000,
            };
            let mut chips: [Still; 4] = core::array::from_fn(|i| Still(Rng::new(i as u64 + 1)));
            let mut rng = Rng::new(77 + u64::from(flood));
            let mut rx = Rx(Default::default());
            let mut wire = Wire {
                out: Sink(std::vec::Vec::new()),
                room: 0,
            };
            let mut backlog = 0;
            for n in 0..2000u32 {
                // This millisecond's bytes from the controller.
                let mut k = 0;
                while k < PER_MS {
                    let kind = if flood == 3 {
                        rng.uniform() * 3.0
                    } else {
                        f32::from(flood)
                    };
                    if kind < 1.0 {
                        rx.0.extend(&request);
                        k += request.len();
                    } else if kind < 2.0 {
                        rx.0.push_back((rng.uniform() * 256.0) as u8);
                        k += 1;
                    } else {
                        rx.0.push_back(0);
                        k += 1;
                    }
                }
                let [a, b, c, d] = &mut chips;
                let mut gyros: [&mut dyn Gyro; 4] = [a, b, c, d];
                let s = sample(
                    &mut Exclusive(&mut pipe),
                    &mut Exclusive(&mut port),
                    &mut Exclusive(&mut noise),
                    &mut gyros,
                    (u64::from(n) * 1000, 0),
                    &view,
                    || {},
                    || StatusFacts {
                        clocks: [ChipTime::default(); 4],
                        stack_peak: 0,
                    },
                );
                assert!(s.sent, "flood {flood}: sample {n} not queued");
                receive(
                    &mut rx,
                    &mut Exclusive(&mut pipe),
                    &mut Exclusive(&mut port),
                );
                // The receive queue is the interrupt's, bounded: what it
                // cannot hold is lost (and fails its CRC as a command).
                while rx.0.len() > 64 {
                    rx.0.pop_front();
                }
                wire.room = PER_MS;
                port.drain(&mut wire);
                backlog = backlog.max(port.queued());
            }
            assert_eq!(port.counters().dropped, 0, "flood {flood}");
            let mut dec = Decoder::<MAX_FRAME>::new();
            let mut last = None;
            let (mut samples, mut statuses, mut acks) = (0, 0, 0);
            for &b in &wire.out.0 {
                match dec.feed::<Frame>(b).map(|f| f.map(|f| f.body)) {
                    Some(Ok(Frame::Sample(s))) => {
                        if let Some(q) = last {
                            assert_eq!(s.seq, q + 1, "flood {flood}");
                        }
                        last = Some(s.seq);
                        samples += 1;
                    }
                    Some(Ok(Frame::Status(_))) => statuses += 1,
                    Some(Ok(Frame::Ack(_))) => acks += 1,
                    _ => {}
                }
            }
            std::println!(
                "flood {flood}: {samples} sample, {statuses} status, {acks} ack frames; backlog {backlog} B"
            );
            // The flood was answered: requests coalesced into a status
            // frame a sample, every command acknowledged.
            if flood == 0 {
                assert!(statuses >= 1990 && acks >= 10_000, "{statuses} {acks}");
            }
            // The last sample's frame may still be on its way.
            assert!(samples >= 1999, "flood {flood}: {samples} sample frames");
            assert!(backlog < 1200, "flood {flood}: backlog {backlog} B");
        }
    }

    #[test]
    fn status_frames_state_the_taus_in_samples() {
        let v = StatusView {
            taus: [0, 4, 8],
            sample_us: 1000,
        };
        assert_eq!(v.taus_in_samples(), [1, 16, 256]);
        let far = StatusView {
            taus: [0, 3, 40],
            sample_us: 1000,
        };
        assert_eq!(far.taus_in_samples(), [1, 8, 0]);
    }
}
