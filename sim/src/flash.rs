//! NOR flash as the STM32F4's (RM0090 section 3.6, "Embedded Flash
//! memory"): an erase sets every bit of a sector to 1; programming can only
//! turn bits from 1 to 0, a byte at a time (PSIZE x8, as stm32f4xx-hal
//! programs it), and a byte already programmed may be programmed again to
//! clear more bits (the F4 has no ECC on its flash words, so stm32f4xx-hal
//! declares it `MultiwriteNorFlash`).
//!
//! Power can be cut at any step (one byte programmed, or one sector
//! erased). The datasheet does not say what a cell reads after an
//! interrupted program or erase, so the step that is cut takes the most
//! general reading: a byte being programmed keeps a random part of the
//! bits it was clearing, a sector being erased has a random part of its
//! bits set; every later step fails until [`NorSim::power_on`]. Over
//! `&mut [u8]`: an array in a host test, or RAM kept across a reset on
//! QEMU's board (which models no flash controller).

use embedded_storage_async::nor_flash::{
    ErrorType, MultiwriteNorFlash, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

use super::Rng;

/// Why a flash operation failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FlashError {
    /// Outside the flash.
    OutOfBounds,
    /// An erase not on sector boundaries.
    NotAligned,
    /// The power was cut (this step or an earlier one).
    PowerLost,
}

impl NorFlashError for FlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            Self::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            Self::NotAligned => NorFlashErrorKind::NotAligned,
            Self::PowerLost => NorFlashErrorKind::Other,
        }
    }
}

/// An emulated NOR flash of sectors of `SECTOR` bytes.
pub struct NorSim<'a, const SECTOR: usize> {
    mem: &'a mut [u8],
    /// Steps left before the power fails (`None`: it never does).
    steps_left: Option<u32>,
    dead: bool,
    rng: Rng,
    /// Bytes programmed since made.
    pub programmed: u32,
    /// Sectors erased since made.
    pub erased: u32,
}

impl<'a, const SECTOR: usize> NorSim<'a, SECTOR> {
    /// A flash over `mem` (its length a whole number of sectors) as it is:
    /// what a board finds after a reset.
    pub fn new(mem: &'a mut [u8], seed: u64) -> Self {
        Self {
            mem,
            steps_left: None,
            dead: false,
            rng: Rng::new(seed),
            programmed: 0,
            erased: 0,
        }
    }

    /// Cut the power at the `step`-th program or erase step from now (0:
    /// the next one).
    pub fn cut_power_at(&mut self, step: u32) {
        self.steps_left = Some(step);
    }

    /// Power back: the cells keep what they hold.
    pub fn power_on(&mut self) {
        self.steps_left = None;
        self.dead = false;
    }

    /// Whether the power was cut.
    pub fn power_lost(&self) -> bool {
        self.dead
    }

    /// The cells.
    pub fn cells(&self) -> &[u8] {
        self.mem
    }

    /// One program or erase step: `Ok(true)` when it completes, `Ok(false)`
    /// when the power goes during it.
    fn step(&mut self) -> Result<bool, FlashError> {
        if self.dead {
            return Err(FlashError::PowerLost);
        }
        match self.steps_left {
            Some(0) => {
                self.dead = true;
                Ok(false)
            }
            Some(ref mut n) => {
                *n -= 1;
                Ok(true)
            }
            None => Ok(true),
        }
    }

    fn range(&self, offset: u32, len: usize) -> Result<core::ops::Range<usize>, FlashError> {
        let start = offset as usize;
        let end = start.checked_add(len).ok_or(FlashError::OutOfBounds)?;
        if end > self.mem.len() {
            return Err(FlashError::OutOfBounds);
        }
        Ok(start..end)
    }
}

impl<const SECTOR: usize> ErrorType for NorSim<'_, SECTOR> {
    type Error = FlashError;
}

impl<const SECTOR: usize> ReadNorFlash for NorSim<'_, SECTOR> {
    const READ_SIZE: usize = 1;

    fn read(
        &mut self,
        offset: u32,
        bytes: &mut [u8],
    ) -> impl core::future::Future<Output = Result<(), FlashError>> {
        // (Answered at once: no `async fn`, whose resumed-after-completion
        // check would be a panic site in the firmware.)
        core::future::ready((|| {
            if self.dead {
                return Err(FlashError::PowerLost);
            }
            let r = self.range(offset, bytes.len())?;
            bytes.copy_from_slice(&self.mem[r]);
            Ok(())
        })())
    }

    fn capacity(&self) -> usize {
        self.mem.len()
    }
}

impl<const SECTOR: usize> NorFlash for NorSim<'_, SECTOR> {
    const WRITE_SIZE: usize = 1;
    const ERASE_SIZE: usize = SECTOR;

    fn erase(
        &mut self,
        from: u32,
        to: u32,
    ) -> impl core::future::Future<Output = Result<(), FlashError>> {
        // (Answered at once: no `async fn`, whose resumed-after-completion
        // check would be a panic site in the firmware.)
        core::future::ready((|| {
            if !(from as usize).is_multiple_of(SECTOR)
                || !(to as usize).is_multiple_of(SECTOR)
                || to < from
            {
                return Err(FlashError::NotAligned);
            }
            let r = self.range(from, (to - from) as usize)?;
            for s in r.step_by(SECTOR) {
                let whole = self.step()?;
                for b in &mut self.mem[s..s + SECTOR] {
                    *b = if whole {
                        0xFF
                    } else {
                        *b | self.rng.next_u32() as u8
                    };
                }
                if !whole {
                    return Err(FlashError::PowerLost);
                }
                self.erased += 1;
            }
            Ok(())
        })())
    }

    fn write(
        &mut self,
        offset: u32,
        bytes: &[u8],
    ) -> impl core::future::Future<Output = Result<(), FlashError>> {
        // (Answered at once: no `async fn`, whose resumed-after-completion
        // check would be a panic site in the firmware.)
        core::future::ready((|| {
            let r = self.range(offset, bytes.len())?;
            for (cell, &b) in self.mem[r].iter_mut().zip(bytes) {
                // (Inlined step: `self` is borrowed by the cells.)
                if self.dead {
                    return Err(FlashError::PowerLost);
                }
                let whole = match self.steps_left {
                    Some(0) => {
                        self.dead = true;
                        false
                    }
                    Some(ref mut n) => {
                        *n -= 1;
                        true
                    }
                    None => true,
                };
                if whole {
                    *cell &= b;
                    self.programmed += 1;
                } else {
                    // Part of the bits being cleared are cleared.
                    *cell &= b | self.rng.next_u32() as u8;
                    return Err(FlashError::PowerLost);
                }
            }
            Ok(())
        })())
    }
}

impl<const SECTOR: usize> MultiwriteNorFlash for NorSim<'_, SECTOR> {}

#[cfg(test)]
mod tests {
    use super::*;
    use embassy_futures::block_on;

    #[test]
    fn programming_only_clears_bits_and_a_cut_step_is_partial() {
        let mut mem = [0u8; 512];
        let mut f = NorSim::<256>::new(&mut mem, 1);
        block_on(f.erase(0, 512)).unwrap();
        assert!(f.cells().iter().all(|&b| b == 0xFF));
        block_on(f.write(3, &[0x0F])).unwrap();
        // Bits cannot be set again by programming.
        block_on(f.write(3, &[0xF3])).unwrap();
        assert_eq!(f.cells()[3], 0x03);
        assert_eq!(block_on(f.erase(1, 256)), Err(FlashError::NotAligned));
        assert_eq!(
            block_on(f.write(511, &[0, 0])),
            Err(FlashError::OutOfBounds)
        );
        // The power goes at the third byte: two written, the third partly,
        // nothing after.
        f.cut_power_at(2);
        assert_eq!(
            block_on(f.write(10, &[0, 0, 0, 0])),
            Err(FlashError::PowerLost)
        );
        assert_eq!(&f.cells()[10..12], &[0, 0]);
        assert_eq!(f.cells()[13], 0xFF);
        assert_eq!(block_on(f.read(0, &mut [0])), Err(FlashError::PowerLost));
        f.power_on();
        // A cut erase leaves a sector with only part of its bits set.
        f.cut_power_at(0);
        assert_eq!(block_on(f.erase(0, 256)), Err(FlashError::PowerLost));
        assert!(
            !f.cells()[..256].iter().all(|&b| b == 0xFF),
            "a whole erase reads 0xFF"
        );
    }
}
