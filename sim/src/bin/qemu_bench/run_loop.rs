//! One scenario's loop, sample by sample, through the board's own schedule
//! (`gyro_array::app`): the sample task (read, fuse, the frame queued,
//! then the calibration's learning and a status frame when due), the
//! transmit queue emptied (untimed), the background's E-DAVARs; the cost
//! of each.

use super::*;

/// The transmit queue the whole-loop bench's port writes into: the
/// board's kind and size.
static BENCH_TX: gyro_array::link::ring::TxBuffer<4096> = gyro_array::link::ring::TxBuffer::new();

/// The measured part of the whole-loop bench, whatever the chips: per
/// sample, `before(n)` (faults, the bus's time; it gives the tick's µs on
/// the captures' clock) untimed, then `step`,
/// which hands the chips to the board's sample task (`app::sample`):
/// timed and marked for the exact count up to its frame queued (the
/// frame's path: phase 0) and after it (the learning, a status frame when
/// due: phase 2); the transmit queue emptied, untimed (the board copies
/// no byte: its DMA sends from the queue); the background's E-DAVARs
/// (phase 1). `meter` reads the emulated bus's own ticks and bytes.
#[allow(clippy::too_many_arguments)]
pub(super) fn run_loop<const N: usize>(
    t: &Ticks,
    ipt: f32,
    faults: &str,
    all: bool,
    pipe: &mut gyro_array::pipeline::Pipeline<N>,
    noise: &mut gyro_array::pipeline::tracker::NoiseTracker<1024, 35, 3>,
    meter: &dyn Fn() -> (gyro_sim::Meter, u32),
    mut before: impl FnMut(u32) -> u64,
    mut step: impl FnMut(
        &mut dyn FnMut(&mut [&mut dyn gyro_array::drivers::Gyro; N]) -> gyro_array::app::Sampled<N>,
    ) -> gyro_array::app::Sampled<N>,
) -> bool {
    use gyro_array::app as schedule;
    use gyro_array::link::msg::Settings;
    use gyro_array::link::port::{ChipTime, NoiseSnapshot, Port};
    use rtic_core::Exclusive;
    const VIEW: schedule::StatusView = schedule::StatusView {
        taus: gyro_array::pipeline::tracker::VIEW_TAUS,
        sample_us: 1000,
    };
    // Every scenario's samples; a build with `BENCH_SAMPLES=N` in its
    // environment counts the first N only (a quicker partial count: the
    // scenarios' faults from sample 1 500 on need their whole length).
    const SAMPLES: u32 = match option_env!("BENCH_SAMPLES") {
        Some(n) => match u32::from_str_radix(n, 10) {
            Ok(n) => n,
            Err(_) => panic!("BENCH_SAMPLES is a number of samples"),
        },
        None => 8000,
    };
    // The board's transmit queue and port (`board-f405`'s `TX_QUEUE`),
    // its reading end emptied after each sample.
    let mut port = Port::with_queue(
        BENCH_TX.stream_producer(),
        Settings::default(),
        gyro_array::app::BOARD_FRAME_PATH,
    );
    let sent = BENCH_TX.stream_consumer();
    let mut bytes = 0u32;
    let pair = pair_cost(t);
    // One clock read, in ticks (averaged: a single one is below a tick).
    let clock_cost = {
        const READS: u32 = 4096;
        let t0 = t.now();
        for _ in 0..READS {
            black_box(gyro_sim::qemu::ticks());
        }
        (t.now() - t0) as f32 / READS as f32
    };
    let (mut fw_sum, mut fw_worst, mut fw_worst_at) = (0.0f32, 0.0f32, 0u32);
    let mut fw_worst_parts = [0.0f32; 3];
    let mut bus_sum = 0.0f32;
    let bytes0 = meter().1;
    // Parts: the sample task to its frame queued, the background's
    // E-DAVARs, the sample task after its frame.
    let mut sum = [0.0f32; 3];
    let (mut worst, mut worst_at) = (0.0f32, 0u32);
    let mut worst_parts = [0.0f32; 3];
    let mut status_worst = 0.0f32;
    let mut fallbacks = 0u32;
    let mut snap = NoiseSnapshot::default();
    let mut bg = schedule::Background {
        tracker: noise,
        taus: gyro_array::pipeline::tracker::VIEW_TAUS,
    };
    mark::scenario();
    for n in 0..SAMPLES {
        mark::sample();
        let t_us = before(n);
        let (m0, _) = meter();
        let t0 = t.now();
        let mut tq = t0;
        mark::fuse();
        let s = step(&mut |gyros| {
            schedule::sample(
                &mut Exclusive(&mut *pipe),
                &mut Exclusive(&mut port),
                &mut Exclusive(&mut snap),
                gyros,
                (t_us, 0),
                &VIEW,
                || {
                    mark::link();
                    tq = t.now();
                },
                || schedule::StatusFacts {
                    clocks: [ChipTime::default(); N],
                    stack_peak: 0,
                },
            )
        });
        mark::off();
        let t1 = t.now();
        let (m1, _) = meter();
        // The bus operations' ticks, and one clock read's overhead for
        // each (the outer interval holds two reads per operation, the
        // operation's own interval one).
        let in_bus = (m1.ticks - m0.ticks) as f32 + (m1.ops - m0.ops) as f32 * clock_cost;
        fallbacks += s.out.fused.iter().flatten().filter(|f| f.fallback).count() as u32;
        // The bench's own ring emptied, untimed: on the board the UART's
        // DMA sends the frames from the queue they were written into, and
        // the sample task copies no byte.
        while let Ok(run) = sent.read() {
            let n = run.len();
            bytes = bytes.wrapping_add(n as u32);
            black_box(&*run);
            run.release(n);
        }
        // The background: this sample's probe into the E-DAVARs.
        let t3a = t.now();
        mark::davar();
        bg.run(
            gyro_array::pipeline::tracker::Probe::from(&s.out),
            &mut Exclusive(&mut snap),
        );
        mark::off();
        let t3 = t.now();
        let after = net(t1 - tq, pair);
        if s.status_sent {
            status_worst = status_worst.max(after);
        }
        // Parts: the sample task to its frame queued, the background's
        // E-DAVARs, the sample task after its frame.
        let parts = [net(tq - t0, pair), net(t3 - t3a, pair), after];
        let total: f32 = parts.iter().sum();
        for (s, p) in sum.iter_mut().zip(parts) {
            *s += p;
        }
        if total > worst {
            (worst, worst_at, worst_parts) = (total, n, parts);
        }
        let fw_parts = [(parts[0] - in_bus).max(0.0), parts[1], parts[2]];
        let fw: f32 = fw_parts.iter().sum();
        fw_sum += fw;
        bus_sum += in_bus.min(parts[0]);
        if fw > fw_worst {
            (fw_worst, fw_worst_at, fw_worst_parts) = (fw, n, fw_parts);
        }
    }
    let bus_bytes = meter().1 - bytes0;
    defmt::info!(
        "bench whole loop, {=str}: ({=u32} axis-samples fused in fallback, {=u32} missing noise samples bridged, {=u32} noise-tracker window restarts)",
        faults,
        fallbacks,
        bg.tracker.bridged(),
        bg.tracker.restarts()
    );
    let f = |ticks: f32| (ticks * ipt) as u32;
    let mean = |ticks: f32| (ticks * ipt / SAMPLES as f32) as u32;
    defmt::info!(
        "bench whole loop, the board's schedule (5 gyros read, calibrated and fused on 3 axes, the frame queued, the learning, status frames; the background's 3 E-DAVARs at lambda2 = 1024), {=u32} samples with faults and a variance step: mean {=u32} instructions per sample (the sample task to its frame queued {=u32}, the background {=u32}, the sample task after its frame {=u32}), worst {=u32} at sample {=u32} ({=u32}, {=u32}, {=u32})",
        SAMPLES,
        mean(sum.iter().sum()),
        mean(sum[0]),
        mean(sum[1]),
        mean(sum[2]),
        f(worst),
        worst_at,
        f(worst_parts[0]),
        f(worst_parts[1]),
        f(worst_parts[2])
    );
    defmt::info!(
        "bench whole loop, the firmware's own instructions (the emulated bus's operations timed and taken out: mean {=u32} instructions, {=u32} bytes a sample): mean {=u32} instructions per sample, worst {=u32} at sample {=u32} (the sample task to its frame queued {=u32}, the background {=u32}, the sample task after its frame {=u32}); SysTick reads each bus operation to a tick (40 instructions), so the worst reads high: `cargo xtask bench` counts it exactly from the execution trace",
        mean(bus_sum),
        bus_bytes / SAMPLES,
        mean(fw_sum),
        f(fw_worst),
        fw_worst_at,
        f(fw_worst_parts[0]),
        f(fw_worst_parts[1]),
        f(fw_worst_parts[2])
    );
    let c = port.counters();
    let ok = c.dropped == 0 && c.sent >= SAMPLES;
    if !all {
        return ok;
    }
    defmt::info!(
        "bench whole loop: the sample task after its frame on a sample with a status frame (the learning and the status frame): worst {=u32} instructions",
        f(status_worst)
    );
    defmt::info!(
        "bench whole loop: {=u32} frames sent, {=u32} dropped, {=u32} bytes",
        c.sent,
        c.dropped,
        bytes
    );
    ok
}

/// Instructions per frame of `step` over `frames` (after one untimed pass
/// over them first when `warm`), less the loop's own `overhead` ticks.
pub(super) fn per_frame<const G: usize>(
    t: &Ticks,
    ipt: f32,
    overhead: u64,
    frames: &[[[f32; G]; 3]],
    warm: bool,
    mut step: impl FnMut(&[[f32; G]; 3]),
) -> f32 {
    if warm {
        frames.iter().for_each(&mut step);
    }
    let ticks = ticks_of(t, frames, step).saturating_sub(overhead);
    ticks as f32 * ipt / frames.len() as f32
}

/// Ticks of one pass of `step` over `frames`.
pub(super) fn ticks_of<const G: usize>(
    t: &Ticks,
    frames: &[[[f32; G]; 3]],
    step: impl FnMut(&[[f32; G]; 3]),
) -> u64 {
    let t0 = t.now();
    frames.iter().for_each(step);
    t.now() - t0
}
