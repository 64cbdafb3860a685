//! `gyro lag`: how far the rates a recording's sample frames carry lie
//! behind the instants the frames state for them, per axis, against a
//! reference rate on the board's clock (a rate table's).
//!
//! The bench measurement of what the datasheet leaves open: it gives the
//! ICM-42688-P's anti-alias and UI filters' bandwidths, not their shapes,
//! and the shapes move the signal path's delay by −52 to +354 µs
//! (docs/timing.md). The board states each instant on the datasheet's
//! reading plus the trim in force (`Settings::path_trim_us`); a lag `L`
//! measured here means the path is `L` longer than that, so the trim to
//! set is the one in force plus `L`.
//!
//! The fit, per axis: the frames' rate `r(t)` at each stated instant `t`
//! against `s · g(t − L) + b` (the reference `g`, a scale and a bias, both
//! fitted: a calibration residual must not read as a lag), least squares
//! over `L` by a scan and a parabola through the three best points; its
//! standard error from the residual and the reference's slope,
//! `σ / √Σ (s g′)²`. Any motion with a slope works; a sine of a few hertz
//! near the largest rate the range allows gives a µs in seconds.

use crate::pointing::Series;
use crate::read_recording;
use crate::Res;
use gyro_array::link::msg::Frame;

/// The scan's reach either way, µs: past the trim's own range.
pub const SPAN_US: f64 = 1500.0;
/// The scan's step, µs: fine enough that the parabola through the three
/// best points sits within a µs of the minimum on a sine.
const STEP_US: f64 = 5.0;
/// Samples an axis needs with the reference on both sides of the scan.
const MIN_SAMPLES: usize = 100;
/// Samples the scan runs on (evenly spaced among all); the minimum is
/// placed on all of them.
const SCAN_SAMPLES: usize = 20_000;
/// The reference's rms slope an axis needs, °/s per s: below it the lag
/// is not observable (about 1 °/s of sway at 0.2 Hz).
const MIN_SLOPE: f64 = 1.0;

/// One axis's fit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AxisLag {
    /// How far the rates lie behind their stated instants, µs (positive:
    /// the rate is older than stated, the path longer than the board
    /// takes it).
    pub lag_us: f64,
    /// Its standard error, µs.
    pub sd_us: f64,
    /// The fitted scale against the reference.
    pub scale: f64,
    /// The fitted bias, °/s.
    pub bias_dps: f64,
    /// The residual's rms, °/s.
    pub residual_dps: f64,
    /// Samples used.
    pub used: usize,
    /// The reference's rms slope over them, °/s per s.
    pub slope_dps_s: f64,
}

/// Scale, bias and the sum of squared residuals of `r` against `g`.
fn line(r: &[f64], g: &[f64]) -> (f64, f64, f64) {
    let n = r.len() as f64;
    let (mr, mg) = (r.iter().sum::<f64>() / n, g.iter().sum::<f64>() / n);
    let (mut sgg, mut sgr, mut srr) = (0.0, 0.0, 0.0);
    for (&ri, &gi) in r.iter().zip(g) {
        let (dg, dr) = (gi - mg, ri - mr);
        sgg += dg * dg;
        sgr += dg * dr;
        srr += dr * dr;
    }
    if sgg <= 0.0 {
        return (0.0, mr, srr);
    }
    let s = sgr / sgg;
    (s, mr - s * mg, (srr - s * sgr).max(0.0))
}

/// The lag of `rate` (stated at `at_us`, board µs) behind `truth` (the
/// reference at a board µs), scanned within ±[`SPAN_US`]; `None` where
/// fewer than [`MIN_SAMPLES`] samples have the reference on both sides
/// or the reference barely moves (below [`MIN_SLOPE`]).
pub fn fit(
    at_us: &[f64],
    rate: &[f64],
    truth: &dyn Fn(f64) -> f64,
    covered: (f64, f64),
) -> Option<AxisLag> {
    let (t, r): (Vec<f64>, Vec<f64>) = at_us
        .iter()
        .zip(rate)
        .filter(|&(&t, &r)| {
            r.is_finite() && t - SPAN_US - 100.0 >= covered.0 && t + SPAN_US + 100.0 <= covered.1
        })
        .map(|(&t, &r)| (t, r))
        .unzip();
    if t.len() < MIN_SAMPLES {
        return None;
    }
    let h = 50.0;
    let slope_ms = t
        .iter()
        .map(|&x| ((truth(x + h) - truth(x - h)) / (2.0 * h * 1e-6)).powi(2))
        .sum::<f64>()
        / t.len() as f64;
    let slope_rms = slope_ms.sqrt();
    if slope_rms.is_nan() || slope_rms < MIN_SLOPE {
        return None;
    }
    let mut g = vec![0.0; t.len()];
    // The residual at `lag` over samples `ts`, `rs`.
    let mut ssr = |ts: &[f64], rs: &[f64], lag: f64| {
        for (gi, &x) in g.iter_mut().zip(ts) {
            *gi = truth(x - lag);
        }
        line(rs, &g[..ts.len()]).2
    };
    // The scan on at most SCAN_SAMPLES of them, evenly spaced (a long
    // recording's would take minutes), the minimum's parabola on all.
    let stride = t.len().div_ceil(SCAN_SAMPLES).max(1);
    let (ts, rs): (Vec<f64>, Vec<f64>) = t.iter().zip(&r).step_by(stride).unzip();
    let steps = (SPAN_US / STEP_US) as i64;
    let scan: Vec<(f64, f64)> = (-steps..=steps)
        .map(|k| {
            let lag = k as f64 * STEP_US;
            (lag, ssr(&ts, &rs, lag))
        })
        .collect();
    let k = (0..scan.len()).min_by(|&a, &b| scan[a].1.total_cmp(&scan[b].1))?;
    let mut lag = scan[k].0;
    if k > 0 && k + 1 < scan.len() {
        let (y0, y1, y2) = (
            ssr(&t, &r, lag - STEP_US),
            ssr(&t, &r, lag),
            ssr(&t, &r, lag + STEP_US),
        );
        let curv = y0 - 2.0 * y1 + y2;
        if curv > 0.0 {
            lag += 0.5 * STEP_US * (y0 - y2) / curv;
        }
    }
    for (gi, &x) in g.iter_mut().zip(&t) {
        *gi = truth(x - lag);
    }
    let (scale, bias, ss) = line(&r, &g);
    let n = t.len();
    let sigma2 = ss / (n.saturating_sub(3).max(1)) as f64;
    // The slope at the fitted lag, in °/s per µs, times the scale.
    let info: f64 = t
        .iter()
        .map(|&x| {
            let d = scale * (truth(x - lag + h) - truth(x - lag - h)) / (2.0 * h);
            d * d
        })
        .sum();
    Some(AxisLag {
        lag_us: lag,
        sd_us: (sigma2 / info.max(1e-300)).sqrt(),
        scale,
        bias_dps: bias,
        residual_dps: (ss / n as f64).sqrt(),
        used: n,
        slope_dps_s: slope_rms,
    })
}

/// The inverse-variance mean of the axes' lags and its standard error.
pub fn combined(axes: &[AxisLag]) -> Option<(f64, f64)> {
    let w: f64 = axes
        .iter()
        .map(|a| 1.0 / (a.sd_us * a.sd_us).max(1e-12))
        .sum();
    if axes.is_empty() || w.is_nan() || w <= 0.0 {
        return None;
    }
    let m = axes
        .iter()
        .map(|a| a.lag_us / (a.sd_us * a.sd_us).max(1e-12))
        .sum::<f64>()
        / w;
    Some((m, w.sqrt().recip()))
}

/// What a recording's sample frames give the fit, per axis: the stated
/// instants and the rates (frames whose rates the board predicted to a
/// later instant are counted, not used: the prediction's own error on the
/// motion would read as a lag), and the trim the last status frame states.
pub struct Stated {
    pub at_us: [Vec<f64>; 3],
    pub rate: [Vec<f64>; 3],
    pub predicted: usize,
    pub trim_us: Option<i16>,
}

/// The frames' stated instants and rates ([`Stated`]).
pub fn stated(frames: &[Frame]) -> Stated {
    let mut s = Stated {
        at_us: Default::default(),
        rate: Default::default(),
        predicted: 0,
        trim_us: None,
    };
    for f in frames {
        match f {
            Frame::Status(st) => s.trim_us = Some(st.settings.path_trim_us),
            Frame::Sample(x) if x.predicted_us.is_some() => s.predicted += 1,
            Frame::Sample(x) => {
                for a in 0..3 {
                    if x.valid & (1 << a) != 0 {
                        s.at_us[a].push(x.t_us as f64 - f64::from(x.age_us[a]));
                        s.rate[a].push(f64::from(x.rate_dps[a]));
                    }
                }
            }
            _ => {}
        }
    }
    s
}

/// `gyro lag FILE --truth CSV`.
pub fn run(file: &std::path::Path, truth: &std::path::PathBuf) -> Res<bool> {
    let (frames, _) = read_recording(file)?;
    let bodies: Vec<Frame> = frames.into_iter().flatten().map(|d| d.body).collect();
    let reference = Series::from_csv(truth)?;
    let s = stated(&bodies);
    let frames_used = s.at_us.iter().map(Vec::len).max().unwrap_or(0);
    println!(
        "{}: {} sample frames with stated instants{}, against {}; the path trim in force {}",
        file.display(),
        frames_used,
        if s.predicted > 0 {
            format!(
                " ({} frames predicted by the board left out: record with --send compensation=off)",
                s.predicted
            )
        } else {
            String::new()
        },
        truth.display(),
        s.trim_us
            .map_or("not stated (no status frame)".into(), |t| format!("{t} µs"))
    );
    let covered = reference.covered();
    let mut fitted = Vec::new();
    println!(
        "{:<5} {:>9} {:>8} {:>9} {:>10} {:>13} {:>8} {:>13}",
        "axis", "lag µs", "± µs", "scale", "bias °/s", "residual °/s", "samples", "slope °/s²"
    );
    for a in 0..3 {
        let g = |t: f64| reference.value(a, t);
        match fit(&s.at_us[a], &s.rate[a], &g, covered) {
            Some(f) => {
                println!(
                    "{:<5} {:>+9.1} {:>8.1} {:>9.5} {:>+10.4} {:>13.4} {:>8} {:>13.1}",
                    ["x", "y", "z"][a],
                    f.lag_us,
                    f.sd_us,
                    f.scale,
                    f.bias_dps,
                    f.residual_dps,
                    f.used,
                    f.slope_dps_s
                );
                fitted.push(f);
            }
            None => println!(
                "{:<5} no lag: fewer than {MIN_SAMPLES} frames inside the reference, or the reference's slope below {MIN_SLOPE} °/s²",
                ["x", "y", "z"][a]
            ),
        }
    }
    let Some((lag, sd)) = combined(&fitted) else {
        println!("no axis moved enough to measure a lag");
        return Ok(false);
    };
    println!("combined (inverse-variance): {lag:+.1} ± {sd:.1} µs");
    match s.trim_us {
        Some(t) => {
            let next = (f64::from(t) + lag).round();
            let max = f64::from(gyro_array::link::msg::MAX_PATH_TRIM_US);
            if next.abs() > max {
                println!(
                    "the trim this asks for, {next:+.0} µs, is past the board's ±{max:.0} µs: a path this far from the datasheet's reading is not the ICM-42688-P's filters (check the reference's clock)"
                );
                return Ok(false);
            }
            println!("set it: --send path-trim={next:.0} --send save (the trim in force {t:+} µs plus the lag)");
        }
        None => println!(
            "set the trim to the one in force plus {lag:+.0} µs (--send path-trim=N --send save)"
        ),
    }
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A lag of 37.3 µs on 100 000 samples of a 3 Hz sine (the scan on a
    /// fifth of them): read to a tenth of a µs, its scale and bias too; a
    /// reference that does not move gives no lag.
    #[test]
    fn a_long_recordings_lag_is_read_to_a_fraction_of_a_microsecond() {
        let truth = |t_us: f64| 80.0 * (2.0 * core::f64::consts::PI * 3.0 * t_us * 1e-6).sin();
        let at: Vec<f64> = (0..100_000).map(|k| 5_000.0 + k as f64 * 1000.0).collect();
        let mut noise = 0x2545_F491_4F6C_DD1Du64;
        let rate: Vec<f64> = at
            .iter()
            .map(|&t| {
                noise ^= noise << 13;
                noise ^= noise >> 7;
                noise ^= noise << 17;
                let n = (noise >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
                0.99 * truth(t - 37.3) + 0.2 + 0.05 * n
            })
            .collect();
        let f = fit(&at, &rate, &truth, (f64::MIN, f64::MAX)).unwrap();
        assert!((f.lag_us - 37.3).abs() < 0.1, "{f:?}");
        assert!(
            (f.scale - 0.99).abs() < 1e-4 && (f.bias_dps - 0.2).abs() < 1e-3,
            "{f:?}"
        );
        assert!(f.sd_us < 0.1, "{f:?}");
        assert_eq!(f.used, 100_000);
        let still = |_: f64| 1.0;
        assert_eq!(fit(&at, &rate, &still, (f64::MIN, f64::MAX)), None);
    }
}
