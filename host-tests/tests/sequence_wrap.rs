//! Months unattended: the pipeline's u32 sample number wraps after 49.7
//! days at 1 kHz. The board is run across the wrap, swaying, with a chip
//! power-cycled 40 samples before it (its restart's waits straddle the
//! wrap) and another stuck across it: every sample is fused, the
//! power-cycled chip comes back as it does anywhere else, the stuck one is
//! kept out, and the noise tracker keeps its window across the wrap, each
//! estimate naming the sample it describes.

use gyro_array::pipeline::tracker::{config, NoiseTracker};
use gyro_sim::checks::run_array_from_seq;
use gyro_sim::{with_bus, Fault, RateProfile};

#[test]
fn the_sample_number_wraps_without_a_seam() {
    // The wrap comes at sample 3000 of the run.
    const WRAP_AT: u32 = 3000;
    let first = 0u32.wrapping_sub(WRAP_AT);
    let profile = RateProfile {
        base_dps: [5.0, -3.0, 60.0],
        sine_dps: [20.0, 15.0, 30.0],
        sine_hz: 1.5,
        sine_start_s: 0.0,
    };
    let mut tracker = NoiseTracker::<1024, 35, 9>::new(config(1024)).unwrap();
    let (mut unfused, mut back_after, mut stuck_used) = (0u32, None, 0u32);
    let mut described = 0u32;
    let mut last_seq = None;
    run_array_from_seq(
        first,
        profile,
        21,
        6000,
        [Fault::None; 5],
        None,
        None,
        None,
        |n, bus, out, _| {
            assert_eq!(out.seq, first.wrapping_add(n), "sample numbers run on");
            if let Some(l) = last_seq {
                assert_eq!(out.seq, u32::wrapping_add(l, 1));
            }
            last_seq = Some(out.seq);
            let _ = match n {
                2960 => with_bus(bus, |b| b.chips[1].power_cycle()),
                2900 => with_bus(bus, |b| b.chips[3].set_fault(Fault::Stuck)),
                3600 => with_bus(bus, |b| b.chips[3].set_fault(Fault::None)),
                _ => None,
            };
            unfused += out.fused.iter().filter(|f| f.is_none()).count() as u32;
            if n > 2960 && back_after.is_none() && out.offered.iter().any(|m| m & 0b10 != 0) {
                back_after = Some(n - 2960);
            }
            if (2920..3600).contains(&n) && out.offered.iter().any(|m| m & 0b1000 != 0) {
                stuck_used += 1;
            }
            tracker.push(out);
            for a in 0..3 {
                if let Some(e) = tracker.estimate(a) {
                    // The estimate describes a sample half a window back at
                    // most a window: never ahead, never a wrap away.
                    let behind = out.seq.wrapping_sub(e.seq);
                    assert!(behind <= 1024 + 64, "axis {a} at {n}: {behind} behind");
                    assert!(e.step.avar.iter().all(|v| v.is_finite()));
                    if n > WRAP_AT + 600 {
                        described += 1;
                    }
                }
            }
        },
    )
    .unwrap();
    assert_eq!(unfused, 0, "every sample fused on every axis");
    let back = back_after.expect("the power-cycled chip came back");
    // Not before its restart's waits (1 ms after the reset, 45 ms after
    // the configuration), which straddle the wrap: compared without the
    // wrap, the last wait ended at once and the chip rejoined after 29.
    assert!(
        (46..=100).contains(&back),
        "back in fusion {back} samples after its reset"
    );
    assert_eq!(stuck_used, 0, "the stuck chip kept out across the wrap");
    assert_eq!(tracker.restarts(), 0, "no window restarted at the wrap");
    assert!(
        described > 3 * 2000,
        "estimates after the wrap: {described}"
    );
}
