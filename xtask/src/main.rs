//! Task runner: `cargo xtask <task>`.
//!
//! - `test`: host tests, then the on-target suite, the demo and the
//!   fault-containment run in QEMU (each passes or fails by its semihosting
//!   exit code), then the board firmware build, then the Python package's
//!   tests (`python`). This is the project's one test command.
//! - `run`: the demo firmware in QEMU, logs decoded by defmt-print.
//! - `python`: build the Python package (`python/`) into a fresh virtual
//!   environment and run its tests against allantools.
//! - `bench`: instruction counts on the Cortex-M4 (QEMU `-icount`); the
//!   board's loop also counted exactly from QEMU's execution trace.
//! - `bench-loop`: that exact count alone (some 40 minutes for the twelve
//!   scenarios; `BENCH_SCENARIOS=KL` counts only those named,
//!   `BENCH_SAMPLES=700` each scenario's first 700 samples, and
//!   `XTASK_TRACE_LINES=1` adds the mean sample by source line;
//!   `XTASK_TRACE_PHASE=0|1|2` breaks down one phase, `all` the whole loop). Each
//!   scenario's whole loop and its frame's path (read + fuse, the frame;
//!   the E-DAVARs run once the frame is out).
//! - `size`: flash and static RAM of the firmware binaries.
//! - `panics`: panic call sites in each release ELF, by the code they come
//!   from (llvm-objdump and llvm-addr2line).
//! - `fuzz [SECONDS]`: replay the committed regression inputs, then run
//!   every cargo-fuzz target for SECONDS (10 by default; CI uses that).
//!
//! Missing tools are installed: the rustup target, qemu-system-arm (apt),
//! defmt-print and flip-link (cargo, pinned).
use std::path::{Path, PathBuf};
use std::process::{exit, Command, Stdio};

mod trace;

const TARGET: &str = "thumbv7em-none-eabihf";
const DEFMT_PRINT: &str = "1.2.0";
/// The firmware links through flip-link (.cargo/config.toml).
const FLIP_LINK: &str = "0.1.12";

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

fn run(cmd: &mut Command) -> bool {
    eprintln!("xtask: {cmd:?}");
    cmd.current_dir(root())
        .status()
        .map(|s| s.success())
        .unwrap_or(false)
}

fn must(ok: bool, what: &str) {
    if !ok {
        eprintln!("xtask: FAILED: {what}");
        exit(1);
    }
}

fn have(tool: &str, arg: &str) -> Option<String> {
    let out = Command::new(tool).arg(arg).output().ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).into_owned())
}

/// Install a Debian package (through sudo when not root), or stop.
fn apt_install(package: &str, what: &str) {
    let sudo = if have("id", "-u").is_some_and(|u| u.trim() != "0") {
        "sudo "
    } else {
        ""
    };
    must(
        run(Command::new("sh").arg("-c").arg(format!(
            "{sudo}apt-get update -qq && {sudo}env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq {package}"
        ))),
        what,
    );
}

fn ensure_tools() {
    must(
        run(Command::new("rustup").args(["target", "add", TARGET])),
        "rustup target add",
    );
    if have("qemu-system-arm", "--version").is_none() {
        apt_install("qemu-system-arm", "install qemu-system-arm");
    }
    // llvm-objdump and llvm-addr2line: the panic-site check.
    if have("llvm-objdump", "--version").is_none() || have("llvm-addr2line", "--version").is_none()
    {
        apt_install("llvm", "install llvm (llvm-objdump, llvm-addr2line)");
    }
    // flip-link has no --version: ask cargo what it installed.
    let v = Command::new("cargo")
        .args(["install", "--list"])
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).into_owned())
        .unwrap_or_default();
    if !v.contains(&format!("flip-link v{FLIP_LINK}")) {
        must(
            run(Command::new("cargo")
                .args(["install", "flip-link", "--locked", "--force", "--version"])
                .arg(format!("={FLIP_LINK}"))),
            "install flip-link",
        );
    }
    let v = have("defmt-print", "--version").unwrap_or_default();
    if !v.contains(DEFMT_PRINT) {
        must(
            run(Command::new("cargo")
                .args(["install", "defmt-print", "--locked", "--force", "--version"])
                .arg(format!("={DEFMT_PRINT}"))),
            "install defmt-print",
        );
    }
}

/// Build one firmware binary for the Cortex-M4 with `feature`; its ELF
/// path. The board's binary is the firmware crate's; the QEMU ones are
/// `gyro-sim`'s (they run the firmware against the emulated chips).
fn build_firmware(feature: &str, bin: &str) -> PathBuf {
    let package = if bin.starts_with("qemu-") {
        "gyro-sim"
    } else {
        "gyro-array"
    };
    must(
        run(Command::new("cargo").args([
            "build",
            "--release",
            "--target",
            TARGET,
            "-p",
            package,
            "--features",
            feature,
            "--bin",
            bin,
        ])),
        &format!("build {bin}"),
    );
    root().join("target").join(TARGET).join("release").join(bin)
}

fn build_qemu(bin: &str) -> PathBuf {
    build_firmware("qemu", bin)
}

/// Run a firmware image in QEMU and decode its defmt stream to stdout; true
/// when QEMU's semihosting exit code and defmt-print both report success.
fn qemu(elf: &Path, icount: bool) -> bool {
    qemu_with(elf, icount, &[]).0
}

/// [`qemu`] with extra QEMU arguments; also returns the decoded log.
fn qemu_with(elf: &Path, icount: bool, extra: &[&str]) -> (bool, String) {
    // A firmware that hangs (a fault loop, a stack overflow) must fail
    // the run, not stall CI: coreutils' `timeout` kills QEMU after 300 s.
    let mut q = qemu_command(elf, icount, 300, extra);
    eprintln!("xtask: {q:?} | defmt-print -e {}", elf.display());
    let mut child = q.spawn().unwrap_or_else(|e| {
        eprintln!("xtask: cannot start qemu: {e}");
        exit(1)
    });
    let stdout = child.stdout.take().unwrap();
    let decoded = defmt_print(elf, stdout).unwrap_or_else(|e| {
        eprintln!("xtask: cannot start defmt-print: {e}");
        exit(1)
    });
    let q_ok = child.wait().map(|s| s.success()).unwrap_or(false);
    let text = String::from_utf8_lossy(&decoded.stdout).into_owned();
    print!("{text}");
    (q_ok && decoded.status.success(), text)
}

/// QEMU's Cortex-M4 board (mps2-an386) running `elf` with semihosting,
/// killed by coreutils' `timeout` after `secs`, with `extra` arguments; its
/// stdout (the defmt stream) piped.
fn qemu_command(elf: &Path, icount: bool, secs: u32, extra: &[&str]) -> Command {
    let mut q = Command::new("timeout");
    q.arg(secs.to_string()).arg("qemu-system-arm");
    q.args([
        "-cpu",
        "cortex-m4",
        "-machine",
        "mps2-an386",
        "-nographic",
        "-monitor",
        "none",
    ]);
    q.args(["-semihosting-config", "enable=on,target=native"]);
    if icount {
        // One instruction per ns of virtual time; idle time (WFI) is
        // skipped, not slept through in real time.
        q.args(["-icount", "shift=0,sleep=off"]);
    }
    q.args(extra);
    q.arg("-kernel").arg(elf).stdout(Stdio::piped());
    q
}

/// The defmt log of `elf` in `stream` (QEMU's stdout), decoded.
fn defmt_print(
    elf: &Path,
    stream: std::process::ChildStdout,
) -> std::io::Result<std::process::Output> {
    Command::new("defmt-print")
        .arg("-e")
        .arg(elf)
        .stdin(stream)
        .stderr(Stdio::inherit())
        .output()
}

/// The host tool (`gyro-tool`), built; its path.
/// The host's run of the demo (`demo-replay`): its "N sample frames,
/// fused-rate CRC-32 0x…".
fn replay_digest(stress: bool) -> Option<String> {
    let mut c = Command::new("cargo");
    c.args([
        "run",
        "--quiet",
        "--profile",
        "host",
        "-p",
        "evaluations",
        "--bin",
        "demo-replay",
    ]);
    if stress {
        c.args(["--", "--stress"]);
    }
    let out = c.output().ok().filter(|o| o.status.success());
    let line = out.and_then(|o| {
        String::from_utf8_lossy(&o.stdout)
            .lines()
            .find_map(|l| l.strip_prefix("link: ").map(str::to_string))
    });
    if line.is_none() {
        eprintln!("xtask: demo-replay did not run or log its digest");
    }
    line
}

fn build_tool() -> PathBuf {
    must(
        run(Command::new("cargo").args(["build", "--profile", "host", "-p", "gyro-tool"])),
        "build gyro-tool",
    );
    root().join("target").join("host").join("gyro")
}

/// The demo end to end: QEMU's UART0 goes to a Unix socket, `gyro record`
/// records it (sending two commands: a status request, accepted, and a
/// divider of 0, rejected), then `gyro check` compares the recording with
/// the count and CRC-32 of fused rates the firmware logged, and
/// `gyro analyse` analyses it; the host's run of the same world through
/// the same schedule (`demo-replay`) must log the same count and CRC-32.
fn demo_end_to_end() -> bool {
    demo_run("qemu").is_some()
}

/// qemu-demo built with `features`, run end to end with its link recorded
/// and checked; its log when everything passed.
fn demo_run(features: &str) -> Option<String> {
    let elf = build_firmware(features, "qemu-demo");
    let gyro = build_tool();
    let dir = root().join("target").join("link");
    let _ = std::fs::create_dir_all(&dir);
    let sock = dir.join("qemu-demo.sock");
    let rec = dir.join("qemu-demo.glk");
    let _ = std::fs::remove_file(&sock);
    let mut recorder = match Command::new(&gyro)
        .arg("record")
        .arg("--from")
        .arg(format!("unix:{}", sock.display()))
        .arg("-o")
        .arg(&rec)
        .args(["--send", "status", "--send", "divider=0", "--quiet"])
        .spawn()
    {
        Ok(c) => c,
        Err(e) => {
            eprintln!("xtask: cannot start gyro record: {e}");
            return None;
        }
    };
    let chardev = format!("socket,id=link,path={},server=on,wait=on", sock.display());
    let (ok, log) = qemu_with(
        &elf,
        true,
        &["-chardev", &chardev, "-serial", "chardev:link"],
    );
    let rec_ok = recorder.wait().map(|s| s.success()).unwrap_or(false);
    if !(ok && rec_ok) {
        eprintln!("xtask: demo {ok}, recorder {rec_ok}");
        return None;
    }
    // "link: N sample frames, fused-rate CRC-32 0x…"
    let Some((n, crc)) = log.lines().find_map(|l| {
        let rest = l.split("link: ").nth(1)?;
        let n = rest.split_whitespace().next()?;
        let crc = rest.split("CRC-32 ").nth(1)?.split_whitespace().next()?;
        Some((n.to_string(), crc.to_string()))
    }) else {
        eprintln!("xtask: the demo did not log its sample count and CRC-32");
        return None;
    };
    let replay = replay_digest(features.contains("demo-stress"))?;
    let target = format!("{n} sample frames, fused-rate CRC-32 {crc}");
    if replay != target {
        eprintln!("xtask: the host's replay logged \"{replay}\", the demo \"{target}\"");
        return None;
    }
    println!("xtask: host replay and QEMU demo agree bit for bit: {target}");
    let ok = run(Command::new(&gyro).arg("check").arg(&rec).args([
        "--samples",
        &n,
        "--fused-crc32",
        &crc,
        "--acks",
        "ok,out-of-range",
    ])) && run(Command::new(&gyro).arg("analyse").arg(&rec))
        && run(Command::new(&gyro).arg("pointing").arg(&rec));
    ok.then_some(log)
}

/// The controller's C library (`clib/`): built as C99 and as C++ with
/// `-Wall -Wextra -Werror` under AddressSanitizer and
/// UndefinedBehaviorSanitizer, its tests run, and, where the demo left its
/// recording, that recording decoded to the same frames by kind and the
/// same CRC-32 of every sample frame's rates as the Rust decoder's
/// (`gyro check`), and its example program's CSV of the sample frames
/// equal, byte for byte, to `gyro decode`'s.
fn clib() -> bool {
    let dir = root().join("clib");
    let out = root().join("target").join("clib");
    let _ = std::fs::create_dir_all(&out);
    let sanitize = [
        "-g",
        "-fsanitize=address,undefined",
        "-fno-sanitize-recover=all",
    ];
    let builds = [
        ("gcc", vec!["-std=c99", "-pedantic"], "test_gyrolink_c"),
        (
            "g++",
            vec!["-x", "c++", "-std=c++17", "-pedantic"],
            "test_gyrolink_cpp",
        ),
    ];
    let mut bins = Vec::new();
    let mut examples = Vec::new();
    for (cc, lang, name) in builds {
        let bin = out.join(name);
        let example = out.join(format!("{name}_example"));
        let build = |main: &str, bin: &Path| {
            run(Command::new(cc)
                .args(&lang)
                .args(["-Wall", "-Wextra", "-Werror"])
                .args(sanitize)
                .arg(dir.join("gyrolink.c"))
                .arg(dir.join(main))
                .arg("-o")
                .arg(bin)
                .arg("-lm"))
        };
        let ok = build("test_gyrolink.c", &bin) && build("example_decode.c", &example);
        if !ok || !run(&mut Command::new(&bin)) {
            eprintln!("xtask: the C library's {cc} build or its tests failed");
            return false;
        }
        bins.push(bin);
        examples.push(example);
    }
    let rec = root().join("target").join("link").join("qemu-demo.glk");
    if !rec.exists() {
        println!("xtask: no demo recording to decode (run `cargo xtask run` first)");
        return true;
    }
    let lines = |o: std::io::Result<std::process::Output>| -> Vec<String> {
        o.map(|o| String::from_utf8_lossy(&o.stdout).into_owned())
            .unwrap_or_default()
            .lines()
            .filter(|l| l.starts_with("frames: ") || l.starts_with("fused-rate CRC-32: "))
            .map(str::to_string)
            .collect()
    };
    let c = lines(Command::new(&bins[0]).arg(&rec).output());
    let rust = lines(Command::new(build_tool()).arg("check").arg(&rec).output());
    println!("xtask: the demo recording, C: {c:?}; Rust: {rust:?}");
    if !(c.len() == 2 && c == rust) {
        return false;
    }
    // Every field of every sample frame, as text.
    let decode = Command::new(build_tool())
        .arg("decode")
        .arg(&rec)
        .output()
        .map(|o| o.stdout)
        .unwrap_or_default();
    for ex in &examples {
        let mine = Command::new(ex)
            .arg(&rec)
            .output()
            .map(|o| o.stdout)
            .unwrap_or_default();
        let lines = mine.iter().filter(|&&b| b == b'\n').count();
        if mine.is_empty() || mine != decode {
            eprintln!(
                "xtask: {} prints the demo's sample frames differently from `gyro decode`",
                ex.display()
            );
            return false;
        }
        println!(
            "xtask: {}: {lines} lines, byte for byte `gyro decode`'s",
            ex.display()
        );
    }
    true
}

/// The sample task's worst response (tick to frame queued, the firmware's
/// own instructions) a demo log states.
fn worst_response(log: &str) -> Option<u64> {
    let line = log
        .lines()
        .find(|l| l.contains("schedule, the firmware's own"))?;
    let rest = line.split("tick to frame queued mean ").nth(1)?;
    rest.split(" worst ")
        .nth(1)?
        .split(';')
        .next()?
        .trim()
        .parse()
        .ok()
}

/// The demo and its stress run (the background ten times slower, a status
/// frame every sample): both pass their checks (no tick during a sample,
/// no job lost, every frame sent), and the sample task's worst response
/// under stress stays within `SLACK` instructions of the plain run's.
fn demo_and_stress() -> bool {
    /// Three SysTick counts (40 instructions each): the measurement's
    /// resolution at each end and a count of jitter.
    const SLACK: u64 = 120;
    let Some(plain) = demo_run("qemu") else {
        return false;
    };
    let Some(stress) = demo_run("qemu,demo-stress") else {
        eprintln!("xtask: the stress run failed");
        return false;
    };
    match (worst_response(&plain), worst_response(&stress)) {
        (Some(p), Some(s)) => {
            println!(
                "xtask: sample task's worst response: {p} instructions plain, {s} under stress"
            );
            if s > p + SLACK {
                eprintln!(
                    "xtask: the background's load reaches the sample task ({s} > {p} + {SLACK})"
                );
                return false;
            }
            true
        }
        _ => {
            eprintln!("xtask: a demo log states no worst response");
            false
        }
    }
}

fn build_board() -> PathBuf {
    build_firmware("board", "board-f405")
}

/// A QEMU Machine Protocol client (JSON lines over a Unix socket).
struct Qmp {
    w: std::os::unix::net::UnixStream,
    r: std::io::BufReader<std::os::unix::net::UnixStream>,
}

impl Qmp {
    fn connect(path: &Path) -> Option<Self> {
        let t0 = std::time::Instant::now();
        let s = loop {
            match std::os::unix::net::UnixStream::connect(path) {
                Ok(s) => break s,
                Err(_) if t0.elapsed().as_secs() < 30 => {
                    std::thread::sleep(std::time::Duration::from_millis(50))
                }
                Err(e) => {
                    eprintln!("xtask: QMP {}: {e}", path.display());
                    return None;
                }
            }
        };
        let mut q = Qmp {
            w: s.try_clone().ok()?,
            r: std::io::BufReader::new(s),
        };
        q.line()?; // greeting
        q.call(r#"{"execute":"qmp_capabilities"}"#)?;
        Some(q)
    }

    fn line(&mut self) -> Option<String> {
        use std::io::BufRead;
        let mut l = String::new();
        (self.r.read_line(&mut l).ok()? > 0).then_some(l)
    }

    /// Send a command; its reply (events in between are skipped).
    fn call(&mut self, cmd: &str) -> Option<String> {
        use std::io::Write;
        self.w.write_all(cmd.as_bytes()).ok()?;
        self.w.write_all(b"\n").ok()?;
        loop {
            let l = self.line()?;
            if l.contains("\"return\"") || l.contains("\"error\"") {
                return Some(l);
            }
        }
    }

    /// Guest physical memory [addr, addr + n).
    fn read(&mut self, addr: u32, n: u32, scratch: &Path) -> Option<Vec<u8>> {
        let r = self.call(&format!(
            r#"{{"execute":"pmemsave","arguments":{{"val":{addr},"size":{n},"filename":"{}"}}}}"#,
            scratch.display()
        ))?;
        if r.contains("\"error\"") {
            return None;
        }
        std::fs::read(scratch).ok()
    }
}

/// An RTT host over QMP: polls the defmt up-channel of the firmware and
/// collects what it wrote. defmt-rtt does not wait for a host (it
/// overwrites), so the poll must outpace the log: 20 ms of QEMU's
/// real-time clock against a 1 KiB buffer and a few lines a second.
struct RttReader {
    block: u32,
    cursor: Option<u32>,
    bytes: Vec<u8>,
}

impl RttReader {
    fn new(elf: &Path) -> Option<Self> {
        use object::{Object, ObjectSymbol};
        let data = std::fs::read(elf).ok()?;
        let file = object::File::parse(&*data).ok()?;
        let block = file
            .symbols()
            .find(|s| s.name() == Ok("_SEGGER_RTT"))?
            .address() as u32;
        Some(Self {
            block,
            cursor: None,
            bytes: Vec::new(),
        })
    }

    fn poll(&mut self, q: &mut Qmp, scratch: &Path) {
        let Some(h) = q.read(self.block, 48, scratch) else {
            return;
        };
        if !h.starts_with(b"SEGGER RTT") {
            return; // not initialised yet
        }
        let word = |o: usize| u32::from_le_bytes([h[o], h[o + 1], h[o + 2], h[o + 3]]);
        let (buf, size, write) = (word(28), word(32), word(36));
        if size == 0 || write >= size {
            return;
        }
        let from = self.cursor.unwrap_or(0);
        if from == write {
            return;
        }
        let Some(b) = q.read(buf, size, scratch) else {
            return;
        };
        if write > from {
            self.bytes
                .extend_from_slice(&b[from as usize..write as usize]);
        } else {
            self.bytes.extend_from_slice(&b[from as usize..]);
            self.bytes.extend_from_slice(&b[..write as usize]);
        }
        self.cursor = Some(write);
    }
}

/// The real board binary on QEMU's STM32F405 (`netduinoplus2`), which
/// models the SPI buses and USARTs but no gyro and no working clock tree:
/// it must take the clock fallback, report every absent chip with its
/// typed error, keep sampling, and stream link frames on USART1, which
/// `gyro record` records while three commands go the other way. Its
/// defmt log is read over QMP (see `RttReader`).
fn board_qemu(seconds: u64) -> bool {
    use gyro_array::link::msg::{ClockSource, Frame};
    use gyro_array::link::wire::{Decoder, MAX_FRAME};
    use gyro_array::pipeline::flag;

    let elf = build_board();
    let gyro = build_tool();
    let dir = root().join("target").join("link");
    let _ = std::fs::create_dir_all(&dir);
    let (sock, qmp, rec, scratch) = (
        dir.join("board.sock"),
        dir.join("board-qmp.sock"),
        dir.join("board.glk"),
        dir.join("board-mem.bin"),
    );
    let _ = std::fs::remove_file(&sock);
    let _ = std::fs::remove_file(&qmp);
    let Some(mut rtt) = RttReader::new(&elf) else {
        eprintln!("xtask: no _SEGGER_RTT in {}", elf.display());
        return false;
    };
    let recorder = Command::new(&gyro)
        .arg("record")
        .arg("--from")
        .arg(format!("unix:{}", sock.display()))
        .arg("-o")
        .arg(&rec)
        .args([
            "--send",
            "status",
            "--send",
            "method=mean",
            "--send",
            "divider=0",
            "--quiet",
        ])
        .spawn();
    let mut q = Command::new("timeout");
    q.arg((seconds + 60).to_string())
        .args([
            "qemu-system-arm",
            "-machine",
            "netduinoplus2",
            "-nographic",
            "-monitor",
            "none",
        ])
        // Instruction-counted time (idle time skipped): the sample timing
        // is the firmware's, not the host's. Paused until the RTT reader
        // is attached, so no boot log is missed.
        .args(["-icount", "shift=0,sleep=off", "-S"])
        .arg("-qmp")
        .arg(format!("unix:{},server=on,wait=off", qmp.display()))
        .arg("-chardev")
        .arg(format!(
            "socket,id=link,path={},server=on,wait=on",
            sock.display()
        ))
        .args(["-serial", "chardev:link", "-kernel"])
        .arg(&elf)
        .stdout(Stdio::null());
    eprintln!("xtask: {q:?}");
    let (Ok(mut recorder), Ok(mut qemu)) = (recorder, q.spawn()) else {
        eprintln!("xtask: cannot start gyro record or qemu-system-arm");
        return false;
    };
    let Some(mut qc) = Qmp::connect(&qmp) else {
        let _ = qemu.kill();
        let _ = recorder.kill();
        return false;
    };
    rtt.poll(&mut qc, &scratch);
    let _ = qc.call(r#"{"execute":"cont"}"#);
    let t0 = std::time::Instant::now();
    while t0.elapsed().as_secs() < seconds {
        rtt.poll(&mut qc, &scratch);
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    rtt.poll(&mut qc, &scratch);
    let _ = qc.call(r#"{"execute":"quit"}"#);
    let _ = qemu.wait();
    let rec_ok = recorder.wait().map(|s| s.success()).unwrap_or(false);

    let log = Command::new("defmt-print")
        .arg("-e")
        .arg(&elf)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .and_then(|mut c| {
            use std::io::Write;
            if let Some(mut i) = c.stdin.take() {
                i.write_all(&rtt.bytes)?;
            }
            c.wait_with_output()
        })
        .map(|o| String::from_utf8_lossy(&o.stdout).into_owned())
        .unwrap_or_default();
    println!(
        "--- board log (RTT, {} bytes) ---\n{log}---",
        rtt.bytes.len()
    );
    let mut fails = Vec::new();
    if !rec_ok {
        fails.push("gyro record failed".to_string());
    }
    if !log.contains("clock: ") {
        fails.push("no clock report".into());
    }
    for i in 0..4 {
        if !log.contains(&format!("gyro {i}: ICM-42688-P init failed: WrongId(0)")) {
            fails.push(format!("gyro {i}: no typed WrongId error logged"));
        }
    }
    if !log.contains("calibration record: Missing; running uncalibrated") {
        fails.push("no typed error for the missing calibration record".into());
    }
    if !log.contains("CLKIN 32000 Hz on PC6 (TIM3 CH1)") {
        fails.push("CLKIN not started (TIM3 CH1 at 32 kHz)".into());
    }
    if !log.contains("gyro 4: ADXRS453 init failed: CheckFailed") {
        fails.push("gyro 4: no typed CheckFailed error logged".into());
    }
    // QEMU's STM32F405 models no DMA: the link's probe must find that and
    // send by the UART's interrupt (the link's check below proves it does).
    if !log.contains("link: DMA2 did not copy a word; sent by USART1's interrupt") {
        fails.push("the link's DMA probe did not fall back to the UART's interrupt".into());
    }
    // The link: the check proper, then what the status frames say.
    if !run(Command::new(&gyro).arg("check").arg(&rec).args([
        "--min-samples",
        "1000",
        "--acks",
        "ok,ok,out-of-range",
    ])) {
        fails.push("the recorded link failed its check".into());
    }
    let bytes = std::fs::read(&rec).unwrap_or_default();
    let mut dec = Decoder::<MAX_FRAME>::new();
    let last_status = bytes
        .iter()
        .filter_map(|&b| dec.feed::<Frame>(b))
        .filter_map(|r| match r {
            Ok(d) => match d.body {
                Frame::Status(s) => Some(s),
                _ => None,
            },
            Err(_) => None,
        })
        .last();
    match last_status {
        Some(s) => {
            let all_out = s.gyros.len() == 5
                && s.gyros
                    .iter()
                    .all(|g| g.flags & flag::INIT_FAILED != 0 && g.reads == 0);
            let retried = s.gyros.iter().all(|g| g.restarts > 0);
            // The four ICM-42688-P on the board's CLKIN (TIM3 runs in QEMU),
            // the ADXRS453 polled.
            let clocks: Vec<_> = s.gyros.iter().map(|g| g.clock).collect();
            let want = [
                ClockSource::ClkIn,
                ClockSource::ClkIn,
                ClockSource::ClkIn,
                ClockSource::ClkIn,
                ClockSource::Polled,
            ];
            println!("board-qemu: clocks {clocks:?}");
            if clocks != want {
                fails.push(format!("status frames' clocks {clocks:?}, not {want:?}"));
            }
            println!(
                "board-qemu: status at seq {}: method {:?}, gyros out {all_out}, re-probed {retried} (restarts {:?}), stack peak {} B",
                s.seq,
                s.settings.method,
                s.gyros.iter().map(|g| g.restarts).collect::<Vec<_>>(),
                s.stack_peak
            );
            if !all_out || !retried {
                fails.push("status frames do not show every absent gyro out and re-probed".into());
            }
        }
        None => fails.push("no status frame".into()),
    }
    for f in &fails {
        println!("board-qemu: FAIL: {f}");
    }
    fails.is_empty()
}

fn main() {
    let task = std::env::args().nth(1).unwrap_or_default();
    match task.as_str() {
        "test" => {
            must(
                run(Command::new("cargo").args(["test", "--workspace", "--profile", "host"])),
                "host tests",
            );
            ensure_tools();
            let ok = qemu(&build_qemu("qemu-tests"), false);
            must(ok, "on-target suite (qemu-tests)");
            must(
                demo_and_stress(),
                "demo and its output link (qemu-demo), and its stress run",
            );
            let ok = qemu(&build_firmware("qemu,persist", "qemu-faults"), false);
            must(ok, "fault containment (qemu-faults)");
            let ok = qemu(&build_qemu("qemu-settings"), false);
            must(ok, "saved settings across a reset (qemu-settings)");
            must(
                clib(),
                "the controller's C library (clib/): builds, tests, the demo recording",
            );
            must(board_qemu(10), "board-f405 on QEMU netduinoplus2");
            // The board firmware panics in no code of its own: each site
            // is a bounds or divisor check the compiler could not drop, a
            // reset waiting to happen in the field.
            let ours = panics(&build_board());
            must(
                ours == 0,
                "no panic call site from this crate in the board ELF (cargo xtask panics)",
            );
            must(
                python_package(),
                "the Python package (python/) and its tests",
            );
            println!("xtask: all checks passed");
        }
        "board-qemu" => {
            ensure_tools();
            must(board_qemu(10), "board-f405 on QEMU netduinoplus2");
        }
        "run" => {
            ensure_tools();
            must(demo_end_to_end(), "demo");
        }
        "clib" => {
            must(clib(), "the controller's C library");
        }
        "stress" => {
            ensure_tools();
            must(demo_and_stress(), "demo and its stress run");
        }
        "bench" => {
            ensure_tools();
            let ok = qemu(&build_qemu("qemu-bench"), true);
            must(ok, "bench");
            // The board's loop again, counted exactly from the trace.
            let ok = trace::loop_counts(&build_firmware("bench-trace", "qemu-bench"));
            must(ok, "bench, exact count of the board's loop");
        }
        "python" => must(
            python_package(),
            "the Python package (python/) and its tests",
        ),
        "bench-loop" => {
            ensure_tools();
            let ok = trace::loop_counts(&build_firmware("bench-trace", "qemu-bench"));
            must(ok, "bench, exact count of the board's loop");
        }
        "size" => {
            ensure_tools();
            size(&build_board());
        }
        "fuzz" => {
            let secs: u64 = match std::env::args().nth(2).map(|s| s.parse()) {
                None => 10,
                Some(Ok(s)) if s > 0 => s,
                Some(_) => {
                    eprintln!("usage: cargo xtask fuzz [SECONDS > 0]");
                    exit(2);
                }
            };
            fuzz(secs);
        }
        "panics" => {
            ensure_tools();
            let elfs = [
                build_qemu("qemu-tests"),
                build_qemu("qemu-demo"),
                build_firmware("qemu,persist", "qemu-faults"),
                build_qemu("qemu-settings"),
                build_board(),
            ];
            let mut ours_total = 0;
            for elf in &elfs {
                ours_total += panics(elf);
            }
            println!("panic call sites from this crate, all ELFs: {ours_total}");
        }
        _ => {
            eprintln!("usage: cargo xtask <test|run|stress|clib|board-qemu|python|bench|bench-loop|size|panics|fuzz [SECONDS]>");
            exit(2);
        }
    }
}

/// Flash (text + rodata + data) and static RAM (data + bss) from the ELF
/// section headers, without binutils.
/// The cargo-fuzz targets (fuzz/fuzz_targets).
const FUZZ_TARGETS: &[&str] = &[
    "fusion", "davar", "allan", "qualify", "drivers", "pipeline", "record", "link",
];
const CARGO_FUZZ: &str = "0.13.2";

/// Replay fuzz/regressions/<target>/*, then fuzz each target for `secs`.
/// The Python package: built from `python/` into a fresh virtual
/// environment under `target/` (with its pinned test requirements from
/// PyPI: pytest, allantools), then its tests. The Rust tests never need
/// Python; this step does.
fn python_package() -> bool {
    let py = std::env::var("PYTHON").unwrap_or_else(|_| "python3".into());
    let venv = root().join("target/python-venv");
    let bin = venv.join("bin");
    run(Command::new(&py).args(["-m", "venv", "--clear"]).arg(&venv))
        && run(Command::new(bin.join("python")).args([
            "-m",
            "pip",
            "install",
            "--quiet",
            "--disable-pip-version-check",
            "./python[test]",
        ]))
        && run(Command::new(bin.join("python")).args(["-m", "pytest", "-q", "python/tests"]))
}

fn fuzz(secs: u64) {
    let v = Command::new("cargo")
        .args(["install", "--list"])
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).into_owned())
        .unwrap_or_default();
    if !v.contains(&format!("cargo-fuzz v{CARGO_FUZZ}")) {
        must(
            run(Command::new("cargo")
                .args(["install", "cargo-fuzz", "--locked", "--version"])
                .arg(format!("={CARGO_FUZZ}"))),
            "install cargo-fuzz",
        );
    }
    let dir = root().join("fuzz");
    for t in FUZZ_TARGETS {
        let reg = dir.join("regressions").join(t);
        if let Ok(entries) = std::fs::read_dir(&reg) {
            for e in entries.flatten() {
                must(
                    run(Command::new("cargo")
                        .args(["+nightly", "fuzz", "run", "--fuzz-dir", "fuzz", t])
                        .arg(e.path())),
                    &format!("fuzz regression {t}/{}", e.file_name().to_string_lossy()),
                );
            }
        }
        must(
            run(Command::new("cargo")
                .args(["+nightly", "fuzz", "run", "--fuzz-dir", "fuzz", t, "--"])
                .arg(format!("-max_total_time={secs}"))),
            &format!("fuzz {t}"),
        );
    }
    println!(
        "xtask: {} fuzz targets ran {secs} s each without a crash",
        FUZZ_TARGETS.len()
    );
}

/// Callees that panic (the core library's panic entry points).
const PANIC_CALLEES: &[&str] = &[
    "core::panicking::",
    "core::slice::index::slice_",
    "core::option::unwrap_failed",
    "core::option::expect_failed",
    "core::result::unwrap_failed",
    "core::cell::panic_already",
    "core::str::slice_error_fail",
];

/// Count the calls into the core library's panic entry points in `elf`
/// and attribute each to the innermost source frame outside the core
/// library (llvm-addr2line -i walks the inlining chain). Prints a summary
/// and this crate's sites; returns how many are this crate's.
fn panics(elf: &Path) -> usize {
    let dis = Command::new("llvm-objdump")
        .args(["-d", "--no-show-raw-insn", "--demangle"])
        .arg(elf)
        .output()
        .unwrap_or_else(|e| {
            eprintln!("xtask: llvm-objdump: {e}");
            exit(1)
        });
    let text = String::from_utf8_lossy(&dis.stdout);
    let mut sites: Vec<(String, String)> = Vec::new(); // (address, callee)
    for line in text.lines() {
        let mut it = line.split_whitespace();
        let (Some(addr), Some(op)) = (it.next(), it.next()) else {
            continue;
        };
        if !matches!(op, "bl" | "b" | "b.w" | "blx") {
            continue;
        }
        let Some(callee) = line.split('<').nth(1).and_then(|c| c.split('>').next()) else {
            continue;
        };
        if PANIC_CALLEES.iter().any(|p| callee.starts_with(p)) {
            let name = callee.rsplit_once("::h").map_or(callee, |(n, _)| n);
            sites.push((
                format!("0x{}", addr.trim_end_matches(':')),
                name.to_string(),
            ));
        }
    }
    let mut a2l = Command::new("llvm-addr2line");
    a2l.args(["-a", "-i", "-e"]).arg(elf);
    for (a, _) in &sites {
        a2l.arg(a);
    }
    let out = a2l.output().unwrap_or_else(|e| {
        eprintln!("xtask: llvm-addr2line: {e}");
        exit(1)
    });
    let chains = String::from_utf8_lossy(&out.stdout);
    // Ours: the firmware crate's code and its drivers' crates.
    let src = root().join("src").display().to_string();
    let drivers = root().join("drivers").display().to_string();
    let root = root().display().to_string();
    let is_ours = |owner: &str| owner.starts_with(&src) || owner.starts_with(&drivers);
    let mut owner_of: Vec<String> = Vec::new();
    for line in chains.lines() {
        if line.starts_with("0x") {
            owner_of.push(String::new());
            continue;
        }
        let Some(cur) = owner_of.last_mut() else {
            continue;
        };
        // The innermost frame outside the Rust library decides.
        if cur.is_empty() && !line.starts_with("/rustc/") && !line.starts_with("??") {
            *cur = line.to_string();
        }
    }
    let mut by: std::collections::BTreeMap<String, usize> = Default::default();
    let mut ours = Vec::new();
    for ((_, callee), owner) in sites.iter().zip(&owner_of) {
        // Line 0: code the compiler made with no source line of ours, as an
        // async state machine's resumed-after-completion check inlined from
        // a dependency's `async fn` (sequential-storage's, driven to its end
        // by `block_on`): counted and listed apart, not as a site of ours.
        let who = if is_ours(owner) && owner.ends_with(":0") {
            format!("no source line ({})", owner.trim_start_matches(&root))
        } else if is_ours(owner) {
            ours.push(format!("{} ({callee})", owner.trim_start_matches(&root)));
            "this crate".to_string()
        } else if owner.is_empty() {
            "the Rust core library".to_string()
        } else {
            owner
                .split("/registry/src/")
                .nth(1)
                .and_then(|r| r.split('/').nth(1))
                .unwrap_or(owner)
                .to_string()
        };
        *by.entry(who).or_default() += 1;
    }
    let name = elf.file_name().unwrap_or_default().to_string_lossy();
    println!("{name}: {} panic call sites", sites.len());
    for (who, n) in &by {
        println!("  {n:>4}  {who}");
    }
    for s in &ours {
        println!("        {}", s.trim_start_matches('/'));
    }
    ours.len()
}

fn size(elf: &Path) {
    let b = std::fs::read(elf).unwrap_or_else(|e| {
        eprintln!("xtask: {}: {e}", elf.display());
        exit(1)
    });
    let u32_at = |o: usize| u32::from_le_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]]) as usize;
    let u16_at = |o: usize| u16::from_le_bytes([b[o], b[o + 1]]) as usize;
    let (shoff, shentsize, shnum, shstrndx) =
        (u32_at(0x20), u16_at(0x2E), u16_at(0x30), u16_at(0x32));
    let sh = |i: usize| shoff + i * shentsize;
    let strtab = u32_at(sh(shstrndx) + 0x10);
    let (mut flash, mut ram) = (0usize, 0usize);
    for i in 0..shnum {
        let name_off = strtab + u32_at(sh(i));
        let end = b[name_off..].iter().position(|c| *c == 0).unwrap_or(0);
        let name = String::from_utf8_lossy(&b[name_off..name_off + end]);
        let size = u32_at(sh(i) + 0x14);
        match name.as_ref() {
            ".vector_table" | ".text" | ".rodata" => flash += size,
            ".data" => {
                flash += size;
                ram += size
            }
            ".bss" | ".uninit" => ram += size,
            _ => {}
        }
    }
    println!("{}: flash {flash} B, static RAM {ram} B", elf.display());
}
