//! `gyro check`: the integrity of a recording.

use std::path::PathBuf;

use clap::ValueEnum;
use gyro_array::link::msg::Reject;
use gyro_tool::{read_recording, summary::Summary, Res};

#[derive(clap::Args)]
pub struct Args {
    /// The recording.
    file: PathBuf,
    /// Expect exactly this many sample frames.
    #[arg(long)]
    samples: Option<u64>,
    /// Expect at least this many sample frames.
    #[arg(long)]
    min_samples: Option<u64>,
    /// Expect this CRC-32 of the fused rates (the firmware's log).
    #[arg(long, value_parser = parse_hex)]
    fused_crc32: Option<u32>,
    /// Expect these acknowledgements, in order (ok, corrupt, too-long,
    /// version, malformed, out-of-range, refused), comma-separated.
    #[arg(long, value_delimiter = ',')]
    acks: Option<Vec<AckKind>>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum AckKind {
    Ok,
    Corrupt,
    TooLong,
    Version,
    Malformed,
    OutOfRange,
    Refused,
    Storage,
}

impl AckKind {
    fn of(r: Result<(), Reject>) -> Self {
        match r {
            Ok(()) => AckKind::Ok,
            Err(Reject::Corrupt) => AckKind::Corrupt,
            Err(Reject::TooLong) => AckKind::TooLong,
            Err(Reject::Version) => AckKind::Version,
            Err(Reject::Malformed) => AckKind::Malformed,
            Err(Reject::OutOfRange) => AckKind::OutOfRange,
            Err(Reject::Refused) => AckKind::Refused,
            Err(Reject::Storage) => AckKind::Storage,
        }
    }
}

fn parse_hex(s: &str) -> Result<u32, String> {
    u32::from_str_radix(s.trim_start_matches("0x"), 16).map_err(|e| format!("{s:?}: {e}"))
}

/// `gyro check`: a recording's frames, counts and errors against what
/// the caller expects.
pub fn run(a: Args) -> Res<bool> {
    let Args {
        file,
        samples,
        min_samples,
        fused_crc32: crc,
        acks,
    } = a;
    let file = file.as_path();
    let (frames, dec) = read_recording(file)?;
    let mut sum = Summary::default();
    for r in &frames {
        sum.add(r);
    }
    let st = dec.stats();
    print!("{}", sum.report(&st));
    let mut fails = Vec::new();
    if st.frames == 0 {
        fails.push("no frame".to_string());
    }
    if st.corrupt + st.too_long + st.version + st.malformed > 0 || st.bytes_dropped > 0 {
        fails.push("frames failed to decode".into());
    }
    if sum.link_missing > 0 || sum.link_restarts > 0 {
        fails.push("gaps in the link sequence numbers".into());
    }
    if sum.sample_gaps > 0 {
        fails.push("gaps in the sample sequence numbers".into());
    }
    if sum.duplicates > 0 {
        fails.push(format!(
            "{} sample frames repeat the previous sequence number",
            sum.duplicates
        ));
    }
    if sum.seq_back > 0 {
        fails.push(format!(
            "the sample sequence number went back {} times",
            sum.seq_back
        ));
    }
    if dec.pending() > 0 {
        // Named, not failed: a live recording stopped mid-stream (the
        // recorder's end, QEMU's) ends inside a frame too.
        println!(
            "note: the recording ends inside a frame ({} bytes after the last delimiter): its last frame is cut short and not counted",
            dec.pending()
        );
    }
    if let Some(n) = samples {
        if sum.samples != n {
            fails.push(format!("{} sample frames, expected {n}", sum.samples));
        }
    }
    if let Some(n) = min_samples {
        if sum.samples < n {
            fails.push(format!(
                "{} sample frames, expected at least {n}",
                sum.samples
            ));
        }
    }
    if let Some(c) = crc {
        if sum.fused_crc32() != c {
            fails.push(format!(
                "fused-rate CRC-32 {:#010x}, the firmware's {c:#010x}",
                sum.fused_crc32()
            ));
        }
    }
    if let Some(want) = acks {
        let got: Vec<AckKind> = sum.acks.iter().map(|a| AckKind::of(a.result)).collect();
        let ids_ok = sum
            .acks
            .iter()
            .enumerate()
            .all(|(i, a)| a.id == Some(i as u8));
        if got != want || !ids_ok {
            fails.push(format!(
                "acknowledgements {got:?}, expected {want:?} for ids 0.."
            ));
        }
    }
    for f in &fails {
        println!("FAIL: {f}");
    }
    if fails.is_empty() {
        println!("check: PASS");
    }
    Ok(fails.is_empty())
}
