//! Seed 001's fusion of local filters ("A new navigation information
//! fusion method based on entropy weights", SINS/USBL/DVL: the copy at
//! hand has no authors or journal), every
//! ambiguity a knob, next to the references a reviewer expects:
//!
//! - the paper's entropy-weighted Gaussian mixture: each local estimate's
//!   position σ gives a differential entropy H = ½ ln(2πeσ²) (eq. 9), an
//!   entropy product SH = σ·H (eq. 10) and a weight α ∝ 1/SH (eq. 11,
//!   read as the inverse form); the fused state is the mixture mean, its
//!   covariance the mixture's;
//! - the paper's baseline, covariance-weighted fusion
//!   (Σ P_i⁻¹)⁻¹ Σ P_i⁻¹ x_i;
//! - covariance intersection (unknown cross-correlation), ω by golden
//!   section on trace(P);
//! - the covariance reset of step 5: literal (P_i ← α_i Σ_j P_j), the
//!   standard federated information sharing (P_i ← P_g/β_i with β_i = α_i),
//!   or none.
//!
//! Ambiguity 1 (SH ≤ 0 for σ < 0.242 in whatever unit σ has: the weights
//! turn negative, infinite or inverted) is [`Guard`]: refuse with a typed
//! error, or floor SH. σ is in metres (the caller converts); which σ
//! (ambiguity 3: per axis, or the position block's RMS) is the caller's
//! choice of what it passes to [`entropy_weights`].

use nalgebra::{RealField, SMatrix, SVector};

/// Why a fusion step could not run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MixError {
    /// An entropy product SH = σ·H is ≤ 0 (σ < 0.242) and the guard
    /// refuses it.
    NonPositiveEntropyProduct,
    /// A σ, state or covariance is NaN, infinite, or a σ is ≤ 0.
    NonFinite,
    /// A covariance cannot be inverted or factored.
    Singular,
}

/// What to do with SH ≤ 0 (ambiguity 1).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Guard {
    /// Refuse: [`MixError::NonPositiveEntropyProduct`].
    Reject,
    /// Use max(SH, floor): every σ below the crossing gets the same,
    /// largest weight.
    Floor(f64),
}

/// Covariance reset after fusion (step 5, ambiguity 4).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CovReset {
    /// The paper as printed: P_i ← α_i Σ_j P_j (the larger weight gets the
    /// larger covariance: the opposite of information sharing).
    PaperLiteral,
    /// Standard federated information sharing: P_i ← P_g / β_i, x_i ← x_g,
    /// with β_i = α_i.
    Federated,
    /// Leave the local filters alone.
    None,
}

/// Differential entropy of N(·, σ²), nats (eq. 9).
pub fn entropy_gaussian(sigma: f64) -> f64 {
    0.5 * libm::log(2.0 * core::f64::consts::PI * core::f64::consts::E * sigma * sigma)
}

/// Entropy product SH = σ·H (eq. 10).
pub fn entropy_product(sigma: f64) -> f64 {
    sigma * entropy_gaussian(sigma)
}

/// Weights α_i ∝ 1/SH(σ_i), summing to 1 (eq. 11).
pub fn entropy_weights<const L: usize>(
    sigmas: &[f64; L],
    guard: Guard,
) -> Result<[f64; L], MixError> {
    let mut inv = [0.0; L];
    for (w, &s) in inv.iter_mut().zip(sigmas) {
        if !(s.is_finite() && s > 0.0) {
            return Err(MixError::NonFinite);
        }
        let sh = entropy_product(s);
        let sh = match guard {
            Guard::Reject if sh <= 0.0 => return Err(MixError::NonPositiveEntropyProduct),
            Guard::Reject => sh,
            Guard::Floor(f) => sh.max(f),
        };
        if !(sh > 0.0) {
            return Err(MixError::NonPositiveEntropyProduct);
        }
        *w = 1.0 / sh;
    }
    let z: f64 = inv.iter().sum();
    Ok(inv.map(|w| w / z))
}

/// Mixture mean Σ α_i x_i and covariance Σ α_i (P_i + (x_i − x)(x_i − x)ᵀ).
pub fn mixture<T: RealField + Copy, const N: usize, const L: usize>(
    xs: &[SVector<T, N>; L],
    ps: &[SMatrix<T, N, N>; L],
    alpha: &[T; L],
) -> (SVector<T, N>, SMatrix<T, N, N>) {
    let mut x = SVector::<T, N>::zeros();
    for (xi, &a) in xs.iter().zip(alpha) {
        x += xi * a;
    }
    let mut p = SMatrix::<T, N, N>::zeros();
    for ((xi, pi), &a) in xs.iter().zip(ps).zip(alpha) {
        let d = xi - x;
        p += (pi + d * d.transpose()) * a;
    }
    (x, p)
}

/// Covariance-weighted (information) fusion, the paper's baseline:
/// P_g = (Σ P_i⁻¹)⁻¹, x_g = P_g Σ P_i⁻¹ x_i. Optimal for independent
/// estimates; over-confident for correlated ones.
pub fn covariance_weighted<T: RealField + Copy, const N: usize, const L: usize>(
    xs: &[SVector<T, N>; L],
    ps: &[SMatrix<T, N, N>; L],
) -> Result<(SVector<T, N>, SMatrix<T, N, N>), MixError> {
    let mut info = SMatrix::<T, N, N>::zeros();
    let mut iv = SVector::<T, N>::zeros();
    for (xi, pi) in xs.iter().zip(ps) {
        let inv = pi.cholesky().ok_or(MixError::Singular)?.inverse();
        iv += inv * xi;
        info += inv;
    }
    let pg = info.cholesky().ok_or(MixError::Singular)?.inverse();
    Ok((pg * iv, pg))
}

/// Covariance intersection of two estimates with unknown correlation:
/// P⁻¹ = ω P₁⁻¹ + (1 − ω) P₂⁻¹, ω ∈ [0, 1] minimising trace(P) (golden
/// section, 60 steps). Consistent whatever the correlation.
pub fn covariance_intersection<T: RealField + Copy, const N: usize>(
    x1: &SVector<T, N>,
    p1: &SMatrix<T, N, N>,
    x2: &SVector<T, N>,
    p2: &SMatrix<T, N, N>,
) -> Result<(SVector<T, N>, SMatrix<T, N, N>, T), MixError> {
    let i1 = p1.cholesky().ok_or(MixError::Singular)?.inverse();
    let i2 = p2.cholesky().ok_or(MixError::Singular)?.inverse();
    let at = |w: T| -> Option<(SMatrix<T, N, N>, T)> {
        let p = (i1 * w + i2 * (T::one() - w)).cholesky()?.inverse();
        let tr = p.trace();
        Some((p, tr))
    };
    // (√5 − 1)/2, the golden section.
    let g: T = nalgebra::convert(0.618_033_988_749_894_9);
    let (mut a, mut b) = (T::zero(), T::one());
    for _ in 0..60 {
        let c = b - (b - a) * g;
        let d = a + (b - a) * g;
        let (tc, td) = (
            at(c).ok_or(MixError::Singular)?.1,
            at(d).ok_or(MixError::Singular)?.1,
        );
        if tc < td {
            b = d;
        } else {
            a = c;
        }
    }
    let w = (a + b) * nalgebra::convert::<f64, T>(0.5);
    let (p, _) = at(w).ok_or(MixError::Singular)?;
    let x = p * (i1 * x1 * w + i2 * x2 * (T::one() - w));
    Ok((x, p, w))
}

/// Apply the covariance reset of step 5 to the local filters' P (and x
/// for the federated rule), given the fused (x_g, P_g) and weights α.
pub fn reset<T: RealField + Copy, const N: usize, const L: usize>(
    rule: CovReset,
    xs: &mut [SVector<T, N>; L],
    ps: &mut [SMatrix<T, N, N>; L],
    fused: &(SVector<T, N>, SMatrix<T, N, N>),
    alpha: &[T; L],
) {
    match rule {
        CovReset::None => {}
        CovReset::PaperLiteral => {
            let mut sum = SMatrix::<T, N, N>::zeros();
            for p in ps.iter() {
                sum += p;
            }
            for (p, &a) in ps.iter_mut().zip(alpha) {
                *p = sum * a;
            }
        }
        CovReset::Federated => {
            for ((x, p), &a) in xs.iter_mut().zip(ps.iter_mut()).zip(alpha) {
                *x = fused.0;
                *p = fused.1 / a;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The board's closed-form chip filter against the general filter
    /// (`algo::kalman::Kf<f32, 2>`): one predict and one update from 2 000
    /// random states, readings and noises (h = [1, 1] and [1, 0]), to 1e-5
    /// of the state's and covariance's scale (f32 rounding).
    #[test]
    fn chip_filter_equals_the_general_filter() {
        use crate::algo::kalman::Kf;
        use nalgebra::{Matrix1, Matrix1x2, Matrix2, Vector1, Vector2};
        let mut rng = gyro_sim::Rng::new(77);
        let mut worst = 0.0f32;
        for n in 0..2000 {
            let mut g = || rng.gaussian();
            let (a, b) = (g() * 3.0, g() * 0.2);
            let p = Matrix2::new(a * a + 0.5, a * b, a * b, b * b + 1e-3);
            let x = Vector2::new(g() * 10.0, g());
            let q = [g().abs() * 5.0, g().abs() * 1e-4];
            let (z, r) = (g() * 10.0, g().abs() + 0.01);
            let h = if n % 2 == 0 { [1.0, 1.0] } else { [1.0, 0.0] };
            let mut general = Kf::new(x, p).unwrap();
            general
                .predict(&Matrix2::identity(), &Matrix2::new(q[0], 0.0, 0.0, q[1]))
                .unwrap();
            general
                .update(
                    &Vector1::new(z),
                    &Matrix1x2::new(h[0], h[1]),
                    &Matrix1::new(r),
                )
                .unwrap();
            let mut chip = ChipKf {
                x: [x[0], x[1]],
                p: [p[(0, 0)], p[(0, 1)], p[(1, 1)]],
            };
            let mut stepped = chip;
            assert!(stepped.step(q, z, h, r));
            assert!(chip.predict(q));
            if h[1] != 0.0 {
                let mut separate = chip;
                assert!(separate.update(z, h, r));
                assert_eq!(stepped, separate, "step = predict then update, bit for bit");
            }
            let updated = if h[1] == 0.0 {
                chip.update_rate(z, r)
            } else {
                chip.update(z, h, r)
            };
            assert!(updated);
            let scale = general.p.abs().max().max(general.x.abs().max()).max(1.0);
            let d = [
                chip.x[0] - general.x[0],
                chip.x[1] - general.x[1],
                chip.p[0] - general.p[(0, 0)],
                chip.p[1] - general.p[(0, 1)],
                chip.p[2] - general.p[(1, 1)],
            ];
            worst = d.iter().fold(worst, |w, v| w.max(v.abs() / scale));
        }
        assert!(worst < 1e-5, "{worst:e}");
        let mut chip = ChipKf {
            x: [0.0; 2],
            p: [1.0, 0.0, 1.0],
        };
        let before = chip;
        assert!(!chip.update(f32::NAN, [1.0, 1.0], 1.0) && chip == before);
        assert!(!chip.update(1.0, [1.0, 1.0], 0.0) && chip == before);
    }
    use nalgebra::{Matrix2, Vector2};

    /// Ambiguity 1, measured: SH crosses 0 at σ = 1/√(2πe) = 0.2420 and
    /// has its minimum −0.0890 at σ = 0.0890; below the crossing the
    /// inverse weights turn negative, so `Reject` refuses and `Floor`
    /// caps.
    #[test]
    fn entropy_product_crossing_and_guard() {
        let cross = 1.0 / (2.0 * core::f64::consts::PI * core::f64::consts::E).sqrt();
        assert!((cross - 0.2420).abs() < 1e-4);
        assert!(entropy_product(cross).abs() < 1e-12);
        let smin = cross / core::f64::consts::E;
        assert!((smin - 0.0890).abs() < 1e-4);
        assert!((entropy_product(smin) + 0.0890).abs() < 1e-4);
        assert_eq!(
            entropy_weights(&[0.1, 2.0], Guard::Reject),
            Err(MixError::NonPositiveEntropyProduct)
        );
        let w = entropy_weights(&[0.1, 2.0], Guard::Floor(1e-3)).unwrap();
        assert!(w[0] > 0.99 && (w[0] + w[1] - 1.0).abs() < 1e-12, "{w:?}");
        assert_eq!(
            entropy_weights(&[f64::NAN, 2.0], Guard::Reject),
            Err(MixError::NonFinite)
        );
        assert_eq!(
            entropy_weights(&[0.0, 2.0], Guard::Reject),
            Err(MixError::NonFinite)
        );
    }

    /// Where SH > 0 the entropy weights favour the smaller σ, but far less
    /// than inverse variance: σ of 1 m and 2 m get 0.75/0.25 (entropy)
    /// against 0.8/0.2 (1/σ²) — the structural reason a quick
    /// simulation found entropy weighting never better than covariance
    /// weighting when the covariances are consistent.
    #[test]
    fn entropy_weights_are_flatter_than_inverse_variance() {
        let w = entropy_weights(&[1.0, 2.0], Guard::Reject).unwrap();
        let iv = [0.8, 0.2];
        assert!(w[0] > 0.5 && w[0] < iv[0], "{w:?}");
        println!("entropy {w:?}, inverse variance {iv:?}");
    }

    /// Covariance-weighted fusion of independent estimates is the
    /// information sum; CI of two equal estimates picks ω = ½ and returns
    /// their covariance (no false gain); the mixture of identical
    /// components is that component.
    #[test]
    fn references_behave() {
        let x1 = Vector2::<f64>::new(1.0, 2.0);
        let x2 = Vector2::new(3.0, 2.0);
        let p1 = Matrix2::<f64>::new(1.0, 0.0, 0.0, 4.0);
        let p2 = Matrix2::<f64>::new(1.0, 0.0, 0.0, 1.0);
        let (x, p) = covariance_weighted(&[x1, x2], &[p1, p2]).unwrap();
        assert!((x[0] - 2.0).abs() < 1e-12 && (p[(0, 0)] - 0.5).abs() < 1e-12);
        assert!((p[(1, 1)] - 0.8).abs() < 1e-12);
        let (_, pc, w) = covariance_intersection(&x1, &p2, &x2, &p2).unwrap();
        assert!((pc - p2).norm() < 1e-9, "{pc}");
        assert!((0.0..=1.0).contains(&w));
        let (xm, pm) = mixture(&[x1, x1], &[p1, p1], &[0.3, 0.7]);
        assert!((xm - x1).norm() < 1e-12 && (pm - p1).norm() < 1e-12);
        // The mixture of separated means adds their spread.
        let (_, pm) = mixture(&[x1, x2], &[p2, p2], &[0.5, 0.5]);
        assert!((pm[(0, 0)] - 2.0).abs() < 1e-12);
        let bad = Matrix2::new(1.0, 2.0, 2.0, 1.0);
        assert_eq!(
            covariance_weighted(&[x1, x2], &[bad, p2]).err(),
            Some(MixError::Singular)
        );
    }

    /// Step 5 as printed gives the larger covariance to the larger weight;
    /// the federated rule the smaller.
    #[test]
    fn literal_reset_is_the_opposite_of_information_sharing() {
        let p = [Matrix2::<f64>::identity(), Matrix2::identity() * 4.0];
        let x = [Vector2::new(0.0, 0.0), Vector2::new(1.0, 1.0)];
        let alpha = [0.8, 0.2];
        let fused = covariance_weighted(&x, &p).unwrap();
        let (mut xl, mut pl) = (x, p);
        reset(CovReset::PaperLiteral, &mut xl, &mut pl, &fused, &alpha);
        assert!(pl[0][(0, 0)] > pl[1][(0, 0)]);
        let (mut xf, mut pf) = (x, p);
        reset(CovReset::Federated, &mut xf, &mut pf, &fused, &alpha);
        assert!(pf[0][(0, 0)] < pf[1][(0, 0)]);
        assert_eq!(xf[0], fused.0);
    }
}

/// How [`ChipFilters`] weighs its local filters.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ChipWeights {
    /// The seed's entropy weights α ∝ 1/SH(σ), σ of each filter's rate in
    /// m°/s (in °/s a gyro's σ is below 0.242 and SH < 0: ambiguity 1),
    /// SH floored at 1e-6.
    Entropy,
    /// Covariance (inverse-variance) weights, the paper's baseline.
    Covariance,
}

/// Seed 001 on the board: each chip of an axis is a
/// local Kalman filter of [rate, its bias] (rate: a random walk as fast as
/// the platform can turn; bias: a slow random walk), measured by the
/// chip's reading with its noise prior; the local rates are fused by
/// [`ChipWeights`]; the fused rate is fed back to every local filter as in
/// the seed's step 4 (a measurement of its rate with the federated share
/// of the fused variance, β_i = α_i), which is what makes each bias
/// observable. f32, no heap.
#[derive(Clone, Copy, Debug)]
pub struct ChipFilters<const N: usize> {
    filters: [ChipKf; N],
    r: [f32; N],
    q: [f32; 2],
    weights: ChipWeights,
}

/// One chip's local filter of [rate, bias], both random walks: the
/// general filter's steps (`algo::kalman::Kf`, predict with F = I and a
/// diagonal Q, the Joseph update of one scalar reading) written out for two
/// states, P kept as its three distinct elements: about 2 500 and 3 800 instructions
/// per 3-axis sample (N = 4) where the general filter cost 8 900–10 200;
/// equal to it to f32 rounding (`chip_filter_equals_the_general_filter`).
#[derive(Clone, Copy, Debug, PartialEq)]
struct ChipKf {
    x: [f32; 2],
    /// P₀₀, P₀₁, P₁₁.
    p: [f32; 3],
}

impl ChipKf {
    /// P ← P + diag(q). False (unchanged) on a non-finite result.
    #[cfg(test)]
    fn predict(&mut self, q: [f32; 2]) -> bool {
        let p = [self.p[0] + q[0], self.p[1], self.p[2] + q[1]];
        let ok = (p[0] + p[2]).is_finite();
        if ok {
            self.p = p;
        }
        ok
    }

    /// Reading z = h·x + v, v ~ N(0, r), Joseph form: P ← A P Aᵀ + r k kᵀ
    /// with A = I − k hᵀ. False (unchanged) if r ≤ 0, S ≤ 0 or anything is
    /// not finite.
    #[cfg(test)]
    fn update(&mut self, z: f32, h: [f32; 2], r: f32) -> bool {
        self.update_from(self.p, z, h, r)
    }

    /// Predict then update, all or nothing: [`ChipKf::update`] from the
    /// predicted P + diag(q), the filter unchanged if refused (no copy to
    /// restore: 120 instructions per 3-axis sample).
    fn step(&mut self, q: [f32; 2], z: f32, h: [f32; 2], r: f32) -> bool {
        self.update_from([self.p[0] + q[0], self.p[1], self.p[2] + q[1]], z, h, r)
    }

    /// [`ChipKf::update`] from the prior covariance `p`.
    fn update_from(&mut self, p: [f32; 3], z: f32, h: [f32; 2], r: f32) -> bool {
        let [a, b, c] = p;
        let ph = [a * h[0] + b * h[1], b * h[0] + c * h[1]];
        let s = h[0] * ph[0] + h[1] * ph[1] + r;
        // (A non-finite z or S ends in a non-finite state, refused below.)
        if !(r > 0.0 && s > 0.0) {
            return false;
        }
        let inv = 1.0 / s;
        let k = [ph[0] * inv, ph[1] * inv];
        let y = z - (h[0] * self.x[0] + h[1] * self.x[1]);
        let x = [self.x[0] + k[0] * y, self.x[1] + k[1] * y];
        let am = [
            [1.0 - k[0] * h[0], -k[0] * h[1]],
            [-k[1] * h[0], 1.0 - k[1] * h[1]],
        ];
        // M = A P, then P' = M Aᵀ + r k kᵀ (its two off-diagonal
        // products averaged, as the general filter symmetrises).
        let m = [
            [am[0][0] * a + am[0][1] * b, am[0][0] * b + am[0][1] * c],
            [am[1][0] * a + am[1][1] * b, am[1][0] * b + am[1][1] * c],
        ];
        let p00 = m[0][0] * am[0][0] + m[0][1] * am[0][1] + r * k[0] * k[0];
        let p01 = 0.5
            * ((m[0][0] * am[1][0] + m[0][1] * am[1][1])
                + (m[1][0] * am[0][0] + m[1][1] * am[0][1]))
            + r * k[0] * k[1];
        let p11 = m[1][0] * am[1][0] + m[1][1] * am[1][1] + r * k[1] * k[1];
        let p = [p00, p01, p11];
        // One check of the sum: a NaN or ±∞ anywhere makes it non-finite
        // (five checks cost 20 instructions an update on the Cortex-M4).
        if !(x[0] + x[1] + p00 + p01 + p11).is_finite() {
            return false;
        }
        (self.x, self.p) = (x, p);
        true
    }

    /// [`ChipKf::update`] with h = [1, 0] (a reading of the rate alone),
    /// the zero terms left out: A = [[1 − k₀, 0], [−k₁, 1]].
    fn update_rate(&mut self, z: f32, r: f32) -> bool {
        let [a, b, c] = self.p;
        let s = a + r;
        if !(r > 0.0 && s > 0.0) {
            return false;
        }
        let inv = 1.0 / s;
        let k = [a * inv, b * inv];
        let y = z - self.x[0];
        let x = [self.x[0] + k[0] * y, self.x[1] + k[1] * y];
        let a00 = 1.0 - k[0];
        let (m00, m01) = (a00 * a, a00 * b);
        let (m10, m11) = (b - k[1] * a, c - k[1] * b);
        let p00 = m00 * a00 + r * k[0] * k[0];
        let p01 = 0.5 * ((m01 - m00 * k[1]) + m10 * a00) + r * k[0] * k[1];
        let p11 = m11 - m10 * k[1] + r * k[1] * k[1];
        if !(x[0] + x[1] + p00 + p01 + p11).is_finite() {
            return false;
        }
        (self.x, self.p) = (x, [p00, p01, p11]);
        true
    }
}

impl<const N: usize> ChipFilters<N> {
    /// Local filters for chips of white-noise σ `sigma_dps` (°/s per
    /// sample), a rate that may change by `rate_step_dps` per sample (1σ)
    /// and a bias that wanders by `bias_step_dps` per sample.
    pub fn new(
        sigma_dps: [f32; N],
        rate_step_dps: f32,
        bias_step_dps: f32,
        weights: ChipWeights,
    ) -> Result<Self, crate::algo::kalman::KfError> {
        use crate::algo::kalman::KfError;
        let r = sigma_dps.map(|s| s * s);
        let q = [rate_step_dps * rate_step_dps, bias_step_dps * bias_step_dps];
        if !r.iter().chain(q.iter()).all(|v| v.is_finite()) {
            return Err(KfError::NonFinite);
        }
        if !r.iter().all(|&v| v > 0.0) || !q.iter().all(|&v| v >= 0.0) {
            return Err(KfError::NotPositiveDefinite);
        }
        let kf = ChipKf {
            x: [0.0; 2],
            p: [1e4, 0.0, 1.0],
        };
        Ok(Self {
            filters: [kf; N],
            r,
            q,
            weights,
        })
    }

    /// One sample: readings `y` (°/s), chips in `mask`. The fused rate and
    /// each chip's weight; None if no chip could be used.
    pub fn fuse(&mut self, y: &[f32; N], mask: u8) -> Option<(f32, [f32; N])> {
        let mut w = [0.0f32; N];
        let mut ok = 0u8;
        for (i, kf) in self.filters.iter_mut().enumerate() {
            if mask & (1 << i) == 0 || !y[i].is_finite() {
                continue;
            }
            if !kf.step(self.q, y[i], [1.0, 1.0], self.r[i]) {
                continue;
            }
            ok |= 1 << i;
            let var = kf.p[0];
            w[i] = match self.weights {
                ChipWeights::Covariance => 1.0 / var,
                ChipWeights::Entropy => {
                    // SH = σ·½ln(2πeσ²), σ in m°/s: σ² = 10⁶·var.
                    const TWO_PI_E_1E6: f32 =
                        2.0 * core::f32::consts::PI * core::f32::consts::E * 1e6;
                    let s = crate::algo::math::sqrtf(var) * 1000.0;
                    let sh = s * (0.5 * crate::algo::math::lnf(TWO_PI_E_1E6 * var));
                    1.0 / if sh > 1e-6 { sh } else { 1e-6 }
                }
            };
        }
        let sw: f32 = w.iter().sum();
        if ok == 0 || !(sw > 0.0) {
            return None;
        }
        let mut rate = 0.0f32;
        let mut pg = 0.0f32;
        let inv_sw = 1.0 / sw;
        for i in 0..N {
            w[i] *= inv_sw;
            if ok & (1 << i) != 0 {
                rate += w[i] * self.filters[i].x[0];
                pg += w[i] * w[i] * self.filters[i].p[0];
            }
        }
        // Step 4, the feedback: the fused rate goes back to each local
        // filter as a measurement of its rate with the federated share of
        // the fused variance, P_g/β_i (β_i = α_i). Without it a chip's bias
        // is unobservable (its reading is rate + bias, and the rate may
        // change by rate_step every sample); with it, each filter learns
        // its bias against the array.
        for i in 0..N {
            if ok & (1 << i) == 0 || !(w[i] > 0.0) {
                continue;
            }
            // (A refused update leaves the filter as it was.)
            self.filters[i].update_rate(rate, (pg / w[i]).max(1e-12));
        }
        Some((rate, w))
    }
}
