//! Delay compensation: the fused rate predicted forward to a stated
//! instant from its recent samples.
//!
//! The fused rate describes an instant some 2 ms before the antenna gets
//! it (the chips' filters, the alignment, the link); on a vehicle's motion
//! every millisecond of it is pointing error (`gyro_tool::antenna`, the host's reference antenna loop). The
//! predictor fits a straight line, by least squares, to the last `K`
//! samples of each axis (one sample period apart) and reads it `h` after
//! the newest, each axis at its own horizon (their delays differ). It is
//! exact for a rate that changes linearly; on a curve it leaves an error
//! that grows with K and h, and it passes white noise with the gain
//! [`Predictor::noise_gain`], so K trades the curve's error against the
//! noise's (`pointing-eval` measures them and picks K).

/// One axis-triple's predictor over the last `K` samples.
#[derive(Clone, Copy, Debug)]
pub struct Predictor<const K: usize> {
    ring: [[f32; 3]; K],
    len: usize,
    /// The oldest sample's slot.
    head: usize,
}

impl<const K: usize> Default for Predictor<K> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const K: usize> Predictor<K> {
    /// Empty.
    pub const fn new() -> Self {
        Self {
            ring: [[0.0; 3]; K],
            len: 0,
            head: 0,
        }
    }

    /// Forget the samples (a gap: an axis without a fused value).
    pub fn clear(&mut self) {
        self.len = 0;
        self.head = 0;
    }

    /// Whether it holds the `K` samples a prediction needs.
    pub fn ready(&self) -> bool {
        self.len == K && K > 0
    }

    /// One sample per axis, one sample period after the last.
    pub fn push(&mut self, y: [f32; 3]) {
        if K == 0 {
            return;
        }
        let mut j = self.head + self.len;
        if j >= K {
            j -= K;
        }
        if let Some(slot) = self.ring.get_mut(j) {
            *slot = y;
        }
        if self.len < K {
            self.len += 1;
        } else {
            self.head = if self.head + 1 >= K { 0 } else { self.head + 1 };
        }
    }

    /// Each axis's least-squares line through the `K` samples, read
    /// `ahead[a]` sample periods after the newest (K = 1: the newest as it
    /// is); `None` until `K` are held.
    pub fn at(&self, ahead: [f32; 3]) -> Option<[f32; 3]> {
        if !self.ready() {
            return None;
        }
        // x_j = j (j = 0 the oldest): ȳ + slope·(x − x̄), x = K − 1 + ahead;
        // the constants fold (K is a type's).
        let (mut sum, mut sxy) = ([0.0f32; 3], [0.0f32; 3]);
        let mut i = self.head;
        for j in 0..K {
            let dx = j as f32 - Self::MEAN_X;
            let Some(s) = self.ring.get(i) else { break };
            for a in 0..3 {
                sum[a] += s[a];
                sxy[a] += dx * s[a];
            }
            i = if i + 1 >= K { 0 } else { i + 1 };
        }
        Some(core::array::from_fn(|a| {
            sum[a] * Self::INV_K + sxy[a] * Self::INV_SXX * (Self::END + ahead[a])
        }))
    }

    /// x̄ of the fit's abscissae 0 … K − 1.
    const MEAN_X: f32 = (K as f32 - 1.0) / 2.0;
    /// The newest sample's abscissa less x̄.
    const END: f32 = K as f32 - 1.0 - Self::MEAN_X;
    /// 1/K.
    const INV_K: f32 = 1.0 / K as f32;
    /// 1/Sxx (0 for K < 2: no slope).
    const INV_SXX: f32 = if K < 2 {
        0.0
    } else {
        12.0 / (K as f32 * (K as f32 * K as f32 - 1.0))
    };

    /// The predicted rate's white noise against one sample's, read
    /// `ahead` periods after the newest: √(1/K + (x − x̄)²/Sxx).
    pub fn noise_gain(ahead: f32) -> f32 {
        if K < 2 {
            return 1.0;
        }
        let d = Self::END + ahead;
        libm::sqrtf(Self::INV_K + d * d * Self::INV_SXX)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ramp_is_predicted_exactly() {
        let mut p = Predictor::<8>::new();
        assert_eq!(p.at([0.0; 3]), None);
        for k in 0..20 {
            let t = k as f32 * 0.001;
            p.push([100.0 * t, -3.0, 5.0 + 40.0 * t]);
        }
        // 2.1 periods ahead on x and z, none on y.
        let g = p.at([2.1, 0.0, 2.1]).unwrap();
        let t = 0.019 + 0.0021;
        assert!((g[0] - 100.0 * t).abs() < 1e-4, "{g:?}");
        assert!((g[1] + 3.0).abs() < 1e-5);
        assert!((g[2] - (5.0 + 40.0 * t)).abs() < 1e-4);
    }

    #[test]
    fn noise_gain_is_the_fits_spread() {
        // The gain against the empirical spread of predictions of white
        // noise.
        let mut p = Predictor::<3>::new();
        let mut x: u32 = 7;
        let (mut n, mut ss) = (0.0f64, 0.0f64);
        for _ in 0..200_000 {
            // Uniform on (−√3, √3): unit variance.
            x = x.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let u = (x >> 8) as f32 / (1u32 << 24) as f32;
            p.push([(2.0 * u - 1.0) * 3f32.sqrt(), 0.0, 0.0]);
            if let Some(v) = p.at([2.136, 0.0, 0.0]) {
                n += 1.0;
                ss += f64::from(v[0]) * f64::from(v[0]);
            }
        }
        let got = (ss / n).sqrt() as f32;
        let want = Predictor::<3>::noise_gain(2.136);
        assert!((got - want).abs() < 0.02 * want, "{got} vs {want}");
        // One sample: no prediction, the newest as it is.
        let mut one = Predictor::<1>::new();
        one.push([1.0, 2.0, 3.0]);
        assert_eq!(one.at([5.0; 3]), Some([1.0, 2.0, 3.0]));
        assert_eq!(Predictor::<1>::noise_gain(5.0), 1.0);
    }
}
