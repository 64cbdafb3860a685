//! `nav-eval` end to end on a short run (2 runs × 300 epochs per scenario):
//! it exits 0, writes its picture, prints every scenario's table and its
//! last line, and on these few epochs "ours" is still the centralized
//! filter with correct noise models (within 2 %). The full run (50 × 5000,
//! 7.5 min) is documented, not run here.

use std::process::Command;

#[test]
fn nav_eval_runs_and_prints_its_ratios() {
    let svg = std::env::temp_dir().join(format!("nav-eval-smoke-{}.svg", std::process::id()));
    let out = Command::new(env!("CARGO_BIN_EXE_nav-eval"))
        .args(["--runs", "2", "--epochs", "300", "--svg"])
        .arg(&svg)
        .output()
        .expect("run nav-eval");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert_eq!(
        text.matches("  centralized ").count(),
        6,
        "six scenarios:\n{text}"
    );
    let last = text.lines().last().expect("a last line");
    assert!(
        last.starts_with("seed-001 ratio entropy/weighted: normal "),
        "{last}"
    );
    let nominal: f64 = last
        .split("ours/centralized nominal ")
        .nth(1)
        .and_then(|r| r.split(';').next())
        .and_then(|v| v.trim().parse().ok())
        .expect("ours/centralized nominal");
    assert!((nominal - 1.0).abs() < 0.02, "{last}");
    let picture = std::fs::read_to_string(&svg).expect("the picture");
    assert!(picture.contains("<svg") && picture.contains("ours"));
    let _ = std::fs::remove_file(&svg);
}
