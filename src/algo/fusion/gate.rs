//! The adaptive method's gates: the warm-up gate on the spread, the
//! median gate on each gyro's noise model, and the consensus gate when two
//! or more gyros are off.

use super::median::{gate_median, median, median_of};
use super::{has, AdaptiveConfig};
use crate::algo::math::sqrtf;

/// The median gate left fewer than two gyros. With an even count the
/// median is the mean of the middle two, so one wild value plus one noisy
/// but honest one (an ADXRS453 among ICM-42688-Ps) can pull it off every
/// quiet gyro: drop the most outlying value and gate again about the new
/// median.
pub(super) fn regate_without_worst<const N: usize>(
    y: &[f32; N],
    v: &[f32; N],
    active: u8,
    med: f32,
    k2: f32,
    v_med: f32,
) -> u8 {
    let mut worst = (0.0f32, 0usize);
    for i in 0..N {
        let e = y[i] - med;
        let z = if has(active, i) {
            e * e / (v[i] + v_med)
        } else {
            0.0
        };
        if z > worst.0 {
            worst = (z, i);
        }
    }
    let rest = active & !(1u8 << (worst.1 & 7));
    if rest & rest.wrapping_sub(1) == 0 {
        // One gyro left (two were active: a pair fused while others that
        // stuck are not yet flagged): it is within the gate about its own
        // value. Through the median's sort and the gate this cost a 3-axis
        // sample 100 more (`cargo xtask bench-loop`, scenario F).
        return rest;
    }
    let med = gate_median(y, v, rest);
    let mut good = rest;
    for i in 0..N {
        let e = y[i] - med;
        let off = e * e > k2 * (v[i] + v_med);
        good &= !(((has(rest, i) && off) as u8) << i);
    }
    good
}

/// The first gate kept fewer than two gyros or left two or more out
/// (rare, so out of line): [`regate_without_worst`] for the first, then
/// [`consensus_gate`] if two or more are out. Also says whether the gyros
/// split with no majority.
#[cold]
#[inline(never)]
#[allow(clippy::too_many_arguments)]
pub(super) fn regate<const N: usize>(
    y: &[f32; N],
    v: &[f32; N],
    w: &[f32; N],
    active: u8,
    mut good: u8,
    med: f32,
    k2: f32,
    v_med: f32,
) -> (u8, bool) {
    if good & good.wrapping_sub(1) == 0 {
        good = regate_without_worst(y, v, active, med, k2, v_med);
    }
    let off = active & !good;
    if off & off.wrapping_sub(1) != 0 {
        return consensus_gate(y, v, w, active, good, k2, v_med);
    }
    (good, false)
}

/// The gate rejected two or more gyros. With an even count the median
/// sits between the middle two, and when two chips agree by chance with a
/// faulty one (a bit error that moved a chip by 1 °/s, beside a noisy but
/// honest ADXRS453) the gate can keep the wrong pair and reject the quiet
/// majority (the fault campaign finds such cases in 10 000 runs). So
/// take every active gyro's value in turn as the reference, gate the
/// others about it as about the median (residual variance vᵢ + v_med: a
/// reference's own variance must not widen the gate, or a chip the noise
/// model already distrusts would vouch for everybody), and keep the
/// largest consistent set; the first gate's choice stands unless another
/// set has more gyros or, as many, fits its members better (the least
/// weighted spread Σwᵢ(yᵢ − ȳ)², a χ² with as many degrees of freedom).
/// A noisy chip (an ADXRS453) sits within the wide gate of two pairs that
/// disagree, so both sets count the same; its reading still says which
/// pair it is near, and the spread reads that where the sets' total
/// weights cannot (two chips with a corrupted range, their noise model
/// frozen while gated out, can outweigh the quiet pair). Returns the set, and whether it is no majority of the
/// active gyros (a split: two against two). Two rejections are rare (two
/// faulty chips at once), so this is out of line.
#[cold]
#[inline(never)]
pub(super) fn consensus_gate<const N: usize>(
    y: &[f32; N],
    v: &[f32; N],
    w: &[f32; N],
    active: u8,
    first: u8,
    k2: f32,
    v_med: f32,
) -> (u8, bool) {
    // Each gyro's gate (its residual variance times k²), then, for every
    // pair once, whether each is within the other's: the same sets as
    // gating all gyros about each reference in turn, with half the
    // squares (this runs on the loop's worst samples: two chips spiking on
    // one axis).
    let mut lim = [0.0f32; N];
    for i in 0..N {
        lim[i] = k2 * (v[i] + v_med);
    }
    let mut agree = [0u8; N];
    for j in 0..N {
        agree[j] |= u8::from(0.0 <= lim[j]) << j;
        for i in 0..j {
            let e = y[i] - y[j];
            let e2 = e * e;
            agree[j] |= u8::from(e2 <= lim[i]) << i;
            agree[i] |= u8::from(e2 <= lim[j]) << j;
        }
    }
    // The set's weighted spread about its weighted mean, from the
    // caller's weights (1/vᵢ over the active gyros: every set here is
    // within them).
    let spread = |set: u8| -> f32 { weighted_spread(y, w, set) };
    // Majority logic first (more gyros agreeing wins), fit second: the
    // spreads are only summed for a tie.
    let (mut best, mut best_n, mut best_s) = (first, first.count_ones(), None);
    for j in 0..N {
        let set = agree[j] & active;
        let n = set.count_ones();
        if !has(active, j) || n < 2 || n < best_n {
            continue;
        }
        if n > best_n {
            (best, best_n, best_s) = (set, n, None);
            continue;
        }
        if set == best {
            // (Most references give the same set: no spread to compare.)
            continue;
        }
        let bs = *best_s.get_or_insert_with(|| spread(best));
        let s = spread(set);
        if s < bs {
            (best, best_s) = (set, Some(s));
        }
    }
    // Split: the largest consistent set is not a majority of the gyros.
    (best, 2 * best_n <= active.count_ones())
}

/// Σ wᵢ(yᵢ − ȳ)² over `set`, ȳ the set's weighted mean, in index order.
pub(super) fn weighted_spread<const N: usize>(y: &[f32; N], w: &[f32; N], set: u8) -> f32 {
    let (mut sw, mut swy) = (0.0f32, 0.0f32);
    for i in 0..N {
        if has(set, i) {
            sw += w[i];
            swy += w[i] * y[i];
        }
    }
    let mean = swy / sw;
    let mut s = 0.0f32;
    for i in 0..N {
        if has(set, i) {
            let e = y[i] - mean;
            s += w[i] * e * e;
        }
    }
    s
}

/// Gate of the warm-up (robust sigmas from the median): wide, because a
/// MAD of three to five values is a rough scale.
pub(super) const WARM_GATE: f32 = 6.0;

/// Warming up (the first `warmup` samples, or a gyro that just joined): no
/// noise model yet, so gate on the spread itself. A value more than
/// [`WARM_GATE`] robust sigmas (1.4826 · MAD about the median) from the
/// median is left out, so a chip that spikes or garbles frames from
/// power-up is not averaged in. Also returns the limit squared, which caps
/// what one sample adds to a warming chip's noise estimate. Out of line:
/// it runs for a few dozen samples after start-up or a rejoin.
#[cold]
#[inline(never)]
pub(super) fn warm_up_gate<const N: usize>(
    c: &AdaptiveConfig,
    y: &[f32; N],
    active: u8,
    med: f32,
) -> (u8, f32) {
    let mut dev = [0.0f32; N];
    for i in 0..N {
        dev[i] = (y[i] - med).abs();
    }
    let lim = WARM_GATE * (1.4826 * median(&dev, active)).max(sqrtf(c.var_floor));
    let mut good = active;
    for i in 0..N {
        good &= !(((has(active, i) && dev[i] > lim) as u8) << i);
    }
    (good, lim * lim)
}

/// The first gate's result: the voters' median, those off it, and the
/// typical variance term.
pub(super) type Gate = (f32, u8, f32);

/// [`first_gate`] for any voters, out of line.
#[inline(never)]
pub(super) fn first_gate_any<const N: usize>(
    c: &AdaptiveConfig,
    y: &[f32; N],
    v: &[f32; N],
    voters: u8,
    n: u32,
    all_warm: bool,
) -> Gate {
    first_gate(c, y, v, voters, n, all_warm)
}

/// The median of `voters` (`n` of them) and, once all are warm and there
/// are three or more, the voters off it and the typical variance term of
/// the gate (0 and 0 otherwise).
#[inline(always)]
pub(super) fn first_gate<const N: usize>(
    c: &AdaptiveConfig,
    y: &[f32; N],
    v: &[f32; N],
    voters: u8,
    n: u32,
    all_warm: bool,
) -> Gate {
    let med = if all_warm {
        gate_median(y, v, voters)
    } else {
        median_of(y, voters)
    };
    if !(n >= 3 && all_warm) {
        return (med, 0, 0.0);
    }
    // The typical variance: the mean of the active gyros' without the
    // largest. The plain mean let one very noisy or spiking gyro widen
    // the gate for all (the fault campaign found a second faulty chip
    // getting through that way); a median of the variances did as well
    // at ~60 more instructions per 3-axis sample.
    let (mut vsum, mut vmax) = (0.0f32, 0.0f32);
    for i in 0..N {
        let vi = if has(voters, i) { v[i] } else { 0.0 };
        vsum += vi;
        vmax = if vi > vmax { vi } else { vmax };
    }
    let nm1 = n as f32 - 1.0;
    let k2 = c.gate_k * c.gate_k;
    // vbar / (n − 1), with vbar = (vsum − vmax) / (n − 1).
    let v_med = (vsum - vmax) / (nm1 * nm1);
    let mut offm = 0u8;
    for i in 0..N {
        let e = y[i] - med;
        let off = has(voters, i) && e * e > k2 * (v[i] + v_med);
        offm |= (off as u8) << i;
    }
    (med, offm, v_med)
}
