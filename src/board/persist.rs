//! Fault containment on the target: a panic or a hard fault is recorded in
//! RAM that survives the reset, the core resets, and the next boot reports
//! what happened ([`take`]). Also the stack: [`guard_stack`] at boot (paint
//! and MPU guard), [`stack_usage`] whenever the firmware reports status.
//!
//! - **Panic**: the message goes to panic-persist's region, the cause to
//!   the [`Record`] (CRC-checked, so power-up garbage never reads as a
//!   fault), then `SYSRESETREQ`.
//! - **Hard fault**: the vector points at a few instructions of assembly
//!   that switch MSP to an emergency stack before anything is pushed. With
//!   flip-link the stack sits at the bottom of RAM, so an overflow faults
//!   while pushing; the handler could not run on that stack (a second fault
//!   in HardFault locks the core up, which is what QEMU showed before).
//!   The handler reads CFSR, HFSR, MMFAR, BFAR and, if the faulting stack
//!   is inside RAM, the stacked PC and LR.
//!
//! Everything here that touches raw memory is `unsafe` and says why.
#![allow(unsafe_code)]

use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicU32, Ordering};

use super::record::{Cause, FaultRegs, Record, WORDS};

/// The record, in `.uninit` (neither loaded nor zeroed at start-up).
#[unsafe(link_section = ".uninit.reset_record")]
static mut RECORD: MaybeUninit<[u32; WORDS]> = MaybeUninit::uninit();

/// Resets by the firmware since power-up, as read at boot.
static BOOTS: AtomicU32 = AtomicU32::new(0);

/// Stack the hard-fault handler runs on (the faulting one may be gone).
const EMERGENCY_WORDS: usize = 256;
#[unsafe(link_section = ".uninit.emergency_stack")]
static mut EMERGENCY: MaybeUninit<[u32; EMERGENCY_WORDS]> = MaybeUninit::uninit();

/// Painted into the free stack at boot.
const PAINT: u32 = 0xCAFE_F00D;

unsafe extern "C" {
    /// Lowest stack address (cortex-m-rt; the bottom of RAM with flip-link).
    static _stack_end: u32;
    /// Initial stack pointer (top of the stack).
    static _stack_start: u32;
}

/// The last run's record, if any, and forget it (a second boot without a
/// new fault reports nothing). Call once, early at boot.
pub fn take() -> Option<Record> {
    // SAFETY: single-threaded at boot; RECORD is plain words, and every bit
    // pattern is a valid `[u32; WORDS]` (decoding checks magic and CRC).
    let rec = unsafe {
        let p = (&raw mut RECORD).cast::<[u32; WORDS]>();
        let w = p.read_volatile();
        p.write_volatile([0; WORDS]);
        Record::decode(&w)
    };
    BOOTS.store(rec.map_or(0, |r| r.boots), Ordering::Relaxed);
    rec
}

/// The panic message kept by panic-persist, if the last run panicked
/// (cleared once read).
pub fn panic_message() -> Option<&'static [u8]> {
    panic_persist::get_panic_message_bytes()
}

/// Record `cause` and reset the core.
pub fn record_and_reset(cause: Cause) -> ! {
    let rec = Record {
        cause,
        boots: BOOTS.load(Ordering::Relaxed).saturating_add(1),
    };
    // SAFETY: RECORD is only written here (with interrupts about to stop
    // mattering: the reset follows) and read in `take` at boot.
    unsafe {
        (&raw mut RECORD)
            .cast::<[u32; WORDS]>()
            .write_volatile(rec.encode());
    }
    cortex_m::asm::dsb();
    cortex_m::peripheral::SCB::sys_reset()
}

/// Log the panic, keep its message, record it and reset.
pub fn panic_reset(info: &core::panic::PanicInfo) -> ! {
    cortex_m::interrupt::disable();
    defmt::error!("panic: {} (resetting)", defmt::Display2Format(info));
    panic_persist::report_panic_info(info);
    record_and_reset(Cause::Panic)
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    panic_reset(info)
}

// The HardFault vector: switch to the emergency stack first (no push
// before `msr msp`), then call the Rust handler with the faulting MSP.
core::arch::global_asm!(
    ".section .HardFault.user, \"ax\"",
    ".global HardFault",
    ".type HardFault,%function",
    ".thumb_func",
    "HardFault:",
    "mrs r0, msp",
    "ldr r1, ={emergency}",
    "add r1, r1, #{size}",
    "msr msp, r1",
    "b {handler}",
    emergency = sym EMERGENCY,
    size = const EMERGENCY_WORDS * 4,
    handler = sym hard_fault,
);

/// The hard-fault handler proper, on the emergency stack.
extern "C" fn hard_fault(sp: u32) -> ! {
    // SAFETY: the SCB fault registers are always readable (ARMv7-M B3.2).
    let reg = |a: usize| unsafe { (a as *const u32).read_volatile() };
    let (lo, hi) = stack_bounds();
    // The exception frame is r0-r3, r12, lr, pc, xpsr at sp; read it only
    // if it lies inside the stack region.
    let frame = |i: u32| {
        let a = sp.wrapping_add(4 * i);
        if a >= lo && a + 4 <= hi {
            // SAFETY: in-bounds, aligned RAM.
            unsafe { (a as *const u32).read_volatile() }
        } else {
            0
        }
    };
    let regs = FaultRegs {
        cfsr: reg(0xE000_ED28),
        hfsr: reg(0xE000_ED2C),
        mmfar: reg(0xE000_ED34),
        bfar: reg(0xE000_ED38),
        pc: frame(6),
        lr: frame(5),
        sp,
    };
    if sp < lo.next_multiple_of(GUARD) + GUARD {
        record_and_reset(Cause::StackOverflow(regs))
    }
    record_and_reset(Cause::HardFault(regs))
}

/// The stack region [bottom, top).
fn stack_bounds() -> (u32, u32) {
    // Linker symbols: only their addresses are used.
    (&raw const _stack_end as u32, &raw const _stack_start as u32)
}

/// Bytes at the bottom of the stack that the MPU makes inaccessible.
const GUARD: u32 = 32;

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
