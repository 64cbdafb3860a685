//! `gyro allan --svg`: the deviation curves on log–log axes, each point's
//! marker hollow where it averages fewer than 16 clusters, and the fitted
//! noise model (with `--fit`) as a line per column, each of its terms
//! dashed.

use plotters::prelude::*;

use crate::dev::Point;
use crate::fit::Terms;

/// One curve to draw.
pub struct Curve<'a> {
    /// Legend.
    pub label: String,
    /// Points.
    pub points: &'a [Point],
}

/// The curves' colours, in turn (also the replay's chips).
pub const COLOURS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(23, 190, 207),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
];

/// The model's σ² at τ, term by term (power-law terms, then each
/// Gauss–Markov process).
fn model(t: &Terms, tau: f64) -> Vec<f64> {
    t.parts(tau / t.tau0)
}

/// Draw `curves` (and `fits`: (label, terms)) into `path`.
pub fn draw(
    path: &std::path::Path,
    title: &str,
    unit: &str,
    curves: &[Curve],
    fits: &[(String, Terms)],
) -> Result<(), Box<dyn std::error::Error>> {
    let pts = || curves.iter().flat_map(|c| c.points.iter());
    let (t0, t1) = pts().fold((f64::MAX, 0.0f64), |(a, b), p| (a.min(p.tau), b.max(p.tau)));
    let (lo, hi) = pts()
        .filter(|p| p.dev > 0.0)
        .fold((f64::MAX, 0.0f64), |(a, b), p| {
            (
                a.min(p.lo.unwrap_or(p.dev).max(p.dev / 10.0)),
                b.max(p.hi.unwrap_or(p.dev).min(p.dev * 10.0)),
            )
        });
    if !(t1 > 0.0 && hi > 0.0) {
        return Err("nothing to plot".into());
    }
    let root = SVGBackend::new(path, (960, 640)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(80)
        .build_cartesian_2d(
            (t0 / 1.5..t1 * 1.5).log_scale(),
            (lo / 3.0..hi * 3.0).log_scale(),
        )?;
    chart
        .configure_mesh()
        .x_desc("τ (s)")
        .y_desc(format!("σ(τ) ({unit})"))
        .x_label_formatter(&|v| format!("{v:.0e}"))
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .draw()?;
    for (i, c) in curves.iter().enumerate() {
        let col = COLOURS[i % COLOURS.len()];
        chart
            .draw_series(LineSeries::new(
                c.points.iter().map(|p| (p.tau, p.dev)),
                col.stroke_width(2),
            ))?
            .label(c.label.clone())
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], col.stroke_width(2)));
        // The confidence intervals, as bars.
        chart.draw_series(c.points.iter().filter_map(|p| {
            let (lo, hi) = (p.lo?, p.hi?);
            Some(PathElement::new(
                [(p.tau, lo), (p.tau, hi)],
                col.stroke_width(1),
            ))
        }))?;
        chart.draw_series(c.points.iter().map(|p| {
            let style = if p.few_clusters {
                col.stroke_width(1)
            } else {
                col.filled()
            };
            Circle::new((p.tau, p.dev), 3, style)
        }))?;
    }
    // The fitted model and its terms' asymptotes.
    let taus: Vec<f64> = (0..=200)
        .map(|i| t0 * (t1 / t0).powf(i as f64 / 200.0))
        .collect();
    for (i, (label, t)) in fits.iter().enumerate() {
        let col = COLOURS[i % COLOURS.len()].mix(0.7);
        // The model where it was fitted: below `tau_min_s` the fit left
        // the shortest points out (see `fit::fit`), and says so.
        let fitted: Vec<f64> = taus
            .iter()
            .copied()
            .filter(|&tau| tau >= t.tau_min_s * (1.0 - 1e-9))
            .collect();
        chart
            .draw_series(LineSeries::new(
                fitted
                    .iter()
                    .map(|&tau| (tau, model(t, tau).iter().sum::<f64>().sqrt())),
                BLACK.mix(0.8).stroke_width(1),
            ))?
            .label(format!(
                "{label}: noise model fit ({})",
                if t.fits {
                    "describes the curve"
                } else {
                    "does not describe the curve"
                }
            ))
            .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK.mix(0.8)));
        for k in 0..model(t, t.tau0).len() {
            if model(t, t.tau_max_s)[k] <= 0.0 {
                continue;
            }
            // Dashes: every other segment of the asymptote.
            let seg: Vec<(f64, f64)> = fitted
                .iter()
                .map(|&tau| (tau, model(t, tau)[k].sqrt()))
                .filter(|&(_, v)| v >= lo / 3.0 && v <= hi * 3.0)
                .collect();
            for (j, w) in seg.windows(2).enumerate() {
                if j % 4 < 2 {
                    chart.draw_series(LineSeries::new(w.iter().copied(), col.stroke_width(1)))?;
                }
            }
        }
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}
