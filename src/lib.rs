//! Firmware core for the gyro board of a satcom-on-the-move antenna.
//!
//! The board reads an array of MEMS gyroscopes over one SPI bus, fuses them
//! into one virtual gyro per axis on every sample, and tracks how the noise
//! changes with a fixed-capacity dynamic Allan variance. Everything here is
//! `no_std` and allocation-free, so the same code runs on the Cortex-M4F, in
//! QEMU and on the host (tests, log analysis).
//!
//! - [`algo`]: pure numerical methods (fusion, Allan variance, E-DAVAR). They
//!   know nothing of hardware.
//! - [`drivers`]: embedded-hal 1.0 drivers for the ICM-42688-P and ADXRS453.
//! - [`pipeline`]: the per-sample loop: read every gyro, account for every
//!   sample, flag and exclude faulty chips, fuse.
//! - [`link`]: the output link to the antenna controller (frames over a
//!   UART, commands back) and its decoder, shared with the host tools.
//! - [`board`]: bindings for the STM32F405 board (firmware builds only),
//!   and the reset record that survives a fault.
//!
//! The chips' emulation, the self-checks and the QEMU binaries live in
//! the `gyro-sim` crate (`sim/`); nothing of them is in the board's build.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![deny(unsafe_code)]
#![warn(missing_docs)]
// `!(x > 0.0)` is deliberate throughout: it is also true for NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]
// Numeric kernels index several arrays by the same gyro index.
#![allow(clippy::needless_range_loop)]

pub mod algo;
pub mod app;
pub mod board;
pub mod drivers;
pub mod link;
pub mod pipeline;
pub mod store;
