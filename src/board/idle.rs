//! The main loop's idle step, shared by the board and the QEMU firmware.

/// Wait for an interrupt unless `ready()` (checked with interrupts
/// masked, so that an interrupt taken just before cannot be slept through:
/// WFI still wakes on a pending one).
pub fn sleep_unless(ready: impl FnOnce() -> bool) {
    cortex_m::interrupt::free(|_| {
        if !ready() {
            cortex_m::asm::wfi();
        }
    });
}
