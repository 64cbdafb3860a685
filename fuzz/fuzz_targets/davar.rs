//! E-DAVAR with arbitrary settings and samples: construction is typed,
//! pushes return, and every published estimate is finite and describes a
//! time inside its window.
#![no_main]
use gyro_array::algo::davar::{Davar, DavarConfig, EntropyKind, Placement, StepMode, Threshold};
use libfuzzer_sys::fuzz_target;
mod common;
use common::Bytes;

fuzz_target!(|data: &[u8]| {
    let mut b = Bytes(data);
    let cfg = DavarConfig {
        lambda1: b.u16() % 600,
        lambda2: b.u16() % 600,
        l_init: b.u16() % 600,
        delta_l: b.u16() % 130,
        step: if b.u8() & 1 == 0 {
            StepMode::Constant
        } else {
            StepMode::Proportional
        },
        entropy: if b.u8() & 1 == 0 {
            EntropyKind::Temporal
        } else {
            EntropyKind::Spectral
        },
        threshold: if b.u8() & 1 == 0 {
            Threshold::Fixed(b.f32())
        } else {
            Threshold::Auto { p_fa: b.f32() }
        },
        placement: if b.u8() & 1 == 0 {
            Placement::Centred
        } else {
            Placement::Segmented
        },
        tau_octaves: 1,
    };
    let Ok(mut d) = Davar::<512, 19, 6>::new(cfg) else {
        return;
    };
    while !b.is_empty() {
        let w = match b.u8() {
            0..=199 => (b.u16() as i16) as i32,
            200..=250 => b.u32() as i32 >> 11,
            251 => {
                d.reset();
                continue;
            }
            _ => b.u32() as i32,
        };
        if let Ok(Some(t)) = d.push(w) {
            let e = d.estimate().expect("published");
            assert_eq!(e.t, t);
            assert!(e.start <= t && t < e.end);
            assert!(
                e.score.is_finite() && e.threshold.is_finite()
                    || cfg.threshold != Threshold::Auto { p_fa: 0.01 }
            );
            assert!(e.avar.iter().all(|v| v.is_finite() && *v >= 0.0));
        }
    }
});
