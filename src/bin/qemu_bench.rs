//! Cortex-M4 cost benchmark, run under `qemu-system-arm -icount shift=0`
//! (`cargo xtask bench`). Prints executed instructions per fused 3-axis
//! sample for every fusion method with N = 4. SysTick counts core clocks;
//! the instructions-per-tick ratio is calibrated on a loop of known length.
#![no_std]
#![no_main]

use core::hint::black_box;
use core::sync::atomic::Ordering;

use cortex_m_rt::{entry, exception};
use defmt_semihosting as _;

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
    exit(ok)
}
