//! Gyro noise qualification beyond the Allan curve (seeds 002 and 003):
//! moments and normality, the reverse-arrangement trend test, detrending,
//! AR modelling, Hurst exponents, fractional differencing and wavelet
//! BayesShrink denoising.
//!
//! Everything is generic over [`Real`] (f32 on the board, f64 on the host),
//! works in caller-provided buffers (no heap), bounds every loop, and
//! returns a typed [`QualifyError`] for input it cannot handle.

pub mod ar;
pub mod emd;
pub mod hurst;
pub mod moments;
pub mod pipeline;
pub mod trend;
pub mod wavelet;

use core::fmt::Debug;
use core::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

/// Why an analysis could not run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum QualifyError {
    /// Too few samples for the requested analysis.
    TooShort,
    /// A sample is NaN or infinite.
    NonFinite,
    /// Zero variance: the statistic is undefined.
    Constant,
    /// A caller-provided buffer is too small.
    Buffer,
    /// A setting is out of range (order, level count, segment count…).
    Parameter,
}

/// The float types the analyses run in.
pub trait Real:
    Copy
    + Debug
    + Default
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
    + DivAssign
{
    /// From an f64 constant (rounded for f32).
    fn of(v: f64) -> Self;
    /// To f64 (exact).
    fn f64(self) -> f64;
    /// Square root.
    fn sqrt(self) -> Self;
    /// Natural logarithm.
    fn ln(self) -> Self;
    /// Absolute value.
    fn abs(self) -> Self {
        if self < Self::of(0.0) {
            -self
        } else {
            self
        }
    }
    /// Neither NaN nor infinite.
    fn finite(self) -> bool;
}

impl Real for f32 {
    fn of(v: f64) -> Self {
        v as f32
    }
    fn f64(self) -> f64 {
        self as f64
    }
    fn sqrt(self) -> Self {
        crate::algo::math::sqrtf(self)
    }
    fn ln(self) -> Self {
        crate::algo::math::lnf(self)
    }
    fn finite(self) -> bool {
        self.is_finite()
    }
}

impl Real for f64 {
    fn of(v: f64) -> Self {
        v
    }
    fn f64(self) -> f64 {
        self
    }
    fn sqrt(self) -> Self {
        libm::sqrt(self)
    }
    fn ln(self) -> Self {
        libm::log(self)
    }
    fn finite(self) -> bool {
        self.is_finite()
    }
}

/// Check every sample is finite.
pub fn check_finite<F: Real>(x: &[F]) -> Result<(), QualifyError> {
    if x.iter().all(|v| v.finite()) {
        Ok(())
    } else {
        Err(QualifyError::NonFinite)
    }
}

#[cfg(test)]
mod tests;
