//! E-DAVAR per sample: one axis and the board tracker's three, every
//! single sample counted.

use super::*;

/// E-DAVAR cost on `AXES` axes fed the same input from the very first
/// sample (so the first fill is included): instructions of every single
/// sample are measured (SysTick read around each, the read pair's own cost
/// subtracted). Prints the mean over the samples after the first estimate,
/// the worst single sample and where it happened (sample index, and its
/// position in the 32-sample hop: 1 is the hop itself).
#[inline(never)]
pub(super) fn bench_davar<
    const CAP: usize,
    const FRAMES: usize,
    const T: usize,
    const STFT: usize,
    const AXES: usize,
>(
    t: &Ticks,
    ipt: f32,
    step: bool,
    cfg: DavarConfig,
    name: &str,
) -> bool {
    // One window per axis, each built in place (a λ2 = 4096 window is
    // 33 KB of the 128 KB stack).
    let Ok(mut a0) = Davar::<CAP, FRAMES, T, STFT>::new(cfg) else {
        return false;
    };
    if AXES == 1 {
        return run_davar(t, ipt, step, name, &mut [&mut a0]);
    }
    // The tracker's stagger of the three axes' hops.
    let (Ok(a1), Ok(a2)) = (Davar::new(cfg), Davar::new(cfg)) else {
        return false;
    };
    let [p0, p1, p2] = gyro_array::pipeline::tracker::HOP_PHASES;
    a0.set_hop_phase(p0);
    let (mut a1, mut a2) = (a1.with_hop_phase(p1), a2.with_hop_phase(p2));
    run_davar(t, ipt, step, name, &mut [&mut a0, &mut a1, &mut a2])
}

/// Ticks of the bench's signal from sample `from` to the end, pushed into
/// the axes (reset first) when `WITH`, else only generated.
#[inline(never)]
pub(super) fn whole_run<
    const CAP: usize,
    const FRAMES: usize,
    const T: usize,
    const STFT: usize,
    const WITH: bool,
>(
    t: &Ticks,
    step: bool,
    from: usize,
    axes: &mut [&mut Davar<CAP, FRAMES, T, STFT>],
) -> u64 {
    for d in axes.iter_mut() {
        d.reset();
    }
    let mut rng = Rng::new(99);
    let mut t0 = t.now();
    for i in 0..WARM + ALLAN_SAMPLES {
        let x = (davar_sigma(step, i) * rng.gaussian()) as i16;
        if i == from {
            t0 = t.now();
        }
        if WITH {
            for d in axes.iter_mut() {
                let _ = black_box(d.push(black_box(x as i32)));
            }
        } else {
            black_box(x);
        }
    }
    t.now() - t0
}

/// σ of the E-DAVAR benches' white noise at sample i: doubled from the
/// middle on when `step`.
pub(super) fn davar_sigma(step: bool, i: usize) -> f32 {
    if step && i >= (WARM + ALLAN_SAMPLES) / 2 {
        200.0
    } else {
        100.0
    }
}

/// The measurement of [`bench_davar`] over the given axes.
#[inline(never)]
pub(super) fn run_davar<
    const CAP: usize,
    const FRAMES: usize,
    const T: usize,
    const STFT: usize,
>(
    t: &Ticks,
    ipt: f32,
    step: bool,
    name: &str,
    axes: &mut [&mut Davar<CAP, FRAMES, T, STFT>],
) -> bool {
    // Cost of the timing itself: two reads back to back, averaged.
    let pair = pair_cost(t);
    let mut ok = true;
    let (mut total, mut counted) = (0.0f32, 0u32);
    let (mut worst, mut worst_at) = (0.0f32, 0usize);
    let (mut published, mut first) = (false, 0);
    // Mean cost by position in the 32-sample hop (after the first estimate).
    let mut by_phase = [0.0f32; 32];
    // White noise generated on the fly (no sample array on the stack), of
    // σ `davar_sigma`.
    let mut rng = Rng::new(99);
    for i in 0..WARM + ALLAN_SAMPLES {
        let x = (davar_sigma(step, i) * rng.gaussian()) as i16;
        let t0 = t.now();
        for d in axes.iter_mut() {
            let r = d.push(black_box(x as i32));
            ok &= r.is_ok();
            published |= matches!(r, Ok(Some(_)));
        }
        let ticks = net(t.now() - t0, pair);
        if ticks > worst {
            worst = ticks;
            worst_at = i;
        }
        if published {
            if counted == 0 {
                first = i;
            }
            total += ticks;
            counted += 1;
            by_phase[(i + 1) % 32] += ticks;
        }
    }
    // The mean once more, exactly: the same samples timed as one stretch
    // (a reading at each end, none per sample), less the same stretch
    // without the E-DAVAR (the signal's generation alone). The per-sample
    // mean carries the timer's pair cost, which moves by tens of
    // instructions between builds; this does not.
    let bare = whole_run::<CAP, FRAMES, T, STFT, false>(t, step, first, axes);
    let with = whole_run::<CAP, FRAMES, T, STFT, true>(t, step, first, axes);
    let exact = with.saturating_sub(bare) as f32 * ipt / counted.max(1) as f32;
    let f = |ticks: f32| (ticks * ipt) as u32;
    defmt::info!(
        "bench e-davar {=str} lambda2 = {=usize} ({=usize} tau, {=usize} axis/axes): mean {=u32} instructions per sample (timed per sample: {=u32}), worst {=u32} at sample {=usize} (hop phase {=usize}), {=usize} B RAM per axis",
        name,
        CAP,
        T,
        axes.len(),
        exact as u32,
        (total * ipt / counted.max(1) as f32) as u32,
        f(worst),
        worst_at,
        (worst_at + 1) % 32,
        core::mem::size_of::<Davar<CAP, FRAMES, T, STFT>>()
    );
    if axes.len() == 1 && STFT == 0 {
        let hops = (counted / 32).max(1) as f32;
        let p = by_phase.map(|x| (x * ipt / hops) as u32);
        defmt::info!(
            "  mean by hop phase (0 = frame end, 1 = hop, 2.. = one tau each): {=[?]}",
            p[..]
        );
    }
    let est = axes[0].estimate();
    ok && est.is_some_and(|e| e.avar[0] > 0.0)
}
