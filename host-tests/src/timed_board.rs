//! The board's four ICM-42688-P on their own clocks through the real
//! pipeline: drivers on the FIFO path, each wrapped in [`TimedIcm`] (INT1
//! captures, clock tracker, alignment to one stated instant per sample),
//! start-up failures marked and restarted as the board does, each sample
//! through the board's own schedule (`gyro_array::app::sample`: the read,
//! fusion, the frame queued on a link port, the calibration's learning,
//! the status frames). The timed fault campaign's harness
//! (`fault-campaign --timed`), `pointing-eval`'s board and the timed
//! pipeline's tests.
//!
//! The ADXRS453 is left out: at the array's instant its rate, 3.9 ms old,
//! is always late (docs/timing.md).

use gyro_array::algo::fusion::{AdaptiveConfig, Method};
use gyro_array::app::{self as schedule, timed_clock, StatusFacts, StatusView};
use gyro_array::drivers::icm42688::{board_fifo, ClockInput, Icm42688};
use gyro_array::drivers::Gyro;
use gyro_array::link::msg::Settings;
use gyro_array::link::port::{ChipTime, NoiseSnapshot, RingPort};
use gyro_array::pipeline::timed::{self, TimedIcm};
use gyro_array::pipeline::{Output, Pipeline, PipelineConfig};
use gyro_sim::timing::{ClockParams, Vibration};
use gyro_sim::{
    emu_device, timed_array, with_bus, ChipTiming, CsLine, EmuBus, EmuCapture, EmuDelay, Fault,
    PastCount, PathReading, RateProfile, RtcTick,
};
use rtic_core::Exclusive;
use std::cell::RefCell;

/// The link as the harness runs it: the board's port, its bytes taken by
/// a UART that takes every byte.
pub struct HostLink<const TX: usize = 2048> {
    /// The port.
    pub port: RingPort<TX>,
    /// Bytes the UART took.
    pub bytes: u64,
}

struct Sink;

impl embedded_hal_nb::serial::ErrorType for Sink {
    type Error = core::convert::Infallible;
}

impl embedded_hal_nb::serial::Write<u8> for Sink {
    fn write(&mut self, _: u8) -> embedded_hal_nb::nb::Result<(), Self::Error> {
        Ok(())
    }
    fn flush(&mut self) -> embedded_hal_nb::nb::Result<(), Self::Error> {
        Ok(())
    }
}

impl<const TX: usize> schedule::Link for HostLink<TX> {
    type Queue = gyro_array::link::ring::ByteRing<TX>;
    fn port(&mut self) -> &mut RingPort<TX> {
        &mut self.port
    }
    fn flush(&mut self) {
        self.bytes += self.port.drain(&mut Sink) as u64;
    }
}

/// What the status frames say of the schedule: the board's.
pub const STATUS_VIEW: StatusView = StatusView {
    taus: gyro_array::pipeline::tracker::VIEW_TAUS,
    sample_us: 1000,
};

/// Chips.
pub const N: usize = 4;
/// The stated instant's distance behind the read, µs: the board's.
pub const DELAY_US: u32 = gyro_array::pipeline::timed::BOARD_DELAY_US;

/// The bus of the timed board.
pub type Bus<'a> = RefCell<EmuBus<'a, N>>;

/// How a run's chips keep time.
#[derive(Clone, Copy, Debug)]
pub struct Timing {
    /// The board drives CLKIN (at 32 kHz) and the chips use it.
    pub clkin: bool,
    /// Each chip's PLL error.
    pub pll: [ClockParams; N],
    /// Out-of-band vibration at the chips' dies.
    pub vibration: Vibration,
    /// What a FIFO stamp count is on CLKIN (open in the sources).
    pub rtc_tick: RtcTick,
    /// What a burst past the FIFO count gets (open in the datasheet).
    pub past_count: PastCount,
    /// The filters' shapes (open in the datasheet).
    pub path_reading: PathReading,
    /// Bus time before the board powers the chips up and starts its loop,
    /// s: where the loop's reads fall against CLKIN's edges and the chips'
    /// sample grids.
    pub power_up_s: f64,
    /// Each chip's scale error (a fraction; the fixture's chips have none).
    pub scale_error: [f32; N],
    /// The board's path trim (`Settings::path_trim_us`), as a rate table
    /// measured it (0: the datasheet's reading).
    pub path_trim_us: i16,
    /// A chip whose PLL has failed from power-up, and its RC oscillator's
    /// error (a fraction): it samples off its nominal rate by that much.
    pub rc_fallback: Option<(usize, f64)>,
}

/// The four chips' PLL errors the timed tests and the power-up sweep run
/// with (within ±1 %, as the board's crystals and the parts' spread
/// allow): offsets, a drift of 10 ppm a second and a slow wander.
pub const PLL_OFFSETS: [f64; N] = [0.009, -0.01, 0.002, -0.004];

/// [`PLL_OFFSETS`] as clock parameters.
pub fn plls() -> [ClockParams; N] {
    PLL_OFFSETS.map(|offset| ClockParams {
        offset,
        drift_per_s: 1e-5,
        wander: 2e-4,
        wander_period_s: 9.0,
    })
}

impl Timing {
    /// A power-up of the sweep ([`power_up`]): the chips on [`plls`],
    /// no vibration, started `power_up_s` into the bus's time.
    pub fn sweep(
        clkin: bool,
        rtc_tick: RtcTick,
        past_count: PastCount,
        path_reading: PathReading,
        power_up_s: f64,
    ) -> Self {
        Self {
            clkin,
            pll: plls(),
            vibration: Vibration::NONE,
            rtc_tick,
            past_count,
            power_up_s,
            path_reading,
            scale_error: [0.0; N],
            rc_fallback: None,
            path_trim_us: 0,
        }
    }
}

/// `f` over `items` on every core, in order (the evaluations' and tests'
/// sweeps of independent emulated runs).
pub fn par_map<T: Sync, R: Send>(items: &[T], f: impl Fn(&T) -> R + Sync) -> Vec<R> {
    let threads = std::thread::available_parallelism().map_or(2, |n| n.get());
    let f = &f;
    std::thread::scope(|s| {
        let jobs: Vec<_> = items
            .chunks(items.len().div_ceil(threads).max(1))
            .map(|c| s.spawn(move || c.iter().map(f).collect::<Vec<_>>()))
            .collect();
        jobs.into_iter()
            .flat_map(|j| j.join().expect("a run panicked"))
            .collect()
    })
}

/// What the harness hands each sample's callback.
pub struct Sample<'a, 'b> {
    /// Pipeline steps so far (this one included: 0 for the first).
    pub n: u32,
    /// The bus (inject faults, stop CLKIN, …).
    pub bus: &'a Bus<'b>,
    /// The pipeline's output.
    pub out: &'a Output<N>,
    /// The pipeline.
    pub pipe: &'a Pipeline<N>,
    /// The instant the sample states, s of bus time.
    pub stated_s: f64,
    /// Per chip, how far the instant its newest moving mean describes lies
    /// behind the read, µs (NaN before its clock is tracked).
    pub newest_behind_us: [f64; N],
}

/// What a run leaves behind.
pub struct Ran {
    /// What each chip's timing layer counted.
    pub timing: [gyro_array::pipeline::timed::TimingCounters; N],
    /// Where each chip takes its clock from at the end.
    pub clock_inputs: [ClockInput; N],
    /// Each chip's clock error as its tracker reports it at the end, ppm.
    pub clock_ppm: [f32; N],
    /// FIFO packets each emulated chip's bus read out whole (the truth
    /// [`Ran::timing`]'s samples are held to).
    pub read_out: [u64; N],
}

/// Run `samples` pipeline steps. `stall(n)` > 0 before step `n` makes the
/// loop miss that many periods (the bus advances, nothing is read, the
/// pipeline is told of the overrun). `each` runs after every step.
pub fn run(
    profile: RateProfile,
    seed: u64,
    samples: u32,
    timing: Timing,
    at_power_up: [Fault; N],
    stall: impl Fn(u32) -> u32,
    mut each: impl FnMut(Sample<'_, '_>),
) -> Ran {
    let mut chips = timed_array(
        profile,
        seed,
        core::array::from_fn(|i| ChipTiming {
            pll: timing.pll[i],
            vibration: timing.vibration,
            rtc_tick: timing.rtc_tick,
            past_count: timing.past_count,
            path_reading: timing.path_reading,
            rc: match timing.rc_fallback {
                Some((chip, offset)) if chip == i => ClockParams::fixed(offset),
                _ => ChipTiming::pll(0.0).rc,
            },
            ..ChipTiming::pll(0.0)
        }),
    );
    for (i, (c, f)) in chips.iter_mut().zip(at_power_up).enumerate() {
        c.set_fault(f);
        if let Some(icm) = c.icm() {
            icm.set_scale_error(timing.scale_error[i]);
            icm.fail_pll(timing.rc_fallback.is_some_and(|(chip, _)| chip == i));
        }
    }
    let cs: [CsLine; N] = Default::default();
    let bus: Bus = RefCell::new(EmuBus::new(chips, &cs));
    // Each byte takes its time at the board's ICM-42688-P SPI clock: the
    // chips sample while a burst is read, as on the board.
    with_bus(&bus, |b| {
        b.spi_byte_s = 8.0 / f64::from(timed::BOARD_SPI_ICM_HZ);
    });
    if timing.clkin {
        with_bus(&bus, |b| b.clkin_hz = Some(32_000.0));
    }
    if timing.power_up_s > 0.0 {
        with_bus(&bus, |b| b.advance(timing.power_up_s as f32));
    }
    let mut delay = EmuDelay::new(&bus, 1e-3);
    let cfg = board_fifo(if timing.clkin {
        ClockInput::ClkIn
    } else {
        ClockInput::Internal
    });
    let Ok(mut pipe) = Pipeline::<N>::new(
        PipelineConfig::default(),
        Method::Adaptive(AdaptiveConfig::default()),
    ) else {
        panic!("pipeline settings")
    };
    let mut t: Vec<_> = (0..N)
        .map(|i| {
            let d = emu_device(&bus, &cs[i]);
            let mut g = Icm42688::new(d);
            if g.init(&mut delay, cfg).is_err() {
                pipe.mark_init_failed(i);
            }
            TimedIcm::new(
                g,
                EmuCapture {
                    bus: &bus,
                    index: i,
                },
            )
        })
        .collect();
    // The chips set up first ran while the others were: one start for all.
    for ti in t.iter_mut() {
        let _ = ti.driver().flush_fifo();
    }
    let mut link: HostLink = HostLink {
        port: RingPort::new(
            Settings {
                path_trim_us: timing.path_trim_us,
                ..Settings::default()
            },
            gyro_array::app::BOARD_FRAME_PATH,
        ),
        bytes: 0,
    };
    let mut noise = NoiseSnapshot::default();
    for n in 0..samples {
        let k = stall(n);
        if k > 0 {
            for _ in 0..k {
                with_bus(&bus, |b| b.advance(1e-3));
            }
        }
        with_bus(&bus, |b| b.advance(1e-3));
        let now_us = with_bus(&bus, |b| b.time64_s()).unwrap_or(0.0) * 1e6;
        let stated_us = now_us - f64::from(timed::board_delay_us(timing.path_trim_us));
        let mut clocks = [ChipTime::default(); N];
        for (slot, ti) in clocks.iter_mut().zip(t.iter()) {
            *slot = timed_clock(ti);
        }
        let out = {
            let (a, rest) = t.split_at_mut(1);
            let (b, rest) = rest.split_at_mut(1);
            let (c, d) = rest.split_at_mut(1);
            let mut g: [&mut dyn Gyro; N] = [&mut a[0], &mut b[0], &mut c[0], &mut d[0]];
            schedule::sample(
                &mut Exclusive(&mut pipe),
                &mut Exclusive(&mut link),
                &mut Exclusive(&mut noise),
                &mut g,
                (now_us as u64, k),
                &STATUS_VIEW,
                || {},
                || StatusFacts {
                    clocks,
                    stack_peak: 0,
                },
            )
            .out
        };
        if std::env::var_os("CAMPAIGN_TRACE").is_some() {
            println!(
                "{n} timing {:?}",
                t.iter()
                    .map(|x| (x.counters.missing, x.counters.acquiring, x.counters.jumps))
                    .collect::<Vec<_>>()
            );
        }
        let now16 = (now_us as u64 as u32).wrapping_mul(16);
        let newest_behind_us = core::array::from_fn(|i| {
            t[i].newest_instant().map_or(f64::NAN, |at| {
                f64::from(now16.wrapping_sub(at) as i32) / 16.0
            })
        });
        each(Sample {
            n,
            bus: &bus,
            out: &out,
            pipe: &pipe,
            stated_s: stated_us * 1e-6,
            newest_behind_us,
        });
    }
    Ran {
        timing: core::array::from_fn(|i| t[i].counters),
        clock_inputs: core::array::from_fn(|i| t[i].clock_input()),
        clock_ppm: core::array::from_fn(|i| t[i].clock().error_ppm()),
        read_out: core::array::from_fn(|i| {
            with_bus(&bus, |b| {
                b.chips[i].icm().map_or(0, |c| c.packets_read_out())
            })
            .unwrap_or(0)
        }),
    }
}

/// One power-up of the phase sweep ([`power_up`]).
#[derive(Clone, Copy, Debug)]
pub struct PowerUp {
    /// Each chip's lag against the truth at the stated instant, µs
    /// (positive: its rate is older than stated), fitted over the
    /// measured part of the run on every axis: the rate's error against
    /// the truth's slope.
    pub lag_us: [f64; N],
    /// Each chip's reads in the measured part, and of those, late ones.
    pub reads: [u32; N],
    /// See [`PowerUp::reads`].
    pub late: [u32; N],
    /// What each chip's timing layer counted over the whole run.
    pub timing: [gyro_array::pipeline::timed::TimingCounters; N],
}

/// Power the timed board up with `timing` (its phase in
/// [`Timing::power_up_s`]) on `profile` for `ms` ms; from `warm_ms` on,
/// fit each chip's lag at the stated instant and count its late reads.
/// A chip tracked a sample period off (250 µs at 4 kHz) reads as a lag of
/// that size.
pub fn power_up(profile: RateProfile, seed: u64, timing: Timing, ms: u32, warm_ms: u32) -> PowerUp {
    let mut num = [0.0f64; N];
    let mut den = [0.0f64; N];
    let mut at_warm = None;
    let mut last = None;
    let ran = run(
        profile,
        seed,
        ms,
        timing,
        [Fault::None; N],
        |_| 0,
        |smp| {
            if smp.n == warm_ms {
                at_warm = Some(*smp.pipe.counters());
            }
            last = Some(*smp.pipe.counters());
            if smp.n < warm_ms {
                return;
            }
            let h = 1e-6;
            let truth = profile.at_f64(smp.stated_s);
            let ahead = profile.at_f64(smp.stated_s + h);
            for (i, rates) in smp.out.rate_dps.iter().enumerate() {
                for a in 0..3 {
                    let r = f64::from(rates[a]);
                    if !r.is_finite() {
                        continue;
                    }
                    let slope = (ahead[a] - truth[a]) / h;
                    // A rate `lag` old is truth − lag · slope.
                    num[i] -= (r - truth[a]) * slope;
                    den[i] += slope * slope;
                }
            }
        },
    );
    let (w, l) = (at_warm.expect("warm-up inside the run"), last.expect("ran"));
    PowerUp {
        lag_us: core::array::from_fn(|i| num[i] / den[i].max(1e-30) * 1e6),
        reads: core::array::from_fn(|i| {
            let f = |c: &gyro_array::pipeline::GyroCounters| c.reads + c.errors + c.late;
            f(&l[i]) - f(&w[i])
        }),
        late: core::array::from_fn(|i| l[i].late - w[i].late),
        timing: ran.timing,
    }
}

/// The bench procedure (docs/timing.md) on the emulated board: `ms` of a
/// rate table's `profile` (the first `warm_ms` left out), the fused rate at
/// each instant the board states, through `gyro lag`'s fit
/// ([`gyro_tool::lag::fit`]) against the table's rate on the board's clock.
/// Per axis the fit, and their inverse-variance lag (`None` where no axis
/// moved enough).
pub fn bench_lag(
    profile: RateProfile,
    seed: u64,
    timing: Timing,
    ms: u32,
    warm_ms: u32,
) -> (Vec<gyro_tool::lag::AxisLag>, Option<(f64, f64)>) {
    let mut at_us: [Vec<f64>; 3] = Default::default();
    let mut rate: [Vec<f64>; 3] = Default::default();
    run(
        profile,
        seed,
        ms,
        timing,
        [Fault::None; N],
        |_| 0,
        |smp| {
            if smp.n < warm_ms {
                return;
            }
            for (a, f) in smp.out.fused.iter().enumerate() {
                if let Some(f) = f {
                    at_us[a].push(smp.stated_s * 1e6);
                    rate[a].push(f64::from(f.rate_dps));
                }
            }
        },
    );
    let axes: Vec<gyro_tool::lag::AxisLag> = (0..3)
        .filter_map(|a| {
            let truth = |t_us: f64| profile.at_f64(t_us * 1e-6)[a];
            gyro_tool::lag::fit(&at_us[a], &rate[a], &truth, (f64::MIN, f64::MAX))
        })
        .collect();
    let lag = gyro_tool::lag::combined(&axes);
    (axes, lag)
}
