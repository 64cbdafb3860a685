//! The `gyro` tool on bad input and closed pipes: a clear error and exit
//! status 2, never a panic, an abort or a silent wrong result.

use std::io::Write;
use std::process::{Command, Stdio};

fn gyro() -> Command {
    Command::new(env!("CARGO_BIN_EXE_gyro"))
}

fn temp(name: &str, text: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("gyro-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::File::create(&p)
        .unwrap()
        .write_all(text.as_bytes())
        .unwrap();
    p
}

/// Exit status and standard error of `gyro args`.
fn fails(args: &[&str], file: &std::path::Path) -> (i32, String) {
    let o = gyro().args(args).arg(file).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert!(!err.contains("panicked"), "{args:?}: {err}");
    (o.status.code().unwrap_or(-1), err)
}

/// Standard output and error of `gyro args file`, which must succeed.
fn succeeds(args: &[&str], file: &std::path::Path) -> (String, String) {
    let o = gyro().args(args).arg(file).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert_eq!(o.status.code(), Some(0), "{args:?}: {err}");
    (String::from_utf8_lossy(&o.stdout).to_string(), err)
}

fn noise(n: usize) -> String {
    let mut s = String::from("z\n");
    let mut x: u64 = 1;
    for _ in 0..n {
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        s.push_str(&format!(
            "{}\n",
            (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        ));
    }
    s
}

#[test]
fn a_file_that_is_not_a_recording_is_refused_by_name() {
    for (name, text) in [("empty.glk", ""), ("log.csv", "t,z\n0,1\n1,2\n")] {
        let p = temp(name, text);
        for cmd in ["decode", "check", "analyse", "pointing"] {
            let (code, err) = fails(&[cmd], &p);
            assert_eq!(code, 2, "{cmd} {name}: {err}");
            assert!(err.contains("not a recording"), "{cmd} {name}: {err}");
        }
    }
}

#[test]
fn numbers_f64_cannot_carry_are_an_error_not_a_result() {
    let mut big = String::from("z\n");
    for i in 0..400 {
        big.push_str(if i % 2 == 0 { "1e308\n" } else { "-1e308\n" });
    }
    let (code, err) = fails(&["allan", "--tau0", "1"], &temp("big.csv", &big));
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("beyond what f64 carries"), "{err}");
    let (code, err) = fails(&["allan", "--tau0", "1e-300"], &temp("n.csv", &noise(300)));
    assert_eq!(code, 2, "{err}");
    let (code, err) = fails(
        &["allan", "--tau0", "1", "--fit", "--format", "csv"],
        &temp("n2.csv", &noise(300)),
    );
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--fit"), "{err}");
}

#[test]
fn rates_no_gyro_gives_are_refused_with_the_reason() {
    let mut chips = String::from("a,b,c\n");
    for _ in 0..3000 {
        chips.push_str("1e30,1e30,1e30\n");
    }
    let svg = std::env::temp_dir().join(format!("gyro-cli-{}/r.svg", std::process::id()));
    let (code, err) = fails(
        &["replay", "--tau0", "0.001", "--svg", svg.to_str().unwrap()],
        &temp("huge.csv", &chips),
    );
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("check the unit"), "{err}");
}

/// The ICM-42688-P's start-up value in the first 32 samples is left out
/// and said; a step makes the log "NOT a static log", and --static
/// analyses the quiet stretch before it.
#[test]
fn a_log_is_checked_before_it_is_believed() {
    let body = noise(20_000);
    let mut text = String::from("z\n");
    for (i, line) in body.lines().skip(1).enumerate() {
        let v: f64 = line.parse().unwrap();
        let v = if i < 32 {
            -250.0
        } else if i >= 15_000 {
            v + 5.0
        } else {
            v
        };
        text.push_str(&format!("{v}\n"));
    }
    let (out, err) = succeeds(
        &["allan", "--tau0", "0.001", "--static"],
        &temp("startup.csv", &text),
    );
    assert!(err.contains("first 32 samples read -250"), "{err}");
    assert!(err.contains("NOT a static log: 1 step(s)"), "{err}");
    assert!(err.contains("analysed alone"), "{err}");
    // The quiet stretch: from sample 32 to the block edge before the step.
    assert!(out.contains("14763 samples at tau0"), "{out}");
}

/// A stuck sensor (every sample one value) is named; its deviations are
/// 0, not the rounding a running sum leaves, and no noise model is fitted
/// to it; a single spike is named as one (not a step) and `--static`
/// analyses the stretch without it.
#[test]
fn a_stuck_column_reads_zero_without_a_model_and_a_spike_is_named() {
    let stuck = temp("stuck.csv", &format!("z\n{}", "1.5\n".repeat(3000)));
    let run = |args: &[&str]| {
        let (out, err) = succeeds(args, &stuck);
        assert!(err.contains("every sample reads 1.5"), "{err}");
        out
    };
    let out = run(&["allan", "--tau0", "0.001", "--format", "csv"]);
    // Exactly 0 (a running sum of 1.5 · 0.001 leaves some 1e-14), and no
    // noise model (one fitted to that rounding called a rate random walk
    // visible).
    let zero = out.lines().filter(|l| l.starts_with("z,oadev,")).count();
    assert!(zero > 8, "{out}");
    assert!(
        out.lines()
            .filter(|l| l.starts_with("z,oadev,"))
            .all(|l| l.split(',').nth(4) == Some("0e0")),
        "{out}"
    );
    let out = run(&["allan", "--tau0", "0.001", "--fit"]);
    assert!(!out.contains("visible"), "{out}");
    let (code, err) = fails(
        &["allan", "--tau0", "0.001", "--kalibr", "/dev/null"],
        &stuck,
    );
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("no gyro fit"), "{err}");
    let mut text = String::from("z\n");
    for (i, line) in noise(20_000).lines().skip(1).enumerate() {
        text.push_str(if i == 12_345 { "1e6\n" } else { line });
        if i != 12_345 {
            text.push('\n');
        }
    }
    let (out, err) = succeeds(
        &["allan", "--tau0", "0.001", "--static"],
        &temp("spike.csv", &text),
    );
    assert!(err.contains("1 spike(s)"), "{err}");
    assert!(err.contains("1.0000e6 at 12.345 s"), "{err}");
    assert!(!err.contains("step"), "{err}");
    // The stretch before the spike's block (samples 0 to 12 000 at the
    // 1 000-sample blocks; the longer one after it is 7 000).
    assert!(out.contains("12000 samples at tau0"), "{out}");
}

/// A row of empty fields between rows with values, in a log without a
/// time column, is a missing sample: refused with its line by the table
/// and the streamed reader alike (dropped, every later sample moved a
/// period earlier), a chip that did not answer in `gyro replay`; the
/// same rows at the end of the file are a spreadsheet's padding.
#[test]
fn an_empty_row_is_a_missing_sample_not_dropped() {
    let mut rows = String::from("a,b\n");
    for i in 0..400 {
        rows.push_str(&format!("{},{}\n", i % 7, i % 5));
        if i == 200 {
            rows.push_str(",\n");
        }
    }
    let mid = temp("mid.csv", &rows);
    for stream in [false, true] {
        let args: &[&str] = if stream {
            &["allan", "--tau0", "1", "--stream"]
        } else {
            &["allan", "--tau0", "1"]
        };
        let (code, err) = fails(args, &mid);
        assert_eq!(code, 2, "{err}");
        assert!(err.contains("mid.csv:203: a row with no value"), "{err}");
    }
    let padded = temp(
        "padded.csv",
        &format!("a,b\n,\n{}\n,\n,\n", "1,2\n3,4\n5,7"),
    );
    let (out, _) = succeeds(&["allan", "--tau0", "1"], &padded);
    assert!(out.contains("3 samples"), "{out}");
    let svg = std::env::temp_dir().join(format!("gyro-cli-{}/e.svg", std::process::id()));
    let (out, _) = succeeds(
        &[
            "replay",
            "--tau0",
            "1",
            "--no-align",
            "--svg",
            svg.to_str().unwrap(),
        ],
        &mid,
    );
    assert!(out.contains("401 samples"), "{out}");
}

/// A ROS 1 bag cut short (a recorder killed mid-write) is an error that
/// says so; the `rosbag` crate panicked on it.
#[test]
fn a_ros1_bag_cut_short_is_refused() {
    let bag = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/vectors/ros1/imu.bag");
    let bytes = std::fs::read(bag).unwrap();
    let dir = std::env::temp_dir().join(format!("gyro-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cut = dir.join("cut.bag");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let (code, err) = fails(&["allan", "--topic", "/imu/data"], &cut);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("cut short"), "{err}");
}

/// An emulated log too short for any analysis is refused, not written.
#[test]
fn an_emulated_log_of_no_samples_is_an_error() {
    let out = std::env::temp_dir().join(format!("gyro-cli-{}/none.csv", std::process::id()));
    let o = gyro()
        .args(["emulate", "--hz", "1e-9", "-o", out.to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("0 samples; the analyses need at least 3"),
        "{err}"
    );
    assert!(!out.exists());
}

/// A reference beyond any rate is refused (its errors read inf); where no
/// sample has both a fused rate and the reference, no RMS is printed.
#[test]
fn a_replays_reference_is_checked() {
    let svg = std::env::temp_dir().join(format!("gyro-cli-{}/t.svg", std::process::id()));
    let mut huge = String::from("t,a,b\n");
    let mut none = String::from("t,a,b\n");
    for i in 0..3000 {
        huge.push_str(&format!(
            "{},{}.5,{}.25\n",
            if i == 7 { 1e300 } else { 0.0 },
            i % 3,
            i % 5
        ));
        none.push_str(&format!(",{}.5,{}.25\n", i % 3, i % 5));
    }
    let args = [
        "replay",
        "--tau0",
        "0.001",
        "--truth",
        "t",
        "--svg",
        svg.to_str().unwrap(),
    ];
    let (code, err) = fails(&args, &temp("huge_truth.csv", &huge));
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("reference t, sample 7"), "{err}");
    let (out, _) = succeeds(&args, &temp("no_truth.csv", &none));
    assert!(
        !out.contains("RMS -0") && !out.contains("RMS 0.0000"),
        "{out}"
    );
    assert!(
        out.contains("fused: no fused sample with the reference"),
        "{out}"
    );
    assert!(
        out.contains("error RMS while in: no sample with the reference"),
        "{out}"
    );
    // One chip of three ever answering: said, never a table of NaN.
    let mut one = String::from("a,b,c\n");
    for i in 0..3000 {
        one.push_str(&format!("{}.5,,\n", i % 3));
    }
    let (out, _) = succeeds(
        &["replay", "--tau0", "0.001", "--svg", svg.to_str().unwrap()],
        &temp("one_chip.csv", &one),
    );
    assert!(!out.contains("NaN") && !out.contains("-0.000"), "{out}");
    assert!(out.contains("never answered"), "{out}");
    assert!(!out.contains("not static"), "{out}");
}

/// `gyro check` on the committed demo recording cut inside its last frame,
/// and with one frame sent twice: each named, where both passed.
#[test]
fn check_names_a_cut_frame_and_a_repeated_sample() {
    let rec = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../python/tests/data/highway.glk"
    );
    let bytes = std::fs::read(rec).unwrap();
    let good = gyro().arg("check").arg(rec).output().unwrap();
    assert!(good.status.success());
    let cut = temp("cut.glk", "");
    std::fs::write(&cut, &bytes[..bytes.len() - 7]).unwrap();
    let o = gyro().arg("check").arg(&cut).output().unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success() && out.contains("ends inside a frame"),
        "{out}"
    );
    // Frames end at each 0x00: repeat the one in the middle.
    let ends: Vec<usize> = bytes
        .iter()
        .enumerate()
        .filter(|(_, &b)| b == 0)
        .map(|(i, _)| i)
        .collect();
    let (a, b) = (ends[ends.len() / 2] + 1, ends[ends.len() / 2 + 1] + 1);
    let mut twice = bytes[..b].to_vec();
    twice.extend_from_slice(&bytes[a..]);
    let dup = temp("dup.glk", "");
    std::fs::write(&dup, &twice).unwrap();
    let o = gyro().arg("check").arg(&dup).output().unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(!o.status.success(), "{out}");
    assert!(
        out.contains("1 sample frames repeat the previous sequence number"),
        "{out}"
    );
}

/// `gyro … | head`: the reader goes away before the tool writes; the tool
/// ends quietly with status 0.
#[test]
fn a_closed_pipe_ends_the_output_quietly() {
    let p = temp("long.csv", &noise(200_000));
    let mut chips = String::from("a,b,c\n");
    for line in noise(60_000).lines().skip(1) {
        chips.push_str(&format!("{line},{line},{line}\n"));
    }
    let c = temp("chips.csv", &chips);
    let svg = std::env::temp_dir().join(format!("gyro-cli-{}/replay.svg", std::process::id()));
    let svg = svg.to_str().unwrap();
    for (args, file) in [
        (vec!["allan", "--tau0", "0.001", "--grid", "all"], &p),
        (vec!["replay", "--tau0", "0.001", "--svg", svg], &c),
    ] {
        let mut child = gyro()
            .args(&args)
            .arg(file)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        drop(child.stdout.take());
        let o = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            !err.contains("panicked") && !err.contains("Broken pipe"),
            "{args:?}: {err}"
        );
        assert_eq!(o.status.code(), Some(0), "{args:?}: {err}");
    }
}

/// A time column with a gap: by default OADEV from only the terms no gap
/// falls in (the term count says so), never the samples joined silently;
/// `--gaps join` joins them and says it; a deviation with no gap-tolerant
/// estimator, or the fit, is refused with the way out.
#[test]
fn a_gap_in_the_time_column_is_never_joined_silently() {
    let mut text = String::from("t,z\n");
    let mut x: u64 = 7;
    for i in 0..3000u32 {
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        if (1000..1040).contains(&i) {
            continue;
        }
        let v = (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
        text.push_str(&format!("{},{v}\n", f64::from(i) * 0.01));
    }
    let p = temp("gap.csv", &text);
    let o = gyro()
        .args(["allan", "--time", "t", "--format", "csv"])
        .arg(&p)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("only the terms no gap falls in"), "{err}");
    let out = String::from_utf8_lossy(&o.stdout);
    // m = 1: 2 999 terms on the 3 000-sample grid, less the 41 that reach
    // into the 40 missing samples.
    let m1 = out.lines().find(|l| l.starts_with("z,oadev,1,")).unwrap();
    assert_eq!(m1.split(',').nth(6), Some("2958"), "{m1}");
    let o = gyro()
        .args(["allan", "--time", "t", "--gaps", "join", "--format", "csv"])
        .arg(&p)
        .output()
        .unwrap();
    assert!(String::from_utf8_lossy(&o.stderr).contains("analysed as contiguous"));
    let out = String::from_utf8_lossy(&o.stdout);
    let m1 = out.lines().find(|l| l.starts_with("z,oadev,1,")).unwrap();
    assert_eq!(m1.split(',').nth(6), Some("2959"), "{m1}");
    for args in [&["--dev", "mdev"][..], &["--fit"][..]] {
        let mut a = vec!["allan", "--time", "t"];
        a.extend_from_slice(args);
        let (code, err) = fails(&a, &p);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(err.contains("--gaps join"), "{args:?}: {err}");
    }
}

/// Stable32's own phase file as a user has it (a headerless column of
/// phase, comment lines first), read with `--phase`: every OADEV of
/// Stable32's octave table to its printed digits, from the command line.
#[test]
fn stable32s_phase_file_reads_as_phase_from_the_command_line() {
    let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/stable32");
    let o = gyro()
        .args(["allan", "--phase", "--tau0", "1", "--format", "csv"])
        .arg(format!("{dir}/PHASE.DAT"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = String::from_utf8_lossy(&o.stdout);
    let table = std::fs::read_to_string(format!("{dir}/phase_dat_oadev_octave.txt")).unwrap();
    let mut checked = 0;
    for row in table.lines().filter(|l| !l.starts_with('#')) {
        let f: Vec<&str> = row.split_whitespace().collect();
        let Some(want) = f.get(5).and_then(|v| v.parse::<f64>().ok()) else {
            continue;
        };
        let line = out
            .lines()
            .find(|l| l.starts_with(&format!("c1,oadev,{},", f[0])))
            .unwrap_or_else(|| panic!("m {}: {out}", f[0]));
        let got: f64 = line.split(',').nth(4).unwrap().parse().unwrap();
        // Printed to five significant digits: within half the last one.
        let ulp = 10f64.powi(want.abs().log10().floor() as i32 - 4);
        assert!(
            (got - want).abs() <= 0.5 * ulp * (1.0 + 1e-9),
            "m {}: {got} against {want}",
            f[0]
        );
        assert_eq!(line.split(',').nth(6), Some(f[2]), "m {}", f[0]);
        checked += 1;
    }
    assert_eq!(checked, 8);
}

/// A robot log's topic by name: `--topic` reads its three axes, or the
/// axes `-c` names; a topic the log does not have lists the ones it has.
#[test]
fn a_robot_logs_topic_is_read_by_name() {
    let v = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/vectors");
    for (log, topic) in [
        ("ros2/imu_bag", "/imu/data"),
        ("ros2/imu_bag_db3", "/imu/data"),
        ("dataflash/test.BIN", "IMU.1"),
    ] {
        let o = gyro()
            .args([
                "allan", "--format", "csv", "--gaps", "join", "--topic", topic,
            ])
            .arg(format!("{v}/{log}"))
            .output()
            .unwrap();
        let out = String::from_utf8_lossy(&o.stdout);
        assert!(
            o.status.success(),
            "{log}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        for a in ["x", "y", "z"] {
            assert!(
                out.lines()
                    .any(|l| l.starts_with(&format!("{topic}.{a},oadev,1,"))),
                "{log} {a}: {out}"
            );
        }
        let o = gyro()
            .args([
                "allan", "--format", "csv", "--gaps", "join", "--topic", topic, "-c", "z",
            ])
            .arg(format!("{v}/{log}"))
            .output()
            .unwrap();
        let out = String::from_utf8_lossy(&o.stdout);
        assert!(
            out.lines().all(|l| !l.starts_with(&format!("{topic}.x,"))),
            "{out}"
        );
        assert!(
            out.lines()
                .any(|l| l.starts_with(&format!("{topic}.z,oadev,1,"))),
            "{out}"
        );
    }
    let (code, err) = fails(
        &["allan", "--topic", "/no/such"],
        std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/vectors/ros2/imu_bag"
        )),
    );
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("/imu/data.x"), "{err}");
}

/// A `.npy` file of f64 as NumPy writes it (version 1.0, header padded to a
/// multiple of 64 bytes).
fn npy(name: &str, values: &[f64]) -> std::path::PathBuf {
    let mut h = format!(
        "{{'descr': '<f8', 'fortran_order': False, 'shape': ({},), }}",
        values.len()
    );
    while !(10 + h.len() + 1).is_multiple_of(64) {
        h.push(' ');
    }
    h.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend_from_slice(&(h.len() as u16).to_le_bytes());
    bytes.extend_from_slice(h.as_bytes());
    for v in values {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    let dir = std::env::temp_dir().join(format!("gyro-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

/// The CSV rows (deviation, m, value, alpha, edf) of `gyro allan`.
fn allan_rows(args: &[&str]) -> Vec<(String, usize, f64, String, String)> {
    let o = gyro().arg("allan").args(args).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{args:?}: {err}");
    String::from_utf8_lossy(&o.stdout)
        .lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (
                f[1].to_string(),
                f[2].parse().unwrap(),
                f[4].parse().unwrap(),
                f[7].to_string(),
                f[9].to_string(),
            )
        })
        .collect()
}

#[test]
fn a_long_log_streams_to_the_same_curves() {
    // 300 000 samples with a 1 MiB ring (131 072 points a column): most
    // lags of the longer factors come back from the spill file.
    let text = noise(300_000);
    let values: Vec<f64> = text.lines().skip(1).map(|l| l.parse().unwrap()).collect();
    let txt = temp("long.csv", &text);
    let bin = npy("long.npy", &values);
    let common = [
        "--tau0",
        "0.01",
        "--dev",
        "oadev,mdev,hdev,tierms",
        "--format",
        "csv",
    ];
    let whole = allan_rows(&[&[txt.to_str().unwrap()], &common[..]].concat());
    for (file, extra) in [(&txt, &["--stream"][..]), (&bin, &[][..])] {
        let mut args = vec![file.to_str().unwrap(), "--memory", "1"];
        args.extend_from_slice(&common);
        args.extend_from_slice(extra);
        let streamed = allan_rows(&args);
        assert_eq!(streamed.len(), whole.len(), "{args:?}");
        for (s, w) in streamed.iter().zip(&whole) {
            assert_eq!((&s.0, s.1, &s.3, &s.4), (&w.0, w.1, &w.3, &w.4), "{args:?}");
            assert!((s.2 / w.2 - 1.0).abs() < 1e-12, "{args:?} {s:?} {w:?}");
        }
    }
}

#[test]
fn a_streamed_log_refuses_what_it_cannot_do_by_name() {
    let mut values = vec![0.5; 1000];
    values[700] = f64::NAN;
    let bad = npy("nan.npy", &values);
    let (code, err) = fails(&["allan", "--tau0", "1"], &bad);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("sample 700 (row 701) is not finite"), "{err}");
    let p = temp("gap.csv", "t,z\n0,1\n1,2\n2,1\n5,2\n6,1\n7,2\n");
    let (code, err) = fails(&["allan", "--stream", "--time", "t"], &p);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains(":5: gap of 3 s") && err.contains("--gaps join"),
        "{err}"
    );
    for (args, says) in [
        (
            &["allan", "--stream", "--tau0", "1", "--dev", "totdev"][..],
            "TOTDEV is not computed in one pass",
        ),
        (
            &["allan", "--stream", "--tau0", "1", "--grid", "all"][..],
            "--grid all",
        ),
        (
            &["allan", "--stream", "--tau0", "1", "--static"][..],
            "--static",
        ),
        (
            &["allan", "--stream", "--tau0", "1", "--memory", "0"][..],
            "--memory: 0 MiB of memory over 2 columns",
        ),
    ] {
        let (code, err) = fails(args, &p);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(err.contains(says), "{args:?}: {err}");
    }
}

/// `gyro lag` on a recording whose rates are 120 µs older than the
/// instants they state, against the table's rate: the lag on every axis,
/// and the trim to set is the one the status frame states plus it. Frames
/// the board predicted are left out and counted; a reference that does not
/// move is said, not fitted.
#[test]
fn lag_reads_the_paths_delay_against_a_rate_table() {
    use gyro_array::link::msg::{Frame, Sample, Status};
    use gyro_array::link::wire::encode;
    let table = |t_us: f64, a: usize| {
        let w = 2.0 * std::f64::consts::PI * [2.0, 3.0, 1.5][a];
        [60.0, -40.0, 90.0][a] * (w * t_us * 1e-6).sin()
    };
    let (age, lag) = (1670.0, 120.0);
    let mut rec = Vec::new();
    let mut buf = [0u8; gyro_array::link::wire::MAX_FRAME];
    let mut status = Status::widest(5);
    status.settings.path_trim_us = 30;
    let n = encode(0, &Frame::Status(status), &mut buf).unwrap();
    rec.extend_from_slice(&buf[..n]);
    let mut truth = String::from("t_us,x_dps,y_dps,z_dps\n");
    for k in 0..4000u32 {
        let t = 10_000.0 + f64::from(k) * 1000.0;
        let stated = t - age;
        let frame = Frame::Sample(Sample {
            seq: k,
            t_us: t as u64,
            age_us: [age as u16; 3],
            predicted_us: (k % 10 == 0).then_some(500),
            rate_dps: core::array::from_fn(|a| {
                (1.002 * table(stated - lag, a) + 0.3 + 0.01 * f64::from(k % 7)) as f32
            }),
            valid: 0b111,
            degraded: 0,
            used: [0b1111; 3],
            health: Default::default(),
            noise: None,
            angle: None,
        });
        let n = encode(k + 1, &frame, &mut buf).unwrap();
        rec.extend_from_slice(&buf[..n]);
    }
    for k in 0..50_000u32 {
        let t = f64::from(k) * 100.0;
        truth.push_str(&format!(
            "{t},{},{},{}\n",
            table(t, 0),
            table(t, 1),
            table(t, 2)
        ));
    }
    let file = temp("lag.glk", "");
    std::fs::write(&file, &rec).unwrap();
    let csv = temp("lag_truth.csv", &truth);
    let (out, _) = succeeds(&["lag", "--truth", csv.to_str().unwrap()], &file);
    assert!(
        out.contains("400 frames predicted by the board left out"),
        "{out}"
    );
    assert!(out.contains("the path trim in force 30 µs"), "{out}");
    for a in ["x", "y", "z"] {
        let line = out
            .lines()
            .find(|l| l.starts_with(&format!("{a} ")))
            .unwrap_or_else(|| panic!("{out}"));
        let got: f64 = line.split_whitespace().nth(1).unwrap().parse().unwrap();
        assert!((got - lag).abs() < 2.0, "{line}");
    }
    assert!(out.contains("--send path-trim=150"), "{out}");
    // A table at rest: no lag can be read.
    let still = temp(
        "still.csv",
        &(0..50_000)
            .map(|k| format!("{},0.5,0.5,0.5\n", k * 100))
            .fold(String::from("t_us,x,y,z\n"), |s, l| s + &l),
    );
    let o = gyro()
        .args(["lag", "--truth", still.to_str().unwrap()])
        .arg(&file)
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(1), "{out}");
    assert!(out.contains("no axis moved enough"), "{out}");
    // A reference with a rate that is no number: refused with its line.
    let bad = temp("bad_truth.csv", &truth.replacen(",0,", ",inf,", 1));
    let (code, err) = fails(&["lag", "--truth", bad.to_str().unwrap()], &file);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains(":2: a rate that is not a number"), "{err}");
    // A recording without sample frames: said, not fitted.
    let empty = temp("status_only.glk", "");
    std::fs::write(
        &empty,
        &rec[..rec.iter().position(|&b| b == 0).unwrap() + 1],
    )
    .unwrap();
    let o = gyro()
        .args(["lag", "--truth", csv.to_str().unwrap()])
        .arg(&empty)
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(1), "{out}");
    assert!(
        out.contains("0 sample frames") && out.contains("no axis moved enough"),
        "{out}"
    );
}

/// TheoBR on a log too short for its bias ratio, beside another deviation:
/// the others computed, TheoBR's table saying why it is empty (the ratio
/// failed the whole command before).
#[test]
fn theobr_on_a_short_log_says_why_it_has_no_value() {
    let file = temp("five.txt", "z\n1\n2\n3\n4\n5\n");
    let (out, _) = succeeds(
        &["allan", "--tau0", "1", "--dev", "theobr,theoh,oadev"],
        &file,
    );
    assert!(
        out.contains(
            "no tau with a value: too few samples (TheoBR's bias ratio needs 90 phase points)"
        ),
        "{out}"
    );
    assert!(
        out.contains("OADEV") && out.contains("7.071068e-1"),
        "{out}"
    );
}
