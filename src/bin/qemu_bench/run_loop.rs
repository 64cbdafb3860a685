//! One scenario's loop, sample by sample, as the board runs it: read and
//! fuse, the frame, then the idle work; its costs per phase.

use super::*;

/// The measured part of the whole-loop bench, whatever the chips: per
/// sample, `before(n)` (faults, the bus's time) untimed, then `step`
/// (read + calibrate + fuse) and the link frame (the frame's path), the
/// UART fed, and the calibration's learning and the E-DAVARs, timed and
/// marked for the exact count (the UART on its own); the status frame in
/// the idle time after, timed on its own. `meter` reads the emulated bus's own
/// ticks and bytes.
#[allow(clippy::too_many_arguments)]
pub(super) fn run_loop<const N: usize>(
    t: &Ticks,
    ipt: f32,
    faults: &str,
    all: bool,
    pipe: &mut gyro_array::pipeline::Pipeline<N>,
    noise: &mut gyro_array::pipeline::tracker::NoiseTracker<1024, 35, 3>,
    meter: &dyn Fn() -> (gyro_array::emu::Meter, u32),
    mut before: impl FnMut(u32),
    mut step: impl FnMut(&mut gyro_array::pipeline::Pipeline<N>) -> gyro_array::pipeline::Output<N>,
) -> bool {
    use gyro_array::link::msg::Settings;
    use gyro_array::link::port::Port;
    const SAMPLES: u32 = 8000;
    let mut port = Port::<2048>::new(Settings::default());
    let mut uart = NullUart(0);
    let pair = pair_cost(t);
    // One clock read, in ticks (averaged: a single one is below a tick).
    let clock_cost = {
        const READS: u32 = 4096;
        let t0 = t.now();
        for _ in 0..READS {
            black_box(gyro_array::board::qemu::ticks());
        }
        (t.now() - t0) as f32 / READS as f32
    };
    let (mut fw_sum, mut fw_worst, mut fw_worst_at) = (0.0f32, 0.0f32, 0u32);
    let mut fw_worst_parts = [0.0f32; 3];
    let mut bus_sum = 0.0f32;
    let bytes0 = meter().1;
    // Parts: read + calibrate + fuse, E-DAVAR, link.
    let mut sum = [0.0f32; 3];
    let (mut worst, mut worst_at) = (0.0f32, 0u32);
    let mut worst_parts = [0.0f32; 3];
    let mut status_worst = 0.0f32;
    let (mut drain_sum, mut drain_worst) = (0.0f32, 0.0f32);
    let mut fallbacks = 0u32;
    mark::scenario();
    for n in 0..SAMPLES {
        mark::sample();
        before(n);
        let (m0, _) = meter();
        let t0 = t.now();
        mark::fuse();
        let out = step(pipe);
        mark::off();
        let t1 = t.now();
        let (m1, _) = meter();
        // The bus operations' ticks, and one clock read's overhead for
        // each (the outer interval holds two reads per operation, the
        // operation's own interval one).
        let in_bus = (m1.ticks - m0.ticks) as f32 + (m1.ops - m0.ops) as f32 * clock_cost;
        fallbacks += out.fused.iter().flatten().filter(|f| f.fallback).count() as u32;
        // The frame first, with the E-DAVAR estimate of the samples before
        // this one: the antenna waits for it, not for the E-DAVARs.
        mark::link();
        port.publish(
            &out,
            u64::from(n) * 1000,
            pipe,
            &noise.at_taus(gyro_array::pipeline::tracker::LINK_TAUS),
        );
        let status_due = port.status_due(out.seq);
        mark::off();
        let t2 = t.now();
        // The UART is fed in the idle time, as on the board (timed on its
        // own).
        let d0 = t.now();
        port.drain(&mut uart);
        let dt_drain = net(t.now() - d0, pair);
        drain_sum += dt_drain;
        drain_worst = drain_worst.max(dt_drain);
        // The calibration's learning and the E-DAVARs, once the frame is
        // out, as on the board.
        let probe = gyro_array::pipeline::tracker::Probe::from(&out);
        let t3a = t.now();
        mark::davar();
        pipe.after_frame(noise, probe);
        mark::off();
        let t3 = t.now();
        // The status frame, as the board builds it: in the idle time after
        // the sample (timed on its own).
        if status_due {
            let s0 = t.now();
            let st = port.status(
                pipe,
                out.seq,
                u64::from(n) * 1000,
                [1, 16, 256],
                1000,
                0,
                &[],
            );
            port.send(&st);
            port.drain(&mut uart);
            status_worst = status_worst.max(net(t.now() - s0, pair));
        }
        let parts = [net(t1 - t0, pair), net(t3 - t3a, pair), net(t2 - t1, pair)];
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
        noise.bridged(),
        noise.restarts()
    );
    let f = |ticks: f32| (ticks * ipt) as u32;
    let mean = |ticks: f32| (ticks * ipt / SAMPLES as f32) as u32;
    defmt::info!(
        "bench whole loop (5 gyros read, calibrated and fused on 3 axes, 3 E-DAVARs at lambda2 = 1024, link frame built and queued), {=u32} samples with faults and a variance step: mean {=u32} instructions per sample (read+fuse {=u32}, after the frame {=u32}, link {=u32}), worst {=u32} at sample {=u32} (read+fuse {=u32}, after the frame {=u32}, link {=u32})",
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
        "bench whole loop, the firmware's own instructions (the emulated bus's operations timed and taken out: mean {=u32} instructions, {=u32} bytes a sample): mean {=u32} instructions per sample, worst {=u32} at sample {=u32} (read+fuse {=u32}, after the frame {=u32}, link {=u32}); SysTick reads each bus operation to a tick (40 instructions), so the worst reads high: `cargo xtask bench` counts it exactly from the execution trace",
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
        "bench whole loop: status frame, built in the idle time after its sample: worst {=u32} instructions",
        f(status_worst)
    );
    defmt::info!(
        "bench whole loop: feeding the UART in the idle time (a sink that takes every byte): mean {=u32}, worst {=u32} instructions per sample",
        mean(drain_sum),
        f(drain_worst)
    );
    defmt::info!(
        "bench whole loop: {=u32} frames sent, {=u32} dropped, {=u32} bytes",
        c.sent,
        c.dropped,
        uart.0
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

/// A UART that takes every byte at once (the board writes one data
/// register per byte as the USART empties).
struct NullUart(u32);

impl embedded_hal_nb::serial::ErrorType for NullUart {
    type Error = core::convert::Infallible;
}

impl embedded_hal_nb::serial::Write<u8> for NullUart {
    fn write(&mut self, b: u8) -> embedded_hal_nb::nb::Result<(), Self::Error> {
        black_box(b);
        self.0 = self.0.wrapping_add(1);
        Ok(())
    }
    fn flush(&mut self) -> embedded_hal_nb::nb::Result<(), Self::Error> {
        Ok(())
    }
}
