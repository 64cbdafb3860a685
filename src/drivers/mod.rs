//! embedded-hal 1.0 SPI drivers for the gyro parts on the board.
//!
//! The drivers themselves are crates of their own (`drivers/icm42688p`,
//! `drivers/adxrs453`: anyone with the part can use them); each takes an
//! [`embedded_hal::spi::SpiDevice`] and does one SPI transaction per
//! register access (ADXRS453: one per 32-bit frame). Here, under the same
//! names, each part as the board uses it: behind [`Gyro`], the small trait
//! the sampling pipeline uses (the ADXRS453 on a board axis).

pub mod adxrs453;
pub mod icm42688;

/// Why a gyro read failed, in the pipeline's terms. The drivers' own error
/// types carry the detail; this is what the health logic needs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ReadFault {
    /// The SPI bus or chip select failed.
    Bus,
    /// A frame arrived with bad parity.
    Parity,
    /// The chip reported a fault in its status bits (raw bits attached).
    ChipFault(u8),
    /// The chip answered with something that is not a data frame.
    BadResponse,
    /// The chip has reset itself since it was configured (a brown-out, a
    /// glitch): its configuration is gone and it must be restarted.
    Reset,
    /// A configuration register read back differs from what the driver
    /// set (corrupted): the chip must be restarted.
    Config,
    /// The chip has no sample for the instant asked for (its delay is
    /// longer than the array's: a clock on its RC oscillator, slow). Not a
    /// fault: the sample is neither lost nor counted.
    Late,
    /// The chip is finding its clock again (after a start, a restart, a
    /// gap in its samples), back within a few reads. Not a fault either.
    Acquiring,
}

/// A board timer's capture of a chip's data-ready pulse: the board's
/// clock, µs, of the newest pulse (an input-capture channel on the chip's
/// INT1). `None` before the first.
pub trait SampleCapture {
    /// The newest capture, µs.
    fn last_us(&mut self) -> Option<u32>;
}

/// One step of a non-blocking restart ([`Gyro::restart`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Restart {
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

/// The axes of `raw` at either end of the range (i16::MIN or MAX: a
/// saturated axis), bit `i` for axis `i`: one unsigned compare an axis,
/// the two ends moved to 0 and 1.
#[inline(always)]
pub fn saturated_axes(raw: &[i16; 3]) -> u8 {
    let mut m = 0;
    for (i, r) in raw.iter().enumerate() {
        m |= u8::from((*r as u16).wrapping_add(0x8001) <= 1) << i;
    }
    m
}

/// One reading of a gyro in its native counts and in degrees per second.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Reading {
    /// Raw counts per axis (x, y, z). Axes the part lacks are 0.
    pub raw: [i16; 3],
    /// Rate in °/s per axis. Axes the part lacks are NaN.
    pub rate_dps: [f32; 3],
    /// Bit i set when axis i exists on this part.
    pub axes: u8,
    /// Bit i set when axis i reads at the end of its range.
    pub saturated: u8,
}

/// What the pipeline needs from any gyro chip.
pub trait Gyro {
    /// Read the latest rate sample of every axis the part has.
    fn read(&mut self) -> Result<Reading, ReadFault>;

    /// Restart the chip (reset, identify, configure) without blocking: the
    /// pipeline calls this with step 0, then with each step it returns,
    /// after the wait it asks for, while the other gyros keep sampling.
    /// Each call is a few SPI transactions. An error ends the attempt.
    fn restart(&mut self, step: u8) -> Result<Restart, ReadFault>;

    /// Read the configuration registers back and compare them with what
    /// the driver set (the pipeline does this for one gyro at a time, at a
    /// low rate). Parts without configuration have nothing to check.
    fn check_config(&mut self) -> Result<(), ReadFault> {
        Ok(())
    }

    /// Die temperature, °C, for the bias-versus-temperature calibration
    /// (read at a low rate). Parts without a sensor answer `BadResponse`.
    fn temperature_c(&mut self) -> Result<f32, ReadFault> {
        Err(ReadFault::BadResponse)
    }

    /// The part, and its identity register as the last start read it (0
    /// before a start read it).
    fn identity(&self) -> (crate::link::msg::Part, u16) {
        (crate::link::msg::Part::Unknown, 0)
    }

    /// How long before its read a reading's rate was the true rate, µs:
    /// the part's filters and how old its newest sample is, as the part's
    /// configuration and datasheet give them (an ideal sampler: 0).
    fn delay_us(&self) -> u32 {
        0
    }

    /// Aim the next read at one instant of the array: `at` on the board's
    /// clock (1/16 µs: `pipeline::clock::Instant16`), `behind_us` before
    /// the read, with the part's signal path `path_trim_us` longer than
    /// its datasheet's reading (`link::msg::Settings::path_trim_us`). A
    /// gyro that reads its newest sample whatever the instant ignores it.
    fn aim(&mut self, _at: u32, _behind_us: u32, _path_trim_us: i16) {}
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_ranges_ends_are_saturated() {
        for (r, end) in [
            (i16::MIN, true),
            (i16::MAX, true),
            (i16::MIN + 1, false),
            (i16::MAX - 1, false),
            (0, false),
            (-1, false),
            (1, false),
        ] {
            assert_eq!(saturated_axes(&[0, r, 0]), u8::from(end) << 1, "{r}");
        }
        assert_eq!(saturated_axes(&[i16::MAX, 5, i16::MIN]), 0b101);
    }
}
