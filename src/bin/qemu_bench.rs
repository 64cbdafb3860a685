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
use gyro_array::algo::calib::{CalConfig, RelCal};
use gyro_array::algo::davar::{Davar, DavarConfig, EntropyKind, Placement, StepMode, Threshold};
use gyro_array::algo::fusion::{noise_probe, AxisState, Fusion, Method};
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

    // The trace build runs the board's loop only: `cargo xtask bench`
    // counts its instructions exactly from QEMU's execution trace.
    if TRACE {
        exit(bench_loops(&t, ipt))
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

/// One ICM-42688-P's read, on the emulated bus with the bus's own time
/// metered out: polled (the data registers, as the board's loop reads
/// them today) against the timed path (`TimedIcm`: the FIFO at 4 kHz, four
/// samples a read, the INT1 capture, the clock tracker, the moving mean
/// and the interpolation to the stated instant). The chip keeps its own
/// time on a clock 0.3 % fast, so reads find one, two or three samples.
fn bench_timed_read(t: &Ticks, ipt: f32) -> bool {
    use core::cell::RefCell;
    use gyro_array::drivers::icm42688::{ClockInput, Config, Icm42688};
    use gyro_array::drivers::Gyro;
    use gyro_array::emu::{
        emu_device, with_bus, Chip, ChipTiming, CsLine, EmuBus, EmuCapture, EmuDelay,
        Icm42688Model, NoiseParams, RateProfile,
    };
    use gyro_array::pipeline::timed::TimedIcm;

    const READS: u32 = 400;
    let mut ok = true;
    for (timed, fifo_only) in [(false, false), (true, true), (true, false)] {
        let cs: [CsLine; 1] = Default::default();
        let mut chip = Icm42688Model::new(NoiseParams::ICM42688, RateProfile::constant(2.0), 3, 70);
        if timed {
            chip.set_timing(Some(ChipTiming::pll(0.003)));
        }
        let bus = RefCell::new(EmuBus::new([Chip::Icm(chip)], &cs));
        let mut delay = EmuDelay::new(&bus, 1e-3);
        let dev = emu_device(&bus, &cs[0]);
        let mut g = Icm42688::new(dev);
        let cfg = if timed {
            Config::board_fifo(ClockInput::Internal)
        } else {
            Config::default()
        };
        if g.init(&mut delay, cfg).is_err() {
            defmt::error!("timed read bench: init failed");
            return false;
        }
        with_bus(&bus, |b| b.clock = Some(gyro_array::board::qemu::ticks));
        let meter = || with_bus(&bus, |b| b.meter).unwrap_or_default();
        let pair = pair_cost(t);
        let mut timed_g = TimedIcm::new(
            g,
            EmuCapture {
                bus: &bus,
                index: 0,
            },
        );
        let (mut sum, mut worst, mut good) = (0.0f32, 0.0f32, 0u32);
        for n in 0..READS + 100 {
            with_bus(&bus, |b| b.advance(1e-3));
            let now_us = with_bus(&bus, |b| b.timer_us()).unwrap_or(0);
            let delay = gyro_array::pipeline::timed::BOARD_DELAY_US;
            let at = gyro_array::pipeline::timed::array_instant(now_us, delay);
            timed_g.set_instant(at, delay);
            let m0 = meter();
            let t0 = t.now();
            let r = if fifo_only {
                let mut buf = [gyro_array::drivers::icm42688::FifoSample {
                    raw: [0; 3],
                    stamp_us: 0,
                }; 4];
                black_box(timed_g.driver().read_fifo(&mut buf))
                    .map(|_| ())
                    .map_err(|_| gyro_array::drivers::ReadFault::Bus)
            } else if timed {
                black_box(timed_g.read()).map(|_| ())
            } else {
                black_box(Gyro::read(timed_g.driver())).map(|_| ())
            };
            let dt = t.now() - t0;
            let m1 = meter();
            // The bus's own time (the chip models standing in for the
            // SPI peripheral and the silicon), and one clock pair per
            // metered operation, out.
            let bus_ticks =
                m1.ticks.wrapping_sub(m0.ticks) as f32 + m1.ops.wrapping_sub(m0.ops) as f32 * pair;
            let own = (net(dt, pair) - bus_ticks).max(0.0) * ipt;
            if n >= 100 {
                sum += own;
                worst = worst.max(own);
                good += u32::from(r.is_ok());
            }
        }
        defmt::info!(
            "one ICM-42688-P read, {=str}: mean {=f32} worst {=f32} instructions (bus time out), {=u32} of {=u32} reads with a rate",
            if fifo_only {
                "the FIFO read alone (4 kHz)"
            } else if timed {
                "timed (FIFO 4 kHz, capture, tracker, aligner)"
            } else {
                "polled (data registers)"
            },
            sum / READS as f32,
            worst,
            good,
            READS
        );
        ok &= good == READS;
    }
    ok
}

/// The board's loop under four fault scenarios: A and B on a still board
/// with the variance step of the emulated motion at 3 s, C and D on other
/// boards in motion.
/// Scenario C's faults (sample, gyro, fault), which D repeats.
const C_FAULTS: [(u32, usize, gyro_array::emu::Fault); 12] = {
    use gyro_array::emu::Fault;
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

fn bench_loops(t: &Ticks, ipt: f32) -> bool {
    use gyro_array::emu::{Fault, RateProfile};
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
    // A fourth, also untuned, tried at the end of the session that added
    // C: it broke the 10 000 at 10 221 (gyro 1 spiking on a fifth of the
    // samples under a 100 deg/s turn: fusion's consensus gate, since made
    // cheaper).
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
    // A sixth, untuned, tried at the end of the session that added E: it
    // broke the 10 000 (10 035, a dozen samples after two chips stuck at
    // once under a slow, wide sway: fusion's regate and general path
    // while the stuck chips were not yet flagged; and 10 083 where the
    // placement of an E-DAVAR compared every change with its history
    // after two chips power-cycled).
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
    // A ninth, untuned, added in the session after G and H: a steady
    // 100 deg/s turn on x under a 2.5 Hz sway up to 80 deg/s; a chip
    // spiking past the rate limit, the ADXRS453 garbling half its frames,
    // two chips power-cycled together and then stuck together beside a
    // third with bit errors, the ADXRS453 silent for 2 s, chips saturated,
    // stuck and spiking at once. It first read 10 107: the E-DAVAR
    // placement sample after the two stuck chips came back (fifteen
    // changes in a span, each looked up in two lists of the last
    // segmentations' changes), since made a read of a per-block stamp.
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
fn pair_cost(t: &Ticks) -> f32 {
    const PAIRS: u32 = 4096;
    let mut sum = 0u64;
    for _ in 0..PAIRS {
        let t0 = t.now();
        sum += t.now() - t0;
    }
    sum as f32 / PAIRS as f32
}

/// An interval of `ticks` less the timer's own `pair` cost (not below 0).
fn net(ticks: u64, pair: f32) -> f32 {
    (ticks as f32 - pair).max(0.0)
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
fn bench_loop(
    t: &Ticks,
    ipt: f32,
    faults: &str,
    plan: &[(u32, usize, gyro_array::emu::Fault)],
    all: bool,
) -> bool {
    // A still board but for a small 250 Hz vibration from 3 s: the
    // E-DAVARs' variance step.
    let profile = gyro_array::emu::RateProfile {
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
fn selected(faults: &str) -> bool {
    match (option_env!("BENCH_SCENARIOS"), faults.as_bytes().get(7)) {
        (Some(set), Some(c)) => set.as_bytes().contains(c),
        _ => true,
    }
}

/// [`bench_loop`] on the emulated board of `seed` moving as `profile`.
#[inline(never)]
#[allow(unsafe_code)]
fn bench_loop_on(
    t: &Ticks,
    ipt: f32,
    faults: &str,
    profile: gyro_array::emu::RateProfile,
    seed: u64,
    plan: &[(u32, usize, gyro_array::emu::Fault)],
    all: bool,
) -> bool {
    if !selected(faults) {
        return true;
    }
    use core::cell::RefCell;
    use gyro_array::algo::fusion::AdaptiveConfig;
    use gyro_array::drivers::Gyro;
    use gyro_array::emu::{
        board_array, board_drivers, with_bus, BoardDrivers, CsLine, EmuBus, EmuDelay,
    };
    use gyro_array::pipeline::startup::start_array;
    use gyro_array::pipeline::tracker::{self, NoiseTracker};
    use gyro_array::pipeline::{Pipeline, PipelineConfig};

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
    with_bus(&bus, |b| b.clock = Some(gyro_array::board::qemu::ticks));
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
        },
        |pipe| {
            let mut gyros: [&mut dyn Gyro; 5] = [&mut g0, &mut g1, &mut g2, &mut g3, &mut g4];
            pipe.read_and_fuse(&mut gyros)
        },
    )
}

/// The whole loop as the board runs it on chips that keep their own
/// time: four ICM-42688-P (`clkin`: on the board's 32 kHz CLKIN; else on
/// their own PLLs, `pll` off) read through their FIFOs at 4 kHz by
/// [`TimedIcm`] (INT1 captures, clock tracker, aligner), each sample at
/// one stated instant 1 670 µs behind the read, fused on 3 axes, the
/// E-DAVARs and the link as in [`bench_loop_on`]. The chips' paths are
/// the delay model (`emu::PathModel::Delay`: the 32 kHz filters are too
/// slow for QEMU). The ADXRS453 is not read: at the array's instant its
/// rate is always late (docs/timing.md).
#[allow(clippy::too_many_arguments)]
#[inline(never)]
fn bench_timed_loop_on(
    t: &Ticks,
    ipt: f32,
    faults: &str,
    profile: gyro_array::emu::RateProfile,
    seed: u64,
    clkin: bool,
    pll: [f64; 4],
    plan: &[(u32, usize, gyro_array::emu::Fault)],
) -> bool {
    if !selected(faults) {
        return true;
    }
    use core::cell::RefCell;
    use gyro_array::algo::fusion::{AdaptiveConfig, Method};
    use gyro_array::drivers::icm42688::{ClockInput, Config, Icm42688};
    use gyro_array::drivers::Gyro;
    use gyro_array::emu::timing::ClockParams;
    use gyro_array::emu::{
        emu_device, timed_array, with_bus, ChipTiming, CsLine, EmuBus, EmuCapture, EmuDelay,
        PathModel,
    };
    use gyro_array::pipeline::timed::TimedIcm;
    use gyro_array::pipeline::tracker::{self, NoiseTracker};
    use gyro_array::pipeline::{Pipeline, PipelineConfig};
    const DELAY_US: u32 = gyro_array::pipeline::timed::BOARD_DELAY_US;

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
    if clkin {
        with_bus(&bus, |b| b.clkin_hz = Some(32_000.0));
    }
    let mut delay = EmuDelay::new(&bus, 1e-3);
    let cfg = Config::board_fifo(if clkin {
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
    with_bus(&bus, |b| b.clock = Some(gyro_array::board::qemu::ticks));
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
            });
        },
        |pipe| {
            // The board's timer would give this instant; the bus's clock
            // stands in for it.
            let now_us = with_bus(&bus, |b| b.timer_us()).unwrap_or(0);
            let at = gyro_array::pipeline::timed::array_instant(now_us, DELAY_US);
            let mut gyros: [&mut TimedIcm<_, _>; 4] = [&mut g0, &mut g1, &mut g2, &mut g3];
            for g in gyros.iter_mut() {
                g.set_instant(at, DELAY_US);
            }
            let [a, b, c, d] = gyros;
            let mut gyros: [&mut dyn Gyro; 4] = [a, b, c, d];
            pipe.read_and_fuse(&mut gyros)
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

/// The measured part of the whole-loop bench, whatever the chips: per
/// sample, `before(n)` (faults, the bus's time) untimed, then `step`
/// (read + calibrate + fuse) and the link frame (the frame's path), the
/// UART fed, and the calibration's learning and the E-DAVARs, timed and
/// marked for the exact count (the UART on its own); the status frame in
/// the idle time after, timed on its own. `meter` reads the emulated bus's own
/// ticks and bytes.
#[allow(clippy::too_many_arguments)]
fn run_loop<const N: usize>(
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
fn per_frame<const G: usize>(
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
fn ticks_of<const G: usize>(
    t: &Ticks,
    frames: &[[[f32; G]; 3]],
    step: impl FnMut(&[[f32; G]; 3]),
) -> u64 {
    let t0 = t.now();
    frames.iter().for_each(step);
    t.now() - t0
}

/// Instructions per fused 3-axis sample of every fusion method (N = 4).
/// Not inlined: its frames stay out of main's stack.
#[inline(never)]
fn bench_fusion(t: &Ticks, ipt: f32, rng: &mut Rng) -> bool {
    // Frames: 4 gyros × 3 axes, noise plus occasional spikes on gyro 1.
    let mut frames = [[[0.0f32; 4]; 3]; FRAMES];
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

    // Loop overhead: the same loop (`per_frame`'s) with the call replaced.
    let overhead = ticks_of(t, &frames, |f| {
        for axis in f.iter() {
            black_box(axis);
        }
    });

    let mut ok = true;
    for (name, m) in methods() {
        let Ok(fusion) = Fusion::<4>::new(m) else {
            exit(false)
        };
        let mut st = [AxisState::<4>::default(); 3];
        // Warmed up first (memory windows, noise estimates).
        let per_sample = per_frame(t, ipt, overhead, &frames, true, |f| {
            for (a, axis) in f.iter().enumerate() {
                let _ = black_box(fusion.fuse(&mut st[a], black_box(axis), 0b1111));
            }
        });
        defmt::info!(
            "bench fusion {=str}: {=u32} instructions per 3-axis sample (N = 4)",
            name,
            per_sample as u32
        );
        ok &= per_sample > 0.0;
    }

    // The adaptive fusion with five gyros, all in or some out (as after a
    // fault): the general mask costs more than the constant one.
    let mut frames5 = [[[0.0f32; 5]; 3]; 200];
    for f in frames5.iter_mut() {
        for (a, axis) in f.iter_mut().enumerate() {
            for (i, y) in axis.iter_mut().enumerate() {
                *y = [95.0, -5.0, 0.0][a] + [0.1, 0.1, 0.1, 0.1, 0.5][i] * rng.gaussian();
            }
        }
    }
    let overhead5 = ticks_of(t, &frames5, |f| {
        for axis in f.iter() {
            black_box(axis);
        }
    });
    for (name, mask) in [
        ("all five", 0b11111u8),
        ("four of five", 0b01111),
        ("three of five", 0b00111),
    ] {
        let Ok(fusion) = Fusion::<5>::new(Method::Adaptive(Default::default())) else {
            exit(false)
        };
        let mut st = [AxisState::<5>::default(); 3];
        let mut step = |f: &[[f32; 5]; 3]| {
            for (a, axis) in f.iter().enumerate() {
                let _ = black_box(fusion.fuse(&mut st[a], black_box(axis), mask));
            }
        };
        // Noise estimates warmed up over three passes (the last in
        // `per_frame`), the fourth timed.
        for _ in 0..2 {
            frames5.iter().for_each(&mut step);
        }
        let per_sample = per_frame(t, ipt, overhead5, &frames5, true, step);
        defmt::info!(
            "bench fusion adaptive, N = 5, {=str} offered: {=u32} instructions per 3-axis sample",
            name,
            per_sample as u32
        );
        ok &= per_sample > 0.0;
    }

    // The default path of the pipeline: relative calibration, adaptive
    // fusion, calibration update (as `Pipeline::step` runs them; the noise
    // probe it adds is timed on its own below).
    let Ok(fusion) = Fusion::<4>::new(Method::Adaptive(Default::default())) else {
        exit(false)
    };
    let mut st = [AxisState::<4>::default(); 3];
    let mut cal = [RelCal::<4>::new(CalConfig::default()); 3];
    let step = |st: &mut [AxisState<4>; 3], cal: &mut [RelCal<4>; 3], f: &[[f32; 4]; 3]| {
        for (a, axis) in f.iter().enumerate() {
            let y = black_box(axis);
            let _ = black_box(cal[a].fuse(&fusion, &mut st[a], y, 0b1111));
        }
    };
    let per_sample = per_frame(t, ipt, overhead, &frames, true, |f| {
        step(&mut st, &mut cal, f)
    });
    defmt::info!(
        "bench fusion adaptive + online relative calibration: {=u32} instructions per 3-axis sample (N = 4)",
        per_sample as u32
    );
    ok &= per_sample > 0.0;

    // The static calibration in front (`Pipeline::board_rates`: each chip's
    // 3×3 matrix, bias and bias-temperature slope), timed alone and then
    // with the rest: calibration, online calibration and fusion.
    use gyro_array::algo::mounting::ChipCal;
    let cal_of = |i: usize| ChipCal {
        m: [
            [1.01, 0.002 * i as f32, -0.001],
            [0.0015, -0.995, 0.002],
            [0.001, -0.002, 1.004],
        ],
        bias_dps: [0.1, -0.2, 0.05],
        bias_tc_dps_per_c: [0.001, -0.002, 0.0005],
        t_ref_c: 25.0,
    };
    let chips = [cal_of(0), cal_of(1), cal_of(2), cal_of(3)];
    let temps = [Some(31.5f32), Some(30.0), Some(29.0), Some(32.0)];
    let apply = |f: &[[f32; 4]; 3]| {
        let mut out = [[0.0f32; 4]; 3];
        for (i, (c, tc)) in chips.iter().zip(temps).enumerate() {
            let b = black_box(c).apply([f[0][i], f[1][i], f[2][i]], 0b111, tc);
            for (a, v) in b.into_iter().enumerate() {
                out[a][i] = v;
            }
        }
        out
    };
    let st_i = per_frame(t, ipt, overhead, &frames, false, |f| {
        black_box(apply(black_box(f)));
    });
    let all = per_frame(t, ipt, overhead, &frames, false, |f| {
        let c = apply(black_box(f));
        step(&mut st, &mut cal, &c);
    });
    defmt::info!(
        "bench fusion default path (static calibration + online relative calibration + adaptive fusion): {=u32} instructions per 3-axis sample (N = 4; static calibration alone {=u32}, target <= 2500)",
        all as u32,
        st_i as u32
    );
    ok &= all > 0.0;
    // The noise probe the pipeline takes from each fused axis for its
    // tracker, on the fused outputs of the frames (timed alone: a second
    // caller of `fuse_probed` here changed its inlining into `fuse` and
    // the path above by +270).
    let fused: [[Option<gyro_array::algo::fusion::Fused<4>>; 3]; FRAMES] = {
        let mut st = [AxisState::<4>::default(); 3];
        core::array::from_fn(|k| {
            core::array::from_fn(|a| fusion.fuse(&mut st[a], &frames[k][a], 0b1111).ok())
        })
    };
    let mut k = 0usize;
    let probe = per_frame(t, ipt, overhead, &frames, false, |f| {
        for (a, axis) in f.iter().enumerate() {
            if let Some(r) = &fused[k % FRAMES][a] {
                black_box(noise_probe(black_box(axis), black_box(r)));
            }
        }
        k += 1;
    });
    defmt::info!(
        "bench fusion noise probe (the pipeline's tracker input, on top of the default path): {=u32} instructions per 3-axis sample (N = 4)",
        probe as u32
    );
    ok &= probe > 0.0;

    // Seed 001 on the array: a local rate+bias Kalman filter per chip,
    // fused by entropy or covariance weights, the fused rate fed back.
    use gyro_array::algo::mixture::{ChipFilters, ChipWeights};
    for (name, weights) in [
        ("entropy", ChipWeights::Entropy),
        ("covariance", ChipWeights::Covariance),
    ] {
        let Ok(cf) = ChipFilters::<4>::new([0.1, 0.1, 0.1, 0.5], 6.3, 1e-4, weights) else {
            exit(false)
        };
        let mut cfs = [cf; 3];
        let per = per_frame(t, ipt, overhead, &frames, true, |f| {
            for (a, axis) in f.iter().enumerate() {
                black_box(cfs[a].fuse(black_box(axis), 0b1111));
            }
        });
        defmt::info!(
            "bench fusion seed 001 local filters ({=str} weights): {=u32} instructions per 3-axis sample (N = 4)",
            name,
            per as u32
        );
        ok &= per > 0.0;
    }

    ok
}

/// Streaming ADEV (10 octave τ), instructions per sample.
#[inline(never)]
fn bench_allan(t: &Ticks, ipt: f32, rng: &mut Rng) -> bool {
    let mut ok = true;
    // Noise samples for the streaming ADEV bench (the E-DAVAR benches make
    // their own, so no large array sits on the stack beside their windows).
    let mut samples = [0i16; ALLAN_SAMPLES];
    for x in samples.iter_mut() {
        *x = (100.0 * rng.gaussian()) as i16;
    }
    let per = |ticks: u64, n: usize| ticks as f32 * ipt / n as f32;
    let loop_ticks = {
        let t0 = t.now();
        for &x in &samples {
            black_box(x as i32);
        }
        t.now() - t0
    };

    let Ok(mut adev) = StreamAdev::<10, 1024>::new() else {
        exit(false)
    };
    let t0 = t.now();
    for &x in &samples {
        ok &= adev.push(black_box(x as i32)).is_ok();
    }
    let ticks = (t.now() - t0).saturating_sub(loop_ticks);
    defmt::info!(
        "bench allan stream (10 octave tau): {=u32} instructions per sample, {=usize} B RAM per axis",
        per(ticks, ALLAN_SAMPLES) as u32,
        core::mem::size_of::<StreamAdev<10, 1024>>()
    );

    ok
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
    h.is_ok_and(|h| h.stationary) && bench_selftest_array(t, ipt, rng)
}

/// Instructions of the whole self-test analysis of the board's five gyros
/// on a swaying board (each block against a fit of its peers' median, then
/// the tests): `selftest::analyse`.
#[inline(never)]
fn bench_selftest_array(t: &Ticks, ipt: f32, rng: &mut Rng) -> bool {
    use gyro_array::pipeline::selftest::{analyse, BLOCK};
    let mut blocks = [[0.0f32; BLOCK]; 5];
    for i in 0..BLOCK {
        let w = 20.0 * libm::sinf(2.0 * core::f32::consts::PI * i as f32 * 1e-3);
        for (g, b) in blocks.iter_mut().enumerate() {
            b[i] = (1.0 + 0.01 * g as f32) * w + 0.09 * rng.gaussian();
        }
    }
    let mut results = [Err(gyro_array::algo::qualify::QualifyError::TooShort); 5];
    let t0 = t.now();
    let ok = analyse(black_box(&blocks), |_| 2, &mut results);
    let ticks = t.now() - t0;
    defmt::info!(
        "bench self-test on a swaying board (5 gyros against their peers): {=u32} instructions, pass {}",
        (ticks as f32 * ipt) as u32,
        ok
    );
    results.iter().all(|r| r.is_ok())
}

const ALLAN_SAMPLES: usize = 8192;
const WARM: usize = 4096;

/// E-DAVAR cost on `AXES` axes fed the same input from the very first
/// sample (so the first fill is included): instructions of every single
/// sample are measured (SysTick read around each, the read pair's own cost
/// subtracted). Prints the mean over the samples after the first estimate,
/// the worst single sample and where it happened (sample index, and its
/// position in the 32-sample hop: 1 is the hop itself).
#[inline(never)]
fn bench_davar<
    const CAP: usize,
    const FRAMES: usize,
    const T: usize,
    const STFT: usize,
    const AXES: usize,
>(
    t: &Ticks,
    ipt: f32,
    step: bool,
    cfg: DavarConfig,
    name: &str,
) -> bool {
    // One window per axis, each built in place (a λ2 = 4096 window is
    // 33 KB of the 128 KB stack).
    let Ok(mut a0) = Davar::<CAP, FRAMES, T, STFT>::new(cfg) else {
        return false;
    };
    if AXES == 1 {
        return run_davar(t, ipt, step, name, &mut [&mut a0]);
    }
    // The tracker's stagger of the three axes' hops.
    let (Ok(a1), Ok(a2)) = (Davar::new(cfg), Davar::new(cfg)) else {
        return false;
    };
    let [p0, p1, p2] = gyro_array::pipeline::tracker::HOP_PHASES;
    a0.set_hop_phase(p0);
    let (mut a1, mut a2) = (a1.with_hop_phase(p1), a2.with_hop_phase(p2));
    run_davar(t, ipt, step, name, &mut [&mut a0, &mut a1, &mut a2])
}

/// Ticks of the bench's signal from sample `from` to the end, pushed into
/// the axes (reset first) when `WITH`, else only generated.
#[inline(never)]
fn whole_run<
    const CAP: usize,
    const FRAMES: usize,
    const T: usize,
    const STFT: usize,
    const WITH: bool,
>(
    t: &Ticks,
    step: bool,
    from: usize,
    axes: &mut [&mut Davar<CAP, FRAMES, T, STFT>],
) -> u64 {
    for d in axes.iter_mut() {
        d.reset();
    }
    let mut rng = Rng::new(99);
    let mut t0 = t.now();
    for i in 0..WARM + ALLAN_SAMPLES {
        let x = (davar_sigma(step, i) * rng.gaussian()) as i16;
        if i == from {
            t0 = t.now();
        }
        if WITH {
            for d in axes.iter_mut() {
                let _ = black_box(d.push(black_box(x as i32)));
            }
        } else {
            black_box(x);
        }
    }
    t.now() - t0
}

/// σ of the E-DAVAR benches' white noise at sample i: doubled from the
/// middle on when `step`.
fn davar_sigma(step: bool, i: usize) -> f32 {
    if step && i >= (WARM + ALLAN_SAMPLES) / 2 {
        200.0
    } else {
        100.0
    }
}

/// The measurement of [`bench_davar`] over the given axes.
#[inline(never)]
fn run_davar<const CAP: usize, const FRAMES: usize, const T: usize, const STFT: usize>(
    t: &Ticks,
    ipt: f32,
    step: bool,
    name: &str,
    axes: &mut [&mut Davar<CAP, FRAMES, T, STFT>],
) -> bool {
    // Cost of the timing itself: two reads back to back, averaged.
    let pair = pair_cost(t);
    let mut ok = true;
    let (mut total, mut counted) = (0.0f32, 0u32);
    let (mut worst, mut worst_at) = (0.0f32, 0usize);
    let (mut published, mut first) = (false, 0);
    // Mean cost by position in the 32-sample hop (after the first estimate).
    let mut by_phase = [0.0f32; 32];
    // White noise generated on the fly (no sample array on the stack), of
    // σ `davar_sigma`.
    let mut rng = Rng::new(99);
    for i in 0..WARM + ALLAN_SAMPLES {
        let x = (davar_sigma(step, i) * rng.gaussian()) as i16;
        let t0 = t.now();
        for d in axes.iter_mut() {
            let r = d.push(black_box(x as i32));
            ok &= r.is_ok();
            published |= matches!(r, Ok(Some(_)));
        }
        let ticks = net(t.now() - t0, pair);
        if ticks > worst {
            worst = ticks;
            worst_at = i;
        }
        if published {
            if counted == 0 {
                first = i;
            }
            total += ticks;
            counted += 1;
            by_phase[(i + 1) % 32] += ticks;
        }
    }
    // The mean once more, exactly: the same samples timed as one stretch
    // (a reading at each end, none per sample), less the same stretch
    // without the E-DAVAR (the signal's generation alone). The per-sample
    // mean carries the timer's pair cost, which moves by tens of
    // instructions between builds; this does not.
    let bare = whole_run::<CAP, FRAMES, T, STFT, false>(t, step, first, axes);
    let with = whole_run::<CAP, FRAMES, T, STFT, true>(t, step, first, axes);
    let exact = with.saturating_sub(bare) as f32 * ipt / counted.max(1) as f32;
    let f = |ticks: f32| (ticks * ipt) as u32;
    defmt::info!(
        "bench e-davar {=str} lambda2 = {=usize} ({=usize} tau, {=usize} axis/axes): mean {=u32} instructions per sample (timed per sample: {=u32}), worst {=u32} at sample {=usize} (hop phase {=usize}), {=usize} B RAM per axis",
        name,
        CAP,
        T,
        axes.len(),
        exact as u32,
        (total * ipt / counted.max(1) as f32) as u32,
        f(worst),
        worst_at,
        (worst_at + 1) % 32,
        core::mem::size_of::<Davar<CAP, FRAMES, T, STFT>>()
    );
    if axes.len() == 1 && STFT == 0 {
        let hops = (counted / 32).max(1) as f32;
        let p = by_phase.map(|x| (x * ipt / hops) as u32);
        defmt::info!(
            "  mean by hop phase (0 = frame end, 1 = hop, 2.. = one tau each): {=[?]}",
            p[..]
        );
    }
    let est = axes[0].estimate();
    ok && est.is_some_and(|e| e.avar[0] > 0.0)
}

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
