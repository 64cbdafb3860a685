//! The start-up noise self-test, one chip and the array.

use super::*;

/// Instructions of the noise-health self-test on one 2048-sample block.
/// Not inlined: its 8 KB block must not sit in main's frame (the stack
/// also holds the E-DAVAR benches' windows).
#[inline(never)]
pub(super) fn bench_selftest(t: &Ticks, ipt: f32, rng: &mut Rng) -> bool {
    let mut block = [0.0f32; gyro_array::pipeline::selftest::BLOCK];
    for v in block.iter_mut() {
        *v = 0.09 * rng.gaussian();
    }
    let t0 = t.now();
    let h = gyro_array::pipeline::selftest::noise_health(black_box(&block));
    let ticks = t.now() - t0;
    defmt::info!(
        "bench self-test (2048 samples, trend + Hurst + normality): {=u32} instructions, {=usize} B block buffer per gyro",
        (ticks as f32 * ipt) as u32,
        core::mem::size_of_val(&block)
    );
    h.is_ok_and(|h| h.stationary) && bench_selftest_array(t, ipt, rng)
}

/// Instructions of the whole self-test analysis of the board's five gyros
/// on a swaying board (each block against a fit of its peers' median, then
/// the tests): `selftest::analyse`.
#[inline(never)]
pub(super) fn bench_selftest_array(t: &Ticks, ipt: f32, rng: &mut Rng) -> bool {
    use gyro_array::pipeline::selftest::{analyse, BLOCK};
    let mut blocks = [[0.0f32; BLOCK]; 5];
    for i in 0..BLOCK {
        let w = 20.0 * libm::sinf(2.0 * core::f32::consts::PI * i as f32 * 1e-3);
        for (g, b) in blocks.iter_mut().enumerate() {
            b[i] = (1.0 + 0.01 * g as f32) * w + 0.09 * rng.gaussian();
        }
    }
    let mut results = [Err(gyro_array::algo::qualify::QualifyError::TooShort); 5];
    let t0 = t.now();
    let ok = analyse(black_box(&blocks), |_| 2, &mut results);
    let ticks = t.now() - t0;
    defmt::info!(
        "bench self-test on a swaying board (5 gyros against their peers): {=u32} instructions, pass {}",
        (ticks as f32 * ipt) as u32,
        ok
    );
    results.iter().all(|r| r.is_ok())
}
