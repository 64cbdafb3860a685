//! Link set-up for the firmware binaries. The host library needs none of it.
fn main() {
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    let target = std::env::var("TARGET").unwrap_or_default();
    if !target.starts_with("thumb") {
        return;
    }
    let qemu = std::env::var_os("CARGO_FEATURE_QEMU").is_some();
    let board = std::env::var_os("CARGO_FEATURE_BOARD").is_some();
    if qemu || board {
        println!("cargo:rustc-link-arg-bins=--nmagic");
        println!("cargo:rustc-link-arg-bins=-Tlink.x");
        println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    }
    if qemu {
        // memory.x reads this symbol to place FLASH at 0x0 on mps2-an386.
        println!("cargo:rustc-link-arg-bins=--defsym=__qemu_layout=1");
        // The interrupt handlers' defaults (src/board/an386.rs), as the
        // `device.x` cortex-m-rt's link.x includes.
        println!("cargo:rerun-if-changed=src/board/an386.x");
        let out = std::path::PathBuf::from(std::env::var_os("OUT_DIR").unwrap_or_default());
        if std::fs::copy("src/board/an386.x", out.join("device.x")).is_ok() {
            println!("cargo:rustc-link-search={}", out.display());
        }
    }
}
