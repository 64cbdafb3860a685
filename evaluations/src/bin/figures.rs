//! The evaluation figures, drawn from the real code paths into SVG.
//!
//! `cargo run -p evaluations --profile host --bin figures -- [--out DIR] [--seed S] [FIGURE...]`
//!
//! - `allan`: Allan deviation of four emulated ICM-42688-P chips, still,
//!   200 s at 1 kHz, and of their fused rate (the shipped adaptive method).
//! - `edavar`: the E-DAVAR t–τ surface of a signal whose noise steps up ×4
//!   and ramps back down, with σ²(τ0) against the truth and against the
//!   best fixed window, and the window the estimator chose.
//! - `replay`: the whole emulated board (real drivers on the emulated SPI
//!   bus, pipeline, recovery, fusion) turning at up to 100 °/s from
//!   power-up while chips stick, reset, spike and garble: the z axis's
//!   fused error, each chip's error, and which chips fusion used.
//! - `motion`: the board's noise tracker on a vehicle turning at 100 °/s
//!   and swaying at 2 Hz: the E-DAVAR estimates (fed the array's noise
//!   probe) against the fused error's Allan deviation and the fused rate's.
//!
//! - `timing`: four ICM-42688-P on their own clocks, read every
//!   millisecond: how far each chip's newest sample lies behind the read
//!   (each chip's phase drifts at its own clock's rate; one on CLKIN holds
//!   still), and the fused error against the truth at instants shifted
//!   from the one the board states: least at the stated instant.
//!
//! Each figure also prints the figures it shows (RMS errors, ratios), so
//! what the picture claims comes from this command.

use std::path::{Path, PathBuf};

use clap::{Parser, ValueEnum};
use gyro_array::algo::allan::{oavar_octave, AdevPoint};
use gyro_array::algo::davar::{Davar, DavarConfig};
use gyro_array::algo::fusion::{AdaptiveConfig, AxisState, Fusion, Method};
use gyro_sim::checks::run_board_array_from;
use gyro_sim::noise::{quantise, AxisNoise};
use gyro_sim::{with_bus, Fault, NoiseParams, RateProfile, Rng, RtcTick};
use gyro_tool::surface;
use host_tests::motion::{self, Run};
use plotters::prelude::*;

type Err = Box<dyn std::error::Error>;

#[derive(Clone, Copy, Debug, PartialEq, ValueEnum)]
enum Figure {
    Allan,
    Edavar,
    Replay,
    Motion,
    Timing,
    /// The board's fusion on a real flight (path 2, y).
    Flight,
}

/// Draw the evaluation figures (SVG).
#[derive(Parser)]
struct Args {
    /// Output folder.
    #[arg(long, default_value = "docs/figures")]
    out: PathBuf,
    /// Noise seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Figures to draw (all when none is given).
    #[arg(value_enum)]
    figures: Vec<Figure>,
}

fn main() -> Result<(), Err> {
    gyro_tool::pipe::quiet_on_closed_pipe();
    let args = Args::parse();
    std::fs::create_dir_all(&args.out)?;
    let all = [
        Figure::Allan,
        Figure::Edavar,
        Figure::Replay,
        Figure::Motion,
        Figure::Timing,
        Figure::Flight,
    ];
    let figs = if args.figures.is_empty() {
        &all[..]
    } else {
        &args.figures[..]
    };
    for f in figs {
        match f {
            Figure::Allan => allan(&args.out, args.seed)?,
            Figure::Edavar => edavar(&args.out, args.seed)?,
            Figure::Replay => replay(&args.out, args.seed)?,
            Figure::Motion => motion(&args.out, args.seed)?,
            Figure::Timing => timing(&args.out, args.seed)?,
            Figure::Flight => flight(&args.out)?,
        }
    }
    Ok(())
}

const PALETTE: [RGBColor; 5] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

/// The series legend every panel uses, boxed at `pos`.
fn legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    pos: SeriesLabelPosition,
) -> Result<(), Err>
where
    DB::ErrorType: 'static,
{
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .position(pos)
        .draw()?;
    Ok(())
}

/// The grid and axis labels of an Allan-deviation panel (log τ, log σ).
fn adev_mesh<'a, DB: DrawingBackend + 'a>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<LogCoord<f64>, LogCoord<f64>>>,
) -> Result<(), Err>
where
    DB::ErrorType: 'static,
{
    chart
        .configure_mesh()
        .x_desc("τ (s)")
        .y_desc("σ(τ) (°/s)")
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .draw()?;
    Ok(())
}

fn curve(rate: &[f64]) -> Result<Vec<AdevPoint>, Err> {
    let mut phase = vec![0.0; rate.len() + 1];
    let mut pts = [AdevPoint::default(); 40];
    let n = oavar_octave(rate, 1e-3, &mut phase, &mut pts).map_err(|e| format!("{e:?}"))?;
    Ok(pts[..n].iter().copied().filter(|p| p.reliable()).collect())
}

fn allan(out: &Path, seed: u64) -> Result<(), Err> {
    const N: usize = 200_000;
    const LSB: f32 = 131.0;
    let params = [NoiseParams::ICM42688; 4];
    let mut rng = Rng::new(seed);
    let mut noise = [AxisNoise::default(); 4];
    let fusion = Fusion::<4>::new(Method::Adaptive(AdaptiveConfig::default()))
        .map_err(|e| format!("{e:?}"))?;
    let mut st = AxisState::<4>::default();
    let mut chips: Vec<Vec<f64>> = (0..4).map(|_| Vec::with_capacity(N)).collect();
    let mut fused = Vec::with_capacity(N);
    for _ in 0..N {
        let mut y = [0.0f32; 4];
        for i in 0..4 {
            let v = noise[i].step(&params[i], &mut rng, 0.0, 1e-3);
            y[i] = quantise(v, LSB) as f32 / LSB;
            chips[i].push(y[i] as f64);
        }
        let f = fusion
            .fuse(&mut st, &y, 0b1111)
            .map_err(|e| format!("{e:?}"))?;
        fused.push(f.rate_dps as f64);
    }
    let curves: Vec<Vec<AdevPoint>> = chips.iter().map(|c| curve(c)).collect::<Result<_, _>>()?;
    let fc = curve(&fused)?;
    // The ideal: four independent equal chips averaged, σ/√4 at every τ.
    let ideal: Vec<(f64, f64)> = (0..fc.len())
        .map(|k| {
            let mean = curves.iter().map(|c| c[k].avar).sum::<f64>() / 4.0;
            (fc[k].tau_s, (mean / 4.0).sqrt())
        })
        .collect();
    println!("allan: τ (s), mean chip σ, fused σ, fused / (chip/√4)");
    for (k, p) in fc.iter().enumerate() {
        let chip = (curves.iter().map(|c| c[k].avar).sum::<f64>() / 4.0).sqrt();
        println!(
            "  {:>9.3} {:>10.3e} {:>10.3e} {:>6.3}",
            p.tau_s,
            chip,
            p.adev(),
            p.adev() / ideal[k].1
        );
    }
    let path = out.join("allan.svg");
    let root = SVGBackend::new(&path, (900, 600)).into_drawing_area();
    root.fill(&WHITE)?;
    let (lo, hi) = fc
        .iter()
        .chain(curves.iter().flatten())
        .fold((f64::MAX, 0.0f64), |(lo, hi), p| {
            (lo.min(p.adev()), hi.max(p.adev()))
        });
    let mut chart = ChartBuilder::on(&root)
        .caption(
            "Allan deviation: four ICM-42688-P chips and the fused virtual gyro (still, 200 s)",
            ("sans-serif", 20),
        )
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(70)
        .build_cartesian_2d(
            (5e-4f64..fc.last().map_or(100.0, |p| p.tau_s * 2.0)).log_scale(),
            (lo * 0.5..hi * 2.0).log_scale(),
        )?;
    adev_mesh(&mut chart)?;
    for (i, c) in curves.iter().enumerate() {
        chart
            .draw_series(LineSeries::new(
                c.iter().map(|p| (p.tau_s, p.adev())),
                PALETTE[i].mix(0.6).stroke_width(1),
            ))?
            .label(format!("chip {i}"))
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], PALETTE[i]));
    }
    chart
        .draw_series(LineSeries::new(
            ideal.iter().copied(),
            BLACK.mix(0.5).stroke_width(1),
        ))?
        .label("ideal: mean chip / √4")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK.mix(0.5)));
    chart
        .draw_series(LineSeries::new(
            fc.iter().map(|p| (p.tau_s, p.adev())),
            RED.stroke_width(3),
        ))?
        .label("fused (adaptive)")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], RED.stroke_width(3)));
    legend(&mut chart, SeriesLabelPosition::UpperRight)?;
    root.present()?;
    println!("wrote {}", path.display());
    Ok(())
}

/// Noise variance of the E-DAVAR test signal at sample t: 1, a step to 4
/// at 3000, held to 6000, a ramp back to 1 by 10000, then 1.
fn edavar_variance(t: usize) -> f64 {
    match t {
        0..3000 => 1.0,
        3000..6000 => 4.0,
        6000..10000 => 4.0 - 3.0 * (t - 6000) as f64 / 4000.0,
        _ => 1.0,
    }
}

fn edavar(out: &Path, seed: u64) -> Result<(), Err> {
    type D = Davar<2048, 67, 8>;
    const N: usize = 13_000;
    const LSB: f64 = 1.0 / 1024.0;
    let (l1, l2) = (256u16, 1024u16);
    let mut rng = Rng::new(seed);
    let w: Vec<i32> = (0..N)
        .map(|t| (edavar_variance(t).sqrt() * rng.gaussian() as f64 / LSB).round() as i32)
        .collect();
    let truth = |t: usize| 0.5 * (edavar_variance(t) + edavar_variance(t + 1));
    let run = |cfg| -> Result<Vec<_>, Err> {
        let mut d = D::new(cfg).map_err(|e| format!("{e:?}"))?;
        let mut v = Vec::new();
        for &x in &w {
            if d.push(x).map_err(|e| format!("{e:?}"))?.is_some() {
                v.extend(d.estimate());
            }
        }
        Ok(v)
    };
    let seg = run(DavarConfig::segmented(l1, l2))?;
    let fixed = run(DavarConfig::fixed(l2))?;
    let short = run(DavarConfig::fixed(l1))?;
    let rms = |v: &[gyro_array::algo::davar::DavarStep<8>]| {
        let e: Vec<f64> = v
            .iter()
            .filter(|s| (l2 as u64 / 2..(N - l2 as usize / 2) as u64).contains(&s.t))
            .map(|s| s.avar[0] as f64 * LSB * LSB - truth(s.t as usize))
            .collect();
        (e.iter().map(|x| x * x).sum::<f64>() / e.len() as f64).sqrt()
    };
    let (rs, rf, r1) = (rms(&seg), rms(&fixed), rms(&short));
    println!(
        "edavar: RMS of σ²(τ0) − truth: segmented {rs:.4}, fixed {l2} {rf:.4}, fixed {l1} {r1:.4}; segmented / best fixed = {:.3}",
        rs / rf.min(r1)
    );

    let path = out.join("edavar.svg");
    let root = SVGBackend::new(&path, (1000, 900)).into_drawing_area();
    root.fill(&WHITE)?;
    let (top, rest) = root.split_vertically(380);
    let (mid, bot) = rest.split_vertically(300);

    // The surface, drawn as `gyro davar` draws it (τ and t in samples).
    let rows: Vec<surface::Row> = seg
        .iter()
        .map(|e| surface::Row {
            t_s: e.t as f64,
            start_s: e.start as f64,
            end_s: e.end as f64,
            adev: e
                .avar
                .iter()
                .map(|&v| (v.max(0.0) as f64).sqrt() * LSB)
                .collect(),
        })
        .collect();
    surface::heatmap(
        &top,
        "noise ×4 at 3000, ramp back 6000–10000",
        "°/s",
        &rows,
        0f64..N as f64,
        (1.0, "samples"),
    )?;

    // σ²(τ0): estimate against truth and the fixed windows.
    let mut chart = ChartBuilder::on(&mid)
        .caption("σ²(τ0) against the truth", ("sans-serif", 17))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(70)
        .build_cartesian_2d(0f64..N as f64, 0f64..5.0)?;
    chart
        .configure_mesh()
        .y_desc("σ²(τ0)")
        .x_label_formatter(&|v| format!("{v:.0}"))
        .draw()?;
    chart
        .draw_series(LineSeries::new(
            (0..N).step_by(16).map(|t| (t as f64, truth(t))),
            BLACK.stroke_width(2),
        ))?
        .label("truth")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK));
    for (v, name, c, wdt) in [
        (&short, format!("fixed {l1} (RMS {r1:.3})"), PALETTE[2], 1),
        (&fixed, format!("fixed {l2} (RMS {rf:.3})"), PALETTE[1], 1),
        (&seg, format!("segmented (RMS {rs:.3})"), RED, 2),
    ] {
        chart
            .draw_series(LineSeries::new(
                v.iter().map(|s| (s.t as f64, s.avar[0] as f64 * LSB * LSB)),
                c.stroke_width(wdt),
            ))?
            .label(name)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], c.stroke_width(2)));
    }
    legend(&mut chart, SeriesLabelPosition::UpperRight)?;

    // The window: its span around each t.
    let mut chart = ChartBuilder::on(&bot)
        .caption(
            "window chosen at each hop: [start, end) − t",
            ("sans-serif", 17),
        )
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(70)
        .build_cartesian_2d(0f64..N as f64, -(l2 as f64)..l2 as f64)?;
    chart
        .configure_mesh()
        .x_desc("t (samples)")
        .y_desc("samples")
        .x_label_formatter(&|v| format!("{v:.0}"))
        .y_label_formatter(&|v| format!("{v:.0}"))
        .draw()?;
    chart.draw_series(seg.windows(2).map(|p| {
        let (a, b) = (p[0], p[1]);
        let t = a.t as f64;
        Rectangle::new(
            [(t, a.start as f64 - t), (b.t as f64, a.end as f64 - t)],
            PALETTE[0].mix(0.5).filled(),
        )
    }))?;
    root.present()?;
    println!("wrote {}", path.display());
    Ok(())
}

/// One scheduled fault of the replay: chip, what, from, to (exclusive).
struct Event {
    chip: usize,
    what: &'static str,
    fault: Option<Fault>,
    start: u32,
    end: u32,
}

fn replay(out: &Path, seed: u64) -> Result<(), Err> {
    const N: u32 = 7000;
    let profile = RateProfile {
        base_dps: [0.5, -0.3, 1.0],
        sine_dps: [15.0, 10.0, 100.0],
        sine_hz: 0.4,
        sine_start_s: 0.0,
    };
    let events = [
        Event {
            chip: 2,
            what: "stuck",
            fault: Some(Fault::Stuck),
            start: 1000,
            end: 2200,
        },
        Event {
            chip: 4,
            what: "power cycle",
            fault: None,
            start: 2800,
            end: 2801,
        },
        Event {
            chip: 1,
            what: "200 °/s spikes",
            fault: Some(Fault::Spikes {
                prob: 0.05,
                magnitude_dps: 200.0,
            }),
            start: 3800,
            end: 4600,
        },
        Event {
            chip: 0,
            what: "bit errors",
            fault: Some(Fault::BitErrors { prob: 0.05 }),
            start: 5200,
            end: 5600,
        },
        Event {
            chip: 3,
            what: "no response",
            fault: Some(Fault::NoResponse),
            start: 6000,
            end: 6400,
        },
    ];
    let mut truth = Vec::new();
    let mut fused = Vec::new();
    let mut rates = vec![Vec::new(); 5];
    let mut used = vec![Vec::new(); 5];
    run_board_array_from(profile, seed, N, [Fault::None; 5], |n, bus, o, _| {
        with_bus(bus, |b| {
            for e in &events {
                if n + 1 == e.start {
                    match e.fault {
                        Some(f) => b.chips[e.chip].set_fault(f),
                        None => b.chips[e.chip].power_cycle(),
                    }
                }
                if n + 1 == e.end && e.fault.is_some() {
                    b.chips[e.chip].set_fault(Fault::None);
                }
            }
        });
        let t = with_bus(bus, |b| b.chips[0].true_rate_dps()).unwrap_or([f32::NAN; 3])[2];
        truth.push(t as f64);
        let f = o.fused[2];
        fused.push(f.map_or(f64::NAN, |f| f.rate_dps as f64));
        for i in 0..5 {
            rates[i].push(o.rate_dps[i][2] as f64);
            used[i].push(f.is_some_and(|f| f.used() & (1 << i) != 0));
        }
    })
    .ok_or("the board array did not start")?;
    let err: Vec<f64> = fused.iter().zip(&truth).map(|(f, t)| f - t).collect();
    let rms = (err.iter().map(|e| e * e).sum::<f64>() / err.len() as f64).sqrt();
    let max = err.iter().fold(0.0f64, |m, e| m.max(e.abs()));
    let peak = truth.iter().fold(0.0f64, |m, t| m.max(t.abs()));
    println!(
        "replay: z axis, {N} samples, |truth| ≤ {peak:.1} °/s: fused error RMS {rms:.3} °/s, max {max:.3} °/s"
    );
    for i in 0..5 {
        let e: Vec<f64> = rates[i]
            .iter()
            .zip(&truth)
            .zip(&used[i])
            .filter(|(_, &u)| u)
            .map(|((r, t), _)| r - t)
            .collect();
        let r = (e.iter().map(|e| e * e).sum::<f64>() / e.len().max(1) as f64).sqrt();
        println!(
            "  chip {i}: in fusion {:>5} of {N} samples, error RMS while in {r:.3} °/s",
            e.len()
        );
    }

    let path = out.join("replay.svg");
    let root = SVGBackend::new(&path, (1000, 950)).into_drawing_area();
    root.fill(&WHITE)?;
    let (top, rest) = root.split_vertically(260);
    let (mid, bot) = rest.split_vertically(400);
    let x = |n: usize| n as f64 * 1e-3;
    let span = 0f64..N as f64 * 1e-3;

    let mut chart = ChartBuilder::on(&top)
        .caption(
            "Board replay, z axis: a 100 °/s sway from power-up while chips fail",
            ("sans-serif", 18),
        )
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(60)
        .build_cartesian_2d(span.clone(), -120f64..120.0)?;
    chart.configure_mesh().y_desc("rate (°/s)").draw()?;
    chart
        .draw_series(LineSeries::new(
            truth.iter().enumerate().map(|(n, &t)| (x(n), t)),
            BLACK.stroke_width(2),
        ))?
        .label("truth")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK));
    chart
        .draw_series(LineSeries::new(
            fused
                .iter()
                .enumerate()
                .filter(|(_, f)| f.is_finite())
                .map(|(n, &f)| (x(n), f)),
            RED.stroke_width(1),
        ))?
        .label("fused")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], RED));
    legend(&mut chart, SeriesLabelPosition::UpperRight)?;

    let lim = 2.0;
    let mut chart = ChartBuilder::on(&mid)
        .caption(
            format!("error against truth (clipped to ±{lim} °/s); fused RMS {rms:.3} °/s, max {max:.3} °/s"),
            ("sans-serif", 16),
        )
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(60)
        .build_cartesian_2d(span.clone(), -lim..lim)?;
    chart.configure_mesh().y_desc("error (°/s)").draw()?;
    for i in 0..5 {
        chart
            .draw_series(LineSeries::new(
                rates[i]
                    .iter()
                    .zip(&truth)
                    .enumerate()
                    .step_by(2)
                    .map(|(n, (r, t))| (x(n), (r - t).clamp(-lim, lim))),
                PALETTE[i].mix(0.35).stroke_width(1),
            ))?
            .label(format!("chip {i}"))
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], PALETTE[i]));
    }
    chart
        .draw_series(LineSeries::new(
            err.iter()
                .enumerate()
                .filter(|(_, e)| e.is_finite())
                .map(|(n, &e)| (x(n), e.clamp(-lim, lim))),
            RED.stroke_width(2),
        ))?
        .label("fused")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], RED.stroke_width(2)));
    legend(&mut chart, SeriesLabelPosition::LowerRight)?;

    // Membership: a bar per chip where fusion used it; the faults as grey.
    let mut chart = ChartBuilder::on(&bot)
        .caption(
            "chips in fusion (colour) and injected faults (grey)",
            ("sans-serif", 16),
        )
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(60)
        .build_cartesian_2d(span, -0.5f64..4.5)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("time since power-up (s)")
        .y_labels(5)
        .y_label_formatter(&|v| format!("chip {}", v.round() as u32))
        .draw()?;
    for e in &events {
        let y = e.chip as f64 - 0.5;
        let end = if e.end == e.start + 1 {
            e.start + 40
        } else {
            e.end
        };
        chart.draw_series([Rectangle::new(
            [(x(e.start as usize), y), (x(end as usize), y + 1.0)],
            BLACK.mix(0.25).filled(),
        )])?;
        chart.draw_series([Text::new(
            e.what,
            (x(e.start as usize), y + 0.9),
            ("sans-serif", 13),
        )])?;
    }
    for (i, u) in used.iter().enumerate() {
        // Runs of "in fusion" as bars.
        let mut start = None;
        for (n, &on) in u.iter().chain([&false]).enumerate() {
            match (on, start) {
                (true, None) => start = Some(n),
                (false, Some(s)) => {
                    chart.draw_series([Rectangle::new(
                        [(x(s), i as f64 - 0.2), (x(n), i as f64 + 0.2)],
                        PALETTE[i].filled(),
                    )])?;
                    start = None;
                }
                _ => {}
            }
        }
    }
    root.present()?;
    println!("wrote {}", path.display());
    Ok(())
}

/// The noise tracker on a moving board (`host_tests::motion`), 60 s. Per
/// axis x and z: the Allan deviation of the fused rate, of the fused error (fused less
/// the emulator's true rate: the oracle) and the tracker's E-DAVAR
/// estimates at its nine τ (median, 10–90 % range).
fn motion(out: &Path, seed: u64) -> Result<(), Err> {
    const N: u32 = 60_000;
    let Run {
        rate,
        err,
        sigma: est,
    } = motion::run(seed + 6, N).ok_or("the board did not start")?;
    let pct = |v: &[f64], q: f64| {
        let mut v = v.to_vec();
        v.sort_by(f64::total_cmp);
        v[((v.len() - 1) as f64 * q) as usize]
    };
    let path = out.join("motion.svg");
    let root = SVGBackend::new(&path, (1100, 520)).into_drawing_area();
    root.fill(&WHITE)?;
    let panels = root.split_evenly((1, 2));
    println!("motion: axis, τ (ms), fused rate σ, fused error σ (oracle), tracker σ median [10 %, 90 %] (°/s)");
    for (panel, (a, name)) in panels.iter().zip([
        (0usize, "x: sway 15 °/s"),
        (2, "z: 100 °/s turn + sway 30 °/s"),
    ]) {
        let (fr, fe) = (curve(&rate[a])?, curve(&err[a])?);
        let tr: Vec<(f64, f64, f64, f64)> = est[a]
            .iter()
            .enumerate()
            .filter(|(_, v)| !v.is_empty())
            .map(|(j, v)| {
                (
                    (1u32 << j) as f64 * 1e-3,
                    pct(v, 0.5),
                    pct(v, 0.1),
                    pct(v, 0.9),
                )
            })
            .collect();
        for &(tau, m, lo, hi) in &tr {
            let oracle = fe
                .iter()
                .find(|p| (p.tau_s - tau).abs() < 1e-9)
                .map_or(f64::NAN, |p| p.adev());
            let moving = fr
                .iter()
                .find(|p| (p.tau_s - tau).abs() < 1e-9)
                .map_or(f64::NAN, |p| p.adev());
            println!(
                "  {a} {:>5.0} {moving:>10.3e} {oracle:>10.3e} {m:>10.3e} [{lo:.3e}, {hi:.3e}]",
                tau * 1e3
            );
        }
        let top = fr.iter().map(|p| p.adev()).fold(0.0f64, f64::max) * 3.0;
        let bottom = fe.iter().map(|p| p.adev()).fold(f64::MAX, f64::min) * 0.3;
        let mut chart = ChartBuilder::on(panel)
            .caption(
                format!("Noise tracker in motion, {name}"),
                ("sans-serif", 17),
            )
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(65)
            .build_cartesian_2d((5e-4f64..0.6f64).log_scale(), (bottom..top).log_scale())?;
        adev_mesh(&mut chart)?;
        chart
            .draw_series(LineSeries::new(
                fr.iter()
                    .filter(|p| p.tau_s < 0.6)
                    .map(|p| (p.tau_s, p.adev())),
                BLACK.mix(0.4).stroke_width(2),
            ))?
            .label("fused rate (what the tracker was fed before)")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK.mix(0.4)));
        chart
            .draw_series(LineSeries::new(
                fe.iter()
                    .filter(|p| p.tau_s < 0.6)
                    .map(|p| (p.tau_s, p.adev())),
                PALETTE[0].stroke_width(3),
            ))?
            .label("fused error (fused − truth): the oracle")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], PALETTE[0].stroke_width(3)));
        chart
            .draw_series(tr.iter().map(|&(t, _, lo, hi)| {
                PathElement::new([(t, lo), (t, hi)], RED.stroke_width(2))
            }))?;
        chart
            .draw_series(
                tr.iter()
                    .map(|&(t, m, _, _)| Circle::new((t, m), 4, RED.filled())),
            )?
            .label("tracker's E-DAVAR (noise probe): median, 10–90 %")
            .legend(|(x, y)| Circle::new((x + 10, y), 4, RED.filled()));
        legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
    }
    root.present()?;
    println!("wrote {}", path.display());
    Ok(())
}

/// A named curve and its colour.
type Curve<'a> = (&'a str, Vec<(f64, f64)>, RGBColor);

fn timing(out: &Path, seed: u64) -> Result<(), Err> {
    use gyro_sim::timing::ClockParams;
    use host_tests::stated;
    use host_tests::timed_board::Timing;
    let profile = RateProfile {
        base_dps: [0.0; 3],
        sine_dps: [95.0, -57.0, 76.0],
        sine_hz: 2.0,
        sine_start_s: 0.0,
    };
    // Free-running: three PLLs and chip 3 fallen back to its RC
    // oscillator; or every chip on CLKIN.
    let run = |clkin: bool| {
        let offsets = [0.008, -0.01, 0.003, 0.0];
        stated::run(stated::Run {
            profile,
            timing: Timing {
                clkin,
                pll: offsets.map(|offset| ClockParams {
                    offset,
                    ..ClockParams::fixed(0.0)
                }),
                rc_fallback: (!clkin).then_some((3, -0.07)),
                path_trim_us: 0,
                ..Timing::sweep(
                    clkin,
                    RtcTick::Microsecond,
                    gyro_sim::PastCount::HandOver,
                    gyro_sim::PathReading::DOCUMENTED,
                    0.0,
                )
            },
            ms: 4000,
            seed,
            restart_at_ms: None,
            band_limited: false,
        })
    };
    let (free, clkin) = (run(false), run(true));
    let path = out.join("timing.svg");
    let root = SVGBackend::new(&path, (1100, 480)).into_drawing_area();
    root.fill(&WHITE)?;
    let panels = root.split_evenly((1, 2));
    // (a) each chip's newest mean behind the read, free-running, 400 ms.
    let mut chart = ChartBuilder::on(&panels[0])
        .caption(
            "Each chip's newest sample behind the read",
            ("sans-serif", 17),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(0f64..400f64, 900f64..2150f64)?;
    chart
        .configure_mesh()
        .x_desc("time (ms)")
        .y_desc("read − newest mean's instant (µs)")
        .draw()?;
    let names = [
        "chip 0, PLL +0.8 %",
        "chip 1, PLL −1 %",
        "chip 2, PLL +0.3 %",
        "chip 3, RC −7 %",
    ];
    for (i, name) in names.iter().enumerate() {
        let pts: Vec<(f64, f64)> = free
            .newest_behind_us
            .iter()
            .take(400)
            .enumerate()
            .filter(|(_, v)| v[i].is_finite())
            .map(|(k, v)| (k as f64, v[i]))
            .collect();
        chart
            .draw_series(LineSeries::new(pts, PALETTE[i].stroke_width(2)))?
            .label(*name)
            .legend(move |(x, y)| {
                PathElement::new([(x, y), (x + 20, y)], PALETTE[i].stroke_width(2))
            });
    }
    let stated = gyro_array::pipeline::timed::BOARD_DELAY_US as f64;
    let on: Vec<(f64, f64)> = clkin
        .newest_behind_us
        .iter()
        .take(400)
        .enumerate()
        .map(|(k, v)| (k as f64, v[0]))
        .collect();
    chart
        .draw_series(LineSeries::new(on, BLACK.stroke_width(2)))?
        .label("chip 0 on CLKIN")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLACK.stroke_width(2)));
    chart
        .draw_series(LineSeries::new(
            [(0.0, stated), (400.0, stated)],
            RED.stroke_width(1),
        ))?
        .label(format!("the stated instant ({stated} µs)"))
        .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], RED));
    legend(&mut chart, SeriesLabelPosition::LowerRight)?;
    // (b) fused error RMS against the truth at shifted instants.
    let shift_rms = |o: &stated::Outcome, a: usize, lag_us: f64| {
        let e: f64 = o
            .fused
            .iter()
            .map(|(t, f)| (f[a] - profile.at_f64(t - lag_us * 1e-6)[a]).powi(2))
            .sum();
        (e / o.fused.len().max(1) as f64).sqrt()
    };
    let lags: Vec<f64> = (-50..=50).map(|k| k as f64 * 10.0).collect();
    let curves: Vec<Curve> = vec![
        (
            "x, free-running",
            lags.iter().map(|l| (*l, shift_rms(&free, 0, *l))).collect(),
            PALETTE[0],
        ),
        (
            "x, CLKIN",
            lags.iter()
                .map(|l| (*l, shift_rms(&clkin, 0, *l)))
                .collect(),
            PALETTE[1],
        ),
    ];
    let top = curves
        .iter()
        .flat_map(|c| c.1.iter().map(|p| p.1))
        .fold(0.0f64, f64::max);
    let mut chart = ChartBuilder::on(&panels[1])
        .caption(
            "Fused error against the truth at shifted instants (95 °/s, 2 Hz)",
            ("sans-serif", 17),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(-500f64..500f64, 0f64..top * 1.05)?;
    chart
        .configure_mesh()
        .x_desc("truth taken this much earlier than stated (µs)")
        .y_desc("RMS error (°/s)")
        .draw()?;
    println!("timing: fused x RMS error at the stated instant and ±100, ±500 µs from it (°/s)");
    for (name, pts, c) in curves {
        let at = |l: f64| {
            pts.iter()
                .find(|p| (p.0 - l).abs() < 1e-9)
                .map_or(f64::NAN, |p| p.1)
        };
        println!(
            "  {name}: {:.4} at 0, {:.4} / {:.4} at ∓100, {:.4} / {:.4} at ∓500",
            at(0.0),
            at(-100.0),
            at(100.0),
            at(-500.0),
            at(500.0)
        );
        chart
            .draw_series(LineSeries::new(pts, c.stroke_width(2)))?
            .label(name)
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], c.stroke_width(2)));
    }
    legend(&mut chart, SeriesLabelPosition::UpperMiddle)?;
    root.present()?;
    println!("wrote {}", path.display());
    Ok(())
}

/// `gyro replay`'s picture of the committed quadrotor flight, path 2, y
/// axis (four Xsens DOT, 120 Hz; `vectors/real/README.md`): the flight on
/// which the earlier noise model gave one chip over 0.9 of the weight on
/// 95 % of the samples. The chips, put on one time grid, as the replay does.
fn flight(out: &std::path::Path) -> Result<(), Err> {
    use gyro_tool::{assess, replay};
    let mut logs = host_tests::real::load(&host_tests::real::committed())?;
    let log = logs
        .iter_mut()
        .find(|l| l.name == "path 2")
        .ok_or("no path 2")?;
    host_tests::real::align(log);
    let chips: Vec<Vec<f64>> = log.chips.iter().map(|c| c[1].clone()).collect();
    let r = replay::replay(&chips)?;
    let a = assess::assess(&chips, &r, 1.0 / 120.0)?;
    println!(
        "flight: path 2, y: leave-one-out {:.3}x the mean, one chip above 0.9 on {:.2} %, mean weights {:?}",
        a.loo_ratio(),
        100.0 * a.one_chip_share,
        a.spread.iter().map(|s| (s.mean * 1000.0).round() / 1000.0).collect::<Vec<_>>()
    );
    let names: Vec<String> = (1..=chips.len()).map(|k| format!("IMU {k}")).collect();
    let path = out.join("flight.svg");
    replay::draw(
        &path,
        "Quadrotor flight, path 2, y (real, 120 Hz)",
        &names,
        &chips,
        &r,
        1.0 / 120.0,
    )?;
    println!("wrote {}", path.display());
    Ok(())
}
