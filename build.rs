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
    }
}
