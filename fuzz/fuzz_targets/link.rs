//! The output link on arbitrary bytes: the host decoder never panics,
//! counts every frame it gives up on, and whatever it accepts re-encodes
//! to a frame that decodes to the same message; the board's command
//! handling never panics, answers every frame, and never leaves a setting
//! out of range.
#![no_main]
use gyro_array::algo::fusion::{AdaptiveConfig, Method};
use gyro_array::link::msg::{Frame, Settings};
use gyro_array::link::port::RingPort;
use gyro_array::link::wire::{encode, Decoder, MAX_FRAME};
use gyro_array::pipeline::{Pipeline, PipelineConfig};
use libfuzzer_sys::fuzz_target;

struct Rx<'a>(&'a [u8]);

impl embedded_hal_nb::serial::ErrorType for Rx<'_> {
    type Error = core::convert::Infallible;
}

impl embedded_hal_nb::serial::Read<u8> for Rx<'_> {
    fn read(&mut self) -> embedded_hal_nb::nb::Result<u8, Self::Error> {
        let (&b, rest) = self.0.split_first().ok_or(embedded_hal_nb::nb::Error::WouldBlock)?;
        self.0 = rest;
        Ok(b)
    }
}

fuzz_target!(|data: &[u8]| {
    // Host side.
    let mut dec = Decoder::<MAX_FRAME>::new();
    let mut results = 0u64;
    for &b in data {
        if let Some(r) = dec.feed::<Frame>(b) {
            results += 1;
            if let Ok(d) = r {
                let mut buf = [0u8; MAX_FRAME];
                let n = encode(d.link_seq, &d.body, &mut buf).expect("a decoded frame re-encodes");
                let mut again = Decoder::<MAX_FRAME>::new();
                let back: Vec<_> = buf[..n].iter().filter_map(|&b| again.feed::<Frame>(b)).collect();
                assert_eq!(back.len(), 1);
                let back = back[0].as_ref().expect("re-encoded frame decodes");
                assert_eq!((back.link_seq, &back.body), (d.link_seq, &d.body));
            }
        }
    }
    let s = dec.stats();
    assert_eq!(results, s.frames + s.corrupt + s.too_long + s.version + s.malformed);

    // Board side: the same bytes as commands.
    let Ok(mut pipe) = Pipeline::<4>::new(
        PipelineConfig::default(),
        Method::Adaptive(AdaptiveConfig::default()),
    ) else {
        return;
    };
    let mut port = RingPort::<4096>::new(Settings::default(), gyro_array::app::BOARD_FRAME_PATH);
    let mut rx = Rx(data);
    while !rx.0.is_empty() {
        port.receive(&mut rx, &mut pipe);
    }
    let st = port.settings();
    assert!((1..=1000).contains(&st.divider));
    assert!(st.status_every == 0 || (100..=60_000).contains(&st.status_every));
    let c = port.counters();
    assert_eq!(c.sent + c.dropped, c.accepted + c.rejected, "one answer per frame");
});
