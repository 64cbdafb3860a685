//! Noise-health self-test (seeds 002 and 003 on the board): a block of one
//! gyro axis is checked for a trend (the reverse-arrangement test), long
//! memory (Hurst by R/S) and normality (skewness, kurtosis).
//!
//! # On a moving board
//!
//! The vehicle's motion is a trend, long memory and a non-Gaussian
//! distribution all at once, so testing a gyro's raw block fails healthy
//! chips whenever the board moves. [`run`] tests what motion cannot
//! explain: each gyro's block minus a least-squares fit `a + b·m` of the
//! median `m` of the other gyros on the same axis, sample by sample. The
//! fit's slope takes out the motion and the chips' scale mismatch, its
//! offset the bias difference. A chip's own drift, long memory or outliers
//! stay in the residual; the median keeps one bad peer out of the
//! reference. The limit: a slow drift of a chip's own during the 2 s block
//! is partly taken as a scale error when the motion itself is slow (under
//! a few Hz the block holds a few cycles, and 0.1 °/s of drift against a
//! 20 °/s sway is a 0.5 % scale error); on a still board it is caught. On a still board `b ≈ 0` and the test is the plain one. The
//! residual's spread includes the reference's noise (for five equal chips,
//! about 1.1× the chip's own σ).

use crate::algo::qualify::hurst::{hurst_rs, octave_windows};
use crate::algo::qualify::moments::{mean_var, skew_kurtosis};
use crate::algo::qualify::trend::reverse_arrangement;
use crate::algo::qualify::QualifyError;
use crate::drivers::{Gyro, Reading};

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
/// `axis(g)`. Each block is then judged against the other gyros on the same
/// axis (module docs); a gyro alone on its axis is judged on its own (the
/// board must then be still). A read error leaves NaN, which the analysis
/// reports as `NonFinite`. Results are logged with defmt when enabled;
/// returns whether every gyro is stationary and normal.
///
/// `to_board` turns gyro g's reading into board-axis rates (the pipeline's
/// [`super::Pipeline::board_rates`]: a chip mounted rotated is compared
/// with its peers on the same board axis).
pub fn run<const N: usize>(
    gyros: &mut [&mut dyn Gyro; N],
    axis: impl Fn(usize) -> usize,
    to_board: impl Fn(usize, &Reading) -> [f32; 3],
    mut tick: impl FnMut(),
    blocks: &mut [[f32; BLOCK]; N],
    results: &mut [Result<NoiseHealth, QualifyError>; N],
) -> bool {
    for i in 0..BLOCK {
        tick();
        for (g, gyro) in gyros.iter_mut().enumerate() {
            blocks[g][i] = gyro
                .read()
                .map_or(f32::NAN, |r| to_board(g, &r)[axis(g).min(2)]);
        }
    }
    analyse(blocks, axis, results)
}

/// The analysis of [`run`] on blocks already read: each gyro against its
/// peers on the same axis (`N` ≤ 8: peer sets are `u8` masks, as in fusion). Returns whether every gyro is stationary and
/// normal.
pub fn analyse<const N: usize>(
    blocks: &[[f32; BLOCK]; N],
    axis: impl Fn(usize) -> usize,
    results: &mut [Result<NoiseHealth, QualifyError>; N],
) -> bool {
    let mut ok = true;
    let mut residual = [0.0f32; BLOCK];
    #[allow(unused_variables)] // g is only logged with defmt
    for g in 0..N {
        let peers = (0..N)
            .filter(|&h| h != g && axis(h) == axis(g))
            .fold(0u8, |m, h| m | 1 << h);
        let r = &mut results[g];
        *r = if peers == 0 {
            noise_health(&blocks[g])
        } else {
            against_peers(blocks, g, peers, &mut residual);
            noise_health(&residual)
        };
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

/// `out = blocks[g] − (a + b·m)`, `m` the per-sample median of the gyros in
/// `peers`, `a` and `b` the least-squares fit (f64 sums: 2048 samples of
/// up to ±2000 °/s). Where no peer read, `m` is the block's mean reference.
/// NaN in the gyro's own block stays NaN. No time term: under slow sway
/// `m` and `t` are nearly collinear over a block, and the fit's error
/// would land in it (`docs/faults.md`, alternatives measured).
fn against_peers<const N: usize>(
    blocks: &[[f32; BLOCK]; N],
    g: usize,
    peers: u8,
    out: &mut [f32; BLOCK],
) {
    let mut vals = [0.0f32; N];
    let (mut n, mut sm, mut sy, mut smm, mut smy) = (0.0f64, 0.0, 0.0, 0.0, 0.0);
    for i in 0..BLOCK {
        let mut finite = 0u8;
        for (h, (v, b)) in vals.iter_mut().zip(blocks.iter()).enumerate() {
            *v = b[i];
            finite |= ((peers & (1 << h) != 0 && v.is_finite()) as u8) << h;
        }
        let m = crate::algo::fusion::median(&vals, finite);
        out[i] = m; // the reference, for the second pass
        let y = blocks[g][i];
        if m.is_finite() && y.is_finite() {
            let (m, y) = (m as f64, y as f64);
            n += 1.0;
            sm += m;
            sy += y;
            smm += m * m;
            smy += m * y;
        }
    }
    let (b, a, mean_m) = if n >= 2.0 {
        let var = smm - sm * sm / n;
        let b = if var > 0.0 {
            (smy - sm * sy / n) / var
        } else {
            0.0
        };
        (b, (sy - b * sm) / n, sm / n)
    } else {
        (0.0, 0.0, 0.0)
    };
    for (o, &y) in out.iter_mut().zip(blocks[g].iter()) {
        let m = if o.is_finite() { *o as f64 } else { mean_m };
        *o = (y as f64 - a - b * m) as f32;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gyro_sim::Rng;

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

    /// Five chips on a swaying board (20 °/s at 0.3–5 Hz, scale errors of
    /// up to ±2 %, different biases), 10 seeds per frequency. Against their
    /// peers, healthy chips fail about as often as the tests' 5 % level
    /// allows on a still board; alone, they fail every time (the motion is
    /// a trend and not Gaussian). A chip with impulsive noise (1 % of
    /// samples off by ±1 °/s) is found non-normal every time, with the
    /// largest kurtosis of the array (its spikes move the others' median,
    /// so they may read non-normal too). A slow drift of a chip's own under
    /// slow sway is not caught (module docs).
    #[test]
    fn motion_is_taken_out_by_the_peers_and_a_spiking_chip_is_still_caught() {
        let scale = [1.02f32, 0.98, 1.0, 1.01, 0.99];
        let bias = [0.3f32, -0.2, 0.0, 0.5, -1.0];
        let (mut runs, mut peer_fail, mut alone_pass) = (0u32, 0u32, 0u32);
        for (k, hz) in [0.3f32, 1.0, 2.5, 5.0].into_iter().enumerate() {
            for seed in 0..10u64 {
                let mut rng = Rng::new(100 * k as u64 + seed);
                let mut blocks = [[0.0f32; BLOCK]; 5];
                for i in 0..BLOCK {
                    let t = i as f32 * 1e-3;
                    let w = 20.0 * libm::sinf(2.0 * core::f32::consts::PI * hz * t + seed as f32);
                    for g in 0..5 {
                        blocks[g][i] = scale[g] * w + bias[g] + 0.09 * rng.gaussian();
                    }
                }
                let mut results = [Err(QualifyError::TooShort); 5];
                analyse(&blocks, |_| 2, &mut results);
                for (g, r) in results.iter().enumerate() {
                    let h = r.unwrap();
                    runs += 1;
                    peer_fail += !(h.stationary && h.normal) as u32;
                    let alone = noise_health(&blocks[g]).unwrap();
                    alone_pass += (alone.stationary && alone.normal) as u32;
                }
                for i in 0..BLOCK {
                    if rng.uniform() < 0.01 {
                        blocks[3][i] += if rng.uniform() < 0.5 { 1.0 } else { -1.0 };
                    }
                }
                analyse(&blocks, |_| 2, &mut results);
                let spiky = results[3].unwrap();
                assert!(!spiky.normal, "{hz} Hz: {spiky:?}");
                for g in [0, 1, 2, 4] {
                    let h = results[g].unwrap();
                    assert!(h.kurtosis < spiky.kurtosis, "{hz} Hz, gyro {g}: {h:?}");
                }
            }
        }
        assert_eq!(alone_pass, 0);
        // 200 healthy chip tests: a 5 % test fails 10 ± 3 of them.
        assert!(
            peer_fail <= 20,
            "{peer_fail} of {runs} healthy chip tests failed"
        );
    }
}
