//! Settings kept across a reset: the link's output settings and the
//! calibration record in use, in a key-value map over two flash sectors
//! (`sequential-storage`: each save appends an item with its own CRC, the
//! newest of a key wins, a full sector is moved on and erased, so a save
//! erases nothing most of the time and the sectors wear evenly; an item
//! cut by a power loss fails its CRC and the one before it stands).
//!
//! What is stored is checked again when it is read: the settings item
//! carries its format, decodes with postcard and must pass
//! [`Settings::check`], the calibration item is the record's own bytes
//! (magic, version, CRC-32: [`CalRecord::decode`]). Anything that fails
//! reads as [`StoreState::Corrupt`] and the defaults come up; the next save
//! writes over it. A save is read back before it is acknowledged.
//!
//! On the board the store is the MCU's flash (sectors 9 and 10, 2 ×
//! 128 KiB, `STORE` in memory.x). The STM32F405 has one flash bank: while a
//! byte is programmed (16 µs typical, datasheet table 39) or a sector
//! erased (1–2 s), every fetch from flash waits, the sample task's
//! included; so the board saves only when the controller asks, and the
//! samples that could not be taken meanwhile are counted as overruns. A
//! save writes the calibration record only when it changed, so it is
//! some 30 bytes (about 0.5 ms); an erase comes once in the some 3 000
//! saves that fill a sector.

use core::ops::Range;

use embassy_futures::block_on;
use embedded_storage_async::nor_flash::MultiwriteNorFlash;
use sequential_storage::cache::{Cache, Uncached};
use sequential_storage::map::{MapConfig, MapStorage, PostcardValue};
use serde::{Deserialize, Serialize};

use crate::algo::static_cal::{self, CalError, CalRecord};
use crate::link::msg::{Settings, StoreState};

/// The settings item's key.
pub const SETTINGS_KEY: u8 = 1;
/// The calibration record's key.
pub const CALIBRATION_KEY: u8 = 2;
/// The settings item's format: a change in [`Settings`] raises it, and an
/// item of another format reads as corrupt (the defaults come up).
pub const FORMAT: u16 = 2;

/// Scratch for one item: its key and the largest value (a calibration
/// record), rounded up.
const BUF: usize = (1 + static_cal::MAX_LEN).next_multiple_of(16);

#[derive(Serialize, Deserialize)]
struct SettingsItem {
    format: u16,
    settings: Settings,
}

impl PostcardValue<'_> for SettingsItem {}

/// Why a save or a clear failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StoreError {
    /// The flash reported an error.
    Flash,
    /// The map is full (only if items larger than a sector were stored).
    Full,
    /// What was written did not read back the same.
    Verify,
    /// The map could not be read (neither erased nor written by this
    /// store).
    Corrupt,
    /// The record does not encode (it cannot: a calibration record is
    /// bounded).
    Encode,
}

/// What the store gave at boot.
#[derive(Clone, Debug, PartialEq)]
pub struct Loaded {
    /// The settings to start with (the defaults unless a good record was
    /// read).
    pub settings: Settings,
    /// What the store holds.
    pub state: StoreState,
    /// The calibration record saved with the settings: `None` when none
    /// was saved (the lab's record in the calibration sector then
    /// applies), or why the saved one cannot be used.
    pub calibration: Option<Result<CalRecord, CalError>>,
}

/// The settings store over a flash `F`.
pub struct Store<F: MultiwriteNorFlash> {
    map: MapStorage<u8, F, Cache<Uncached, Uncached, Uncached, u8>>,
    buf: [u8; BUF],
    state: StoreState,
}

impl<F: MultiwriteNorFlash> Store<F> {
    /// A store over `range` of `flash` (whole erase sectors, at least two);
    /// `None` if the range cannot hold one.
    pub fn new(flash: F, range: Range<u32>) -> Option<Self> {
        let config = MapConfig::try_new(range).ok()?;
        Some(Self {
            map: MapStorage::new(flash, config, Cache::new_uncached()),
            buf: [0; BUF],
            state: StoreState::Defaults,
        })
    }

    /// What the store holds now.
    pub fn state(&self) -> StoreState {
        self.state
    }

    /// The flash, back.
    pub fn into_flash(self) -> F {
        self.map.destroy().0
    }

    /// Read the stored settings and calibration record (at boot).
    pub fn load(&mut self) -> Loaded {
        let settings = match block_on(
            self.map
                .fetch_item::<SettingsItem>(&mut self.buf, &SETTINGS_KEY),
        ) {
            Ok(Some(item)) if item.format == FORMAT && item.settings.check().is_ok() => {
                Ok(Some(item.settings))
            }
            Ok(None) => Ok(None),
            _ => Err(()),
        };
        let calibration = match block_on(
            self.map
                .fetch_item::<&[u8]>(&mut self.buf, &CALIBRATION_KEY),
        ) {
            Ok(Some(bytes)) => Some(CalRecord::decode(bytes)),
            Ok(None) => None,
            Err(_) => Some(Err(CalError::Crc)),
        };
        let (settings, state) = match settings {
            Ok(Some(s)) => (s, StoreState::Stored),
            Ok(None) => (Settings::default(), StoreState::Defaults),
            Err(()) => (Settings::default(), StoreState::Corrupt),
        };
        self.state = state;
        Loaded {
            settings,
            state,
            calibration,
        }
    }

    /// Save `settings` and `calibration` (when given), and read both back.
    pub fn save(
        &mut self,
        settings: &Settings,
        calibration: Option<&CalRecord>,
    ) -> Result<(), StoreError> {
        let item = SettingsItem {
            format: FORMAT,
            settings: *settings,
        };
        let r = self.put(&item, calibration);
        // A map the crate found corrupt (a record of another layout, a
        // sector neither erased nor written) is erased once and written
        // again: the save is what the controller asked for.
        let r = match r {
            Err(StoreError::Corrupt) => {
                block_on(self.map.erase_all()).map_err(|_| StoreError::Flash)?;
                self.put(&item, calibration)
            }
            r => r,
        };
        self.state = if r.is_ok() {
            StoreState::Stored
        } else {
            StoreState::Corrupt
        };
        r
    }

    fn put(
        &mut self,
        item: &SettingsItem,
        calibration: Option<&CalRecord>,
    ) -> Result<(), StoreError> {
        use sequential_storage::Error as E;
        let map_err = |e: E<F::Error>| match e {
            E::FullStorage | E::ItemTooBig => StoreError::Full,
            E::Corrupted { .. } => StoreError::Corrupt,
            _ => StoreError::Flash,
        };
        if let Some(rec) = calibration {
            let mut bytes = [0u8; static_cal::MAX_LEN];
            let n = rec.encode(&mut bytes).map_err(|_| StoreError::Encode)?;
            let same = matches!(
                block_on(self.map.fetch_item::<&[u8]>(&mut self.buf, &CALIBRATION_KEY)),
                Ok(Some(b)) if b == &bytes[..n]
            );
            // The record changes rarely: written again only when it has,
            // so a save is some 30 bytes, not 400.
            if !same {
                block_on(
                    self.map
                        .store_item(&mut self.buf, &CALIBRATION_KEY, &&bytes[..n]),
                )
                .map_err(map_err)?;
                match block_on(
                    self.map
                        .fetch_item::<&[u8]>(&mut self.buf, &CALIBRATION_KEY),
                ) {
                    Ok(Some(b)) if b == &bytes[..n] => {}
                    _ => return Err(StoreError::Verify),
                }
            }
        }
        block_on(self.map.store_item(&mut self.buf, &SETTINGS_KEY, item)).map_err(map_err)?;
        match block_on(
            self.map
                .fetch_item::<SettingsItem>(&mut self.buf, &SETTINGS_KEY),
        ) {
            Ok(Some(back)) if back.format == item.format && back.settings == item.settings => {
                Ok(())
            }
            _ => Err(StoreError::Verify),
        }
    }

    /// Erase what is saved (a factory reset): the next boot comes up with
    /// the defaults and the lab's calibration record.
    pub fn clear(&mut self) -> Result<(), StoreError> {
        let r = match block_on(self.map.remove_all_items(&mut self.buf)) {
            Ok(()) => Ok(()),
            // Nothing readable to mark removed: erase the sectors.
            Err(_) => block_on(self.map.erase_all()).map_err(|_| StoreError::Flash),
        };
        self.state = if r.is_ok() {
            StoreState::Defaults
        } else {
            StoreState::Corrupt
        };
        r
    }
}

#[cfg(test)]
mod tests;
