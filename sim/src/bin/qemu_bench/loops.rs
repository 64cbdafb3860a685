//! The board's whole loop in its fault scenarios A–L: the plans, and the
//! scenarios run polled (A–J) and timed (K, L).

use super::*;

/// The board's loop under four fault scenarios: A and B on a still board
/// with the variance step of the emulated motion at 3 s, C and D on other
/// boards in motion.
/// Scenario C's faults (sample, gyro, fault), which D repeats.
pub(super) const C_FAULTS: [(u32, usize, gyro_sim::Fault); 12] = {
    use gyro_sim::Fault;
    [
        (1200, 3, Fault::Saturated),
        (1500, 3, Fault::None),
        (
            2500,
            4,
            Fault::Spikes {
                prob: 0.1,
                magnitude_dps: 100.0,
            },
        ),
        (3500, 4, Fault::None),
        (4200, 1, Fault::FrameBitError { prob: 0.2 }),
        (4700, 1, Fault::None),
        (5000, 0, Fault::Stuck),
        (5100, 2, Fault::Stuck),
        (6000, 0, Fault::None),
        (6000, 2, Fault::None),
        (6800, 3, Fault::PoweredOff),
        (6900, 3, Fault::None),
    ]
};

pub(super) fn bench_loops(t: &Ticks, ipt: f32) -> bool {
    use gyro_sim::{Fault, RateProfile};
    let mut ok = bench_loop(
        t,
        ipt,
        "faults A: gyro 2 stuck from 1.5 s, ADXRS453 bit errors 2.0-2.2 s, gyro 1 powered off 4.5-4.6 s",
        &[
            (1500, 2, Fault::Stuck),
            (2000, 4, Fault::BitErrors { prob: 0.05 }),
            (2200, 4, Fault::None),
            (4500, 1, Fault::PoweredOff),
            (4600, 1, Fault::None),
        ],
        true,
    );
    ok &= bench_loop(
        t,
        ipt,
        "faults B: gyro 0 spikes 1.0-2.5 s, gyros 3 and 1 stuck 3.0/3.2-4.5 s, gyro 2 bit errors 5-6 s, ADXRS453 silent 6.5-7 s",
        &[
            (1000, 0, Fault::Spikes { prob: 0.05, magnitude_dps: 50.0 }),
            (2500, 0, Fault::None),
            (3000, 3, Fault::Stuck),
            (3200, 1, Fault::Stuck),
            (4500, 3, Fault::None),
            (4500, 1, Fault::None),
            (5000, 2, Fault::BitErrors { prob: 0.05 }),
            (6000, 2, Fault::None),
            (6500, 4, Fault::NoResponse),
            (7000, 4, Fault::None),
        ],
        false,
    );
    // A third board, motion and fault plan, none of which the loop was
    // tuned on (added after it met its target on A and B).
    ok &= bench_loop_on(
        t,
        ipt,
        "faults C: another board (seed 17) turning at 60 deg/s under a 5 Hz, 20 deg/s sway; gyro 3 saturated 1.2-1.5 s, ADXRS453 spiking 100 deg/s 2.5-3.5 s, gyro 1 frame bit errors 4.2-4.7 s, gyros 0 and 2 stuck 5.0/5.1-6.0 s, gyro 3 powered off 6.8-6.9 s",
        RateProfile {
            base_dps: [-30.0, 12.0, 60.0],
            sine_dps: [20.0, 20.0, 20.0],
            sine_hz: 5.0,
            sine_start_s: 2.0,
        },
        17,
        &C_FAULTS,
        false,
    );
    // D: C's faults and two more.
    let mut d_plan = [(0, 0, Fault::None); C_FAULTS.len() + 4];
    d_plan[..4].copy_from_slice(&[
        (700, 2, Fault::PoweredOff),
        (760, 2, Fault::None),
        (
            3000,
            1,
            Fault::Spikes {
                prob: 0.2,
                magnitude_dps: 30.0,
            },
        ),
        (3900, 1, Fault::None),
    ]);
    d_plan[4..].copy_from_slice(&C_FAULTS);
    // Untuned, as every scenario after B: gyro 1 spiking on a fifth of the
    // samples under a 100 deg/s turn works fusion's consensus gate.
    ok &= bench_loop_on(
        t,
        ipt,
        "faults D: another board (seed 29) turning at 80/-45/-95 deg/s under a 0.7 Hz sway up to 35 deg/s; gyro 2 powered off 0.70-0.76 s, gyro 3 saturated 1.2-1.5 s, gyro 1 spiking 30 deg/s on 20 % of samples 3.0-3.9 s, ADXRS453 spiking 100 deg/s 2.5-3.5 s, gyro 1 frame bit errors 4.2-4.7 s, gyros 0 and 2 stuck 5.0/5.1-6.0 s, gyro 3 powered off 6.8-6.9 s",
        RateProfile {
            base_dps: [80.0, -45.0, -95.0],
            sine_dps: [10.0, 35.0, 5.0],
            sine_hz: 0.7,
            sine_start_s: 0.5,
        },
        29,
        &d_plan,
        false,
    );
    // A fifth, untuned: two chips spiking at once (the consensus gate on
    // every axis), the ADXRS453 silent, a chip power-cycled, another
    // stuck, under a 100 deg/s turn with a 12 Hz vibration. Its fallbacks
    // restarted the noise tracker's windows 22 times (now 4: the others
    // are bridged), and it broke the 10 000 at 10 113 where a restarted
    // window summed its first term of a long τ from scratch (now gathered
    // as the samples come).
    ok &= bench_loop_on(
        t,
        ipt,
        "faults E: another board (seed 41) turning at 100/-70/30 deg/s under a 12 Hz, 8 deg/s vibration; gyros 0 and 3 spiking 40 deg/s on 10 % of samples 1.0-2.0 s, ADXRS453 silent 2.2-2.4 s, gyro 2 frame bit errors 2.5-3.5 s, gyro 1 powered off 4.00-4.05 s, ADXRS453 stuck 5.0-5.5 s, gyro 0 bit errors 6.0-7.0 s with gyro 3 spiking 20 deg/s on 20 % 6.5-7.5 s",
        RateProfile {
            base_dps: [100.0, -70.0, 30.0],
            sine_dps: [8.0, 8.0, 8.0],
            sine_hz: 12.0,
            sine_start_s: 0.3,
        },
        41,
        &[
            (1000, 0, Fault::Spikes { prob: 0.1, magnitude_dps: 40.0 }),
            (1000, 3, Fault::Spikes { prob: 0.1, magnitude_dps: 40.0 }),
            (2000, 0, Fault::None),
            (2000, 3, Fault::None),
            (2200, 4, Fault::NoResponse),
            (2400, 4, Fault::None),
            (2500, 2, Fault::FrameBitError { prob: 0.3 }),
            (3500, 2, Fault::None),
            (4000, 1, Fault::PoweredOff),
            (4050, 1, Fault::None),
            (5000, 4, Fault::Stuck),
            (5500, 4, Fault::None),
            (6000, 0, Fault::BitErrors { prob: 0.1 }),
            (6500, 3, Fault::Spikes { prob: 0.2, magnitude_dps: 20.0 }),
            (7000, 0, Fault::None),
            (7500, 3, Fault::None),
        ],
        false,
    );
    // Two chips stuck at once under a slow, wide sway work fusion's regate
    // and general path until they are flagged; two chips power-cycled
    // give an E-DAVAR span many changes to place.
    ok &= bench_loop_on(
        t,
        ipt,
        "faults F: another board (seed 53) swaying 90/60/100 deg/s at 0.2 Hz; ADXRS453 powered off 0.50-0.52 s and 1.50-1.53 s, gyro 0 saturated 2.0-2.1 s, gyros 2 and 3 stuck together 3.0-3.8 s with gyro 1 bit errors 3.1-3.9 s, ADXRS453 spiking 200 deg/s with gyro 0 frame bit errors 5.0-6.5 s, gyros 1 and 2 powered off 7.00-7.04/7.06 s",
        RateProfile {
            base_dps: [0.0, 20.0, -10.0],
            sine_dps: [90.0, 60.0, 100.0],
            sine_hz: 0.2,
            sine_start_s: 0.0,
        },
        53,
        &[
            (500, 4, Fault::PoweredOff),
            (520, 4, Fault::None),
            (1500, 4, Fault::PoweredOff),
            (1530, 4, Fault::None),
            (2000, 0, Fault::Saturated),
            (2100, 0, Fault::None),
            (3000, 2, Fault::Stuck),
            (3000, 3, Fault::Stuck),
            (3100, 1, Fault::BitErrors { prob: 0.1 }),
            (3800, 2, Fault::None),
            (3800, 3, Fault::None),
            (3900, 1, Fault::None),
            (5000, 4, Fault::Spikes { prob: 0.05, magnitude_dps: 200.0 }),
            (5000, 0, Fault::FrameBitError { prob: 0.1 }),
            (6500, 4, Fault::None),
            (6500, 0, Fault::None),
            (7000, 1, Fault::PoweredOff),
            (7000, 2, Fault::PoweredOff),
            (7040, 1, Fault::None),
            (7060, 2, Fault::None),
        ],
        false,
    );
    // A seventh, untuned, added after F was fixed: a steady 100 deg/s turn
    // on z with a 3 Hz sway on x and y; two ICM-42688-Ps stuck together
    // while a third spikes, the ADXRS453 garbling frames while a chip
    // power-cycles, the ADXRS453 saturated, a chip silent.
    ok &= bench_loop_on(
        t,
        ipt,
        "faults G: another board (seed 67) turning at 100 deg/s on z with a 3 Hz, 30 deg/s sway on x and y; gyro 3 spiking 100 deg/s on 10 % of samples 1.0-2.0 s, gyros 0 and 1 stuck together 1.5-2.5 s, ADXRS453 frame bit errors 4.0-5.0 s with gyro 2 powered off 4.00-4.06 s, ADXRS453 saturated 6.0-6.3 s, gyro 1 silent 7.0-7.5 s",
        RateProfile {
            base_dps: [0.0, 0.0, 100.0],
            sine_dps: [30.0, 30.0, 0.0],
            sine_hz: 3.0,
            sine_start_s: 0.0,
        },
        67,
        &[
            (1000, 3, Fault::Spikes { prob: 0.1, magnitude_dps: 100.0 }),
            (1500, 0, Fault::Stuck),
            (1500, 1, Fault::Stuck),
            (2000, 3, Fault::None),
            (2500, 0, Fault::None),
            (2500, 1, Fault::None),
            (4000, 4, Fault::FrameBitError { prob: 0.1 }),
            (4000, 2, Fault::PoweredOff),
            (4060, 2, Fault::None),
            (5000, 4, Fault::None),
            (6000, 4, Fault::Saturated),
            (6300, 4, Fault::None),
            (7000, 1, Fault::NoResponse),
            (7500, 1, Fault::None),
        ],
        false,
    );
    // An eighth, untuned, added with G: a 1 Hz sway of 100 deg/s on every
    // axis (0.6 deg/s from one sample to the next at its fastest); the
    // ADXRS453 stuck, two chips spiking at once, a chip power-cycled, two
    // with bit errors, one saturated, three of the four ICM-42688-Ps
    // stuck together (no majority on x and y), a chip silent.
    ok &= bench_loop_on(
        t,
        ipt,
        "faults H: another board (seed 79) swaying 100 deg/s at 1 Hz on every axis; ADXRS453 stuck 1.0-1.5 s, gyros 1 and 3 spiking 50 deg/s on 5 % of samples 2.0-3.0 s, gyro 0 powered off 3.50-3.55 s, gyros 0 and 2 bit errors 4.0-5.0 s, gyro 1 saturated 5.5-5.8 s, gyros 0, 1 and 2 stuck together 6.5-6.7 s, gyro 3 silent 7.2-7.4 s",
        RateProfile {
            base_dps: [0.0, 0.0, 0.0],
            sine_dps: [100.0, 100.0, 100.0],
            sine_hz: 1.0,
            sine_start_s: 0.0,
        },
        79,
        &[
            (1000, 4, Fault::Stuck),
            (1500, 4, Fault::None),
            (2000, 1, Fault::Spikes { prob: 0.05, magnitude_dps: 50.0 }),
            (2000, 3, Fault::Spikes { prob: 0.05, magnitude_dps: 50.0 }),
            (3000, 1, Fault::None),
            (3000, 3, Fault::None),
            (3500, 0, Fault::PoweredOff),
            (3550, 0, Fault::None),
            (4000, 2, Fault::BitErrors { prob: 0.05 }),
            (4000, 0, Fault::BitErrors { prob: 0.05 }),
            (5000, 2, Fault::None),
            (5000, 0, Fault::None),
            (5500, 1, Fault::Saturated),
            (5800, 1, Fault::None),
            (6500, 0, Fault::Stuck),
            (6500, 1, Fault::Stuck),
            (6500, 2, Fault::Stuck),
            (6700, 0, Fault::None),
            (6700, 1, Fault::None),
            (6700, 2, Fault::None),
            (7200, 3, Fault::NoResponse),
            (7400, 3, Fault::None),
        ],
        false,
    );
    // A steady 100 deg/s turn on x under a 2.5 Hz sway up to 80 deg/s; a
    // chip spiking past the rate limit, the ADXRS453 garbling half its
    // frames, two chips power-cycled together and then stuck together
    // beside a third with bit errors, the ADXRS453 silent for 2 s, chips
    // saturated, stuck and spiking at once. The E-DAVAR's placement after
    // the two stuck chips come back meets fifteen changes in a span.
    ok &= bench_loop_on(
        t,
        ipt,
        "faults I: another board (seed 97) turning at -100 deg/s on x with a 2.5 Hz sway of 15/50/80 deg/s; gyro 2 spiking 300 deg/s on 30 % of samples 0.8-1.6 s, ADXRS453 frame bit errors on half its frames 1.2-2.6 s, gyros 1 and 3 powered off 3.000-3.020/3.025 s, gyro 0 bit errors 4.2-5.3 s with gyros 1 and 3 stuck together 4.3-5.2 s, ADXRS453 silent 5.8-7.8 s, gyro 0 saturated 6.20-6.25 s, gyro 2 stuck with gyro 3 spiking 60 deg/s on 10 % 6.9-7.3 s",
        RateProfile {
            base_dps: [-100.0, 40.0, 0.0],
            sine_dps: [15.0, 50.0, 80.0],
            sine_hz: 2.5,
            sine_start_s: 0.2,
        },
        97,
        &[
            (800, 2, Fault::Spikes { prob: 0.3, magnitude_dps: 300.0 }),
            (1200, 4, Fault::FrameBitError { prob: 0.5 }),
            (1600, 2, Fault::None),
            (2600, 4, Fault::None),
            (3000, 1, Fault::PoweredOff),
            (3000, 3, Fault::PoweredOff),
            (3020, 1, Fault::None),
            (3025, 3, Fault::None),
            (4200, 0, Fault::BitErrors { prob: 0.1 }),
            (4300, 1, Fault::Stuck),
            (4300, 3, Fault::Stuck),
            (5200, 1, Fault::None),
            (5200, 3, Fault::None),
            (5300, 0, Fault::None),
            (5800, 4, Fault::NoResponse),
            (6200, 0, Fault::Saturated),
            (6250, 0, Fault::None),
            (6900, 2, Fault::Stuck),
            (6900, 3, Fault::Spikes { prob: 0.1, magnitude_dps: 60.0 }),
            (7300, 2, Fault::None),
            (7300, 3, Fault::None),
            (7800, 4, Fault::None),
        ],
        false,
    );
    // A tenth, untuned, added with I: a 100 deg/s turn on y under a
    // 40 Hz vibration; all four ICM-42688-Ps with bit errors at once, the
    // ADXRS453 reporting a chip fault, a chip powered off for 2 s, another
    // reading the wrong identity, small dense spikes, a chip saturated
    // while the ADXRS453 sticks, two chips silent together. Its first run
    // (in a scratch copy of the bench) read 9 994, where a calibration
    // solve for a chip just warmed up met an E-DAVAR segmentation row.
    ok &= bench_loop_on(
        t,
        ipt,
        "faults J: another board (seed 113) turning at 100 deg/s on y under a 40 Hz, 5 deg/s vibration; gyros 0-3 bit errors 0.6-1.6 s, ADXRS453 chip fault 2.0-2.6 s, gyro 2 powered off 3.0-5.0 s, gyro 0 wrong identity 3.5-3.9 s, gyro 1 spiking 5 deg/s on half its samples 4.2-4.8 s, gyro 3 saturated with the ADXRS453 stuck 5.6-6.1 s, gyros 0 and 1 silent 6.800-6.850/6.870 s",
        RateProfile {
            base_dps: [5.0, 100.0, -20.0],
            sine_dps: [5.0, 5.0, 5.0],
            sine_hz: 40.0,
            sine_start_s: 0.0,
        },
        113,
        &[
            (600, 0, Fault::BitErrors { prob: 0.02 }),
            (600, 1, Fault::BitErrors { prob: 0.02 }),
            (600, 2, Fault::BitErrors { prob: 0.02 }),
            (600, 3, Fault::BitErrors { prob: 0.02 }),
            (1600, 0, Fault::None),
            (1600, 1, Fault::None),
            (1600, 2, Fault::None),
            (1600, 3, Fault::None),
            (2000, 4, Fault::ChipFault),
            (2600, 4, Fault::None),
            (3000, 2, Fault::PoweredOff),
            (3500, 0, Fault::WrongId),
            (3900, 0, Fault::None),
            (4200, 1, Fault::Spikes { prob: 0.5, magnitude_dps: 5.0 }),
            (4800, 1, Fault::None),
            (5000, 2, Fault::None),
            (5600, 3, Fault::Saturated),
            (5600, 4, Fault::Stuck),
            (6100, 3, Fault::None),
            (6100, 4, Fault::None),
            (6800, 0, Fault::NoResponse),
            (6800, 1, Fault::NoResponse),
            (6850, 0, Fault::None),
            (6870, 1, Fault::None),
        ],
        false,
    );
    // The board as it runs: the chips on their own clocks, read through
    // their FIFOs and aligned to one stated instant (`TimedIcm`).
    ok &= bench_timed_loop_on(
        t,
        ipt,
        "faults K: four ICM-42688-P on their own clocks (PLLs +0.8 %, -1 %, +0.3 %, one on its RC oscillator at -7 %), FIFO at 4 kHz, swaying 95 deg/s at 2 Hz; gyro 2 stuck 1.5-2.5 s, gyro 1 powered off 4.5-4.6 s, gyro 3 spiking 50 deg/s on 5 % of samples 6.0-7.0 s",
        RateProfile {
            base_dps: [0.0, 10.0, -20.0],
            sine_dps: [95.0, 60.0, 40.0],
            sine_hz: 2.0,
            sine_start_s: 0.0,
        },
        91,
        false,
        [0.008, -0.01, 0.003, -0.07],
        &[
            (1500, 2, Fault::Stuck),
            (2500, 2, Fault::None),
            (4500, 1, Fault::PoweredOff),
            (4600, 1, Fault::None),
            (6000, 3, Fault::Spikes { prob: 0.05, magnitude_dps: 50.0 }),
            (7000, 3, Fault::None),
        ],
    );
    // The chips on the board's CLKIN, one power-cycled (a new phase),
    // under a sway that crosses 100 deg/s.
    ok &= bench_timed_loop_on(
        t,
        ipt,
        "faults L: four ICM-42688-P on the board's 32 kHz CLKIN, FIFO at 4 kHz, swaying 130 deg/s at 1 Hz on x (crossing 100 deg/s) over a 30 deg/s turn on z; gyro 0 powered off 2.00-2.05 s (back at a new phase), gyro 1 bit errors 3.0-3.5 s, gyro 3 stuck 5.0-5.5 s, gyro 2 saturated 6.0-6.2 s",
        RateProfile {
            base_dps: [0.0, -5.0, 30.0],
            sine_dps: [130.0, 40.0, 20.0],
            sine_hz: 1.0,
            sine_start_s: 0.0,
        },
        103,
        true,
        [0.0; 4],
        &[
            (2000, 0, Fault::PoweredOff),
            (2050, 0, Fault::None),
            (3000, 1, Fault::BitErrors { prob: 0.05 }),
            (3500, 1, Fault::None),
            (5000, 3, Fault::Stuck),
            (5500, 3, Fault::None),
            (6000, 2, Fault::Saturated),
            (6200, 2, Fault::None),
        ],
    );
    ok
}

/// Ticks of an empty `t.now()` pair.
/// Ticks of an empty `t.now()` pair, averaged over 4096 (one pair is a
/// fraction of a tick, so a single reading says 0 or 1): what every timed
/// interval holds besides the code it times.
pub(super) fn pair_cost(t: &Ticks) -> f32 {
    const PAIRS: u32 = 4096;
    let mut sum = 0u64;
    for _ in 0..PAIRS {
        let t0 = t.now();
        sum += t.now() - t0;
    }
    sum as f32 / PAIRS as f32
}

/// An interval of `ticks` less the timer's own `pair` cost (not below 0).
pub(super) fn net(ticks: u64, pair: f32) -> f32 {
    (ticks as f32 - pair).max(0.0)
}

/// The board's whole per-sample loop on the emulated array, every sample
/// timed: read the five gyros through the real drivers (over the emulated
/// SPI bus: its byte exchanges stand in for the SPI peripheral's register
/// accesses and bus time on the board), calibrate and fuse three axes,
/// push the three E-DAVARs (λ2 = 1024, the board's tracker), build the
/// link frame and queue it. As on the board, the status frame (every
/// second) and the UART's feeding happen in the idle time after the
/// sample, and are timed on their own. Over 8000 samples with the faults
/// of `plan` (sample, gyro, fault) and a variance step (a 250 Hz vibration
/// of 0.3 °/s from 3 s). The sensors' own sample-period update (`advance`)
/// is outside the timing. `all`: also print the idle-time figures.
pub(super) fn bench_loop(
    t: &Ticks,
    ipt: f32,
    faults: &str,
    plan: &[(u32, usize, gyro_sim::Fault)],
    all: bool,
) -> bool {
    // A still board but for a small 250 Hz vibration from 3 s: the
    // E-DAVARs' variance step.
    let profile = gyro_sim::RateProfile {
        base_dps: [0.5, -0.2, 10.0],
        sine_dps: [0.3, 0.3, 0.3],
        sine_hz: 250.0,
        sine_start_s: 3.0,
    };
    bench_loop_on(t, ipt, faults, profile, 3, plan, all)
}

/// Whether the loop scenario described by `faults` ("faults X: ...") is
/// among those named at build time in `BENCH_SCENARIOS` (letters, e.g.
/// `KL`); all when it is unset. Lets one scenario be counted alone.
pub(super) fn selected(faults: &str) -> bool {
    match (option_env!("BENCH_SCENARIOS"), faults.as_bytes().get(7)) {
        (Some(set), Some(c)) => set.as_bytes().contains(c),
        _ => true,
    }
}

/// [`bench_loop`] on the emulated board of `seed` moving as `profile`.
#[inline(never)]
#[allow(unsafe_code)]
pub(super) fn bench_loop_on(
    t: &Ticks,
    ipt: f32,
    faults: &str,
    profile: gyro_sim::RateProfile,
    seed: u64,
    plan: &[(u32, usize, gyro_sim::Fault)],
    all: bool,
) -> bool {
    if !selected(faults) {
        return true;
    }
    use core::cell::RefCell;
    use gyro_array::algo::fusion::AdaptiveConfig;
    use gyro_array::drivers::Gyro;
    use gyro_array::pipeline::startup::start_array;
    use gyro_array::pipeline::tracker::{self, NoiseTracker};
    use gyro_array::pipeline::{Pipeline, PipelineConfig};
    use gyro_sim::{board_array, board_drivers, with_bus, BoardDrivers, CsLine, EmuBus, EmuDelay};

    let cs: [CsLine; 5] = Default::default();
    let bus = RefCell::new(EmuBus::new(board_array(profile, seed), &cs));
    let dt = 1e-3;
    let mut delay = EmuDelay::new(&bus, dt);
    let BoardDrivers {
        icm: [mut g0, mut g1, mut g2, mut g3],
        adx: mut g4,
    } = board_drivers(&bus, &cs);
    let Ok(mut pipe) = Pipeline::<5>::new(
        PipelineConfig::default(),
        gyro_array::algo::fusion::Method::Adaptive(AdaptiveConfig::default()),
    ) else {
        exit(false)
    };
    start_array(
        [&mut g0, &mut g1, &mut g2, &mut g3],
        &mut g4,
        &mut delay,
        Some(20),
        &mut pipe,
    );
    let mut slot = core::mem::MaybeUninit::<NoiseTracker<1024, 35, 3>>::uninit();
    let Ok(noise) = NoiseTracker::init_in(&mut slot, tracker::link_config(1024)) else {
        exit(false)
    };
    // The reads alone (drivers and the emulated SPI exchange), fault-free:
    // the share of "read + fuse" that is bus traffic.
    let pair = pair_cost(t);
    let mut read_ticks = 0.0f32;
    const READS: u32 = 500;
    for _ in 0..READS {
        with_bus(&bus, |b| b.advance(dt));
        let t0 = t.now();
        for g in [&mut g0 as &mut dyn Gyro, &mut g1, &mut g2, &mut g3, &mut g4] {
            let _ = black_box(g.read());
        }
        read_ticks += net(t.now() - t0, pair);
    }
    defmt::info!(
        "bench whole loop: reading the 5 gyros alone (drivers + emulated SPI): mean {=u32} instructions",
        (read_ticks * ipt / READS as f32) as u32
    );
    // From here the emulated bus times its own operations: the chip models
    // stand in for the SPI peripheral and the silicon, so their
    // instructions are not the firmware's (on the board the CPU waits for
    // the bus instead: the bus time is printed with the figures).
    with_bus(&bus, |b| b.clock = Some(gyro_sim::qemu::ticks));
    let meter = || with_bus(&bus, |b| (b.meter, b.bytes)).unwrap_or_default();
    let meter = &meter;
    run_loop(
        t,
        ipt,
        faults,
        all,
        &mut pipe,
        noise,
        meter,
        |n| {
            with_bus(&bus, |b| {
                for &(at, chip, fault) in plan {
                    if at == n {
                        if let Some(c) = b.chips.get_mut(chip) {
                            c.set_fault(fault);
                        }
                    }
                }
                b.advance(dt);
            });
            u64::from(n) * 1000
        },
        |sample| {
            let mut gyros: [&mut dyn Gyro; 5] = [&mut g0, &mut g1, &mut g2, &mut g3, &mut g4];
            sample(&mut gyros)
        },
    )
}

/// The whole loop as the board runs it on chips that keep their own
/// time: four ICM-42688-P (`clkin`: on the board's 32 kHz CLKIN; else on
/// their own PLLs, `pll` off) read through their FIFOs at 4 kHz by
/// [`TimedIcm`] (INT1 captures, clock tracker, aligner), each sample at
/// one stated instant 1 670 µs behind the read, fused on 3 axes, the
/// E-DAVARs and the link as in [`bench_loop_on`]. The chips' paths are
/// the delay model (`gyro_sim::PathModel::Delay`: the 32 kHz filters are too
/// slow for QEMU). The ADXRS453 is not read: at the array's instant its
/// rate is always late (docs/timing.md).
#[allow(clippy::too_many_arguments)]
#[inline(never)]
pub(super) fn bench_timed_loop_on(
    t: &Ticks,
    ipt: f32,
    faults: &str,
    profile: gyro_sim::RateProfile,
    seed: u64,
    clkin: bool,
    pll: [f64; 4],
    plan: &[(u32, usize, gyro_sim::Fault)],
) -> bool {
    if !selected(faults) {
        return true;
    }
    use core::cell::RefCell;
    use gyro_array::algo::fusion::{AdaptiveConfig, Method};
    use gyro_array::drivers::icm42688::{board_fifo, ClockInput, Icm42688};
    use gyro_array::drivers::Gyro;
    use gyro_array::pipeline::timed::TimedIcm;
    use gyro_array::pipeline::tracker::{self, NoiseTracker};
    use gyro_array::pipeline::{Pipeline, PipelineConfig};
    use gyro_sim::timing::ClockParams;
    use gyro_sim::{
        emu_device, timed_array, with_bus, ChipTiming, CsLine, EmuBus, EmuCapture, EmuDelay,
        PathModel,
    };
    let chips = timed_array(
        profile,
        seed,
        core::array::from_fn(|i| ChipTiming {
            pll: ClockParams {
                offset: pll[i],
                drift_per_s: 1e-5,
                wander: 2e-4,
                wander_period_s: 3.0 + i as f64,
            },
            path: PathModel::Delay,
            ..ChipTiming::pll(0.0)
        }),
    );
    let cs: [CsLine; 4] = Default::default();
    let bus = RefCell::new(EmuBus::new(chips, &cs));
    // Each byte takes its time at the board's SPI clock, so pulses fall
    // inside bursts and the capture's pairing reads the count again where
    // the board would.
    with_bus(&bus, |b| {
        b.spi_byte_s = 8.0 / f64::from(gyro_array::pipeline::timed::BOARD_SPI_ICM_HZ)
    });
    if clkin {
        with_bus(&bus, |b| b.clkin_hz = Some(32_000.0));
    }
    let mut delay = EmuDelay::new(&bus, 1e-3);
    let cfg = board_fifo(if clkin {
        ClockInput::ClkIn
    } else {
        ClockInput::Internal
    });
    let Ok(mut pipe) = Pipeline::<4>::new(
        PipelineConfig::default(),
        Method::Adaptive(AdaptiveConfig::default()),
    ) else {
        exit(false)
    };
    let dev = |i: usize| emu_device(&bus, &cs[i]);
    let timed = |i: usize, pipe: &mut Pipeline<4>, delay: &mut EmuDelay<'_, '_, 4>| {
        let mut g = Icm42688::new(dev(i));
        if g.init(delay, cfg).is_err() {
            defmt::warn!("timed loop bench: gyro {=usize} failed its init", i);
            pipe.mark_init_failed(i);
        }
        TimedIcm::new(
            g,
            EmuCapture {
                bus: &bus,
                index: i,
            },
        )
    };
    let (mut g0, mut g1, mut g2, mut g3) = (
        timed(0, &mut pipe, &mut delay),
        timed(1, &mut pipe, &mut delay),
        timed(2, &mut pipe, &mut delay),
        timed(3, &mut pipe, &mut delay),
    );
    // One start for all (the chips set up first ran while the others were).
    for g in [&mut g0, &mut g1, &mut g2, &mut g3] {
        let _ = g.driver().flush_fifo();
    }
    let mut slot = core::mem::MaybeUninit::<NoiseTracker<1024, 35, 3>>::uninit();
    let Ok(noise) = NoiseTracker::init_in(&mut slot, tracker::link_config(1024)) else {
        exit(false)
    };
    with_bus(&bus, |b| b.clock = Some(gyro_sim::qemu::ticks));
    let meter = || with_bus(&bus, |b| (b.meter, b.bytes)).unwrap_or_default();
    let ok = run_loop(
        t,
        ipt,
        faults,
        false,
        &mut pipe,
        noise,
        &meter,
        |n| {
            with_bus(&bus, |b| {
                for &(at, chip, fault) in plan {
                    if at == n {
                        if let Some(c) = b.chips.get_mut(chip) {
                            c.set_fault(fault);
                        }
                    }
                }
                b.advance(1e-3);
                // The captures' µs at the read (TIM5's on the board): the
                // sample task aims the chips from it.
                u64::from(b.timer_us())
            })
            .unwrap_or(0)
        },
        |sample| {
            // The board's sample task aims them at the tick's instant.
            let mut gyros: [&mut dyn Gyro; 4] = [&mut g0, &mut g1, &mut g2, &mut g3];
            sample(&mut gyros)
        },
    );
    let late: [u32; 4] = [
        g0.counters.late,
        g1.counters.late,
        g2.counters.late,
        g3.counters.late,
    ];
    defmt::info!(
        "bench whole loop, {=str}: late answers per chip {=[?]}, FIFO overflows {=[?]}",
        faults,
        late,
        [
            g0.counters.overflows,
            g1.counters.overflows,
            g2.counters.overflows,
            g3.counters.overflows
        ]
    );
    ok
}
