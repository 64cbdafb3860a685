//! The QEMU demo's world on the host (`gyro_sim::demo`: the array,
//! its start-up, its faults) through the board's schedule
//! (`gyro_array::app::sample`), sample by sample, as `demo-replay` and
//! `link-timing` run it.

use std::cell::RefCell;

use gyro_array::app::{self as schedule, timed_clock, Sampled, StatusFacts};
use gyro_array::drivers::Gyro;
use gyro_array::link::port::{ChipTime, NoiseSnapshot};
use gyro_array::pipeline::Pipeline;
use gyro_sim::{demo, with_bus, CsLine, EmuBus};
use rtic_core::Exclusive;

/// Gyros in the demo's array (four ICM-42688-P, one ADXRS453).
pub const GYROS: usize = 5;

/// The demo's start-up as `demo::start` reported it.
pub struct Started {
    /// The calibration record taken, or why not.
    pub calibration: Result<(), gyro_array::algo::static_cal::CalError>,
    /// Every gyro passed its self-test.
    pub self_test_ok: bool,
    /// Chips whose FIFO set-up failed (bit i: gyro i).
    pub fifo_failed: u8,
}

/// Run `samples` of the demo's world: `started` once after start-up, then
/// per sample `before(n)` (before the faults and the chips' step),
/// the board's sample task into `link` with the E-DAVARs' newest
/// estimates from `noise`, and `after(n, sampled, link, pipe, noise)`
/// (where the background's work goes).
pub fn run<L: schedule::Link>(
    samples: u32,
    link: &mut L,
    noise: &mut NoiseSnapshot,
    started: impl FnOnce(&Started),
    mut before: impl FnMut(u32),
    mut after: impl FnMut(u32, &Sampled<GYROS>, &mut L, &mut Pipeline<GYROS>, &mut NoiseSnapshot),
) {
    let cs: [CsLine; GYROS] = Default::default();
    let bus = RefCell::new(EmuBus::new(demo::chips(), &cs));
    let Ok(mut pipe) = demo::pipeline() else {
        panic!("the demo's pipeline refused its settings");
    };
    let demo::Started {
        chips,
        calibration,
        self_test_ok,
        fifo_failed,
    } = demo::start(&bus, &cs, &mut pipe);
    started(&Started {
        calibration,
        self_test_ok,
        fifo_failed,
    });
    let demo::Chips {
        mut timed, mut adx, ..
    } = chips;
    let now_us = with_bus(&bus, |b| b.timer_us()).unwrap_or(0);
    let mut clock = schedule::SampleClock::new(now_us, 1_000_000 / demo::FS_HZ);
    let mut clocks = [ChipTime::default(); GYROS];
    for n in 0..samples {
        before(n);
        with_bus(&bus, |b| {
            demo::inject(n, b);
            b.advance(1.0 / demo::FS_HZ as f32);
        });
        let now_us = with_bus(&bus, |b| b.timer_us()).unwrap_or(0);
        let (t_us, missed) = clock.tick(now_us);
        let s = {
            let [c0, c1, c2, c3] = &mut timed;
            let mut gyros: [&mut dyn Gyro; GYROS] = [c0, c1, c2, c3, &mut adx];
            schedule::sample(
                &mut Exclusive(&mut pipe),
                &mut Exclusive(&mut *link),
                &mut Exclusive(&mut *noise),
                &mut gyros,
                (t_us, missed),
                &demo::STATUS_VIEW,
                || {},
                || StatusFacts {
                    clocks,
                    stack_peak: 0,
                },
            )
        };
        for (slot, t) in clocks.iter_mut().zip(timed.iter()) {
            *slot = timed_clock(t);
        }
        after(n, &s, link, &mut pipe, noise);
    }
}
