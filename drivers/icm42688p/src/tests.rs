//! Byte-exact SPI scripts from the datasheet. Register addresses are
//! re-declared here on purpose, so a wrong constant in the driver fails.
use super::*;
use embedded_hal::delay::DelayNs;
use embedded_hal_mock::eh1::spi::{Mock, Transaction as T};

struct NoDelay;
impl DelayNs for NoDelay {
    fn delay_ns(&mut self, _: u32) {}
}

fn rd(addr: u8, v: &[u8]) -> [T<u8>; 4] {
    [
        T::transaction_start(),
        T::write_vec(vec![0x80 | addr]),
        T::read_vec(v.to_vec()),
        T::transaction_end(),
    ]
}
fn wr(addr: u8, v: u8) -> [T<u8>; 3] {
    [
        T::transaction_start(),
        T::write_vec(vec![addr, v]),
        T::transaction_end(),
    ]
}
/// A write and its read-back.
fn wrc(s: &mut Vec<T<u8>>, addr: u8, v: u8) {
    s.extend(wr(addr, v));
    s.extend(rd(addr, &[v]));
}

/// The signal path and clock: bank 1 (GYRO_CONFIG_STATIC2..5 at
/// 0x0B..0x0E, INTF_CONFIG5 at 0x7B), then INTF_CONFIG1 (0x4D),
/// GYRO_CONFIG1 (0x51), GYRO_ACCEL_CONFIG0 (0x52).
fn path(s: &mut Vec<T<u8>>, aaf: [u8; 4], pin9: u8, intf1: u8, cfg1: u8, gac0: u8) {
    s.extend(wr(0x76, 0x01));
    for (i, v) in aaf.iter().enumerate() {
        wrc(s, 0x0B + i as u8, *v);
    }
    wrc(s, 0x7B, pin9);
    s.extend(wr(0x76, 0x00));
    wrc(s, 0x4D, intf1);
    wrc(s, 0x51, cfg1);
    wrc(s, 0x52, gac0);
}

/// 258 Hz AAF: DELT 6, DELTSQR 36, BITSHIFT 10 (datasheet table 17).
const AAF_258: [u8; 4] = [0xA0, 6, 36, 0xA0];

#[test]
fn init_resets_checks_id_and_configures() {
    let mut s = Vec::new();
    s.extend(wr(0x11, 0x01)); // DEVICE_CONFIG soft reset
    s.extend(wr(0x76, 0x00)); // bank 0
    s.extend(rd(0x75, &[0x47])); // WHO_AM_I
                                 // AFSR off: INTF_CONFIG1 0x91 -> 0x51; UI filter 2nd order at
                                 // ODR/4 (the reset values 0x16 and 0x11).
    path(&mut s, AAF_258, 0x00, 0x51, 0x16, 0x11);
    wrc(&mut s, 0x4F, 0x66); // ±250 °/s (011) | 1 kHz (0110)
    wrc(&mut s, 0x4C, 0x30); // INTF_CONFIG0 at reset: no FIFO
    wrc(&mut s, 0x5F, 0x00); // FIFO_CONFIG1: nothing in the FIFO
    wrc(&mut s, 0x16, 0x00); // FIFO_CONFIG: bypass
    wrc(&mut s, 0x4E, 0x0C); // gyro low-noise
    s.extend(rd(0x2D, &[0x10])); // INT_STATUS: clears RESET_DONE
    let mut spi = Mock::new(&s);
    let mut g = Icm42688::new(spi.clone());
    g.init(&mut NoDelay, Config::default()).unwrap();
    assert_eq!(g.full_scale(), FullScale::Dps250);
    spi.done();
}

#[test]
fn init_with_fifo_and_clkin() {
    let mut s = Vec::new();
    s.extend(wr(0x11, 0x01));
    s.extend(wr(0x76, 0x00));
    s.extend(rd(0x75, &[0x47]));
    // PX4's 585 Hz AAF (DELT 13, DELTSQR 170, BITSHIFT 8), pin 9 as
    // CLKIN (0b10 << 1), RTC_MODE (bit 2) with AFSR off; a 3rd-order UI
    // filter (0b10 << 2) at ODR/5.
    path(&mut s, [0xA0, 13, 170, 0x80], 0x04, 0x55, 0x1A, 0x12);
    wrc(&mut s, 0x4F, 0x66);
    wrc(&mut s, 0x4C, 0x70); // count in records
    wrc(&mut s, 0x5F, 0x07); // temperature, gyro, accel slots
    wrc(&mut s, 0x16, 0x80); // stop-on-full
    wrc(&mut s, 0x14, 0x03); // INT1 push-pull, active high, pulsed
    wrc(&mut s, 0x64, 0x00); // INT_ASYNC_RESET cleared
    wrc(&mut s, 0x65, 0x08); // data ready on INT1
    wrc(&mut s, 0x4E, 0x0C);
    s.extend(rd(0x2D, &[0x10]));
    s.extend(wr(0x4B, 0x02)); // SIGNAL_PATH_RESET.FIFO_FLUSH
    s.extend(rd(0x2D, &[0x02])); // and the FIFO_FULL latched before
    let mut spi = Mock::new(&s);
    let mut g = Icm42688::new(spi.clone());
    let cfg = Config {
        filter: Filter {
            aaf_delt: 13,
            ui_order: 3,
            ui_bw: 2,
        },
        clock: ClockInput::ClkIn,
        sampling: Sampling::Fifo,
        ..Config::default()
    };
    g.init(&mut NoDelay, cfg).unwrap();
    spi.done();
}

#[test]
fn an_aaf_setting_outside_the_table_is_refused() {
    let mut s = Vec::new();
    s.extend(wr(0x11, 0x01));
    s.extend(wr(0x76, 0x00));
    s.extend(rd(0x75, &[0x47]));
    let mut spi = Mock::new(&s);
    let mut g = Icm42688::new(spi.clone());
    let cfg = Config {
        filter: Filter {
            aaf_delt: 60,
            ..Filter::ARDUPILOT
        },
        ..Config::default()
    };
    assert_eq!(g.init(&mut NoDelay, cfg), Err(Error::InvalidArgument));
    spi.done();
}

#[test]
fn wrong_id_is_a_typed_error() {
    let mut s = Vec::new();
    s.extend(wr(0x11, 0x01));
    s.extend(wr(0x76, 0x00));
    s.extend(rd(0x75, &[0x98]));
    let mut spi = Mock::new(&s);
    let mut g = Icm42688::new(spi.clone());
    assert_eq!(
        g.init(&mut NoDelay, Config::default()),
        Err(Error::WrongId(0x98))
    );
    spi.done();
}

#[test]
fn config_read_back_mismatch_is_reported() {
    let mut s = Vec::new();
    s.extend(wr(0x4F, 0x06));
    s.extend(rd(0x4F, &[0x00]));
    let mut spi = Mock::new(&s);
    let mut g = Icm42688::new(spi.clone());
    let cfg = Config {
        full_scale: FullScale::Dps2000,
        ..Config::default()
    };
    assert_eq!(
        g.configure(cfg),
        Err(Error::ConfigMismatch {
            reg: 0x4F,
            wrote: 0x06,
            read: 0
        })
    );
    spi.done();
}

#[test]
fn burst_read_scales_big_endian_counts() {
    // GYRO_DATA_X1..Z0, TMST (2), INT_STATUS (data ready only).
    let s = rd(
        0x25,
        &[0x00, 0x83, 0xFF, 0x7D, 0x7F, 0xFF, 0x12, 0x34, 0x08],
    );
    let mut spi = Mock::new(&s);
    let mut g = Icm42688::new(spi.clone());
    g.full_scale = FullScale::Dps250;
    let (raw, status) = g.read_sample().unwrap();
    assert_eq!(raw, [131, -131, 32767]);
    assert_eq!(status, 0x08);
    let s = g.full_scale().lsb_per_dps();
    assert_eq!((raw[0] as f32 / s, raw[1] as f32 / s), (1.0, -1.0));
    spi.done();
}

#[test]
fn a_silent_reset_is_reported_and_a_restart_reconfigures() {
    let mut s = Vec::new();
    // INT_STATUS with RESET_DONE: the chip reset since it was set up.
    s.extend(rd(0x25, &[0x80, 0x00, 0x80, 0x00, 0x80, 0x00, 0, 0, 0x10]));
    s.extend(wr(0x11, 0x01)); // step 0: soft reset
    s.extend(wr(0x76, 0x00)); // step 1: bank 0, id
    s.extend(rd(0x75, &[0x47]));
    // Then at most six transactions a step: bank 1 (AAF 258 Hz, pin 9).
    s.extend(wr(0x76, 0x01));
    wrc(&mut s, 0x0B, AAF_258[0]);
    wrc(&mut s, 0x0C, AAF_258[1]);
    s.extend(wr(0x76, 0x00));
    s.extend(wr(0x76, 0x01));
    wrc(&mut s, 0x0D, AAF_258[2]);
    wrc(&mut s, 0x0E, AAF_258[3]);
    s.extend(wr(0x76, 0x00));
    s.extend(wr(0x76, 0x01));
    wrc(&mut s, 0x7B, 0x00);
    s.extend(wr(0x76, 0x00));
    wrc(&mut s, 0x4D, 0x51); // AFSR off
    wrc(&mut s, 0x51, 0x16);
    wrc(&mut s, 0x52, 0x11);
    wrc(&mut s, 0x4F, 0x06); // the configuration set before
    wrc(&mut s, 0x4C, 0x30);
    wrc(&mut s, 0x5F, 0x00);
    wrc(&mut s, 0x16, 0x00);
    wrc(&mut s, 0x4E, 0x0C); // gyro on, then RESET_DONE cleared
    s.extend(rd(0x2D, &[0x10]));
    let mut spi = Mock::new(&s);
    let mut g = Icm42688::new(spi.clone());
    assert_eq!(g.read_sample().unwrap().1 & RESET_DONE, RESET_DONE);
    let mut step = 0;
    let mut waits = Vec::new();
    loop {
        match g.restart_step(step) {
            Ok(Step::Again { step: s, wait_us }) => {
                waits.push(wait_us);
                step = s;
            }
            Ok(Step::Done) => break,
            Err(e) => panic!("{e:?}"),
        }
    }
    // Reset, identity, six steps of writes, the 45 ms start-up.
    assert_eq!(waits, [1000, 0, 0, 0, 0, 0, 0, 45_000]);
    spi.done();
}

#[test]
fn config_check_reads_the_core_every_time_and_three_groups_in_turn() {
    // The core: REG_BANK_SEL, 0x4C..=0x52 in one burst (±2000 °/s,
    // 1 kHz as `new` assumes).
    let core = |s: &mut Vec<T<u8>>, intf1: u8| {
        s.extend(rd(0x76, &[0x00]));
        s.extend(rd(0x4C, &[0x30, intf1, 0x0C, 0x06, 0x06, 0x16, 0x11]));
    };
    let mut s = Vec::new();
    // Group 0: FIFO_CONFIG, FIFO_CONFIG1 (reset values without the FIFO).
    core(&mut s, 0x51);
    s.extend(rd(0x16, &[0x00]));
    s.extend(rd(0x5F, &[0x00]));
    // Group 1: INT_CONFIG, then INT_CONFIG1 and INT_SOURCE0 in one burst.
    core(&mut s, 0x51);
    s.extend(rd(0x14, &[0x00]));
    s.extend(rd(0x64, &[0x10, 0x10]));
    // Group 2: bank 1, GYRO_CONFIG_STATIC2..5 in one burst, INTF_CONFIG5.
    core(&mut s, 0x51);
    s.extend(wr(0x76, 0x01));
    s.extend(rd(0x0B, &AAF_258));
    s.extend(rd(0x7B, &[0x00]));
    s.extend(wr(0x76, 0x00));
    // Then: AFSR back on (a reset value) in the core; INT1 set up
    // behind the driver's back; the AAF at another setting.
    core(&mut s, 0x91);
    core(&mut s, 0x51);
    s.extend(rd(0x14, &[0x03]));
    core(&mut s, 0x51);
    s.extend(wr(0x76, 0x01));
    s.extend(rd(0x0B, &[0xA0, 13, 170, 0x80]));
    s.extend(rd(0x7B, &[0x00]));
    s.extend(wr(0x76, 0x00));
    let mut spi = Mock::new(&s);
    let mut g = Icm42688::new(spi.clone());
    for _ in 0..3 {
        assert_eq!(g.check_config(), Ok(()));
    }
    // Each names the first register that differs.
    assert_eq!(
        g.check_config(),
        Err(Error::ConfigMismatch {
            reg: 0x4D,
            wrote: 0x51,
            read: 0x91
        })
    );
    assert_eq!(
        g.check_config(),
        Err(Error::ConfigMismatch {
            reg: 0x14,
            wrote: 0x00,
            read: 0x03
        })
    );
    assert_eq!(
        g.check_config(),
        Err(Error::ConfigMismatch {
            reg: 0x0C,
            wrote: AAF_258[1],
            read: 13
        })
    );
    spi.done();
}

/// A packet 3: header 0x68, accel −32768 ×3, gyro, temperature, stamp.
fn packet(g: [i16; 3], stamp: u16) -> [u8; 16] {
    let mut p = [0u8; 16];
    p[0] = 0x68;
    for i in 0..3 {
        p[1 + 2 * i] = 0x80;
        p[7 + 2 * i..9 + 2 * i].copy_from_slice(&g[i].to_be_bytes());
    }
    p[14..16].copy_from_slice(&stamp.to_be_bytes());
    p
}

fn fifo_driver(s: &[T<u8>]) -> (Mock<u8>, Icm42688<Mock<u8>>) {
    let spi = Mock::new(s);
    let mut g = Icm42688::new(spi.clone());
    g.config.sampling = Sampling::Fifo;
    (spi, g)
}

/// The burst INT_STATUS, FIFO_COUNTH/L, one packet.
fn head(status: u8, count: u16, p: &[u8; 16]) -> [T<u8>; 4] {
    let mut v = vec![status];
    v.extend(count.to_be_bytes());
    v.extend(p);
    rd(0x2D, &v)
}

#[test]
fn fifo_reads_one_packet_in_one_transaction_and_more_in_a_second() {
    let mut s = Vec::new();
    s.extend(head(0x08, 1, &packet([1, -2, 3], 0xFFF0)));
    // Two more came: the second is read from FIFO_DATA (0x30); the stamp
    // wraps (0xFFF0 + 1000 µs).
    s.extend(head(
        0x08,
        2,
        &packet([4, 5, 6], 0xFFF0u16.wrapping_add(1000)),
    ));
    s.extend(rd(0x30, &packet([7, 8, 9], 0xFFF0u16.wrapping_add(2000))));
    // Empty: the packet bytes read 0x80 and are not looked at.
    s.extend(head(0x00, 0, &[0x80; 16]));
    let (mut spi, mut g) = fifo_driver(&s);
    let mut out = [FifoSample {
        raw: [0; 3],
        stamp: 0,
    }; 4];
    let r = g.read_fifo(&mut out).unwrap();
    assert_eq!((r.samples, r.left, r.status), (1, 0, 0x08));
    assert_eq!(out[0].raw, [1, -2, 3]);
    assert_eq!(out[0].stamp, 0xFFF0);
    let r = g.read_fifo(&mut out).unwrap();
    assert_eq!((r.samples, r.left), (2, 0));
    assert_eq!(out[0].raw, [4, 5, 6]);
    assert_eq!(out[0].stamp, 0xFFF0 + 1000);
    assert_eq!(out[1].stamp, 0xFFF0 + 2000);
    assert_eq!(g.read_fifo(&mut out).unwrap().samples, 0);
    spi.done();
}

#[test]
fn at_2_khz_one_burst_holds_two_packets_and_the_rest_comes_in_one_more() {
    let mut two = vec![0x08, 0x00, 0x02];
    two.extend(packet([1, 1, 1], 100));
    two.extend(packet([2, 2, 2], 600));
    let mut one = vec![0x08, 0x00, 0x01];
    one.extend(packet([3, 3, 3], 1100));
    one.extend([0x80; 16]); // room for a second, not counted
    let mut four = vec![0x08, 0x00, 0x04];
    four.extend(packet([4, 4, 4], 1600));
    four.extend(packet([5, 5, 5], 2100));
    let mut rest = packet([6, 6, 6], 2600).to_vec();
    rest.extend(packet([7, 7, 7], 3100));
    let mut s = Vec::new();
    s.extend(rd(0x2D, &two));
    s.extend(rd(0x2D, &one));
    s.extend(rd(0x2D, &four));
    s.extend(rd(0x30, &rest));
    let (mut spi, mut g) = fifo_driver(&s);
    g.config.odr = Odr::Hz2000;
    g.per_read = g.config.per_read();
    g.stamp_lim = g.config.stamp_step_max();
    let mut out = [FifoSample {
        raw: [0; 3],
        stamp: 0,
    }; 8];
    assert_eq!(g.read_fifo(&mut out).unwrap().samples, 2);
    assert_eq!(out[1].raw, [2, 2, 2]);
    assert_eq!(g.read_fifo(&mut out).unwrap().samples, 1);
    assert_eq!(g.read_fifo(&mut out).unwrap().samples, 4);
    assert_eq!(out[3].raw, [7, 7, 7]);
    assert_eq!(out[3].stamp, 3100);
    spi.done();
}

/// A burst cut inside its last packet (chip select lost: the tail reads
/// the idle line's 0xFF) leaves that packet, which the chip sends again
/// whole; a packet handed over past the count and sent again is known by
/// its stamp. Each sample is handed on once.
#[test]
fn a_cut_packet_is_read_again_and_a_packet_sent_again_is_dropped() {
    let mut s = Vec::new();
    // Two counted, the second cut after its gyro bytes.
    let mut cut = vec![0x08, 0x00, 0x02];
    cut.extend(packet([1, 1, 1], 1000));
    let mut tail = packet([2, 2, 2], 1234);
    tail[13..].fill(0xFF);
    cut.extend(tail);
    cut.extend([0xFF; 32]);
    // The next burst: the cut packet whole, one more counted, one past
    // the count handed over.
    let mut again = vec![0x08, 0x00, 0x02];
    again.extend(packet([2, 2, 2], 1234));
    again.extend(packet([3, 3, 3], 1468));
    again.extend(packet([4, 4, 4], 1702));
    again.extend([0x80; 16]);
    // The packet handed over past the count, sent again, and one more.
    let mut resent = vec![0x08, 0x00, 0x02];
    resent.extend(packet([4, 4, 4], 1702));
    resent.extend(packet([5, 5, 5], 1936));
    resent.extend([0x80; 32]);
    s.extend(rd(0x2D, &cut));
    s.extend(rd(0x2D, &again));
    s.extend(rd(0x2D, &resent));
    let (mut spi, mut g) = fifo_driver(&s);
    g.per_read = 4;
    let mut got = Vec::new();
    let r = g.read_fifo_with(8, |x| got.push(x.stamp)).unwrap();
    assert!(r.cut);
    assert_eq!((r.samples, r.left), (1, 1));
    let r = g.read_fifo_with(8, |x| got.push(x.stamp)).unwrap();
    assert_eq!((r.samples, r.counted, r.left, r.cut), (3, 2, 0, false));
    let r = g.read_fifo_with(8, |x| got.push(x.stamp)).unwrap();
    assert_eq!((r.samples, r.resent), (1, 1));
    assert_eq!(got, [1000, 1234, 1468, 1702, 1936]);
    spi.done();
}

#[test]
fn fifo_leaves_what_the_buffer_cannot_hold() {
    let mut s = Vec::new();
    s.extend(head(0x08, 3, &packet([1, 1, 1], 0)));
    s.extend(rd(0x30, &packet([2, 2, 2], 1000)));
    let (mut spi, mut g) = fifo_driver(&s);
    let mut out = [FifoSample {
        raw: [0; 3],
        stamp: 0,
    }; 2];
    let r = g.read_fifo(&mut out).unwrap();
    assert_eq!((r.samples, r.left), (2, 1));
    spi.done();
}

#[test]
fn fifo_overflow_bad_header_short_fifo_and_reset_are_typed_errors() {
    let mut s = Vec::new();
    s.extend(head(0x0A, 128, &packet([0; 3], 0))); // FIFO_FULL
    s.extend(wr(0x4B, 0x02));
    s.extend(rd(0x2D, &[0x00]));
    let mut bad = packet([0; 3], 0);
    bad[0] = 0x28; // gyro only: not the format configured
    s.extend(head(0x08, 1, &bad));
    s.extend(wr(0x4B, 0x02));
    s.extend(rd(0x2D, &[0x00]));
    s.extend(head(0x08, 1, &[0x80; 16])); // counted, but empty
    s.extend(wr(0x4B, 0x02));
    s.extend(rd(0x2D, &[0x10])); // and a reset seen while flushing
    s.extend(head(0x08, 1, &packet([0; 3], 0))); // reported by the next read
    s.extend(head(0x18, 1, &packet([0; 3], 0))); // RESET_DONE itself
    let (mut spi, mut g) = fifo_driver(&s);
    let mut out = [FifoSample {
        raw: [0; 3],
        stamp: 0,
    }; 2];
    assert_eq!(g.read_fifo(&mut out), Err(Error::FifoOverflow));
    assert_eq!(g.read_fifo(&mut out), Err(Error::FifoBadHeader(0x28)));
    assert_eq!(g.read_fifo(&mut out), Err(Error::FifoShort));
    assert_eq!(g.read_fifo(&mut out), Err(Error::ChipReset));
    assert_eq!(g.read_fifo(&mut out), Err(Error::ChipReset));
    spi.done();
}

#[test]
fn fifo_full_beside_a_count_no_full_fifo_has_is_a_bad_status_and_flushes_nothing() {
    let mut s = Vec::new();
    // FIFO_FULL (and data-ready) beside one record: a garbled status;
    // no flush, so the same packet is there for the next read.
    s.extend(head(0x0A, 1, &packet([4, 5, 6], 100)));
    s.extend(head(0x08, 1, &packet([4, 5, 6], 100)));
    // Half the FIFO or more beside FIFO_FULL: a real overflow.
    s.extend(head(0x0A, FIFO_RECORDS as u16 / 2, &packet([0; 3], 0)));
    s.extend(wr(0x4B, 0x02));
    s.extend(rd(0x2D, &[0x00]));
    let (mut spi, mut g) = fifo_driver(&s);
    let mut out = [FifoSample {
        raw: [0; 3],
        stamp: 0,
    }; 2];
    assert_eq!(g.read_fifo(&mut out), Err(Error::FifoBadStatus(0x0A)));
    let r = g.read_fifo(&mut out).unwrap();
    assert_eq!((r.samples, out[0].raw), (1, [4, 5, 6]));
    assert_eq!(g.read_fifo(&mut out), Err(Error::FifoOverflow));
    spi.done();
}

#[test]
fn fifo_read_without_fifo_sampling_is_refused() {
    let (mut spi, mut g) = fifo_driver(&[]);
    g.config.sampling = Sampling::Registers;
    let mut out = [FifoSample {
        raw: [0; 3],
        stamp: 0,
    }; 1];
    assert_eq!(g.read_fifo(&mut out), Err(Error::NotFifo));
    spi.done();
}

#[test]
fn factory_code_formula() {
    assert_eq!(factory_response_lsb(1), 327.5);
    assert!((factory_response_lsb(101) - 327.5 * 1.01f32.powi(100)).abs() < 0.05);
    assert_eq!(factory_response_lsb(0), 0.0);
}

#[test]
fn aaf_coefficient_table() {
    // The pairs PX4 (585 Hz) and ArduPilot (258, 536, 997 Hz) write.
    assert_eq!(aaf_coefficients(6), Some((36, 10)));
    assert_eq!(aaf_coefficients(12), Some((144, 8)));
    assert_eq!(aaf_coefficients(13), Some((170, 8)));
    assert_eq!(aaf_coefficients(21), Some((440, 6)));
    assert_eq!(aaf_coefficients(63), Some((3968, 3)));
    assert_eq!(aaf_coefficients(60), None);
    assert_eq!(aaf_coefficients(0), None);
}
