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
