//! A rate log checked before its noise is believed: a chip's start-up "no
//! data" samples, steps, and motion.
//!
//! - **Start-up value.** Before its first conversion a gyro reads a fixed
//!   code (the ICM-42688-P's data registers read −32 768, −250 °/s at
//!   ±250 °/s, for the first samples after power-up). A leading run of one
//!   repeated value, far from the rest of the log, is that; those samples
//!   are left out, and the same value anywhere later is refused (a chip
//!   that stopped converting mid-log).
//! - **Steps and motion.** The log is cut in blocks (one second, at least
//!   10 samples, at most 1/50 of the log) and the means of neighbouring
//!   blocks compared. At rest they differ by the noise at that τ: white
//!   noise (σ from the median sample-to-sample change) gives σ√(2/B), and
//!   a MEMS bias wanders by about as much again at a second. A difference
//!   over ten times the larger of that and the differences' own median
//!   scale is a step; the log moves when the typical difference itself
//!   is ten times the white noise's.
//!
//! - **Spikes.** A sample over twenty times the white noise (or the
//!   quantisation step, where that is larger) from both its neighbours,
//!   the same way: a bit error or a shock, not noise (a Gaussian sample
//!   that far out comes once in 10⁸⁸). Named with its place and value, and
//!   left out of the block means, so that it does not read as a step.
//! - **A constant column.** Every sample one value: a stuck or saturated
//!   sensor, or a setting logged as a rate; it has no noise to analyse.
//!
//! The longest stretch with none of these is offered for the analysis
//! (`gyro allan --static`).

/// What the check found in one column.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Screen {
    /// Leading samples at a repeated start-up value (left out).
    pub startup: usize,
    /// That value, if any.
    pub startup_value: Option<f64>,
    /// The same value later in the log (a chip that stopped converting).
    pub no_data_later: usize,
    /// Block length, samples.
    pub block: usize,
    /// Steps: (sample index, size in the rate's unit).
    pub steps: Vec<(usize, f64)>,
    /// The log moves: neighbouring blocks differ typically by over ten
    /// times what white noise alone gives.
    pub moving: bool,
    /// The longest stretch without a step, motion or spike, [start, end)
    /// samples.
    pub quiet: (usize, usize),
    /// Spikes: (sample index, value), the first [`SPIKES_LISTED`].
    pub spikes: Vec<(usize, f64)>,
    /// How many spikes in all.
    pub spike_count: usize,
    /// Every sample (after any start-up run) reads this value.
    pub constant: Option<f64>,
}

/// Spikes listed by place; the rest are counted.
pub const SPIKES_LISTED: usize = 10;

/// A spike is this many times the white noise (or the quantisation step)
/// from both neighbours.
pub const SPIKE_SIGMAS: f64 = 20.0;

impl Screen {
    /// Nothing found: the log can be analysed as a static record.
    pub fn is_static(&self) -> bool {
        !self.moving && self.steps.is_empty() && self.no_data_later == 0
    }
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
    *m
}

/// Check one column sampled every `tau0` s.
pub fn screen(rate: &[f64], tau0: f64) -> Screen {
    let mut s = Screen::default();
    let n = rate.len();
    if n < 20 {
        s.quiet = (0, n);
        return s;
    }
    // A leading run of one value, far from the rest (ten robust σ).
    let lead = rate.iter().take_while(|&&v| v == rate[0]).count();
    if lead >= 2 && lead < n / 2 {
        let mut rest: Vec<f64> = rate[lead..].to_vec();
        let med = median(&mut rest);
        let mut dev: Vec<f64> = rate[lead..].iter().map(|v| (v - med).abs()).collect();
        let mad = median(&mut dev) / 0.6745;
        if (rate[0] - med).abs() > 10.0 * mad.max(f64::MIN_POSITIVE) {
            s.startup = lead;
            s.startup_value = Some(rate[0]);
            s.no_data_later = rate[lead..].iter().filter(|&&v| v == rate[0]).count();
        }
    }
    let body = &rate[s.startup..];
    let m = body.len();
    if body.iter().all(|&v| v == body[0]) {
        s.constant = Some(body[0]);
        s.quiet = (s.startup, n);
        return s;
    }
    let block = ((1.0 / tau0).round() as usize).clamp(10, (m / 50).max(10));
    s.block = block;
    let mut d: Vec<f64> = body.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
    // The quantisation step: the smallest change there is.
    let q = d
        .iter()
        .copied()
        .filter(|&v| v > 0.0)
        .fold(f64::INFINITY, f64::min);
    // Median |Δ| of white noise σ: σ√2 · 0.6745.
    let sigma = median(&mut d) / (0.6745 * 2f64.sqrt());
    // Spikes: far from both neighbours, the same way. The block means
    // take the mean of the neighbours in their place.
    let far = SPIKE_SIGMAS * sigma.max(q);
    let mut spiked: Vec<usize> = Vec::new();
    for i in 1..m.saturating_sub(1) {
        let (a, b) = (body[i] - body[i - 1], body[i] - body[i + 1]);
        if a.abs() > far && b.abs() > far && (a > 0.0) == (b > 0.0) {
            spiked.push(i);
        }
    }
    s.spike_count = spiked.len();
    s.spikes = spiked
        .iter()
        .take(SPIKES_LISTED)
        .map(|&i| (s.startup + i, body[i]))
        .collect();
    let cleaned: Vec<f64>;
    let smooth = if spiked.is_empty() {
        body
    } else {
        let mut c = body.to_vec();
        for &i in &spiked {
            c[i] = 0.5 * (body[i - 1] + body[i + 1]);
        }
        cleaned = c;
        &cleaned
    };
    let means: Vec<f64> = smooth
        .chunks_exact(block)
        .map(|c| c.iter().sum::<f64>() / block as f64)
        .collect();
    let white = sigma * (2.0 / block as f64).sqrt();
    let diffs: Vec<f64> = means.windows(2).map(|w| w[1] - w[0]).collect();
    let mut abs: Vec<f64> = diffs.iter().map(|v| v.abs()).collect();
    let typical = median(&mut abs) / 0.6745;
    s.moving = diffs.len() >= 4 && typical > 10.0 * white;
    let limit = 10.0 * typical.max(2.0 * white);
    let mut cut = vec![false; diffs.len()];
    for (k, &dv) in diffs.iter().enumerate() {
        if dv.abs() > limit || (s.moving && dv.abs() > 10.0 * white) {
            cut[k] = true;
            if !s.moving {
                // A step inside a block shows in the two differences
                // around it: one step, at the first.
                match s.steps.last_mut() {
                    Some(last) if k > 0 && cut[k - 1] => last.1 += dv,
                    _ => s.steps.push((s.startup + (k + 1) * block, dv)),
                }
            }
        }
    }
    // A block with a spike is cut from both neighbours (after the steps:
    // it is not one).
    for &i in &spiked {
        let k = i / block;
        for j in [k.wrapping_sub(1), k] {
            if let Some(c) = cut.get_mut(j) {
                *c = true;
            }
        }
    }
    // The longest run of blocks with no cut between them.
    let (mut best, mut start) = ((0usize, 0usize), 0usize);
    for k in 0..=diffs.len() {
        if cut.get(k).is_none_or(|&c| c) {
            if k + 1 - start > best.1 - best.0 {
                best = (start, k + 1);
            }
            start = k + 1;
        }
    }
    let (b0, b1) = (best.0 * block, (best.1 * block).min(m));
    s.quiet = if diffs.is_empty() {
        (s.startup, n)
    } else {
        // The last block's tail belongs to the stretch that ends there,
        // unless a spike is in it.
        let tail_spike = spiked.iter().any(|&i| i >= means.len() * block);
        let end = if best.1 == means.len() && !tail_spike {
            m
        } else {
            b1
        };
        (s.startup + b0, s.startup + end)
    };
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noise(n: usize, sigma: f64, seed: u64) -> Vec<f64> {
        let mut rng = gyro_sim::Rng::new(seed);
        (0..n).map(|_| sigma * f64::from(rng.gaussian())).collect()
    }

    #[test]
    fn a_quiet_log_is_static() {
        let s = screen(&noise(100_000, 0.05, 1), 0.001);
        assert!(s.is_static(), "{s:?}");
        assert_eq!(s.quiet, (0, 100_000));
        assert_eq!(s.startup, 0);
    }

    /// The ICM-42688-P's first 32 samples at −32 768 counts (−250 °/s at
    /// ±250 °/s): left out, and counted.
    #[test]
    fn the_start_up_value_is_left_out() {
        let mut y = noise(20_000, 0.05, 2);
        for v in y.iter_mut().take(32) {
            *v = -250.0;
        }
        let s = screen(&y, 0.001);
        assert_eq!(s.startup, 32);
        assert_eq!(s.startup_value, Some(-250.0));
        assert!(s.is_static(), "{s:?}");
        assert_eq!(s.quiet.0, 32);
    }

    #[test]
    fn a_step_is_found_where_it_is() {
        let mut y = noise(60_000, 0.05, 3);
        for v in y.iter_mut().skip(40_000) {
            *v += 0.5;
        }
        let s = screen(&y, 0.001);
        assert_eq!(s.steps.len(), 1, "{s:?}");
        assert!((s.steps[0].0 as i64 - 40_000).abs() <= 1000, "{s:?}");
        assert!(!s.is_static());
        assert_eq!(s.quiet, (0, 40_000));
    }

    /// A bit error's sample, far from both neighbours, is a spike: named
    /// with its place, left out of the quiet stretch, and no step.
    #[test]
    fn a_spike_is_named_and_is_not_a_step() {
        let mut y = noise(60_000, 0.05, 6);
        y[30_500] = 1.0e6;
        y[45_001] = -40.0;
        let s = screen(&y, 0.001);
        assert_eq!(s.spike_count, 2, "{s:?}");
        assert_eq!(s.spikes, vec![(30_500, 1.0e6), (45_001, -40.0)]);
        assert!(s.steps.is_empty() && !s.moving, "{s:?}");
        assert!(s.is_static());
        // Blocks of 1 000: the longest stretch without a spike's block.
        assert_eq!(s.quiet, (0, 30_000));
        // In the tail after the last whole block: the stretch ends before it.
        let mut y = noise(60_500, 0.05, 9);
        y[60_400] = 5.0;
        let s = screen(&y, 0.001);
        assert_eq!(s.spikes, vec![(60_400, 5.0)]);
        assert_eq!(s.quiet, (0, 60_000));
    }

    /// Quantised noise (most steps 0 or one LSB) has no spikes: the
    /// threshold is twenty LSB where the noise's median step is smaller.
    #[test]
    fn quantised_noise_has_no_spikes() {
        let y: Vec<f64> = noise(50_000, 0.05, 7)
            .iter()
            .map(|v| (v / 0.1).round() * 0.1)
            .collect();
        let s = screen(&y, 0.01);
        assert_eq!(s.spike_count, 0, "{s:?}");
        assert!(s.constant.is_none());
    }

    /// A column of one value is constant, start-up run or not.
    #[test]
    fn a_stuck_column_is_constant() {
        assert_eq!(screen(&[2.5; 1000], 0.001).constant, Some(2.5));
        assert_eq!(screen(&noise(1000, 0.05, 8), 0.001).constant, None);
    }

    /// A car's yaw: a few °/s at 0.3 Hz over the noise.
    #[test]
    fn motion_is_found() {
        let y: Vec<f64> = noise(30_000, 0.05, 4)
            .iter()
            .enumerate()
            .map(|(i, v)| v + 3.0 * (2.0 * std::f64::consts::PI * 0.3 * i as f64 * 0.001).sin())
            .collect();
        let s = screen(&y, 0.001);
        assert!(s.moving && !s.is_static(), "{s:?}");
    }

    /// A random walk and flicker at the ICM-42688-P's levels over 4 h at
    /// 100 Hz are not called motion.
    #[test]
    fn a_wandering_bias_is_not_motion() {
        let p = gyro_sim::NoiseParams {
            rrw_deg_h_rt_h: 40.0,
            ..gyro_sim::NoiseParams::ICM42688
        };
        let mut rng = gyro_sim::Rng::new(5);
        let mut axis = gyro_sim::noise::AxisNoise::default();
        let y: Vec<f64> = (0..1_440_000)
            .map(|_| f64::from(axis.step(&p, &mut rng, 0.0, 0.01)))
            .collect();
        let s = screen(&y, 0.01);
        assert!(s.is_static(), "{s:?}");
    }
}
