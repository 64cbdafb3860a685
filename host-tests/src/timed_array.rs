//! Four ICM-42688-P on their own clocks, read through the real driver's
//! FIFO path, their samples put on the board's clock by the INT1 captures
//! ([`gyro_array::pipeline::clock`]) and brought to common output
//! instants ([`gyro_array::pipeline::align`]), fused per axis by the
//! pipeline's default path (online relative calibration, then the adaptive
//! method); beside them the same four chips as today's
//! ideal lockstep sampler, polled. The harness of `timing-eval`'s fusion
//! table and of the alignment tests.
//!
//! Not yet the board's loop: `Pipeline::step` still polls the data
//! registers. This measures what its alignment will deliver.

use gyro_array::algo::calib::{CalConfig, RelCal};
use gyro_array::algo::fusion::{AdaptiveConfig, AxisState, Fusion, Method};
use gyro_array::drivers::icm42688::{
    ClockInput, Config, FifoSample, Filter, Icm42688, Odr, Sampling,
};
use gyro_array::drivers::Gyro;
use gyro_array::emu::rng::Rng;
use gyro_array::emu::timing::{ClockParams, Vibration};
use gyro_array::emu::{
    emu_device, with_bus, Chip, ChipTiming, CsLine, EmuBus, EmuDelay, Icm42688Model, NoiseParams,
    PathModel, RateProfile, RtcTick,
};
use gyro_array::pipeline::align::{Aligned, Aligner};
use gyro_array::pipeline::clock::{ChipClock, Instant16};
use gyro_array::pipeline::stamps::StampScale;
use std::cell::RefCell;

/// Chips in the array.
pub const N: usize = 4;
/// Samples before the errors count (trackers acquired, fusion warm).
const WARM_MS: u32 = 600;

/// How the array's chips keep time.
#[derive(Clone, Copy, Debug)]
pub enum Clocks {
    /// Every chip on the board's CLKIN at 32 kHz, its FIFO stamps counting
    /// as the reading says (the sources leave it open).
    ClkIn(RtcTick),
    /// Free-running: PLLs ±1 % with drift and wander, chip 3 fallen back
    /// to its RC oscillator (−7 %).
    Free,
}

/// One run's settings.
#[derive(Clone, Copy, Debug)]
pub struct Run {
    /// The motion.
    pub profile: RateProfile,
    /// How the chips keep time.
    pub clocks: Clocks,
    /// Output data rate and filters of the timed chips.
    pub odr: Odr,
    /// Their filters.
    pub filter: Filter,
    /// The array's output delay: the fused rate describes `now − delay`.
    pub delay_us: u32,
    /// Length, ms.
    pub ms: u32,
    /// Noise seed.
    pub seed: u64,
    /// Restart chip 1 at this ms (a new phase), if any.
    pub restart_at_ms: Option<u32>,
    /// Give the chips scale errors of ±1 % (otherwise none).
    pub scale_errors: bool,
    /// Out-of-band vibration at the timed chips' dies (the lockstep
    /// sampler has no signal path to alias it, so it sees none).
    pub vibration: Vibration,
    /// Also measure the errors below 100 Hz.
    pub band_limited: bool,
    /// Draw the free-running clocks from this seed (each PLL off by up
    /// to ±1 % and drifting, the failing chip's RC oscillator by up to
    /// ±8 %) instead of the fixed set the tables quote.
    pub clock_seed: Option<u64>,
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
    /// Output samples with fewer than four chips aligned.
    pub short: u32,
    /// Samples read that were not one sample period after the last, per
    /// chip (a repeat or a skip; the FIFO makes none).
    pub repeats_or_skips: u32,
    /// FIFO errors of any kind.
    pub fifo_errors: u32,
    /// Chip clock errors the trackers found, ppm (chip 0..3).
    pub clock_ppm: [f32; N],
    /// Per output sample: the stated instant (s) and the fused rate.
    pub fused: Vec<(f64, [f64; 3])>,
    /// Per ms after warm-up: how far each chip's newest mean lies behind
    /// the read, µs (NaN before it has one).
    pub newest_behind_us: Vec<[f64; N]>,
}

fn timings(c: Clocks, vibration: Vibration, clock_seed: Option<u64>) -> [ChipTiming; N] {
    let mut free = [
        ClockParams {
            offset: 0.008,
            drift_per_s: 2e-5,
            wander: 5e-4,
            wander_period_s: 7.0,
        },
        ClockParams {
            offset: -0.01,
            drift_per_s: -1e-5,
            wander: 3e-4,
            wander_period_s: 11.0,
        },
        ClockParams {
            offset: 0.003,
            drift_per_s: 0.0,
            wander: 1e-3,
            wander_period_s: 5.0,
        },
        ClockParams::fixed(0.0),
    ];
    let mut rc = -0.07;
    if let Some(seed) = clock_seed {
        let mut rng = Rng::new(seed);
        let mut u = |lo: f64, hi: f64| lo + (hi - lo) * f64::from(rng.uniform());
        for p in free.iter_mut() {
            *p = ClockParams {
                offset: u(-0.01, 0.01),
                drift_per_s: u(-2e-5, 2e-5),
                wander: u(0.0, 1e-3),
                wander_period_s: u(3.0, 15.0),
            };
        }
        // The RC oscillator's ±8 %, at least 1 % off (else it reads as a PLL).
        rc = u(0.01, 0.08) * if u(0.0, 1.0) < 0.5 { -1.0 } else { 1.0 };
    }
    core::array::from_fn(|i| ChipTiming {
        pll: match c {
            Clocks::Free => free[i],
            Clocks::ClkIn(_) => ClockParams::fixed(0.02),
        },
        rc: ClockParams::fixed(rc),
        vibration,
        path: PathModel::Filters,
        rtc_tick: match c {
            Clocks::ClkIn(t) => t,
            Clocks::Free => RtcTick::Microsecond,
        },
        // Its bus takes no time a byte: nothing comes during a burst.
        past_count: gyro_array::emu::PastCount::HandOver,
        path_reading: gyro_array::emu::PathReading::DOCUMENTED,
    })
}

fn noise(i: usize, scale: bool) -> NoiseParams {
    NoiseParams {
        bias_dps: [0.02, -0.015, 0.01, -0.005][i],
        scale_error: if scale {
            [0.01, -0.01, 0.004, -0.006][i]
        } else {
            0.0
        },
        ..NoiseParams::ICM42688
    }
}

fn truth(p: &RateProfile, t_s: f64) -> [f64; 3] {
    p.at_f64(t_s)
}

/// Run the timed array and the lockstep one on the same motion.
pub fn run(r: Run) -> Outcome {
    let mut out = Outcome::default();
    let timed = timed(&r, &mut out);
    let lock = lockstep(&r);
    out.fused = timed.clone();
    for a in 0..3 {
        out.rms_dps[a] = rms(&timed
            .iter()
            .map(|s| s.1[a] - truth(&r.profile, s.0)[a])
            .collect::<Vec<_>>());
        out.lockstep_rms_dps[a] = rms(&lock
            .iter()
            .map(|s| s.1[a] - truth(&r.profile, s.0)[a])
            .collect::<Vec<_>>());
        if r.band_limited {
            let e: Vec<f64> = timed
                .iter()
                .map(|s| s.1[a] - truth(&r.profile, s.0)[a])
                .collect();
            let l: Vec<f64> = lock
                .iter()
                .map(|s| s.1[a] - truth(&r.profile, s.0)[a])
                .collect();
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

/// The pipeline's default path per axis: online relative calibration,
/// then the adaptive fusion.
struct Fuser {
    fusion: Fusion<N>,
    st: [AxisState<N>; 3],
    cal: [RelCal<N>; 3],
}

impl Fuser {
    fn new() -> Self {
        let Ok(fusion) = Fusion::new(Method::Adaptive(AdaptiveConfig::default())) else {
            panic!("fusion settings")
        };
        Self {
            fusion,
            st: [AxisState::default(); 3],
            cal: core::array::from_fn(|a| RelCal::for_axis(CalConfig::default(), a)),
        }
    }

    fn fuse(&mut self, y: &[[f32; N]; 3], offered: u8) -> Option<[f64; 3]> {
        let mut f = [0.0f64; 3];
        for a in 0..3 {
            let (v, _) = self.cal[a]
                .fuse_probed(&self.fusion, &mut self.st[a], &y[a], offered)
                .ok()?;
            f[a] = v.rate_dps as f64;
        }
        f.iter().all(|v| v.is_finite()).then_some(f)
    }
}

/// (stated instant s, fused rate) per output sample.
fn timed(r: &Run, out: &mut Outcome) -> Vec<(f64, [f64; 3])> {
    let t = timings(r.clocks, r.vibration, r.clock_seed);
    let chips: [Chip; N] = core::array::from_fn(|i| {
        let mut c = Icm42688Model::new(
            noise(i, r.scale_errors),
            r.profile,
            r.seed * 31 + i as u64,
            70,
        );
        c.set_timing(Some(t[i]));
        if let (Clocks::Free, 3) = (r.clocks, i) {
            c.fail_pll(true);
        }
        Chip::Icm(c)
    });
    let cs: [CsLine; N] = Default::default();
    let bus = RefCell::new(EmuBus::new(chips, &cs));
    if let Clocks::ClkIn(_) = r.clocks {
        with_bus(&bus, |b| b.clkin_hz = Some(32_000.0));
    }
    let mut delay = EmuDelay::new(&bus, 1e-3);
    let cfg = Config {
        odr: r.odr,
        filter: r.filter,
        clock: match r.clocks {
            Clocks::ClkIn(_) => ClockInput::ClkIn,
            Clocks::Free => ClockInput::Internal,
        },
        sampling: Sampling::Fifo,
        ..Config::default()
    };
    // The path's delay is a time on the chip's clock (8 % longer on the
    // board's for an RC oscillator 8 % slow): the aligners work there.
    let path16 = (r.filter.group_delay_us(r.odr) * 16.0).round() as u32;
    let per_ms = (r.odr.hz() / 1000.0).round().max(1.0) as u8;
    let period_us = 1e6 / r.odr.hz() as f64;
    let mut g: Vec<_> = (0..N)
        .map(|i| {
            let d = emu_device(&bus, &cs[i]);
            let mut g = Icm42688::new(d);
            g.init(&mut delay, cfg).expect("init");
            g
        })
        .collect();
    // The chips set up first have run while the others were: start every
    // FIFO empty together, as the board's start-up does.
    for gi in g.iter_mut() {
        gi.flush_fifo().expect("flush");
    }
    let mut clocks = [ChipClock::new(); N];
    // The FIFO stamps' counts onto µs of each chip's clock, as the board's
    // `TimedIcm` does.
    let new_scale = || StampScale::new(cfg.clock, period_us.round() as u32);
    let mut scales = [new_scale(); N];
    let mut align = [Aligner::<8>::new(per_ms); N];
    let mut fuser = Fuser::new();
    let mut last_stamp: [Option<u32>; N] = [None; N];
    let mut buf = [FifoSample {
        raw: [0; 3],
        stamp: 0,
    }; 16];
    let mut fused = Vec::new();
    // Chip 1's restart: the next step and the ms it is due.
    let mut restart: Option<(u8, u32)> = None;
    for n in 0..r.ms {
        if Some(n) == r.restart_at_ms {
            // A reset behind the driver's back: the chip starts again at a
            // new phase; the driver's restart, in steps as the pipeline
            // runs it, configures it again while the others sample.
            with_bus(&bus, |b| b.chips[1].power_cycle());
            restart = Some((0, n));
            clocks[1].reset();
            align[1].clear();
            last_stamp[1] = None;
            scales[1] = new_scale();
        }
        with_bus(&bus, |b| b.advance(1e-3));
        let now_s = with_bus(&bus, |b| b.time64_s()).unwrap_or(0.0);
        if let Some((step, due)) = restart {
            if n >= due {
                restart = match g[1].restart(step) {
                    Ok(gyro_array::drivers::Restart::Again { step, wait_us }) => {
                        Some((step, n + 1 + wait_us / 1000))
                    }
                    _ => None,
                };
            }
        }
        for i in 0..N {
            if i == 1 && restart.is_some() {
                continue;
            }
            let cap = with_bus(&bus, |b| b.int1_capture_us(i)).flatten();
            match g[i].read_fifo(&mut buf) {
                Ok(f) if f.samples > 0 => {
                    let s = &buf[..f.samples];
                    let mut newest = 0;
                    for x in s {
                        let us = scales[i].convert(x.stamp);
                        // (Until the scale has decided what a count is, its
                        // µs are a guess's.)
                        if let (Some(l), true) = (last_stamp[i], scales[i].decided()) {
                            let d = us.wrapping_sub(l) as f64;
                            if (d - period_us).abs() > 2.0 {
                                out.repeats_or_skips += 1;
                            }
                        }
                        last_stamp[i] = Some(us);
                        align[i].push(us, x.raw);
                        newest = us;
                    }
                    if scales[i].take_changed() {
                        clocks[i].reset();
                        align[i].clear();
                        last_stamp[i] = None;
                    }
                    if let Some(c) = cap {
                        clocks[i].observe(newest, c);
                    }
                }
                Ok(_) => {}
                Err(e) => {
                    if std::env::var_os("TIMING_DEBUG").is_some() {
                        eprintln!("n {n} chip {i}: {e:?}");
                    }
                    out.fifo_errors += 1;
                    align[i].clear();
                }
            }
        }
        if n < 100 {
            continue; // trackers acquiring
        }
        let stated_s = now_s - r.delay_us as f64 * 1e-6;
        let t_q: Instant16 = ((stated_s * 1e6 * 16.0) as u64) as u32;
        if n >= WARM_MS {
            let now_q = ((now_s * 1e6 * 16.0) as u64) as u32;
            out.newest_behind_us.push(core::array::from_fn(|i| {
                // The newest mean's instant less the path's delay (a time
                // on the chip's clock), on the board's.
                align[i]
                    .newest()
                    .and_then(|t| clocks[i].board_instant16(t.wrapping_sub(path16)))
                    .map_or(f64::NAN, |t| now_q.wrapping_sub(t) as i32 as f64 / 16.0)
            }));
        }
        let mut y = [[0.0f32; N]; 3];
        let mut offered = 0u8;
        for i in 0..N {
            // The stated instant on the chip's clock, plus the path's delay:
            // the samples that describe it.
            let Some(t) = clocks[i].chip_instant(t_q) else {
                continue;
            };
            let dps_per_lsb = 1.0 / g[i].full_scale().lsb_per_dps();
            if let Aligned::Rate(v) = align[i].at(t.wrapping_add(path16), dps_per_lsb) {
                offered |= 1 << i;
                for a in 0..3 {
                    y[a][i] = v[a];
                }
            }
        }
        if offered != 0b1111 && n >= WARM_MS && restart.is_none() {
            out.short += 1;
        }
        if std::env::var_os("TIMING_DEBUG").is_some() && n >= WARM_MS && n % 250 == 0 {
            let tr = truth(&r.profile, stated_s);
            let e: Vec<String> = (0..N)
                .map(|i| format!("{:+.4}", y[0][i] as f64 - tr[0]))
                .collect();
            eprintln!(
                "n {n} x errors per chip {e:?} ppm {:?}",
                clocks.map(|c| c.error_ppm())
            );
        }
        if offered.count_ones() < 2 {
            continue;
        }
        if let Some(f) = fuser.fuse(&y, offered) {
            if n >= WARM_MS {
                fused.push((stated_s, f));
            }
        }
    }
    for i in 0..N {
        out.clock_ppm[i] = clocks[i].error_ppm();
    }
    fused
}

/// (read instant s, fused rate) per sample of the lockstep array.
fn lockstep(r: &Run) -> Vec<(f64, [f64; 3])> {
    let chips: [Chip; N] = core::array::from_fn(|i| {
        Chip::Icm(Icm42688Model::new(
            noise(i, r.scale_errors),
            r.profile,
            r.seed * 31 + i as u64,
            70,
        ))
    });
    let cs: [CsLine; N] = Default::default();
    let bus = RefCell::new(EmuBus::new(chips, &cs));
    let mut delay = EmuDelay::new(&bus, 1e-3);
    let mut g: Vec<_> = (0..N)
        .map(|i| {
            let d = emu_device(&bus, &cs[i]);
            let mut g = Icm42688::new(d);
            g.init(&mut delay, Config::default()).expect("init");
            g
        })
        .collect();
    let mut fuser = Fuser::new();
    let mut fused = Vec::new();
    for n in 0..r.ms {
        with_bus(&bus, |b| b.advance(1e-3));
        // The lockstep chips sample the profile at the bus's f32 time
        // (summed in f32: 0.5 ms off after 5 s), so their truth is there.
        let now_s = with_bus(&bus, |b| b.time_s()).unwrap_or(0.0) as f64;
        let mut y = [[0.0f32; N]; 3];
        for (i, gi) in g.iter_mut().enumerate() {
            if let Ok(v) = Gyro::read(gi) {
                for a in 0..3 {
                    y[a][i] = v.rate_dps[a];
                }
            }
        }
        if let Some(f) = fuser.fuse(&y, 0b1111) {
            if n >= WARM_MS {
                fused.push((now_s, f));
            }
        }
    }
    fused
}

#[cfg(test)]
mod tests {
    use super::lag_fit;
    use gyro_array::emu::Rng;

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
