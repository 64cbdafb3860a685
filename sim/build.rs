//! Link set-up for the QEMU binaries (mps2-an386). The host library needs
//! none of it.
fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=../memory.x");
    println!("cargo:rerun-if-changed=src/qemu/an386.x");
    let target = std::env::var("TARGET").unwrap_or_default();
    if !target.starts_with("thumb") || std::env::var_os("CARGO_FEATURE_QEMU").is_none() {
        return;
    }
    println!("cargo:rustc-link-arg-bins=--nmagic");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    // memory.x (the repository's one, for the board and QEMU) reads this
    // symbol to place FLASH at 0x0 on mps2-an386.
    println!("cargo:rustc-link-arg-bins=--defsym=__qemu_layout=1");
    // memory.x, and the interrupt handlers' defaults (src/qemu/an386.rs)
    // as the `device.x` cortex-m-rt's link.x includes, where the linker
    // (and flip-link) look.
    let out = std::path::PathBuf::from(std::env::var_os("OUT_DIR").unwrap_or_default());
    let copied = std::fs::copy("../memory.x", out.join("memory.x")).is_ok()
        && std::fs::copy("src/qemu/an386.x", out.join("device.x")).is_ok();
    if copied {
        println!("cargo:rustc-link-search={}", out.display());
    }
}
