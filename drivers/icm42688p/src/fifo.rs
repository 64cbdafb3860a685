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
    /// Of those, the first `counted` were within the FIFO count the read
    /// latched; the rest came during the burst and were handed over past
    /// it (see [`Icm42688::read_fifo_with`]).
    pub counted: usize,
    /// Packets left in the FIFO for the next read (more than `max`, or
    /// after a cut packet).
    pub left: usize,
    /// Packets the chip sent again (the one handed over past the count
    /// last time), dropped.
    pub resent: usize,
    /// A packet was cut (chip select lost inside it) and left for the next
    /// read with the rest.
    pub cut: bool,
    /// The newest sample handed over, if any.
    pub last: Option<FifoSample>,
    /// The stamp of the newest sample within the count, if any (the
    /// sample whose INT1 pulse came last before the count was latched).
    pub counted_stamp: Option<u32>,
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
/// What FIFO_DATA reads with nothing to give (the header's FIFO-empty
/// bit alone).
pub(super) const EMPTY_MARKER: u8 = 0x80;
/// Four empty markers read as one word.
const MARKER_WORD: u32 = u32::from_ne_bytes([EMPTY_MARKER; 4]);
/// The header bits checked against [`HEADER_EXPECTED`].
pub(super) const HEADER_MASK: u8 = 0xFC;

/// Why [`parse_packets`] stopped before the end of its bytes.
pub(super) enum Stop<E> {
    /// A packet no FIFO stream holds (the error): the stream is out of
    /// step and is flushed.
    Bad(Error<E>),
    /// A packet whose bytes were not all the chip's: a burst cut inside it
    /// (chip select lost) reads the idle line's 0xFF from the cut on. The
    /// chip did not finish the packet, so it keeps it and sends it again
    /// whole (FIFO_RESUME_PARTIAL_RD clear, datasheet 6.2); it is left for
    /// the next burst, as is everything after it.
    Cut,
}

/// Why a packet whose header is not [`HEADER_EXPECTED`] stops a parse.
#[cold]
fn header_stop<E>(h: u8) -> Stop<E> {
    if h == 0xFF {
        // Not a header the chip sends (the empty marker is 0x80): the
        // line idle after a cut.
        Stop::Cut
    } else if h & bits::HEADER_MSG != 0 {
        Stop::Bad(Error::FifoShort)
    } else {
        Stop::Bad(Error::FifoBadHeader(h))
    }
}

/// A packet's gyroscope counts (big-endian, bytes 7–12).
#[inline(always)]
fn gyro_of(p: &[u8; FIFO_PACKET]) -> [i16; 3] {
    let w = |i: usize| i16::from_be_bytes([p[i], p[i + 1]]);
    [w(7), w(9), w(11)]
}

/// Parse whole packets from `bytes`, handing each sample to `each` and
/// counting it in `read`; the first bad or cut packet stops it. Returns
/// the packets taken out of `bytes` (handed over or dropped as sent
/// again) and why it stopped early. `stamp` is the last sample's extended
/// timestamp, `step` the last step between two (0: none yet), `lim` the
/// largest step the configured rate allows. The loop keeps to what a
/// whole packet on time needs (one compare of its header, its stamp's
/// step, its counts); the counts, the stamp and the newest sample are
/// stored once, after it: sixteen packets a millisecond on the board.
pub(super) fn parse_packets<E>(
    bytes: &[u8],
    stamp: &mut Option<u32>,
    step: &mut u16,
    lim: u16,
    read: &mut FifoRead,
    each: &mut impl FnMut(FifoSample),
) -> (usize, Option<Stop<E>>) {
    let (mut st, mut sp, mut n, mut taken, mut stop) = (*stamp, *step, 0, 0, None);
    // The newest packet handed over.
    let mut newest = None;
    // Whole packets as arrays: no index into one is checked.
    let (packets, _) = bytes.as_chunks::<FIFO_PACKET>();
    // The stamp is the packet's last two bytes: a cut anywhere in it
    // leaves at least the last at 0xFF, and the next packet's header at
    // 0xFF too (one that is not says the line was whole). Looked at only
    // where a stamp is in doubt.
    let line = |j: usize, p: &[u8; FIFO_PACKET]| {
        p[15] == 0xFF && packets.get(j + 1).is_none_or(|q| q[0] == 0xFF)
    };
    for (j, p) in packets.iter().enumerate() {
        let h = p[0];
        // (0xFF and the message bit fail it too: `header_stop` says which.)
        if h & HEADER_MASK != HEADER_EXPECTED {
            stop = Some(header_stop(h));
            break;
        }
        let stamp16 = u16::from_be_bytes([p[14], p[15]]);
        let stamp = match st {
            Some(prev) => {
                let d = stamp16.wrapping_sub(prev as u16);
                // Such a stamp off the stream's step by more than a count
                // or two (a PLL or CLKIN moves no more in one sample), or
                // before a step is known beyond `lim`, is the line's, not
                // the chip's. A clock failing over to its RC oscillator
                // (5–8 %) steps once: its packet is taken unless its stamp
                // ends in 0xFF (1 in 256) and it ends the burst, and then it
                // is lost (the chip sent it whole).
                let off = if sp == 0 {
                    d > lim
                } else {
                    d.abs_diff(sp) > (sp / 32).max(2)
                };
                if off && line(j, p) {
                    stop = Some(Stop::Cut);
                    break;
                }
                // A step back of less than a sample period (0 included): the
                // packet handed over last (past the count, or cut in its
                // stamp's last byte and taken) sent again. Taken, not a
                // sample.
                if (d as i16) <= 0 && (d as i16) > -(lim as i16) {
                    taken += 1;
                    read.resent += 1;
                    continue;
                }
                sp = d;
                prev.wrapping_add(u32::from(d))
            }
            // The first packet of a stream (after a flush) has nothing to
            // be checked against but the line: a stamp of 0xFFFF with the
            // line at 0xFF after it is a cut (a true 0xFFFF there, 1 in
            // 65 536, loses that one sample).
            None if p[14] == 0xFF && line(j, p) => {
                stop = Some(Stop::Cut);
                break;
            }
            None => u32::from(stamp16),
        };
        st = Some(stamp);
        each(FifoSample {
            raw: gyro_of(p),
            stamp,
        });
        newest = Some(p);
        n += 1;
        taken += 1;
    }
    *stamp = st;
    *step = sp;
    read.samples += n;
    // The newest handed over is the stream's last stamp (a packet sent
    // again, or one that stops the parse, leaves it as it was).
    if let (Some(p), Some(stamp)) = (newest, st) {
        read.last = Some(FifoSample {
            raw: gyro_of(p),
            stamp,
        });
    }
    (taken, stop)
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
        self.step = 0;
        Ok(())
    }

    /// Empty the FIFO (SIGNAL_PATH_RESET.FIFO_FLUSH) and clear the
    /// FIFO_FULL it may have latched before (INT_STATUS clears on read); a
    /// RESET_DONE seen there is kept for the next [`Self::read_fifo`].
    pub fn flush_fifo(&mut self) -> Result<(), Error<SPI::Error>> {
        self.stamp = None;
        self.step = 0;
        self.write(reg::SIGNAL_PATH_RESET, bits::FIFO_FLUSH)?;
        if self.read(reg::INT_STATUS)? & RESET_DONE != 0 {
            self.reset_seen = true;
        }
        Ok(())
    }

    /// The FIFO's count now, packets (FIFO_COUNT_REC is set with FIFO
    /// sampling): one short read, for the clock's pairing of a capture
    /// with a sample (`pipeline::timed`).
    pub fn fifo_count(&mut self) -> Result<usize, Error<SPI::Error>> {
        let mut b = [0u8; 2];
        self.read_burst(reg::FIFO_COUNTH, &mut b)?;
        Ok(usize::from(u16::from_be_bytes(b)))
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
        let lim = self.stamp_lim;
        let want = count.min(max);
        let mut read = FifoRead {
            status,
            samples: 0,
            counted: 0,
            left: count - want,
            last: None,
            counted_stamp: None,
            resent: 0,
            cut: false,
        };
        let in_first = want.min(k);
        let (mut taken, mut stop) = parse_packets(
            &self.fifo_buf[3..3 + FIFO_PACKET * in_first],
            &mut self.stamp,
            &mut self.step,
            lim,
            &mut read,
            &mut each,
        );
        // The burst read `k` packets whatever the count. Past the count it
        // read (FIFO_COUNTH/L, two bytes before the packets) the datasheet
        // does not say what comes: the empty marker, a packet that came
        // during the burst and left the FIFO with it, or one handed over
        // and sent again next time (the emulator takes each,
        // `gyro_sim::PastCount`). A packet that came while the marker was being
        // read starts where it came, not on a packet's boundary: it begins
        // at the first byte that is not the marker (a header is never
        // 0x80). Such a packet is kept while its header is whole, and one
        // sent again is known by its stamp; dropped, 0.1–1.9 % of a chip's
        // samples were lost (16 % on one fallen back to its RC
        // oscillator). Past the count nothing was promised: a bad header
        // there is no error.
        read.counted = read.samples;
        read.counted_stamp = read.last.map(|x| x.stamp);
        if stop.is_none() && want == in_first {
            let mut at = 3 + FIFO_PACKET * in_first;
            let end = 3 + FIFO_PACKET * k;
            loop {
                // The markers four at a time (a slot past the count is
                // usually sixteen of them), then one at a time.
                while at + 4 <= end
                    && self
                        .fifo_buf
                        .get(at..at + 4)
                        .and_then(|m| <[u8; 4]>::try_from(m).ok())
                        .is_some_and(|m| u32::from_ne_bytes(m) == MARKER_WORD)
                {
                    at += 4;
                }
                while at < end && self.fifo_buf[at] == EMPTY_MARKER {
                    at += 1;
                }
                // The whole packets from there, as many as `max` leaves
                // room for, in one parse: a packet not whole, a header that
                // is not a packet's (past the count no error) or markers
                // stop it.
                let room = max.saturating_sub(read.samples);
                let whole = ((end.saturating_sub(at)) / FIFO_PACKET).min(room);
                if whole == 0 {
                    break;
                }
                let Some(p) = self.fifo_buf.get(at..at + FIFO_PACKET * whole) else {
                    break;
                };
                let (t, s) = parse_packets::<SPI::Error>(
                    p,
                    &mut self.stamp,
                    &mut self.step,
                    lim,
                    &mut read,
                    &mut each,
                );
                at += FIFO_PACKET * t;
                // Markers after a packet that came past the count: look on.
                let more = matches!(s, Some(Stop::Bad(Error::FifoShort)))
                    && self.fifo_buf.get(at) == Some(&EMPTY_MARKER);
                if !more {
                    break;
                }
            }
        }
        // The rest, in more bursts from FIFO_DATA.
        while stop.is_none() && taken < want {
            let n = (want - taken).min(MAX_PER_READ);
            let rest = &mut self.fifo_buf[..FIFO_PACKET * n];
            self.spi
                .transaction(&mut [
                    Operation::Write(&[reg::FIFO_DATA | READ]),
                    Operation::Read(rest),
                ])
                .map_err(Error::Spi)?;
            let (t, s) = parse_packets(
                &self.fifo_buf[..FIFO_PACKET * n],
                &mut self.stamp,
                &mut self.step,
                lim,
                &mut read,
                &mut each,
            );
            taken += t;
            stop = s;
        }
        if want > in_first {
            // Every packet came within the count, over more bursts.
            read.counted = read.samples;
            read.counted_stamp = read.last.map(|x| x.stamp);
        }
        match stop {
            None => Ok(read),
            Some(Stop::Cut) => {
                // The cut packet and those after it are still the chip's.
                read.cut = true;
                read.left += want - taken;
                Ok(read)
            }
            Some(Stop::Bad(e)) => {
                self.flush_fifo()?;
                Err(e)
            }
        }
    }
}
