//! demo-replay: the QEMU demo's run on the host. The same world
//! (`gyro_sim::demo`: the array, its start-up, its faults) through
//! the same schedule (`gyro_array::app`: the sample task, then the
//! background's E-DAVARs, in the order RTIC runs them when the background
//! keeps up), with the demo's link settings. Prints the sample frames sent
//! and the CRC-32 of the rates they carried, as the firmware logs them;
//! `cargo xtask test` requires the two to be equal, bit for bit.
//!
//! `cargo run --profile host -p evaluations --bin demo-replay [-- --stress]`
//! (`--stress`: a status frame every sample, as the demo's stress run).

use gyro_array::app as schedule;
use gyro_array::link::port::{NoiseSnapshot, Port};
use gyro_sim::demo;
use host_tests::demo_host;
use host_tests::timed_board::HostLink;
use rtic_core::Exclusive;

static CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

fn main() {
    gyro_tool::pipe::quiet_on_closed_pipe();
    let stress = std::env::args().any(|a| a == "--stress");
    // The demo's port size, its bytes taken at once.
    let mut link = HostLink::<1024> {
        port: Port::new(
            demo::link_settings(stress),
            gyro_array::app::BOARD_FRAME_PATH,
        ),
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
    let mut digest = CRC32.digest();
    let mut frames = 0u32;
    demo_host::run(
        demo::SAMPLES,
        &mut link,
        &mut noise,
        |s| {
            println!(
                "start-up: calibration {:?}, self-test {}, FIFO set-up failed on {:#06b}",
                s.calibration,
                if s.self_test_ok { "passed" } else { "FAILED" },
                s.fifo_failed
            )
        },
        |_| {},
        |_, s, link, _, noise| {
            if s.sent {
                frames += 1;
                for v in link.port.last_sample_rates().unwrap_or([f32::NAN; 3]) {
                    digest.update(&v.to_le_bytes());
                }
            }
            // The background's E-DAVARs after each sample, as RTIC runs
            // them when the background keeps up; the snapshot they leave
            // goes into the next frame.
            bg.run(schedule::Job::from(&s.out), &mut Exclusive(noise));
        },
    );
    println!(
        "link: {frames} sample frames, fused-rate CRC-32 {:#010x}",
        digest.finalize()
    );
}
