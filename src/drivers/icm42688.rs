//! TDK InvenSense ICM-42688-P 6-axis IMU, gyro part, over SPI (mode 0 or 3).
//!
//! Register map and bit fields from the ICM-42688-P datasheet (DS-000347
//! rev 1.8), section 14 "Register map" (user bank 0 and bank 1). SPI reads set
//! bit 7 of the address byte; multi-byte reads auto-increment.

use embedded_hal::delay::DelayNs;
use embedded_hal::spi::{Operation, SpiDevice};

use super::{Gyro, ReadFault, Reading, Restart};

/// Register addresses (datasheet names). Bank 0 unless noted.
#[allow(missing_docs)]
pub mod reg {
    pub const DEVICE_CONFIG: u8 = 0x11;
    pub const INT_CONFIG: u8 = 0x14;
    pub const FIFO_CONFIG: u8 = 0x16;
    pub const TEMP_DATA1: u8 = 0x1D;
    pub const GYRO_DATA_X1: u8 = 0x25;
    pub const INT_STATUS: u8 = 0x2D;
    pub const FIFO_COUNTH: u8 = 0x2E;
    pub const FIFO_COUNTL: u8 = 0x2F;
    pub const FIFO_DATA: u8 = 0x30;
    pub const SIGNAL_PATH_RESET: u8 = 0x4B;
    pub const INTF_CONFIG0: u8 = 0x4C;
    pub const INTF_CONFIG1: u8 = 0x4D;
    pub const PWR_MGMT0: u8 = 0x4E;
    pub const GYRO_CONFIG0: u8 = 0x4F;
    pub const GYRO_CONFIG1: u8 = 0x51;
    pub const GYRO_ACCEL_CONFIG0: u8 = 0x52;
    pub const TMST_CONFIG: u8 = 0x54;
    pub const FIFO_CONFIG1: u8 = 0x5F;
    pub const FIFO_CONFIG2: u8 = 0x60;
    pub const FIFO_CONFIG3: u8 = 0x61;
    pub const INT_CONFIG1: u8 = 0x64;
    pub const INT_SOURCE0: u8 = 0x65;
    pub const SELF_TEST_CONFIG: u8 = 0x70;
    pub const WHO_AM_I: u8 = 0x75;
    pub const REG_BANK_SEL: u8 = 0x76;
    /// Bank 1: GYRO_AAF_DIS (bit 1), GYRO_NF_DIS (bit 0).
    pub const GYRO_CONFIG_STATIC2: u8 = 0x0B;
    /// Bank 1: GYRO_AAF_DELT (bits 5:0).
    pub const GYRO_CONFIG_STATIC3: u8 = 0x0C;
    /// Bank 1: GYRO_AAF_DELTSQR\[7:0\].
    pub const GYRO_CONFIG_STATIC4: u8 = 0x0D;
    /// Bank 1: GYRO_AAF_BITSHIFT (7:4), GYRO_AAF_DELTSQR\[11:8\] (3:0).
    pub const GYRO_CONFIG_STATIC5: u8 = 0x0E;
    /// Bank 1: factory self-test codes for the gyro axes.
    pub const XG_ST_DATA: u8 = 0x5F;
    pub const YG_ST_DATA: u8 = 0x60;
    pub const ZG_ST_DATA: u8 = 0x61;
    /// Bank 1: PIN9_FUNCTION (bits 2:1; 0b10 = CLKIN).
    pub const INTF_CONFIG5: u8 = 0x7B;
}

/// Register bit fields (datasheet section 14), bank 0 unless noted.
#[allow(missing_docs)]
pub mod bits {
    /// INT_STATUS.
    pub const DATA_RDY: u8 = 1 << 3;
    pub const FIFO_THS: u8 = 1 << 2;
    pub const FIFO_FULL: u8 = 1 << 1;
    /// FIFO_CONFIG.FIFO_MODE (bits 7:6).
    pub const FIFO_MODE_MASK: u8 = 0b11 << 6;
    pub const FIFO_MODE_STREAM: u8 = 0b01 << 6;
    pub const FIFO_MODE_STOP_ON_FULL: u8 = 0b10 << 6;
    /// FIFO_CONFIG1.
    pub const FIFO_RESUME_PARTIAL_RD: u8 = 1 << 6;
    pub const FIFO_WM_GT_TH: u8 = 1 << 5;
    pub const FIFO_HIRES_EN: u8 = 1 << 4;
    pub const FIFO_TMST_FSYNC_EN: u8 = 1 << 3;
    pub const FIFO_TEMP_EN: u8 = 1 << 2;
    pub const FIFO_GYRO_EN: u8 = 1 << 1;
    pub const FIFO_ACCEL_EN: u8 = 1 << 0;
    /// SIGNAL_PATH_RESET.
    pub const FIFO_FLUSH: u8 = 1 << 1;
    /// INTF_CONFIG0.
    pub const FIFO_COUNT_REC: u8 = 1 << 6;
    pub const FIFO_COUNT_ENDIAN: u8 = 1 << 5;
    pub const SENSOR_DATA_ENDIAN: u8 = 1 << 4;
    /// INTF_CONFIG1: AFSR (bits 7:6, undocumented; 0b01 turns it off, as
    /// PX4, ArduPilot and Betaflight write), RTC_MODE, CLKSEL (bits 1:0).
    pub const AFSR_MASK: u8 = 0b11 << 6;
    pub const AFSR_OFF: u8 = 0b01 << 6;
    pub const RTC_MODE: u8 = 1 << 2;
    pub const CLKSEL_MASK: u8 = 0b11;
    pub const CLKSEL_PLL: u8 = 0b01;
    /// TMST_CONFIG.
    pub const TMST_TO_REGS_EN: u8 = 1 << 4;
    pub const TMST_RES: u8 = 1 << 3;
    pub const TMST_DELTA_EN: u8 = 1 << 2;
    pub const TMST_EN: u8 = 1 << 0;
    /// INT_CONFIG: INT1 push-pull (bit 1), active high (bit 0), pulsed
    /// (bit 2 clear).
    pub const INT1_PUSH_PULL_HIGH: u8 = 0b011;
    /// INT_CONFIG1.INT_ASYNC_RESET (bit 4): must be cleared for the INT
    /// pins to work (datasheet 14.x; PX4 clears it).
    pub const INT_ASYNC_RESET: u8 = 1 << 4;
    /// INT_SOURCE0.UI_DRDY_INT1_EN: data ready on INT1.
    pub const UI_DRDY_INT1_EN: u8 = 1 << 3;
    /// Bank 1 GYRO_CONFIG_STATIC2.
    pub const GYRO_AAF_DIS: u8 = 1 << 1;
    /// Bank 1 INTF_CONFIG5.PIN9_FUNCTION (bits 2:1).
    pub const PIN9_MASK: u8 = 0b11 << 1;
    pub const PIN9_CLKIN: u8 = 0b10 << 1;
    /// FIFO header (datasheet 6.2).
    pub const HEADER_MSG: u8 = 1 << 7;
    pub const HEADER_ACCEL: u8 = 1 << 6;
    pub const HEADER_GYRO: u8 = 1 << 5;
    pub const HEADER_20: u8 = 1 << 4;
    pub const HEADER_TIMESTAMP_ODR: u8 = 0b10 << 2;
    pub const HEADER_ODR_ACCEL: u8 = 1 << 1;
    pub const HEADER_ODR_GYRO: u8 = 1 << 0;
}

/// Reset values the driver and the emulated chip agree on (datasheet
/// section 14).
#[allow(missing_docs)]
pub mod reset {
    pub const INTF_CONFIG0: u8 = 0x30;
    pub const INTF_CONFIG1: u8 = 0x91;
    pub const GYRO_CONFIG1: u8 = 0x16;
    pub const GYRO_ACCEL_CONFIG0: u8 = 0x11;
    pub const TMST_CONFIG: u8 = 0x23;
    pub const INT_CONFIG1: u8 = 0x10;
    pub const INT_SOURCE0: u8 = 0x10;
}

/// WHO_AM_I value of the ICM-42688-P.
pub const WHO_AM_I_VALUE: u8 = 0x47;
/// DEVICE_CONFIG.SOFT_RESET_CONFIG.
const SOFT_RESET: u8 = 0x01;
/// PWR_MGMT0.GYRO_MODE = 0b11, low-noise mode (bits 3:2); accel off.
const GYRO_MODE_LN: u8 = 0b11 << 2;
/// SELF_TEST_CONFIG: EN_GX | EN_GY | EN_GZ.
const EN_G_ALL: u8 = 0b111;
/// Address bit 7 marks a read.
const READ: u8 = 0x80;
/// INT_STATUS.RESET_DONE_INT (bit 4): set when the chip comes out of a
/// reset, cleared when INT_STATUS is read.
pub const RESET_DONE: u8 = 1 << 4;

/// TEMP_DATA counts per °C (datasheet 14.6, 16-bit temperature).
pub const TEMP_LSB_PER_C: f32 = 132.48;

/// Die temperature, °C, of TEMP_DATA counts.
pub fn temperature_c(counts: i16) -> f32 {
    counts as f32 / TEMP_LSB_PER_C + 25.0
}

/// Gyro full-scale range, GYRO_CONFIG0.GYRO_FS_SEL (bits 7:5).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[allow(missing_docs)]
pub enum FullScale {
    Dps2000 = 0,
    Dps1000 = 1,
    Dps500 = 2,
    Dps250 = 3,
    Dps125 = 4,
    Dps62_5 = 5,
    Dps31_25 = 6,
    Dps15_625 = 7,
}

impl FullScale {
    /// Sensitivity in LSB per °/s (datasheet table 1). (From a `const`
    /// table: an array literal indexed in place was built on the stack on
    /// every read, 86 instructions per sample for the board's four chips
    /// in `cargo xtask bench-loop`.)
    pub fn lsb_per_dps(self) -> f32 {
        const LSB_PER_DPS: [f32; 8] = [16.4, 32.8, 65.5, 131.0, 262.0, 524.3, 1048.6, 2097.2];
        LSB_PER_DPS[self as usize]
    }
    /// Range in °/s.
    pub fn range_dps(self) -> f32 {
        2000.0 / (1u32 << self as u32) as f32
    }
    /// Decode GYRO_FS_SEL (3 bits).
    pub fn from_bits(b: u8) -> Self {
        match b & 7 {
            0 => Self::Dps2000,
            1 => Self::Dps1000,
            2 => Self::Dps500,
            3 => Self::Dps250,
            4 => Self::Dps125,
            5 => Self::Dps62_5,
            6 => Self::Dps31_25,
            _ => Self::Dps15_625,
        }
    }
}

/// Gyro output data rate, GYRO_CONFIG0.GYRO_ODR (bits 3:0).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[allow(missing_docs)]
pub enum Odr {
    Hz8000 = 0x3,
    Hz4000 = 0x4,
    Hz2000 = 0x5,
    Hz1000 = 0x6,
    Hz200 = 0x7,
    Hz100 = 0x8,
    Hz50 = 0x9,
    Hz25 = 0xA,
    Hz500 = 0xF,
}

impl Odr {
    /// Decode GYRO_ODR (bits 3:0); `None` for the rates this driver does
    /// not use (32 and 16 kHz, and below 25 Hz).
    pub fn from_bits(b: u8) -> Option<Self> {
        Some(match b & 0x0F {
            0x3 => Self::Hz8000,
            0x4 => Self::Hz4000,
            0x5 => Self::Hz2000,
            0x6 => Self::Hz1000,
            0x7 => Self::Hz200,
            0x8 => Self::Hz100,
            0x9 => Self::Hz50,
            0xA => Self::Hz25,
            0xF => Self::Hz500,
            _ => return None,
        })
    }

    /// Rate in Hz.
    pub fn hz(self) -> f32 {
        match self {
            Self::Hz8000 => 8000.0,
            Self::Hz4000 => 4000.0,
            Self::Hz2000 => 2000.0,
            Self::Hz1000 => 1000.0,
            Self::Hz200 => 200.0,
            Self::Hz100 => 100.0,
            Self::Hz50 => 50.0,
            Self::Hz25 => 25.0,
            Self::Hz500 => 500.0,
        }
    }

    /// Samples per millisecond, the board's output period (at least 1):
    /// the samples each output's moving mean spans.
    pub fn per_ms(self) -> usize {
        (libm::roundf(self.hz() / 1000.0) as usize).max(1)
    }
}

/// Driver errors, generic over the SPI error.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Error<E> {
    /// SPI transfer failed.
    Spi(E),
    /// WHO_AM_I did not read 0x47.
    WrongId(u8),
    /// A configuration register did not read back what was written.
    ConfigMismatch {
        /// Register address.
        reg: u8,
        /// Value written.
        wrote: u8,
        /// Value read back.
        read: u8,
    },
    /// The self-test response was below half the factory value on these axes
    /// (bit 0 = x).
    SelfTestFailed(u8),
    /// The self-test needs at least one sample per phase, or an AAF
    /// setting the driver does not know.
    InvalidArgument,
    /// FIFO_FULL was set: samples were lost. The FIFO has been flushed.
    FifoOverflow,
    /// INT_STATUS said FIFO_FULL beside a count no full FIFO has (a
    /// garbled status byte, this one). The FIFO is left as it is: its
    /// packets are read next time.
    FifoBadStatus(u8),
    /// A FIFO packet's header is not a gyro packet's (`0x68` in its top six
    /// bits): the stream is out of step. The FIFO has been flushed.
    FifoBadHeader(u8),
    /// The count promised a packet the FIFO did not hold (its header read
    /// "empty"). The FIFO has been flushed.
    FifoShort,
    /// FIFO sampling is not configured.
    NotFifo,
    /// INT_STATUS.RESET_DONE: the chip reset since it was configured; it
    /// must be restarted.
    ChipReset,
}

impl<E> Error<E> {
    /// Convert the bus error (e.g. from a `DeviceError` to its bus part).
    pub fn map_spi<F>(self, f: impl FnOnce(E) -> F) -> Error<F> {
        match self {
            Error::Spi(e) => Error::Spi(f(e)),
            Error::WrongId(v) => Error::WrongId(v),
            Error::ConfigMismatch { reg, wrote, read } => {
                Error::ConfigMismatch { reg, wrote, read }
            }
            Error::SelfTestFailed(a) => Error::SelfTestFailed(a),
            Error::InvalidArgument => Error::InvalidArgument,
            Error::FifoOverflow => Error::FifoOverflow,
            Error::FifoBadStatus(s) => Error::FifoBadStatus(s),
            Error::FifoBadHeader(h) => Error::FifoBadHeader(h),
            Error::FifoShort => Error::FifoShort,
            Error::NotFifo => Error::NotFifo,
            Error::ChipReset => Error::ChipReset,
        }
    }
}

/// The gyro's signal path (datasheet section 5): the anti-alias filter
/// (AAF) at the 32 kHz internal rate, then the UI filter that decimates to
/// the ODR.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Filter {
    /// GYRO_AAF_DELT: 0 turns the AAF off; otherwise an entry of
    /// datasheet table 17 that [`aaf_coefficients`] knows.
    pub aaf_delt: u8,
    /// GYRO_UI_FILT_ORD as an order, 1..=3.
    pub ui_order: u8,
    /// GYRO_UI_FILT_BW: 0..=7 for ODR/2, /4, /5, /8, /10, /16, /20, /40;
    /// 14 or 15 for the low-latency settings.
    pub ui_bw: u8,
}

impl Filter {
    /// The chip's reset values: AAF at 585 Hz (assumed; see
    /// `emu::icm42688`), UI filter of 2nd order at ODR/4.
    pub const RESET: Self = Self {
        aaf_delt: 13,
        ui_order: 2,
        ui_bw: 1,
    };
    /// PX4's: AAF at 585 Hz, the UI filter left at reset (run at 8 kHz
    /// there, averaged down in software).
    pub const PX4: Self = Self::RESET;
    /// ArduPilot's at a 1 kHz ODR: AAF at 258 Hz, the UI filter at reset.
    pub const ARDUPILOT: Self = Self {
        aaf_delt: 6,
        ui_order: 2,
        ui_bw: 1,
    };
    /// This board's at 1 kHz with the data registers polled (see
    /// [`Config::default`]): ArduPilot's, the least aliasing of the flight
    /// stacks' at that rate (`timing-eval`).
    pub const BOARD: Self = Self::ARDUPILOT;
    /// This board's for FIFO sampling at [`BOARD_FIFO_ODR`], averaged in
    /// fours to the 1 kHz output: AAF at 394 Hz, UI filter of 2nd order at
    /// ODR/8 (500 Hz). It aliases no more than ArduPilot's and PX4's at
    /// any out-of-band tone measured, and of the settings that do, it
    /// reaches the wire soonest at 4 kHz; at 2 kHz the fastest such
    /// setting takes 200 µs longer, past the 2 ms the antenna allows
    /// (`timing-eval`; its `--search` weighs every setting the driver can
    /// write at 2, 4 and 8 kHz, `docs/timing.md`).
    pub const BOARD_FIFO: Self = Self {
        aaf_delt: 9,
        ui_order: 2,
        ui_bw: 3,
    };

    /// GYRO_CONFIG1's GYRO_UI_FILT_ORD bits (3:2).
    fn order_bits(self) -> u8 {
        (self.ui_order.clamp(1, 3) - 1) << 2
    }
}

/// GYRO_AAF_DELTSQR and GYRO_AAF_BITSHIFT for GYRO_AAF_DELT `delt`
/// (datasheet table 17: DELTSQR is close to DELT² but not always equal),
/// for DELT 1..=56 and 63; `None` for the others, which the driver does
/// not set.
pub fn aaf_coefficients(delt: u8) -> Option<(u16, u8)> {
    const T: [(u16, u8); 56] = [
        (1, 15),
        (4, 13),
        (9, 12),
        (16, 11),
        (25, 10),
        (36, 10),
        (49, 9),
        (64, 9),
        (81, 9),
        (100, 8),
        (122, 8),
        (144, 8),
        (170, 8),
        (196, 7),
        (224, 7),
        (256, 7),
        (288, 7),
        (324, 7),
        (360, 6),
        (400, 6),
        (440, 6),
        (488, 6),
        (528, 6),
        (576, 6),
        (624, 6),
        (680, 6),
        (736, 5),
        (784, 5),
        (848, 5),
        (896, 5),
        (960, 5),
        (1024, 5),
        (1088, 5),
        (1152, 5),
        (1232, 5),
        (1296, 5),
        (1376, 4),
        (1440, 4),
        (1536, 4),
        (1600, 4),
        (1696, 4),
        (1760, 4),
        (1856, 4),
        (1952, 4),
        (2016, 4),
        (2112, 4),
        (2208, 4),
        (2304, 4),
        (2400, 4),
        (2496, 4),
        (2592, 4),
        (2720, 4),
        (2816, 3),
        (2944, 3),
        (3008, 3),
        (3136, 3),
    ];
    match delt {
        1..=56 => Some(T[delt as usize - 1]),
        63 => Some((3968, 3)),
        _ => None,
    }
}

/// Datasheet table 17: GYRO_AAF_DELT against the AAF's 3 dB bandwidth, Hz,
/// at the entries the public drivers quote (1–14, 21, 38, 52, 63).
const AAF_TABLE: [(u8, f32); 18] = [
    (1, 42.0),
    (2, 84.0),
    (3, 126.0),
    (4, 170.0),
    (5, 213.0),
    (6, 258.0),
    (7, 303.0),
    (8, 348.0),
    (9, 394.0),
    (10, 441.0),
    (11, 488.0),
    (12, 536.0),
    (13, 585.0),
    (14, 634.0),
    (21, 997.0),
    (38, 2029.0),
    (52, 3057.0),
    (63, 3979.0),
];

/// The AAF's 3 dB bandwidth, Hz, for GYRO_AAF_DELT `delt` (1..=63):
/// table 17, linear between the entries the public drivers quote (the
/// table is within 2 % of linear between them). 0 reads as 1.
pub fn aaf_hz(delt: u8) -> f32 {
    let d = delt.clamp(1, 63);
    let mut prev = AAF_TABLE[0];
    for &(k, hz) in AAF_TABLE.iter() {
        if k == d {
            return hz;
        }
        if k > d {
            let f = (d - prev.0) as f32 / (k - prev.0) as f32;
            return prev.1 + f * (hz - prev.1);
        }
        prev = (k, hz);
    }
    prev.1
}

/// The UI filter's bandwidth divisor for GYRO_UI_FILT_BW (datasheet
/// GYRO_ACCEL_CONFIG0: BW = max(400 Hz, ODR)/k); `None` for the
/// low-latency settings 14 and 15 (and reserved codes), which bypass it.
pub fn ui_divisor(code: u8) -> Option<f32> {
    const K: [f32; 8] = [2.0, 4.0, 5.0, 8.0, 10.0, 16.0, 20.0, 40.0];
    K.get(code as usize).copied()
}

impl Filter {
    /// The signal path's group delay at DC for output rate `odr`, µs: the
    /// AAF as a 2nd-order Butterworth at its table-17 bandwidth (√2/ω) and
    /// the UI filter as a Butterworth of its order at its bandwidth (1/ω,
    /// √2/ω, 2/ω). The datasheet gives bandwidths, not delays; the chip
    /// model's filters are built the same way and their delay is measured
    /// against this (`host-tests/tests/chip_timing.rs`).
    pub fn group_delay_us(&self, odr: Odr) -> f32 {
        let aaf = (self.aaf_delt != 0).then(|| aaf_hz(self.aaf_delt));
        let ui = ui_divisor(self.ui_bw).map(|k| (self.ui_order, odr.hz().max(400.0) / k));
        path_delay_us(aaf, ui)
    }
}

/// The DC group delay of an AAF of 3 dB bandwidth `aaf_hz` (2nd-order
/// Butterworth, √2/ω) followed by a UI filter of (order, bandwidth)
/// `ui` (Butterworth: 1/ω, √2/ω, 2/ω), µs; `None` for a stage that is off.
pub fn path_delay_us(aaf_hz: Option<f32>, ui: Option<(u8, f32)>) -> f32 {
    let w = |hz: f32| 2.0 * core::f32::consts::PI * hz;
    let mut d = 0.0;
    if let Some(a) = aaf_hz {
        d += core::f32::consts::SQRT_2 / w(a);
    }
    if let Some((order, bw)) = ui {
        d += match order {
            0 | 1 => 1.0,
            2 => core::f32::consts::SQRT_2,
            _ => 2.0,
        } / w(bw);
    }
    d * 1e6
}

/// Where the chip takes its clock from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ClockInput {
    /// Its own PLL (±1 %; datasheet table 2).
    Internal,
    /// The board's 31–50 kHz clock on pin 9 (INTF_CONFIG5.PIN9_FUNCTION =
    /// CLKIN, INTF_CONFIG1.RTC_MODE): the ODR follows it.
    ClkIn,
}

/// How samples reach the host.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Sampling {
    /// The data registers, polled.
    Registers,
    /// The FIFO: 16-byte packets with a 16-bit timestamp (datasheet 6.2,
    /// packet 3), stop-on-full, the count in records.
    Fifo,
}

/// Gyro configuration applied by [`Icm42688::init`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Config {
    /// Full-scale range.
    pub full_scale: FullScale,
    /// Output data rate.
    pub odr: Odr,
    /// Signal-path filters.
    pub filter: Filter,
    /// Clock source.
    pub clock: ClockInput,
    /// Registers or FIFO.
    pub sampling: Sampling,
}

impl Default for Config {
    /// ±250 °/s (the board turns at up to 100 °/s), 1 kHz, ArduPilot's
    /// filters at 1 kHz, AFSR off (always: it freezes the output for
    /// 1–2 ms when the rate crosses 100 °/s), the internal clock, the data
    /// registers.
    fn default() -> Self {
        Self {
            full_scale: FullScale::Dps250,
            odr: Odr::Hz1000,
            filter: Filter::BOARD,
            clock: ClockInput::Internal,
            sampling: Sampling::Registers,
        }
    }
}

/// The ODR the board samples its ICM-42688-Ps at through their FIFOs:
/// four samples a millisecond (see [`Filter::BOARD_FIFO`]).
pub const BOARD_FIFO_ODR: Odr = Odr::Hz4000;

impl Config {
    /// The board's FIFO sampling ([`BOARD_FIFO_ODR`] through
    /// [`Filter::BOARD_FIFO`]) on clock `clock`.
    pub const fn board_fifo(clock: ClockInput) -> Self {
        Self {
            full_scale: FullScale::Dps250,
            odr: BOARD_FIFO_ODR,
            filter: Filter::BOARD_FIFO,
            clock,
            sampling: Sampling::Fifo,
        }
    }

    /// The delay a polled read of this configuration carries, µs: the
    /// filters' group delay and half a sample period.
    pub fn polled_delay_us(&self) -> u32 {
        libm::roundf(self.filter.group_delay_us(self.odr) + 0.5e6 / self.odr.hz()) as u32
    }

    /// GYRO_CONFIG0.
    fn gyro_config0(&self) -> u8 {
        ((self.full_scale as u8) << 5) | self.odr as u8
    }
    /// INTF_CONFIG1: the reset value with AFSR off and RTC_MODE as chosen.
    fn intf_config1(&self) -> u8 {
        let rtc = if self.clock == ClockInput::ClkIn {
            bits::RTC_MODE
        } else {
            0
        };
        (reset::INTF_CONFIG1 & !(bits::AFSR_MASK | bits::RTC_MODE)) | bits::AFSR_OFF | rtc
    }
    /// GYRO_CONFIG1: the reset value with the UI filter's order.
    fn gyro_config1(&self) -> u8 {
        (reset::GYRO_CONFIG1 & !(0b11 << 2)) | self.filter.order_bits()
    }
    /// GYRO_ACCEL_CONFIG0: the accelerometer's half at reset, the UI
    /// filter's bandwidth.
    fn gyro_accel_config0(&self) -> u8 {
        (reset::GYRO_ACCEL_CONFIG0 & 0xF0) | (self.filter.ui_bw & 0x0F)
    }
    /// INTF_CONFIG0: big-endian data and count (reset), the count in
    /// records with the FIFO.
    fn intf_config0(&self) -> u8 {
        match self.sampling {
            Sampling::Fifo => reset::INTF_CONFIG0 | bits::FIFO_COUNT_REC,
            Sampling::Registers => reset::INTF_CONFIG0,
        }
    }
    /// FIFO_CONFIG1: accel, gyro and temperature slots (packet 3 carries the
    /// timestamp; the accelerometer stays off and reads −32768).
    fn fifo_config1(&self) -> u8 {
        match self.sampling {
            Sampling::Fifo => bits::FIFO_TEMP_EN | bits::FIFO_GYRO_EN | bits::FIFO_ACCEL_EN,
            Sampling::Registers => 0,
        }
    }
    /// INT_CONFIG, INT_CONFIG1 and INT_SOURCE0: with the FIFO, a pulse on
    /// INT1 at every sample (the board captures its time: the instant each
    /// sample was made, on the board's clock); otherwise their reset values.
    fn int1(&self) -> [u8; 3] {
        match self.sampling {
            Sampling::Fifo => [
                bits::INT1_PUSH_PULL_HIGH,
                reset::INT_CONFIG1 & !bits::INT_ASYNC_RESET,
                bits::UI_DRDY_INT1_EN,
            ],
            Sampling::Registers => [0, reset::INT_CONFIG1, reset::INT_SOURCE0],
        }
    }
    /// FIFO_CONFIG: stop-on-full (what is kept stays in order; an overflow
    /// is flagged and flushed), or bypass.
    fn fifo_config(&self) -> u8 {
        match self.sampling {
            Sampling::Fifo => bits::FIFO_MODE_STOP_ON_FULL,
            Sampling::Registers => 0,
        }
    }
    /// Bank-1 GYRO_CONFIG_STATIC2..5 (0x0B..0x0E) and INTF_CONFIG5, or
    /// `None` for an AAF setting the driver does not know.
    fn bank1(&self) -> Option<([u8; 4], u8)> {
        // With the AAF off its coefficients stay at the reset entry.
        let (d, dis) = match self.filter.aaf_delt {
            0 => (13, bits::GYRO_AAF_DIS),
            d => (d, 0),
        };
        let (sq, shift) = aaf_coefficients(d)?;
        let static2 = (STATIC2_RESET & !bits::GYRO_AAF_DIS) | dis;
        let st = [
            static2,
            d & 0x3F,
            sq as u8,
            (shift << 4) | ((sq >> 8) as u8 & 0x0F),
        ];
        let pin9 = if self.clock == ClockInput::ClkIn {
            bits::PIN9_CLKIN
        } else {
            0
        };
        Some((st, pin9))
    }
}

/// GYRO_CONFIG_STATIC2 at reset (AAF and notch on); see `emu::icm42688`.
const STATIC2_RESET: u8 = 0xA0;

/// One sample out of the FIFO.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FifoSample {
    /// Raw counts per axis.
    pub raw: [i16; 3],
    /// The chip's timestamp of the sample, µs of its own clock (TMST_RES
    /// = 0), extended past the packet's 16 bits.
    pub stamp_us: u32,
}

/// What one FIFO read found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FifoRead {
    /// INT_STATUS as read with the count.
    pub status: u8,
    /// Samples handed to the caller.
    pub samples: usize,
    /// Samples left in the FIFO (more than the buffer held).
    pub left: usize,
    /// The newest sample handed over, if any.
    pub last: Option<FifoSample>,
}

/// FIFO packet size, bytes (packet 3).
pub const FIFO_PACKET: usize = 16;
/// Packets a full FIFO holds: 2 KiB (datasheet 6.1) of 16-byte packets;
/// the count is in records.
pub const FIFO_RECORDS: usize = 2048 / FIFO_PACKET;
/// Most packets one burst of [`Icm42688::read_fifo`] reads.
pub const MAX_PER_READ: usize = 4;
/// The header of a packet 3 with accel and gyro slots and an ODR
/// timestamp; the low two bits flag an ODR change and are not checked.
const HEADER_EXPECTED: u8 = bits::HEADER_ACCEL | bits::HEADER_GYRO | bits::HEADER_TIMESTAMP_ODR;
/// The header bits checked against [`HEADER_EXPECTED`].
const HEADER_MASK: u8 = 0xFC;

/// Parse whole packets from `bytes`, handing each sample to `each` and
/// counting it in `read`; the first bad packet stops it (its error).
/// `stamp` is the last sample's extended timestamp. The counts and the
/// stamp live in registers through the loop and are stored once (per
/// packet they were stores the caller's closure kept the compiler from
/// sinking: some 5 instructions a packet, 16 packets a millisecond).
fn parse_packets<E>(
    bytes: &[u8],
    stamp: &mut Option<u32>,
    read: &mut FifoRead,
    each: &mut impl FnMut(FifoSample),
) -> Option<Error<E>> {
    let (mut st, mut n, mut last, mut bad) = (*stamp, 0, None, None);
    for p in bytes.chunks_exact(FIFO_PACKET) {
        let h = p[0];
        if h & bits::HEADER_MSG != 0 {
            bad = Some(Error::FifoShort);
            break;
        }
        if h & HEADER_MASK != HEADER_EXPECTED {
            bad = Some(Error::FifoBadHeader(h));
            break;
        }
        let w = |i: usize| i16::from_be_bytes([p[i], p[i + 1]]);
        let stamp16 = u16::from_be_bytes([p[14], p[15]]);
        let stamp_us = match st {
            Some(prev) => prev.wrapping_add(stamp16.wrapping_sub(prev as u16) as u32),
            None => stamp16 as u32,
        };
        st = Some(stamp_us);
        let x = FifoSample {
            raw: [w(7), w(9), w(11)],
            stamp_us,
        };
        last = Some(x);
        each(x);
        n += 1;
    }
    *stamp = st;
    read.samples += n;
    if last.is_some() {
        read.last = last;
    }
    bad
}

/// The configuration a self-test saved, restored by
/// [`Icm42688::self_test_end`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SavedConfig {
    gyro_config0: u8,
    config: Config,
}

/// Self-test outcome per axis (x, y, z), in LSB at ±250 °/s.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SelfTest {
    /// Measured response: mean with self-test on minus mean with it off.
    pub response_lsb: [f32; 3],
    /// Factory response from the bank-1 codes.
    pub factory_lsb: [f32; 3],
}

impl SelfTest {
    /// Ratio of measured to factory response; the datasheet's pass criterion
    /// is a ratio above 0.5.
    pub fn ratio(&self) -> [f32; 3] {
        let mut r = [0.0; 3];
        for (i, v) in r.iter_mut().enumerate() {
            *v = if self.factory_lsb[i] > 0.0 {
                self.response_lsb[i] / self.factory_lsb[i]
            } else {
                0.0
            };
        }
        r
    }
}

/// ICM-42688-P gyro driver.
pub struct Icm42688<SPI> {
    spi: SPI,
    full_scale: FullScale,
    /// The configuration last set (a restart sets it again).
    config: Config,
    /// Which register group the next [`Gyro::check_config`] reads.
    check_group: u8,
    /// The last FIFO timestamp (16 bits) and its extension.
    stamp: Option<u32>,
    /// RESET_DONE was seen by a read that could not report it.
    reset_seen: bool,
    /// [`Gyro::delay_us`] for the configuration set (worked out when it is
    /// set: the loop asks every sample).
    delay_us: u32,
    /// FIFO packets the first burst of a read makes room for (see
    /// [`Self::read_fifo`]), worked out when the configuration is set.
    per_read: usize,
    /// The FIFO bursts' buffer: kept, so a read does not zero 67 bytes
    /// first (some 45 instructions a read on the Cortex-M4).
    fifo_buf: [u8; 3 + FIFO_PACKET * MAX_PER_READ],
}

impl<SPI: SpiDevice> Icm42688<SPI> {
    /// Wrap an SPI device. Nothing is sent until [`init`](Self::init).
    pub fn new(spi: SPI) -> Self {
        Self {
            spi,
            full_scale: FullScale::Dps2000,
            config: Config {
                full_scale: FullScale::Dps2000,
                ..Config::default()
            },
            check_group: 0,
            stamp: None,
            reset_seen: false,
            delay_us: 0,
            per_read: 1,
            fifo_buf: [0; 3 + FIFO_PACKET * MAX_PER_READ],
        }
    }

    /// Hand the SPI device back.
    pub fn destroy(self) -> SPI {
        self.spi
    }

    /// The range the driver scales by.
    pub fn full_scale(&self) -> FullScale {
        self.full_scale
    }

    /// The configuration last set.
    pub fn config(&self) -> Config {
        self.config
    }

    /// Soft-reset, check WHO_AM_I, set the signal path, clock, range, rate
    /// and FIFO (each with read-back) and start the gyro in low-noise
    /// mode; with the FIFO, flush what the gyro's start-up produced.
    pub fn init(&mut self, delay: &mut impl DelayNs, cfg: Config) -> Result<(), Error<SPI::Error>> {
        // Kept first, so a restart after a failed init sets this
        // configuration too (the FIFO, the clock), not the last one.
        self.config = cfg;
        self.per_read = cfg.per_read();
        self.write(reg::DEVICE_CONFIG, SOFT_RESET)?;
        delay.delay_ms(1); // datasheet: wait 1 ms after a soft reset
        self.write(reg::REG_BANK_SEL, 0)?;
        let id = self.read(reg::WHO_AM_I)?;
        if id != WHO_AM_I_VALUE {
            return Err(Error::WrongId(id));
        }
        self.configure_path(cfg)?;
        self.configure(cfg)?;
        self.configure_fifo(cfg)?;
        self.write_checked(reg::PWR_MGMT0, GYRO_MODE_LN)?;
        // Clear RESET_DONE (set by the reset above): from here on, a set
        // bit in a sample's INT_STATUS means the chip reset behind our back.
        self.read(reg::INT_STATUS)?;
        delay.delay_ms(45); // gyro start-up time, datasheet table 1
        if cfg.sampling == Sampling::Fifo {
            self.flush_fifo()?;
        }
        Ok(())
    }

    /// The signal path and the clock: bank 1 (AAF coefficients, pin 9),
    /// then INTF_CONFIG1 (AFSR off, RTC_MODE), GYRO_CONFIG1 (UI filter
    /// order) and GYRO_ACCEL_CONFIG0 (its bandwidth), each read back.
    /// Pin 9 becomes CLKIN before RTC_MODE asks for it (TDK's driver does
    /// the same).
    pub fn configure_path(&mut self, cfg: Config) -> Result<(), Error<SPI::Error>> {
        let (st, pin9) = cfg.bank1().ok_or(Error::InvalidArgument)?;
        self.write(reg::REG_BANK_SEL, 1)?;
        let r = self.write_bank1(st, pin9);
        self.write(reg::REG_BANK_SEL, 0)?;
        r?;
        self.write_checked(reg::INTF_CONFIG1, cfg.intf_config1())?;
        self.write_checked(reg::GYRO_CONFIG1, cfg.gyro_config1())?;
        self.write_checked(reg::GYRO_ACCEL_CONFIG0, cfg.gyro_accel_config0())?;
        Ok(())
    }

    fn write_bank1(&mut self, st: [u8; 4], pin9: u8) -> Result<(), Error<SPI::Error>> {
        for (i, v) in st.iter().enumerate() {
            self.write_checked(reg::GYRO_CONFIG_STATIC2 + i as u8, *v)?;
        }
        self.write_checked(reg::INTF_CONFIG5, pin9)
    }

    /// INTF_CONFIG0, FIFO_CONFIG1, FIFO_CONFIG and (with the FIFO) INT1 as
    /// a data-ready pulse, for the sampling chosen, each read back.
    pub fn configure_fifo(&mut self, cfg: Config) -> Result<(), Error<SPI::Error>> {
        self.write_checked(reg::INTF_CONFIG0, cfg.intf_config0())?;
        self.write_checked(reg::FIFO_CONFIG1, cfg.fifo_config1())?;
        self.write_checked(reg::FIFO_CONFIG, cfg.fifo_config())?;
        if cfg.sampling == Sampling::Fifo {
            let [c, c1, s0] = cfg.int1();
            self.write_checked(reg::INT_CONFIG, c)?;
            self.write_checked(reg::INT_CONFIG1, c1)?;
            self.write_checked(reg::INT_SOURCE0, s0)?;
        }
        self.config.sampling = cfg.sampling;
        self.stamp = None;
        Ok(())
    }

    /// Empty the FIFO (SIGNAL_PATH_RESET.FIFO_FLUSH) and clear the
    /// FIFO_FULL it may have latched before (INT_STATUS clears on read); a
    /// RESET_DONE seen there is kept for the next [`Self::read_fifo`].
    pub fn flush_fifo(&mut self) -> Result<(), Error<SPI::Error>> {
        self.stamp = None;
        self.write(reg::SIGNAL_PATH_RESET, bits::FIFO_FLUSH)?;
        if self.read(reg::INT_STATUS)? & RESET_DONE != 0 {
            self.reset_seen = true;
        }
        Ok(())
    }

    /// Read what the FIFO holds, oldest first, into `out` (at most
    /// `out.len()` samples; the rest stay for the next read).
    pub fn read_fifo(&mut self, out: &mut [FifoSample]) -> Result<FifoRead, Error<SPI::Error>> {
        let mut i = 0;
        self.read_fifo_with(out.len(), |s| {
            if let Some(slot) = out.get_mut(i) {
                *slot = s;
            }
            i += 1;
        })
    }

    /// Read up to `max` of the samples the FIFO holds, oldest first, each
    /// handed to `each` as its packet is parsed (no buffer between the
    /// bus and the caller: the board's loop reads four chips a
    /// millisecond).
    ///
    /// One transaction in the usual case: a burst from INT_STATUS through
    /// FIFO_COUNTH/L into FIFO_DATA (the address stays on FIFO_DATA), with
    /// room for the packets a millisecond makes at the ODR; one more for
    /// the rest when the count says more came (a fast chip clock, a late
    /// read). Each header is checked;
    /// FIFO_FULL, a bad header or a short FIFO flush it and return a typed
    /// error (FIFO_FULL beside a count no full FIFO has is a garbled status
    /// and flushes nothing), so the next read starts on a packet boundary
    /// and the caller counts the gap (the samples handed over before the bad packet are
    /// the caller's to drop). Timestamps are extended from 16 bits by their
    /// difference from the last (reads must come within 65 ms).
    pub fn read_fifo_with(
        &mut self,
        max: usize,
        mut each: impl FnMut(FifoSample),
    ) -> Result<FifoRead, Error<SPI::Error>> {
        if self.config.sampling != Sampling::Fifo {
            return Err(Error::NotFifo);
        }
        // Room for the packets one read usually finds (one per ms of the
        // ODR): what the count does not cover reads 0x80 and is not looked
        // at, and a packet arriving during the burst is read again whole
        // (FIFO_RESUME_PARTIAL_RD is clear).
        let k = self.per_read.clamp(1, MAX_PER_READ);
        let first = &mut self.fifo_buf[..3 + FIFO_PACKET * k];
        self.spi
            .transaction(&mut [
                Operation::Write(&[reg::INT_STATUS | READ]),
                Operation::Read(first),
            ])
            .map_err(Error::Spi)?;
        let [status, count_h, count_l, ..] = self.fifo_buf;
        if status & RESET_DONE != 0 || self.reset_seen {
            self.reset_seen = false;
            return Err(Error::ChipReset);
        }
        let count = u16::from_be_bytes([count_h, count_l]) as usize;
        if status & bits::FIFO_FULL != 0 {
            // Stop-on-full keeps a full FIFO full until it is read, and
            // this driver is its only reader: FIFO_FULL beside a count
            // under half of it is a bit error in the status, not lost
            // samples, and flushing would lose the packets it holds.
            if count < FIFO_RECORDS / 2 {
                return Err(Error::FifoBadStatus(status));
            }
            self.flush_fifo()?;
            return Err(Error::FifoOverflow);
        }
        let want = count.min(max);
        let mut read = FifoRead {
            status,
            samples: 0,
            left: count - want,
            last: None,
        };
        let in_first = want.min(k);
        let mut bad = parse_packets(
            &self.fifo_buf[3..3 + FIFO_PACKET * in_first],
            &mut self.stamp,
            &mut read,
            &mut each,
        );
        // The rest, in more bursts from FIFO_DATA.
        while bad.is_none() && read.samples < want {
            let n = (want - read.samples).min(MAX_PER_READ);
            let rest = &mut self.fifo_buf[..FIFO_PACKET * n];
            self.spi
                .transaction(&mut [
                    Operation::Write(&[reg::FIFO_DATA | READ]),
                    Operation::Read(rest),
                ])
                .map_err(Error::Spi)?;
            bad = parse_packets(
                &self.fifo_buf[..FIFO_PACKET * n],
                &mut self.stamp,
                &mut read,
                &mut each,
            );
        }
        match bad {
            None => Ok(read),
            Some(e) => {
                self.flush_fifo()?;
                Err(e)
            }
        }
    }

    /// Die temperature, °C: TEMP_DATA1/0 (0x1D, 0x1E), big-endian
    /// counts; datasheet 14.6: T = TEMP_DATA / 132.48 + 25.
    pub fn read_temperature_c(&mut self) -> Result<f32, Error<SPI::Error>> {
        let mut b = [0u8; 2];
        self.spi
            .transaction(&mut [
                Operation::Write(&[reg::TEMP_DATA1 | READ]),
                Operation::Read(&mut b),
            ])
            .map_err(Error::Spi)?;
        Ok(temperature_c(i16::from_be_bytes(b)))
    }

    /// One sample: a burst read of GYRO_DATA_X1..Z0, TMST_FSYNCH and
    /// INT_STATUS (0x25..=0x2D, 9 bytes). Returns the raw counts and
    /// INT_STATUS, whose RESET_DONE bit reveals a silent reset.
    pub fn read_sample(&mut self) -> Result<([i16; 3], u8), Error<SPI::Error>> {
        let mut b = [0u8; 9];
        self.spi
            .transaction(&mut [
                Operation::Write(&[reg::GYRO_DATA_X1 | READ]),
                Operation::Read(&mut b),
            ])
            .map_err(Error::Spi)?;
        Ok((
            [
                i16::from_be_bytes([b[0], b[1]]),
                i16::from_be_bytes([b[2], b[3]]),
                i16::from_be_bytes([b[4], b[5]]),
            ],
            b[8],
        ))
    }

    /// Set range and output data rate, and check the read-back. The rest
    /// of `cfg` is remembered as set by [`Self::configure_path`] and
    /// [`Self::configure_fifo`].
    pub fn configure(&mut self, cfg: Config) -> Result<(), Error<SPI::Error>> {
        let v = cfg.gyro_config0();
        self.write_checked(reg::GYRO_CONFIG0, v)?;
        self.full_scale = FullScale::from_bits(v >> 5);
        self.config = cfg;
        self.delay_us = cfg.polled_delay_us();
        self.per_read = cfg.per_read();
        Ok(())
    }

    /// Raw gyro counts (x, y, z), one burst read of GYRO_DATA_X1..Z0.
    pub fn read_raw(&mut self) -> Result<[i16; 3], Error<SPI::Error>> {
        let mut b = [0u8; 6];
        self.spi
            .transaction(&mut [
                Operation::Write(&[reg::GYRO_DATA_X1 | READ]),
                Operation::Read(&mut b),
            ])
            .map_err(Error::Spi)?;
        Ok([
            i16::from_be_bytes([b[0], b[1]]),
            i16::from_be_bytes([b[2], b[3]]),
            i16::from_be_bytes([b[4], b[5]]),
        ])
    }

    /// Rates in °/s (x, y, z).
    pub fn read_dps(&mut self) -> Result<[f32; 3], Error<SPI::Error>> {
        let raw = self.read_raw()?;
        let s = self.full_scale.lsb_per_dps();
        Ok([raw[0] as f32 / s, raw[1] as f32 / s, raw[2] as f32 / s])
    }

    /// Gyro self-test (datasheet section 10 and AN-000150): at ±250 °/s and
    /// 1 kHz, average `samples` readings with self-test off and on; the
    /// response must exceed half the factory value
    /// `ST_OTP = 2620 / 2^3 · 1.01^(code − 1)` LSB. The previous
    /// configuration is restored afterwards.
    ///
    /// This is the single-chip test of the datasheet: it needs the board
    /// still, since a change of rate between the two averages reads as
    /// response. On a moving board, the array test
    /// ([`crate::pipeline::startup`]) uses [`Self::self_test_begin`],
    /// [`Self::set_self_test`] and [`Self::self_test_end`] on every chip at
    /// once and takes the motion out with the chips whose self-test is off.
    pub fn self_test(
        &mut self,
        delay: &mut impl DelayNs,
        samples: u16,
    ) -> Result<SelfTest, Error<SPI::Error>> {
        if samples == 0 {
            return Err(Error::InvalidArgument);
        }
        let saved = self.self_test_begin()?;
        delay.delay_ms(20);
        let off = self.mean_raw(delay, samples)?;
        self.set_self_test(true)?;
        delay.delay_ms(200); // datasheet: settle before reading
        let on = self.mean_raw(delay, samples)?;
        self.self_test_end(saved, [on[0] - off[0], on[1] - off[1], on[2] - off[2]])
    }

    /// First step of a self-test: save the configuration and set ±250 °/s
    /// and 1 kHz (the range the factory codes are defined at). Pass the
    /// returned value to [`Self::self_test_end`].
    pub fn self_test_begin(&mut self) -> Result<SavedConfig, Error<SPI::Error>> {
        let saved = SavedConfig {
            gyro_config0: self.read(reg::GYRO_CONFIG0)?,
            config: self.config,
        };
        self.configure(Config {
            full_scale: FullScale::Dps250,
            odr: Odr::Hz1000,
            ..self.config
        })?;
        Ok(saved)
    }

    /// Switch the self-test actuation of all three axes on or off (the
    /// datasheet asks for 200 ms of settling after switching it on).
    pub fn set_self_test(&mut self, on: bool) -> Result<(), Error<SPI::Error>> {
        self.write(reg::SELF_TEST_CONFIG, if on { EN_G_ALL } else { 0 })
    }

    /// Last step of a self-test: switch the actuation off, read the factory
    /// codes, restore the saved
    /// configuration and judge the measured response (LSB at ±250 °/s, per
    /// axis) against half the factory response.
    pub fn self_test_end(
        &mut self,
        saved: SavedConfig,
        response_lsb: [f32; 3],
    ) -> Result<SelfTest, Error<SPI::Error>> {
        self.write(reg::SELF_TEST_CONFIG, 0)?;
        self.write(reg::REG_BANK_SEL, 1)?;
        let codes = [
            self.read(reg::XG_ST_DATA)?,
            self.read(reg::YG_ST_DATA)?,
            self.read(reg::ZG_ST_DATA)?,
        ];
        self.write(reg::REG_BANK_SEL, 0)?;
        self.write_checked(reg::GYRO_CONFIG0, saved.gyro_config0)?;
        self.full_scale = FullScale::from_bits(saved.gyro_config0 >> 5);
        self.config = saved.config;
        self.delay_us = saved.config.polled_delay_us();
        self.per_read = saved.config.per_read();

        let mut st = SelfTest {
            response_lsb,
            factory_lsb: [0.0; 3],
        };
        let mut failed = 0u8;
        for i in 0..3 {
            st.factory_lsb[i] = factory_response_lsb(codes[i]);
            if !(st.response_lsb[i] > 0.5 * st.factory_lsb[i]) {
                failed |= 1 << i;
            }
        }
        if failed != 0 {
            return Err(Error::SelfTestFailed(failed));
        }
        Ok(st)
    }

    fn mean_raw(
        &mut self,
        delay: &mut impl DelayNs,
        n: u16,
    ) -> Result<[f32; 3], Error<SPI::Error>> {
        let mut acc = [0i32; 3];
        for _ in 0..n {
            delay.delay_us(1000); // one sample at 1 kHz
            let r = self.read_raw()?;
            for i in 0..3 {
                acc[i] += r[i] as i32;
            }
        }
        Ok([
            acc[0] as f32 / n as f32,
            acc[1] as f32 / n as f32,
            acc[2] as f32 / n as f32,
        ])
    }

    /// Read `b.len()` consecutive registers from `addr` in one burst.
    pub fn read_burst(&mut self, addr: u8, b: &mut [u8]) -> Result<(), Error<SPI::Error>> {
        self.spi
            .transaction(&mut [Operation::Write(&[addr | READ]), Operation::Read(b)])
            .map_err(Error::Spi)
    }

    /// Read one register (bank as currently selected).
    pub fn read(&mut self, addr: u8) -> Result<u8, Error<SPI::Error>> {
        let mut b = [0u8; 1];
        self.spi
            .transaction(&mut [Operation::Write(&[addr | READ]), Operation::Read(&mut b)])
            .map_err(Error::Spi)?;
        Ok(b[0])
    }

    /// Write one register.
    pub fn write(&mut self, addr: u8, value: u8) -> Result<(), Error<SPI::Error>> {
        self.spi.write(&[addr & !READ, value]).map_err(Error::Spi)
    }

    fn write_checked(&mut self, addr: u8, value: u8) -> Result<(), Error<SPI::Error>> {
        self.write(addr, value)?;
        let read = self.read(addr)?;
        if read != value {
            return Err(Error::ConfigMismatch {
                reg: addr,
                wrote: value,
                read,
            });
        }
        Ok(())
    }
}

/// Factory self-test response in LSB at ±250 °/s from a bank-1 code
/// (datasheet: `ST_OTP = (2620 / 2^FS) · 1.01^(code − 1)`, FS = 3).
pub fn factory_response_lsb(code: u8) -> f32 {
    if code == 0 {
        return 0.0;
    }
    2620.0 / 8.0 * libm::powf(1.01, code as f32 - 1.0)
}

impl<SPI: SpiDevice> Gyro for Icm42688<SPI> {
    fn read(&mut self) -> Result<Reading, ReadFault> {
        let (raw, status) = self.read_sample().map_err(|_| ReadFault::Bus)?;
        if status & RESET_DONE != 0 {
            return Err(ReadFault::Reset);
        }
        let s = self.full_scale.lsb_per_dps();
        let mut saturated = 0;
        for (i, r) in raw.iter().enumerate() {
            if *r == i16::MAX || *r == i16::MIN {
                saturated |= 1 << i;
            }
        }
        Ok(Reading {
            raw,
            rate_dps: [raw[0] as f32 / s, raw[1] as f32 / s, raw[2] as f32 / s],
            axes: 0b111,
            saturated,
        })
    }

    fn temperature_c(&mut self) -> Result<f32, ReadFault> {
        self.read_temperature_c().map_err(|_| ReadFault::Bus)
    }

    /// Polled: the filters' group delay and half a sample period (the
    /// newest sample is 0 to 1 period old at the read).
    fn delay_us(&self) -> u32 {
        self.delay_us
    }

    /// The configuration `init` set, as PX4 re-checks its register table a
    /// little at a time: on every call REG_BANK_SEL and the burst
    /// INTF_CONFIG0 .. GYRO_ACCEL_CONFIG0 (0x4C..=0x52, ACCEL_CONFIG0
    /// skipped: the range and rate, whose corruption rescales the data
    /// silently, power, AFSR, clock, UI filter), then one of three groups in
    /// turn: FIFO_CONFIG and FIFO_CONFIG1; INT_CONFIG and the burst
    /// INT_CONFIG1, INT_SOURCE0; bank 1, GYRO_CONFIG_STATIC2..5 in one burst
    /// and INTF_CONFIG5.
    fn check_config(&mut self) -> Result<(), ReadFault> {
        let cfg = self.config;
        let bus = |_| ReadFault::Bus;
        let group = self.check_group;
        self.check_group = (self.check_group + 1) % 3;
        let same = |ok: bool| if ok { Ok(()) } else { Err(ReadFault::Config) };
        same(self.read(reg::REG_BANK_SEL).map_err(bus)? == 0)?;
        let mut b = [0u8; 7];
        self.read_burst(reg::INTF_CONFIG0, &mut b).map_err(bus)?;
        same(
            b == [
                cfg.intf_config0(),
                cfg.intf_config1(),
                GYRO_MODE_LN,
                cfg.gyro_config0(),
                b[4], // ACCEL_CONFIG0: not set by this driver
                cfg.gyro_config1(),
                cfg.gyro_accel_config0(),
            ],
        )?;
        match group {
            0 => {
                same(self.read(reg::FIFO_CONFIG).map_err(bus)? == cfg.fifo_config())?;
                same(self.read(reg::FIFO_CONFIG1).map_err(bus)? == cfg.fifo_config1())
            }
            1 => {
                let [c, c1, s0] = cfg.int1();
                same(self.read(reg::INT_CONFIG).map_err(bus)? == c)?;
                let mut b = [0u8; 2];
                self.read_burst(reg::INT_CONFIG1, &mut b).map_err(bus)?;
                same(b == [c1, s0])
            }
            _ => {
                let (st, pin9) = cfg.bank1().ok_or(ReadFault::Config)?;
                self.write(reg::REG_BANK_SEL, 1).map_err(bus)?;
                let mut b = [0u8; 4];
                let r = self.read_burst(reg::GYRO_CONFIG_STATIC2, &mut b);
                let p = self.read(reg::INTF_CONFIG5);
                self.write(reg::REG_BANK_SEL, 0).map_err(bus)?;
                r.map_err(bus)?;
                same(b == st && p.map_err(bus)? & bits::PIN9_MASK == pin9)
            }
        }
    }

    /// `init` in steps of at most six transactions, so that a restart
    /// never makes a heavy sample: soft reset; 1 ms later identify; then
    /// the configuration's checked writes ([`Config::setup_write`]), a few a
    /// step (bank 1 first: pin 9 is CLKIN before RTC_MODE asks for it);
    /// the gyro started, RESET_DONE cleared; after the 45 ms gyro start-up
    /// the FIFO flushed (with FIFO sampling), done. The configuration is
    /// the last one set.
    fn restart(&mut self, step: u8) -> Result<Restart, ReadFault> {
        let bus = |_| ReadFault::Bus;
        let bad = |_| ReadFault::BadResponse;
        let cfg = self.config;
        let again = |step: u8, wait_us: u32| Ok(Restart::Again { step, wait_us });
        match step {
            0 => {
                self.write(reg::DEVICE_CONFIG, SOFT_RESET).map_err(bus)?;
                again(1, 1000)
            }
            1 => {
                self.write(reg::REG_BANK_SEL, 0).map_err(bus)?;
                if self.read(reg::WHO_AM_I).map_err(bus)? != WHO_AM_I_VALUE {
                    return Err(ReadFault::BadResponse);
                }
                again(2, 0)
            }
            RESTART_FLUSH => {
                if cfg.sampling == Sampling::Fifo {
                    self.flush_fifo().map_err(bus)?;
                }
                Ok(Restart::Done)
            }
            s => {
                let mut pos = (s - 2) as usize;
                let mut cost = 0;
                let mut bank1 = false;
                while let Some(w) = cfg.setup_write(pos) {
                    let (bank, r, v) = w.ok_or(ReadFault::BadResponse)?;
                    // A write and its read-back, and a bank change (bank 1
                    // is left again before the step ends).
                    let switch = u8::from(bank == 1) != u8::from(bank1);
                    let c =
                        2 + if switch { 1 } else { 0 } + if bank == 1 && !bank1 { 1 } else { 0 };
                    if cost + c > 6 {
                        break;
                    }
                    if switch {
                        self.write(reg::REG_BANK_SEL, bank).map_err(bus)?;
                        bank1 = bank == 1;
                    }
                    let w = self.write_checked(r, v);
                    if w.is_err() && bank1 {
                        self.write(reg::REG_BANK_SEL, 0).map_err(bus)?;
                    }
                    w.map_err(bad)?;
                    cost += 2 + u8::from(switch);
                    pos += 1;
                }
                if bank1 {
                    self.write(reg::REG_BANK_SEL, 0).map_err(bus)?;
                }
                if cfg.setup_write(pos).is_some() {
                    return again(2 + pos as u8, 0);
                }
                // All set: clear RESET_DONE (set by the reset), then wait
                // for the gyro's start-up.
                self.full_scale = cfg.full_scale;
                self.stamp = None;
                self.read(reg::INT_STATUS).map_err(bus)?;
                again(RESTART_FLUSH, 45_000)
            }
        }
    }
}

/// The restart step after the gyro's start-up.
const RESTART_FLUSH: u8 = 201;

impl Config {
    /// Packets the first burst of [`Icm42688::read_fifo`] makes room for:
    /// one per millisecond of the ODR (the board reads every millisecond).
    pub fn per_read(&self) -> usize {
        self.odr.per_ms().min(MAX_PER_READ)
    }

    /// Write `i` of the checked writes a restart makes, in order, as
    /// (bank, register, value): bank 1 (the AAF, pin 9), then
    /// INTF_CONFIG1, the UI filter, range and rate, the FIFO and INT1, and
    /// the gyro's power last. `None` past the last; `Some(None)` for an
    /// AAF setting the driver does not know. Worked out one at a time: a
    /// restart step makes a few of them, and the whole table built and
    /// returned by value (a `heapless::Vec`) cost some 1 300 instructions
    /// a step in copies on the Cortex-M4 (`cargo xtask bench-loop`,
    /// scenario A, the loop's worst sample).
    pub fn setup_write(&self, i: usize) -> Option<Option<(u8, u8, u8)>> {
        let fifo = self.sampling == Sampling::Fifo;
        let w = match i {
            0..=3 => self
                .bank1()
                .map(|(st, _)| (1, reg::GYRO_CONFIG_STATIC2 + i as u8, st[i])),
            4 => self.bank1().map(|(_, pin9)| (1, reg::INTF_CONFIG5, pin9)),
            5 => Some((0, reg::INTF_CONFIG1, self.intf_config1())),
            6 => Some((0, reg::GYRO_CONFIG1, self.gyro_config1())),
            7 => Some((0, reg::GYRO_ACCEL_CONFIG0, self.gyro_accel_config0())),
            8 => Some((0, reg::GYRO_CONFIG0, self.gyro_config0())),
            9 => Some((0, reg::INTF_CONFIG0, self.intf_config0())),
            10 => Some((0, reg::FIFO_CONFIG1, self.fifo_config1())),
            11 => Some((0, reg::FIFO_CONFIG, self.fifo_config())),
            12..=14 if fifo => {
                let v = self.int1();
                let r = [reg::INT_CONFIG, reg::INT_CONFIG1, reg::INT_SOURCE0];
                Some((0, r[i - 12], v[i - 12]))
            }
            12 if !fifo => Some((0, reg::PWR_MGMT0, GYRO_MODE_LN)),
            15 if fifo => Some((0, reg::PWR_MGMT0, GYRO_MODE_LN)),
            _ => return None,
        };
        Some(w)
    }
}

#[cfg(test)]
mod tests {
    //! Byte-exact SPI scripts from the datasheet. Register addresses are
    //! re-declared here on purpose, so a wrong constant in the driver fails.
    use super::*;
    use embedded_hal::delay::DelayNs;
    use embedded_hal_mock::eh1::spi::{Mock, Transaction as T};

    struct NoDelay;
    impl DelayNs for NoDelay {
        fn delay_ns(&mut self, _: u32) {}
    }

    fn rd(addr: u8, v: &[u8]) -> [T<u8>; 4] {
        [
            T::transaction_start(),
            T::write_vec(vec![0x80 | addr]),
            T::read_vec(v.to_vec()),
            T::transaction_end(),
        ]
    }
    fn wr(addr: u8, v: u8) -> [T<u8>; 3] {
        [
            T::transaction_start(),
            T::write_vec(vec![addr, v]),
            T::transaction_end(),
        ]
    }
    /// A write and its read-back.
    fn wrc(s: &mut Vec<T<u8>>, addr: u8, v: u8) {
        s.extend(wr(addr, v));
        s.extend(rd(addr, &[v]));
    }

    /// The signal path and clock: bank 1 (GYRO_CONFIG_STATIC2..5 at
    /// 0x0B..0x0E, INTF_CONFIG5 at 0x7B), then INTF_CONFIG1 (0x4D),
    /// GYRO_CONFIG1 (0x51), GYRO_ACCEL_CONFIG0 (0x52).
    fn path(s: &mut Vec<T<u8>>, aaf: [u8; 4], pin9: u8, intf1: u8, cfg1: u8, gac0: u8) {
        s.extend(wr(0x76, 0x01));
        for (i, v) in aaf.iter().enumerate() {
            wrc(s, 0x0B + i as u8, *v);
        }
        wrc(s, 0x7B, pin9);
        s.extend(wr(0x76, 0x00));
        wrc(s, 0x4D, intf1);
        wrc(s, 0x51, cfg1);
        wrc(s, 0x52, gac0);
    }

    /// 258 Hz AAF: DELT 6, DELTSQR 36, BITSHIFT 10 (datasheet table 17).
    const AAF_258: [u8; 4] = [0xA0, 6, 36, 0xA0];

    #[test]
    fn init_resets_checks_id_and_configures() {
        let mut s = Vec::new();
        s.extend(wr(0x11, 0x01)); // DEVICE_CONFIG soft reset
        s.extend(wr(0x76, 0x00)); // bank 0
        s.extend(rd(0x75, &[0x47])); // WHO_AM_I
                                     // AFSR off: INTF_CONFIG1 0x91 -> 0x51; UI filter 2nd order at
                                     // ODR/4 (the reset values 0x16 and 0x11).
        path(&mut s, AAF_258, 0x00, 0x51, 0x16, 0x11);
        wrc(&mut s, 0x4F, 0x66); // ±250 °/s (011) | 1 kHz (0110)
        wrc(&mut s, 0x4C, 0x30); // INTF_CONFIG0 at reset: no FIFO
        wrc(&mut s, 0x5F, 0x00); // FIFO_CONFIG1: nothing in the FIFO
        wrc(&mut s, 0x16, 0x00); // FIFO_CONFIG: bypass
        wrc(&mut s, 0x4E, 0x0C); // gyro low-noise
        s.extend(rd(0x2D, &[0x10])); // INT_STATUS: clears RESET_DONE
        let mut spi = Mock::new(&s);
        let mut g = Icm42688::new(spi.clone());
        g.init(&mut NoDelay, Config::default()).unwrap();
        assert_eq!(g.full_scale(), FullScale::Dps250);
        spi.done();
    }

    #[test]
    fn init_with_fifo_and_clkin() {
        let mut s = Vec::new();
        s.extend(wr(0x11, 0x01));
        s.extend(wr(0x76, 0x00));
        s.extend(rd(0x75, &[0x47]));
        // PX4's 585 Hz AAF (DELT 13, DELTSQR 170, BITSHIFT 8), pin 9 as
        // CLKIN (0b10 << 1), RTC_MODE (bit 2) with AFSR off; a 3rd-order UI
        // filter (0b10 << 2) at ODR/5.
        path(&mut s, [0xA0, 13, 170, 0x80], 0x04, 0x55, 0x1A, 0x12);
        wrc(&mut s, 0x4F, 0x66);
        wrc(&mut s, 0x4C, 0x70); // count in records
        wrc(&mut s, 0x5F, 0x07); // temperature, gyro, accel slots
        wrc(&mut s, 0x16, 0x80); // stop-on-full
        wrc(&mut s, 0x14, 0x03); // INT1 push-pull, active high, pulsed
        wrc(&mut s, 0x64, 0x00); // INT_ASYNC_RESET cleared
        wrc(&mut s, 0x65, 0x08); // data ready on INT1
        wrc(&mut s, 0x4E, 0x0C);
        s.extend(rd(0x2D, &[0x10]));
        s.extend(wr(0x4B, 0x02)); // SIGNAL_PATH_RESET.FIFO_FLUSH
        s.extend(rd(0x2D, &[0x02])); // and the FIFO_FULL latched before
        let mut spi = Mock::new(&s);
        let mut g = Icm42688::new(spi.clone());
        let cfg = Config {
            filter: Filter {
                aaf_delt: 13,
                ui_order: 3,
                ui_bw: 2,
            },
            clock: ClockInput::ClkIn,
            sampling: Sampling::Fifo,
            ..Config::default()
        };
        g.init(&mut NoDelay, cfg).unwrap();
        spi.done();
    }

    #[test]
    fn an_aaf_setting_outside_the_table_is_refused() {
        let mut s = Vec::new();
        s.extend(wr(0x11, 0x01));
        s.extend(wr(0x76, 0x00));
        s.extend(rd(0x75, &[0x47]));
        let mut spi = Mock::new(&s);
        let mut g = Icm42688::new(spi.clone());
        let cfg = Config {
            filter: Filter {
                aaf_delt: 60,
                ..Filter::BOARD
            },
            ..Config::default()
        };
        assert_eq!(g.init(&mut NoDelay, cfg), Err(Error::InvalidArgument));
        spi.done();
    }

    #[test]
    fn wrong_id_is_a_typed_error() {
        let mut s = Vec::new();
        s.extend(wr(0x11, 0x01));
        s.extend(wr(0x76, 0x00));
        s.extend(rd(0x75, &[0x98]));
        let mut spi = Mock::new(&s);
        let mut g = Icm42688::new(spi.clone());
        assert_eq!(
            g.init(&mut NoDelay, Config::default()),
            Err(Error::WrongId(0x98))
        );
        spi.done();
    }

    #[test]
    fn config_read_back_mismatch_is_reported() {
        let mut s = Vec::new();
        s.extend(wr(0x4F, 0x06));
        s.extend(rd(0x4F, &[0x00]));
        let mut spi = Mock::new(&s);
        let mut g = Icm42688::new(spi.clone());
        let cfg = Config {
            full_scale: FullScale::Dps2000,
            ..Config::default()
        };
        assert_eq!(
            g.configure(cfg),
            Err(Error::ConfigMismatch {
                reg: 0x4F,
                wrote: 0x06,
                read: 0
            })
        );
        spi.done();
    }

    #[test]
    fn burst_read_scales_big_endian_counts() {
        // GYRO_DATA_X1..Z0, TMST (2), INT_STATUS (data ready only).
        let s = rd(
            0x25,
            &[0x00, 0x83, 0xFF, 0x7D, 0x7F, 0xFF, 0x12, 0x34, 0x08],
        );
        let mut spi = Mock::new(&s);
        let mut g = Icm42688::new(spi.clone());
        g.full_scale = FullScale::Dps250;
        let r = Gyro::read(&mut g).unwrap();
        assert_eq!(r.raw, [131, -131, 32767]);
        assert_eq!(r.rate_dps[0], 1.0);
        assert_eq!(r.rate_dps[1], -1.0);
        assert_eq!(r.saturated, 0b100);
        spi.done();
    }

    #[test]
    fn a_silent_reset_is_reported_and_a_restart_reconfigures() {
        let mut s = Vec::new();
        // INT_STATUS with RESET_DONE: the chip reset since it was set up.
        s.extend(rd(0x25, &[0x80, 0x00, 0x80, 0x00, 0x80, 0x00, 0, 0, 0x10]));
        s.extend(wr(0x11, 0x01)); // step 0: soft reset
        s.extend(wr(0x76, 0x00)); // step 1: bank 0, id
        s.extend(rd(0x75, &[0x47]));
        // Then at most six transactions a step: bank 1 (AAF 258 Hz, pin 9).
        s.extend(wr(0x76, 0x01));
        wrc(&mut s, 0x0B, AAF_258[0]);
        wrc(&mut s, 0x0C, AAF_258[1]);
        s.extend(wr(0x76, 0x00));
        s.extend(wr(0x76, 0x01));
        wrc(&mut s, 0x0D, AAF_258[2]);
        wrc(&mut s, 0x0E, AAF_258[3]);
        s.extend(wr(0x76, 0x00));
        s.extend(wr(0x76, 0x01));
        wrc(&mut s, 0x7B, 0x00);
        s.extend(wr(0x76, 0x00));
        wrc(&mut s, 0x4D, 0x51); // AFSR off
        wrc(&mut s, 0x51, 0x16);
        wrc(&mut s, 0x52, 0x11);
        wrc(&mut s, 0x4F, 0x06); // the configuration set before
        wrc(&mut s, 0x4C, 0x30);
        wrc(&mut s, 0x5F, 0x00);
        wrc(&mut s, 0x16, 0x00);
        wrc(&mut s, 0x4E, 0x0C); // gyro on, then RESET_DONE cleared
        s.extend(rd(0x2D, &[0x10]));
        let mut spi = Mock::new(&s);
        let mut g = Icm42688::new(spi.clone());
        assert_eq!(Gyro::read(&mut g), Err(ReadFault::Reset));
        let mut step = 0;
        let mut waits = Vec::new();
        loop {
            match g.restart(step) {
                Ok(Restart::Again { step: s, wait_us }) => {
                    waits.push(wait_us);
                    step = s;
                }
                Ok(Restart::Done) => break,
                Err(e) => panic!("{e:?}"),
            }
        }
        // Reset, identity, six steps of writes, the 45 ms start-up.
        assert_eq!(waits, [1000, 0, 0, 0, 0, 0, 0, 45_000]);
        spi.done();
    }

    #[test]
    fn config_check_reads_the_core_every_time_and_three_groups_in_turn() {
        // The core: REG_BANK_SEL, 0x4C..=0x52 in one burst (±2000 °/s,
        // 1 kHz as `new` assumes).
        let core = |s: &mut Vec<T<u8>>, intf1: u8| {
            s.extend(rd(0x76, &[0x00]));
            s.extend(rd(0x4C, &[0x30, intf1, 0x0C, 0x06, 0x06, 0x16, 0x11]));
        };
        let mut s = Vec::new();
        // Group 0: FIFO_CONFIG, FIFO_CONFIG1 (reset values without the FIFO).
        core(&mut s, 0x51);
        s.extend(rd(0x16, &[0x00]));
        s.extend(rd(0x5F, &[0x00]));
        // Group 1: INT_CONFIG, then INT_CONFIG1 and INT_SOURCE0 in one burst.
        core(&mut s, 0x51);
        s.extend(rd(0x14, &[0x00]));
        s.extend(rd(0x64, &[0x10, 0x10]));
        // Group 2: bank 1, GYRO_CONFIG_STATIC2..5 in one burst, INTF_CONFIG5.
        core(&mut s, 0x51);
        s.extend(wr(0x76, 0x01));
        s.extend(rd(0x0B, &AAF_258));
        s.extend(rd(0x7B, &[0x00]));
        s.extend(wr(0x76, 0x00));
        // Then: AFSR back on (a reset value) in the core; INT1 set up
        // behind the driver's back; the AAF at another setting.
        core(&mut s, 0x91);
        core(&mut s, 0x51);
        s.extend(rd(0x14, &[0x03]));
        core(&mut s, 0x51);
        s.extend(wr(0x76, 0x01));
        s.extend(rd(0x0B, &[0xA0, 13, 170, 0x80]));
        s.extend(rd(0x7B, &[0x00]));
        s.extend(wr(0x76, 0x00));
        let mut spi = Mock::new(&s);
        let mut g = Icm42688::new(spi.clone());
        for _ in 0..3 {
            assert_eq!(g.check_config(), Ok(()));
        }
        for _ in 0..3 {
            assert_eq!(g.check_config(), Err(ReadFault::Config));
        }
        spi.done();
    }

    /// A packet 3: header 0x68, accel −32768 ×3, gyro, temperature, stamp.
    fn packet(g: [i16; 3], stamp: u16) -> [u8; 16] {
        let mut p = [0u8; 16];
        p[0] = 0x68;
        for i in 0..3 {
            p[1 + 2 * i] = 0x80;
            p[7 + 2 * i..9 + 2 * i].copy_from_slice(&g[i].to_be_bytes());
        }
        p[14..16].copy_from_slice(&stamp.to_be_bytes());
        p
    }

    fn fifo_driver(s: &[T<u8>]) -> (Mock<u8>, Icm42688<Mock<u8>>) {
        let spi = Mock::new(s);
        let mut g = Icm42688::new(spi.clone());
        g.config.sampling = Sampling::Fifo;
        (spi, g)
    }

    /// The burst INT_STATUS, FIFO_COUNTH/L, one packet.
    fn head(status: u8, count: u16, p: &[u8; 16]) -> [T<u8>; 4] {
        let mut v = vec![status];
        v.extend(count.to_be_bytes());
        v.extend(p);
        rd(0x2D, &v)
    }

    #[test]
    fn fifo_reads_one_packet_in_one_transaction_and_more_in_a_second() {
        let mut s = Vec::new();
        s.extend(head(0x08, 1, &packet([1, -2, 3], 0xFFF0)));
        // Two more came: the second is read from FIFO_DATA (0x30); the stamp
        // wraps (0xFFF0 + 1000 µs).
        s.extend(head(
            0x08,
            2,
            &packet([4, 5, 6], 0xFFF0u16.wrapping_add(1000)),
        ));
        s.extend(rd(0x30, &packet([7, 8, 9], 0xFFF0u16.wrapping_add(2000))));
        // Empty: the packet bytes read 0x80 and are not looked at.
        s.extend(head(0x00, 0, &[0x80; 16]));
        let (mut spi, mut g) = fifo_driver(&s);
        let mut out = [FifoSample {
            raw: [0; 3],
            stamp_us: 0,
        }; 4];
        let r = g.read_fifo(&mut out).unwrap();
        assert_eq!((r.samples, r.left, r.status), (1, 0, 0x08));
        assert_eq!(out[0].raw, [1, -2, 3]);
        assert_eq!(out[0].stamp_us, 0xFFF0);
        let r = g.read_fifo(&mut out).unwrap();
        assert_eq!((r.samples, r.left), (2, 0));
        assert_eq!(out[0].raw, [4, 5, 6]);
        assert_eq!(out[0].stamp_us, 0xFFF0 + 1000);
        assert_eq!(out[1].stamp_us, 0xFFF0 + 2000);
        assert_eq!(g.read_fifo(&mut out).unwrap().samples, 0);
        spi.done();
    }

    #[test]
    fn at_2_khz_one_burst_holds_two_packets_and_the_rest_comes_in_one_more() {
        let mut two = vec![0x08, 0x00, 0x02];
        two.extend(packet([1, 1, 1], 100));
        two.extend(packet([2, 2, 2], 600));
        let mut one = vec![0x08, 0x00, 0x01];
        one.extend(packet([3, 3, 3], 1100));
        one.extend([0x80; 16]); // room for a second, not counted
        let mut four = vec![0x08, 0x00, 0x04];
        four.extend(packet([4, 4, 4], 1600));
        four.extend(packet([5, 5, 5], 2100));
        let mut rest = packet([6, 6, 6], 2600).to_vec();
        rest.extend(packet([7, 7, 7], 3100));
        let mut s = Vec::new();
        s.extend(rd(0x2D, &two));
        s.extend(rd(0x2D, &one));
        s.extend(rd(0x2D, &four));
        s.extend(rd(0x30, &rest));
        let (mut spi, mut g) = fifo_driver(&s);
        g.config.odr = Odr::Hz2000;
        g.per_read = g.config.per_read();
        let mut out = [FifoSample {
            raw: [0; 3],
            stamp_us: 0,
        }; 8];
        assert_eq!(g.read_fifo(&mut out).unwrap().samples, 2);
        assert_eq!(out[1].raw, [2, 2, 2]);
        assert_eq!(g.read_fifo(&mut out).unwrap().samples, 1);
        assert_eq!(g.read_fifo(&mut out).unwrap().samples, 4);
        assert_eq!(out[3].raw, [7, 7, 7]);
        assert_eq!(out[3].stamp_us, 3100);
        spi.done();
    }

    #[test]
    fn fifo_leaves_what_the_buffer_cannot_hold() {
        let mut s = Vec::new();
        s.extend(head(0x08, 3, &packet([1, 1, 1], 0)));
        s.extend(rd(0x30, &packet([2, 2, 2], 1000)));
        let (mut spi, mut g) = fifo_driver(&s);
        let mut out = [FifoSample {
            raw: [0; 3],
            stamp_us: 0,
        }; 2];
        let r = g.read_fifo(&mut out).unwrap();
        assert_eq!((r.samples, r.left), (2, 1));
        spi.done();
    }

    #[test]
    fn fifo_overflow_bad_header_short_fifo_and_reset_are_typed_errors() {
        let mut s = Vec::new();
        s.extend(head(0x0A, 128, &packet([0; 3], 0))); // FIFO_FULL
        s.extend(wr(0x4B, 0x02));
        s.extend(rd(0x2D, &[0x00]));
        let mut bad = packet([0; 3], 0);
        bad[0] = 0x28; // gyro only: not the format configured
        s.extend(head(0x08, 1, &bad));
        s.extend(wr(0x4B, 0x02));
        s.extend(rd(0x2D, &[0x00]));
        s.extend(head(0x08, 1, &[0x80; 16])); // counted, but empty
        s.extend(wr(0x4B, 0x02));
        s.extend(rd(0x2D, &[0x10])); // and a reset seen while flushing
        s.extend(head(0x08, 1, &packet([0; 3], 0))); // reported by the next read
        s.extend(head(0x18, 1, &packet([0; 3], 0))); // RESET_DONE itself
        let (mut spi, mut g) = fifo_driver(&s);
        let mut out = [FifoSample {
            raw: [0; 3],
            stamp_us: 0,
        }; 2];
        assert_eq!(g.read_fifo(&mut out), Err(Error::FifoOverflow));
        assert_eq!(g.read_fifo(&mut out), Err(Error::FifoBadHeader(0x28)));
        assert_eq!(g.read_fifo(&mut out), Err(Error::FifoShort));
        assert_eq!(g.read_fifo(&mut out), Err(Error::ChipReset));
        assert_eq!(g.read_fifo(&mut out), Err(Error::ChipReset));
        spi.done();
    }

    #[test]
    fn fifo_full_beside_a_count_no_full_fifo_has_is_a_bad_status_and_flushes_nothing() {
        let mut s = Vec::new();
        // FIFO_FULL (and data-ready) beside one record: a garbled status;
        // no flush, so the same packet is there for the next read.
        s.extend(head(0x0A, 1, &packet([4, 5, 6], 100)));
        s.extend(head(0x08, 1, &packet([4, 5, 6], 100)));
        // Half the FIFO or more beside FIFO_FULL: a real overflow.
        s.extend(head(0x0A, FIFO_RECORDS as u16 / 2, &packet([0; 3], 0)));
        s.extend(wr(0x4B, 0x02));
        s.extend(rd(0x2D, &[0x00]));
        let (mut spi, mut g) = fifo_driver(&s);
        let mut out = [FifoSample {
            raw: [0; 3],
            stamp_us: 0,
        }; 2];
        assert_eq!(g.read_fifo(&mut out), Err(Error::FifoBadStatus(0x0A)));
        let r = g.read_fifo(&mut out).unwrap();
        assert_eq!((r.samples, out[0].raw), (1, [4, 5, 6]));
        assert_eq!(g.read_fifo(&mut out), Err(Error::FifoOverflow));
        spi.done();
    }

    #[test]
    fn fifo_read_without_fifo_sampling_is_refused() {
        let (mut spi, mut g) = fifo_driver(&[]);
        g.config.sampling = Sampling::Registers;
        let mut out = [FifoSample {
            raw: [0; 3],
            stamp_us: 0,
        }; 1];
        assert_eq!(g.read_fifo(&mut out), Err(Error::NotFifo));
        spi.done();
    }

    #[test]
    fn factory_code_formula() {
        assert_eq!(factory_response_lsb(1), 327.5);
        assert!((factory_response_lsb(101) - 327.5 * 1.01f32.powi(100)).abs() < 0.05);
        assert_eq!(factory_response_lsb(0), 0.0);
    }

    #[test]
    fn aaf_coefficient_table() {
        // The pairs PX4 (585 Hz) and ArduPilot (258, 536, 997 Hz) write.
        assert_eq!(aaf_coefficients(6), Some((36, 10)));
        assert_eq!(aaf_coefficients(12), Some((144, 8)));
        assert_eq!(aaf_coefficients(13), Some((170, 8)));
        assert_eq!(aaf_coefficients(21), Some((440, 6)));
        assert_eq!(aaf_coefficients(63), Some((3968, 3)));
        assert_eq!(aaf_coefficients(60), None);
        assert_eq!(aaf_coefficients(0), None);
    }
}
