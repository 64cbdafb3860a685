//! link-timing: when each of the board's frames leaves, after its sample's
//! tick, on a wire-time model. The frames are the port's own (`link::port`,
//! through the board's schedule `gyro_array::app`, on the QEMU demo's
//! world: four timed ICM-42688-Ps and the ADXRS453, their faults), with a
//! controller asking for status, for the board's info and sending a
//! command it refuses, each on its own period; the times they are queued
//! at come from the board's measured worst cases (below); the wire takes
//! them in order at the UART's rate, one byte every 10 bits, whether DMA2
//! sends them (one transfer of what is queued, the next when it ends) or
//! the TXE interrupt (a byte as the data register empties): both leave
//! the wire idle only when nothing is queued.
//!
//! Times after the tick, µs, at 168 MHz, one instruction a cycle:
//! - the sample frame queued at [`FRAME_US`]: the four chips' FIFO bursts
//!   (the SPI's 110 µs, `app::BOARD_FRAME_PATH`) and the sample task's
//!   worst response on the timed board (K, 11 113 instructions, 66 µs,
//!   `BENCH_SCENARIOS=K cargo xtask bench-loop`);
//! - a status or info frame [`AFTER_US`] later (the sample task after its
//!   frame at its worst, 4 672 instructions, 28 µs, the status frame's
//!   build among them);
//! - an acknowledgement [`ACK_US`] after the frame (the background's
//!   E-DAVAR job, some 2 000 instructions at worst, and the command's
//!   handling, after the sample task).
//!
//! Twice at each rate: the frames as the run encoded them, and every frame
//! at its widest encoding, as after months (every counter and time at its
//! largest: the sample frame at `SAMPLE_FRAME_MAX`, the status frame at
//! `Status::widest`). Printed beside each: how far the sample frames' last
//! byte lands from the instant the delay compensation predicts their rates
//! to (`Port::horizon_us`, which allows the frame path 10 000 instructions:
//! a path longer than that ends after it).
//!
//! The run fails (exit code 1) unless at the board's 6 Mbaud no sample
//! frame ever waits behind another frame on the wire, in both cases.
//!
//! `cargo run --profile host -p evaluations --bin link-timing [-- --samples N]`

use std::cell::RefCell;
use std::collections::VecDeque;

use gyro_array::app as schedule;
use gyro_array::link::msg::{Command, Frame, Op, Settings, Status};
use gyro_array::link::port::{NoiseSnapshot, RingPort, SAMPLE_FRAME_MAX};
use gyro_array::link::ring::ByteRing;
use gyro_array::link::wire::{encode, Decoder, MAX_FRAME};
use gyro_array::link::{BAUD, FALLBACK_BAUD};
use gyro_sim::demo;
use host_tests::demo_host;
use rtic_core::Exclusive;

/// The sample frame queued, µs after the tick (see the module's text).
const FRAME_US: f64 = 110.0 + 11_113.0 / 168.0;
/// A status or info frame queued after the sample frame, µs.
const AFTER_US: f64 = 4_672.0 / 168.0;
/// An acknowledgement queued after the sample frame, µs.
const ACK_US: f64 = AFTER_US + 2_000.0 / 168.0 + 10.0;

/// One frame the port queued: the sample's number, its kind (an index
/// of [`KINDS`]), its bytes, and whether the background queued it.
#[derive(Clone, Copy)]
struct Queued {
    n: u32,
    kind: usize,
    bytes: usize,
    background: bool,
}

const KINDS: [&str; 4] = ["sample", "status", "info", "acknowledgement or sync"];

/// The board's port, each frame it queued recorded.
struct Recorder {
    port: RingPort<4096>,
    n: u32,
    background: bool,
    decoder: Decoder<MAX_FRAME>,
    log: Vec<Queued>,
}

/// The flushed bytes, decoded frame by frame.
struct Frames<'a> {
    r: &'a mut Decoder<MAX_FRAME>,
    n: u32,
    background: bool,
    bytes: usize,
    log: &'a mut Vec<Queued>,
}

impl embedded_hal_nb::serial::ErrorType for Frames<'_> {
    type Error = core::convert::Infallible;
}

impl embedded_hal_nb::serial::Write<u8> for Frames<'_> {
    fn write(&mut self, b: u8) -> embedded_hal_nb::nb::Result<(), Self::Error> {
        self.bytes += 1;
        if let Some(Ok(d)) = self.r.feed::<Frame>(b) {
            let kind = match d.body {
                Frame::Sample(_) | Frame::Raw(_) => 0,
                Frame::Status(_) => 1,
                Frame::Info(_) => 2,
                Frame::Ack(_) | Frame::Sync(_) => 3,
            };
            self.log.push(Queued {
                n: self.n,
                kind,
                bytes: self.bytes,
                background: self.background,
            });
            self.bytes = 0;
        }
        Ok(())
    }
    fn flush(&mut self) -> embedded_hal_nb::nb::Result<(), Self::Error> {
        Ok(())
    }
}

impl schedule::Link for Recorder {
    type Queue = ByteRing<4096>;
    fn port(&mut self) -> &mut RingPort<4096> {
        &mut self.port
    }
    fn flush(&mut self) {
        let mut f = Frames {
            r: &mut self.decoder,
            n: self.n,
            background: self.background,
            bytes: 0,
            log: &mut self.log,
        };
        self.port.drain(&mut f);
    }
}

/// Bytes from the controller, as the receive interrupt queues them.
struct Rx(VecDeque<u8>);

impl embedded_hal_nb::serial::ErrorType for Rx {
    type Error = core::convert::Infallible;
}

impl embedded_hal_nb::serial::Read<u8> for Rx {
    fn read(&mut self) -> embedded_hal_nb::nb::Result<u8, Self::Error> {
        self.0
            .pop_front()
            .ok_or(embedded_hal_nb::nb::Error::WouldBlock)
    }
}

fn command(id: u8, op: Op) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME];
    let n = encode(u32::from(id), &Command { id, op }, &mut buf).unwrap_or(0);
    buf[..n].to_vec()
}

/// The board's run: every frame it queued, and the compensation's
/// horizon at `baud`.
fn run(samples: u32, baud: u32) -> (Vec<Queued>, f64) {
    let mut link = Recorder {
        port: RingPort::new(Settings::default(), gyro_array::app::BOARD_FRAME_PATH),
        n: 0,
        background: false,
        decoder: Decoder::new(),
        log: Vec::new(),
    };
    link.port.set_timing(baud, 1_000_000 / demo::FS_HZ);
    let horizon = f64::from(link.port.horizon_us().unwrap_or(0));
    let mut rx = Rx(VecDeque::new());
    let commands = RefCell::new(VecDeque::new());
    demo_host::run(
        samples,
        &mut link,
        &mut NoiseSnapshot::default(),
        |_| {},
        |n| {
            // The controller: status every 250 ms, the board's info every
            // 700 ms, a divider of 0 (refused) every 330 ms.
            let mut c = commands.borrow_mut();
            if n % 250 == 7 {
                c.extend(command(1, Op::RequestStatus));
            }
            if n % 700 == 11 {
                c.extend(command(2, Op::RequestInfo));
            }
            if n % 330 == 13 {
                c.extend(command(3, Op::SetDivider(0)));
            }
        },
        |n, _, link, pipe, _| {
            link.n = n;
            link.background = true;
            rx.0.append(&mut commands.borrow_mut());
            schedule::receive(&mut rx, &mut Exclusive(pipe), &mut Exclusive(&mut *link));
            // The next sample's frames are the sample task's.
            link.n = n + 1;
            link.background = false;
        },
    );
    (link.log, horizon)
}

/// Per kind: frames, worst and mean first byte after the tick, worst last
/// byte; the sample frames' worst first byte behind their queueing; the
/// wire's busy share.
struct Wire {
    count: [u32; 4],
    first_worst: [f64; 4],
    first_sum: [f64; 4],
    last_worst: [f64; 4],
    last_best: [f64; 4],
    waited_worst: f64,
    busy: f64,
}

/// `log` on the wire at `baud`; with `widest`, each frame of a kind it
/// names at that many bytes instead of its own.
fn on_wire(log: &[Queued], baud: u32, samples: u32, widest: &[Option<usize>; 4]) -> Wire {
    let byte_us = 10.0e6 / f64::from(baud);
    let mut w = Wire {
        count: [0; 4],
        first_worst: [0.0; 4],
        first_sum: [0.0; 4],
        last_worst: [0.0; 4],
        last_best: [f64::INFINITY; 4],
        waited_worst: 0.0,
        busy: 0.0,
    };
    // The wire is free from `free` on, µs of the run.
    let mut free = 0.0f64;
    for q in log {
        let tick = f64::from(q.n) * 1000.0;
        let queued = tick
            + match (q.background, q.kind) {
                (true, _) => FRAME_US + ACK_US,
                (false, 0) => FRAME_US,
                (false, _) => FRAME_US + AFTER_US,
            };
        let first = free.max(queued);
        let wire = widest[q.kind].unwrap_or(q.bytes) as f64 * byte_us;
        free = first + wire;
        w.busy += wire;
        let k = q.kind;
        w.count[k] += 1;
        w.first_worst[k] = w.first_worst[k].max(first - tick);
        w.first_sum[k] += first - tick;
        w.last_worst[k] = w.last_worst[k].max(free - tick);
        w.last_best[k] = w.last_best[k].min(free - tick);
        if k == 0 {
            w.waited_worst = w.waited_worst.max(first - queued);
        }
    }
    w.busy /= f64::from(samples) * 1000.0;
    w
}

fn main() {
    gyro_tool::pipe::quiet_on_closed_pipe();
    let mut samples = 5_000u32;
    let args: Vec<String> = std::env::args().collect();
    if let Some(i) = args.iter().position(|a| a == "--samples") {
        samples = args
            .get(i + 1)
            .and_then(|s| s.parse().ok())
            .unwrap_or(samples);
    }
    println!(
        "link-timing: {samples} samples of the demo's world through the board's schedule; queued {FRAME_US:.0} µs after the tick (a sample frame), {:.0} (a status or info frame), {:.0} (an acknowledgement)",
        FRAME_US + AFTER_US,
        FRAME_US + ACK_US
    );
    let mut pass = true;
    // The frames as a board sends them after months: every counter and
    // time at its widest encoding (the sample frame at `SAMPLE_FRAME_MAX`,
    // the largest without the angle, which is off by default; the status
    // frame of five gyros at `Status::widest`).
    let widest_status = {
        let mut buf = [0u8; MAX_FRAME];
        encode(u32::MAX, &Frame::Status(Status::widest(5)), &mut buf).unwrap_or(0)
    };
    let widest = [
        Some(SAMPLE_FRAME_MAX as usize),
        Some(widest_status),
        None,
        None,
    ];
    for (baud, name) in [
        (BAUD, "the board's"),
        (FALLBACK_BAUD, "the fallback on the internal oscillator"),
    ] {
        let (log, horizon) = run(samples, baud);
        for (case, sizes) in [
            ("as encoded in the run", [None; 4]),
            ("every frame at its widest (after months)", widest),
        ] {
            let w = on_wire(&log, baud, samples, &sizes);
            println!(
                "{baud} baud ({name}), {case}; the wire busy {:.1} % of the time:",
                100.0 * w.busy
            );
            for (k, kind) in KINDS.iter().enumerate() {
                if w.count[k] == 0 {
                    continue;
                }
                println!(
                    "  {kind} frames: {}, first byte after the tick mean {:.0} µs, worst {:.0}; last byte {:.0} to {:.0}",
                    w.count[k],
                    w.first_sum[k] / f64::from(w.count[k]),
                    w.first_worst[k],
                    w.last_best[k],
                    w.last_worst[k]
                );
            }
            let late = w.last_worst[0] - horizon;
            println!(
                "  sample frames: at worst {:.0} µs behind a frame ahead of them on the wire; the last byte at worst {late:+.0} µs from the {horizon:.0} µs the compensation predicts the rates to",
                w.waited_worst
            );
            if baud == BAUD && w.waited_worst > 0.0 {
                println!("  FAIL: a sample frame waits behind another at the board's rate");
                pass = false;
            }
        }
    }
    if !pass {
        std::process::exit(1);
    }
}
