//! STM32F405 bring-up that does not depend on any one part working:
//! clocks with fallbacks, a cycle-count delay, SysTick sample pacing and an
//! interrupt-fed receive queue for the link's commands (the interrupts
//! themselves are the application's tasks, `src/bin/board_f405.rs`). The same code runs
//! on the board and on QEMU's `netduinoplus2` (whose RCC reads 0: no
//! crystal, no PLL lock), where it takes the last fallback.

use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;
use embedded_hal_nb::nb;
use heapless::spsc::{Consumer, Producer, Queue};
use stm32f4xx_hal::pac::{self, USART1};
use stm32f4xx_hal::prelude::*;
use stm32f4xx_hal::rcc::{Config as RccConfig, Rcc};
use stm32f4xx_hal::serial::Rx;

/// The board's crystal.
pub const HSE_HZ: u32 = 8_000_000;
/// The internal RC oscillator (±1 % over temperature, RM0090 6.2.2).
pub const HSI_HZ: u32 = 16_000_000;
/// The core clock with the PLL.
pub const PLL_HZ: u32 = 168_000_000;
/// Polls of a ready flag before giving up: ≥ 100 ms at 16 MHz (each poll
/// is a volatile read and a branch, ≥ 4 cycles), the HSE start-up budget
/// ST's own HAL uses.
const READY_POLLS: u32 = 400_000;

/// Which clock the core runs on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ClockSource {
    /// Crystal and PLL: 168 MHz, as designed.
    HsePll,
    /// The crystal did not start: internal oscillator and PLL, 168 MHz
    /// (±1 % instead of the crystal's ppm).
    HsiPll,
    /// Nor did the PLL lock: the internal oscillator alone, 16 MHz. The
    /// per-sample work then takes ten times longer.
    Hsi,
}

fn wait_for(ready: impl Fn() -> bool) -> bool {
    (0..READY_POLLS).any(|_| ready())
}

/// Does the PLL lock from this source? (M = source/1 MHz, N = 336, P = 2:
/// the 168 MHz set-up the HAL programs too.) Leaves the PLL off.
#[allow(unsafe_code)]
fn pll_locks(rcc: &pac::RCC, hse: bool) -> bool {
    let m = if hse { HSE_HZ } else { HSI_HZ } / 1_000_000;
    // SAFETY: M = 8 or 16, N = 336 and Q = 7 are valid field values
    // (RM0090 6.3.2: 2 ≤ M ≤ 63, 50 ≤ N ≤ 432, 2 ≤ Q ≤ 15).
    rcc.pllcfgr().write(|w| unsafe {
        w.pllm().bits(m as u8);
        w.plln().bits(336);
        w.pllp().div2();
        w.pllq().bits(7);
        w.pllsrc().bit(hse)
    });
    rcc.cr().modify(|_, w| w.pllon().set_bit());
    let ok = wait_for(|| rcc.cr().read().pllrdy().bit_is_set());
    rcc.cr().modify(|_, w| w.pllon().clear_bit());
    ok
}

/// Start the clocks: the crystal and PLL if they come up, else the best
/// fallback (see [`ClockSource`]). The HAL's `freeze` waits for ready
/// flags without a time-out, so each part is tried here first, with one.
pub fn start_clocks(rcc: pac::RCC) -> (Rcc, ClockSource) {
    rcc.cr().modify(|_, w| w.hseon().set_bit());
    let hse = wait_for(|| rcc.cr().read().hserdy().bit_is_set());
    if !hse {
        rcc.cr().modify(|_, w| w.hseon().clear_bit());
    }
    let (cfg, src) = if hse && pll_locks(&rcc, true) {
        (
            RccConfig::hse(HSE_HZ.Hz()).sysclk(PLL_HZ.Hz()),
            ClockSource::HsePll,
        )
    } else if pll_locks(&rcc, false) {
        (RccConfig::hsi().sysclk(PLL_HZ.Hz()), ClockSource::HsiPll)
    } else {
        (RccConfig::hsi().sysclk(HSI_HZ.Hz()), ClockSource::Hsi)
    };
    (rcc.freeze(cfg), src)
}

/// A delay that counts core cycles (no timer: QEMU does not model the
/// one-pulse mode a timer delay needs). At least as long as asked.
pub struct CycleDelay {
    hz: u32,
}

impl CycleDelay {
    /// For a core running at `hz`.
    pub fn new(hz: u32) -> Self {
        Self { hz }
    }
}

impl embedded_hal::delay::DelayNs for CycleDelay {
    fn delay_ns(&mut self, ns: u32) {
        let cycles = (u64::from(ns) * u64::from(self.hz)).div_ceil(1_000_000_000);
        cortex_m::asm::delay(cycles.clamp(1, u64::from(u32::MAX)) as u32);
    }
}

/// Tick at `rate_hz` from a core clock of `core_hz` (SysTick reload ≤ 2²⁴),
/// its exception left off: the application turns it on once the array
/// has started ([`wait_tick`] paces the start-up until then).
pub fn start_ticks(mut syst: SYST, core_hz: u32, rate_hz: u32) -> SYST {
    syst.disable_counter();
    syst.disable_interrupt();
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload((core_hz / rate_hz.max(1)).clamp(2, 1 << 24) - 1);
    syst.clear_current();
    syst.enable_counter();
    syst
}

/// Wait for the next SysTick wrap, polled (COUNTFLAG; ARMv7-M ARM
/// B3.3.3): the start-up's pacing, before the sample task owns the tick.
pub fn wait_tick(syst: &mut SYST) {
    while !syst.has_wrapped() {
        core::hint::spin_loop();
    }
}

/// The link's received bytes, queued by USART1's interrupt so that none
/// is lost while the background is busy (the USART holds one byte).
pub type RxBytes = Queue<u8, 256>;

/// Receive errors (overrun, framing, noise, parity) and queue overflows.
static RX_ERRORS: AtomicU32 = AtomicU32::new(0);

/// The interrupt's side of the receive queue: USART1's receiver and the
/// queue's producer.
pub struct RxFeed {
    rx: Rx<USART1>,
    queue: Producer<'static, u8>,
}

impl RxFeed {
    /// Take what the receiver holds (from USART1's interrupt). Bounded:
    /// the USART holds one byte; errors clear on read.
    pub fn on_interrupt(&mut self) {
        for _ in 0..4 {
            match embedded_hal_nb::serial::Read::read(&mut self.rx) {
                Ok(b) => {
                    if self.queue.enqueue(b).is_err() {
                        RX_ERRORS.fetch_add(1, Ordering::Relaxed);
                    }
                }
                Err(nb::Error::WouldBlock) => break,
                Err(nb::Error::Other(_)) => {
                    RX_ERRORS.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    }
}

/// The receive side of the link as the background reads it: the queue's
/// consumer.
pub struct RxQueue {
    queue: Consumer<'static, u8>,
}

impl RxQueue {
    /// Bytes waiting.
    pub fn waiting(&self) -> bool {
        self.queue.ready()
    }

    /// Receive errors and dropped bytes so far.
    pub fn errors(&self) -> u32 {
        RX_ERRORS.load(Ordering::Relaxed)
    }
}

/// Split USART1's receiver into the interrupt's feed and the background's
/// queue over `store`, its RXNE interrupt on. Unmasking USART1 in the
/// NVIC is the application's (its task binds it).
pub fn rx_queue(mut rx: Rx<USART1>, store: &'static mut RxBytes) -> (RxFeed, RxQueue) {
    use stm32f4xx_hal::serial::RxListen;
    rx.listen();
    let (p, c) = store.split();
    (RxFeed { rx, queue: p }, RxQueue { queue: c })
}

impl embedded_hal_nb::serial::ErrorType for RxQueue {
    type Error = core::convert::Infallible;
}

impl embedded_hal_nb::serial::Read<u8> for RxQueue {
    fn read(&mut self) -> nb::Result<u8, Self::Error> {
        self.queue.dequeue().ok_or(nb::Error::WouldBlock)
    }
}

/// The ICM-42688-Ps' CLKIN (their pin 9, set to CLKIN through
/// INTF_CONFIG5): TIM3 channel 1 on PC6 (AF2), at half duty. 32 kHz is in
/// the 31–50 kHz RTC-mode range, gives the chips' 4 kHz ODR as CLKIN / 8,
/// and both of the board's APB1 timer clocks divide to it exactly
/// (84 MHz / 2 625 with the PLL, 16 MHz / 500 on the internal oscillator
/// alone).
pub const CLKIN_HZ: u32 = 32_000;

/// Start CLKIN on PC6. Returns the frequency made, Hz, or `None` (and
/// leaves the timer off) when the timer clock does not divide to
/// [`CLKIN_HZ`] within TIM3's 16-bit period: the chips then run on their
/// own clocks, tracked (`pipeline::clock`).
pub fn start_clkin(
    tim: pac::TIM3,
    _pin: stm32f4xx_hal::gpio::Pin<'C', 6, stm32f4xx_hal::gpio::Alternate<2>>,
    rcc: &mut Rcc,
) -> Option<u32> {
    use stm32f4xx_hal::rcc::Enable;
    let clk = rcc.clocks.timclk1().raw();
    let period = clk / CLKIN_HZ;
    if period < 2 || period > u32::from(u16::MAX) + 1 || clk % CLKIN_HZ != 0 {
        return None;
    }
    pac::TIM3::enable(rcc);
    // RM0090 18.3.9 (PWM mode 1): high while CNT < CCR1, period ARR + 1.
    tim.psc().write(|w| w.psc().set(0));
    tim.arr().write(|w| w.arr().set((period - 1) as u16));
    tim.ccr1().write(|w| w.ccr().set((period / 2) as u16));
    tim.ccmr1_output()
        .modify(|_, w| w.oc1m().pwm_mode1().oc1pe().set_bit());
    tim.ccer()
        .modify(|_, w| w.cc1e().set_bit().cc1p().clear_bit());
    tim.egr().write(|w| w.ug().set_bit());
    tim.cr1().modify(|_, w| w.arpe().set_bit().cen().set_bit());
    Some(clk / period)
}

/// The chips' INT1 pulses (one at each sample: `Sampling::Fifo`'s INT1
/// set-up), captured by TIM5 channels 1–4 on PA0–PA3 (AF2), rising edge,
/// against TIM5 counting µs on its 32 bits (it wraps after 71 minutes;
/// the clock tracker works in wrapping µs). TIM5's count is the board's µs
/// clock for the instants the array states ([`Int1Captures::micros`]).
pub struct Int1Captures {
    tim: pac::TIM5,
}

// SAFETY: shared only for reads of CNT and the capture registers (one
// 32-bit load each) and, per channel, the write of SR that clears that
// channel's overcapture flag alone (rc_w0: 1 leaves the other flags); no
// read-modify-write of a register two channels share.
#[allow(unsafe_code)]
unsafe impl Sync for Int1Captures {}

/// The INT1 pins, in chip order.
pub type Int1Pins = (
    stm32f4xx_hal::gpio::Pin<'A', 0, stm32f4xx_hal::gpio::Alternate<2>>,
    stm32f4xx_hal::gpio::Pin<'A', 1, stm32f4xx_hal::gpio::Alternate<2>>,
    stm32f4xx_hal::gpio::Pin<'A', 2, stm32f4xx_hal::gpio::Alternate<2>>,
    stm32f4xx_hal::gpio::Pin<'A', 3, stm32f4xx_hal::gpio::Alternate<2>>,
);

impl Int1Captures {
    /// Start TIM5 at 1 MHz with its four channels capturing. `None` when
    /// the timer clock is not a whole number of MHz.
    pub fn start(tim: pac::TIM5, _pins: Int1Pins, rcc: &mut Rcc) -> Option<Self> {
        use stm32f4xx_hal::rcc::Enable;
        let clk = rcc.clocks.timclk1().raw();
        if clk % 1_000_000 != 0 || clk < 1_000_000 {
            return None;
        }
        pac::TIM5::enable(rcc);
        tim.psc()
            .write(|w| w.psc().set((clk / 1_000_000 - 1) as u16));
        tim.arr().write(|w| w.arr().set(u32::MAX));
        // RM0090 18.3.5: CCxS = TIx, no filter, no prescaler; CCxP = 0
        // (rising edge: INT1 is push-pull, active high, pulsed).
        tim.ccmr1_input().modify(|_, w| w.cc1s().ti1().cc2s().ti2());
        tim.ccmr2_input().modify(|_, w| w.cc3s().ti3().cc4s().ti4());
        tim.ccer().modify(|_, w| {
            w.cc1p().clear_bit().cc1e().set_bit();
            w.cc2p().clear_bit().cc2e().set_bit();
            w.cc3p().clear_bit().cc3e().set_bit();
            w.cc4p().clear_bit().cc4e().set_bit()
        });
        tim.egr().write(|w| w.ug().set_bit());
        tim.cr1().modify(|_, w| w.cen().set_bit());
        Some(Self { tim })
    }

    /// The board's µs clock (TIM5's count).
    pub fn micros(&self) -> u32 {
        self.tim.cnt().read().bits()
    }

    /// Chip `ch`'s capture (0..=3).
    pub fn channel(&self, ch: usize) -> Int1Capture<'_> {
        Int1Capture {
            tim: self,
            ch: ch.min(3),
            last: None,
        }
    }
}

/// One chip's INT1 capture ([`crate::drivers::SampleCapture`]).
pub struct Int1Capture<'a> {
    tim: &'a Int1Captures,
    ch: usize,
    last: Option<u32>,
}

impl crate::drivers::SampleCapture for Int1Capture<'_> {
    #[allow(unsafe_code)]
    fn last_us(&mut self) -> Option<u32> {
        let sr = self.tim.tim.sr().read().bits();
        if sr & (1 << (1 + self.ch)) != 0 {
            // Reading CCRx clears CCxIF (RM0090 18.4.5). A pulse captured
            // over an unread one sets CCxOF: the register holds the newer,
            // which is the one wanted; the flag is cleared by writing 0 to
            // it and 1 elsewhere (rc_w0: the other channels' flags are
            // left as they are).
            self.last = Some(self.tim.tim.ccr(self.ch).read().bits());
            if sr & (1 << (9 + self.ch)) != 0 {
                // SAFETY: SR's flags are rc_w0; writing 1 leaves them.
                self.tim
                    .tim
                    .sr()
                    .write(|w| unsafe { w.bits(!(1 << (9 + self.ch))) });
            }
        }
        self.last
    }
}

/// The MCU's flash under the settings store (`gyro_array::store`):
/// stm32f4xx-hal's blocking `NorFlash` (byte programming, 128 KiB erase
/// unit, reprogramming allowed: RM0090 3.6) behind the async trait the
/// store is written against. Unlocked for each program or erase only, so a
/// stray write at any other time faults instead of changing the flash.
pub struct StoreFlash(stm32f4xx_hal::flash::LockedFlash);

impl StoreFlash {
    /// The flash, locked.
    pub fn new(flash: pac::FLASH) -> Self {
        Self(stm32f4xx_hal::flash::LockedFlash::new(flash))
    }
}

impl embedded_storage_async::nor_flash::ErrorType for StoreFlash {
    type Error = stm32f4xx_hal::flash::Error;
}

impl embedded_storage_async::nor_flash::ReadNorFlash for StoreFlash {
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        embedded_storage::nor_flash::ReadNorFlash::read(&mut self.0, offset, bytes)
    }

    fn capacity(&self) -> usize {
        embedded_storage::nor_flash::ReadNorFlash::capacity(&self.0)
    }
}

impl embedded_storage_async::nor_flash::NorFlash for StoreFlash {
    const WRITE_SIZE: usize = 1;
    const ERASE_SIZE: usize = 128 * 1024;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        use stm32f4xx_hal::flash::FlashExt;
        // A 128 KiB sector erase at the HAL's x8 parallelism takes up to
        // 4 s (datasheet table 39), with every fetch from flash stalled: no
        // task can feed the watchdog meanwhile, so its period is widened
        // for the erase and put back after.
        let saved = widen_watchdog();
        let r = embedded_storage::nor_flash::NorFlash::erase(&mut self.0.unlocked(), from, to);
        restore_watchdog(saved);
        r
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        use stm32f4xx_hal::flash::FlashExt;
        embedded_storage::nor_flash::NorFlash::write(&mut self.0.unlocked(), offset, bytes)
    }
}

impl embedded_storage_async::nor_flash::MultiwriteNorFlash for StoreFlash {}

/// The independent watchdog's prescaler and reload values.
type WatchdogPeriod = (u8, u16);

/// Reload the watchdog and set its period to 8 s (LSI 32 kHz / 256, 1 000
/// counts); what it was, back.
#[allow(unsafe_code)]
fn widen_watchdog() -> WatchdogPeriod {
    // SAFETY: the IWDG's registers only; the sample task writes nothing
    // but the reload key (KR = 0xAAAA), which is safe at any time, and the
    // background task that saves is the only writer of PR and RLR after
    // start-up.
    let iwdg = unsafe { pac::IWDG::steal() };
    let saved = (iwdg.pr().read().pr().bits(), iwdg.rlr().read().rl().bits());
    set_watchdog(&iwdg, (6, 1000));
    saved
}

/// Put the watchdog's period back and reload it.
#[allow(unsafe_code)]
fn restore_watchdog(saved: WatchdogPeriod) {
    // SAFETY: as in `widen_watchdog`.
    let iwdg = unsafe { pac::IWDG::steal() };
    set_watchdog(&iwdg, saved);
}

/// RM0090 21.3.2: unlock PR and RLR (0x5555), write them, wait until the
/// watchdog has taken both (PVU, RVU clear), reload (0xAAAA).
#[allow(unsafe_code)]
fn set_watchdog(iwdg: &pac::IWDG, (pr, rl): WatchdogPeriod) {
    iwdg.kr().write(|w| unsafe { w.key().bits(0xAAAA) });
    iwdg.kr().write(|w| unsafe { w.key().bits(0x5555) });
    iwdg.pr().write(|w| unsafe { w.pr().bits(pr) });
    iwdg.rlr().write(|w| unsafe { w.rl().bits(rl) });
    let mut polls = READY_POLLS;
    while iwdg.sr().read().bits() & 0b11 != 0 && polls > 0 {
        polls -= 1;
    }
    iwdg.kr().write(|w| unsafe { w.key().bits(0xAAAA) });
}

/// The MCU's 96-bit unique ID (RM0090 39.1, at 0x1FFF_7A10), as bytes in
/// address order.
pub fn unique_id() -> [u8; 12] {
    let uid = stm32f4xx_hal::signature::Uid::get();
    let mut out = [0u8; 12];
    out[0..2].copy_from_slice(&uid.x().to_le_bytes());
    out[2..4].copy_from_slice(&uid.y().to_le_bytes());
    out[4] = uid.waf_num();
    out[5..12].copy_from_slice(uid.lot_num().as_bytes());
    out
}
