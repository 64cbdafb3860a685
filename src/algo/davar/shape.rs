//! The tests that tell a step from a gradual change, over a span's frame
//! prefix sums: one line against the step, two joined lines, t's own
//! segment's slope.

use crate::algo::math::at_least;

/// How much better one line explains the frame energies of l..r than the
/// step at c does, in cost units: (SS_line − SS_step)·ν/(2m²), the sums of
/// squares the least-squares line and the two segment means explain,
/// scaled by the variance 2m²/ν of a frame energy at the pooled mean m.
/// That is the second-order form of the difference of their Gamma
/// deviances, from the prefix sums alone: r − l additions and no
/// logarithm, so the board's placement sample can afford it. −∞ where it
/// does not apply.
#[cfg(test)]
pub(super) fn line_over_step(px: &[f32], nu: f32, (l, c, r): (usize, usize, usize)) -> f32 {
    line_over_step_from(px, nu, (l, c, r), line_sums(px, l, r))
}

/// `line_over_step` with [`line_sums`] over l..r already made.
pub(super) fn line_over_step_from(
    px: &[f32],
    nu: f32,
    (l, c, r): (usize, usize, usize),
    (m, sfc, sxx): (f32, f32, f32),
) -> f32 {
    if c <= l || r <= c || r < l + 3 || !(m > 0.5) {
        return f32::NEG_INFINITY;
    }
    (sfc * sfc / sxx - step_ss(px, (l, c, r))) * nu / (2.0 * m * m)
}

/// The sum of squares about the mean of l..r that the two segment means
/// of l..c and c..r explain (l < c < r), from the prefix sums.
fn step_ss(px: &[f32], (l, c, r): (usize, usize, usize)) -> f32 {
    let p = |i: usize| px.get(i).copied().unwrap_or(0.0);
    let (n, n1, n2) = ((r - l) as f32, (c - l) as f32, (r - c) as f32);
    let d = (p(c) - p(l)) / n1 - (p(r) - p(c)) / n2;
    n1 * n2 / n * d * d
}

/// How much better two lines joined at the best knot explain the frame
/// energies of l..r than the step at c does, in the cost units of
/// `line_over_step` (the same second-order form of the Gamma deviances,
/// from the prefix sums). A hinge (a level that starts to slope, or a
/// slope that levels off) is a gradual change that one line through both
/// segments fits poorly, so the step at c wins the line test and bounds
/// the window, one-sided on the slope; joined lines fit it. The knot is
/// free (every other frame boundary with two frames on either side), not the
/// step's c: on a ramp the segmentation puts c where the noise makes the
/// step look best, often far from where the slope starts, and lines forced
/// to join there fall short of a step that chose its place. A sharp step
/// is explained about three quarters by joined lines wherever their knot
/// falls (one knot cannot both rise and level off), so a step shows as a
/// deficit of about a quarter of its gain. −∞ where it does not apply.
#[cfg(test)]
pub(super) fn hinge_over_step(px: &[f32], nu: f32, (l, c, r): (usize, usize, usize)) -> f32 {
    hinge_over_step_from(px, nu, (l, c, r), line_sums(px, l, r))
}

/// `hinge_over_step` with [`line_sums`] over l..r already made. One walk
/// from r down to l: for a knot at κ the regressors are the frame index
/// and w = f − κ + ½ on the frames f ≥ κ (0 before), whose sums are
/// closed forms in the count on the right, and whose product with the
/// energies follows from the previous knot's (R₁(κ) = R₁(κ+1) + R₀(κ+1),
/// R₀ the energy from κ on, R₁ = Σ (f − κ)·x_f): O(1) a knot, no
/// second pass.
pub(super) fn hinge_over_step_from(
    px: &[f32],
    nu: f32,
    (l, c, r): (usize, usize, usize),
    (m, sfc, sxx): (f32, f32, f32),
) -> f32 {
    let p = |i: usize| px.get(i).copied().unwrap_or(0.0);
    if c < l + 2 || r < c + 2 || !(m > 0.5) {
        return f32::NEG_INFINITY;
    }
    let n = (r - l) as f32;
    // The explained sum of squares of (f, w) about their means is the
    // line's, sfc²/sxx, plus w's part orthogonal to f: (cwe − b·sfc)² over
    // cww − cxw²/sxx, b = cxw/sxx. (The 2 × 2 form gᵀA⁻¹g of the same
    // cancels to a few digits where w is nearly f.) Knot r − 1 starts the
    // running sums; every other knot from r − 2 down to l + 2 is scored
    // (a knot a frame off changes the explained sum little, and the
    // scan's cost on the board's placement sample halves).
    let (pr, slope, half_m) = (p(r), sfc / sxx, 0.5 * m);
    let (mut r0, mut r1, mut mr, mut best) = (pr - p(r - 1), 0.0f32, 1.0f32, 0.0f32);
    for (i, &pk) in px.get(l + 2..r - 1).unwrap_or(&[]).iter().rev().enumerate() {
        r1 += r0;
        r0 = pr - pk;
        mr += 1.0;
        if i % 2 == 1 {
            continue;
        }
        let (nl, m2) = (n - mr, mr * mr);
        let sww = mr * (4.0 * m2 - 1.0) * (1.0 / 12.0);
        let cxw = sww + 0.25 * (nl - mr) * m2;
        let e = r1 + 0.5 * r0 - half_m * m2 - cxw * slope;
        // 144 (sxx·cww − cxw²), factored: positive with two frames a side.
        let q = mr * nl;
        let det = q * (4.0 * q * q - 3.0 * q - m2 - nl * nl + 1.0);
        best = best.max(e * e / det);
    }
    let hinge = sfc * slope + 144.0 * sxx * best;
    (hinge - step_ss(px, (l, c, r))) * nu / (2.0 * m * m)
}

/// The slope of the frames' energies over l..r, squared, over its own
/// variance under the scaled-χ²_ν model at their mean (a z²), and whether
/// it rises. None where fewer than 4 frames or a mean not positive.
pub(super) fn slope_z2(px: &[f32], nu: f32, (l, r): (usize, usize)) -> Option<(f32, bool)> {
    if r < l + 4 {
        return None;
    }
    let (m, sfc, sxx) = line_sums(px, l, r);
    if !(m > 0.0) {
        return None;
    }
    Some((sfc * sfc / sxx * nu / (2.0 * m * m), sfc > 0.0))
}

/// Over the frames l..r (r > l) of the prefix sums `px`: their mean
/// energy, Σ (f − f̄)·x_f and Σ (f − f̄)², the sums of a least-squares line.
pub(super) fn line_sums(px: &[f32], l: usize, r: usize) -> (f32, f32, f32) {
    let p = |i: usize| px.get(i).copied().unwrap_or(0.0);
    let n = (r - l) as f32;
    let s = p(r) - p(l);
    // Σ (f − l)·x_f = n·P(r) − Σ_{j = l+1..=r} P(j) (P the prefix sums;
    // P(l) cancels), then about the centre l + (n − 1)/2.
    // (Four running sums: fewer instructions than one at λ2 = 4096.)
    let w = px.get(l + 1..=r).unwrap_or(&[]);
    let mut quads = w.chunks_exact(4);
    let mut acc = [0.0f32; 4];
    for q in &mut quads {
        for (a, &v) in acc.iter_mut().zip(q) {
            *a += v;
        }
    }
    let sp = (acc[0] + acc[1]) + (acc[2] + acc[3]) + quads.remainder().iter().sum::<f32>();
    let sfc = n * p(r) - sp - 0.5 * (n - 1.0) * s;
    (s / n, sfc, n * (n * n - 1.0) / 12.0)
}

/// |ln(a/b)| without a logarithm: max(a, b)/min(a, b) orders the same way.
pub(super) fn ratio_gap(a: f32, b: f32) -> f32 {
    let (a, b) = (
        at_least(a, f32::MIN_POSITIVE),
        at_least(b, f32::MIN_POSITIVE),
    );
    if a > b {
        a / b
    } else {
        b / a
    }
}
