//! Board bindings (firmware builds only): what differs between the QEMU
//! machine and the real STM32F405 board.

#[cfg(feature = "qemu")]
pub mod qemu;
