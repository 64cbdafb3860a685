//! Exact instruction counts of the board's loop, from QEMU's execution
//! trace (`-d in_asm,exec,nochain`), for `cargo xtask bench`.
//!
//! The timed bench reads SysTick, whose tick is 40 instructions under
//! `-icount shift=0`, and takes out the emulated bus's operations timed one
//! by one: some forty a sample, each off by up to a tick. The sum's error
//! is about ±100 instructions a sample, so the worst of 8 000 samples reads
//! some 200 high (both are printed). Here every executed instruction is counted: the trace
//! logs each translated block's instructions (`IN:`) and each execution of
//! a block (`Trace`); the bench's trace build (feature `bench-trace`)
//! calls a marker function at each phase of a sample; and an instruction
//! is the emulator's, not the firmware's, when any of its inline frames
//! (DWARF) is in `gyro_sim`'s emulated world (but for the chip-select pins, which
//! stand in for the board's GPIO writes) or the bench's clock, or when it
//! runs inside a call made from such an instruction: the parse follows
//! the calls (`bl`, `blx`) and their returns, so whatever the emulator
//! calls (soft-float f64, libm, `core`'s helpers) is the emulator's too,
//! and an interrupt taken meanwhile is not. On the board the CPU waits
//! for the SPI bus instead; that time is not counted here.

use std::collections::HashMap;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::Stdio;

use object::{Object, ObjectSection, ObjectSymbol};

/// Per sample: firmware instructions in read + calibrate + fuse, after the
/// frame (the calibration's learning, the E-DAVARs), link; and the
/// emulated bus's inside read + fuse.
#[derive(Clone, Copy, Default)]
struct Sample {
    fw: [u64; 3],
    bus: u64,
}

/// A scenario's samples, and firmware instructions by function (innermost
/// inline frame) in its worst sample and over all its samples: where the
/// worst sample's extra cost goes.
#[derive(Default)]
struct Scenario {
    samples: Vec<Sample>,
    worst_total: u64,
    worst_by_fn: Vec<(u32, u64)>,
    all_by_fn: Vec<u64>,
}

/// One translated block: firmware and emulator instructions, and the
/// firmware's by function id.
#[derive(Clone, Default)]
struct Block {
    fw: u64,
    emu: u64,
    by_fn: Vec<(u32, u64)>,
    /// Instructions of compiler_builtins' own routines (memcpy, memset,
    /// soft float): counted as whoever called them, the emulator or the
    /// firmware (these leaf routines are entered from their caller's last
    /// block).
    builtin: u64,
    /// The function id of its last instruction that is not a builtin's.
    last_id: Option<u32>,
    /// How the block ends: a call, a return, or neither.
    end: End,
    /// Whether its last instruction is the emulator's (by DWARF): a call
    /// from it enters the emulator's time.
    last_emu: bool,
}

/// How a translated block ends (its last instruction).
#[derive(Clone, Copy, Default, PartialEq)]
enum End {
    #[default]
    Other,
    /// `bl` or `blx`: the callee (at `target` where the instruction
    /// names it) returns to `ret`.
    Call { ret: u64, target: Option<u64> },
    /// `bx lr`, or a `pop`/`ldm`/`ldr` of `pc` from the stack.
    Return,
}

/// One open call or exception, and whose time its caller ran in.
#[derive(Clone, Copy)]
enum Frame {
    Call { ret: u64, emu: bool },
    Exception { emu: bool },
}

/// The calls open at the current block: whether it runs in the emulator's
/// time (called, however deep, from the emulator's code).
#[derive(Default)]
struct Calls {
    frames: Vec<Frame>,
    emu: bool,
    /// The last block was a call, to this address where it names it: a
    /// handler's address next is its callee, not an exception taken.
    called: Option<Option<u64>>,
    /// The last block returned from an exception handler's own frame.
    exception_return: bool,
    /// The vector table's handlers (Thumb bit cleared).
    handlers: std::collections::HashSet<u64>,
}

impl Calls {
    /// Enter the block at `pc`: close the call it returns to, or open the
    /// exception it starts; whether it runs in the emulator's time.
    fn enter(&mut self, pc: u64) -> bool {
        if std::mem::take(&mut self.exception_return) {
            if let Some(&Frame::Exception { emu }) = self.frames.last() {
                self.frames.pop();
                self.emu = emu;
            }
        }
        // A return lands on the newest open call's return address; a frame
        // left open above it (a call that never returned by `bx lr`, as a
        // tail-called diverging function) is dropped with it. The search
        // stops at an exception: its handler's calls are its own.
        let found = self
            .frames
            .iter()
            .enumerate()
            .rev()
            .take(4)
            .take_while(|(_, f)| matches!(f, Frame::Call { .. }))
            .find(|(_, f)| matches!(f, Frame::Call { ret, .. } if *ret == pc))
            .map(|(k, _)| k);
        if let Some(k) = found {
            if let Frame::Call { emu, .. } = self.frames[k] {
                self.emu = emu;
            }
            self.frames.truncate(k);
        } else if self.handlers.contains(&pc)
            && !matches!(self.called, Some(t) if t.is_none_or(|t| t == pc))
        {
            self.frames.push(Frame::Exception { emu: self.emu });
            self.emu = false;
        }
        self.called = None;
        self.emu
    }

    /// Leave the block `b` (entered with [`Calls::enter`]).
    fn leave(&mut self, b: &Block) {
        match b.end {
            End::Call { ret, target } => {
                // A block cut short at a device access and run again from
                // the cut ends in the same call twice over: one frame.
                let again =
                    matches!(self.frames.last(), Some(Frame::Call { ret: r, .. }) if *r == ret);
                if !again {
                    self.frames.push(Frame::Call { ret, emu: self.emu });
                }
                self.emu |= b.last_emu;
                self.called = Some(target);
            }
            End::Return => {
                self.exception_return = matches!(self.frames.last(), Some(Frame::Exception { .. }));
            }
            End::Other => {}
        }
    }
}

/// What a marker does.
#[derive(Clone, Copy, PartialEq)]
enum Mark {
    Scenario,
    Sample,
    Phase(usize),
    Off,
}

/// Run the trace build `elf` under QEMU; print each scenario's exact
/// figures (and its decoded log if it failed). False if QEMU, defmt-print
/// or the parse failed.
pub fn loop_counts(elf: &Path) -> bool {
    let (marks, handlers) = match markers(elf) {
        Ok(m) => m,
        Err(e) => {
            eprintln!("xtask: {}: {e}", elf.display());
            return false;
        }
    };
    let loader = match addr2line::Loader::new(elf) {
        Ok(l) => l,
        Err(e) => {
            eprintln!("xtask: {}: no DWARF: {e}", elf.display());
            return false;
        }
    };
    // The trace logs every executed block, the emulated world's too: K and
    // L (the chips' own clocks and FIFOs, a millisecond of their world in
    // f64 soft float each sample) take most of an hour each on a 2-core
    // host, A–J minutes. Four hours before QEMU is stopped.
    let mut q = crate::qemu_command(
        elf,
        true,
        14_400,
        &["-d", "in_asm,exec,nochain", "-D", "/dev/stderr"],
    );
    q.stderr(Stdio::piped());
    eprintln!(
        "xtask: {q:?} (trace parsed here) | defmt-print -e {}",
        elf.display()
    );
    let Ok(mut child) = q.spawn() else {
        eprintln!("xtask: cannot start qemu");
        return false;
    };
    let (Some(stdout), Some(stderr)) = (child.stdout.take(), child.stderr.take()) else {
        return false;
    };
    let elf_arg = elf.to_path_buf();
    let printer = std::thread::spawn(move || crate::defmt_print(&elf_arg, stdout));
    let (scenarios, fn_names) = parse(
        BufReader::with_capacity(1 << 20, stderr),
        &marks,
        handlers,
        &loader,
    );
    let q_ok = child.wait().is_ok_and(|s| s.success());
    let Ok(Ok(decoded)) = printer.join() else {
        eprintln!("xtask: defmt-print failed");
        return false;
    };
    let text = String::from_utf8_lossy(&decoded.stdout);
    // The trace build's own SysTick lines (its markers timed in) would
    // only repeat the timed run's: its log is shown when it failed.
    let ok = q_ok && decoded.status.success();
    if !ok {
        print!("{text}");
    }
    // The scenarios' names, in the order the bench ran them, and what
    // the bench says of their fallbacks and tracker restarts.
    let names: Vec<(&str, &str)> = text
        .lines()
        .filter_map(|l| l.split_once("bench whole loop, faults "))
        .filter(|(_, r)| r.contains("window restarts"))
        .filter_map(|(_, r)| {
            let (name, rest) = r.split_once(':')?;
            Some((name, rest.rsplit_once(" (").map_or("", |(_, c)| c)))
        })
        .collect();
    for (k, s) in scenarios.iter().enumerate() {
        let (name, counts) = names.get(k).copied().unwrap_or(("?", ""));
        report(name, s, &fn_names);
        if !counts.is_empty() {
            println!("  ({counts}");
        }
    }
    // The worst samples of them all: the sample task's response (what the
    // antenna's deadline is about; the bare loop's frame path was 9 782 at
    // worst on K, the figure it must not pass) and everything a sample
    // costs (the CPU's load).
    let worst_of = |f: &dyn Fn(&Sample) -> u64| {
        scenarios
            .iter()
            .enumerate()
            .flat_map(|(k, s)| {
                let name = names.get(k).map_or("?", |n| n.0);
                s.samples.iter().map(move |x| (f(x), name))
            })
            .max_by_key(|&(w, _)| w)
    };
    if let Some((w, name)) = worst_of(&|x| x.fw[0]) {
        println!(
            "bench whole loop, every scenario: the sample task's worst response (tick to frame queued) {w} instructions ({name}); target <= 9782 (the bare loop's frame path on K): {}",
            if w <= 9_782 {
                format!("met, {} to spare", 9_782 - w)
            } else {
                format!("NOT met, {} over", w - 9_782)
            }
        );
    }
    if let Some((w, name)) = worst_of(&|x| x.fw.iter().sum()) {
        println!(
            "bench whole loop, every scenario: everything one sample costs (the sample task and the background's share), worst {w} instructions ({name}), {:.1} % of a 1 ms period at 168 MHz (one instruction a cycle)",
            w as f64 / 1680.0
        );
    }
    ok && !scenarios.is_empty()
}

/// The marker functions' addresses, and the exception handlers' from the
/// vector table (Thumb bit cleared).
type Markers = (HashMap<u64, Mark>, std::collections::HashSet<u64>);

fn markers(elf: &Path) -> Result<Markers, String> {
    let data = std::fs::read(elf).map_err(|e| e.to_string())?;
    let file = object::File::parse(&*data).map_err(|e| e.to_string())?;
    // The vector table: the initial stack pointer, then the handlers
    // (Reset among them; it is never entered from another block).
    let table = file
        .section_by_name(".vector_table")
        .ok_or("no .vector_table section")?;
    let words = table.data().map_err(|e| e.to_string())?;
    let handlers = words
        .chunks_exact(4)
        .skip(1)
        .map(|w| u64::from(u32::from_le_bytes([w[0], w[1], w[2], w[3]])) & !1)
        .filter(|&a| a != 0)
        .collect();
    let mut m = HashMap::new();
    for sym in file.symbols() {
        let kind = match sym.name() {
            Ok("bench_mark_scenario") => Mark::Scenario,
            Ok("bench_mark_sample") => Mark::Sample,
            Ok("bench_mark_fuse") => Mark::Phase(0),
            Ok("bench_mark_davar") => Mark::Phase(1),
            Ok("bench_mark_link") => Mark::Phase(2),
            Ok("bench_mark_off") => Mark::Off,
            _ => continue,
        };
        m.insert(sym.address() & !1, kind);
    }
    if m.len() == 6 {
        Ok((m, handlers))
    } else {
        Err(format!(
            "{} of the 6 bench_mark_* symbols (built without bench-trace?)",
            m.len()
        ))
    }
}

/// Whether the instruction at `addr` is the emulator's (or the bench
/// clock's): any inline frame in `gyro_sim` but its chip-select pins
/// (`EmuCs`), its checks and its QEMU support, or in `gyro_sim::qemu::ticks`; and its innermost frame's function.
fn classify(loader: &addr2line::Loader, addr: u64) -> (bool, String, bool) {
    let Ok(mut frames) = loader.find_frames(addr) else {
        return (false, "?".into(), true);
    };
    let mut builtin = false;
    let mut innermost = None;
    let mut first = None;
    let mut emu = false;
    while let Ok(Some(f)) = frames.next() {
        if let Some(name) = f.function.as_ref().and_then(|n| n.demangle().ok()) {
            // The emulated chip-select pins stay the firmware's: a few
            // instructions each, as a GPIO write is on the board.
            let sim = name.contains("gyro_sim::")
                && !name.contains("EmuCs")
                && !name.contains("gyro_sim::checks::")
                && !name.contains("gyro_sim::qemu::");
            if sim || name.contains("gyro_sim::qemu::ticks") {
                emu = true;
            }
            // `XTASK_TRACE_LINES=1`: by the line of this crate's code the
            // instruction comes from (its innermost frame in the crate),
            // not by function.
            if std::env::var_os("XTASK_TRACE_LINES").is_some() {
                if innermost.is_none() && name.contains("gyro_array::") {
                    let loc = f.location.as_ref();
                    let file = loc
                        .and_then(|l| l.file)
                        .and_then(|p| p.rsplit('/').next())
                        .unwrap_or("?");
                    let line = loc.and_then(|l| l.line).unwrap_or(0);
                    innermost = Some(format!("{} {file}:{line}", short_name(&name)));
                }
            } else if innermost.is_none() {
                innermost = Some(short_name(&name));
            }
            if first.is_none() {
                first = Some(short_name(&name));
            }
            builtin |= name.starts_with("compiler_builtins::") || name.starts_with("__aeabi");
        }
    }
    let name = innermost.or(first);
    let builtin = builtin || name.is_none();
    (emu, name.unwrap_or_else(|| "?".into()), builtin)
}

/// One instruction of QEMU's `in_asm` log: its address, its size in
/// bytes and its text (mnemonic and operands), from a line such as
/// `0x000000d8:  f029 fa4e  bl       #0x29578`.
fn instruction(line: &[u8]) -> Option<(u64, u64, &[u8])> {
    let hex = std::str::from_utf8(line.strip_prefix(b"0x")?.get(..8)?).ok()?;
    let addr = u64::from_str_radix(hex, 16).ok()?;
    let rest = line.get(10..)?.strip_prefix(b":  ")?;
    let cut = rest.windows(2).position(|w| w == b"  ")?;
    let size = rest[..cut].iter().filter(|c| c.is_ascii_hexdigit()).count() as u64 / 2;
    let text = rest[cut..].trim_ascii_start();
    Some((addr, size, text))
}

/// How an instruction at the end of a block ends it; `next` is the
/// address after it (where a call returns).
fn end_of(next: u64, insn: &[u8]) -> End {
    let text = String::from_utf8_lossy(insn);
    let mut words = text.split_whitespace();
    let mnemonic = words.next().unwrap_or("");
    let operands: String = words.collect();
    match mnemonic {
        "bl" | "blx" => End::Call {
            ret: next,
            target: operands
                .strip_prefix("#0x")
                .and_then(|h| u64::from_str_radix(h, 16).ok()),
        },
        "bx" if operands == "lr" => End::Return,
        "pop" | "pop.w" if operands.contains("pc}") => End::Return,
        "ldm" | "ldm.w" | "ldmia" | "ldmia.w"
            if operands.starts_with("sp!") && operands.contains("pc}") =>
        {
            End::Return
        }
        "ldr" | "ldr.w" if operands.starts_with("pc,[sp]") => End::Return,
        _ => End::Other,
    }
}

/// A demangled path without its hash and crate-internal generics, for
/// the worst sample's breakdown.
fn short_name(name: &str) -> String {
    let name = name.strip_prefix('<').unwrap_or(name);
    let name = match name.rsplit_once("::h") {
        Some((head, hash)) if hash.len() == 16 => head,
        _ => name,
    };
    name.replace("gyro_array::", "")
}

/// Count the trace: per scenario, per sample. Also returns the function
/// names that `Scenario::worst_by_fn` indexes.
fn parse(
    r: impl BufRead,
    marks: &HashMap<u64, Mark>,
    handlers: std::collections::HashSet<u64>,
    loader: &addr2line::Loader,
) -> (Vec<Scenario>, Vec<String>) {
    let mut blocks: HashMap<u64, Block> = HashMap::new();
    // Per instruction address: (emulator's?, function id, a builtin?).
    let mut at: HashMap<u64, (bool, u32, bool)> = HashMap::new();
    let mut calls = Calls {
        handlers,
        ..Calls::default()
    };
    // The last instruction's function id of the last block that was not a
    // builtin's: builtins are charged to it in the by-line breakdown.
    let mut caller_id: Option<u32> = None;
    let mut names: Vec<String> = Vec::new();
    let mut ids: HashMap<String, u32> = HashMap::new();
    let mut building: Option<(u64, Block)> = None;
    let mut scenarios: Vec<Scenario> = Vec::new();
    let mut phase: Option<usize> = None;
    // The current sample's firmware instructions by function id.
    let mut by_fn: Vec<u64> = Vec::new();
    let only_phase = only_phase();
    let whole_loop = whole_loop();
    for line in r.split(b'\n') {
        let Ok(line) = line else { break };
        if line.starts_with(b"IN:") {
            building = Some((u64::MAX, Block::default()));
            continue;
        }
        if let Some((start, block)) = building.as_mut() {
            // "0x000180ec:  b580  push {r7, lr}"
            if let Some((addr, size, insn)) = instruction(&line) {
                if *start == u64::MAX {
                    *start = addr;
                }
                block.end = end_of(addr + size, insn);
                let (e, id, builtin) = *at.entry(addr).or_insert_with(|| {
                    let (e, name, builtin) = classify(loader, addr);
                    let builtin = builtin && !e;
                    let next = ids.len() as u32;
                    let id = *ids.entry(name.clone()).or_insert_with(|| {
                        names.push(name);
                        next
                    });
                    (e, id, builtin)
                });
                block.last_emu = e;
                if e {
                    block.emu += 1;
                } else if builtin {
                    block.builtin += 1;
                    match block.by_fn.iter_mut().find(|(f, _)| *f == id) {
                        Some((_, n)) => *n += 1,
                        None => block.by_fn.push((id, 1)),
                    }
                } else {
                    block.last_id = Some(id);
                    block.fw += 1;
                    match block.by_fn.iter_mut().find(|(f, _)| *f == id) {
                        Some((_, n)) => *n += 1,
                        None => block.by_fn.push((id, 1)),
                    }
                }
                continue;
            }
            let (start, block) = building.take().unwrap_or_default();
            // The longest translation of a start address stands: under
            // -icount a block cut short at a device access is translated
            // again, run once and logged, while the cached full block runs
            // on unlogged (this bench's only device reads are the clock's,
            // which is not counted).
            if start != u64::MAX {
                let b = blocks.entry(start).or_default();
                if block.fw + block.emu + block.builtin > b.fw + b.emu + b.builtin {
                    *b = block;
                }
            }
        }
        // "Trace 0: 0x7f.. [00800408/000180ec/00000110/ff020200] name"
        let Some(pc) = line
            .strip_prefix(b"Trace ")
            .and_then(|l| l.iter().position(|&b| b == b'[').map(|i| &l[i + 1..]))
            .and_then(|l| l.get(9..17))
            .and_then(|h| std::str::from_utf8(h).ok())
            .and_then(|h| u64::from_str_radix(h, 16).ok())
        else {
            continue;
        };
        // Every block, markers too, opens and closes its calls.
        let b = blocks.get(&pc);
        let in_emu = calls.enter(pc);
        if let Some(b) = b {
            calls.leave(b);
        }
        match marks.get(&pc) {
            Some(Mark::Scenario) => {
                close_sample(scenarios.last_mut(), &mut by_fn);
                scenarios.push(Scenario::default());
                phase = None;
            }
            Some(Mark::Sample) => {
                close_sample(scenarios.last_mut(), &mut by_fn);
                if let Some(s) = scenarios.last_mut() {
                    s.samples.push(Sample::default());
                }
                phase = None;
            }
            Some(Mark::Phase(p)) => phase = Some(*p),
            Some(Mark::Off) => phase = None,
            None => {
                let Some(b) = b else { continue };
                let builtin_only = b.fw + b.emu == 0;
                if !builtin_only && b.last_id.is_some() {
                    caller_id = b.last_id;
                }
                let (Some(p), Some(s)) = (
                    phase,
                    scenarios.last_mut().and_then(|s| s.samples.last_mut()),
                ) else {
                    continue;
                };
                // Called from the emulator: all of it the emulator's.
                if in_emu {
                    if p == 0 {
                        s.bus += b.fw + b.emu + b.builtin;
                    }
                    continue;
                }
                s.fw[p] += b.fw + b.builtin;
                if p == 0 {
                    s.bus += b.emu;
                }
                // `XTASK_TRACE_PHASE=0|1|2`: the breakdown by function of one
                // phase alone (the sample task to its frame queued, the
                // background, the sample task after its frame), `all` every
                // one. By default the frame's path alone (phase 0).
                if !whole_loop && only_phase.map_or(p != 0, |q| q != p) {
                    continue;
                }
                let lines = std::env::var_os("XTASK_TRACE_LINES").is_some();
                let charged: Vec<(u32, u64)> = b
                    .by_fn
                    .iter()
                    .map(|&(id, n)| match (builtin_only && lines, caller_id) {
                        // By line: a builtin under the line that called it.
                        (true, Some(c)) => {
                            let key = format!("{} <- {}", names[id as usize], names[c as usize]);
                            let next = ids.len() as u32;
                            let id = *ids.entry(key.clone()).or_insert_with(|| {
                                names.push(key);
                                next
                            });
                            (id, n)
                        }
                        _ => (id, n),
                    })
                    .collect();
                for (id, n) in charged {
                    let id = id as usize;
                    if by_fn.len() <= id {
                        by_fn.resize(id + 1, 0);
                    }
                    by_fn[id] += n;
                }
            }
        }
    }
    close_sample(scenarios.last_mut(), &mut by_fn);
    (scenarios, names)
}

/// End the scenario's last sample: keep its breakdown by function if its
/// frame's path (the sample task to its frame queued) is the worst so
/// far; clear `by_fn` for the next.
fn close_sample(scenario: Option<&mut Scenario>, by_fn: &mut [u64]) {
    if let Some(sc) = scenario {
        if sc.all_by_fn.len() < by_fn.len() {
            sc.all_by_fn.resize(by_fn.len(), 0);
        }
        for (a, n) in sc.all_by_fn.iter_mut().zip(by_fn.iter()) {
            *a += n;
        }
        if let Some(last) = sc.samples.last() {
            let total = match only_phase() {
                _ if whole_loop() => last.fw.iter().sum(),
                Some(q) => last.fw.get(q).copied().unwrap_or(0),
                None => last.fw[0],
            };
            // `>=`: the last of equal worst samples, as `report` picks.
            if total >= sc.worst_total {
                sc.worst_total = total;
                sc.worst_by_fn = by_fn
                    .iter()
                    .enumerate()
                    .filter(|(_, &n)| n > 0)
                    .map(|(id, &n)| (id as u32, n))
                    .collect();
            }
        }
    }
    by_fn.iter_mut().for_each(|n| *n = 0);
}

/// Whether the function `name` (as the trace names it, with what called
/// it in the by-line mode) is a memory builtin.
fn is_mem_builtin(name: &str) -> bool {
    let callee = name.split(" <- ").next().unwrap_or(name);
    callee.starts_with("compiler_builtins::mem")
        || ["memcpy", "memcmp", "memset", "memmove", "bcmp"]
            .iter()
            .any(|m| callee.contains(m))
}

/// `XTASK_TRACE_PHASE=all`: the breakdowns by function over the whole
/// loop (its worst sample, every phase).
fn whole_loop() -> bool {
    std::env::var("XTASK_TRACE_PHASE").is_ok_and(|v| v == "all")
}

fn only_phase() -> Option<usize> {
    std::env::var("XTASK_TRACE_PHASE")
        .ok()
        .and_then(|v| v.parse().ok())
}

/// Print one scenario's mean and worst sample, and the worst sample's
/// costliest functions.
fn report(name: &str, scenario: &Scenario, fn_names: &[String]) {
    let samples = &scenario.samples;
    let n = samples.len().max(1) as f64;
    let total = |s: &Sample| s.fw.iter().sum::<u64>();
    let mean = |f: &dyn Fn(&Sample) -> u64| samples.iter().map(f).sum::<u64>() as f64 / n;
    let Some((at, worst)) = samples.iter().enumerate().max_by_key(|(_, s)| total(s)) else {
        return;
    };
    // The next worst, at least a sample away: how much the worst stands out.
    let second = samples
        .iter()
        .enumerate()
        .filter(|(i, _)| i.abs_diff(at) > 1)
        .map(|(_, s)| total(s))
        .max()
        .unwrap_or(0);
    println!(
        "bench whole loop, faults {name}: exact count (execution trace) over {} samples: the firmware's own instructions, mean {:.0} per sample (the sample task to its frame queued {:.0}, the background's e-davars {:.0}, the sample task after its frame (learning, status frames) {:.0}; the emulated bus {:.0} more), worst {} at sample {at} ({}, {}, {}), next worst {second}",
        samples.len(),
        mean(&total),
        mean(&|s| s.fw[0]),
        mean(&|s| s.fw[1]),
        mean(&|s| s.fw[2]),
        mean(&|s| s.bus),
        total(worst),
        worst.fw[0],
        worst.fw[1],
        worst.fw[2],
    );
    // The part the antenna waits for: the sample task's response, tick to
    // frame queued (the read, the fusion, the frame); the learning and a
    // status frame follow in the same task, the E-DAVARs in the background.
    let path = |s: &Sample| s.fw[0];
    let task = |s: &Sample| s.fw[0] + s.fw[2];
    if let Some((pat, pworst)) = samples.iter().enumerate().max_by_key(|(_, s)| path(s)) {
        let tworst = samples.iter().map(task).max().unwrap_or(0);
        println!(
            "  the sample task's response (tick to frame queued: read, fuse, frame): mean {:.0}, worst {} at sample {pat} (target: no higher than the bare loop's frame path, 9 782 on K); the sample task whole: mean {:.0}, worst {tworst}",
            mean(&path),
            path(pworst),
            mean(&task),
        );
    }
    // Where the worst sample spends more than the mean sample does.
    let mut extra: Vec<(u32, f64)> = scenario
        .worst_by_fn
        .iter()
        .map(|&(id, w)| {
            let all = scenario.all_by_fn.get(id as usize).copied().unwrap_or(0);
            (id, w as f64 - all as f64 / n)
        })
        .collect();
    extra.sort_by(|a, b| b.1.total_cmp(&a.1));
    let line: Vec<String> = extra
        .iter()
        .take(10)
        .map(|&(id, x)| format!("+{x:.0} {}", fn_names.get(id as usize).map_or("?", |s| s)))
        .collect();
    println!(
        "  the frame path's worst sample (or XTASK_TRACE_PHASE's), its extra over the mean sample, by function (innermost inline frame): {}",
        line.join(", ")
    );
    // The memory builtins (memcpy, memcmp, memset and their helpers): a
    // copy or a compare the compiler could not open up, a call each, on
    // the loop's path. Each of the two found here cost 85-200 a sample.
    let builtins: f64 = scenario
        .all_by_fn
        .iter()
        .enumerate()
        .filter(|(id, _)| fn_names.get(*id).is_some_and(|f| is_mem_builtin(f)))
        .map(|(_, &c)| c as f64 / n)
        .sum();
    println!(
        "  the mean sample's memory builtins (memcpy, memcmp, memset; in the phases broken down): {builtins:.0} instructions"
    );
    // Where the mean sample goes: what a cut in the mean must come from.
    let mut all: Vec<(usize, f64)> = scenario
        .all_by_fn
        .iter()
        .enumerate()
        .map(|(id, &c)| (id, c as f64 / n))
        .collect();
    all.sort_by(|a, b| b.1.total_cmp(&a.1));
    let line: Vec<String> = all
        .iter()
        .take(if std::env::var_os("XTASK_TRACE_LINES").is_some() {
            400
        } else if only_phase().is_some() || whole_loop() {
            40
        } else {
            16
        })
        .map(|&(id, x)| format!("{x:.0} {}", fn_names.get(id).map_or("?", |s| s)))
        .collect();
    println!(
        "  the mean sample's frame path (or XTASK_TRACE_PHASE's), by function (innermost inline frame): {}",
        line.join(", ")
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_instructions_and_how_blocks_end() {
        let (a, n, t) = instruction(b"0x000000d8:  f029 fa4e  bl       #0x29578").unwrap();
        assert_eq!((a, n), (0xd8, 4));
        assert!(
            end_of(a + n, t)
                == End::Call {
                    ret: 0xdc,
                    target: Some(0x29578)
                }
        );
        let (a, n, t) = instruction(b"0x00029578:  4798       blx      r3").unwrap();
        assert!(
            end_of(a + n, t)
                == End::Call {
                    ret: 0x2957a,
                    target: None
                }
        );
        for ret in [
            "0x00000100:  bd80       pop      {r7, pc}",
            "0x00000100:  e8bd 8ff0  pop.w    {r4, r5, r6, r7, r8, sb, sl, fp, pc}",
            "0x00000100:  4770       bx       lr",
            "0x00000100:  f85d fb04  ldr      pc, [sp], #4",
        ] {
            let (a, n, t) = instruction(ret.as_bytes()).unwrap();
            assert!(end_of(a + n, t) == End::Return, "{ret}");
        }
        for other in [
            "0x00000100:  b580       push     {r7, lr}",
            "0x00000100:  d3f2       blo      #0xe8",
            "0x00000100:  4718       bx       r3",
            "0x00000100:  bc80       pop      {r7}",
        ] {
            let (a, n, t) = instruction(other.as_bytes()).unwrap();
            assert!(end_of(a + n, t) == End::Other, "{other}");
        }
    }

    fn block(end: End, last_emu: bool) -> Block {
        Block {
            end,
            last_emu,
            ..Block::default()
        }
    }

    #[test]
    fn a_call_from_the_emulator_is_the_emulators_to_its_return() {
        let mut c = Calls {
            handlers: [0x900].into_iter().collect(),
            ..Calls::default()
        };
        let call = |ret, target| End::Call {
            ret,
            target: Some(target),
        };
        // Firmware at 0x100 calls the emulator at 0x200, which calls a
        // helper at 0x300 (not the emulator's by DWARF), which returns.
        assert!(!c.enter(0x100));
        c.leave(&block(call(0x104, 0x200), false));
        assert!(!c.enter(0x200));
        c.leave(&block(call(0x208, 0x300), true));
        assert!(c.enter(0x300));
        // An interrupt taken inside the helper runs in the firmware's time.
        c.leave(&block(End::Other, false));
        assert!(!c.enter(0x900));
        c.leave(&block(End::Return, false));
        assert!(c.enter(0x304));
        c.leave(&block(End::Return, false));
        // Back in the emulator (its own instructions the emulator's by
        // DWARF, called from the firmware's), then back in the firmware.
        assert!(!c.enter(0x208));
        c.leave(&block(End::Return, true));
        assert!(!c.enter(0x104));
        assert!(c.frames.is_empty());
        // A call to a handler's address is a call, not an exception.
        c.leave(&block(call(0x108, 0x900), false));
        assert!(!c.enter(0x900));
        assert_eq!(c.frames.len(), 1);
    }
}
