//! `gyro`: the host side of the gyro board's output link.
//!
//! - `gyro record --from SRC -o FILE`: save the byte stream (the recording
//!   is the wire format itself, so nothing is lost), with a live view.
//! - `gyro watch --from SRC`: the live view alone.
//! - `--send OP` (record, watch): commands to the board, acknowledged in
//!   the stream: `status`, `divider=N`, `status-every=N`,
//!   `mode=fused|raw`, `method=mean|zhang|adaptive`,
//!   `compensation=off|frame|MICROSECONDS` (the delay compensation: off,
//!   to the frame's last byte, or to a horizon after the sample's time),
//!   `path-trim=MICROSECONDS` (the chips' signal path measured longer
//!   than the datasheet's reading: `gyro lag`).
//! - `gyro check FILE`: integrity of a recording (no corrupt frame, no
//!   gap), optionally against the firmware's own count and CRC-32.
//! - `gyro decode FILE --what samples|noise|raw|status -o CSV`.
//! - `gyro analyse FILE`: Allan deviation of each fused axis and the
//!   E-DAVAR estimates the board sent.
//! - `gyro pointing FILE [--truth CSV] [--svg OUT]`: the recording through
//!   the reference stabilisation loop: the pointing error it adds to the
//!   ideal gyro's per axis, split into delay and noise (and, against a
//!   reference, calibration and faults).
//! - `gyro lag FILE --truth CSV`: how far the frames' rates lie behind the
//!   instants they state, per axis, against a rate table's reference: the
//!   path trim to set (docs/timing.md, the bench procedure).
//!
//! SRC is `serial:PATH[@BAUD]`, `tcp:HOST:PORT`, `unix:PATH`, `file:PATH`
//! or `-`. Protocol: `docs/link.md`.

mod allan;
mod check;
mod davar;
mod decode;
mod emulate;
mod link;
mod log_args;
mod replay;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use gyro_tool::{analyse, lag, pointing};

#[derive(Parser)]
#[command(
    name = "gyro",
    version,
    about = "Record, watch, check and analyse the gyro board's output link"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Save the link's bytes to a file, with a live view.
    Record {
        #[command(flatten)]
        link: link::LinkArgs,
        /// The recording (the raw wire bytes).
        #[arg(short, long)]
        out: PathBuf,
    },
    /// Show the link live.
    Watch {
        #[command(flatten)]
        link: link::LinkArgs,
    },
    /// Check a recording: no corrupt frame, no gap in the link or sample
    /// sequence numbers; exit 1 otherwise.
    Check(check::Args),
    /// Export one kind of frame from a recording as CSV.
    Decode(decode::Args),
    /// Allan deviation of each fused axis, and the board's E-DAVAR
    /// estimates, from a recording.
    Analyse {
        /// The recording.
        file: PathBuf,
    },
    /// A recording through the reference stabilisation loop: the pointing
    /// error its stated delay and its noise leave, per axis.
    Pointing {
        /// The recording.
        file: PathBuf,
        /// The true rate on the board's clock (CSV: t_us,x_dps,y_dps,z_dps;
        /// an emulated run's, `pointing-eval --write`): the error then
        /// splits into delay, calibration, noise and faults.
        #[arg(long)]
        truth: Option<PathBuf>,
        /// Draw the motion and the pointing error of the axis that moved
        /// most as SVG.
        #[arg(long)]
        svg: Option<PathBuf>,
    },
    /// How far the sample frames' rates lie behind the instants they
    /// state, against a reference rate on the board's clock (a rate
    /// table's): the signal path's trim to set (`--send path-trim=N`).
    Lag {
        /// The recording (made with `--send compensation=off`).
        file: PathBuf,
        /// The true rate on the board's clock (CSV: t_us,x_dps,y_dps,z_dps).
        #[arg(long)]
        truth: PathBuf,
    },
    /// Allan-family deviations of a rate log: comma-, semicolon-, tab- or
    /// blank-separated text, with a header line or without one, one column
    /// per series.
    Allan(allan::Args),
    /// Write a rate log of an emulated chip at rest (`gyro_sim::noise`), one
    /// axis: the analysis tools' test input, of any length.
    Emulate(emulate::Args),
    /// The E-DAVAR t–τ–σ surface of one column of a rate log (the board's
    /// segmented window), with σ(τ0) and the window over time.
    Davar(davar::Args),
    /// Replay the board's fusion over a multi-gyro log: one column per
    /// chip, the same axis (at most 8).
    Replay(replay::Args),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        if !gyro_tool::pipe::broken_pipe(info.payload()) {
            default_hook(info)
        }
    }));
    let r = match std::panic::catch_unwind(|| run(cli)) {
        Ok(r) => r,
        Err(p) if gyro_tool::pipe::broken_pipe(&*p) => return ExitCode::SUCCESS,
        Err(p) => std::panic::resume_unwind(p),
    };
    match r {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::FAILURE,
        // A closed pipe met through a writer: the same quiet end.
        Err(e)
            if e.downcast_ref::<std::io::Error>()
                .is_some_and(|e| e.kind() == std::io::ErrorKind::BrokenPipe) =>
        {
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("gyro: {e}");
            ExitCode::from(2)
        }
    }
}

fn run(cli: Cli) -> gyro_tool::Res<bool> {
    match cli.cmd {
        Cmd::Record { link, out } => link::stream(&link, Some(out)),
        Cmd::Watch { link } => link::stream(&link, None),
        Cmd::Check(a) => check::run(a),
        Cmd::Decode(a) => decode::run(a),
        Cmd::Analyse { file } => analyse::run(&file),
        Cmd::Pointing { file, truth, svg } => pointing::run(&file, truth.as_ref(), svg.as_ref()),
        Cmd::Lag { file, truth } => lag::run(&file, &truth),
        Cmd::Allan(a) => allan::run(a),
        Cmd::Emulate(a) => emulate::run(a),
        Cmd::Davar(a) => davar::run(a),
        Cmd::Replay(a) => replay::run(a),
    }
}
