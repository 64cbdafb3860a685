//! `gyro analyse`: the Allan deviation of each fused axis over the longest
//! gap-free stretch of a recording, and a summary of the E-DAVAR
//! estimates the board sent (σ at its three τ, window lengths, how far
//! behind the frame each estimate's time is, and how many came from
//! windows with bridged samples).
//!
//! The fused rate holds the vehicle's motion, so on a moving vehicle its
//! Allan deviation is mostly the motion's: the board's E-DAVAR estimates
//! (fed its noise probe) are the noise; so is `gyro replay`'s probe over a
//! raw-mode recording.

use std::path::Path;

use gyro_array::algo::allan::AdevPoint;
use gyro_array::link::msg::{Frame, Noise};

use super::{read_recording, Res};
use crate::dev::octave_oavar;

pub fn run(file: &Path) -> Res<bool> {
    let (frames, dec) = read_recording(file)?;
    let mut tau0_s = None;
    // Until a status frame says otherwise, the τ the board's tracker sends
    // by default (2^VIEW_TAUS samples: 1, 16, 256).
    let mut noise_tau = crate::summary::DEFAULT_NOISE_TAU;
    // The longest run of consecutive samples with all three axes valid.
    let (mut best, mut cur): (Vec<[f64; 3]>, Vec<[f64; 3]>) = (Vec::new(), Vec::new());
    let mut last_seq: Option<u32> = None;
    // Per axis: each estimate with how far behind its frame it describes.
    let mut noise: [Vec<(u32, Noise)>; 3] = Default::default();
    for d in frames.iter().flatten() {
        match &d.body {
            Frame::Status(s) => {
                tau0_s.get_or_insert(crate::summary::tau0_s(s));
                noise_tau = s.noise_tau;
            }
            Frame::Sample(s) => {
                let contiguous = last_seq.is_some_and(|l| s.seq.wrapping_sub(l) == 1);
                if !contiguous || s.valid != 0b111 {
                    if cur.len() > best.len() {
                        best = std::mem::take(&mut cur);
                    }
                    cur.clear();
                }
                if s.valid == 0b111 {
                    cur.push(s.rate_dps.map(f64::from));
                }
                last_seq = Some(s.seq);
                if let Some(n) = s.noise {
                    if let Some(v) = noise.get_mut(usize::from(n.axis)) {
                        v.push((s.seq.wrapping_sub(n.seq), n));
                    }
                }
            }
            _ => {}
        }
    }
    if cur.len() > best.len() {
        best = cur;
    }
    let st = dec.stats();
    println!(
        "{}: {} frames ({} discarded)",
        file.display(),
        st.frames,
        st.corrupt + st.too_long + st.version + st.malformed
    );
    // The instant each sample's rate describes, and how steady it is.
    let mut summary = crate::summary::Summary::default();
    for r in &frames {
        summary.add(r);
    }
    print!("{}", summary.timing_report());
    let tau0 = tau0_s.unwrap_or(1e-3);
    if best.len() < 16 {
        println!("fewer than 16 contiguous fused samples: no Allan deviation");
    } else {
        println!(
            "Allan deviation (overlapping, octave τ) of the fused rate over {} contiguous samples, τ0 = {} ms (the motion included; the E-DAVAR estimates below are the noise alone):",
            best.len(),
            tau0 * 1e3
        );
        let mut pts: [Vec<AdevPoint>; 3] = Default::default();
        for (a, p) in pts.iter_mut().enumerate() {
            let rate: Vec<f64> = best.iter().map(|r| r[a]).collect();
            *p = octave_oavar(&rate, tau0).map_err(|e| format!("{e:?}"))?;
        }
        println!(
            "{:>12} {:>14} {:>14} {:>14}",
            "tau_s", "x_dps", "y_dps", "z_dps"
        );
        for ((x, y), z) in pts[0].iter().zip(&pts[1]).zip(&pts[2]) {
            println!(
                "{:>12.4} {:>14.6e} {:>14.6e} {:>14.6e}{}",
                x.tau_s,
                x.adev(),
                y.adev(),
                z.adev(),
                if x.reliable() {
                    ""
                } else {
                    "  (fewer than 10 clusters)"
                }
            );
        }
    }
    println!(
        "E-DAVAR estimates sent by the board (σ at τ = {:?} samples):",
        noise_tau
    );
    for (a, v) in noise.iter().enumerate() {
        if v.is_empty() {
            println!("  axis {a}: none");
            continue;
        }
        let med = |mut x: Vec<f64>| {
            x.sort_by(f64::total_cmp);
            x[x.len() / 2]
        };
        let s0: Vec<f64> = v.iter().map(|e| f64::from(e.1.sigma_dps[0])).collect();
        let lo = s0.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = s0.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let lens: Vec<f64> = v.iter().map(|e| f64::from(e.1.len)).collect();
        let lag: Vec<f64> = v.iter().map(|e| f64::from(e.0)).collect();
        let held = v.iter().filter(|e| e.1.bridged > 0).count();
        let most = v.iter().map(|e| e.1.bridged).max().unwrap_or(0);
        println!(
            "  axis {a}: {} estimates; σ(τ0) min {lo:.4e} median {:.4e} max {hi:.4e} dps; window median {} samples; each describes the sample {} before its frame (median); {held} over windows with bridged samples (at most {most} in one)",
            v.len(),
            med(s0.clone()),
            med(lens),
            med(lag)
        );
    }
    Ok(true)
}
