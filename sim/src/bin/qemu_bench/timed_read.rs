//! One timed chip's FIFO read through `TimedIcm`, counted alone.

use super::*;

/// One ICM-42688-P's read, on the emulated bus with the bus's own time
/// metered out: polled (the data registers, as the board's loop reads
/// them today) against the timed path (`TimedIcm`: the FIFO at 4 kHz, four
/// samples a read, the INT1 capture, the clock tracker, the moving mean
/// and the interpolation to the stated instant). The chip keeps its own
/// time on a clock 0.3 % fast, so reads find one, two or three samples.
pub(super) fn bench_timed_read(t: &Ticks, ipt: f32) -> bool {
    use core::cell::RefCell;
    use gyro_array::drivers::icm42688::{board_fifo, ClockInput, Config, Icm42688};
    use gyro_array::drivers::Gyro;
    use gyro_array::pipeline::timed::TimedIcm;
    use gyro_sim::{
        emu_device, with_bus, Chip, ChipTiming, CsLine, EmuBus, EmuCapture, EmuDelay,
        Icm42688Model, NoiseParams, RateProfile,
    };

    const READS: u32 = 400;
    let mut ok = true;
    for (timed, fifo_only) in [(false, false), (true, true), (true, false)] {
        let cs: [CsLine; 1] = Default::default();
        let mut chip = Icm42688Model::new(NoiseParams::ICM42688, RateProfile::constant(2.0), 3, 70);
        if timed {
            chip.set_timing(Some(ChipTiming::pll(0.003)));
        }
        let bus = RefCell::new(EmuBus::new([Chip::Icm(chip)], &cs));
        let mut delay = EmuDelay::new(&bus, 1e-3);
        let dev = emu_device(&bus, &cs[0]);
        let mut g = Icm42688::new(dev);
        let cfg = if timed {
            board_fifo(ClockInput::Internal)
        } else {
            Config::default()
        };
        if g.init(&mut delay, cfg).is_err() {
            defmt::error!("timed read bench: init failed");
            return false;
        }
        with_bus(&bus, |b| b.clock = Some(gyro_sim::qemu::ticks));
        let meter = || with_bus(&bus, |b| b.meter).unwrap_or_default();
        let pair = pair_cost(t);
        let mut timed_g = TimedIcm::new(
            g,
            EmuCapture {
                bus: &bus,
                index: 0,
            },
        );
        let (mut sum, mut worst, mut good) = (0.0f32, 0.0f32, 0u32);
        for n in 0..READS + 100 {
            with_bus(&bus, |b| b.advance(1e-3));
            let now_us = with_bus(&bus, |b| b.timer_us()).unwrap_or(0);
            let delay = gyro_array::pipeline::timed::BOARD_DELAY_US;
            let at = gyro_array::pipeline::timed::array_instant(now_us, delay);
            timed_g.set_instant(at, delay);
            let m0 = meter();
            let t0 = t.now();
            let r = if fifo_only {
                let mut buf = [gyro_array::drivers::icm42688::FifoSample {
                    raw: [0; 3],
                    stamp: 0,
                }; 4];
                black_box(timed_g.driver().read_fifo(&mut buf))
                    .map(|_| ())
                    .map_err(|_| gyro_array::drivers::ReadFault::Bus)
            } else if timed {
                black_box(timed_g.read()).map(|_| ())
            } else {
                black_box(Gyro::read(timed_g.driver())).map(|_| ())
            };
            let dt = t.now() - t0;
            let m1 = meter();
            // The bus's own time (the chip models standing in for the
            // SPI peripheral and the silicon), and one clock pair per
            // metered operation, out.
            let bus_ticks =
                m1.ticks.wrapping_sub(m0.ticks) as f32 + m1.ops.wrapping_sub(m0.ops) as f32 * pair;
            let own = (net(dt, pair) - bus_ticks).max(0.0) * ipt;
            if n >= 100 {
                sum += own;
                worst = worst.max(own);
                good += u32::from(r.is_ok());
            }
        }
        defmt::info!(
            "one ICM-42688-P read, {=str}: mean {=f32} worst {=f32} instructions (bus time out), {=u32} of {=u32} reads with a rate",
            if fifo_only {
                "the FIFO read alone (4 kHz)"
            } else if timed {
                "timed (FIFO 4 kHz, capture, tracker, aligner)"
            } else {
                "polled (data registers)"
            },
            sum / READS as f32,
            worst,
            good,
            READS
        );
        ok &= good == READS;
    }
    ok
}
