//! `gyro pointing`: a recording through the reference stabilisation loop
//! (`crate::antenna`), per axis: the pointing error the stream
//! leaves at the beam, against the ideal gyro's, and its split.
//!
//! The frames reach the antenna at the end of their own transmission
//! (`t_us` plus the loop's budgeted time and the largest frame on the
//! wire: `link::port::Port::horizon_us`); the positioner holds each until
//! the next. Each frame's rates describe the instant the frame states
//! (`t_us − age_us`, or `t_us + predicted_us` when the board predicted
//! them). The ideal gyro is the motion itself, sampled at each arrival.
//!
//! With a reference (`--truth`, the true rate on the board's clock: an
//! emulated run's, or a rate table's), the motion is the truth and the
//! error splits exactly, the loop being linear while no limit is reached:
//!
//! - **delay**: the truth at each frame's stated instant, through the same
//!   arrivals, less the ideal gyro;
//! - **calibration**: the frames' rate error against that, fitted by a
//!   scale and a bias per axis;
//! - **faults**: the rest of the error on frames where a gyro was flagged;
//! - **noise**: the rest on the other frames.
//!
//! Without one, the recorded motion stands for the truth: the delay's share
//! is what the stated delay costs on that motion (about 0 when the board
//! predicted the rates to the frame's end), the noise's is white noise of
//! the fused rate's own σ at τ0 (the frames' E-DAVAR estimates) through
//! the board's prediction and the loop; calibration and faults need the
//! reference.

use std::path::PathBuf;

use crate::antenna::{fit_line, stats, ErrorStats, Loop, LoopParams};
use gyro_array::algo::predict::Predictor;
use gyro_array::link::msg::Frame;
use gyro_array::link::port::{RingPort, PREDICT_K};

use super::{read_recording, Res};

/// One sample frame, as the loop sees it.
struct Frm {
    t_us: u64,
    /// Per axis, the instant the rate describes, µs (board clock).
    at_us: [f64; 3],
    rate: [f64; 3],
    /// The measurement's age before `t_us` (`age_us`), µs.
    age_us: [f64; 3],
    predicted: Option<u16>,
    flagged: bool,
}

/// Simulation steps per millisecond (the loop's 10 µs).
const SUB: usize = 100;

/// A rate series on the board's clock, read linearly between its points.
pub struct Series {
    t_us: Vec<f64>,
    rate: Vec<[f64; 3]>,
}

impl Series {
    /// The rate on axis `a` at `t` (µs), `hint` the index last found.
    fn at(&self, a: usize, t: f64, hint: &mut usize) -> f64 {
        let n = self.t_us.len();
        if n == 0 {
            return 0.0;
        }
        while *hint + 1 < n && self.t_us[*hint + 1] <= t {
            *hint += 1;
        }
        while *hint > 0 && self.t_us[*hint] > t {
            *hint -= 1;
        }
        let k1 = (*hint + 1).min(n - 1);
        let span = self.t_us[k1] - self.t_us[*hint];
        let (r0, r1) = (self.rate[*hint][a], self.rate[k1][a]);
        if span <= 0.0 {
            return r0;
        }
        r0 + ((t - self.t_us[*hint]) / span).clamp(0.0, 1.0) * (r1 - r0)
    }

    /// The rate on axis `a` at `t` (µs), read linearly; the end values
    /// outside.
    pub fn value(&self, a: usize, t: f64) -> f64 {
        let mut hint = self.t_us.partition_point(|&x| x <= t).saturating_sub(1);
        self.at(a, t, &mut hint)
    }

    /// The first and last instants, µs.
    pub fn covered(&self) -> (f64, f64) {
        (
            self.t_us.first().copied().unwrap_or(0.0),
            self.t_us.last().copied().unwrap_or(0.0),
        )
    }

    /// A `t_us,x_dps,y_dps,z_dps` CSV (a header line, then rows in time
    /// order).
    pub fn from_csv(path: &PathBuf) -> Res<Self> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let mut s = Self {
            t_us: Vec::new(),
            rate: Vec::new(),
        };
        for (i, line) in text.lines().enumerate().skip(1) {
            let v: Vec<f64> = line
                .split(',')
                .map(|x| x.trim().parse::<f64>())
                .collect::<Result<_, _>>()
                .map_err(|e| format!("{}:{}: {e}", path.display(), i + 1))?;
            let [t, x, y, z] = v[..] else {
                return Err(format!(
                    "{}:{}: expected t_us,x_dps,y_dps,z_dps",
                    path.display(),
                    i + 1
                )
                .into());
            };
            if s.t_us.last().is_some_and(|&l| t <= l) || !t.is_finite() {
                return Err(format!("{}:{}: time not increasing", path.display(), i + 1).into());
            }
            if ![x, y, z].iter().all(|v| v.is_finite()) {
                return Err(
                    format!("{}:{}: a rate that is not a number", path.display(), i + 1).into(),
                );
            }
            s.t_us.push(t);
            s.rate.push([x, y, z]);
        }
        if s.t_us.len() < 2 {
            return Err(format!("{}: fewer than two rows", path.display()).into());
        }
        Ok(s)
    }
}

/// What [`analyse`] finds, per axis: pointing-error series (one a
/// millisecond, from the score's start) and the motion.
pub struct Report {
    pub frames: usize,
    /// Times the board's clock went back (a reset): only the longest
    /// stretch of rising time is run through the loop.
    pub restarts: usize,
    pub predicted: usize,
    pub flagged: usize,
    pub after_us: f64,
    pub skip_ms: usize,
    /// The stream's error against the ideal gyro's.
    pub total: [Vec<f64>; 3],
    pub delay: [Vec<f64>; 3],
    pub noise: [Vec<f64>; 3],
    /// With a reference only.
    pub calibration: Option<[Vec<f64>; 3]>,
    pub faults: Option<[Vec<f64>; 3]>,
    pub motion: [Vec<f64>; 3],
}

/// The loop against `motion` (µs → °/s; or none: an error signal alone),
/// fed `feed[k]` from `arrive[k]` (µs); the pointing error each
/// millisecond past `skip`.
fn through(
    lp: &Loop,
    motion: Option<&mut dyn FnMut(f64) -> f64>,
    t0: f64,
    arrive: &[f64],
    feed: &[f64],
    ms: usize,
    skip: usize,
) -> Vec<f64> {
    let arrive_s: Vec<f64> = arrive.iter().map(|t| t * 1e-6).collect();
    let feed: Vec<[f64; 1]> = feed.iter().map(|&v| [v]).collect();
    let mut out = Vec::with_capacity(ms.saturating_sub(skip));
    let mut in_s = motion.map(|m| move |t: f64| [m(t * 1e6)]);
    lp.run_held(
        in_s.as_mut().map(|m| m as &mut dyn FnMut(f64) -> [f64; 1]),
        t0 * 1e-6,
        ms * SUB,
        &arrive_s,
        &feed,
        1e-3,
        |j, _, e| {
            if (j + 1) % SUB == 0 && (j + 1) / SUB > skip {
                out.push(e[0]);
            }
        },
    );
    out
}

/// Run the sample frames among `frames` through the reference loop,
/// against `truth` where given; `None` with fewer than 100 frames whose
/// every axis is valid.
pub fn analyse(frames: &[Frame], truth: Option<&Series>) -> Option<Report> {
    let mut fr: Vec<Frm> = Vec::new();
    let mut sigma: [Vec<f64>; 3] = Default::default();
    let mut tau0_is_one = true;
    for body in frames {
        match body {
            Frame::Status(s) => tau0_is_one = s.noise_tau[0] == 1,
            Frame::Sample(s) if s.valid == 0b111 => {
                let t = s.t_us as f64;
                fr.push(Frm {
                    t_us: s.t_us,
                    at_us: core::array::from_fn(|a| match s.predicted_us {
                        Some(p) => t + f64::from(p),
                        None => t - f64::from(s.age_us[a]),
                    }),
                    rate: s.rate_dps.map(f64::from),
                    age_us: s.age_us.map(f64::from),
                    predicted: s.predicted_us,
                    flagged: s.health.iter().any(|h| *h != 0),
                });
                if let Some(n) = s.noise {
                    if let Some(v) = sigma.get_mut(usize::from(n.axis)) {
                        v.push(f64::from(n.sigma_dps[0]));
                    }
                }
            }
            _ => {}
        }
    }
    // A board reset starts t_us again: the loop runs over the longest
    // stretch of rising board time, and the report says how many restarts
    // it left out.
    let mut restarts = 0usize;
    let (mut best, mut start) = ((0usize, 0usize), 0usize);
    for i in 1..=fr.len() {
        if i == fr.len() || fr[i].t_us <= fr[i - 1].t_us {
            if i < fr.len() {
                restarts += 1;
            }
            if i - start > best.1 - best.0 {
                best = (start, i);
            }
            start = i;
        }
    }
    fr.truncate(best.1);
    fr.drain(..best.0);
    if fr.len() < 100 {
        return None;
    }
    let after_us = f64::from(
        RingPort::<64>::new(Default::default(), gyro_array::app::BOARD_FRAME_PATH)
            .horizon_us()
            .unwrap_or(0),
    );
    let lp = Loop::new(LoopParams::VEHICLE);
    let t0 = fr[0].t_us as f64;
    let arrive: Vec<f64> = fr.iter().map(|f| f.t_us as f64 + after_us).collect();
    let ms = (fr.last().map_or(0, |f| f.t_us).saturating_sub(fr[0].t_us) / 1000) as usize;
    // Scored after the loops settle (2 s).
    let skip = 2000usize.min(ms / 2);
    // The recorded motion: each frame's rates at the instants they describe.
    let recorded: [Series; 3] = core::array::from_fn(|a| Series {
        t_us: fr.iter().map(|f| f.at_us[a]).collect(),
        rate: fr.iter().map(|f| [f.rate[a]; 3]).collect(),
    });
    let motion_at = |a: usize, t: f64, hint: &mut usize| match truth {
        Some(s) => s.at(a, t, hint),
        None => recorded[a].at(a, t, hint),
    };
    let mut r = Report {
        frames: fr.len(),
        restarts,
        predicted: fr.iter().filter(|f| f.predicted.is_some()).count(),
        flagged: fr.iter().filter(|f| f.flagged).count(),
        after_us,
        skip_ms: skip,
        total: Default::default(),
        delay: Default::default(),
        noise: Default::default(),
        calibration: truth.map(|_| Default::default()),
        faults: truth.map(|_| Default::default()),
        motion: Default::default(),
    };
    for a in 0..3 {
        let mut h = 0usize;
        let mut motion = |t: f64| motion_at(a, t, &mut h);
        let run = |feed: &[f64], motion: Option<&mut dyn FnMut(f64) -> f64>| {
            through(&lp, motion, t0, &arrive, feed, ms, skip)
        };
        let mut h2 = 0usize;
        let ideal: Vec<f64> = arrive.iter().map(|&t| motion_at(a, t, &mut h2)).collect();
        let mut h3 = 0usize;
        let stated: Vec<f64> = fr
            .iter()
            .map(|f| motion_at(a, f.at_us[a], &mut h3))
            .collect();
        let rates: Vec<f64> = fr.iter().map(|f| f.rate[a]).collect();
        let e_ideal = run(&ideal, Some(&mut motion));
        let e_frames = run(&rates, Some(&mut motion));
        let e_stated = run(&stated, Some(&mut motion));
        r.total[a] = e_frames.iter().zip(&e_ideal).map(|(x, y)| x - y).collect();
        r.delay[a] = e_stated.iter().zip(&e_ideal).map(|(x, y)| x - y).collect();
        let mut h4 = 0usize;
        r.motion[a] = (skip..ms)
            .map(|k| motion_at(a, t0 + (k + 1) as f64 * 1000.0, &mut h4))
            .collect();
        if truth.is_some() {
            // The rate error against the truth at the stated instants:
            // scale and bias fitted, the rest split by the health flags.
            let eps: Vec<f64> = rates.iter().zip(&stated).map(|(x, s)| x - s).collect();
            let scored = |k: usize| fr[k].t_us as f64 - t0 >= skip as f64 * 1000.0;
            let (m, b) = fit_line(
                (0..fr.len())
                    .filter(|&k| scored(k) && !fr[k].flagged)
                    .map(|k| (stated[k], eps[k])),
                0.0,
            );
            let cal: Vec<f64> = stated.iter().map(|x| m * x + b).collect();
            let rest = |k: usize| eps[k] - cal[k];
            let faults: Vec<f64> = (0..fr.len())
                .map(|k| if fr[k].flagged { rest(k) } else { 0.0 })
                .collect();
            let noise: Vec<f64> = (0..fr.len())
                .map(|k| if fr[k].flagged { 0.0 } else { rest(k) })
                .collect();
            if let Some(c) = r.calibration.as_mut() {
                c[a] = run(&cal, None);
            }
            if let Some(f) = r.faults.as_mut() {
                f[a] = run(&faults, None);
            }
            r.noise[a] = run(&noise, None);
        } else {
            // White noise of the fused rate's σ(τ0), as the board sent it,
            // through its prediction where the frames were predicted.
            let mut sig = sigma[a].clone();
            sig.sort_by(f64::total_cmp);
            let s = if tau0_is_one && !sig.is_empty() {
                sig[sig.len() / 2]
            } else {
                0.0
            };
            let mut pred = Predictor::<PREDICT_K>::new();
            let mut rng: u64 = 0x9E37_79B9_7F4A_7C15 ^ a as u64;
            let mut gauss = || {
                // Box–Muller on a xorshift stream: reproducible.
                let mut u = || {
                    rng ^= rng << 13;
                    rng ^= rng >> 7;
                    rng ^= rng << 17;
                    ((rng >> 11) as f64 + 0.5) / (1u64 << 53) as f64
                };
                let (u1, u2) = (u(), u());
                (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
            };
            let noise: Vec<f64> = fr
                .iter()
                .map(|f| {
                    let w = s * gauss();
                    pred.push([w as f32, 0.0, 0.0]);
                    match f.predicted {
                        Some(h) => {
                            // As the board reads its line: from the
                            // measurement's instant to the stated one.
                            let ahead = (f.age_us[a] + f64::from(h)) / 1000.0;
                            pred.at([ahead as f32, 0.0, 0.0])
                                .map_or(w, |v| f64::from(v[0]))
                        }
                        None => w,
                    }
                })
                .collect();
            r.noise[a] = run(&noise, None);
        }
    }
    Some(r)
}

pub fn run(file: &std::path::Path, truth: Option<&PathBuf>, svg: Option<&PathBuf>) -> Res<bool> {
    let (frames, _) = read_recording(file)?;
    let bodies: Vec<Frame> = frames.into_iter().flatten().map(|d| d.body).collect();
    let truth = truth.map(Series::from_csv).transpose()?;
    let Some(r) = analyse(&bodies, truth.as_ref()) else {
        println!(
            "{}: fewer than 100 sample frames with every axis valid",
            file.display()
        );
        return Ok(false);
    };
    let p = LoopParams::VEHICLE;
    if r.restarts > 0 {
        println!(
            "{}: the board's time went back {} times (a reset): the longest stretch of rising time is analysed",
            file.display(),
            r.restarts
        );
    }
    println!(
        "{}: {} sample frames ({} predicted by the board, {} with a gyro flagged); reference loop {} Hz rate loop, {} Hz tracking; frames at the antenna {:.0} µs after t_us; scored from {:.1} s; against {}",
        file.display(),
        r.frames,
        r.predicted,
        r.flagged,
        p.rate_bw_hz,
        p.track_hz,
        r.after_us,
        r.skip_ms as f64 * 1e-3,
        if truth.is_some() { "the reference" } else { "the recorded motion (no reference given)" }
    );
    let show = |name: &str, e: &[Vec<f64>; 3]| {
        let s: Vec<ErrorStats> = e.iter().map(|v| stats(&mut v.clone())).collect();
        println!(
            "  {name:<40} rms {:.4} / {:.4} / {:.4}   p99.9 {:.4} / {:.4} / {:.4}   max {:.4} / {:.4} / {:.4} °",
            s[0].rms, s[1].rms, s[2].rms, s[0].p999, s[1].p999, s[2].p999, s[0].max, s[1].max, s[2].max
        );
    };
    println!("pointing error the stream adds to the ideal gyro's, x / y / z:");
    if truth.is_some() {
        show("total", &r.total);
        show("  from the stated delay", &r.delay);
        if let Some(c) = &r.calibration {
            show("  from calibration (scale, bias)", c);
        }
        show("  from noise", &r.noise);
        if let Some(f) = &r.faults {
            show("  from faults (frames with a gyro flagged)", f);
        }
    } else {
        let total: [Vec<f64>; 3] = core::array::from_fn(|a| {
            r.delay[a]
                .iter()
                .zip(&r.noise[a])
                .map(|(d, n)| d + n)
                .collect()
        });
        show("delay + noise", &total);
        show("  from the stated delay", &r.delay);
        show("  from noise (E-DAVAR σ at τ0)", &r.noise);
        println!(
            "  calibration residuals and faults: not observable without a reference (--truth)"
        );
    }
    if let Some(path) = svg {
        // The axis that moved most, its first 10 s scored.
        let spread = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / v.len().max(1) as f64;
            v.iter().map(|x| (x - m) * (x - m)).sum::<f64>()
        };
        let a = (0..3)
            .max_by(|&i, &j| spread(&r.motion[i]).total_cmp(&spread(&r.motion[j])))
            .unwrap_or(0);
        let cut = |v: &[f64]| v[..v.len().min(10_000)].to_vec();
        let total = if truth.is_some() {
            cut(&r.total[a])
        } else {
            cut(&r.delay[a]
                .iter()
                .zip(&r.noise[a])
                .map(|(d, n)| d + n)
                .collect::<Vec<_>>())
        };
        draw(
            path,
            ["x", "y", "z"][a],
            &cut(&r.motion[a]),
            &total,
            &cut(&r.delay[a]),
        )
        .map_err(|e| format!("{}: {e}", path.display()))?;
        println!(
            "drawn: {} (axis {}, the one that moved most)",
            path.display(),
            ["x", "y", "z"][a]
        );
    }
    Ok(true)
}

fn draw(
    path: &PathBuf,
    axis: &str,
    motion: &[f64],
    total: &[f64],
    delay: &[f64],
) -> Result<(), String> {
    use plotters::prelude::*;
    let root = SVGBackend::new(path, (1000, 700)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| e.to_string())?;
    let (top, bottom) = root.split_vertically(300);
    let n = motion.len().min(total.len()).min(delay.len());
    let x = |k: usize| k as f64 * 1e-3;
    let lim = |v: &[f64]| v.iter().fold(1e-6f64, |m, y| m.max(y.abs())) * 1.1;
    let mut c = ChartBuilder::on(&top)
        .caption(format!("rate on {axis} (the motion)"), ("sans-serif", 16))
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..x(n), -lim(&motion[..n])..lim(&motion[..n]))
        .map_err(|e| e.to_string())?;
    c.configure_mesh()
        .x_desc("s from the score's start")
        .y_desc("deg/s")
        .draw()
        .map_err(|e| e.to_string())?;
    c.draw_series(LineSeries::new((0..n).map(|k| (x(k), motion[k])), BLACK))
        .map_err(|e| e.to_string())?;
    let l = lim(&total[..n]).max(lim(&delay[..n]));
    let mut c = ChartBuilder::on(&bottom)
        .caption(
            format!("pointing error on {axis} the stream adds, and its delay's share"),
            ("sans-serif", 16),
        )
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(60)
        .build_cartesian_2d(0.0..x(n), -l..l)
        .map_err(|e| e.to_string())?;
    c.configure_mesh()
        .x_desc("s from the score's start")
        .y_desc("degrees")
        .draw()
        .map_err(|e| e.to_string())?;
    for (name, v, col) in [("added", total, BLUE), ("its delay's share", delay, RED)] {
        c.draw_series(LineSeries::new((0..n).map(|k| (x(k), v[k])), col))
            .map_err(|e| e.to_string())?
            .label(name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], col));
    }
    c.configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|e| e.to_string())?;
    root.present().map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;
    use gyro_array::link::msg::Sample;

    /// A sine of `a` °/s at `hz` on x, frames at 1 kHz stating `age` µs,
    /// the rate `scale` times the truth plus `bias`; gyro 0 flagged and
    /// its frames off by `fault` on frames 6 000..6 100.
    fn frames(
        a: f64,
        hz: f64,
        age: u16,
        seconds: u32,
        scale: f64,
        bias: f64,
        fault: f64,
    ) -> Vec<Frame> {
        (0..seconds * 1000)
            .map(|k| {
                let t_us = 1_000 * u64::from(k) + 1_000;
                let at = (t_us as f64 - f64::from(age)) * 1e-6;
                let faulty = (6000..6100).contains(&k);
                let w = scale * a * (2.0 * std::f64::consts::PI * hz * at).sin()
                    + bias
                    + if faulty { fault } else { 0.0 };
                Frame::Sample(Sample {
                    seq: k,
                    t_us,
                    age_us: [age; 3],
                    predicted_us: None,
                    rate_dps: [w as f32, 0.0, 0.0],
                    valid: 0b111,
                    degraded: 0,
                    used: [0b1111; 3],
                    health: [u8::from(faulty), 0, 0, 0, 0].into_iter().collect(),
                    noise: None,
                    angle: None,
                })
            })
            .collect()
    }

    fn truth(a: f64, hz: f64, seconds: u32) -> Series {
        let n = seconds as usize * 10_000 + 100;
        Series {
            t_us: (0..n).map(|k| k as f64 * 100.0).collect(),
            rate: (0..n)
                .map(|k| {
                    [
                        a * (2.0 * std::f64::consts::PI * hz * k as f64 * 1e-4).sin(),
                        0.0,
                        0.0,
                    ]
                })
                .collect(),
        }
    }

    /// A board reset mid-recording (its time starts again): the longest
    /// stretch of rising time is analysed and the restart counted, where
    /// the span from the first frame to the last once underflowed into an
    /// allocation of 1.5e17 bytes.
    #[test]
    fn a_reset_mid_recording_is_counted_not_a_crash() {
        let mut f = frames(30.0, 2.0, 2000, 6, 1.0, 0.0, 0.0);
        f.extend(frames(30.0, 2.0, 2000, 4, 1.0, 0.0, 0.0));
        let r = analyse(&f, None).expect("enough frames");
        assert_eq!(r.restarts, 1);
        assert_eq!(r.frames, 6000);
    }

    #[test]
    fn a_stated_delay_costs_its_closed_form_on_a_sine() {
        // The frames reach the antenna `after_us` past t_us: the stream is
        // age + after_us late against the motion it carries.
        for (hz, age) in [(2.0, 2000u16), (0.7, 1000), (8.0, 2000)] {
            let r =
                analyse(&frames(30.0, hz, age, 12, 1.0, 0.0, 0.0), None).expect("enough frames");
            let d = (f64::from(age) + r.after_us) * 1e-6;
            let want = LoopParams::VEHICLE.error_gain(hz, d).0 * 30.0;
            let got = stats(&mut r.delay[0].clone()).max;
            assert!((got - want).abs() < 0.03 * want, "{hz} Hz: {got} vs {want}");
            assert!(stats(&mut r.delay[1].clone()).max < 1e-9);
        }
    }

    #[test]
    fn against_a_reference_the_parts_add_up_and_each_is_where_it_belongs() {
        // 1 % scale, 0.05 °/s bias, a 2 °/s fault for 100 ms, a 2 ms delay.
        let f = frames(30.0, 0.7, 2000, 12, 1.01, 0.05, 2.0);
        let r = analyse(&f, Some(&truth(30.0, 0.7, 12))).expect("enough frames");
        let (cal, faults) = (r.calibration.as_ref().unwrap(), r.faults.as_ref().unwrap());
        let mut worst_sum: f64 = 0.0;
        for k in 0..r.total[0].len() {
            let sum = r.delay[0][k] + cal[0][k] + r.noise[0][k] + faults[0][k];
            worst_sum = worst_sum.max((sum - r.total[0][k]).abs());
        }
        assert!(worst_sum < 1e-6, "{worst_sum}");
        let max = |v: &[f64]| stats(&mut v.to_vec()).max;
        // Each error is in its own share: no noise was added.
        assert!(max(&r.noise[0]) < 1e-4, "{}", max(&r.noise[0]));
        assert!(max(&cal[0]) > 0.01 && max(&faults[0]) > 0.01);
        // The fault is 2 °/s for 0.1 s: at most 0.2° before the loops act.
        assert!(max(&faults[0]) < 0.2);
    }
}
