//! Board firmware for the STM32F405RG gyro board.
//!
//! Wiring: SPI1 (PA5 SCK, PA6 MISO, PA7 MOSI, mode 0, 21 MHz: the
//! ICM-42688-P is rated to 24 MHz) to four ICM-42688-P (CS on PA4, PB0,
//! PB1, PC4); SPI2 (PB13 SCK, PB14 MISO, PB15 MOSI, mode 0, 5.25 MHz: rated
//! to 8 MHz) to one ADXRS453 on the z axis (CS on PC5). The output link
//! (`gyro_array::link`, `docs/link.md`) is USART1 (PA9 TX, PA10 RX) at
//! 6 Mbaud, 8N1 (`link::BAUD`). SysTick paces sampling at 1 kHz; a tick that comes
//! before the previous sample is done is counted as an overrun.
//!
//! Time (`docs/timing.md`): TIM3 CH1 on PC6 drives every ICM-42688-P's
//! CLKIN (pin 9) at 32 kHz; each chip's INT1 pulses at every sample into
//! TIM5 CH1–4 (PA0–PA3), captured against TIM5's µs count, the board's
//! clock for the instants it states. After their self-tests (data
//! registers) the chips sample into their FIFOs at 4 kHz on CLKIN; each is
//! read through `TimedIcm` (its clock tracked from the captures, its
//! samples brought to one instant 1 670 µs behind the read), and one that
//! loses CLKIN moves to its own clock, tracked. The status frames carry
//! each chip's clock and its error. The ADXRS453's reading is older than
//! that instant (3.9 ms): read and watched, not fused (`AtInstant`).
//! Logs go out over RTT (defmt); flash and run with `cargo flash`.
//!
//! Clocks (`board::f405::start_clocks`): the 8 MHz crystal and the PLL to
//! 168 MHz; if the crystal does not start, the internal oscillator with
//! the PLL (logged as a warning); if the PLL does not lock either, the
//! internal oscillator at 16 MHz (an error). QEMU's `netduinoplus2` takes
//! the last path (its RCC reads 0), which `cargo xtask board-qemu` runs.
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
    serial::{config::Config as SerialConfig, Serial},
    spi::{Mode, Phase, Polarity, Spi},
    time::Hertz,
    watchdog::IndependentWatchdog,
};

use gyro_array::algo::fusion::{AdaptiveConfig, Method};
use gyro_array::algo::mounting::{self, CalRecord};
use gyro_array::algo::qualify::QualifyError;
use gyro_array::board::f405::{self, ClockSource, CycleDelay, RxQueue};
use gyro_array::board::record::Cause;
use gyro_array::board::{idle, persist, stack};
use gyro_array::drivers::adxrs453::Adxrs453;
use gyro_array::drivers::icm42688::{ClockInput, Config, Icm42688};
use gyro_array::drivers::Gyro;
use gyro_array::link::msg::Settings;
use gyro_array::link::port::{timed_clock, ChipTime, Port};
use gyro_array::link::{BAUD, FALLBACK_BAUD};
use gyro_array::pipeline::selftest;
use gyro_array::pipeline::startup::start_array;
use gyro_array::pipeline::timed::{self, AtInstant, TimedIcm, BOARD_DELAY_US};
use gyro_array::pipeline::tracker::{self, NoiseTracker, Probe};
use gyro_array::pipeline::{Pipeline, PipelineConfig};

const FS_HZ: u32 = 1000;
/// ICM-42688-P SPI clock limit (datasheet: 24 MHz).
const ICM_SPI_MAX_HZ: u32 = 24_000_000;
/// ADXRS453 SPI clock limit (datasheet: 8 MHz).
const ADX_SPI_MAX_HZ: u32 = 8_000_000;
/// σ of the link's noise estimates at τ = 2^k ms: 1, 16, 256 ms (the
/// tracker makes their records ready as its estimates are published).
const NOISE_TAU: [usize; 3] = tracker::LINK_TAUS;

/// The fastest SPI clock within `max` that the prescaler (bus clock / 2ⁿ)
/// gives exactly, so that the HAL's rounding cannot pick a faster one.
fn spi_clock(pclk: Hertz, max: u32) -> Hertz {
    let mut d = 2;
    while pclk.raw() / d > max && d < 256 {
        d *= 2;
    }
    // Never 0: the HAL divides the bus clock by it.
    Hertz::from_raw((pclk.raw() / d).max(1))
}

/// The board's noise tracker: three E-DAVARs.
type Tracker = NoiseTracker<1024, 35, 3>;

/// The noise tracker (22 KB) in a static of its own, built in place
/// (`NoiseTracker::init_in`). `None` if the configuration is refused.
/// Not inlined, so that the axis under construction is off main's frame
/// once built. Called once.
#[inline(never)]
#[allow(unsafe_code)]
fn noise_tracker() -> Option<&'static mut Tracker> {
    use core::mem::MaybeUninit;
    #[unsafe(link_section = ".uninit.tracker")]
    static mut TRACKER: MaybeUninit<Tracker> = MaybeUninit::uninit();
    // SAFETY: called once, from main, before anything refers to TRACKER.
    let slot = unsafe { (&raw mut TRACKER).as_mut() }?;
    Tracker::init_in(slot, tracker::link_config(1024)).ok()
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

/// The calibration record's flash sector (`CALIB` in memory.x, sector
/// 11), as bytes.
#[allow(unsafe_code)]
fn calib_bytes() -> &'static [u8] {
    unsafe extern "C" {
        static _calib_start: u8;
    }
    // SAFETY: CALIB is 128 KiB of memory-mapped flash that nothing writes
    // while the firmware runs; MAX_LEN is far less.
    unsafe { core::slice::from_raw_parts(&raw const _calib_start, mounting::MAX_LEN) }
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
    let (Some(dp), Some(cp)) = (pac::Peripherals::take(), cortex_m::Peripherals::take()) else {
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
    let (mut rcc, clock) = f405::start_clocks(dp.RCC);
    let core_hz = rcc.clocks.sysclk().raw();
    match clock {
        ClockSource::HsePll => defmt::info!("clock: crystal and PLL, {} Hz", core_hz),
        ClockSource::HsiPll => defmt::warn!(
            "clock: the crystal did not start; internal oscillator and PLL, {} Hz (±1 %)",
            core_hz
        ),
        ClockSource::Hsi => defmt::error!(
            "clock: neither the crystal nor the PLL started; internal oscillator alone, {} Hz",
            core_hz
        ),
    }
    let _systick = f405::start_ticks(cp.SYST, core_hz, FS_HZ);
    let mut delay = CycleDelay::new(core_hz);

    let gpioa = dp.GPIOA.split(&mut rcc);
    let gpiob = dp.GPIOB.split(&mut rcc);
    let gpioc = dp.GPIOC.split(&mut rcc);
    // The chips' clock (TIM3 CH1, PC6) and their INT1 captures (TIM5
    // CH1-4, PA0-PA3), before anything else takes the pins.
    let clkin = f405::start_clkin(dp.TIM3, gpioc.pc6.into_alternate(), &mut rcc);
    match clkin {
        Some(hz) => defmt::info!("CLKIN {} Hz on PC6 (TIM3 CH1)", hz),
        None => defmt::warn!(
            "CLKIN: the timer clock does not divide to 32 kHz; the chips keep their own clocks"
        ),
    }
    let Some(captures) = f405::Int1Captures::start(
        dp.TIM5,
        (
            gpioa.pa0.into_alternate(),
            gpioa.pa1.into_alternate(),
            gpioa.pa2.into_alternate(),
            gpioa.pa3.into_alternate(),
        ),
        &mut rcc,
    ) else {
        // Both of the board's clock trees (the PLL's 84 MHz APB1 timers,
        // the internal oscillator's 16 MHz) are whole MHz.
        give_up("TIM5 at 1 MHz")
    };
    let mode = Mode {
        polarity: Polarity::IdleLow,
        phase: Phase::CaptureOnFirstTransition,
    };
    let (icm_hz, adx_hz) = (
        spi_clock(rcc.clocks.pclk2(), ICM_SPI_MAX_HZ),
        spi_clock(rcc.clocks.pclk1(), ADX_SPI_MAX_HZ),
    );
    defmt::info!(
        "SPI1 (ICM-42688-P) {} Hz, SPI2 (ADXRS453) {} Hz",
        icm_hz.raw(),
        adx_hz.raw()
    );
    let spi1 = Spi::new(
        dp.SPI1,
        (Some(gpioa.pa5), Some(gpioa.pa6), Some(gpioa.pa7)),
        mode,
        icm_hz,
        &mut rcc,
    );
    let spi2 = Spi::new(
        dp.SPI2,
        (Some(gpiob.pb13), Some(gpiob.pb14), Some(gpiob.pb15)),
        mode,
        adx_hz,
        &mut rcc,
    );
    // USART1 reaches pclk2 / 8 (oversampling by 8): the link's rate on the
    // PLL's 84 MHz; on the internal oscillator alone (16 MHz: the crystal
    // and the PLL failed) the fallback rate, logged, so the board still
    // talks to a controller that can follow it.
    let baud = if rcc.clocks.pclk2().raw() / 8 >= BAUD {
        BAUD
    } else {
        defmt::error!(
            "link: pclk2 {} Hz cannot make {} baud; {} baud instead",
            rcc.clocks.pclk2().raw(),
            BAUD,
            FALLBACK_BAUD
        );
        FALLBACK_BAUD
    };
    let Ok(serial) = Serial::new(
        dp.USART1,
        (gpioa.pa9, gpioa.pa10),
        SerialConfig::default().baudrate(baud.bps()),
        &mut rcc,
    ) else {
        give_up("USART1 at the link's baud rate")
    };
    let (mut tx, rx) = serial.split();
    let mut rx = RxQueue::start(rx);
    let Some(port) = cortex_m::singleton!(: Port<2048> = Port::new(Settings::default())) else {
        give_up("link port taken twice")
    };
    // The delay compensation predicts each frame's rates to its last byte
    // at the rate the link runs.
    port.set_timing(baud, 1_000_000 / FS_HZ);
    let bus = RefCell::new(spi1);
    let bus2 = RefCell::new(spi2);

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
        RefCellDevice::new_no_delay(&bus2, cs4),
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
    // The static calibration (mounting, scale, misalignment, bias and its
    // temperature slope). Without a valid record the board runs
    // uncalibrated and says so: here, and in every sample frame (bit 7 of
    // `degraded`).
    match pipe.set_calibration(CalRecord::decode(calib_bytes()).as_ref().map_err(|e| *e)) {
        Ok(()) => defmt::info!("calibration record in use"),
        Err(e) => defmt::warn!("calibration record: {}; running uncalibrated", e),
    }
    let failed = start_array(
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

    // Noise-health self-test: 2048 samples of every gyro at the sampling
    // rate, then trend, Hurst and normality against the array's median.
    // The blocks (40 KB) live in the core-coupled RAM, out of the stack.
    // With no gyro running there is nothing to test (QEMU's STM32F405,
    // which has no chips, has no core-coupled RAM either).
    if failed == 0b1_1111 {
        defmt::warn!("noise-health self-test skipped: no gyro started");
    } else {
        let blocks = selftest_blocks();
        let mut results = [Err(QualifyError::TooShort); 5];
        let mut gyros: [&mut dyn Gyro; 5] = [&mut g0, &mut g1, &mut g2, &mut g3, &mut g4];
        let ok = selftest::run(
            &mut gyros,
            |_| 2, // z: every chip measures it, so each has four peers
            |i, r| pipe.board_rates(i, r),
            || {
                let t = f405::ticks();
                while f405::ticks() == t {
                    idle::sleep_unless(|| f405::ticks() != t);
                }
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
        // Each gyro's measured noise: fusion's priors for an axis left
        // with two gyros.
        pipe.set_noise_priors(results.map(|r| r.ok().map(|h| h.std_dps)));
    }

    // The chips from their self-tests (data registers) to the board's
    // sampling: FIFO at 4 kHz, each sample's INT1 captured, on CLKIN where
    // the board drives it (`docs/timing.md`). A chip that failed before is
    // set up too, so its restarts bring it back to this configuration.
    let cfg = Config::board_fifo(if clkin.is_some() {
        ClockInput::ClkIn
    } else {
        ClockInput::Internal
    });
    for (i, g) in [&mut g0, &mut g1, &mut g2, &mut g3].into_iter().enumerate() {
        if let Err(e) = g.init(&mut delay, cfg) {
            if failed & (1 << i) == 0 {
                defmt::error!("gyro {}: FIFO set-up failed: {}", i, e);
            }
            pipe.mark_init_failed(i);
        }
    }
    // One start for all: a chip set up first samples through the others'
    // set-up (46 ms each, the driver's reset and start-up waits), some 550
    // records at 4 kHz against its FIFO's 128, and would start on an
    // overflow.
    for g in [&mut g0, &mut g1, &mut g2, &mut g3] {
        let _ = g.flush_fifo();
    }
    let (mut t0, mut t1, mut t2, mut t3) = (
        TimedIcm::new(g0, captures.channel(0)),
        TimedIcm::new(g1, captures.channel(1)),
        TimedIcm::new(g2, captures.channel(2)),
        TimedIcm::new(g3, captures.channel(3)),
    );
    // The ADXRS453's reading is older than the array's instant: read and
    // watched, not fused (z is the four ICM-42688-P's).
    let mut g4 = AtInstant::new(g4, BOARD_DELAY_US);
    // What the status frames say of each chip's clock.
    let clocks = |t: [&TimedIcm<_, _>; 4]| {
        let mut c = [ChipTime::default(); 5];
        for (slot, t) in c.iter_mut().zip(t) {
            *slot = timed_clock(t);
        }
        c
    };

    let u = stack::stack_usage();
    defmt::info!("stack after start-up: {} of {} bytes", u.peak, u.size);
    watchdog.start(100.millis());
    let mut meter = stack::StackMeter::new();
    let mut status_for: Option<(u32, u64)> = None;
    // The last sample's noise probe, for the E-DAVARs once its frame is out.
    let mut probe: Option<Probe> = None;
    let mut last = f405::ticks();
    // Sample clock, µs (64-bit: the tick counter wraps after 49 days).
    let mut t_us: u64 = 0;
    loop {
        // Idle time until the tick: the UART fed, then the calibration's
        // learning and the E-DAVARs, then a status frame when one is due;
        // commands read.
        let now = loop {
            let t = f405::ticks();
            if t != last {
                // Every sample reaches the calibration and the E-DAVARs,
                // whatever is still queued when the next one is due.
                if let Some(p) = probe.take() {
                    pipe.after_frame(noise, p);
                }
                break t;
            }
            port.drain(&mut tx);
            if port.queued() == 0 {
                if let Some(p) = probe.take() {
                    pipe.after_frame(noise, p);
                } else if let Some((seq, t)) = status_for.take() {
                    let st = port.status(
                        &pipe,
                        seq,
                        t,
                        [1, 16, 256],
                        1_000_000 / FS_HZ,
                        meter.peak(),
                        &clocks([&t0, &t1, &t2, &t3]),
                    );
                    port.send(&st);
                }
            }
            port.receive(&mut rx, &mut pipe);
            idle::sleep_unless(|| {
                f405::ticks() != last
                    || port.queued() != 0
                    || probe.is_some()
                    || status_for.is_some()
            });
        };
        let elapsed = now.wrapping_sub(last);
        last = now;
        t_us += u64::from(elapsed) * u64::from(1_000_000 / FS_HZ);
        if elapsed > 1 {
            pipe.note_overrun(elapsed - 1);
            defmt::warn!("overrun: {} period(s) missed", elapsed - 1);
        }
        // One instant for the array, a fixed delay behind the read, on
        // TIM5's µs (the captures' clock), in 1/16 µs.
        let at = timed::array_instant(captures.micros(), BOARD_DELAY_US);
        for t in [&mut t0, &mut t1, &mut t2, &mut t3] {
            t.set_instant(at, BOARD_DELAY_US);
        }
        let mut gyros: [&mut dyn Gyro; 5] = [&mut t0, &mut t1, &mut t2, &mut t3, &mut g4];
        let out = pipe.read_and_fuse(&mut gyros);
        pipe.log_health_changes(&out);
        // The frame first, with the E-DAVARs' estimate of the samples
        // before this one: the antenna waits for the frame, and the
        // calibration and the E-DAVARs take this sample in the idle time
        // once it is out.
        port.publish(&out, t_us, &pipe, &noise.at_taus(NOISE_TAU));
        probe = Some(Probe::from(&out));
        meter.step(64);
        // A status frame is built in the idle time that follows, not in
        // the sample's own time.
        if port.status_due(out.seq) {
            status_for = Some((out.seq, t_us));
        }
        // A completed sample is the only thing that feeds the watchdog.
        watchdog.feed();
        if out.seq % 10_000 == 0 {
            let l = port.counters();
            defmt::info!(
                "seq {}: stack peak {} bytes; link {} frames sent, {} dropped, commands {} accepted {} rejected, rx errors {}",
                out.seq,
                meter.peak(),
                l.sent,
                l.dropped,
                l.accepted,
                l.rejected,
                rx.errors()
            );
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
                        "seq {} axis {}: E-DAVAR for seq {} L={} ({} bridged) score {=f32} sigma(1/16/256 ms) = {=f32} {=f32} {=f32} dps",
                        out.seq,
                        a,
                        d.seq,
                        e.len,
                        d.bridged,
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
