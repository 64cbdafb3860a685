//! A gyro's noise model fitted to its Allan variance curve.
//!
//! The model sums IEEE Std 952's five power-law terms (Q quantisation, N
//! angle random walk, B bias instability as flicker, K rate random walk,
//! R rate ramp) and up to two first-order Gauss–Markov processes (σ, τc),
//! the exponentially correlated bias MEMS parts show and the correlation
//! their output filters leave, each as the discrete process a sampled
//! gyro produces ([`model`]). It is fitted as the GMWM fits its latent
//! processes (Guerrier et al., "Wavelet-Variance-Based Estimation for
//! Composite Stochastic Processes", JASA 108, 2013): the squared
//! coefficients enter linearly and are found by non-negative least
//! squares, the correlation times by a search, and the weights are the
//! inverse of the estimates' covariance matrix ([`cov`]) under the fitted
//! model itself, refitted until it settles. That covariance gives each
//! point the degrees of freedom of the noise actually present at its τ
//! and takes the correlation between neighbouring τ into account, so no
//! stretch of the curve decides the fit by the number of its points.
//!
//! With those weights the residual χ² has a known distribution when the
//! model describes the curve: the goodness-of-fit test. A term is
//! *visible* only when the fit passes, the term is resolved (the fit
//! without it is worse by [`DCHI2_TERM`] in χ², [`DCHI2_GM`] for a
//! Gauss–Markov process) and it carries a tenth of the model somewhere on
//! the curve; a Gauss–Markov process also needs
//! its τc resolved inside the fitted τ (else it cannot be told from a rate
//! random walk or white noise).

mod cov;
mod kalibr;
mod model;
mod nnls;
mod report;

pub use kalibr::kalibr_yaml;
pub use model::{POWER, POWER_NAMES};

use crate::dev::Point;
use cov::{avar_cov, Spectrum};
use model::{gm_avar, power_avar, power_avar_at};
use nalgebra::{DMatrix, DVector};
pub use report::write_table;

/// Points averaging fewer clusters than this are left out of the fit:
/// their estimates are too far from Gaussian for a χ² test.
pub const FIT_CLUSTERS: usize = 8;
/// Points of at least this many clusters are "well resolved": the fitted
/// model must lie within their intervals for the fit to pass.
pub const SOLID_CLUSTERS: usize = 30;
/// At most this many Gauss–Markov processes.
pub const MAX_GM: usize = 2;
/// The fit passes when the χ² test's p-value is at least this.
pub const P_FIT: f64 = 0.01;
/// A power-law term is resolved when the fit without it has a χ² larger
/// by this much (4σ for one parameter).
pub const DCHI2_TERM: f64 = 16.0;
/// A Gauss–Markov process is resolved when the fit without it has a χ²
/// larger by this much: two parameters, and its τc the best of some 40
/// searched, so a 1e-3 chance over the search needs χ²₂ > 2 ln(40/1e-3).
pub const DCHI2_GM: f64 = 21.0;
/// A well-resolved point's interval leaves out this much on either side
/// (a 99.9 % interval).
const Z_TAIL: f64 = 0.0005;
/// Correlation times searched, per decade.
const GRID_PER_DECADE: f64 = 8.0;

/// A first-order Gauss–Markov process in the fitted model.
#[derive(Clone, Debug, serde::Serialize)]
pub struct GaussMarkov {
    /// Its standard deviation, in the curve's rate unit.
    pub sigma: f64,
    /// Its 95 % interval.
    pub sigma_ci: [f64; 2],
    /// Correlation time, s.
    pub tau_c_s: f64,
    /// Its 95 % interval.
    pub tau_c_ci: [f64; 2],
    /// Resolved and inside the fitted τ, in a fit that passes.
    pub visible: bool,
}

/// The fitted model, in the curve's rate unit (°/s below): Q in °, N in
/// °/s·√s (= °/√s, ×60 for °/√h), B in °/s, K in °/s/√s, R in °/s².
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Terms {
    /// The power-law terms (0 where the term is not in the fit).
    pub value: [f64; POWER],
    /// Standard errors of the values (NaN for a term at 0).
    pub sd: [f64; POWER],
    /// 95 % intervals ([0, upper] where the term may be 0).
    pub ci: [[f64; 2]; POWER],
    /// IEEE 952 tangent readings: each term where its own asymptote
    /// touches the curve from below, over the fitted points. An upper
    /// bound for each term, not an estimate.
    pub tangent: [f64; POWER],
    /// The term is visible (see the module's documentation).
    pub visible: [bool; POWER],
    /// Gauss–Markov processes, shortest τc first.
    pub gm: Vec<GaussMarkov>,
    /// Points used.
    pub points: usize,
    /// The weighted residual (generalised least squares, full covariance).
    pub chi2: f64,
    /// Its degrees of freedom: points less free parameters.
    pub dof: usize,
    /// P(χ² ≥ chi2) under the model.
    pub p_value: f64,
    /// Well-resolved points (at least [`SOLID_CLUSTERS`] clusters) whose
    /// 99.9 % interval misses the model.
    pub outside: usize,
    /// The goodness-of-fit verdict: p-value ≥ [`P_FIT`] and no
    /// well-resolved point outside.
    pub fits: bool,
    /// Bias instability as IEEE 952 reads it: the fitted model's flat
    /// region (its first minimum along τ) / 0.664, °/s; None where the
    /// model still falls at the longest τ.
    pub bias_instability: Option<f64>,
    /// Where that minimum lies, s.
    pub bias_instability_tau_s: Option<f64>,
    /// The angle random walk seen beyond the shortest correlation times,
    /// °/√s: N and every Gauss–Markov process of τc under 3 τ0 (a
    /// sensor's output filter correlates neighbouring samples; beyond τc
    /// such a process is white noise of N² = 2σ²τc). What a navigation
    /// filter takes as the noise density.
    pub arw: f64,
    /// Its 95 % interval.
    pub arw_ci: [f64; 2],
    /// Sample interval, s.
    pub tau0: f64,
    /// Points left out at the short end for the model to describe the
    /// rest (see [`fit`]); 0 when it describes every point.
    pub short_left_out: usize,
    /// The shortest τ fitted, s.
    pub tau_min_s: f64,
    /// The longest τ fitted, s. A Gauss–Markov process whose Allan peak
    /// (at 1.89 τc) lies beyond it is a rising slope here: the fit reads it
    /// as K (and a ramp R), which it cannot be told from.
    pub tau_max_s: f64,
}

impl Terms {
    /// The model's σ² at averaging factor m, term by term: the five
    /// power-law terms, then each Gauss–Markov process.
    pub fn parts(&self, m: f64) -> Vec<f64> {
        let p = power_avar_at(m, self.tau0);
        let mut v: Vec<f64> = (0..POWER)
            .map(|k| self.value[k] * self.value[k] * p[k])
            .collect();
        let mu = m.max(1.0).round() as usize;
        for g in &self.gm {
            v.push(g.sigma * g.sigma * gm_avar(mu, self.tau0, g.tau_c_s));
        }
        v
    }

    /// The model's σ² at τ.
    pub fn avar(&self, tau: f64) -> f64 {
        self.parts(tau / self.tau0).iter().sum()
    }
}

/// Why [`fit_phase`] has no fit.
#[derive(Debug)]
pub enum FitError {
    /// The OADEV curve could not be made (too short, not finite, …).
    Curve(crate::dev::DevError),
    /// Fewer than three of the curve's points average enough clusters.
    TooFewPoints,
}

impl core::fmt::Display for FitError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            FitError::Curve(e) => e.fmt(f),
            FitError::TooFewPoints => write!(
                f,
                "too few points of at least {FIT_CLUSTERS} clusters to fit (three needed)"
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

/// The fitted points, whitened: b = L⁻¹a and the power-law columns
/// L⁻¹X, with Σ = LLᵀ.
struct Whitened {
    chol: nalgebra::Cholesky<f64, nalgebra::Dyn>,
    b: DVector<f64>,
    power: Vec<DVector<f64>>,
}

struct Data {
    ms: Vec<usize>,
    taus: Vec<f64>,
    avar: Vec<f64>,
    tau0: f64,
    n: usize,
}

impl Data {
    fn gm_column(&self, tau_c: f64) -> DVector<f64> {
        DVector::from_iterator(
            self.ms.len(),
            self.ms.iter().map(|&m| gm_avar(m, self.tau0, tau_c)),
        )
    }
}

impl Whitened {
    fn new(d: &Data, sigma: &DMatrix<f64>) -> Option<Self> {
        let p = d.ms.len();
        // The quadrature leaves the matrix a hair from positive definite
        // where neighbouring τ correlate closely: a ridge of a millionth of
        // each variance, more only if the factor still fails.
        let chol = [1e-6, 1e-4, 1e-2].iter().find_map(|&ridge| {
            let mut s = sigma.clone();
            for i in 0..p {
                s[(i, i)] *= 1.0 + ridge;
            }
            nalgebra::Cholesky::new(s)
        })?;
        let a = DVector::from_column_slice(&d.avar);
        let b = chol.l().solve_lower_triangular(&a)?;
        let power = (0..POWER)
            .map(|k| {
                let col = DVector::from_iterator(p, d.ms.iter().map(|&m| power_avar(m, d.tau0)[k]));
                chol.l().solve_lower_triangular(&col)
            })
            .collect::<Option<Vec<_>>>()?;
        Some(Whitened { chol, b, power })
    }

    fn whiten(&self, col: &DVector<f64>) -> DVector<f64> {
        self.chol
            .l()
            .solve_lower_triangular(col)
            .unwrap_or_else(|| DVector::zeros(col.len()))
    }
}

/// One candidate model: amplitudes (power-law squared coefficients, then
/// Gauss–Markov variances), the correlation times, the residual.
#[derive(Clone, Debug)]
struct Candidate {
    theta: Vec<f64>,
    tau_c: Vec<f64>,
    chi2: f64,
}

impl Candidate {
    fn active(&self) -> usize {
        let amps = self.theta.iter().filter(|&&v| v > 0.0).count();
        let gms = self.theta[POWER..].iter().filter(|&&v| v > 0.0).count();
        amps + gms
    }
}

fn solve_with(w: &Whitened, gm_cols: &[DVector<f64>], tau_c: &[f64]) -> Candidate {
    solve_without(w, gm_cols, tau_c, None)
}

/// As [`solve_with`], with power-law term `drop` held at 0.
fn solve_without(
    w: &Whitened,
    gm_cols: &[DVector<f64>],
    tau_c: &[f64],
    drop: Option<usize>,
) -> Candidate {
    let zero = DVector::zeros(w.b.len());
    let cols: Vec<&DVector<f64>> = w
        .power
        .iter()
        .enumerate()
        .map(|(k, c)| if Some(k) == drop { &zero } else { c })
        .chain(gm_cols.iter())
        .collect();
    let k = cols.len();
    let g = DMatrix::from_fn(k, k, |i, j| cols[i].dot(cols[j]));
    let c = DVector::from_fn(k, |i, _| cols[i].dot(&w.b));
    let (x, chi2) = nnls::nnls(&g, &c, w.b.dot(&w.b));
    Candidate {
        theta: x.iter().copied().collect(),
        tau_c: tau_c.to_vec(),
        chi2,
    }
}

/// The shortest correlation time searched, in τ0: a process correlated
/// over less than two samples is white noise to every τ (collinear with N,
/// it left both unresolved on real records).
const TAU_C_MIN: f64 = 2.0;

/// The correlation-time grid: from 2 τ0 to three times the longest fitted τ.
fn tau_c_grid(d: &Data) -> Vec<f64> {
    let lo = TAU_C_MIN * d.tau0;
    let hi = 3.0 * d.taus.last().copied().unwrap_or(d.tau0);
    let n = ((hi / lo).log10() * GRID_PER_DECADE).ceil().max(1.0) as usize;
    (0..=n)
        .map(|i| lo * (hi / lo).powf(i as f64 / n as f64))
        .collect()
}

/// The best model with `g` Gauss–Markov processes: the grid searched,
/// then each τc refined by golden section in ln τc within a grid step.
fn best_with(d: &Data, w: &Whitened, grid: &[f64], cols: &[DVector<f64>], g: usize) -> Candidate {
    let mut best = match g {
        0 => solve_with(w, &[], &[]),
        1 => (0..grid.len())
            .map(|i| solve_with(w, &cols[i..=i], &grid[i..=i]))
            .min_by(|a, b| a.chi2.total_cmp(&b.chi2))
            .unwrap_or_else(|| solve_with(w, &[], &[])),
        _ => {
            // Two processes at least a factor 3 apart in τc.
            let gap = (3.0f64.log10() * GRID_PER_DECADE).ceil() as usize;
            let mut best: Option<Candidate> = None;
            for i in 0..grid.len() {
                for j in (i + gap)..grid.len() {
                    let c = solve_with(w, &[cols[i].clone(), cols[j].clone()], &[grid[i], grid[j]]);
                    if best.as_ref().is_none_or(|b| c.chi2 < b.chi2) {
                        best = Some(c);
                    }
                }
            }
            best.unwrap_or_else(|| solve_with(w, &[], &[]))
        }
    };
    let step = (10f64).powf(1.0 / GRID_PER_DECADE).ln();
    for _ in 0..2 {
        for k in 0..best.tau_c.len() {
            let eval = |lt: f64| {
                let mut tc = best.tau_c.clone();
                tc[k] = lt.exp();
                let gcols: Vec<DVector<f64>> =
                    tc.iter().map(|&t| w.whiten(&d.gm_column(t))).collect();
                solve_with(w, &gcols, &tc)
            };
            let floor = (TAU_C_MIN * d.tau0).ln();
            let (mut a, mut b) = (
                (best.tau_c[k].ln() - step).max(floor),
                best.tau_c[k].ln() + step,
            );
            let r = 0.618_033_988_749_895;
            for _ in 0..24 {
                let x1 = b - r * (b - a);
                let x2 = a + r * (b - a);
                if eval(x1).chi2 < eval(x2).chi2 {
                    b = x2;
                } else {
                    a = x1;
                }
            }
            let c = eval(0.5 * (a + b));
            if c.chi2 < best.chi2 {
                best = c;
            }
        }
    }
    best
}

/// The model chosen over 0, 1 and 2 Gauss–Markov processes by the
/// Bayesian information criterion (χ² + k ln p, k the active parameters
/// with each process's τc): a process joins only where it lowers χ² by
/// more than its two parameters' cost.
fn search(d: &Data, w: &Whitened) -> Candidate {
    let grid = tau_c_grid(d);
    let cols: Vec<DVector<f64>> = grid.iter().map(|&t| w.whiten(&d.gm_column(t))).collect();
    let lnp = (d.ms.len() as f64).ln();
    let score = |c: &Candidate| c.chi2 + lnp * c.active() as f64;
    (0..=MAX_GM)
        .map(|g| best_with(d, w, &grid, &cols, g))
        .min_by(|a, b| score(a).total_cmp(&score(b)))
        .unwrap_or_else(|| solve_with(w, &[], &[]))
}

fn spectrum_of(c: &Candidate, tau0: f64) -> Spectrum {
    let mut power = [0.0; POWER];
    power.copy_from_slice(&c.theta[..POWER]);
    Spectrum {
        power,
        gm: c.theta[POWER..]
            .iter()
            .zip(&c.tau_c)
            .map(|(&v, &t)| (v, t))
            .collect(),
        tau0,
    }
}

fn model_avar(d: &Data, c: &Candidate) -> Vec<f64> {
    d.ms.iter()
        .map(|&m| {
            let p = power_avar(m, d.tau0);
            let mut v: f64 = (0..POWER).map(|k| c.theta[k] * p[k]).sum();
            for (a, &t) in c.theta[POWER..].iter().zip(&c.tau_c) {
                v += a * gm_avar(m, d.tau0, t);
            }
            v
        })
        .collect()
}

/// The covariance under candidate `c`, each variance floored at 1e-3 of
/// the white-FM estimate's (a term the model lacks still weighs its point
/// finitely).
fn covariance(d: &Data, c: &Candidate, diag_floor: &[f64]) -> DMatrix<f64> {
    let spec = spectrum_of(c, d.tau0);
    let cv = avar_cov(&spec, &d.ms, d.n);
    let p = d.ms.len();
    let mut s = DMatrix::from_fn(p, p, |i, j| cv[i][j]);
    for i in 0..p {
        s[(i, i)] = s[(i, i)].max(1e-3 * diag_floor[i]);
    }
    s
}

/// Fit the model to an overlapping Allan deviation curve of `n` phase
/// points (rate samples + 1). None if fewer than three usable points.
///
/// Where the model does not describe the whole curve, the shortest τ are
/// left out one at a time (up to a decade of them, keeping at least ten
/// points) until it does: a sensor's output filter, or a tone from its
/// drive, shapes the first milliseconds in ways no noise term describes,
/// and those points, whose EDF is the largest, would otherwise bend the
/// fit everywhere else. The fit says how many it left out
/// ([`Terms::short_left_out`]); if none of those fits passes, the fit over
/// every point is returned, failing its test.
pub fn fit(curve: &[Point], n: usize) -> Option<Terms> {
    let pts: Vec<&Point> = curve
        .iter()
        .filter(|p| n / p.m.max(1) >= FIT_CLUSTERS && p.dev > 0.0 && p.dev.is_finite())
        .collect();
    let whole = fit_points(&pts, n)?;
    if whole.fits {
        return Some(whole);
    }
    let decade = pts
        .iter()
        .take_while(|p| p.tau < 100.0 * pts[0].tau)
        .count();
    for k in 1..=decade {
        if pts.len() - k < 10 {
            break;
        }
        if let Some(mut t) = fit_points(&pts[k..], n) {
            if t.fits {
                t.short_left_out = k;
                return Some(t);
            }
        }
    }
    Some(whole)
}

/// The fit over `pts` alone, from the diagonal weights: the same answer
/// as for a curve that held only these points. (Starting a trimmed fit
/// from the whole curve's model was measured: 25 % faster, but the
/// answer then depends on the points it left out, on one ADIS16405 curve
/// the τ it is described from moved from 0.06 s to 0.75 s.)
fn fit_points(pts: &[&Point], n: usize) -> Option<Terms> {
    if pts.len() < 3 {
        return None;
    }
    let tau0 = pts[0].tau / pts[0].m as f64;
    let d = Data {
        ms: pts.iter().map(|p| p.m).collect(),
        taus: pts.iter().map(|p| p.tau).collect(),
        avar: pts.iter().map(|p| p.dev * p.dev).collect(),
        tau0,
        n,
    };
    let p = d.ms.len();
    // The first weights: each point alone, by its EDF (Greenhall's for its
    // identified noise type, white FM's where it has none).
    let edf: Vec<f64> = pts
        .iter()
        .map(|pt| {
            pt.edf
                .unwrap_or_else(|| {
                    use gyro_array::algo::allan::{edf, NoiseType};
                    edf(NoiseType::WhiteFm, n as u64, pt.m as u64).unwrap_or(1.0)
                })
                .max(1.0)
        })
        .collect();
    let floor: Vec<f64> = (0..p)
        .map(|i| 2.0 * d.avar[i] * d.avar[i] / edf[i])
        .collect();
    let sigma0 = DMatrix::from_fn(p, p, |i, j| if i == j { floor[i] } else { 0.0 });
    let w0 = Whitened::new(&d, &sigma0)?;
    let mut best = search(&d, &w0);
    let mut w = w0;
    // Refit under the covariance of the model just fitted, until it
    // settles (three rounds: the weights change little after the first).
    for _ in 0..3 {
        let sigma = covariance(&d, &best, &floor);
        let Some(wn) = Whitened::new(&d, &sigma) else {
            break;
        };
        w = wn;
        best = search(&d, &w);
    }
    Some(summarise(&d, &w, &best, n))
}

/// Statistics of the final candidate: intervals from the linearised
/// covariance of every active parameter (amplitudes and ln τc), the χ²
/// test, visibility, IEEE 952's B.
fn summarise(d: &Data, w: &Whitened, c: &Candidate, n: usize) -> Terms {
    let p = d.ms.len();
    let g = c.tau_c.len();
    // Columns of the whitened Jacobian for the active parameters.
    let mut jac: Vec<DVector<f64>> = Vec::new();
    // (parameter, is ln τc)
    let mut which: Vec<(usize, bool)> = Vec::new();
    let gm_cols: Vec<DVector<f64>> = c.tau_c.iter().map(|&t| w.whiten(&d.gm_column(t))).collect();
    // Every power-law term, also those the fit holds at 0: the
    // constraint is no information, and the intervals of the terms in the
    // fit must allow for those at the boundary (without them, N's interval
    // covered its truth on 84 % of runs with flicker, 95 % with).
    for k in 0..POWER {
        jac.push(w.power[k].clone());
        which.push((k, false));
    }
    for (j, col) in gm_cols.iter().enumerate() {
        let a = c.theta[POWER + j];
        if a > 0.0 {
            jac.push(col.clone());
            which.push((POWER + j, false));
            let h: f64 = 1e-4;
            let up = d.gm_column(c.tau_c[j] * h.exp());
            let dn = d.gm_column(c.tau_c[j] * (-h).exp());
            let deriv = (up - dn) * (a / (2.0 * h));
            jac.push(w.whiten(&deriv));
            which.push((POWER + j, true));
        }
    }
    let k = jac.len();
    let dof = p.saturating_sub(c.active());
    let p_value = if dof > 0 {
        1.0 - gyro_array::algo::stats::inc_gamma_p(0.5 * dof as f64, 0.5 * c.chi2)
    } else {
        f64::NAN
    };
    let fmat = DMatrix::from_fn(k, k, |i, j| jac[i].dot(&jac[j]));
    let cov = fmat.clone().try_inverse().unwrap_or_else(|| {
        // Singular (a process's τc not identified): the amplitudes alone.
        DMatrix::from_fn(k, k, |i, j| {
            if i == j {
                1.0 / fmat[(i, i)].max(f64::MIN_POSITIVE)
            } else {
                0.0
            }
        })
    });
    let model = model_avar(d, c);
    let sigma_ii: Vec<f64> = {
        // The point's own variance: the whitening factor's row norms.
        let l = w.chol.l();
        (0..p).map(|i| l.row(i).norm_squared()).collect()
    };
    let outside = (0..p)
        .filter(|&i| n / d.ms[i] >= SOLID_CLUSTERS)
        .filter(|&i| {
            // The point's 99.9 % interval from χ² with the EDF its variance
            // under the model implies (2σ⁴/Var): skewed where clusters are
            // few, which a normal interval is not.
            let edf = 2.0 * model[i] * model[i] / sigma_ii[i];
            match crate::edf::interval_with(
                d.avar[i].sqrt(),
                edf,
                1.0 - 2.0 * Z_TAIL,
                crate::edf::Chi2::Exact,
            ) {
                Some((lo, hi)) => !(lo..=hi).contains(&model[i].max(0.0).sqrt()),
                None => false,
            }
        })
        .count();
    let fits = p_value >= P_FIT && outside == 0;
    let scale = if fits {
        1.0
    } else {
        (c.chi2 / dof.max(1) as f64).max(1.0)
    };
    let sd_of = |idx: usize| (cov[(idx, idx)] * scale).max(0.0).sqrt();
    // A term carries a tenth of the model at some solid point.
    let carries = |part: &dyn Fn(usize) -> f64| {
        (0..p)
            .filter(|&i| n / d.ms[i] >= crate::dev::MIN_CLUSTERS)
            .any(|i| part(i) >= 0.1 * model[i])
    };
    let mut t = Terms {
        points: p,
        chi2: c.chi2,
        dof,
        p_value,
        outside,
        fits,
        tau0: d.tau0,
        tau_max_s: d.taus[p - 1],
        tau_min_s: d.taus[0],
        sd: [f64::NAN; POWER],
        ..Terms::default()
    };
    for (col, &(param, is_tau)) in which.iter().enumerate() {
        if is_tau || param >= POWER {
            continue;
        }
        let th = c.theta[param];
        let sd = sd_of(col);
        if th <= 0.0 {
            // Not in the fit: only an upper bound.
            t.ci[param] = [0.0, (1.96 * sd).sqrt()];
            continue;
        }
        t.value[param] = th.sqrt();
        t.sd[param] = sd / (2.0 * th.sqrt());
        t.ci[param] = [(th - 1.96 * sd).max(0.0).sqrt(), (th + 1.96 * sd).sqrt()];
        let part = |i: usize| th * power_avar(d.ms[i], d.tau0)[param];
        let without = solve_without(w, &gm_cols, &c.tau_c, Some(param));
        t.visible[param] = fits && without.chi2 - c.chi2 >= DCHI2_TERM && carries(&part);
    }
    for j in 0..g {
        let a = c.theta[POWER + j];
        if a <= 0.0 {
            continue;
        }
        let col = which
            .iter()
            .position(|&(q, tau)| q == POWER + j && !tau)
            .unwrap_or(0);
        let sd = sd_of(col);
        let sd_ln: f64 = sd_of(col + 1);
        let tc = c.tau_c[j];
        let mut tau_c_ci = [tc * (-1.96 * sd_ln).exp(), tc * (1.96 * sd_ln).exp()];
        let mut sigma_ci = [(a - 1.96 * sd).max(0.0).sqrt(), (a + 1.96 * sd).sqrt()];
        // The χ² profile over τc (the amplitudes refitted at each): τc
        // and σ trade along a ridge the linearisation sees as narrower
        // than it is. Each interval is the union of both readings.
        let allow = 3.84 * scale;
        for step in -60..=60 {
            let t_try = tc * (f64::from(step) * 0.05).exp();
            if t_try < TAU_C_MIN * d.tau0 {
                continue;
            }
            let mut tcs = c.tau_c.clone();
            tcs[j] = t_try;
            let cols: Vec<DVector<f64>> = tcs.iter().map(|&t| w.whiten(&d.gm_column(t))).collect();
            let fitted = solve_with(w, &cols, &tcs);
            if fitted.chi2 <= c.chi2 + allow {
                let amp = fitted.theta[POWER + j];
                tau_c_ci = [tau_c_ci[0].min(t_try), tau_c_ci[1].max(t_try)];
                sigma_ci = [sigma_ci[0].min(amp.sqrt()), sigma_ci[1].max(amp.sqrt())];
            }
        }
        let inside = tau_c_ci[0] >= d.tau0 && tau_c_ci[1] <= d.taus[p - 1];
        let part = |i: usize| a * gm_avar(d.ms[i], d.tau0, tc);
        let others: Vec<usize> = (0..g).filter(|&o| o != j).collect();
        let without = solve_with(
            w,
            &others
                .iter()
                .map(|&o| gm_cols[o].clone())
                .collect::<Vec<_>>(),
            &others.iter().map(|&o| c.tau_c[o]).collect::<Vec<_>>(),
        );
        let resolved = without.chi2 - c.chi2 >= DCHI2_GM;
        t.gm.push(GaussMarkov {
            sigma: a.sqrt(),
            sigma_ci,
            tau_c_s: tc,
            tau_c_ci,
            visible: fits && resolved && sd_ln.is_finite() && inside && carries(&part),
        });
    }
    t.gm.sort_by(|a, b| a.tau_c_s.total_cmp(&b.tau_c_s));
    let (mut arw2, mut lo2, mut hi2) = (
        t.value[1] * t.value[1],
        t.ci[1][0] * t.ci[1][0],
        t.ci[1][1] * t.ci[1][1],
    );
    for g in t.gm.iter().filter(|g| g.tau_c_s < 3.0 * d.tau0) {
        arw2 += 2.0 * g.sigma * g.sigma * g.tau_c_s;
        lo2 += 2.0 * g.sigma_ci[0] * g.sigma_ci[0] * g.tau_c_ci[0];
        hi2 += 2.0 * g.sigma_ci[1] * g.sigma_ci[1] * g.tau_c_ci[1];
    }
    t.arw = arw2.sqrt();
    t.arw_ci = [lo2.sqrt(), hi2.sqrt()];
    // Tangent readings: the least value each term alone would need.
    t.tangent = [f64::INFINITY; POWER];
    for (i, &m) in d.ms.iter().enumerate() {
        let b = power_avar(m, d.tau0);
        for (tk, bk) in t.tangent.iter_mut().zip(b) {
            *tk = tk.min((d.avar[i] / bk).sqrt());
        }
    }
    // IEEE 952's B: the model's floor, its first minimum along τ inside
    // the fitted τ (a curve that still falls at the longest τ has none).
    let fine: Vec<f64> = (0..=400)
        .map(|i| d.taus[0] * (d.taus[p - 1] / d.taus[0]).powf(i as f64 / 400.0))
        .collect();
    let v: Vec<f64> = fine.iter().map(|&tau| t.avar(tau)).collect();
    // A minimum over a quarter decade either side (the discrete terms step
    // at the shortest τ), at ten samples or more.
    let span = 20usize;
    let is_floor = |i: usize| {
        fine[i] >= 10.0 * d.tau0 && v[i] > 0.0 && v[i - span..=i + span].iter().all(|&u| v[i] <= u)
    };
    if let Some(i) = (span..v.len().saturating_sub(span)).find(|&i| is_floor(i)) {
        let flat = (2.0 * std::f64::consts::LN_2 / std::f64::consts::PI).sqrt();
        t.bias_instability = Some(v[i].sqrt() / flat);
        t.bias_instability_tau_s = Some(fine[i]);
    }
    t
}
