//! Analog Devices ADXRS453 single-axis angular rate sensor over SPI (mode 0).
//!
//! Every exchange is one 32-bit full-duplex frame framed by chip select
//! (datasheet rev. B, "SPI communication protocol"). The part is pipelined:
//! the response clocked out during frame *n* answers the command of frame
//! *n − 1*. Commands carry odd parity in bit 0; sensor-data responses carry
//! two parity bits, P0 (bit 28, odd over bits 31:16) and P1 (bit 0, odd over
//! bits 15:0), and the fault bits PLL, Q, NVM, POR, PWR, CST, CHK.
//!
//! ```
//! use adxrs453::{Adxrs453, Error};
//! use embedded_hal::{delay::DelayNs, spi::SpiDevice};
//!
//! /// Run the start-up fault check, then read the rate, °/s.
//! fn rate<SPI: SpiDevice>(spi: SPI, delay: &mut impl DelayNs) -> Result<f32, Error<SPI::Error>> {
//!     let mut gyro = Adxrs453::new(spi);
//!     gyro.init(delay)?;
//!     gyro.read_dps()
//! }
//! ```

#![cfg_attr(not(test), no_std)]
#![deny(unsafe_code)]
#![warn(missing_docs)]

use embedded_hal::delay::DelayNs;
use embedded_hal::spi::SpiDevice;

/// Register addresses (datasheet table "Register map"); 16-bit registers
/// are read at their even (high-byte) address.
#[allow(missing_docs)]
pub mod reg {
    pub const RATE1: u16 = 0x00;
    pub const TEM1: u16 = 0x02;
    pub const LOCST1: u16 = 0x04;
    pub const HICST1: u16 = 0x06;
    pub const QUAD1: u16 = 0x08;
    pub const FAULT1: u16 = 0x0A;
    pub const PID1: u16 = 0x0C;
    pub const SN3: u16 = 0x0E;
}

/// Command opcodes (bits 31:29) and bits.
#[allow(missing_docs)]
pub mod cmd {
    pub const SENSOR_DATA: u32 = 0b001 << 29;
    pub const WRITE: u32 = 0b010 << 29;
    pub const READ: u32 = 0b100 << 29;
    /// Sensor-data request bit that starts the fault-detection check.
    pub const CHK: u32 = 1 << 1;
}

/// Fault bits in the low byte of a sensor-data response.
#[allow(missing_docs)]
pub mod fault {
    pub const PLL: u8 = 1 << 7;
    pub const Q: u8 = 1 << 6;
    pub const NVM: u8 = 1 << 5;
    pub const POR: u8 = 1 << 4;
    pub const PWR: u8 = 1 << 3;
    pub const CST: u8 = 1 << 2;
    pub const CHK: u8 = 1 << 1;
    /// Every fault bit (bits 7:1).
    pub const ALL: u8 = 0xFE;
}

/// Part ID high byte (PID register reads 0x52xx).
pub const PID_HIGH: u8 = 0x52;
/// Sensitivity, LSB per °/s (datasheet table 1).
pub const LSB_PER_DPS: f32 = 80.0;
/// Read response opcode (bits 31:29).
const READ_RESPONSE: u32 = 0b010;
/// Sensor-data status ST[1:0]: valid sensor data.
const ST_VALID: u32 = 0b01;

/// Driver errors, generic over the SPI error.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Error<E> {
    /// SPI transfer failed.
    Spi(E),
    /// A response failed its parity check (raw frame attached).
    Parity(u32),
    /// The response was not the kind the previous command asks for.
    BadResponse(u32),
    /// The sensor reported faults (fault bits attached).
    Fault(u8),
    /// The start-up check (CHK) did not raise and then clear every fault.
    CheckFailed {
        /// Fault bits while the check was forced (should be all).
        forced: u8,
        /// Fault bits after the check (should be none).
        after: u8,
    },
    /// The PID register did not read 0x52xx.
    WrongId(u16),
}

impl<E> Error<E> {
    /// Convert the bus error (e.g. from a `DeviceError` to its bus part).
    pub fn map_spi<F>(self, f: impl FnOnce(E) -> F) -> Error<F> {
        match self {
            Error::Spi(e) => Error::Spi(f(e)),
            Error::Parity(r) => Error::Parity(r),
            Error::BadResponse(r) => Error::BadResponse(r),
            Error::Fault(f) => Error::Fault(f),
            Error::CheckFailed { forced, after } => Error::CheckFailed { forced, after },
            Error::WrongId(v) => Error::WrongId(v),
        }
    }
}

/// What the previous frame asked for, which is what the next response holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Pending {
    Nothing,
    SensorData,
    Register,
}

/// One decoded sensor-data response.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SensorData {
    /// Rate in counts (80 LSB per °/s).
    pub rate: i16,
    /// ST\[1:0\]: 01 valid data, 10 self-test data, 00 invalid.
    pub status: u8,
    /// Fault bits (see [`fault`]).
    pub faults: u8,
}

/// ADXRS453 driver.
pub struct Adxrs453<SPI> {
    spi: SPI,
    pending: Pending,
    /// PID as the last start read it.
    pid: u16,
}

/// One step of a non-blocking restart ([`Adxrs453::restart_step`]).
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
    /// The check passed and the part id read 0x52xx.
    Done,
}

/// True when `v` has an odd number of set bits.
fn odd(v: u32) -> bool {
    v.count_ones() % 2 == 1
}

/// °C of a TEM1/TEM0 register value (see [`Adxrs453::read_temperature_c`]).
pub fn tem_to_c(v: u16) -> f32 {
    let t10 = ((v as i16) >> 6) as f32; // arithmetic shift keeps the sign
    45.0 + t10 / 5.0
}

/// °C to a TEM1/TEM0 register value (the emulated part).
pub fn c_to_tem(c: f32) -> u16 {
    let t10 = ((c - 45.0) * 5.0) as i32;
    (((t10.clamp(-512, 511)) as i16) << 6) as u16
}

/// Add bit 0 so that the command has odd parity.
pub fn with_parity(c: u32) -> u32 {
    let c = c & !1;
    if odd(c) {
        c
    } else {
        c | 1
    }
}

/// Check the two parity bits of a sensor-data response.
pub fn response_parity_ok(r: u32) -> bool {
    odd(r >> 16) && odd(r & 0xFFFF)
}

impl<SPI: SpiDevice> Adxrs453<SPI> {
    /// Wrap an SPI device (mode 0, up to 8 MHz).
    pub fn new(spi: SPI) -> Self {
        Self {
            spi,
            pending: Pending::Nothing,
            pid: 0,
        }
    }

    /// The PID register as the last start read it (0 before one did).
    pub fn pid(&self) -> u16 {
        self.pid
    }

    /// Hand the SPI device back.
    pub fn destroy(self) -> SPI {
        self.spi
    }

    /// The recommended start-up: a sensor-data request with CHK set forces
    /// every fault bit; the next response must show them all and the one
    /// after must be clean. Then the part id must read 0x52xx.
    pub fn init(&mut self, delay: &mut impl DelayNs) -> Result<(), Error<SPI::Error>> {
        delay.delay_ms(100); // power-on time
        self.frame(with_parity(cmd::SENSOR_DATA | cmd::CHK))?;
        delay.delay_ms(50);
        let forced = self.frame(with_parity(cmd::SENSOR_DATA))?;
        delay.delay_ms(50);
        let after = self.frame(with_parity(cmd::SENSOR_DATA))?;
        self.pending = Pending::SensorData;
        let forced = (forced & 0xFF) as u8 & fault::ALL;
        let after = (after & 0xFF) as u8 & fault::ALL;
        if forced != fault::ALL || after != 0 {
            return Err(Error::CheckFailed { forced, after });
        }
        let pid = self.read_register(reg::PID1)?;
        self.pid = pid;
        if (pid >> 8) as u8 != PID_HIGH {
            return Err(Error::WrongId(pid));
        }
        Ok(())
    }

    /// Read a 16-bit register: the read command, then a sensor-data request
    /// that clocks out its answer.
    pub fn read_register(&mut self, addr: u16) -> Result<u16, Error<SPI::Error>> {
        self.frame(with_parity(cmd::READ | ((addr as u32 & 0x1FF) << 17)))?;
        self.pending = Pending::Register;
        let r = self.frame(with_parity(cmd::SENSOR_DATA))?;
        self.pending = Pending::SensorData;
        if !response_parity_ok(r) {
            return Err(Error::Parity(r));
        }
        if r >> 29 != READ_RESPONSE {
            return Err(Error::BadResponse(r));
        }
        Ok(((r >> 5) & 0xFFFF) as u16)
    }

    /// Latest sensor data. In steady state this is one frame whose response
    /// answers the previous request (one sample of latency, as on the part).
    pub fn read_sensor(&mut self) -> Result<SensorData, Error<SPI::Error>> {
        if self.pending != Pending::SensorData {
            self.frame(with_parity(cmd::SENSOR_DATA))?;
            self.pending = Pending::SensorData;
        }
        let r = self.frame(with_parity(cmd::SENSOR_DATA))?;
        if !response_parity_ok(r) {
            return Err(Error::Parity(r));
        }
        let d = SensorData {
            rate: ((r >> 10) & 0xFFFF) as u16 as i16,
            status: ((r >> 26) & 0b11) as u8,
            faults: (r & 0xFF) as u8 & fault::ALL,
        };
        if d.faults != 0 {
            return Err(Error::Fault(d.faults));
        }
        if d.status as u32 != ST_VALID {
            return Err(Error::BadResponse(r));
        }
        Ok(d)
    }

    /// Die temperature, °C, from TEM1/TEM0: a 10-bit two's-complement
    /// value in bits 15:6, 5 LSB/°C, 0 at 45 °C (datasheet, TEM register).
    /// (Analog Devices' no-OS driver computes `((reg >> 6) − 0x31F) / 5`
    /// unsigned, the same below 45 °C and wrong above it.)
    pub fn read_temperature_c(&mut self) -> Result<f32, Error<SPI::Error>> {
        let v = self.read_register(reg::TEM1)?;
        Ok(tem_to_c(v))
    }

    /// Rate in °/s.
    pub fn read_dps(&mut self) -> Result<f32, Error<SPI::Error>> {
        Ok(self.read_sensor()?.rate as f32 / LSB_PER_DPS)
    }

    /// [`Adxrs453::init`]'s start-up check in steps 50 ms apart, for a
    /// caller that keeps sampling other parts meanwhile: call with step 0,
    /// then with each step returned once its wait has passed. Step 0
    /// requests the check (CHK); step 1 finds every fault bit raised;
    /// step 2 finds them cleared and reads the part id.
    pub fn restart_step(&mut self, step: u8) -> Result<Step, Error<SPI::Error>> {
        match step {
            0 => {
                self.frame(with_parity(cmd::SENSOR_DATA | cmd::CHK))?;
                Ok(Step::Again {
                    step: 1,
                    wait_us: 50_000,
                })
            }
            1 => {
                let forced = (self.frame(with_parity(cmd::SENSOR_DATA))? & 0xFF) as u8 & fault::ALL;
                if forced != fault::ALL {
                    return Err(Error::CheckFailed { forced, after: 0 });
                }
                Ok(Step::Again {
                    step: 2,
                    wait_us: 50_000,
                })
            }
            _ => {
                let after = (self.frame(with_parity(cmd::SENSOR_DATA))? & 0xFF) as u8 & fault::ALL;
                self.pending = Pending::SensorData;
                if after != 0 {
                    return Err(Error::CheckFailed {
                        forced: fault::ALL,
                        after,
                    });
                }
                let pid = self.read_register(reg::PID1)?;
                if (pid >> 8) as u8 != PID_HIGH {
                    return Err(Error::WrongId(pid));
                }
                self.pid = pid;
                Ok(Step::Done)
            }
        }
    }

    /// One 32-bit frame, MSB first; returns the response to the previous one.
    fn frame(&mut self, command: u32) -> Result<u32, Error<SPI::Error>> {
        let mut buf = command.to_be_bytes();
        self.spi.transfer_in_place(&mut buf).map_err(Error::Spi)?;
        Ok(u32::from_be_bytes(buf))
    }
}

/// The rate's bandwidth, Hz (datasheet table 1).
pub const BANDWIDTH_HZ: f32 = 77.5;

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_hal::delay::DelayNs;
    use embedded_hal_mock::eh1::spi::{Mock, Transaction as T};

    struct NoDelay;
    impl DelayNs for NoDelay {
        fn delay_ns(&mut self, _: u32) {}
    }

    fn frame(mosi: u32, miso: u32) -> [T<u8>; 3] {
        [
            T::transaction_start(),
            T::transfer_in_place(mosi.to_be_bytes().to_vec(), miso.to_be_bytes().to_vec()),
            T::transaction_end(),
        ]
    }

    /// `r` with its two parity bits set: P0 (bit 28) odd over bits 31:16,
    /// P1 (bit 0) odd over bits 15:0.
    fn with_response_parity(mut r: u32) -> u32 {
        if !odd(r >> 16) {
            r |= 1 << 28;
        }
        if !odd(r & 0xFFFF) {
            r |= 1;
        }
        r
    }

    /// A sensor-data response with valid parity.
    fn data(rate: i16, st: u32, faults: u8) -> u32 {
        with_response_parity((st << 26) | ((rate as u16 as u32) << 10) | faults as u32)
    }

    /// The start-up check as the datasheet runs it and the part id after
    /// it: CHK forced, every fault raised, none, then PID1 read as 0x5201.
    fn startup(s: &mut Vec<T<u8>>) {
        s.extend(frame(0x2000_0003, 0));
        s.extend(frame(0x2000_0000, data(0, 0b00, fault::ALL)));
        s.extend(frame(0x2000_0000, data(0, 0b01, 0)));
        s.extend(frame(0x8018_0000, data(0, 0b01, 0)));
        s.extend(frame(0x2000_0000, read_response(0x5201)));
    }

    /// A read response carrying `v`, with valid parity.
    fn read_response(v: u16) -> u32 {
        with_response_parity((READ_RESPONSE << 29) | (u32::from(v) << 5))
    }

    #[test]
    fn commands_have_odd_parity_as_in_the_datasheet() {
        // The datasheet's start-up command is 0x2000_0003 and the plain
        // sensor-data request 0x2000_0000 (parity bit clear: 0x2 has one 1).
        assert_eq!(with_parity(0x2000_0002), 0x2000_0003);
        assert_eq!(with_parity(0x2000_0000), 0x2000_0000);
        // Read of PID1 (0x0C): 0x8000_0000 | 0x0C << 17 = 0x8018_0000 has
        // three ones, so P stays clear; a read of 0x0E gets P set.
        assert_eq!(with_parity(0x8018_0000), 0x8018_0000);
        assert_eq!(with_parity(0x801C_0000), 0x801C_0001);
    }

    #[test]
    fn init_runs_the_check_then_reads_the_part_id() {
        let mut s = Vec::new();
        startup(&mut s);
        let mut spi = Mock::new(&s);
        let mut g = Adxrs453::new(spi.clone());
        g.init(&mut NoDelay).unwrap();
        spi.done();
    }

    #[test]
    fn a_check_that_does_not_raise_faults_fails_init() {
        let mut s = Vec::new();
        s.extend(frame(0x2000_0003, 0));
        s.extend(frame(0x2000_0000, data(0, 0b01, 0)));
        s.extend(frame(0x2000_0000, data(0, 0b01, 0)));
        let mut spi = Mock::new(&s);
        let mut g = Adxrs453::new(spi.clone());
        assert_eq!(
            g.init(&mut NoDelay),
            Err(Error::CheckFailed {
                forced: 0,
                after: 0
            })
        );
        spi.done();
    }

    #[test]
    fn rate_parity_and_faults() {
        let good = data(-160, 0b01, 0);
        let mut s = Vec::new();
        s.extend(frame(0x2000_0000, 0)); // primes the pipeline
        s.extend(frame(0x2000_0000, good));
        s.extend(frame(0x2000_0000, good ^ (1 << 12))); // one flipped bit
        s.extend(frame(0x2000_0000, data(5, 0b01, fault::PLL)));
        let mut spi = Mock::new(&s);
        let mut g = Adxrs453::new(spi.clone());
        let d = g.read_sensor().unwrap();
        assert_eq!((d.rate, d.status, d.faults), (-160, 0b01, 0));
        assert_eq!(d.rate as f32 / LSB_PER_DPS, -2.0);
        assert_eq!(g.read_sensor(), Err(Error::Parity(good ^ (1 << 12))));
        assert_eq!(g.read_sensor(), Err(Error::Fault(fault::PLL)));
        spi.done();
    }

    #[test]
    fn the_restart_in_steps_is_inits_check() {
        let mut s = Vec::new();
        startup(&mut s);
        // A second restart whose check never raises the faults.
        s.extend(frame(0x2000_0003, 0));
        s.extend(frame(0x2000_0000, data(0, 0b01, 0)));
        let mut spi = Mock::new(&s);
        let mut g = Adxrs453::new(spi.clone());
        assert_eq!(
            g.restart_step(0),
            Ok(Step::Again {
                step: 1,
                wait_us: 50_000
            })
        );
        assert_eq!(
            g.restart_step(1),
            Ok(Step::Again {
                step: 2,
                wait_us: 50_000
            })
        );
        assert_eq!(g.restart_step(2), Ok(Step::Done));
        assert_eq!(g.pid(), 0x5201);
        assert!(g.restart_step(0).is_ok());
        assert_eq!(
            g.restart_step(1),
            Err(Error::CheckFailed {
                forced: 0,
                after: 0
            })
        );
        spi.done();
    }

    #[test]
    fn temperature_register_round_trip() {
        for c in [-40.0f32, 0.0, 25.0, 45.0, 85.0, 105.0] {
            assert!((tem_to_c(c_to_tem(c)) - c).abs() <= 0.2, "{c}");
        }
    }
}
