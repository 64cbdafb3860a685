//! The self-check suite that also runs inside QEMU (`qemu-tests`), run here
//! on the host. Golden digests live in `vectors/digests.in`; with
//! `UPDATE_SNAPSHOTS=1` this test rewrites them after a deliberate change.
use gyro_sim::checks;

#[test]
fn host_runs_the_on_target_suite() {
    let fusion = checks::fusion_digest();
    let pipeline = checks::pipeline_digest();
    let allan = checks::allan_digest();
    let qualify = checks::qualify_digest();
    if std::env::var_os("UPDATE_SNAPSHOTS").is_some() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/vectors/digests.in");
        let text = std::fs::read_to_string(path).unwrap();
        let mut out = String::new();
        for line in text.lines() {
            if line.starts_with("pub const FUSION") {
                out += &format!("pub const FUSION: u64 = {fusion:#018x};\n");
            } else if line.starts_with("pub const PIPELINE") {
                out += &format!("pub const PIPELINE: u64 = {pipeline:#018x};\n");
            } else if line.starts_with("pub const ALLAN") {
                out += &format!("pub const ALLAN: u64 = {allan:#018x};\n");
            } else if line.starts_with("pub const QUALIFY") {
                out += &format!("pub const QUALIFY: u64 = {qualify:#018x};\n");
            } else {
                out += line;
                out += "\n";
            }
        }
        std::fs::write(path, out).unwrap();
        println!("rewrote {path}; rebuild to check");
        return;
    }
    let mut failed = Vec::new();
    let (pass, fail) = checks::run_all(&mut |name, ok| {
        println!("{} {name}", if ok { "ok  " } else { "FAIL" });
        if !ok {
            failed.push(name.to_string());
        }
    });
    println!(
        "fusion digest {fusion:#018x}, pipeline digest {pipeline:#018x}, allan digest {allan:#018x}"
    );
    assert_eq!(fail, 0, "failed: {failed:?}");
    assert!(pass >= 13);
}
