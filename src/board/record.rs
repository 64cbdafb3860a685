//! The reset record: what ended the last run, kept in RAM across a reset
//! and reported at the next boot. Pure encoding (host-tested); the RAM it
//! lives in and the handlers that write it are in `persist`.
//!
//! Layout, little-endian 32-bit words: magic, version, kind, boots since
//! the last power-up, seven fault registers, CRC-32 (ISO-HDLC) of the ten
//! words before it. RAM that was never written (power-up) or was corrupted
//! fails the magic or the CRC and reads as "no record", never as a bogus
//! fault.

use crc::{Crc, CRC_32_ISO_HDLC};

/// Words in an encoded record.
pub const WORDS: usize = 12;
const MAGIC: u32 = 0x5245_5354; // "REST"
const VERSION: u32 = 1;
const CRC32: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);

/// Registers captured by the hard-fault handler (ARMv7-M SCB and the
/// stacked frame; 0 where the frame could not be read).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FaultRegs {
    /// Configurable Fault Status Register (MMFSR | BFSR | UFSR).
    pub cfsr: u32,
    /// HardFault Status Register (FORCED, VECTTBL).
    pub hfsr: u32,
    /// MemManage fault address (valid when CFSR.MMARVALID).
    pub mmfar: u32,
    /// Bus fault address (valid when CFSR.BFARVALID).
    pub bfar: u32,
    /// Stacked PC of the faulting instruction.
    pub pc: u32,
    /// Stacked LR.
    pub lr: u32,
    /// Main stack pointer at the fault (below RAM: a stack overflow).
    pub sp: u32,
}

impl FaultRegs {
    /// CFSR.STKERR or MSTKERR: the exception frame could not be pushed,
    /// which is what a stack overflow under flip-link looks like.
    pub fn stacking_error(&self) -> bool {
        self.cfsr & ((1 << 12) | (1 << 4)) != 0
    }
}

/// Why the last run ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Cause {
    /// A panic (its message is kept by panic-persist).
    Panic,
    /// A hard fault, with its registers.
    HardFault(FaultRegs),
    /// A hard fault with the stack pointer in or below the stack guard:
    /// the stack overflowed.
    StackOverflow(FaultRegs),
    /// The firmware asked for the reset (for example after a start-up
    /// failure it could not recover from).
    Requested,
}

/// A decoded record.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Record {
    /// What ended the last run.
    pub cause: Cause,
    /// Resets by the firmware itself since the last power-up (this one
    /// included).
    pub boots: u32,
}

impl Record {
    /// Encode with magic, version and CRC.
    pub fn encode(&self) -> [u32; WORDS] {
        let (kind, regs) = match self.cause {
            Cause::Panic => (1, FaultRegs::default()),
            Cause::HardFault(r) => (2, r),
            Cause::Requested => (3, FaultRegs::default()),
            Cause::StackOverflow(r) => (4, r),
        };
        let mut w = [
            MAGIC, VERSION, kind, self.boots, regs.cfsr, regs.hfsr, regs.mmfar, regs.bfar, regs.pc,
            regs.lr, regs.sp, 0,
        ];
        w[WORDS - 1] = crc_of(&w[..WORDS - 1]);
        w
    }

    /// Decode; `None` for anything that is not an intact record of this
    /// version (never-written RAM, corruption, another firmware's layout).
    pub fn decode(w: &[u32; WORDS]) -> Option<Self> {
        if w[0] != MAGIC || w[1] != VERSION || crc_of(&w[..WORDS - 1]) != w[WORDS - 1] {
            return None;
        }
        let regs = FaultRegs {
            cfsr: w[4],
            hfsr: w[5],
            mmfar: w[6],
            bfar: w[7],
            pc: w[8],
            lr: w[9],
            sp: w[10],
        };
        let cause = match w[2] {
            1 => Cause::Panic,
            2 => Cause::HardFault(regs),
            3 => Cause::Requested,
            4 => Cause::StackOverflow(regs),
            _ => return None,
        };
        Some(Self { cause, boots: w[3] })
    }
}

fn crc_of(words: &[u32]) -> u32 {
    let mut d = CRC32.digest();
    for w in words {
        d.update(&w.to_le_bytes());
    }
    d.finalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_every_single_bit_flip_is_rejected() {
        let regs = FaultRegs {
            cfsr: 0x1000,
            hfsr: 0x4000_0000,
            mmfar: 0,
            bfar: 0x1fff_ffe0,
            pc: 0x0800_1234,
            lr: 0xffff_fff9,
            sp: 0x1fff_ffe0,
        };
        for cause in [
            Cause::Panic,
            Cause::HardFault(regs),
            Cause::Requested,
            Cause::StackOverflow(regs),
        ] {
            let r = Record { cause, boots: 7 };
            let w = r.encode();
            assert_eq!(Record::decode(&w), Some(r));
            for i in 0..WORDS * 32 {
                let mut bad = w;
                bad[i / 32] ^= 1 << (i % 32);
                assert_eq!(Record::decode(&bad), None, "bit {i}");
            }
        }
        assert!(regs.stacking_error());
    }

    #[test]
    fn blank_or_random_ram_is_no_record() {
        assert_eq!(Record::decode(&[0; WORDS]), None);
        assert_eq!(Record::decode(&[u32::MAX; WORDS]), None);
        let mut rng = gyro_sim::Rng::new(3);
        for _ in 0..10_000 {
            let w = core::array::from_fn(|_| rng.next_u32());
            assert_eq!(Record::decode(&w), None);
        }
    }
}
