//! A reference stabilisation loop for one axis of a satcom-on-the-move
//! antenna: what is left of the vehicle's motion at the beam when the
//! positioner counter-rotates on the board's fused rate.
//!
//! The gyro board sits on the vehicle, under the positioner (a
//! base-mounted rate sensor: the common layout for mechanically steered
//! vehicle terminals). Per axis, small angles, the axes independent:
//!
//! - the vehicle turns at ω_v; the beam's pointing error is
//!   e = θ_v + φ, with θ_v = ∫ω_v and φ the positioner's angle against
//!   the vehicle (the satellite is fixed in inertial space: e = 0 is on
//!   target);
//! - the positioner's rate loop follows its command c through a first
//!   order lag of bandwidth `rate_bw_hz` (τ φ̈ + φ̇ = c), with its angular
//!   acceleration and rate limited;
//! - the command counter-rotates on the gyro, c = −ω_g − k_p e − k_i ∫e:
//!   the slow tracking loop (beacon or step-track) removes what the gyro
//!   cannot see (its bias, its drift), a PI loop on the pointing error of
//!   natural frequency `track_hz` and damping `track_zeta` (k_p = 2ζω_n,
//!   k_i = ω_n²).
//!
//! The tracking loop sees the true pointing error: a real step-track
//! measures it from the beacon's strength with noise and a dither, which
//! this model leaves out (they would add the same to every gyro compared).
//!
//! Between two steps of `dt_s` the command is held and the rate loop's lag
//! is integrated exactly, so the model is the continuous loop to within the
//! command's hold (dt/2 of delay: 5 µs at the default 10 µs, which the
//! closed-form checks below see as 0.3 % of the rate loop's lag).
//!
//! With ideal gyro input (ω_g = ω_v) and no limit reached, the error's
//! transfer function from ω_v is
//!
//! ```text
//! E(s)/Ω_v(s) = (1 + sτ − e^(−sD)) / (s(1 + sτ) + k_p + k_i/s)
//! ```
//!
//! for a gyro delayed by D (D = 0 for the ideal gyro): the rate loop's lag
//! τ acts as a delay of its own, and at frequencies well above the tracking
//! loop's, the error is the rate times (τ + D) integrated, which is why the
//! gyro's delay matters as much as the positioner's.

/// The loop's parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoopParams {
    /// The rate loop's bandwidth, Hz (first order).
    pub rate_bw_hz: f64,
    /// The positioner's rate limit, °/s.
    pub rate_limit_dps: f64,
    /// The positioner's angular acceleration limit, °/s².
    pub accel_limit_dps2: f64,
    /// The tracking loop's natural frequency, Hz.
    pub track_hz: f64,
    /// The tracking loop's damping.
    pub track_zeta: f64,
    /// The rate loop's lag led on the gyro's feed: the command adds
    /// τ·ω̇_g, so the positioner's rate follows the gyro's without the
    /// loop's lag (model-based feedforward: the controller knows its own
    /// rate loop).
    pub lead: bool,
    /// Simulation step, s.
    pub dt_s: f64,
}

impl LoopParams {
    /// A vehicle terminal's positioner, direct drive. The stored public
    /// material gives the limit (0.2°, FCC 47 CFR 25.226 for vehicle-mounted
    /// earth stations) and the motion (turns to 100 °/s, sway to 12 Hz) but
    /// no positioner's figures, so these are this model's choices, stated:
    /// a rate loop of 100 Hz (a 1.6 ms lag) with its lag led on the gyro's
    /// feed (without the lead the ideal gyro leaves 0.057° on
    /// `pointing-eval`'s 30 °/s, 0.7 Hz sway, above the 0.05° aimed at;
    /// with it, the 1 kHz feed's hold is what is left), 200 °/s and
    /// 5 000 °/s² (twice the fastest turn and four times the largest
    /// acceleration the profiles ask: the limits are not what is being
    /// measured), and a 0.5 Hz tracking loop, damping 0.7.
    pub const VEHICLE: Self = Self {
        rate_bw_hz: 100.0,
        rate_limit_dps: 200.0,
        accel_limit_dps2: 5_000.0,
        track_hz: 0.5,
        track_zeta: 0.7,
        lead: true,
        dt_s: 1e-5,
    };

    /// The rate loop's time constant, s.
    pub fn tau_s(&self) -> f64 {
        1.0 / (2.0 * core::f64::consts::PI * self.rate_bw_hz)
    }

    /// The tracking loop's gains (k_p, 1/s; k_i, 1/s²).
    pub fn gains(&self) -> (f64, f64) {
        let wn = 2.0 * core::f64::consts::PI * self.track_hz;
        (2.0 * self.track_zeta * wn, wn * wn)
    }

    /// |E/Ω_v| and its phase (rad) at `hz` for a gyro `delay_s` late, with
    /// no limit reached: the closed form above (with the lead, its
    /// numerator is (1 + sτ)(1 − e^(−sD)): an ideal gyro leaves nothing).
    pub fn error_gain(&self, hz: f64, delay_s: f64) -> (f64, f64) {
        let w = 2.0 * core::f64::consts::PI * hz;
        let tau = self.tau_s();
        let (kp, ki) = self.gains();
        // Complex numbers as (re, im).
        let (c, s) = (libm::cos(w * delay_s), libm::sin(w * delay_s));
        // 1 + jωτ − e^(−jωD), or with the lead (1 + jωτ)(1 − e^(−jωD))
        let num = if self.lead {
            let (a, b) = (1.0 - c, s);
            (a - w * tau * b, b + w * tau * a)
        } else {
            (1.0 - c, w * tau + s)
        };
        // jω(1 + jωτ) + k_p + k_i/(jω) = (k_p − ω²τ) + j(ω − k_i/ω)
        let den = (kp - w * w * tau, w - ki / w);
        let d2 = den.0 * den.0 + den.1 * den.1;
        let re = (num.0 * den.0 + num.1 * den.1) / d2;
        let im = (num.1 * den.0 - num.0 * den.1) / d2;
        (libm::sqrt(re * re + im * im), libm::atan2(im, re))
    }
}

/// One axis's loop state.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Axis {
    /// The positioner's angle against the vehicle, °.
    pub phi_deg: f64,
    /// Its rate, °/s.
    pub phi_dps: f64,
    /// The tracking loop's integral of the pointing error, ° s.
    pub integral: f64,
    /// The pointing error after the last step, °.
    pub error_deg: f64,
}

/// The loop, its constants worked out once.
#[derive(Clone, Copy, Debug)]
pub struct Loop {
    p: LoopParams,
    tau: f64,
    /// e^(−dt/τ).
    decay: f64,
    kp: f64,
    ki: f64,
}

impl Loop {
    /// The loop for `p`.
    pub fn new(p: LoopParams) -> Self {
        let tau = p.tau_s();
        let (kp, ki) = p.gains();
        Self {
            p,
            tau,
            decay: libm::exp(-p.dt_s / tau),
            kp,
            ki,
        }
    }

    /// The parameters.
    pub fn params(&self) -> &LoopParams {
        &self.p
    }

    /// One step: the vehicle's angle at the step's start (°, the integral
    /// of its true rate), the gyro rate the controller holds (°/s) and its
    /// rate of change (°/s², for the lead; the controller's own estimate).
    /// Returns the pointing error at the step's start.
    pub fn step(&self, st: &mut Axis, theta_v_deg: f64, gyro_dps: f64, gyro_dps2: f64) -> f64 {
        let p = &self.p;
        let dt = p.dt_s;
        let e = theta_v_deg + st.phi_deg;
        st.integral += e * dt;
        let lead = if p.lead { self.tau * gyro_dps2 } else { 0.0 };
        let c = (-gyro_dps - lead - self.kp * e - self.ki * st.integral)
            .clamp(-p.rate_limit_dps, p.rate_limit_dps);
        let accel = (c - st.phi_dps) / self.tau;
        if accel.abs() <= p.accel_limit_dps2 {
            // τ φ̈ + φ̇ = c with c held: exact over the step.
            let gap = st.phi_dps - c;
            st.phi_deg += c * dt + gap * self.tau * (1.0 - self.decay);
            st.phi_dps = c + gap * self.decay;
        } else {
            // At the acceleration limit (for this step: the limit binds
            // only where the lag's own acceleration is beyond it).
            let a = p.accel_limit_dps2.copysign(accel);
            st.phi_deg += st.phi_dps * dt + 0.5 * a * dt * dt;
            st.phi_dps += a * dt;
        }
        st.error_deg = e;
        e
    }

    /// The loop on `A` axes fed a gyro's samples as a positioner gets
    /// them: `feed[k]` held from `arrive_s[k]` on, the controller's estimate
    /// of its change (for the lead) the difference of the last two received
    /// over `period_s`; against the vehicle's rate `motion(t)` (its angle
    /// by the trapezoid over each step; `None`: no motion, the response to
    /// an error signal alone). `steps` steps of `dt_s` from `t0_s`;
    /// `each(j, t, e)` gets step `j`'s start time and pointing errors.
    #[allow(clippy::too_many_arguments)]
    pub fn run_held<const A: usize>(
        &self,
        mut motion: Option<&mut dyn FnMut(f64) -> [f64; A]>,
        t0_s: f64,
        steps: usize,
        arrive_s: &[f64],
        feed: &[[f64; A]],
        period_s: f64,
        mut each: impl FnMut(usize, f64, &[f64; A]),
    ) {
        let dt = self.p.dt_s;
        let mut st = [Axis::default(); A];
        let (mut g, mut dg, mut theta) = ([0.0f64; A], [0.0f64; A], [0.0f64; A]);
        let mut last = motion.as_mut().map_or([0.0; A], |m| m(t0_s));
        let mut k = 0usize;
        let mut e = [0.0f64; A];
        for j in 0..steps {
            let t = t0_s + j as f64 * dt;
            while k < feed.len() && arrive_s[k] <= t {
                if k > 0 {
                    dg = core::array::from_fn(|a| (feed[k][a] - g[a]) / period_s);
                }
                g = feed[k];
                k += 1;
            }
            for a in 0..A {
                e[a] = self.step(&mut st[a], theta[a], g[a], dg[a]);
            }
            if let Some(m) = motion.as_mut() {
                let next = m(t + dt);
                for a in 0..A {
                    theta[a] += 0.5 * (last[a] + next[a]) * dt;
                }
                last = next;
            }
            each(j, t, &e);
        }
    }
}

/// Pointing-error statistics of a run, °.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ErrorStats {
    /// RMS.
    pub rms: f64,
    /// 99.9th percentile of |e|.
    pub p999: f64,
    /// Largest |e|.
    pub max: f64,
}

/// The statistics of `e` (sorted in place by |e|). Empty gives zeros.
pub fn stats(e: &mut [f64]) -> ErrorStats {
    if e.is_empty() {
        return ErrorStats::default();
    }
    let mut ss = 0.0;
    for v in e.iter_mut() {
        ss += *v * *v;
        *v = v.abs();
    }
    e.sort_unstable_by(f64::total_cmp);
    let n = e.len();
    // Nearest rank.
    let k = libm::ceil(0.999 * n as f64) as usize;
    ErrorStats {
        rms: libm::sqrt(ss / n as f64),
        p999: e[k.clamp(1, n) - 1],
        max: e[n - 1],
    }
}

/// The least-squares line y = m·x + b through `points`: (m, b). Where x
/// does not vary (a still vehicle: nothing to tell a scale from), m is
/// `flat_slope` and b what is left of the mean. The scale-and-bias fit of
/// a gyro's rate error (`pointing-eval`, `gyro pointing`).
pub fn fit_line(points: impl IntoIterator<Item = (f64, f64)>, flat_slope: f64) -> (f64, f64) {
    let (mut n, mut sx, mut sy, mut sxx, mut sxy) = (0.0f64, 0.0, 0.0, 0.0, 0.0);
    for (x, y) in points {
        n += 1.0;
        sx += x;
        sy += y;
        sxx += x * x;
        sxy += x * y;
    }
    let n1 = n.max(1.0);
    let var = sxx - sx * sx / n1;
    let m = if var > 1e-6 * n {
        (sxy - sx * sy / n1) / var
    } else {
        flat_slope
    };
    (m, (sy - m * sx) / n1)
}

/// The closed-form check of a rate step: the largest error, relative to
/// R τ, of the simulated e(t) against R τ (1 − e^(−t/τ)) over 20 τ, with
/// no tracking loop, no lead (a step has no derivative to lead) and no
/// acceleration limit.
pub fn step_check(p: LoopParams) -> f64 {
    let p = LoopParams {
        accel_limit_dps2: f64::INFINITY,
        track_hz: 0.0,
        lead: false,
        ..p
    };
    let l = Loop::new(p);
    let tau = p.tau_s();
    let r = 50.0;
    let mut st = Axis::default();
    let mut worst: f64 = 0.0;
    let steps = libm::ceil(20.0 * tau / p.dt_s) as usize;
    for k in 0..steps {
        let t = k as f64 * p.dt_s;
        l.step(&mut st, r * t, r, 0.0);
        let t_end = t + p.dt_s;
        let e_end = r * t_end + st.phi_deg;
        let want = r * tau * (1.0 - libm::exp(-t_end / tau));
        worst = worst.max((e_end - want).abs() / (r * tau));
    }
    worst
}

/// The sines [`sine_check`] is run on (Hz, gyro delay s): with the lead,
/// an undelayed gyro leaves no error to compare.
pub const SINE_CHECKS: [(f64, f64); 5] = [
    (0.1, 0.002),
    (0.5, 0.002),
    (2.0, 0.001),
    (2.0, 0.002),
    (12.0, 0.001),
];

/// The closed-form check of a sine: the simulated steady-state peak of |e|
/// for ω_v = `a_dps` sin(2π `hz` t) seen by a gyro `delay_s` late, and
/// |E/Ω_v|·A.
pub fn sine_check(p: LoopParams, hz: f64, a_dps: f64, delay_s: f64) -> (f64, f64) {
    let l = Loop::new(p);
    let w = 2.0 * core::f64::consts::PI * hz;
    let mut st = Axis::default();
    // θ_v = A/ω (1 − cos ωt): ω_v = A sin ωt.
    let theta = |t: f64| a_dps / w * (1.0 - libm::cos(w * t));
    let rate = |t: f64| a_dps * libm::sin(w * t);
    let accel = |t: f64| a_dps * w * libm::cos(w * t);
    // Past the tracking loop's transient (its envelope decays at ζω_n).
    let settle = (8.0 / hz).max(20.0);
    let steps = ((settle + 2.0 / hz) / p.dt_s) as usize;
    let from = (settle / p.dt_s) as usize;
    let mut peak: f64 = 0.0;
    for k in 0..steps {
        let t = k as f64 * p.dt_s;
        let e = l.step(&mut st, theta(t), rate(t - delay_s), accel(t - delay_s));
        if k >= from {
            peak = peak.max(e.abs());
        }
    }
    (peak, p.error_gain(hz, delay_s).0 * a_dps)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn no_tracking() -> LoopParams {
        LoopParams {
            track_hz: 0.0,
            ..LoopParams::VEHICLE
        }
    }

    #[test]
    fn a_rate_step_leaves_the_rate_loop_lag_in_closed_form() {
        // The command's hold (half a step of delay) against τ.
        let worst = step_check(LoopParams::VEHICLE);
        assert!(worst < 0.01, "{worst}");
    }

    #[test]
    fn a_sine_leaves_the_closed_form_amplitude() {
        // With the tracking loop and a gyro delayed by D, at 0.1 to 12 Hz.
        for lead in [false, true] {
            let p = LoopParams {
                lead,
                ..LoopParams::VEHICLE
            };
            for (hz, d) in SINE_CHECKS {
                let (sim, want) = sine_check(p, hz, 30.0, d);
                let rel = (sim - want).abs() / want;
                assert!(
                    rel < 0.01,
                    "lead {lead}, {hz} Hz, D {d}: {sim} vs {want} ({rel})"
                );
            }
        }
    }

    #[test]
    fn the_tracking_loop_removes_a_gyro_bias() {
        // A 0.5 °/s bias: the PI loop takes the error back to 0.
        let p = LoopParams::VEHICLE;
        let l = Loop::new(p);
        let mut st = Axis::default();
        let mut e = 0.0;
        for _ in 0..(20.0 / p.dt_s) as usize {
            e = l.step(&mut st, 0.0, 0.5, 0.0);
        }
        assert!(e.abs() < 1e-4, "{e}");
    }

    #[test]
    fn limits_bind_on_a_faster_turn() {
        // A 400 °/s command against the 200 °/s limit: the error grows at
        // the difference.
        let p = no_tracking();
        let l = Loop::new(p);
        let mut st = Axis::default();
        for k in 0..100_000 {
            let t = k as f64 * p.dt_s;
            l.step(&mut st, 400.0 * t, 400.0, 0.0);
        }
        assert!((st.phi_dps + 200.0).abs() < 1e-9, "{}", st.phi_dps);
    }

    #[test]
    fn a_line_is_fitted_and_a_flat_one_keeps_its_slope() {
        let (m, b) = fit_line((0..100).map(|k| (k as f64, 3.0 * k as f64 - 2.0)), 1.0);
        assert!((m - 3.0).abs() < 1e-12 && (b + 2.0).abs() < 1e-9);
        assert_eq!(fit_line((0..10).map(|_| (5.0, 7.0)), 1.0), (1.0, 2.0));
    }

    #[test]
    fn stats_are_nearest_rank() {
        let mut e: Vec<f64> = (1..=2000)
            .map(|k| if k % 2 == 0 { k as f64 } else { -(k as f64) })
            .collect();
        let s = stats(&mut e);
        assert_eq!(s.max, 2000.0);
        assert_eq!(s.p999, 1998.0);
    }
}
