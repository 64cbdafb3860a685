//! The gyro board's world, emulated: the ICM-42688-P and the ADXRS453 at
//! register and SPI-byte level, the bus between them and the board, the
//! board's flash, a controller's clock, the motion and noise the chips see,
//! the demo's scenario, and the self-checks run on the host and in QEMU.
//! None of it is flashed onto the board: the firmware crate (`gyro-array`)
//! builds without it, and this crate's QEMU binaries run the firmware's own
//! code on QEMU's `mps2-an386` against it.
//!
//! [`EmuBus`] implements [`embedded_hal::spi::SpiBus`] and [`EmuCs`]
//! implements [`embedded_hal::digital::OutputPin`], so an
//! `embedded_hal_bus::spi::RefCellDevice` built from them is an ordinary
//! `SpiDevice` and the real drivers run on it unchanged. Each chip sees the
//! bytes of a frame exactly as the silicon would, starting at the chip-select
//! falling edge.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![deny(unsafe_code)]
#![warn(missing_docs)]
#![allow(clippy::neg_cmp_op_on_partial_ord)]
#![allow(clippy::needless_range_loop)]

pub mod checks;
#[cfg(feature = "qemu")]
pub mod qemu;

pub mod adxrs453;
pub mod board;
pub mod controller;
pub mod demo;
pub mod flash;
pub mod icm42688;
pub mod mount;
pub mod noise;
pub mod rng;
pub mod timing;

use core::cell::Cell;
use core::convert::Infallible;

use embedded_hal::digital::{ErrorType as PinErrorType, OutputPin};
use embedded_hal::spi::{ErrorKind, ErrorType, SpiBus};

pub use adxrs453::{AdxTiming, Adxrs453Model};
pub use board::{board_drivers, emu_device, BoardDrivers, EmuDevice};
pub use icm42688::{ChipTiming, Icm42688Model, PathModel, RtcTick};
pub use mount::{Mount, TempProfile};
pub use noise::{NoiseParams, RateProfile};
pub use rng::Rng;
pub use timing::{PastCount, PathReading};

/// A fault the emulated chip injects on demand.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Fault {
    /// Behaves as specified.
    None,
    /// Output registers stop updating.
    Stuck,
    /// Output pinned at the positive end of the range.
    Saturated,
    /// With probability `prob` per sample, add `magnitude_dps` of either sign.
    Spikes {
        /// Probability per sample.
        prob: f32,
        /// Spike size in °/s.
        magnitude_dps: f32,
    },
    /// Each MISO byte has one bit flipped with probability `prob`.
    BitErrors {
        /// Probability per byte.
        prob: f32,
    },
    /// With probability `prob` per frame, one bit of the frame is flipped
    /// (ADXRS453 only; two flips in one parity half would escape any parity
    /// check, which is what [`Fault::BitErrors`] can produce).
    FrameBitError {
        /// Probability per frame.
        prob: f32,
    },
    /// The identity register reads another part's id.
    WrongId,
    /// The chip does not drive MISO (reads 0xFF, the pull-up).
    NoResponse,
    /// The chip reports an internal fault (ADXRS453 fault bits).
    ChipFault,
    /// The built-in self-test produces no deflection.
    DeadSelfTest,
    /// The chip has no power: it does not drive MISO and ignores every
    /// command. Clearing this fault powers it up in its reset state (a late
    /// power-up, or the end of a brown-out).
    PoweredOff,
    /// The zero-rate output of every axis ramps at `dps_per_s` from the
    /// moment the fault is set (a chip failing slowly, far faster than
    /// temperature moves a part's bias); clearing the fault takes the ramp
    /// away. ICM-42688-P only (the ADXRS453 reads as specified).
    BiasDrift {
        /// Ramp, °/s per second.
        dps_per_s: f32,
    },
}

/// A chip on the emulated bus. No heap here, so the variants are not boxed;
/// the size difference is a few hundred bytes per chip.
#[allow(clippy::large_enum_variant)]
pub enum Chip {
    /// An ICM-42688-P.
    Icm(Icm42688Model),
    /// An ADXRS453.
    Adx(Adxrs453Model),
}

impl Chip {
    fn begin_frame(&mut self) {
        match self {
            Chip::Icm(c) => c.begin_frame(),
            Chip::Adx(c) => c.begin_frame(),
        }
    }
    fn exchange(&mut self, mosi: u8) -> u8 {
        match self {
            Chip::Icm(c) => c.exchange(mosi),
            Chip::Adx(c) => c.exchange(mosi),
        }
    }
    /// Advance the chip's sensor by one bus step to time `t_s` (f32; and
    /// `t64_s`, the same time in f64, for the chips that keep their own
    /// time), with the board driving CLKIN at `clkin_hz`.
    pub fn advance(&mut self, t_s: f32, dt_s: f32, t64_s: f64, clkin_hz: Option<f64>) {
        match self {
            Chip::Icm(c) => c.advance(t_s, dt_s, t64_s, clkin_hz),
            Chip::Adx(c) => c.advance(t_s, dt_s, t64_s),
        }
    }
    /// Inject (or clear, with [`Fault::None`]) a fault. Leaving
    /// [`Fault::PoweredOff`] powers the chip up in its reset state.
    pub fn set_fault(&mut self, f: Fault) {
        let was_off = self.fault() == Fault::PoweredOff;
        match self {
            Chip::Icm(c) => c.fault = f,
            Chip::Adx(c) => c.fault = f,
        }
        if was_off && f != Fault::PoweredOff {
            self.power_cycle();
        }
    }

    /// Mount the chip: rotation, scale/misalignment, bias slope and die
    /// temperature ([`Mount`]).
    pub fn set_mount(&mut self, m: Mount) {
        match self {
            Chip::Icm(c) => c.mount = m,
            Chip::Adx(c) => c.mount = m,
        }
    }

    /// The chip's mounting.
    pub fn mount(&self) -> Mount {
        match self {
            Chip::Icm(c) => c.mount,
            Chip::Adx(c) => c.mount,
        }
    }

    /// The constant bias of its noise model, °/s, and its scale error.
    pub fn bias_and_scale(&self) -> (f32, f32) {
        let p = match self {
            Chip::Icm(c) => c.params(),
            Chip::Adx(c) => c.params(),
        };
        (p.bias_dps, p.scale_error)
    }

    /// The fault being injected.
    pub fn fault(&self) -> Fault {
        match self {
            Chip::Icm(c) => c.fault,
            Chip::Adx(c) => c.fault,
        }
    }

    /// A reset as at power-up (a brown-out, a glitch on the reset line):
    /// the ICM-42688-P loses its configuration and flags RESET_DONE; the
    /// ADXRS453 flags POR until its start-up check runs again.
    pub fn power_cycle(&mut self) {
        match self {
            Chip::Icm(c) => c.power_cycle(),
            Chip::Adx(c) => c.power_cycle(),
        }
    }
    /// A corrupted configuration register (a single-event upset, a bad
    /// write): the ICM-42688-P's GYRO_CONFIG0 flips its full-scale bits, so
    /// its data change scale without any flag. The ADXRS453 has no
    /// configuration; nothing happens.
    pub fn corrupt_config(&mut self) {
        if let Chip::Icm(c) = self {
            c.corrupt_config();
        }
    }

    /// The ICM-42688-P model, if this is one.
    pub fn icm(&mut self) -> Option<&mut Icm42688Model> {
        match self {
            Chip::Icm(c) => Some(c),
            Chip::Adx(_) => None,
        }
    }

    /// The true rate (°/s, per board axis) the chip's sensor sees now.
    pub fn true_rate_dps(&self) -> [f32; 3] {
        match self {
            Chip::Icm(c) => c.true_rate_dps,
            Chip::Adx(c) => c.true_rate_dps,
        }
    }
}

/// One chip-select line: its level and a count of falling edges, which is
/// how the bus tells a new frame from the continuation of one.
pub struct CsLine {
    low: Cell<bool>,
    edges: Cell<u32>,
}

impl CsLine {
    /// A deasserted (high) line.
    pub const fn new() -> Self {
        Self {
            low: Cell::new(false),
            edges: Cell::new(0),
        }
    }
}

impl Default for CsLine {
    fn default() -> Self {
        Self::new()
    }
}

/// Chip-select output pin driving a [`CsLine`].
pub struct EmuCs<'a>(pub &'a CsLine);

impl PinErrorType for EmuCs<'_> {
    type Error = Infallible;
}

impl OutputPin for EmuCs<'_> {
    fn set_low(&mut self) -> Result<(), Infallible> {
        if !self.0.low.get() {
            self.0.edges.set(self.0.edges.get().wrapping_add(1));
        }
        self.0.low.set(true);
        Ok(())
    }
    fn set_high(&mut self) -> Result<(), Infallible> {
        self.0.low.set(false);
        Ok(())
    }
}

/// Bus errors the emulated controller can report.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BusError {
    /// More than one chip select was low during a transfer.
    Contention,
}

impl embedded_hal::spi::Error for BusError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::ChipSelectFault
    }
}

/// The shared SPI bus with `N` emulated chips, one chip-select line each.
pub struct EmuBus<'a, const N: usize> {
    /// The chips, indexed like their chip-select lines.
    pub chips: [Chip; N],
    cs: &'a [CsLine; N],
    seen: [u32; N],
    t_s: f32,
    t64_s: f64,
    /// The board's CLKIN output to every ICM-42688-P, Hz (`None`: not
    /// driven, or stopped).
    pub clkin_hz: Option<f64>,
    /// Bytes exchanged so far (a bus-load figure for benchmarks).
    pub bytes: u32,
    /// A benchmark's clock: when set, the time spent inside the bus
    /// operations (the chip models standing in for the SPI peripheral and
    /// the silicon) is summed in [`Meter`], so that it can be told apart
    /// from the firmware's own instructions.
    pub clock: Option<fn() -> u64>,
    /// What [`EmuBus::clock`] measured.
    pub meter: Meter,
    /// Each byte on the bus takes this long, s (0: a transaction takes no
    /// time). With it, chips sample while a burst is read (a sample can
    /// land between a FIFO count's read and the capture read after the
    /// burst); [`EmuBus::advance`] then advances by what is left of its
    /// step, so a loop that steps by its period keeps it.
    pub spi_byte_s: f64,
    /// Time the bytes advanced since the last [`EmuBus::advance`].
    spi_ahead_s: f64,
    /// Chip `i`'s next FIFO read (a read burst from INT_STATUS or
    /// FIFO_DATA) of more than `cut[i]` bytes loses its chip select after
    /// that many (a glitch on the line): the chip sees its frame end
    /// there, and the rest of the bytes read the idle line's 0xFF. (A
    /// glitch in a register read-back is a configuration fault, the
    /// campaign's own kind.)
    pub cut: [Option<u32>; N],
    /// Whether each chip's current frame is a FIFO read.
    fifo_frame: [bool; N],
    /// Bytes of each chip's current frame.
    frame_bytes: [u32; N],
    /// The bus time each chip was last advanced to ([`EmuBus::catch_up`]).
    synced_s: [f64; N],
}

/// Time inside the emulated bus's operations, in the clock's units, and
/// how many operations were timed (each adds one clock read's overhead).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Meter {
    /// Clock units inside the operations.
    pub ticks: u64,
    /// Operations timed.
    pub ops: u32,
}

impl<'a, const N: usize> EmuBus<'a, N> {
    /// A bus with `chips[i]` selected by `cs[i]`.
    pub fn new(chips: [Chip; N], cs: &'a [CsLine; N]) -> Self {
        Self {
            chips,
            cs,
            seen: [0; N],
            t_s: 0.0,
            t64_s: 0.0,
            clkin_hz: None,
            bytes: 0,
            clock: None,
            meter: Meter::default(),
            spi_byte_s: 0.0,
            spi_ahead_s: 0.0,
            cut: [None; N],
            fifo_frame: [false; N],
            frame_bytes: [0; N],
            synced_s: [0.0; N],
        }
    }

    /// Run one bus operation, timed when a clock is set.
    fn metered<R>(&mut self, op: impl FnOnce(&mut Self) -> R) -> R {
        let Some(clock) = self.clock else {
            return op(self);
        };
        let t0 = clock();
        let r = op(self);
        let dt = clock().wrapping_sub(t0);
        self.meter.ticks = self.meter.ticks.wrapping_add(dt);
        self.meter.ops = self.meter.ops.wrapping_add(1);
        r
    }

    /// Advance every chip by one sample period (less the time the bus's
    /// bytes took since the last, [`EmuBus::spi_byte_s`]).
    pub fn advance(&mut self, dt_s: f32) {
        if self.spi_ahead_s == 0.0 {
            self.t_s += dt_s;
            self.t64_s += dt_s as f64;
            for c in self.chips.iter_mut() {
                c.advance(self.t_s, dt_s, self.t64_s, self.clkin_hz);
            }
            self.synced_s = [self.t64_s; N];
            return;
        }
        let d = f64::from(dt_s) - self.spi_ahead_s;
        self.spi_ahead_s = 0.0;
        if d > 0.0 {
            self.t64_s += d;
            self.t_s = self.t64_s as f32;
        } else {
            self.spi_ahead_s = -d;
        }
        for i in 0..N {
            self.catch_up(i);
        }
    }

    /// Advance chip `i` to the bus's time. The bytes of a burst move the
    /// bus's time only; each chip is brought up to it when it is next
    /// selected or its INT1 captured (the chips do not interact, so this is
    /// the same as advancing all of them every byte, at a fraction of the
    /// emulator's cost).
    fn catch_up(&mut self, i: usize) {
        let dt = self.t64_s - self.synced_s[i];
        if dt > 0.0 {
            self.synced_s[i] = self.t64_s;
            self.chips[i].advance(self.t_s, dt as f32, self.t64_s, self.clkin_hz);
        }
    }

    /// Emulated time in seconds.
    pub fn time_s(&self) -> f32 {
        self.t_s
    }

    /// The board timer's capture of chip `i`'s INT1 (its last data-ready
    /// pulse), µs of bus time, truncated to the timer's 1 µs tick: the
    /// input-capture channel each ICM-42688-P's INT1 is wired to.
    /// (Metered like a bus operation: on the board it is a register read
    /// of a few instructions; here it is the model's f64 arithmetic.)
    pub fn int1_capture_us(&mut self, i: usize) -> Option<u32> {
        if i < N {
            self.catch_up(i);
        }
        self.metered(|b| match b.chips.get(i)? {
            Chip::Icm(c) => c.int1_at_s().map(|t| (t * 1e6) as u64 as u32),
            Chip::Adx(_) => None,
        })
    }

    /// Emulated time in seconds, f64 (the chips on their own clocks run on
    /// it).
    pub fn time64_s(&self) -> f64 {
        self.t64_s
    }

    /// The board timer's count at the bus's time, µs, wrapping at 2³²: what
    /// the board reads from TIM5 (1 µs tick) in one register read; here the
    /// model's f64 time converted (the emulator's work, not the loop's).
    pub fn timer_us(&self) -> u32 {
        (self.t64_s * 1e6) as u64 as u32
    }

    fn exchange(&mut self, mosi: u8) -> Result<u8, BusError> {
        self.bytes = self.bytes.wrapping_add(1);
        let mut selected = None;
        for (i, line) in self.cs.iter().enumerate() {
            if line.low.get() {
                if selected.is_some() {
                    return Err(BusError::Contention);
                }
                selected = Some(i);
            }
        }
        let Some(i) = selected else {
            return Ok(0xFF); // nobody drives MISO: the pull-up reads high
        };
        let edges = self.cs[i].edges.get();
        if edges != self.seen[i] {
            self.seen[i] = edges;
            self.frame_bytes[i] = 0;
            self.chips[i].begin_frame();
        }
        self.catch_up(i);
        let n = self.frame_bytes[i];
        self.frame_bytes[i] = n.saturating_add(1);
        if n == 0 {
            let (read, a) = (mosi & 0x80 != 0, mosi & 0x7F);
            use gyro_array::drivers::icm42688::reg;
            self.fifo_frame[i] = read && (a == reg::INT_STATUS || a == reg::FIFO_DATA);
        }
        let miso = match self.cut[i] {
            Some(k) if n >= k && self.fifo_frame[i] => {
                if n == k {
                    // One glitch: the next transaction is whole.
                    self.cut[i] = None;
                    self.frame_bytes[i] = u32::MAX;
                }
                0xFF
            }
            _ if self.frame_bytes[i] == u32::MAX => 0xFF,
            _ => self.chips[i].exchange(mosi),
        };
        if self.spi_byte_s > 0.0 {
            self.t64_s += self.spi_byte_s;
            self.t_s = self.t64_s as f32;
            self.spi_ahead_s += self.spi_byte_s;
        }
        Ok(miso)
    }
}

/// The board timer's input capture of chip `index`'s INT1 on `bus`
/// ([`EmuBus::int1_capture_us`]).
pub struct EmuCapture<'a, 'b, const N: usize> {
    /// The bus.
    pub bus: &'a core::cell::RefCell<EmuBus<'b, N>>,
    /// The chip.
    pub index: usize,
}

impl<const N: usize> gyro_array::drivers::SampleCapture for EmuCapture<'_, '_, N> {
    fn last_us(&mut self) -> Option<u32> {
        with_bus(self.bus, |b| b.int1_capture_us(self.index)).flatten()
    }
}

/// Run `f` on the bus behind its `RefCell`, if nothing else holds it
/// (the harness never nests borrows; `None` rather than a panic path if
/// it ever did).
pub fn with_bus<'a, const N: usize, R>(
    bus: &core::cell::RefCell<EmuBus<'a, N>>,
    f: impl FnOnce(&mut EmuBus<'a, N>) -> R,
) -> Option<R> {
    bus.try_borrow_mut().ok().map(|mut b| f(&mut b))
}

impl<const N: usize> ErrorType for EmuBus<'_, N> {
    type Error = BusError;
}

impl<const N: usize> SpiBus<u8> for EmuBus<'_, N> {
    fn read(&mut self, words: &mut [u8]) -> Result<(), BusError> {
        self.metered(|b| {
            for w in words.iter_mut() {
                *w = b.exchange(0)?;
            }
            Ok(())
        })
    }
    fn write(&mut self, words: &[u8]) -> Result<(), BusError> {
        self.metered(|b| {
            for w in words {
                b.exchange(*w)?;
            }
            Ok(())
        })
    }
    fn transfer(&mut self, read: &mut [u8], write: &[u8]) -> Result<(), BusError> {
        self.metered(|b| {
            for i in 0..read.len().max(write.len()) {
                let r = b.exchange(write.get(i).copied().unwrap_or(0))?;
                if let Some(slot) = read.get_mut(i) {
                    *slot = r;
                }
            }
            Ok(())
        })
    }
    fn transfer_in_place(&mut self, words: &mut [u8]) -> Result<(), BusError> {
        self.metered(|b| {
            for w in words.iter_mut() {
                *w = b.exchange(*w)?;
            }
            Ok(())
        })
    }
    fn flush(&mut self) -> Result<(), BusError> {
        Ok(())
    }
}

/// Flip one random bit of `b` with probability `prob` (MISO corruption).
pub(crate) fn corrupt(rng: &mut Rng, b: u8, fault: Fault) -> u8 {
    match fault {
        Fault::NoResponse | Fault::PoweredOff => 0xFF,
        Fault::BitErrors { prob } if rng.uniform() < prob => b ^ (1 << (rng.next_u32() % 8)),
        _ => b,
    }
}

/// A delay that advances emulated time: each elapsed sample period steps
/// every chip on the bus, so drivers that wait for data (self-tests) see it.
pub struct EmuDelay<'a, 'b, const N: usize> {
    bus: &'a core::cell::RefCell<EmuBus<'b, N>>,
    dt_s: f32,
    pending_ns: u64,
}

impl<'a, 'b, const N: usize> EmuDelay<'a, 'b, N> {
    /// Step the chips every `dt_s` seconds of requested delay.
    pub fn new(bus: &'a core::cell::RefCell<EmuBus<'b, N>>, dt_s: f32) -> Self {
        Self {
            bus,
            dt_s,
            pending_ns: 0,
        }
    }
}

impl<const N: usize> embedded_hal::delay::DelayNs for EmuDelay<'_, '_, N> {
    fn delay_ns(&mut self, ns: u32) {
        self.pending_ns += ns as u64;
        let step = (self.dt_s * 1e9) as u64;
        while step > 0 && self.pending_ns >= step {
            self.pending_ns -= step;
            with_bus(self.bus, |b| b.advance(self.dt_s));
        }
    }
}

/// The mountings of a board whose chips are not aligned with it, as real
/// boards are: chip 0 aligned, chip 1 turned 90° about z, chip 2 upside
/// down (180° about x), chip 3 turned 90° about y, the ADXRS453 on z; each
/// with its own scale (±1 %) and misalignment (±0.3°) errors and a bias
/// slope of 0.003–0.012 °/s/°C, at die temperature `temp`.
pub fn mounted_board(temp: TempProfile) -> [Mount; 5] {
    const R: [[[f32; 3]; 3]; 5] = [
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
        [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]],
        [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]],
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
    ];
    // Scale (diagonal) and misalignment (off-diagonal, radians) per chip.
    const E: [[[f32; 3]; 3]; 5] = [
        [
            [0.008, 0.004, -0.003],
            [-0.002, -0.006, 0.005],
            [0.001, 0.003, 0.01],
        ],
        [
            [-0.009, -0.005, 0.002],
            [0.004, 0.007, -0.001],
            [-0.003, 0.002, -0.004],
        ],
        [
            [0.005, 0.001, 0.004],
            [0.003, -0.01, -0.002],
            [-0.005, 0.004, 0.006],
        ],
        [
            [-0.004, 0.002, 0.005],
            [-0.001, 0.009, 0.003],
            [0.002, -0.005, -0.007],
        ],
        [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.004, -0.003, 0.012]],
    ];
    const TC: [[f32; 3]; 5] = [
        [0.006, -0.004, 0.008],
        [-0.005, 0.007, 0.003],
        [0.01, 0.004, -0.006],
        [-0.003, -0.008, 0.005],
        [0.0, 0.0, 0.012],
    ];
    core::array::from_fn(|k| {
        let mut m = [[0.0f32; 3]; 3];
        // chip = (I + E) · R · board
        for i in 0..3 {
            for j in 0..3 {
                let mut v = 0.0;
                for l in 0..3 {
                    let e = if i == l { 1.0 + E[k][i][l] } else { E[k][i][l] };
                    v += e * R[k][l][j];
                }
                m[i][j] = v;
            }
        }
        Mount {
            m,
            bias_tc_dps_per_c: TC[k],
            temp,
        }
    })
}

/// The constant biases of [`timed_array`]'s chips, °/s.
pub const TIMED_ARRAY_BIAS_DPS: [f32; 4] = [0.02, -0.015, 0.01, -0.005];

/// The timed board's array: four ICM-42688-P keeping their own time as
/// `timing` says, each with its own noise seed and a small bias (no scale
/// error: the timing figures compare it with the same chips in lockstep).
pub fn timed_array(profile: RateProfile, seed: u64, timing: [ChipTiming; 4]) -> [Chip; 4] {
    core::array::from_fn(|i| {
        let p = NoiseParams {
            bias_dps: TIMED_ARRAY_BIAS_DPS[i],
            ..NoiseParams::ICM42688
        };
        let mut c =
            Icm42688Model::new(p, profile, seed.wrapping_mul(31).wrapping_add(i as u64), 70);
        c.set_timing(Some(timing[i]));
        Chip::Icm(c)
    })
}

/// The board's array: four ICM-42688-P (chips 0..=3, all axes) and one
/// ADXRS453 on the z axis (chip 4), each with its own noise seed and
/// a small per-chip bias and scale error.
pub fn board_array(profile: RateProfile, seed: u64) -> [Chip; 5] {
    let icm = |k: u64, bias: f32, scale: f32| {
        let p = NoiseParams {
            bias_dps: bias,
            scale_error: scale,
            ..NoiseParams::ICM42688
        };
        Chip::Icm(Icm42688Model::new(
            p,
            profile,
            seed.wrapping_mul(31).wrapping_add(k),
            70 + k as u8,
        ))
    };
    let adx = NoiseParams {
        bias_dps: 0.01,
        scale_error: -0.001,
        ..NoiseParams::ADXRS453
    };
    [
        icm(0, 0.02, 0.002),
        icm(1, -0.015, -0.001),
        icm(2, 0.01, 0.0015),
        icm(3, -0.005, -0.002),
        Chip::Adx(Adxrs453Model::new(
            adx,
            profile,
            seed.wrapping_mul(31).wrapping_add(4),
            2,
        )),
    ]
}
