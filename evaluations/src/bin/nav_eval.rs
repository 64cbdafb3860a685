//! `nav-eval`: seed 001's experiment ("A new navigation information
//! fusion method based on entropy weights") on the host. A
//! linear 21-state SINS/USBL/DVL error model (`nav_eval/model.rs`: the
//! paper's sea motion, initial errors, IMU, USBL and DVL errors, every
//! parameter it left out named there) is simulated for `--epochs` 1 s
//! epochs, `--runs` Monte-Carlo runs per scenario, and every fusion method
//! of `nav_eval/methods.rs` estimates the position:
//!
//! - the paper's entropy-weighted mixture of the two local filters
//!   (SINS/USBL, SINS/DVL), faithful: σ the RMS of the position block in
//!   metres, SH ≤ 0 floored (and counted), the literal covariance reset,
//!   fused state fed back; and its variants (federated reset; neither);
//! - the paper's weighted (covariance-weighted) Kalman fusion, P(k/k) and
//!   the P(k/k−1) reading; the standard federated filter (β = ½);
//!   covariance intersection; each local filter alone;
//! - the centralized filter over both sensors;
//! - ours: the centralized filter with each sensor's noise scale learnt
//!   from its innovations and a χ² gate on outliers.
//!
//! Scenarios: normal and degraded (the paper's; the filters know the
//! noise), and with wrong models (the filters keep the nominal noise):
//! sensors 2–4× worse, USBL outliers, DVL dropouts, and all three.
//!
//! It prints, per scenario, each method's E/N/U position RMS and largest
//! error, its ANEES (position, 3 dof) and the share of epochs whose
//! run-averaged NEES is inside the 95 % χ² band; the entropy weights over
//! time and how often σ·H ≤ 0; a picture of the position error over time;
//! and one line with the ratios.

use std::path::PathBuf;

use clap::Parser;
use gyro_array::algo::mixture::CovReset;
use gyro_array::algo::stats::chi2_quantile;
use nalgebra::Vector3;
use plotters::prelude::*;

#[path = "nav_eval/methods.rs"]
mod methods;
#[path = "nav_eval/model.rs"]
mod model;

use methods::{Central, Est, Meas, Ours, Pair};
use model::{epoch, p0, Motion, Params, N};

#[derive(Parser)]
#[command(about = "Seed 001: SINS/USBL/DVL fusion methods, Monte-Carlo")]
struct Args {
    /// Monte-Carlo runs per scenario.
    #[arg(long, default_value_t = 50, value_parser = clap::value_parser!(u32).range(1..=10_000))]
    runs: u32,
    /// Epochs (1 s) per run.
    #[arg(long, default_value_t = 5000, value_parser = clap::value_parser!(u32).range(10..=100_000))]
    epochs: u32,
    /// Base random seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// The picture of the position error over time.
    #[arg(long, default_value = "nav-eval.svg")]
    svg: PathBuf,
}

/// A small f64 generator (xorshift64*, Box–Muller).
struct Rng(u64);

impl Rng {
    fn new(seed: u64) -> Self {
        Self(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    fn u(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        ((self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    fn g(&mut self) -> f64 {
        (-2.0 * self.u().ln()).sqrt() * (2.0 * std::f64::consts::PI * self.u()).cos()
    }
}

#[derive(Clone, Copy, PartialEq)]
enum Scenario {
    Normal,
    Degraded,
    MisSet,
    Outliers,
    Dropouts,
    Mismatched,
}

impl Scenario {
    const ALL: [Scenario; 6] = [
        Scenario::Normal,
        Scenario::Degraded,
        Scenario::MisSet,
        Scenario::Outliers,
        Scenario::Dropouts,
        Scenario::Mismatched,
    ];
    fn name(self) -> &'static str {
        match self {
            Scenario::Normal => "normal (the filters know the noise)",
            Scenario::Degraded => "degraded: USBL 2 per mille, DVL 0.4/0.8 m/s, process x3 (known)",
            Scenario::MisSet => "mis-set noise: sensors 2-4x worse than the filters assume",
            Scenario::Outliers => "outliers: 1 % of USBL fixes 10 sigma off",
            Scenario::Dropouts => {
                "dropouts: DVL lost 20 s at a time (0.25 %/s), 10 % of USBL fixes lost"
            }
            Scenario::Mismatched => "wrong models: all three of the above",
        }
    }
}

const METHODS: [&str; 12] = [
    "centralized",
    "ours",
    "weighted P(k/k)",
    "weighted P(k/k-1)",
    "entropy (faithful)",
    "entropy, fed. reset",
    "entropy, open",
    "entropy, sigma in m",
    "federated",
    "cov. intersection",
    "SINS/USBL alone",
    "SINS/DVL alone",
];
const M: usize = METHODS.len();

/// Accumulated over runs.
#[derive(Clone)]
struct Stats {
    sq: [[f64; 3]; M],
    max: [[f64; 3]; M],
    nees: [f64; M],
    count: u64,
    /// Per epoch: Σ NEES over runs, Σ |e|² over runs (per method).
    nees_t: Vec<[f64; M]>,
    err_t: Vec<[f64; M]>,
    /// Per epoch Σ α_USBL of the faithful entropy method.
    alpha_t: Vec<f64>,
    sh_nonpos: u64,
    refused: u64,
}

impl Stats {
    fn new(epochs: usize) -> Self {
        Self {
            sq: [[0.0; 3]; M],
            max: [[0.0; 3]; M],
            nees: [0.0; M],
            count: 0,
            nees_t: vec![[0.0; M]; epochs],
            err_t: vec![[0.0; M]; epochs],
            alpha_t: vec![0.0; epochs],
            sh_nonpos: 0,
            refused: 0,
        }
    }
    fn merge(&mut self, o: &Stats) {
        for m in 0..M {
            for a in 0..3 {
                self.sq[m][a] += o.sq[m][a];
                self.max[m][a] = self.max[m][a].max(o.max[m][a]);
            }
            self.nees[m] += o.nees[m];
        }
        self.count += o.count;
        for (t, (n, e)) in self
            .nees_t
            .iter_mut()
            .zip(self.err_t.iter_mut())
            .enumerate()
        {
            for m in 0..M {
                n[m] += o.nees_t[t][m];
                e[m] += o.err_t[t][m];
            }
            self.alpha_t[t] += o.alpha_t[t];
        }
        self.sh_nonpos += o.sh_nonpos;
        self.refused += o.refused;
    }
    fn rms(&self, m: usize) -> [f64; 3] {
        self.sq[m].map(|s| (s / self.count as f64).sqrt())
    }
    /// √(mean of the three axes' mean squares).
    fn rms3(&self, m: usize) -> f64 {
        (self.sq[m].iter().sum::<f64>() / (3.0 * self.count as f64)).sqrt()
    }
}

fn run(scn: Scenario, seed: u64, epochs: usize, st: &mut Stats) {
    let motion = Motion::default();
    let mut rng = Rng::new(seed);
    let nominal = match scn {
        Scenario::Degraded => Params::degraded(),
        _ => Params::normal(),
    };
    let truth = match scn {
        Scenario::MisSet | Scenario::Mismatched => nominal.sensors_times(2.0 + 2.0 * rng.u()),
        _ => nominal,
    };
    let (outliers, dropouts) = match scn {
        Scenario::Outliers => (true, false),
        Scenario::Dropouts => (false, true),
        Scenario::Mismatched => (true, true),
        _ => (false, false),
    };
    let p0t = p0(&truth);
    let p0f = p0(&nominal);
    let mut x = model::V::zeros();
    for i in 0..N {
        x[i] = p0t[(i, i)].sqrt() * rng.g();
    }
    let mut central = Central::new(&p0f);
    let mut ours = Ours::new(&p0f);
    let mut indep = Pair::new(&p0f);
    let mut ent = Pair::new(&p0f);
    let mut ent_fed = Pair::new(&p0f);
    let mut ent_m = Pair::new(&p0f);
    let mut fed = Pair::new(&p0f);
    let mut dvl_out = 0u32;
    for k in 0..epochs {
        let et = epoch(&motion, &truth, k + 1);
        let ef = epoch(&motion, &nominal, k + 1);
        let mut w = model::V::zeros();
        for i in 0..N {
            w[i] = et.q[(i, i)].sqrt() * rng.g();
        }
        x = et.f * x + w;
        let noise = |rng: &mut Rng, r: &nalgebra::Matrix3<f64>| {
            Vector3::new(
                r[(0, 0)].sqrt() * rng.g(),
                r[(1, 1)].sqrt() * rng.g(),
                r[(2, 2)].sqrt() * rng.g(),
            )
        };
        let mut usbl = et.h_usbl * x + noise(&mut rng, &et.r_usbl);
        if outliers && rng.u() < 0.01 {
            usbl += noise(&mut rng, &et.r_usbl) * 10.0;
        }
        let usbl = (!(dropouts && rng.u() < 0.1)).then_some(usbl);
        let dvl = et.h_dvl * x + noise(&mut rng, &et.r_dvl);
        if dropouts && dvl_out == 0 && rng.u() < 0.0025 {
            dvl_out = 20;
        }
        let dvl = if dvl_out > 0 {
            dvl_out -= 1;
            None
        } else {
            Some(dvl)
        };
        let z = Meas { usbl, dvl };
        // The filters' model: F, Q and R as the filters believe them.
        let b = &ef;
        indep.step(b, &z);
        ent.step(b, &z);
        ent_fed.step(b, &z);
        ent_m.step(b, &z);
        fed.step_shared(b, &z, [0.5, 0.5]);
        // σ in millimetres (SH > 0 for any σ above 0.24 mm): the faithful
        // reading; in metres the same method, SH ≤ 0 floored.
        let (e_ent, alpha, _) =
            methods::entropy_step(&mut ent, CovReset::PaperLiteral, true, 1000.0);
        let (e_entf, _, _) = methods::entropy_step(&mut ent_fed, CovReset::Federated, true, 1000.0);
        // (Neither reset nor fed back: the independent pair is left as it is.)
        let (e_open, _, _) = methods::entropy_step(&mut indep, CovReset::None, false, 1000.0);
        let (e_m, _, nonpos) = methods::entropy_step(&mut ent_m, CovReset::PaperLiteral, true, 1.0);
        let ests: [Est; M] = [
            central.step(b, &z),
            ours.step(b, &z),
            methods::weighted(&indep, false),
            methods::weighted(&indep, true),
            e_ent,
            e_entf,
            e_open,
            e_m,
            methods::federated_step(&mut fed),
            methods::ci(&indep),
            methods::local(&indep, 0),
            methods::local(&indep, 1),
        ];
        st.alpha_t[k] += alpha[0];
        st.sh_nonpos += u64::from(nonpos);
        let p = x.fixed_view::<3, 1>(6, 0).into_owned();
        for (m, e) in ests.iter().enumerate() {
            let d = p - e.p;
            for a in 0..3 {
                st.sq[m][a] += d[a] * d[a];
                st.max[m][a] = st.max[m][a].max(d[a].abs());
            }
            let nees = e
                .cov
                .cholesky()
                .map_or(f64::INFINITY, |c| (d.transpose() * c.solve(&d))[(0, 0)]);
            st.nees[m] += nees;
            st.nees_t[k][m] += nees;
            st.err_t[k][m] += d.norm_squared();
        }
        st.count += 1;
    }
    st.refused += ours.refused;
}

fn scenario(scn: Scenario, args: &Args) -> Stats {
    let epochs = args.epochs as usize;
    let runs = args.runs as u64;
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(8) as u64;
    let parts: Vec<Stats> = std::thread::scope(|s| {
        let hs: Vec<_> = (0..threads)
            .map(|t| {
                s.spawn(move || {
                    let mut st = Stats::new(epochs);
                    for r in (t..runs).step_by(threads as usize) {
                        let seed = args.seed * 1_000_003 + (scn as u64) * 10_007 + r;
                        run(scn, seed, epochs, &mut st);
                    }
                    st
                })
            })
            .collect();
        hs.into_iter().map(|h| h.join().expect("run")).collect()
    });
    let mut all = Stats::new(epochs);
    for p in &parts {
        all.merge(p);
    }
    all
}

fn report(scn: Scenario, st: &Stats, args: &Args) {
    let runs = f64::from(args.runs);
    let dof = 3.0 * runs;
    let (lo, hi) = (
        chi2_quantile(0.025, dof).unwrap_or(0.0) / dof,
        chi2_quantile(0.975, dof).unwrap_or(f64::INFINITY) / dof,
    );
    println!(
        "\n{} ({} runs x {} epochs)",
        scn.name(),
        args.runs,
        args.epochs
    );
    println!(
        "  {:<21} {:>7} {:>7} {:>7}   {:>7} {:>7} {:>7}   {:>8}  {:>7}",
        "method (m)", "E RMS", "N RMS", "U RMS", "max E", "max N", "max U", "ANEES", "in band"
    );
    for (m, name) in METHODS.iter().enumerate() {
        let r = st.rms(m);
        let anees = st.nees[m] / (3.0 * st.count as f64);
        let inside = st
            .nees_t
            .iter()
            .filter(|n| {
                let v = n[m] / dof;
                v >= lo && v <= hi
            })
            .count() as f64
            / st.nees_t.len() as f64;
        println!(
            "  {:<21} {:>7.3} {:>7.3} {:>7.3}   {:>7.2} {:>7.2} {:>7.2}   {:>8.3}  {:>6.1}%",
            name,
            r[0],
            r[1],
            r[2],
            st.max[m][0],
            st.max[m][1],
            st.max[m][2],
            anees,
            100.0 * inside
        );
    }
    let at = |k: usize| {
        st.alpha_t
            .get(k.min(st.alpha_t.len() - 1))
            .copied()
            .unwrap_or(0.0)
            / runs
    };
    let n = st.alpha_t.len();
    println!(
        "  ANEES 95 % band per epoch over {} runs: [{lo:.3}, {hi:.3}]; entropy weight of SINS/USBL at epochs 10/{}/{}/{}: {:.3}/{:.3}/{:.3}/{:.3}; sigma*H <= 0 (sigma in m) at {} of {} epoch-runs; ours refused {} readings",
        args.runs,
        n / 4,
        n / 2,
        n - 1,
        at(10),
        at(n / 4),
        at(n / 2),
        at(n - 1),
        st.sh_nonpos,
        st.count,
        st.refused
    );
}

fn draw(
    path: &PathBuf,
    panels: &[(Scenario, &Stats)],
    runs: f64,
) -> Result<(), Box<dyn std::error::Error>> {
    let root = SVGBackend::new(path, (1000, 420 * panels.len() as u32)).into_drawing_area();
    root.fill(&WHITE)?;
    let areas = root.split_evenly((panels.len(), 1));
    let show = [0usize, 1, 2, 4, 8, 9];
    let colours = [BLACK, RED, BLUE, GREEN, MAGENTA, CYAN];
    for (area, (scn, st)) in areas.iter().zip(panels) {
        let n = st.err_t.len();
        let rms = |m: usize, k: usize| (st.err_t[k][m] / runs).sqrt();
        let top = show
            .iter()
            .flat_map(|&m| (0..n).map(move |k| (m, k)))
            .map(|(m, k)| rms(m, k))
            .fold(0.0f64, f64::max)
            .min(60.0);
        let mut chart = ChartBuilder::on(area)
            .caption(
                format!("position error (3-D, RMS over runs): {}", scn.name()),
                ("sans-serif", 16),
            )
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(55)
            .build_cartesian_2d(0f64..n as f64, 0f64..top * 1.05)?;
        chart
            .configure_mesh()
            .x_desc("epoch (s)")
            .y_desc("m")
            .draw()?;
        for (i, &m) in show.iter().enumerate() {
            let c = colours[i];
            chart
                .draw_series(LineSeries::new(
                    (0..n)
                        .step_by(10)
                        .map(|k| (k as f64, rms(m, k).min(top * 1.05))),
                    c.stroke_width(if m == 1 { 2 } else { 1 }),
                ))?
                .label(METHODS[m])
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], c.stroke_width(2)));
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()?;
    }
    root.present()?;
    Ok(())
}

fn main() {
    gyro_tool::pipe::quiet_on_closed_pipe();
    let args = Args::parse();
    let t0 = std::time::Instant::now();
    let mut results = Vec::new();
    for scn in Scenario::ALL {
        let st = scenario(scn, &args);
        report(scn, &st, &args);
        results.push((scn, st));
    }
    let get = |s: Scenario| &results.iter().find(|(x, _)| *x == s).expect("scenario").1;
    let (normal, degraded, mism) = (
        get(Scenario::Normal),
        get(Scenario::Degraded),
        get(Scenario::Mismatched),
    );
    let (ent, wtd, cen, ours) = (4, 2, 0, 1);
    if let Err(e) = draw(
        &args.svg,
        &[(Scenario::Normal, normal), (Scenario::Mismatched, mism)],
        f64::from(args.runs),
    ) {
        eprintln!("nav-eval: picture: {e}");
        std::process::exit(1);
    }
    eprintln!(
        "nav-eval: {} s; picture {}",
        t0.elapsed().as_secs(),
        args.svg.display()
    );
    println!(
        "seed-001 ratio entropy/weighted: normal {:.3} degraded {:.3}; ours/centralized nominal {:.3}; ours/weighted mismatched {:.3}",
        normal.rms3(ent) / normal.rms3(wtd),
        degraded.rms3(ent) / degraded.rms3(wtd),
        normal.rms3(ours) / normal.rms3(cen),
        mism.rms3(ours) / mism.rms3(wtd),
    );
}
