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
//! are reported as gaps (sample index in place of a line).

use std::collections::HashMap;
use std::path::Path;

use px4_ulog::full_parser::{read_file, Completeness, SomeVec};

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

const AXES: [&str; 3] = ["x", "y", "z"];

fn floats(v: &SomeVec) -> Option<Vec<f64>> {
    Some(match v {
        SomeVec::Float(v) => v.iter().map(|&x| f64::from(x)).collect(),
        SomeVec::Double(v) => v.clone(),
        _ => return None,
    })
}

fn stamps(v: &SomeVec) -> Option<Vec<u64>> {
    match v {
        SomeVec::UInt64(v) => Some(v.clone()),
        _ => None,
    }
}

/// A gyro instance in the log: topic, instance, samples.
struct Found<'a> {
    topic: &'static str,
    axes: [&'static str; 3],
    stamp: &'static str,
    instance: u8,
    fields: &'a HashMap<String, SomeVec>,
    samples: usize,
}

/// Read the gyro `columns` (every axis of the largest gyro instance when
/// empty) of the ULog at `path`.
pub fn read(path: &Path, columns: &[String]) -> Result<Series, TableError> {
    let p = || path.to_path_buf();
    let text = path.to_string_lossy();
    let parsed = read_file(&text).map_err(|e| TableError::Io(p(), e))?;
    if let Completeness::MalformedRecord(why) = &parsed.completeness {
        return Err(TableError::Record(p(), 0, format!("ULog record: {why}")));
    }
    let mut found: Vec<Found> = Vec::new();
    for (topic, axes, stamp) in TOPICS {
        let Some(instances) = parsed.messages.get(topic) else {
            continue;
        };
        for (id, fields) in instances {
            let samples = fields.get(stamp).and_then(stamps).map_or(0, |s| s.len());
            found.push(Found {
                topic,
                axes,
                stamp,
                instance: id.value(),
                fields,
                samples,
            });
        }
    }
    found.sort_by_key(|f| (f.topic, f.instance));
    let names = |f: &Found| -> Vec<String> {
        AXES.iter()
            .map(|a| format!("{}.{}.{a}", f.topic, f.instance))
            .collect()
    };
    let all: Vec<String> = found.iter().flat_map(names).collect();
    // The instance and its axes the columns name.
    let (which, axes): (&Found, Vec<usize>) = if columns.is_empty() {
        let f = found
            .iter()
            .max_by_key(|f| f.samples)
            .ok_or_else(|| TableError::NoColumn(p(), "sensor_gyro".into(), all.clone()))?;
        (f, vec![0, 1, 2])
    } else {
        let mut which: Option<&Found> = None;
        let mut axes = Vec::new();
        for c in columns {
            let hit = found
                .iter()
                .find_map(|f| names(f).iter().position(|n| n == c).map(|a| (f, a)));
            let Some((f, a)) = hit else {
                return Err(TableError::NoColumn(p(), c.clone(), all.clone()));
            };
            if which.is_some_and(|w| (w.topic, w.instance) != (f.topic, f.instance)) {
                return Err(TableError::Record(
                    p(),
                    0,
                    format!("{c}: one topic instance a read (each has its own time base)"),
                ));
            }
            which = Some(f);
            axes.push(a);
        }
        match which {
            Some(w) => (w, axes),
            None => return Err(TableError::NoColumn(p(), String::new(), all)),
        }
    };
    let t = which
        .fields
        .get(which.stamp)
        .and_then(stamps)
        .ok_or_else(|| TableError::NoColumn(p(), which.stamp.into(), all.clone()))?;
    let deg = 180.0 / std::f64::consts::PI;
    let mut rates = Vec::with_capacity(axes.len());
    for &a in &axes {
        let v = which
            .fields
            .get(which.axes[a])
            .and_then(floats)
            .ok_or_else(|| TableError::NoColumn(p(), which.axes[a].into(), all.clone()))?;
        if let Some(k) = v.iter().position(|x| !x.is_finite()) {
            return Err(TableError::Number(
                p(),
                k,
                names(which)[a].clone(),
                v[k].to_string(),
            ));
        }
        rates.push(v.into_iter().map(|x| x * deg).collect::<Vec<f64>>());
    }
    let n = t.len();
    if n < 3 {
        return Err(TableError::TooShort(p(), n));
    }
    if let Some(k) = t.windows(2).position(|w| w[1] <= w[0]) {
        return Err(TableError::Time(
            p(),
            k + 1,
            t[k] as f64 * 1e-6,
            t[k + 1] as f64 * 1e-6,
        ));
    }
    let steps: Vec<f64> = t.windows(2).map(|w| (w[1] - w[0]) as f64 * 1e-6).collect();
    let (tau0, (gaps, gap_samples)) = crate::table::gaps_of(&steps);
    Ok(Series {
        names: axes.iter().map(|&a| names(which)[a].clone()).collect(),
        rates,
        tau0,
        gaps,
        gap_samples,
    })
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
            let s = read(&log, &[f[0].to_string()]).unwrap();
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
        let s = read(&log, &[]).unwrap();
        assert_eq!(
            s.names,
            [
                "sensor_combined.0.x",
                "sensor_combined.0.y",
                "sensor_combined.0.z"
            ]
        );
        // Two instances in one read: refused, with the reason.
        let e = read(&log, &["sensor_gyro.0.x".into(), "sensor_gyro.1.x".into()]).unwrap_err();
        assert!(e.to_string().contains("one topic instance"), "{e}");
        // A column that is not there names those that are.
        let e = read(&log, &["sensor_gyro.7.x".into()]).unwrap_err();
        assert!(e.to_string().contains("sensor_gyro.2.z"), "{e}");
        // Not a ULog.
        let bad = std::env::temp_dir().join(format!("gyro-ulog-{}.ulg", std::process::id()));
        std::fs::write(&bad, b"t,x\n0,1\n").unwrap();
        assert!(read(&bad, &[]).is_err());
    }
}
