//! Host speed: overlapping ADEV at octave τ over 10⁷ rate samples, ours
//! (f64 batch path, `gyro_array::algo::allan`) against allantools on the
//! same data, in one run; prints both times and the ratio.
//!
//! `cargo run -p evaluations --profile host --bin allan-speed`
//!
//! allantools is installed on first use into `target/allan-venv` (PyPI);
//! this benchmark is the only thing that needs Python, and CI does not run
//! it. Each side is timed on its best of 3 runs, from data in memory to
//! the finished curve; both curves are compared to 1e-9.

use std::path::Path;
use std::process::Command;
use std::time::Instant;

#[cfg(target_arch = "x86_64")]
use gyro_array::algo::allan::second_diff_sums_avx2;
use gyro_array::algo::allan::{
    fill_phase, oavar_octave, second_diff_sums, AdevPoint, OctaveSums, GROUP,
};
use gyro_sim::Rng;

const N: usize = 10_000_000;

fn ours(rate: &[f64], phase: &mut [f64], out: &mut [AdevPoint]) -> usize {
    oavar_octave(rate, 1.0, phase, out).expect("finite data")
}

/// The same sweep with the term range split between two threads.
fn ours_2threads(rate: &[f64], phase: &mut [f64], out: &mut [AdevPoint]) -> usize {
    fill_phase(rate, phase).expect("finite data");
    let phase = &phase[..rate.len() + 1];
    let half = phase.len() / 2;
    let mut a = OctaveSums::new(phase.len());
    let mut b = OctaveSums::new(phase.len());
    std::thread::scope(|s| {
        s.spawn(|| a.add_range(phase, 0, half));
        b.add_range(phase, half, phase.len());
    });
    a.merge(&b);
    a.finish(1.0, out)
}

fn avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    return gyro_array::algo::allan::has_avx2_fma();
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// The sums of factors m0, m0 + 1, … (`sums.len()`, at most `GROUP`)
/// through the library's grouped kernel, in its AVX2 + FMA build where the
/// CPU has both (the same bits as the plain build: `allan::tests`).
fn grouped(phase: &[f64], m0: usize, sums: &mut [f64]) {
    #[cfg(target_arch = "x86_64")]
    if avx2() {
        // SAFETY: the CPU has AVX2 and FMA (checked), the build's only
        // requirements.
        return unsafe { second_diff_sums_avx2(phase, m0, sums) };
    }
    second_diff_sums(phase, m0, sums)
}

/// Every τ of `rate` (m = 1 … (N − 1)/2), on `threads` threads taking
/// groups of `GROUP` consecutive factors in turn, through the grouped
/// kernel as `gyro allan` and the Python package run them.
fn ours_all(rate: &[f64], threads: usize) -> Vec<AdevPoint> {
    let mut phase = vec![0.0; rate.len() + 1];
    fill_phase(rate, &mut phase).expect("finite data");
    let max_m = rate.len().saturating_sub(1) / 2;
    let n = rate.len() as u64;
    let mut parts: Vec<Vec<AdevPoint>> = Vec::new();
    std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads)
            .map(|t| {
                let phase = &phase;
                s.spawn(move || {
                    let mut out = Vec::new();
                    let mut sums = [0.0; GROUP];
                    for m0 in (1 + t * GROUP..=max_m).step_by(threads * GROUP) {
                        let g = GROUP.min(max_m - m0 + 1);
                        grouped(phase, m0, &mut sums[..g]);
                        for (j, s) in sums[..g].iter().enumerate() {
                            let m = m0 + j;
                            let terms = (phase.len() - 2 * m) as u64;
                            out.push(AdevPoint::from_sum(m, 1.0, *s, terms, n));
                        }
                    }
                    out
                })
            })
            .collect();
        parts = handles
            .into_iter()
            .map(|h| h.join().expect("thread"))
            .collect();
    });
    let mut all: Vec<AdevPoint> = parts.into_iter().flatten().collect();
    all.sort_by_key(|p| p.m);
    all
}

/// Run a timing script of allantools on `data`: its time (first line) and
/// its (m, deviation) lines.
fn allantools(py: &Path, script: &str, data: &Path) -> (f64, Vec<(u32, f64)>) {
    let out = Command::new(py)
        .args(["-c", script])
        .arg(data)
        .output()
        .expect("run python");
    if !out.status.success() {
        eprintln!("{}", String::from_utf8_lossy(&out.stderr));
        std::process::exit(1);
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let mut lines = text.lines();
    let time: f64 = lines
        .next()
        .and_then(|l| l.trim().parse().ok())
        .expect("time");
    let devs = lines
        .filter_map(|l| {
            let mut it = l.split_whitespace();
            Some((it.next()?.parse().ok()?, it.next()?.parse().ok()?))
        })
        .collect();
    (time, devs)
}

/// The worst relative difference of `curve` (sorted by m) from
/// allantools' points with the same m, and how many were compared.
fn agreement(curve: &[AdevPoint], theirs: &[(u32, f64)]) -> (f64, usize) {
    let (mut worst, mut compared) = (0.0f64, 0);
    for &(m, d) in theirs {
        // (Both curves are sorted by m.)
        if let Ok(i) = curve.binary_search_by_key(&m, |p| p.m) {
            let p = &curve[i];
            worst = worst.max((p.adev() - d).abs() / d);
            compared += 1;
        }
    }
    (worst, compared)
}

const PY_ALL: &str = r#"
import sys, time, numpy as np, allantools
y = np.fromfile(sys.argv[1], dtype='<f8')
t0 = time.perf_counter()
taus, dev, err, n = allantools.oadev(y, rate=1.0, data_type='freq', taus='all')
print(time.perf_counter() - t0)
for t, d in zip(taus, dev):
    print(int(round(t)), repr(float(d)))
"#;

const PY: &str = r#"
import sys, time, numpy as np, allantools
y = np.fromfile(sys.argv[1], dtype='<f8')
best = 1e9
for _ in range(3):
    t0 = time.perf_counter()
    taus, dev, err, n = allantools.oadev(y, rate=1.0, data_type='freq', taus='octave')
    best = min(best, time.perf_counter() - t0)
print(best)
for t, d in zip(taus, dev):
    print(int(t), repr(float(d)))
"#;

fn main() {
    gyro_tool::pipe::quiet_on_closed_pipe();
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let target = root.join("target");
    let venv = target.join("allan-venv");
    let py = venv.join("bin/python3");
    if !py.exists() {
        eprintln!("allan-speed: installing allantools into {}", venv.display());
        let ok = Command::new("python3")
            .args(["-m", "venv"])
            .arg(&venv)
            .status()
            .is_ok_and(|s| s.success())
            && Command::new(&py)
                .args([
                    "-m",
                    "pip",
                    "install",
                    "-q",
                    "allantools==2024.6",
                    "numpy",
                    "scipy",
                ])
                .status()
                .is_ok_and(|s| s.success());
        if !ok {
            eprintln!("allan-speed: cannot install allantools (needs python3-venv and PyPI)");
            std::process::exit(1);
        }
    }

    // White + random-walk rate noise around a 95 °/s bias.
    let mut rng = Rng::new(11);
    let mut rw = 0.0f64;
    let rate: Vec<f64> = (0..N)
        .map(|_| {
            rw += 1e-4 * rng.gaussian() as f64;
            95.0 + 0.1 * rng.gaussian() as f64 + rw
        })
        .collect();
    let data = target.join("allan-speed.f64");
    let bytes: Vec<u8> = rate.iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(&data, bytes).expect("write data");

    let mut phase = vec![0.0; N + 1];
    let mut out = [AdevPoint::default(); 64];
    let mut best = f64::MAX;
    let mut best2 = f64::MAX;
    let mut out2 = [AdevPoint::default(); 64];
    let mut count = 0;
    for _ in 0..3 {
        let t0 = Instant::now();
        count = ours(&rate, &mut phase, &mut out);
        best = best.min(t0.elapsed().as_secs_f64());
        let t0 = Instant::now();
        let c2 = ours_2threads(&rate, &mut phase, &mut out2);
        best2 = best2.min(t0.elapsed().as_secs_f64());
        assert_eq!(c2, count);
    }
    let curve = &out[..count];
    let split_diff = curve
        .iter()
        .zip(&out2)
        .map(|(a, b)| ((a.avar - b.avar) / a.avar).abs())
        .fold(0.0, f64::max);

    let (theirs, ref_devs) = allantools(&py, PY, &data);
    let (worst, compared) = agreement(curve, &ref_devs);
    println!(
        "OADEV, octave tau, {N} samples ({} tau), best of 3, same run:\n  \
         allantools {theirs:.3} s\n  ours, 1 thread  {best:.3} s: {:.1}x faster\n  \
         ours, 2 threads {best2:.3} s: {:.1}x faster\n  \
         curves agree with allantools to {worst:.1e} (relative, {compared} tau); \
         split sums agree to {split_diff:.1e}",
        curve.len(),
        theirs / best,
        theirs / best2,
    );
    let _ = std::fs::remove_file(&data);
    if worst > 1e-9 || compared != curve.len() {
        std::process::exit(1);
    }

    // Every τ of 10⁵ samples: allantools' taus='all' against ours.
    const N_ALL: usize = 100_000;
    let small = &rate[..N_ALL];
    let bytes: Vec<u8> = small.iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(&data, bytes).expect("write data");
    let (mut one, mut two) = (f64::MAX, f64::MAX);
    let mut curve = Vec::new();
    for _ in 0..2 {
        let t0 = Instant::now();
        curve = ours_all(small, 1);
        one = one.min(t0.elapsed().as_secs_f64());
        let t0 = Instant::now();
        let c2 = ours_all(small, 2);
        two = two.min(t0.elapsed().as_secs_f64());
        assert_eq!(c2.len(), curve.len());
    }
    let (theirs, ref_devs) = allantools(&py, PY_ALL, &data);
    let _ = std::fs::remove_file(&data);
    let (worst, compared) = agreement(&curve, &ref_devs);
    println!(
        "OADEV, every tau, {N_ALL} samples ({} tau, AVX2 build: {}), same run:\n  \
         allantools {theirs:.3} s\n  ours, 1 thread  {one:.3} s: {:.1}x faster\n  \
         ours, 2 threads {two:.3} s: {:.1}x faster\n  \
         curves agree with allantools to {worst:.1e} (relative, {compared} tau)",
        curve.len(),
        if avx2() { "yes" } else { "no" },
        theirs / one,
        theirs / two,
    );
    if worst > 1e-9 || compared != curve.len() {
        std::process::exit(1);
    }
}
