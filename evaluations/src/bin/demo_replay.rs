//! demo-replay: the QEMU demo's run on the host. The same world
//! (`gyro_array::emu::demo`: the array, its start-up, its faults) through
//! the same schedule (`gyro_array::app`: the sample task, then the
//! background's E-DAVARs, in the order RTIC runs them when the background
//! keeps up), with the demo's link settings. Prints the sample frames sent
//! and the CRC-32 of the rates they carried, as the firmware logs them;
//! `cargo xtask test` requires the two to be equal, bit for bit.
//!
//! `cargo run --profile host -p evaluations --bin demo-replay [-- --stress]`
//! (`--stress`: a status frame every sample, as the demo's stress run).

use gyro_array::app::{self as schedule, StatusFacts, StatusView};
use gyro_array::drivers::Gyro;
use gyro_array::emu::{demo, with_bus, CsLine, EmuBus};
use gyro_array::link::port::{timed_clock, ChipTime, NoiseSnapshot, Port};
use gyro_array::pipeline::timed::{self, BOARD_DELAY_US};
use host_tests::timed_board::HostLink;
use rtic_core::Exclusive;
use std::cell::RefCell;

const VIEW: StatusView = StatusView {
    taus: demo::NOISE_TAU,
    sample_us: 1_000_000 / demo::FS_HZ,
};

static CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

fn main() {
    let stress = std::env::args().any(|a| a == "--stress");
    let cs: [CsLine; 5] = Default::default();
    let bus = RefCell::new(EmuBus::new(demo::chips(), &cs));
    let Ok(mut pipe) = demo::pipeline() else {
        eprintln!("demo-replay: the pipeline refused its settings");
        std::process::exit(1);
    };
    let demo::Started {
        chips,
        calibration,
        self_test_ok,
        fifo_failed,
    } = demo::start(&bus, &cs, &mut pipe);
    println!(
        "start-up: calibration {:?}, self-test {}, FIFO set-up failed on {fifo_failed:#06b}",
        calibration,
        if self_test_ok { "passed" } else { "FAILED" }
    );
    let demo::Chips {
        mut timed, mut adx, ..
    } = chips;
    let settings = demo::link_settings(stress);
    // The demo's port size, its bytes taken at once.
    let mut link = HostLink::<1024> {
        port: Port::new(settings),
        bytes: 0,
    };
    let mut noise = NoiseSnapshot::default();
    let Ok(mut tracker) = demo::Tracker::new(demo::tracker_config()) else {
        eprintln!("demo-replay: the E-DAVAR refused its settings");
        std::process::exit(1);
    };
    tracker.set_view(demo::NOISE_TAU);
    let mut bg = schedule::Background {
        tracker: &mut tracker,
        taus: demo::NOISE_TAU,
    };
    let now_us = with_bus(&bus, |b| b.timer_us()).unwrap_or(0);
    let mut clock = schedule::SampleClock::new(now_us, 1_000_000 / demo::FS_HZ);
    let mut clocks = [ChipTime::default(); 5];
    let mut digest = CRC32.digest();
    let mut frames = 0u32;
    for n in 0..demo::SAMPLES {
        with_bus(&bus, |b| {
            demo::inject(n, b);
            b.advance(1.0 / demo::FS_HZ as f32);
        });
        let now_us = with_bus(&bus, |b| b.timer_us()).unwrap_or(0);
        let (t_us, missed) = clock.tick(now_us);
        let at = timed::array_instant(now_us, BOARD_DELAY_US);
        for t in timed.iter_mut() {
            t.set_instant(at, BOARD_DELAY_US);
        }
        let s = {
            let [c0, c1, c2, c3] = &mut timed;
            let mut gyros: [&mut dyn Gyro; 5] = [c0, c1, c2, c3, &mut adx];
            schedule::sample(
                &mut Exclusive(&mut pipe),
                &mut Exclusive(&mut link),
                &mut Exclusive(&mut noise),
                &mut gyros,
                (t_us, missed),
                &VIEW,
                || {},
                || StatusFacts {
                    clocks,
                    stack_peak: 0,
                },
            )
        };
        if s.sent {
            frames += 1;
            for v in link.port.last_sample_rates().unwrap_or([f32::NAN; 3]) {
                digest.update(&v.to_le_bytes());
            }
        }
        for (slot, t) in clocks.iter_mut().zip(timed.iter()) {
            *slot = timed_clock(t);
        }
        bg.run(schedule::Job::from(&s.out), &mut Exclusive(&mut noise));
    }
    println!(
        "link: {frames} sample frames, fused-rate CRC-32 {:#010x}",
        digest.finalize()
    );
}
