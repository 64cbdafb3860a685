//! `pointing-eval` end to end on a short run (8 s per profile): it exits
//! 0, its model agrees with the closed forms to 1 %, and with the
//! compensation it picks, on every profile with faults, the board adds
//! at most 0.05° (p99.9), the delay's share falls at least 4× on the city
//! and highway profiles and the noise's grows at most 1.5×. The full run
//! (20 s per profile) is documented in docs/pointing.md.

use std::process::Command;

fn number_after(line: &str, key: &str) -> f64 {
    let rest = line
        .split(key)
        .nth(1)
        .unwrap_or_else(|| panic!("{key:?} in {line}"));
    let v: String = rest
        .trim_start()
        .chars()
        .take_while(|c| c.is_ascii_digit() || *c == '.')
        .collect();
    v.parse()
        .unwrap_or_else(|_| panic!("a number after {key:?} in {line}"))
}

#[test]
fn pointing_eval_runs_and_meets_its_targets_on_a_short_run() {
    let out = Command::new(env!("CARGO_BIN_EXE_pointing-eval"))
        .args(["--seconds", "8", "--realisations", "1"])
        .output()
        .expect("run pointing-eval");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let model = text
        .lines()
        .find(|l| l.starts_with("model against closed form"))
        .expect("the model's check");
    assert!(number_after(model, "rate step ") < 1.0, "{model}");
    assert!(
        number_after(model, "with and without the lead) ") < 1.0,
        "{model}"
    );
    let chosen: Vec<&str> = text
        .lines()
        .skip_while(|l| !l.starts_with("the least: "))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .collect();
    assert_eq!(chosen.len(), 5, "five profiles:\n{text}");
    for l in chosen {
        let adds = number_after(l, "fault-free, ");
        assert!(adds <= 0.05, "{l}");
        let noise = number_after(l, "noise share ×");
        let moving = l.trim_start().starts_with("city") || l.trim_start().starts_with("highway");
        if moving {
            assert!(number_after(l, "(÷") >= 4.0, "{l}");
            assert!(noise <= 1.5, "{l}");
        }
    }
}
