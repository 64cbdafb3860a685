//! Both drivers on an SPI device that answers with arbitrary bytes (a
//! broken, absent or hostile chip): init, reads and restarts return errors,
//! never panic, and a reading that is accepted is finite.
#![no_main]
use embedded_hal::spi::{ErrorKind, ErrorType, Operation, SpiDevice};
use gyro_array::drivers::adxrs453::{Adxrs453, OnAxis};
use gyro_array::drivers::icm42688::{ClockInput, Config, FifoSample, Icm42688, Odr, Sampling};
use gyro_array::drivers::Gyro;
use libfuzzer_sys::fuzz_target;
mod common;
use common::Bytes;

struct Miso<'a>(Bytes<'a>);

#[derive(Debug)]
struct E;
impl embedded_hal::spi::Error for E {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Other
    }
}
impl ErrorType for Miso<'_> {
    type Error = E;
}
impl SpiDevice for Miso<'_> {
    fn transaction(&mut self, ops: &mut [Operation<'_, u8>]) -> Result<(), E> {
        if self.0.u8() == 0xEE {
            return Err(E);
        }
        for op in ops {
            match op {
                Operation::Read(b) => b.iter_mut().for_each(|x| *x = self.0.u8()),
                Operation::Transfer(r, _) => r.iter_mut().for_each(|x| *x = self.0.u8()),
                Operation::TransferInPlace(b) => b.iter_mut().for_each(|x| *x = self.0.u8()),
                Operation::Write(_) | Operation::DelayNs(_) => {}
            }
        }
        Ok(())
    }
}

struct NoDelay;
impl embedded_hal::delay::DelayNs for NoDelay {
    fn delay_ns(&mut self, _: u32) {}
}

fuzz_target!(|data: &[u8]| {
    let which = data.first().copied().unwrap_or(0);
    let spi = Miso(Bytes(data.get(1..).unwrap_or(&[])));
    if which & 3 == 2 {
        // The FIFO path: packets, counts and headers from a hostile chip.
        let mut g = Icm42688::new(spi);
        let cfg = Config {
            odr: Odr::Hz2000,
            clock: if which & 4 == 0 {
                ClockInput::Internal
            } else {
                ClockInput::ClkIn
            },
            sampling: Sampling::Fifo,
            ..Config::default()
        };
        let _ = g.init(&mut NoDelay, cfg);
        let mut buf = [FifoSample {
            raw: [0; 3],
            stamp: 0,
        }; 4];
        for _ in 0..6 {
            if let Ok(r) = g.read_fifo(&mut buf) {
                assert!(r.samples <= buf.len());
            }
            let _ = g.check_config();
        }
    } else if which & 1 == 0 {
        let mut g = Icm42688::new(spi);
        let _ = g.init(&mut NoDelay, Config::default());
        let _ = g.self_test(&mut NoDelay, 1 + (which >> 4) as u16);
        for step in 0..4 {
            let _ = g.restart(step);
            if let Ok(r) = Gyro::read(&mut g) {
                assert!(r.rate_dps.iter().all(|v| v.is_finite()));
            }
        }
    } else {
        let mut g = OnAxis::new(Adxrs453::new(spi), (which >> 1) as usize);
        let _ = g.init(&mut NoDelay);
        for step in 0..4 {
            let _ = g.restart(step);
            if let Ok(r) = Gyro::read(&mut g) {
                assert!(r
                    .rate_dps
                    .iter()
                    .filter(|v| !v.is_nan())
                    .all(|v| v.is_finite()));
            }
        }
    }
});
