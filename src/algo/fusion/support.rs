//! The support-degree methods: Zhang's `exp(−(yi−yj)²)` (Zhang 2012,
//! eq. 2 and 9) and the seed's normalised distance with log support,
//! Grubbs rejection and limited memory (Zhou, Yao and Shen, 2019, eq.
//! 3–16).

use super::median::median;
use super::{
    each_pair, full, has, mean_of, weighted, AxisState, Denominator, Fused, Fusion, MemoryConfig,
    Normaliser, StdKind, SupportConfig, MAX_GYROS, MAX_MEMORY,
};
use crate::algo::math::{expf, lnf};

impl<const N: usize> Fusion<N> {
    pub(super) fn zhang(&self, y: &[f32; N], m: u8, out: &mut Fused<N>) -> Option<(f32, [f32; N])> {
        if m == 0 {
            return None;
        }
        let mut r = [0.0f32; N];
        each_pair::<N>(m, |i, j| {
            let d = y[i] - y[j];
            let s = expf(-d * d);
            r[i] += s;
            r[j] += s;
        });
        if m.count_ones() == 1 {
            return Some(mean_of(y, m));
        }
        weighted(y, &r, m).or_else(|| {
            out.fallback = true;
            Some(mean_of(y, m))
        })
    }

    pub(super) fn seed(
        &self,
        c: &SupportConfig,
        st: &mut AxisState<N>,
        y: &[f32; N],
        m: u8,
        out: &mut Fused<N>,
    ) -> Option<(f32, [f32; N])> {
        // Inlined twice: for all gyros (a constant mask, so the mask tests
        // fold away and the loops unroll) and for the general mask.
        if m == full::<N>() {
            self.seed_masked(c, st, y, full::<N>(), out)
        } else {
            self.seed_masked(c, st, y, m, out)
        }
    }

    #[inline(always)]
    fn seed_masked(
        &self,
        c: &SupportConfig,
        st: &mut AxisState<N>,
        y: &[f32; N],
        m: u8,
        out: &mut Fused<N>,
    ) -> Option<(f32, [f32; N])> {
        let n = m.count_ones() as usize;
        if n == 0 {
            return None;
        }
        if n == 1 {
            return Some(mean_of(y, m));
        }
        // Eq. 3–4: distances and their normaliser over ordered pairs.
        let mut d = [[0.0f32; N]; N];
        let mut sum = 0.0;
        each_pair::<N>(m, |i, j| {
            let dij = (y[i] - y[j]).abs();
            d[i][j] = dij;
            d[j][i] = dij;
            sum += 2.0 * dij;
        });
        let nf = n as f32;
        let denom = match c.denominator {
            Denominator::MSquaredMinus1 => nf * nf - 1.0,
            Denominator::OrderedPairs => nf * (nf - 1.0),
        };
        let scale = match c.normaliser {
            Normaliser::Instant => sum / denom,
            Normaliser::Running { k, alpha } => {
                let mad = mad(y, m);
                st.spread = if st.spread > 0.0 {
                    st.spread + alpha * (mad - st.spread)
                } else {
                    mad
                };
                k * st.spread
            }
        };
        // Eq. 5–6: support matrix. All-equal inputs give 0/0 in eq. 4; we
        // take d* = 0 (full support), which is the limit for equal values.
        let mut s = [[1.0f32; N]; N];
        if scale > 0.0 && scale.is_finite() {
            let inv = 1.0 / scale;
            each_pair::<N>(m, |i, j| {
                let v = 1.0 - lnf(1.0 + d[i][j] * inv);
                s[i][j] = v;
                s[j][i] = v;
            });
        }
        // Eq. 10–12: Grubbs on each row; zeroing breaks symmetry, as printed.
        if let Some(g) = c.grubbs {
            let nrow = if g.include_diagonal { n } else { n - 1 };
            let t = self.grubbs_t[nrow.min(MAX_GYROS)];
            if t > 0.0 {
                // The diagonal choice as a const, so the row tests fold.
                if g.include_diagonal {
                    grubbs_rows::<N, true>(&mut s, m, nrow, t * t, g.std);
                } else {
                    grubbs_rows::<N, false>(&mut s, m, nrow, t * t, g.std);
                }
            }
        }
        // Eq. 7: total support.
        let mut r = [0.0f32; N];
        for i in 0..N {
            if !has(m, i) {
                continue;
            }
            for j in 0..N {
                if !has(m, j) || j == i {
                    continue;
                }
                r[i] += s[i][j];
            }
            if c.clamp_negative && r[i] < 0.0 {
                r[i] = 0.0;
            }
        }
        for i in 0..N {
            if !has(m, i) {
                continue;
            }
            if r[i] <= 0.0 && c.clamp_negative {
                out.rejected |= 1 << i;
            }
        }
        // Eq. 13–16: limited memory.
        let r = match c.memory {
            Some(mc) => memory_weights(&mc, &self.inv_t2, st, &r, m),
            None => r,
        };
        weighted(y, &r, m).or_else(|| {
            out.fallback = true;
            Some(mean_of(y, m))
        })
    }
}

/// Grubbs rejection (eq. 10–12) on every row of the support matrix: an
/// element whose statistic |s_ij − s̄_i|/σ_i reaches T is set to 0. `DIAG`:
/// the row includes s_ii = 1 (then it has `nrow` = n elements).
#[inline(always)]
pub(super) fn grubbs_rows<const N: usize, const DIAG: bool>(
    s: &mut [[f32; N]; N],
    m: u8,
    nrow: usize,
    t2: f32,
    std: StdKind,
) {
    let dof = match std {
        StdKind::Population => nrow as f32,
        StdKind::Sample => nrow as f32 - 1.0,
    };
    for i in 0..N {
        if !has(m, i) {
            continue;
        }
        let inrow = |j: usize| has(m, j) && (DIAG || j != i);
        let (mut s1, mut s2) = (0.0f32, 0.0f32);
        for j in 0..N {
            s1 += if inrow(j) { s[i][j] } else { 0.0 };
        }
        let mean = s1 / nrow as f32;
        for j in 0..N {
            let e = s[i][j] - mean;
            s2 += if inrow(j) { e * e } else { 0.0 };
        }
        let var = s2 / dof;
        if !(var > 0.0) {
            continue;
        }
        // T_ij ≥ T  ⇔  (s_ij − s̄)² ≥ T²·σ² (no division, no sqrt). Both
        // sides are non-negative and finite, so their bit patterns order
        // like the values: an integer compare replaces `vcmp` + `vmrs`.
        let thr = (t2 * var).to_bits();
        for j in 0..N {
            let e = s[i][j] - mean;
            let out = inrow(j) && (e * e).to_bits() >= thr;
            s[i][j] = if out { 0.0 } else { s[i][j] };
        }
    }
}

/// Eq. 13–16 with our consistent indexing: `R_i(k) = Σ_u r_i(u)·∂_i(u;k)`
/// over the last `len` epochs, `∂ = 1 / (t² ((r_i(u) − r̄_i(u))² + ε))`,
/// `t = k − u + lag0`; r̄ is the running mean since start (eq. 13). μ and
/// 1/k cancel in eq. 16 and are left out.
pub(super) fn memory_weights<const N: usize>(
    mc: &MemoryConfig,
    inv_t2: &[f32; MAX_MEMORY],
    st: &mut AxisState<N>,
    r: &[f32; N],
    m: u8,
) -> [f32; N] {
    let kf = st.k as f32;
    st.head = (st.head + 1) % MAX_MEMORY;
    for i in 0..N {
        let on = has(m, i);
        st.rbar[i] = if on {
            st.rbar[i] + (r[i] - st.rbar[i]) / kf
        } else {
            st.rbar[i]
        };
        let dev = r[i] - st.rbar[i];
        let ri = if on { r[i] } else { 0.0 };
        // Kept as one product: (r·∂′)·(1/t²) rounds exactly as r·∂′·(1/t²).
        st.ring[st.head][i] = ri * (1.0 / (dev * dev + mc.eps));
    }
    let mut big_r = [0.0f32; N];
    let len = mc.len.min(st.k as usize);
    // A skipped lag (t = 0) has 1/t² = 0 in the table: adding r·0 = ±0
    // leaves the sums unchanged, so no branch is needed.
    for (lag, &it2) in inv_t2.iter().enumerate().take(len) {
        let u = (st.head + MAX_MEMORY - lag) % MAX_MEMORY;
        for i in 0..N {
            big_r[i] += st.ring[u][i] * it2;
        }
    }
    big_r
}

/// Median absolute deviation from the median over the masked values.
pub(super) fn mad<const N: usize>(y: &[f32; N], m: u8) -> f32 {
    let med = median(y, m);
    let mut dev = [0.0f32; N];
    for i in 0..N {
        dev[i] = (y[i] - med).abs();
    }
    median(&dev, m)
}
