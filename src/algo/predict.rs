//! Delay compensation: the fused rate predicted forward to a stated
//! instant from its recent samples.
//!
//! The fused rate describes an instant some 2 ms before the antenna gets
//! it (the chips' filters, the alignment, the link); on a vehicle's motion
//! every millisecond of it is pointing error (`algo::pointing`). The
//! predictor fits a straight line, by least squares, to the last `K`
//! samples of each axis (1 ms apart) and reads it `h` ahead of the newest:
//! a fixed FIR, ŷ = Σ w_j y_j, its weights worked out once for the horizon
//! (K multiply-adds an axis a sample). It is exact for a rate that changes
//! linearly; on a curve it leaves (K/2 + h)·h/2·ÿ, and it passes white
//! noise with the gain √Σw² ([`Predictor::noise_gain`]), so K trades the
//! curve's error against the noise's (`pointing-eval` picks it).

/// One axis-triple's predictor over the last `K` samples.
#[derive(Clone, Copy, Debug)]
pub struct Predictor<const K: usize> {
    ring: [[f32; 3]; K],
    len: usize,
    head: usize,
    /// Weights, oldest sample first.
    w: [f32; K],
    horizon_s: f32,
}

impl<const K: usize> Predictor<K> {
    /// A predictor `horizon_s` ahead of the newest of samples `period_s`
    /// apart (K ≥ 2; K = 1 gives the newest sample, no prediction).
    pub fn new(horizon_s: f32, period_s: f32) -> Self {
        let mut p = Self {
            ring: [[0.0; 3]; K],
            len: 0,
            head: 0,
            w: [0.0; K],
            horizon_s,
        };
        p.set_horizon(horizon_s, period_s);
        p
    }

    /// The horizon, s.
    pub fn horizon_s(&self) -> f32 {
        self.horizon_s
    }

    /// Set the horizon (a command, or the link's delay changed).
    pub fn set_horizon(&mut self, horizon_s: f32, period_s: f32) {
        self.horizon_s = horizon_s;
        if K < 2 || period_s <= 0.0 {
            self.w = [0.0; K];
            if let Some(last) = self.w.last_mut() {
                *last = 1.0;
            }
            return;
        }
        // x_j = j (j = 0 the oldest), the line read at x = K − 1 + h/T:
        // w_j = 1/K + (x_j − x̄)(x − x̄)/Sxx.
        let k = K as f32;
        let mean = (k - 1.0) / 2.0;
        let sxx = k * (k * k - 1.0) / 12.0;
        let x = k - 1.0 + horizon_s / period_s;
        for (j, w) in self.w.iter_mut().enumerate() {
            *w = 1.0 / k + (j as f32 - mean) * (x - mean) / sxx;
        }
    }

    /// √Σw²: the predicted rate's white noise against one sample's.
    pub fn noise_gain(&self) -> f32 {
        libm::sqrtf(self.w.iter().map(|w| w * w).sum())
    }

    /// Forget the samples (a gap: an axis without a fused value).
    pub fn clear(&mut self) {
        self.len = 0;
        self.head = 0;
    }

    /// Whether it has the `K` samples a prediction needs.
    pub fn ready(&self) -> bool {
        self.len == K
    }

    /// One sample per axis; the prediction once `K` are held, else `None`.
    pub fn push(&mut self, y: [f32; 3]) -> Option<[f32; 3]> {
        if K == 0 {
            return None;
        }
        let mut j = self.head + self.len;
        if j >= K {
            j -= K;
        }
        self.ring[j] = y;
        if self.len < K {
            self.len += 1;
            if self.len < K {
                return None;
            }
        } else {
            self.head = if self.head + 1 >= K { 0 } else { self.head + 1 };
        }
        let mut out = [0.0f32; 3];
        let mut i = self.head;
        for w in &self.w {
            let s = &self.ring[i];
            out[0] += w * s[0];
            out[1] += w * s[1];
            out[2] += w * s[2];
            i = if i + 1 >= K { 0 } else { i + 1 };
        }
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ramp_is_predicted_exactly_and_the_weights_sum_to_one() {
        let mut p = Predictor::<8>::new(0.0021, 0.001);
        assert!((p.w.iter().sum::<f32>() - 1.0).abs() < 1e-5);
        let mut got = None;
        for k in 0..20 {
            let t = k as f32 * 0.001;
            got = p.push([100.0 * t, -3.0, 5.0 + 40.0 * t]);
        }
        let t = 19.0 * 0.001 + 0.0021;
        let g = got.unwrap();
        assert!((g[0] - 100.0 * t).abs() < 1e-4, "{g:?}");
        assert!((g[1] + 3.0).abs() < 1e-5);
        assert!((g[2] - (5.0 + 40.0 * t)).abs() < 1e-4);
    }

    #[test]
    fn noise_gain_is_the_fits_variance() {
        // The least-squares line's variance at x: 1/K + (x − x̄)²/Sxx.
        let p = Predictor::<8>::new(0.002, 0.001);
        let x = 7.0 + 2.0;
        let want = (1.0 / 8.0 + (x - 3.5f32).powi(2) / 42.0).sqrt();
        assert!((p.noise_gain() - want).abs() < 1e-5);
        // One sample, no prediction: the newest as it is.
        let mut one = Predictor::<1>::new(0.002, 0.001);
        assert_eq!(one.push([1.0, 2.0, 3.0]), Some([1.0, 2.0, 3.0]));
    }
}
