//! The device support an RTIC application needs on QEMU's `mps2-an386`
//! (Arm's AN386 FPGA image: a Cortex-M4 on the MPS2 board), written by
//! hand because no peripheral-access crate covers it: the interrupt
//! numbers, the NVIC's priority bits and the vector table's interrupt
//! part.
//!
//! The numbers are AN386's (Application Note AN386, "Interrupt map"),
//! which QEMU's `hw/arm/mps2.c` wires for its AN385 and AN386 machines:
//! each CMSDK UART's receive interrupt at an even number and its transmit
//! one above it (UART0 0/1, UART1 2/3, UART2 4/5, UART3 18/19, UART4
//! 20/21), the overflows of UARTs 0–2 ORed on 12, TIMER0 8, TIMER1 9, the
//! dual timer 10, the Ethernet controller 13. The FPGA's Cortex-M4 keeps
//! 3 priority bits (CMSIS `CMSDK_CM4.h`: `__NVIC_PRIO_BITS 3`).

/// Priority bits the NVIC implements.
pub const NVIC_PRIO_BITS: u8 = 3;

/// AN386's interrupts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u16)]
#[allow(clippy::upper_case_acronyms, missing_docs)]
pub enum Interrupt {
    UART0RX = 0,
    UART0TX = 1,
    UART1RX = 2,
    UART1TX = 3,
    UART2RX = 4,
    UART2TX = 5,
    GPIO0 = 6,
    GPIO1 = 7,
    TIMER0 = 8,
    TIMER1 = 9,
    DUALTIMER = 10,
    SPI01 = 11,
    UARTOVF = 12,
    ETHERNET = 13,
    I2S = 14,
    TOUCH = 15,
    GPIO2 = 16,
    GPIO3 = 17,
    UART3RX = 18,
    UART3TX = 19,
    UART4RX = 20,
    UART4TX = 21,
    SPI2 = 22,
    SPI34 = 23,
}

/// The name RTIC looks its bindings up under.
pub use self::Interrupt as interrupt;

// SAFETY: each variant is one of the NVIC's interrupt numbers on AN386.
#[allow(unsafe_code)]
unsafe impl cortex_m::interrupt::InterruptNumber for Interrupt {
    fn number(self) -> u16 {
        self as u16
    }
}

/// One entry of the vector table: a handler, or a reserved word.
#[derive(Clone, Copy)]
#[repr(C)]
pub union Vector {
    handler: unsafe extern "C" fn(),
    reserved: usize,
}

macro_rules! vectors {
    ($($name:ident),* $(,)?) => {
        #[allow(unsafe_code)]
        unsafe extern "C" {
            $(fn $name();)*
        }

        /// The vector table's interrupts, in AN386's order. Each handler
        /// is `DefaultHandler` unless the application defines it
        /// (`an386.x` beside this file PROVIDEs the default; `build.rs`
        /// hands it to the linker as the `device.x` cortex-m-rt includes).
        #[allow(unsafe_code)]
        #[unsafe(link_section = ".vector_table.interrupts")]
        #[unsafe(no_mangle)]
        pub static __INTERRUPTS: [Vector; 24] = [$(Vector { handler: $name }),*];
    };
}

vectors!(
    UART0RX, UART0TX, UART1RX, UART1TX, UART2RX, UART2TX, GPIO0, GPIO1, TIMER0, TIMER1, DUALTIMER,
    SPI01, UARTOVF, ETHERNET, I2S, TOUCH, GPIO2, GPIO3, UART3RX, UART3TX, UART4RX, UART4TX, SPI2,
    SPI34,
);
