//! TDK InvenSense ICM-42688-P 6-axis IMU, gyro part, over SPI (mode 0 or 3).
//!
//! Register map and bit fields from the ICM-42688-P datasheet (DS-000347
//! rev 1.8), section 14 "Register map" (user bank 0 and bank 1). SPI reads set
//! bit 7 of the address byte; multi-byte reads auto-increment.
//!
//! An [`embedded_hal::spi::SpiDevice`] driver: the data registers polled,
//! or the FIFO with its timestamps read in bursts (as PX4 and ArduPilot run
//! the part), every configuration write read back, a restart in
//! non-blocking steps and a configuration check a little at a time (as
//! PX4 re-checks its register table), and the datasheet's self-test.
//!
//! ```
//! use embedded_hal::{delay::DelayNs, spi::SpiDevice};
//! use icm42688p::{Config, Error, Icm42688};
//!
//! /// Start the part (±250 °/s at 1 kHz, every write read back) and read
//! /// its rates, °/s.
//! fn rates<SPI: SpiDevice>(
//!     spi: SPI,
//!     delay: &mut impl DelayNs,
//! ) -> Result<[f32; 3], Error<SPI::Error>> {
//!     let mut gyro = Icm42688::new(spi);
//!     gyro.init(delay, Config::default())?;
//!     gyro.read_dps()
//! }
//! ```
//!
//! Here: the driver and its register access. Beside it, one file each:
//! `regs` (the register map), `config` (what the driver sets, and the
//! checked writes a restart makes), `filter` (the anti-alias and UI
//! filters and their delay), `fifo` (packets, timestamps, burst reads)
//! and `selftest`.

#![cfg_attr(not(test), no_std)]
#![deny(unsafe_code)]
#![warn(missing_docs)]

use embedded_hal::delay::DelayNs;
use embedded_hal::spi::{Operation, SpiDevice};

mod config;
mod fifo;
mod filter;
mod regs;
mod selftest;
#[cfg(test)]
mod tests;

use config::RESTART_FLUSH;
pub use config::{ClockInput, Config, Sampling};
pub use fifo::{FifoRead, FifoSample, FIFO_PACKET, FIFO_RECORDS, MAX_PER_READ};
pub use filter::{aaf_coefficients, aaf_hz, path_delay_us, ui_divisor, Filter};
pub use regs::{bits, reg, reset};
pub use selftest::{factory_response_lsb, SavedConfig, SelfTest};

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
    /// Sensitivity in LSB per °/s (datasheet table 1), from a `const`
    /// table (an array literal indexed in place is built on the stack on
    /// every call).
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

    /// Samples per millisecond (at least 1): for a 1 kHz output, the
    /// samples each output's moving mean spans.
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

/// GYRO_CONFIG_STATIC2 at reset (AAF and notch on).
const STATIC2_RESET: u8 = 0xA0;

/// One step of a non-blocking restart ([`Icm42688::restart_step`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Step {
    /// Call again with `step` once at least `wait_us` have passed.
    Again {
        /// The next step.
        step: u8,
        /// Microseconds to wait first.
        wait_us: u32,
    },
    /// The chip is configured and producing data again.
    Done,
}

/// ICM-42688-P gyro driver.
pub struct Icm42688<SPI> {
    spi: SPI,
    full_scale: FullScale,
    /// The configuration last set (a restart sets it again).
    config: Config,
    /// Which register group the next [`Icm42688::check_config`] reads.
    check_group: u8,
    /// The last FIFO timestamp (16 bits) and its extension.
    stamp: Option<u32>,
    /// The last step between two FIFO timestamps, counts (0: none since
    /// the stream began).
    step: u16,
    /// RESET_DONE was seen by a read that could not report it.
    reset_seen: bool,
    /// [`Icm42688::polled_delay_us`] for the configuration set (worked
    /// out when it is set: a sampling loop asks every sample).
    delay_us: u32,
    /// FIFO packets the first burst of a read makes room for (see
    /// [`Self::read_fifo`]), worked out when the configuration is set.
    per_read: usize,
    /// [`Config::stamp_step_max`] for the configuration set (worked out
    /// when it is set, not on every read).
    stamp_lim: u16,
    /// The FIFO bursts' buffer: kept, so a read does not zero 67 bytes
    /// first (some 45 instructions a read on the Cortex-M4).
    fifo_buf: [u8; 3 + FIFO_PACKET * MAX_PER_READ],
    /// WHO_AM_I as the last init read it.
    who_am_i: u8,
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
            step: 0,
            reset_seen: false,
            delay_us: 0,
            per_read: 1,
            stamp_lim: Config::default().stamp_step_max(),
            fifo_buf: [0; 3 + FIFO_PACKET * MAX_PER_READ],
            who_am_i: 0,
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

    /// WHO_AM_I as the last init read it (0 before one did).
    pub fn who_am_i(&self) -> u8 {
        self.who_am_i
    }

    /// Polled: how long before a data-register read its rate was the true
    /// rate, µs: the filters' group delay and half a sample period (the
    /// newest sample is 0 to 1 period old at the read).
    pub fn polled_delay_us(&self) -> u32 {
        self.delay_us
    }

    /// Soft-reset, check WHO_AM_I, set the signal path, clock, range, rate
    /// and FIFO (each with read-back) and start the gyro in low-noise
    /// mode; with the FIFO, flush what the gyro's start-up produced.
    pub fn init(&mut self, delay: &mut impl DelayNs, cfg: Config) -> Result<(), Error<SPI::Error>> {
        // Kept first, so a restart after a failed init sets this
        // configuration too (the FIFO, the clock), not the last one.
        self.config = cfg;
        self.per_read = cfg.per_read();
        self.stamp_lim = cfg.stamp_step_max();
        self.write(reg::DEVICE_CONFIG, SOFT_RESET)?;
        delay.delay_ms(1); // datasheet: wait 1 ms after a soft reset
        self.write(reg::REG_BANK_SEL, 0)?;
        let id = self.read(reg::WHO_AM_I)?;
        self.who_am_i = id;
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
        // A new clock (RTC_MODE) steps its stamps by another count, from
        // wherever its counter stands: the stamps before are no stream to
        // check the next against (a step back across the switch read as a
        // packet sent again dropped a sample the chip gave out, the timed
        // fault campaign at CLKIN's loss).
        self.step = 0;
        self.stamp = None;
        Ok(())
    }

    fn write_bank1(&mut self, st: [u8; 4], pin9: u8) -> Result<(), Error<SPI::Error>> {
        for (i, v) in st.iter().enumerate() {
            self.write_checked(reg::GYRO_CONFIG_STATIC2 + i as u8, *v)?;
        }
        self.write_checked(reg::INTF_CONFIG5, pin9)
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
        self.stamp_lim = cfg.stamp_step_max();
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

impl<SPI: SpiDevice> Icm42688<SPI> {
    /// The configuration `init` set, as PX4 re-checks its register table a
    /// little at a time: on every call REG_BANK_SEL and the burst
    /// INTF_CONFIG0 .. GYRO_ACCEL_CONFIG0 (0x4C..=0x52, ACCEL_CONFIG0
    /// skipped: the range and rate, whose corruption rescales the data
    /// silently, power, AFSR, clock, UI filter), then one of three groups in
    /// turn: FIFO_CONFIG and FIFO_CONFIG1; INT_CONFIG and the burst
    /// INT_CONFIG1, INT_SOURCE0; bank 1, GYRO_CONFIG_STATIC2..5 in one burst
    /// and INTF_CONFIG5. A register that differs is
    /// [`Error::ConfigMismatch`] (the first that differs; `wrote` is what
    /// the driver set).
    pub fn check_config(&mut self) -> Result<(), Error<SPI::Error>> {
        let cfg = self.config;
        let group = self.check_group;
        self.check_group = (self.check_group + 1) % 3;
        // The first register of `got` that is not `want`'s, from `addr` on.
        let same = |addr: u8, got: &[u8], want: &[u8]| match got
            .iter()
            .zip(want)
            .enumerate()
            .find(|(_, (g, w))| g != w)
        {
            None => Ok(()),
            Some((k, (&read, &wrote))) => Err(Error::ConfigMismatch {
                reg: addr + k as u8,
                wrote,
                read,
            }),
        };
        same(reg::REG_BANK_SEL, &[self.read(reg::REG_BANK_SEL)?], &[0])?;
        let mut b = [0u8; 7];
        self.read_burst(reg::INTF_CONFIG0, &mut b)?;
        same(
            reg::INTF_CONFIG0,
            &b,
            &[
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
                same(
                    reg::FIFO_CONFIG,
                    &[self.read(reg::FIFO_CONFIG)?],
                    &[cfg.fifo_config()],
                )?;
                same(
                    reg::FIFO_CONFIG1,
                    &[self.read(reg::FIFO_CONFIG1)?],
                    &[cfg.fifo_config1()],
                )
            }
            1 => {
                let [c, c1, s0] = cfg.int1();
                same(reg::INT_CONFIG, &[self.read(reg::INT_CONFIG)?], &[c])?;
                let mut b = [0u8; 2];
                self.read_burst(reg::INT_CONFIG1, &mut b)?;
                same(reg::INT_CONFIG1, &b, &[c1, s0])
            }
            _ => {
                let (st, pin9) = cfg.bank1().ok_or(Error::InvalidArgument)?;
                self.write(reg::REG_BANK_SEL, 1)?;
                let mut b = [0u8; 4];
                let r = self.read_burst(reg::GYRO_CONFIG_STATIC2, &mut b);
                let p = self.read(reg::INTF_CONFIG5);
                self.write(reg::REG_BANK_SEL, 0)?;
                r?;
                same(reg::GYRO_CONFIG_STATIC2, &b, &st)?;
                same(reg::INTF_CONFIG5, &[p? & bits::PIN9_MASK], &[pin9])
            }
        }
    }

    /// `init` in steps of at most six transactions, for a caller that
    /// keeps sampling other chips meanwhile and must never make a heavy
    /// sample: soft reset; 1 ms later identify; then the configuration's
    /// checked writes ([`Config::setup_write`]), a few a step (bank 1
    /// first: pin 9 is CLKIN before RTC_MODE asks for it); the gyro
    /// started, RESET_DONE cleared; after the 45 ms gyro start-up the FIFO
    /// flushed (with FIFO sampling), done. Call with step 0, then with
    /// each step returned once its wait has passed. The configuration is
    /// the last one set.
    pub fn restart_step(&mut self, step: u8) -> Result<Step, Error<SPI::Error>> {
        let cfg = self.config;
        let again = |step: u8, wait_us: u32| Ok(Step::Again { step, wait_us });
        match step {
            0 => {
                self.write(reg::DEVICE_CONFIG, SOFT_RESET)?;
                again(1, 1000)
            }
            1 => {
                self.write(reg::REG_BANK_SEL, 0)?;
                let id = self.read(reg::WHO_AM_I)?;
                if id != WHO_AM_I_VALUE {
                    return Err(Error::WrongId(id));
                }
                again(2, 0)
            }
            RESTART_FLUSH => {
                if cfg.sampling == Sampling::Fifo {
                    self.flush_fifo()?;
                }
                Ok(Step::Done)
            }
            s => {
                let mut pos = (s - 2) as usize;
                let mut cost = 0;
                let mut bank1 = false;
                while let Some(w) = cfg.setup_write(pos) {
                    let (bank, r, v) = w.ok_or(Error::InvalidArgument)?;
                    // A write and its read-back, and a bank change (bank 1
                    // is left again before the step ends).
                    let switch = u8::from(bank == 1) != u8::from(bank1);
                    let c =
                        2 + if switch { 1 } else { 0 } + if bank == 1 && !bank1 { 1 } else { 0 };
                    if cost + c > 6 {
                        break;
                    }
                    if switch {
                        self.write(reg::REG_BANK_SEL, bank)?;
                        bank1 = bank == 1;
                    }
                    let w = self.write_checked(r, v);
                    if w.is_err() && bank1 {
                        self.write(reg::REG_BANK_SEL, 0)?;
                    }
                    w?;
                    cost += 2 + u8::from(switch);
                    pos += 1;
                }
                if bank1 {
                    self.write(reg::REG_BANK_SEL, 0)?;
                }
                if cfg.setup_write(pos).is_some() {
                    return again(2 + pos as u8, 0);
                }
                // All set: clear RESET_DONE (set by the reset), then wait
                // for the gyro's start-up.
                self.full_scale = cfg.full_scale;
                self.stamp = None;
                self.step = 0;
                self.read(reg::INT_STATUS)?;
                again(RESTART_FLUSH, 45_000)
            }
        }
    }
}
