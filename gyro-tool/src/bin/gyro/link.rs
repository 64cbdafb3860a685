//! `gyro record` and `gyro watch`: the live link, and commands to the board.

use std::io::{Read, Write};
use std::path::PathBuf;
use std::time::{Duration, Instant};

use gyro_array::link::msg::{Command, Compensation, Frame, FusionMethod, Mode, Op};
use gyro_array::link::wire::{encode, Decoded, Decoder, MAX_FRAME};
use gyro_tool::source::{self, Source};
use gyro_tool::summary::{status_line, Summary};
use gyro_tool::Res;
use indicatif::{ProgressBar, ProgressStyle};

#[derive(clap::Args)]
pub struct LinkArgs {
    /// serial:PATH[@BAUD], tcp:HOST:PORT, unix:PATH, file:PATH or -.
    #[arg(long)]
    from: Source,
    /// Commands to send once connected (repeatable).
    #[arg(long = "send", value_parser = parse_op)]
    send: Vec<Op>,
    /// Stop after this many seconds (default: at the end of the stream).
    #[arg(long)]
    seconds: Option<f64>,
    /// How long to keep trying to connect to a socket, seconds.
    #[arg(long, default_value_t = 30.0)]
    connect_timeout: f64,
    /// No live view.
    #[arg(short, long)]
    quiet: bool,
}

fn parse_op(s: &str) -> Result<Op, String> {
    let (k, v) = s.split_once('=').unwrap_or((s, ""));
    let num = |v: &str| v.parse::<u32>().map_err(|e| format!("{s:?}: {e}"));
    Ok(match (k, v) {
        ("status", "") => Op::RequestStatus,
        ("save", "") => Op::SaveSettings,
        ("info", "") => Op::RequestInfo,
        ("factory-reset", "") => Op::FactoryReset,
        ("angle", "on") => Op::SetAngle(true),
        ("angle", "off") => Op::SetAngle(false),
        // Out-of-range values are sent as they are: the board rejects them.
        ("divider", v) => Op::SetDivider(u16::try_from(num(v)?).unwrap_or(u16::MAX)),
        ("status-every", v) => Op::SetStatusEvery(num(v)?),
        ("mode", "fused") => Op::SetMode(Mode::Fused),
        ("mode", "raw") => Op::SetMode(Mode::Raw),
        ("method", "mean") => Op::SetMethod(FusionMethod::Mean),
        ("method", "zhang") => Op::SetMethod(FusionMethod::Zhang),
        ("method", "adaptive") => Op::SetMethod(FusionMethod::Adaptive),
        ("compensation", "off") => Op::SetCompensation(Compensation::Off),
        ("compensation", "frame") => Op::SetCompensation(Compensation::ToFrame),
        ("compensation", v) => {
            Op::SetCompensation(Compensation::Horizon(u16::try_from(num(v)?).unwrap_or(u16::MAX)))
        }
        ("path-trim", v) => {
            let t = v.parse::<i32>().map_err(|e| format!("{s:?}: {e}"))?;
            Op::SetPathTrim(i16::try_from(t).unwrap_or(if t < 0 { i16::MIN } else { i16::MAX }))
        }
        _ => {
            return Err(format!(
                "{s:?}: expected status, info, save, factory-reset, angle=on|off, divider=N, status-every=N, mode=fused|raw, method=mean|zhang|adaptive, compensation=off|frame|MICROSECONDS or path-trim=MICROSECONDS"
            ))
        }
    })
}

/// `record` and `watch`.
pub fn stream(args: &LinkArgs, out: Option<PathBuf>) -> Res<bool> {
    let wait = Duration::from_secs_f64(args.connect_timeout.max(0.0));
    let mut conn = source::open(&args.from, wait)?;
    let mut file = match &out {
        Some(p) => Some(std::fs::File::create(p).map_err(|e| format!("{}: {e}", p.display()))?),
        None => None,
    };
    // Commands go out once the board is heard from (a UART drops what
    // arrives before it is enabled), all in one write.
    let mut commands = Vec::new();
    for (id, op) in args.send.iter().enumerate() {
        let mut buf = [0u8; MAX_FRAME];
        let id = u8::try_from(id).map_err(|_| "at most 256 commands")?;
        let n = encode(u32::from(id), &Command { id, op: *op }, &mut buf)
            .map_err(|e| format!("{e:?}"))?;
        commands.extend_from_slice(&buf[..n]);
    }
    if !commands.is_empty() && conn.writer.is_none() {
        return Err("--send needs a serial port or a socket".into());
    }
    let bar = if args.quiet {
        ProgressBar::hidden()
    } else {
        let b = ProgressBar::new_spinner();
        b.set_style(ProgressStyle::with_template(
            "{spinner} {elapsed} {bytes} {msg}",
        )?);
        b
    };
    let deadline = args
        .seconds
        .map(|s| Instant::now() + Duration::from_secs_f64(s.max(0.0)));
    let mut dec = Decoder::<MAX_FRAME>::new();
    let mut sum = Summary::default();
    let mut buf = [0u8; 4096];
    let mut last_view = Instant::now();
    loop {
        if deadline.is_some_and(|d| Instant::now() >= d) {
            break;
        }
        let n = match conn.reader.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e.into()),
        };
        if let Some(f) = file.as_mut() {
            f.write_all(&buf[..n])?;
        }
        bar.inc(n as u64);
        for &b in &buf[..n] {
            if let Some(r) = dec.feed::<Frame>(b) {
                if let Ok(Decoded {
                    body: Frame::Status(st),
                    ..
                }) = &r
                {
                    bar.println(status_line(st));
                }
                if let Ok(Decoded {
                    body: Frame::Ack(a),
                    ..
                }) = &r
                {
                    bar.println(format!("ack: command {:?} -> {:?}", a.id, a.result));
                }
                sum.add(&r);
                if r.is_ok() && !commands.is_empty() {
                    if let Some(w) = conn.writer.as_mut() {
                        w.write_all(&commands)?;
                        w.flush()?;
                    }
                    commands.clear();
                }
            }
        }
        if last_view.elapsed() > Duration::from_millis(100) {
            last_view = Instant::now();
            let st = dec.stats();
            let rate = sum
                .last_sample
                .as_ref()
                .map(|s| {
                    format!(
                        "seq {} rate {:+8.3} {:+8.3} {:+8.3} dps",
                        s.seq, s.rate_dps[0], s.rate_dps[1], s.rate_dps[2]
                    )
                })
                .unwrap_or_default();
            bar.set_message(format!(
                "{} frames, {} corrupt, {} missing | {rate}",
                st.frames, st.corrupt, sum.link_missing
            ));
        }
    }
    bar.finish_and_clear();
    if let Some(f) = file.as_mut() {
        f.flush()?;
    }
    eprint!("{}", sum.report(&dec.stats()));
    Ok(true)
}
