//! `gyro pointing`: a recording through the reference stabilisation loop
//! (`gyro_array::algo::pointing`), per axis: what the stream leaves at the
//! beam, split into the stated delay's share and the noise's.
//!
//! A recording carries no truth, so the recorded motion stands for it:
//! each sample frame's rates at the instant the frame says they describe
//! (`t_us − age_us`, or `t_us + predicted_us` when the board predicted
//! them), interpolated between frames. The frames reach the antenna at the
//! end of their own transmission (`t_us` plus the loop's budgeted time and
//! the largest frame on the wire: `link::port::Port::horizon_us` at the
//! link's speed); the positioner holds each until the next.
//!
//! - **delay**: the loop fed the frames as they arrive, less the loop fed
//!   the recorded motion at each arrival instant: what the time between
//!   the instant a frame describes and its arrival costs on this motion
//!   (about 0 when the board predicted the rates to the frame's end);
//! - **noise**: white noise of the fused rate's own σ at τ0 (the board's
//!   E-DAVAR estimates in the frames: its noise probe, so none of the
//!   motion), through the board's prediction when the frames were
//!   predicted, then the loop;
//! - calibration residuals and faults need a reference rate and are not
//!   observable from the stream alone: `pointing-eval` measures them on the
//!   emulated board. The frames' health flags say where a gyro was out.

use std::path::PathBuf;

use gyro_array::algo::pointing::{stats, Axis, ErrorStats, Loop, LoopParams};
use gyro_array::algo::predict::Predictor;
use gyro_array::link::msg::Frame;
use gyro_array::link::port::{Port, PREDICT_K};

use super::{read_recording, Res};

#[cfg(test)]
mod tests {
    use super::*;
    use gyro_array::link::msg::Sample;

    /// A sine of `a` °/s at `hz` on x, frames at 1 kHz stating `age` µs.
    fn frames(a: f64, hz: f64, age: u16, seconds: u32) -> Vec<Frame> {
        (0..seconds * 1000)
            .map(|k| {
                let t_us = 1_000 * u64::from(k) + 1_000;
                let at = (t_us as f64 - f64::from(age)) * 1e-6;
                let w = a * (2.0 * std::f64::consts::PI * hz * at).sin();
                Frame::Sample(Sample {
                    seq: k,
                    t_us,
                    age_us: [age; 3],
                    predicted_us: None,
                    rate_dps: [w as f32, 0.0, 0.0],
                    valid: 0b111,
                    degraded: 0,
                    used: [0b1111; 3],
                    health: Default::default(),
                    noise: None,
                })
            })
            .collect()
    }

    #[test]
    fn a_stated_delay_costs_its_closed_form_on_a_sine() {
        // The frames reach the antenna `after_us` past t_us: the stream is
        // age + after_us late against the motion it carries.
        for (hz, age) in [(2.0, 2000u16), (0.7, 1000), (8.0, 2000)] {
            let r = analyse(&frames(30.0, hz, age, 12)).expect("enough frames");
            let d = (f64::from(age) + r.after_us) * 1e-6;
            let want = LoopParams::VEHICLE.error_gain(hz, d).0 * 30.0;
            let got = stats(&mut r.delay[0].clone()).max;
            assert!((got - want).abs() < 0.03 * want, "{hz} Hz: {got} vs {want}");
            assert!(stats(&mut r.delay[1].clone()).max < 1e-9);
        }
    }
}

/// One sample frame, as the loop sees it.
struct Frm {
    t_us: u64,
    /// Per axis, the instant the rate describes, µs (board clock).
    at_us: [f64; 3],
    rate: [f64; 3],
    predicted: Option<u16>,
    flagged: bool,
}

/// Simulation steps per millisecond (the loop's 10 µs).
const SUB: usize = 100;

/// What [`analyse`] finds, per axis: the pointing error series (one a
/// millisecond, from the score's start) and the recorded motion.
pub struct Report {
    pub frames: usize,
    pub predicted: usize,
    pub flagged: usize,
    pub after_us: f64,
    pub skip_ms: usize,
    pub delay: [Vec<f64>; 3],
    pub noise: [Vec<f64>; 3],
    pub motion: [Vec<f64>; 3],
}

pub fn run(file: &PathBuf, svg: Option<&PathBuf>) -> Res<bool> {
    let (frames, _) = read_recording(file)?;
    let bodies: Vec<Frame> = frames.into_iter().flatten().map(|d| d.body).collect();
    let Some(r) = analyse(&bodies) else {
        println!(
            "{}: fewer than 100 sample frames with every axis valid",
            file.display()
        );
        return Ok(false);
    };
    let p = LoopParams::VEHICLE;
    println!(
        "{}: {} sample frames ({} predicted by the board, {} with a gyro flagged); reference loop {} Hz rate loop, {} Hz tracking; frames at the antenna {:.0} µs after t_us; scored from {:.1} s",
        file.display(),
        r.frames,
        r.predicted,
        r.flagged,
        p.rate_bw_hz,
        p.track_hz,
        r.after_us,
        r.skip_ms as f64 * 1e-3
    );
    let show = |name: &str, e: &[Vec<f64>; 3]| {
        let s: Vec<ErrorStats> = e.iter().map(|v| stats(&mut v.clone())).collect();
        println!(
            "  {name:<38} rms {:.4} / {:.4} / {:.4}   p99.9 {:.4} / {:.4} / {:.4}   max {:.4} / {:.4} / {:.4} °",
            s[0].rms, s[1].rms, s[2].rms, s[0].p999, s[1].p999, s[2].p999, s[0].max, s[1].max, s[2].max
        );
    };
    println!("pointing error, x / y / z:");
    let total: [Vec<f64>; 3] = core::array::from_fn(|a| {
        r.delay[a]
            .iter()
            .zip(&r.noise[a])
            .map(|(d, n)| d + n)
            .collect()
    });
    show("delay + noise (the stream's share)", &total);
    show("  from the stated delay", &r.delay);
    show("  from the noise (E-DAVAR σ at τ0)", &r.noise);
    println!("  calibration residuals and faults: not observable without a reference (pointing-eval measures them)");
    if let Some(path) = svg {
        // The axis that moved most, its first 10 s scored.
        let spread = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / v.len().max(1) as f64;
            v.iter().map(|x| (x - m) * (x - m)).sum::<f64>()
        };
        let a = (0..3)
            .max_by(|&i, &j| spread(&r.motion[i]).total_cmp(&spread(&r.motion[j])))
            .unwrap_or(0);
        let n = 10_000;
        let cut = |v: &[f64]| v[..v.len().min(n)].to_vec();
        draw(
            path,
            ["x", "y", "z"][a],
            &cut(&r.motion[a]),
            &cut(&total[a]),
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

/// Run the sample frames among `frames` through the reference loop;
/// `None` with fewer than 100 frames whose every axis is valid.
pub fn analyse(frames: &[Frame]) -> Option<Report> {
    let mut fr: Vec<Frm> = Vec::new();
    let mut sigma: [Vec<f64>; 3] = Default::default();
    let mut tau0_is_one = true;
    for body in frames {
        match body {
            Frame::Status(s) => tau0_is_one = s.noise_tau[0] == 1,
            Frame::Sample(s) if s.valid == 0b111 => {
                let t = s.t_us as f64;
                let at_us = core::array::from_fn(|a| match s.predicted_us {
                    Some(p) => t + f64::from(p),
                    None => t - f64::from(s.age_us[a]),
                });
                fr.push(Frm {
                    t_us: s.t_us,
                    at_us,
                    rate: s.rate_dps.map(f64::from),
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
    if fr.len() < 100 {
        return None;
    }
    let after_us = f64::from(
        Port::<64>::new(Default::default())
            .horizon_us()
            .unwrap_or(0),
    );
    let lp = Loop::new(LoopParams::VEHICLE);
    let p = lp.params();
    let t0 = fr[0].t_us as f64;
    let arrive: Vec<f64> = fr.iter().map(|f| f.t_us as f64 + after_us).collect();
    // The recorded motion at instant t (µs): linear between the frames'
    // described instants, per axis.
    let motion = |a: usize, t: f64, k_hint: &mut usize| -> f64 {
        while *k_hint + 1 < fr.len() && fr[*k_hint + 1].at_us[a] <= t {
            *k_hint += 1;
        }
        while *k_hint > 0 && fr[*k_hint].at_us[a] > t {
            *k_hint -= 1;
        }
        let (f0, f1) = (&fr[*k_hint], &fr[(*k_hint + 1).min(fr.len() - 1)]);
        let span = f1.at_us[a] - f0.at_us[a];
        if span <= 0.0 {
            return f0.rate[a];
        }
        let x = ((t - f0.at_us[a]) / span).clamp(0.0, 1.0);
        f0.rate[a] + x * (f1.rate[a] - f0.rate[a])
    };
    let ms = ((fr.last().map_or(0, |f| f.t_us) - fr[0].t_us) / 1000) as usize;
    // Scored after the loops settle (2 s).
    let skip = 2000usize.min(ms / 2);
    let mut delay: [Vec<f64>; 3] = Default::default();
    let mut noise: [Vec<f64>; 3] = Default::default();
    let mut moved: [Vec<f64>; 3] = Default::default();
    for a in 0..3 {
        // The two runs against the recorded motion.
        let (mut st_frames, mut st_ideal) = (Axis::default(), Axis::default());
        let (mut g_f, mut g_i) = (0.0f64, 0.0f64);
        let (mut dg_f, mut dg_i) = (0.0f64, 0.0f64);
        let mut theta = 0.0f64;
        let (mut k, mut hint, mut hint2) = (0usize, 0usize, 0usize);
        let mut last = motion(a, t0, &mut hint);
        for j in 0..ms * SUB {
            let t = t0 + j as f64 * p.dt_s * 1e6;
            while k < fr.len() && arrive[k] <= t {
                let (gf, gi) = (fr[k].rate[a], motion(a, arrive[k], &mut hint2));
                if k > 0 {
                    dg_f = (gf - g_f) / 1e-3;
                    dg_i = (gi - g_i) / 1e-3;
                }
                (g_f, g_i) = (gf, gi);
                k += 1;
            }
            let ef = lp.step(&mut st_frames, theta, g_f, dg_f);
            let ei = lp.step(&mut st_ideal, theta, g_i, dg_i);
            let next = motion(a, t + p.dt_s * 1e6, &mut hint);
            theta += 0.5 * (last + next) * p.dt_s;
            last = next;
            if (j + 1) % SUB == 0 && (j + 1) / SUB > skip {
                delay[a].push(ef - ei);
                moved[a].push(next);
            }
        }
        // White noise of the fused rate's σ(τ0), as the board sent it.
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
        let mut st = Axis::default();
        let (mut g, mut dg) = (0.0f64, 0.0f64);
        for (kf, f) in fr.iter().enumerate().take(ms) {
            let w = s * gauss();
            pred.push([w as f32, 0.0, 0.0]);
            let v = match f.predicted {
                Some(h) => {
                    let ahead = (f64::from(h) + (f.t_us as f64 - f.at_us[a]).max(0.0)) / 1000.0;
                    pred.at([ahead as f32, 0.0, 0.0])
                        .map_or(w, |v| f64::from(v[0]))
                }
                None => w,
            };
            if kf > 0 {
                dg = (v - g) / 1e-3;
            }
            g = v;
            let mut e = 0.0;
            for _ in 0..SUB {
                e = lp.step(&mut st, 0.0, g, dg);
            }
            if kf >= skip {
                noise[a].push(e);
            }
        }
    }
    Some(Report {
        frames: fr.len(),
        predicted: fr.iter().filter(|f| f.predicted.is_some()).count(),
        flagged: fr.iter().filter(|f| f.flagged).count(),
        after_us,
        skip_ms: skip,
        delay,
        noise,
        motion: moved,
    })
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
        .caption(
            format!("recorded rate on {axis} (the motion)"),
            ("sans-serif", 16),
        )
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
            format!("pointing error on {axis}: the stream's share, and its delay's"),
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
    for (name, v, col) in [("delay + noise", total, BLUE), ("delay", delay, RED)] {
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
