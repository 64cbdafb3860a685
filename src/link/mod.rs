//! The output link to the antenna controller: versioned binary frames over
//! a UART (specification: `docs/link.md`).
//!
//! - [`msg`]: the messages (fused samples, raw samples, status, command
//!   acknowledgements; commands the other way).
//! - [`wire`]: framing (postcard body, CRC-16, COBS, 0x00 delimiter) and
//!   the streaming [`wire::Decoder`] the board and the host tools share.
//! - [`port`]: the board's end: a transmit queue ([`ring`]) fed from the
//!   pipeline, drained from idle time, and command handling.
//!
//! Budget: every frame must fit in one sample period at [`BAUD`] with
//! 8N1 framing (10 bits a byte): [`frame_budget`] bytes at 1 kHz. The
//! largest frames are measured by the tests (`link::tests`).

pub mod msg;
pub mod port;
pub mod ring;
pub mod sync;
pub mod wire;

#[cfg(test)]
mod tests;

/// Protocol version, the first byte of every payload.
pub const VERSION: u8 = 8;

/// UART speed: 6 Mbaud, exact on the STM32F405's USART1 (84 MHz APB2,
/// oversampling by 8, USARTDIV = 1.75), on RS-422 to the antenna
/// controller (TIA-422 carries 10 Mbit/s over 12 m), and within reach of
/// FT232H, FT2232H and CH343 USB bridges (not of CP2102N: 3 Mbaud). At
/// this speed the status frame, queued after its sample's frame, is on the
/// wire before the next sample frame comes, so no sample frame ever waits
/// behind one: at 2 Mbaud the status frame (385 B, 1.9 ms) held the next
/// sample frames back by up to 1.5 ms, over the 2.5 ms the antenna allows
/// from the true rate to the frame (docs/timing.md).
pub const BAUD: u32 = 6_000_000;

/// The link's speed when the board runs on its internal 16 MHz oscillator
/// alone (crystal and PLL failed): the fastest USART1 reaches there
/// (16 MHz / 8), where the status frame again delays the sample frames.
pub const FALLBACK_BAUD: u32 = 2_000_000;

/// Bytes the link carries per sample period of `sample_us` at [`BAUD`],
/// 8N1.
pub const fn frame_budget(sample_us: u32) -> u32 {
    (BAUD as u64 / 10 * sample_us as u64 / 1_000_000) as u32
}
