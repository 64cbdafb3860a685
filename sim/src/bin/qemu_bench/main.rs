//! Cortex-M4 cost benchmark, run under `qemu-system-arm -icount shift=0`
//! (`cargo xtask bench`). Prints executed instructions per fused 3-axis
//! sample for every fusion method with N = 4, per input sample for
//! streaming ADEV (10 octave τ) and E-DAVAR at λ2 = 256, 1024 and 4096, and
//! the RAM per axis of each. SysTick counts core clocks; the
//! instructions-per-tick ratio is calibrated on a loop of known length.
//!
//! One file per bench: `fusion`, `allan`, `davar`, `selftest`,
//! `timed_read` (one timed chip's FIFO read), and the board's whole loop
//! (`loops`: its fault scenarios A–L; `run_loop`: one scenario sample by
//! sample). The phase markers `cargo xtask bench-loop` counts between are
//! here (`mark`).
#![no_std]
#![no_main]

use core::hint::black_box;
use core::sync::atomic::Ordering;

use cortex_m_rt::{entry, exception};
use defmt_semihosting as _;

use gyro_array::algo::allan::stream::StreamAdev;
use gyro_array::algo::calib::{CalConfig, RelCal};
use gyro_array::algo::davar::{Davar, DavarConfig, EntropyKind, Placement, StepMode, Threshold};
use gyro_array::algo::fusion::{noise_probe, AxisState, Fusion, Method};
use gyro_sim::checks::methods;
use gyro_sim::qemu::{exit, instructions_per_tick, Ticks, WRAPS};
use gyro_sim::Rng;

const FRAMES: usize = 256;

mod allan;
mod davar;
mod fusion;
mod loops;
mod run_loop;
mod selftest;
mod timed_read;

use allan::*;
use davar::*;
use fusion::*;
use loops::*;
use run_loop::*;
use selftest::*;
use timed_read::*;

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

    // The trace build runs the board's loop only: `cargo xtask bench`
    // counts its instructions exactly from QEMU's execution trace.
    if TRACE {
        exit(bench_loops(&t, ipt))
    }
    if option_env!("BENCH_ONLY_TIMED").is_some() {
        exit(bench_timed_read(&t, ipt))
    }
    let mut rng = Rng::new(7);
    let mut ok = bench_fusion(&t, ipt, &mut rng);
    ok &= bench_allan(&t, ipt, &mut rng);
    for (input, step) in [("stationary", false), ("one variance step", true)] {
        defmt::info!("e-davar input: {=str}", input);
        let seg = |l2: usize| DavarConfig::segmented((l2 / 2) as u16, l2 as u16);
        ok &= bench_davar::<256, 11, 7, 0, 1>(&t, ipt, step, seg(256), "segmented");
        ok &= bench_davar::<1024, 35, 7, 0, 1>(&t, ipt, step, seg(1024), "segmented");
        ok &= bench_davar::<4096, 131, 7, 0, 1>(&t, ipt, step, seg(4096), "segmented");
        let centred = DavarConfig {
            lambda1: 512,
            lambda2: 1024,
            l_init: 1024,
            delta_l: 64,
            step: StepMode::Constant,
            entropy: EntropyKind::Temporal,
            threshold: Threshold::Auto { p_fa: 0.01 },
            placement: Placement::Centred,
            tau_octaves: 1,
        };
        ok &= bench_davar::<1024, 35, 7, 35, 1>(&t, ipt, step, centred, "centred temporal");
        // The board's tracker: three axes, the link's three τ (1, 16 and
        // 256 samples), λ2 = 1024, fed the same samples, hops staggered as
        // the tracker does it; and the same at every octave (9 τ).
        let link = gyro_array::pipeline::tracker::link_config(1024);
        ok &= bench_davar::<1024, 35, 3, 0, 1>(&t, ipt, step, link, "board tracker, one axis");
        ok &= bench_davar::<1024, 35, 3, 0, 3>(&t, ipt, step, link, "board tracker");
        ok &= bench_davar::<1024, 35, 9, 0, 3>(&t, ipt, step, seg(1024), "board tracker, 9 tau");
    }
    ok &= bench_selftest(&t, ipt, &mut rng);
    ok &= bench_timed_read(&t, ipt);
    ok &= bench_loops(&t, ipt);
    exit(ok)
}

const ALLAN_SAMPLES: usize = 8192;
const WARM: usize = 4096;

/// Built with the `bench-trace` feature: only the board's loop runs, with
/// its phase markers.
const TRACE: bool = cfg!(feature = "bench-trace");

/// Phase markers of the whole-loop bench for `cargo xtask bench`'s exact
/// count: each is a function of its own (a distinct volatile store, so
/// none is merged with another) whose entry the execution trace shows.
/// The count runs from `fuse` to `off` of each sample, in the phase last
/// marked; `scenario` starts a scenario, `sample` a sample. Called only in
/// the trace build, so the timed builds run without them.
mod mark {
    use core::ptr::{addr_of_mut, write_volatile};

    static mut MARK: u32 = 0;

    macro_rules! marker {
        ($name:ident, $sym:ident, $k:expr) => {
            #[inline(never)]
            #[no_mangle]
            #[allow(unsafe_code)]
            extern "C" fn $sym() {
                // SAFETY: a plain store to a static only this module
                // touches, on the one thread.
                unsafe { write_volatile(addr_of_mut!(MARK), $k) }
            }
            #[inline(always)]
            pub fn $name() {
                if super::TRACE {
                    $sym();
                }
            }
        };
    }
    marker!(scenario, bench_mark_scenario, 0x5ce7);
    marker!(sample, bench_mark_sample, 0x5a3b);
    marker!(fuse, bench_mark_fuse, 0xf05e);
    marker!(davar, bench_mark_davar, 0xda7a);
    marker!(link, bench_mark_link, 0x1137);
    marker!(off, bench_mark_off, 0x0ff0);
}
