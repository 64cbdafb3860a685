//! Allan variance entry points with arbitrary data and sizes.
#![no_main]
use gyro_array::algo::allan::stream::StreamAdev;
use gyro_array::algo::allan::{
    avar_phase, edf, fill_phase, local_slope, oavar_octave_phase, oavar_phase, AdevPoint, NoiseType,
};
use libfuzzer_sys::fuzz_target;
mod common;
use common::Bytes;

fuzz_target!(|data: &[u8]| {
    let mut b = Bytes(data);
    let m = match b.u8() {
        0..=200 => (b.u8() as usize) + 1,
        _ => b.u64() as usize,
    };
    let tau0 = if b.u8() < 200 { 0.001 } else { b.f64() };
    let n = (b.u16() % 300) as usize;
    let rate: Vec<f64> = (0..n)
        .map(|_| {
            if b.u8() < 230 {
                (b.u16() as i16) as f64
            } else {
                b.f64()
            }
        })
        .collect();
    let mut phase = vec![0.0; n + 1];
    if fill_phase(&rate, &mut phase).is_ok() {
        let _ = oavar_phase(&phase, tau0, m);
        let _ = avar_phase(&phase, tau0, m);
        let mut pts = [AdevPoint::default(); 24];
        let c = oavar_octave_phase(&phase, tau0, &mut pts);
        let _ = local_slope(&pts[..c.min(24)], m);
    }
    let _ = edf(NoiseType::WhiteFm, b.u64(), b.u64());
    let _ = fill_phase(&rate, &mut phase[..n / 2]);
    if let Ok(mut s) = StreamAdev::<6, 128>::new() {
        while !b.is_empty() {
            let _ = s.push(b.u32() as i32 >> (b.u8() % 32));
        }
        for j in 0..8 {
            let _ = s.point(j, 1.0, tau0);
        }
    }
});
