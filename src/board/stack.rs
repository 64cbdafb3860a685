//! The stack: painted at boot and guarded by the MPU ([`guard_stack`]), and
//! its high-water mark ([`stack_usage`]) for status reports. Shared by
//! every firmware binary (QEMU and board).
#![allow(unsafe_code)]

/// Painted into the free stack at boot.
const PAINT: u32 = 0xCAFE_F00D;

unsafe extern "C" {
    /// Lowest stack address (cortex-m-rt; the bottom of RAM with flip-link).
    static _stack_end: u32;
    /// Initial stack pointer (top of the stack).
    static _stack_start: u32;
}

/// The stack region [bottom, top).
pub fn stack_bounds() -> (u32, u32) {
    // Linker symbols: only their addresses are used.
    (&raw const _stack_end as u32, &raw const _stack_start as u32)
}

/// Bytes at the bottom of the stack that the MPU makes inaccessible.
pub const GUARD: u32 = 32;

/// Paint the free stack below the current stack pointer (keeping 64 bytes
/// of margin), so that [`stack_usage`] can find the deepest use later, and
/// put an MPU no-access region of 32 bytes at the bottom of the stack.
///
/// flip-link already puts the stack at the bottom of RAM, where on the
/// STM32F405 an overflow hits reserved space and bus-faults. The guard
/// makes the overflow fault on any memory map: QEMU's mps2-an386 ignores
/// accesses to unmapped addresses, and there a runaway stack went on
/// writing until it wrecked the code. Call once, early in `main`.
pub fn guard_stack() {
    let (lo, _) = stack_bounds();
    let base = lo.next_multiple_of(GUARD);
    let sp = cortex_m::register::msp::read() - 64;
    let mut a = base + GUARD;
    while a < sp {
        // SAFETY: [lo, sp) is stack below the live frames: nothing uses it.
        unsafe { (a as *mut u32).write_volatile(PAINT) };
        a += 4;
    }
    // MPU region 0 (ARMv7-M B3.5): base, 32 bytes, AP = no access, XN;
    // the default map stays in force elsewhere (PRIVDEFENA).
    let w = |addr: usize, v: u32| {
        // SAFETY: MPU registers, written in the documented order before
        // the region is used; nothing else configures the MPU.
        unsafe { (addr as *mut u32).write_volatile(v) }
    };
    w(0xE000_ED98, 0); // RNR
    w(0xE000_ED9C, base); // RBAR
    w(
        0xE000_EDA0,
        (1 << 28) | ((GUARD.trailing_zeros() - 1) << 1) | 1,
    ); // RASR
    w(0xE000_ED94, (1 << 2) | 1); // CTRL: PRIVDEFENA | ENABLE
    cortex_m::asm::dsb();
    cortex_m::asm::isb();
}

/// Stack use so far.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StackUsage {
    /// Deepest use since the paint, bytes.
    pub peak: u32,
    /// Size of the stack region, bytes.
    pub size: u32,
}

/// The high-water mark: the first word from the bottom that is no longer
/// paint marks the deepest the stack has been.
pub fn stack_usage() -> StackUsage {
    let (lo, hi) = stack_bounds();
    let lo = lo.next_multiple_of(GUARD) + GUARD;
    let mut a = lo;
    // SAFETY: reading the stack region's own words.
    while a < hi && unsafe { (a as *const u32).read_volatile() } == PAINT {
        a += 4;
    }
    StackUsage {
        peak: hi - a,
        size: hi - lo,
    }
}

/// The high-water mark measured a little at a time: a full
/// [`stack_usage`] reads every free word (≈ 12 000 on the board, some
/// 60 000 cycles), too much for one 1 ms sample. The meter reads `words`
/// words per call, from the bottom of the stack up, and completes a pass
/// when it meets the first word that is no longer paint; [`StackMeter::peak`]
/// is the deepest use found by the passes so far.
pub struct StackMeter {
    lo: u32,
    hi: u32,
    at: u32,
    peak: u32,
}

impl Default for StackMeter {
    fn default() -> Self {
        Self::new()
    }
}

impl StackMeter {
    /// A meter for the stack painted by [`guard_stack`], its first pass
    /// done now (call it where a long scan is acceptable, at start-up).
    pub fn new() -> Self {
        let (lo, hi) = stack_bounds();
        let lo = lo.next_multiple_of(GUARD) + GUARD;
        Self {
            lo,
            hi,
            at: lo,
            peak: stack_usage().peak,
        }
    }

    /// Scan up to `words` more words.
    pub fn step(&mut self, words: u32) {
        for _ in 0..words {
            // SAFETY: reading the stack region's own words.
            if self.at >= self.hi || unsafe { (self.at as *const u32).read_volatile() } != PAINT {
                self.peak = self.peak.max(self.hi - self.at);
                self.at = self.lo;
                return;
            }
            self.at += 4;
        }
    }

    /// Deepest use found so far, bytes.
    pub fn peak(&self) -> u32 {
        self.peak
    }
}
