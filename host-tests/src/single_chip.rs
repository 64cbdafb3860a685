//! One ICM-42688-P on the emulated bus, keeping its own time, read
//! through the real driver's FIFO path every millisecond: the harness of
//! the chip-timing tests and of `timing-eval`.

use gyro_array::drivers::icm42688::{Config, Error, FifoSample, Icm42688};
use gyro_sim::{
    emu_device, with_bus, Chip, ChipTiming, CsLine, EmuBus, EmuDelay, Icm42688Model, NoiseParams,
    RateProfile,
};
use std::cell::RefCell;

/// The bus of one chip.
pub type Bus<'a> = RefCell<EmuBus<'a, 1>>;

/// An ICM-42688-P seeing `profile` with `noise`, keeping time by `timing`.
pub fn chip(profile: RateProfile, noise: NoiseParams, timing: ChipTiming) -> Chip {
    let mut c = Icm42688Model::new(noise, profile, 7, 80);
    c.set_timing(Some(timing));
    Chip::Icm(c)
}

/// What a run of FIFO reads found.
#[derive(Default, Debug)]
pub struct Reads {
    /// Every sample read, oldest first.
    pub samples: Vec<FifoSample>,
    /// Bus time of the read each sample came out in, s.
    pub read_at_s: Vec<f64>,
    /// Reads that found the FIFO empty.
    pub empty: u32,
    /// Reads that found FIFO_FULL set.
    pub overflows: u32,
    /// Reads that failed otherwise.
    pub other_errors: u32,
    /// Bus time of the chip's last reset (tick 0 of its stamps), s.
    pub origin_s: f64,
    /// Samples the chip made since then.
    pub made: u64,
}

/// Initialise the chip with `cfg` (the board driving CLKIN at `clkin_hz`),
/// then run `ms` bus steps of 1 ms, reading the FIFO after each unless
/// `skip(n)`; `each(n, bus)` runs before each step.
pub fn run(
    c: Chip,
    cfg: Config,
    clkin_hz: Option<f64>,
    ms: u32,
    mut each: impl FnMut(u32, &Bus),
    skip: impl Fn(u32) -> bool,
) -> Reads {
    let cs: [CsLine; 1] = Default::default();
    let bus: Bus = RefCell::new(EmuBus::new([c], &cs));
    with_bus(&bus, |b| b.clkin_hz = clkin_hz);
    let mut delay = EmuDelay::new(&bus, 1e-3);
    let dev = emu_device(&bus, &cs[0]);
    let mut g = Icm42688::new(dev);
    g.init(&mut delay, cfg).expect("init");
    let mut r = Reads::default();
    let mut buf = [FifoSample {
        raw: [0; 3],
        stamp: 0,
    }; 16];
    for n in 0..ms {
        each(n, &bus);
        with_bus(&bus, |b| b.advance(1e-3));
        if skip(n) {
            continue;
        }
        let now = with_bus(&bus, |b| b.time64_s()).unwrap_or(0.0);
        match g.read_fifo(&mut buf) {
            Ok(f) => {
                if f.samples == 0 {
                    r.empty += 1;
                }
                r.samples.extend_from_slice(&buf[..f.samples]);
                r.read_at_s.extend(std::iter::repeat_n(now, f.samples));
            }
            Err(Error::FifoOverflow) => r.overflows += 1,
            Err(_) => r.other_errors += 1,
        }
    }
    if let Some(Some((origin, made))) = with_bus(&bus, |b| {
        b.chips[0]
            .icm()
            .and_then(|c| Some((c.clock_origin_s()?, c.samples_made())))
    }) {
        r.origin_s = origin;
        r.made = made;
    }
    r
}
