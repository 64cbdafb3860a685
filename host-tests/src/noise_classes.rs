//! Gyro rate records with known noise terms, generated independently of
//! the fit's own formulas: each process simulated sample by sample as it
//! is defined (white angle noise differenced for quantisation, white
//! rate, a summed random walk, a first-order autoregression, a ramp) and
//! flicker by Kasdin's fractional-difference filter (N. J. Kasdin and T.
//! Walter, "Discrete simulation of power law noise", 1992 IEEE Frequency
//! Control Symposium), whose spectrum is B²/(2 sin πf) per cycle a
//! sample: B²/(2πf) at low f, IEEE 952's flicker of coefficient B.

use gyro_sim::Rng;

/// The terms of a record, in °/s units as `gyro_tool::fit` reports them:
/// Q °, N °/√s, B °/s, K °/s/√s, R °/s², and Gauss–Markov (σ °/s, τc s).
#[derive(Clone, Debug, Default)]
pub struct Truth {
    pub power: [f64; 5],
    pub gm: Vec<(f64, f64)>,
}

/// Standard normals in f64 (Box–Muller on 53-bit uniforms): the board's
/// f32 generator's coarse logarithm is not wanted in a reference.
pub struct Normal(Rng);

impl Normal {
    pub fn new(seed: u64) -> Self {
        Normal(Rng::new(seed))
    }
    fn uniform(&mut self) -> f64 {
        let hi = u64::from(self.0.next_u32() >> 5);
        let lo = u64::from(self.0.next_u32() >> 6);
        ((hi << 26 | lo) as f64 + 0.5) / (1u64 << 53) as f64
    }
    pub fn sample(&mut self) -> f64 {
        let (u, v) = (self.uniform(), self.uniform());
        (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
    }
}

/// Flicker rate noise of coefficient `b` over `n` samples: white noise of
/// variance b² through (1 − z⁻¹)^(−½), as a linear convolution by FFT.
pub fn flicker(b: f64, n: usize, rng: &mut Normal) -> Vec<f64> {
    use rustfft::{num_complex::Complex, FftPlanner};
    let len = (2 * n).next_power_of_two();
    let mut h = vec![Complex::new(0.0, 0.0); len];
    let mut w = vec![Complex::new(0.0, 0.0); len];
    let mut c = 1.0f64;
    for k in 0..n {
        if k > 0 {
            c *= (k as f64 - 1.0 + 0.5) / k as f64;
        }
        h[k].re = c;
        w[k].re = b * rng.sample();
    }
    let mut planner = FftPlanner::<f64>::new();
    let fwd = planner.plan_fft_forward(len);
    let inv = planner.plan_fft_inverse(len);
    fwd.process(&mut h);
    fwd.process(&mut w);
    for (a, b) in w.iter_mut().zip(&h) {
        *a *= *b;
    }
    inv.process(&mut w);
    w[..n].iter().map(|z| z.re / len as f64).collect()
}

/// `n` rate samples τ0 apart with the terms of `t`, from `seed`.
pub fn generate(t: &Truth, tau0: f64, n: usize, seed: u64) -> Vec<f64> {
    let mut rng = Normal::new(seed);
    let [q, nn, b, k, r] = t.power;
    let mut y = vec![0.0f64; n];
    if q > 0.0 {
        let mut prev = q * rng.sample();
        for v in y.iter_mut() {
            let x = q * rng.sample();
            *v += (x - prev) / tau0;
            prev = x;
        }
    }
    if nn > 0.0 {
        let s = nn / tau0.sqrt();
        for v in y.iter_mut() {
            *v += s * rng.sample();
        }
    }
    if b > 0.0 {
        for (v, f) in y.iter_mut().zip(flicker(b, n, &mut rng)) {
            *v += f;
        }
    }
    if k > 0.0 {
        let s = k * tau0.sqrt();
        let mut walk = 0.0;
        for v in y.iter_mut() {
            walk += s * rng.sample();
            *v += walk;
        }
    }
    if r != 0.0 {
        for (i, v) in y.iter_mut().enumerate() {
            *v += r * i as f64 * tau0;
        }
    }
    for &(sigma, tau_c) in &t.gm {
        let phi = (-tau0 / tau_c).exp();
        let drive = sigma * (1.0 - phi * phi).sqrt();
        let mut a = sigma * rng.sample();
        for v in y.iter_mut() {
            a = phi * a + drive * rng.sample();
            *v += a;
        }
    }
    y
}
