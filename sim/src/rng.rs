//! A small deterministic generator (xoshiro128++ seeded by SplitMix64), so a
//! seed reproduces a run bit for bit on the host and on the target.

use gyro_array::algo::math::{lnf, sqrtf};

/// xoshiro128++ with a cached second Gaussian from Box–Muller.
#[derive(Clone)]
pub struct Rng {
    s: [u32; 4],
    spare: Option<f32>,
}

impl Rng {
    /// Seed from a 64-bit value (any value, including 0).
    pub fn new(seed: u64) -> Self {
        let mut z = seed;
        let mut next = || {
            z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut x = z;
            x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            x ^ (x >> 31)
        };
        let a = next();
        let b = next();
        Self {
            s: [a as u32, (a >> 32) as u32, b as u32, (b >> 32) as u32 | 1],
            spare: None,
        }
    }

    /// Next 32 random bits.
    pub fn next_u32(&mut self) -> u32 {
        let s = &mut self.s;
        let r = s[0].wrapping_add(s[3]).rotate_left(7).wrapping_add(s[0]);
        let t = s[1] << 9;
        s[2] ^= s[0];
        s[3] ^= s[1];
        s[1] ^= s[2];
        s[0] ^= s[3];
        s[2] ^= t;
        s[3] = s[3].rotate_left(11);
        r
    }

    /// Uniform in [0, 1), 24 bits.
    pub fn uniform(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / 16_777_216.0)
    }

    /// Standard normal (Box–Muller, polar form).
    pub fn gaussian(&mut self) -> f32 {
        if let Some(g) = self.spare.take() {
            return g;
        }
        loop {
            let u = 2.0 * self.uniform() - 1.0;
            let v = 2.0 * self.uniform() - 1.0;
            let s = u * u + v * v;
            if s > 0.0 && s < 1.0 {
                let f = sqrtf(-2.0 * lnf(s) / s);
                self.spare = Some(v * f);
                return u * f;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gaussian_moments() {
        let mut r = Rng::new(7);
        let n = 200_000;
        let (mut s1, mut s2, mut s4) = (0.0f64, 0.0f64, 0.0f64);
        for _ in 0..n {
            let g = r.gaussian() as f64;
            s1 += g;
            s2 += g * g;
            s4 += g * g * g * g;
        }
        let m = s1 / n as f64;
        let v = s2 / n as f64 - m * m;
        assert!(m.abs() < 0.01, "mean {m}");
        assert!((v - 1.0).abs() < 0.01, "var {v}");
        assert!((s4 / n as f64 / (v * v) - 3.0).abs() < 0.05, "kurtosis");
    }
}
