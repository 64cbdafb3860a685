use super::*;
use crate::emu::controller::{run, CtrlParams};

#[test]
fn instants_in_the_controllers_clock_are_within_20_us() {
    for ppm in [-50.0, 0.0, 50.0] {
        for seed in [1, 2, 3] {
            let p = CtrlParams::typical(ppm);
            let r = run(&p, 300, None, seed);
            println!("{ppm:+} ppm seed {seed}: {r:?}");
            assert!(r.lock_pulses as usize <= LOCK_PAIRS + 1, "{r:?}");
            assert!(r.rms_settled_us < 20.0, "{ppm} ppm: {r:?}");
            assert!(r.rms_us < 20.0, "{ppm} ppm: {r:?}");
            assert_eq!((r.dropped, r.unpaired, r.unstated_ms), (0, 0, 0), "{r:?}");
        }
    }
}

#[test]
fn a_stopped_pulse_is_called_lost_within_three_periods() {
    let p = CtrlParams::typical(30.0);
    let r = run(&p, 120, Some(60), 4);
    let lost = r.lost_after_us.expect("never called lost");
    assert!(lost <= LOST_PERIODS * 1_000_000 + 1_000, "{lost} us");
    assert!(
        lost > (LOST_PERIODS - 1) * 1_000_000,
        "{lost} us: too eager"
    );
}

#[test]
fn lost_messages_and_missed_pulses_are_dropped_not_believed() {
    let p = CtrlParams {
        lose_message_every: 7,
        miss_pulse_every: 11,
        ..CtrlParams::typical(-40.0)
    };
    let r = run(&p, 300, None, 5);
    println!("{r:?}");
    // A missed capture leaves its message paired with nothing or with the
    // pulse before (a period off): dropped either way.
    assert!(r.dropped + r.unpaired > 0, "{r:?}");
    assert!(r.rms_us < 20.0 && r.worst_us < 100.0, "{r:?}");
}

#[test]
fn a_line_started_on_a_wrong_pair_starts_again() {
    let mut c = CtrlClock::new();
    // Two pairs a period apart in the controller's time but not the
    // board's: a rate of 100 %, then right pairs.
    c.pulse(0);
    c.time(5_000_000);
    c.pulse(1_000_000);
    c.time(7_000_000);
    for k in 2..12u64 {
        c.pulse(k * 1_000_000);
        c.time(5_000_000 + k * 1_000_000);
    }
    assert_eq!(c.state(), SyncState::Locked);
    let (_, _, ppm, _) = c.line().unwrap();
    assert!(ppm.abs() < 1.0, "{ppm}");
    assert_eq!(c.to_ctrl(20_000_000), Some(25_000_000));
}
