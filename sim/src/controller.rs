//! An antenna controller's clock and sync output, for the evaluation of the
//! board's tracker (`link::sync`): the controller's crystal off the board's
//! by a constant part and a part that changes with time (temperature), a
//! pulse every period of its own clock, each pulse's own timestamp read
//! with jitter (its interrupt latency and its clock's granularity), the
//! board's capture of the edge late by up to its interrupt's latency, and
//! lost messages and missed pulses.

use super::Rng;
use gyro_array::link::sync::{CtrlClock, SyncState};

/// The controller and the wires.
#[derive(Clone, Copy, Debug)]
pub struct CtrlParams {
    /// Its clock at the board's time 0, µs.
    pub offset_us: u64,
    /// Its crystal against the board's, ppm (positive: fast).
    pub ppm: f64,
    /// How fast that changes, ppm an hour.
    pub ppm_per_hour: f64,
    /// 1σ of its timestamp of each pulse, µs.
    pub stamp_jitter_us: f64,
    /// Pulse period, µs of its own clock.
    pub period_us: u64,
    /// The board's capture is late by up to this, µs (uniform).
    pub capture_latency_us: f64,
    /// Every n-th time message is lost (0: none).
    pub lose_message_every: u32,
    /// Every n-th pulse is not captured (0: none).
    pub miss_pulse_every: u32,
}

impl CtrlParams {
    /// The controller: ±50 ppm, 10 µs of timestamp jitter, a pulse
    /// a second, the board's capture up to 2 µs late (an EXTI interrupt
    /// behind the sample task's locks).
    pub fn typical(ppm: f64) -> Self {
        Self {
            offset_us: 1_234_567_890_123,
            ppm,
            ppm_per_hour: 2.0,
            stamp_jitter_us: 10.0,
            period_us: 1_000_000,
            capture_latency_us: 2.0,
            lose_message_every: 0,
            miss_pulse_every: 0,
        }
    }

    /// The controller's clock at the board's time `t_us` (exact).
    pub fn clock(&self, t_us: f64) -> f64 {
        let drift = self.ppm * t_us + 0.5 * self.ppm_per_hour / 3.6e9 * t_us * t_us;
        self.offset_us as f64 + t_us + drift * 1e-6
    }

    /// The board's time at which the controller's clock reads `c`.
    fn board_time_of(&self, c: f64) -> f64 {
        let mut t = c - self.offset_us as f64;
        for _ in 0..3 {
            t -= self.clock(t) - c;
        }
        t
    }
}

/// What a run measured.
#[derive(Clone, Copy, Debug, Default)]
pub struct SyncReport {
    /// RMS and worst error of the instants stated in the controller's
    /// clock, every ms from the pulse that locked the tracker, µs.
    pub rms_us: f64,
    /// The worst.
    pub worst_us: f64,
    /// The same from the [`gyro_array::link::sync::WINDOW`]-th pulse on.
    pub rms_settled_us: f64,
    /// The worst there.
    pub worst_settled_us: f64,
    /// Pulses until locked.
    pub lock_pulses: u32,
    /// From the last pulse to the tracker saying it is lost, µs (`None`:
    /// the pulse did not stop, or it was never said).
    pub lost_after_us: Option<u64>,
    /// Pairs the gate dropped, and messages without a pulse.
    pub dropped: u32,
    /// The latter.
    pub unpaired: u32,
    /// Board ms with no controller time stated after the lock (while
    /// pulses still came).
    pub unstated_ms: u32,
}

/// Run the controller and the board's tracker for `seconds` of board time;
/// the pulses stop at `stop_s` if given.
pub fn run(p: &CtrlParams, seconds: u32, stop_s: Option<u32>, seed: u64) -> SyncReport {
    let mut rng = Rng::new(seed);
    let mut clock = CtrlClock::new();
    let end = u64::from(seconds) * 1_000_000;
    let stop = stop_s.map(|s| u64::from(s) * 1_000_000).unwrap_or(u64::MAX);
    // The controller's first pulse: its next whole period after the start.
    let first = (p.offset_us / p.period_us + 1) * p.period_us;
    let mut k: u64 = 0;
    let mut next_pulse = p.board_time_of(first as f64);
    let mut message: Option<(f64, u64)> = None;
    let mut r = SyncReport::default();
    let (mut n, mut ss, mut n_settled, mut ss_settled) = (0u64, 0.0, 0u64, 0.0);
    let mut pulses = 0u32;
    let mut last_pulse = 0u64;
    for t in (0..end).step_by(1000) {
        // Pulses and messages due before this ms, in order.
        while next_pulse <= t as f64 && (next_pulse as u64) < stop {
            k += 1;
            pulses += 1;
            let late = f64::from(rng.uniform()) * p.capture_latency_us;
            let captured =
                p.miss_pulse_every == 0 || !k.is_multiple_of(u64::from(p.miss_pulse_every));
            if captured {
                clock.pulse((next_pulse + late) as u64);
            }
            last_pulse = next_pulse as u64;
            let stamp = p.clock(next_pulse) + f64::from(rng.gaussian()) * p.stamp_jitter_us;
            let lost =
                p.lose_message_every != 0 && k.is_multiple_of(u64::from(p.lose_message_every));
            if !lost {
                // Through the controller's UART queue: 2 ms later.
                message = Some((next_pulse + 2_000.0, libm::round(stamp) as u64));
            }
            let c = first + k * p.period_us;
            next_pulse = p.board_time_of(c as f64);
        }
        if let Some((at, stamp)) = message {
            if at <= t as f64 {
                clock.time(stamp);
                message = None;
            }
        }
        clock.tick(t);
        if clock.state() == SyncState::Locked && r.lock_pulses == 0 {
            r.lock_pulses = pulses;
        }
        if clock.state() == SyncState::Lost && r.lost_after_us.is_none() && t >= stop {
            r.lost_after_us = Some(t - last_pulse);
        }
        if r.lock_pulses == 0 || t >= stop {
            continue;
        }
        let Some(stated) = clock.to_ctrl(t) else {
            r.unstated_ms += 1;
            continue;
        };
        let e = stated as f64 - p.clock(t as f64);
        n += 1;
        ss += e * e;
        r.worst_us = r.worst_us.max(e.abs());
        if pulses as usize > gyro_array::link::sync::WINDOW {
            n_settled += 1;
            ss_settled += e * e;
            r.worst_settled_us = r.worst_settled_us.max(e.abs());
        }
    }
    r.rms_us = libm::sqrt(ss / n.max(1) as f64);
    r.rms_settled_us = libm::sqrt(ss_settled / n_settled.max(1) as f64);
    r.dropped = clock.dropped;
    r.unpaired = clock.unpaired;
    r
}

/// The board's clock tracking (`gyro_array::link::sync`) against these
/// controllers.
#[cfg(test)]
mod tests {
    use super::*;
    use gyro_array::link::sync::{LOCK_PAIRS, LOST_PERIODS};

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
}
