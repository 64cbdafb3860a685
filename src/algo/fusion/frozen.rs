//! Frozen outputs: a chip whose samples stay bit-identical while the
//! others move is left out before it drifts away.

use super::{has, AdaptiveConfig, AxisState};

/// Frozen outputs: bit-identical for `frozen_after` samples while some
/// other gyro moves. A stuck chip is caught before it drifts away. Returns
/// the gyros of `valid` that are not frozen. Lane loops here and below are
/// select-style (see `mean_of`).
#[inline(always)]
pub(super) fn frozen_check<const N: usize>(
    c: &AdaptiveConfig,
    st: &mut AxisState<N>,
    y: &[f32; N],
    valid: u8,
) -> u8 {
    // A gyro is frozen when its own run of repeats is long enough and some
    // other gyro has moved since it froze (its run is longer than the
    // shortest). Asking only "did another gyro move on this sample" let a
    // stuck chip back in whenever a healthy one repeated a quantised value
    // (2.4 % of samples with N = 2). Candidates are rare: the comparison
    // runs out of line.
    let mut candidates = 0u8;
    for i in 0..N {
        let on = has(valid, i);
        let same = y[i].to_bits() == st.last[i].to_bits();
        let f = st.frozen[i];
        let f = match (on, same) {
            (false, _) => f,
            (true, true) => f.saturating_add(1),
            (true, false) => 0,
        };
        st.frozen[i] = f;
        candidates |= ((on && f.saturating_add(1) >= c.frozen_after) as u8) << i;
        st.last[i] = if on { y[i] } else { st.last[i] };
    }
    if candidates == 0 {
        valid
    } else {
        drop_frozen(st, valid, candidates)
    }
}

/// The gyros of `valid` left after dropping the `candidates` whose run of
/// repeats is longer than the shortest among `valid`. Select-style: it
/// runs on every sample while a chip that stuck is caught here but not
/// yet flagged by the pipeline (branchy, some 330 instructions a 3-axis
/// sample). Out of line: inlined, it costs the all-in path 16 more.
#[cold]
#[inline(never)]
pub(super) fn drop_frozen<const N: usize>(st: &AxisState<N>, valid: u8, candidates: u8) -> u8 {
    let mut shortest = u8::MAX;
    for i in 0..N {
        let f = if has(valid, i) { st.frozen[i] } else { u8::MAX };
        shortest = shortest.min(f);
    }
    let mut longer = 0u8;
    for i in 0..N {
        longer |= u8::from(st.frozen[i] > shortest) << i;
    }
    valid & !(candidates & longer)
}
