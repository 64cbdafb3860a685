//! The QEMU demo's world and its start-up, in one place: `qemu-demo` runs
//! it on the Cortex-M4 under RTIC, `evaluations`' `demo-replay` runs the
//! same world through the same schedule on the host, and `cargo xtask
//! test` holds the two runs' fused rates to one CRC-32 (the library's code
//! gives the same bits on both targets).
//!
//! The array: four ICM-42688-P and one ADXRS453 on z, mounted rotated,
//! upside down and misaligned (`mounted_board`), their dies warming from
//! 20 to 35 °C; the ICM-42688-Ps on free-running PLLs (0.6 % fast, 0.9 %
//! slow, 0.3 % fast, 0.4 % slow, drifting and wandering) with the delay
//! model of their signal paths (the 32 kHz filters are too slow for a
//! minute of QEMU). The motion: a still x and y with small offsets, z
//! slewing in a 20 °/s sine on 10 °/s. The faults: see [`inject`].

use core::cell::RefCell;

use super::board::{board_drivers, BoardDrivers};
use super::timing::ClockParams;
use super::{
    board_array, mounted_board, with_bus, Chip, ChipTiming, CsLine, EmuBus, EmuCapture, EmuDelay,
    EmuDevice, Fault, PathModel, RateProfile, TempProfile,
};
use gyro_array::algo::davar::DavarConfig;
use gyro_array::algo::fusion::{AdaptiveConfig, ConfigError, Method};
use gyro_array::algo::qualify::QualifyError;
use gyro_array::algo::static_cal::{CalError, CalRecord};
use gyro_array::drivers::adxrs453::OnAxis;
use gyro_array::drivers::icm42688::{board_fifo, ClockInput};
use gyro_array::drivers::Gyro;
use gyro_array::pipeline::selftest;
use gyro_array::pipeline::startup::start_array;
use gyro_array::pipeline::timed::{AtInstant, TimedIcm, BOARD_DELAY_US};
use gyro_array::pipeline::tracker::{self, NoiseTracker};
use gyro_array::pipeline::{Pipeline, PipelineConfig};

/// Samples a second.
pub const FS_HZ: u32 = 1000;
/// The run: 60 s of output.
pub const SAMPLES: u32 = 60_000;
/// The board's calibration record, as the host procedure wrote it for this
/// array (`calibrate --out host-tests/vectors/board.gcal`).
pub const CALIBRATION: &[u8] = include_bytes!("../../host-tests/vectors/board.gcal");
/// The motion every chip sees.
pub const PROFILE: RateProfile = RateProfile {
    base_dps: [0.5, -0.2, 10.0],
    sine_dps: [0.0, 0.0, 20.0],
    sine_hz: 1.0,
    sine_start_s: 0.0,
};
/// The dies' temperature.
pub const WARM_UP: TempProfile = TempProfile {
    start_c: 20.0,
    ramp_c_per_s: 0.5,
    ramp_from_s: 5.0,
    end_c: 35.0,
};
/// The ICM-42688-Ps' PLL errors.
pub const PLL: [f64; 4] = [0.006, -0.009, 0.003, -0.004];

/// σ of the link's noise estimates at τ = 1, 8, 64 ms.
pub const NOISE_TAU: [usize; 3] = [0, 3, 6];
/// What the status frames say of the demo's schedule.
pub const STATUS_VIEW: gyro_array::app::StatusView = gyro_array::app::StatusView {
    taus: NOISE_TAU,
    sample_us: 1_000_000 / FS_HZ,
};
/// E-DAVAR per axis: λ2 = 512 samples, the link's τ alone (1, 8 and 64 ms:
/// every third octave).
pub type Tracker = NoiseTracker<512, 19, 3>;

/// The E-DAVARs' settings.
pub const fn tracker_config() -> DavarConfig {
    tracker::config(512).with_tau_octaves(3)
}

/// The emulated bus of the demo's array.
pub type Bus<'c> = RefCell<EmuBus<'c, 5>>;
/// A chip's device on it.
pub type Dev<'a, 'c> = EmuDevice<'a, 'c>;
/// An ICM-42688-P as the board reads it.
pub type Timed<'a, 'c> = TimedIcm<Dev<'a, 'c>, EmuCapture<'a, 'c, 5>>;

/// The array's chips.
pub fn chips() -> [Chip; 5] {
    let mut chips = board_array(PROFILE, 1);
    for (i, (c, m)) in chips.iter_mut().zip(mounted_board(WARM_UP)).enumerate() {
        c.set_mount(m);
        if let (Chip::Icm(c), Some(&offset)) = (c, PLL.get(i)) {
            c.set_timing(Some(ChipTiming {
                pll: ClockParams {
                    offset,
                    drift_per_s: 1e-5,
                    wander: 2e-4,
                    wander_period_s: 3.0 + i as f64,
                },
                path: PathModel::Delay,
                ..ChipTiming::pll(0.0)
            }));
        }
    }
    chips
}

/// A fault the demo injects.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Event {
    /// The chip's output registers stop updating.
    Stuck(usize),
    /// The chip's bytes take bit errors (5 % of bytes).
    BitErrors(usize),
    /// They stop.
    BitErrorsEnd(usize),
    /// The chip's PLL fails: it runs on its RC oscillator.
    ClockToRc(usize),
    /// Its PLL is back.
    ClockToPll(usize),
}

/// Before sample `n` (from 0): gyro 2 sticks at 1.5 s, the ADXRS453 takes
/// bit errors from 2.0 s to 2.2 s, gyro 3's clock falls back to its RC
/// oscillator from 3.0 s to 4.0 s. Returns what it injected, if anything.
pub fn inject(n: u32, b: &mut EmuBus<'_, 5>) -> Option<Event> {
    let e = match n {
        1500 => Event::Stuck(2),
        2000 => Event::BitErrors(4),
        2200 => Event::BitErrorsEnd(4),
        3000 => Event::ClockToRc(3),
        4000 => Event::ClockToPll(3),
        _ => return None,
    };
    match e {
        Event::Stuck(i) => b.chips[i].set_fault(Fault::Stuck),
        Event::BitErrors(i) => b.chips[i].set_fault(Fault::BitErrors { prob: 0.05 }),
        Event::BitErrorsEnd(i) => b.chips[i].set_fault(Fault::None),
        Event::ClockToRc(i) | Event::ClockToPll(i) => {
            if let Some(c) = b.chips[i].icm() {
                c.fail_pll(matches!(e, Event::ClockToRc(_)));
            }
        }
    }
    Some(e)
}

/// Every chip and the emulated world they live in, as the sample task owns
/// them after start-up.
pub struct Chips<'a, 'c> {
    /// The ICM-42688-Ps on the FIFO path, each on the board's clock.
    pub timed: [Timed<'a, 'c>; 4],
    /// The ADXRS453, read at the array's instant (and never fused there:
    /// its reading is older).
    pub adx: AtInstant<OnAxis<Dev<'a, 'c>>>,
    /// The bus.
    pub bus: &'a Bus<'c>,
}

/// The demo's link settings: the defaults with the integrated angle on
/// (every field of the sample frame exercised); under stress, a status
/// frame every sample.
pub fn link_settings(stress: bool) -> gyro_array::link::msg::Settings {
    gyro_array::link::msg::Settings {
        status_every: if stress {
            1
        } else {
            gyro_array::link::msg::Settings::default().status_every
        },
        angle: true,
        ..gyro_array::link::msg::Settings::default()
    }
}

/// The board's pipeline: default settings, the adaptive fusion.
pub fn pipeline() -> Result<Pipeline<5>, ConfigError> {
    Pipeline::new(
        PipelineConfig::default(),
        Method::Adaptive(AdaptiveConfig::default()),
    )
}

/// What start-up left.
pub struct Started<'a, 'c> {
    /// The chips.
    pub chips: Chips<'a, 'c>,
    /// The calibration record's verdict (the pipeline runs uncalibrated on
    /// an error).
    pub calibration: Result<(), CalError>,
    /// The noise-health self-test passed on every gyro.
    pub self_test_ok: bool,
    /// Chips whose FIFO set-up failed (bit `i`: chip `i`), marked failed.
    pub fifo_failed: u8,
}

/// The board's start-up on the demo's array: the calibration record, the
/// array's start (the ICM-42688-P self-test across it), the noise-health
/// self-test (2 048 samples of every gyro's z, each against the median of
/// the others; its noise figures become fusion's priors), then the
/// ICM-42688-Ps moved to the board's sampling (FIFO at 4 kHz on their own
/// clocks, INT1 captured) and started together. `pipe` (from
/// [`pipeline`]) leaves calibrated, with each gyro's measured noise as
/// fusion's priors; it stays the caller's (on the Cortex-M4 a second copy
/// of it in this frame would not fit the demo's stack beside the
/// self-test's blocks).
pub fn start<'a, 'c>(
    bus: &'a Bus<'c>,
    cs: &'c [CsLine; 5],
    pipe: &mut Pipeline<5>,
) -> Started<'a, 'c> {
    let dt = 1.0 / FS_HZ as f32;
    let mut delay = EmuDelay::new(bus, dt);
    let BoardDrivers {
        icm: [mut g0, mut g1, mut g2, mut g3],
        adx: mut g4,
    } = board_drivers(bus, cs);
    let calibration = pipe.set_calibration(CalRecord::decode(CALIBRATION).as_ref().map_err(|e| *e));
    start_array(
        [&mut g0, &mut g1, &mut g2, &mut g3],
        &mut g4,
        &mut delay,
        Some(20),
        pipe,
    );
    let (self_test_ok, results) = {
        let mut gyros: [&mut dyn Gyro; 5] = [&mut g0, &mut g1, &mut g2, &mut g3, &mut g4];
        self_test(&mut gyros, pipe, bus, dt)
    };
    pipe.set_noise_priors(results.map(|r| r.ok().map(|h| h.std_dps)));
    // QEMU's board has no CLKIN to drive: the chips on their own clocks.
    let cfg = board_fifo(ClockInput::Internal);
    let mut fifo_failed = 0;
    for (i, g) in [&mut g0, &mut g1, &mut g2, &mut g3].into_iter().enumerate() {
        if g.init(&mut delay, cfg).is_err() {
            pipe.mark_init_failed(i);
            fifo_failed |= 1 << i;
        }
    }
    // One start for all (the chips set up first ran while the others were).
    for g in [&mut g0, &mut g1, &mut g2, &mut g3] {
        let _ = g.flush_fifo();
    }
    let capture = |index: usize| EmuCapture { bus, index };
    Started {
        chips: Chips {
            timed: [
                TimedIcm::new(g0, capture(0)),
                TimedIcm::new(g1, capture(1)),
                TimedIcm::new(g2, capture(2)),
                TimedIcm::new(g3, capture(3)),
            ],
            adx: AtInstant::new(g4, BOARD_DELAY_US),
            bus,
        },
        calibration,
        self_test_ok,
        fifo_failed,
    }
}

/// The noise-health self-test, its 40 KB of blocks in a frame of its own,
/// gone before the application starts (on the Cortex-M4 the demo's `init`
/// would not hold it beside its own).
#[inline(never)]
fn self_test(
    gyros: &mut [&mut dyn Gyro; 5],
    pipe: &Pipeline<5>,
    bus: &Bus<'_>,
    dt: f32,
) -> (bool, [Result<selftest::NoiseHealth, QualifyError>; 5]) {
    let mut blocks = [[0.0f32; selftest::BLOCK]; 5];
    let mut results = [Err(QualifyError::TooShort); 5];
    let ok = selftest::run(
        gyros,
        |_| 2, // z: every chip measures it, so each has four peers
        |i, r| pipe.board_rates(i, r),
        || {
            with_bus(bus, |b| b.advance(dt));
        },
        &mut blocks,
        &mut results,
    );
    (ok, results)
}
