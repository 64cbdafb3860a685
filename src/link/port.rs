//! The board's end of the link: the frames built from the pipeline's
//! output and written into a transmit queue, and the command decoder.
//!
//! Nothing here blocks. The sample task calls [`Port::publish`] once per
//! sample and the background [`Port::receive`]; the frames go out from
//! the queue they were written into (`ring`: on the board the UART's
//! interrupt and DMA read them there; a [`RingPort`] is drained by whoever
//! holds it). A frame goes into the queue whole or not at all; one that
//! does not fit is counted in [`LinkCounters::dropped`] and leaves a gap in
//! the link sequence number.

use heapless::Vec;

use super::msg::{
    Ack, Angle, ChipInfo, ClockSource, Command, Compensation, FifoAnomalies, Frame, FrameRef,
    FusionMethod, GyroStatus, Info, LinkCounters, Mode, Noise, Op, Raw, Reject, Sample, Settings,
    Start, Status, StoreState, SyncStatus, MAX_GYROS,
};
use super::ring::{ByteRing, TxQueue};
use super::sync::{CtrlClock, SyncState};
use super::wire::{
    encode_in_place, encode_payload, frame_payload, framed_len, Decoded, Decoder, FrameError,
    IN_PLACE_MAX, MAX_PAYLOAD,
};
use crate::algo::fusion::{AdaptiveConfig, Method};
use crate::algo::predict::Predictor;
use crate::drivers::Gyro;

/// The array the port speaks for, as its frames state it, and the one
/// command the port hands on to it (the fusion method). The port knows the
/// array only through this: the board's pipeline is one (`app` implements
/// it), a test's fixture can be another.
pub trait Array {
    /// Gyro `i`'s health flags (0 past the last gyro).
    fn flags(&self, i: usize) -> u8;
    /// Gyros.
    fn gyros(&self) -> usize;
    /// Gyro `i` as a status frame states it, its clock aside (the port
    /// fills [`GyroStatus::clock`], `clock_ppm` and `fifo` from the sample
    /// task's timed reads).
    fn gyro_status(&self, i: usize) -> GyroStatus;
    /// Per axis (bit `a`): the axis's chips share an error their noise
    /// figures cannot see.
    fn shared_errors(&self) -> u8;
    /// A static calibration record is in use.
    fn calibrated(&self) -> bool;
    /// Samples the sample task missed.
    fn overruns(&self) -> u32;
    /// Gyro `i`'s start-up and its die's temperature, °C, if known.
    fn start(&self, i: usize) -> (Start, Option<f32>);
    /// Fuse with `method` from now on (its noise model starts again), or
    /// refuse it.
    fn set_method(&mut self, method: FusionMethod) -> Result<(), Reject>;
}

/// One sample as its frame states it: what the port reads of the
/// pipeline's output (`app` implements it for `pipeline::Output`).
pub trait SampleOut {
    /// Sequence number (every sample period, overruns included).
    fn seq(&self) -> u32;
    /// Axis `axis`'s fused rate (°/s), whether fusion fell back to the
    /// plain mean, and the gyros used (a bit each); `None` without one.
    fn fused(&self, axis: usize) -> Option<(f32, bool, u8)>;
    /// Per axis, how long before the read the fused rate was true, µs.
    fn age_us(&self) -> [u16; 3];
    /// Per gyro, its rates (°/s, NaN where not read), for raw frames.
    fn gyro_rates(&self) -> &[[f32; 3]];
    /// Per gyro, how long before the read its rate was true, µs.
    fn gyro_delays_us(&self) -> &[u32];
}

/// Where the E-DAVAR estimates come from (the pipeline's noise tracker).
pub trait NoiseSource {
    /// Sequence number of the sample the axis's newest estimate describes
    /// (cheap: the port asks every sample).
    fn described(&self, axis: usize) -> Option<u32>;
    /// The axis's newest estimate (asked only when it is new).
    fn noise(&self, axis: usize) -> Option<Noise>;
}

/// No noise tracking.
impl NoiseSource for () {
    fn described(&self, _: usize) -> Option<u32> {
        None
    }
    fn noise(&self, _: usize) -> Option<Noise> {
        None
    }
}

/// Each axis's newest estimate, copied out of a [`NoiseSource`] for a
/// reader that must not wait for the tracker: on the board the
/// background owns the E-DAVARs and leaves this copy for the sample task
/// after each update (copying it is the only time the two share).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NoiseSnapshot {
    described: [Option<u32>; 3],
    noise: [Option<Noise>; 3],
}

impl NoiseSnapshot {
    /// The estimates `src` holds now.
    pub fn of(src: &impl NoiseSource) -> Self {
        let mut s = Self::default();
        for a in 0..3 {
            s.described[a] = src.described(a);
            if s.described[a].is_some() {
                s.noise[a] = src.noise(a);
            }
        }
        s
    }
}

impl NoiseSource for NoiseSnapshot {
    fn described(&self, axis: usize) -> Option<u32> {
        self.described.get(axis).copied().flatten()
    }

    fn noise(&self, axis: usize) -> Option<Noise> {
        self.noise.get(axis).copied().flatten()
    }
}

/// Longest command frame the board accepts (commands are ≤ 16 bytes).
pub const RX_MAX: usize = 64;

/// Samples the delay compensation fits its line to: the length that leaves
/// the reference pointing loop the least error over the vehicle profiles
/// (`pointing-eval`: K = 2 to 16 measured; longer fits lag on the 8 Hz
/// road, two samples pass more noise). At the board's 1.97 ms horizon the
/// predicted rate's white noise is 2.18 times the measured rate's
/// ([`Predictor::noise_gain`]), all of it at high frequency (the line's
/// slope), which the positioner integrates away: the pointing error's
/// share from noise grows 3–7 %.
pub const PREDICT_K: usize = 3;

/// Bytes of a sample frame on the wire the horizon of
/// [`Compensation::ToFrame`] allows for: the largest (five gyros, an
/// E-DAVAR estimate; `link::tests` checks it). A frame without an estimate
/// ends before the instant stated, by some 20 µs at 6 Mbaud.
pub const SAMPLE_FRAME_MAX: u32 = 81;

/// The firmware's version, from the crate's.
pub const FIRMWARE: [u8; 3] = [
    parse_u8(env!("CARGO_PKG_VERSION_MAJOR")),
    parse_u8(env!("CARGO_PKG_VERSION_MINOR")),
    parse_u8(env!("CARGO_PKG_VERSION_PATCH")),
];

/// The commit the firmware was built from, its first 32 bits (`build.rs`;
/// 0 outside a git checkout).
pub const BUILD: u32 = match option_env!("GYRO_BUILD") {
    Some(h) => parse_hex32(h),
    None => 0,
};

const fn parse_u8(s: &str) -> u8 {
    let b = s.as_bytes();
    let mut v: u32 = 0;
    let mut i = 0;
    while i < b.len() {
        v = v * 10 + (b[i] - b'0') as u32;
        i += 1;
    }
    if v > 255 {
        255
    } else {
        v as u8
    }
}

const fn parse_hex32(s: &str) -> u32 {
    let b = s.as_bytes();
    let mut v: u32 = 0;
    let mut i = 0;
    while i < b.len() && i < 8 {
        let d = match b[i] {
            c @ b'0'..=b'9' => c - b'0',
            c @ b'a'..=b'f' => c - b'a' + 10,
            c @ b'A'..=b'F' => c - b'A' + 10,
            _ => 0,
        };
        v = (v << 4) | d as u32;
        i += 1;
    }
    v
}

/// Bytes [`Sample::angle`] adds (three u32, fixed width).
pub const ANGLE_BYTES: u32 = 12;

/// 2³² / 360 / 10⁶: °/s × µs to 2⁻³² turn. In f32 (soft f64 costs the
/// Cortex-M4 hundreds of cycles): a step of 2 000 °/s over 1 ms is 2.4 × 10⁷
/// units, held to 2 units (2 × 10⁻⁷ °) with rounding errors that do not
/// add up one way (`link::tests`: 10⁴ steps against an f64 sum). Nothing is
/// integrated while the angle is off.
const TURN_UNITS: f32 = (4_294_967_296.0 / 360.0 / 1e6) as f32;

/// What [`Compensation::ToFrame`] allows for between a sample's read
/// (`t_us`) and its frame being queued: the bus's time for the reads, and
/// the frame path's instructions at the core's clock (taken as cycles: a
/// Cortex-M4 with flash wait states and its cache runs about one an
/// instruction). The board's own is `app::BOARD_FRAME_PATH`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FramePath {
    /// The SPI transfers of the sample's reads, µs.
    pub spi_us: u32,
    /// The frame path's budget, instructions.
    pub instructions: u32,
    /// The core clock the path runs at, Hz.
    pub core_hz: u32,
}

impl FramePath {
    /// The read to the frame queued, µs (the path's part rounded up).
    pub fn us(&self) -> u32 {
        let path =
            (u64::from(self.instructions) * 1_000_000).div_ceil(u64::from(self.core_hz.max(1)));
        self.spi_us
            .saturating_add(path.min(u64::from(u32::MAX)) as u32)
    }
}

/// What a status frame says of a chip's time ([`Port::status`]'s
/// `clocks`; the default: a polled chip).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ChipTime {
    /// Where its samples take their time from.
    pub source: ClockSource,
    /// Its clock's error, ppm, once the tracker follows it (0 before).
    pub ppm: i32,
    /// What its FIFO reads met.
    pub fifo: FifoAnomalies,
}

impl FusionMethod {
    /// The fusion method with its default settings.
    pub fn method(self) -> Method {
        match self {
            FusionMethod::Mean => Method::Mean,
            FusionMethod::Zhang => Method::Zhang,
            FusionMethod::Adaptive => Method::Adaptive(AdaptiveConfig::default()),
        }
    }
}

/// What a command asked of the settings store (done in the background:
/// a flash write stalls the core, see `src/store.rs`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StoreRequest {
    /// Save these settings.
    Save(Settings),
    /// Erase what is saved (the defaults are already in force).
    Clear,
}

/// The board's end of the link, its frames queued in `Q`.
pub struct Port<Q> {
    tx: Q,
    rx: Decoder<RX_MAX>,
    link_seq: u32,
    settings: Settings,
    counters: LinkCounters,
    /// The axis whose E-DAVAR estimate goes into the next frame.
    noise_turn: usize,
    /// Per axis, the described sequence number last sent.
    noise_sent: [Option<u32>; 3],
    status_requested: bool,
    /// The settings store's state, and the store command waiting for it
    /// (its id and what it asks), acknowledged once done.
    store: StoreState,
    store_pending: Option<(u8, StoreRequest)>,
    /// Encoding scratch, kept so that a frame zeroes no buffers.
    payload: [u8; MAX_PAYLOAD],
    /// The fused rates' recent samples, for the delay compensation.
    predictor: Predictor<PREDICT_K>,
    /// The sequence number of the last sample the predictor took.
    predictor_seq: Option<u32>,
    /// The UART's speed, baud.
    baud: u32,
    /// 1 / the sample period, 1/µs.
    per_sample: f32,
    /// The sample's read to its frame queued, µs ([`FramePath::us`]).
    loop_us: u32,
    /// [`Self::horizon_us`], worked out when the settings or the timing
    /// change, not each sample.
    horizon: Option<u16>,
    /// The rates of the last sample frame queued.
    last_rates: Option<[f32; 3]>,
    /// Per axis, the integrated angle (2⁻³² turn, wrapping) and the last
    /// measured rate with the instant it describes, µs.
    angle: [u64; 3],
    angle_from: [Option<(u64, f32)>; 3],
    /// The controller's clock.
    sync: CtrlClock,
    /// An info frame was asked for; the MCU's unique ID.
    info_requested: bool,
    uid: [u8; 12],
}

/// A port with a queue of its own, `TX` bytes, drained by whoever holds
/// it ([`Port::drain`]): the host's tools and tests, the benches.
pub type RingPort<const TX: usize> = Port<ByteRing<TX>>;

impl<const TX: usize> RingPort<TX> {
    /// A port with `settings` and an empty queue of its own, its frames
    /// queued `path` after their samples' reads; its method must be the
    /// pipeline's.
    pub fn new(settings: Settings, path: FramePath) -> Self {
        Port::with_queue(ByteRing::new(), settings, path)
    }

    /// Bytes waiting to be sent.
    pub fn queued(&self) -> usize {
        self.tx.len()
    }

    /// Send queued bytes until the UART would block or the queue is empty;
    /// the bytes sent.
    pub fn drain<W: embedded_hal_nb::serial::Write<u8>>(&mut self, uart: &mut W) -> usize {
        let mut n = 0;
        while !self.tx.is_empty() {
            let mut k = 0;
            for &b in self.tx.front() {
                // WouldBlock, or a UART error: try again next time.
                if uart.write(b).is_err() {
                    break;
                }
                k += 1;
            }
            self.tx.consume(k);
            n += k;
            if k == 0 {
                break;
            }
        }
        n
    }
}

impl<Q: TxQueue> Port<Q> {
    /// A port with `settings` that queues its frames in `tx`, `path` after
    /// their samples' reads; its method must be the pipeline's.
    pub fn with_queue(tx: Q, settings: Settings, path: FramePath) -> Self {
        let mut p = Self {
            tx,
            rx: Decoder::new(),
            link_seq: 0,
            settings,
            counters: LinkCounters::default(),
            noise_turn: 0,
            noise_sent: [None; 3],
            status_requested: false,
            store: StoreState::Absent,
            store_pending: None,
            payload: [0; MAX_PAYLOAD],
            predictor: Predictor::new(),
            predictor_seq: None,
            baud: super::BAUD,
            per_sample: 1e-3,
            loop_us: path.us(),
            horizon: None,
            last_rates: None,
            angle: [0; 3],
            angle_from: [None; 3],
            sync: CtrlClock::new(),
            info_requested: false,
            uid: [0; 12],
        };
        p.retime();
        p
    }

    /// The rates the last sample frame queued carried (predicted, when the
    /// compensation is on): what a recording of the link holds.
    pub fn last_sample_rates(&self) -> Option<[f32; 3]> {
        self.last_rates
    }

    /// The UART's speed and the sample period the delay compensation works
    /// with (by default [`super::BAUD`] and 1 ms).
    pub fn set_timing(&mut self, baud: u32, sample_us: u32) {
        self.baud = baud.max(1);
        self.per_sample = 1.0 / sample_us.max(1) as f32;
        self.retime();
    }

    fn retime(&mut self) {
        self.horizon = match self.settings.compensation {
            Compensation::Off => None,
            Compensation::ToFrame => {
                // (baud ≥ 1: set_timing keeps it so.)
                let frame = SAMPLE_FRAME_MAX + if self.settings.angle { ANGLE_BYTES } else { 0 };
                let bits = frame * 10 * 1_000_000;
                let wire = bits
                    .checked_div(self.baud)
                    .zip(bits.checked_rem(self.baud))
                    .map_or(u32::MAX, |(q, r)| q + u32::from(r != 0));
                Some((self.loop_us + wire).min(u16::MAX as u32) as u16)
            }
            Compensation::Horizon(h) => Some(h),
        };
    }

    /// How far after `t_us` a sample frame's rates are predicted to, µs,
    /// under the settings in force (`None`: not predicted).
    pub fn horizon_us(&self) -> Option<u16> {
        self.horizon
    }

    /// The settings in force.
    pub fn settings(&self) -> Settings {
        self.settings
    }

    /// What the link counted.
    pub fn counters(&self) -> LinkCounters {
        self.counters
    }

    /// Queue `frame` whole, or drop it (counted) if the queue lacks room.
    /// Either way it uses a link sequence number. True if queued.
    pub fn send(&mut self, frame: &Frame) -> bool {
        self.send_ref(frame.as_ref())
    }

    /// [`Port::send`] of a borrowed frame.
    pub fn send_ref(&mut self, frame: FrameRef<'_>) -> bool {
        let seq = self.link_seq;
        self.link_seq = self.link_seq.wrapping_add(1);
        // Straight into the queue (no copy), in room for any frame that
        // can be encoded in place: the queue is drained every sample
        // period, so the room is almost always there, at its start. Else
        // (a backlog, or a frame too long to encode in place) through the
        // payload scratch into the room the queue finds for it.
        let placed = self
            .tx
            .put(IN_PLACE_MAX + 2, |room| encode_in_place(seq, &frame, room));
        let ok = match placed {
            Some(Ok(_)) => true,
            _ => match encode_payload(seq, &frame, &mut self.payload) {
                Ok(k) => {
                    let payload = self.payload.get(..k).unwrap_or(&[]);
                    matches!(
                        self.tx
                            .put(framed_len(k), |room| frame_payload(payload, room)),
                        Some(Ok(_))
                    )
                }
                Err(_) => false,
            },
        };
        if ok {
            self.counters.sent = self.counters.sent.wrapping_add(1);
        } else {
            self.counters.dropped = self.counters.dropped.wrapping_add(1);
        }
        ok
    }

    /// Queue the frame for sample `out` if the divider selects it: a
    /// [`Sample`] (with the next new E-DAVAR estimate from `noise`) or a
    /// [`Raw`] frame. `t_us` is the sample's time.
    pub fn publish(
        &mut self,
        out: &impl SampleOut,
        t_us: u64,
        array: &impl Array,
        noise: &impl NoiseSource,
    ) {
        // Every sample goes to the predictor, sent or not; a missed sample
        // or an axis without a value starts its fit again.
        let follows = self
            .predictor_seq
            .is_none_or(|q| out.seq().wrapping_sub(q) == 1);
        if !follows {
            self.predictor.clear();
        }
        let rate = |a: usize| out.fused(a).map(|f| f.0).filter(|r| r.is_finite());
        match [rate(0), rate(1), rate(2)] {
            [Some(x), Some(y), Some(z)] => self.predictor.push([x, y, z]),
            _ => self.predictor.clear(),
        }
        self.predictor_seq = Some(out.seq());
        let age_us = out.age_us();
        self.integrate(out, t_us, age_us);
        // A pulse that stopped is said once, in its own frame.
        let was = self.sync.state();
        self.sync.tick(t_us);
        if was != SyncState::Lost && self.sync.state() == SyncState::Lost {
            self.send_sync();
        }
        let div = u32::from(self.settings.divider.max(1));
        if !out.seq().is_multiple_of(div) {
            return;
        }
        let mut health = Vec::<u8, MAX_GYROS>::new();
        for i in 0..array.gyros().min(MAX_GYROS) {
            let _ = health.push(array.flags(i));
        }
        match self.settings.mode {
            Mode::Fused => {
                let mut s = Sample {
                    seq: out.seq(),
                    t_us,
                    age_us,
                    predicted_us: None,
                    rate_dps: [f32::NAN; 3],
                    valid: 0,
                    degraded: 0,
                    used: [0; 3],
                    health,
                    noise: None,
                    angle: self.settings.angle.then(|| {
                        let [x, y, z] = self.angle.map(|a| a as u32);
                        Angle { x, y, z }
                    }),
                };
                for a in 0..3 {
                    if let Some((rate, fallback, used)) = out.fused(a) {
                        s.rate_dps[a] = rate;
                        s.valid |= 1 << a;
                        s.degraded |= u8::from(fallback) << a;
                        s.used[a] = used;
                    }
                }
                // Each axis's line read from the instant its measurement
                // describes to the instant stated (`t_us + d`).
                if let Some(d) = self.horizon {
                    let per = self.per_sample;
                    let ahead = age_us.map(|a| (f32::from(a) + f32::from(d)) * per);
                    if let Some(p) = self.predictor.at(ahead) {
                        s.rate_dps = p;
                        s.predicted_us = Some(d);
                    }
                }
                // Bits 3–5: the axis's chips share an error its noise
                // figures cannot see. Bit 7: no static calibration record
                // in use.
                s.degraded |= array.shared_errors() << 3;
                s.degraded |= u8::from(!array.calibrated()) << 7;
                // The newest estimate not sent yet (a copy the background
                // left, on the board: no E-DAVAR work on the frame's path).
                s.noise = self.next_noise(noise);
                let sent = self.counters.sent;
                self.send_ref(FrameRef::Sample(&s));
                if self.counters.sent != sent {
                    self.last_rates = Some(s.rate_dps);
                }
            }
            Mode::Raw => {
                let mut rates = Vec::<[f32; 3], MAX_GYROS>::new();
                for r in out.gyro_rates().iter().take(MAX_GYROS) {
                    let _ = rates.push(*r);
                }
                let mut age_us = Vec::<u16, MAX_GYROS>::new();
                for d in out.gyro_delays_us().iter().take(MAX_GYROS) {
                    let _ = age_us.push((*d).min(u16::MAX as u32) as u16);
                }
                let r = Raw {
                    seq: out.seq(),
                    t_us,
                    age_us,
                    rate_dps: rates,
                    health,
                };
                self.send_ref(FrameRef::Raw(&r));
            }
        }
    }

    /// Every sample's measured fused rates into the angles (while the
    /// angle is on): per axis, the trapezoid from the instant the last
    /// measurement described to this one's (`t_us − age_us`), so a missed
    /// sample's period is spanned and the chips' changing delay is
    /// followed. An axis without a value stops its integral until it has
    /// two values again.
    fn integrate(&mut self, out: &impl SampleOut, t_us: u64, age_us: [u16; 3]) {
        if !self.settings.angle {
            self.angle_from = [None; 3];
            return;
        }
        for a in 0..3 {
            let now = out
                .fused(a)
                .map(|f| f.0)
                .filter(|r| r.is_finite())
                .map(|r| (t_us.saturating_sub(u64::from(age_us[a])), r));
            if let (Some((t0, r0)), Some((t1, r1))) = (self.angle_from[a], now) {
                let dt = t1.saturating_sub(t0);
                let step = 0.5 * (r0 + r1) * TURN_UNITS;
                let units = if dt <= 1 << 16 {
                    // The FPU's conversion, rounded half away from zero:
                    // |step| ≤ 2 000 °/s × 65 536 µs is 1.6 × 10⁹ units, inside
                    // an i32 (the cast saturates beyond).
                    let x = step * dt as f32;
                    i64::from((x + 0.5f32.copysign(x)) as i32)
                } else {
                    // A gap of more than 65 ms: in f64 (rare, and slow).
                    libm::round(f64::from(step) * dt as f64) as i64
                };
                self.angle[a] = self.angle[a].wrapping_add(units as u64);
            }
            self.angle_from[a] = now;
        }
    }

    /// The next axis (in turn) with an estimate not sent yet, finite.
    fn next_noise(&mut self, noise: &impl NoiseSource) -> Option<Noise> {
        for k in 0..3 {
            let a = (self.noise_turn + k) % 3;
            let Some(seq) = noise.described(a) else {
                continue;
            };
            if self.noise_sent.get(a).copied().flatten() == Some(seq) {
                continue;
            }
            // Asked once per new estimate: one that is not finite is
            // skipped, never sent.
            if let Some(s) = self.noise_sent.get_mut(a) {
                *s = Some(seq);
            }
            let Some(n) = noise.noise(a) else { continue };
            if n.sigma_dps.iter().all(|s| s.is_finite()) {
                self.noise_turn = (a + 1) % 3;
                return Some(n);
            }
        }
        None
    }

    /// Whether a status frame is due with sample `seq` (periodic or
    /// requested); clears the request.
    pub fn status_due(&mut self, seq: u32) -> bool {
        let every = self.settings.status_every;
        let due = self.status_requested || (every != 0 && seq.is_multiple_of(every));
        self.status_requested = false;
        due
    }

    /// The status frame: settings, the link's and the pipeline's counters,
    /// and each chip's time (`clocks[i]`: its clock's source and error
    /// against the board's, ppm, and its FIFO's anomalies; missing entries
    /// read as polled).
    #[allow(clippy::too_many_arguments)]
    pub fn status(
        &self,
        array: &impl Array,
        seq: u32,
        t_us: u64,
        noise_tau: [u16; 3],
        sample_us: u32,
        stack_peak: u32,
        clocks: &[ChipTime],
    ) -> Frame {
        let mut gyros = Vec::<GyroStatus, MAX_GYROS>::new();
        for i in 0..array.gyros().min(MAX_GYROS) {
            let _ = gyros.push(GyroStatus {
                clock: clocks.get(i).map_or(ClockSource::Polled, |c| c.source),
                clock_ppm: clocks.get(i).map_or(0, |c| c.ppm),
                fifo: clocks.get(i).map_or(FifoAnomalies::default(), |c| c.fifo),
                ..array.gyro_status(i)
            });
        }
        Frame::Status(Status {
            seq,
            t_us,
            settings: self.settings,
            noise_tau,
            sample_us,
            overruns: array.overruns(),
            link: self.counters,
            stack_peak,
            store: self.store,
            gyros,
        })
    }

    /// The MCU's unique ID, for the info frames.
    pub fn set_uid(&mut self, uid: [u8; 12]) {
        self.uid = uid;
    }

    /// Whether an info frame goes with sample `seq`: when asked for, and
    /// once every `status_every` samples (at least every 1 000) half way
    /// between status frames.
    pub fn info_due(&mut self, seq: u32) -> bool {
        let every = match self.settings.status_every {
            0 => 0,
            n => n.max(1000),
        };
        let due = self.info_requested || (every != 0 && seq % every == every / 2);
        self.info_requested = false;
        due
    }

    /// The info frame: the board, the firmware, and each gyro as `gyros`
    /// and the pipeline know it.
    pub fn info<const N: usize>(&self, array: &impl Array, gyros: &[&mut dyn Gyro; N]) -> Frame {
        let mut chips = Vec::<ChipInfo, MAX_GYROS>::new();
        for (i, g) in gyros.iter().enumerate() {
            let (start, t) = array.start(i);
            let (part, id) = g.identity();
            // (A saturating cast: ±327 °C is beyond any die.)
            let temp_cc = t.map(|t| (t * 100.0) as i16);
            let _ = chips.push(ChipInfo {
                part,
                id,
                start,
                temp_cc,
            });
        }
        Frame::Info(Info {
            uid: self.uid,
            firmware: FIRMWARE,
            build: BUILD,
            chips,
        })
    }

    /// Read the bytes the UART has; apply every complete command to the
    /// settings (and the fusion method to `array`), and queue its [`Ack`].
    /// A command that cannot be read or applied changes nothing and is
    /// rejected.
    pub fn receive<R: embedded_hal_nb::serial::Read<u8>>(
        &mut self,
        uart: &mut R,
        array: &mut impl Array,
    ) {
        // Bounded: a UART that always has a byte cannot hold the loop.
        for _ in 0..RX_MAX {
            let Ok(b) = uart.read() else { break };
            if let Some(r) = self.rx.feed::<Command>(b) {
                self.handle(r, array);
            }
        }
    }

    /// Apply one received frame (see [`Port::receive`]).
    pub fn handle(&mut self, r: Result<Decoded<Command>, FrameError>, array: &mut impl Array) {
        let (id, result) = match r {
            Err(e) => (
                None,
                Err(match e {
                    FrameError::Cobs | FrameError::Crc => Reject::Corrupt,
                    FrameError::TooLong => Reject::TooLong,
                    FrameError::Version(_) => Reject::Version,
                    FrameError::Malformed => Reject::Malformed,
                }),
            ),
            Ok(d) => {
                let r = self.apply(d.body, array);
                if r.is_ok() && matches!(d.body.op, Op::SaveSettings | Op::FactoryReset) {
                    // Acknowledged by `store_done`.
                    return;
                }
                if r.is_ok() && matches!(d.body.op, Op::SyncTime(_)) {
                    self.acknowledge(Some(d.body.id), r);
                    self.send_sync();
                    return;
                }
                (Some(d.body.id), r)
            }
        };
        self.acknowledge(id, result);
    }

    /// The controller's sync pulse, captured at `board_us` (on the
    /// sample clock's 64-bit µs).
    pub fn sync_pulse(&mut self, board_us: u64) {
        self.sync.pulse(board_us);
    }

    /// The controller's clock as tracked.
    pub fn sync(&self) -> &CtrlClock {
        &self.sync
    }

    fn send_sync(&mut self) {
        let (board_us, ctrl_us, ppm, residual_us) = self.sync.line().unwrap_or((0, 0, 0.0, 0.0));
        let s = SyncStatus {
            state: self.sync.state(),
            board_us,
            ctrl_us,
            ppm,
            residual_us,
            dropped: self.sync.dropped,
            unpaired: self.sync.unpaired,
        };
        self.send_ref(FrameRef::Sync(&s));
    }

    fn acknowledge(&mut self, id: Option<u8>, result: Result<(), Reject>) {
        if result.is_ok() {
            self.counters.accepted = self.counters.accepted.wrapping_add(1);
        } else {
            self.counters.rejected = self.counters.rejected.wrapping_add(1);
        }
        self.send_ref(FrameRef::Ack(&Ack { id, result }));
    }

    /// The settings store's state at boot (a port starts [`StoreState::Absent`]:
    /// store commands are refused).
    pub fn set_store_state(&mut self, state: StoreState) {
        self.store = state;
    }

    /// The store command waiting, if any (it stays pending until
    /// [`Port::store_done`]).
    pub fn store_request(&self) -> Option<StoreRequest> {
        self.store_pending.map(|(_, r)| r)
    }

    /// The pending store command was carried out with `result` and the
    /// store is now in `state`: its acknowledgement is queued.
    pub fn store_done(&mut self, result: Result<(), Reject>, state: StoreState) {
        self.store = state;
        if let Some((id, _)) = self.store_pending.take() {
            self.acknowledge(Some(id), result);
        }
    }

    fn apply(&mut self, c: Command, array: &mut impl Array) -> Result<(), Reject> {
        let mut next = self.settings;
        match c.op {
            Op::SetMode(m) => next.mode = m,
            Op::SetMethod(m) => next.method = m,
            Op::SetDivider(d) => next.divider = d,
            Op::SetStatusEvery(n) => next.status_every = n,
            Op::RequestStatus => self.status_requested = true,
            Op::SetCompensation(c) => next.compensation = c,
            Op::SetAngle(on) => next.angle = on,
            Op::RequestInfo => self.info_requested = true,
            Op::SetPathTrim(t) => next.path_trim_us = t,
            Op::SyncTime(t) => {
                // Taken whether or not it pairs: the Sync frame says what
                // became of it.
                self.sync.time(t);
            }
            Op::SaveSettings | Op::FactoryReset => {
                if self.store == StoreState::Absent || self.store_pending.is_some() {
                    return Err(Reject::Refused);
                }
                if c.op == Op::FactoryReset {
                    next = Settings::default();
                }
            }
        }
        // The value the command sets, in its range (a stored record is
        // checked whole; a port may be built with values no command sets,
        // as the demo's stress run's status frame every sample).
        let mut set = Settings::default();
        match c.op {
            Op::SetDivider(d) => set.divider = d,
            Op::SetStatusEvery(n) => set.status_every = n,
            Op::SetCompensation(c) => set.compensation = c,
            Op::SetPathTrim(t) => set.path_trim_us = t,
            _ => {}
        }
        set.check()?;
        // A method selected again starts its noise model again.
        if matches!(c.op, Op::SetMethod(_)) || next.method != self.settings.method {
            array.set_method(next.method)?;
        }
        self.settings = next;
        self.retime();
        self.store_pending = match c.op {
            Op::SaveSettings => Some((c.id, StoreRequest::Save(next))),
            Op::FactoryReset => Some((c.id, StoreRequest::Clear)),
            _ => self.store_pending,
        };
        Ok(())
    }
}
