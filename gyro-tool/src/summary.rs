//! What a stream of link frames held: counts, gaps, acknowledgements, the
//! newest status, and a CRC-32 of the fused rates (to compare with the
//! firmware's own). Shared by `record`, `watch` and `check`.

use gyro_array::link::msg::{Ack, Frame, Noise, Sample, Status};
use gyro_array::link::wire::{DecodeStats, Decoded, FrameError};

const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// Running summary of decoded frames.
pub struct Summary {
    pub samples: u64,
    pub raws: u64,
    pub statuses: u64,
    pub acks: Vec<Ack>,
    /// Frames missing by the link sequence number.
    pub link_missing: u64,
    /// Frames whose link sequence number went backwards (a board reset).
    pub link_restarts: u64,
    /// Places where the sample sequence number skipped (beyond the divider).
    pub sample_gaps: u64,
    /// Samples missing in those gaps.
    pub samples_missing: u64,
    pub first_seq: Option<u32>,
    pub last_seq: Option<u32>,
    pub last_sample: Option<Sample>,
    pub last_status: Option<Status>,
    pub noise: Vec<(u32, Noise)>,
    last_link: Option<u32>,
    digest: crc::Digest<'static, u32>,
}

impl Default for Summary {
    fn default() -> Self {
        Self {
            samples: 0,
            raws: 0,
            statuses: 0,
            acks: Vec::new(),
            link_missing: 0,
            link_restarts: 0,
            sample_gaps: 0,
            samples_missing: 0,
            first_seq: None,
            last_seq: None,
            last_sample: None,
            last_status: None,
            noise: Vec::new(),
            last_link: None,
            digest: CRC32.digest(),
        }
    }
}

impl Summary {
    /// Account for one decoder result (errors are counted by the decoder).
    pub fn add(&mut self, r: &Result<Decoded<Frame>, FrameError>) {
        let Ok(d) = r else { return };
        if let Some(last) = self.last_link {
            let step = d.link_seq.wrapping_sub(last);
            if step == 0 || step > u32::MAX / 2 {
                self.link_restarts += 1;
            } else {
                self.link_missing += u64::from(step - 1);
            }
        }
        self.last_link = Some(d.link_seq);
        match &d.body {
            Frame::Sample(s) => {
                self.samples += 1;
                self.sample_seq(s.seq);
                for r in s.rate_dps {
                    self.digest.update(&r.to_le_bytes());
                }
                if let Some(n) = s.noise {
                    self.noise.push((s.seq, n));
                }
                self.last_sample = Some(s.clone());
            }
            Frame::Raw(r) => {
                self.raws += 1;
                self.sample_seq(r.seq);
            }
            Frame::Status(s) => {
                self.statuses += 1;
                self.last_status = Some(s.clone());
            }
            Frame::Ack(a) => self.acks.push(*a),
        }
    }

    fn sample_seq(&mut self, seq: u32) {
        let div = self
            .last_status
            .as_ref()
            .map_or(1, |s| u32::from(s.settings.divider.max(1)));
        if let Some(last) = self.last_seq {
            let step = seq.wrapping_sub(last);
            if step != div && step < u32::MAX / 2 {
                self.sample_gaps += 1;
                self.samples_missing += u64::from(step.saturating_sub(div) / div);
            }
        }
        self.first_seq.get_or_insert(seq);
        self.last_seq = Some(seq);
    }

    /// CRC-32 (ISO-HDLC) of the little-endian bytes of every sample
    /// frame's three fused rates, in order: what the QEMU demo logs.
    pub fn fused_crc32(&self) -> u32 {
        self.digest.clone().finalize()
    }

    /// A short human-readable report.
    pub fn report(&self, stats: &DecodeStats) -> String {
        let mut s = format!(
            "frames: {} decoded ({} sample, {} raw, {} status, {} ack)\n\
             wire: {} corrupt, {} too long, {} other version, {} malformed, {} bytes dropped\n\
             link: {} frames missing by sequence number, {} restarts\n\
             samples: seq {}..={}, {} gaps ({} samples missing)\n",
            stats.frames,
            self.samples,
            self.raws,
            self.statuses,
            self.acks.len(),
            stats.corrupt,
            stats.too_long,
            stats.version,
            stats.malformed,
            stats.bytes_dropped,
            self.link_missing,
            self.link_restarts,
            self.first_seq.map_or("-".into(), |v| v.to_string()),
            self.last_seq.map_or("-".into(), |v| v.to_string()),
            self.sample_gaps,
            self.samples_missing,
        );
        if self.samples > 0 {
            s += &format!("fused-rate CRC-32: {:#010x}\n", self.fused_crc32());
        }
        for (i, a) in self.acks.iter().enumerate() {
            s += &format!("ack {i}: command {:?} -> {:?}\n", a.id, a.result);
        }
        if let Some(st) = &self.last_status {
            s += &format!("last status: {}\n", status_line(st));
        }
        s
    }
}

/// One line for a status frame.
pub fn status_line(st: &Status) -> String {
    let flags: Vec<String> = st
        .gyros
        .iter()
        .map(|g| format!("{:#04x}", g.flags))
        .collect();
    // The online relative calibration on z (every gyro is on z).
    let cal: Vec<String> = st
        .gyros
        .iter()
        .map(|g| format!("{:+}ppm/{:+}m", g.scale_ppm[2], g.bias_mdps[2]))
        .collect();
    format!(
        "seq {} t {:.3} s | {:?} {:?} div {} | overruns {} | link sent {} dropped {} cmds {}/{} | stack {} B | gyro flags [{}] | z calibration [{}]",
        st.seq,
        st.t_us as f64 * 1e-6,
        st.settings.mode,
        st.settings.method,
        st.settings.divider,
        st.overruns,
        st.link.sent,
        st.link.dropped,
        st.link.accepted,
        st.link.rejected,
        st.stack_peak,
        flags.join(" "),
        cal.join(" ")
    )
}
