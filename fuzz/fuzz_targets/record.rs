//! The reset record decoder on arbitrary RAM contents: garbage is "no
//! record", and whatever decodes re-encodes to the same words.
#![no_main]
use gyro_array::board::record::{Record, WORDS};
use libfuzzer_sys::fuzz_target;
mod common;
use common::Bytes;

fuzz_target!(|data: &[u8]| {
    let mut b = Bytes(data);
    let w: [u32; WORDS] = core::array::from_fn(|_| b.u32());
    if let Some(r) = Record::decode(&w) {
        assert_eq!(r.encode(), w);
    }
});
