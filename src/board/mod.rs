//! Board bindings: what differs between the QEMU machine and the real
//! STM32F405 board, and the fault containment both share.

#[cfg(feature = "qemu")]
pub mod an386;
#[cfg(feature = "qemu")]
pub mod cmsdk_uart;
#[cfg(feature = "board")]
pub mod f405;
#[cfg(any(feature = "qemu", feature = "board"))]
pub mod idle;
#[cfg(feature = "persist")]
pub mod persist;
#[cfg(feature = "qemu")]
pub mod qemu;
pub mod record;
#[cfg(any(feature = "qemu", feature = "persist"))]
pub mod stack;
