//! The IEEE Std 952 gyro noise model fitted to an Allan variance curve by
//! weighted least squares:
//!
//! σ²(τ) = 3Q²/τ² + N²/τ + (2 ln 2/π)B² + K²τ/3 + R²τ²/2
//!
//! (Q quantisation, N angle random walk, B bias instability, K rate random
//! walk, R rate ramp). The model is linear in the five squared terms; each
//! point is weighted by 1/Var(σ²) = EDF/(2σ⁴) with the EDF of the
//! overlapping estimator for white noise (SP 1065), points from fewer
//! than `MIN_CLUSTERS` clusters left out, and the non-negative solution
//! found exactly (every subset of the five terms, the feasible one with the
//! least weighted residual). Each term carries its standard error from the
//! fit's covariance, and what an IEEE 952 tangent reading gives next to it.

use crate::dev::Point;

/// Points averaging fewer clusters than this are left out of the fit
/// (their σ² has a few degrees of freedom: a handful of them decided K
/// on 4 h logs, off by −14 to +150 %).
pub use crate::dev::MIN_CLUSTERS;
/// Points of at least this many clusters go into the fit, weighted by
/// their EDF (16 read K 6 % lower on average on 4 h of the emulated
/// ICM-42688-P; its longest τ carry K).
const FIT_CLUSTERS: usize = 8;

/// The model's terms, in the curve's rate unit (°/s below): Q in °, N in
/// °/s·√s (= °/√s, ×60 for °/√h), B in °/s, K in °/s/√s, R in °/s².
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct Terms {
    /// Values (0 where the term is not in the fit).
    pub value: [f64; 5],
    /// Standard errors (NaN for a term fixed at 0).
    pub sd: [f64; 5],
    /// Points used.
    pub points: usize,
    /// IEEE 952 tangent readings: each term where its own asymptote
    /// touches the curve from below (the least value it could have), over
    /// the same points. An upper bound for each term, not an estimate.
    pub tangent: [f64; 5],
    /// The term is visible in the curve: it carries at least half of the
    /// fitted σ² at some fitted τ, and its value is more than twice its
    /// standard error. A term that is not is an upper bound at best.
    pub visible: [bool; 5],
}

fn basis(tau: f64) -> [f64; 5] {
    [
        3.0 / (tau * tau),
        1.0 / tau,
        2.0 * std::f64::consts::LN_2 / std::f64::consts::PI,
        tau / 3.0,
        tau * tau / 2.0,
    ]
}

/// EDF of an overlapping Allan variance at factor m over n phase points,
/// white FM (SP 1065's simple form, `gyro_array::algo::allan::edf`), at
/// least 1.
fn edf_oadev(n: usize, m: usize) -> f64 {
    use gyro_array::algo::allan::{edf, NoiseType};
    edf(NoiseType::WhiteFm, n as u64, m as u64).map_or(1.0, |e| e.max(1.0))
}

/// Solve the weighted normal equations on the terms in `mask`; None if
/// singular.
/// A weighted fit on a subset of the terms: solution, (XᵀWX)⁻¹ and the
/// weighted residual sum of squares.
type Solved = ([f64; 5], [[f64; 5]; 5], f64);

fn solve(rows: &[([f64; 5], f64, f64)], mask: u8) -> Option<Solved> {
    use nalgebra::{Matrix5, Vector5};
    let on = |i: usize| mask & (1 << i) != 0;
    let (mut a, mut b) = (Matrix5::<f64>::zeros(), Vector5::<f64>::zeros());
    for (x, y, w) in rows {
        for i in (0..5).filter(|&i| on(i)) {
            b[i] += w * x[i] * y;
            for j in (0..5).filter(|&j| on(j)) {
                a[(i, j)] += w * x[i] * x[j];
            }
        }
    }
    // Scaled to unit diagonal (the basis spans many decades), the terms
    // left out as identity rows, then a Cholesky factor: the normal matrix
    // is symmetric and, unless the subset is degenerate, positive definite.
    let mut d = Vector5::<f64>::repeat(1.0);
    for i in (0..5).filter(|&i| on(i)) {
        d[i] = a[(i, i)].sqrt();
        if !(d[i].is_finite() && d[i] > 0.0) {
            return None;
        }
    }
    let mut m = Matrix5::<f64>::identity();
    for i in (0..5).filter(|&i| on(i)) {
        for j in (0..5).filter(|&j| on(j)) {
            m[(i, j)] = a[(i, j)] / (d[i] * d[j]);
        }
    }
    let chol = nalgebra::Cholesky::new(m)?;
    // A pivot this small: the terms are collinear over these τ.
    if chol.l_dirty().diagonal().iter().any(|&l| l * l < 1e-13) {
        return None;
    }
    let scaled = chol.inverse();
    let mut inv = [[0.0; 5]; 5];
    let mut sol = [0.0; 5];
    for i in (0..5).filter(|&i| on(i)) {
        for j in (0..5).filter(|&j| on(j)) {
            inv[i][j] = scaled[(i, j)] / (d[i] * d[j]);
        }
    }
    for i in (0..5).filter(|&i| on(i)) {
        sol[i] = (0..5).filter(|&j| on(j)).map(|j| inv[i][j] * b[j]).sum();
    }
    let rss = rows
        .iter()
        .map(|(x, y, w)| {
            let f: f64 = (0..5).map(|i| x[i] * sol[i]).sum();
            w * (y - f) * (y - f)
        })
        .sum();
    Some((sol, inv, rss))
}

/// Every subset of the terms: the feasible (all ≥ 0) fit with the least
/// weighted residual, and its mask.
fn best_subset(rows: &[([f64; 5], f64, f64)]) -> Option<(Solved, u8)> {
    let mut best: Option<(Solved, u8)> = None;
    for mask in 1u8..32 {
        if mask.count_ones() as usize > rows.len() {
            continue;
        }
        let Some(solved) = solve(rows, mask) else {
            continue;
        };
        let feasible = (0..5).all(|i| mask & (1 << i) == 0 || solved.0[i] >= 0.0);
        if feasible && best.as_ref().is_none_or(|b| solved.2 < b.0 .2) {
            best = Some((solved, mask));
        }
    }
    best
}

/// Why [`fit_phase`] has no fit.
#[derive(Debug)]
pub enum FitError {
    /// The OADEV curve could not be made (too short, not finite, …).
    Curve(crate::dev::DevError),
    /// Fewer than two of the curve's points average enough clusters.
    TooFewPoints,
}

impl core::fmt::Display for FitError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            FitError::Curve(e) => e.fmt(f),
            FitError::TooFewPoints => write!(
                f,
                "too few points of at least {FIT_CLUSTERS} clusters to fit (two needed)"
            ),
        }
    }
}

impl std::error::Error for FitError {}

/// The model fitted to phase `x` (τ0 `tau0`) as `gyro allan --fit` and
/// the Python package's `noise_fit` do it: on its OADEV at 8 points a
/// decade.
pub fn fit_phase(x: &[f64], tau0: f64) -> Result<Terms, FitError> {
    let c = crate::dev::curve(
        crate::dev::Kind::Oadev,
        x,
        tau0,
        crate::dev::Grid::PerDecade(8),
    )
    .map_err(FitError::Curve)?;
    fit(&c, x.len()).ok_or(FitError::TooFewPoints)
}

/// Fit the model to an overlapping Allan deviation curve of `n` phase
/// points (rate samples + 1). None if fewer than two usable points.
///
/// The weights are 1/Var(σ²) = EDF/(2σ⁴) with each point's own EDF
/// (Greenhall's, for its noise type; white FM's where it has none) and σ²
/// from the fitted model, refitted until the weights settle (iteratively
/// reweighted). Weights from the observed σ² favour the points that came
/// out low, and with the white-FM EDF everywhere the few-cluster points at
/// long τ weigh too much: together they read K 6 % low on average
/// (`noise_terms_of_the_emulated_icm42688`).
pub fn fit(curve: &[Point], n: usize) -> Option<Terms> {
    let pts: Vec<(&Point, f64)> = curve
        .iter()
        .filter(|p| n / p.m.max(1) >= FIT_CLUSTERS && p.dev > 0.0 && p.dev.is_finite())
        .map(|p| (p, p.edf.unwrap_or_else(|| edf_oadev(n, p.m)).max(1.0)))
        .collect();
    if pts.len() < 2 {
        return None;
    }
    let mut rows: Vec<([f64; 5], f64, f64)> = pts
        .iter()
        .map(|(p, e)| {
            let v = p.dev * p.dev;
            (basis(p.tau), v, e / (2.0 * v * v))
        })
        .collect();
    let mut best = best_subset(&rows)?;
    for _ in 0..4 {
        let sol = best.0 .0;
        for ((x, v, w), (_, e)) in rows.iter_mut().zip(&pts) {
            let model: f64 = (0..5).map(|k| x[k] * sol[k].max(0.0)).sum();
            let m = if model > 0.0 { model } else { *v };
            *w = e / (2.0 * m * m);
        }
        best = best_subset(&rows)?;
    }
    let ((sol, inv, rss), mask) = best;
    // Tangent readings: min over τ of the term that σ(τ) alone would need.
    let mut tangent = [f64::INFINITY; 5];
    for (x, v, _) in &rows {
        for (t, b) in tangent.iter_mut().zip(x) {
            *t = t.min((v / b).sqrt());
        }
    }
    let dof = (rows.len() as f64 - mask.count_ones() as f64).max(1.0);
    // Residual variance factor (χ²/dof), at least 1: the weights are
    // approximate.
    let s2 = (rss / dof).max(1.0);
    let mut t = Terms {
        points: rows.len(),
        tangent,
        ..Terms::default()
    };
    for i in 0..5 {
        if mask & (1 << i) == 0 {
            t.sd[i] = f64::NAN;
            continue;
        }
        let c = sol[i].max(0.0);
        t.value[i] = c.sqrt();
        // sd of √c from sd of c: sd/(2√c).
        let sdc = (inv[i][i] * s2).sqrt();
        t.sd[i] = if c > 0.0 {
            sdc / (2.0 * c.sqrt())
        } else {
            sdc.sqrt()
        };
    }
    for (i, vis) in t.visible.iter_mut().enumerate() {
        // Judged on the points of at least MIN_CLUSTERS clusters: the
        // longest τ also weigh in the fit, but a term that only they carry
        // (a rate ramp out of a few clusters) is not seen.
        let solid = rows
            .iter()
            .zip(&pts)
            .filter(|(_, (p, _))| n / p.m.max(1) >= MIN_CLUSTERS);
        let dominant = solid.map(|(r, _)| r).any(|(x, _, _)| {
            let model: f64 = (0..5).map(|k| x[k] * sol[k].max(0.0)).sum();
            model > 0.0 && x[i] * sol[i].max(0.0) >= 0.5 * model
        });
        *vis = mask & (1 << i) != 0 && dominant && t.value[i] > 2.0 * t.sd[i];
    }
    Some(t)
}

/// A Kalibr `imu.yaml` for the gyro terms (rad/s/√Hz and rad/s²/√Hz from
/// N and K in °/s·√s and °/s/√s); the accelerometer fields are not known
/// here and are left out, with a comment.
pub fn kalibr_yaml(t: &Terms, rate_hz: f64, topic: &str) -> String {
    let rad = std::f64::consts::PI / 180.0;
    format!(
        "# gyro allan --fit: IEEE 952 model fitted by weighted least squares\n\
         # N = {:.6e} deg/s/sqrt(Hz) +- {:.2e}, K = {:.6e} deg/s^2/sqrt(Hz) +- {:.2e}\n\
         # accelerometer_* fields: not measured by this tool, add your own\n\
         rostopic: {topic}\n\
         update_rate: {rate_hz:.6}\n\
         gyroscope_noise_density: {:.9e}  # rad/s/sqrt(Hz)\n\
         gyroscope_random_walk: {:.9e}  # rad/s^2/sqrt(Hz)\n",
        t.value[1],
        t.sd[1],
        t.value[3],
        t.sd[3],
        t.value[1] * rad,
        t.value[3] * rad,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dev::{curve, phase_from_rate, Grid, Kind};

    /// Two hours at 100 Hz of white rate noise (N) plus a rate random walk
    /// (K), generated here: the fit finds N within 2 % and K within 25 %,
    /// and leaves B, Q, R near 0.
    #[test]
    fn fit_recovers_arw_and_rrw_of_a_generated_log() {
        let (fs, secs) = (100.0f64, 7200.0f64);
        let n = (fs * secs) as usize;
        let (n_true, k_true) = (0.005f64, 2e-4f64); // °/s·√s, °/s/√s
        let mut rng = gyro_array::emu::Rng::new(17);
        let dt = 1.0 / fs;
        let mut walk = 0.0f64;
        let rate: Vec<f64> = (0..n)
            .map(|_| {
                walk += k_true * dt.sqrt() * f64::from(rng.gaussian());
                walk + n_true / dt.sqrt() * f64::from(rng.gaussian())
            })
            .collect();
        let x = phase_from_rate(&rate, dt).unwrap();
        let c = curve(Kind::Oadev, &x, dt, Grid::PerDecade(8)).unwrap();
        let t = fit(&c, x.len()).unwrap();
        println!("fit: {:?} sd {:?} over {} points", t.value, t.sd, t.points);
        assert!((t.value[1] / n_true - 1.0).abs() < 0.02, "N {}", t.value[1]);
        assert!((t.value[3] / k_true - 1.0).abs() < 0.25, "K {}", t.value[3]);
        assert!(t.value[2] < 0.2 * n_true, "B {}", t.value[2]);
        let y = kalibr_yaml(&t, fs, "/imu0");
        assert!(y.contains("gyroscope_noise_density") && y.contains("update_rate: 100.000000"));
    }

    /// Four hours at 100 Hz of the emulated ICM-42688-P (`emu::noise`) of
    /// `p` from seed `seed`, at rest: its OADEV fit.
    fn fit_emulated(p: &gyro_array::emu::NoiseParams, seed: u64) -> Terms {
        let (fs, secs) = (100.0f32, 4.0 * 3600.0f32);
        let dt = 1.0 / fs;
        let mut rng = gyro_array::emu::Rng::new(seed);
        let mut axis = gyro_array::emu::noise::AxisNoise::default();
        let rate: Vec<f64> = (0..(fs * secs) as usize)
            .map(|_| f64::from(axis.step(p, &mut rng, 0.0, dt)))
            .collect();
        let x = phase_from_rate(&rate, f64::from(dt)).unwrap();
        let c = curve(Kind::Oadev, &x, f64::from(dt), Grid::PerDecade(8)).unwrap();
        fit(&c, x.len()).unwrap()
    }

    /// The noise terms of 4 h of the emulated ICM-42688-P with all three
    /// of N, B and K visible in its model (0.168 °/√h; 5 °/h flicker; a
    /// rate random walk of 40 °/h/√h, which crosses the floor at 74 s),
    /// over five seeds: N within 2 %, B within 10 %, K within 10 %, each
    /// flagged visible, and Q and R not. With the datasheet's 2 °/h/√h (it
    /// would cross the floor at 8 h), K is not flagged visible.
    /// `cargo test -p gyro-tool --profile host noise_terms -- --nocapture`
    /// prints the table.
    #[test]
    fn noise_terms_of_the_emulated_icm42688() {
        use gyro_array::emu::NoiseParams;
        let p = NoiseParams {
            bias_tau_s: 0.0,
            rrw_deg_h_rt_h: 40.0,
            ..NoiseParams::ICM42688
        };
        let truth = [
            f64::from(p.arw_deg_rt_h),
            f64::from(p.bias_instability_deg_h),
            f64::from(p.rrw_deg_h_rt_h),
        ];
        // °/s·√s → °/√h, °/s → °/h, °/s/√s → °/h/√h.
        let unit = [60.0, 3600.0, 3600.0 * 60.0];
        println!("seed   N (deg/rt h)      B (deg/h)   K (deg/h/rt h)   visible Q N B K R");
        // SEEDS=20 runs more seeds (printed and summarised; the assertions
        // hold for the first five).
        let last: u64 = std::env::var("SEEDS")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(5);
        let mut k_err = Vec::new();
        for seed in 1..=last.max(5) {
            let t = fit_emulated(&p, seed);
            let v: Vec<f64> = (0..3).map(|k| t.value[k + 1] * unit[k]).collect();
            let err: Vec<f64> = (0..3).map(|k| v[k] / truth[k] - 1.0).collect();
            println!(
                "{seed:>4} {:>8.4} ({:+.1} %) {:>6.3} ({:+.1} %) {:>7.2} ({:+.1} %)   {:?}",
                v[0],
                100.0 * err[0],
                v[1],
                100.0 * err[1],
                v[2],
                100.0 * err[2],
                t.visible
            );
            k_err.push(err[2]);
            if seed > 5 {
                continue;
            }
            assert!(err[0].abs() < 0.02, "seed {seed}: N {}", v[0]);
            assert!(err[1].abs() < 0.10, "seed {seed}: B {}", v[1]);
            assert!(err[2].abs() < 0.10, "seed {seed}: K {}", v[2]);
            assert_eq!(t.visible, [false, true, true, true, false], "seed {seed}");
        }
        let rms = (k_err.iter().map(|e| e * e).sum::<f64>() / k_err.len() as f64).sqrt();
        let within = k_err.iter().filter(|e| e.abs() < 0.1).count();
        println!(
            "K over {} seeds: RMS error {:.1} %, {within} within 10 %",
            k_err.len(),
            100.0 * rms
        );
        let stock = NoiseParams {
            bias_tau_s: 0.0,
            ..NoiseParams::ICM42688
        };
        let t = fit_emulated(&stock, 1);
        println!("K = 2 deg/h/rt h: visible {:?}", t.visible);
        assert!(!t.visible[3], "K of 2 is not visible in 4 h");
    }
}
