//! Gyro rates from a ROS 2 bag, in MCAP storage (the default since ROS 2
//! Iron) or in sqlite3 (the default before it: Foxy to Humble, what most
//! of Kalibr's and allan_variance_ros' users have): every
//! `sensor_msgs/msg/Imu` topic, the container read by the `mcap` crate or
//! through `rusqlite` (the `topics` and `messages` tables rosbag2's
//! sqlite3 plugin writes; the columns read are in every schema version
//! since Foxy), each message's CDR decoded by the `cdr` crate.
//!
//! Columns are `TOPIC.x`, `TOPIC.y`, `TOPIC.z` (`/imu/data.z`) from
//! `angular_velocity`, rad/s turned into °/s; one topic a read, by default
//! the one with the most messages. Each sample's time is its header stamp
//! (when the IMU sampled, not when the bag logged it): τ0 is the stamps'
//! median step, steps over 1.5 τ0 are gaps (message index in place of a
//! line). A bag directory (with `metadata.yaml`) or its `.mcap` or `.db3`
//! file; a bag split over several files is refused, naming them.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::table::{Series, TableError};

/// `sensor_msgs/msg/Imu` as CDR lays it out.
#[derive(serde::Deserialize)]
struct Imu {
    header: Header,
    _orientation: [f64; 4],
    _orientation_covariance: [f64; 9],
    angular_velocity: [f64; 3],
}

#[derive(serde::Deserialize)]
struct Header {
    sec: i32,
    nanosec: u32,
    _frame_id: String,
}

const IMU: &str = "sensor_msgs/msg/Imu";

/// How a bag's messages are stored.
#[derive(Clone, Copy, PartialEq, Debug)]
enum Storage {
    Mcap,
    Sqlite3,
}

fn storage_of(path: &Path) -> Option<Storage> {
    let ext = path.extension()?;
    if ext.eq_ignore_ascii_case("mcap") {
        Some(Storage::Mcap)
    } else if ext.eq_ignore_ascii_case("db3") {
        Some(Storage::Sqlite3)
    } else {
        None
    }
}

/// The storage file of a bag given as a directory or as the file.
fn bag_file(path: &Path) -> Result<(PathBuf, Storage), TableError> {
    if !path.is_dir() {
        let s = storage_of(path).ok_or_else(|| {
            TableError::Record(
                path.to_path_buf(),
                0,
                "not a ROS 2 bag file (.mcap or .db3)".into(),
            )
        })?;
        return Ok((path.to_path_buf(), s));
    }
    let entries = std::fs::read_dir(path).map_err(|e| TableError::Io(path.to_path_buf(), e))?;
    let mut files: Vec<(PathBuf, Storage)> = entries
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter_map(|p| storage_of(&p).map(|s| (p, s)))
        .collect();
    files.sort_by(|a, b| a.0.cmp(&b.0));
    match files.len() {
        1 => Ok(files.remove(0)),
        0 => Err(TableError::Record(
            path.to_path_buf(),
            0,
            "no .mcap or .db3 file in the bag".into(),
        )),
        n => Err(TableError::Record(
            path.to_path_buf(),
            0,
            format!(
                "{n} storage files in the bag (a split bag): give one of {}",
                files
                    .iter()
                    .filter_map(|(f, _)| f.file_name().map(|n| n.to_string_lossy().into_owned()))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        )),
    }
}

/// Whether `path` is a ROS 2 bag this module reads.
pub fn is_bag(path: &Path) -> bool {
    storage_of(path).is_some() || (path.is_dir() && path.join("metadata.yaml").is_file())
}

/// Read the gyro `columns` (every axis of the largest IMU topic when empty)
/// of the bag at `path`.
pub fn read(path: &Path, columns: &[String], grid: bool) -> Result<Series, TableError> {
    let (file, storage) = bag_file(path)?;
    let topics = match storage {
        Storage::Mcap => mcap_topics(&file)?,
        Storage::Sqlite3 => sqlite_topics(&file)?,
    };
    series_of(&topics, columns, &file, IMU, grid)
}

/// One message's CDR as (stamp ns, angular velocity rad/s).
fn decode(data: &[u8], topic: &str, file: &Path) -> Result<(i64, [f64; 3]), TableError> {
    let imu: Imu = cdr::deserialize(data)
        .map_err(|e| TableError::Record(file.to_path_buf(), 0, format!("{topic}: {e}")))?;
    let ns = i64::from(imu.header.sec) * 1_000_000_000 + i64::from(imu.header.nanosec);
    Ok((ns, imu.angular_velocity))
}

/// The IMU topics of a sqlite3 bag, each in the order the recorder wrote
/// them (the `messages` table's row id).
fn sqlite_topics(file: &Path) -> Result<Topics, TableError> {
    use rusqlite::{Connection, OpenFlags};
    let p = || file.to_path_buf();
    let bad = |e: &dyn std::fmt::Display| TableError::Record(p(), 0, format!("sqlite3 bag: {e}"));
    if !file.is_file() {
        return Err(TableError::Io(
            p(),
            std::io::Error::new(std::io::ErrorKind::NotFound, "no such file"),
        ));
    }
    // Read-only, and no journal or lock files beside a bag that may sit
    // on a read-only medium.
    let db = Connection::open_with_flags(
        file,
        OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX,
    )
    .map_err(|e| bad(&e))?;
    let mut topics = Topics::new();
    let mut formats = db
        .prepare("SELECT name, serialization_format FROM topics WHERE type = ?1")
        .map_err(|e| bad(&e))?;
    let rows = formats
        .query_map([IMU], |r| {
            Ok((r.get::<_, String>(0)?, r.get::<_, String>(1)?))
        })
        .map_err(|e| bad(&e))?;
    for row in rows {
        let (topic, format) = row.map_err(|e| bad(&e))?;
        if format != "cdr" {
            return Err(bad(&format!(
                "{topic}: serialization format {format:?}, not cdr"
            )));
        }
    }
    let mut stmt = db
        .prepare(
            "SELECT topics.name, messages.data FROM messages \
             JOIN topics ON messages.topic_id = topics.id \
             WHERE topics.type = ?1 ORDER BY messages.id",
        )
        .map_err(|e| bad(&e))?;
    let mut rows = stmt.query([IMU]).map_err(|e| bad(&e))?;
    while let Some(row) = rows.next().map_err(|e| bad(&e))? {
        let topic: String = row.get(0).map_err(|e| bad(&e))?;
        let data = row.get_ref(1).map_err(|e| bad(&e))?;
        let bytes = data.as_blob().map_err(|e| bad(&format!("{topic}: {e}")))?;
        let m = decode(bytes, &topic, file)?;
        topics.entry(topic).or_default().push(m);
    }
    Ok(topics)
}

/// The IMU topics of an MCAP bag, in the file's order.
fn mcap_topics(file: &Path) -> Result<Topics, TableError> {
    let p = || file.to_path_buf();
    let bytes = std::fs::read(file).map_err(|e| TableError::Io(p(), e))?;
    let bad = |e: &dyn std::fmt::Display| TableError::Record(p(), 0, format!("MCAP: {e}"));
    // Per IMU topic: (stamp ns, rates rad/s) in the file's order.
    let mut topics = Topics::new();
    let stream = mcap::MessageStream::new(&bytes).map_err(|e| bad(&e))?;
    for m in stream {
        let m = m.map_err(|e| bad(&e))?;
        let is_imu = m.channel.schema.as_ref().is_some_and(|s| s.name == IMU);
        if !is_imu {
            continue;
        }
        if m.channel.message_encoding != "cdr" {
            return Err(bad(&format!(
                "{}: message encoding {:?}, not cdr",
                m.channel.topic, m.channel.message_encoding
            )));
        }
        let msg = decode(&m.data, &m.channel.topic, file)?;
        topics.entry(m.channel.topic.clone()).or_default().push(msg);
    }
    Ok(topics)
}

/// Per IMU topic, its messages as (stamp ns, angular velocity rad/s) in
/// the log's order.
pub(crate) type Topics = BTreeMap<String, Vec<(i64, [f64; 3])>>;

/// The `columns` (`TOPIC.x` …; every axis of the topic with the most
/// messages when empty) of `topics` as a rate log in °/s, timed by the
/// stamps. `file` names the log in errors, `what` the message type.
///
/// Columns of several topics (several IMUs: `gyro replay`'s chips) only
/// with `grid`: they are put on the first column's topic's stamps, each
/// other topic's message nearest a grid stamp taken where it lies within
/// half the grid's τ0 (each message once), and NaN, a chip that did not
/// answer, where none does. Nearest, not interpolated: a value between two
/// samples of white noise has half their variance, which the fusion's
/// noise model would read as a quieter chip; a lag of whole samples is
/// `gyro replay`'s alignment to take out.
pub(crate) fn series_of(
    topics: &Topics,
    columns: &[String],
    file: &Path,
    what: &str,
    grid: bool,
) -> Result<Series, TableError> {
    let p = || file.to_path_buf();
    let names =
        |t: &str| -> Vec<String> { ["x", "y", "z"].iter().map(|a| format!("{t}.{a}")).collect() };
    let all: Vec<String> = topics.keys().flat_map(|t| names(t)).collect();
    // Each column as (topic, axis).
    let picks: Vec<(&String, usize)> = if columns.is_empty() {
        // The first in name order where several have the most (`max_by_key`
        // keeps the last of equals).
        let t = topics
            .iter()
            .rev()
            .max_by_key(|(_, v)| v.len())
            .map(|(t, _)| t)
            .ok_or_else(|| TableError::NoColumn(p(), what.into(), all.clone()))?;
        (0..3).map(|a| (t, a)).collect()
    } else {
        let mut picks = Vec::new();
        for c in columns {
            let hit = topics
                .keys()
                .find_map(|t| names(t).iter().position(|n| n == c).map(|a| (t, a)));
            let Some((t, a)) = hit else {
                return Err(TableError::NoColumn(p(), c.clone(), all.clone()));
            };
            if !grid && picks.first().is_some_and(|&(w, _)| w != t) {
                return Err(TableError::Record(
                    p(),
                    0,
                    format!(
                        "{c}: one topic instance a read (each has its own time base; `gyro replay` puts several on one)"
                    ),
                ));
            }
            picks.push((t, a));
        }
        picks
    };
    let Some(&(topic, _)) = picks.first() else {
        return Err(TableError::NoColumn(p(), String::new(), all));
    };
    let msgs = &topics[topic];
    let n = msgs.len();
    if n < 3 {
        return Err(TableError::TooShort(p(), n));
    }
    for (t, m) in topics
        .iter()
        .filter(|(t, _)| picks.iter().any(|q| q.0 == *t))
    {
        if let Some(k) = m.windows(2).position(|w| w[1].0 <= w[0].0) {
            let (a, b) = (m[k].0 as f64 * 1e-9, m[k + 1].0 as f64 * 1e-9);
            // The grid's own topic as a time column is; another by name
            // (its message index is not the grid's).
            return Err(if t == topic {
                TableError::Time(p(), k + 1, a, b)
            } else {
                TableError::Record(
                    p(),
                    k + 1,
                    format!("{t}: stamp {b} s does not follow {a} s (non-monotonic)"),
                )
            });
        }
    }
    let steps: Vec<f64> = msgs
        .windows(2)
        .map(|w| (w[1].0 - w[0].0) as f64 * 1e-9)
        .collect();
    let (tau0, (gaps, gap_samples)) = crate::table::gaps_of(&steps);
    let deg = 180.0 / std::f64::consts::PI;
    let mut rates = Vec::with_capacity(picks.len());
    for &(t, a) in &picks {
        let v: Vec<f64> = if t == topic {
            msgs.iter().map(|m| m.1[a] * deg).collect()
        } else {
            on_grid(msgs, &topics[t], tau0)
                .into_iter()
                .map(|m| m.map_or(f64::NAN, |m| m.1[a] * deg))
                .collect()
        };
        if let Some(k) = v
            .iter()
            .position(|x| x.is_infinite() || (t == topic && x.is_nan()))
        {
            return Err(TableError::Number(
                p(),
                k,
                names(t)[a].clone(),
                v[k].to_string(),
            ));
        }
        rates.push(v);
    }
    Ok(Series {
        names: picks.iter().map(|&(t, a)| names(t)[a].clone()).collect(),
        rates,
        tau0,
        gaps,
        gap_samples,
    })
}

/// Per stamp of `grid`, the message of `other` nearest it within τ0/2 (τ0
/// in s), each message used once; both in time order.
fn on_grid<'a>(
    grid: &[(i64, [f64; 3])],
    other: &'a [(i64, [f64; 3])],
    tau0: f64,
) -> Vec<Option<&'a (i64, [f64; 3])>> {
    let half = (tau0 * 0.5e9) as i64;
    let mut j = 0;
    grid.iter()
        .map(|&(g, _)| {
            // The first message not before g − τ0/2 and its successor: the
            // nearest to g is one of them.
            while other.get(j).is_some_and(|m| m.0 < g - half) {
                j += 1;
            }
            let best = [j, j + 1]
                .into_iter()
                .filter_map(|k| other.get(k).map(|m| (k, m)))
                .filter(|(_, m)| (m.0 - g).abs() <= half)
                .min_by_key(|(_, m)| (m.0 - g).abs());
            best.map(|(k, m)| {
                j = k + 1;
                m
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    const DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/vectors/ros2");

    /// A bag `rosbags` wrote (`make_bag.py`): every rate as written (°/s
    /// from rad/s), the stamps' step and the one dropped message as a gap,
    /// the other topic skipped; the bag as a directory or as its file.
    #[test]
    fn an_imu_topic_reads_as_rosbags_wrote_it() {
        let bag = Path::new(DIR).join("imu_bag");
        let want: Vec<Vec<f64>> = std::fs::read_to_string(Path::new(DIR).join("expected.csv"))
            .unwrap()
            .lines()
            .skip(1)
            .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
            .collect();
        assert!(is_bag(&bag));
        for path in [bag.clone(), bag.join("imu_bag.mcap")] {
            let s = read(&path, &[], false).unwrap();
            assert_eq!(s.names, ["/imu/data.x", "/imu/data.y", "/imu/data.z"]);
            assert_eq!(s.rates[0].len(), want.len());
            let deg = 180.0 / std::f64::consts::PI;
            for (k, w) in want.iter().enumerate() {
                for a in 0..3 {
                    assert_eq!(s.rates[a][k], w[a + 1] * deg, "message {k} axis {a}");
                }
            }
            assert!((s.tau0 - 0.005).abs() < 1e-12, "{}", s.tau0);
            assert_eq!(s.gap_samples, [(250, 1)]);
        }
        let s = read(&bag, &["/imu/data.z".into()], false).unwrap();
        assert_eq!(s.rates.len(), 1);
        let e = read(&bag, &["/imu/data.w".into()], false).unwrap_err();
        assert!(e.to_string().contains("/imu/data.x"), "{e}");
    }

    /// Several topics on the first's stamps: a topic 1 ms late, one
    /// running twice as fast, one that misses a message; each matched to
    /// the nearest within half a period, the rest NaN; refused without
    /// `grid`.
    #[test]
    fn several_topics_on_one_grid() {
        let ms = 1_000_000i64;
        let msg = |t: i64, v: f64| (t, [v, 0.0, 0.0]);
        let mut topics = Topics::new();
        topics.insert(
            "/a".into(),
            (0..10).map(|k| msg(10 * ms * k, k as f64)).collect(),
        );
        topics.insert(
            "/b".into(),
            (0..10)
                .map(|k| msg(10 * ms * k + ms, 10.0 + k as f64))
                .collect(),
        );
        topics.insert(
            "/c".into(),
            (0..20).map(|k| msg(5 * ms * k, 20.0 + k as f64)).collect(),
        );
        topics.insert(
            "/d".into(),
            (0..10)
                .filter(|&k| k != 4)
                .map(|k| msg(10 * ms * k + 6 * ms, 40.0 + k as f64))
                .collect(),
        );
        let cols: Vec<String> = ["/a.x", "/b.x", "/c.x", "/d.x"].map(String::from).to_vec();
        let f = Path::new("x.bag");
        let s = series_of(&topics, &cols, f, IMU, true).unwrap();
        let deg = 180.0 / std::f64::consts::PI;
        let got: Vec<Vec<f64>> = s
            .rates
            .iter()
            .map(|r| r.iter().map(|v| (v / deg * 1e6).round() / 1e6).collect())
            .collect();
        assert!((s.tau0 - 0.01).abs() < 1e-12);
        assert_eq!(got[0], (0..10).map(f64::from).collect::<Vec<_>>());
        assert_eq!(
            got[1],
            (0..10).map(|k| 10.0 + f64::from(k)).collect::<Vec<_>>()
        );
        assert_eq!(
            got[2],
            (0..10)
                .map(|k| 20.0 + 2.0 * f64::from(k))
                .collect::<Vec<_>>()
        );
        // /d is 6 ms late, past half a period: its message is nearer the
        // next grid stamp (4 ms), taken there; none for stamp 0; the one it
        // missed leaves one more hole.
        let d: Vec<Option<f64>> = got[3].iter().map(|v| v.is_finite().then_some(*v)).collect();
        assert_eq!(d[0], None);
        assert_eq!(d[1], Some(40.0));
        assert_eq!(d[5], None, "{d:?}");
        assert_eq!(d.iter().flatten().count(), 8, "{d:?}");
        let e = series_of(&topics, &cols, f, IMU, false)
            .unwrap_err()
            .to_string();
        assert!(e.contains("one topic instance a read"), "{e}");
        // A topic whose stamps go back is named, the log's path kept.
        topics.get_mut("/b").unwrap()[5].0 = 0;
        let e = series_of(&topics, &cols, f, IMU, true)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("x.bag:5: /b: stamp 0 s"), "{e}");
    }

    /// The same messages `rosbags` wrote in sqlite3 storage read exactly as
    /// their MCAP twin, as a directory or as the `.db3` file; a bag with
    /// two storage files is refused, naming both.
    #[test]
    fn a_sqlite3_bag_reads_as_its_mcap_twin() {
        let mcap = read(&Path::new(DIR).join("imu_bag"), &[], false).unwrap();
        let bag = Path::new(DIR).join("imu_bag_db3");
        assert!(is_bag(&bag));
        for path in [bag.clone(), bag.join("imu_bag_db3.db3")] {
            assert!(is_bag(&path));
            let s = read(&path, &[], false).unwrap();
            assert_eq!(s.names, mcap.names);
            assert_eq!(s.rates, mcap.rates);
            assert_eq!(s.tau0, mcap.tau0);
            assert_eq!(s.gap_samples, mcap.gap_samples);
        }
        let split = std::env::temp_dir().join(format!("gyro-split-bag-{}", std::process::id()));
        std::fs::create_dir_all(&split).unwrap();
        for f in ["a_0.db3", "a_1.db3"] {
            std::fs::copy(bag.join("imu_bag_db3.db3"), split.join(f)).unwrap();
        }
        std::fs::write(split.join("metadata.yaml"), "").unwrap();
        let e = read(&split, &[], false).unwrap_err().to_string();
        std::fs::remove_dir_all(&split).unwrap();
        assert!(e.contains("a_0.db3") && e.contains("a_1.db3"), "{e}");
        // Not a database: a typed error, not a panic.
        let junk = std::env::temp_dir().join(format!("gyro-junk-{}.db3", std::process::id()));
        std::fs::write(&junk, b"not sqlite").unwrap();
        let e = read(&junk, &[], false).unwrap_err().to_string();
        std::fs::remove_file(&junk).unwrap();
        assert!(e.contains("sqlite3 bag"), "{e}");
    }
}
