//! Gyro rates from an ArduPilot dataflash log (`.bin`/`.BIN`, what the
//! autopilot writes to its SD card), read by the `ardupilot-binlog` crate.
//!
//! The log is self-describing (its FMT messages give every message's
//! layout), and its gyro messages have changed names over the years:
//! `IMU`, `IMU2`, `IMU3` (one message per IMU, before ArduPilot 4.1), `IMU`
//! with an instance field `I` (since), each `GyrX`, `GyrY`, `GyrZ` in rad/s
//! stamped `TimeUS`; and `GYR` (the batch sampler's and fast logging's raw
//! samples, `I`, stamped `SampleUS` where it is logged). Each IMU is a
//! topic `IMU.INSTANCE` (`IMU2` is `IMU.1`, whichever name the log uses),
//! each raw stream `GYR.INSTANCE`; columns `IMU.1.z` and so on. One read
//! takes one topic (one time base), by default the one with the most
//! samples; rates are turned into °/s, and τ0 and gaps come from the
//! stamps, as a ROS bag's IMU topics do ([`crate::ros2::series_of`]).
//!
//! The crate steps over corrupt bytes to the next message header (a log
//! cut by a power loss ends in a partial message): what it could not
//! decode is not reported here.

use std::path::Path;

use ardupilot_binlog::{Entry, File};

use crate::ros2::{series_of, Topics};
use crate::table::{Series, TableError};

/// Every dataflash message starts with these two bytes (`HEAD_BYTE1`,
/// `HEAD_BYTE2` in ArduPilot's `LogStructure.h`).
const MAGIC: [u8; 2] = [0xA3, 0x95];

/// Whether `path` is a dataflash log: a `.bin` whose first bytes are a
/// message header (a raw binary column file may be named `.bin` too).
pub fn is_log(path: &Path) -> bool {
    use std::io::Read;
    if !path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("bin"))
    {
        return false;
    }
    let mut head = [0u8; 2];
    std::fs::File::open(path)
        .and_then(|mut f| f.read_exact(&mut head))
        .is_ok_and(|()| head == MAGIC)
}

/// The topic, stamp (µs) and rates (rad/s) of a gyro message; None for any
/// other message.
fn gyro_of(e: &Entry) -> Option<(String, u64, [f64; 3])> {
    let (kind, old_instance) = match e.name.as_str() {
        "IMU" => ("IMU", 0),
        "IMU2" => ("IMU", 1),
        "IMU3" => ("IMU", 2),
        "GYR" => ("GYR", 0),
        _ => return None,
    };
    let instance = e.get_i64("I").unwrap_or(old_instance);
    let stamp = e
        .get("SampleUS")
        .or_else(|| e.get("TimeUS"))
        .and_then(|v| {
            v.as_u64()
                .or_else(|| v.as_i64().and_then(|t| u64::try_from(t).ok()))
        })?;
    let rates = [e.get_f64("GyrX")?, e.get_f64("GyrY")?, e.get_f64("GyrZ")?];
    Some((format!("{kind}.{instance}"), stamp, rates))
}

/// Read the gyro `columns` (every axis of the largest gyro topic when
/// empty) of the dataflash log at `path`.
pub fn read(path: &Path, columns: &[String], grid: bool) -> Result<Series, TableError> {
    let p = || path.to_path_buf();
    let bad = |e: &dyn std::fmt::Display| TableError::Record(p(), 0, format!("dataflash log: {e}"));
    let file = File::open(path).map_err(|e| bad(&e))?;
    let mut topics = Topics::new();
    for entry in file.entries().map_err(|e| bad(&e))? {
        let entry = entry.map_err(|e| bad(&e))?;
        if let Some((topic, us, rates)) = gyro_of(&entry) {
            let ns = i64::try_from(us)
                .ok()
                .and_then(|u| u.checked_mul(1_000))
                .ok_or_else(|| bad(&format!("{topic}: stamp {us} µs out of range")))?;
            topics.entry(topic).or_default().push((ns, rates));
        }
    }
    series_of(&topics, columns, path, "IMU or GYR message", grid)
}

#[cfg(test)]
mod tests {
    use super::*;

    const DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/vectors/dataflash");

    /// pymavlink's test log (a real ArduCopter log with two IMUs logged as
    /// `IMU` and `IMU2`): every rate and stamp as pymavlink's `DFReader`
    /// reads them (`make_expected.py`), per IMU; the default read is the
    /// first of the two largest.
    #[test]
    fn pymavlinks_test_log_reads_as_pymavlink_reads_it() {
        let log = Path::new(DIR).join("test.BIN");
        assert!(is_log(&log));
        let text = std::fs::read_to_string(Path::new(DIR).join("expected.csv")).unwrap();
        let deg = 180.0 / std::f64::consts::PI;
        for instance in 0..2 {
            let want: Vec<Vec<f64>> = text
                .lines()
                .skip(1)
                .map(|l| l.split(',').collect::<Vec<_>>())
                .filter(|f| f[1] == instance.to_string())
                .map(|f| f[2..].iter().map(|v| v.parse().unwrap()).collect())
                .collect();
            assert_eq!(want.len(), 45);
            let cols: Vec<String> = ["x", "y", "z"]
                .iter()
                .map(|a| format!("IMU.{instance}.{a}"))
                .collect();
            let s = read(&log, &cols, false).unwrap();
            assert_eq!(s.names, cols);
            assert_eq!(s.rates[0].len(), want.len());
            for (k, w) in want.iter().enumerate() {
                for a in 0..3 {
                    assert_eq!(
                        s.rates[a][k],
                        w[a + 1] * deg,
                        "IMU.{instance} message {k} axis {a}"
                    );
                }
            }
            // τ0 is the stamps' median step.
            let mut steps: Vec<f64> = want
                .windows(2)
                .map(|w| (w[1][0] - w[0][0]) * 1e-6)
                .collect();
            steps.sort_by(f64::total_cmp);
            assert!((s.tau0 - steps[steps.len() / 2]).abs() < 1e-9, "{}", s.tau0);
        }
        let s = read(&log, &[], false).unwrap();
        assert_eq!(s.names, ["IMU.0.x", "IMU.0.y", "IMU.0.z"]);
        let e = read(&log, &["IMU.2.x".into()], false)
            .unwrap_err()
            .to_string();
        assert!(e.contains("IMU.1.x"), "{e}");
    }

    /// A `.bin` that is not a dataflash log is not taken for one; a log
    /// cut short reads what came before the cut.
    #[test]
    fn other_bin_files_and_a_cut_log() {
        let dir = std::env::temp_dir();
        let raw = dir.join(format!("gyro-raw-{}.bin", std::process::id()));
        std::fs::write(&raw, 1.5f32.to_le_bytes().repeat(8)).unwrap();
        assert!(!is_log(&raw));
        std::fs::remove_file(&raw).unwrap();
        let bytes = std::fs::read(Path::new(DIR).join("test.BIN")).unwrap();
        let cut = dir.join(format!("gyro-cut-{}.bin", std::process::id()));
        std::fs::write(&cut, &bytes[..bytes.len() / 2 + 7]).unwrap();
        let s = read(&cut, &[], false);
        std::fs::remove_file(&cut).unwrap();
        let whole = read(&Path::new(DIR).join("test.BIN"), &[], false).unwrap();
        let s = s.unwrap();
        let n = s.rates[0].len();
        assert!(n > 3 && n < whole.rates[0].len(), "{n}");
        assert_eq!(s.rates[0][..], whole.rates[0][..n]);
    }
}
