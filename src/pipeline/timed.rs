//! An ICM-42688-P read through its FIFO and put on the board's clock: the
//! driver's samples with their stamps ([`Icm42688::read_fifo`]), the
//! chip's clock tracked from its INT1 captures ([`ChipClock`]), each
//! sample's instant less the chip's signal-path delay, and the rate at the
//! array's common instant ([`Aligner`]). It is a [`Gyro`], so the pipeline
//! fuses aligned rates without knowing how they were made.
//!
//! The instant each read is for is set before it ([`TimedIcm::set_instant`]):
//! the board loop states one instant for the whole array, a fixed delay
//! behind its own clock. A chip with nothing for it answers
//! [`ReadFault::Late`] (its delay is longer than the array's) or
//! [`ReadFault::Acquiring`] (finding its clock again), which the pipeline
//! neither counts as an error nor fuses; while a chip is acquiring, the
//! pipeline fuses no pair. An overflow (a stalled bus) is a gap: the aligner starts again
//! and the chip is late until it has two samples again; it is counted
//! here, not held against the chip.

use embedded_hal::spi::SpiDevice;

use super::align::{Aligned, Aligner};
use super::clock::{ChipClock, ClockState, Instant16, Q};
use super::stamps::StampScale;
use crate::drivers::icm42688::{
    ClockInput, Config, Error, FifoRead, FifoSample, Icm42688, FIFO_PACKET, FIFO_RECORDS,
    MAX_PER_READ,
};
use crate::drivers::{saturated_axes, Gyro, ReadFault, Reading, Restart, SampleCapture};

/// Samples kept per chip: 8 ms at 4 kHz, room for an instant up to 7 ms
/// behind the newest sample (the ADXRS453's filter delay, for comparison,
/// is 2.9 ms). A power of two, so the ring's index is a mask.
pub const ALIGN_CAP: usize = 32;

/// What the timing layer counted for one chip.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TimingCounters {
    /// Samples read from the FIFO.
    pub samples: u32,
    /// Reads with nothing for the instant asked for.
    pub late: u32,
    /// Of those, reads with the instant older than every sample kept (a
    /// gap behind it) or the clock not yet acquired.
    pub acquiring: u32,
    /// FIFO overflows (the FIFO was flushed: a gap).
    pub overflows: u32,
    /// Captures that did not fit the tracked clock (see
    /// [`super::clock::JUMP_US`]).
    pub jumps: u32,
    /// Reads whose instant fell behind every sample kept, the clock
    /// tracking (a gap, or instants out of order).
    pub missing: u32,
    /// Times the chip was moved off CLKIN to its own clock because no
    /// sample came for [`CLKIN_LOST_READS`] reads.
    pub clkin_lost: u32,
    /// Samples left out as spikes (see [`SPIKE_DPS`]).
    pub spikes: u32,
    /// FIFO reads that found the stream out of step (a bad header, a
    /// count the FIFO did not hold, a garbled status): a gap.
    pub bad_fifo: u32,
    /// Packets the chip sent again after handing them over past a burst's
    /// count, dropped.
    pub resent: u32,
    /// Bursts cut inside a packet (chip select lost), the packet read
    /// again whole.
    pub cuts: u32,
}

/// A step between two of a chip's samples (0.25 ms apart at 4 kHz) larger
/// than this, °/s, on any axis, is no rate the chip's filters can pass:
/// a vehicle's motion (1 200 °/s² at 95 °/s and 2 Hz) moves 0.3 °/s in
/// 0.25 ms, white noise some 0.1, and a 20 °/s vibration tone at 600 Hz
/// (the worst the AAF and UI filter let through, some 4.5 °/s of it) some
/// 4 (some 7 at 2 kHz with 0.5 ms between samples). A spike left in
/// would be smeared by the moving mean and the interpolation over two or
/// three outputs of a few °/s each, inside the fusion's gate, where a chip
/// spiking 200 °/s on 5 % of its samples takes all the weight (its
/// residual, less the others', drives its variance down; `fault-campaign
/// --timed`). The sample is left out and the read
/// is a read error, as a garbled frame is; two samples in a row that
/// agree with each other are a new level (a chip that saturates), taken.
pub const SPIKE_DPS: f32 = 25.0;

/// How far behind its read the board states each sample's instant, µs,
/// for its chips' FIFO sampling (`icm42688::board_fifo`, 4 kHz through
/// `icm42688::BOARD_FILTER_FIFO`): [`stated_delay_us`], 1 021 µs of path,
/// 375 of the mean of four's half-span and a 250 µs sample period, for a
/// chip 1 % slow.
pub const BOARD_DELAY_US: u32 = 1670;

/// The board's SPI clocks, Hz (`board-f405` at 168 MHz): SPI1 to the
/// four ICM-42688-P, APB2's 84 MHz / 4, the fastest within the chip's
/// 24 MHz; SPI2 to the ADXRS453, APB1's 42 MHz / 8, within its 8 MHz.
pub const BOARD_SPI_ICM_HZ: u32 = 21_000_000;
/// See [`BOARD_SPI_ICM_HZ`].
pub const BOARD_SPI_ADXRS_HZ: u32 = 5_250_000;

/// How long one sample's SPI transfers take on the board, µs, its four
/// ICM-42688-P sampling through `cfg`'s FIFO: per chip the command byte,
/// INT_STATUS, FIFO_COUNT and a millisecond's packets (one more command
/// byte for each further burst of [`MAX_PER_READ`]), and the ADXRS453's
/// 32-bit frame. The drivers' `SpiDevice` transfers block, so the CPU
/// waits these out on the frame's path, beside the loop's instructions
/// (which `cargo xtask bench-loop` counts without them); the bytes are
/// taken back to back. A configuration read-back or a temperature read,
/// once in 32 samples, adds a few bytes more.
pub fn board_spi_us(cfg: &Config) -> f32 {
    let packets = cfg.odr.per_ms();
    let bursts = packets.div_ceil(MAX_PER_READ).max(1);
    let icm_bytes = 4 * (bursts + 3 + FIFO_PACKET * packets);
    (icm_bytes * 8) as f32 * 1e6 / BOARD_SPI_ICM_HZ as f32 + 32.0 * 1e6 / BOARD_SPI_ADXRS_HZ as f32
}

/// How far behind its read an instant can be stated for chips sampling
/// through `cfg`'s FIFO, µs: the path's group delay, the moving mean's
/// half-span and one sample period for the newest mean to exist, for a
/// chip 1 % slow (a PLL's limit), rounded up to 10 µs. A chip fallen back
/// to its RC oscillator, up to 8 % slow, is late for part of its samples
/// and left out of those (`timing-eval` prints the budget). `path_trim_us`:
/// the path measured that much longer than the datasheet's reading
/// ([`crate::link::msg::Settings::path_trim_us`]).
pub fn stated_delay_us(cfg: &Config, path_trim_us: i16) -> u32 {
    let n = cfg.odr.per_ms() as f32;
    let period = 1e6 / cfg.odr.hz();
    let path = cfg.filter.group_delay_us(cfg.odr) + f32::from(path_trim_us);
    let d = 1.01 * (path.max(0.0) + (n - 1.0) / 2.0 * period + period);
    (libm::ceilf(d / 10.0) * 10.0) as u32
}

/// The board's [`stated_delay_us`] with its path trimmed by
/// `path_trim_us`: [`BOARD_DELAY_US`] untrimmed.
pub fn board_delay_us(path_trim_us: i16) -> u32 {
    if path_trim_us == 0 {
        BOARD_DELAY_US
    } else {
        stated_delay_us(
            &crate::drivers::icm42688::board_fifo(ClockInput::Internal),
            path_trim_us,
        )
    }
}

/// Reads without a sample after which a chip on CLKIN is taken to have lost
/// it (at 4 kHz, 20 reads without one of 80 expected samples) and is moved
/// to its own clock: the chip's grid stops without CLKIN (see
/// `gyro_sim::timing`), and its own PLL keeps it sampling.
pub const CLKIN_LOST_READS: u16 = 20;

/// Reads with samples after a gap (an overflow, a restart, a stream out
/// of step) before a chip answers again. Time alone would bring the chips
/// that shared a gap back one by one, a read apart as their phases fall,
/// and for a read two of four could be fused, one of them perhaps faulty;
/// a count of reads brings them back together (4 reads hold 16 samples at
/// 4 kHz, more than the stated instant needs).
pub const REJOIN_READS: u8 = 4;

/// An ICM-42688-P on the board's clock.
pub struct TimedIcm<SPI, C> {
    g: Icm42688<SPI>,
    capture: C,
    clock: ChipClock,
    /// Where the samples go as they are parsed.
    intake: Intake,
    /// The signal path's delay, 1/16 µs of the chip's clock, as the
    /// datasheet reads it.
    path16: u32,
    /// What a rate table measured the path longer than that, 1/16 µs
    /// ([`Gyro::aim`]; wrapping, so a shorter path is a negative trim).
    trim16: u32,
    /// Chip µs between samples.
    period_us: u32,
    /// °/s per LSB at the configured full scale.
    dps_per_lsb: f32,
    at: Option<Instant16>,
    /// How far the instant asked for is behind the read, µs.
    behind_us: u32,
    last_raw: [i16; 3],
    /// Reads in a row without a sample.
    dry: u16,
    /// Reads with samples still to come before the aligner answers again
    /// after a gap (see [`REJOIN_READS`]).
    rejoin: u8,
    /// Added to the stamps' µs: after a flush the count's high bits are
    /// lost, and the µs off by whole wraps of it; this puts them back on
    /// the tracked clock's (see [`TimedIcm::rebase`]).
    stamp_offset: u32,
    /// The next samples need [`Self::stamp_offset`] found again.
    rebase: bool,
    /// What was counted.
    pub counters: TimingCounters,
}

/// The instant an array's reads are for (board clock, 1/16 µs, as
/// [`TimedIcm::set_instant`] takes it): `behind_us` before `now_us`, the
/// captures' µs count at the read. One for every chip of the array.
pub fn array_instant(now_us: u32, behind_us: u32) -> Instant16 {
    now_us.wrapping_sub(behind_us).wrapping_mul(16)
}

impl<SPI: SpiDevice, C: SampleCapture> TimedIcm<SPI, C> {
    /// Wrap a driver set up (or to be restarted) with FIFO sampling
    /// `cfg`, and the capture of its INT1.
    pub fn new(g: Icm42688<SPI>, capture: C) -> Self {
        let cfg = g.config();
        let period_us = libm::roundf(1e6 / cfg.odr.hz()) as u32;
        Self {
            g,
            capture,
            clock: ChipClock::new(),
            intake: Intake {
                align: Aligner::new(cfg.odr.per_ms() as u8),
                spike: SpikeCheck::new(),
                spike_lsb: (SPIKE_DPS * cfg.full_scale.lsb_per_dps()) as u32,
                scale: StampScale::new(cfg.clock, period_us),
                spiked: 0,
            },
            path16: libm::roundf(cfg.filter.group_delay_us(cfg.odr) * Q) as u32,
            trim16: 0,
            period_us,
            dps_per_lsb: 1.0 / cfg.full_scale.lsb_per_dps(),
            at: None,
            behind_us: 0,
            last_raw: [0; 3],
            dry: 0,
            rejoin: REJOIN_READS,
            stamp_offset: 0,
            rebase: false,
            counters: TimingCounters::default(),
        }
    }

    /// The driver.
    pub fn driver(&mut self) -> &mut Icm42688<SPI> {
        &mut self.g
    }

    /// The chip's clock tracker.
    pub fn clock(&self) -> &ChipClock {
        &self.clock
    }

    /// The instant its newest moving mean describes, on the board's clock
    /// (1/16 µs): the mean's stamp less the signal path's delay, the
    /// inverse of the mapping a read makes. `None` before the clock is
    /// tracked. How far the newest data lie behind the read.
    pub fn newest_instant(&self) -> Option<Instant16> {
        let chip = self
            .intake
            .scale
            .us16_of(self.intake.align.newest()?)
            .wrapping_add(self.stamp_offset.wrapping_mul(16))
            .wrapping_sub(self.path16.wrapping_add(self.trim16));
        self.clock.board_instant16(chip)
    }

    /// Where the chip takes its clock from now.
    pub fn clock_input(&self) -> ClockInput {
        self.g.config().clock
    }

    /// The instant (board clock, 1/16 µs) the next read is for, and how
    /// far it is behind the read, µs (what [`Gyro::delay_us`] states).
    pub fn set_instant(&mut self, at: Instant16, behind_us: u32) {
        self.at = Some(at);
        self.behind_us = behind_us;
    }

    /// Start again (after a restart: new stamps, a new phase).
    fn forget(&mut self) {
        self.clock.reset();
        self.gap();
        let cfg = self.g.config();
        self.intake.scale = StampScale::new(cfg.clock, self.period_us);
        self.stamp_offset = 0;
        self.rebase = false;
    }

    /// A gap in the samples (the FIFO was flushed): the aligner starts
    /// again; the clock is kept, and the stamps are put back on its count
    /// by the first capture after the gap.
    fn gap(&mut self) {
        self.intake.align.clear();
        self.intake.spike = SpikeCheck::new();
        self.rejoin = REJOIN_READS;
        self.rebase = true;
        if self.clock.state() != ClockState::Tracking {
            // Nothing to put the new stamps back on: acquire afresh.
            self.clock.reset();
        }
    }

    /// The stamps' high bits are lost over a flush (a 16-bit count wraps
    /// every 70 ms on the chip's own clock, and a gap can be longer), so
    /// their µs after it are off by whole wraps ([`StampScale::wrap_us`]):
    /// the tracked clock predicts the newest sample's stamp from its
    /// capture well within a wrap (tens of µs after a gap of seconds),
    /// which tells how many.
    fn rebase(&mut self, newest: u32, capture_us: u32) {
        if let Some(pred) = self.clock.stamp_at(capture_us) {
            let cur = newest.wrapping_add(self.stamp_offset);
            let w = self.intake.scale.wrap_us() as f32;
            let j = libm::roundf(pred.wrapping_sub(cur) as i32 as f32 / w);
            self.stamp_offset = self.stamp_offset.wrapping_add((j * w) as i32 as u32);
        }
        self.rebase = false;
    }

    /// A sample of burst `f` (its stamp, a count) and its INT1
    /// capture, from the captures before and after the burst. The burst
    /// reads the FIFO's count before its packets, so the newest sample
    /// counted is the one whose pulse came last before the count was read:
    /// the capture before the burst, unless a pulse came during it. Such a
    /// pulse may have come before the count or after it (a window of a
    /// byte or two, where a chip on CLKIN can keep its phase for seconds,
    /// and the emulator's per-byte bus time shows it): its sample was
    /// either counted, or handed over past the count, or left in the FIFO;
    /// what the burst handed over and, failing that, a second read of the
    /// count say which. Paired by time alone (the capture after the burst
    /// with the newest sample), a chip whose pulse fell in that window on
    /// every read was tracked a sample period off for good.
    fn pair(
        &mut self,
        f: &FifoRead,
        before: Option<u32>,
        after: Option<u32>,
    ) -> Option<(u32, u32)> {
        if f.left > 0 || f.cut {
            // Not the newest: the rest is read next.
            return None;
        }
        let counted = f.counted_stamp;
        match after {
            Some(a) if after != before => {
                if f.samples > f.counted {
                    // The pulse's sample came past the count.
                    Some((f.last?.stamp, a))
                } else {
                    match self.g.fifo_count() {
                        Ok(0) => Some((counted?, a)),
                        Ok(_) => Some((counted?, before?)),
                        Err(_) => None,
                    }
                }
            }
            _ => Some((counted?, before?)),
        }
    }

    /// The clock's observation for one FIFO read: a sample's stamp (its
    /// count, put on µs of the chip's clock by [`StampScale`]) and its
    /// INT1 capture ([`TimedIcm::pair`]).
    fn observe(&mut self, count: u32, c: u32) {
        let newest = self.intake.scale.us_of(count);
        if self.rebase {
            self.rebase(newest, c);
            self.clock
                .reanchor(newest.wrapping_add(self.stamp_offset), c);
            return;
        }
        let stamp = newest.wrapping_add(self.stamp_offset);
        let jumps = self.clock.jumps;
        self.clock.observe(stamp, c);
        self.counters.jumps = self
            .counters
            .jumps
            .wrapping_add(self.clock.jumps.wrapping_sub(jumps));
    }
}

/// Where a read's samples go as the driver parses them: the stamps' scale
/// while it learns its unit, the spike check, the aligner. One struct, so
/// the parse's per-sample call reaches all of it through one pointer.
#[derive(Clone, Copy, Debug)]
struct Intake {
    align: Aligner<ALIGN_CAP>,
    spike: SpikeCheck,
    /// The spike check's limit, LSB (see [`SPIKE_DPS`]).
    spike_lsb: u32,
    /// The chip's stamp counts onto µs of its nominal clock.
    scale: StampScale,
    /// Samples left out as spikes in this read.
    spiked: u32,
}

impl Intake {
    /// One sample as the driver parsed it. The aligner keeps counts: its
    /// means and interpolation are the same in any unit linear in the
    /// chip's time, and the one instant a read asks for is put in counts.
    #[inline(always)]
    fn take(&mut self, x: FifoSample) {
        if !self.scale.decided() {
            // Every step votes while the unit is learnt on CLKIN, spikes
            // too: their stamps are the chip's.
            self.scale.learn(x.stamp);
        }
        if self.spike.pass(x.raw, self.spike_lsb) {
            self.align.push(x.stamp, x.raw);
        } else {
            self.spiked += 1;
        }
    }
}

/// The spike check (see [`SPIKE_DPS`]): the last sample taken, and one
/// left out waiting to be confirmed as a new level by the next.
#[derive(Clone, Copy, Debug)]
struct SpikeCheck {
    last: [i16; 3],
    has_last: bool,
    pending: [i16; 3],
    has_pending: bool,
}

impl SpikeCheck {
    const fn new() -> Self {
        Self {
            last: [0; 3],
            has_last: false,
            pending: [0; 3],
            has_pending: false,
        }
    }

    /// Whether raw sample `x` is one the chip's filters could have made
    /// after the last one taken, `lim` LSB a step.
    fn pass(&mut self, x: [i16; 3], lim: u32) -> bool {
        // |d| ≤ lim as one unsigned compare of d + lim against 2·lim, the
        // three axes or'ed without branches (lim is a few thousand LSB).
        let near = |b: [i16; 3]| {
            let far = |k: usize| {
                (i32::from(x[k]) - i32::from(b[k])).wrapping_add(lim as i32) as u32 > 2 * lim
            };
            !(far(0) | far(1) | far(2))
        };
        // Two in a row that agree: a new level, not a spike.
        if !self.has_last || near(self.last) || (self.has_pending && near(self.pending)) {
            self.last = x;
            self.has_last = true;
            self.has_pending = false;
            true
        } else {
            self.pending = x;
            self.has_pending = true;
            false
        }
    }
}

impl<SPI: SpiDevice, C: SampleCapture> Gyro for TimedIcm<SPI, C> {
    fn read(&mut self) -> Result<Reading, ReadFault> {
        let mut fresh = false;
        let lost = self.clock.lost;
        self.intake.spiked = 0;
        // Bursts until the FIFO is read down: a full FIFO is
        // FIFO_RECORDS / MAX_PER_READ of them; more is a chip that keeps
        // cutting its bursts, whose samples wait for the next read.
        for _ in 0..=FIFO_RECORDS / MAX_PER_READ {
            // Each sample goes to the aligner as it is parsed, on the
            // driver's stamps: the clock is needed only for the instant a
            // read asks for. The capture before the burst and after it:
            // which sample the capture is of (see [`TimedIcm::pair`]).
            let before = self.capture.last_us();
            let Self { g, intake, .. } = self;
            let r = g.read_fifo_with(MAX_PER_READ, |x| intake.take(x));
            let after = self.capture.last_us();
            match r {
                Ok(f) => {
                    fresh |= f.samples > 0;
                    self.counters.resent = self.counters.resent.wrapping_add(f.resent as u32);
                    self.counters.cuts = self.counters.cuts.wrapping_add(u32::from(f.cut));
                    self.counters.samples = self.counters.samples.wrapping_add(f.samples as u32);
                    if let Some(x) = f.last {
                        self.last_raw = x.raw;
                        // The read's newest sample is the scale's base for
                        // the maps near it (the pair's stamp, the instant).
                        self.intake.scale.convert(x.stamp);
                        if self.intake.scale.take_changed() {
                            // The unit was decided other than guessed: the
                            // µs so far do not join the next.
                            self.clock.reset();
                            self.gap();
                        }
                        if let Some((stamp, capture)) = self.pair(&f, before, after) {
                            self.observe(stamp, capture);
                        }
                    }
                    if f.left == 0 {
                        break;
                    }
                }
                Err(Error::ChipReset) => return Err(ReadFault::Reset),
                Err(Error::FifoOverflow) => {
                    self.counters.overflows = self.counters.overflows.wrapping_add(1);
                    self.gap();
                    break;
                }
                Err(Error::Spi(_)) => return Err(ReadFault::Bus),
                Err(_) => {
                    // A bad header or a short FIFO: the stream was out of
                    // step (flushed); the samples around it are gone. A
                    // garbled status is the chip's own read error too (a
                    // shared stall is FIFO_FULL with a full count, above).
                    self.counters.bad_fifo = self.counters.bad_fifo.wrapping_add(1);
                    self.gap();
                    return Err(ReadFault::BadResponse);
                }
            }
        }
        self.counters.spikes = self.counters.spikes.wrapping_add(self.intake.spiked);
        if self.intake.spiked > 0 {
            // A sample no rate could have made: a faulty chip's, as a
            // garbled frame is (the pipeline flags it).
            return Err(ReadFault::BadResponse);
        }
        if self.clock.lost != lost {
            // The stamps or captures stopped making sense (a garbled
            // stream, a clock that jumped): a read error, so a chip that
            // keeps doing it is flagged and restarted, not left acquiring.
            self.gap();
            return Err(ReadFault::BadResponse);
        }
        self.dry = if fresh { 0 } else { self.dry.saturating_add(1) };
        if fresh && self.rejoin > 0 {
            self.rejoin -= 1;
        }
        if self.dry >= CLKIN_LOST_READS && self.g.config().clock == ClockInput::ClkIn {
            // CLKIN is gone: the chip's own clock from now on (a few
            // checked writes; its read-back follows the new setting).
            let cfg = Config {
                clock: ClockInput::Internal,
                ..self.g.config()
            };
            self.g
                .configure_path(cfg)
                .map_err(|_| ReadFault::BadResponse)?;
            self.g.configure(cfg).map_err(|_| ReadFault::BadResponse)?;
            self.counters.clkin_lost = self.counters.clkin_lost.wrapping_add(1);
            self.forget();
            self.dry = 0;
        }
        let at = self.at.ok_or(ReadFault::Late)?;
        // The instant on the chip's clock (`None` while the clock is not
        // tracked), on the driver's stamps, plus the path's delay (a time on
        // the chip's clock): the samples that describe it.
        let chip = self.clock.chip_instant(at).filter(|_| self.rejoin == 0);
        let Some(chip) = chip else {
            self.counters.late = self.counters.late.wrapping_add(1);
            self.counters.acquiring = self.counters.acquiring.wrapping_add(1);
            return Err(ReadFault::Acquiring);
        };
        let t = self.intake.scale.counts16_of(
            chip.wrapping_sub(self.stamp_offset.wrapping_mul(16))
                .wrapping_add(self.path16.wrapping_add(self.trim16)),
        );
        match self.intake.align.at(t, self.dps_per_lsb) {
            Aligned::Rate(rate_dps) => {
                let saturated = saturated_axes(&self.last_raw);
                Ok(Reading {
                    raw: self.last_raw,
                    rate_dps,
                    axes: 0b111,
                    saturated,
                })
            }
            Aligned::Late => {
                self.counters.late = self.counters.late.wrapping_add(1);
                Err(ReadFault::Late)
            }
            Aligned::Missing => {
                self.counters.late = self.counters.late.wrapping_add(1);
                self.counters.acquiring = self.counters.acquiring.wrapping_add(1);
                self.counters.missing = self.counters.missing.wrapping_add(1);
                Err(ReadFault::Acquiring)
            }
        }
    }

    fn restart(&mut self, step: u8) -> Result<Restart, ReadFault> {
        let r = self.g.restart(step);
        if step == 0 || r == Ok(Restart::Done) {
            self.forget();
        }
        r
    }

    fn check_config(&mut self) -> Result<(), ReadFault> {
        Gyro::check_config(&mut self.g)
    }

    fn temperature_c(&mut self) -> Result<f32, ReadFault> {
        self.g.temperature_c()
    }

    fn identity(&self) -> (crate::link::msg::Part, u16) {
        self.g.identity()
    }

    fn delay_us(&self) -> u32 {
        self.behind_us
    }

    fn aim(&mut self, at: Instant16, behind_us: u32, path_trim_us: i16) {
        self.set_instant(at, behind_us);
        self.trim16 = (i32::from(path_trim_us) * Q as i32) as u32;
    }
}

/// Whether the tracker has the chip's clock.
pub fn tracking(c: &ChipClock) -> bool {
    c.state() == ClockState::Tracking
}

/// A polled gyro in an array that states one instant `behind_us` behind
/// the read (the board's, [`BOARD_DELAY_US`]): its reading describes its
/// own delay behind the read ([`Gyro::delay_us`]). One whose delay is
/// longer has nothing for the instant and answers [`ReadFault::Late`]
/// (neither fused nor a fault) after its read, so its health is still
/// watched: the ADXRS453, whose 2.9 ms filter and one-frame-late response
/// make 3.9 ms, on the board's 1.67 ms instant. (Reading the ADXRS453 at
/// the instant would need its rate predicted 2 ms forward, its noise
/// doubled: `docs/timing.md`.)
pub struct AtInstant<G> {
    g: G,
    behind_us: u32,
}

impl<G: Gyro> AtInstant<G> {
    /// `g` in an array stating instants `behind_us` behind the read.
    pub fn new(g: G, behind_us: u32) -> Self {
        Self { g, behind_us }
    }

    /// The gyro.
    pub fn inner(&mut self) -> &mut G {
        &mut self.g
    }
}

impl<G: Gyro> Gyro for AtInstant<G> {
    fn read(&mut self) -> Result<Reading, ReadFault> {
        let r = self.g.read()?;
        if self.g.delay_us() > self.behind_us {
            return Err(ReadFault::Late);
        }
        Ok(r)
    }

    fn restart(&mut self, step: u8) -> Result<Restart, ReadFault> {
        self.g.restart(step)
    }

    fn check_config(&mut self) -> Result<(), ReadFault> {
        self.g.check_config()
    }

    fn temperature_c(&mut self) -> Result<f32, ReadFault> {
        self.g.temperature_c()
    }

    fn delay_us(&self) -> u32 {
        self.g.delay_us()
    }

    /// The array's distance behind the read (the trim is the ICM-42688-P's
    /// path, not this part's).
    fn aim(&mut self, _at: Instant16, behind_us: u32, _path_trim_us: i16) {
        self.behind_us = behind_us;
    }

    fn identity(&self) -> (crate::link::msg::Part, u16) {
        self.g.identity()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drivers::icm42688::board_fifo;

    /// A gyro whose reading describes `delay_us` behind its read.
    struct Fixed {
        delay_us: u32,
        fail: bool,
    }

    impl Gyro for Fixed {
        fn read(&mut self) -> Result<Reading, ReadFault> {
            if self.fail {
                return Err(ReadFault::Bus);
            }
            Ok(Reading {
                raw: [1, 2, 3],
                rate_dps: [0.1, 0.2, 0.3],
                axes: 0b100,
                saturated: 0,
            })
        }
        fn restart(&mut self, _: u8) -> Result<Restart, ReadFault> {
            Ok(Restart::Done)
        }
        fn delay_us(&self) -> u32 {
            self.delay_us
        }
    }

    #[test]
    fn a_gyro_older_than_the_instant_is_late_and_its_faults_still_count() {
        let mut old = AtInstant::new(
            Fixed {
                delay_us: 3900,
                fail: false,
            },
            BOARD_DELAY_US,
        );
        assert_eq!(old.read(), Err(ReadFault::Late));
        old.inner().fail = true;
        assert_eq!(old.read(), Err(ReadFault::Bus));
        let mut new = AtInstant::new(
            Fixed {
                delay_us: 1200,
                fail: false,
            },
            BOARD_DELAY_US,
        );
        assert!(new.read().is_ok());
        assert_eq!(new.delay_us(), 1200);
    }

    #[test]
    fn the_boards_spi_time_is_its_bytes_at_its_clocks() {
        // Four bursts of 1 + 3 + 4 × 16 bytes at 21 MHz, 4 bytes at 5.25 MHz.
        let us = board_spi_us(&board_fifo(ClockInput::ClkIn));
        let want = 4.0 * 68.0 * 8.0 / 21.0 + 32.0 / 5.25;
        assert!((us - want).abs() < 1e-3, "{us} against {want}");
    }

    #[test]
    fn the_board_states_the_delay_its_sampling_needs() {
        for clock in [ClockInput::Internal, ClockInput::ClkIn] {
            assert_eq!(stated_delay_us(&board_fifo(clock), 0), BOARD_DELAY_US);
            // A path measured longer is stated further behind (the slow UI
            // filter's reading, docs/timing.md), a shorter one nearer.
            assert_eq!(board_delay_us(353), 2020);
            assert_eq!(board_delay_us(-53), 1610);
            assert_eq!(board_delay_us(0), BOARD_DELAY_US);
        }
    }
}
