//! Static chip calibration: each chip's mounting rotation, scale and
//! misalignment (one 3×3 matrix to board axes), bias and bias-versus-
//! temperature slope, kept by the board in a typed, versioned,
//! CRC-checked record.
//!
//! board rate = M · (chip rate − b − k·(T − T_ref))
//!
//! A single-axis chip (the ADXRS453) uses the diagonal entry of its axis
//! only: one axis cannot undo a misalignment, it can only be scaled.
//!
//! Record layout (little-endian): magic "GCAL" (u32 0x4C41_4347), version
//! (u16), payload length (u16), the payload (postcard: serial number, then
//! per chip M row by row, b, k, T_ref, all f32), CRC-32 (ISO-HDLC) of
//! everything before it. Erased flash (all 0xFF) or zeros read as
//! [`CalError::Missing`], never as a calibration.

use crc::{Crc, CRC_32_ISO_HDLC};

use crate::algo::qualify::Real;
use heapless::Vec;
use serde::{Deserialize, Serialize};

/// "GCAL".
pub const MAGIC: u32 = 0x4C41_4347;
/// Record format version.
pub const VERSION: u16 = 1;
/// Most chips a record holds.
pub const MAX_CHIPS: usize = 8;
/// Longest encoded record.
pub const MAX_LEN: usize = 8 + 5 + MAX_CHIPS * 4 * 16 + 4;

const CRC32: Crc<u32> = Crc::<u32>::new(&CRC_32_ISO_HDLC);

/// One chip's constants.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ChipCal {
    /// Chip axes to board axes: rotation, scale and misalignment.
    pub m: [[f32; 3]; 3],
    /// Bias at `t_ref_c`, per chip axis, °/s.
    pub bias_dps: [f32; 3],
    /// Bias slope, per chip axis, °/s per °C.
    pub bias_tc_dps_per_c: [f32; 3],
    /// Temperature of `bias_dps`, °C.
    pub t_ref_c: f32,
}

impl ChipCal {
    /// No correction.
    pub const IDENTITY: Self = Self {
        m: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        bias_dps: [0.0; 3],
        bias_tc_dps_per_c: [0.0; 3],
        t_ref_c: 25.0,
    };

    /// Board-axis rates of chip rates `chip` (°/s; axes the part lacks are
    /// not read) at die temperature `temp_c` (`None`: unknown, taken as
    /// `t_ref_c`). `axes` is the part's axis mask: a single-axis part is
    /// only scaled on its axis.
    pub fn apply(&self, chip: [f32; 3], axes: u8, temp_c: Option<f32>) -> [f32; 3] {
        let dt = temp_c.map_or(0.0, |t| t - self.t_ref_c);
        let mut c = [0.0f32; 3];
        for (i, v) in c.iter_mut().enumerate() {
            *v = chip[i] - self.bias_dps[i] - self.bias_tc_dps_per_c[i] * dt;
        }
        if axes == 0b111 {
            mul3(&self.m, &c)
        } else {
            let mut out = [f32::NAN; 3];
            for a in 0..3 {
                if axes & (1 << a) != 0 {
                    out[a] = self.m[a][a] * c[a];
                }
            }
            out
        }
    }
}

/// Inverse of a 3×3 matrix (`None` when singular or not finite): the
/// chip-frame view of board-frame rates for a calibrated chip (f32 on the
/// board), and M = A⁻¹ in the host's calibration procedure (f64).
pub fn inverse3<F: Real>(a: &[[F; 3]; 3]) -> Option<[[F; 3]; 3]> {
    let c = |i: usize, j: usize| {
        let (r0, r1) = ((i + 1) % 3, (i + 2) % 3);
        let (c0, c1) = ((j + 1) % 3, (j + 2) % 3);
        a[r0][c0] * a[r1][c1] - a[r0][c1] * a[r1][c0]
    };
    let det = a[0][0] * c(0, 0) + a[0][1] * c(0, 1) + a[0][2] * c(0, 2);
    if !(det.abs() > F::of(1e-12)) || !det.f64().is_finite() {
        return None;
    }
    // inverse = adjugate / det; adjugate[j][i] = cofactor(i, j).
    Some(core::array::from_fn(|j| {
        core::array::from_fn(|i| c(i, j) / det)
    }))
}

/// m · v for a 3×3 matrix: chip axes to board axes (or back).
pub fn mul3(m: &[[f32; 3]; 3], v: &[f32; 3]) -> [f32; 3] {
    m.map(|r| r[0] * v[0] + r[1] * v[1] + r[2] * v[2])
}

/// A board's calibration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CalRecord {
    /// Board serial number (or any identifier the lab uses).
    pub serial: u32,
    /// Per chip, in the pipeline's gyro order.
    pub chips: Vec<ChipCal, MAX_CHIPS>,
}

/// Why a record cannot be used. The firmware then runs uncalibrated and
/// says so.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CalError {
    /// Erased or blank storage: no record was ever written.
    Missing,
    /// Not a record (wrong magic).
    Magic,
    /// A record of another format version.
    Version(u16),
    /// Shorter than its header says, or longer than any record.
    Length,
    /// The CRC does not match: corrupted.
    Crc,
    /// The CRC matched but the payload does not decode, or a value is not
    /// finite.
    Malformed,
    /// The record is for another number of chips.
    Chips,
}

impl CalRecord {
    /// Encode into `out`; the length written.
    pub fn encode(&self, out: &mut [u8]) -> Result<usize, CalError> {
        let (head, rest) = out.split_at_mut_checked(8).ok_or(CalError::Length)?;
        let n = postcard::to_slice(self, rest)
            .map_err(|_| CalError::Length)?
            .len();
        head[0..4].copy_from_slice(&MAGIC.to_le_bytes());
        head[4..6].copy_from_slice(&VERSION.to_le_bytes());
        head[6..8].copy_from_slice(&(n as u16).to_le_bytes());
        let end = 8 + n;
        let crc = CRC32.checksum(out.get(..end).ok_or(CalError::Length)?);
        out.get_mut(end..end + 4)
            .ok_or(CalError::Length)?
            .copy_from_slice(&crc.to_le_bytes());
        Ok(end + 4)
    }

    /// Decode and check a record read from storage (trailing bytes, the
    /// rest of a flash sector, are ignored).
    pub fn decode(bytes: &[u8]) -> Result<Self, CalError> {
        let head = bytes.get(..8).ok_or(CalError::Length)?;
        if head.iter().all(|&b| b == 0xFF) || head.iter().all(|&b| b == 0) {
            return Err(CalError::Missing);
        }
        let word = |i: usize| u32::from_le_bytes([head[i], head[i + 1], head[i + 2], head[i + 3]]);
        if word(0) != MAGIC {
            return Err(CalError::Magic);
        }
        let version = u16::from_le_bytes([head[4], head[5]]);
        if version != VERSION {
            return Err(CalError::Version(version));
        }
        let n = u16::from_le_bytes([head[6], head[7]]) as usize;
        if 8 + n + 4 > MAX_LEN {
            return Err(CalError::Length);
        }
        let body = bytes.get(..8 + n).ok_or(CalError::Length)?;
        let crc = bytes.get(8 + n..8 + n + 4).ok_or(CalError::Length)?;
        if CRC32.checksum(body) != u32::from_le_bytes([crc[0], crc[1], crc[2], crc[3]]) {
            return Err(CalError::Crc);
        }
        let rec: CalRecord = match postcard::take_from_bytes(&body[8..]) {
            Ok((r, [])) => r,
            _ => return Err(CalError::Malformed),
        };
        let finite = rec.chips.iter().all(|c| {
            c.m.iter().flatten().all(|v| v.is_finite())
                && c.bias_dps.iter().all(|v| v.is_finite())
                && c.bias_tc_dps_per_c.iter().all(|v| v.is_finite())
                && c.t_ref_c.is_finite()
        });
        if !finite {
            return Err(CalError::Malformed);
        }
        Ok(rec)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record() -> CalRecord {
        let mut chips = Vec::new();
        for k in 0..5 {
            let mut c = ChipCal::IDENTITY;
            c.m[0][1] = 0.001 * k as f32;
            c.bias_dps = [0.1, -0.2, 0.3];
            c.bias_tc_dps_per_c[2] = 0.01;
            chips.push(c).unwrap();
        }
        CalRecord { serial: 42, chips }
    }

    #[test]
    fn a_record_round_trips_and_every_damage_is_typed() {
        let mut buf = [0xFFu8; 1024];
        let n = record().encode(&mut buf).unwrap();
        assert!(n <= MAX_LEN);
        assert_eq!(CalRecord::decode(&buf), Ok(record()));
        assert_eq!(CalRecord::decode(&[0xFF; 64]), Err(CalError::Missing));
        assert_eq!(CalRecord::decode(&[0; 64]), Err(CalError::Missing));
        assert_eq!(CalRecord::decode(&buf[..5]), Err(CalError::Length));
        // Every single flipped bit of the record is caught.
        for bit in 0..n * 8 {
            let mut b = buf;
            b[bit / 8] ^= 1 << (bit % 8);
            assert!(CalRecord::decode(&b).is_err(), "bit {bit}");
        }
        let mut b = buf;
        b[4] = 2;
        assert_eq!(CalRecord::decode(&b), Err(CalError::Version(2)));
    }

    #[test]
    fn inverse3_inverts() {
        let m = [[0.0, -1.01, 0.003], [0.99, 0.002, 0.0], [0.001, 0.0, 1.02]];
        let inv = inverse3(&m).unwrap();
        for i in 0..3 {
            for j in 0..3 {
                let v: f32 = (0..3).map(|k| m[i][k] * inv[k][j]).sum();
                assert!((v - if i == j { 1.0 } else { 0.0 }).abs() < 1e-6);
            }
        }
        assert_eq!(inverse3(&[[1.0; 3]; 3]), None);
    }

    #[test]
    fn apply_undoes_a_mounting() {
        // A chip rotated 90° about z: chip x = board y, chip y = −board x.
        let mut c = ChipCal::IDENTITY;
        c.m = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
        c.bias_dps = [0.5, 0.0, 0.0];
        c.bias_tc_dps_per_c = [0.01, 0.0, 0.0];
        let board = [3.0f32, 4.0, 5.0];
        let chip = [4.0 + 0.5 + 0.01 * 10.0, -3.0, 5.0];
        let got = c.apply(chip, 0b111, Some(35.0));
        for a in 0..3 {
            assert!((got[a] - board[a]).abs() < 1e-5, "{got:?}");
        }
        // Single axis: scaled only.
        let mut z = ChipCal::IDENTITY;
        z.m[2][2] = 1.01;
        let got = z.apply([f32::NAN, f32::NAN, 2.0], 0b100, None);
        assert!(got[0].is_nan() && (got[2] - 2.02).abs() < 1e-6);
    }
}
