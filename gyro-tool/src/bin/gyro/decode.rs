//! `gyro decode`: one kind of frame of a recording as CSV.

use std::io::Write;
use std::path::PathBuf;

use clap::ValueEnum;
use gyro_array::link::msg::Frame;
use gyro_tool::{read_recording, Res};

#[derive(clap::Args)]
pub struct Args {
    /// The recording.
    file: PathBuf,
    /// Which frames.
    #[arg(long, value_enum, default_value = "samples")]
    what: What,
    /// The CSV file (standard output if absent).
    #[arg(short, long)]
    out: Option<PathBuf>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum What {
    Samples,
    Noise,
    Raw,
    Status,
    /// The controller's clock as the board tracked it.
    Sync,
}

/// The first three CSV columns of a sample or raw frame.
fn lead(link_seq: u32, seq: u32, t_us: u64) -> Vec<String> {
    vec![link_seq.to_string(), seq.to_string(), t_us.to_string()]
}

/// `gyro decode`: one kind of frame of a recording as CSV.
pub fn run(a: Args) -> Res<bool> {
    let Args { file, what, out } = a;
    let file = file.as_path();
    let (frames, dec) = read_recording(file)?;
    let sink: Box<dyn Write> = match &out {
        Some(p) => Box::new(std::fs::File::create(p).map_err(|e| format!("{}: {e}", p.display()))?),
        None => Box::new(std::io::stdout().lock()),
    };
    let mut w = csv::Writer::from_writer(sink);
    let mut header_done = false;
    for d in frames.iter().flatten() {
        match (&d.body, what) {
            (Frame::Sample(s), What::Samples) => {
                if !header_done {
                    let mut h: Vec<String> = [
                        "link_seq",
                        "seq",
                        "t_us",
                        "age_x_us",
                        "age_y_us",
                        "age_z_us",
                        "predicted_us",
                        "x_dps",
                        "y_dps",
                        "z_dps",
                        "valid",
                        "degraded",
                        "used_x",
                        "used_y",
                        "used_z",
                    ]
                    .map(String::from)
                    .to_vec();
                    h.extend((0..s.health.len()).map(|i| format!("flags_{i}")));
                    h.extend(["angle_x", "angle_y", "angle_z"].map(String::from));
                    w.write_record(&h)?;
                    header_done = true;
                }
                let mut r = lead(d.link_seq, s.seq, s.t_us);
                r.extend(s.age_us.iter().map(|v| v.to_string()));
                r.push(s.predicted_us.map_or(String::new(), |v| v.to_string()));
                r.extend(s.rate_dps.iter().map(|v| v.to_string()));
                r.extend([s.valid, s.degraded].iter().map(|v| v.to_string()));
                r.extend(s.used.iter().map(|v| v.to_string()));
                r.extend(s.health.iter().map(|v| v.to_string()));
                // The integrated angle, 2⁻³² turn (empty where not sent).
                match s.angle {
                    Some(a) => r.extend(a.turns32().map(|v| v.to_string())),
                    None => r.extend(["", "", ""].map(String::from)),
                }
                w.write_record(&r)?;
            }
            (Frame::Sample(s), What::Noise) => {
                let Some(n) = s.noise else { continue };
                if !header_done {
                    w.write_record([
                        "frame_seq",
                        "axis",
                        "describes_seq",
                        "window",
                        "bridged",
                        "sigma0_dps",
                        "sigma1_dps",
                        "sigma2_dps",
                    ])?;
                    header_done = true;
                }
                let mut r = vec![
                    s.seq.to_string(),
                    n.axis.to_string(),
                    n.seq.to_string(),
                    n.len.to_string(),
                    n.bridged.to_string(),
                ];
                r.extend(n.sigma_dps.iter().map(|v| v.to_string()));
                w.write_record(&r)?;
            }
            (Frame::Raw(s), What::Raw) => {
                if !header_done {
                    let mut h = vec!["link_seq".to_string(), "seq".into(), "t_us".into()];
                    h.extend((0..s.age_us.len()).map(|i| format!("g{i}_age_us")));
                    for i in 0..s.rate_dps.len() {
                        h.extend(["x", "y", "z"].map(|a| format!("g{i}_{a}_dps")));
                    }
                    h.extend((0..s.health.len()).map(|i| format!("flags_{i}")));
                    w.write_record(&h)?;
                    header_done = true;
                }
                let mut r = lead(d.link_seq, s.seq, s.t_us);
                r.extend(s.age_us.iter().map(|v| v.to_string()));
                for g in &s.rate_dps {
                    r.extend(g.iter().map(|v| v.to_string()));
                }
                r.extend(s.health.iter().map(|v| v.to_string()));
                w.write_record(&r)?;
            }
            (Frame::Status(s), What::Status) => {
                if !header_done {
                    let mut h: Vec<String> = [
                        "seq",
                        "t_us",
                        "mode",
                        "method",
                        "divider",
                        "overruns",
                        "sent",
                        "dropped",
                        "accepted",
                        "rejected",
                        "stack_peak",
                        "store",
                    ]
                    .map(String::from)
                    .to_vec();
                    // The online relative calibration and the clock of
                    // every gyro.
                    for i in 0..s.gyros.len() {
                        for q in ["scale_ppm", "bias_mdps"] {
                            h.extend(["x", "y", "z"].map(|a| format!("g{i}_{q}_{a}")));
                        }
                        h.extend(["clock", "clock_ppm", "late"].map(|q| format!("g{i}_{q}")));
                    }
                    w.write_record(&h)?;
                    header_done = true;
                }
                let mut r = vec![
                    s.seq.to_string(),
                    s.t_us.to_string(),
                    format!("{:?}", s.settings.mode),
                    format!("{:?}", s.settings.method),
                    s.settings.divider.to_string(),
                    s.overruns.to_string(),
                    s.link.sent.to_string(),
                    s.link.dropped.to_string(),
                    s.link.accepted.to_string(),
                    s.link.rejected.to_string(),
                    s.stack_peak.to_string(),
                    format!("{:?}", s.store),
                ];
                for g in &s.gyros {
                    r.extend(g.scale_ppm.iter().map(|v| v.to_string()));
                    r.extend(g.bias_mdps.iter().map(|v| v.to_string()));
                    r.extend([
                        format!("{:?}", g.clock),
                        g.clock_ppm.to_string(),
                        g.late.to_string(),
                    ]);
                }
                w.write_record(&r)?;
            }
            (Frame::Sync(y), What::Sync) => {
                if !header_done {
                    w.write_record([
                        "link_seq",
                        "state",
                        "board_us",
                        "ctrl_us",
                        "ppm",
                        "residual_us",
                        "dropped",
                        "unpaired",
                    ])?;
                    header_done = true;
                }
                w.write_record([
                    d.link_seq.to_string(),
                    format!("{:?}", y.state),
                    y.board_us.to_string(),
                    y.ctrl_us.to_string(),
                    y.ppm.to_string(),
                    y.residual_us.to_string(),
                    y.dropped.to_string(),
                    y.unpaired.to_string(),
                ])?;
            }
            _ => {}
        }
    }
    w.flush()?;
    drop(w);
    if !header_done {
        // A CSV without even a header is no table: say why instead, and
        // leave no empty file behind.
        if let Some(p) = &out {
            let _ = std::fs::remove_file(p);
        }
        return Err(format!(
            "{}: no {} frames in this recording ({} frames of other kinds)",
            file.display(),
            format!("{what:?}").to_lowercase(),
            frames.iter().flatten().count()
        )
        .into());
    }
    let st = dec.stats();
    if st.frames != frames.len() as u64 {
        eprintln!(
            "gyro: {} of {} frames did not decode ({} bytes dropped)",
            frames.len() as u64 - st.frames,
            frames.len(),
            st.bytes_dropped
        );
    }
    Ok(true)
}
