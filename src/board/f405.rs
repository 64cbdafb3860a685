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

use crate::link::ring::{TxConsumer, TxGrant};

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

/// The MCU's flash under the settings store (`gyro_array::store`), on its
/// registers (RM0090 3.6): byte programming (PSIZE x8, so any byte may be
/// written, as the store's 1-byte write size needs), sector erase at x32
/// (the board runs at 3.3 V: 1–2 s for 128 KiB, datasheet table 39), and a
/// byte may be programmed again to clear more bits (the F4 has no ECC on
/// its flash words). Unlocked for each program or erase only, so a stray
/// write at any other time faults instead of changing the flash.
///
/// Written on the registers rather than through stm32f4xx-hal's `NorFlash`:
/// that one sizes the flash from its size register in system memory
/// (0x1FFF_7A22), which QEMU's STM32F405 does not map (the read bus-faults,
/// and the board-f405 run in CI with it); this one knows the part (1 MiB,
/// RM0090 table 5) and touches only the flash and its registers.
pub struct StoreFlash {
    regs: pac::FLASH,
}

/// Why a flash operation failed (FLASH_SR's error bits, RM0090 3.8.4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, defmt::Format)]
pub enum FlashError {
    /// Outside the flash.
    OutOfBounds,
    /// An erase not on sector boundaries.
    NotAligned,
    /// PGSERR, PGPERR or PGAERR: the programming sequence.
    Sequence,
    /// WRPERR: the sector is write-protected.
    Protected,
    /// OPERR.
    Operation,
}

impl embedded_storage_async::nor_flash::NorFlashError for FlashError {
    fn kind(&self) -> embedded_storage_async::nor_flash::NorFlashErrorKind {
        use embedded_storage_async::nor_flash::NorFlashErrorKind as K;
        match self {
            Self::OutOfBounds => K::OutOfBounds,
            Self::NotAligned => K::NotAligned,
            _ => K::Other,
        }
    }
}

/// The STM32F405RG's flash: 1 MiB at 0x0800_0000 (RM0090 table 5).
const FLASH_BASE: u32 = 0x0800_0000;
const FLASH_LEN: u32 = 1 << 20;
/// Sectors 5 to 11 are 128 KiB from 0x2_0000 (sectors 0–4 hold the
/// firmware; the store never erases them).
const BIG_SECTOR: u32 = 128 * 1024;

#[allow(unsafe_code)]
impl StoreFlash {
    /// The flash, locked.
    pub fn new(regs: pac::FLASH) -> Self {
        Self { regs }
    }

    fn unlock(&mut self) {
        // RM0090 3.5.1: the two keys in order unlock FLASH_CR.
        if self.regs.cr().read().lock().bit_is_set() {
            self.regs
                .keyr()
                .write(|w| unsafe { w.key().bits(0x4567_0123) });
            self.regs
                .keyr()
                .write(|w| unsafe { w.key().bits(0xCDEF_89AB) });
        }
    }

    fn lock(&mut self) {
        self.regs.cr().modify(|_, w| w.lock().set_bit());
    }

    /// Wait for BSY to clear, then the error bits (cleared for the next
    /// operation).
    fn finish(&mut self) -> Result<(), FlashError> {
        while self.regs.sr().read().bsy().bit_is_set() {}
        let sr = self.regs.sr().read();
        let r = if sr.wrperr().bit_is_set() {
            Err(FlashError::Protected)
        } else if sr.pgserr().bit_is_set() || sr.pgperr().bit_is_set() || sr.pgaerr().bit_is_set() {
            Err(FlashError::Sequence)
        } else if sr.operr().bit_is_set() {
            Err(FlashError::Operation)
        } else {
            Ok(())
        };
        // (The error bits clear by writing 1.)
        self.regs.sr().write(|w| unsafe { w.bits(0xF3) });
        r
    }

    fn erase_sector(&mut self, n: u8) -> Result<(), FlashError> {
        self.unlock();
        // SER, the sector, x32 parallelism; then STRT.
        self.regs.cr().modify(|_, w| unsafe {
            w.pg()
                .clear_bit()
                .ser()
                .set_bit()
                .snb()
                .bits(n)
                .psize()
                .bits(0b10)
        });
        self.regs.cr().modify(|_, w| w.strt().set_bit());
        let r = self.finish();
        self.regs.cr().modify(|_, w| w.ser().clear_bit());
        self.lock();
        r
    }

    fn program(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        self.unlock();
        self.regs
            .cr()
            .modify(|_, w| unsafe { w.ser().clear_bit().pg().set_bit().psize().bits(0b00) });
        let mut r = Ok(());
        for (k, &b) in bytes.iter().enumerate() {
            let at = (FLASH_BASE + offset + k as u32) as *mut u8;
            // SAFETY: inside the flash (checked by the caller), with PG set:
            // the write programs the byte (RM0090 3.6.4).
            unsafe { at.write_volatile(b) };
            r = self.finish();
            if r.is_err() {
                break;
            }
        }
        self.regs.cr().modify(|_, w| w.pg().clear_bit());
        self.lock();
        r
    }
}

fn in_flash(offset: u32, len: usize) -> Result<(), FlashError> {
    let end = offset
        .checked_add(len as u32)
        .ok_or(FlashError::OutOfBounds)?;
    if end > FLASH_LEN {
        return Err(FlashError::OutOfBounds);
    }
    Ok(())
}

impl embedded_storage_async::nor_flash::ErrorType for StoreFlash {
    type Error = FlashError;
}

impl embedded_storage_async::nor_flash::ReadNorFlash for StoreFlash {
    const READ_SIZE: usize = 1;

    #[allow(unsafe_code)]
    fn read(
        &mut self,
        offset: u32,
        bytes: &mut [u8],
    ) -> impl core::future::Future<Output = Result<(), FlashError>> {
        // (Answered at once: no `async fn`, whose resumed-after-completion
        // check would be a panic site in the firmware.)
        core::future::ready((|| {
            in_flash(offset, bytes.len())?;
            for (k, b) in bytes.iter_mut().enumerate() {
                // SAFETY: memory-mapped flash, inside the part (checked above).
                *b = unsafe { ((FLASH_BASE + offset + k as u32) as *const u8).read_volatile() };
            }
            Ok(())
        })())
    }

    fn capacity(&self) -> usize {
        FLASH_LEN as usize
    }
}

impl embedded_storage_async::nor_flash::NorFlash for StoreFlash {
    const WRITE_SIZE: usize = 1;
    const ERASE_SIZE: usize = BIG_SECTOR as usize;

    fn erase(
        &mut self,
        from: u32,
        to: u32,
    ) -> impl core::future::Future<Output = Result<(), FlashError>> {
        // (Answered at once: no `async fn`, whose resumed-after-completion
        // check would be a panic site in the firmware.)
        core::future::ready((|| {
            in_flash(from, to.saturating_sub(from) as usize)?;
            // (Only the 128 KiB sectors: the ones below hold the vectors.)
            if from < BIG_SECTOR
                || !from.is_multiple_of(BIG_SECTOR)
                || !to.is_multiple_of(BIG_SECTOR)
            {
                return Err(FlashError::NotAligned);
            }
            // A 128 KiB sector erase stalls every fetch from flash for up to
            // 2 s: no task can feed the watchdog meanwhile, so its period is
            // widened for the erase and put back after.
            let saved = widen_watchdog();
            let mut r = Ok(());
            for start in (from..to).step_by(BIG_SECTOR as usize) {
                // Sector 5 starts at 0x2_0000, then one every 128 KiB.
                let n = (5 + (start - BIG_SECTOR) / BIG_SECTOR) as u8;
                r = self.erase_sector(n);
                if r.is_err() {
                    break;
                }
            }
            restore_watchdog(saved);
            r
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
            in_flash(offset, bytes.len())?;
            self.program(offset, bytes)
        })())
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
/// address order; zeros where the system memory does not answer (QEMU's
/// STM32F405 does not map it: the read is probed, not taken).
pub fn unique_id() -> [u8; 12] {
    let mut out = [0u8; 12];
    for (k, chunk) in out.chunks_exact_mut(4).enumerate() {
        match probe_u32(0x1FFF_7A10 + 4 * k) {
            Some(w) => chunk.copy_from_slice(&w.to_le_bytes()),
            None => return [0; 12],
        }
    }
    out
}

/// A word read that may bus-fault, taken as `None` instead: BusFault is
/// enabled for the one `ldr.w`, and its handler (below), finding a probe
/// armed, marks it failed and returns past the load (ARMv7-M ARM B1.5.6:
/// the stacked PC is the faulting instruction's). Needs PRIMASK clear (a
/// masked BusFault escalates to HardFault): call it from thread mode with
/// interrupts on, as `idle` does.
#[allow(unsafe_code)]
pub fn probe_u32(addr: usize) -> Option<u32> {
    const SHCSR: *mut u32 = 0xE000_ED24 as *mut u32;
    const BUSFAULTENA: u32 = 1 << 17;
    let v: u32;
    // SAFETY: SHCSR's enable bit, set for the probe and cleared after; the
    // load is of any address, its fault taken by `BusFault`, which skips
    // exactly this 4-byte instruction.
    unsafe {
        SHCSR.write_volatile(SHCSR.read_volatile() | BUSFAULTENA);
        core::arch::asm!("dsb", "isb");
        PROBE.store(1, Ordering::SeqCst);
        core::arch::asm!("ldr.w {v}, [{a}]", v = out(reg) v, a = in(reg) addr, options(nostack, readonly));
        let faulted = PROBE.swap(0, Ordering::SeqCst) == 2;
        SHCSR.write_volatile(SHCSR.read_volatile() & !BUSFAULTENA);
        core::arch::asm!("dsb", "isb");
        (!faulted).then_some(v)
    }
}

/// 1 while [`probe_u32`] loads, 2 once its load faulted.
static PROBE: AtomicU32 = AtomicU32::new(0);

// BusFault: a probe's fault is marked and stepped over (the stacked PC
// moved past the 4-byte load, BFSR cleared, write-1-to-clear); any other
// goes on to the HardFault handler, which records it and resets
// (`board::persist`): LR still holds the EXC_RETURN that handler reads.
#[allow(unsafe_code)]
mod bus_fault {
    core::arch::global_asm!(
    ".section .text.BusFault,\"ax\",%progbits",
    ".global BusFault",
    ".type BusFault,%function",
    ".thumb_func",
    "BusFault:",
    "  ldr r0, ={probe}",
    "  ldr r1, [r0]",
    "  cmp r1, #1",
    "  bne 1f",
    "  movs r1, #2",
    "  str r1, [r0]",
    "  tst lr, #4",
    "  ite eq",
    "  mrseq r2, msp",
    "  mrsne r2, psp",
    "  ldr r1, [r2, #24]",
    "  adds r1, #4",
    "  str r1, [r2, #24]",
    "  ldr r0, =0xE000ED28",
    "  mov r1, #0xFF00",
    "  str r1, [r0]",
    "  bx lr",
    "1:",
    "  b HardFault",
    probe = sym super::PROBE,
    );
}

/// The link's transmitter: USART1 fed by DMA2 stream 7, channel 4
/// (USART1_TX; RM0090 Table 43), one transfer at a time straight from the
/// transmit queue the port wrote its frames into (a `Q`-byte
/// [`TxBuffer`](crate::link::ring::TxBuffer), in SRAM: DMA cannot reach
/// the core-coupled RAM, RM0090 2.3.1), its bytes released once sent; or,
/// where DMA does not answer (QEMU's `netduinoplus2` models none) or a
/// transfer failed, by USART1's TXE interrupt a byte at a time.
///
/// Why DMA: at 6 Mbaud the UART takes a byte every 1.7 µs; by TXE a
/// 93-byte sample frame is 93 interrupts a millisecond, each some 60
/// cycles with its entry and exit (ARMv7-M: 12 to enter, 10 to return),
/// about 3 % of the core at 168 MHz and as many preemptions of whatever
/// runs. By DMA it is one interrupt, and no byte is copied.
pub struct TxLink<const Q: usize> {
    tx: stm32f4xx_hal::serial::Tx<USART1>,
    /// DMA2, while the link uses it.
    dma: Option<pac::DMA2>,
    /// The queued bytes the transfer in flight sends, and how many of
    /// them (NDTR's 16 bits).
    in_flight: Option<(TxGrant<Q>, u16)>,
    /// The transfer's start (TIM5 µs) and how long it may take.
    started_us: u32,
    limit_us: u32,
    /// A byte's time on the wire, in ns (10 bits).
    byte_ns: u32,
}

/// Clear every flag of DMA2 stream 7 (RM0090 10.5.4: a stream is enabled
/// only with its flags clear).
fn clear_flags(dma: &pac::DMA2) {
    dma.hifcr().write(|w| {
        w.ctcif7().clear();
        w.chtif7().clear();
        w.cteif7().clear();
        w.cdmeif7().clear();
        w.cfeif7().clear()
    });
}

impl<const Q: usize> TxLink<Q> {
    /// The link's transmitter at `baud`: DMA2 stream 7 if a copy of one
    /// word by DMA2 (memory to memory, RM0090 10.3.6) completes, else
    /// interrupts (logged). Enables DMA2's clock.
    #[allow(unsafe_code)]
    pub fn new(
        tx: stm32f4xx_hal::serial::Tx<USART1>,
        dma: pac::DMA2,
        rcc: &mut Rcc,
        baud: u32,
    ) -> Self {
        use stm32f4xx_hal::rcc::{Enable, Reset};
        pac::DMA2::enable(rcc);
        pac::DMA2::reset(rcc);
        let mut link = Self {
            tx,
            dma: None,
            in_flight: None,
            started_us: 0,
            limit_us: 0,
            byte_ns: (10_000_000_000u64 / u64::from(baud.max(1))) as u32,
        };
        let src: u32 = 0x5a5a_a5a5;
        let mut dst: u32 = 0;
        let st = dma.st(7);
        // SAFETY: the stream is off (reset above); the addresses are two
        // words on this stack that outlive the poll below, which waits for
        // the transfer's end or turns the stream off before returning.
        unsafe {
            // Memory to memory runs through the FIFO (RM0090 10.3.11: no
            // direct mode there).
            st.fcr().write(|w| {
                w.dmdis().disabled();
                w.fth().full()
            });
            st.par().write(|w| w.pa().bits(&raw const src as u32));
            st.m0ar().write(|w| w.m0a().bits(&raw mut dst as u32));
            st.ndtr().write(|w| w.ndt().bits(1));
            st.cr().write(|w| {
                w.dir().memory_to_memory();
                w.pinc().incremented();
                w.minc().incremented();
                w.psize().bits32();
                w.msize().bits32();
                w.en().enabled()
            });
        }
        let done = (0..1000).any(|_| dma.hisr().read().tcif7().is_complete());
        st.cr().modify(|_, w| w.en().disabled());
        clear_flags(&dma);
        // SAFETY: the transfer has ended or the stream is off: nothing
        // writes `dst` any more.
        let copied = unsafe { core::ptr::read_volatile(&raw const dst) } == src;
        // Every register of the stream back to its reset value (direct
        // mode for the UART's transfers).
        pac::DMA2::reset(rcc);
        if done && copied {
            // SAFETY: USART1's DMA request for transmission (RM0090
            // 30.6.6 CR3.DMAT); the driver sets no other CR3 bit.
            unsafe { (*USART1::ptr()).cr3().modify(|_, w| w.dmat().set_bit()) };
            link.dma = Some(dma);
            defmt::info!("link: sent by DMA2 stream 7");
        } else {
            defmt::warn!("link: DMA2 did not copy a word; sent by USART1's interrupt");
        }
        link
    }

    /// Send what `queue` holds: start a transfer if none is in flight, or
    /// end one that has overrun its time; on the interrupt path, write
    /// while the UART takes bytes (at most `turn`). `now_us` is TIM5's.
    /// From USART1's task and the DMA stream's, both at one priority.
    pub fn kick(&mut self, queue: &mut TxConsumer<Q>, now_us: u32, turn: usize) {
        if self.in_flight.is_some() {
            if now_us.wrapping_sub(self.started_us) <= self.limit_us {
                return;
            }
            self.fail();
        }
        let Some(dma) = &self.dma else {
            self.by_interrupt(queue, turn);
            return;
        };
        // The oldest contiguous run of queued bytes (the rest, past the
        // buffer's end, is the next transfer's).
        let Ok(bytes) = queue.read() else { return };
        let n = bytes.len().min(usize::from(u16::MAX)) as u16;
        // The port's writes land before the stream may read them (the
        // register writes below are volatile; the bytes' writes are not).
        core::sync::atomic::compiler_fence(Ordering::Release);
        let st = dma.st(7);
        clear_flags(dma);
        // SAFETY: the stream is off (no transfer in flight); the bytes are
        // the 'static queue's, held by the read grant kept in `in_flight`
        // until the transfer has ended or been stopped (the port cannot
        // write them meanwhile); PAR is USART1's data register.
        #[allow(unsafe_code)]
        unsafe {
            st.par()
                .write(|w| w.pa().bits((*USART1::ptr()).dr().as_ptr() as u32));
            st.m0ar().write(|w| w.m0a().bits(bytes.as_ptr() as u32));
            st.ndtr().write(|w| w.ndt().bits(n));
            st.cr().write(|w| {
                w.chsel().bits(4);
                w.dir().memory_to_peripheral();
                w.minc().incremented();
                w.psize().bits8();
                w.msize().bits8();
                w.pl().high();
                w.tcie().enabled();
                w.teie().enabled();
                w.en().enabled()
            });
        }
        self.in_flight = Some((bytes, n));
        self.started_us = now_us;
        // Twice the bytes' wire time and 200 µs: a transfer that takes
        // longer has stopped (a stalled stream, a lost request).
        self.limit_us = 200 + (2 * u64::from(n) * u64::from(self.byte_ns) / 1000) as u32;
    }

    /// The DMA stream's interrupt: the transfer ended (its bytes leave the
    /// queue) or failed; then the next one.
    pub fn on_dma(&mut self, queue: &mut TxConsumer<Q>, now_us: u32, turn: usize) {
        let Some(dma) = &self.dma else { return };
        let isr = dma.hisr().read();
        let error = isr.teif7().is_error();
        let complete = isr.tcif7().is_complete();
        clear_flags(dma);
        if error {
            self.fail();
        } else if complete {
            if let Some((bytes, n)) = self.in_flight.take() {
                bytes.release(usize::from(n));
            }
        }
        self.kick(queue, now_us, turn);
    }

    /// A transfer failed or overran: stop it, release what it sent (what
    /// it did not stays queued, first in line), and send by interrupts
    /// from now on.
    fn fail(&mut self) {
        let mut left = 0;
        if let Some(dma) = self.dma.take() {
            let st = dma.st(7);
            st.cr().modify(|_, w| w.en().disabled());
            // RM0090 10.3.17: EN reads 1 until the stream has stopped.
            let _ = (0..1000).any(|_| st.cr().read().en().is_disabled());
            left = st.ndtr().read().ndt().bits();
            #[allow(unsafe_code)]
            // SAFETY: USART1's CR3.DMAT off: the UART stops asking DMA.
            unsafe {
                (*USART1::ptr()).cr3().modify(|_, w| w.dmat().clear_bit())
            };
            defmt::warn!(
                "link: a DMA transfer failed or overran; sent by USART1's interrupt from now on"
            );
        }
        if let Some((bytes, n)) = self.in_flight.take() {
            bytes.release(usize::from(n.saturating_sub(left)));
        }
    }

    /// The interrupt path: the queue's bytes while the UART takes them (at
    /// most `turn`); TXE's interrupt on while bytes wait.
    fn by_interrupt(&mut self, queue: &mut TxConsumer<Q>, turn: usize) {
        use embedded_hal_nb::serial::Write;
        use stm32f4xx_hal::serial::TxListen;
        if let Ok(bytes) = queue.read() {
            let mut k = 0;
            for &b in bytes.iter().take(turn) {
                if self.tx.write(b).is_err() {
                    break;
                }
                k += 1;
            }
            bytes.release(k);
        }
        // TXE stays set while the data register is empty: listening while
        // bytes wait brings the task back for the next. (A grant dropped
        // unreleased takes nothing from the queue.)
        if queue.read().is_ok() {
            self.tx.listen();
        } else {
            self.tx.unlisten();
        }
    }
}
