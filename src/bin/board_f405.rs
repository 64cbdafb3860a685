//! Board firmware for the STM32F405RG gyro board.
//!
//! Wiring: SPI1 (PA5 SCK, PA6 MISO, PA7 MOSI, mode 0, 1 MHz) shared by four
//! ICM-42688-P (CS on PA4, PB0, PB1, PC4) and one ADXRS453 on the z axis
//! (CS on PC5). TIM2 paces sampling at 1 kHz; the DWT cycle counter measures
//! the time between ticks, so missed periods are counted as overruns.
//! Logs go out over RTT (defmt); flash and run with `cargo flash`.
//!
//! Faults are contained (`gyro_array::board::persist`): a panic or a hard
//! fault is recorded in RAM kept across the reset and reported at the next
//! boot; an MPU guard under the flip-link stack turns an overflow into a
//! hard fault; the independent watchdog (IWDG, LSI ≈ 32 kHz) resets the
//! core if the main loop stops completing samples: 2 s while the array
//! starts and self-tests, then 100 ms nominal (68–188 ms over the LSI's
//! 17–47 kHz datasheet range) against a 1 ms sample period.
#![no_std]
#![no_main]

use core::cell::RefCell;

use cortex_m_rt::entry;
use defmt_rtt as _;
use embedded_hal_bus::spi::RefCellDevice;
use stm32f4xx_hal::{
    pac,
    prelude::*,
    rcc::Config as RccConfig,
    spi::{Mode, Phase, Polarity, Spi},
    watchdog::IndependentWatchdog,
};

use gyro_array::algo::fusion::{AdaptiveConfig, Method};
use gyro_array::algo::qualify::QualifyError;
use gyro_array::board::record::Cause;
use gyro_array::board::{persist, stack};
use gyro_array::drivers::adxrs453::Adxrs453;
use gyro_array::drivers::icm42688::Icm42688;
use gyro_array::drivers::Gyro;
use gyro_array::pipeline::selftest;
use gyro_array::pipeline::startup::start_array;
use gyro_array::pipeline::tracker::{self, NoiseTracker};
use gyro_array::pipeline::{Pipeline, PipelineConfig};

const FS_HZ: u32 = 1000;
const SYSCLK_HZ: u32 = 168_000_000;

/// The board's noise tracker: three E-DAVARs.
type Tracker = NoiseTracker<1024, 35, 9>;

/// The noise tracker (33 KB) in a static of its own, built by a function
/// that is not inlined: its construction's temporaries live in that
/// function's frame, freed on return, not in main's for good. `None` if
/// the configuration is refused. Called once.
#[inline(never)]
#[allow(unsafe_code)]
fn noise_tracker() -> Option<&'static mut Tracker> {
    use core::mem::MaybeUninit;
    #[unsafe(link_section = ".uninit.tracker")]
    static mut TRACKER: MaybeUninit<Tracker> = MaybeUninit::uninit();
    let t = Tracker::new(tracker::config(1024)).ok()?;
    // SAFETY: called once, from main, before anything refers to TRACKER.
    unsafe {
        let p = (&raw mut TRACKER).cast::<Tracker>();
        p.write(t);
        Some(&mut *p)
    }
}

/// The self-test's five 8 KB blocks, in CCM RAM (`.ccmram`, see memory.x),
/// zeroed. Called once.
#[allow(unsafe_code)]
fn selftest_blocks() -> &'static mut [[f32; selftest::BLOCK]; 5] {
    use core::mem::MaybeUninit;
    #[unsafe(link_section = ".ccmram.selftest")]
    static mut BLOCKS: MaybeUninit<[[f32; selftest::BLOCK]; 5]> = MaybeUninit::uninit();
    // SAFETY: called once, from main, before anything else refers to
    // BLOCKS; all-zero bits are valid f32s.
    unsafe {
        let p = &raw mut BLOCKS;
        p.cast::<u8>()
            .write_bytes(0, core::mem::size_of::<[[f32; selftest::BLOCK]; 5]>());
        (*p).assume_init_mut()
    }
}

/// A start-up step that cannot go on: log it and reset (the record says
/// the firmware asked; the next boot reports it).
fn give_up(what: &str) -> ! {
    defmt::error!("start-up failed: {=str}; resetting", what);
    persist::record_and_reset(Cause::Requested)
}

#[entry]
fn main() -> ! {
    let record = persist::take();
    stack::guard_stack();
    let (Some(dp), Some(mut cp)) = (pac::Peripherals::take(), cortex_m::Peripherals::take()) else {
        give_up("peripherals taken twice")
    };
    // What ended the last run: our own record, else the reset flags.
    let csr = dp.RCC.csr().read();
    match record {
        Some(r) => defmt::warn!("last run ended by {} (reset {} since power-up)", r, r.boots),
        None if csr.wdgrstf().bit_is_set() => defmt::warn!("last run ended by the watchdog"),
        None => defmt::info!("cold start"),
    }
    if let Some(msg) = persist::panic_message() {
        defmt::warn!("last panic: {=[u8]:a}", msg);
    }
    dp.RCC.csr().modify(|_, w| w.rmvf().set_bit());
    let mut watchdog = IndependentWatchdog::new(dp.IWDG);
    watchdog.start(2000.millis());
    let mut rcc = dp
        .RCC
        .freeze(RccConfig::hse(8.MHz()).sysclk(SYSCLK_HZ.Hz()));
    cp.DCB.enable_trace();
    cp.DWT.enable_cycle_counter();

    let gpioa = dp.GPIOA.split(&mut rcc);
    let gpiob = dp.GPIOB.split(&mut rcc);
    let gpioc = dp.GPIOC.split(&mut rcc);
    let mode = Mode {
        polarity: Polarity::IdleLow,
        phase: Phase::CaptureOnFirstTransition,
    };
    let spi = Spi::new(
        dp.SPI1,
        (Some(gpioa.pa5), Some(gpioa.pa6), Some(gpioa.pa7)),
        mode,
        1.MHz(),
        &mut rcc,
    );
    let bus = RefCell::new(spi);
    let mut delay = dp.TIM5.delay_us(&mut rcc);

    let cs0 = gpioa.pa4.into_push_pull_output().erase();
    let cs1 = gpiob.pb0.into_push_pull_output().erase();
    let cs2 = gpiob.pb1.into_push_pull_output().erase();
    let cs3 = gpioc.pc4.into_push_pull_output().erase();
    let cs4 = gpioc.pc5.into_push_pull_output().erase();
    let (Ok(d0), Ok(d1), Ok(d2), Ok(d3), Ok(d4)) = (
        RefCellDevice::new_no_delay(&bus, cs0),
        RefCellDevice::new_no_delay(&bus, cs1),
        RefCellDevice::new_no_delay(&bus, cs2),
        RefCellDevice::new_no_delay(&bus, cs3),
        RefCellDevice::new_no_delay(&bus, cs4),
    );
    let (mut g0, mut g1, mut g2, mut g3) = (
        Icm42688::new(d0),
        Icm42688::new(d1),
        Icm42688::new(d2),
        Icm42688::new(d3),
    );
    let mut g4 = Adxrs453::new(d4, 2);

    let Ok(mut pipe) = Pipeline::<5>::new(
        PipelineConfig::default(),
        Method::Adaptive(AdaptiveConfig::default()),
    ) else {
        give_up("pipeline configuration")
    };
    start_array(
        [&mut g0, &mut g1, &mut g2, &mut g3],
        &mut g4,
        &mut delay,
        Some(200),
        &mut pipe,
    );

    // E-DAVAR per fused axis: λ2 = 1024 samples (1 s), τ = 1 … 256 ms.
    let Some(noise) = noise_tracker() else {
        give_up("noise tracker configuration")
    };

    let mut tick = dp.TIM2.counter_hz(&mut rcc);
    if tick.start(FS_HZ.Hz()).is_err() {
        give_up("sampling timer");
    }
    // Noise-health self-test (the board must be still): 2048 samples of
    // every gyro at the sampling rate, then trend, Hurst and normality.
    // The blocks (40 KB) live in the core-coupled RAM, out of the stack.
    {
        let blocks = selftest_blocks();
        let mut results = [Err(QualifyError::TooShort); 5];
        let mut gyros: [&mut dyn Gyro; 5] = [&mut g0, &mut g1, &mut g2, &mut g3, &mut g4];
        let ok = selftest::run(
            &mut gyros,
            |_| 2, // z: every chip measures it, so each has four peers
            || {
                let _ = nb::block!(tick.wait());
                watchdog.feed();
            },
            blocks,
            &mut results,
        );
        if ok {
            defmt::info!("noise-health self-test: all gyros pass");
        } else {
            defmt::warn!("noise-health self-test: FAILED (see above)");
        }
    }

    let u = stack::stack_usage();
    defmt::info!("stack after start-up: {} of {} bytes", u.peak, u.size);
    watchdog.start(100.millis());
    let period = SYSCLK_HZ / FS_HZ;
    let mut last = cortex_m::peripheral::DWT::cycle_count();
    loop {
        let _ = nb::block!(tick.wait());
        let now = cortex_m::peripheral::DWT::cycle_count();
        let missed = (now.wrapping_sub(last) + period / 2) / period;
        last = now;
        if missed > 1 {
            pipe.note_overrun(missed - 1);
            defmt::warn!("overrun: {} period(s) missed", missed - 1);
        }
        let mut gyros: [&mut dyn Gyro; 5] = [&mut g0, &mut g1, &mut g2, &mut g3, &mut g4];
        let out = pipe.step(&mut gyros);
        pipe.log_health_changes(&out);
        noise.push(&out);
        // A completed sample is the only thing that feeds the watchdog.
        watchdog.feed();
        if out.seq % 10_000 == 0 {
            let u = stack::stack_usage();
            defmt::info!("seq {}: stack peak {} of {} bytes", out.seq, u.peak, u.size);
        }
        if out.seq % 1000 == 0 {
            for (a, cal) in pipe.calibration().iter().enumerate() {
                defmt::info!(
                    "seq {} axis {}: relative calibration scale {} bias {} dps",
                    out.seq,
                    a,
                    cal.scale(),
                    cal.bias()
                );
            }
            for f in out.fused.iter().flatten() {
                defmt::info!(
                    "seq {}: fused {=f32} dps, weights {}",
                    out.seq,
                    f.rate_dps,
                    f.weights
                );
            }
            for a in 0..3 {
                if let Some(d) = noise.estimate(a) {
                    let e = d.step;
                    defmt::info!(
                        "seq {} axis {}: E-DAVAR for seq {} L={} score {=f32} sigma(1/16/256 ms) = {=f32} {=f32} {=f32} dps",
                        out.seq,
                        a,
                        d.seq,
                        e.len,
                        e.score,
                        tracker::sigma_dps(&e, 0),
                        tracker::sigma_dps(&e, 4),
                        tracker::sigma_dps(&e, 8)
                    );
                }
            }
        }
    }
}
