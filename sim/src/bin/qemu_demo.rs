//! QEMU demo firmware: the board's real drivers read an emulated array
//! (4 × ICM-42688-P, 1 × ADXRS453 on z) over one shared SPI bus, the
//! pipeline fuses every sample, and faults are injected on a schedule:
//! gyro 2 sticks at 1.5 s, the ADXRS453 has bit errors from 2.0 s to 2.2 s.
//! E-DAVAR (segmented, λ2 = 512) tracks the noise of each fused axis
//! and logs its window length, entropy deficit and σ(τ) every 500 samples
//! (z slews in a 20 °/s sine from power-up, so its long-τ σ and deficit
//! show the motion). The chips are mounted rotated and misaligned, and
//! the board applies the calibration record made for it by the host
//! procedure (`calibrate`). The board boots while it sways: the ICM-42688-P
//! self-test runs across the array, and the noise-health self-test takes
//! 2048 samples of every gyro's z axis and checks trend, long memory and
//! normality of each against the median of the others.
//! The ICM-42688-Ps keep their own time (`gyro_sim::timing`): free-running PLLs
//! 0.6 % fast, 0.9 % slow, 0.3 % fast and 0.4 % slow, drifting and
//! wandering, chip 3's failing over to its RC oscillator (5 % fast) from
//! 3.0 s to 4.0 s. After the self-tests (data registers) they sample into
//! their FIFOs at the board's 4 kHz, each read through `TimedIcm` (its
//! INT1 captured, its clock tracked, its samples brought to one instant
//! `BOARD_DELAY_US` behind the read), as `board-f405` reads them; the
//! ADXRS453, whose reading is older than that instant, is read and
//! watched, not fused. The chips' signal paths are the delay model
//! (`gyro_sim::PathModel::Delay`: the 32 kHz filters are too slow for a minute
//! of QEMU), their clocks, FIFOs, stamps and INT1 the full model's.
//! Every sample goes out over UART0 as an output-link frame (`link`),
//! with a status frame every second and an acknowledgement for every
//! command received; the run lasts 60 s of emulated time.
//!
//! The application is RTIC 2, the board's schedule (`gyro_array::app`)
//! on the board's priorities: the sample task on SysTick (priority 2;
//! it queues the sample's frame, then a status frame when one is due),
//! UART0's receive interrupt above it (3) and its transmit interrupt
//! beside it (2, a turn of 16 bytes), the E-DAVARs, commands and logs in a
//! background task (1). With `--features demo-stress` the background is
//! ten times slower and a status frame follows every sample. The run
//! measures the schedule as it runs, on SysTick's count (QEMU's
//! `-icount shift=0`: one count is 40 executed instructions, checked at
//! start-up on a loop of known length): each tick to the sample task's
//! start, to its frame queued and to each frame's first byte on the
//! UART; the CPU's load (the instructions idle did not spin).
//!
//! The run fails (exit code 1) unless the stuck gyro is excluded within
//! 20 samples, every bit error is caught, every sample is accounted for,
//! no chip is flagged for its clock alone, no frame is dropped, no tick
//! comes before the sample task is done with the last, the background
//! loses no job, and E-DAVAR's σ(1 ms) on x matches the fused noise
//! (0.02–0.1 °/s). It ends by logging the number of sample frames and a
//! CRC-32 of their fused rates, which `cargo xtask test` compares with the
//! host's recording of the UART.
#![no_std]
#![no_main]

use core::cell::RefCell;
use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

use defmt_semihosting as _;
use heapless::spsc::{Consumer, Producer, Queue};

use gyro_array::app::{self as schedule, timed_clock};
use gyro_array::board::stack;
use gyro_array::drivers::Gyro;
use gyro_array::link::port::{ChipTime, NoiseSnapshot, Port};
use gyro_array::link::ring::{TxBuffer, TxConsumer, TxProducer};
use gyro_array::pipeline::timed::TimingCounters;
use gyro_array::pipeline::tracker;
use gyro_array::pipeline::Pipeline;
use gyro_sim::qemu::cmsdk_uart::{CmsdkUart, UART0};
use gyro_sim::qemu::exit;
use gyro_sim::{demo, with_bus, CsLine, EmuBus};

use demo::{Tracker, FS_HZ, NOISE_TAU, SAMPLES};
/// mps2-an386 core clock.
const CORE_HZ: u32 = 25_000_000;
/// SysTick's reload: one sample period.
const RELOAD: u32 = CORE_HZ / FS_HZ - 1;
/// The sample task's jobs for the background.
const JOBS: usize = 8;
/// The link's bytes the UART's task writes in one turn at most.
const TX_TURN: usize = 16;
/// The stack's deepest use, for the status frames (the background scans).
static STACK_PEAK: AtomicU32 = AtomicU32::new(0);
/// The stress run (`--features demo-stress`): the background made ten
/// times slower (each job followed by nine times its own length of busy
/// work) and a status frame with every sample (built by the sample task
/// behind its frame).
const STRESS: bool = cfg!(feature = "demo-stress");

/// Busy work of about `n` instructions (`subs` + `bne` a turn).
fn burn(n: u32) {
    let turns = (n / 2).max(1);
    #[allow(unsafe_code)]
    // SAFETY: a register-only countdown loop.
    unsafe {
        core::arch::asm!("1:", "subs {n}, {n}, #1", "bne 1b", n = inout(reg) turns => _, options(nomem, nostack));
    }
}

/// SysTick counts from `from` (a [`since_tick`] reading) to now, across
/// at most one tick.
fn counts_since(from: u32) -> u32 {
    let now = since_tick();
    if now >= from {
        now - from
    } else {
        now + RELOAD + 1 - from
    }
}

/// The background's time in its jobs, SysTick counts (preemption
/// included), and the jobs.
static BG_COUNTS: AtomicU32 = AtomicU32::new(0);
static BG_JOBS: AtomicU32 = AtomicU32::new(0);
/// Idle's spins, for the CPU's load.
static IDLE_SPINS: AtomicU32 = AtomicU32::new(0);

type Bus = demo::Bus<'static>;

/// Every chip and the emulated world they live in, as the sample task
/// owns them after start-up.
pub struct Chips(demo::Chips<'static, 'static>);

// SAFETY: the drivers, the captures and `bus` all reach the one emulated
// bus (`init`'s 'static local), which nothing else names; they move
// together from `init` to the sample task.
#[allow(unsafe_code)]
unsafe impl Send for Chips {}

/// The link's transmit queue: the port writes each frame into it, the
/// UART's task sends the bytes from there.
const TX_BYTES: usize = 4096;
static TX_QUEUE: TxBuffer<TX_BYTES> = TxBuffer::new();
/// The UART's task found the transmit queue empty.
static TX_EMPTY: AtomicBool = AtomicBool::new(true);

/// The link: the port (its frames written into `TX_QUEUE`).
pub struct Link {
    port: &'static mut Port<TxProducer<TX_BYTES>>,
}

impl schedule::Link for Link {
    type Queue = TxProducer<TX_BYTES>;
    fn port(&mut self) -> &mut Port<TxProducer<TX_BYTES>> {
        self.port
    }

    fn flush(&mut self) {
        rtic::pend(gyro_sim::qemu::an386::Interrupt::UART0TX);
    }
}

/// Received bytes, read as a UART by the background.
struct RxQueue(Consumer<'static, u8>);

impl embedded_hal_nb::serial::ErrorType for RxQueue {
    type Error = core::convert::Infallible;
}

impl embedded_hal_nb::serial::Read<u8> for RxQueue {
    fn read(&mut self) -> embedded_hal_nb::nb::Result<u8, Self::Error> {
        self.0
            .dequeue()
            .ok_or(embedded_hal_nb::nb::Error::WouldBlock)
    }
}

/// SysTick counts since the current period's tick: the counter reads 0
/// at the tick, then RELOAD, RELOAD − 1, … (ARMv7-M ARM B3.3.1).
fn since_tick() -> u32 {
    (RELOAD + 1 - cortex_m::peripheral::SYST::get_current()) % (RELOAD + 1)
}

/// The emulated bus's clock for its meter: SysTick counts since the tick
/// (the bus is read only inside the sample task, which ends within its
/// period: a tick during it is counted late and fails the run).
fn bus_clock() -> u64 {
    u64::from(since_tick())
}

/// Ticks so far, and the tick of the last sample task that queued frames.
static TICK_N: AtomicU32 = AtomicU32::new(0);
static QUEUED_TICK: AtomicU32 = AtomicU32::new(0);
/// The emulated world's SysTick counts in that sample task.
static QUEUED_EMU: AtomicU32 = AtomicU32::new(0);
/// Worst SysTick counts from a frame's tick (that of the last sample task
/// that queued frames) to its first byte on the UART: as it ran, and the
/// firmware's own (the emulated world's share taken out).
static FIRST_BYTE_WORST: AtomicU32 = AtomicU32::new(0);
static FIRST_BYTE_FW_WORST: AtomicU32 = AtomicU32::new(0);

/// What the sample task hands the background.
pub struct Work {
    job: schedule::Job,
    /// The sample's number in the run.
    n: u32,
    /// Each axis's fused rate and weights, and the true rate (for the log).
    fused: [Option<(f32, [f32; 5])>; 3],
    truth: [f32; 3],
    /// After the last sample: what the sample task found.
    last: Option<Verdict>,
}

/// The sample task's findings at the end of the run.
#[derive(Clone, Copy)]
pub struct Verdict {
    sample_frames: u32,
    crc: u32,
    stuck_at: Option<u32>,
    excluded_at: Option<u32>,
    fused_everywhere: bool,
    timing: [(TimingCounters, f32); 4],
    /// Ticks that came while the sample task still ran; jobs lost.
    late: u32,
    lost: u32,
    /// Worst and mean SysTick counts from the tick to the task's start
    /// and to its frame queued; the task's worst length.
    start_worst: u32,
    queued_worst: u32,
    queued_sum: u64,
    task_worst: u32,
    /// The same less the emulated world's share (the chips' step and the
    /// bus's operations): the firmware's own.
    fw_queued_worst: u32,
    fw_queued_sum: u64,
    fw_task_worst: u32,
    emu_sum: u64,
}

/// The sample task's measurements and the demo's checks.
pub struct Run {
    n: u32,
    stuck_at: Option<u32>,
    excluded_at: Option<u32>,
    digest: crc::Digest<'static, u32>,
    sample_frames: u32,
    fused_everywhere: bool,
    late: u32,
    lost: u32,
    start_worst: u32,
    queued_worst: u32,
    queued_sum: u64,
    task_worst: u32,
    fw_queued_worst: u32,
    fw_queued_sum: u64,
    fw_task_worst: u32,
    emu_sum: u64,
}

static CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// The emulated array on its bus, built in a frame of its own (the chips
/// are some 18 KB, moved twice on the way into the bus). Called once.
#[inline(never)]
fn make_bus(slot: &'static mut Option<Bus>, cs: &'static [CsLine; 5]) -> &'static Bus {
    slot.insert(RefCell::new(EmuBus::new(demo::chips(), cs)))
}

#[rtic::app(device = gyro_sim::qemu::an386, peripherals = false, dispatchers = [SPI2, SPI34])]
mod app {
    use super::*;
    use rtic::Mutex;
    use rtic_sync::channel::{Receiver, Sender};
    use rtic_sync::make_channel;

    #[shared]
    struct Shared {
        pipe: Pipeline<5>,
        link: Link,
        noise: NoiseSnapshot,
        uart: CmsdkUart,
    }

    #[local]
    struct Local {
        chips: Chips,
        clock: schedule::SampleClock,
        /// Each chip's clock after the last sample, for the status frames.
        clocks: [ChipTime; 5],
        jobs: Sender<'static, Work, JOBS>,
        run: Run,
        tx: TxConsumer<TX_BYTES>,
        rx_in: Producer<'static, u8>,
        rx: RxQueue,
        tracker: &'static mut Tracker,
        /// Instructions a SysTick count, measured.
        ipc: f32,
        /// Instructions an idle spin, measured.
        per_spin: f32,
        self_test_ok: bool,
        calibrated: bool,
        /// The last byte written was a frame's delimiter.
        at_delimiter: bool,
    }

    #[init(local = [
        cs: [CsLine; 5] = [CsLine::new(), CsLine::new(), CsLine::new(), CsLine::new(), CsLine::new()],
        bus_slot: Option<Bus> = None,
        port_slot: Option<Port<TxProducer<TX_BYTES>>> = None,
        tracker_slot: MaybeUninit<Tracker> = MaybeUninit::uninit(),
        rx_store: Queue<u8, 64> = Queue::new(),
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        stack::guard_stack();
        let mut syst = cx.core.SYST;
        syst.set_clock_source(cortex_m::peripheral::syst::SystClkSource::Core);
        syst.set_reload(RELOAD);
        syst.clear_current();
        syst.enable_counter();
        // Instructions a SysTick count: 20 000 of a loop of known length
        // (`subs` + `bne`), well inside one period.
        let ipc = {
            while cortex_m::peripheral::SYST::get_current() < RELOAD / 2 {}
            let c0 = cortex_m::peripheral::SYST::get_current();
            #[allow(unsafe_code)]
            // SAFETY: a register-only countdown loop.
            unsafe {
                core::arch::asm!("1:", "subs {n}, {n}, #1", "bne 1b", n = inout(reg) 10_000u32 => _, options(nomem, nostack));
            }
            let c1 = cortex_m::peripheral::SYST::get_current();
            20_000.0 / c0.saturating_sub(c1).max(1) as f32
        };
        defmt::info!("SysTick: {=f32} instructions a count", ipc);
        // Instructions an idle spin takes: 10 000 of them timed.
        let per_spin = {
            let spins = AtomicU32::new(0);
            let t0 = since_tick();
            for _ in 0..10_000 {
                spins.fetch_add(1, Ordering::Relaxed);
            }
            counts_since(t0) as f32 * ipc / 10_000.0
        };

        let cs: &'static [CsLine; 5] = cx.local.cs;
        let bus = make_bus(cx.local.bus_slot, cs);

        let mut pipe = demo::pipeline().unwrap_or_else(|_| exit(false));
        let demo::Started {
            chips,
            calibration,
            self_test_ok,
            fifo_failed,
        } = demo::start(bus, cs, &mut pipe);
        let calibrated = match calibration {
            Ok(()) => {
                defmt::info!("calibration record in use");
                true
            }
            Err(e) => {
                defmt::error!("calibration record: {}; running uncalibrated", e);
                false
            }
        };
        for i in 0..4 {
            if fifo_failed & (1 << i) != 0 {
                defmt::error!("gyro {}: FIFO set-up failed", i);
            }
        }
        let chips = Chips(chips);
        let Ok(tracker) = Tracker::init_in(cx.local.tracker_slot, demo::tracker_config()) else {
            exit(false)
        };
        tracker.set_view(NOISE_TAU);

        // SAFETY: UART0 is used by nothing else.
        #[allow(unsafe_code)]
        let mut uart = unsafe { CmsdkUart::new(UART0, 16) };
        uart.listen();
        let settings = demo::link_settings(STRESS);
        let port = cx.local.port_slot.insert(Port::with_queue(
            TX_QUEUE.stream_producer(),
            settings,
            gyro_array::app::BOARD_FRAME_PATH,
        ));
        if STRESS {
            defmt::info!("stress: the background ten times slower, a status frame every sample");
        }
        let tx = TX_QUEUE.stream_consumer();
        let (rx_in, rx) = cx.local.rx_store.split();
        let (jobs, inbox) = make_channel!(Work, JOBS);
        if background::spawn(inbox).is_err() {
            exit(false)
        }
        let now_us = with_bus(bus, |b| {
            b.clock = Some(bus_clock);
            b.timer_us()
        })
        .unwrap_or(0);
        // The sample task from here: SysTick's exception on (taken once
        // init returns).
        syst.clear_current();
        syst.enable_interrupt();
        (
            Shared {
                pipe,
                link: Link { port },
                noise: NoiseSnapshot::default(),
                uart,
            },
            Local {
                chips,
                clock: schedule::SampleClock::new(now_us, 1_000_000 / FS_HZ),
                clocks: [ChipTime::default(); 5],
                jobs,
                run: Run {
                    n: 0,
                    stuck_at: None,
                    excluded_at: None,
                    digest: CRC32.digest(),
                    sample_frames: 0,
                    fused_everywhere: true,
                    late: 0,
                    lost: 0,
                    start_worst: 0,
                    queued_worst: 0,
                    queued_sum: 0,
                    task_worst: 0,
                    fw_queued_worst: 0,
                    fw_queued_sum: 0,
                    fw_task_worst: 0,
                    emu_sum: 0,
                },
                tx,
                rx_in,
                rx: RxQueue(rx),
                tracker,
                ipc,
                per_spin,
                self_test_ok,
                calibrated,
                at_delimiter: true,
            },
        )
    }

    /// Idle spins, counted: the CPU's load is what it did not spin.
    #[idle]
    fn idle(_: idle::Context) -> ! {
        loop {
            IDLE_SPINS.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// One sample (`gyro_array::app::sample`), with the demo's faults and
    /// checks, and the schedule's timing measured.
    #[task(binds = SysTick, priority = 2, shared = [pipe, link, noise],
           local = [chips, clock, clocks, jobs, run])]
    fn sample(mut cx: sample::Context) {
        let start = since_tick();
        let l = cx.local;
        let r = &mut *l.run;
        let n = r.n;
        if n >= SAMPLES {
            return;
        }
        let tick = TICK_N.fetch_add(1, Ordering::Relaxed).wrapping_add(1);
        r.n += 1;
        let bus = l.chips.0.bus;
        let step0 = since_tick();
        let event = with_bus(bus, |b| {
            let e = demo::inject(n, b);
            b.advance(1.0 / FS_HZ as f32);
            e
        })
        .flatten();
        match event {
            Some(demo::Event::Stuck(i)) => {
                r.stuck_at = Some(n);
                defmt::warn!("t={}ms: injecting: gyro {} stuck", n, i);
            }
            Some(demo::Event::BitErrors(i)) => {
                defmt::warn!("t={}ms: injecting: gyro {} bit errors", n, i)
            }
            Some(demo::Event::ClockToRc(i)) => defmt::warn!(
                "t={}ms: gyro {}'s clock falls back to its RC oscillator",
                n,
                i
            ),
            Some(demo::Event::ClockToPll(i)) => {
                defmt::warn!("t={}ms: gyro {}'s clock back on its PLL", n, i)
            }
            Some(demo::Event::BitErrorsEnd(_)) | None => {}
        }
        let step = since_tick().saturating_sub(step0);
        let ops0 = with_bus(bus, |b| b.meter.ticks).unwrap_or(0);
        // One clock: the captures' µs (the bus's here, TIM5's on the
        // board), for the instant and the frame.
        let now_us = with_bus(bus, |b| b.timer_us()).unwrap_or(0);
        let (t_us, missed) = l.clock.tick(now_us);
        let clocks = *l.clocks;
        let demo::Chips { timed, adx, .. } = &mut l.chips.0;
        let [c0, c1, c2, c3] = timed;
        let mut gyros: [&mut dyn Gyro; 5] = [c0, c1, c2, c3, adx];
        let mut queued = 0;
        let s = schedule::sample(
            &mut cx.shared.pipe,
            &mut cx.shared.link,
            &mut cx.shared.noise,
            &mut gyros,
            (t_us, missed),
            &demo::STATUS_VIEW,
            || queued = since_tick(),
            || schedule::StatusFacts {
                clocks,
                stack_peak: STACK_PEAK.load(Ordering::Relaxed),
            },
        );
        let ops = with_bus(bus, |b| b.meter.ticks)
            .unwrap_or(0)
            .wrapping_sub(ops0);
        let emu = step.saturating_add(ops.min(u64::from(u32::MAX)) as u32);
        r.emu_sum += u64::from(emu);
        r.start_worst = r.start_worst.max(start);
        r.queued_worst = r.queued_worst.max(queued);
        r.queued_sum += u64::from(queued);
        let fw_queued = queued.saturating_sub(emu);
        r.fw_queued_worst = r.fw_queued_worst.max(fw_queued);
        r.fw_queued_sum += u64::from(fw_queued);
        if let (Some(_), None) = (r.stuck_at, r.excluded_at) {
            if s.out.fused[0].is_some_and(|f| f.weights[2] == 0.0) {
                r.excluded_at = Some(n);
            }
        }
        if s.sent {
            r.sample_frames += 1;
            // What the frame carried (the rates predicted to its last byte:
            // the link's delay compensation).
            let rates = cx.shared.link.lock(|l| l.port.last_sample_rates());
            for v in rates.unwrap_or([f32::NAN; 3]) {
                r.digest.update(&v.to_le_bytes());
            }
        }
        // The chips' clocks as this sample left them, for the next status
        // frame (read after the frame is out, not before the read).
        for (slot, t) in l.clocks.iter_mut().zip(l.chips.0.timed.iter()) {
            *slot = timed_clock(t);
        }
        let probe = schedule::Job::from(&s.out);
        let log = if n < 3000 {
            n % 500 == 499
        } else {
            n % 10_000 == 9_999
        };
        let mut fused = [None; 3];
        let mut truth = [0.0; 3];
        if log {
            // Every axis fused at every logged sample.
            if s.out.fused.iter().any(Option::is_none) {
                defmt::error!("seq {}: an axis has no fused value", s.out.seq);
                r.fused_everywhere = false;
            }
            for (f, o) in fused.iter_mut().zip(s.out.fused.iter()) {
                *f = o.map(|o| (o.rate_dps, o.weights));
            }
            truth = with_bus(bus, |b| b.chips[0].true_rate_dps()).unwrap_or([0.0; 3]);
        }
        let last = n + 1 == SAMPLES;
        // The task's length so far, and whether the next tick already came.
        let length = since_tick().saturating_sub(start);
        r.task_worst = r.task_worst.max(length);
        r.fw_task_worst = r.fw_task_worst.max(length.saturating_sub(emu));
        if cortex_m::peripheral::SCB::is_pendst_pending() {
            r.late += 1;
        }
        // This task's frames go out once it returns (the UART's task runs
        // at its priority): their first bytes count from this tick.
        QUEUED_TICK.store(tick, Ordering::Relaxed);
        QUEUED_EMU.store(emu, Ordering::Relaxed);
        let verdict = last.then(|| {
            let mut timing = [(TimingCounters::default(), 0.0); 4];
            for (slot, t) in timing.iter_mut().zip(l.chips.0.timed.iter()) {
                *slot = (t.counters, t.clock().error_ppm());
            }
            Verdict {
                sample_frames: r.sample_frames,
                crc: r.digest.clone().finalize(),
                stuck_at: r.stuck_at,
                excluded_at: r.excluded_at,
                fused_everywhere: r.fused_everywhere,
                timing,
                late: r.late,
                lost: r.lost,
                start_worst: r.start_worst,
                queued_worst: r.queued_worst,
                queued_sum: r.queued_sum,
                task_worst: r.task_worst,
                fw_queued_worst: r.fw_queued_worst,
                fw_queued_sum: r.fw_queued_sum,
                fw_task_worst: r.fw_task_worst,
                emu_sum: r.emu_sum,
            }
        });
        let w = Work {
            job: probe,
            n,
            fused,
            truth,
            last: None,
        };
        if l.jobs.try_send(w).is_err() {
            r.lost += 1;
        }
        if let Some(v) = verdict {
            let w = Work {
                job: probe,
                n: SAMPLES,
                fused: [None; 3],
                truth,
                last: Some(v),
            };
            if l.jobs.try_send(w).is_err() {
                defmt::error!("the run's end did not reach the background");
                exit(false);
            }
        }
    }

    /// UART0's transmit interrupt (a byte has gone out), or a kick from
    /// whoever queued bytes: the next bytes from the queue, `TX_TURN` at
    /// most. At the sample task's priority, not above: QEMU's UART takes
    /// bytes as fast as they come, and a status frame's 389 bytes written
    /// above it delayed the sample task's start by 16 960 instructions
    /// (measured in the stress run); here it waits one turn at most (a
    /// tick pending beside this interrupt goes first: SysTick's exception
    /// number is the lower).
    #[task(binds = UART0TX, priority = 2, shared = [uart], local = [tx, at_delimiter])]
    fn uart_tx(mut cx: uart_tx::Context) {
        use embedded_hal_nb::serial::Write;
        let l = cx.local;
        cx.shared.uart.lock(|u| {
            u.clear_tx_interrupt();
            // The UART holds one byte; QEMU sends it at once, and the
            // interrupt that follows brings the next.
            let Ok(bytes) = l.tx.read() else {
                TX_EMPTY.store(true, Ordering::Relaxed);
                return;
            };
            TX_EMPTY.store(false, Ordering::Relaxed);
            let mut k = 0;
            for &b in bytes.iter().take(TX_TURN) {
                if u.write(b).is_err() {
                    break;
                }
                k += 1;
                if *l.at_delimiter {
                    let periods = TICK_N
                        .load(Ordering::Relaxed)
                        .wrapping_sub(QUEUED_TICK.load(Ordering::Relaxed));
                    let at = periods
                        .saturating_mul(RELOAD + 1)
                        .saturating_add(since_tick());
                    FIRST_BYTE_WORST.fetch_max(at, Ordering::Relaxed);
                    let fw = at.saturating_sub(QUEUED_EMU.load(Ordering::Relaxed));
                    FIRST_BYTE_FW_WORST.fetch_max(fw, Ordering::Relaxed);
                }
                *l.at_delimiter = b == 0;
            }
            bytes.release(k);
        });
    }

    /// UART0's receive interrupt: the byte into the background's queue.
    #[task(binds = UART0RX, priority = 3, shared = [uart], local = [rx_in])]
    fn uart_rx(mut cx: uart_rx::Context) {
        use embedded_hal_nb::serial::Read;
        let q = cx.local.rx_in;
        cx.shared.uart.lock(|u| {
            u.clear_rx_interrupt();
            while let Ok(b) = u.read() {
                // A full queue loses the byte: the command fails its CRC
                // and is not acknowledged.
                let _ = q.enqueue(b);
            }
        });
    }

    /// The background (`gyro_array::app::Background`): the E-DAVARs,
    /// status frames, commands, the logs, and the run's end.
    #[task(priority = 1, shared = [pipe, link, noise, uart],
           local = [rx, tracker, ipc, per_spin, self_test_ok, calibrated])]
    async fn background(mut cx: background::Context, mut inbox: Receiver<'static, Work, JOBS>) {
        let l = cx.local;
        let mut bg = schedule::Background {
            tracker: l.tracker,
            taus: NOISE_TAU,
        };
        let mut sigma_x_1ms = f32::NAN;
        loop {
            let Ok(w) = inbox.recv().await else {
                continue;
            };
            if let Some(v) = w.last {
                finish(
                    &mut cx.shared,
                    &v,
                    &bg,
                    sigma_x_1ms,
                    (*l.ipc, *l.per_spin),
                    *l.self_test_ok,
                    *l.calibrated,
                );
            }
            // The stack's peak for the status frames: a scan of every free
            // word, once a second.
            if w.n % 1000 == 0 {
                STACK_PEAK.store(stack::stack_usage().peak, Ordering::Relaxed);
            }
            let t0 = since_tick();
            bg.run(w.job, &mut cx.shared.noise);
            let took = counts_since(t0);
            if STRESS {
                burn(((9 * took) as f32 * *l.ipc) as u32);
            }
            BG_COUNTS.fetch_add(counts_since(t0), Ordering::Relaxed);
            BG_JOBS.fetch_add(1, Ordering::Relaxed);
            if w.fused.iter().any(Option::is_some) {
                for a in 0..3 {
                    let Some(d) = bg.tracker.estimate(a) else {
                        continue;
                    };
                    let e = d.step;
                    defmt::info!(
                        "seq {} axis {}: E-DAVAR for seq {} L={} ({} bridged) score {=f32} (threshold {=f32}) sigma(1/8/64 ms) = {=f32} {=f32} {=f32} dps",
                        w.n,
                        a,
                        d.seq,
                        e.len,
                        d.bridged,
                        e.score,
                        e.threshold,
                        tracker::sigma_dps(&e, 0),
                        tracker::sigma_dps(&e, 3),
                        tracker::sigma_dps(&e, 6)
                    );
                    if a == 0 {
                        sigma_x_1ms = tracker::sigma_dps(&e, 0);
                    }
                }
                let (scale, bias) = cx
                    .shared
                    .pipe
                    .lock(|p| (p.calibration()[2].scale(), p.calibration()[2].bias()));
                defmt::info!(
                    "seq {} axis 2: relative calibration scale {} bias {} dps",
                    w.n,
                    scale,
                    bias
                );
                for (a, f) in w.fused.iter().enumerate() {
                    if let Some((rate, weights)) = f {
                        defmt::info!(
                            "seq {} axis {}: fused {=f32} dps (true {=f32}), weights {}",
                            w.n,
                            a,
                            rate,
                            w.truth[a],
                            weights
                        );
                    }
                }
            }
            schedule::receive(&mut *l.rx, &mut cx.shared.pipe, &mut cx.shared.link);
        }
    }

    /// The run's end: the link drained, every check, the exit code.
    fn finish(
        shared: &mut background::SharedResources<'_>,
        v: &Verdict,
        bg: &schedule::Background<'_, 512, 19, 3>,
        sigma_x_1ms: f32,
        (ipc, per_spin): (f32, f32),
        self_test_ok: bool,
        calibrated: bool,
    ) -> ! {
        let spins = IDLE_SPINS.load(Ordering::Relaxed);
        // Send what is still queued (bounded: the UART takes a byte at a
        // time; its task, above this one, says when it found none).
        TX_EMPTY.store(false, Ordering::Relaxed);
        for _ in 0..100_000 {
            rtic::pend(gyro_sim::qemu::an386::Interrupt::UART0TX);
            if TX_EMPTY.load(Ordering::Relaxed) {
                break;
            }
        }
        let mut pass = self_test_ok && calibrated;
        let lc = shared.link.lock(|l| l.port.counters());
        let sent_all = TX_EMPTY.load(Ordering::Relaxed);
        let rx_overruns = shared.uart.lock(|u| u.rx_overruns());
        defmt::info!(
            "link: {} frames sent, {} dropped, everything sent {}; commands {} accepted, {} rejected; rx overruns {}",
            lc.sent,
            lc.dropped,
            sent_all,
            lc.accepted,
            lc.rejected,
            rx_overruns
        );
        defmt::info!(
            "link: {} sample frames, fused-rate CRC-32 {=u32:#010x}",
            v.sample_frames,
            v.crc
        );
        pass &= lc.dropped == 0 && sent_all && v.sample_frames == SAMPLES && v.fused_everywhere;
        let (c, overruns) = shared.pipe.lock(|p| (*p.counters(), p.overruns()));
        for (i, c) in c.iter().enumerate() {
            defmt::info!(
                "gyro {}: reads {} errors {} (parity {}, chip {}) not read (restarting) {} saturated {} excluded {}; restarts {}, completed {}",
                i,
                c.reads,
                c.errors,
                c.parity,
                c.chip_faults,
                c.not_read,
                c.saturated,
                c.excluded,
                c.restarts,
                c.restarted
            );
        }
        let accounted = c
            .iter()
            .all(|c| c.reads + c.errors + c.not_read + c.late == SAMPLES);
        for (i, (k, ppm)) in v.timing.iter().enumerate() {
            defmt::info!(
                "gyro {} timing: {} FIFO samples, late {} (acquiring {}), overflows {}, clock jumps {}, spikes {}; clock {=f32} ppm",
                i,
                k.samples,
                k.late,
                k.acquiring,
                k.overflows,
                k.jumps,
                k.spikes,
                ppm
            );
        }
        // The chips with no fault of their own (0, 1 and 3, whose clock fails
        // over to its RC oscillator and back) are never flagged: out of fusion
        // only while the array finds its clocks at boot.
        let clock_alone_ok = [0, 1, 3]
            .iter()
            .all(|&i| c[i].errors == 0 && c[i].excluded <= 50);
        defmt::info!(
            "chips with no fault of their own never flagged: {}",
            clock_alone_ok
        );
        pass &= clock_alone_ok;
        defmt::info!(
            "samples {} overruns {} accounted {}",
            SAMPLES,
            overruns,
            accounted
        );
        match (v.stuck_at, v.excluded_at) {
            (Some(s), Some(e)) => {
                defmt::info!("stuck gyro excluded {} samples after the fault", e - s);
                pass &= e - s <= 20;
            }
            _ => pass = false,
        }
        defmt::info!(
            "E-DAVAR: sigma(1 ms) on x = {=f32} dps, {} window restarts, {} missing samples bridged",
            sigma_x_1ms,
            bg.tracker.restarts(),
            bg.tracker.bridged()
        );
        pass &= sigma_x_1ms > 0.02 && sigma_x_1ms < 0.1;
        defmt::info!(
            "noise-health self-test: {}",
            if self_test_ok {
                "all gyros pass"
            } else {
                "FAILED"
            }
        );
        pass &= accounted && c[4].parity > 0 && overruns == 0;
        // The schedule as it ran.
        let ins = |counts: u32| (counts as f32 * ipc) as u32;
        defmt::info!(
            "schedule, as it ran (the emulated world included): tick to the sample task's start worst {} instructions; to its frame queued mean {} worst {}; the task's worst length {}; a frame's first byte on the UART worst {} after its sample's tick",
            ins(v.start_worst),
            ins((v.queued_sum / u64::from(SAMPLES)) as u32),
            ins(v.queued_worst),
            ins(v.task_worst),
            ins(FIRST_BYTE_WORST.load(Ordering::Relaxed))
        );
        let mean = |sum: u64| ins((sum / u64::from(SAMPLES)) as u32);
        defmt::info!(
            "schedule, the firmware's own (the emulated world's step and bus operations, mean {} instructions a sample, taken out): tick to frame queued mean {} worst {}; the sample task's worst length {}; a frame's first byte on the UART worst {} after its sample's tick",
            mean(v.emu_sum),
            mean(v.fw_queued_sum),
            ins(v.fw_queued_worst),
            ins(v.fw_task_worst),
            ins(FIRST_BYTE_FW_WORST.load(Ordering::Relaxed))
        );
        let jobs = BG_JOBS.load(Ordering::Relaxed).max(1);
        let total = SAMPLES as f32 * (RELOAD + 1) as f32 * ipc;
        defmt::info!(
            "schedule: background mean {} instructions a job ({} jobs, preemption included), {=f32} % of the CPU; the CPU busy {=f32} % of the run (idle spun {} times, {=f32} instructions each){=str}",
            ins(BG_COUNTS.load(Ordering::Relaxed) / jobs),
            jobs,
            100.0 * BG_COUNTS.load(Ordering::Relaxed) as f32 * ipc / total,
            100.0 * (1.0 - spins as f32 * per_spin / total),
            spins,
            per_spin,
            if STRESS { " (stress: ten times slower, a status frame every sample)" } else { "" }
        );
        defmt::info!(
            "schedule: {} ticks came while the sample task still ran, {} jobs the background had no room for",
            v.late,
            v.lost
        );
        pass &= v.late == 0 && v.lost == 0;
        let u = stack::stack_usage();
        defmt::info!("stack: peak {} of {} bytes", u.peak, u.size);
        defmt::info!("demo {}", if pass { "PASS" } else { "FAIL" });
        exit(pass)
    }
}
