//! Host speed of OADEV at every τ: the one-factor kernel run factor by
//! factor against the grouped kernel (`allan::second_diff_sums`, up to
//! `allan::GROUP` consecutive factors block by block), on the same 10⁵
//! points of random-walk phase in one run, three rounds. Both give each
//! factor the same sum, bit for bit (checked here too).
//!
//! `cargo run -p evaluations --profile host --bin every-tau-speed`

use std::time::Instant;

use gyro_array::algo::allan::{second_diff_sum, second_diff_sums, GROUP};
#[cfg(target_arch = "x86_64")]
use gyro_array::algo::allan::{second_diff_sum_avx2, second_diff_sums_avx2};
use gyro_sim::Rng;

const N: usize = 100_001;

fn one(x: &[f64], m: usize) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if gyro_array::algo::allan::has_avx2_fma() {
        // SAFETY: the CPU has AVX2 and FMA.
        return unsafe { second_diff_sum_avx2(x, m, 0, x.len() - 2 * m) };
    }
    second_diff_sum(x, m, 0, x.len() - 2 * m)
}

fn grouped(x: &[f64], m0: usize, sums: &mut [f64]) {
    #[cfg(target_arch = "x86_64")]
    if gyro_array::algo::allan::has_avx2_fma() {
        // SAFETY: the CPU has AVX2 and FMA.
        return unsafe { second_diff_sums_avx2(x, m0, sums) };
    }
    second_diff_sums(x, m0, sums)
}

fn main() {
    gyro_tool::pipe::quiet_on_closed_pipe();
    let mut rng = Rng::new(1);
    let mut x = vec![0.0f64; N];
    for i in 1..N {
        x[i] = x[i - 1] + f64::from(rng.gaussian());
    }
    let top = (N - 1) / 2;
    let (mut a, mut b) = (vec![0.0; top + 1], vec![0.0; top + 1]);
    for round in 1..=3 {
        let t = Instant::now();
        for (m, s) in a.iter_mut().enumerate().skip(1) {
            *s = one(&x, m);
        }
        let t_one = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let mut m = 1;
        while m <= top {
            let g = GROUP.min(top - m + 1);
            grouped(&x, m, &mut b[m..m + g]);
            m += g;
        }
        let t_grouped = t.elapsed().as_secs_f64();
        let same = a.iter().zip(&b).all(|(p, q)| p.to_bits() == q.to_bits());
        println!(
            "round {round}: every tau of {} points, one factor at a time {t_one:.3} s, grouped {t_grouped:.3} s: {:.2}x (the same sums: {same})",
            N - 1,
            t_one / t_grouped
        );
        assert!(same, "the grouped kernel changed a sum");
    }
}
