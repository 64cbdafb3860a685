//! Board firmware for the STM32F405RG gyro board.
//!
//! Wiring: SPI1 (PA5 SCK, PA6 MISO, PA7 MOSI, mode 0, 21 MHz: the
//! ICM-42688-P is rated to 24 MHz) to four ICM-42688-P (CS on PA4, PB0,
//! PB1, PC4); SPI2 (PB13 SCK, PB14 MISO, PB15 MOSI, mode 0, 5.25 MHz: rated
//! to 8 MHz) to one ADXRS453 on the z axis (CS on PC5). The output link
//! (`gyro_array::link`, `docs/link.md`) is USART1 (PA9 TX, PA10 RX) at
//! 6 Mbaud, 8N1 (`link::BAUD`).
//!
//! The application is RTIC 2 (as quartiq's stabilizer runs its sample
//! path): three priorities on the NVIC, each lock a BASEPRI ceiling.
//!
//! | priority | task | does |
//! |---|---|---|
//! | 3 | `uart` (USART1), `uart_dma` (DMA2 stream 7) | the link's bytes in (RXNE, into a queue) and out (by DMA2 from a queue, one transfer at a time; by TXE where DMA does not answer, as on QEMU); share only with each other, at one priority, so no lock holds them off |
//! | 2 | `sample` (SysTick, 1 kHz) | reads the chips at the stated instant, fuses, queues the frame, the calibration's learning (deterministic: every sample, in order) |
//! | 1 | `background` (async, fed by a channel) | the E-DAVARs, status frames, commands, logs, the stack meter |
//!
//! `idle` sleeps. The sample task never waits for the background: the
//! E-DAVARs' newest estimates reach it as a copy (`NoiseSnapshot`), and a
//! background that falls behind loses probes (counted, bridged by the
//! E-DAVAR) rather than delaying a frame. The locks the background still
//! takes over the sample task's resources (the port and the pipeline, to
//! build a status frame or apply a command) are the sample task's only
//! blocking. Every time the board states is TIM5's µs count (the frames'
//! `t_us`, the chips' instants); a sample that starts more than half a
//! period late counts the periods it missed as overruns.
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
//! Logs go out over RTT (defmt), never holding off a higher task: no
//! critical section (a frame that meets another task's is dropped) and no
//! waiting on a probe that holds RTT in blocking mode (a frame that does
//! not fit is dropped); flash and run with `cargo run-board`.
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
//! core if the sample task stops completing samples: 2 s while the array
//! starts and self-tests, then 100 ms nominal (68–188 ms over the LSI's
//! 17–47 kHz datasheet range) against a 1 ms sample period.
#![no_std]
#![no_main]

use core::cell::RefCell;
use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use defmt_rtt as _;

use embedded_hal_bus::spi::{NoDelay, RefCellDevice};
use stm32f4xx_hal::{
    gpio::{self, Edge, ErasedPin, ExtiPin, Output},
    pac,
    prelude::*,
    serial::{config::Config as SerialConfig, Serial},
    spi::{Mode, Phase, Polarity, Spi},
    time::Hertz,
    watchdog::IndependentWatchdog,
};

use gyro_array::algo::fusion::{AdaptiveConfig, Method};
use gyro_array::algo::qualify::QualifyError;
use gyro_array::algo::static_cal::{self, CalRecord};
use gyro_array::app::{self as schedule, timed_clock, SampleClock, BOARD_FRAME_PATH};
use gyro_array::board::f405::{self, ClockSource, CycleDelay, Int1Capture, Int1Captures};
use gyro_array::board::record::Cause;
use gyro_array::board::{persist, stack};
use gyro_array::drivers::adxrs453::{Adxrs453, OnAxis};
use gyro_array::drivers::icm42688::{board_fifo, ClockInput, Icm42688};
use gyro_array::drivers::Gyro;
use gyro_array::link::msg::{Settings, StoreState};
use gyro_array::link::port::{ChipTime, FramePath, NoiseSnapshot, Port};
use gyro_array::link::ring::{TxBuffer, TxConsumer, TxProducer};
use gyro_array::link::{BAUD, FALLBACK_BAUD};
use gyro_array::pipeline::selftest;
use gyro_array::pipeline::startup::start_array;
use gyro_array::pipeline::timed::{AtInstant, TimedIcm, BOARD_DELAY_US};
use gyro_array::pipeline::tracker::{self, NoiseTracker};
use gyro_array::pipeline::{Pipeline, PipelineConfig};
use gyro_array::store::Store;

const FS_HZ: u32 = 1000;
/// ICM-42688-P SPI clock limit (datasheet: 24 MHz).
const ICM_SPI_MAX_HZ: u32 = 24_000_000;
/// ADXRS453 SPI clock limit (datasheet: 8 MHz).
const ADX_SPI_MAX_HZ: u32 = 8_000_000;
/// σ of the link's noise estimates at τ = 2^k ms: 1, 16, 256 ms (the
/// tracker makes their records ready as its estimates are published).
const NOISE_TAU: [usize; 3] = tracker::VIEW_TAUS;

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
    unsafe { core::slice::from_raw_parts(&raw const _calib_start, static_cal::MAX_LEN) }
}

/// The settings store's sectors (`STORE` in memory.x), as offsets into
/// the flash.
#[allow(unsafe_code)]
fn store_range() -> core::ops::Range<u32> {
    unsafe extern "C" {
        static _store_start: u8;
        static _store_end: u8;
    }
    const FLASH_BASE: u32 = 0x0800_0000;
    let at = |p: *const u8| (p as u32).wrapping_sub(FLASH_BASE);
    at(&raw const _store_start)..at(&raw const _store_end)
}

/// The board's settings store.
type BoardStore = Store<f405::StoreFlash>;

/// A start-up step that cannot go on: log it and reset (the record says
/// the firmware asked; the next boot reports it).
fn give_up(what: &str) -> ! {
    defmt::error!("start-up failed: {=str}; resetting", what);
    persist::record_and_reset(Cause::Requested)
}

/// The link's bytes the USART1 interrupt writes in one turn at most
/// (a UART that takes bytes as fast as they come, as QEMU's does, would
/// otherwise keep it for the whole queue).
const TX_TURN: usize = 64;

/// The link's transmit queue: the port writes each frame into it, USART1's
/// task and its DMA stream send the bytes from there (in SRAM: `.bss`).
const TX_BYTES: usize = 4096;
static TX_QUEUE: TxBuffer<TX_BYTES> = TxBuffer::new();

/// The sample task's jobs for the background, in sample order.
const JOBS: usize = 8;

/// What the status frames say of the schedule.
const STATUS_VIEW: schedule::StatusView = schedule::StatusView {
    taus: NOISE_TAU,
    sample_us: 1_000_000 / FS_HZ,
};

/// The stack meter's deepest use so far (the background's meter, the
/// sample task's status frames).
static STACK_PEAK: AtomicU32 = AtomicU32::new(0);

/// Probes the background had no room for (the E-DAVAR bridged them).
static LOST_JOBS: AtomicU32 = AtomicU32::new(0);

/// The controller's newest sync pulse: TIM5's µs at its rising edge on
/// PB8 (EXTI8), and whether the sample task has not taken it yet.
static SYNC_US: AtomicU32 = AtomicU32::new(0);
static SYNC_NEW: AtomicBool = AtomicBool::new(false);

/// What the sample task hands the background: the schedule's job, with
/// what the board's logs need of its sample.
pub struct Work {
    job: schedule::Job,
    /// Gyros whose health flags changed with the sample.
    health_changed: u8,
    /// Each axis's fused rate and weights (for the periodic log).
    fused: [Option<(f32, [f32; 5])>; 3],
}

type Spi1Bus = RefCell<Spi<pac::SPI1>>;
type Spi2Bus = RefCell<Spi<pac::SPI2>>;
type Cs = ErasedPin<Output>;
type IcmDev = RefCellDevice<'static, Spi<pac::SPI1>, Cs, NoDelay>;
type AdxDev = RefCellDevice<'static, Spi<pac::SPI2>, Cs, NoDelay>;
type Timed = TimedIcm<IcmDev, Int1Capture<'static>>;

/// Every chip, as the sample task owns them after start-up.
pub struct Chips {
    timed: [Timed; 4],
    adx: AtInstant<OnAxis<AdxDev>>,
}

// SAFETY: the devices borrow the two buses' RefCells (`init`'s 'static
// locals), which nothing else names; all five move together from `init`
// to the sample task, so no two contexts ever reach one bus. (The RefCells
// are what make the devices !Send; the shared-bus devices that are Send
// have error types defmt cannot print.)
#[allow(unsafe_code)]
unsafe impl Send for Chips {}

/// The link's sending side, as USART1's task and the DMA stream's share
/// it: the transmitter, the bytes the port queued for it, and the board's
/// µs clock (a transfer's time limit).
pub struct TxSide {
    link: f405::TxLink<TX_BYTES>,
    bytes: TxConsumer<TX_BYTES>,
    clock: &'static Int1Captures,
}

/// The link as the sample task and the background share it: the port
/// (frames, settings, commands), which writes its frames into the
/// transmit queue whose reading end USART1's task owns alone, so that
/// nothing it does waits for a lock.
pub struct Link {
    port: &'static mut Port<TxProducer<TX_BYTES>>,
}

impl schedule::Link for Link {
    type Queue = TxProducer<TX_BYTES>;
    fn port(&mut self) -> &mut Port<TxProducer<TX_BYTES>> {
        self.port
    }

    /// Wake USART1's task: it starts a transfer of the queued bytes.
    fn flush(&mut self) {
        rtic::pend(pac::Interrupt::USART1);
    }
}

#[rtic::app(device = stm32f4xx_hal::pac, peripherals = true, dispatchers = [EXTI0])]
mod app {
    use super::*;
    use rtic_sync::channel::{Receiver, Sender};
    use rtic_sync::make_channel;

    #[shared]
    struct Shared {
        pipe: Pipeline<5>,
        link: Link,
        /// The E-DAVARs' newest estimates, for the sample task's frames.
        noise: NoiseSnapshot,
        /// The link's transmitter and the bytes it sends (USART1's task and
        /// the DMA stream's, one priority: no lock is taken).
        tx: TxSide,
    }

    #[local]
    struct Local {
        chips: Chips,
        captures: &'static Int1Captures,
        watchdog: IndependentWatchdog,
        jobs: Sender<'static, Work, JOBS>,
        /// The samples' time: TIM5 against a period measured at start-up.
        clock: SampleClock,
        /// Whether idle sleeps.
        sleep: bool,
        /// Each chip's clock after the last sample, for the status frames.
        clocks: [ChipTime; 5],
        rx_feed: f405::RxFeed,
        rx: f405::RxQueue,
        tracker: &'static mut Tracker,
        meter: stack::StackMeter,
        sync_pin: gpio::PB8<gpio::Input>,
        sync_captures: &'static Int1Captures,
        /// The settings store, and the calibration record in use (saved
        /// beside the settings).
        store: BoardStore,
        calibration: Option<CalRecord>,
    }

    #[init(local = [
        bus1: Option<Spi1Bus> = None,
        bus2: Option<Spi2Bus> = None,
        captures_store: Option<Int1Captures> = None,
        rx_bytes: f405::RxBytes = f405::RxBytes::new(),
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let record = persist::take();
        stack::guard_stack();
        let dp = cx.device;
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
        let mut syst = f405::start_ticks(cx.core.SYST, core_hz, FS_HZ);
        let mut delay = CycleDelay::new(core_hz);

        let gpioa = dp.GPIOA.split(&mut rcc);
        let gpiob = dp.GPIOB.split(&mut rcc);
        let gpioc = dp.GPIOC.split(&mut rcc);
        // The controller's sync pulse on PB8: its rising edge interrupts
        // (EXTI8, the highest priority: its only work is to read TIM5, so
        // its latency is the hardware's plus the longest lock, < 2 µs).
        let mut syscfg = dp.SYSCFG.constrain(&mut rcc);
        let mut exti = dp.EXTI;
        let mut sync_pin = gpiob.pb8.into_pull_down_input();
        sync_pin.make_interrupt_source(&mut syscfg);
        sync_pin.trigger_on_edge(&mut exti, Edge::Rising);
        sync_pin.enable_interrupt(&mut exti);
        // The chips' clock (TIM3 CH1, PC6) and their INT1 captures (TIM5
        // CH1-4, PA0-PA3), before anything else takes the pins.
        let clkin = f405::start_clkin(dp.TIM3, gpioc.pc6.into_alternate(), &mut rcc);
        match clkin {
            Some(hz) => defmt::info!("CLKIN {} Hz on PC6 (TIM3 CH1)", hz),
            None => defmt::warn!(
                "CLKIN: the timer clock does not divide to 32 kHz; the chips keep their own clocks"
            ),
        }
        let Some(captures) = Int1Captures::start(
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
        let captures: &'static Int1Captures = cx.local.captures_store.insert(captures);
        // TIM5's count over eight SysTick periods: 8 000 µs where both
        // run from the one oscillator, as on the board. QEMU's
        // netduinoplus2 clocks its timers and SysTick apart from the RCC it
        // reads as 0, so the firmware measures the period it counts
        // overruns against rather than assume it.
        f405::wait_tick(&mut syst);
        let t0 = captures.micros();
        for _ in 0..8 {
            f405::wait_tick(&mut syst);
        }
        let period_us = (captures.micros().wrapping_sub(t0) / 8).max(1);
        let nominal = 1_000_000 / FS_HZ;
        // Idle sleeps (WFI) where the clocks agree. Where they do not
        // (QEMU), it spins: under QEMU's `-icount sleep=off` a WFI let only
        // every other SysTick through, measured (each sample a period
        // late), bare or with PRIMASK set.
        let sleep = period_us.abs_diff(nominal) <= nominal / 100;
        if !sleep {
            defmt::warn!(
                "TIM5 counts {} us a sample period, not {}: the timers' and the core's clocks disagree (an emulator?); idle spins",
                period_us,
                nominal
            );
        }
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
        let (tx, rx) = serial.split();
        let tx = f405::TxLink::new(tx, dp.DMA2, &mut rcc, baud);
        let (rx_feed, rx) = f405::rx_queue(rx, cx.local.rx_bytes);
        // The saved settings (the defaults where none are saved or the record
        // does not check, said in the log and in every status frame).
        let Some(mut store) = Store::new(f405::StoreFlash::new(dp.FLASH), store_range()) else {
            give_up("settings store range")
        };
        let saved = store.load();
        match saved.state {
            StoreState::Stored => defmt::info!("settings: saved ones in use"),
            StoreState::Corrupt => {
                defmt::warn!("settings: the saved record does not check; defaults")
            }
            _ => defmt::info!("settings: none saved; defaults"),
        }
        let bus: &'static Spi1Bus = cx.local.bus1.insert(RefCell::new(spi1));
        let bus2: &'static Spi2Bus = cx.local.bus2.insert(RefCell::new(spi2));

        let cs0 = gpioa.pa4.into_push_pull_output().erase();
        let cs1 = gpiob.pb0.into_push_pull_output().erase();
        let cs2 = gpiob.pb1.into_push_pull_output().erase();
        let cs3 = gpioc.pc4.into_push_pull_output().erase();
        let cs4 = gpioc.pc5.into_push_pull_output().erase();
        let (Ok(d0), Ok(d1), Ok(d2), Ok(d3), Ok(d4)) = (
            RefCellDevice::new_no_delay(bus, cs0),
            RefCellDevice::new_no_delay(bus, cs1),
            RefCellDevice::new_no_delay(bus, cs2),
            RefCellDevice::new_no_delay(bus, cs3),
            RefCellDevice::new_no_delay(bus2, cs4),
        );
        let (mut g0, mut g1, mut g2, mut g3) = (
            Icm42688::new(d0),
            Icm42688::new(d1),
            Icm42688::new(d2),
            Icm42688::new(d3),
        );
        let mut g4 = OnAxis::new(Adxrs453::new(d4), 2);

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
        // The record saved with the settings, else the lab's in its sector.
        let calibration = match saved.calibration {
            Some(Ok(rec)) => Ok(rec),
            Some(Err(e)) => {
                defmt::warn!("saved calibration record: {}; the lab's record instead", e);
                CalRecord::decode(calib_bytes())
            }
            None => CalRecord::decode(calib_bytes()),
        };
        match pipe.set_calibration(calibration.as_ref().map_err(|e| *e)) {
            Ok(()) => defmt::info!("calibration record in use"),
            Err(e) => defmt::warn!("calibration record: {}; running uncalibrated", e),
        }
        let settings = match pipe.set_method(saved.settings.method.method()) {
            Ok(()) => saved.settings,
            Err(_) => {
                defmt::error!("the saved fusion method is refused; the defaults instead");
                Settings::default()
            }
        };
        // The frame path at the clock the core runs (16 MHz on the fallback
        // oscillator, where its instructions take 625 µs, not 60).
        let path = FramePath {
            core_hz,
            ..BOARD_FRAME_PATH
        };
        let Some(port) = cortex_m::singleton!(
            : Port<TxProducer<TX_BYTES>> = Port::with_queue(TX_QUEUE.stream_producer(), settings, path)
        ) else {
            give_up("link port taken twice")
        };
        port.set_store_state(saved.state);
        // The delay compensation predicts each frame's rates to its last byte
        // at the rate the link runs.
        port.set_timing(baud, 1_000_000 / FS_HZ);
        let failed = start_array(
            [&mut g0, &mut g1, &mut g2, &mut g3],
            &mut g4,
            &mut delay,
            Some(200),
            &mut pipe,
        );

        // E-DAVAR per fused axis: λ2 = 1024 samples (1 s), τ = 1 … 256 ms.
        let Some(tracker) = noise_tracker() else {
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
                    f405::wait_tick(&mut syst);
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
        let cfg = board_fifo(if clkin.is_some() {
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
        let chips = Chips {
            timed: [
                TimedIcm::new(g0, captures.channel(0)),
                TimedIcm::new(g1, captures.channel(1)),
                TimedIcm::new(g2, captures.channel(2)),
                TimedIcm::new(g3, captures.channel(3)),
            ],
            // The ADXRS453's reading is older than the array's instant: read
            // and watched, not fused (z is the four ICM-42688-P's).
            adx: AtInstant::new(g4, BOARD_DELAY_US),
        };

        let u = stack::stack_usage();
        defmt::info!("stack after start-up: {} of {} bytes", u.peak, u.size);
        let meter = stack::StackMeter::new();
        watchdog.start(100.millis());
        let (jobs, inbox) = make_channel!(Work, JOBS);
        if background::spawn(inbox).is_err() {
            give_up("background task spawned twice");
        }
        // The sample task from here: SysTick's exception on (taken once
        // init returns and interrupts are enabled).
        syst.clear_current();
        syst.enable_interrupt();
        let now = captures.micros();
        (
            Shared {
                pipe,
                link: Link { port },
                noise: NoiseSnapshot::default(),
                tx: TxSide {
                    link: tx,
                    bytes: TX_QUEUE.stream_consumer(),
                    clock: captures,
                },
            },
            Local {
                chips,
                captures,
                watchdog,
                jobs,
                clock: SampleClock::new(now, period_us),
                clocks: [ChipTime::default(); 5],
                sleep,
                rx_feed,
                rx,
                tracker,
                meter,
                store,
                calibration: calibration.ok(),
                sync_pin,
                sync_captures: captures,
            },
        )
    }

    #[idle(local = [sleep], shared = [link])]
    fn idle(mut cx: idle::Context) -> ! {
        // The MCU's unique ID for the info frames: probed here, in thread
        // mode with interrupts on, where a bus fault (QEMU's STM32F405 maps
        // no system memory) can be stepped over (`f405::probe_u32`).
        let uid = f405::unique_id();
        cx.shared.link.lock(|l| l.port.set_uid(uid));
        let sleep = *cx.local.sleep;
        loop {
            if sleep {
                cortex_m::asm::wfi();
            } else {
                cortex_m::asm::nop();
            }
        }
    }

    /// One sample: the array read at one instant, fused, its frame queued
    /// and the UART woken; the calibration learns from it; the background
    /// gets its probe (`gyro_array::app::sample`).
    #[task(binds = SysTick, priority = 2, shared = [pipe, link, noise],
           local = [chips, captures, watchdog, jobs, clock, clocks])]
    fn sample(mut cx: sample::Context) {
        let l = cx.local;
        // One clock: TIM5's µs at the read, for the instant and the frame.
        let now = l.captures.micros();
        let (t_us, missed) = l.clock.tick(now);
        // A sync pulse since the last tick, on the same 64-bit µs.
        if SYNC_NEW.swap(false, Ordering::Acquire) {
            // (Signed: the edge may come between `now` and this line.)
            let ago = now.wrapping_sub(SYNC_US.load(Ordering::Relaxed)) as i32;
            let edge = t_us.wrapping_sub(i64::from(ago) as u64);
            cx.shared.link.lock(|l| l.port.sync_pulse(edge));
        }
        let clocks = *l.clocks;
        let Chips { timed, adx } = l.chips;
        let [c0, c1, c2, c3] = timed;
        let mut gyros: [&mut dyn Gyro; 5] = [c0, c1, c2, c3, adx];
        let s = schedule::sample(
            &mut cx.shared.pipe,
            &mut cx.shared.link,
            &mut cx.shared.noise,
            &mut gyros,
            (t_us, missed),
            &STATUS_VIEW,
            || {},
            || schedule::StatusFacts {
                clocks,
                stack_peak: STACK_PEAK.load(Ordering::Relaxed),
            },
        );
        // The chips' clocks as this sample left them, for the next status
        // frame (read after the frame is out, not before the read).
        for (slot, t) in l.clocks.iter_mut().zip(l.chips.timed.iter()) {
            *slot = timed_clock(t);
        }
        let mut fused = [None; 3];
        for (f, o) in fused.iter_mut().zip(s.out.fused.iter()) {
            *f = o.map(|o| (o.rate_dps, o.weights));
        }
        let w = Work {
            job: schedule::Job::from(&s.out),
            health_changed: s.out.health_changed,
            fused,
        };
        // A background this far behind loses the probe (the E-DAVAR
        // bridges it), never the sample task's time.
        if l.jobs.try_send(w).is_err() {
            LOST_JOBS.fetch_add(1, Ordering::Relaxed);
        }
        // A completed sample is the only thing that feeds the watchdog.
        l.watchdog.feed();
    }

    /// The controller's sync pulse: its edge's time on TIM5, for the
    /// sample task to hand to the port (`link::sync`).
    #[task(binds = EXTI9_5, priority = 4, local = [sync_pin, sync_captures])]
    fn sync_pulse(cx: sync_pulse::Context) {
        SYNC_US.store(cx.local.sync_captures.micros(), Ordering::Relaxed);
        SYNC_NEW.store(true, Ordering::Release);
        cx.local.sync_pin.clear_interrupt_pending_bit();
    }

    /// The link's bytes: received into the background's queue; sent from
    /// the UART's queue (a DMA transfer started, or the bytes the UART
    /// takes). Above the sample task and sharing only with the DMA
    /// stream's task, at its priority: at 6 Mbaud a byte arrives every
    /// 1.7 µs and the USART holds one, so no lock may hold this task off.
    #[task(binds = USART1, priority = 3, local = [rx_feed], shared = [tx])]
    fn uart(mut cx: uart::Context) {
        cx.local.rx_feed.on_interrupt();
        cx.shared.tx.lock(|t| {
            let now = t.clock.micros();
            t.link.kick(&mut t.bytes, now, TX_TURN);
        });
    }

    /// The link's DMA transfer ended: the next one.
    #[task(binds = DMA2_STREAM7, priority = 3, shared = [tx])]
    fn uart_dma(mut cx: uart_dma::Context) {
        cx.shared.tx.lock(|t| {
            let now = t.clock.micros();
            t.link.on_dma(&mut t.bytes, now, TX_TURN);
        });
    }

    /// Everything that does not have to be done within the sample
    /// (`gyro_array::app::Background`): the E-DAVARs, commands; and the
    /// logs, the stack meter.
    #[task(priority = 1, shared = [pipe, link, noise], local = [rx, tracker, meter, store, calibration])]
    async fn background(mut cx: background::Context, mut inbox: Receiver<'static, Work, JOBS>) {
        let l = cx.local;
        let mut bg = schedule::Background {
            tracker: l.tracker,
            taus: NOISE_TAU,
        };
        loop {
            // The sender lives in the sample task for good: the channel
            // never closes, and this task never ends.
            let Ok(w) = inbox.recv().await else {
                continue;
            };
            l.meter.step(64);
            STACK_PEAK.store(l.meter.peak(), Ordering::Relaxed);
            bg.run(w.job, &mut cx.shared.noise);
            {
                let probe = w.job;
                if w.health_changed != 0 {
                    log_health(&mut cx.shared.pipe, probe.seq, w.health_changed);
                }
                if probe.seq % 1000 == 0 {
                    log_periodic(&mut cx.shared.pipe, bg.tracker, probe.seq, &w.fused);
                }
                if probe.seq % 10_000 == 0 {
                    let c = cx.shared.link.lock(|l| l.port.counters());
                    defmt::info!(
                        "seq {}: stack peak {} bytes; link {} frames sent, {} dropped, commands {} accepted {} rejected, rx errors {}; probes the background had no room for {}",
                        probe.seq,
                        l.meter.peak(),
                        c.sent,
                        c.dropped,
                        c.accepted,
                        c.rejected,
                        l.rx.errors(),
                        LOST_JOBS.load(Ordering::Relaxed)
                    );
                }
            }
            if l.rx.waiting() {
                schedule::receive(&mut *l.rx, &mut cx.shared.pipe, &mut cx.shared.link);
                schedule::store(l.store, l.calibration.as_ref(), &mut cx.shared.link);
            }
        }
    }

    /// The health flags that changed with sample `seq`, copied out under
    /// the lock and logged after it.
    fn log_health(pipe: &mut impl rtic::Mutex<T = Pipeline<5>>, seq: u32, changed: u8) {
        for i in 0..5 {
            if changed & (1 << i) == 0 {
                continue;
            }
            let (h, c) = pipe.lock(|p| (p.health()[i], p.counters()[i]));
            defmt::warn!(
                "seq {}: gyro {} health flags now {=u8:#07b} ({}; resets {}, restarts {}, restarted {})",
                seq,
                i,
                h.flags,
                h.recovery,
                c.resets,
                c.restarts,
                c.restarted
            );
        }
    }

    /// Once a second: the calibration, the fused rates, the E-DAVARs.
    fn log_periodic(
        pipe: &mut impl rtic::Mutex<T = Pipeline<5>>,
        tracker: &Tracker,
        seq: u32,
        fused: &[Option<(f32, [f32; 5])>; 3],
    ) {
        let cal = pipe.lock(|p| {
            let mut c = [([0.0f32; 5], [0.0f32; 5]); 3];
            for (slot, cal) in c.iter_mut().zip(p.calibration().iter()) {
                *slot = (cal.scale(), cal.bias());
            }
            c
        });
        for (a, (scale, bias)) in cal.iter().enumerate() {
            defmt::info!(
                "seq {} axis {}: relative calibration scale {} bias {} dps",
                seq,
                a,
                scale,
                bias
            );
        }
        for (rate, weights) in fused.iter().flatten() {
            defmt::info!("seq {}: fused {=f32} dps, weights {}", seq, rate, weights);
        }
        for a in 0..3 {
            if let Some(d) = tracker.estimate(a) {
                let e = d.step;
                defmt::info!(
                    "seq {} axis {}: E-DAVAR for seq {} L={} ({} bridged) score {=f32} sigma(1/16/256 ms) = {=f32} {=f32} {=f32} dps",
                    seq,
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
