//! MEMS gyro error model (IEEE Std 952 terms) and the true-rate profile.

use super::Rng;
use gyro_array::algo::math::{expf, sqrtf};

/// Error terms of one gyro axis, in the units of a datasheet.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct NoiseParams {
    /// Angle random walk N, °/√h (white rate noise; 60 × the °/s/√Hz density).
    pub arw_deg_rt_h: f32,
    /// Bias instability B, °/h: the Allan floor is 0.664·B.
    pub bias_instability_deg_h: f32,
    /// Correlation time of the Gauss–Markov bias process, s; 0 for flicker
    /// noise instead (a flat Allan floor of 0.664·B from 3 s to 3000 s, see
    /// [`AxisNoise::step`]).
    pub bias_tau_s: f32,
    /// Rate random walk K, °/h/√h.
    pub rrw_deg_h_rt_h: f32,
    /// Constant bias, °/s.
    pub bias_dps: f32,
    /// Scale-factor error, as a fraction (0.01 = 1 %).
    pub scale_error: f32,
}

impl NoiseParams {
    /// ICM-42688-P: 0.0028 °/s/√Hz noise density (datasheet table 1), a few °/h
    /// of bias instability as typical for consumer MEMS.
    pub const ICM42688: Self = Self {
        arw_deg_rt_h: 0.168,
        bias_instability_deg_h: 5.0,
        bias_tau_s: 100.0,
        rrw_deg_h_rt_h: 2.0,
        bias_dps: 0.0,
        scale_error: 0.0,
    };
    /// ADXRS453: 0.015 °/s/√Hz noise density, 16 °/h bias stability.
    pub const ADXRS453: Self = Self {
        arw_deg_rt_h: 0.9,
        bias_instability_deg_h: 16.0,
        bias_tau_s: 100.0,
        rrw_deg_h_rt_h: 2.0,
        bias_dps: 0.0,
        scale_error: 0.0,
    };
    /// No noise at all (for exact tests).
    pub const IDEAL: Self = Self {
        arw_deg_rt_h: 0.0,
        bias_instability_deg_h: 0.0,
        bias_tau_s: 100.0,
        rrw_deg_h_rt_h: 0.0,
        bias_dps: 0.0,
        scale_error: 0.0,
    };

    /// Standard deviation of the white noise per sample, °/s, at `fs_hz`.
    pub fn white_sigma_dps(&self, fs_hz: f32) -> f32 {
        self.arw_deg_rt_h / 60.0 * sqrtf(fs_hz)
    }
}

/// Flicker bias instability as a sum of Gauss–Markov poles: correlation
/// times half a decade apart, 0.1 s to 31 623 s, each of standard
/// deviation `FLICKER_POLE`·B. Their Allan deviations add up to a floor
/// flat within ±1.2 % from 3 s to 3000 s whose mean is 1.0934 × one pole's
/// σ (the exact Gauss–Markov Allan variance summed over the poles), so
/// that the floor is 0.664·B as IEEE 952 defines B.
const FLICKER_POLES: usize = 12;
const FLICKER_POLE: f32 = 0.664 / 1.0934;

/// Running error state of one axis.
#[derive(Clone, Copy, Debug, Default)]
pub struct AxisNoise {
    gm_dps: f32,
    rw_dps: f32,
    flicker_dps: [f32; FLICKER_POLES],
    /// The poles have been drawn from their stationary distribution (a pole
    /// of 9 h started at 0 would take hours to reach it).
    flicker_on: bool,
}

impl AxisNoise {
    /// Measured rate for true rate `true_dps` over one step of `dt_s`.
    ///
    /// Bias instability is a first-order Gauss–Markov process of σ = 1.52·B
    /// (meant to put its Allan peak on the flicker floor 0.664·B, taking
    /// the peak as 0.437·σ; it is 0.617·σ at τ ≈ 1.89·τc, exactly and
    /// measured, so the peak is 0.94·B: 1.41× the nominal floor. Left as it
    /// is: every golden digest and evaluation figure rests on it), or with
    /// `bias_tau_s` = 0 flicker noise whose floor is 0.664·B (the
    /// `FLICKER_POLES`). Rate random walk adds K·√dt per step.
    pub fn step(&mut self, p: &NoiseParams, rng: &mut Rng, true_dps: f32, dt_s: f32) -> f32 {
        let white = p.white_sigma_dps(1.0 / dt_s) * rng.gaussian();
        if p.bias_instability_deg_h > 0.0 && p.bias_tau_s == 0.0 {
            // Each pole as x += −c·x + σ·√(c(2 − c))·g with c = 1 − e^(−dt/T)
            // from expm1 (the slowest poles have c ≈ 3e-7: as 1 − a in f32
            // it would be off by 10 %).
            let sigma = FLICKER_POLE * p.bias_instability_deg_h / 3600.0;
            if !self.flicker_on {
                self.flicker_on = true;
                for x in self.flicker_dps.iter_mut() {
                    *x = sigma * rng.gaussian();
                }
            }
            let mut t = 0.1f32;
            for x in self.flicker_dps.iter_mut() {
                let c = -libm::expm1f(-dt_s / t);
                *x += -c * *x + sigma * sqrtf(c * (2.0 - c)) * rng.gaussian();
                t *= 3.162_277_7;
            }
            self.gm_dps = self.flicker_dps.iter().sum();
        } else if p.bias_instability_deg_h > 0.0 {
            let sigma = 1.52 * p.bias_instability_deg_h / 3600.0;
            let a = expf(-dt_s / p.bias_tau_s);
            self.gm_dps = a * self.gm_dps + sigma * sqrtf(1.0 - a * a) * rng.gaussian();
        }
        if p.rrw_deg_h_rt_h > 0.0 {
            // K in °/h/√h = K/3600 °/s per √h = K/(3600·60) °/s per √s.
            self.rw_dps += p.rrw_deg_h_rt_h / 216_000.0 * sqrtf(dt_s) * rng.gaussian();
        }
        (1.0 + p.scale_error) * true_dps + p.bias_dps + self.gm_dps + self.rw_dps + white
    }
}

/// The true angular rate seen by the array: a constant per axis plus an
/// optional sine (an antenna slewing or a vehicle rocking).
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RateProfile {
    /// Constant part per axis, °/s.
    pub base_dps: [f32; 3],
    /// Sine amplitude per axis, °/s.
    pub sine_dps: [f32; 3],
    /// Sine frequency, Hz.
    pub sine_hz: f32,
    /// Time the sine starts, s (the board self-tests while still).
    pub sine_start_s: f32,
}

impl RateProfile {
    /// The same constant rate on every axis.
    pub const fn constant(dps: f32) -> Self {
        Self {
            base_dps: [dps; 3],
            sine_dps: [0.0; 3],
            sine_hz: 0.0,
            sine_start_s: 0.0,
        }
    }

    /// The true rate at time `t_s`.
    pub fn at(&self, t_s: f32) -> [f32; 3] {
        let t = t_s - self.sine_start_s;
        let s = if t > 0.0 {
            libm::sinf(2.0 * core::f32::consts::PI * self.sine_hz * t)
        } else {
            0.0
        };
        [
            self.base_dps[0] + self.sine_dps[0] * s,
            self.base_dps[1] + self.sine_dps[1] * s,
            self.base_dps[2] + self.sine_dps[2] * s,
        ]
    }
}

impl RateProfile {
    /// The true rate at time `t_s`, in f64: the chips on their own clocks
    /// sample it at 32 kHz for minutes, where an f32 time is 61 µs coarse
    /// after 10 minutes.
    pub fn at_f64(&self, t_s: f64) -> [f64; 3] {
        let t = t_s - self.sine_start_s as f64;
        let s = if t > 0.0 {
            libm::sin(2.0 * core::f64::consts::PI * self.sine_hz as f64 * t)
        } else {
            0.0
        };
        core::array::from_fn(|i| self.base_dps[i] as f64 + self.sine_dps[i] as f64 * s)
    }
}

/// Round to counts and clamp to the 16-bit output register.
pub fn quantise(dps: f32, lsb_per_dps: f32) -> i16 {
    let c = libm::roundf(dps * lsb_per_dps);
    if c.is_nan() {
        0
    } else if c >= i16::MAX as f32 {
        i16::MAX
    } else if c <= i16::MIN as f32 {
        i16::MIN
    } else {
        c as i16
    }
}

/// Fractional Gaussian noise with Hurst exponent `h` (0 < h < 1), unit
/// variance, by Hosking's exact method (Durbin–Levinson on the fGn
/// autocovariance), into `x`; `phi` and `prev` are scratch of `x.len()`.
/// `gauss` supplies one N(0, 1) draw per sample, in order. O(n²): meant
/// for blocks of a few thousand samples (the long-memory test data of
/// seed 002).
pub fn fgn_hosking(
    h: f64,
    mut gauss: impl FnMut() -> f64,
    x: &mut [f64],
    phi: &mut [f64],
    prev: &mut [f64],
) {
    let n = x.len().min(phi.len()).min(prev.len());
    if n == 0 {
        return;
    }
    let gam = |k: f64| {
        0.5 * (libm::pow(libm::fabs(k + 1.0), 2.0 * h) - 2.0 * libm::pow(libm::fabs(k), 2.0 * h)
            + libm::pow(libm::fabs(k - 1.0), 2.0 * h))
    };
    let mut v = 1.0;
    x[0] = gauss();
    for t in 1..n {
        let mut s = 0.0;
        for j in 0..t - 1 {
            s += phi[j] * gam((t - 1 - j) as f64);
        }
        let kappa = (gam(t as f64) - s) / v;
        prev[..t - 1].copy_from_slice(&phi[..t - 1]);
        for j in 0..t - 1 {
            phi[j] = prev[j] - kappa * prev[t - 2 - j];
        }
        phi[t - 1] = kappa;
        v *= 1.0 - kappa * kappa;
        let mut p = 0.0;
        for j in 0..t {
            p += phi[j] * x[t - 1 - j];
        }
        x[t] = p + libm::sqrt(v) * gauss();
    }
}
