//! Start-up on a moving vehicle: 40 boards, each booting
//! while it sways at a random 0–20 °/s per axis and 0.2–5 Hz, through the
//! ICM-42688-P array self-test (20 samples per phase, as the board runs
//! it). No healthy chip may fail; a chip with a dead self-test must.
//!
//! `cargo test -p host-tests --test startup_sway -- --nocapture` prints the
//! counts.

use gyro_sim::checks::run_board_array_with;
use gyro_sim::{Fault, RateProfile, Rng};

#[test]
fn no_healthy_chip_fails_start_up_under_sway_and_a_dead_one_always_does() {
    let mut rng = Rng::new(2026);
    let (mut healthy, mut healthy_failed, mut dead, mut dead_passed) = (0, 0, 0, 0);
    for board in 0..40u64 {
        let profile = RateProfile {
            base_dps: [
                rng.uniform() * 10.0 - 5.0,
                rng.uniform() * 10.0 - 5.0,
                rng.uniform() * 10.0 - 5.0,
            ],
            sine_dps: [
                20.0 * rng.uniform(),
                20.0 * rng.uniform(),
                20.0 * rng.uniform(),
            ],
            sine_hz: 0.2 + 4.8 * rng.uniform(),
            sine_start_s: 0.0,
        };
        let mut faults = [Fault::None; 5];
        let bad = (board % 5) as usize;
        // 16 of the 40 boards have one chip with a dead self-test.
        let with_dead = board % 5 < 4 && board % 2 == 0;
        if with_dead {
            faults[bad] = Fault::DeadSelfTest;
        }
        let failed =
            run_board_array_with(profile, 1000 + board, 0, faults, Some(20), |_, _, _, _| {})
                .expect("the pipeline builds");
        for chip in 0..4 {
            let f = failed & (1 << chip) != 0;
            if with_dead && chip == bad {
                dead += 1;
                dead_passed += !f as u32;
            } else {
                healthy += 1;
                healthy_failed += f as u32;
            }
        }
        assert_eq!(failed & 1 << 4, 0, "board {board}: the ADXRS453 failed");
    }
    println!(
        "start-up under sway: {healthy_failed} of {healthy} healthy ICM-42688-P failed, {dead_passed} of {dead} dead ones passed"
    );
    assert_eq!(healthy_failed, 0);
    assert_eq!(dead_passed, 0);
    assert!(dead > 0);
}
