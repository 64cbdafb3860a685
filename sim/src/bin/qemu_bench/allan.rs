//! Streaming ADEV at ten octave τ, per input sample.

use super::*;

/// Streaming ADEV (10 octave τ), instructions per sample.
#[inline(never)]
pub(super) fn bench_allan(t: &Ticks, ipt: f32, rng: &mut Rng) -> bool {
    let mut ok = true;
    // Noise samples for the streaming ADEV bench (the E-DAVAR benches make
    // their own, so no large array sits on the stack beside their windows).
    let mut samples = [0i16; ALLAN_SAMPLES];
    for x in samples.iter_mut() {
        *x = (100.0 * rng.gaussian()) as i16;
    }
    let per = |ticks: u64, n: usize| ticks as f32 * ipt / n as f32;
    let loop_ticks = {
        let t0 = t.now();
        for &x in &samples {
            black_box(x as i32);
        }
        t.now() - t0
    };

    let Ok(mut adev) = StreamAdev::<10, 1024>::new() else {
        exit(false)
    };
    let t0 = t.now();
    for &x in &samples {
        ok &= adev.push(black_box(x as i32)).is_ok();
    }
    let ticks = (t.now() - t0).saturating_sub(loop_ticks);
    defmt::info!(
        "bench allan stream (10 octave tau): {=u32} instructions per sample, {=usize} B RAM per axis",
        per(ticks, ALLAN_SAMPLES) as u32,
        core::mem::size_of::<StreamAdev<10, 1024>>()
    );

    ok
}
