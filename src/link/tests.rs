//! Link tests: round trips, frame sizes against the budget, resync after
//! damage, command handling.

use heapless::Vec;
use proptest::prelude::*;

use super::msg::*;
use super::port::RingPort;
use super::wire::{encode, encode_in_place, Decoded, Decoder, FrameError, IN_PLACE_MAX, MAX_FRAME};
use super::{frame_budget, VERSION};
use crate::algo::fusion::{AdaptiveConfig, Method};
use crate::pipeline::{Pipeline, PipelineConfig};

fn vec<T: Clone, const N: usize>(v: T, n: usize) -> Vec<T, N> {
    let mut out = Vec::new();
    for _ in 0..n {
        out.push(v.clone()).ok().unwrap();
    }
    out
}

/// The largest sample frame for `n` gyros: every field at its widest.
fn big_sample(n: usize) -> Frame {
    Frame::Sample(Sample {
        seq: u32::MAX,
        t_us: u64::MAX,
        age_us: [u16::MAX; 3],
        predicted_us: Some(u16::MAX),
        rate_dps: [-1234.5; 3],
        valid: 7,
        degraded: 7,
        used: [0xFF; 3],
        health: vec(0xFF, n),
        noise: Some(Noise {
            axis: 2,
            seq: u32::MAX,
            len: u16::MAX,
            bridged: u8::MAX,
            sigma_dps: [1.0; 3],
        }),
        angle: Some(Angle {
            x: u32::MAX,
            y: u32::MAX,
            z: u32::MAX,
        }),
    })
}

fn big_raw(n: usize) -> Frame {
    Frame::Raw(Raw {
        seq: u32::MAX,
        t_us: u64::MAX,
        age_us: vec(u16::MAX, n),
        rate_dps: vec([1.0; 3], n),
        health: vec(0xFF, n),
    })
}

fn big_status(n: usize) -> Frame {
    Frame::Status(Status::widest(n))
}

fn wire_len(f: &Frame) -> usize {
    let mut buf = [0u8; MAX_FRAME];
    encode(u32::MAX, f, &mut buf).unwrap()
}

fn decode_all(
    bytes: &[u8],
) -> (
    std::vec::Vec<Result<Decoded<Frame>, FrameError>>,
    Decoder<MAX_FRAME>,
) {
    let mut d = Decoder::<MAX_FRAME>::new();
    let out = bytes.iter().filter_map(|&b| d.feed::<Frame>(b)).collect();
    (out, d)
}

#[test]
fn every_frame_kind_round_trips() {
    let frames = [
        big_sample(5),
        big_raw(5),
        big_status(5),
        Frame::Ack(Ack {
            id: Some(7),
            result: Err(Reject::OutOfRange),
        }),
        Frame::Ack(Ack {
            id: None,
            result: Ok(()),
        }),
    ];
    for (k, f) in frames.iter().enumerate() {
        let mut buf = [0u8; MAX_FRAME];
        let n = encode(k as u32, f, &mut buf).unwrap();
        assert_eq!(buf[n - 1], 0);
        assert!(!buf[..n - 1].contains(&0), "COBS leaves no 0x00 inside");
        let (got, d) = decode_all(&buf[..n]);
        assert_eq!(got.len(), 1);
        let got = got[0].as_ref().unwrap();
        assert_eq!((got.link_seq, &got.body), (k as u32, f));
        assert_eq!(d.stats().frames, 1);
    }
}

/// Every frame kind's payload is postcard's own bytes (the port writes it
/// byte by byte), and a buffer a byte short is refused.
#[test]
fn every_payload_is_postcards() {
    let ack = Frame::Ack(Ack {
        id: Some(7),
        result: Err(Reject::OutOfRange),
    });
    for (k, f) in [big_sample(5), big_raw(5), big_status(5), big_sample(1), ack]
        .iter()
        .enumerate()
    {
        let mut payload = [0u8; MAX_FRAME];
        let n = super::wire::encode_payload(k as u32, f, &mut payload).unwrap();
        // Short of the CRC, and of the envelope's last byte.
        for short in [n - 1, n - 3] {
            assert!(super::wire::encode_payload(k as u32, f, &mut payload[..short]).is_err());
        }
        let mut want = [0u8; MAX_FRAME];
        want[0] = VERSION;
        let body = postcard::to_slice(&(k as u32).to_le_bytes(), &mut want[1..])
            .unwrap()
            .len();
        let m = 1 + body + postcard::to_slice(f, &mut want[1 + body..]).unwrap().len();
        assert_eq!(payload[..n - 2], want[..m], "{f:?}");
    }
}

#[test]
fn frame_ref_encodes_as_the_frame() {
    let frames = [
        big_sample(5),
        big_raw(3),
        big_status(5),
        Frame::Ack(Ack {
            id: Some(2),
            result: Err(Reject::OutOfRange),
        }),
    ];
    for f in &frames {
        let (mut a, mut b) = ([0u8; MAX_FRAME], [0u8; MAX_FRAME]);
        let n = encode(9, f, &mut a).unwrap();
        let m = encode(9, &f.as_ref(), &mut b).unwrap();
        assert_eq!(a[..n], b[..m], "{f:?}");
    }
}

/// The largest frames the board (5 gyros) sends at 1 kHz fit the budget
/// with room for an acknowledgement in the same period; printed for the
/// specification.
#[test]
fn the_largest_frames_fit_one_sample_period_at_1_khz() {
    let budget = frame_budget(1000) as usize;
    let ack = wire_len(&Frame::Ack(Ack {
        id: Some(255),
        result: Err(Reject::Refused),
    }));
    for n in [5, MAX_GYROS] {
        let (s, r, st) = (
            wire_len(&big_sample(n)),
            wire_len(&big_raw(n)),
            wire_len(&big_status(n)),
        );
        println!("{n} gyros: sample {s} B, raw {r} B, status {st} B, ack {ack} B; budget {budget} B per 1 ms");
        assert!(s + ack <= budget && r + ack <= budget);
        // A status frame (once a second, queued after its sample's frame)
        // and an acknowledgement are on the wire before the next sample
        // frame for the board's five gyros, so none waits behind them;
        // with eight, the status frame drains within two periods.
        let periods = if n <= 5 { 1 } else { 2 };
        assert!(st + ack + periods * s <= periods * budget);
    }
    assert_eq!(budget, 600);
    // The delay compensation's horizon allows for the largest sample frame,
    // with the angle and without.
    assert_eq!(
        (super::port::SAMPLE_FRAME_MAX + super::port::ANGLE_BYTES) as usize,
        wire_len(&big_sample(5))
    );
    let Frame::Sample(mut s) = big_sample(5) else {
        unreachable!()
    };
    s.angle = None;
    assert_eq!(
        super::port::SAMPLE_FRAME_MAX as usize,
        wire_len(&Frame::Sample(s))
    );
}

#[test]
fn every_single_bit_flip_in_a_frame_is_caught() {
    let f = big_sample(5);
    let mut buf = [0u8; MAX_FRAME];
    let n = encode(1, &f, &mut buf).unwrap();
    let mut caught = 0;
    for bit in 0..(n - 1) * 8 {
        let mut b = buf[..n].to_vec();
        b[bit / 8] ^= 1 << (bit % 8);
        let (got, d) = decode_all(&b);
        assert!(
            got.iter().all(|r| r.is_err()),
            "bit {bit} flipped went through"
        );
        assert_eq!(d.stats().frames, 0);
        caught += 1;
    }
    assert_eq!(caught, (n - 1) * 8);
}

#[test]
fn a_frame_of_another_version_is_counted_not_decoded() {
    let mut buf = [0u8; MAX_FRAME];
    let n = encode(1, &big_raw(2), &mut buf).unwrap();
    // Re-frame the payload with another version byte and a fresh CRC.
    let mut payload = [0u8; MAX_FRAME];
    let m = cobs::decode(&buf[..n - 1], &mut payload).unwrap();
    payload[0] = VERSION + 1;
    let crc = crc::Crc::<u16>::new(&crc::CRC_16_IBM_3740).checksum(&payload[..m - 2]);
    payload[m - 2..m].copy_from_slice(&crc.to_le_bytes());
    let mut out = [0u8; MAX_FRAME];
    let k = cobs::encode(&payload[..m], &mut out);
    out[k] = 0;
    let (got, d) = decode_all(&out[..=k]);
    assert_eq!(got, [Err(FrameError::Version(VERSION + 1))]);
    assert_eq!(d.stats().version, 1);
}

fn stream(frames: &[Frame]) -> std::vec::Vec<u8> {
    let mut out = std::vec::Vec::new();
    for (k, f) in frames.iter().enumerate() {
        let mut buf = [0u8; MAX_FRAME];
        let n = encode(k as u32, f, &mut buf).unwrap();
        out.extend_from_slice(&buf[..n]);
    }
    out
}

proptest! {
    /// The in-place encoder writes the crate encoder's bytes, for bodies
    /// with zeros anywhere (runs up to the longest payload it takes), and
    /// refuses what it cannot take (too long, or too little room) without
    /// a wrong frame.
    #[test]
    fn in_place_frames_are_the_crate_encoders(
        body in proptest::collection::vec(prop_oneof![Just(0u8), 1u8..=255], 0..260),
        seq in any::<u32>(),
        room_len in 0usize..300,
    ) {
        let body: &[u8] = &body;
        let mut want = [0u8; MAX_FRAME];
        let n = encode(seq, &body, &mut want).unwrap();
        let mut room = [0xAAu8; 300];
        match encode_in_place(seq, &body, &mut room[..room_len]) {
            Ok(m) => prop_assert_eq!(&room[..m], &want[..n]),
            Err(_) => prop_assert!(n - 2 > IN_PLACE_MAX || n > room_len, "refused {} bytes in {}", n, room_len),
        }
        // Every frame it can take fits its room when the room is large.
        if n - 2 <= IN_PLACE_MAX {
            let m = encode_in_place(seq, &body, &mut room[..IN_PLACE_MAX + 2]).unwrap();
            prop_assert_eq!(&room[..m], &want[..n]);
        }
    }

    /// Garbage never panics the decoder and never yields a frame that was
    /// not sent (the CRC would have to collide: 2⁻¹⁶ per garbage frame;
    /// these inputs are short).
    #[test]
    fn garbage_is_counted_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..2000)) {
        let (got, d) = decode_all(&bytes);
        let s = d.stats();
        prop_assert_eq!(got.len() as u64, s.frames + s.corrupt + s.too_long + s.version + s.malformed);
    }

    /// Damage anywhere in a stream (bytes changed, dropped or inserted)
    /// costs only the frames it touches: every frame it does not touch is
    /// decoded, in order, with its link sequence number.
    #[test]
    fn the_decoder_resynchronises_after_damage(
        at in 0usize..1000, len in 1usize..40, kind in 0u8..3, junk in any::<u8>()
    ) {
        let frames: std::vec::Vec<Frame> = (0..12).map(|k| match k % 3 {
            0 => big_sample(5),
            1 => big_raw(4),
            _ => big_status(3),
        }).collect();
        let clean = stream(&frames);
        // Frame boundaries: end offsets (exclusive) of each frame.
        let mut ends = std::vec::Vec::new();
        for (i, &b) in clean.iter().enumerate() {
            if b == 0 { ends.push(i + 1); }
        }
        let at = at % clean.len();
        let end = (at + len).min(clean.len());
        let mut bad = clean.clone();
        match kind {
            0 => for b in &mut bad[at..end] { *b ^= junk | 1 },
            1 => { bad.drain(at..end); }
            _ => { for _ in 0..len { bad.insert(at, junk); } }
        }
        let (got, _) = decode_all(&bad);
        let ok: std::vec::Vec<u32> = got.iter().filter_map(|r| r.as_ref().ok().map(|d| d.link_seq)).collect();
        // Frames entirely before the damage, or starting after it (plus the
        // one the damage runs into), must all come through.
        let mut start = 0;
        let mut want = std::vec::Vec::new();
        for (k, &e) in ends.iter().enumerate() {
            let untouched = e <= at || (kind != 2 && start > end) || (kind == 2 && start > at);
            if untouched { want.push(k as u32); }
            start = e;
        }
        for k in &want {
            prop_assert!(ok.contains(k), "frame {} lost: got {:?}", k, ok);
        }
        for (k, d) in got.iter().flatten().enumerate() {
            // Whatever decodes is a frame that was sent, unchanged.
            prop_assert_eq!(&d.body, &frames[d.link_seq as usize], "frame {}", k);
        }
        prop_assert!(ok.windows(2).all(|w| w[0] < w[1]));
    }
}

fn pipeline() -> Pipeline<4> {
    Pipeline::new(
        PipelineConfig::default(),
        Method::Adaptive(AdaptiveConfig::default()),
    )
    .unwrap()
}

fn command_bytes(id: u8, op: Op) -> std::vec::Vec<u8> {
    let mut buf = [0u8; MAX_FRAME];
    let n = encode(0, &Command { id, op }, &mut buf).unwrap();
    buf[..n].to_vec()
}

/// A UART that takes every byte the port sends.
struct Tx(std::vec::Vec<u8>);

impl embedded_hal_nb::serial::ErrorType for Tx {
    type Error = core::convert::Infallible;
}

impl embedded_hal_nb::serial::Write<u8> for Tx {
    fn write(&mut self, b: u8) -> embedded_hal_nb::nb::Result<(), Self::Error> {
        self.0.push(b);
        Ok(())
    }
    fn flush(&mut self) -> embedded_hal_nb::nb::Result<(), Self::Error> {
        Ok(())
    }
}

/// Feed `bytes` to the port as received, then decode what it sent.
fn exchange(
    port: &mut RingPort<1024>,
    pipe: &mut impl super::port::Array,
    bytes: &[u8],
) -> std::vec::Vec<Frame> {
    struct Rx<'a>(&'a [u8]);
    impl embedded_hal_nb::serial::ErrorType for Rx<'_> {
        type Error = core::convert::Infallible;
    }
    impl embedded_hal_nb::serial::Read<u8> for Rx<'_> {
        fn read(&mut self) -> embedded_hal_nb::nb::Result<u8, Self::Error> {
            let (&b, rest) = self
                .0
                .split_first()
                .ok_or(embedded_hal_nb::nb::Error::WouldBlock)?;
            self.0 = rest;
            Ok(b)
        }
    }
    let mut rx = Rx(bytes);
    while !rx.0.is_empty() {
        port.receive(&mut rx, pipe);
    }
    let mut tx = Tx(std::vec::Vec::new());
    port.drain(&mut tx);
    decode_all(&tx.0)
        .0
        .into_iter()
        .map(|r| r.unwrap().body)
        .collect()
}

#[test]
fn every_command_is_acknowledged_or_rejected_with_its_reason() {
    let mut pipe = pipeline();
    let mut port = RingPort::<1024>::new(Settings::default(), crate::app::BOARD_FRAME_PATH);
    let cases = [
        (Op::SetDivider(10), Ok(())),
        (Op::SetDivider(0), Err(Reject::OutOfRange)),
        (Op::SetDivider(1001), Err(Reject::OutOfRange)),
        (Op::SetMode(Mode::Raw), Ok(())),
        (Op::SetMethod(FusionMethod::Mean), Ok(())),
        (Op::SetStatusEvery(50), Err(Reject::OutOfRange)),
        (Op::SetStatusEvery(0), Ok(())),
        (Op::RequestStatus, Ok(())),
        (
            Op::SetCompensation(Compensation::Horizon(MAX_HORIZON_US + 1)),
            Err(Reject::OutOfRange),
        ),
        (Op::SetCompensation(Compensation::Horizon(3000)), Ok(())),
        (
            Op::SetPathTrim(MAX_PATH_TRIM_US + 1),
            Err(Reject::OutOfRange),
        ),
        (
            Op::SetPathTrim(-MAX_PATH_TRIM_US - 1),
            Err(Reject::OutOfRange),
        ),
        (Op::SetPathTrim(-354), Ok(())),
    ];
    for (id, (op, want)) in cases.iter().enumerate() {
        let got = exchange(&mut port, &mut pipe, &command_bytes(id as u8, *op));
        assert_eq!(
            got,
            [Frame::Ack(Ack {
                id: Some(id as u8),
                result: *want
            })],
            "{op:?}"
        );
    }
    let s = port.settings();
    assert_eq!(
        (
            s.divider,
            s.mode,
            s.method,
            s.status_every,
            s.compensation,
            s.path_trim_us
        ),
        (
            10,
            Mode::Raw,
            FusionMethod::Mean,
            0,
            Compensation::Horizon(3000),
            -354
        )
    );
    assert_eq!(pipe.fusion().method(), Method::Mean);
    assert!(port.status_due(1), "requested");
    assert!(!port.status_due(2), "request cleared, periodic off");
    let c = port.counters();
    assert_eq!((c.accepted, c.rejected), (7, 6));
}

#[test]
fn a_damaged_command_changes_nothing_and_is_rejected() {
    let mut pipe = pipeline();
    let mut port = RingPort::<1024>::new(Settings::default(), crate::app::BOARD_FRAME_PATH);
    let before = port.settings();
    let good = command_bytes(3, Op::SetDivider(5));
    // Every single-byte corruption of the frame body.
    for i in 0..good.len() - 1 {
        let mut b = good.clone();
        b[i] ^= 0x40;
        let got = exchange(&mut port, &mut pipe, &b);
        assert!(!got.is_empty());
        for f in got {
            let Frame::Ack(a) = f else { panic!("{f:?}") };
            assert!(a.result.is_err(), "byte {i}: {a:?}");
        }
        assert_eq!(port.settings(), before);
    }
    // A well-formed frame that is not a command, and one too long.
    let mut buf = [0u8; MAX_FRAME];
    let n = encode(0, &big_status(2), &mut buf).unwrap();
    let got = exchange(&mut port, &mut pipe, &buf[..n]);
    assert!(
        matches!(
            got[..],
            [Frame::Ack(Ack {
                id: None,
                result: Err(Reject::TooLong | Reject::Malformed)
            })]
        ),
        "{got:?}"
    );
    assert_eq!(port.settings(), before);
}

#[test]
fn a_full_queue_drops_whole_frames_and_the_gap_shows() {
    let mut port = RingPort::<100>::new(Settings::default(), crate::app::BOARD_FRAME_PATH);
    let f = big_sample(5);
    assert!(port.send(&f));
    assert!(!port.send(&f), "no room for a second");
    assert_eq!(port.counters().dropped, 1);
    let mut tx = Tx(std::vec::Vec::new());
    port.drain(&mut tx);
    assert!(port.send(&f));
    port.drain(&mut tx);
    let (got, _) = decode_all(&tx.0);
    let seqs: std::vec::Vec<u32> = got.iter().map(|r| r.as_ref().unwrap().link_seq).collect();
    assert_eq!(
        seqs,
        [0, 2],
        "link sequence 1 was dropped and shows as a gap"
    );
}

/// An array that is not the pipeline: two gyros, one method it refuses.
struct Fixture {
    method: FusionMethod,
}

impl super::port::Array for Fixture {
    fn flags(&self, i: usize) -> u8 {
        [0b1, 0b100][i]
    }
    fn gyros(&self) -> usize {
        2
    }
    fn gyro_status(&self, i: usize) -> GyroStatus {
        GyroStatus {
            flags: self.flags(i),
            reads: 10 * i as u32 + 1,
            errors: 0,
            excluded: 0,
            restarts: 0,
            restarted: 0,
            scale_ppm: [0; 3],
            bias_mdps: [0; 3],
            clock: ClockSource::Polled,
            clock_ppm: 0,
            late: 0,
            fifo: FifoAnomalies::default(),
        }
    }
    fn shared_errors(&self) -> u8 {
        0b010
    }
    fn calibrated(&self) -> bool {
        false
    }
    fn overruns(&self) -> u32 {
        7
    }
    fn start(&self, _: usize) -> (Start, Option<f32>) {
        (Start::Passed, Some(25.0))
    }
    fn set_method(&mut self, method: FusionMethod) -> Result<(), Reject> {
        if method == FusionMethod::Zhang {
            return Err(Reject::Refused);
        }
        self.method = method;
        Ok(())
    }
}

/// The port states what its array says and hands it the method, whatever
/// the array is: a method the array refuses is acknowledged as refused and
/// leaves the settings as they were.
#[test]
fn the_port_speaks_for_any_array() {
    let mut array = Fixture {
        method: FusionMethod::Adaptive,
    };
    let mut port = RingPort::<1024>::new(Settings::default(), crate::app::BOARD_FRAME_PATH);
    let before = port.settings();
    let mut commands = command_bytes(1, Op::SetMethod(FusionMethod::Zhang));
    commands.extend(command_bytes(2, Op::SetMethod(FusionMethod::Mean)));
    let acks: std::vec::Vec<_> = exchange(&mut port, &mut array, &commands)
        .into_iter()
        .filter_map(|f| match f {
            Frame::Ack(a) => Some(a),
            _ => None,
        })
        .collect();
    assert_eq!(
        acks,
        [
            Ack {
                id: Some(1),
                result: Err(Reject::Refused)
            },
            Ack {
                id: Some(2),
                result: Ok(())
            }
        ]
    );
    assert_eq!(array.method, FusionMethod::Mean);
    assert_eq!(port.settings().method, FusionMethod::Mean);
    assert_eq!(port.settings().divider, before.divider);
    let Frame::Status(st) = port.status(&array, 5, 5_000, [1, 16, 256], 1000, 0, &[]) else {
        panic!("a status frame");
    };
    assert_eq!(st.gyros.len(), 2);
    assert_eq!((st.gyros[0].flags, st.gyros[1].reads), (0b1, 11));
    assert_eq!(st.overruns, 7);
}

/// What the reading end of the board's queue holds, taken whole (both
/// contiguous runs when it wraps).
fn take_all(q: &super::ring::TxConsumer<600>, out: &mut std::vec::Vec<u8>) {
    while let Ok(run) = q.read() {
        out.extend_from_slice(&run);
        let n = run.len();
        run.release(n);
    }
}

/// The board's queue (`bbqueue`'s bip buffer, read where the port wrote
/// the frames) sends the bytes a port's own ring sends, across the
/// buffer's end many times; behind a reader that falls back it drops
/// whole frames only, each a gap in the link sequence.
#[test]
fn the_boards_queue_sends_what_a_ring_sends() {
    use super::port::Port;
    use super::ring::TxBuffer;
    let buf: &'static TxBuffer<600> = std::boxed::Box::leak(std::boxed::Box::new(TxBuffer::new()));
    let mut board = Port::with_queue(
        buf.stream_producer(),
        Settings::default(),
        crate::app::BOARD_FRAME_PATH,
    );
    let reader = buf.stream_consumer();
    let mut ring = RingPort::<600>::new(Settings::default(), crate::app::BOARD_FRAME_PATH);
    let (mut from_board, mut from_ring) = (std::vec::Vec::new(), Tx(std::vec::Vec::new()));
    // A reader that keeps up: the same bytes, frame sizes varied so that
    // frames meet the buffer's end at many offsets.
    for k in 0..200 {
        let f = big_sample(k % 5 + 1);
        assert!(board.send(&f) && ring.send(&f), "frame {k}");
        if k % 3 == 2 {
            take_all(&reader, &mut from_board);
            ring.drain(&mut from_ring);
        }
    }
    take_all(&reader, &mut from_board);
    ring.drain(&mut from_ring);
    assert_eq!(from_board, from_ring.0);
    assert_eq!(decode_all(&from_board).0.len(), 200);
    // A reader that takes a frame's worth every other frame: the queue
    // fills, whole frames are dropped, what is sent decodes.
    let f = big_sample(5);
    let size = {
        let mut one = Tx(std::vec::Vec::new());
        let mut p = RingPort::<600>::new(Settings::default(), crate::app::BOARD_FRAME_PATH);
        p.send(&f);
        p.drain(&mut one);
        one.0.len()
    };
    let mut sent = std::vec::Vec::new();
    for k in 0..300 {
        board.send(&f);
        if k % 2 == 0 {
            if let Ok(run) = reader.read() {
                let n = run.len().min(size);
                sent.extend_from_slice(&run[..n]);
                run.release(n);
            }
        }
    }
    take_all(&reader, &mut sent);
    let c = board.counters();
    assert!(c.dropped > 50, "the reader must fall back: {c:?}");
    let (got, _) = decode_all(&sent);
    let seqs: std::vec::Vec<u32> = got.iter().map(|r| r.as_ref().unwrap().link_seq).collect();
    // Link sequence 200 on (the first 200 frames above): every frame
    // either arrived whole or was counted dropped.
    assert_eq!(seqs.len() as u32 + c.dropped, 300);
    assert_eq!(seqs.len() as u32, c.sent - 200);
    assert!(seqs.first().is_some_and(|&s| s >= 200));
    assert!(seqs.windows(2).all(|w| w[0] < w[1]));
}

/// The two worked examples of `docs/link.md`, byte for byte.
#[test]
fn the_specification_examples_are_what_the_code_sends() {
    let mut buf = [0u8; MAX_FRAME];
    let n = encode(
        0,
        &Command {
            id: 7,
            op: Op::RequestStatus,
        },
        &mut buf,
    )
    .unwrap();
    assert_eq!(
        buf[..n],
        [0x02, 0x08, 0x01, 0x01, 0x01, 0x05, 0x07, 0x04, 0x70, 0xbb, 0x00]
    );
    // The store commands, as the C library's test has them.
    for (op, crc) in [
        (Op::SaveSettings, [0x32, 0x9b]),
        (Op::FactoryReset, [0x13, 0x8b]),
    ] {
        let n = encode(0, &Command { id: 7, op }, &mut buf).unwrap();
        let code = if op == Op::SaveSettings { 0x06 } else { 0x07 };
        assert_eq!(
            buf[..n],
            [0x02, 0x08, 0x01, 0x01, 0x01, 0x05, 0x07, code, crc[0], crc[1], 0x00]
        );
    }
    let n = encode(
        0,
        &Command {
            id: 7,
            op: Op::SyncTime(0x1234_5678_9ABC),
        },
        &mut buf,
    )
    .unwrap();
    assert_eq!(
        buf[..n],
        [
            0x02, 0x08, 0x01, 0x01, 0x01, 0x0c, 0x07, 0x09, 0xbc, 0xb5, 0xe2, 0xb3, 0xc5, 0xc6,
            0x04, 0xe2, 0x96, 0x00
        ]
    );
    let n = encode(
        0,
        &Command {
            id: 7,
            op: Op::SetAngle(true),
        },
        &mut buf,
    )
    .unwrap();
    assert_eq!(
        buf[..n],
        [0x02, 0x08, 0x01, 0x01, 0x01, 0x06, 0x07, 0x08, 0x01, 0xfc, 0x33, 0x00]
    );
    let n = encode(
        5,
        &Frame::Ack(Ack {
            id: Some(7),
            result: Err(Reject::OutOfRange),
        }),
        &mut buf,
    )
    .unwrap();
    assert_eq!(
        buf[..n],
        [0x03, 0x08, 0x05, 0x01, 0x01, 0x08, 0x03, 0x01, 0x07, 0x01, 0x04, 0xfd, 0xb2, 0x00]
    );
    // The path trim: an i16 as a zigzag varint (+354 → 708 → c4 05).
    let n = encode(
        0,
        &Command {
            id: 7,
            op: Op::SetPathTrim(354),
        },
        &mut buf,
    )
    .unwrap();
    assert_eq!(
        buf[..n],
        [0x02, 0x08, 0x01, 0x01, 0x01, 0x07, 0x07, 0x0b, 0xc4, 0x05, 0x64, 0x1a, 0x00]
    );
}

/// The output of one sample with every axis fused at `rate` and the chips'
/// delay `age_us`.
fn output(seq: u32, rate: [f32; 3], age_us: u32) -> crate::pipeline::Output<4> {
    use crate::algo::fusion::Fused;
    crate::pipeline::Output {
        seq,
        rate_dps: [rate; 4],
        delay_us: [age_us; 4],
        offered: [0b1111; 3],
        fused: rate.map(|r| {
            Some(Fused {
                rate_dps: r,
                weights: [0.25; 4],
                rejected: 0,
                fallback: false,
            })
        }),
        noise_probe_dps: [None; 3],
        health_changed: 0,
    }
}

/// The sample frames `port` sends for `outs`.
fn samples(
    port: &mut RingPort<1024>,
    outs: &[crate::pipeline::Output<4>],
) -> std::vec::Vec<Sample> {
    let pipe = pipeline();
    let mut got = std::vec::Vec::new();
    for (k, o) in outs.iter().enumerate() {
        port.publish(o, 1_000 * k as u64, &pipe, &());
        for f in exchange(port, &mut pipeline(), &[]) {
            if let Frame::Sample(s) = f {
                got.push(s);
            }
        }
    }
    got
}

#[test]
fn compensated_frames_state_the_instant_their_rates_are_predicted_to() {
    // A rate rising 2 °/s per ms on x, falling 1 on z, measured 2 ms late.
    let ramp = |k: u32| [2.0 * k as f32, 5.0, -(k as f32)];
    let outs: std::vec::Vec<_> = (0..10).map(|k| output(k, ramp(k), 2000)).collect();
    let mut port = RingPort::<1024>::new(Settings::default(), crate::app::BOARD_FRAME_PATH);
    let got = samples(&mut port, &outs);
    assert_eq!(got.len(), 10);
    let d = port.horizon_us().expect("on by default");
    // The frame's end at 6 Mbaud: the SPI reads and the loop's time, then
    // the largest sample frame, 10 bits a byte.
    assert_eq!(d, 170 + 135);
    for (k, s) in got.iter().enumerate() {
        if k + 1 < super::port::PREDICT_K {
            // Not enough samples to fit yet: the measured rates, unstated.
            assert_eq!(s.predicted_us, None);
            assert_eq!(s.rate_dps, ramp(k as u32));
            continue;
        }
        assert_eq!(s.predicted_us, Some(d));
        // The ramp at t_us + d: 2 ms of age and d µs past t_us.
        let ahead = (2000.0 + f32::from(d)) / 1000.0;
        let want = [2.0 * (k as f32 + ahead), 5.0, -(k as f32 + ahead)];
        for a in 0..3 {
            assert!(
                (s.rate_dps[a] - want[a]).abs() < 1e-3,
                "{k}: {:?} vs {want:?}",
                s.rate_dps
            );
        }
    }
    // Off: the measured rates. A missed sample starts the fit again.
    let mut port = RingPort::<1024>::new(
        Settings {
            compensation: Compensation::Off,
            ..Settings::default()
        },
        crate::app::BOARD_FRAME_PATH,
    );
    assert!(samples(&mut port, &outs)
        .iter()
        .all(|s| s.predicted_us.is_none()));
    let mut port = RingPort::<1024>::new(Settings::default(), crate::app::BOARD_FRAME_PATH);
    let gap = [
        output(0, ramp(0), 2000),
        output(1, ramp(1), 2000),
        output(2, ramp(2), 2000),
        output(5, ramp(5), 2000),
    ];
    let got = samples(&mut port, &gap);
    assert_eq!(
        got.iter()
            .map(|s| s.predicted_us.is_some())
            .collect::<std::vec::Vec<_>>(),
        [false, false, true, false]
    );
}

#[test]
fn the_horizon_follows_the_core_clock() {
    use super::msg::Compensation;
    use super::port::FramePath;
    let horizon = |path: FramePath| {
        let mut port = RingPort::<512>::new(
            Settings {
                compensation: Compensation::ToFrame,
                ..Settings::default()
            },
            path,
        );
        port.set_timing(super::BAUD, 1000);
        port.horizon_us().unwrap()
    };
    let board = crate::app::BOARD_FRAME_PATH;
    let at_168 = horizon(board);
    assert_eq!(
        horizon(FramePath {
            core_hz: 168_000_000,
            ..board
        }),
        at_168
    );
    // The internal oscillator alone: the frame path's 10 000 instructions
    // take 625 µs, not 60.
    assert_eq!(
        horizon(FramePath {
            core_hz: 16_000_000,
            ..board
        }),
        at_168 + 625 - 60
    );
}

#[test]
fn a_store_command_is_acknowledged_once_the_store_has_done_it() {
    use super::port::StoreRequest;
    let ack = |id, result| {
        Frame::Ack(Ack {
            id: Some(id),
            result,
        })
    };
    let mut pipe = pipeline();
    let mut port = RingPort::<1024>::new(Settings::default(), crate::app::BOARD_FRAME_PATH);
    // A build without a store refuses, and changes nothing.
    let got = exchange(&mut port, &mut pipe, &command_bytes(1, Op::SaveSettings));
    assert_eq!(got, [ack(1, Err(Reject::Refused))]);
    assert_eq!(port.store_request(), None);

    port.set_store_state(StoreState::Defaults);
    let mut bytes = command_bytes(2, Op::SetDivider(4));
    bytes.extend(command_bytes(3, Op::SaveSettings));
    // A second while the first is under way is refused; other commands
    // still go through.
    bytes.extend(command_bytes(4, Op::FactoryReset));
    bytes.extend(command_bytes(5, Op::SetMode(Mode::Raw)));
    let got = exchange(&mut port, &mut pipe, &bytes);
    assert_eq!(
        got,
        [ack(2, Ok(())), ack(4, Err(Reject::Refused)), ack(5, Ok(()))],
        "no acknowledgement for the save before it is done"
    );
    let saved = Settings {
        divider: 4,
        ..Settings::default()
    };
    assert_eq!(port.store_request(), Some(StoreRequest::Save(saved)));
    port.store_done(Ok(()), StoreState::Stored);
    assert_eq!(port.store_request(), None);
    let got = exchange(&mut port, &mut pipe, &[]);
    assert_eq!(got, [ack(3, Ok(()))]);

    // A factory reset: the defaults at once, the erase acknowledged after.
    let got = exchange(&mut port, &mut pipe, &command_bytes(6, Op::FactoryReset));
    assert!(got.is_empty());
    assert_eq!(port.settings(), Settings::default());
    assert_eq!(port.store_request(), Some(StoreRequest::Clear));
    port.store_done(Err(Reject::Storage), StoreState::Corrupt);
    let got = exchange(&mut port, &mut pipe, &[]);
    assert_eq!(got, [ack(6, Err(Reject::Storage))]);
    let counters = port.counters();
    assert_eq!((counters.accepted, counters.rejected), (3, 3));
}

#[test]
fn the_angles_add_up_to_the_integrated_rate_across_skipped_and_lost_frames() {
    // 10 s: a 1 Hz, 100 °/s sway on x, a 300 °/s turn on y, a slow drift on
    // z; the chips' delay changing; samples 4 000–4 002 missed; one frame
    // in a sample frame every third sample, and every 50th frame lost on
    // the way.
    let rate = |k: u32| {
        let t = f64::from(k) * 1e-3;
        [
            (100.0 * (2.0 * std::f64::consts::PI * t).sin()) as f32,
            300.0,
            (0.01 + 1e-4 * f64::from(k)) as f32,
        ]
    };
    let mut port = RingPort::<1024>::new(
        Settings {
            divider: 3,
            angle: true,
            ..Settings::default()
        },
        crate::app::BOARD_FRAME_PATH,
    );
    let pipe = pipeline();
    let mut reference = [0.0f64; 3];
    let mut last: Option<(u64, [f32; 3])> = None;
    let mut got = std::vec::Vec::new();
    for k in 0..10_000u32 {
        if (4_000..4_003).contains(&k) {
            continue;
        }
        let age = 1_500 + (k % 7) * 10;
        let t_us = 1_000 * u64::from(k) + 1_700;
        port.publish(&output(k, rate(k), age), t_us, &pipe, &());
        let at = t_us - u64::from(age);
        if let Some((t0, r0)) = last {
            for a in 0..3 {
                reference[a] +=
                    0.5 * (f64::from(r0[a]) + f64::from(rate(k)[a])) * (at - t0) as f64 * 1e-6;
            }
        }
        last = Some((at, rate(k)));
        for f in exchange(&mut port, &mut pipeline(), &[]) {
            if let Frame::Sample(s) = f {
                got.push((s.seq, s.angle.unwrap().turns32(), reference));
            }
        }
    }
    let kept: std::vec::Vec<_> = got
        .iter()
        .enumerate()
        .filter(|(i, _)| i % 50 != 49)
        .map(|(_, g)| g)
        .collect();
    assert!(kept.len() > 3_000);
    let unit = 360.0 / 4_294_967_296.0;
    let mut sum = [0.0f64; 3];
    let mut worst = 0.0f64;
    for w in kept.windows(2) {
        let ((_, a0, _), (_, a1, r1)) = (w[0], w[1]);
        for a in 0..3 {
            sum[a] += f64::from(a1[a].wrapping_sub(a0[a]) as i32) * unit;
            let want = r1[a] - kept[0].2[a];
            worst = worst.max((sum[a] - want).abs());
        }
    }
    println!("worst angle error over 10 s: {worst:.2e} deg");
    assert!(worst < 2e-5, "{worst} deg");
}

#[test]
fn sync_time_messages_give_the_controllers_clock_and_a_stopped_pulse_is_said() {
    let mut pipe = pipeline();
    let mut port = RingPort::<1024>::new(Settings::default(), crate::app::BOARD_FRAME_PATH);
    let ctrl = |b: u64| 9_000_000_000 + b + b / 20_000; // 50 ppm fast
    let mut syncs = std::vec::Vec::new();
    for k in 1..=5u64 {
        let b = k * 1_000_000;
        port.sync_pulse(b);
        for f in exchange(
            &mut port,
            &mut pipe,
            &command_bytes(k as u8, Op::SyncTime(ctrl(b))),
        ) {
            match f {
                Frame::Ack(a) => assert_eq!(a.result, Ok(())),
                Frame::Sync(s) => syncs.push(s),
                other => panic!("{other:?}"),
            }
        }
    }
    let states: std::vec::Vec<_> = syncs.iter().map(|s| s.state).collect();
    use super::sync::SyncState::*;
    assert_eq!(states, [Acquiring, Acquiring, Locked, Locked, Locked]);
    let last = syncs.last().unwrap();
    assert_eq!((last.board_us, last.ctrl_us), (5_000_000, ctrl(5_000_000)));
    assert!((last.ppm - 50.0).abs() < 0.01, "{}", last.ppm);
    assert_eq!(port.sync().to_ctrl(5_500_000), Some(ctrl(5_500_000)));
    // No more pulses: the sample frames' path says it once, within three
    // periods.
    let pipe = pipeline();
    let mut lost_at = None;
    for ms in 5_001..10_000u64 {
        port.publish(&output(ms as u32, [0.0; 3], 0), ms * 1_000, &pipe, &());
        for f in exchange(&mut port, &mut pipeline(), &[]) {
            if let Frame::Sync(s) = f {
                assert_eq!(s.state, Lost);
                assert!(lost_at.replace(ms).is_none(), "said twice");
            }
        }
    }
    let lost_at = lost_at.expect("never said");
    assert!((8_000..=8_001).contains(&lost_at), "{lost_at}");
    assert_eq!(port.sync().to_ctrl(9_000_000), None);
}

#[test]
fn the_info_frame_names_the_board_the_build_and_each_chip() {
    use crate::drivers::{Gyro, ReadFault, Reading, Restart};
    use crate::link::msg::{Part, Start};
    struct Chip(Part, u16);
    impl Gyro for Chip {
        fn read(&mut self) -> Result<Reading, ReadFault> {
            Err(ReadFault::BadResponse)
        }
        fn restart(&mut self, _: u8) -> Result<Restart, ReadFault> {
            Ok(Restart::Done)
        }
        fn identity(&self) -> (Part, u16) {
            (self.0, self.1)
        }
    }
    let mut pipe = pipeline();
    pipe.set_start(0, Start::Passed);
    pipe.set_start(2, Start::SelfTestFailed);
    pipe.mark_init_failed(2);
    pipe.mark_init_failed(3);
    let mut port = RingPort::<1024>::new(Settings::default(), crate::app::BOARD_FRAME_PATH);
    port.set_uid([7; 12]);
    // Due half way between status frames, and on request.
    assert!(!port.info_due(0) && port.info_due(500) && !port.info_due(501));
    exchange(&mut port, &mut pipe, &command_bytes(1, Op::RequestInfo));
    assert!(port.info_due(501) && !port.info_due(502));
    let (mut a, mut b, mut c, mut d) = (
        Chip(Part::Icm42688P, 0x47),
        Chip(Part::Icm42688P, 0x47),
        Chip(Part::Icm42688P, 0x12),
        Chip(Part::Adxrs453, 0x5201),
    );
    let gyros: [&mut dyn Gyro; 4] = [&mut a, &mut b, &mut c, &mut d];
    let Frame::Info(i) = port.info(&pipe, &gyros) else {
        panic!("not an info frame")
    };
    assert_eq!(i.uid, [7; 12]);
    assert_eq!(i.firmware, super::port::FIRMWARE);
    let starts: std::vec::Vec<_> = i.chips.iter().map(|c| (c.part, c.id, c.start)).collect();
    assert_eq!(
        starts,
        [
            (Part::Icm42688P, 0x47, Start::Passed),
            (Part::Icm42688P, 0x47, Start::Unknown),
            (Part::Icm42688P, 0x12, Start::SelfTestFailed),
            (Part::Adxrs453, 0x5201, Start::InitFailed),
        ]
    );
    // It fits beside a sample frame in any period.
    let n = wire_len(&Frame::Info(i));
    println!("info frame {n} B");
    assert!(n + wire_len(&big_sample(4)) <= 600);
}

#[test]
fn a_command_is_checked_for_its_own_value_not_the_ports_others() {
    // The demo's stress run builds its port with a status frame every
    // sample, a period no command may set: other commands still apply.
    let mut pipe = pipeline();
    let mut port = RingPort::<1024>::new(
        Settings {
            status_every: 1,
            ..Settings::default()
        },
        crate::app::BOARD_FRAME_PATH,
    );
    let mut bytes = command_bytes(0, Op::SetDivider(2));
    bytes.extend(command_bytes(1, Op::SetStatusEvery(1)));
    let got = exchange(&mut port, &mut pipe, &bytes);
    let results: std::vec::Vec<_> = got
        .iter()
        .filter_map(|f| match f {
            Frame::Ack(a) => Some(a.result),
            _ => None,
        })
        .collect();
    assert_eq!(results, [Ok(()), Err(Reject::OutOfRange)]);
    assert_eq!(port.settings().divider, 2);
}
