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
//! The longest stretch with neither is offered for the analysis
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
    /// The longest stretch without a step or motion, [start, end) samples.
    pub quiet: (usize, usize),
}

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
    let block = ((1.0 / tau0).round() as usize).clamp(10, (m / 50).max(10));
    s.block = block;
    let means: Vec<f64> = body
        .chunks_exact(block)
        .map(|c| c.iter().sum::<f64>() / block as f64)
        .collect();
    let mut d: Vec<f64> = body.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
    // Median |Δ| of white noise σ: σ√2 · 0.6745.
    let sigma = median(&mut d) / (0.6745 * 2f64.sqrt());
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
        // The last block's tail belongs to the stretch that ends there.
        let end = if best.1 == means.len() { m } else { b1 };
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
