//! The messages of the output link (protocol version [`super::VERSION`]).
//!
//! Board → host: [`Frame`]; host → board: [`Command`]. Both travel in an
//! envelope (`super::wire`) with the link sequence number. Field order is
//! the wire order (postcard: integers marked `fixint` are little-endian of
//! their width, other integers are LEB128 varints, `f32` is IEEE-754
//! little-endian, `Option` is a 0/1 byte then the value, enums a varint
//! variant index, `heapless::Vec` a varint length then the items).
//! `docs/link.md` is the specification with byte offsets.

use heapless::Vec;
use serde::{Deserialize, Serialize};

/// Most gyros a frame describes.
pub const MAX_GYROS: usize = 8;

/// A frame from the board.
// The status variant (8 gyros' counters and calibration, ~470 B) is the
// large one. There is no heap to box it in; a frame lives on the stack
// only while it is encoded, and status frames are built in idle time.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Frame {
    /// One fused sample (mode [`Mode::Fused`]).
    Sample(Sample),
    /// Every gyro's reading of one sample (mode [`Mode::Raw`]).
    Raw(Raw),
    /// Counters and settings (every `status_every` samples and on request).
    Status(Status),
    /// The answer to a command.
    Ack(Ack),
    /// The controller's clock as the board tracks it (after each sync
    /// time message, and when the pulse is lost).
    Sync(SyncStatus),
    /// The board and its chips: on request, and once every
    /// `status_every` samples half way between status frames.
    Info(Info),
}

/// A borrowed [`Frame`]: the same variants in the same order, so it
/// encodes to the same bytes (`frame_ref_encodes_as_the_frame`), without
/// moving a sample into the ~470-byte enum first (250 instructions a frame
/// on the Cortex-M4, `cargo xtask bench`).
#[derive(Clone, Copy, Debug, Serialize)]
pub enum FrameRef<'a> {
    /// [`Frame::Sample`].
    Sample(&'a Sample),
    /// [`Frame::Raw`].
    Raw(&'a Raw),
    /// [`Frame::Status`].
    Status(&'a Status),
    /// [`Frame::Ack`].
    Ack(&'a Ack),
    /// [`Frame::Sync`].
    Sync(&'a SyncStatus),
    /// [`Frame::Info`].
    Info(&'a Info),
}

impl Frame {
    /// The frame, borrowed.
    pub fn as_ref(&self) -> FrameRef<'_> {
        match self {
            Frame::Sample(s) => FrameRef::Sample(s),
            Frame::Raw(r) => FrameRef::Raw(r),
            Frame::Status(s) => FrameRef::Status(s),
            Frame::Ack(a) => FrameRef::Ack(a),
            Frame::Sync(s) => FrameRef::Sync(s),
            Frame::Info(i) => FrameRef::Info(i),
        }
    }
}

/// One fused sample.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Sample {
    /// Sample sequence number (counts every sample period, missed ones too).
    #[serde(with = "postcard::fixint::le")]
    pub seq: u32,
    /// Time of the sample (when it was read and queued), µs since boot.
    #[serde(with = "postcard::fixint::le")]
    pub t_us: u64,
    /// Per axis, how long before `t_us` the fused rate was the true rate,
    /// µs: the instant it describes is `t_us − age_us[a]` (the chips'
    /// filters and the array's alignment included; 0 where not valid).
    pub age_us: [u16; 3],
    /// Delay compensation ([`Compensation`]): `Some(d)`, the rates are
    /// predicted to `t_us + d` from the recent samples (the instant the
    /// measurement described is still `t_us − age_us`); `None`, they are the
    /// measured rates.
    pub predicted_us: Option<u16>,
    /// Fused rate x, y, z, °/s; NaN where the axis is not valid.
    pub rate_dps: [f32; 3],
    /// Bit a set: axis a has a fused value.
    pub valid: u8,
    /// Bit a set: axis a fell back to the plain mean (degraded). Bit
    /// 3 + a set: axis a's chips share an error (a common vibration, two
    /// chips on one arm of a flexing frame), which the noise figures sent
    /// for it, measured on the array's noise probe, cannot see: they give
    /// the part of the fused error the chips do not share. Bit 7 set: the
    /// board runs without a static calibration record.
    pub degraded: u8,
    /// Per axis, the gyros in the fused value (bit i = gyro i).
    pub used: [u8; 3],
    /// Per gyro, the pipeline's health flags (`pipeline::flag`).
    pub health: Vec<u8, MAX_GYROS>,
    /// The newest E-DAVAR estimate of one axis (the axes take turns; only
    /// new estimates are sent, never before a window has filled).
    pub noise: Option<Noise>,
    /// With [`Settings::angle`]: the integrated angles.
    pub angle: Option<Angle>,
}

/// Per axis, the fused rate integrated since the angle was turned on, up to
/// the instant its measurement describes, in 2⁻³² turn, wrapping. The angle between two
/// frames is the wrapping difference read as an `i32` (× 360 / 2³² °),
/// whatever frames were skipped by the divider or lost on the way, up to
/// half a turn. It does not advance while the axis has no value (`valid`
/// clear). Fixed-width on the wire: the values are spread over the whole
/// range, where varints would take five bytes each.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Angle {
    /// x.
    #[serde(with = "postcard::fixint::le")]
    pub x: u32,
    /// y.
    #[serde(with = "postcard::fixint::le")]
    pub y: u32,
    /// z.
    #[serde(with = "postcard::fixint::le")]
    pub z: u32,
}

impl Angle {
    /// x, y, z.
    pub fn turns32(self) -> [u32; 3] {
        [self.x, self.y, self.z]
    }
}

/// The controller's clock against the board's (`link::sync`): a line
/// through the last pulses. Any board instant `t` (a sample's `t_us −
/// age_us`, say) is, in the controller's clock, `ctrl_us + (t − board_us) ×
/// (1 + ppm × 10⁻⁶)`, while `state` is `Locked`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SyncStatus {
    /// The tracker's state.
    pub state: SyncState,
    /// The newest pulse's capture, board µs (0 before two pairs).
    #[serde(with = "postcard::fixint::le")]
    pub board_us: u64,
    /// The controller's time there, by the line, µs.
    #[serde(with = "postcard::fixint::le")]
    pub ctrl_us: u64,
    /// The controller's clock against the board's, ppm (positive: fast).
    pub ppm: f32,
    /// RMS distance of the pulses' times from the line, µs: the
    /// controller's timestamp jitter and what the line cannot follow.
    pub residual_us: f32,
    /// Time messages dropped as not their pulse's (far from the line),
    /// and messages with no pulse captured before them.
    pub dropped: u32,
    /// The latter.
    pub unpaired: u32,
}

pub use super::sync::SyncState;

/// Which board, which firmware, which chips. A frame of its own, not a
/// part of the status frame: with an acknowledgement and a sample frame
/// the status frame fills all 600 bytes a millisecond carries at
/// 6 Mbaud (`link::tests`), and none of this changes from one second to
/// the next but the temperatures.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Info {
    /// The MCU's 96-bit unique ID (RM0090 39.1; zeros where there is none,
    /// as on QEMU's boards).
    pub uid: [u8; 12],
    /// Firmware version: major, minor, patch.
    pub firmware: [u8; 3],
    /// The commit it was built from: its first 32 bits (0: unknown).
    #[serde(with = "postcard::fixint::le")]
    pub build: u32,
    /// Per gyro, in the pipeline's order.
    pub chips: Vec<ChipInfo, MAX_GYROS>,
}

/// One gyro in [`Info`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ChipInfo {
    /// The part.
    pub part: Part,
    /// Its identity register as read at start-up (ICM-42688-P WHO_AM_I,
    /// 0x47; ADXRS453 PID, 0x52xx; 0 where not read).
    pub id: u16,
    /// How its start-up went.
    pub start: Start,
    /// Its die temperature, 0.01 °C (`None` where not read: only while a
    /// static calibration is in use, or a part without a sensor).
    pub temp_cc: Option<i16>,
}

/// A gyro part.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Part {
    /// Not identified.
    #[default]
    Unknown,
    /// TDK InvenSense ICM-42688-P.
    Icm42688P,
    /// Analog Devices ADXRS453.
    Adxrs453,
}

/// How a gyro's start-up went.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Start {
    /// Not started through the board's start-up (a host replay).
    #[default]
    Unknown,
    /// Identified, configured, and its self-test passed (where it has one).
    Passed,
    /// It did not answer, or not as its part.
    InitFailed,
    /// Its self-test (the array's actuation test) failed.
    SelfTestFailed,
}

/// One E-DAVAR estimate with the time it describes.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Noise {
    /// Axis (0 = x).
    pub axis: u8,
    /// Sequence number of the sample the estimate describes (it lags the
    /// frame's own `seq` by about half a window).
    #[serde(with = "postcard::fixint::le")]
    pub seq: u32,
    /// Window length, samples.
    pub len: u16,
    /// Samples of the window that were missing and bridged by holding the
    /// one before (fusion had no noise probe: no majority vouched for any
    /// chip). Each reads σ²(τ0) about 1/len low.
    pub bridged: u8,
    /// Allan deviation of the fused rate's noise (measured on the array's
    /// noise probe, free of the platform's motion) at the three τ of
    /// [`Status::noise_tau`], °/s.
    pub sigma_dps: [f32; 3],
}

/// Every gyro's reading of one sample.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Raw {
    /// Sample sequence number.
    #[serde(with = "postcard::fixint::le")]
    pub seq: u32,
    /// Time of the sample, µs since boot.
    #[serde(with = "postcard::fixint::le")]
    pub t_us: u64,
    /// Per gyro, how long before `t_us` its rate was the true rate, µs.
    pub age_us: Vec<u16, MAX_GYROS>,
    /// Per gyro, x, y, z in °/s (NaN where not read or absent).
    pub rate_dps: Vec<[f32; 3], MAX_GYROS>,
    /// Per gyro, health flags.
    pub health: Vec<u8, MAX_GYROS>,
}

/// Counters of one gyro.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct GyroStatus {
    /// Health flags.
    pub flags: u8,
    /// Good reads.
    pub reads: u32,
    /// Failed reads.
    pub errors: u32,
    /// Samples out of fusion.
    pub excluded: u32,
    /// Restarts begun.
    pub restarts: u32,
    /// Restarts completed.
    pub restarted: u32,
    /// Online relative calibration per board axis: the chip's scale against
    /// the array's median chip, (s − 1) in parts per million (0: not
    /// estimated, or the chip is not on that axis).
    pub scale_ppm: [i32; 3],
    /// Online relative calibration per board axis: the chip's bias against
    /// the median chip, m°/s.
    pub bias_mdps: [i16; 3],
    /// Where the chip's samples take their time from.
    pub clock: ClockSource,
    /// The chip's clock against the board's, ppm (positive: fast; 0 where
    /// not tracked).
    pub clock_ppm: i32,
    /// Samples in which the chip had nothing yet for the stated instant.
    pub late: u32,
    /// What its FIFO reads met (0 for a polled chip).
    pub fifo: FifoAnomalies,
}

/// What a timed chip's FIFO reads met, counted since boot
/// (`pipeline::timed::TimingCounters`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FifoAnomalies {
    /// Overflows: FIFO_FULL, the FIFO flushed and its samples lost.
    pub overflows: u32,
    /// Reads that found the stream out of step (a bad header, a count the
    /// FIFO did not hold, a garbled status): flushed, a gap.
    pub bad: u32,
    /// Bursts cut inside a packet (chip select lost), the packet read
    /// again whole: nothing lost.
    pub cuts: u32,
    /// Packets the chip sent again after handing them over past a burst's
    /// count, dropped: nothing counted twice.
    pub resent: u32,
}

/// Where a chip's samples take their time from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ClockSource {
    /// Its data registers are polled: the newest sample, its delay the
    /// driver's figure.
    #[default]
    Polled,
    /// Its FIFO, on its own oscillator, tracked against the board's clock.
    Own,
    /// Its FIFO, on the board's CLKIN.
    ClkIn,
}

/// Counters and settings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Status {
    /// Sequence number of the newest sample.
    pub seq: u32,
    /// Time, µs since boot.
    pub t_us: u64,
    /// Output settings in force.
    pub settings: Settings,
    /// τ of the three σ in [`Noise`], samples.
    pub noise_tau: [u16; 3],
    /// Sample period, µs.
    pub sample_us: u32,
    /// Sample periods missed (overruns).
    pub overruns: u32,
    /// Link counters.
    pub link: LinkCounters,
    /// Peak stack use, bytes (0 where not measured).
    pub stack_peak: u32,
    /// What the settings store holds.
    pub store: StoreState,
    /// Per gyro counters.
    pub gyros: Vec<GyroStatus, MAX_GYROS>,
}

/// What the link itself counted.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct LinkCounters {
    /// Frames queued for sending.
    pub sent: u32,
    /// Frames dropped because the transmit queue was full (each one is a
    /// gap in the link sequence number).
    pub dropped: u32,
    /// Commands accepted.
    pub accepted: u32,
    /// Commands rejected (including received frames that did not decode).
    pub rejected: u32,
}

/// What the board streams.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Mode {
    /// [`Sample`] frames.
    Fused,
    /// [`Raw`] frames, for characterising the chips.
    Raw,
}

/// The fusion method a command may select.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FusionMethod {
    /// Plain mean.
    Mean,
    /// Support-degree weighting (Zhang).
    Zhang,
    /// Inverse-variance weighting with online noise estimates (default).
    Adaptive,
}

/// Output settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Settings {
    /// Stream mode.
    pub mode: Mode,
    /// Fusion method.
    pub method: FusionMethod,
    /// One sample or raw frame every `divider` samples (1 ..= 1000).
    pub divider: u16,
    /// One status frame every `status_every` samples (0 = on request only).
    pub status_every: u32,
    /// Delay compensation of the sample frames.
    pub compensation: Compensation,
    /// Whether sample frames carry [`Sample::angle`].
    pub angle: bool,
    /// How much longer the ICM-42688-P's signal path is than its datasheet
    /// reading, µs (± [`MAX_PATH_TRIM_US`]; new in version 8): measured on
    /// a rate table (`gyro lag`, docs/timing.md), since the datasheet
    /// gives the filters' bandwidths and not their shapes. The chips' rates
    /// are then taken from that much later in their streams, and the
    /// stated instant's distance behind the read grows by it.
    pub path_trim_us: i16,
}

/// What the sample frames' rates are predicted to ([`Sample::predicted_us`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Compensation {
    /// The measured rates.
    Off,
    /// The instant the frame's last byte leaves the board (its time on the
    /// wire after `t_us`): what leaves the reference pointing loop the
    /// least error (`pointing-eval`); the default.
    ToFrame,
    /// A horizon the controller sets, µs after `t_us` (at most
    /// [`MAX_HORIZON_US`]).
    Horizon(u16),
}

impl Status {
    /// The status frame of `n` gyros (at most [`MAX_GYROS`]) with every
    /// field at its widest encoding (every counter at its largest, as after
    /// months): the longest a board of `n` gyros sends, what the link's
    /// budget and its wire time allow for.
    pub fn widest(n: usize) -> Self {
        let gyro = GyroStatus {
            flags: 0xFF,
            reads: u32::MAX,
            errors: u32::MAX,
            excluded: u32::MAX,
            restarts: u32::MAX,
            restarted: u32::MAX,
            scale_ppm: [i32::MIN; 3],
            bias_mdps: [i16::MIN; 3],
            clock: ClockSource::ClkIn,
            clock_ppm: i32::MIN,
            late: u32::MAX,
            fifo: FifoAnomalies {
                overflows: u32::MAX,
                bad: u32::MAX,
                cuts: u32::MAX,
                resent: u32::MAX,
            },
        };
        let mut gyros = Vec::new();
        for _ in 0..n.min(MAX_GYROS) {
            let _ = gyros.push(gyro);
        }
        Self {
            seq: u32::MAX,
            t_us: u64::MAX,
            settings: Settings {
                mode: Mode::Raw,
                method: FusionMethod::Adaptive,
                divider: 1000,
                status_every: u32::MAX,
                compensation: Compensation::Horizon(u16::MAX),
                angle: true,
                path_trim_us: -MAX_PATH_TRIM_US,
            },
            noise_tau: [u16::MAX; 3],
            sample_us: u32::MAX,
            overruns: u32::MAX,
            link: LinkCounters {
                sent: u32::MAX,
                dropped: u32::MAX,
                accepted: u32::MAX,
                rejected: u32::MAX,
            },
            stack_peak: u32::MAX,
            store: StoreState::Corrupt,
            gyros,
        }
    }
}

impl Settings {
    /// Whether every value is inside the range a command may set (a
    /// stored record is checked the same way before it is used).
    pub fn check(&self) -> Result<(), Reject> {
        let status_ok = self.status_every == 0 || (100..=60_000).contains(&self.status_every);
        let horizon_ok = match self.compensation {
            Compensation::Horizon(h) => h <= MAX_HORIZON_US,
            _ => true,
        };
        let trim_ok = self.path_trim_us.unsigned_abs() <= MAX_PATH_TRIM_US.unsigned_abs();
        if (1..=1000).contains(&self.divider) && status_ok && horizon_ok && trim_ok {
            Ok(())
        } else {
            Err(Reject::OutOfRange)
        }
    }
}

/// What the board's settings store holds (`src/store.rs`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StoreState {
    /// This build keeps no settings (a host replay, the QEMU demo).
    #[default]
    Absent,
    /// Nothing saved (or cleared by a factory reset): the defaults came up
    /// at boot.
    Defaults,
    /// A record read back and checked, at boot or after a save.
    Stored,
    /// The record found at boot did not read back or check: the defaults
    /// are in force until the next save.
    Corrupt,
}

/// The longest horizon [`Compensation::Horizon`] takes, µs: a line fitted
/// to a few milliseconds says little about the rate further out.
pub const MAX_HORIZON_US: u16 = 10_000;

/// The largest [`Settings::path_trim_us`] either way, µs: twice the spread
/// the datasheet's silence allows (a critically damped anti-alias filter
/// −52 µs, a UI filter with the 0.8 ms delay a flight stack quotes +354 µs:
/// docs/timing.md), within the 8 ms of samples each chip keeps.
pub const MAX_PATH_TRIM_US: i16 = 800;

impl Default for Settings {
    fn default() -> Self {
        Self {
            mode: Mode::Fused,
            method: FusionMethod::Adaptive,
            divider: 1,
            status_every: 1000,
            compensation: Compensation::ToFrame,
            angle: false,
            path_trim_us: 0,
        }
    }
}

/// The answer to a command.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Ack {
    /// The command's id; `None` when the frame was too damaged to read it.
    pub id: Option<u8>,
    /// Done, or why not (nothing changed then).
    pub result: Result<(), Reject>,
}

/// Why a command was rejected. A rejected command changes nothing.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Reject {
    /// COBS or CRC failed: the frame was damaged.
    Corrupt,
    /// Longer than any command.
    TooLong,
    /// Another protocol version.
    Version,
    /// The bytes do not decode as a command.
    Malformed,
    /// A value outside its range (the divider).
    OutOfRange,
    /// The firmware refused the change (the fusion configuration; a save
    /// while one is under way or on a build without a store).
    Refused,
    /// The settings store failed to write or to read back what it wrote
    /// (the settings in force are unchanged by it).
    Storage,
}

/// A command to the board.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Command {
    /// Chosen by the host; echoed in the [`Ack`].
    pub id: u8,
    /// What to do.
    pub op: Op,
}

/// The operations.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Op {
    /// Select the stream mode.
    SetMode(Mode),
    /// Select the fusion method (its noise model starts again).
    SetMethod(FusionMethod),
    /// Output every `n`-th sample, n in 1 ..= 1000.
    SetDivider(u16),
    /// Status every `n` samples (0 = on request only; else 100 ..= 60 000).
    SetStatusEvery(u32),
    /// Send a status frame now.
    RequestStatus,
    /// Select the delay compensation of the sample frames.
    SetCompensation(Compensation),
    /// Save the settings in force (and the calibration record in use) to
    /// flash; they come up at the next boot. The acknowledgement comes
    /// once the record is written and read back.
    SaveSettings,
    /// The default settings now, and the saved ones erased: the next
    /// boot comes up with the defaults and the lab's calibration record.
    FactoryReset,
    /// Whether sample frames carry the integrated angle ([`Sample::angle`]).
    SetAngle(bool),
    /// The controller's own time, µs, at its last sync pulse (the board's
    /// sync input): answered by an [`Ack`] and a [`Frame::Sync`].
    SyncTime(u64),
    /// Send a [`Frame::Info`] now.
    RequestInfo,
    /// Set [`Settings::path_trim_us`] (new in version 8).
    SetPathTrim(i16),
}
