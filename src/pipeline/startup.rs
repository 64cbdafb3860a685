//! Bring-up of the board's array, shared by the firmware, the QEMU demo and
//! the self-checks: gyros 0–3 are ICM-42688-P (init, then the datasheet
//! self-test), gyro 4 is the ADXRS453 (CHK start-up). A gyro that fails is
//! logged and marked in the pipeline, which then never offers it to fusion.

use embedded_hal::delay::DelayNs;
use embedded_hal::spi::SpiDevice;

use super::Pipeline;
use crate::drivers::adxrs453::Adxrs453;
use crate::drivers::icm42688::{Config, Icm42688};

/// What the log needs of a bus error: `defmt::Format` with the defmt
/// feature, nothing without it (the host tests).
#[cfg(feature = "defmt")]
pub trait Loggable: defmt::Format {}
#[cfg(feature = "defmt")]
impl<T: defmt::Format> Loggable for T {}
/// What the log needs of a bus error (nothing without defmt).
#[cfg(not(feature = "defmt"))]
pub trait Loggable {}
#[cfg(not(feature = "defmt"))]
impl<T> Loggable for T {}

/// Start the array. `self_test` is the number of samples per ICM-42688-P
/// self-test phase, or `None` to skip it. Returns the mask of gyros that
/// failed (also marked in `pipe`).
pub fn start_array<SPI: SpiDevice>(
    icm: [&mut Icm42688<SPI>; 4],
    adx: &mut Adxrs453<SPI>,
    delay: &mut impl DelayNs,
    self_test: Option<u16>,
    pipe: &mut Pipeline<5>,
) -> u8
where
    SPI::Error: Loggable,
{
    let mut failed = 0u8;
    for (i, g) in icm.into_iter().enumerate() {
        let r = g
            .init(delay, Config::default())
            .and_then(|_| match self_test {
                Some(n) => g.self_test(delay, n).map(Some),
                None => Ok(None),
            });
        match r {
            Ok(_st) =>
            {
                #[cfg(feature = "defmt")]
                match _st {
                    Some(st) => {
                        defmt::info!("gyro {}: ICM-42688-P ok, self-test ratio {}", i, st.ratio())
                    }
                    None => defmt::info!("gyro {}: ICM-42688-P ok", i),
                }
            }
            Err(_e) => {
                #[cfg(feature = "defmt")]
                defmt::error!("gyro {}: ICM-42688-P init failed: {}", i, _e);
                pipe.mark_init_failed(i);
                failed |= 1 << i;
            }
        }
    }
    match adx.init(delay) {
        Ok(()) => {
            #[cfg(feature = "defmt")]
            defmt::info!("gyro 4: ADXRS453 ok (CHK passed, PID 0x52xx) on z");
        }
        Err(_e) => {
            #[cfg(feature = "defmt")]
            defmt::error!("gyro 4: ADXRS453 init failed: {}", _e);
            pipe.mark_init_failed(4);
            failed |= 1 << 4;
        }
    }
    failed
}
