//! Every fusion method on arbitrary values (NaN, inf, huge) and masks, for
//! N = 2, 4 and 5: it returns, and a fused value is finite.
#![no_main]
use gyro_array::algo::fusion::{AxisState, Fusion};
use gyro_sim::checks::methods;
use libfuzzer_sys::fuzz_target;
mod common;
use common::Bytes;

fn run<const N: usize>(b: &mut Bytes) {
    let list = methods();
    let (_, m) = list[b.u8() as usize % list.len()];
    let Ok(f) = Fusion::<N>::new(m) else { return };
    let mut st = AxisState::<N>::default();
    while !b.is_empty() {
        let mut y = [0.0f32; N];
        for v in y.iter_mut() {
            // Mostly plausible rates, sometimes raw bit patterns.
            *v = if b.u8() < 200 {
                (b.u16() as i16) as f32 / 16.0
            } else {
                b.f32()
            };
        }
        if let Ok(out) = f.fuse(&mut st, &y, b.u8()) {
            assert!(out.rate_dps.is_finite(), "{y:?} -> {}", out.rate_dps);
        }
    }
}

fuzz_target!(|data: &[u8]| {
    let mut b = Bytes(data);
    match b.u8() % 3 {
        0 => run::<2>(&mut b),
        1 => run::<4>(&mut b),
        _ => run::<5>(&mut b),
    }
});
