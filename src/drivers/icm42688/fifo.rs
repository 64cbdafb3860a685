//! The FIFO: 16-byte packets (header, accel, gyro, temperature, a 16-bit
//! timestamp; datasheet section 6), read in bursts with their count.

use super::*;

/// One sample out of the FIFO.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FifoSample {
    /// Raw counts per axis.
    pub raw: [i16; 3],
    /// The chip's timestamp of the sample in its counts (TMST_RES = 0: on
    /// its own clock 32/30 µs a count, on CLKIN open:
    /// `pipeline::stamps`), extended past the packet's 16 bits.
    pub stamp: u32,
}

/// What one FIFO read found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FifoRead {
    /// INT_STATUS as read with the count.
    pub status: u8,
    /// Samples handed to the caller.
    pub samples: usize,
    /// Samples left in the FIFO (more than the buffer held).
    pub left: usize,
    /// The newest sample handed over, if any.
    pub last: Option<FifoSample>,
}

/// FIFO packet size, bytes (packet 3).
pub const FIFO_PACKET: usize = 16;
/// Packets a full FIFO holds: 2 KiB (datasheet 6.1) of 16-byte packets;
/// the count is in records.
pub const FIFO_RECORDS: usize = 2048 / FIFO_PACKET;
/// Most packets one burst of [`Icm42688::read_fifo`] reads.
pub const MAX_PER_READ: usize = 4;
/// The header of a packet 3 with accel and gyro slots and an ODR
/// timestamp; the low two bits flag an ODR change and are not checked.
pub(super) const HEADER_EXPECTED: u8 =
    bits::HEADER_ACCEL | bits::HEADER_GYRO | bits::HEADER_TIMESTAMP_ODR;
/// The header bits checked against [`HEADER_EXPECTED`].
pub(super) const HEADER_MASK: u8 = 0xFC;

/// Parse whole packets from `bytes`, handing each sample to `each` and
/// counting it in `read`; the first bad packet stops it (its error).
/// `stamp` is the last sample's extended timestamp. The counts and the
/// stamp live in registers through the loop and are stored once (per
/// packet they were stores the caller's closure kept the compiler from
/// sinking: some 5 instructions a packet, 16 packets a millisecond).
pub(super) fn parse_packets<E>(
    bytes: &[u8],
    stamp: &mut Option<u32>,
    read: &mut FifoRead,
    each: &mut impl FnMut(FifoSample),
) -> Option<Error<E>> {
    let (mut st, mut n, mut last, mut bad) = (*stamp, 0, None, None);
    for p in bytes.chunks_exact(FIFO_PACKET) {
        let h = p[0];
        if h & bits::HEADER_MSG != 0 {
            bad = Some(Error::FifoShort);
            break;
        }
        if h & HEADER_MASK != HEADER_EXPECTED {
            bad = Some(Error::FifoBadHeader(h));
            break;
        }
        let w = |i: usize| i16::from_be_bytes([p[i], p[i + 1]]);
        let stamp16 = u16::from_be_bytes([p[14], p[15]]);
        let stamp = match st {
            Some(prev) => prev.wrapping_add(stamp16.wrapping_sub(prev as u16) as u32),
            None => stamp16 as u32,
        };
        st = Some(stamp);
        let x = FifoSample {
            raw: [w(7), w(9), w(11)],
            stamp,
        };
        last = Some(x);
        each(x);
        n += 1;
    }
    *stamp = st;
    read.samples += n;
    if last.is_some() {
        read.last = last;
    }
    bad
}

impl<SPI: SpiDevice> Icm42688<SPI> {
    /// INTF_CONFIG0, FIFO_CONFIG1, FIFO_CONFIG and (with the FIFO) INT1 as
    /// a data-ready pulse, for the sampling chosen, each read back.
    pub fn configure_fifo(&mut self, cfg: Config) -> Result<(), Error<SPI::Error>> {
        self.write_checked(reg::INTF_CONFIG0, cfg.intf_config0())?;
        self.write_checked(reg::FIFO_CONFIG1, cfg.fifo_config1())?;
        self.write_checked(reg::FIFO_CONFIG, cfg.fifo_config())?;
        if cfg.sampling == Sampling::Fifo {
            let [c, c1, s0] = cfg.int1();
            self.write_checked(reg::INT_CONFIG, c)?;
            self.write_checked(reg::INT_CONFIG1, c1)?;
            self.write_checked(reg::INT_SOURCE0, s0)?;
        }
        self.config.sampling = cfg.sampling;
        self.stamp = None;
        Ok(())
    }

    /// Empty the FIFO (SIGNAL_PATH_RESET.FIFO_FLUSH) and clear the
    /// FIFO_FULL it may have latched before (INT_STATUS clears on read); a
    /// RESET_DONE seen there is kept for the next [`Self::read_fifo`].
    pub fn flush_fifo(&mut self) -> Result<(), Error<SPI::Error>> {
        self.stamp = None;
        self.write(reg::SIGNAL_PATH_RESET, bits::FIFO_FLUSH)?;
        if self.read(reg::INT_STATUS)? & RESET_DONE != 0 {
            self.reset_seen = true;
        }
        Ok(())
    }

    /// Read what the FIFO holds, oldest first, into `out` (at most
    /// `out.len()` samples; the rest stay for the next read).
    pub fn read_fifo(&mut self, out: &mut [FifoSample]) -> Result<FifoRead, Error<SPI::Error>> {
        let mut i = 0;
        self.read_fifo_with(out.len(), |s| {
            if let Some(slot) = out.get_mut(i) {
                *slot = s;
            }
            i += 1;
        })
    }

    /// Read up to `max` of the samples the FIFO holds, oldest first, each
    /// handed to `each` as its packet is parsed (no buffer between the
    /// bus and the caller: the board's loop reads four chips a
    /// millisecond).
    ///
    /// One transaction in the usual case: a burst from INT_STATUS through
    /// FIFO_COUNTH/L into FIFO_DATA (the address stays on FIFO_DATA), with
    /// room for the packets a millisecond makes at the ODR; one more for
    /// the rest when the count says more came (a fast chip clock, a late
    /// read). Each header is checked;
    /// FIFO_FULL, a bad header or a short FIFO flush it and return a typed
    /// error (FIFO_FULL beside a count no full FIFO has is a garbled status
    /// and flushes nothing), so the next read starts on a packet boundary
    /// and the caller counts the gap (the samples handed over before the bad packet are
    /// the caller's to drop). Timestamps are extended from 16 bits by their
    /// difference from the last (reads must come within 65 ms).
    pub fn read_fifo_with(
        &mut self,
        max: usize,
        mut each: impl FnMut(FifoSample),
    ) -> Result<FifoRead, Error<SPI::Error>> {
        if self.config.sampling != Sampling::Fifo {
            return Err(Error::NotFifo);
        }
        // Room for the packets one read usually finds (one per ms of the
        // ODR): what the count does not cover reads 0x80 and is not looked
        // at, and a packet arriving during the burst is read again whole
        // (FIFO_RESUME_PARTIAL_RD is clear).
        let k = self.per_read.clamp(1, MAX_PER_READ);
        let first = &mut self.fifo_buf[..3 + FIFO_PACKET * k];
        self.spi
            .transaction(&mut [
                Operation::Write(&[reg::INT_STATUS | READ]),
                Operation::Read(first),
            ])
            .map_err(Error::Spi)?;
        let [status, count_h, count_l, ..] = self.fifo_buf;
        if status & RESET_DONE != 0 || self.reset_seen {
            self.reset_seen = false;
            return Err(Error::ChipReset);
        }
        let count = u16::from_be_bytes([count_h, count_l]) as usize;
        if status & bits::FIFO_FULL != 0 {
            // Stop-on-full keeps a full FIFO full until it is read, and
            // this driver is its only reader: FIFO_FULL beside a count
            // under half of it is a bit error in the status, not lost
            // samples, and flushing would lose the packets it holds.
            if count < FIFO_RECORDS / 2 {
                return Err(Error::FifoBadStatus(status));
            }
            self.flush_fifo()?;
            return Err(Error::FifoOverflow);
        }
        let want = count.min(max);
        let mut read = FifoRead {
            status,
            samples: 0,
            left: count - want,
            last: None,
        };
        let in_first = want.min(k);
        let mut bad = parse_packets(
            &self.fifo_buf[3..3 + FIFO_PACKET * in_first],
            &mut self.stamp,
            &mut read,
            &mut each,
        );
        // The rest, in more bursts from FIFO_DATA.
        while bad.is_none() && read.samples < want {
            let n = (want - read.samples).min(MAX_PER_READ);
            let rest = &mut self.fifo_buf[..FIFO_PACKET * n];
            self.spi
                .transaction(&mut [
                    Operation::Write(&[reg::FIFO_DATA | READ]),
                    Operation::Read(rest),
                ])
                .map_err(Error::Spi)?;
            bad = parse_packets(
                &self.fifo_buf[..FIFO_PACKET * n],
                &mut self.stamp,
                &mut read,
                &mut each,
            );
        }
        match bad {
            None => Ok(read),
            Some(e) => {
                self.flush_fifo()?;
                Err(e)
            }
        }
    }
}
