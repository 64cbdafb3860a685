//! The host analysis behind `gyro` (and the Python package): Allan-family
//! deviations with their confidence intervals, the IEEE 952 fit, the
//! E-DAVAR surface, fusion replay, recordings and their summaries.

pub mod analyse;
pub mod antenna;
pub mod assess;
pub mod bulk;
pub mod dataflash;
pub mod dev;
pub mod edf;
pub mod fit;
pub mod kind;
pub mod lag;
pub mod pipe;
pub mod plot;
pub mod pointing;
pub mod replay;
pub mod ros1;
pub mod ros2;
pub mod screen;
pub mod source;
pub mod stream;
pub mod summary;
pub mod surface;
pub mod table;
pub mod ulog;

/// `v` to 7 significant digits, then as short as it prints (a τ0 taken
/// from a time column is 0.00999999999999 rather than 0.01).
pub fn short(v: f64) -> f64 {
    format!("{v:.6e}").parse().unwrap_or(v)
}

use std::path::Path;

use gyro_array::link::msg::Frame;
use gyro_array::link::wire::{Decoded, Decoder, FrameError, MAX_FRAME};

/// The tool's fallible result: every error is a message for the user.
pub type Res<T> = Result<T, Box<dyn std::error::Error>>;

/// A long computation was asked to stop (its stop flag was set) and gave
/// up.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Stopped;

impl std::fmt::Display for Stopped {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("stopped")
    }
}

impl std::error::Error for Stopped {}

/// Samples between two looks at a stop flag: some milliseconds of work.
pub const STOP_EVERY: usize = 1 << 16;

/// Every decoder result of a recording, and the decoder with its counts.
pub type Recording = (Vec<Result<Decoded<Frame>, FrameError>>, Decoder<MAX_FRAME>);

/// Decode every frame of a recording; an error where not one frame
/// decodes (an empty file, a CSV, any file that is not a recording of the
/// board's link), rather than an empty recording.
pub fn read_recording(file: &Path) -> Res<Recording> {
    let bytes = std::fs::read(file).map_err(|e| format!("{}: {e}", file.display()))?;
    let mut dec = Decoder::<MAX_FRAME>::new();
    let frames: Vec<_> = bytes.iter().filter_map(|&b| dec.feed::<Frame>(b)).collect();
    if !frames.iter().any(|f| f.is_ok()) {
        return Err(format!(
            "{}: not a recording of the board's link: no frame decodes in its {} bytes ({} frames refused)",
            file.display(),
            bytes.len(),
            frames.len()
        )
        .into());
    }
    Ok((frames, dec))
}
