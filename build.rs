//! Link set-up for the firmware binaries. The host library needs none of it.
fn main() {
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    build_id();
    let target = std::env::var("TARGET").unwrap_or_default();
    if !target.starts_with("thumb") {
        return;
    }
    if std::env::var_os("CARGO_FEATURE_BOARD").is_some() {
        println!("cargo:rustc-link-arg-bins=--nmagic");
        println!("cargo:rustc-link-arg-bins=-Tlink.x");
        println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    }
}

/// The commit the firmware is built from, for the link's board-information
/// frame: `GYRO_BUILD`, the commit's first 32 bits as hex (absent outside a
/// git checkout; the frame then says 0). Built again when HEAD moves.
fn build_id() {
    let git = |args: &[&str]| {
        std::process::Command::new("git")
            .args(args)
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    let Some(hash) = git(&["rev-parse", "HEAD"]) else {
        return;
    };
    // (Only files that exist: cargo runs a script again every build for
    // one that does not, and a fresh clone keeps its refs packed.)
    if let Some(dir) = git(&["rev-parse", "--git-dir"]) {
        let mut watch = vec![format!("{dir}/HEAD"), format!("{dir}/packed-refs")];
        if let Some(r) = git(&["symbolic-ref", "-q", "HEAD"]) {
            watch.push(format!("{dir}/{r}"));
        }
        for w in watch.iter().filter(|w| std::path::Path::new(w).exists()) {
            println!("cargo:rerun-if-changed={w}");
        }
    }
    if let Some(head) = hash.get(..8) {
        println!("cargo:rustc-env=GYRO_BUILD={head}");
    }
}
