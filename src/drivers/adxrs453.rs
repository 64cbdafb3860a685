//! The ADXRS453 as the board uses it: the part's driver (the `adxrs453`
//! crate, re-exported here) on one board axis, behind [`Gyro`].

use core::ops::{Deref, DerefMut};

use embedded_hal::spi::SpiDevice;

pub use ::adxrs453::*;

use super::{Gyro, ReadFault, Reading, Restart};

/// The delay the board states for the part, µs: the rate filter's group
/// delay at DC taken as a 2nd-order Butterworth's (√2/ω at
/// [`BANDWIDTH_HZ`]; the datasheet gives the bandwidth, not the order),
/// and one 1 kHz sample period, since each response carries the rate
/// latched at the previous frame.
pub const DELAY_US: u32 = 2904 + 1000;

/// An ADXRS453 mounted along one board axis (0 = x, 1 = y, 2 = z): its
/// one rate in that axis of a [`Reading`]. Everything else is the
/// driver's (`Deref`).
pub struct OnAxis<SPI> {
    chip: Adxrs453<SPI>,
    axis: usize,
}

impl<SPI> OnAxis<SPI> {
    /// `chip` along board axis `axis` (0..=2, clamped).
    pub fn new(chip: Adxrs453<SPI>, axis: usize) -> Self {
        Self {
            chip,
            axis: axis.min(2),
        }
    }
}

impl<SPI> Deref for OnAxis<SPI> {
    type Target = Adxrs453<SPI>;
    fn deref(&self) -> &Adxrs453<SPI> {
        &self.chip
    }
}

impl<SPI> DerefMut for OnAxis<SPI> {
    fn deref_mut(&mut self) -> &mut Adxrs453<SPI> {
        &mut self.chip
    }
}

impl<SPI: SpiDevice> Gyro for OnAxis<SPI> {
    fn temperature_c(&mut self) -> Result<f32, ReadFault> {
        self.chip.read_temperature_c().map_err(|_| ReadFault::Bus)
    }

    fn delay_us(&self) -> u32 {
        DELAY_US
    }

    fn identity(&self) -> (crate::link::msg::Part, u16) {
        (crate::link::msg::Part::Adxrs453, self.chip.pid())
    }

    fn read(&mut self) -> Result<Reading, ReadFault> {
        let d = self.chip.read_sensor().map_err(|e| match e {
            Error::Spi(_) => ReadFault::Bus,
            Error::Parity(_) => ReadFault::Parity,
            // POR set: the part went through a power-on reset and needs
            // its start-up check again (our reading of the POR bit).
            Error::Fault(f) if f & fault::POR != 0 => ReadFault::Reset,
            Error::Fault(f) => ReadFault::ChipFault(f),
            _ => ReadFault::BadResponse,
        })?;
        let mut r = Reading {
            raw: [0; 3],
            rate_dps: [f32::NAN; 3],
            axes: 1 << self.axis,
            saturated: 0,
        };
        // `axis` is clamped to 0..=2 in `new`; `min` lets the compiler see it.
        let axis = self.axis.min(2);
        r.raw[axis] = d.rate;
        r.rate_dps[axis] = d.rate as f32 / LSB_PER_DPS;
        r.saturated = super::saturated_axes(&r.raw);
        Ok(r)
    }

    /// The driver's start-up check in steps, 50 ms apart: a bus error on
    /// the first is the bus's; anything after it, a bad answer.
    fn restart(&mut self, step: u8) -> Result<Restart, ReadFault> {
        match self.chip.restart_step(step) {
            Ok(Step::Again { step, wait_us }) => Ok(Restart::Again { step, wait_us }),
            Ok(Step::Done) => Ok(Restart::Done),
            Err(_) if step == 0 => Err(ReadFault::Bus),
            Err(_) => Err(ReadFault::BadResponse),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_hal_mock::eh1::spi::{Mock, Transaction as T};

    fn frame(mosi: u32, miso: u32) -> [T<u8>; 3] {
        [
            T::transaction_start(),
            T::transfer_in_place(mosi.to_be_bytes().to_vec(), miso.to_be_bytes().to_vec()),
            T::transaction_end(),
        ]
    }

    /// A sensor-data response with valid parity.
    fn data(rate: i16, st: u32, faults: u8) -> u32 {
        let mut r = (st << 26) | ((rate as u16 as u32) << 10) | faults as u32;
        if (r >> 16).count_ones().is_multiple_of(2) {
            r |= 1 << 28;
        }
        if (r & 0xFFFF).count_ones().is_multiple_of(2) {
            r |= 1;
        }
        r
    }

    #[test]
    fn a_reading_on_its_axis_and_faults_in_the_pipelines_terms() {
        let good = data(-160, 0b01, 0);
        let mut s = Vec::new();
        s.extend(frame(0x2000_0000, 0)); // primes the pipeline
        s.extend(frame(0x2000_0000, good));
        s.extend(frame(0x2000_0000, good ^ (1 << 12))); // one flipped bit
        s.extend(frame(0x2000_0000, data(5, 0b01, fault::PLL)));
        s.extend(frame(0x2000_0000, data(5, 0b01, fault::POR)));
        s.extend(frame(0x2000_0000, data(i16::MAX, 0b01, 0)));
        let mut spi = Mock::new(&s);
        let mut g = OnAxis::new(Adxrs453::new(spi.clone()), 2);
        let r = Gyro::read(&mut g).unwrap();
        assert_eq!(r.raw[2], -160);
        assert_eq!(r.rate_dps[2], -2.0);
        assert_eq!(r.axes, 0b100);
        assert!(r.rate_dps[0].is_nan());
        assert_eq!(Gyro::read(&mut g), Err(ReadFault::Parity));
        assert_eq!(Gyro::read(&mut g), Err(ReadFault::ChipFault(fault::PLL)));
        assert_eq!(Gyro::read(&mut g), Err(ReadFault::Reset));
        assert_eq!(Gyro::read(&mut g).unwrap().saturated, 0b100);
        spi.done();
    }
}
