//! The noise model fit (`gyro_tool::fit`) against records of known terms
//! generated independently (`host_tests::noise_classes`) and against the
//! Allan curves of real static MEMS gyros (six ADIS16405 records,
//! `vectors/real/adis16405`). `fit-eval` runs the full sweep.

use gyro_tool::dev::{curve, phase_from_rate, Grid, Kind, Point};
use gyro_tool::fit::{fit, Terms, SOLID_CLUSTERS};
use host_tests::noise_classes::{generate, Truth};

fn fit_record(t: &Truth, tau0: f64, n: usize, seed: u64) -> Terms {
    let y = generate(t, tau0, n, seed);
    let x = phase_from_rate(&y, tau0).unwrap();
    let c = curve(Kind::Oadev, &x, tau0, Grid::PerDecade(8)).unwrap();
    fit(&c, x.len()).unwrap()
}

/// White rate noise, flicker and a Gauss–Markov bias of 30 s over 4 h at
/// 100 Hz: the fit passes, calls exactly N, B and the process visible,
/// each inside its interval, in at least four of five seeds; never a
/// term that is not there.
#[test]
fn the_terms_of_a_generated_record_are_found_within_their_intervals() {
    let truth = Truth {
        power: [0.0, 0.1 / 60.0, 3.0 / 3600.0, 0.0, 0.0],
        gm: vec![(10.0 / 3600.0, 30.0)],
    };
    let mut good = 0;
    for seed in 1..=5u64 {
        let t = fit_record(&truth, 0.01, 1_440_000, seed);
        println!(
            "seed {seed}: fits {} p {:.3} visible {:?} value {:?} gm {:?}",
            t.fits, t.p_value, t.visible, t.value, t.gm
        );
        assert!(
            !t.visible[0] && !t.visible[3] && !t.visible[4],
            "seed {seed}"
        );
        assert!(
            t.gm.iter().filter(|g| g.visible).count() <= 1,
            "seed {seed}"
        );
        let inside = |k: usize| (t.ci[k][0]..=t.ci[k][1]).contains(&truth.power[k]);
        let gm_ok = t.gm.iter().any(|g| {
            g.visible
                && (g.sigma_ci[0]..=g.sigma_ci[1]).contains(&truth.gm[0].0)
                && (g.tau_c_ci[0]..=g.tau_c_ci[1]).contains(&truth.gm[0].1)
        });
        if t.fits && t.visible[1] && t.visible[2] && inside(1) && inside(2) && gm_ok {
            good += 1;
        }
    }
    assert!(good >= 4, "{good} of 5");
}

/// The committed curves: (record, column, phase points, points).
fn adis_curves() -> Vec<(String, String, usize, Vec<Point>)> {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/vectors/real/adis16405/oadev.csv"
    );
    let text = std::fs::read_to_string(path).unwrap();
    let mut out: Vec<(String, String, usize, Vec<Point>)> = Vec::new();
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let (rec, col, n) = (f[0].to_string(), f[1].to_string(), f[2].parse().unwrap());
        let m: usize = f[3].parse().unwrap();
        let p = Point {
            m,
            tau: f[4].parse().unwrap(),
            dev: f[5].parse().unwrap(),
            terms: 0,
            alpha: None,
            few_clusters: false,
            edf: f[6].parse().ok(),
            lo: None,
            hi: None,
        };
        match out.last_mut() {
            Some(last) if last.0 == rec && last.1 == col => last.3.push(p),
            _ => out.push((rec, col, n, vec![p])),
        }
    }
    out
}

/// On the six ADIS16405 records' x and y curves the model describes the
/// curve (its χ² test passes) from a few tens of milliseconds on on at
/// least 10 of 12, the angle random walk visible on at least 9; where it passes, it
/// lies within 13 % of the measured deviation at every fitted τ of 30
/// clusters or more (the IEEE 952 fit before sat 1.9× above at 80 s), and
/// each curve's worst gap inside its point's own 95 % interval. The z
/// axes carry a periodic disturbance (σ(20 ms) = σ(10 ms), rising again at
/// 70 ms) no term describes: their test fails, or passes only from τ
/// beyond the tone's reach.
#[test]
fn the_model_follows_real_static_gyro_curves() {
    let (mut worst, mut passing, mut arw_seen) = (0.0f64, 0, 0);
    // Each described x or y curve's worst gap as a fraction of its point's
    // own 95 % half-width: the largest.
    let mut worst_interval = 0.0f64;
    for (rec, col, n, pts) in adis_curves().iter().filter(|c| c.1.starts_with('g')) {
        let t = fit(pts, *n).unwrap();
        let mut dev_worst = 0.0f64;
        // The worst point's τ, clusters and its own 95 % interval's
        // half-width (the larger side), as a fraction of the deviation.
        let mut at_worst = (0.0, 0, 0.0);
        for p in pts
            .iter()
            .filter(|p| n / p.m >= SOLID_CLUSTERS && p.tau >= t.tau_min_s)
        {
            let r = (t.avar(p.tau).sqrt() / p.dev - 1.0).abs();
            let half = p
                .edf
                .and_then(|e| {
                    gyro_tool::edf::interval_with(p.dev, e, 0.95, gyro_tool::edf::Chi2::Exact)
                })
                .map_or(f64::NAN, |(lo, hi)| (hi - p.dev).max(p.dev - lo) / p.dev);
            if r > dev_worst {
                at_worst = (p.tau, n / p.m, half);
            }
            dev_worst = dev_worst.max(r);
        }
        if t.fits && col != "gz" {
            worst_interval = worst_interval.max(dev_worst / at_worst.2);
        }
        println!(
            "record {rec} {col}: fits {} from tau {} s (chi2 {:.1}/{}, p {:.3}, outside {}), worst at 30 clusters or more {:.1} % (at {} s, {} clusters, the point's own 95 % interval ±{:.1} %), ARW {:.3} deg/rt h, B(IEEE) {:?} deg/h, visible {:?}, gm {:?}",
            t.fits,
            t.tau_min_s,
            t.chi2,
            t.dof,
            t.p_value,
            t.outside,
            100.0 * dev_worst,
            at_worst.0,
            at_worst.1,
            100.0 * at_worst.2,
            t.arw * 60.0,
            t.bias_instability.map(|b| b * 3600.0),
            t.visible,
            t.gm.iter().map(|g| (g.sigma * 3600.0, g.tau_c_s, g.visible)).collect::<Vec<_>>()
        );
        if col == "gz" {
            // The tone is in no term: the model describes z only beyond it.
            assert!(
                !t.fits || t.tau_min_s >= 0.1,
                "record {rec} gz from {}",
                t.tau_min_s
            );
            continue;
        }
        if t.fits {
            passing += 1;
            arw_seen += usize::from(t.visible[1]);
            worst = worst.max(dev_worst);
        }
    }
    println!(
        "x and y curves the model describes: {passing} of 12, N visible on {arw_seen}; worst gap {:.1} %, at most {:.2} of its point's own 95 % half-width",
        100.0 * worst,
        worst_interval
    );
    assert!(passing >= 10 && arw_seen >= 9, "{passing} {arw_seen}");
    assert!(worst < 0.13, "worst {worst}");
    assert!(
        worst_interval < 1.0,
        "worst gap / its interval {worst_interval}"
    );
}
