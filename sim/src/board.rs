//! The emulated board's wiring: each chip's driver on the one emulated bus
//! behind its own chip-select, as `board-f405` wires the real ones (chips
//! 0–3 the ICM-42688-Ps, chip 4 the ADXRS453 on z). The demo, the bench and
//! the host/target checks build their array here.

use core::cell::RefCell;

use embedded_hal_bus::spi::{NoDelay, RefCellDevice};

use super::{CsLine, EmuBus, EmuCs};
use gyro_array::drivers::adxrs453::{Adxrs453, OnAxis};
use gyro_array::drivers::icm42688::Icm42688;

/// One chip's SPI device on an emulated bus of `N` chips (the board's five
/// by default).
pub type EmuDevice<'a, 'c, const N: usize = 5> =
    RefCellDevice<'a, EmuBus<'c, N>, EmuCs<'c>, NoDelay>;

/// The SPI device of the chip behind `cs` on `bus`: what every harness of
/// the emulated chips, of any array size, talks through.
pub fn emu_device<'a, 'c, const N: usize>(
    bus: &'a RefCell<EmuBus<'c, N>>,
    cs: &'c CsLine,
) -> EmuDevice<'a, 'c, N> {
    // An emulated chip-select cannot fail (its error is `Infallible`).
    let Ok(d) = RefCellDevice::new_no_delay(bus, EmuCs(cs));
    d
}

/// The board's five drivers, not yet started.
pub struct BoardDrivers<'a, 'c> {
    /// The four ICM-42688-P, chips 0–3.
    pub icm: [Icm42688<EmuDevice<'a, 'c>>; 4],
    /// The ADXRS453, chip 4.
    pub adx: OnAxis<EmuDevice<'a, 'c>>,
}

/// The drivers of the board's array on `bus`, chip `i` behind `cs[i]`.
pub fn board_drivers<'a, 'c>(
    bus: &'a RefCell<EmuBus<'c, 5>>,
    cs: &'c [CsLine; 5],
) -> BoardDrivers<'a, 'c> {
    let dev = |i: usize| emu_device(bus, &cs[i]);
    BoardDrivers {
        icm: [0, 1, 2, 3].map(|i| Icm42688::new(dev(i))),
        // The ADXRS453 measures the board's z axis (2).
        adx: OnAxis::new(Adxrs453::new(dev(4)), 2),
    }
}
