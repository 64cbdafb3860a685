//! The noise-qualification functions on arbitrary series, sizes and
//! buffers: each returns (a typed error for bad input), none panics.
#![no_main]
use gyro_array::algo::qualify::ar::{burg, select_order, yule_walker};
use gyro_array::algo::qualify::emd::{emd, masm, work_len, EmdConfig};
use gyro_array::algo::qualify::hurst::{
    frac_diff, frac_weights, hurst_mrs, hurst_rs, octave_windows,
};
use gyro_array::algo::qualify::moments::{mean_var, skew_kurtosis};
use gyro_array::algo::qualify::trend::{detrend_poly, reverse_arrangement};
use gyro_array::algo::qualify::wavelet::{bayes_shrink, dwt, wavedec, waverec, DB4, DB5};
use libfuzzer_sys::fuzz_target;
mod common;
use common::Bytes;

fuzz_target!(|data: &[u8]| {
    let mut b = Bytes(data);
    let what = b.u8();
    let n = (b.u16() % 300) as usize;
    let x: Vec<f64> = (0..n)
        .map(|_| match b.u8() {
            0..=220 => (b.u16() as i16) as f64 / 64.0,
            221..=240 => b.u8() as f64, // plateaus and integer counts
            _ => b.f64(),
        })
        .collect();
    let k = b.u8() as usize;
    let short = b.u8() as usize;
    let mut s = vec![0.0f64; (8 * n + 64).saturating_sub(short)];
    let mut t = vec![0.0f64; (2 * n + 64).saturating_sub(short)];
    match what % 9 {
        0 => {
            let _ = mean_var(&x);
            let _ = skew_kurtosis(&x);
            let _ = yule_walker(&x, k % 12);
            let _ = burg(&x, k % 12, &mut s);
            let _ = select_order(&x, k % 12, &mut s);
        }
        1 => {
            let mut ns = [0usize; 24];
            let c = octave_windows(n, &mut ns);
            let _ = hurst_rs(&x, &ns[..c.min(24)]);
            let _ = hurst_rs(&x, &[k, short]);
            let _ = hurst_mrs(&x);
        }
        2 => {
            let mut h = vec![0.0; k % 40];
            frac_weights(b.f64(), &mut h);
            let _ = frac_diff(&x, &h, &mut t);
        }
        3 => {
            let mut means = vec![0.0; k % 20];
            let _ = reverse_arrangement(&x, k % 20, &mut means);
            let mut y = x.clone();
            let _ = detrend_poly(&mut y, k % 5);
        }
        4 => {
            let w = if k & 1 == 0 { &DB4 } else { &DB5 };
            let half = t.len() / 2;
            let (a, d) = t.split_at_mut(half);
            let _ = dwt(w, &x, a, d);
        }
        5 => {
            let w = if k & 1 == 0 { &DB4 } else { &DB5 };
            if let Ok(lay) = wavedec(w, &x, 1 + k % 8, &mut t, &mut s) {
                let mut tmp = vec![0.0; short];
                let _ = bayes_shrink(&mut t, &lay, &mut tmp);
                let mut out = vec![0.0; n.saturating_sub(short % 3)];
                let _ = waverec(w, &t, &lay, &mut out, &mut s);
            }
        }
        6 | 7 => {
            let n = n.min(96);
            let cfg = EmdConfig {
                max_sift: 1 + k % 20,
                max_imfs: 1 + short % 8,
                ..EmdConfig::default()
            };
            let mut rows = vec![0.0; 10 * n];
            let mut work = vec![0.0; work_len(n).saturating_sub(short % 2)];
            let mut idx = vec![0u32; n];
            if let Ok(d) = emd(&x[..n], &cfg, &mut rows, &mut work, &mut idx) {
                let mut acc = vec![0.0; n];
                let mut h = [0.0; 17];
                let _ = masm(&rows, n, d.imfs + d.residue as usize, &mut acc, &mut h);
            }
        }
        _ => {
            let mut acc = vec![0.0; short];
            let mut h = vec![0.0; k % 20];
            let _ = masm(&x, k % 50, short % 20, &mut acc, &mut h);
        }
    }
});
