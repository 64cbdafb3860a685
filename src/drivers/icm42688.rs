//! The ICM-42688-P as the board uses it: the part's driver (the
//! `icm42688p` crate, re-exported here) behind [`Gyro`].

use embedded_hal::spi::SpiDevice;

pub use ::icm42688p::*;

use super::{Gyro, ReadFault, Reading, Restart};

/// The board's filters at 1 kHz with the data registers polled (the
/// driver's [`Config::default`]): ArduPilot's, the least aliasing of the
/// flight stacks' at that rate (`timing-eval`).
pub const BOARD_FILTER: Filter = Filter::ARDUPILOT;

/// The ODR the board samples its ICM-42688-Ps at through their FIFOs:
/// four samples a millisecond (see [`BOARD_FILTER_FIFO`]).
pub const BOARD_FIFO_ODR: Odr = Odr::Hz4000;

/// The board's filters for FIFO sampling at [`BOARD_FIFO_ODR`], averaged
/// in fours to the 1 kHz output: AAF at 394 Hz, UI filter of 2nd order at
/// ODR/8 (500 Hz). It aliases no more than ArduPilot's and PX4's at any
/// out-of-band tone measured, and of the settings that do, it reaches the
/// wire soonest at 4 kHz; at 2 kHz the fastest such setting takes 200 µs
/// longer, past the 2 ms the antenna allows (`timing-eval`; its `--search`
/// weighs every setting the driver can write at 2, 4 and 8 kHz,
/// `docs/timing.md`).
pub const BOARD_FILTER_FIFO: Filter = Filter {
    aaf_delt: 9,
    ui_order: 2,
    ui_bw: 3,
};

/// The board's FIFO sampling ([`BOARD_FIFO_ODR`] through
/// [`BOARD_FILTER_FIFO`], ±250 °/s) on clock `clock`.
pub const fn board_fifo(clock: ClockInput) -> Config {
    Config {
        full_scale: FullScale::Dps250,
        odr: BOARD_FIFO_ODR,
        filter: BOARD_FILTER_FIFO,
        clock,
        sampling: Sampling::Fifo,
    }
}

impl<SPI: SpiDevice> Gyro for Icm42688<SPI> {
    /// The data registers: a silent reset (RESET_DONE in the same burst)
    /// is [`ReadFault::Reset`]; a count at either end of the range marks
    /// its axis saturated.
    fn read(&mut self) -> Result<Reading, ReadFault> {
        let (raw, status) = self.read_sample().map_err(|_| ReadFault::Bus)?;
        if status & RESET_DONE != 0 {
            return Err(ReadFault::Reset);
        }
        let s = self.full_scale().lsb_per_dps();
        let saturated = super::saturated_axes(&raw);
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

    fn delay_us(&self) -> u32 {
        self.polled_delay_us()
    }

    fn identity(&self) -> (crate::link::msg::Part, u16) {
        (
            crate::link::msg::Part::Icm42688P,
            u16::from(self.who_am_i()),
        )
    }

    /// The driver's check, a group at a time: a bus error is the bus's, a
    /// register that differs (or a configuration without its bank 1) a
    /// corrupted configuration.
    fn check_config(&mut self) -> Result<(), ReadFault> {
        Icm42688::check_config(self).map_err(|e| match e {
            Error::Spi(_) => ReadFault::Bus,
            _ => ReadFault::Config,
        })
    }

    /// The driver's restart in steps of at most six transactions. Why it
    /// failed does not matter to the pipeline, which tries again later.
    fn restart(&mut self, step: u8) -> Result<Restart, ReadFault> {
        match self.restart_step(step) {
            Ok(Step::Again { step, wait_us }) => Ok(Restart::Again { step, wait_us }),
            Ok(Step::Done) => Ok(Restart::Done),
            Err(Error::Spi(_)) => Err(ReadFault::Bus),
            Err(_) => Err(ReadFault::BadResponse),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_hal_mock::eh1::spi::{Mock, Transaction as T};

    fn rd(addr: u8, v: &[u8]) -> [T<u8>; 4] {
        [
            T::transaction_start(),
            T::write_vec(vec![0x80 | addr]),
            T::read_vec(v.to_vec()),
            T::transaction_end(),
        ]
    }

    #[test]
    fn a_reading_in_the_pipelines_terms() {
        let mut s = Vec::new();
        // GYRO_DATA_X1..Z0, TMST (2), INT_STATUS: ±2000 °/s as `new` sets.
        s.extend(rd(
            0x25,
            &[0x00, 0x83, 0xFF, 0x7D, 0x7F, 0xFF, 0x12, 0x34, 0x08],
        ));
        // RESET_DONE: the chip reset since it was set up.
        s.extend(rd(0x25, &[0x80, 0x00, 0x80, 0x00, 0x80, 0x00, 0, 0, 0x10]));
        // The core of the configuration check, AFSR back on.
        s.extend(rd(0x76, &[0x00]));
        s.extend(rd(0x4C, &[0x30, 0x91, 0x0C, 0x06, 0x06, 0x16, 0x11]));
        let mut spi = Mock::new(&s);
        let mut g = Icm42688::new(spi.clone());
        let r = Gyro::read(&mut g).unwrap();
        assert_eq!(r.raw, [131, -131, 32767]);
        assert_eq!(r.rate_dps[0], 131.0 / 16.4);
        assert_eq!((r.axes, r.saturated), (0b111, 0b100));
        assert_eq!(Gyro::read(&mut g), Err(ReadFault::Reset));
        assert_eq!(Gyro::check_config(&mut g), Err(ReadFault::Config));
        spi.done();
    }
}
