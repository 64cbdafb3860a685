//! Fault containment, end to end in QEMU: a forced panic, a forced stack
//! overflow and a hang must each end in a reset, with the cause reported at
//! the next boot, and the run must then carry on. The stages survive the
//! resets in a RAM word of their own (`.uninit`).
//!
//! 1. Cold boot: no record. Paint and guard the stack, panic.
//! 2. The record says Panic and panic-persist holds the message. Recurse
//!    until the stack overflows into the MPU guard at its bottom.
//! 3. The record says StackOverflow (the SP in or below the guard). Start
//!    the watchdog and hang.
//! 4. No record (no handler ran) in stage 4: the watchdog reset the core.
//!    Pass.
//!
//! Anything else (no reset, a wrong record, a lock-up caught by the
//! runner's timeout) fails the run.
#![no_std]
#![no_main]
#![allow(unsafe_code)]

use cortex_m_rt::entry;
use defmt_semihosting as _;
use gyro_array::board::record::Cause;
use gyro_array::board::{persist, stack};
use gyro_sim::qemu::{self, exit};

/// This binary's guard for its stage word (`gyro_sim::qemu::stage`).
const GUARD: u32 = 0x57A6_E000;

fn stage() -> u32 {
    qemu::stage(GUARD)
}

fn set_stage(s: u32) {
    qemu::set_stage(GUARD, s)
}

/// The mps2-an386's CMSDK APB watchdog (ARM DDI 0479, at 0x4000_8000, on
/// the 25 MHz system clock): the first expiry raises its interrupt (NMI,
/// whose default handler spins), the second resets the system. 1 ms per
/// expiry.
fn start_watchdog() {
    const BASE: usize = 0x4000_8000;
    let w = |off: usize, v: u32| {
        // SAFETY: the watchdog's documented registers.
        unsafe { ((BASE + off) as *mut u32).write_volatile(v) }
    };
    w(0xC00, 0x1ACC_E551); // WDOGLOCK: unlock
    w(0x000, 25_000); // WDOGLOAD
    w(0x008, 0b11); // WDOGCONTROL: INTEN | RESEN
    w(0xC00, 0); // lock
}

/// Burns 256 bytes of stack per level, forever.
#[inline(never)]
#[allow(unconditional_recursion)]
fn deep(n: u32) -> u32 {
    let mut buf = [n; 64];
    buf[(n % 64) as usize] ^= 1;
    core::hint::black_box(&mut buf);
    deep(n + 1).wrapping_add(buf[3])
}

#[entry]
fn main() -> ! {
    let record = persist::take();
    stack::guard_stack();
    match (stage(), record) {
        (0, _) => {
            defmt::info!("stage 1: cold boot (record: {}), forcing a panic", record);
            set_stage(1);
            let v = core::hint::black_box(3usize);
            let a = [1u8; 2];
            defmt::info!("unreachable {}", a[v]);
        }
        (1, Some(r)) if r.cause == Cause::Panic => {
            let msg = persist::panic_message().unwrap_or(b"");
            defmt::info!(
                "stage 2: reset after a panic (boot {}), message: {=[u8]:a}",
                r.boots,
                msg
            );
            if msg.is_empty() {
                exit(false);
            }
            set_stage(2);
            let u = stack::stack_usage();
            defmt::info!(
                "stack before the overflow: {} of {} bytes used",
                u.peak,
                u.size
            );
            defmt::info!("forcing a stack overflow");
            let r = deep(core::hint::black_box(0));
            defmt::info!("unreachable {}", r);
        }
        (2, Some(r)) => match r.cause {
            Cause::StackOverflow(f) => {
                defmt::info!(
                    "stage 3: reset after a stack overflow (boot {}): CFSR {=u32:#010x} HFSR {=u32:#010x} MMFAR {=u32:#010x} SP {=u32:#010x}",
                    r.boots,
                    f.cfsr,
                    f.hfsr,
                    f.mmfar,
                    f.sp
                );
                set_stage(3);
                defmt::info!("starting the watchdog, then hanging");
                start_watchdog();
                #[allow(clippy::empty_loop)]
                loop {}
            }
            other => {
                defmt::error!("stage 3: expected a stack overflow, got {}", other);
                exit(false);
            }
        },
        (3, None) => {
            // No handler ran: only the watchdog can have reset the core.
            defmt::info!("stage 4: reset by the watchdog after the hang");
            set_stage(0);
            defmt::info!(
                "fault containment: a panic, a stack overflow and a hang each ended in a reset and were reported"
            );
            exit(true);
        }
        (s, r) => defmt::error!("stage {}: unexpected record {}", s, r),
    }
    set_stage(0);
    exit(false)
}
