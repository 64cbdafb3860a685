//! Medians of the masked gyros by integer sorting networks: the gates'
//! reference, and the consensus of the online calibration and the
//! self-test.

use super::{full, has};

/// Median of the masked values: an odd–even transposition sort (N rounds,
/// fully unrolled for the const N) of order-preserving integer keys, with
/// gyros outside `m` keyed last. On the Cortex-M4 integer compare-exchanges
/// are far cheaper than float compares (`vcmp` + `vmrs`) or an insertion
/// sort's data-dependent loops; three or four gyros (every set after a
/// chip or two fails) take a short network on their gathered keys
/// instead. NaN when `m` is empty. Also the consensus of the online
/// calibration and of the self-test.
pub(crate) fn median<const N: usize>(y: &[f32; N], m: u8) -> f32 {
    median_of(y, m)
}

/// [`median`], inlined: the adaptive method's constant sets fold it.
#[inline(always)]
pub(super) fn median_of<const N: usize>(y: &[f32; N], m: u8) -> f32 {
    // Sign-magnitude to two's complement: an involution on the bits.
    let key = |b: i32| b ^ (((b >> 31) as u32) >> 1) as i32;
    let mut k = [i32::MAX; N];
    for i in 0..N {
        k[i] = if has(m, i) {
            key(y[i].to_bits() as i32)
        } else {
            i32::MAX
        };
    }
    let (lo, hi) = middle_keys(k, m);
    let f = |j: i32| f32::from_bits(key(j) as u32);
    if one_middle(m) {
        f(lo)
    } else {
        0.5 * (f(lo) + f(hi))
    }
}

/// The two middle keys of the keys `k` of the gyros in `m` (the others
/// keyed `i32::MAX`), sorted: the same one twice where there is one middle
/// ([`one_middle`]). Three or four gyros (every set after a chip or two
/// fails) take a short network on their gathered keys (4 and 6 min/max);
/// the others the odd–even transposition sort.
#[inline(always)]
pub(super) fn middle_keys<const N: usize>(mut k: [i32; N], m: u8) -> (i32, i32) {
    let n = m.count_ones();
    if n == 3 {
        let [a, b, c, _] = four(&k, m);
        let mid = a.min(b).max(a.max(b).min(c));
        return (mid, mid);
    }
    if n == 4 {
        // The middle pair is (max of the two minima, min of the two maxima).
        let [a, b, c, d] = four(&k, m);
        let (a, b) = (a.min(b), a.max(b));
        let (c, d) = (c.min(d), c.max(d));
        return (a.max(c), b.min(d));
    }
    for round in 0..N {
        let mut i = round % 2;
        while i + 1 < N {
            let (a, b) = (k[i], k[i + 1]);
            k[i] = a.min(b);
            k[i + 1] = a.max(b);
            i += 2;
        }
    }
    let n = n as usize;
    let at = |j: usize| k.get(j).copied().unwrap_or(0);
    (at(n.saturating_sub(1) / 2), at(n / 2))
}

/// Whether the gyros in `m` have one middle value (an odd count, or none).
#[inline(always)]
pub(super) fn one_middle(m: u8) -> bool {
    let n = m.count_ones();
    n % 2 == 1 || n == 0
}

/// The median for the adaptive gate: with an odd count the middle value;
/// with an even count the inverse-variance weighted mean of the middle two
/// (with the plain mean of them a noisy but honest gyro, an ADXRS453 among
/// ICM-42688-Ps, drags the reference off every quiet gyro once a third one
/// is wild). Same sorting as
/// [`median`], with each gyro's index in the key's three low bits, so the
/// middle two are known; the values returned are the exact inputs.
#[inline(always)]
pub(super) fn gate_median<const N: usize>(y: &[f32; N], v: &[f32; N], m: u8) -> f32 {
    let key = |b: i32| b ^ (((b >> 31) as u32) >> 1) as i32;
    let mut k = [i32::MAX; N];
    for i in 0..N {
        k[i] = if has(m, i) {
            (key(y[i].to_bits() as i32) & !7) | (i as i32 & 7)
        } else {
            i32::MAX
        };
    }
    // (Indices are < N; `% N` lets the compiler see it: no bounds checks.)
    let pick = |lo: i32, hi: i32| {
        let (a, b) = ((lo & 7) as usize % N, (hi & 7) as usize % N);
        let (ya, yb, va, vb) = (y[a], y[b], v[a], v[b]);
        // (ya/va + yb/vb) / (1/va + 1/vb), without the divisions.
        (ya * vb + yb * va) / (va + vb)
    };
    let (lo, hi) = middle_keys(k, m);
    if one_middle(m) {
        y[(lo & 7) as usize % N]
    } else {
        pick(lo, hi)
    }
}

/// The keys of the (up to) four gyros in `m`, in order; `i32::MAX` after
/// them. With `m` a constant (the adaptive method's constant sets) the
/// gather folds to four loads.
#[inline(always)]
pub(super) fn four<const N: usize>(k: &[i32; N], m: u8) -> [i32; 4] {
    if N == 4 && m == full::<N>() {
        // All four (the online calibration's usual consensus with four
        // gyros, a runtime mask): no gather.
        let at = |j: usize| k.get(j).copied().unwrap_or(i32::MAX);
        return [at(0), at(1), at(2), at(3)];
    }
    let mut g = [i32::MAX; 4];
    let mut j = 0usize;
    for i in 0..N {
        if has(m, i) {
            if let Some(s) = g.get_mut(j) {
                *s = k[i];
            }
            j += 1;
        }
    }
    g
}
