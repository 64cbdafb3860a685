use super::*;
use crate::algo::static_cal::ChipCal;
use crate::link::msg::{Compensation, FusionMethod, Mode};
use gyro_sim::flash::NorSim;
use heapless::Vec;

/// Three sectors of 1 KiB: a calibration record (about 340 B) and the
/// settings fill one in two or three saves, so the saves below move the
/// map on and erase sectors many times.
const SECTOR: usize = 1024;
const SIZE: usize = 3 * SECTOR;

fn store(mem: &mut [u8]) -> Store<NorSim<'_, SECTOR>> {
    Store::new(NorSim::new(mem, 7), 0..SIZE as u32).unwrap()
}

fn settings(i: u32) -> Settings {
    Settings {
        mode: if i.is_multiple_of(2) {
            Mode::Fused
        } else {
            Mode::Raw
        },
        method: [
            FusionMethod::Mean,
            FusionMethod::Zhang,
            FusionMethod::Adaptive,
        ][i as usize % 3],
        divider: 1 + (i % 1000) as u16,
        status_every: 100 + i,
        compensation: Compensation::Horizon((i % 10_000) as u16),
        angle: i % 3 == 1,
        path_trim_us: (i % 1601) as i16 - 800,
    }
}

fn record(serial: u32) -> CalRecord {
    let mut chips = Vec::new();
    for k in 0..5 {
        let f = serial as f32 + k as f32;
        let _ = chips.push(ChipCal {
            m: [[1.0 + f * 1e-3, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            bias_dps: [f, -f, 0.5],
            bias_tc_dps_per_c: [0.01; 3],
            t_ref_c: 25.0,
        });
    }
    CalRecord { serial, chips }
}

#[test]
fn a_saved_record_comes_back_at_the_next_boot() {
    let mut mem = [0xFFu8; SIZE];
    let loaded = store(&mut mem).load();
    assert_eq!(loaded.state, StoreState::Defaults);
    assert_eq!(loaded.settings, Settings::default());
    assert_eq!(loaded.calibration, None);
    store(&mut mem)
        .save(&settings(5), Some(&record(5)))
        .unwrap();
    let loaded = store(&mut mem).load();
    assert_eq!(loaded.state, StoreState::Stored);
    assert_eq!(loaded.settings, settings(5));
    assert_eq!(loaded.calibration, Some(Ok(record(5))));
    // The same record again: only the settings item is written.
    let mut s = store(&mut mem);
    s.save(&settings(6), Some(&record(5))).unwrap();
    let programmed = s.into_flash().programmed;
    assert!(programmed < 48, "{programmed} bytes for a settings save");
    assert_eq!(boot(&mut mem), (StoreState::Stored, settings(6), Some(5)));
    // A factory reset: the defaults at the next boot.
    let mut s = store(&mut mem);
    s.clear().unwrap();
    assert_eq!(s.state(), StoreState::Defaults);
    let loaded = store(&mut mem).load();
    assert_eq!(loaded.state, StoreState::Defaults);
    assert_eq!(loaded.settings, Settings::default());
    assert_eq!(loaded.calibration, None);
}

#[test]
fn storage_never_written_comes_up_with_the_defaults_and_takes_a_save() {
    // RAM cleared at power-up (QEMU's board) or a sector of another use.
    for fill in [0x00u8, 0x5A] {
        let mut mem = [fill; SIZE];
        let loaded = store(&mut mem).load();
        assert_eq!(loaded.settings, Settings::default(), "fill {fill:#x}");
        assert_ne!(loaded.state, StoreState::Stored, "fill {fill:#x}");
        store(&mut mem).save(&settings(9), None).unwrap();
        let loaded = store(&mut mem).load();
        assert_eq!(loaded.state, StoreState::Stored, "fill {fill:#x}");
        assert_eq!(loaded.settings, settings(9));
    }
}

#[test]
fn out_of_range_settings_are_not_saved_as_good() {
    // The store is only given checked settings, but a record of a range
    // the firmware no longer takes must read as corrupt, not be used.
    let mut mem = [0xFFu8; SIZE];
    let mut bad = settings(1);
    bad.divider = 0;
    store(&mut mem).save(&bad, None).unwrap();
    let loaded = store(&mut mem).load();
    assert_eq!(loaded.state, StoreState::Corrupt);
    assert_eq!(loaded.settings, Settings::default());
}

/// What the store reads after a boot: the settings, and the calibration
/// record's serial (or `None`).
fn boot(mem: &mut [u8]) -> (StoreState, Settings, Option<u32>) {
    let l = store(mem).load();
    let serial = l
        .calibration
        .map(|r| r.expect("a calibration record read as bad").serial);
    (l.state, l.settings, serial)
}

#[test]
fn a_power_cut_at_every_step_of_a_save_leaves_the_old_record_or_the_new() {
    let mut mem = [0xFFu8; SIZE];
    store(&mut mem)
        .save(&settings(0), Some(&record(0)))
        .unwrap();
    let mut cuts = 0;
    let mut erases = 0;
    for i in 1..=12u32 {
        // The save's steps, uninterrupted, on a copy.
        let mut probe = mem;
        let mut s = store(&mut probe);
        s.save(&settings(i), Some(&record(i))).unwrap();
        let f = s.into_flash();
        let steps = f.programmed + f.erased;
        erases += f.erased;
        for k in 0..steps {
            let mut cut = mem;
            let mut f = NorSim::<SECTOR>::new(&mut cut, u64::from(k));
            f.cut_power_at(k);
            let mut s = Store::new(f, 0..SIZE as u32).unwrap();
            assert!(
                s.save(&settings(i), Some(&record(i))).is_err(),
                "save {i} cut at {k}"
            );
            assert!(s.into_flash().power_lost());
            cuts += 1;
            let (state, got, serial) = boot(&mut cut);
            assert_eq!(state, StoreState::Stored, "save {i} cut at {k}");
            // Each item is the old one or the new one, never a mix.
            assert!(
                got == settings(i - 1) || got == settings(i),
                "save {i} cut at {k}: {got:?}"
            );
            assert!(
                serial == Some(i - 1) || serial == Some(i),
                "save {i} cut at {k}: {serial:?}"
            );
            // And the store takes the next save.
            store(&mut cut)
                .save(&settings(99), Some(&record(99)))
                .unwrap();
            assert_eq!(boot(&mut cut), (StoreState::Stored, settings(99), Some(99)));
        }
        store(&mut mem)
            .save(&settings(i), Some(&record(i)))
            .unwrap();
        assert_eq!(boot(&mut mem), (StoreState::Stored, settings(i), Some(i)));
    }
    // The loop met sector erases (the map moved on), and cut each one.
    assert!(erases >= 4, "{erases} erases");
    assert!(cuts > 4_000, "{cuts} cuts");
}

#[test]
fn a_power_cut_at_every_step_of_a_factory_reset_leaves_the_record_or_nothing() {
    let mut mem = [0xFFu8; SIZE];
    for i in 0..4 {
        store(&mut mem)
            .save(&settings(i), Some(&record(i)))
            .unwrap();
    }
    let mut probe = mem;
    let mut s = store(&mut probe);
    s.clear().unwrap();
    let f = s.into_flash();
    let steps = f.programmed + f.erased;
    assert!(steps > 0);
    for k in 0..steps {
        let mut cut = mem;
        let mut f = NorSim::<SECTOR>::new(&mut cut, u64::from(k));
        f.cut_power_at(k);
        let mut s = Store::new(f, 0..SIZE as u32).unwrap();
        assert!(s.clear().is_err());
        let (state, got, serial) = boot(&mut cut);
        match state {
            StoreState::Stored => assert_eq!(got, settings(3), "cut at {k}"),
            StoreState::Defaults => assert_eq!(got, Settings::default()),
            StoreState::Corrupt | StoreState::Absent => panic!("cut at {k}: {state:?}"),
        }
        assert!(serial.is_none() || serial == Some(3), "cut at {k}");
    }
}

#[test]
fn a_damaged_byte_is_never_read_as_a_good_record() {
    let mut mem = [0xFFu8; SIZE];
    store(&mut mem)
        .save(&settings(3), Some(&record(3)))
        .unwrap();
    store(&mut mem)
        .save(&settings(4), Some(&record(4)))
        .unwrap();
    let written: std::vec::Vec<usize> = (0..SIZE).filter(|&i| mem[i] != 0xFF).collect();
    for (n, &at) in written.iter().enumerate() {
        for flip in [0x01u8, 0x80, 0xFF] {
            let mut bad = mem;
            bad[at] ^= flip;
            let l = store(&mut bad).load();
            // Either a record that was saved, or the defaults, flagged.
            match l.state {
                StoreState::Stored => assert!(
                    l.settings == settings(4) || l.settings == settings(3),
                    "byte {n} at {at} ^ {flip:#x}: {:?}",
                    l.settings
                ),
                _ => assert_eq!(l.settings, Settings::default()),
            }
            if let Some(Ok(r)) = l.calibration {
                assert!(r == record(4) || r == record(3), "byte {at} ^ {flip:#x}");
            }
        }
    }
}
