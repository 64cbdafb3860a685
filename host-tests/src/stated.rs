//! The fused rate's error at the stated instant: the timed board
//! ([`crate::timed_board::run`]: the drivers on the FIFO path, each chip in
//! `TimedIcm`, every sample through the board's schedule) against the same
//! four chips as ideal lockstep samplers, polled through the same
//! schedule. The timed chips' truth is the rate at the instant each sample
//! states; the lockstep chips' the rate at the read. `timing-eval`'s
//! fusion table and the timing figure.

use crate::timed_board::{self, HostLink, Timing, STATUS_VIEW};
use gyro_array::algo::fusion::{AdaptiveConfig, Method};
use gyro_array::app::{self as schedule, StatusFacts};
use gyro_array::drivers::icm42688::{Config, Icm42688};
use gyro_array::drivers::Gyro;
use gyro_array::link::msg::Settings;
use gyro_array::link::port::{NoiseSnapshot, Port};
use gyro_array::pipeline::{Pipeline, PipelineConfig};
use gyro_sim::{
    emu_device, with_bus, Chip, CsLine, EmuBus, EmuDelay, Fault, Icm42688Model, NoiseParams,
    RateProfile,
};
use rtic_core::Exclusive;
use std::cell::RefCell;

/// Chips in the array.
pub const N: usize = timed_board::N;
/// Samples before the errors count (clocks acquired, fusion warm).
const WARM_MS: u32 = 600;

/// One run's settings.
#[derive(Clone, Copy, Debug)]
pub struct Run {
    /// The motion.
    pub profile: RateProfile,
    /// How the timed chips keep time (their scale errors are the lockstep
    /// chips' too).
    pub timing: Timing,
    /// Length, ms.
    pub ms: u32,
    /// Noise seed.
    pub seed: u64,
    /// Reset chip 1 at this ms behind the driver's back (a new phase, its
    /// configuration lost), if any: the board finds it and restarts it.
    pub restart_at_ms: Option<u32>,
    /// Also measure the errors below 100 Hz.
    pub band_limited: bool,
}

/// What one run measured, per axis.
#[derive(Clone, Debug, Default)]
pub struct Outcome {
    /// RMS of (fused − truth at the stated instant), °/s, per axis.
    pub rms_dps: [f64; 3],
    /// The same below 100 Hz (where the antenna's loops work), and the
    /// lockstep array's.
    pub rms_below_100_dps: [f64; 3],
    /// See `rms_below_100_dps`.
    pub lockstep_rms_below_100_dps: [f64; 3],
    /// The same for the lockstep array (truth at the read).
    pub lockstep_rms_dps: [f64; 3],
    /// The lag that best aligns the fused rate with the truth, minus the
    /// stated one, µs (positive: the rate is older than stated).
    pub lag_error_us: [f64; 3],
    /// The standard error of that lag, µs (from the fit's residuals): large
    /// where the motion barely moves over the run, so that no lag is
    /// measurable.
    pub lag_se_us: [f64; 3],
    /// Output samples after warm-up with fewer than four chips offered on
    /// x, outside a restart (from the reset until the chip answers again).
    pub short: u32,
    /// Samples from chip 1's reset until the board had it offered again.
    pub restart_out: u32,
    /// FIFO anomalies over the run, every chip: overflows, streams out of
    /// step, cut bursts, packets sent again (each a gap or a repair).
    pub fifo_anomalies: u32,
    /// Each chip's clock error as its tracker reports it at the end, ppm.
    pub clock_ppm: [f32; N],
    /// Per output sample after warm-up: the stated instant (s) and the
    /// fused rate.
    pub fused: Vec<(f64, [f64; 3])>,
    /// Per sample after warm-up: how far each chip's newest mean lies
    /// behind the read, µs (NaN before its clock is tracked).
    pub newest_behind_us: Vec<[f64; N]>,
}

fn truth(p: &RateProfile, t_s: f64) -> [f64; 3] {
    p.at_f64(t_s)
}

/// Run the timed board and the lockstep array on the same motion.
pub fn run(r: Run) -> Outcome {
    let mut out = Outcome::default();
    let timed = timed(&r, &mut out);
    let lock = lockstep(&r);
    out.fused = timed.clone();
    for a in 0..3 {
        let e: Vec<f64> = timed
            .iter()
            .map(|s| s.1[a] - truth(&r.profile, s.0)[a])
            .collect();
        let l: Vec<f64> = lock
            .iter()
            .map(|s| s.1[a] - truth(&r.profile, s.0)[a])
            .collect();
        out.rms_dps[a] = rms(&e);
        out.lockstep_rms_dps[a] = rms(&l);
        if r.band_limited {
            out.rms_below_100_dps[a] = rms_below(&e, 1000.0, 100.0);
            out.lockstep_rms_below_100_dps[a] = rms_below(&l, 1000.0, 100.0);
        }
        // The lag: the error regressed on the truth's derivative, the
        // truth itself (a scale error) and 1 (a bias), by least squares;
        // e ≈ −lag·ẇ + k·w + b.
        let h = 1e-4;
        let rows: Vec<[f64; 4]> = timed
            .iter()
            .map(|s| {
                let w = truth(&r.profile, s.0)[a];
                let dw =
                    (truth(&r.profile, s.0 + h)[a] - truth(&r.profile, s.0 - h)[a]) / (2.0 * h);
                [dw, w, 1.0, s.1[a] - w]
            })
            .collect();
        let (best, se) = lag_fit(&rows);
        out.lag_error_us[a] = best * 1e6;
        out.lag_se_us[a] = se * 1e6;
    }
    out
}

/// The fused rate per output sample after warm-up, at its stated instant.
fn timed(r: &Run, out: &mut Outcome) -> Vec<(f64, [f64; 3])> {
    let mut fused = Vec::new();
    // From the reset until chip 1 is offered again.
    let mut restarting = false;
    let ran = timed_board::run(
        r.profile,
        r.seed,
        r.ms,
        r.timing,
        [Fault::None; N],
        |_| 0,
        |smp| {
            if Some(smp.n) == r.restart_at_ms {
                with_bus(smp.bus, |b| b.chips[1].power_cycle());
                restarting = true;
                return;
            }
            if restarting {
                if smp.out.offered[0] & 0b10 != 0 {
                    restarting = false;
                } else {
                    out.restart_out += 1;
                }
            }
            if smp.n < WARM_MS {
                return;
            }
            out.newest_behind_us.push(smp.newest_behind_us);
            if smp.out.offered[0].count_ones() < N as u32 && !restarting {
                out.short += 1;
            }
            let f = smp.out.fused.map(|f| f.map(|f| f64::from(f.rate_dps)));
            if let [Some(x), Some(y), Some(z)] = f {
                if [x, y, z].iter().all(|v| v.is_finite()) {
                    fused.push((smp.stated_s, [x, y, z]));
                }
            }
        },
    );
    out.fifo_anomalies = ran
        .timing
        .iter()
        .map(|c| c.overflows + c.bad_fifo + c.cuts + c.resent)
        .sum();
    out.clock_ppm = ran.clock_ppm;
    fused
}

/// (read instant s, fused rate) per sample of the lockstep array: the same
/// chips (noise, bias, scale) as ideal samplers, polled through the same
/// schedule.
fn lockstep(r: &Run) -> Vec<(f64, [f64; 3])> {
    let chips: [Chip; N] = core::array::from_fn(|i| {
        let p = NoiseParams {
            bias_dps: gyro_sim::TIMED_ARRAY_BIAS_DPS[i],
            scale_error: r.timing.scale_error[i],
            ..NoiseParams::ICM42688
        };
        Chip::Icm(Icm42688Model::new(
            p,
            r.profile,
            r.seed.wrapping_mul(31).wrapping_add(i as u64),
            70,
        ))
    });
    let cs: [CsLine; N] = Default::default();
    let bus = RefCell::new(EmuBus::new(chips, &cs));
    let mut delay = EmuDelay::new(&bus, 1e-3);
    let mut g: Vec<_> = (0..N)
        .map(|i| {
            let mut g = Icm42688::new(emu_device(&bus, &cs[i]));
            g.init(&mut delay, Config::default()).expect("init");
            g
        })
        .collect();
    let Ok(mut pipe) = Pipeline::<N>::new(
        PipelineConfig::default(),
        Method::Adaptive(AdaptiveConfig::default()),
    ) else {
        panic!("pipeline settings")
    };
    let mut link: HostLink = HostLink {
        port: Port::new(Settings::default(), gyro_array::app::BOARD_FRAME_PATH),
        bytes: 0,
    };
    let mut noise = NoiseSnapshot::default();
    let mut fused = Vec::new();
    for n in 0..r.ms {
        with_bus(&bus, |b| b.advance(1e-3));
        // The lockstep chips sample the profile at the bus's f32 time
        // (summed in f32: 0.5 ms off after 5 s), so their truth is there.
        let now_s = with_bus(&bus, |b| b.time_s()).unwrap_or(0.0) as f64;
        let out = {
            let [a, b, c, d] = &mut g[..] else {
                unreachable!("four chips")
            };
            let mut gy: [&mut dyn Gyro; N] = [a, b, c, d];
            schedule::sample(
                &mut Exclusive(&mut pipe),
                &mut Exclusive(&mut link),
                &mut Exclusive(&mut noise),
                &mut gy,
                ((now_s * 1e6) as u64, 0),
                &STATUS_VIEW,
                || {},
                || StatusFacts {
                    clocks: Default::default(),
                    stack_peak: 0,
                },
            )
            .out
        };
        if n < WARM_MS {
            continue;
        }
        if let [Some(x), Some(y), Some(z)] = out.fused.map(|f| f.map(|f| f64::from(f.rate_dps))) {
            fused.push((now_s, [x, y, z]));
        }
    }
    fused
}

/// −β₀ of the least-squares fit of column 3 on columns 0..3 and its
/// standard error (σ̂²·(XᵀX)⁻¹₀₀, σ̂² the residuals' mean square over
/// n − 3); (0, ∞) where the derivative does not vary (no motion) or the
/// columns are collinear.
fn lag_fit(rows: &[[f64; 4]]) -> (f64, f64) {
    let mut ata = nalgebra::Matrix3::<f64>::zeros();
    let mut atb = nalgebra::Vector3::<f64>::zeros();
    for r in rows {
        let x = nalgebra::Vector3::new(r[0], r[1], r[2]);
        ata += x * x.transpose();
        atb += x * r[3];
    }
    let none = (0.0, f64::INFINITY);
    if ata[(0, 0)] < 1e-6 * rows.len() as f64 || rows.len() < 4 {
        return none;
    }
    let lu = ata.lu();
    let (Some(b), Some(inv)) = (lu.solve(&atb), lu.try_inverse()) else {
        return none;
    };
    let rss: f64 = rows
        .iter()
        .map(|r| {
            let e = r[3] - (b[0] * r[0] + b[1] * r[1] + b[2] * r[2]);
            e * e
        })
        .sum();
    let var = rss / (rows.len() - 3) as f64 * inv[(0, 0)];
    (
        -b[0],
        if var >= 0.0 {
            var.sqrt()
        } else {
            f64::INFINITY
        },
    )
}

/// RMS of the part of `x` (sampled at `fs`) below `f_max`, from its DFT
/// (Parseval over the bins below `f_max`, DC included).
pub fn rms_below(x: &[f64], fs: f64, f_max: f64) -> f64 {
    let n = x.len();
    if n == 0 {
        return 0.0;
    }
    let kmax = (f_max / fs * n as f64) as usize;
    let mut p = 0.0;
    for k in 0..kmax.min(n / 2) {
        let (mut re, mut im) = (0.0, 0.0);
        let w = 2.0 * std::f64::consts::PI * k as f64 / n as f64;
        for (i, v) in x.iter().enumerate() {
            re += v * (w * i as f64).cos();
            im += v * (w * i as f64).sin();
        }
        let m = (re * re + im * im) / (n as f64 * n as f64);
        p += if k == 0 { m } else { 2.0 * m };
    }
    p.sqrt()
}

fn rms(x: &[f64]) -> f64 {
    (x.iter().map(|v| v * v).sum::<f64>() / x.len().max(1) as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::lag_fit;
    use gyro_sim::Rng;

    /// Rows of the lag fit for a rate `w(t)` read `lag` late with white
    /// noise `sd`, a bias and a scale error, at 1 kHz for `secs`.
    fn rows(w: impl Fn(f64) -> f64, lag: f64, sd: f64, secs: f64, seed: u64) -> Vec<[f64; 4]> {
        let mut rng = Rng::new(seed);
        let h = 1e-4;
        (0..(secs * 1000.0) as usize)
            .map(|i| {
                let t = i as f64 * 1e-3;
                let truth = w(t);
                let dw = (w(t + h) - w(t - h)) / (2.0 * h);
                let read = 1.002 * w(t - lag) + 0.05 + sd * f64::from(rng.gaussian());
                [dw, truth, 1.0, read - truth]
            })
            .collect()
    }

    #[test]
    fn the_fitted_lag_lies_within_its_standard_errors() {
        // A 2 Hz sway, 95 °/s: the lag is well placed (a few µs).
        let sway = |t: f64| 95.0 * (2.0 * std::f64::consts::PI * 2.0 * t).sin();
        for (seed, lag) in [(1, 0.0), (2, 30e-6), (3, -80e-6)] {
            let (fit, se) = lag_fit(&rows(sway, lag, 0.05, 10.0, seed));
            assert!(se < 5e-6, "sd {se}");
            assert!(
                (fit - lag).abs() < 4.0 * se + 1e-6,
                "{fit} against {lag} ± {se}"
            );
        }
    }

    #[test]
    fn a_slow_turn_over_a_short_run_has_no_measurable_lag() {
        // 2 s of a 0.1 Hz turn: the derivative barely moves, collinear with
        // the bias; the standard error says so.
        let turn = |t: f64| 100.0 * (2.0 * std::f64::consts::PI * 0.1 * t).sin();
        let (_, short) = lag_fit(&rows(turn, 0.0, 0.05, 2.0, 4));
        let (_, long) = lag_fit(&rows(turn, 0.0, 0.05, 10.0, 4));
        assert!(short > 25e-6, "2 s: ±{short}");
        assert!(long < short / 4.0, "10 s: ±{long} against 2 s: ±{short}");
        // No motion at all: no lag, and no claim to one.
        let (fit, se) = lag_fit(&rows(|_| 0.0, 0.0, 0.05, 2.0, 5));
        assert_eq!((fit, se), (0.0, f64::INFINITY));
    }
}
