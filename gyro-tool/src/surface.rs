//! `gyro davar`: the board's E-DAVAR (segmented window, λ1 = λ2/2) over one
//! column of a rate log: the t–τ–σ surface as a heatmap, σ(τ0) over time,
//! and the window chosen at each hop; optionally the rows as CSV.
//!
//! The rates are quantised to integers as the board's tracker does, with
//! the smallest power-of-two step that keeps every sample inside the
//! E-DAVAR's ±2²⁰ range and still resolves the data's noise ([`step_for`];
//! its own white noise, step²/12, and any samples clipped are printed next
//! to the result so that it can be judged against the data's).

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

use gyro_array::algo::allan::stream::SAMPLE_MAX;
use gyro_array::algo::davar::{Davar, DavarConfig};
use plotters::prelude::*;
use plotters::style::colors::colormaps::ViridisRGB;

use crate::Res;

/// One published row, in the log's units.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Row {
    /// The time the estimate describes, s from the first sample.
    pub t_s: f64,
    /// Its window, s.
    pub start_s: f64,
    pub end_s: f64,
    /// Allan deviation at τ = 2ʲ·τ0, j = 0, 1, …, in the rate's unit.
    pub adev: Vec<f64>,
}

/// The window lengths the tool offers (each a fixed-capacity E-DAVAR).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Lambda2 {
    #[value(name = "256")]
    L256,
    #[value(name = "1024")]
    L1024,
    #[value(name = "4096")]
    L4096,
}

fn run<const CAP: usize, const FRAMES: usize, const T: usize>(
    w: &[i32],
    lambda2: u16,
    lsb: f64,
    tau0: f64,
    stop: &AtomicBool,
) -> Res<Vec<Row>> {
    let mut d = Box::new(
        Davar::<CAP, FRAMES, T, 0>::new(DavarConfig::segmented(lambda2 / 2, lambda2))
            .map_err(|e| format!("E-DAVAR: {e:?}"))?,
    );
    let mut rows = Vec::new();
    for (i, &x) in w.iter().enumerate() {
        if i % crate::STOP_EVERY == 0 && stop.load(Ordering::Relaxed) {
            return Err(crate::Stopped.into());
        }
        let r = d.push(x).map_err(|e| format!("sample {i}: {e:?}"))?;
        if r.is_some() {
            if let Some(s) = d.estimate() {
                rows.push(Row {
                    t_s: s.t as f64 * tau0,
                    start_s: s.start as f64 * tau0,
                    end_s: s.end as f64 * tau0,
                    adev: s
                        .avar
                        .iter()
                        .map(|&v| (v.max(0.0) as f64).sqrt() * lsb)
                        .collect(),
                });
            }
        }
    }
    Ok(rows)
}

/// The quantisation step: the smallest power of two with every |rate|/step
/// inside the E-DAVAR's range, but no coarser than 1/64 of the typical
/// sample-to-sample change (the median |Δrate|), so that one wild sample
/// (10⁶ °/s in a log of 0.01 °/s noise) cannot quantise the rest to 0.
/// Samples beyond the range at that step are clipped to it, as a
/// saturating sensor does ([`clipped`] counts them).
pub fn step_for(rate: &[f64]) -> f64 {
    let peak = rate.iter().fold(0.0f64, |m, r| m.max(r.abs()));
    if peak.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return 1.0;
    }
    let pow2_ceil = |v: f64| 2f64.powi(v.log2().ceil() as i32);
    let by_peak = pow2_ceil(peak / SAMPLE_MAX as f64);
    let mut diffs: Vec<f64> = rate.windows(2).map(|w| (w[1] - w[0]).abs()).collect();
    let mid = diffs.len() / 2;
    if diffs.is_empty() {
        return by_peak;
    }
    let (_, typical, _) = diffs.select_nth_unstable_by(mid, |a, b| a.total_cmp(b));
    if *typical > 0.0 {
        by_peak.min(pow2_ceil(*typical / 64.0))
    } else {
        by_peak
    }
}

/// Samples of `rate` beyond the E-DAVAR's range at step `lsb`: clipped.
pub fn clipped(rate: &[f64], lsb: f64) -> usize {
    rate.iter()
        .filter(|r| (r.abs() / lsb).round() > SAMPLE_MAX as f64)
        .count()
}

/// The surface of `rate` (sampled every `tau0` s).
pub fn surface(rate: &[f64], tau0: f64, l2: Lambda2) -> Res<(Vec<Row>, f64, u16)> {
    surface_until(rate, tau0, l2, &AtomicBool::new(false))
}

/// [`surface`], given up with [`crate::Stopped`] soon after `stop` is
/// set (the Python package's Ctrl-C).
pub fn surface_until(
    rate: &[f64],
    tau0: f64,
    l2: Lambda2,
    stop: &AtomicBool,
) -> Res<(Vec<Row>, f64, u16)> {
    crate::dev::check(rate, tau0)?;
    let lsb = step_for(rate);
    let max = SAMPLE_MAX as f64;
    let w: Vec<i32> = rate
        .iter()
        .map(|r| (r / lsb).round().clamp(-max, max) as i32)
        .collect();
    let (rows, lambda2) = match l2 {
        Lambda2::L256 => (run::<256, 11, 7>(&w, 256, lsb, tau0, stop)?, 256),
        Lambda2::L1024 => (run::<1024, 35, 9>(&w, 1024, lsb, tau0, stop)?, 1024),
        Lambda2::L4096 => (run::<4096, 131, 11>(&w, 4096, lsb, tau0, stop)?, 4096),
    };
    Ok((rows, lsb, lambda2))
}

/// The t–τ–σ surface of `rows` as a heatmap on `area`: log10 σ(τ) over
/// (t, τ), each hop a column of cells, τ labelled in the rows' time unit
/// `t_unit` (`tau0` one step of it). Shared by `gyro davar` and the figures.
pub fn heatmap(
    area: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    title: &str,
    unit: &str,
    rows: &[Row],
    span: core::ops::Range<f64>,
    (tau0, t_unit): (f64, &str),
) -> Res<()> {
    let taus = rows.first().map_or(0, |r| r.adev.len());
    let cells: Vec<(f64, f64, usize, f64)> = rows
        .windows(2)
        .flat_map(|p| {
            let (a, b) = (&p[0], &p[1]);
            (0..taus).map(move |j| (a.t_s, b.t_s, j, a.adev[j].max(1e-300).log10()))
        })
        .collect();
    let (vlo, vhi) = cells.iter().fold((f64::MAX, f64::MIN), |(lo, hi), c| {
        (lo.min(c.3), hi.max(c.3))
    });
    let mut chart = ChartBuilder::on(area)
        .caption(
            format!(
                "{title}: E-DAVAR σ(τ) from {:.3e} (dark) to {:.3e} {unit} (yellow), log colour",
                10f64.powf(vlo),
                10f64.powf(vhi)
            ),
            ("sans-serif", 16),
        )
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(70)
        .build_cartesian_2d(span, -0.5f64..taus as f64 - 0.5)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .y_desc(format!("τ ({t_unit})"))
        .y_labels(taus)
        .y_label_formatter(&|v| {
            let j = v.round().clamp(0.0, 30.0) as i32;
            format!("{}", crate::short(tau0 * 2f64.powi(j)))
        })
        .x_label_formatter(&|v| format!("{}", crate::short(*v)))
        .draw()?;
    chart.draw_series(cells.iter().map(|&(x0, x1, j, v)| {
        Rectangle::new(
            [(x0, j as f64 - 0.5), (x1, j as f64 + 0.5)],
            ViridisRGB::get_color_normalized(v, vlo, vhi.max(vlo + 1e-12)).filled(),
        )
    }))?;
    Ok(())
}

/// Draw the surface, σ(τ0) and the windows of `rows` into `path`.
pub fn draw(
    path: &Path,
    title: &str,
    unit: &str,
    rows: &[Row],
    lambda2: u16,
    tau0: f64,
) -> Res<()> {
    let (Some(first), Some(last)) = (rows.first(), rows.last()) else {
        return Err("no estimate: the log is shorter than one window and a hop".into());
    };
    let span = first.start_s.min(0.0)..last.end_s;
    let root = SVGBackend::new(path, (1000, 900)).into_drawing_area();
    root.fill(&WHITE)?;
    let (top, rest) = root.split_vertically(380);
    let (mid, bot) = rest.split_vertically(280);

    heatmap(&top, title, unit, rows, span.clone(), (tau0, "s"))?;

    // σ(τ0) and σ at the longest τ over time.
    let s0: Vec<(f64, f64)> = rows.iter().map(|r| (r.t_s, r.adev[0])).collect();
    let smax = s0.iter().fold(0.0f64, |m, p| m.max(p.1));
    let mut chart = ChartBuilder::on(&mid)
        .caption(
            format!("σ(τ0 = {} s) of each window ({unit})", crate::short(tau0)),
            ("sans-serif", 16),
        )
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(70)
        .build_cartesian_2d(span.clone(), 0f64..smax * 1.1)?;
    chart
        .configure_mesh()
        .y_label_formatter(&|v| format!("{v:.2e}"))
        .draw()?;
    chart.draw_series(LineSeries::new(s0, RED.stroke_width(2)))?;

    // The window around each t.
    let l2 = lambda2 as f64 * tau0;
    let mut chart = ChartBuilder::on(&bot)
        .caption(
            format!("window of each estimate: [start, end) − t (λ2 = {lambda2} samples)"),
            ("sans-serif", 16),
        )
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(70)
        .build_cartesian_2d(span, -l2..l2)?;
    chart.configure_mesh().x_desc("t (s)").y_desc("s").draw()?;
    chart.draw_series(rows.windows(2).map(|p| {
        let (a, b) = (&p[0], &p[1]);
        Rectangle::new(
            [(a.t_s, a.start_s - a.t_s), (b.t_s, a.end_s - a.t_s)],
            BLUE.mix(0.4).filled(),
        )
    }))?;
    root.present()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// White noise of σ 0.01 °/s on a 100 °/s offset whose σ doubles at
    /// 20 s (1 kHz): away from the step, σ(τ0) averages within 2 % of the
    /// truth on each side and no single estimate is 15 % off (4.5 of its
    /// standard deviations), and σ(8τ0)·√8/σ(τ0) averages within 5 % of 1
    /// (white noise's τ^−½).
    /// One 10⁶ °/s spike in 50 000 samples of 0.01 °/s noise: the step
    /// still resolves the noise (it was 1 °/s, and σ read 0 everywhere),
    /// the spike is clipped and counted.
    #[test]
    fn one_wild_sample_does_not_quantise_the_rest_away() {
        let mut rng = gyro_sim::Rng::new(9);
        let mut rate: Vec<f64> = (0..50_000)
            .map(|_| 0.01 * f64::from(rng.gaussian()))
            .collect();
        rate[25_000] = 1e6;
        let lsb = step_for(&rate);
        assert!(lsb <= 0.01 / 32.0, "{lsb}");
        assert_eq!(clipped(&rate, lsb), 1);
        let (rows, _, _) = surface(&rate, 1e-3, Lambda2::L1024).unwrap();
        let early = &rows[rows.len() / 10];
        assert!(
            (early.adev[0] / 0.01 - 1.0).abs() < 0.2,
            "{}",
            early.adev[0]
        );
    }

    #[test]
    fn the_surface_follows_a_noise_step() {
        let mut rng = gyro_sim::Rng::new(8);
        let n = 40_000;
        let sigma = |t: f64| if t < 20.0 { 0.01 } else { 0.02 };
        let rate: Vec<f64> = (0..n)
            .map(|i| 100.0 + sigma(i as f64 * 1e-3) * f64::from(rng.gaussian()))
            .collect();
        let (rows, lsb, l2) = surface(&rate, 1e-3, Lambda2::L1024).unwrap();
        assert_eq!(l2, 1024);
        assert!(lsb <= 2.0 * 100.0 / SAMPLE_MAX as f64 && lsb >= 100.0 / SAMPLE_MAX as f64);
        assert!(rows.len() > 1000);
        for before in [true, false] {
            let side: Vec<&Row> = rows
                .iter()
                .filter(|r| (r.t_s - 20.0).abs() > 1.0 && (r.t_s < 20.0) == before)
                .collect();
            let s = if before { 0.01 } else { 0.02 };
            let mean = side.iter().map(|r| r.adev[0]).sum::<f64>() / side.len() as f64;
            assert!(
                (mean / s - 1.0).abs() < 0.02,
                "before {before}: mean σ {mean}"
            );
            for r in &side {
                assert!(
                    (r.adev[0] / s - 1.0).abs() < 0.15,
                    "t {} σ {}",
                    r.t_s,
                    r.adev[0]
                );
            }
            let white = side
                .iter()
                .map(|r| r.adev[3] * 8f64.sqrt() / r.adev[0])
                .sum::<f64>()
                / side.len() as f64;
            assert!(
                (white - 1.0).abs() < 0.05,
                "before {before}: τ^-1/2 ratio {white}"
            );
        }
    }
}
