//! QEMU demo firmware: the board's real drivers read an emulated array
//! (4 × ICM-42688-P, 1 × ADXRS453 on z) over one shared SPI bus, the
//! pipeline fuses every sample, and faults are injected on a schedule:
//! gyro 2 sticks at 1.5 s, the ADXRS453 has bit errors from 2.0 s to 2.2 s.
//! E-DAVAR (segmented, λ2 = 512) tracks the noise of each fused axis
//! and logs its window length, entropy deficit and σ(τ) every 500 samples
//! (z slews in a 20 °/s sine from power-up, so its long-τ σ and deficit
//! show the motion). The chips are mounted rotated and misaligned, and
//! the board applies the calibration record made for it by the host
//! procedure (`calibrate`). The board boots while it sways: the ICM-42688-P
//! self-test runs across the array, and the noise-health self-test takes
//! 2048 samples of every gyro's z axis and checks trend, long memory and
//! normality of each against the median of the others.
//! The ICM-42688-Ps keep their own time (`emu::timing`): free-running PLLs
//! 0.6 % fast, 0.9 % slow, 0.3 % fast and 0.4 % slow, drifting and
//! wandering, chip 3's failing over to its RC oscillator (5 % fast) from
//! 3.0 s to 4.0 s. After the self-tests (data registers) they sample into
//! their FIFOs at the board's 4 kHz, each read through `TimedIcm` (its
//! INT1 captured, its clock tracked, its samples brought to one instant
//! `BOARD_DELAY_US` behind the read), as `board-f405` reads them; the
//! ADXRS453, whose reading is older than that instant, is read and
//! watched, not fused. The chips' signal paths are the delay model
//! (`emu::PathModel::Delay`: the 32 kHz filters are too slow for a minute
//! of QEMU), their clocks, FIFOs, stamps and INT1 the full model's.
//! Every sample goes out over UART0 as an output-link frame (`link`),
//! with a status frame every second and an acknowledgement for every
//! command received; the run lasts 60 s of emulated time.
//! The run fails (exit code 1) unless the stuck gyro is excluded within
//! 20 samples, every bit error is caught, every sample is accounted for,
//! no chip is flagged for its clock alone, no frame is dropped, and E-DAVAR's σ(1 ms) on x matches the fused noise
//! (0.02–0.1 °/s). It ends by logging the number of sample frames and a
//! CRC-32 of their fused rates, which `cargo xtask test` compares with the
//! host's recording of the UART.
#![no_std]
#![no_main]

use core::cell::RefCell;
use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m_rt::{entry, exception};
use defmt_semihosting as _;

use gyro_array::algo::fusion::{AdaptiveConfig, Method};
use gyro_array::algo::mounting::CalRecord;
use gyro_array::algo::qualify::QualifyError;
use gyro_array::app as schedule;
use gyro_array::board::cmsdk_uart::{CmsdkUart, UART0};
use gyro_array::board::qemu::exit;
use gyro_array::board::{idle, stack};
use gyro_array::drivers::icm42688::{ClockInput, Config};
use gyro_array::drivers::Gyro;
use gyro_array::emu::timing::ClockParams;
use gyro_array::emu::{
    board_array, board_drivers, mounted_board, with_bus, BoardDrivers, Chip, ChipTiming, CsLine,
    EmuBus, EmuCapture, EmuDelay, Fault, PathModel, RateProfile, TempProfile,
};
use gyro_array::link::msg::Settings;
use gyro_array::link::port::{timed_clock, ChipTime, NoiseSnapshot, Port};
use gyro_array::pipeline::selftest;
use gyro_array::pipeline::startup::start_array;
use gyro_array::pipeline::timed::{self, AtInstant, TimedIcm, BOARD_DELAY_US};
use gyro_array::pipeline::tracker::{self, NoiseTracker};
use gyro_array::pipeline::{Pipeline, PipelineConfig};
use rtic_core::Exclusive;

const FS_HZ: u32 = 1000;
/// The board's calibration record, as the procedure wrote it.
const CALIBRATION: &[u8] = include_bytes!("../../host-tests/vectors/board.gcal");
/// 60 s of output.
const SAMPLES: u32 = 60_000;
/// σ of the link's noise estimates at τ = 1, 8, 64 ms.
const NOISE_TAU: [usize; 3] = [0, 3, 6];
/// mps2-an386 core clock.
const CORE_HZ: u32 = 25_000_000;

/// E-DAVAR per axis: λ2 = 512 samples, the link's τ alone (1, 8 and 64 ms:
/// every third octave).
type Tracker = NoiseTracker<512, 19, 3>;

static TICKS: AtomicU32 = AtomicU32::new(0);

#[exception]
fn SysTick() {
    TICKS.fetch_add(1, Ordering::Release);
}

#[entry]
fn main() -> ! {
    stack::guard_stack();
    let cp = cortex_m::Peripherals::take().unwrap_or_else(|| exit(false));
    let profile = RateProfile {
        base_dps: [0.5, -0.2, 10.0],
        sine_dps: [0.0, 0.0, 20.0],
        sine_hz: 1.0,
        sine_start_s: 0.0,
    };
    let cs: [CsLine; 5] = Default::default();
    // The chips are mounted as a real board's are (rotated, upside down,
    // misaligned; `emu::mounted_board`), their die warming from 20 to
    // 35 °C, and the board carries the record the calibration procedure
    // made for it (`calibrate --out host-tests/vectors/board.gcal`).
    let mut chips = board_array(profile, 1);
    let warm_up = TempProfile {
        start_c: 20.0,
        ramp_c_per_s: 0.5,
        ramp_from_s: 5.0,
        end_c: 35.0,
    };
    const PLL: [f64; 4] = [0.006, -0.009, 0.003, -0.004];
    for (i, (c, m)) in chips.iter_mut().zip(mounted_board(warm_up)).enumerate() {
        c.set_mount(m);
        if let (Chip::Icm(c), Some(&offset)) = (c, PLL.get(i)) {
            c.set_timing(Some(ChipTiming {
                pll: ClockParams {
                    offset,
                    drift_per_s: 1e-5,
                    wander: 2e-4,
                    wander_period_s: 3.0 + i as f64,
                },
                path: PathModel::Delay,
                ..ChipTiming::pll(0.0)
            }));
        }
    }
    let bus = RefCell::new(EmuBus::new(chips, &cs));
    let dt = 1.0 / FS_HZ as f32;
    let mut delay = EmuDelay::new(&bus, dt);

    let BoardDrivers {
        icm: [mut g0, mut g1, mut g2, mut g3],
        adx: mut g4,
    } = board_drivers(&bus, &cs);

    let mut pipe: Pipeline<5> = Pipeline::new(
        PipelineConfig::default(),
        Method::Adaptive(AdaptiveConfig::default()),
    )
    .unwrap_or_else(|_| exit(false));
    let calibrated =
        match pipe.set_calibration(CalRecord::decode(CALIBRATION).as_ref().map_err(|e| *e)) {
            Ok(()) => {
                defmt::info!("calibration record in use");
                true
            }
            Err(e) => {
                defmt::error!("calibration record: {}; running uncalibrated", e);
                false
            }
        };
    start_array(
        [&mut g0, &mut g1, &mut g2, &mut g3],
        &mut g4,
        &mut delay,
        Some(20),
        &mut pipe,
    );

    let mut blocks = [[0.0f32; selftest::BLOCK]; 5];
    let mut results = [Err(QualifyError::TooShort); 5];
    let self_test_ok = {
        let mut gyros: [&mut dyn Gyro; 5] = [&mut g0, &mut g1, &mut g2, &mut g3, &mut g4];
        selftest::run(
            &mut gyros,
            |_| 2, // z: every chip measures it, so each has four peers
            |i, r| pipe.board_rates(i, r),
            || {
                with_bus(&bus, |b| b.advance(dt));
            },
            &mut blocks,
            &mut results,
        )
    };

    // Each gyro's measured noise: fusion's priors for an axis left with
    // two gyros.
    pipe.set_noise_priors(results.map(|r| r.ok().map(|h| h.std_dps)));

    // From the self-tests (data registers) to the board's sampling, as
    // `board-f405` does it: FIFO at 4 kHz on each chip's own clock, each
    // sample's INT1 captured (QEMU's board has no CLKIN to drive).
    let cfg = Config::board_fifo(ClockInput::Internal);
    for (i, g) in [&mut g0, &mut g1, &mut g2, &mut g3].into_iter().enumerate() {
        if let Err(e) = g.init(&mut delay, cfg) {
            defmt::error!("gyro {}: FIFO set-up failed: {}", i, e);
            pipe.mark_init_failed(i);
        }
    }
    // One start for all (the chips set up first ran while the others were).
    for g in [&mut g0, &mut g1, &mut g2, &mut g3] {
        let _ = g.flush_fifo();
    }
    let capture = |index: usize| EmuCapture { bus: &bus, index };
    let (mut g0, mut g1, mut g2, mut g3) = (
        TimedIcm::new(g0, capture(0)),
        TimedIcm::new(g1, capture(1)),
        TimedIcm::new(g2, capture(2)),
        TimedIcm::new(g3, capture(3)),
    );
    let mut g4 = AtInstant::new(g4, BOARD_DELAY_US);
    // What the status frames say of each chip's clock.
    let clocks = |t: [&TimedIcm<_, _>; 4]| {
        let mut c = [ChipTime::default(); 5];
        for (slot, t) in c.iter_mut().zip(t) {
            *slot = timed_clock(t);
        }
        c
    };
    let mut noise =
        Tracker::new(tracker::config(512).with_tau_octaves(3)).unwrap_or_else(|_| exit(false));
    noise.set_view(NOISE_TAU);
    let mut sigma_x_1ms = f32::NAN;

    let _ticks = {
        let mut syst = cp.SYST;
        syst.set_clock_source(cortex_m::peripheral::syst::SystClkSource::Core);
        syst.set_reload(CORE_HZ / FS_HZ - 1);
        syst.clear_current();
        syst.enable_interrupt();
        syst.enable_counter();
        syst
    };

    // SAFETY: UART0 is used by nothing else.
    #[allow(unsafe_code)]
    let mut uart = unsafe { CmsdkUart::new(UART0, 16) };
    let mut port = Port::<1024>::new(Settings::default());
    // CRC-32 of the rates of every sample frame, as the firmware computed
    // them (NaN where an axis has none, as the frame carries).
    let crc32 = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
    let mut digest = crc32.digest();
    let mut sample_frames = 0u32;

    // The schedule (`gyro_array::app`) as one loop runs it: the sample
    // task's work at each tick, the background's in the idle time after,
    // every piece borrowed in turn (`Exclusive`).
    let mut snapshot = NoiseSnapshot::default();
    let mut bg = schedule::Background {
        tracker: &mut noise,
        taus: NOISE_TAU,
        sample_us: 1_000_000 / FS_HZ,
    };
    // The jobs the last sample handed on: its probe, and a status frame
    // when one was due.
    let mut probe: Option<schedule::Job<5>> = None;
    let mut status_for: Option<schedule::Job<5>> = None;
    let mut last_tick = TICKS.load(Ordering::Acquire);
    let mut stuck_at = None;
    let mut excluded_at = None;
    let mut pass = true;
    for n in 0..SAMPLES {
        // Wait for the sample tick; count periods we missed. Idle time
        // feeds the UART, then runs the calibration's learning and the
        // E-DAVARs, then builds a status
        // frame when one is due, and reads commands.
        let now = loop {
            let t = TICKS.load(Ordering::Acquire);
            if t != last_tick {
                // Every sample reaches the E-DAVARs, whatever is still
                // queued when the next one is due.
                if let Some(j) = probe.take() {
                    bg.run(
                        j,
                        &mut Exclusive(&mut pipe),
                        &mut Exclusive(&mut port),
                        &mut Exclusive(&mut snapshot),
                        0,
                    );
                }
                break t;
            }
            port.drain(&mut uart);
            if port.queued() == 0 {
                if let Some(j) = probe.take().or_else(|| status_for.take()) {
                    let peak = stack::stack_usage().peak;
                    bg.run(
                        j,
                        &mut Exclusive(&mut pipe),
                        &mut Exclusive(&mut port),
                        &mut Exclusive(&mut snapshot),
                        peak,
                    );
                }
            }
            schedule::receive(
                &mut uart,
                &mut Exclusive(&mut pipe),
                &mut Exclusive(&mut port),
            );
            // Sleep only if the tick has still not come, checked with
            // interrupts masked: a tick taken between the check above and
            // the WFI would otherwise be slept through, a missed sample
            // (WFI still wakes on the pending interrupt).
            idle::sleep_unless(|| {
                TICKS.load(Ordering::Acquire) != last_tick
                    || port.queued() != 0
                    || probe.is_some()
                    || status_for.is_some()
            });
        };
        let missed = now.wrapping_sub(last_tick).saturating_sub(1);
        if missed > 0 {
            defmt::warn!("overrun: {} sample(s) missed before sample {}", missed, n);
        }
        last_tick = now;

        with_bus(&bus, |b| {
            match n {
                1500 => {
                    b.chips[2].set_fault(Fault::Stuck);
                    stuck_at = Some(n);
                    defmt::warn!("t={}ms: injecting: gyro 2 stuck", n);
                }
                2000 => {
                    b.chips[4].set_fault(Fault::BitErrors { prob: 0.05 });
                    defmt::warn!("t={}ms: injecting: gyro 4 bit errors", n);
                }
                2200 => b.chips[4].set_fault(Fault::None),
                3000 | 4000 => {
                    if let Chip::Icm(c) = &mut b.chips[3] {
                        c.fail_pll(n == 3000);
                    }
                    defmt::warn!(
                        "t={}ms: gyro 3's clock {}",
                        n,
                        if n == 3000 {
                            "falls back to its RC oscillator"
                        } else {
                            "back on its PLL"
                        }
                    );
                }
                _ => {}
            }
            b.advance(dt);
        });
        // One instant for the array, a fixed delay behind the read, on the
        // captures' µs clock (the bus's here, TIM5's on the board), in
        // 1/16 µs.
        let now_us = with_bus(&bus, |b| b.timer_us()).unwrap_or(0);
        let at = timed::array_instant(now_us, BOARD_DELAY_US);
        for t in [&mut g0, &mut g1, &mut g2, &mut g3] {
            t.set_instant(at, BOARD_DELAY_US);
        }

        let t_us = u64::from(now) * u64::from(1_000_000 / FS_HZ);
        let mut gyros: [&mut dyn Gyro; 5] = [&mut g0, &mut g1, &mut g2, &mut g3, &mut g4];
        let sampled = schedule::sample(
            &mut Exclusive(&mut pipe),
            &mut Exclusive(&mut port),
            &mut Exclusive(&mut snapshot),
            &mut gyros,
            t_us,
            missed,
        );
        let out = sampled.out;
        pipe.log_health_changes(&out);
        if let (Some(_), None) = (stuck_at, excluded_at) {
            if out.fused[0].is_some_and(|f| f.weights[2] == 0.0) {
                excluded_at = Some(n);
            }
        }
        let (p, st) = schedule::jobs(&sampled, t_us, || clocks([&g0, &g1, &g2, &g3]));
        probe = Some(p);
        if st.is_some() {
            status_for = st;
        }
        if sampled.sent {
            sample_frames += 1;
            // What the frame carried (the rates predicted to its last byte:
            // the link's delay compensation).
            for r in port.last_sample_rates().unwrap_or([f32::NAN; 3]) {
                digest.update(&r.to_le_bytes());
            }
        }
        let log_now = if n < 3000 {
            n % 500 == 499
        } else {
            n % 10_000 == 9_999
        };
        if log_now {
            for a in 0..3 {
                let Some(d) = bg.tracker.estimate(a) else {
                    continue;
                };
                let e = d.step;
                defmt::info!(
                    "seq {} axis {}: E-DAVAR for seq {} L={} ({} bridged) score {=f32} (threshold {=f32}) sigma(1/8/64 ms) = {=f32} {=f32} {=f32} dps",
                    out.seq,
                    a,
                    d.seq,
                    e.len,
                    d.bridged,
                    e.score,
                    e.threshold,
                    tracker::sigma_dps(&e, 0),
                    tracker::sigma_dps(&e, 3),
                    tracker::sigma_dps(&e, 6)
                );
                if a == 0 {
                    sigma_x_1ms = tracker::sigma_dps(&e, 0);
                }
            }
            let cal = &pipe.calibration()[2];
            defmt::info!(
                "seq {} axis 2: relative calibration scale {} bias {} dps",
                out.seq,
                cal.scale(),
                cal.bias()
            );
            let truth = with_bus(&bus, |b| b.chips[0].true_rate_dps()).unwrap_or([0.0; 3]);
            for (a, f) in out.fused.iter().enumerate() {
                match f {
                    Some(f) => defmt::info!(
                        "seq {} axis {}: fused {=f32} dps (true {=f32}), weights {}",
                        out.seq,
                        a,
                        f.rate_dps,
                        truth[a],
                        f.weights
                    ),
                    None => {
                        defmt::error!("seq {} axis {}: no fused value", out.seq, a);
                        pass = false;
                    }
                }
            }
        }
    }

    if let Some(j) = probe.take() {
        bg.run(
            j,
            &mut Exclusive(&mut pipe),
            &mut Exclusive(&mut port),
            &mut Exclusive(&mut snapshot),
            0,
        );
    }
    // Send what is still queued (bounded: the UART takes a byte at a time).
    for _ in 0..100_000 {
        if port.queued() == 0 {
            break;
        }
        port.drain(&mut uart);
    }
    let lc = port.counters();
    defmt::info!(
        "link: {} frames sent, {} dropped, {} left; commands {} accepted, {} rejected; rx overruns {}",
        lc.sent,
        lc.dropped,
        port.queued(),
        lc.accepted,
        lc.rejected,
        uart.rx_overruns()
    );
    defmt::info!(
        "link: {} sample frames, fused-rate CRC-32 {=u32:#010x}",
        sample_frames,
        digest.finalize()
    );
    pass &= lc.dropped == 0 && port.queued() == 0 && sample_frames == SAMPLES;

    let c = pipe.counters();
    for (i, c) in c.iter().enumerate() {
        defmt::info!(
            "gyro {}: reads {} errors {} (parity {}, chip {}) not read (restarting) {} saturated {} excluded {}; restarts {}, completed {}",
            i,
            c.reads,
            c.errors,
            c.parity,
            c.chip_faults,
            c.not_read,
            c.saturated,
            c.excluded,
            c.restarts,
            c.restarted
        );
    }
    let accounted = c
        .iter()
        .all(|c| c.reads + c.errors + c.not_read + c.late == SAMPLES);
    for (i, t) in [&g0, &g1, &g2, &g3].into_iter().enumerate() {
        let k = &t.counters;
        defmt::info!(
            "gyro {} timing: {} FIFO samples, late {} (acquiring {}), overflows {}, clock jumps {}, spikes {}; clock {=f32} ppm",
            i,
            k.samples,
            k.late,
            k.acquiring,
            k.overflows,
            k.jumps,
            k.spikes,
            t.clock().error_ppm()
        );
    }
    // The chips with no fault of their own (0, 1 and 3, whose clock fails
    // over to its RC oscillator and back) are never flagged: out of fusion
    // only while the array finds its clocks at boot.
    let clock_alone_ok = [0, 1, 3]
        .iter()
        .all(|&i| c[i].errors == 0 && c[i].excluded <= 50);
    defmt::info!(
        "chips with no fault of their own never flagged: {}",
        clock_alone_ok
    );
    pass &= clock_alone_ok;
    defmt::info!(
        "samples {} overruns {} accounted {}",
        SAMPLES,
        pipe.overruns(),
        accounted
    );
    match (stuck_at, excluded_at) {
        (Some(s), Some(e)) => {
            defmt::info!("stuck gyro excluded {} samples after the fault", e - s);
            pass &= e - s <= 20;
        }
        _ => pass = false,
    }
    defmt::info!(
        "E-DAVAR: sigma(1 ms) on x = {=f32} dps, {} window restarts, {} missing samples bridged",
        sigma_x_1ms,
        bg.tracker.restarts(),
        bg.tracker.bridged()
    );
    pass &= sigma_x_1ms > 0.02 && sigma_x_1ms < 0.1;
    defmt::info!(
        "noise-health self-test: {}",
        if self_test_ok {
            "all gyros pass"
        } else {
            "FAILED"
        }
    );
    pass &= self_test_ok && calibrated;
    pass &= accounted && c[4].parity > 0 && pipe.overruns() == 0;
    let u = stack::stack_usage();
    defmt::info!("stack: peak {} of {} bytes", u.peak, u.size);
    defmt::info!("demo {}", if pass { "PASS" } else { "FAIL" });
    exit(pass)
}
