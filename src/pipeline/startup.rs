//! Bring-up of the board's array, shared by the firmware, the QEMU demo and
//! the self-checks: gyros 0–3 are ICM-42688-P (init, then the datasheet
//! self-test, run across the array so that it holds on a moving board),
//! gyro 4 is the ADXRS453 (CHK start-up). A gyro that fails is logged and
//! marked in the pipeline, which then never offers it to fusion.
//!
//! # Self-test on a moving board
//!
//! The datasheet test compares two averages 200 ms apart, one with the
//! self-test actuation off and one with it on; the response is about
//! 2.5 °/s. A vehicle swaying at 4 °/s changes its rate by more than that
//! between the two averages, so a chip tested alone fails or passes by
//! chance. Here the four ICM-42688-P are tested together and read at the
//! same instants: phase 0 with every actuation off, phase 1 with chips
//! {0, 2} on, phase 2 with {1, 3} on. A chip's response is its change from
//! phase 0 minus the mean change of the chips that stayed off, which saw
//! the same motion. What is left of the motion is the chips' scale
//! mismatch times the rate change (1 % of 40 °/s is 0.4 °/s, against a
//! pass threshold of 1.25 °/s). With a single chip alive there is no
//! reference and the test is the datasheet's (the board must be still).
//!
//! A faulty chip present at power-up must not fail the healthy ones. Each
//! chip's level in a phase is therefore not a mean but the median, over
//! the phase's samples, of its reading minus the array's common motion at
//! that instant (per board axis, the median over the live chips): a chip
//! spiking ±200 °/s moves neither. A chip whose output never changes
//! within a phase (stuck, saturated) is no reference, and fails. Before
//! this, a chip spiking from power-up failed two or three healthy chips
//! on every board tried, and a stuck one the two it served as reference
//! for (`fusion-eval`, class (l)).

use embedded_hal::delay::DelayNs;
use embedded_hal::spi::SpiDevice;

use super::Pipeline;
use crate::algo::fusion::median;
use crate::algo::static_cal::{inverse3, mul3, ChipCal};
use crate::drivers::adxrs453::OnAxis;
use crate::drivers::icm42688::{Config, Error, Icm42688, SavedConfig, SelfTest};

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

/// Start the array. `self_test` is the number of samples per phase of the
/// ICM-42688-P array self-test, or `None` to skip it. Returns the mask of
/// gyros that failed (also marked in `pipe`).
/// The ADXRS453 may sit on its own bus (`ADX`): it is rated to 8 MHz, the
/// ICM-42688-P to 24 MHz.
pub fn start_array<SPI: SpiDevice, ADX: SpiDevice>(
    mut icm: [&mut Icm42688<SPI>; 4],
    adx: &mut OnAxis<ADX>,
    delay: &mut impl DelayNs,
    self_test: Option<u16>,
    pipe: &mut Pipeline<5>,
) -> u8
where
    SPI::Error: Loggable,
    ADX::Error: Loggable,
{
    let mut failed = 0u8;
    for (i, g) in icm.iter_mut().enumerate() {
        if let Err(_e) = g.init(delay, Config::default()) {
            #[cfg(feature = "defmt")]
            defmt::error!("gyro {}: ICM-42688-P init failed: {}", i, _e);
            failed |= 1 << i;
        }
    }
    let tests = match self_test {
        Some(n) => {
            // With a static calibration, the motion is compared in board
            // axes: a chip mounted rotated sees it on other axes.
            let mounts = pipe
                .static_calibration()
                .map(|c| core::array::from_fn(|i| c.get(i).map_or(ChipCal::IDENTITY.m, |c| c.m)));
            array_self_test(&mut icm, !failed & 0b1111, delay, n, mounts)
        }
        None => [const { Ok(None) }; 4],
    };
    for (i, r) in tests.iter().enumerate() {
        if failed & (1 << i) != 0 {
            pipe.mark_init_failed(i);
            continue;
        }
        match r {
            Ok(_st) => {
                pipe.set_start(i, crate::link::msg::Start::Passed);
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
                defmt::error!("gyro {}: ICM-42688-P self-test failed: {}", i, _e);
                pipe.set_start(i, crate::link::msg::Start::SelfTestFailed);
                pipe.mark_init_failed(i);
                failed |= 1 << i;
            }
        }
    }
    match adx.init(delay) {
        Ok(()) => {
            pipe.set_start(4, crate::link::msg::Start::Passed);
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

/// Chips whose actuation is on in phases 1 and 2 of the array self-test.
const ST_SETS: [u8; 2] = [0b0101, 0b1010];

/// Most samples per phase of the array self-test (each is kept for the
/// phase's median: 3 KiB of stack at 64).
pub const ST_MAX: usize = 64;

/// Median of a slice (reordered in place); the mean of the two middle
/// values for an even length, 0 for an empty slice.
fn median_of(v: &mut [f32]) -> f32 {
    // Insertion sort: at most 64 values, once per phase at start-up.
    for i in 1..v.len() {
        let mut j = i;
        while j > 0 {
            let (Some(&a), Some(&b)) = (v.get(j - 1), v.get(j)) else {
                break;
            };
            if a.total_cmp(&b).is_le() {
                break;
            }
            v.swap(j - 1, j);
            j -= 1;
        }
    }
    let k = v.len();
    match (v.get(k.wrapping_sub(1) / 2), v.get(k / 2)) {
        (Some(a), Some(b)) if k > 0 => 0.5 * (a + b),
        _ => 0.0,
    }
}

/// Outcome of one chip's self-test (`None`: not run).
type StResult<E> = Result<Option<SelfTest>, Error<E>>;

/// The array self-test (module docs) on the chips in `alive`, `n` samples
/// per phase. A chip not in `alive` gets `Ok(None)`.
///
/// `mounts` (chip axes to board axes, from the static calibration) lets
/// the chips' changes be compared in board axes; `None`: chips aligned.
pub fn array_self_test<SPI: SpiDevice>(
    icm: &mut [&mut Icm42688<SPI>; 4],
    alive: u8,
    delay: &mut impl DelayNs,
    n: u16,
    mounts: Option<[[[f32; 3]; 3]; 4]>,
) -> [StResult<SPI::Error>; 4] {
    let mut out: [StResult<SPI::Error>; 4] = [const { Ok(None) }; 4];
    if n == 0 || usize::from(n) > ST_MAX {
        return [0, 1, 2, 3].map(|i| {
            if alive & (1 << i) != 0 {
                Err(Error::InvalidArgument)
            } else {
                Ok(None)
            }
        });
    }
    let mut saved: [Option<SavedConfig>; 4] = [None; 4];
    // Chips still in the test (an error takes a chip out). The loops zip
    // the per-chip arrays rather than index them: no bounds checks, no
    // panic paths in the firmware.
    let mut live = 0u8;
    for (i, ((g, sv), o)) in icm
        .iter_mut()
        .zip(saved.iter_mut())
        .zip(out.iter_mut())
        .enumerate()
    {
        if alive & (1 << i) == 0 {
            continue;
        }
        match g.self_test_begin() {
            Ok(s) => {
                *sv = Some(s);
                live |= 1 << i;
            }
            Err(e) => *o = Err(e),
        }
    }
    delay.delay_ms(20);
    // Chip axes to board axes and back, per chip (identity: aligned, or a
    // singular matrix).
    let to_board = mounts.unwrap_or([ChipCal::IDENTITY.m; 4]);
    let to_chip = to_board.map(|m| inverse3(&m).unwrap_or(ChipCal::IDENTITY.m));
    // Robust level per phase, chip and axis (raw LSB): the median over the
    // phase's samples of the chip's reading minus the array's common
    // motion at that instant (below).
    let mut means = [[[0.0f32; 3]; 4]; 3];
    let mut resid = [[[0.0f32; ST_MAX]; 3]; 4];
    let mut frozen = 0u8;
    let n = usize::from(n);
    for (phase, mean) in means.iter_mut().enumerate() {
        if let Some(&on) = phase.checked_sub(1).and_then(|k| ST_SETS.get(k)) {
            for (i, (g, o)) in icm.iter_mut().zip(out.iter_mut()).enumerate() {
                if live & (1 << i) != 0 {
                    if let Err(e) = g.set_self_test(on & (1 << i) != 0) {
                        *o = Err(e);
                        live &= !(1 << i);
                    }
                }
            }
            delay.delay_ms(200); // datasheet: settle before reading
        }
        let mut first = [[0i16; 3]; 4];
        let mut moving = 0u8;
        for t in 0..n {
            delay.delay_us(1000); // one sample at 1 kHz, every chip
            let mut raw = [[0.0f32; 3]; 4];
            for (i, ((g, o), r)) in icm
                .iter_mut()
                .zip(out.iter_mut())
                .zip(raw.iter_mut())
                .enumerate()
            {
                if live & (1 << i) == 0 {
                    continue;
                }
                match g.read_raw() {
                    Ok(v) => {
                        *r = v.map(f32::from);
                        // A chip whose output never changes within a
                        // phase (stuck, saturated: real noise moves it by
                        // ~12 LSB every sample) is no reference.
                        if let Some(f) = first.get_mut(i) {
                            if t == 0 {
                                *f = v;
                            } else if *f != v {
                                moving |= 1 << i;
                            }
                        }
                    }
                    Err(e) => {
                        *o = Err(e);
                        live &= !(1 << i);
                    }
                }
            }
            // The motion common to the array at this instant: per board
            // axis, the median over the live chips (a chip spiking from
            // power-up moves it by nothing). Taken out of every chip
            // sample by sample, it leaves each chip's offset, whatever the
            // vehicle does within the phase; the same for every chip, it
            // cancels in the comparison with the reference chips below.
            // With one chip there is nothing to compare with: none is
            // taken out (the datasheet's test, on a still board).
            let mut common = [0.0f32; 3];
            if live.count_ones() >= 2 {
                let board: [[f32; 3]; 4] = core::array::from_fn(|i| {
                    let (m, r) = (&to_board[i], &raw[i]);
                    mul3(m, r)
                });
                for (a, c) in common.iter_mut().enumerate() {
                    *c = median(&board.map(|b| b[a]), live);
                }
            }
            for (i, (r, rs)) in raw.iter().zip(resid.iter_mut()).enumerate() {
                if live & (1 << i) == 0 {
                    continue;
                }
                let seen = mul3(&to_chip[i], &common);
                for ((slot, v), c) in rs.iter_mut().zip(r).zip(seen) {
                    if let Some(x) = slot.get_mut(t) {
                        *x = v - c;
                    }
                }
            }
        }
        if n >= 2 {
            frozen |= live & !moving;
        }
        for (m, rs) in mean.iter_mut().zip(resid.iter_mut()) {
            for (mv, r) in m.iter_mut().zip(rs.iter_mut()) {
                *mv = median_of(r.get_mut(..n).unwrap_or(&mut []));
            }
        }
    }
    let [base, on1, on2] = means;
    for (&set, phase) in ST_SETS.iter().zip([on1, on2]) {
        // Change of every chip from phase 0.
        let mut delta = [[0.0f32; 3]; 4];
        for ((d, p), b) in delta.iter_mut().zip(phase.iter()).zip(base.iter()) {
            for ((x, pv), bv) in d.iter_mut().zip(p).zip(b) {
                *x = pv - bv;
            }
        }
        // The chips that stayed off in this phase saw the same motion (in
        // board axes when the chips are mounted otherwise).
        let refs = live & !set & !frozen;
        let count = refs.count_ones() as f32;
        let mut motion = [0.0f32; 3];
        if count > 0.0 {
            for (h, d) in delta.iter().enumerate() {
                if refs & (1 << h) != 0 {
                    let d = match (mounts, h) {
                        (Some(m), h) if h < 4 => mul3(&m[h], d),
                        _ => *d,
                    };
                    for (m, v) in motion.iter_mut().zip(d) {
                        *m += v / count;
                    }
                }
            }
        }
        let chips = icm
            .iter_mut()
            .zip(delta.iter())
            .zip(out.iter_mut().zip(saved.iter()));
        for (i, ((g, d), (o, sv))) in chips.enumerate() {
            if set & (1 << i) == 0 {
                continue;
            }
            let Some(s) = *sv else { continue };
            // The motion as this chip sees it.
            let seen = match mounts.and_then(|m| m.get(i).and_then(inverse3)) {
                Some(a) => mul3(&a, &motion),
                None => motion,
            };
            let mut response = [0.0f32; 3];
            // A frozen output has no response, whatever the motion did.
            if frozen & (1 << i) == 0 {
                for ((r, dv), m) in response.iter_mut().zip(d).zip(seen) {
                    *r = dv - m;
                }
            }
            let end = g.self_test_end(s, response);
            if live & (1 << i) != 0 {
                *o = end.map(Some);
            }
        }
    }
    out
}
