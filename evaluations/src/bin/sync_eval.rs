//! sync-eval: the board's tracking of the antenna controller's clock
//! (`gyro_array::link::sync`), against emulated controllers
//! (`gyro_sim::controller`): crystals from −50 to +50 ppm drifting
//! 0 to 10 ppm an hour, 10 µs of timestamp jitter, a pulse a second, the
//! board's capture up to 2 µs late; lost messages and missed pulses; a
//! pulse that stops. Prints the error of the instants the board states in
//! the controller's clock (every ms, against the controller's true clock)
//! and checks the targets: ≤ 20 µs 1σ after the lock, a stopped pulse
//! called lost within three periods.
//!
//! `cargo run --profile host -p evaluations --bin sync-eval [-- SECONDS [SEEDS]]`

use gyro_array::link::sync::LOST_PERIODS;
use gyro_sim::controller::{run, CtrlParams};

fn main() {
    gyro_tool::pipe::quiet_on_closed_pipe();
    let mut args = std::env::args().skip(1);
    let seconds: u32 = args.next().and_then(|a| a.parse().ok()).unwrap_or(600);
    let seeds: u64 = args.next().and_then(|a| a.parse().ok()).unwrap_or(10);
    println!("controller clock tracking, {seconds} s a run, {seeds} seeds a row; errors in us (1 sigma = RMS over every ms)");
    println!(
        "{:>8} {:>9} {:>12} {:>10} {:>11} {:>10} {:>11} {:>7} {:>8}",
        "ppm",
        "ppm/h",
        "case",
        "lock puls",
        "rms locked",
        "worst",
        "rms settled",
        "dropped",
        "unstated"
    );
    let mut worst_rms: f64 = 0.0;
    let mut ok = true;
    for (case, lose, miss) in [("clean", 0, 0), ("lossy", 7, 11)] {
        for ppm in [-50.0, -20.0, 0.0, 20.0, 50.0] {
            for drift in [0.0, 2.0, 10.0] {
                let p = CtrlParams {
                    ppm_per_hour: drift,
                    lose_message_every: lose,
                    miss_pulse_every: miss,
                    ..CtrlParams::typical(ppm)
                };
                let rs: Vec<_> = (0..seeds)
                    .map(|s| run(&p, seconds, None, 100 + s))
                    .collect();
                let lock = rs.iter().map(|r| r.lock_pulses).max().unwrap_or(0);
                let rms = rs.iter().map(|r| r.rms_us).fold(0.0, f64::max);
                let worst = rs.iter().map(|r| r.worst_us).fold(0.0, f64::max);
                let settled = rs.iter().map(|r| r.rms_settled_us).fold(0.0, f64::max);
                let dropped: u32 = rs.iter().map(|r| r.dropped + r.unpaired).sum();
                let unstated: u32 = rs.iter().map(|r| r.unstated_ms).sum();
                println!(
                    "{ppm:>+8.0} {drift:>9.0} {case:>12} {lock:>10} {rms:>11.2} {worst:>10.1} {settled:>11.2} {dropped:>7} {unstated:>8}"
                );
                worst_rms = worst_rms.max(rms);
                ok &= rms <= 20.0;
            }
        }
    }
    // A pulse that stops is called lost within three of its periods (the
    // controller's, on the board's clock), plus the 1 ms the check runs at;
    // controllers from −50 to +50 ppm in turn.
    let (mut worst_lost, mut worst_bound) = (0u64, 0u64);
    for s in 0..seeds {
        let p = CtrlParams::typical(-50.0 + 10.0 * (s % 11) as f64);
        let r = run(&p, 200, Some(100), 200 + s);
        let period = p.period_us as f64 / (1.0 + p.ppm * 1e-6);
        let bound = (LOST_PERIODS as f64 * period).ceil() as u64 + 1_000;
        match r.lost_after_us {
            Some(t) => {
                ok &= t <= bound;
                worst_lost = worst_lost.max(t);
                worst_bound = worst_bound.max(bound);
            }
            None => {
                println!("seed {s}: a stopped pulse was never called lost");
                ok = false;
            }
        }
    }
    println!(
        "worst RMS after the lock {worst_rms:.2} us (target 20); a stopped pulse called lost {:.6} s after its last edge at worst (bound: three of the controller's periods and 1 ms, at most {:.6} s)",
        worst_lost as f64 * 1e-6,
        worst_bound as f64 * 1e-6
    );
    println!("targets {}", if ok { "met" } else { "NOT met" });
    std::process::exit(i32::from(!ok));
}
