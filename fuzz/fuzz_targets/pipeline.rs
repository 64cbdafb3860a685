//! The pipeline (health, recovery, fusion) driven by gyros whose readings,
//! errors and restart answers are arbitrary: it returns, accounts for every
//! sample, and every fused value is finite.
#![no_main]
use gyro_array::algo::fusion::{AdaptiveConfig, Method};
use gyro_array::drivers::{Gyro, ReadFault, Reading, Restart};
use gyro_array::pipeline::{Pipeline, PipelineConfig};
use libfuzzer_sys::fuzz_target;
mod common;
use common::Bytes;
use std::cell::RefCell;

struct G<'a, 'b>(&'a RefCell<Bytes<'b>>, u8);

impl Gyro for G<'_, '_> {
    fn read(&mut self) -> Result<Reading, ReadFault> {
        let mut b = self.0.borrow_mut();
        match b.u8() % 8 {
            0 => Err(ReadFault::Bus),
            1 => Err(ReadFault::Reset),
            2 => Err(ReadFault::Parity),
            3 => Err(ReadFault::Late),
            4 => Err(ReadFault::Acquiring),
            _ => {
                let raw = [b.u16() as i16, b.u16() as i16, b.u16() as i16];
                let rate = if b.u8() < 240 {
                    [
                        raw[0] as f32 / 16.4,
                        raw[1] as f32 / 16.4,
                        raw[2] as f32 / 16.4,
                    ]
                } else {
                    [b.f32(), b.f32(), b.f32()]
                };
                Ok(Reading {
                    raw,
                    rate_dps: rate,
                    axes: if self.1 == 4 { 0b100 } else { 0b111 },
                    saturated: b.u8() & 0b111 & if b.u8() < 240 { 0 } else { 0b111 },
                })
            }
        }
    }
    fn restart(&mut self, step: u8) -> Result<Restart, ReadFault> {
        let mut b = self.0.borrow_mut();
        match b.u8() % 4 {
            0 => Err(ReadFault::BadResponse),
            1 => Ok(Restart::Done),
            _ => Ok(Restart::Again {
                step: step.wrapping_add(1),
                wait_us: b.u32() % 200_000,
            }),
        }
    }
}

fuzz_target!(|data: &[u8]| {
    let bytes = RefCell::new(Bytes(data));
    let restart_after = 1 + bytes.borrow_mut().u8() as u16;
    let backoff_min = 1 + bytes.borrow_mut().u8() as u32;
    let cfg = PipelineConfig {
        restart_after,
        backoff_min,
        ..PipelineConfig::default()
    };
    let Ok(mut p) = Pipeline::<5>::new(cfg, Method::Adaptive(AdaptiveConfig::default())) else {
        return;
    };
    if bytes.borrow_mut().u8() & 1 == 0 {
        p.mark_init_failed(bytes.borrow_mut().u8() as usize);
    }
    let (mut g0, mut g1, mut g2, mut g3, mut g4) = (
        G(&bytes, 0),
        G(&bytes, 1),
        G(&bytes, 2),
        G(&bytes, 3),
        G(&bytes, 4),
    );
    let mut samples = 0u32;
    while !bytes.borrow().is_empty() {
        let mut gs: [&mut dyn Gyro; 5] = [&mut g0, &mut g1, &mut g2, &mut g3, &mut g4];
        let out = p.step(&mut gs);
        samples += 1;
        for f in out.fused.iter().flatten() {
            assert!(f.rate_dps.is_finite());
        }
    }
    for c in p.counters() {
        assert_eq!(c.reads + c.errors + c.not_read + c.late, samples);
    }
});
