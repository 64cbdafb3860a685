//! The CMSDK APB UART of QEMU's `mps2-an386` (ARM DDI0479C, section 4.3),
//! as an embedded-hal-nb serial port: the demo streams the output link
//! over UART0, which QEMU connects to its `-serial` back end.
//!
//! Registers: DATA (0x00), STATE (0x04: bit 0 TX buffer full, bit 1 RX
//! buffer full, bits 2–3 TX/RX overrun, write 1 to clear), CTRL (0x08:
//! bit 0 TX enable, bit 1 RX enable, bit 2 TX interrupt enable, bit 3 RX
//! interrupt enable), INTSTATUS/INTCLEAR (0x0C: bit 0 TX, bit 1 RX; write
//! 1 to clear), BAUDDIV (0x10, at least 16). One byte of buffer each way,
//! no FIFO. The TX interrupt comes when a byte has gone out, the RX one
//! when a byte has come in (AN386: UART0 RX on IRQ 0, TX on IRQ 1).

use core::convert::Infallible;

use embedded_hal_nb::nb;
use embedded_hal_nb::serial::{ErrorType, Read, Write};

const DATA: usize = 0x00;
const STATE: usize = 0x04;
const CTRL: usize = 0x08;
const INTCLEAR: usize = 0x0C;
const BAUDDIV: usize = 0x10;
const TX_INT_EN: u32 = 1 << 2;
const RX_INT_EN: u32 = 1 << 3;
const TX_FULL: u32 = 1 << 0;
const RX_FULL: u32 = 1 << 1;
const RX_OVERRUN: u32 = 1 << 3;

/// UART0 of `mps2-an386`.
pub const UART0: usize = 0x4000_4000;

/// One CMSDK APB UART.
pub struct CmsdkUart {
    base: usize,
    rx_overruns: u32,
}

impl CmsdkUart {
    /// Enable the UART at `base` for transmit and receive with the given
    /// divider of the 25 MHz peripheral clock (16 is the fastest:
    /// 1.5625 Mbaud; QEMU does not pace the bytes anyway).
    ///
    /// # Safety
    /// `base` must be a CMSDK APB UART that nothing else drives.
    #[allow(unsafe_code)]
    pub unsafe fn new(base: usize, bauddiv: u32) -> Self {
        let u = Self {
            base,
            rx_overruns: 0,
        };
        u.write_reg(BAUDDIV, bauddiv.max(16));
        u.write_reg(CTRL, 0b11);
        u
    }

    /// Turn on the TX and RX interrupts.
    pub fn listen(&mut self) {
        self.write_reg(CTRL, 0b11 | TX_INT_EN | RX_INT_EN);
    }

    /// Acknowledge the TX interrupt (a byte has gone out).
    pub fn clear_tx_interrupt(&mut self) {
        self.write_reg(INTCLEAR, 1);
    }

    /// Acknowledge the RX interrupt (a byte has come in).
    pub fn clear_rx_interrupt(&mut self) {
        self.write_reg(INTCLEAR, 2);
    }

    /// Received bytes lost because the one-byte buffer was full.
    pub fn rx_overruns(&self) -> u32 {
        self.rx_overruns
    }

    #[allow(unsafe_code)]
    fn read_reg(&self, off: usize) -> u32 {
        // SAFETY: an aligned register of the UART `new` was given.
        unsafe { core::ptr::read_volatile((self.base + off) as *const u32) }
    }

    #[allow(unsafe_code)]
    fn write_reg(&self, off: usize, v: u32) {
        // SAFETY: as in read_reg.
        unsafe { core::ptr::write_volatile((self.base + off) as *mut u32, v) }
    }
}

impl ErrorType for CmsdkUart {
    type Error = Infallible;
}

impl Write<u8> for CmsdkUart {
    fn write(&mut self, b: u8) -> nb::Result<(), Infallible> {
        if self.read_reg(STATE) & TX_FULL != 0 {
            return Err(nb::Error::WouldBlock);
        }
        self.write_reg(DATA, u32::from(b));
        Ok(())
    }

    fn flush(&mut self) -> nb::Result<(), Infallible> {
        if self.read_reg(STATE) & TX_FULL != 0 {
            return Err(nb::Error::WouldBlock);
        }
        Ok(())
    }
}

impl Read<u8> for CmsdkUart {
    fn read(&mut self) -> nb::Result<u8, Infallible> {
        let s = self.read_reg(STATE);
        if s & RX_OVERRUN != 0 {
            self.rx_overruns = self.rx_overruns.wrapping_add(1);
            self.write_reg(STATE, RX_OVERRUN);
        }
        if s & RX_FULL == 0 {
            return Err(nb::Error::WouldBlock);
        }
        Ok(self.read_reg(DATA) as u8)
    }
}
