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
    pub const TEMP_DATA1: u8 = 0x1D;
    pub const GYRO_DATA_X1: u8 = 0x25;
    pub const INT_STATUS: u8 = 0x2D;
    pub const PWR_MGMT0: u8 = 0x4E;
    pub const GYRO_CONFIG0: u8 = 0x4F;
    pub const SELF_TEST_CONFIG: u8 = 0x70;
    pub const WHO_AM_I: u8 = 0x75;
    pub const REG_BANK_SEL: u8 = 0x76;
    /// Bank 1: factory self-test codes for the gyro axes.
    pub const XG_ST_DATA: u8 = 0x5F;
    pub const YG_ST_DATA: u8 = 0x60;
    pub const ZG_ST_DATA: u8 = 0x61;
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
    /// The self-test needs at least one sample per phase.
    InvalidArgument,
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
        }
    }
}

/// Gyro configuration applied by [`Icm42688::init`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Config {
    /// Full-scale range.
    pub full_scale: FullScale,
    /// Output data rate.
    pub odr: Odr,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            full_scale: FullScale::Dps250,
            odr: Odr::Hz1000,
        }
    }
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
}

impl<SPI: SpiDevice> Icm42688<SPI> {
    /// Wrap an SPI device. Nothing is sent until [`init`](Self::init).
    pub fn new(spi: SPI) -> Self {
        Self {
            spi,
            full_scale: FullScale::Dps2000,
            config: Config {
                full_scale: FullScale::Dps2000,
                odr: Odr::Hz1000,
            },
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

    /// Soft-reset, check WHO_AM_I, set range and rate (with read-back) and
    /// start the gyro in low-noise mode.
    pub fn init(&mut self, delay: &mut impl DelayNs, cfg: Config) -> Result<(), Error<SPI::Error>> {
        self.write(reg::DEVICE_CONFIG, SOFT_RESET)?;
        delay.delay_ms(1); // datasheet: wait 1 ms after a soft reset
        self.write(reg::REG_BANK_SEL, 0)?;
        let id = self.read(reg::WHO_AM_I)?;
        if id != WHO_AM_I_VALUE {
            return Err(Error::WrongId(id));
        }
        self.configure(cfg)?;
        self.write_checked(reg::PWR_MGMT0, GYRO_MODE_LN)?;
        // Clear RESET_DONE (set by the reset above): from here on, a set
        // bit in a sample's INT_STATUS means the chip reset behind our back.
        self.read(reg::INT_STATUS)?;
        delay.delay_ms(45); // gyro start-up time, datasheet table 1
        Ok(())
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

    /// Set range and output data rate, and check the read-back.
    pub fn configure(&mut self, cfg: Config) -> Result<(), Error<SPI::Error>> {
        let v = ((cfg.full_scale as u8) << 5) | cfg.odr as u8;
        self.write_checked(reg::GYRO_CONFIG0, v)?;
        self.full_scale = FullScale::from_bits(v >> 5);
        self.config = cfg;
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

    /// REG_BANK_SEL, GYRO_CONFIG0 and PWR_MGMT0 as `init` left them.
    fn check_config(&mut self) -> Result<(), ReadFault> {
        let cfg = self.config;
        let want = [
            (reg::REG_BANK_SEL, 0),
            (
                reg::GYRO_CONFIG0,
                ((cfg.full_scale as u8) << 5) | cfg.odr as u8,
            ),
            (reg::PWR_MGMT0, GYRO_MODE_LN),
        ];
        for (r, v) in want {
            if self.read(r).map_err(|_| ReadFault::Bus)? != v {
                return Err(ReadFault::Config);
            }
        }
        Ok(())
    }

    /// `init` in steps: soft reset; 1 ms later identify, configure (with
    /// read-back), start the gyro and clear RESET_DONE; done after the
    /// 45 ms gyro start-up. The configuration is the last one set.
    fn restart(&mut self, step: u8) -> Result<Restart, ReadFault> {
        let bus = |_| ReadFault::Bus;
        match step {
            0 => {
                self.write(reg::DEVICE_CONFIG, SOFT_RESET).map_err(bus)?;
                Ok(Restart::Again {
                    step: 1,
                    wait_us: 1000,
                })
            }
            1 => {
                self.write(reg::REG_BANK_SEL, 0).map_err(bus)?;
                if self.read(reg::WHO_AM_I).map_err(bus)? != WHO_AM_I_VALUE {
                    return Err(ReadFault::BadResponse);
                }
                let cfg = self.config;
                self.configure(cfg).map_err(|_| ReadFault::BadResponse)?;
                self.write_checked(reg::PWR_MGMT0, GYRO_MODE_LN)
                    .map_err(|_| ReadFault::BadResponse)?;
                self.read(reg::INT_STATUS).map_err(bus)?;
                Ok(Restart::Again {
                    step: 2,
                    wait_us: 45_000,
                })
            }
            _ => Ok(Restart::Done),
        }
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

    #[test]
    fn init_resets_checks_id_and_configures() {
        let mut s = Vec::new();
        s.extend(wr(0x11, 0x01)); // DEVICE_CONFIG soft reset
        s.extend(wr(0x76, 0x00)); // bank 0
        s.extend(rd(0x75, &[0x47])); // WHO_AM_I
        s.extend(wr(0x4F, 0x66)); // ±250 °/s (011) | 1 kHz (0110)
        s.extend(rd(0x4F, &[0x66]));
        s.extend(wr(0x4E, 0x0C)); // gyro low-noise
        s.extend(rd(0x4E, &[0x0C]));
        s.extend(rd(0x2D, &[0x10])); // INT_STATUS: clears RESET_DONE
        let mut spi = Mock::new(&s);
        let mut g = Icm42688::new(spi.clone());
        g.init(&mut NoDelay, Config::default()).unwrap();
        assert_eq!(g.full_scale(), FullScale::Dps250);
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
            odr: Odr::Hz1000,
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
        s.extend(wr(0x76, 0x00)); // step 1: bank 0, id, config, gyro on
        s.extend(rd(0x75, &[0x47]));
        s.extend(wr(0x4F, 0x06)); // the configuration set before
        s.extend(rd(0x4F, &[0x06]));
        s.extend(wr(0x4E, 0x0C));
        s.extend(rd(0x4E, &[0x0C]));
        s.extend(rd(0x2D, &[0x10]));
        let mut spi = Mock::new(&s);
        let mut g = Icm42688::new(spi.clone());
        g.config = Config {
            full_scale: FullScale::Dps2000,
            odr: Odr::Hz1000,
        };
        assert_eq!(Gyro::read(&mut g), Err(ReadFault::Reset));
        assert_eq!(
            g.restart(0),
            Ok(Restart::Again {
                step: 1,
                wait_us: 1000
            })
        );
        assert_eq!(
            g.restart(1),
            Ok(Restart::Again {
                step: 2,
                wait_us: 45_000
            })
        );
        assert_eq!(g.restart(2), Ok(Restart::Done));
        spi.done();
    }

    #[test]
    fn config_check_reads_back_three_registers() {
        let mut s = Vec::new();
        s.extend(rd(0x76, &[0x00]));
        s.extend(rd(0x4F, &[0x06])); // ±2000 °/s, 1 kHz: as set
        s.extend(rd(0x4E, &[0x0C]));
        s.extend(rd(0x76, &[0x00]));
        s.extend(rd(0x4F, &[0x66])); // ±250 °/s: not what was set
        let mut spi = Mock::new(&s);
        let mut g = Icm42688::new(spi.clone());
        assert_eq!(g.check_config(), Ok(()));
        assert_eq!(g.check_config(), Err(ReadFault::Config));
        spi.done();
    }

    #[test]
    fn factory_code_formula() {
        assert_eq!(factory_response_lsb(1), 327.5);
        assert!((factory_response_lsb(101) - 327.5 * 1.01f32.powi(100)).abs() < 0.05);
        assert_eq!(factory_response_lsb(0), 0.0);
    }
}
