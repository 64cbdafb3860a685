//! `link-timing` end to end on a short run (1 100 samples: a status frame
//! at 0 and 1 000, an info frame at 500, the controller's commands): it
//! exits 0 (at 6 Mbaud no sample frame waits behind another, the frames
//! as encoded and at their widest), and it prints every frame kind at both
//! baud rates.

use std::process::Command;

#[test]
fn link_timing_runs_and_every_sample_frame_leaves_when_queued() {
    let out = Command::new(env!("CARGO_BIN_EXE_link-timing"))
        .args(["--samples", "1100"])
        .output()
        .expect("run link-timing");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    for kind in ["sample", "status", "info", "acknowledgement or sync"] {
        let at = |rate: &str| {
            text.split(rate)
                .nth(1)
                .is_some_and(|t| t.contains(&format!("  {kind} frames: ")))
        };
        assert!(
            at("6000000 baud") && at("2000000 baud"),
            "{kind} at both rates:\n{text}"
        );
    }
    let board: Vec<_> = text
        .lines()
        .filter(|l| l.contains("at worst") && l.contains("behind a frame"))
        .take(2)
        .collect();
    assert_eq!(board.len(), 2, "{text}");
    for l in board {
        assert!(l.contains("at worst 0 µs behind"), "{l}");
    }
}
