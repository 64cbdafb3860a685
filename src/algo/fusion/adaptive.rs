//! The adaptive method (ours, the default): per-gyro noise variances from
//! the pairs' slow mean squares (the N-cornered hat, [`attribute`]; with
//! two gyros, from the residual against the other), weights that tend to
//! equal where the evidence is weak, a drift watch ([`rise`]), and the
//! dispatch that runs each set of three or more gyros with a constant
//! mask.

use super::frozen::frozen_check;
use super::gate::{first_gate, first_gate_any, regate, warm_up_gate, Gate};
use super::{each_pair, full, has, mean_of, put, weighted, AdaptiveConfig, AxisState, Fused};
use crate::algo::math::at_least;

/// The adaptive method over `valid`, into `out`; false if nothing fused.
pub(super) fn adaptive<const N: usize>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    valid: u8,
    out: &mut Fused<N>,
) -> bool {
    if valid == 0 {
        return false;
    }
    // Sets of three or more gyros run with a constant mask when N ≤ 5 (16
    // sets for the board's five, 5 for four, 1 for three), and all gyros
    // do for larger N. With the mask a constant, every phase's mask tests
    // fold away and its lane loops shrink to the gyros in the set: after a
    // chip fails, the loop costs what it did before (through the general
    // mask, three of five cost some 1.5× the constant four of five). Sets
    // of one or two have no gate and take the general path. Same
    // arithmetic in the same order either way.
    // With fewer than five gyros, all of them (the usual case) is inlined
    // here, which saves the call; with five, inlining it makes the other
    // sets' calls dearer.
    if N < 5 && valid == full::<N>() {
        adaptive_const(c, st, y, full::<N>(), out)
    } else {
        adaptive_dispatch(c, st, y, valid, out)
    }
}

/// [`adaptive`] for the sets not inlined there: the jump table.
#[inline(never)]
pub(super) fn adaptive_dispatch<const N: usize>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    valid: u8,
    out: &mut Fused<N>,
) -> bool {
    macro_rules! dispatch {
        ($($m:literal)*) => {
            match valid {
                $( $m if N <= 5 && ($m as u32) >> N == 0 => adaptive_set::<N, $m>(c, st, y, out), )*
                _ if N > 5 && valid == full::<N>() => adaptive_set::<N, 0>(c, st, y, out),
                _ => adaptive_general(c, st, y, valid, out),
            }
        };
    }
    dispatch!(7 11 13 14 15 19 21 22 23 25 26 27 28 29 30 31)
}

/// [`adaptive`] with the constant set `M` valid (0: all N gyros): one copy
/// per set, its phases inlined with the mask folded in.
#[inline(never)]
pub(super) fn adaptive_set<const N: usize, const M: u8>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    out: &mut Fused<N>,
) -> bool {
    adaptive_const(c, st, y, if M == 0 { full::<N>() } else { M }, out)
}

/// [`adaptive`] with the set `m` valid, inlined for a constant `m`.
#[inline(always)]
pub(super) fn adaptive_const<const N: usize>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    m: u8,
    out: &mut Fused<N>,
) -> bool {
    let active = frozen_check(c, st, y, m);
    if active == m {
        put(
            adaptive_active(c, st, y, m, m, m, (true, true), None, out),
            out,
        )
    } else if active != 0 {
        // A frozen chip votes but is not fused: the gate is over the
        // voters, the constant `m`, so it is taken here, folded, and passed
        // on, not through the general mask.
        let all_warm = active & !st.warm == 0;
        let v = floored(st, c);
        let g = first_gate(c, y, &v, m, m.count_ones(), all_warm);
        adaptive_frozen(c, st, y, m, active, Some((g, v)), out)
    } else {
        adaptive_frozen(c, st, y, m, active, None, out)
    }
}

/// Each gyro's variance for the gate, floored: its share of the slow
/// pairs, or, in a burst, its quick mean square from the median. The
/// slow share is the vibration of a whole flight (its growing window is
/// longer than a quadrotor's 30 s flights at 120 Hz); in a manoeuvre's
/// burst the chips' disagreement is several times it, and a gate on the
/// slow share alone left a chip out on 0.5–2 % of a flight's samples
/// (a fault at 5σ would be 10⁻⁶).
#[inline(always)]
pub(super) fn floored<const N: usize>(st: &AxisState<N>, c: &AdaptiveConfig) -> [f32; N] {
    let mut v = [0.0f32; N];
    for i in 0..N {
        let g = st.gvar[i];
        let f = st.ef[i];
        let f = if f > BURST_CAP * g { BURST_CAP * g } else { f };
        v[i] = at_least(if f > g { f } else { g }, c.var_floor);
    }
    v
}

/// The quick mean square widens the gate to at most this multiple of the
/// slow share (2× in σ): enough for a manoeuvre's burst on the quadrotor
/// flights (the same leave-one-out as without a cap), while a chip whose
/// faults pass the gate cannot widen its own gate without bound.
pub(super) const BURST_CAP: f32 = 4.0;

/// Factor of the gate's quick mean square (a time constant of 64
/// samples; its χ² with 128 degrees of freedom reads within ±25 %).
pub(super) const GATE_ALPHA: f32 = 1.0 / 64.0;

/// [`adaptive`] for any set.
#[inline(never)]
pub(super) fn adaptive_general<const N: usize>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    valid: u8,
    out: &mut Fused<N>,
) -> bool {
    let active = frozen_check(c, st, y, valid);
    adaptive_frozen(c, st, y, valid, active, None, out)
}

/// The rest of [`adaptive`] once the frozen check has left `active` of
/// `valid`. Frozen candidates are not fused but still vote in the median
/// gate: a healthy chip that repeats a quantised value four times (it
/// happens) must not leave a faulty one ungated for want of a quorum
/// (three gyros on x, one rescaled, one repeating: without its vote the
/// rescaled one is fused). A chip that sticks is frozen here for the 12
/// samples until the pipeline flags it stuck, on every axis: the gyros
/// left to fuse run with a constant mask too (the gate, over the voters,
/// with the general one), or each of those samples costs some 1 750
/// instructions more.
#[inline(never)]
pub(super) fn adaptive_frozen<const N: usize>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    valid: u8,
    active: u8,
    gate: Option<(Gate, [f32; N])>,
    out: &mut Fused<N>,
) -> bool {
    if active == 0 {
        out.rejected |= valid;
        return false;
    }
    macro_rules! dispatch {
        ($($m:literal)*) => {
            match active {
                $( $m if N <= 5 && ($m as u32) >> N == 0 => adaptive_fused_set::<N, $m>(c, st, y, valid, gate, out), )*
                _ => put(adaptive_active(c, st, y, valid, active, valid, (false, false), gate, out), out),
            }
        };
    }
    // (Pairs among the first four too: two ICM-42688-Ps left on x or y
    // while two others that stuck together are not yet flagged, 300
    // instructions more through the general path.)
    dispatch!(3 5 6 9 10 12 7 11 13 14 15 19 21 22 23 25 26 27 28 29 30)
}

/// [`adaptive_frozen`] fusing the constant set `M` of `valid`.
#[inline(never)]
pub(super) fn adaptive_fused_set<const N: usize, const M: u8>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    valid: u8,
    gate: Option<(Gate, [f32; N])>,
    out: &mut Fused<N>,
) -> bool {
    put(
        adaptive_active(c, st, y, valid, M, valid, (false, true), gate, out),
        out,
    )
}

/// Weights, median gate, noise update and the fused value over `active`;
/// the gate's median and quorum are over `voters` (⊇ `active`).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn adaptive_active<const N: usize>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    valid: u8,
    active: u8,
    voters: u8,
    (fast_gate, fast_fuse): (bool, bool),
    gate: Option<(Gate, [f32; N])>,
    out: &mut Fused<N>,
) -> Option<(f32, [f32; N])> {
    let n = voters.count_ones();
    // Current weights: inverse variance once warmed up, equal before.
    let all_warm = active & !st.warm == 0;
    let v = match gate {
        Some((_, v)) => v,
        None => floored(st, c),
    };
    let mut w = [0.0f32; N];
    for i in 0..N {
        let wi = if all_warm {
            1.0 / at_least(st.var[i], c.var_floor)
        } else {
            1.0
        };
        w[i] = if has(active, i) { wi } else { 0.0 };
    }
    // Median gate (needs 3 gyros to tell which one is off): the residual
    // y_i − median has variance about σ_i² + (typical σ²)/(n − 1). With
    // `fast_gate`, the voters are `active` and it is a constant; `gate`,
    // the caller took it.
    let (med, offm, v_med) = match gate {
        Some((g, _)) => g,
        None if fast_gate => first_gate(c, y, &v, active, n, all_warm),
        None => first_gate_any(c, y, &v, voters, n, all_warm),
    };
    let k2 = c.gate_k * c.gate_k;
    let mut good = active;
    let mut warm_cap = f32::INFINITY;
    if n >= 3 && all_warm {
        good = active & !offm;
        // Voters that agree with the median: the fused ones and any frozen
        // candidate (a healthy chip repeating a value still vouches).
        let mut support = voters & !offm;
        // Fewer than two agree, or two or more fused gyros out (one AND
        // each, no popcount): rare, out of line.
        let out_active = active & offm;
        if support & support.wrapping_sub(1) == 0 || out_active & out_active.wrapping_sub(1) != 0 {
            let split;
            (good, split) = regate(y, &v, &w, active, good, med, k2, v_med);
            support = good | (voters & !active & !offm);
            if split {
                // No majority agrees (two chips against two): nothing
                // tells which pair is right. Hold the last output, flagged
                // as degraded, rather than follow either pair (the pair
                // that is wrong together also looks quieter to the noise
                // model, and was followed).
                out.fallback = true;
                out.rejected |= valid & !good;
                // No gyro is used (weights 0): nothing learns from a
                // sample nobody can vouch for (the online calibration
                // learns from the gyros fusion used).
                let held = st.last_out;
                if held.is_finite() {
                    return Some((held, [0.0; N]));
                }
            }
        }
        if good == 0 || support & support.wrapping_sub(1) == 0 {
            // Still fewer than two: everybody disagrees, nothing to single
            // out; fall back.
            good = active;
            out.fallback = true;
        }
    } else if n == 2 && all_warm && voters == active {
        good = pair_gate(st, y, &v, active, k2);
    } else if n >= 3 {
        (good, warm_cap) = warm_up_gate(c, y, voters, med);
        good &= active;
        if good & good.wrapping_sub(1) == 0 {
            good = active;
            out.fallback = true;
        }
    }
    out.rejected |= valid & !good;
    // With `fast_fuse`, `active` is the caller's constant set: inlined for
    // it when the gate kept every gyro, out of line otherwise (N ≥ 5).
    let warm = (all_warm, warm_cap);
    let one_out = (active & !good).is_power_of_two();
    let r = if fast_fuse && good == active {
        update_and_fuse(c, st, y, active, active, warm, med, &v, &w, out)
    } else if N < 5 && fast_fuse {
        // A gyro gated out of a constant set, with fewer than five: inlined
        // too (the bench's spiking gyro is gated out of 5 % of the axes).
        update_and_fuse(c, st, y, active, good, warm, med, &v, &w, out)
    } else if fast_fuse && N == 5 && one_out && active == 31 {
        // One gyro gated out of the board's healthy sets (all five on z,
        // the four ICM-42688-Ps on x and y), out of line, not through the
        // general path: a chip that glitches on all three axes at once
        // takes it on every axis.
        without_one::<N, 31>(c, st, y, good, warm, med, &v, &w, out)
    } else if fast_fuse && N == 5 && one_out && active == 15 {
        without_one::<N, 15>(c, st, y, good, warm, med, &v, &w, out)
    } else {
        update_and_fuse_general(c, st, y, active, good, warm, med, &v, &w, out)
    };
    // Warming up (the first samples after power-up or a rejoin), the
    // output is the median of the voters: equal weights over what a rough
    // MAD gate let through can still carry a second faulty chip (one chip
    // stuck, one garbling bytes, and the noisy ADXRS453 widening the MAD).
    // The noise model still learns
    // from the gated set; the weights reported are its equal weights.
    let r = if !all_warm && n >= 3 {
        r.map(|(_, wts)| (med, wts))
    } else {
        r
    };
    if let Some((x, _)) = r {
        st.last_out = x;
        // (Every gyro in `good` has a weight 1/vᵢ > 0.)
        st.last_used = good;
    }
    r
}

/// Two voters: no third to say which is off. Where they disagree beyond
/// the gate and fusion used one of them last sample but not the other,
/// that one stays alone: the other was already out of the consensus (a
/// chip with a corrupted range that no read-back has found yet, left with
/// a good one while a third drops a sample, would otherwise be fused at
/// half weight, its error some 100 °/s). Otherwise both stay: a pair both
/// fused (under motion their scale errors part them) is the pair's own
/// noise model's to weigh.
#[cold]
#[inline(never)]
fn pair_gate<const N: usize>(
    st: &AxisState<N>,
    y: &[f32; N],
    v: &[f32; N],
    active: u8,
    k2: f32,
) -> u8 {
    let i = active.trailing_zeros() as usize & 7;
    let j = (active & active.wrapping_sub(1)).trailing_zeros() as usize & 7;
    let (Some(&yi), Some(&yj), Some(&vi), Some(&vj)) = (y.get(i), y.get(j), v.get(i), v.get(j))
    else {
        return active;
    };
    let e = yi - yj;
    if e * e <= k2 * (vi + vj) {
        return active;
    }
    let kept = st.last_used & active;
    if kept.is_power_of_two() {
        kept
    } else {
        active
    }
}

/// [`update_and_fuse`] over the constant set `M` with one gyro, `M` less
/// `good`, gated out: one copy per gyro, `good` a constant too.
#[allow(clippy::too_many_arguments)]
#[inline(never)]
pub(super) fn without_one<const N: usize, const M: u8>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    good: u8,
    warm: (bool, f32),
    med: f32,
    v: &[f32; N],
    w: &[f32; N],
    out: &mut Fused<N>,
) -> Option<(f32, [f32; N])> {
    macro_rules! without {
        ($($b:literal)*) => {
            match M & !good {
                $( $b if M & $b != 0 => update_and_fuse(c, st, y, M, M & !$b, warm, med, v, w, out), )*
                _ => update_and_fuse(c, st, y, M, good, warm, med, v, w, out),
            }
        };
    }
    without!(1 2 4 8 16)
}

/// [`update_and_fuse`] for any sets, out of line.
#[allow(clippy::too_many_arguments)]
#[inline(never)]
pub(super) fn update_and_fuse_general<const N: usize>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    active: u8,
    good: u8,
    warm: (bool, f32),
    med: f32,
    v: &[f32; N],
    w: &[f32; N],
    out: &mut Fused<N>,
) -> Option<(f32, [f32; N])> {
    update_and_fuse(c, st, y, active, good, warm, med, v, w, out)
}

/// Noise update and inverse-variance fusion over `good` (⊆ `active`).
///
/// Each gyro is compared with the weighted mean of the *other* good gyros,
/// x₋ᵢ, whose variance V₋ᵢ = 1/Σ_{j≠i} w_j is known from the current
/// estimates, so E[(y_i − x₋ᵢ)²] − V₋ᵢ = σ_i². Sums are taken about the
/// median to keep precision at high rates.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn update_and_fuse<const N: usize>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    active: u8,
    good: u8,
    (all_warm, warm_cap): (bool, f32),
    med: f32,
    v: &[f32; N],
    w: &[f32; N],
    out: &mut Fused<N>,
) -> Option<(f32, [f32; N])> {
    let (mut sw, mut swy) = (0.0f32, 0.0f32);
    for i in 0..N {
        let on = has(good, i);
        sw += if on { w[i] } else { 0.0 };
        swy += if on { w[i] * (y[i] - med) } else { 0.0 };
    }
    // Exactly two good gyros with priors for both: the variance of their
    // difference is shared in proportion to the priors.
    let rest = good & good.wrapping_sub(1);
    let pair_prior = if rest != 0 && rest & rest.wrapping_sub(1) == 0 {
        pair_prior_sum(&st.prior, good)
    } else {
        0.0
    };
    // Three or more good gyros, no pair with priors: the pairwise model.
    let three = rest & rest.wrapping_sub(1) != 0;
    if three && pair_prior == 0.0 {
        // What the sample teaches the noise model waits for
        // [`AxisState::learn_pending`]: the fused value does not depend on
        // it, and the board's loop runs it once the frame is on the wire.
        st.pend = Some(PendLearn {
            y: *y,
            med,
            active,
            good,
            warm_cap,
            alpha: c.alpha,
            warmup: c.warmup,
        });
    } else if good & good.wrapping_sub(1) != 0 {
        // Two good gyros (or a pair with priors): the residual against the
        // other one, as below.
        for i in 0..N {
            let inside = has(good, i);
            let wo = if inside { sw - w[i] } else { sw };
            let wyo = if inside {
                swy - w[i] * (y[i] - med)
            } else {
                swy
            };
            if !has(active, i) || !(wo > 0.0) {
                continue;
            }
            let was_warm = has(st.warm, i);
            // A warm chip the gate left out this sample teaches its noise
            // estimate nothing: its error is an outlier's, and the
            // estimate is what the gate judges it by. Capped by Huber
            // instead, 20 °/s spikes on 2 % of a chip's samples raised its
            // variance 11 % and cost its clean samples a tenth of their
            // weight (0.5 % of the RMS error, worse than zhang). A chip
            // whose noise really grows still teaches it through the
            // samples inside the gate (Huber below), and one the gate
            // always leaves out is out of the fusion anyway.
            if was_warm && !inside {
                continue;
            }
            let e = (y[i] - med) - wyo / wo;
            let v_others = if all_warm { 1.0 / wo } else { 0.0 };
            let mut e2 = e * e;
            // Warming up, one sample adds at most the warm-up gate's limit
            // squared: a chip that spikes from power-up does not start with
            // its spikes in its variance, and one that is plainly wrong
            // still warms up (with a large variance) instead of holding the
            // axis in warm-up.
            if !was_warm && e2 > warm_cap {
                e2 = warm_cap;
            }
            // Huber's scale estimate once warm: e² capped at c²·(its expected
            // value) with c = 2, times κ = 1/E[min(z², 4)] = 1.0864 so that
            // Gaussian noise is estimated without bias. With the cap at the
            // gate (c = 5), outliers at more than 1/(κc²) ≈ 4 % of samples
            // (a chip spiking at 5 %) would make the estimate grow without
            // bound until the spikes fitted inside the gate; with c = 2 it
            // stays bounded up to 23 %.
            if was_warm {
                let cap = HUBER_C2 * (v[i] + v_others);
                e2 = if e2 > cap { cap } else { e2 } * HUBER_KAPPA;
            }
            // Plain average until `warmup` updates, then the EWMA; the count
            // stops once warm (it is only needed until then).
            let a = if was_warm {
                c.alpha
            } else {
                st.n_upd[i] += 1;
                st.warm |= ((st.n_upd[i] >= c.warmup) as u8) << i;
                1.0 / st.n_upd[i] as f32
            };
            if pair_prior > 0.0 && has(good, i) {
                // Two chips: the power of their difference is learnt once
                // (on the lower index), and each chip's variance is its
                // prior's share of the part the priors explain plus half of
                // any excess. What the priors do not explain (scale errors
                // under motion, a drift) cannot be pinned on either chip,
                // and scale errors that are alike in size are best averaged
                // equally: split in proportion to the priors instead, it
                // left the pair 1.08× the mean on a 30 °/s sway with scale
                // errors in ±1 % (`fusion-eval` class (k), seed 2).
                if i as u32 == good.trailing_zeros() {
                    if st.pair != good {
                        st.pair = good;
                        st.pair_power = pair_var_sum(&st.var, good);
                    }
                    st.pair_power += a * (e2 - st.pair_power);
                }
                // (Only the excess beyond PAIR_SLACK × the priors' sum is
                // split equally: the learnt power itself fluctuates by
                // ~6 % (χ²₁ through an EWMA of 1/256), and splitting those
                // fluctuations equally gave a 5× noisier chip 1/20 of the
                // weight instead of 1/26.)
                let (p, knee) = (st.pair_power, PAIR_SLACK * pair_prior);
                st.var[i] = st.prior[i] * (p.min(knee) / pair_prior) + 0.5 * (p - knee).max(0.0);
                st.gvar[i] = st.var[i];
                st.own[i] = st.var[i];
                continue;
            }
            st.var[i] += a * (e2 - v_others - st.var[i]);
            st.gvar[i] = st.var[i];
            st.own[i] = st.var[i];
        }
    }
    if pair_prior == 0.0 {
        st.pair = 0;
    }
    // Inverse-variance weights over the good set.
    weighted(y, w, good).or_else(|| {
        out.fallback = true;
        Some(mean_of(y, good))
    })
}

/// Factor of the slow mean of each pair's squared difference once its
/// growing window is full: 1/4096, the relative calibration's forgetting
/// (`CalConfig::alpha`). The weights follow the pairs, so they move no
/// faster than the calibration removes the chips' biases: a weight that
/// wanders by 0.03 multiplies a 3 °/s bias difference into 0.09 °/s of
/// fused error. (With 1/256 the weights of a static eight-chip rig
/// wandered that much.)
pub const NOISE_ALPHA: f32 = 1.0 / 4096.0;

/// Once warm, the pairs learn on one sample in `PAIR_STRIDE`.
pub(super) const PAIR_STRIDE: u32 = 2;

/// The attribution is solved again every `SOLVE_EVERY` samples (and at
/// once when the set changes): the pairs move by 1/4096 a sample.
pub(super) const SOLVE_EVERY: u32 = 16;

/// Shrinkage towards equal weights: each attributed variance is raised by
/// this share of the median one. A chip the hat reads as noiseless then
/// takes at most 1/SHRINK = 4 times a typical chip's weight (0.57 of four
/// equal chips' sum, never 0.9), while a chip 5× noisier than the rest
/// (25× the variance) still weighs 1/20 of them.
pub(super) const SHRINK: f32 = 0.25;

/// The slow pairs take seconds to see a chip that starts to drift, and
/// its weight must fall first (a chip drifting at 0.2 °/s per s has under
/// 5 % of the weight before its error reaches 3σ). So each chip's fast
/// mean distance from the median is watched against its slow one: beyond
/// [`DRIFT_Z`] standard errors of the fast mean (σ²·α/2 for noise of
/// variance σ²), less the median gyro's move (the median itself moves
/// when a chip leaves, joins or freezes), the weighing variance is raised
/// by the square of the excess. Vibration, however strong, is zero-mean
/// and leaves it; a bias that moves does not. (Watching the fast mean
/// square against the slow one as well, for a chip that grows noisy,
/// down-weighted the chips of the quadrotor's flights that see vibration
/// in bursts: leave-one-out 1.11× the mean on one axis. The slow pairs
/// and the gate see such a chip.)
pub(super) const DRIFT_Z: f32 = 4.0;

/// Raise the weighing variance of the gyros in `set` that drift (see
/// [`DRIFT_Z`]); `alpha` is the fast means' factor.
pub(super) fn rise<const N: usize>(st: &mut AxisState<N>, set: u8, alpha: f32) {
    let mut dd = [0.0f32; N];
    for i in 0..N {
        dd[i] = st.mf[i] - st.ms[i];
    }
    let d0 = super::median(&dd, set);
    for i in 0..N {
        if !has(set, i) {
            continue;
        }
        let d = dd[i] - d0;
        let v = at_least(st.es[i] - st.ms[i] * st.ms[i], 0.0) * (0.5 * alpha);
        let z2 = d * d / (DRIFT_Z * DRIFT_Z * v);
        if z2 > 1.0 {
            st.var[i] *= z2;
        }
    }
}

/// A fused sample's learning for the pairwise model, kept until
/// [`AxisState::learn_pending`] (see [`update_and_fuse`]).
#[derive(Clone, Copy, Debug)]
pub(super) struct PendLearn<const N: usize> {
    y: [f32; N],
    med: f32,
    active: u8,
    good: u8,
    warm_cap: f32,
    alpha: f32,
    warmup: u16,
}

/// The pairwise model's learning from one fused sample `p`: the pairs,
/// each chip's means about the median, and on its samples the attribution
/// and the drift watch. Out of line: after the frame on the board.
#[inline(never)]
pub(super) fn learn<const N: usize>(st: &mut AxisState<N>, p: &PendLearn<N>) {
    let (y, med, active, good) = (&p.y, p.med, p.active, p.good);
    // The chips this sample teaches: the gated-in ones and those still
    // warming up. The variances are solved over them only: a warm chip the
    // gate leaves out keeps the variance it had, which the gate judges it
    // by, and its pairs (a range flipped ×16 reads as 19 °/s of "noise")
    // do not spread into the others' (fault-campaign seed 2846).
    let learners = good | (active & !st.warm);
    pairwise_update(p.warmup, st, y, active, good, p.warm_cap);
    for i in 0..N {
        if has(good, i) {
            let e = y[i] - med;
            let e2 = e * e;
            let g = 1.0 / st.n_pair[i].max(1) as f32;
            let (fast, slow) = (at_least(g, p.alpha), at_least(g, NOISE_ALPHA));
            st.mf[i] += fast * (e - st.mf[i]);
            st.ms[i] += slow * (e - st.ms[i]);
            st.es[i] += slow * (e2 - st.es[i]);
            st.ef[i] += at_least(g, GATE_ALPHA) * (e2 - st.ef[i]);
        }
    }
    if learners != st.solved || st.k.wrapping_add(st.slot).is_multiple_of(SOLVE_EVERY) {
        attribute(st, learners);
        rise(st, active, p.alpha);
    }
}

/// Learn each pair's squared difference among the gyros that learn this
/// sample: the good ones, and the active ones still warming up (a chip
/// the warm-up gate left out still warms up, with its difference capped).
/// Once both are warm, Huber's cap at [`PAIR_HUBER_C2`] = 9 times the
/// pair's mean, times κ, keeps a chip's spikes from inflating its pairs.
#[inline(always)]
fn pairwise_update<const N: usize>(
    warmup: u16,
    st: &mut AxisState<N>,
    y: &[f32; N],
    active: u8,
    good: u8,
    warm_cap: f32,
) {
    let was_warm = st.warm;
    let learn = good | (active & !was_warm);
    let full = (1.0 / NOISE_ALPHA) as u16;
    for i in 0..N {
        if has(learn, i) {
            if !has(was_warm, i) {
                st.n_upd[i] += 1;
                st.warm |= ((st.n_upd[i] >= warmup) as u8) << i;
            }
            st.n_pair[i] = (st.n_pair[i] + 1).min(full);
        }
    }
    // Once every learner is warm, the pairs learn on one sample in
    // [`PAIR_STRIDE`] (each update standing for that many): their slow
    // means move by 1/4096 a sample, and learning all of them on every
    // sample cost the board's frame path some 800 instructions (three
    // axes, 22 pairs).
    let all_warm = learn & !was_warm == 0;
    if all_warm && !st.k.wrapping_add(st.slot).is_multiple_of(PAIR_STRIDE) {
        return;
    }
    let stride = if all_warm { PAIR_STRIDE as f32 } else { 1.0 };
    each_pair::<N>(learn, |i, j| {
        let d = y[i] - y[j];
        let mut d2 = d * d;
        let p = st.pd[i][j];
        if has(was_warm, i) && has(was_warm, j) && p > 0.0 {
            let cap = PAIR_HUBER_C2 * p;
            d2 = if d2 > cap { cap } else { d2 } * PAIR_HUBER_KAPPA;
        } else if d2 > 4.0 * warm_cap {
            // Each is within √cap of the median while warming up.
            d2 = 4.0 * warm_cap;
        }
        let n = st.n_pair[i].min(st.n_pair[j]).max(1);
        let a = at_least(stride / n as f32, stride * NOISE_ALPHA);
        let a = if a < 1.0 { a } else { 1.0 };
        st.pd[i][j] = p + a * (d2 - p);
    });
}

/// Each gyro's noise variance in `set` from the pairs: the N-cornered
/// hat, σᵢ² = (Rᵢ − S)/(n − 2) with Rᵢ = Σⱼ Dᵢⱼ and S = Σσ² =
/// ΣRᵢ/(2(n − 1)), which no weight enters (estimated against a fused rate
/// a chip itself dominates, a chip that gains weight looks quieter and
/// gains more: on a flying quadrotor one chip took 0.9 of the weight on
/// 93 % of the samples). Then:
///
/// - a variance below zero means chips share an error (two on one arm of
///   a vibrating frame): as much as the most negative one is spread over
///   every chip, which pulls the weights together;
/// - [`SHRINK`] of the median is added to each, so that weak evidence
///   gives near-equal weights;
/// - three gyros: the hat is exactly determined, and a chip that is
///   noisier cannot be told from two that share an error (on the
///   quadrotor's flights, weights from each three chips' own hat, known
///   in advance, lose to the plain mean on 59 of 81 axes under
///   leave-one-out). Four can: so three are weighed by their hat only
///   after the last attribution over four or more found no shared error.
///   Otherwise, without priors the three are weighed equally; with priors
///   the priors share what they explain and the excess over
///   [`PAIR_SLACK`] of their sum is split equally, as with two.
pub(super) fn attribute<const N: usize>(st: &mut AxisState<N>, set: u8) {
    let n = set.count_ones();
    if n < 3 {
        return;
    }
    let mut r = [0.0f32; N];
    each_pair::<N>(set, |i, j| {
        r[i] += st.pd[i][j];
        r[j] += st.pd[i][j];
    });
    let nf = n as f32;
    let mut total = 0.0;
    for i in 0..N {
        total += if has(set, i) { r[i] } else { 0.0 };
    }
    let s_all = total / (2.0 * (nf - 1.0));
    // Each chip's own share, the gate's variance in any case.
    let mut h = [0.0f32; N];
    let mut lo = 0.0f32;
    for i in 0..N {
        if has(set, i) {
            h[i] = (r[i] - s_all) / (nf - 2.0);
            lo = if h[i] < lo { h[i] } else { lo };
        }
    }
    // A variance below zero beyond the estimates' own noise (5 % of the
    // mean chip's: the pairs' slow means fluctuate by about 2 %) means some
    // chips share an error; within it, it is noise.
    let shared = lo < -0.05 * s_all / nf;
    if !shared {
        lo = 0.0;
    }
    if n >= 4 {
        st.four = if shared { 2 } else { 1 };
    }
    // No shared error and four or more: one reweighted step. Each pair's
    // mean square has a variance ∝ its square, so the pairs of quiet chips
    // say most about them; with equal pair weights a chip 5× noisier than
    // three others made their estimates 3× as noisy.
    if n >= 4 && !shared {
        if let Some(w) = reweighted(&st.pd, &h, set) {
            h = w;
        }
    }
    for i in 0..N {
        h[i] = at_least(h[i], 0.0);
    }
    let m = super::median(&h, set);
    for i in 0..N {
        if has(set, i) {
            st.own[i] = h[i];
            st.gvar[i] = h[i] - lo + SHRINK * m;
        }
    }
    if n == 3 && st.four != 1 {
        let priors = pair_prior_sum(&st.prior, set);
        for i in 0..N {
            if has(set, i) {
                st.var[i] = if priors > 0.0 {
                    let knee = PAIR_SLACK * priors;
                    st.prior[i] * (if s_all < knee { s_all } else { knee } / priors)
                        + at_least(s_all - knee, 0.0) / nf
                } else {
                    s_all / nf
                };
            }
        }
    } else {
        for i in 0..N {
            if has(set, i) {
                st.var[i] = st.gvar[i];
            }
        }
    }
    st.solved = set;
}

/// The hat by weighted least squares: minimise Σ wᵢⱼ(Dᵢⱼ − σᵢ² − σⱼ²)²
/// with wᵢⱼ = 1/(hᵢ + hⱼ)² from the equal-weight solution `h` (the
/// variance of an mean square is ∝ its mean's square). The normal
/// equations are Aσ = b with Aᵢᵢ = Σⱼwᵢⱼ, Aᵢⱼ = wᵢⱼ, bᵢ = ΣⱼwᵢⱼDᵢⱼ,
/// solved by Gaussian elimination (A is diagonally dominant: no pivoting).
/// `None` if a pivot vanishes.
fn reweighted<const N: usize>(pd: &[[f32; N]; N], h: &[f32; N], set: u8) -> Option<[f32; N]> {
    let mut a = [[0.0f32; N]; N];
    let mut b = [0.0f32; N];
    each_pair::<N>(set, |i, j| {
        let p = at_least(h[i] + h[j], f32::MIN_POSITIVE);
        let w = 1.0 / (p * p);
        a[i][i] += w;
        a[j][j] += w;
        a[i][j] = w;
        a[j][i] = w;
        b[i] += w * pd[i][j];
        b[j] += w * pd[i][j];
    });
    // Outside the set: the identity, so the elimination runs over 0..N.
    for i in 0..N {
        if !has(set, i) {
            a[i][i] = 1.0;
        }
    }
    for k in 0..N {
        let piv = a[k][k];
        if !(piv > 0.0) {
            return None;
        }
        for i in (k + 1)..N {
            let f = a[i][k] / piv;
            if f != 0.0 {
                for j in k..N {
                    a[i][j] -= f * a[k][j];
                }
                b[i] -= f * b[k];
            }
        }
    }
    let mut x = [0.0f32; N];
    for k in (0..N).rev() {
        let mut v = b[k];
        for j in (k + 1)..N {
            v -= a[k][j] * x[j];
        }
        x[k] = v / a[k][k];
    }
    for i in 0..N {
        if !has(set, i) {
            x[i] = 0.0;
        }
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Sum of the priors of the gyros in `good`, or 0 unless all have one.
pub(super) fn pair_prior_sum<const N: usize>(prior: &[f32; N], good: u8) -> f32 {
    let mut sum = 0.0;
    for i in 0..N {
        if has(good, i) {
            if !(prior[i] > 0.0) {
                return 0.0;
            }
            sum += prior[i];
        }
    }
    sum
}

/// With two gyros, the power of their difference up to this multiple of
/// the priors' sum is shared in the priors' proportion (4 standard
/// deviations of its EWMA estimate); only what exceeds it is split equally.
pub(super) const PAIR_SLACK: f32 = 1.25;

/// Sum of the noise variances of the gyros in `good`.
pub(super) fn pair_var_sum<const N: usize>(var: &[f32; N], good: u8) -> f32 {
    let mut sum = 0.0;
    for i in 0..N {
        if has(good, i) {
            sum += var[i];
        }
    }
    sum
}

/// Huber's c² for the pairs (c = 3). With c = 2 (the per-chip update's)
/// the heavy tails of a vibrating frame's differences (kurtosis 6–10 on
/// the quadrotor's flights) read 30–50 % low, the gate sat too close,
/// and fusion left a chip out on 1–2 % of its samples where its whole-log
/// variance puts 0.02 % beyond 5σ. Samples beyond the gate teach nothing
/// anyway, so the cap only bounds what an in-gate sample can add.
pub(super) const PAIR_HUBER_C2: f32 = 9.0;

/// 1 / E[min(z², 9)] for z ~ N(0, 1): 1 / (P(|z| < 3) − 6φ(3) + 9·P(|z| > 3))
/// = 1 / 0.995 005.
pub(super) const PAIR_HUBER_KAPPA: f32 = 1.005_02;

/// Huber's c² for the noise update (c = 2).
pub(super) const HUBER_C2: f32 = 4.0;

/// 1 / E[min(z², c²)] for z ~ N(0, 1) and c = 2: 1 / (P(|z| < 2) − 4φ(2)
/// + 4·P(|z| > 2)) = 1 / 0.920 537 (checked by `huber_kappa_is_the_gaussian_consistency_factor`).
pub(super) const HUBER_KAPPA: f32 = 1.086_322_5;
