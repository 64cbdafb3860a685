//! Real multi-IMU recordings in the layout of the quadrotor flights of
//! Hurwitz and Klein (CC BY 4.0, `vectors/real/README.md`): a folder per
//! log, `path_N/IMU_k.csv.gz` per chip with its `Gyr_X/Y/Z` columns,
//! deg/s, 120 Hz. Shared by `real-eval` and the `real_recordings` test.

use std::io::Read;
use std::path::{Path, PathBuf};

use gyro_tool::assess;

/// One log: per chip, the three axes' rates (°/s), 120 Hz.
pub struct Log {
    pub name: String,
    pub chips: Vec<[Vec<f64>; 3]>,
}

fn read_gz(p: &Path) -> Result<String, String> {
    let f = std::fs::File::open(p).map_err(|e| format!("{}: {e}", p.display()))?;
    let mut s = String::new();
    flate2::read::GzDecoder::new(f)
        .read_to_string(&mut s)
        .map_err(|e| format!("{}: {e}", p.display()))?;
    Ok(s)
}

/// The `Gyr_X/Y/Z` columns of one IMU file.
fn gyro_columns(text: &str, p: &Path) -> Result<[Vec<f64>; 3], String> {
    let mut lines = text.lines();
    let head: Vec<&str> = lines.next().unwrap_or("").split(',').collect();
    let col = |n: &str| {
        head.iter()
            .position(|h| h.trim() == n)
            .ok_or_else(|| format!("{}: no column {n}", p.display()))
    };
    let idx = [col("Gyr_X")?, col("Gyr_Y")?, col("Gyr_Z")?];
    let mut out: [Vec<f64>; 3] = Default::default();
    for (ln, l) in lines.enumerate() {
        let f: Vec<&str> = l.split(',').collect();
        for (a, &c) in idx.iter().enumerate() {
            let v = f
                .get(c)
                .and_then(|v| v.trim().parse::<f64>().ok())
                .ok_or_else(|| {
                    format!("{} line {}: no number in column {c}", p.display(), ln + 2)
                })?;
            out[a].push(v);
        }
    }
    Ok(out)
}

pub fn load(dir: &Path) -> Result<Vec<Log>, String> {
    let mut paths: Vec<(u32, PathBuf)> = std::fs::read_dir(dir)
        .map_err(|e| format!("{}: {e}", dir.display()))?
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().to_string();
            name.strip_prefix("path_")
                .and_then(|n| n.parse().ok())
                .map(|n| (n, e.path()))
        })
        .collect();
    paths.sort();
    let mut logs = Vec::new();
    for (n, p) in paths {
        let mut chips = Vec::new();
        for k in 1..=8 {
            let f = p.join(format!("IMU_{k}.csv.gz"));
            if !f.exists() {
                break;
            }
            chips.push(gyro_columns(&read_gz(&f)?, &f)?);
        }
        // The files of a flight differ in length by a few rows: cut to
        // the shortest.
        let len = chips.iter().map(|c| c[0].len()).min().unwrap_or(0);
        for c in &mut chips {
            for a in c.iter_mut() {
                a.truncate(len);
            }
        }
        logs.push(Log {
            name: format!("path {n}"),
            chips,
        });
    }
    Ok(logs)
}

/// Shift every chip by its lag against the first (`assess::lags` over
/// the three axes); the lags.
pub fn align(log: &mut Log) -> Vec<i64> {
    let axes: Vec<Vec<Vec<f64>>> = (0..3)
        .map(|ax| log.chips.iter().map(|c| c[ax].clone()).collect())
        .collect();
    let refs: Vec<&[Vec<f64>]> = axes.iter().map(|a| &a[..]).collect();
    let lags = assess::lags(&refs);
    for (ax, chips) in axes.iter().enumerate() {
        for (c, v) in assess::shifted(chips, &lags).into_iter().enumerate() {
            log.chips[c][ax] = v;
        }
    }
    lags
}

/// The committed flights (`vectors/real/quadrotor`).
pub fn committed() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("vectors/real/quadrotor")
}
