//! QEMU `mps2-an386` (Cortex-M4F): semihosting exit codes and an
//! instruction counter built on SysTick.
//!
//! Under `qemu-system-arm -icount shift=0` SysTick, clocked from the core,
//! advances a fixed number of executed instructions per tick; the bench
//! calibrates that ratio against a loop of known length at start-up.

pub mod an386;
pub mod cmsdk_uart;

use core::sync::atomic::{AtomicU32, Ordering};
use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;

/// SysTick wraps counted by the binary's SysTick handler.
pub static WRAPS: AtomicU32 = AtomicU32::new(0);

const RELOAD: u32 = 0x00FF_FFFF;

/// End the QEMU run with a pass or fail exit code.
pub fn exit(pass: bool) -> ! {
    use cortex_m_semihosting::debug;
    debug::exit(if pass {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    #[allow(clippy::empty_loop)]
    loop {}
}

/// A free-running 24-bit SysTick extended by the wrap counter.
pub struct Ticks {
    _syst: SYST,
}

impl Ticks {
    /// Start SysTick on the core clock with the wrap interrupt enabled.
    pub fn start(mut syst: SYST) -> Self {
        syst.disable_counter();
        syst.set_clock_source(SystClkSource::Core);
        syst.set_reload(RELOAD);
        syst.clear_current();
        syst.enable_interrupt();
        syst.enable_counter();
        // VAL reads 0 until the first reload; wait for it so that time
        // starts at RELOAD and only moves forward.
        while SYST::get_current() == 0 {}
        Self { _syst: syst }
    }

    /// Ticks since start (monotonic, 64-bit).
    pub fn now(&self) -> u64 {
        ticks()
    }
}

/// Ticks of the SysTick started by [`Ticks::start`] (for code that cannot
/// hold the [`Ticks`], such as a metered emulated bus). A changed wrap
/// counter means the read raced the wrap handler: retry. The handler can
/// also still be pending when VAL has already reloaded (QEMU takes
/// exceptions between translation blocks): then the wrap is counted here,
/// or the clock steps back by 2²⁴ ticks and the next interval gains them
/// (one bench run showed a 671-million-instruction "sample" that way).
#[inline]
pub fn ticks() -> u64 {
    loop {
        let w = WRAPS.load(Ordering::Acquire);
        let v = SYST::get_current();
        // Pending with VAL just reloaded: the wrap came before this read
        // (the handler runs within a few instructions of it, so only a VAL
        // in the top 4096 ticks needs the pending flag read at all).
        let missed = v > RELOAD - 4096 && cortex_m::peripheral::SCB::is_pendst_pending();
        if WRAPS.load(Ordering::Acquire) == w {
            let w = w as u64 + u64::from(missed);
            return w * (RELOAD as u64 + 1) + (RELOAD - v) as u64;
        }
    }
}

/// A panic ends the QEMU run as a failure (the `persist` feature replaces
/// this with record-and-reset, tested by `qemu-faults`).
#[cfg(not(feature = "persist"))]
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    defmt::error!("panic: {}", defmt::Display2Format(info));
    exit(false)
}

/// Executed instructions per SysTick tick, measured on a loop of known
/// length (`subs` + `bne`: 2 instructions per iteration).
pub fn instructions_per_tick(t: &Ticks) -> f32 {
    const ITER: u32 = 1_000_000;
    let t0 = t.now();
    #[allow(unsafe_code)]
    // SAFETY: a register-only countdown loop.
    unsafe {
        core::arch::asm!("1:", "subs {n}, {n}, #1", "bne 1b", n = inout(reg) ITER => _, options(nomem, nostack));
    }
    let ticks = t.now() - t0;
    (2 * ITER) as f32 / ticks as f32
}

/// A hard fault (a stack overflow, a bad access) ends the QEMU run as a
/// failure instead of looping forever in the default handler.
#[cfg(not(feature = "persist"))]
#[cortex_m_rt::exception]
#[allow(unsafe_code)] // cortex-m-rt requires the HardFault handler to be `unsafe fn`.
unsafe fn HardFault(ef: &cortex_m_rt::ExceptionFrame) -> ! {
    defmt::error!("hard fault at pc {=u32:#010x}", ef.pc());
    exit(false)
}

/// A multi-boot test's stage, in RAM the runtime does not initialise
/// (`.uninit`) and QEMU keeps across a system reset; garbage at power-up,
/// so stored beside `guard ^ stage` and read as 0 unless the two agree.
#[allow(unsafe_code)]
#[unsafe(link_section = ".uninit.stage")]
static mut STAGE: core::mem::MaybeUninit<[u32; 2]> = core::mem::MaybeUninit::uninit();

/// The stage [`set_stage`] left before the last reset (0: none, or
/// power-up).
#[allow(unsafe_code)]
pub fn stage(guard: u32) -> u32 {
    // SAFETY: plain words, single-threaded test binaries.
    let [s, g] = unsafe { (&raw const STAGE).cast::<[u32; 2]>().read_volatile() };
    if g == guard ^ s {
        s
    } else {
        0
    }
}

/// Keep `s` for the next boot.
#[allow(unsafe_code)]
pub fn set_stage(guard: u32, s: u32) {
    // SAFETY: as in `stage`.
    unsafe {
        (&raw mut STAGE)
            .cast::<[u32; 2]>()
            .write_volatile([s, guard ^ s])
    };
}
