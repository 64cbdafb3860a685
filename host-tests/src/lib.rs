//! Host-side helpers shared by the tests and the evaluation binaries.
// As in the firmware crate: `!(x > 0.0)` is also true for NaN, and the
// numeric code indexes several arrays by the same chip index.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop)]

pub mod demo_host;
pub mod noise_classes;
pub mod real;
pub mod single_chip;

pub mod args {
    //! Value parsers the evaluations' command lines share (clap's
    //! `value_parser`).

    /// A finite number above 0.
    pub fn positive(s: &str) -> Result<f64, String> {
        match s.parse::<f64>() {
            Ok(v) if v > 0.0 && v.is_finite() => Ok(v),
            _ => Err(format!("{s}: not a positive number")),
        }
    }
}

pub mod latency {
    //! The board's delay from a sample's read to the antenna, shared by
    //! `timing-eval` (its latency budget) and `pointing-eval` (when each
    //! sample reaches the positioner).

    use gyro_array::drivers::icm42688::{board_fifo, ClockInput, Config};

    /// The loop's compute on the frame's path, µs: `cargo xtask
    /// bench-loop`'s target (10 000 instructions) at the STM32F405's
    /// 168 MHz.
    pub const COMPUTE_US: f64 = 10_000.0 / 168.0;

    /// The SPI transfers of one sample's reads on the board, µs, with the
    /// ICM-42688-Ps sampling through `cfg`'s FIFO (the board's own
    /// figure, `pipeline::timed::board_spi_us`).
    pub fn spi_us(cfg: &Config) -> f64 {
        f64::from(gyro_array::pipeline::timed::board_spi_us(cfg))
    }

    /// From the read to the sample frame queued, µs, with chips sampling
    /// through `cfg`: the SPI transfers, then the compute.
    pub fn loop_us(cfg: &Config) -> f64 {
        spi_us(cfg) + COMPUTE_US
    }

    /// Bytes of the largest sample frame on the wire (every field filled,
    /// an E-DAVAR estimate included, five gyros): the link's own figure,
    /// which its tests check against its encoder.
    pub fn sample_frame_bytes() -> usize {
        gyro_array::link::port::SAMPLE_FRAME_MAX as usize
    }

    /// The frame's time on the wire at the link's speed (8N1), µs.
    pub fn wire_us(frame_bytes: usize) -> f64 {
        frame_bytes as f64 * 10.0 / gyro_array::link::BAUD as f64 * 1e6
    }

    /// From the read to the sample frame's last byte at the antenna, µs:
    /// the board's SPI reads, the loop's worst sample and the largest
    /// frame on the wire.
    pub fn read_to_antenna_us() -> f64 {
        loop_us(&board_fifo(ClockInput::ClkIn)) + wire_us(sample_frame_bytes())
    }
}
pub mod stated;
pub mod timed_board;

pub mod calibration {
    //! The static calibration procedure on the emulated array:
    //! a rate table (±100 °/s about each board axis at 25 °C) and a
    //! thermal chamber (still, at 5, 25 and 45 °C), each held for `hold`
    //! samples, read through the real drivers and pipeline (with an
    //! identity calibration so that the pipeline reports chip-frame rates
    //! and polls each chip's die temperature). From the means:
    //!
    //! - chip = A · board + b(T): column k of A is (r₊ − r₋)/(2ω) of the
    //!   runs about board axis k; M = A⁻¹ (the ADXRS453: 1/A_zz);
    //! - b(T) = b₂₅ + k·(T − 25): a least-squares line through the three
    //!   still runs against the temperature the drivers read.

    use gyro_array::algo::static_cal::{inverse3, CalRecord, ChipCal};
    use gyro_sim::checks::run_array_from_seq;
    use gyro_sim::{board_array, mounted_board, Fault, Mount, RateProfile, TempProfile};

    /// Rate of the rate-table runs, °/s.
    pub const OMEGA: f32 = 100.0;
    /// Samples ignored at the start of each run (start-up, filters).
    const SETTLE: u32 = 200;

    /// Mean chip-frame rate per chip and axis, and mean die temperature
    /// per chip, of one run.
    fn run(rate: [f32; 3], temp_c: f32, hold: u32, seed: u64) -> ([[f64; 3]; 5], [f64; 5]) {
        let profile = RateProfile {
            base_dps: rate,
            sine_dps: [0.0; 3],
            sine_hz: 0.0,
            sine_start_s: 0.0,
        };
        let identity = CalRecord {
            serial: 0,
            chips: [ChipCal::IDENTITY; 5].into_iter().collect(),
        };
        let mut sum = [[0.0f64; 3]; 5];
        let mut n = [[0u32; 3]; 5];
        let (mut tsum, mut tn) = ([0.0f64; 5], [0u32; 5]);
        run_array_from_seq(
            0,
            profile,
            seed,
            SETTLE + hold,
            [Fault::None; 5],
            None,
            Some(mounted_board(TempProfile::constant(temp_c))),
            Some(&identity),
            |k, _, out, pipe| {
                if k < SETTLE {
                    return;
                }
                for (i, r) in out.rate_dps.iter().enumerate() {
                    for a in 0..3 {
                        if r[a].is_finite() {
                            sum[i][a] += r[a] as f64;
                            n[i][a] += 1;
                        }
                    }
                }
                if k % 50 == 25 {
                    for (i, t) in pipe.temperatures().iter().enumerate() {
                        if let Some(t) = t {
                            tsum[i] += *t as f64;
                            tn[i] += 1;
                        }
                    }
                }
            },
        );
        let mean = core::array::from_fn(|i| {
            core::array::from_fn(|a| {
                if n[i][a] > 0 {
                    sum[i][a] / n[i][a] as f64
                } else {
                    f64::NAN
                }
            })
        });
        let temp = core::array::from_fn(|i| {
            if tn[i] > 0 {
                tsum[i] / tn[i] as f64
            } else {
                f64::NAN
            }
        });
        (mean, temp)
    }

    /// Run the procedure; the record for the emulated board.
    pub fn calibrate(hold: u32, seed: u64) -> Option<CalRecord> {
        let w = OMEGA as f64;
        let mut a = [[[0.0f64; 3]; 3]; 5];
        for k in 0..3 {
            let mut rate = [0.0f32; 3];
            rate[k] = OMEGA;
            let (p, _) = run(rate, 25.0, hold, seed);
            rate[k] = -OMEGA;
            let (m, _) = run(rate, 25.0, hold, seed + 1);
            for i in 0..5 {
                for r in 0..3 {
                    a[i][r][k] = (p[i][r] - m[i][r]) / (2.0 * w);
                }
            }
        }
        // Still runs at three temperatures: bias line per chip axis.
        let runs: Vec<_> = [5.0f32, 25.0, 45.0]
            .iter()
            .enumerate()
            .map(|(j, &t)| run([0.0; 3], t, hold, seed + 10 + j as u64))
            .collect();
        let mut chips = heapless::Vec::new();
        for i in 0..5 {
            let ts: Vec<f64> = runs.iter().map(|r| r.1[i]).collect();
            let tbar = ts.iter().sum::<f64>() / 3.0;
            let mut c = ChipCal::IDENTITY;
            for r in 0..3 {
                let bs: Vec<f64> = runs.iter().map(|x| x.0[i][r]).collect();
                let bbar = bs.iter().sum::<f64>() / 3.0;
                let (mut sxy, mut sxx) = (0.0, 0.0);
                for (t, b) in ts.iter().zip(&bs) {
                    sxy += (t - tbar) * (b - bbar);
                    sxx += (t - tbar) * (t - tbar);
                }
                let k = if sxx > 0.0 { sxy / sxx } else { 0.0 };
                let b25 = bbar + k * (25.0 - tbar);
                c.bias_tc_dps_per_c[r] = if k.is_finite() { k as f32 } else { 0.0 };
                c.bias_dps[r] = if b25.is_finite() { b25 as f32 } else { 0.0 };
            }
            c.t_ref_c = 25.0;
            if i < 4 {
                let m = inverse3(&a[i])?;
                c.m = m.map(|r| r.map(|v| v as f32));
            } else {
                c.m[2][2] = (1.0 / a[i][2][2]) as f32;
            }
            chips.push(c).ok()?;
        }
        Some(CalRecord { serial: 1, chips })
    }

    /// How far a record is from the emulated board's true constants.
    #[derive(Debug)]
    pub struct Errors {
        /// Largest |(M·A_true − I)ᵢⱼ| per chip (scale and misalignment left).
        pub scale: [f64; 5],
        /// Largest |b − b_true| per chip, °/s.
        pub bias_dps: [f64; 5],
        /// Largest |k − k_true| per chip, °/s/°C.
        pub tc: [f64; 5],
    }

    /// Compare `rec` with the truth of the emulated board.
    pub fn errors(rec: &CalRecord) -> Errors {
        let chips = board_array(RateProfile::constant(0.0), 1);
        let mounts: [Mount; 5] = mounted_board(TempProfile::ROOM);
        let mut e = Errors {
            scale: [0.0; 5],
            bias_dps: [0.0; 5],
            tc: [0.0; 5],
        };
        for i in 0..5 {
            let (bias, se) = chips[i].bias_and_scale();
            let c = &rec.chips[i];
            let at = |r: usize, k: usize| (1.0 + se as f64) * mounts[i].m[r][k] as f64;
            let axes: &[usize] = if i < 4 { &[0, 1, 2] } else { &[2] };
            for &r in axes {
                e.bias_dps[i] = e.bias_dps[i].max((c.bias_dps[r] as f64 - bias as f64).abs());
                e.tc[i] = e.tc[i].max(
                    (c.bias_tc_dps_per_c[r] as f64 - mounts[i].bias_tc_dps_per_c[r] as f64).abs(),
                );
                for k in 0..3 {
                    let v = if i < 4 {
                        (0..3).map(|l| c.m[r][l] as f64 * at(l, k)).sum::<f64>()
                    } else if k == 2 {
                        c.m[2][2] as f64 * at(2, 2)
                    } else {
                        continue;
                    };
                    let want = if r == k { 1.0 } else { 0.0 };
                    e.scale[i] = e.scale[i].max((v - want).abs());
                }
            }
        }
        e
    }
}

pub mod motion {
    //! The board's noise tracker on a moving vehicle, shared by the
    //! `noise_in_motion` test and the `motion` figure: the emulated board
    //! (five chips through their drivers, calibration and fusion) turning
    //! at 100 °/s about z and swaying at 2 Hz (30 °/s on z, 15 °/s on x, y
    //! still), its fused rate, its fused error against the emulator's true
    //! rate, and the tracker's E-DAVAR estimates.

    use gyro_array::pipeline::tracker::{self, sigma_dps, NoiseTracker};
    use gyro_sim::checks::run_board_array_from;
    use gyro_sim::{Fault, RateProfile};

    /// The vehicle's motion.
    pub const PROFILE: RateProfile = RateProfile {
        base_dps: [0.0, 0.0, 100.0],
        sine_dps: [15.0, 0.0, 30.0],
        sine_hz: 2.0,
        sine_start_s: 0.0,
    };

    /// One run, per axis (x, y, z).
    pub struct Run {
        /// The fused rate, °/s, on every sample that has one.
        pub rate: [Vec<f64>; 3],
        /// The fused rate less the true rate, °/s (the oracle's input).
        pub err: [Vec<f64>; 3],
        /// σ (°/s) of each new tracker estimate at τ = 2ʲ samples, per j.
        pub sigma: [[Vec<f64>; 9]; 3],
    }

    /// `samples` samples of the board with noise seed `seed`; `None` if it
    /// does not start.
    pub fn run(seed: u64, samples: u32) -> Option<Run> {
        let mut noise = NoiseTracker::<1024, 35, 9>::new(tracker::config(1024)).ok()?;
        let mut out = Run {
            rate: Default::default(),
            err: Default::default(),
            sigma: Default::default(),
        };
        let mut last = [None; 3];
        run_board_array_from(PROFILE, seed, samples, [Fault::None; 5], |_, bus, o, _| {
            noise.push(o);
            let truth = bus.borrow().chips[0].true_rate_dps();
            for a in 0..3 {
                if let Some(f) = o.fused[a] {
                    out.err[a].push(f64::from(f.rate_dps - truth[a]));
                    out.rate[a].push(f64::from(f.rate_dps));
                }
                if let Some(e) = noise.estimate(a) {
                    if last[a] != Some(e.seq) {
                        last[a] = Some(e.seq);
                        for (j, v) in out.sigma[a].iter_mut().enumerate() {
                            v.push(f64::from(sigma_dps(&e.step, j)));
                        }
                    }
                }
            }
        })?;
        Some(out)
    }
}
