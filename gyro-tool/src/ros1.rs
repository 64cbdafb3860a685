//! Gyro rates from a ROS 1 bag (`.bag`; what Kalibr's, imu_utils' and
//! allan_variance_ros' users record): every `sensor_msgs/Imu` topic, the
//! bag's records read by the `rosbag` crate. Columns, units, time and gaps
//! as for ROS 2 bags ([`crate::ros2`]).
//!
//! The messages are decoded here: ROS 1's serialisation is little-endian
//! fields back to back (no alignment), and of `sensor_msgs/Imu` only the
//! header's stamp and the angular velocity are read, past the header's
//! variable-length frame id; no maintained crate decodes it without the
//! message's generated type.

use std::path::Path;

use rosbag::{ChunkRecord, MessageRecord, RosBag};

use crate::ros2::{series_of, Topics};
use crate::table::{Series, TableError};

const IMU: &str = "sensor_msgs/Imu";

/// Whether `path` is a ROS 1 bag this module reads (by its extension).
pub fn is_bag(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("bag"))
}

/// The little-endian u32 at byte `o` of `b`, if it holds one (ROS 1
/// serialises every length and integer so).
fn u32_le(b: &[u8], o: usize) -> Option<u32> {
    b.get(o..o + 4)?.try_into().ok().map(u32::from_le_bytes)
}

/// The stamp (ns) and angular velocity (rad/s) of a serialised
/// `sensor_msgs/Imu`: header (seq u32, stamp sec u32 + nsec u32, frame_id
/// u32 length + bytes), orientation (4 f64), its covariance (9 f64), the
/// angular velocity (3 f64).
fn decode(d: &[u8]) -> Option<(i64, [f64; 3])> {
    let u32_at = |o: usize| u32_le(d, o);
    let f64_at = |o: usize| {
        d.get(o..o + 8)
            .and_then(|b| b.try_into().ok())
            .map(f64::from_le_bytes)
    };
    let (sec, nsec) = (u32_at(4)?, u32_at(8)?);
    let frame_len = u32_at(12)? as usize;
    let w = 16usize.checked_add(frame_len)? + 13 * 8;
    let ns = i64::from(sec) * 1_000_000_000 + i64::from(nsec);
    Some((ns, [f64_at(w)?, f64_at(w + 8)?, f64_at(w + 16)?]))
}

/// The index position the bag header states (ROS bag format 2.0: the
/// magic line, then the header record: its length, then fields of a
/// length and `name=value`, `index_pos` a u64); None where there is no
/// such header.
fn index_pos(path: &Path) -> std::io::Result<Option<u64>> {
    use std::io::Read;
    const MAGIC: &[u8] = b"#ROSBAG V2.0\n";
    let mut head = Vec::new();
    std::fs::File::open(path)?
        .take(MAGIC.len() as u64 + 4 + 4096)
        .read_to_end(&mut head)?;
    let Some(rest) = head.strip_prefix(MAGIC) else {
        return Ok(None);
    };
    let len_at = |b: &[u8], o: usize| u32_le(b, o).map(|n| n as usize);
    let Some(header) = len_at(rest, 0).and_then(|n| rest.get(4..4 + n)) else {
        return Ok(None);
    };
    let mut at = 0;
    while let Some(n) = len_at(header, at) {
        let Some(field) = header.get(at + 4..at + 4 + n) else {
            break;
        };
        if let Some(v) = field.strip_prefix(b"index_pos=") {
            return Ok(<[u8; 8]>::try_from(v).ok().map(u64::from_le_bytes));
        }
        at += 4 + n;
    }
    Ok(None)
}

/// Read the gyro `columns` (every axis of the largest IMU topic when empty)
/// of the ROS 1 bag at `path`.
pub fn read(path: &Path, columns: &[String], grid: bool) -> Result<Series, TableError> {
    let p = || path.to_path_buf();
    let bad = |e: &dyn std::fmt::Display| TableError::Record(p(), 0, format!("ROS bag: {e}"));
    // `rosbag` 0.6.3 slices its chunk section up to the header's index
    // position without checking it against the file (a bag cut short, as a
    // recorder killed mid-write leaves it, panicked there): checked here.
    let len = std::fs::metadata(path)
        .map_err(|e| TableError::Io(p(), e))?
        .len();
    match index_pos(path).map_err(|e| TableError::Io(p(), e))? {
        Some(at) if at <= len => {}
        Some(at) => {
            return Err(bad(&format!(
                "cut short: its index is at byte {at}, the file has {len} (`rosbag reindex` rebuilds it from the chunks)"
            )))
        }
        None => return Err(bad(&"no bag header with an index position (not a ROS 1 bag 2.0)")),
    }
    let bag = RosBag::new(path).map_err(|e| TableError::Io(p(), e))?;
    // Connection id → topic, for the IMU connections.
    let mut imu_conns = std::collections::HashMap::new();
    let mut topics = Topics::new();
    for record in bag.chunk_records() {
        let ChunkRecord::Chunk(chunk) = record.map_err(|e| bad(&e))? else {
            continue;
        };
        for m in chunk.messages() {
            match m.map_err(|e| bad(&e))? {
                MessageRecord::Connection(c) => {
                    if c.tp == IMU {
                        imu_conns.insert(c.id, c.topic.to_string());
                    }
                }
                MessageRecord::MessageData(m) => {
                    let Some(topic) = imu_conns.get(&m.conn_id) else {
                        continue;
                    };
                    let v = decode(m.data).ok_or_else(|| {
                        bad(&format!("{topic}: a message shorter than sensor_msgs/Imu"))
                    })?;
                    topics.entry(topic.clone()).or_default().push(v);
                }
            }
        }
    }
    series_of(&topics, columns, path, IMU, grid)
}

#[cfg(test)]
mod tests {
    use super::*;

    const DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/vectors/ros1");

    /// A bag `rosbags` wrote (`make_bag.py`): every rate as written, frame
    /// ids of three lengths, the dropped message a gap, the other topic
    /// skipped; a file that is not a bag refused.
    #[test]
    fn an_imu_topic_reads_as_rosbags_wrote_it() {
        let bag = Path::new(DIR).join("imu.bag");
        let want: Vec<Vec<f64>> = std::fs::read_to_string(Path::new(DIR).join("expected.csv"))
            .unwrap()
            .lines()
            .skip(1)
            .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
            .collect();
        assert!(is_bag(&bag));
        let s = read(&bag, &[], false).unwrap();
        assert_eq!(s.names, ["/imu.x", "/imu.y", "/imu.z"]);
        assert_eq!(s.rates[0].len(), want.len());
        let deg = 180.0 / std::f64::consts::PI;
        for (k, w) in want.iter().enumerate() {
            for a in 0..3 {
                assert_eq!(s.rates[a][k], w[a + 1] * deg, "message {k} axis {a}");
            }
        }
        assert!((s.tau0 - 0.01).abs() < 1e-12, "{}", s.tau0);
        assert_eq!(s.gap_samples, [(100, 1)]);
        let not = std::env::temp_dir().join(format!("gyro-ros1-{}.bag", std::process::id()));
        std::fs::write(&not, b"t,x\n0,1\n").unwrap();
        assert!(read(&not, &[], false).is_err());
    }
}
