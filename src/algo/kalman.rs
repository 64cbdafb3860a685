//! A linear Kalman filter core on nalgebra's fixed-size matrices (no heap,
//! f32 or f64): predict, and an update in Joseph form, which keeps P
//! symmetric and positive semidefinite whatever the gain's rounding. Every
//! step checks what it is given and what it produces, and fails with a
//! typed [`KfError`] instead of spreading NaN. Checked
//! against filterpy's `KalmanFilter` (`host-tests/vectors/kalman.in`, made
//! by `make_kalman_vectors.py`).

use nalgebra::{RealField, SMatrix, SVector};

/// Why a filter step was refused. The filter is left as it was.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum KfError {
    /// A covariance (P, Q or R) is not symmetric positive (semi)definite:
    /// its Cholesky factorisation failed (P, R: definite; Q: P + Q is
    /// checked after the step).
    NotPositiveDefinite,
    /// The innovation covariance S = H P Hᵀ + R cannot be factored.
    SingularInnovation,
    /// An input, or the result, holds NaN or ±inf.
    NonFinite,
}

/// The state estimate and its covariance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Kf<T: RealField + Copy, const N: usize> {
    /// State.
    pub x: SVector<T, N>,
    /// Covariance.
    pub p: SMatrix<T, N, N>,
}

/// What an update saw.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Innovation<T: RealField + Copy, const M: usize> {
    /// y = z − H x (before the update).
    pub y: SVector<T, M>,
    /// S = H P Hᵀ + R.
    pub s: SMatrix<T, M, M>,
    /// Normalised innovation squared yᵀ S⁻¹ y (χ²_M when consistent).
    pub nis: T,
}

fn finite<T: RealField + Copy, const R: usize, const C: usize>(m: &SMatrix<T, R, C>) -> bool {
    m.iter().all(|v| v.is_finite())
}

fn symmetrise<T: RealField + Copy, const N: usize>(p: &SMatrix<T, N, N>) -> SMatrix<T, N, N> {
    (p + p.transpose()) * nalgebra::convert::<f64, T>(0.5)
}

impl<T: RealField + Copy, const N: usize> Kf<T, N> {
    /// A filter at `x` with covariance `p` (symmetric positive definite).
    pub fn new(x: SVector<T, N>, p: SMatrix<T, N, N>) -> Result<Self, KfError> {
        if !finite(&x) || !finite(&p) {
            return Err(KfError::NonFinite);
        }
        let p = symmetrise(&p);
        if p.cholesky().is_none() {
            return Err(KfError::NotPositiveDefinite);
        }
        Ok(Self { x, p })
    }

    /// x ← F x, P ← F P Fᵀ + Q.
    pub fn predict(&mut self, f: &SMatrix<T, N, N>, q: &SMatrix<T, N, N>) -> Result<(), KfError> {
        if !finite(f) || !finite(q) {
            return Err(KfError::NonFinite);
        }
        let x = f * self.x;
        let p = symmetrise(&(f * self.p * f.transpose() + q));
        if !finite(&x) || !finite(&p) {
            return Err(KfError::NonFinite);
        }
        // Q may be singular (semidefinite), P + Q must stay definite.
        if p.cholesky().is_none() {
            return Err(KfError::NotPositiveDefinite);
        }
        (self.x, self.p) = (x, p);
        Ok(())
    }

    /// Measurement `z` = H x + v, v ~ N(0, R): K = P Hᵀ S⁻¹, x ← x + K y,
    /// P ← (I − K H) P (I − K H)ᵀ + K R Kᵀ (Joseph).
    pub fn update<const M: usize>(
        &mut self,
        z: &SVector<T, M>,
        h: &SMatrix<T, M, N>,
        r: &SMatrix<T, M, M>,
    ) -> Result<Innovation<T, M>, KfError> {
        if !finite(z) || !finite(h) || !finite(r) {
            return Err(KfError::NonFinite);
        }
        if symmetrise(r).cholesky().is_none() {
            return Err(KfError::NotPositiveDefinite);
        }
        let y = z - h * self.x;
        let pht = self.p * h.transpose();
        let s = symmetrise(&(h * pht + r));
        if !finite(&y) || !finite(&s) {
            return Err(KfError::NonFinite);
        }
        let chol = s.cholesky().ok_or(KfError::SingularInnovation)?;
        // K = P Hᵀ S⁻¹, solved rather than inverted: Kᵀ = S⁻¹ H P.
        let k = chol.solve(&pht.transpose()).transpose();
        let x = self.x + k * y;
        let ikh = SMatrix::<T, N, N>::identity() - k * h;
        let p = symmetrise(&(ikh * self.p * ikh.transpose() + k * r * k.transpose()));
        if !finite(&x) || !finite(&p) {
            return Err(KfError::NonFinite);
        }
        let nis = (y.transpose() * chol.solve(&y))[(0, 0)];
        (self.x, self.p) = (x, p);
        Ok(Innovation { y, s, nis })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix2, Matrix2x4, Matrix3, Matrix4, Vector2, Vector3, Vector4};

    #[allow(clippy::excessive_precision, clippy::unreadable_literal)]
    mod v {
        include!("../../host-tests/vectors/kalman.in");
    }

    /// A constant-velocity filter and its F, Q, H and R.
    type Cv<T> = (Kf<T, 4>, Matrix4<T>, Matrix4<T>, Matrix2x4<T>, Matrix2<T>);

    fn cv<T: RealField + Copy>() -> Cv<T> {
        let c = |v: f64| nalgebra::convert::<f64, T>(v);
        let dt = 0.1;
        let kf = Kf::new(
            Vector4::new(c(0.0), c(0.0), c(1.0), c(0.5)),
            Matrix4::from_diagonal(&Vector4::new(c(1.0), c(1.0), c(4.0), c(4.0))),
        )
        .unwrap();
        let f = Matrix4::new(
            c(1.0),
            c(0.0),
            c(dt),
            c(0.0),
            c(0.0),
            c(1.0),
            c(0.0),
            c(dt),
            c(0.0),
            c(0.0),
            c(1.0),
            c(0.0),
            c(0.0),
            c(0.0),
            c(0.0),
            c(1.0),
        );
        let (q, a, b) = (0.05, dt * dt * dt / 3.0, dt * dt / 2.0);
        let qm = Matrix4::new(
            c(q * a),
            c(0.0),
            c(q * b),
            c(0.0),
            c(0.0),
            c(q * a),
            c(0.0),
            c(q * b),
            c(q * b),
            c(0.0),
            c(q * dt),
            c(0.0),
            c(0.0),
            c(q * b),
            c(0.0),
            c(q * dt),
        );
        let h = Matrix2x4::new(
            c(1.0),
            c(0.0),
            c(0.0),
            c(0.0),
            c(0.0),
            c(1.0),
            c(0.0),
            c(0.0),
        );
        let r = Matrix2::new(c(0.25), c(0.05), c(0.05), c(0.16));
        (kf, f, qm, h, r)
    }

    fn z_cv<T: RealField + Copy>(k: usize) -> Vector2<T> {
        let t = (k + 1) as f64 * 0.1;
        let a = 1.0 * t + 0.3 * (((k * 37) % 11) as f64 / 10.0 - 0.5);
        let b = 0.5 * t + 0.2 * (((k * 53) % 13) as f64 / 12.0 - 0.5);
        Vector2::new(nalgebra::convert(a), nalgebra::convert(b))
    }

    /// f64 against filterpy to 1e-12 relative (of each quantity's scale);
    /// f32 to 2e-5.
    #[test]
    fn constant_velocity_filter_matches_filterpy() {
        let (mut kf, f, q, h, r) = cv::<f64>();
        let (mut k32, f32m, q32, h32, r32) = cv::<f32>();
        let (mut worst64, mut worst32) = (0.0f64, 0.0f64);
        for k in 0..50 {
            kf.predict(&f, &q).unwrap();
            kf.update(&z_cv(k), &h, &r).unwrap();
            k32.predict(&f32m, &q32).unwrap();
            k32.update(&z_cv(k), &h32, &r32).unwrap();
            for i in 0..4 {
                let want = v::CV_X[4 * k + i];
                worst64 = worst64.max((kf.x[i] - want).abs() / want.abs().max(1.0));
                worst32 = worst32.max((f64::from(k32.x[i]) - want).abs() / want.abs().max(1.0));
            }
            for i in 0..16 {
                let want = v::CV_P[16 * k + i];
                let scale = v::CV_P[16 * k]; // P[0][0]
                worst64 = worst64.max((kf.p[(i / 4, i % 4)] - want).abs() / scale);
                worst32 = worst32.max((f64::from(k32.p[(i / 4, i % 4)]) - want).abs() / scale);
            }
        }
        println!("worst relative error: f64 {worst64:.2e}, f32 {worst32:.2e}");
        assert!(worst64 < 1e-12, "{worst64}");
        assert!(worst32 < 2e-5, "{worst32}");
    }

    #[test]
    fn mixed_measurement_filter_matches_filterpy() {
        let mut kf = Kf::new(
            Vector3::new(1.0, -1.0, 0.5),
            Matrix3::new(2.0, 0.3, 0.0, 0.3, 1.0, 0.1, 0.0, 0.1, 0.5),
        )
        .unwrap();
        let f = Matrix3::new(0.9, 0.1, 0.0, 0.0, 0.95, 0.05, 0.02, 0.0, 0.99);
        let q = Matrix3::from_diagonal(&Vector3::new(0.01, 0.02, 0.005));
        let h = nalgebra::Matrix2x3::new(1.0, 0.0, 1.0, 0.0, 2.0, -1.0);
        let r = Matrix2::from_diagonal(&Vector2::new(0.1, 0.3));
        let mut worst = 0.0f64;
        for k in 0..30 {
            kf.predict(&f, &q).unwrap();
            let z = Vector2::new(libm::sin(0.3 * k as f64), 0.5 * libm::cos(0.2 * k as f64));
            let inn = kf.update(&z, &h, &r).unwrap();
            assert!(inn.nis.is_finite() && inn.nis >= 0.0);
            for i in 0..3 {
                worst = worst.max((kf.x[i] - v::MIX_X[3 * k + i]).abs());
            }
            for i in 0..9 {
                worst = worst.max((kf.p[(i / 3, i % 3)] - v::MIX_P[9 * k + i]).abs());
            }
        }
        assert!(worst < 1e-12, "{worst}");
    }

    /// Bad input is a typed error and leaves the filter as it was.
    #[test]
    fn bad_covariances_and_non_finite_input_are_typed_errors() {
        let (mut kf, f, q, h, r) = cv::<f64>();
        let before = kf;
        let mut bad_p = Matrix4::identity();
        bad_p[(0, 0)] = -1.0;
        assert_eq!(
            Kf::new(before.x, bad_p).err(),
            Some(KfError::NotPositiveDefinite)
        );
        let mut nan_x = before.x;
        nan_x[1] = f64::NAN;
        assert_eq!(Kf::new(nan_x, before.p).err(), Some(KfError::NonFinite));
        let mut f_inf = f;
        f_inf[(0, 2)] = f64::INFINITY;
        assert_eq!(kf.predict(&f_inf, &q), Err(KfError::NonFinite));
        assert_eq!(
            kf.predict(&f, &(-q * 1e6)),
            Err(KfError::NotPositiveDefinite)
        );
        assert_eq!(
            kf.update(&Vector2::new(f64::NAN, 0.0), &h, &r).err(),
            Some(KfError::NonFinite)
        );
        assert_eq!(
            kf.update(
                &Vector2::new(0.0, 0.0),
                &h,
                &Matrix2::new(1.0, 2.0, 2.0, 1.0)
            )
            .err(),
            Some(KfError::NotPositiveDefinite)
        );
        // A zero-noise measurement (R = 0) is refused: with R definite, S
        // is definite too, so `SingularInnovation` is left for rounding.
        assert_eq!(
            kf.update(&Vector2::new(1.0, 2.0), &h, &Matrix2::zeros())
                .err(),
            Some(KfError::NotPositiveDefinite)
        );
        // Overflow in the product is caught as non-finite.
        let huge = h * 1e200;
        assert_eq!(
            kf.update(&Vector2::new(1.0, 2.0), &huge, &r).err(),
            Some(KfError::NonFinite)
        );
        assert_eq!(kf, before, "refused steps change nothing");
    }
}
