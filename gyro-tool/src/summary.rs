//! What a stream of link frames held: counts, gaps, acknowledgements, the
//! newest status, and a CRC-32 of the fused rates (to compare with the
//! firmware's own). Shared by `record`, `watch` and `check`.

use gyro_array::link::msg::{Ack, ClockSource, Frame, Noise, Sample, Status};
use gyro_array::link::wire::{DecodeStats, Decoded, FrameError};

const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// The sample period of the frames a status describes, s (the board's
/// sample period times its output divider).
pub fn tau0_s(s: &Status) -> f64 {
    f64::from(s.sample_us) * 1e-6 * f64::from(s.settings.divider.max(1))
}

/// The τ of the board's noise records, samples, as its tracker sends them
/// by default (2^VIEW_TAUS): what a recording without a status frame is
/// read with.
pub const DEFAULT_NOISE_TAU: [u16; 3] = {
    let t = gyro_array::pipeline::tracker::VIEW_TAUS;
    [1 << t[0], 1 << t[1], 1 << t[2]]
};

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
    /// Sample frames that repeat the previous one's sequence number.
    pub duplicates: u64,
    /// Places where the sample sequence number went back (a board reset).
    pub seq_back: u64,
    pub first_seq: Option<u32>,
    pub last_seq: Option<u32>,
    pub last_sample: Option<Sample>,
    pub last_status: Option<Status>,
    pub noise: Vec<(u32, Noise)>,
    /// Per axis, the delay every valid sample stated (`age_us`), µs.
    pub ages_us: [Vec<u16>; 3],
    /// The horizons of the sample frames whose rates were predicted
    /// (`predicted_us`), µs, and the frames that were not.
    pub predicted_us: Vec<u16>,
    pub not_predicted: u64,
    /// Spacing of consecutive sample frames' `t_us` (where no sample is
    /// missing between them), µs.
    pub spacing_us: Vec<i64>,
    last_t_us: Option<(u32, u64)>,
    last_link: Option<u32>,
    digest: crc::Digest<'static, u32>,
    /// Sync frames, and the newest (the controller's clock).
    pub syncs: u64,
    pub last_sync: Option<gyro_array::link::msg::SyncStatus>,
    /// Board-information frames, and the newest.
    pub infos: u64,
    pub last_info: Option<gyro_array::link::msg::Info>,
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
            duplicates: 0,
            seq_back: 0,
            first_seq: None,
            last_seq: None,
            last_sample: None,
            last_status: None,
            noise: Vec::new(),
            ages_us: Default::default(),
            predicted_us: Vec::new(),
            not_predicted: 0,
            spacing_us: Vec::new(),
            last_t_us: None,
            last_link: None,
            digest: CRC32.digest(),
            syncs: 0,
            last_sync: None,
            last_info: None,
            infos: 0,
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
                for a in 0..3 {
                    if s.valid & (1 << a) != 0 {
                        self.ages_us[a].push(s.age_us[a]);
                    }
                }
                match s.predicted_us {
                    Some(d) => self.predicted_us.push(d),
                    None => self.not_predicted += 1,
                }
                if let Some((seq, t)) = self.last_t_us {
                    if s.seq.wrapping_sub(seq) == 1 {
                        self.spacing_us.push(s.t_us as i64 - t as i64);
                    }
                }
                self.last_t_us = Some((s.seq, s.t_us));
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
            Frame::Sync(s) => {
                self.syncs += 1;
                self.last_sync = Some(*s);
            }
            Frame::Info(i) => {
                self.infos += 1;
                self.last_info = Some(i.clone());
            }
        }
    }

    fn sample_seq(&mut self, seq: u32) {
        let div = self
            .last_status
            .as_ref()
            .map_or(1, |s| u32::from(s.settings.divider.max(1)));
        if let Some(last) = self.last_seq {
            let step = seq.wrapping_sub(last);
            if step == 0 {
                self.duplicates += 1;
            } else if step >= u32::MAX / 2 {
                self.seq_back += 1;
            } else if step != div {
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
            "frames: {} decoded ({} sample, {} raw, {} status, {} ack, {} sync, {} info)\n\
             wire: {} corrupt, {} too long, {} other version, {} malformed, {} bytes dropped\n\
             link: {} frames missing by sequence number, {} restarts\n\
             samples: seq {}..={}, {} gaps ({} samples missing)\n",
            stats.frames,
            self.samples,
            self.raws,
            self.statuses,
            self.acks.len(),
            self.syncs,
            self.infos,
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
            s += &self.timing_report();
        }
        for (i, a) in self.acks.iter().enumerate() {
            s += &format!("ack {i}: command {:?} -> {:?}\n", a.id, a.result);
        }
        if let Some(st) = &self.last_status {
            s += &format!("last status: {}\n", status_line(st));
        }
        if let Some(i) = &self.last_info {
            let uid: String = i.uid.iter().map(|b| format!("{b:02x}")).collect();
            let chips: Vec<String> = i
                .chips
                .iter()
                .map(|c| {
                    let t = c
                        .temp_cc
                        .map_or("-".into(), |t| format!("{:.2} C", f32::from(t) / 100.0));
                    format!("{:?} id {:#06x} {:?} {t}", c.part, c.id, c.start)
                })
                .collect();
            s += &format!(
                "board: uid {uid}, firmware {}.{}.{} build {:08x}; chips [{}]\n",
                i.firmware[0],
                i.firmware[1],
                i.firmware[2],
                i.build,
                chips.join(", ")
            );
        }
        if let Some(y) = &self.last_sync {
            s += &format!(
                "controller clock: {:?}, {:+.2} ppm, residual {:.1} us, {} sync frames ({} dropped, {} unpaired)\n",
                y.state, y.ppm, y.residual_us, self.syncs, y.dropped, y.unpaired
            );
        }
        s
    }
}

impl Summary {
    /// The delay the samples stated (the fused rate describes `t_us −
    /// age_us`), per axis: median, range and its jitter (standard
    /// deviation); and the spacing of the frames' `t_us`.
    pub fn timing_report(&self) -> String {
        let mut s = String::from("stated delay (age_us):");
        for (a, v) in self.ages_us.iter().enumerate() {
            let name = ["x", "y", "z"][a];
            if v.is_empty() {
                s += &format!(" {name} -;");
                continue;
            }
            let mut sorted = v.clone();
            sorted.sort_unstable();
            let mean = v.iter().map(|x| *x as f64).sum::<f64>() / v.len() as f64;
            let sd =
                (v.iter().map(|x| (*x as f64 - mean).powi(2)).sum::<f64>() / v.len() as f64).sqrt();
            s += &format!(
                " {name} median {} µs, {}..={}, jitter {:.1} µs;",
                sorted[sorted.len() / 2],
                sorted[0],
                sorted[sorted.len() - 1],
                sd
            );
        }
        s.pop();
        s.push('\n');
        if !self.predicted_us.is_empty() {
            let mut d = self.predicted_us.clone();
            d.sort_unstable();
            s += &format!(
                "delay compensation: {} sample frames predicted to t_us + {}..={} µs (median {}), {} measured as they are\n",
                d.len(),
                d[0],
                d[d.len() - 1],
                d[d.len() / 2],
                self.not_predicted
            );
        } else {
            s += &format!(
                "delay compensation: off ({} sample frames measured as they are)\n",
                self.not_predicted
            );
        }
        if !self.spacing_us.is_empty() {
            let n = self.spacing_us.len() as f64;
            let mean = self.spacing_us.iter().map(|x| *x as f64).sum::<f64>() / n;
            let sd = (self
                .spacing_us
                .iter()
                .map(|x| (*x as f64 - mean).powi(2))
                .sum::<f64>()
                / n)
                .sqrt();
            let (lo, hi) = (
                self.spacing_us.iter().min().copied().unwrap_or(0),
                self.spacing_us.iter().max().copied().unwrap_or(0),
            );
            s += &format!(
                "sample spacing (t_us): mean {mean:.1} µs, {lo}..={hi}, jitter {sd:.1} µs\n"
            );
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
    let clocks: Vec<String> = st
        .gyros
        .iter()
        .map(|g| {
            let f = g.fifo;
            let fifo = format!(
                "fifo overflows {} bad {} cuts {} resent {}",
                f.overflows, f.bad, f.cuts, f.resent
            );
            match g.clock {
                ClockSource::Polled => "polled".to_string(),
                ClockSource::Own => format!("own {:+}ppm late {} {fifo}", g.clock_ppm, g.late),
                ClockSource::ClkIn => format!("clkin {:+}ppm late {} {fifo}", g.clock_ppm, g.late),
            }
        })
        .collect();
    format!(
        "seq {} t {:.3} s | {:?} {:?} div {} | overruns {} | link sent {} dropped {} cmds {}/{} | stack {} B | gyro flags [{}] | z calibration [{}] | clocks [{}]",
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
        cal.join(" "),
        clocks.join(", ")
    )
}

#[cfg(test)]
mod default_tau_tests {
    #[test]
    fn the_default_noise_tau_is_what_the_board_sends() {
        assert_eq!(super::DEFAULT_NOISE_TAU, [1, 16, 256]);
    }
}
