//! STM32F405 bring-up that does not depend on any one part working:
//! clocks with fallbacks, a cycle-count delay, SysTick sample pacing and an
//! interrupt-fed receive queue for the link's commands. The same code runs
//! on the board and on QEMU's `netduinoplus2` (whose RCC reads 0: no
//! crystal, no PLL lock), where it takes the last fallback.

use core::cell::RefCell;
use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;
use critical_section::Mutex;
use embedded_hal_nb::nb;
use heapless::Deque;
use stm32f4xx_hal::pac::{self, interrupt, USART1};
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

/// Sample ticks since [`start_ticks`].
static TICKS: AtomicU32 = AtomicU32::new(0);

#[cortex_m_rt::exception]
fn SysTick() {
    TICKS.fetch_add(1, Ordering::Release);
}

/// Tick at `rate_hz` from a core clock of `core_hz` (SysTick reload ≤ 2²⁴).
pub fn start_ticks(mut syst: SYST, core_hz: u32, rate_hz: u32) -> SYST {
    syst.disable_counter();
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload((core_hz / rate_hz.max(1)).clamp(2, 1 << 24) - 1);
    syst.clear_current();
    syst.enable_interrupt();
    syst.enable_counter();
    syst
}

/// Sample ticks so far.
pub fn ticks() -> u32 {
    TICKS.load(Ordering::Acquire)
}

/// Bytes received on USART1 and not yet read, filled by its interrupt so
/// that none is lost while the main loop works (the USART holds one).
static RX: Mutex<RefCell<Option<Rx<USART1>>>> = Mutex::new(RefCell::new(None));
static RX_QUEUE: Mutex<RefCell<Deque<u8, 128>>> = Mutex::new(RefCell::new(Deque::new()));
/// Receive errors (overrun, framing, noise, parity) and queue overflows.
static RX_ERRORS: AtomicU32 = AtomicU32::new(0);

#[interrupt]
fn USART1() {
    critical_section::with(|cs| {
        let mut rx = RX.borrow_ref_mut(cs);
        let mut q = RX_QUEUE.borrow_ref_mut(cs);
        let Some(rx) = rx.as_mut() else { return };
        // Bounded: the USART holds one byte; errors clear on read.
        for _ in 0..4 {
            match embedded_hal_nb::serial::Read::read(rx) {
                Ok(b) => {
                    if q.push_back(b).is_err() {
                        RX_ERRORS.fetch_add(1, Ordering::Relaxed);
                    }
                }
                Err(nb::Error::WouldBlock) => break,
                Err(nb::Error::Other(_)) => {
                    RX_ERRORS.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    });
}

/// The receive side of the link: USART1's bytes, through its interrupt.
pub struct RxQueue(());

impl RxQueue {
    /// Hand `rx` to the interrupt and unmask it. Call once.
    #[allow(unsafe_code)]
    pub fn start(mut rx: Rx<USART1>) -> Self {
        use stm32f4xx_hal::serial::RxListen;
        rx.listen();
        critical_section::with(|cs| *RX.borrow_ref_mut(cs) = Some(rx));
        // SAFETY: the handler only touches the statics above, through
        // critical sections.
        unsafe { cortex_m::peripheral::NVIC::unmask(pac::Interrupt::USART1) };
        Self(())
    }

    /// Receive errors and dropped bytes so far.
    pub fn errors(&self) -> u32 {
        RX_ERRORS.load(Ordering::Relaxed)
    }
}

impl embedded_hal_nb::serial::ErrorType for RxQueue {
    type Error = core::convert::Infallible;
}

impl embedded_hal_nb::serial::Read<u8> for RxQueue {
    fn read(&mut self) -> nb::Result<u8, Self::Error> {
        critical_section::with(|cs| RX_QUEUE.borrow_ref_mut(cs).pop_front())
            .ok_or(nb::Error::WouldBlock)
    }
}
