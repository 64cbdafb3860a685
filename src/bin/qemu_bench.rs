//! Cortex-M4 cost benchmark, run under `qemu-system-arm -icount shift=0`
//! (`cargo xtask bench`). Prints executed instructions per fused 3-axis
//! sample for every fusion method with N = 4, per input sample for
//! streaming ADEV (10 octave τ) and E-DAVAR at λ2 = 256, 1024 and 4096, and
//! the RAM per axis of each. SysTick counts core clocks; the
//! instructions-per-tick ratio is calibrated on a loop of known length.
#![no_std]
#![no_main]

use core::hint::black_box;
use core::sync::atomic::Ordering;

use cortex_m_rt::{entry, exception};
use defmt_semihosting as _;

use gyro_array::algo::allan::stream::StreamAdev;
use gyro_array::algo::davar::{Davar, DavarConfig, EntropyKind, Placement, StepMode, Threshold};
use gyro_array::algo::fusion::{AxisState, Fusion};
use gyro_array::board::qemu::{exit, instructions_per_tick, Ticks, WRAPS};
use gyro_array::checks::methods;
use gyro_array::emu::Rng;

const FRAMES: usize = 256;

#[exception]
fn SysTick() {
    WRAPS.fetch_add(1, Ordering::Release);
}

#[entry]
fn main() -> ! {
    let Some(cp) = cortex_m::Peripherals::take() else {
        exit(false)
    };
    let t = Ticks::start(cp.SYST);
    let ipt = instructions_per_tick(&t);
    defmt::info!("calibration: {=f32} instructions per SysTick tick", ipt);

    // Frames: 4 gyros × 3 axes, noise plus occasional spikes on gyro 1.
    let mut frames = [[[0.0f32; 4]; 3]; FRAMES];
    let mut rng = Rng::new(7);
    for f in frames.iter_mut() {
        for (a, axis) in f.iter_mut().enumerate() {
            for (i, y) in axis.iter_mut().enumerate() {
                *y = [95.0, -5.0, 0.0][a] + [0.1, 0.1, 0.1, 0.5][i] * rng.gaussian();
            }
            if rng.uniform() < 0.05 {
                axis[1] += 10.0;
            }
        }
    }

    // Loop overhead: the same loop with the fusion call replaced.
    let t0 = t.now();
    for f in frames.iter() {
        for axis in f.iter() {
            black_box(axis);
        }
    }
    let overhead = t.now() - t0;

    let mut ok = true;
    for (name, m) in methods() {
        let Ok(fusion) = Fusion::<4>::new(m) else {
            exit(false)
        };
        let mut st = [AxisState::<4>::default(); 3];
        // Warm up the state (memory windows, noise estimates) first.
        for f in frames.iter() {
            for (a, axis) in f.iter().enumerate() {
                let _ = black_box(fusion.fuse(&mut st[a], black_box(axis), 0b1111));
            }
        }
        let t0 = t.now();
        for f in frames.iter() {
            for (a, axis) in f.iter().enumerate() {
                let _ = black_box(fusion.fuse(&mut st[a], black_box(axis), 0b1111));
            }
        }
        let ticks = (t.now() - t0).saturating_sub(overhead);
        let per_sample = ticks as f32 * ipt / FRAMES as f32;
        defmt::info!(
            "bench fusion {=str}: {=u32} instructions per 3-axis sample (N = 4)",
            name,
            per_sample as u32
        );
        ok &= per_sample > 0.0;
    }

    // Noise samples for the Allan benches: WARM samples of white noise to
    // fill the windows, then ALLAN_SAMPLES measured ones: stationary, and
    // again with one variance step (×4) in the middle so the E-DAVAR window
    // really moves. The same input for every λ2.
    let mut steady = [0i16; WARM + ALLAN_SAMPLES];
    for x in steady.iter_mut() {
        *x = (100.0 * rng.gaussian()) as i16;
    }
    let mut samples = steady;
    let per = |ticks: u64, n: usize| ticks as f32 * ipt / n as f32;
    let loop_ticks = {
        let t0 = t.now();
        for &x in &samples[WARM..] {
            black_box(x as i32);
        }
        t.now() - t0
    };

    let Ok(mut adev) = StreamAdev::<10, 1024>::new() else {
        exit(false)
    };
    let t0 = t.now();
    for &x in &samples[WARM..] {
        ok &= adev.push(black_box(x as i32)).is_ok();
    }
    let ticks = (t.now() - t0).saturating_sub(loop_ticks);
    defmt::info!(
        "bench allan stream (10 octave tau): {=u32} instructions per sample, {=usize} B RAM per axis",
        per(ticks, ALLAN_SAMPLES) as u32,
        core::mem::size_of::<StreamAdev<10, 1024>>()
    );

    for (input, step) in [("stationary", false), ("one variance step", true)] {
        for (x, s) in samples.iter_mut().zip(steady.iter()) {
            *x = *s;
        }
        if step {
            for x in samples[WARM + ALLAN_SAMPLES / 2..].iter_mut() {
                *x *= 2;
            }
        }
        defmt::info!("e-davar input: {=str}", input);
        ok &= bench_davar::<256, 9>(&t, ipt, &samples, loop_ticks, Placement::ChangeAware);
        ok &= bench_davar::<1024, 33>(&t, ipt, &samples, loop_ticks, Placement::ChangeAware);
        ok &= bench_davar::<4096, 129>(&t, ipt, &samples, loop_ticks, Placement::ChangeAware);
        ok &= bench_davar::<1024, 33>(&t, ipt, &samples, loop_ticks, Placement::Centred);
    }
    ok &= bench_selftest(&t, ipt, &mut rng);
    exit(ok)
}

/// Instructions of the noise-health self-test on one 2048-sample block.
/// Not inlined: its 8 KB block must not sit in main's frame (the stack
/// also holds the E-DAVAR benches' windows).
#[inline(never)]
fn bench_selftest(t: &Ticks, ipt: f32, rng: &mut Rng) -> bool {
    let mut block = [0.0f32; gyro_array::pipeline::selftest::BLOCK];
    for v in block.iter_mut() {
        *v = 0.09 * rng.gaussian();
    }
    let t0 = t.now();
    let h = gyro_array::pipeline::selftest::noise_health(black_box(&block));
    let ticks = t.now() - t0;
    defmt::info!(
        "bench self-test (2048 samples, trend + Hurst + normality): {=u32} instructions, {=usize} B block buffer per gyro",
        (ticks as f32 * ipt) as u32,
        core::mem::size_of_val(&block)
    );
    h.is_ok_and(|h| h.stationary)
}

const ALLAN_SAMPLES: usize = 8192;
const WARM: usize = 4096;
/// E-DAVAR τ grid: m = 1 … 64 at every λ2 (2^7 ≤ λ1 = λ2/2 at λ2 = 256).
const DAVAR_TAUS: usize = 7;

/// Instructions per sample of E-DAVAR with λ2 = CAP, λ1 = λ2/2, after the
/// window has filled.
#[inline(never)]
fn bench_davar<const CAP: usize, const FRAMES: usize>(
    t: &Ticks,
    ipt: f32,
    samples: &[i16],
    loop_ticks: u64,
    placement: Placement,
) -> bool {
    let cfg = DavarConfig {
        lambda1: (CAP / 2) as u16,
        lambda2: CAP as u16,
        l_init: CAP as u16,
        delta_l: (CAP / 16) as u16,
        step: StepMode::Constant,
        entropy: EntropyKind::Temporal,
        threshold: Threshold::Auto { p_fa: 0.01 },
        placement,
    };
    let Ok(mut d) = Davar::<CAP, FRAMES, DAVAR_TAUS>::new(cfg) else {
        return false;
    };
    let mut ok = true;
    for &x in &samples[WARM - CAP..WARM] {
        ok &= d.push(x as i32).is_ok();
    }
    let t0 = t.now();
    for &x in &samples[WARM..] {
        ok &= d.push(black_box(x as i32)).is_ok();
    }
    let ticks = (t.now() - t0).saturating_sub(loop_ticks);
    let name = match placement {
        Placement::ChangeAware => "change-aware",
        Placement::Centred => "centred",
    };
    defmt::info!(
        "bench e-davar {=str} lambda2 = {=usize} (7 octave tau): {=u32} instructions per sample, {=usize} B RAM per axis",
        name,
        CAP,
        (ticks as f32 * ipt / ALLAN_SAMPLES as f32) as u32,
        core::mem::size_of::<Davar<CAP, FRAMES, DAVAR_TAUS>>()
    );
    let est = d.estimate();
    ok && est.avar[0] > 0.0
}
