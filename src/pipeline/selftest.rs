//! Noise-health self-test (seeds 002 and 003 on the board): a block of one
//! gyro axis, taken while the board is still, is checked for a trend (the
//! reverse-arrangement test), long memory (Hurst by R/S) and normality
//! (skewness, kurtosis).

use crate::algo::qualify::hurst::{hurst_rs, octave_windows};
use crate::algo::qualify::moments::{mean_var, skew_kurtosis};
use crate::algo::qualify::trend::reverse_arrangement;
use crate::algo::qualify::QualifyError;
use crate::drivers::Gyro;

/// Samples per self-test block.
pub const BLOCK: usize = 2048;
/// Segments of the reverse-arrangement test.
pub const SEGMENTS: usize = 32;

/// Result of one gyro axis.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct NoiseHealth {
    /// Standard deviation of the block, °/s.
    pub std_dps: f32,
    /// λ of the reverse-arrangement test over 32 segments.
    pub lambda: f32,
    /// |λ| ≤ 2 (no trend at the 5 % level, as seed 003 reads it).
    pub stationary: bool,
    /// Hurst exponent by R/S over windows 8 … N/2 (white noise reads
    /// about 0.55–0.6 at N = 2048: R/S is biased up for short windows).
    pub hurst: f32,
    /// Skewness (0 for Gaussian).
    pub skewness: f32,
    /// Kurtosis (3 for Gaussian).
    pub kurtosis: f32,
    /// Within 5 standard errors of Gaussian: |ξ| ≤ 5√(6/N) and
    /// |υ − 3| ≤ 5√(24/N).
    pub normal: bool,
}

/// Run the self-test on one block (any length ≥ 64; 2048 on the board).
/// Constant blocks (a dead or stuck axis) and NaN are typed errors.
pub fn noise_health(block: &[f32]) -> Result<NoiseHealth, QualifyError> {
    if block.len() < 64 {
        return Err(QualifyError::TooShort);
    }
    let (_, var) = mean_var(block)?;
    let (skewness, kurtosis) = skew_kurtosis(block)?;
    let mut means = [0.0f32; SEGMENTS];
    let ra = reverse_arrangement(block, SEGMENTS, &mut means)?;
    let mut ws = [0usize; 24];
    let k = octave_windows(block.len(), &mut ws);
    let hurst = hurst_rs(block, &ws[..k])?;
    let n = block.len() as f32;
    let se_s = crate::algo::math::sqrtf(6.0 / n);
    let se_k = crate::algo::math::sqrtf(24.0 / n);
    Ok(NoiseHealth {
        std_dps: crate::algo::math::sqrtf(var),
        lambda: ra.lambda as f32,
        stationary: ra.stationary(),
        hurst,
        skewness,
        kurtosis,
        normal: skewness.abs() <= 5.0 * se_s && (kurtosis - 3.0).abs() <= 5.0 * se_k,
    })
}

/// The self-test mode: `tick` waits for the next sample period (and moves
/// an emulated bus's time), then every gyro is read once; gyro g's axis is
/// `axis(g)` (its first one). A read error leaves NaN, which the analysis
/// reports as `NonFinite`. Results are logged with defmt when enabled;
/// returns whether every gyro is stationary and normal.
pub fn run<const N: usize>(
    gyros: &mut [&mut dyn Gyro; N],
    axis: impl Fn(usize) -> usize,
    mut tick: impl FnMut(),
    blocks: &mut [[f32; BLOCK]; N],
    results: &mut [Result<NoiseHealth, QualifyError>; N],
) -> bool {
    for i in 0..BLOCK {
        tick();
        for (g, gyro) in gyros.iter_mut().enumerate() {
            blocks[g][i] = gyro.read().map_or(f32::NAN, |r| r.rate_dps[axis(g).min(2)]);
        }
    }
    let mut ok = true;
    #[allow(unused_variables)] // g is only logged with defmt
    for (g, (b, r)) in blocks.iter().zip(results.iter_mut()).enumerate() {
        *r = noise_health(b);
        match r {
            Ok(h) => {
                #[cfg(feature = "defmt")]
                defmt::info!(
                    "self-test gyro {}: std {=f32} dps, lambda {=f32} (stationary {}), H {=f32}, skew {=f32}, kurt {=f32} (normal {})",
                    g,
                    h.std_dps,
                    h.lambda,
                    h.stationary,
                    h.hurst,
                    h.skewness,
                    h.kurtosis,
                    h.normal
                );
                ok &= h.stationary && h.normal;
            }
            Err(_e) => {
                #[cfg(feature = "defmt")]
                defmt::error!("self-test gyro {}: {}", g, _e);
                ok = false;
            }
        }
    }
    ok
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emu::Rng;

    #[test]
    fn white_noise_passes_and_a_trend_or_a_dead_axis_does_not() {
        let mut rng = Rng::new(4);
        let mut b = [0.0f32; BLOCK];
        for v in b.iter_mut() {
            *v = 0.09 * rng.gaussian();
        }
        let h = noise_health(&b).unwrap();
        assert!(h.stationary && h.normal, "{h:?}");
        assert!(
            (h.std_dps - 0.09).abs() < 0.005 && h.hurst > 0.4 && h.hurst < 0.7,
            "{h:?}"
        );
        for (i, v) in b.iter_mut().enumerate() {
            *v += 0.1 * i as f32 / BLOCK as f32; // a 0.1 °/s drift over the block
        }
        assert!(!noise_health(&b).unwrap().stationary);
        assert_eq!(noise_health(&[0.5; BLOCK]), Err(QualifyError::Constant));
        assert_eq!(noise_health(&[0.5; 10]), Err(QualifyError::TooShort));
        b[7] = f32::NAN;
        assert_eq!(noise_health(&b), Err(QualifyError::NonFinite));
    }
}
