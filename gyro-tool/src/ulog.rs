//! Gyro rates from a PX4 ULog (`.ulg`), read by the `px4-ulog` crate.
//!
//! The gyro topics PX4 logs: `sensor_gyro` (each IMU's calibrated rate,
//! fields `x`, `y`, `z` in rad/s, stamped `timestamp_sample` µs), one
//! instance per IMU, and `sensor_combined` (the selected IMU's,
//! `gyro_rad[0..2]`). Columns are named `TOPIC.INSTANCE.AXIS`
//! (`sensor_gyro.1.z`, `sensor_combined.0.x`). One read takes columns of
//! one topic instance (one time base); by default every axis of the gyro
//! instance with the most samples. Rates are turned from the log's rad/s
//! into °/s; τ0 is the median step of the stamps, and steps over 1.5 τ0
//! are reported as gaps (sample index in place of a line): as ROS bags'
//! IMU topics are ([`crate::ros2::series_of`]).

use std::path::Path;

use px4_ulog::full_parser::{read_file, Completeness, SomeVec};

use crate::ros2::{series_of, Topics};
use crate::table::{Series, TableError};

/// The gyro topics: (topic, the axes' fields, the stamp's field).
const TOPICS: [(&str, [&str; 3], &str); 2] = [
    ("sensor_gyro", ["x", "y", "z"], "timestamp_sample"),
    (
        "sensor_combined",
        ["gyro_rad[0]", "gyro_rad[1]", "gyro_rad[2]"],
        "timestamp",
    ),
];

fn floats(v: &SomeVec) -> Option<Vec<f64>> {
    Some(match v {
        SomeVec::Float(v) => v.iter().map(|&x| f64::from(x)).collect(),
        SomeVec::Double(v) => v.clone(),
        _ => return None,
    })
}

/// Read the gyro `columns` (every axis of the largest gyro instance when
/// empty) of the ULog at `path`: each topic instance as `TOPIC.INSTANCE`,
/// its samples (stamp, rates) chosen and checked as a ROS bag's IMU
/// topics are ([`crate::ros2::series_of`]).
pub fn read(path: &Path, columns: &[String], grid: bool) -> Result<Series, TableError> {
    let p = || path.to_path_buf();
    let text = path.to_string_lossy();
    let parsed = read_file(&text).map_err(|e| TableError::Io(p(), e))?;
    if let Completeness::MalformedRecord(why) = &parsed.completeness {
        return Err(TableError::Record(p(), 0, format!("ULog record: {why}")));
    }
    let mut topics = Topics::new();
    for (topic, axes, stamp) in TOPICS {
        let Some(instances) = parsed.messages.get(topic) else {
            continue;
        };
        for (id, fields) in instances {
            let name = format!("{topic}.{}", id.value());
            let missing = |f: &str| TableError::NoColumn(p(), format!("{name}: {f}"), Vec::new());
            let t = match fields.get(stamp) {
                Some(SomeVec::UInt64(t)) => t,
                _ => return Err(missing(stamp)),
            };
            let mut v = [Vec::new(), Vec::new(), Vec::new()];
            for (slot, field) in v.iter_mut().zip(axes) {
                *slot = fields
                    .get(field)
                    .and_then(floats)
                    .ok_or_else(|| missing(field))?;
            }
            if v.iter().any(|a| a.len() != t.len()) {
                return Err(TableError::Record(
                    p(),
                    0,
                    format!("{name}: fields of unequal length"),
                ));
            }
            // µs stamps as ns: exact, and the bags' unit.
            let samples = t
                .iter()
                .enumerate()
                .map(|(k, &us)| (us as i64 * 1000, [v[0][k], v[1][k], v[2][k]]))
                .collect();
            topics.insert(name, samples);
        }
    }
    series_of(&topics, columns, path, "sensor_gyro", grid)
}

#[cfg(test)]
mod tests {
    use super::*;

    const DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/vectors/ulog");

    /// pyulog's test log (`tests/vectors/ulog`, BSD 3-Clause): every gyro
    /// topic instance as pyulog reads it (`make_expected.py`): the sample
    /// count, the median stamp step, the first and last rate in °/s.
    #[test]
    fn the_gyro_topics_read_as_pyulog_reads_them() {
        let log = Path::new(DIR).join("sample_log_small.ulg");
        let expected = std::fs::read_to_string(Path::new(DIR).join("expected.csv")).unwrap();
        let mut checked = 0;
        for l in expected.lines().skip(1) {
            let f: Vec<&str> = l.split(',').collect();
            let s = read(&log, &[f[0].to_string()], false).unwrap();
            assert_eq!(s.names, [f[0]]);
            assert_eq!(s.rates[0].len(), f[1].parse::<usize>().unwrap(), "{l}");
            assert!((s.tau0 - f[2].parse::<f64>().unwrap()).abs() < 1e-12, "{l}");
            for (got, want) in [(s.rates[0][0], f[3]), (*s.rates[0].last().unwrap(), f[4])] {
                let want: f64 = want.parse().unwrap();
                // f32 in the log, the same conversion: to the last bits.
                assert!(
                    (got - want).abs() <= 1e-12 * want.abs().max(1.0),
                    "{l}: {got}"
                );
            }
            checked += 1;
        }
        assert_eq!(checked, 12);
        // By default every axis of the instance with the most samples.
        let s = read(&log, &[], false).unwrap();
        assert_eq!(
            s.names,
            [
                "sensor_combined.0.x",
                "sensor_combined.0.y",
                "sensor_combined.0.z"
            ]
        );
        // Two instances in one read: refused, with the reason.
        let e = read(
            &log,
            &["sensor_gyro.0.x".into(), "sensor_gyro.1.x".into()],
            false,
        )
        .unwrap_err();
        assert!(e.to_string().contains("one topic instance"), "{e}");
        // A column that is not there names those that are.
        let e = read(&log, &["sensor_gyro.7.x".into()], false).unwrap_err();
        assert!(e.to_string().contains("sensor_gyro.2.z"), "{e}");
        // Not a ULog.
        let bad = std::env::temp_dir().join(format!("gyro-ulog-{}.ulg", std::process::id()));
        std::fs::write(&bad, b"t,x\n0,1\n").unwrap();
        assert!(read(&bad, &[], false).is_err());
    }
}
