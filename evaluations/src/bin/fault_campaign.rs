//! Fault-injection campaign through the whole emulated board: the real
//! drivers on the emulated SPI bus, start-up, the pipeline with recovery and
//! fusion, for many runs with random fault schedules.
//!
//! `cargo run -p evaluations --profile host --bin fault-campaign -- [--runs N] [--seed S] [--samples N]`
//!
//! Each run draws a rate profile (constant, or a sway of up to 20 °/s at
//! 0.2–5 Hz, running from power-up), one or two faulty chips (two at once
//! in half the runs), and for each a fault, an onset (at power-up in a
//! quarter of the cases) and a duration (permanent in a quarter). Faults:
//! stuck, saturated, spikes (small or large), byte bit errors, single-bit
//! frame errors (ADXRS453), wrong id, no response, chip fault (ADXRS453),
//! power off (a late power-up when it starts at power-up), a power cycle
//! (a reset, instantaneous) and a corrupted range register (ICM-42688-P,
//! instantaneous, unflagged: only the configuration read-back finds it).
//!
//! Invariants checked per run (a violation prints the run's seed, which
//! reproduces it with `--seed S --runs 1`; `CAMPAIGN_TRACE=A` then prints
//! axis A's fusion (0 = x; anything else: z) and the faulty chips' health
//! at every sample):
//! 1. no panic;
//! 2. every sample accounted for: sequence numbers 0, 1, 2, … and, per
//!    gyro, reads + errors + samples not read (restarting) = samples;
//! 3. a deterministic fault (stuck, saturated, wrong id, no response, chip
//!    fault, power off) is out of fusion within 20 samples of its onset and
//!    stays out while it lasts (a stuck chip: from the sample it is flagged
//!    or rejected, as its first frozen samples still equal the truth);
//! 4. the fused rate is within 1 °/s of the truth on every axis where a
//!    healthy majority exists (more chips on that axis without a fault than
//!    with one);
//! 5. every chip is back in fusion after its fault ends: within 100 samples,
//!    plus the part's datasheet restart time after a reset (ICM-42688-P
//!    46 ms, ADXRS453 100 ms of start-up check; a corrupted register, up to
//!    [`READ_BACK`] samples until its read-back comes round), plus, when the chip was in
//!    the restart cycle as its fault ended, the back-off then in force and
//!    one restart (retries of a chip that stays lost slow down to once a
//!    second).

use std::process::ExitCode;
use std::sync::atomic::{AtomicU32, Ordering};

use gyro_sim::checks::run_board_array_from;
use gyro_sim::{Fault, RateProfile, Rng};

const SAMPLES: u32 = 3000;

/// Samples until a gyro's configuration is read back, at most: the
/// pipeline reads one gyro's in turn every `check_every` samples, five
/// gyros. A chip with a corrupted register counts as faulty until then
/// and its restart.
const READ_BACK: u32 = 5 * gyro_array::pipeline::PipelineConfig::DEFAULT_CHECK_EVERY;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    Fault(Fault),
    PowerCycle,
    /// A corrupted configuration register (ICM-42688-P range bits).
    CorruptConfig,
}

#[derive(Clone, Copy, Debug)]
struct Injection {
    chip: usize,
    kind: Kind,
    start: u32,
    /// Exclusive end (u32::MAX: permanent).
    end: u32,
}

impl Injection {
    fn active(&self, n: u32) -> bool {
        (self.start..self.end).contains(&n)
    }
    /// A fault whose chip must be out of fusion while it lasts. A wrong
    /// id only matters when the chip is probed: at power-up, not while it
    /// delivers good data.
    fn deterministic(&self) -> bool {
        match self.kind {
            Kind::Fault(Fault::WrongId) => self.start == 0,
            Kind::Fault(
                Fault::Stuck
                | Fault::Saturated
                | Fault::NoResponse
                | Fault::ChipFault
                | Fault::PoweredOff,
            ) => true,
            _ => false,
        }
    }
}

fn draw(seed: u64, samples: u32) -> (RateProfile, Vec<Injection>) {
    let mut rng = Rng::new(seed);
    let profile = if rng.uniform() < 0.5 {
        RateProfile::constant(rng.uniform() * 10.0 - 5.0)
    } else {
        RateProfile {
            base_dps: [0.5, -0.3, 1.0],
            sine_dps: [
                20.0 * rng.uniform(),
                20.0 * rng.uniform(),
                20.0 * rng.uniform(),
            ],
            sine_hz: 0.2 + 4.8 * rng.uniform(),
            sine_start_s: 0.0,
        }
    };
    let count = if rng.uniform() < 0.5 { 1 } else { 2 };
    let mut inj: Vec<Injection> = Vec::new();
    while inj.len() < count {
        let chip = (rng.next_u32() % 5) as usize;
        if inj.iter().any(|i| i.chip == chip) {
            continue;
        }
        let adx = chip == 4;
        let kinds: &[Kind] = &[
            Kind::Fault(Fault::Stuck),
            Kind::Fault(Fault::Saturated),
            Kind::Fault(Fault::Spikes {
                prob: 0.05,
                magnitude_dps: 0.3,
            }),
            Kind::Fault(Fault::Spikes {
                prob: 0.05,
                magnitude_dps: 200.0,
            }),
            Kind::Fault(Fault::BitErrors { prob: 0.05 }),
            Kind::Fault(Fault::WrongId),
            Kind::Fault(Fault::NoResponse),
            Kind::Fault(Fault::PoweredOff),
            Kind::PowerCycle,
            Kind::CorruptConfig,
            Kind::Fault(if adx { Fault::ChipFault } else { Fault::Stuck }),
            Kind::Fault(if adx {
                Fault::FrameBitError { prob: 0.05 }
            } else {
                Fault::BitErrors { prob: 0.01 }
            }),
        ];
        let kind = kinds[(rng.next_u32() as usize) % kinds.len()];
        let instant = matches!(kind, Kind::PowerCycle | Kind::CorruptConfig);
        let start = if rng.uniform() < 0.25 && !instant {
            0
        } else {
            1 + rng.next_u32() % (samples * 2 / 3)
        };
        let end = match kind {
            Kind::PowerCycle | Kind::CorruptConfig => start + 1,
            _ if rng.uniform() < 0.25 => u32::MAX,
            _ => start + 50 + rng.next_u32() % 1000,
        };
        inj.push(Injection {
            chip,
            kind,
            start,
            end,
        });
    }
    (profile, inj)
}

/// Inject for the next sample (the chips advance before it): each fault at
/// its start, cleared at its end.
fn inject<const N: usize>(b: &mut gyro_sim::EmuBus<'_, N>, inj: &[Injection], n: u32) {
    for i in inj {
        if n + 1 == i.start {
            match i.kind {
                Kind::Fault(f) => b.chips[i.chip].set_fault(f),
                Kind::PowerCycle => b.chips[i.chip].power_cycle(),
                Kind::CorruptConfig => b.chips[i.chip].corrupt_config(),
            }
        }
        if n + 1 == i.end && !matches!(i.kind, Kind::PowerCycle | Kind::CorruptConfig) {
            b.chips[i.chip].set_fault(Fault::None);
        }
    }
}

/// After a run: invariant 2 on the counters (every sample one of reads,
/// errors, not read, late) and invariant 3 on each deterministic fault
/// (out of fusion within 20 samples of its onset).
fn check_after_run(
    counters: Option<&[gyro_array::pipeline::GyroCounters]>,
    samples: u32,
    inj: &[Injection],
    out_at: &[Option<u32>],
    bad: &mut Vec<String>,
) {
    for (g, c) in counters.unwrap_or(&[]).iter().enumerate() {
        let total = c.reads + c.errors + c.not_read + c.late;
        if total != samples {
            bad.push(format!(
                "2: gyro {g}: reads + errors + not read + late = {total} of {samples}"
            ));
        }
    }
    for (i, out) in inj.iter().zip(out_at) {
        if i.deterministic() && i.end > i.start + 20 {
            match out {
                Some(o) if *o <= i.start + 20 => {}
                o => bad.push(format!(
                    "3: chip {} out at {o:?} after {:?} from {}",
                    i.chip, i.kind, i.start
                )),
            }
        }
    }
}

/// The invariants a run broke (empty: none).
fn run(seed: u64, samples: u32) -> Vec<String> {
    let (profile, inj) = draw(seed, samples);
    let mut bad: Vec<String> = Vec::new();
    let mut at_power_up = [Fault::None; 5];
    for i in &inj {
        if let (Kind::Fault(f), 0) = (i.kind, i.start) {
            at_power_up[i.chip] = f;
        }
    }
    // Per injection: first sample out of fusion, first sample back.
    let mut out_at = vec![None::<u32>; inj.len()];
    let mut back_at = vec![None::<u32>; inj.len()];
    let mut backoff_at_end = vec![0u32; inj.len()];
    let mut flagged_at = vec![None::<u32>; inj.len()];
    let mut last_counters = None;
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        run_board_array_from(profile, seed, samples, at_power_up, |n, bus, out, pipe| {
            // Inject for the next sample (the chips advance before it).
            gyro_sim::with_bus(bus, |b| inject(b, &inj, n));
            if out.seq != n {
                bad.push(format!("2: sequence {} at sample {n}", out.seq));
            }
            let truth = gyro_sim::with_bus(bus, |b| b.chips[0].true_rate_dps()).unwrap_or([0.0; 3]);
            for (k, i) in inj.iter().enumerate() {
                let used = out.offered.iter().any(|m| m & (1 << i.chip) != 0);
                let flagged = pipe.health()[i.chip].flags != 0;
                if i.active(n) {
                    if !used && out_at[k].is_none() {
                        out_at[k] = Some(n);
                    }
                    if flagged && flagged_at[k].is_none() {
                        flagged_at[k] = Some(n);
                    }
                    if i.deterministic() && used && n >= i.start + 20 {
                        let frozen_ok = i.kind == Kind::Fault(Fault::Stuck)
                            && flagged_at[k].is_none_or(|f| n < f);
                        if !frozen_ok {
                            bad.push(format!(
                                "3: chip {} used at sample {n} during {:?}",
                                i.chip, i.kind
                            ));
                        }
                    }
                } else if n >= i.end && used && back_at[k].is_none() {
                    back_at[k] = Some(n);
                }
                if n + 1 == i.end || n == i.end {
                    // The restart cycle the chip is in as its fault ends
                    // (a restart may have been triggered by the last bad
                    // sample, which the pipeline reads on the end sample).
                    backoff_at_end[k] = backoff_at_end[k].max(pipe_backoff(pipe, i.chip, n));
                }
            }
            // Healthy majority per axis: chips on the axis with / without an
            // active fault.
            for (a, f) in out.fused.iter().enumerate() {
                let on_axis = |c: usize| a == 2 || c < 4;
                let faulty = inj
                    .iter()
                    .filter(|i| {
                        // A reset chip counts as faulty while it restarts;
                        // a silently corrupted one until its read-back.
                        on_axis(i.chip)
                            && (i.active(n)
                                || i.kind == Kind::PowerCycle && n >= i.start && n < i.start + 200
                                || i.kind == Kind::CorruptConfig
                                    && n >= i.start
                                    && n < i.start + READ_BACK + 50)
                    })
                    .count();
                let total = (0..5).filter(|&c| on_axis(c)).count();
                if total - faulty > faulty {
                    match f {
                        Some(f) if (f.rate_dps - truth[a]).abs() <= 1.0 => {}
                        Some(f) => bad.push(format!(
                            "4: axis {a} fused {:.2} vs truth {:.2} at sample {n}",
                            f.rate_dps, truth[a]
                        )),
                        None => bad.push(format!("4: axis {a} has no fused value at sample {n}")),
                    }
                }
            }
            last_counters = Some(*pipe.counters());
            if let Some(axis) = std::env::var("CAMPAIGN_TRACE")
                .ok()
                .map(|v| v.parse::<usize>().unwrap_or(2).min(2))
            {
                if let Some(f) = out.fused[axis] {
                    println!(
                        "{n} {} fused {:.3} truth {:.3} w {:?} rates {:?} rej {:#07b} fb {}",
                        ["x", "y", "z"][axis],
                        f.rate_dps,
                        truth[axis],
                        f.weights,
                        out.rate_dps.iter().map(|r| r[axis]).collect::<Vec<_>>(),
                        f.rejected,
                        f.fallback
                    );
                }
                for i in &inj {
                    let h = pipe.health()[i.chip];
                    println!(
                        "{n} chip {} flags {:#07b} {:?} offered {}",
                        i.chip,
                        h.flags,
                        h.recovery,
                        out.offered.iter().any(|m| m & (1 << i.chip) != 0)
                    );
                }
            }
        })
    }));
    if result.is_err() {
        bad.push("1: panic".into());
        return bad;
    }
    check_after_run(
        last_counters.as_ref().map(|c| &c[..]),
        samples,
        &inj,
        &out_at,
        &mut bad,
    );
    for (k, i) in inj.iter().enumerate() {
        if i.end < samples.saturating_sub(400) {
            let restart = match (i.kind, i.chip) {
                (Kind::PowerCycle | Kind::Fault(Fault::PoweredOff), 4) => 100,
                (Kind::PowerCycle | Kind::Fault(Fault::PoweredOff), _) => 46,
                // Found by the read-back: each gyro every 5 × 50 samples.
                (Kind::CorruptConfig, _) => READ_BACK + 46,
                _ => 0,
            };
            // A chip out of fusion long enough is restarted; when its fault
            // ends it may be waiting for the next attempt, plus that
            // attempt's restart time.
            let backoff = if backoff_at_end[k] > 0 {
                backoff_at_end[k] + if i.chip == 4 { 100 } else { 46 }
            } else {
                0
            };
            let limit = i.end + 100 + restart + backoff;
            if limit >= samples {
                continue; // not observable within the run
            }
            match back_at[k] {
                Some(b) if b <= limit => {}
                b => bad.push(format!(
                    "5: chip {} back at {b:?} after {:?} ended at {} (limit {limit})",
                    i.chip, i.kind, i.end
                )),
            }
        }
    }
    bad
}

/// How long a gyro in the restart cycle at sample `n` may take to start
/// its first attempt that can succeed: the wait to the next attempt, or,
/// with one under way (begun while the fault lasted, so it fails), that
/// attempt's rest plus the back-off after it. 0 when it is running.
fn pipe_backoff(pipe: &gyro_array::pipeline::Pipeline<5>, chip: usize, n: u32) -> u32 {
    let h = pipe.health()[chip];
    match h.recovery {
        gyro_array::pipeline::Recovery::Waiting { at } => at.saturating_sub(n).max(1),
        gyro_array::pipeline::Recovery::Restarting { at, .. } => {
            at.saturating_sub(n) + 100 + h.backoff()
        }
        gyro_array::pipeline::Recovery::Running => 0,
    }
}

/// A timing event of the timed campaign (no chip fault: the chips'
/// samples stay good).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Timing {
    /// The chip's PLL fails for a while: it runs on its RC oscillator.
    ClockToRc,
    /// CLKIN stops (every chip on it at once), for good.
    ClkInLost,
    /// The loop stalls this many ms (the bus does not): FIFOs overflow.
    Stall(u32),
    /// The chip's next FIFO burst loses its chip select after this many
    /// bytes (inside its packets: a cut in the status or count bytes reads
    /// as a chip that stopped answering, a fault).
    Cut(u32),
}

#[derive(Clone, Copy, Debug)]
struct TimingEvent {
    chip: usize,
    what: Timing,
    start: u32,
    end: u32,
}

/// A timed run's draw: the motion, whether the chips are on CLKIN and
/// their PLL errors, chip faults (as [`draw`], the ICM-42688-P's only) and
/// one or two timing events.
fn draw_timed(
    seed: u64,
    samples: u32,
) -> (
    RateProfile,
    host_tests::timed_board::Timing,
    Vec<Injection>,
    Vec<TimingEvent>,
) {
    use gyro_sim::timing::ClockParams;
    let (profile, inj) = draw(seed, samples);
    let inj: Vec<Injection> = inj.into_iter().filter(|i| i.chip < 4).collect();
    let mut rng = Rng::new(seed ^ 0x5EED_71AE);
    let clkin = rng.uniform() < 0.5;
    let pll = core::array::from_fn(|_| ClockParams {
        offset: 0.02 * (rng.uniform() as f64 - 0.5),
        drift_per_s: 2e-5 * (rng.uniform() as f64 - 0.5),
        wander: 1e-3 * rng.uniform() as f64,
        wander_period_s: 2.0 + 10.0 * rng.uniform() as f64,
    });
    // Every reading of what a CLKIN stamp count is (the sources leave it
    // open), drawn after the rest so the earlier draws stay as they were.
    let mut ev = Vec::new();
    for _ in 0..1 + (rng.next_u32() % 2) {
        let start = 300 + rng.next_u32() % (samples / 2);
        let chip = (rng.next_u32() % 4) as usize;
        let what = match rng.next_u32() % 3 {
            0 => Timing::ClockToRc,
            1 if clkin => Timing::ClkInLost,
            _ => Timing::Stall(80 + rng.next_u32() % 300),
        };
        let end = match what {
            Timing::ClockToRc => start + 200 + rng.next_u32() % 800,
            _ => start + 1,
        };
        ev.push(TimingEvent {
            chip,
            what,
            start,
            end,
        });
    }
    let rtc_tick = gyro_sim::RtcTick::ALL[(rng.next_u32() % 3) as usize];
    // What a burst past the FIFO count gets (the datasheet is silent), and
    // a few bursts cut inside their packets, anywhere in a burst of four
    // (the first packet's header is its fourth byte).
    let past_count = gyro_sim::PastCount::ALL[(rng.next_u32() % 3) as usize];
    for _ in 0..rng.next_u32() % 4 {
        let start = 200 + rng.next_u32() % (samples - 300);
        let chip = (rng.next_u32() % 4) as usize;
        let at = 4 + rng.next_u32() % (4 * 16);
        ev.push(TimingEvent {
            chip,
            what: Timing::Cut(at),
            start,
            end: start + 1,
        });
    }
    (
        profile,
        host_tests::timed_board::Timing {
            clkin,
            pll,
            vibration: gyro_sim::timing::Vibration::NONE,
            rtc_tick,
            past_count,
            power_up_s: 0.0,
            path_reading: gyro_sim::PathReading::DOCUMENTED,
            scale_error: [0.0; 4],
            rc_fallback: None,
            path_trim_us: 0,
        },
        inj,
        ev,
    )
}

/// The ms the timed loop stalls before step `n`.
fn stall_at(ev: &[TimingEvent], n: u32) -> u32 {
    ev.iter()
        .filter(|e| e.start == n)
        .map(|e| match e.what {
            Timing::Stall(k) => k,
            _ => 0,
        })
        .sum()
}

/// The timed campaign's run: the invariants of [`run`] on the timed board
/// (truth at the stated instant), and 6: no chip is flagged for a timing
/// event alone, and a fused value is missing only while the chips re-find
/// their clocks after one (a lost CLKIN: 60 samples; a stall or a clock
/// switch: 40).
fn run_timed(seed: u64, samples: u32) -> Vec<String> {
    let (profile, timing, inj, ev) = draw_timed(seed, samples);
    let mut bad: Vec<String> = Vec::new();
    let mut at_power_up = [Fault::None; 4];
    for i in &inj {
        if let (Kind::Fault(f), 0) = (i.kind, i.start) {
            at_power_up[i.chip] = f;
        }
    }
    let mut out_at = vec![None::<u32>; inj.len()];
    let mut back_at = vec![None::<u32>; inj.len()];
    let mut stalled = 0u32;
    let mut last_counters = None;
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        host_tests::timed_board::run(
            profile,
            seed,
            samples,
            timing,
            at_power_up,
            |n| stall_at(&ev, n),
            |smp| {
                let n = smp.n;
                gyro_sim::with_bus(smp.bus, |b| {
                    inject(b, &inj, n);
                    for e in &ev {
                        match e.what {
                            Timing::ClockToRc if n + 1 == e.start || n + 1 == e.end => {
                                if let Some(c) = b.chips[e.chip].icm() {
                                    c.fail_pll(n + 1 == e.start);
                                }
                            }
                            Timing::ClkInLost if n + 1 == e.start => b.clkin_hz = None,
                            Timing::Cut(at) if n + 1 == e.start => b.cut[e.chip] = Some(at),
                            _ => {}
                        }
                    }
                });
                stalled += stall_at(&ev, n);
                let out = smp.out;
                if out.seq != n + stalled {
                    bad.push(format!(
                        "2: sequence {} at step {n} (+{stalled} stalled)",
                        out.seq
                    ));
                }
                let truth = profile.at_f64(smp.stated_s);
                let faulty_now = |c: usize| {
                    inj.iter().any(|i| {
                        i.chip == c
                            && (i.active(n)
                                || i.kind == Kind::PowerCycle && n >= i.start && n < i.start + 250
                                || i.kind == Kind::CorruptConfig
                                    && n >= i.start
                                    && n < i.start + READ_BACK + 100)
                    })
                };
                let regrace = ev.iter().any(|e| {
                    let grace = match e.what {
                        Timing::ClkInLost => 60,
                        // A cut burst loses nothing: no grace.
                        Timing::Cut(_) => 0,
                        _ => 40,
                    };
                    n >= e.start && n < e.start + grace
                        || e.what == Timing::ClockToRc && n >= e.end && n < e.end + grace
                });
                for (k, i) in inj.iter().enumerate() {
                    let used = out.offered.iter().any(|m| m & (1 << i.chip) != 0);
                    if i.active(n) {
                        if !used && out_at[k].is_none() {
                            out_at[k] = Some(n);
                        }
                        let flagged = smp.pipe.health()[i.chip].flags != 0;
                        if i.deterministic() && used && n >= i.start + 20 {
                            let frozen_ok = i.kind == Kind::Fault(Fault::Stuck) && !flagged;
                            if !frozen_ok {
                                bad.push(format!(
                                    "3: chip {} used at step {n} during {:?}",
                                    i.chip, i.kind
                                ));
                            }
                        }
                    } else if n >= i.end && used && back_at[k].is_none() {
                        back_at[k] = Some(n);
                    }
                }
                // 6: a chip with no fault of its own is never flagged.
                for c in 0..4 {
                    let ever_faulty = inj.iter().any(|i| i.chip == c);
                    if !ever_faulty && smp.pipe.health()[c].flags != 0 {
                        bad.push(format!(
                            "6: chip {c} flagged {:#04x} at step {n} with no fault of its own",
                            smp.pipe.health()[c].flags
                        ));
                    }
                }
                if std::env::var_os("CAMPAIGN_TRACE").is_some() {
                    println!(
                        "{n} offered {:?} fused x {:?} truth {:.2} rates x {:?} flags {:?}",
                        out.offered,
                        out.fused[0].map(|f| (f.rate_dps, f.fallback, f.used(), f.weights)),
                        truth[0],
                        out.rate_dps.iter().map(|r| r[0]).collect::<Vec<_>>(),
                        smp.pipe
                            .health()
                            .iter()
                            .map(|h| h.flags)
                            .collect::<Vec<_>>()
                    );
                }
                let faulty = (0..4).filter(|c| faulty_now(*c)).count();
                if 4 - faulty > faulty {
                    for (a, f) in out.fused.iter().enumerate() {
                        match f {
                            Some(f) if (f.rate_dps as f64 - truth[a]).abs() <= 1.0 => {}
                            Some(f) => bad.push(format!(
                                "4: axis {a} fused {:.2} vs truth {:.2} at step {n}",
                                f.rate_dps, truth[a]
                            )),
                            None if regrace || n < 100 => {}
                            None => bad.push(format!("6: axis {a} has no fused value at step {n}")),
                        }
                    }
                }
                last_counters = Some(*smp.pipe.counters());
            },
        )
    }));
    let Ok(ran) = result else {
        bad.push("1: panic".into());
        return bad;
    };
    // 2: every packet a chip's FIFO gave out whole was handed on once: none
    // lost in a cut burst, none counted twice when sent again (the
    // emulator's count against the timing layer's). An overflow is a gap
    // by design (the burst that finds FIFO_FULL flushes what it read).
    for c in 0..4 {
        let clean = !inj.iter().any(|i| i.chip == c) && ran.timing[c].overflows == 0;
        if clean && u64::from(ran.timing[c].samples) != ran.read_out[c] {
            bad.push(format!(
                "2: chip {c} handed on {} samples of {} its FIFO gave out ({:?})",
                ran.timing[c].samples, ran.read_out[c], ran.timing[c]
            ));
        }
    }
    check_after_run(
        last_counters.as_ref().map(|c| &c[..]),
        samples,
        &inj,
        &out_at,
        &mut bad,
    );
    for (k, i) in inj.iter().enumerate() {
        if i.end < samples.saturating_sub(600) {
            // As the polled board, plus the restarts' four slotted steps,
            // the tracker's 20 ms acquisition, and a back-off cycle (up to
            // the longest, the chip may have been lost for a while).
            let restart = match i.kind {
                Kind::PowerCycle | Kind::Fault(Fault::PoweredOff) => 46 + 16 + 30,
                Kind::CorruptConfig => 3 * READ_BACK + 46 + 30,
                _ => 30,
            };
            let limit = i.end + 100 + restart + 1000;
            if limit >= samples {
                continue;
            }
            match back_at[k] {
                Some(b) if b <= limit => {}
                b => bad.push(format!(
                    "5: chip {} back at {b:?} after {:?} ended at {} (limit {limit})",
                    i.chip, i.kind, i.end
                )),
            }
        }
    }
    bad
}

/// Randomised fault injection on the emulated board.
#[derive(clap::Parser)]
#[command(name = "fault-campaign")]
struct Args {
    /// Runs (each a random board, faults and motion).
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(1..))]
    runs: u64,
    /// Seed of the campaign.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Samples per run (at least 1000: the faults are placed in them).
    #[arg(long, default_value_t = SAMPLES, value_parser = clap::value_parser!(u32).range(1000..))]
    samples: u32,
    /// The timed board: four ICM-42688-P on their own clocks (CLKIN or
    /// free-running), their FIFOs, the alignment, and timing events (a
    /// clock falling back to RC, CLKIN lost, a stalled bus) beside the
    /// faults.
    #[arg(long)]
    timed: bool,
}

fn main() -> ExitCode {
    gyro_tool::pipe::quiet_on_closed_pipe();
    let args = <Args as clap::Parser>::parse();
    // Panics are caught per run and counted; keep their default message off
    // the terminal.
    std::panic::set_hook(Box::new(|_| {}));
    let violations: [AtomicU32; 6] = Default::default();
    let failed_runs = AtomicU32::new(0);
    let next = AtomicU32::new(0);
    let workers = std::thread::available_parallelism().map_or(2, |n| n.get());
    let reports = std::sync::Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..workers {
            s.spawn(|| loop {
                let r = next.fetch_add(1, Ordering::Relaxed) as u64;
                if r >= args.runs {
                    break;
                }
                let seed = args.seed + r;
                let bad = if args.timed {
                    run_timed(seed, args.samples)
                } else {
                    run(seed, args.samples)
                };
                if !bad.is_empty() {
                    failed_runs.fetch_add(1, Ordering::Relaxed);
                    for b in &bad {
                        let k = b.as_bytes()[0] - b'1';
                        violations[k as usize % 6].fetch_add(1, Ordering::Relaxed);
                    }
                    let what = if args.timed {
                        let (_, t, inj, ev) = draw_timed(seed, args.samples);
                        format!("clkin {}, faults {inj:?}, timing {ev:?}", t.clkin)
                    } else {
                        format!("faults {:?}", draw(seed, args.samples).1)
                    };
                    reports.lock().unwrap().push(format!(
                        "seed {seed}: {} violation(s), first: {}; {what}",
                        bad.len(),
                        bad[0]
                    ));
                }
            });
        }
    });
    let mut reports = reports.into_inner().unwrap();
    reports.sort();
    for r in reports.iter().take(20) {
        println!("{r}");
    }
    let names = [
        "no panic",
        "every sample accounted for",
        "deterministic fault out within 20 samples, kept out",
        "fused within 1 °/s where a healthy majority exists",
        "back in fusion after the fault ends",
        "timing alone flags no chip and loses no fused value (timed board)",
    ];
    println!(
        "fault campaign{}: {} runs × {} samples from seed {}; runs with a violation: {}",
        if args.timed { " (timed board)" } else { "" },
        args.runs,
        args.samples,
        args.seed,
        failed_runs.load(Ordering::Relaxed)
    );
    for (i, n) in names
        .iter()
        .enumerate()
        .take(if args.timed { 6 } else { 5 })
    {
        println!(
            "  invariant {}: {n}: {} violations",
            i + 1,
            violations[i].load(Ordering::Relaxed)
        );
    }
    if failed_runs.load(Ordering::Relaxed) == 0 {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}
