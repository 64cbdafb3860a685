//! Framing: version byte, link sequence number and postcard body, then a
//! CRC-16, COBS-encoded and ended by a 0x00 byte.
//!
//! ```text
//! payload = VERSION (u8) | link_seq (u32 LE) | postcard(body)
//! frame   = COBS(payload | CRC-16/IBM-3740(payload) LE) | 0x00
//! ```
//!
//! COBS leaves no 0x00 inside a frame, so a receiver that starts anywhere,
//! or loses bytes, finds the next frame at the next 0x00. The CRC
//! (CRC-16/IBM-3740, also called CCITT-FALSE: poly 0x1021, init 0xFFFF)
//! catches every error of up to 3 bits and every burst of up to 16 bits in
//! frames this short (Hamming distance 4 up to 32 751 bits).

use crc::{Crc, CRC_16_IBM_3740};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use super::VERSION;

/// Longest payload (version to CRC) either side sends; longer frames are
/// rejected as [`FrameError::TooLong`].
pub const MAX_PAYLOAD: usize = 768;
/// Longest frame on the wire: COBS adds one byte per 254, plus the 0x00.
pub const MAX_FRAME: usize = MAX_PAYLOAD + MAX_PAYLOAD / 254 + 2;

const CRC16: Crc<u16> = Crc::<u16>::new(&CRC_16_IBM_3740);

#[derive(Serialize, Deserialize)]
struct Envelope<T> {
    #[serde(with = "postcard::fixint::le")]
    link_seq: u32,
    body: T,
}

/// Why a frame could not be built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncodeError {
    /// The message does not fit in [`MAX_PAYLOAD`] or the output buffer.
    TooLong,
}

/// Encode `body` with `link_seq` into `out`: the whole frame, 0x00
/// included. Returns its length. (The board's port runs the two steps,
/// [`encode_payload`] and [`frame_payload`], with scratch it keeps, and
/// frames straight into its transmit ring.)
pub fn encode<T: Serialize>(link_seq: u32, body: &T, out: &mut [u8]) -> Result<usize, EncodeError> {
    let mut payload = [0u8; MAX_PAYLOAD];
    let k = encode_payload(link_seq, body, &mut payload)?;
    frame_payload(payload.get(..k).ok_or(EncodeError::TooLong)?, out)
}

/// The version byte and the envelope (`link_seq`, `body`) at the start of
/// `out`: the payload less its CRC; its length.
fn version_and_envelope<T: Serialize>(
    link_seq: u32,
    body: &T,
    out: &mut [u8],
) -> Result<usize, EncodeError> {
    let (head, rest) = out.split_first_mut().ok_or(EncodeError::TooLong)?;
    *head = VERSION;
    let env = Envelope { link_seq, body };
    postcard::serialize_with_flavor(&env, Bytes { buf: rest, at: 0 })
        .map(|n| n + 1)
        .map_err(|_| EncodeError::TooLong)
}

/// postcard's output into a slice, byte by byte. postcard's own `Slice`
/// flavor copies each field with `copy_nonoverlapping`, and a varint's
/// length (1–3 bytes for a u16) is known only at run time, so each was a
/// call to memcpy: some 140 instructions a sample frame on the
/// Cortex-M4, for the same bytes.
struct Bytes<'a> {
    buf: &'a mut [u8],
    at: usize,
}

impl postcard::ser_flavors::Flavor for Bytes<'_> {
    /// The bytes written.
    type Output = usize;

    #[inline(always)]
    fn try_push(&mut self, b: u8) -> postcard::Result<()> {
        let slot = self
            .buf
            .get_mut(self.at)
            .ok_or(postcard::Error::SerializeBufferFull)?;
        *slot = b;
        self.at += 1;
        Ok(())
    }

    fn finalize(self) -> postcard::Result<usize> {
        Ok(self.at)
    }
}

/// The first step of [`encode`]: the payload (version, envelope,
/// CRC) into `payload`; its length.
pub fn encode_payload<T: Serialize>(
    link_seq: u32,
    body: &T,
    payload: &mut [u8],
) -> Result<usize, EncodeError> {
    let payload = payload
        .get_mut(..MAX_PAYLOAD.min(payload.len()))
        .ok_or(EncodeError::TooLong)?;
    let n = version_and_envelope(link_seq, body, payload)?;
    let (data, tail) = payload
        .split_at_mut_checked(n)
        .ok_or(EncodeError::TooLong)?;
    let crc = CRC16.checksum(data).to_le_bytes();
    tail.get_mut(..2)
        .ok_or(EncodeError::TooLong)?
        .copy_from_slice(&crc);
    Ok(n + 2)
}

/// Longest payload (version to CRC) [`encode_in_place`] takes: COBS
/// never has to split a run of so few bytes.
pub const IN_PLACE_MAX: usize = 253;

/// CRC-16/IBM-3740 a byte at a time (MSB first, poly 0x1021), for the
/// one pass of [`encode_in_place`]; the same table the `crc` crate builds
/// for [`CRC16`] (`the_one_pass_crc_is_the_crates`).
const CRC_TABLE: [u16; 256] = {
    let mut t = [0u16; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = (i as u16) << 8;
        let mut b = 0;
        while b < 8 {
            c = if c & 0x8000 != 0 {
                (c << 1) ^ 0x1021
            } else {
                c << 1
            };
            b += 1;
        }
        t[i] = c;
        i += 1;
    }
    t
};

/// One byte of the in-place COBS pass: a zero byte closes the open run
/// (its code byte gets the run's length) and becomes the next run's code
/// byte. Returns the open run's code byte and length.
#[inline(always)]
fn cobs_step<'a>(b: &'a mut u8, code: &'a mut u8, run: u8) -> (&'a mut u8, u8) {
    if *b == 0 {
        *code = run;
        (b, 1)
    } else {
        (code, run + 1)
    }
}

/// [`encode`] straight into `room`: the payload is serialised at
/// `room[1..]`, then one pass over it computes the CRC and COBS-encodes
/// it where it lies, each zero byte becoming the length code of the run
/// before it (the CRC's two bytes join the pass at its end). No copy and
/// one pass, which the board pays on every sample frame: the CRC and the
/// COBS in two passes cost 620 instructions a sample frame on the
/// Cortex-M4 (`cargo xtask bench-loop`). For payloads of at most
/// [`IN_PLACE_MAX`] bytes (every sample and raw frame of up to 8 gyros); a
/// longer one, or one that does not fit in `room`, is `Err(TooLong)` and
/// goes through [`encode`]. The bytes are those of [`encode`]
/// (`in_place_frames_are_the_crate_encoders`).
pub fn encode_in_place<T: Serialize>(
    link_seq: u32,
    body: &T,
    room: &mut [u8],
) -> Result<usize, EncodeError> {
    let room = room
        .get_mut(..room.len().min(IN_PLACE_MAX + 2))
        .ok_or(EncodeError::TooLong)?;
    // Version and envelope at room[1..=n]; the CRC goes at n + 1, n + 2
    // and the delimiter at n + 3.
    let (_, rest) = room.split_first_mut().ok_or(EncodeError::TooLong)?;
    let n = version_and_envelope(link_seq, body, rest)?;
    let k = n + 2;
    if k > IN_PLACE_MAX {
        return Err(EncodeError::TooLong);
    }
    let buf = room.get_mut(..k + 2).ok_or(EncodeError::TooLong)?;
    let (code0, rest) = buf.split_first_mut().ok_or(EncodeError::TooLong)?;
    let (data, tail) = rest.split_at_mut_checked(n).ok_or(EncodeError::TooLong)?;
    let (crc_lo, tail) = tail.split_first_mut().ok_or(EncodeError::TooLong)?;
    let (crc_hi, end) = tail.split_first_mut().ok_or(EncodeError::TooLong)?;
    // The open run's code byte, and the run's length so far: a zero
    // byte becomes the code of the run before it.
    let mut code: &mut u8 = code0;
    let mut run = 1u8;
    let mut crc = 0xFFFFu32;
    for b in data.iter_mut() {
        crc = (crc << 8) ^ u32::from(CRC_TABLE[usize::from((crc >> 8) as u8 ^ *b)]);
        (code, run) = cobs_step(b, code, run);
    }
    *crc_lo = crc as u8;
    *crc_hi = (crc >> 8) as u8;
    for b in [crc_lo, crc_hi] {
        (code, run) = cobs_step(b, code, run);
    }
    *code = run;
    if let Some(d) = end.first_mut() {
        *d = 0;
    }
    Ok(k + 2)
}

/// The second step of [`encode`]: a payload COBS-encoded into `out`
/// with its 0x00 delimiter; the frame's length. At most
/// [`framed_len`]`(payload.len())` bytes.
pub fn frame_payload(payload: &[u8], out: &mut [u8]) -> Result<usize, EncodeError> {
    let m = cobs::try_encode(payload, out).map_err(|_| EncodeError::TooLong)?;
    let end = out.get_mut(m).ok_or(EncodeError::TooLong)?;
    *end = 0;
    Ok(m + 1)
}

/// The longest frame a payload of `k` bytes can make (COBS's overhead and
/// the delimiter).
pub const fn framed_len(k: usize) -> usize {
    k + k / 254 + 2
}

/// Why a received frame was discarded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FrameError {
    /// COBS decoding failed, or the frame is shorter than version + CRC.
    Cobs,
    /// The CRC does not match.
    Crc,
    /// More than [`MAX_FRAME`] bytes before the delimiter.
    TooLong,
    /// Another protocol version (the byte it had).
    Version(u8),
    /// The CRC matched but the body does not decode as the expected type
    /// (or has bytes left over).
    Malformed,
}

/// What a [`Decoder`] counted.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DecodeStats {
    /// Frames decoded.
    pub frames: u64,
    /// Frames discarded for COBS or CRC errors.
    pub corrupt: u64,
    /// Frames discarded as too long.
    pub too_long: u64,
    /// Frames with another protocol version.
    pub version: u64,
    /// Frames whose body did not decode.
    pub malformed: u64,
    /// Bytes in discarded frames (delimiters not counted).
    pub bytes_dropped: u64,
}

/// One decoded frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Decoded<T> {
    /// The link sequence number: consecutive frames differ by 1, so a gap
    /// shows frames lost on the board (see `LinkCounters::dropped`) or on
    /// the wire.
    pub link_seq: u32,
    /// The message.
    pub body: T,
}

/// A streaming decoder: feed it bytes as they come; it never panics,
/// resynchronises at the next 0x00 after any damage and counts what it
/// dropped. `MAX` is its buffer (at least [`MAX_FRAME`] for board frames).
pub struct Decoder<const MAX: usize> {
    buf: [u8; MAX],
    len: usize,
    overflow: bool,
    stats: DecodeStats,
}

impl<const MAX: usize> Default for Decoder<MAX> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const MAX: usize> Decoder<MAX> {
    /// An empty decoder.
    pub const fn new() -> Self {
        Self {
            buf: [0; MAX],
            len: 0,
            overflow: false,
            stats: DecodeStats {
                frames: 0,
                corrupt: 0,
                too_long: 0,
                version: 0,
                malformed: 0,
                bytes_dropped: 0,
            },
        }
    }

    /// The counters so far.
    pub fn stats(&self) -> DecodeStats {
        self.stats
    }

    /// Bytes held waiting for a delimiter.
    pub fn pending(&self) -> usize {
        self.len
    }

    /// Feed one byte; at a delimiter that ends a non-empty frame, the
    /// frame or why it was discarded.
    pub fn feed<T: DeserializeOwned>(
        &mut self,
        byte: u8,
    ) -> Option<Result<Decoded<T>, FrameError>> {
        if byte != 0 {
            match self.buf.get_mut(self.len) {
                Some(slot) if !self.overflow => {
                    *slot = byte;
                    self.len += 1;
                }
                _ => {
                    self.overflow = true;
                    self.stats.bytes_dropped += 1;
                }
            }
            return None;
        }
        let (len, overflow) = (self.len, self.overflow);
        self.len = 0;
        self.overflow = false;
        if len == 0 && !overflow {
            return None; // back-to-back delimiters: nothing lost
        }
        let r = if overflow {
            Err(FrameError::TooLong)
        } else {
            self.buf
                .get_mut(..len)
                .map_or(Err(FrameError::TooLong), decode_frame::<T>)
        };
        match r {
            Ok(_) => self.stats.frames += 1,
            Err(e) => {
                self.stats.bytes_dropped += len as u64;
                match e {
                    FrameError::Cobs | FrameError::Crc => self.stats.corrupt += 1,
                    FrameError::TooLong => self.stats.too_long += 1,
                    FrameError::Version(_) => self.stats.version += 1,
                    FrameError::Malformed => self.stats.malformed += 1,
                }
            }
        }
        Some(r)
    }
}

/// Decode one COBS frame (without its 0x00), in place.
fn decode_frame<T: DeserializeOwned>(frame: &mut [u8]) -> Result<Decoded<T>, FrameError> {
    let n = cobs::decode_in_place(frame).map_err(|_| FrameError::Cobs)?;
    let payload = frame.get(..n).ok_or(FrameError::Cobs)?;
    let Some((data, crc)) = payload.split_last_chunk::<2>() else {
        return Err(FrameError::Cobs);
    };
    if CRC16.checksum(data) != u16::from_le_bytes(*crc) {
        return Err(FrameError::Crc);
    }
    let Some((&version, body)) = data.split_first() else {
        return Err(FrameError::Cobs);
    };
    if version != VERSION {
        return Err(FrameError::Version(version));
    }
    match postcard::take_from_bytes::<Envelope<T>>(body) {
        Ok((env, [])) => Ok(Decoded {
            link_seq: env.link_seq,
            body: env.body,
        }),
        _ => Err(FrameError::Malformed),
    }
}

#[cfg(test)]
mod crc_tests {
    use super::*;

    fn crc_byte(crc: u16, b: u8) -> u16 {
        (crc << 8) ^ CRC_TABLE[usize::from((crc >> 8) as u8 ^ b)]
    }

    #[test]
    fn the_one_pass_crc_is_the_crates() {
        let mut x = 0x1234_5678u32;
        for len in 0..300usize {
            let mut v = [0u8; 300];
            for b in v.iter_mut().take(len) {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                *b = if x.is_multiple_of(5) { 0 } else { x as u8 };
            }
            let ours = v[..len].iter().fold(0xFFFF, |c, &b| crc_byte(c, b));
            assert_eq!(ours, CRC16.checksum(&v[..len]), "{len} bytes");
        }
        // The catalogue's check value: CRC of "123456789".
        let check = b"123456789".iter().fold(0xFFFF, |c, &b| crc_byte(c, b));
        assert_eq!(check, 0x29B1);
    }
}
