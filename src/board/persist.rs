//! Fault containment on the target: a panic or a hard fault is recorded in
//! RAM that survives the reset, the core resets, and the next boot reports
//! what happened ([`take`]). The stack guard that turns an overflow into a
//! hard fault is in [`super::stack`].
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
use super::stack::{stack_bounds, GUARD};

/// The record, in `.uninit` (neither loaded nor zeroed at start-up).
#[unsafe(link_section = ".uninit.reset_record")]
static mut RECORD: MaybeUninit<[u32; WORDS]> = MaybeUninit::uninit();

/// Resets by the firmware since power-up, as read at boot.
static BOOTS: AtomicU32 = AtomicU32::new(0);

/// Stack the hard-fault handler runs on (the faulting one may be gone).
const EMERGENCY_WORDS: usize = 256;
#[unsafe(link_section = ".uninit.emergency_stack")]
static mut EMERGENCY: MaybeUninit<[u32; EMERGENCY_WORDS]> = MaybeUninit::uninit();

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
