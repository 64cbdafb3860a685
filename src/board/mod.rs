//! Board bindings: the STM32F405 board's, and the fault containment and
//! stack meter every firmware build shares (the board's, and the QEMU
//! binaries' in `gyro-sim`).

#[cfg(feature = "board")]
pub mod f405;
#[cfg(feature = "cortex-m")]
pub mod idle;
#[cfg(feature = "persist")]
pub mod persist;
pub mod record;
#[cfg(any(feature = "cortex-m", feature = "persist"))]
pub mod stack;
