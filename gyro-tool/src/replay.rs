//! `gyro replay`: the board's fusion over a multi-gyro log. Each column is
//! one chip's rate about the same axis (as `gyro decode --what raw` writes
//! them, or any logger); every sample is fused exactly as the firmware
//! fuses an axis: the online relative calibration (`algo::calib`) takes
//! each chip's scale and bias out, then the adaptive fusion (`algo::fusion`:
//! median gate, frozen-chip check, inverse-variance weights learnt online)
//! weighs them. A NaN or empty cell is a chip that did not answer.
//!
//! Each sample also gives the array's noise probe (`fusion::noise_probe`):
//! noise with the fused rate's variance and none of the motion, whose
//! Allan deviation is the fused gyro's noise even on a moving vehicle,
//! where the fused rate's own is mostly the motion.
//!
//! Not replayed: the drivers' checks (parity, stuck raw counts, restarts),
//! which need the chips' register reads; a log of rates does not carry them.
//!
//! The picture: the chips' rates and the fused rate; each chip's weight
//! over time; and a strip per chip where fusion used it (colour) or left it
//! out (grey).

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};

use gyro_array::algo::calib::{CalConfig, RelCal};
use gyro_array::algo::fusion::{AdaptiveConfig, AxisState, Fusion, Method};
use plotters::prelude::*;

use crate::plot::COLOURS;
use crate::Res;

/// Most chips a replay takes (the firmware's fixed array size).
pub const MAX_CHIPS: usize = 8;

/// The replay of one log.
pub struct Replay {
    /// Fused rate per sample (NaN where no fused value).
    pub fused: Vec<f64>,
    /// Per sample, each chip's weight (0 when not used).
    pub weights: Vec<[f32; MAX_CHIPS]>,
    /// The noise probe per sample (NaN where fewer than two chips fused).
    pub probe: Vec<f64>,
    /// Samples on which fusion's noise model read an error the chips
    /// share (`AxisState::shared_error`): the probe cannot see that part.
    pub shared: usize,
    /// Per chip, samples it answered and samples fusion used it.
    pub offered: Vec<usize>,
    pub used: Vec<usize>,
}

/// The largest rate a replay takes, °/s.
pub const RATE_MAX_DPS: f64 = 1e6;

/// Fuse `chips` (one rate series each, same length, ≤ [`MAX_CHIPS`]).
pub fn replay(chips: &[Vec<f64>]) -> Res<Replay> {
    replay_until(chips, &AtomicBool::new(false))
}

/// Every sample of `col` (named `what`) within ±[`RATE_MAX_DPS`]: one
/// beyond it is no gyro's rate, and the fusion's f32 squares (or errors
/// against it) would overflow.
pub fn check_rates(what: &str, col: &[f64]) -> Res<()> {
    match col.iter().position(|v| v.abs() > RATE_MAX_DPS) {
        Some(i) => Err(format!(
            "{what}, sample {i}: {:e} deg/s is beyond +-{RATE_MAX_DPS:e} deg/s, no gyro's rate (check the unit)",
            col[i]
        )
        .into()),
        None => Ok(()),
    }
}

/// [`replay`], given up with [`crate::Stopped`] soon after `stop` is set
/// (the Python package's Ctrl-C).
pub fn replay_until(chips: &[Vec<f64>], stop: &AtomicBool) -> Res<Replay> {
    let k = chips.len();
    if !(2..=MAX_CHIPS).contains(&k) {
        return Err(format!("a replay needs 2 to {MAX_CHIPS} chip columns, got {k}").into());
    }
    let n = chips[0].len();
    if let Some(c) = chips.iter().position(|c| c.len() != n) {
        return Err(format!(
            "chip column {c} has {} samples, column 0 has {n}: a replay needs them equal",
            chips[c].len()
        )
        .into());
    }
    // The fusion squares rates in f32 (variances, weights): a rate beyond
    // 1e6 °/s, far past any gyro's full scale (the board's chips: ±2000),
    // overflows it and every sample is refused without a word. Say so.
    for (c, col) in chips.iter().enumerate() {
        check_rates(&format!("chip column {c}"), col)?;
    }
    let fusion = Fusion::<MAX_CHIPS>::new(Method::Adaptive(AdaptiveConfig::default()))
        .map_err(|e| format!("fusion: {e:?}"))?;
    let mut st = AxisState::<MAX_CHIPS>::default();
    let mut cal = RelCal::<MAX_CHIPS>::new(CalConfig::default());
    let mut out = Replay {
        fused: Vec::with_capacity(n),
        weights: Vec::with_capacity(n),
        probe: Vec::with_capacity(n),
        shared: 0,
        offered: vec![0; k],
        used: vec![0; k],
    };
    for i in 0..n {
        if i % crate::STOP_EVERY == 0 && stop.load(Ordering::Relaxed) {
            return Err(crate::Stopped.into());
        }
        let mut y = [f32::NAN; MAX_CHIPS];
        let mut offered = 0u8;
        for (c, col) in chips.iter().enumerate() {
            let v = col[i] as f32;
            if v.is_finite() {
                y[c] = v;
                offered |= 1 << c;
                out.offered[c] += 1;
            }
        }
        let fused = cal.fuse_probed(&fusion, &mut st, &y, offered);
        out.shared += usize::from(st.shared_error());
        match fused {
            Ok((f, p)) => {
                out.fused.push(f64::from(f.rate_dps));
                out.probe.push(p.map_or(f64::NAN, f64::from));
                for (c, u) in out.used.iter_mut().enumerate() {
                    *u += usize::from(f.used() & (1 << c) != 0);
                }
                out.weights.push(f.weights);
            }
            Err(_) => {
                out.fused.push(f64::NAN);
                out.probe.push(f64::NAN);
                out.weights.push([0.0; MAX_CHIPS]);
            }
        }
    }
    Ok(out)
}

/// Overlapping Allan deviation at octave τ of the longest run of finite
/// values in `x` (sampled every `tau0` s); the run's length and the
/// points, (τ, σ).
pub fn longest_run_adev(x: &[f64], tau0: f64) -> (usize, Vec<(f64, f64)>) {
    let (mut best, mut start) = (0..0, 0);
    for (i, v) in x.iter().chain([f64::NAN].iter()).enumerate() {
        if !v.is_finite() {
            if i - start > best.len() {
                best = start..i;
            }
            start = i + 1;
        }
    }
    let run = &x[best];
    if run.len() < 16 {
        return (run.len(), Vec::new());
    }
    let pts = crate::dev::octave_oavar(run, tau0).unwrap_or_default();
    (run.len(), pts.iter().map(|p| (p.tau_s, p.adev())).collect())
}

/// Draw the replay of `chips` (named `names`, sampled every `tau0` s).
pub fn draw(
    path: &Path,
    title: &str,
    names: &[String],
    chips: &[Vec<f64>],
    r: &Replay,
    tau0: f64,
) -> Res<()> {
    let n = r.fused.len();
    let t = |i: usize| i as f64 * tau0;
    let span = 0.0..t(n.max(1));
    // Plot at most ~4000 points per line.
    let stride = (n / 4000).max(1);
    let (lo, hi) = r
        .fused
        .iter()
        .filter(|v| v.is_finite())
        .fold((f64::MAX, f64::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    let (lo, hi) = if lo <= hi { (lo, hi) } else { (-1.0, 1.0) };
    let pad = ((hi - lo) * 0.2).max(1e-6);
    let root = SVGBackend::new(path, (1000, 950)).into_drawing_area();
    root.fill(&WHITE)?;
    let (top, rest) = root.split_vertically(380);
    let (mid, bot) = rest.split_vertically(300);

    let mut chart = ChartBuilder::on(&top)
        .caption(
            format!("{title}: the chips and the fused rate"),
            ("sans-serif", 17),
        )
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(70)
        .build_cartesian_2d(span.clone(), (lo - pad)..(hi + pad))?;
    chart.configure_mesh().y_desc("rate").draw()?;
    for (c, col) in chips.iter().enumerate() {
        let colour = COLOURS[c % COLOURS.len()];
        chart
            .draw_series(LineSeries::new(
                col.iter()
                    .enumerate()
                    .step_by(stride)
                    .filter(|(_, v)| v.is_finite())
                    .map(|(i, &v)| (t(i), v.clamp(lo - pad, hi + pad))),
                colour.mix(0.35).stroke_width(1),
            ))?
            .label(names[c].clone())
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], colour));
    }
    chart
        .draw_series(LineSeries::new(
            r.fused
                .iter()
                .enumerate()
                .step_by(stride)
                .filter(|(_, v)| v.is_finite())
                .map(|(i, &v)| (t(i), v)),
            BLACK.stroke_width(2),
        ))?
        .label("fused")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK.stroke_width(2)));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;

    let mut chart = ChartBuilder::on(&mid)
        .caption("weight of each chip in the fused rate", ("sans-serif", 16))
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(70)
        .build_cartesian_2d(span.clone(), 0f64..1.0)?;
    chart.configure_mesh().y_desc("weight").draw()?;
    for c in 0..chips.len() {
        chart.draw_series(LineSeries::new(
            r.weights
                .iter()
                .enumerate()
                .step_by(stride)
                .map(|(i, w)| (t(i), f64::from(w[c]))),
            COLOURS[c % COLOURS.len()].stroke_width(2),
        ))?;
    }

    let k = chips.len();
    let mut chart = ChartBuilder::on(&bot)
        .caption(
            "in the fusion (colour), answered but left out (grey), no answer (white)",
            ("sans-serif", 16),
        )
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(70)
        .build_cartesian_2d(span, -0.5f64..k as f64 - 0.5)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("t (s)")
        .y_labels(k)
        .y_label_formatter(&|v| {
            names
                .get(v.round().max(0.0) as usize)
                .cloned()
                .unwrap_or_default()
        })
        .draw()?;
    // Runs of one state per chip, as rectangles.
    for c in 0..k {
        let state = |i: usize| -> u8 {
            if r.weights[i][c] > 0.0 {
                2
            } else if chips[c][i].is_finite() {
                1
            } else {
                0
            }
        };
        let mut i = 0;
        while i < n {
            let s = state(i);
            let mut j = i + 1;
            while j < n && state(j) == s {
                j += 1;
            }
            let fill = match s {
                2 => COLOURS[c % COLOURS.len()].filled(),
                1 => RGBColor(190, 190, 190).filled(),
                _ => WHITE.filled(),
            };
            let y = c as f64;
            chart.draw_series(std::iter::once(Rectangle::new(
                [(t(i), y - 0.35), (t(j), y + 0.35)],
                fill,
            )))?;
            i = j;
        }
    }
    root.present()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use gyro_sim::Rng;

    /// One chip per `sd`: `truth` plus white noise of that σ (drawn chip
    /// after chip).
    fn noisy_chips(truth: &[f64], sd: &[f64], rng: &mut Rng) -> Vec<Vec<f64>> {
        sd.iter()
            .map(|s| {
                truth
                    .iter()
                    .map(|t| t + s * f64::from(rng.gaussian()))
                    .collect()
            })
            .collect()
    }

    /// Four chips, one noisier and one that sticks half-way: the noisy one
    /// gets the least weight and the stuck one leaves the fusion; the fused
    /// rate is better than the plain mean.
    #[test]
    fn the_replay_weighs_and_excludes_as_the_firmware() {
        let mut rng = Rng::new(3);
        let n = 4000;
        let truth: Vec<f64> = (0..n).map(|i| 20.0 * (i as f64 * 0.003).sin()).collect();
        let mut chips = noisy_chips(&truth, &[0.05, 0.05, 0.05, 0.25], &mut rng);
        let held = chips[1][2000];
        for v in chips[1][2000..].iter_mut() {
            *v = held;
        }
        let r = replay(&chips).unwrap();
        let late = 3000..n;
        let w = |c: usize| {
            late.clone()
                .map(|i| f64::from(r.weights[i][c]))
                .sum::<f64>()
                / 1000.0
        };
        assert!(w(1) == 0.0, "the stuck chip is out: {}", w(1));
        assert!(
            w(3) < 0.1 * w(0),
            "the noisy chip weighs little: {} vs {}",
            w(3),
            w(0)
        );
        let rms = |f: &dyn Fn(usize) -> f64| {
            (late.clone().map(|i| (f(i) - truth[i]).powi(2)).sum::<f64>() / 1000.0).sqrt()
        };
        let fused = rms(&|i| r.fused[i]);
        let mean = rms(&|i| (chips[0][i] + chips[2][i] + chips[3][i]) / 3.0);
        assert!(
            fused < 0.8 * mean,
            "fused {fused} vs mean of the live chips {mean}"
        );
    }

    /// On a board turning at up to ±100 °/s, the fused rate's Allan
    /// deviation is the motion's; the probe's is the fused error's
    /// (computed from the truth), within 10 % at τ = 1–64 samples (1.5 %
    /// measured; the fused rate's reads 14–3 000× the fused error's).
    #[test]
    fn the_probe_gives_the_fused_noise_under_motion() {
        let mut rng = Rng::new(5);
        let n = 40_000;
        let truth: Vec<f64> = (0..n)
            .map(|i| 100.0 * (i as f64 * 0.002).sin() + 20.0 * (i as f64 * 0.05).sin())
            .collect();
        let chips = noisy_chips(&truth, &[0.05, 0.07, 0.1, 0.2], &mut rng);
        let r = replay(&chips).unwrap();
        let err: Vec<f64> = r.fused.iter().zip(&truth).map(|(f, t)| f - t).collect();
        let (len, probe) = longest_run_adev(&r.probe[1000..], 1e-3);
        let (_, oracle) = longest_run_adev(&err[1000..], 1e-3);
        let (_, fused) = longest_run_adev(&r.fused[1000..], 1e-3);
        assert_eq!(len, n - 1000, "a probe on every sample");
        for j in 0..7 {
            let ratio = probe[j].1 / oracle[j].1;
            assert!(
                (0.9..1.1).contains(&ratio),
                "τ = 2^{j}: probe / oracle {ratio}"
            );
        }
        assert!(
            fused[6].1 > 20.0 * oracle[6].1,
            "the fused rate holds the motion"
        );
    }
}
