//! Seed 001's fusion of local filters (SEEDS.md "Seed 001"), every
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
    /// against 0.8/0.2 (1/σ²) — the structural reason the quick
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

/// Seed 001 on the board (issue 14, item 4): each chip of an axis is a
/// local Kalman filter of [rate, its bias] (rate: a random walk as fast as
/// the platform can turn; bias: a slow random walk), measured by the
/// chip's reading with its noise prior; the local rates are fused by
/// [`ChipWeights`]; the fused rate is fed back to every local filter as in
/// the seed's step 4 (a measurement of its rate with the federated share
/// of the fused variance, β_i = α_i), which is what makes each bias
/// observable. f32, no heap.
#[derive(Clone, Copy, Debug)]
pub struct ChipFilters<const N: usize> {
    filters: [crate::algo::kalman::Kf<f32, 2>; N],
    r: [f32; N],
    q: nalgebra::Matrix2<f32>,
    weights: ChipWeights,
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
        use crate::algo::kalman::Kf;
        let p0 = nalgebra::Matrix2::new(1e4, 0.0, 0.0, 1.0);
        let kf = Kf::new(nalgebra::Vector2::zeros(), p0)?;
        Ok(Self {
            filters: [kf; N],
            r: sigma_dps.map(|s| s * s),
            q: nalgebra::Matrix2::new(
                rate_step_dps * rate_step_dps,
                0.0,
                0.0,
                bias_step_dps * bias_step_dps,
            ),
            weights,
        })
    }

    /// One sample: readings `y` (°/s), chips in `mask`. The fused rate and
    /// each chip's weight; None if no chip could be used.
    pub fn fuse(&mut self, y: &[f32; N], mask: u8) -> Option<(f32, [f32; N])> {
        let f = nalgebra::Matrix2::identity();
        let h = nalgebra::Matrix1x2::new(1.0f32, 1.0);
        let mut w = [0.0f32; N];
        let mut ok = 0u8;
        for (i, kf) in self.filters.iter_mut().enumerate() {
            if mask & (1 << i) == 0 || !y[i].is_finite() {
                continue;
            }
            let before = *kf;
            let z = nalgebra::Vector1::new(y[i]);
            let r = nalgebra::Matrix1::new(self.r[i]);
            if kf.predict(&f, &self.q).is_err() || kf.update(&z, &h, &r).is_err() {
                *kf = before;
                continue;
            }
            ok |= 1 << i;
            let var = kf.p[(0, 0)];
            w[i] = match self.weights {
                ChipWeights::Covariance => 1.0 / var,
                ChipWeights::Entropy => {
                    let s = crate::algo::math::sqrtf(var) * 1000.0;
                    let sh = s
                        * (0.5
                            * crate::algo::math::lnf(
                                2.0 * core::f32::consts::PI * core::f32::consts::E * s * s,
                            ));
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
        for i in 0..N {
            w[i] /= sw;
            if ok & (1 << i) != 0 {
                rate += w[i] * self.filters[i].x[0];
                pg += w[i] * w[i] * self.filters[i].p[(0, 0)];
            }
        }
        // Step 4, the feedback: the fused rate goes back to each local
        // filter as a measurement of its rate with the federated share of
        // the fused variance, P_g/β_i (β_i = α_i). Without it a chip's bias
        // is unobservable (its reading is rate + bias, and the rate may
        // change by rate_step every sample); with it, each filter learns
        // its bias against the array.
        let hr = nalgebra::Matrix1x2::new(1.0f32, 0.0);
        for i in 0..N {
            if ok & (1 << i) == 0 || !(w[i] > 0.0) {
                continue;
            }
            let kf = &mut self.filters[i];
            let before = *kf;
            let r = nalgebra::Matrix1::new((pg / w[i]).max(1e-12));
            if kf.update(&nalgebra::Vector1::new(rate), &hr, &r).is_err() {
                *kf = before;
            }
        }
        Some((rate, w))
    }
}
