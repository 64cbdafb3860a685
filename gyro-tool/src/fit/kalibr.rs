//! Kalibr's `imu.yaml` from the fitted noise models.
//!
//! Kalibr (`kalibr_common/ConfigReader.py`, `ImuParameters`) reads
//! `rostopic`, `update_rate`, `accelerometer_noise_density`,
//! `accelerometer_random_walk`, `gyroscope_noise_density` and
//! `gyroscope_random_walk`, and refuses any of the four densities that is
//! not above 0. Its loader is PyYAML (YAML 1.1), which takes a number for
//! a float only with a decimal point and a signed exponent (`1.0e-05`;
//! `1e-05` and `0.000000000e0` load as strings).

use super::Terms;

/// A number as PyYAML reads a float: `d.ddddddddde±xx`.
fn yaml_float(v: f64) -> String {
    let s = format!("{v:.9e}");
    match s.split_once('e') {
        Some((m, e)) if !e.starts_with('-') => format!("{m}e+{e}"),
        _ => s,
    }
}

/// White noise density and random walk for Kalibr from a fit: the fitted
/// value where the term is visible, else the upper end of its 95 %
/// interval, else its IEEE 952 tangent reading (an upper bound from the
/// curve). Never 0: Kalibr takes 0 as a perfect sensor and refuses it.
/// The second of each pair says which was used.
fn density_and_walk(t: &Terms) -> [(f64, &'static str); 2] {
    [1usize, 3].map(|k| {
        if k == 1 && t.fits && t.arw > 0.0 {
            // N with the sample-scale correlation folded in (`Terms::arw`).
            (t.arw, "fitted")
        } else if k == 1 && t.arw_ci[1] > 0.0 && t.arw_ci[1].is_finite() {
            (
                t.arw_ci[1],
                "95 % upper bound (the fit does not describe the curve)",
            )
        } else if t.visible[k] && t.value[k] > 0.0 {
            (t.value[k], "fitted")
        } else if t.ci[k][1] > 0.0 && t.ci[k][1].is_finite() {
            (t.ci[k][1], "95 % upper bound (not resolved)")
        } else {
            (
                t.tangent[k],
                "IEEE 952 tangent upper bound (not in the fit)",
            )
        }
    })
}

/// Kalibr takes one value for all axes: the largest of the axes' (the
/// conservative choice), and which axis gave it.
fn largest(fits: &[Terms]) -> [(f64, &'static str, usize); 2] {
    let mut out = [(0.0, "", 0); 2];
    for (axis, t) in fits.iter().enumerate() {
        for (o, (v, how)) in out.iter_mut().zip(density_and_walk(t)) {
            if v > o.0 {
                *o = (v, how, axis);
            }
        }
    }
    out
}

/// The `imu.yaml` text: the gyro's keys from the fits of its axes'
/// curves in °/s (written in rad/s/√Hz and rad/s²/√Hz), the
/// accelerometer's from its axes' fits in m/s² when given (else its keys
/// are stated absent, commented out: Kalibr needs the user's own values
/// there). Every written value is a positive number PyYAML reads as a
/// float; None without a gyro fit.
pub fn kalibr_yaml(gyro: &[Terms], accel: &[Terms], rate_hz: f64, topic: &str) -> Option<String> {
    if gyro.is_empty() {
        return None;
    }
    let rad = std::f64::consts::PI / 180.0;
    let [n, k] = largest(gyro);
    let mut s = String::new();
    s.push_str(
        "# gyro allan: noise model fitted to the overlapping Allan variance of each axis;
",
    );
    s.push_str(
        "# each key the largest over the axes
",
    );
    for (axis, t) in gyro.iter().chain(accel).enumerate() {
        s.push_str(&format!(
            "# axis {axis}: chi2 {:.1} on {} dof, p = {:.3}: {}
",
            t.chi2,
            t.dof,
            t.p_value,
            if t.fits {
                "the model describes the curve"
            } else {
                "the model does NOT describe the curve: read its values with care"
            }
        ));
    }
    s.push_str(&format!(
        "rostopic: {topic}
"
    ));
    s.push_str(&format!(
        "update_rate: {}
",
        yaml_float(rate_hz)
    ));
    if accel.is_empty() {
        s.push_str(
            "# accelerometer_noise_density, accelerometer_random_walk: absent (no accelerometer\n\
             # columns were given); Kalibr needs both, above 0: add your accelerometer's here.\n",
        );
    } else {
        let [an, ak] = largest(accel);
        s.push_str(&format!(
            "accelerometer_noise_density: {}  # m/s^2/sqrt(Hz), {} (accelerometer axis {})\n",
            yaml_float(an.0),
            an.1,
            an.2
        ));
        s.push_str(&format!(
            "accelerometer_random_walk: {}  # m/s^3/sqrt(Hz), {} (accelerometer axis {})\n",
            yaml_float(ak.0),
            ak.1,
            ak.2
        ));
    }
    s.push_str(&format!(
        "gyroscope_noise_density: {}  # rad/s/sqrt(Hz), {} (gyro axis {})\n",
        yaml_float(n.0 * rad),
        n.1,
        n.2
    ));
    s.push_str(&format!(
        "gyroscope_random_walk: {}  # rad/s^2/sqrt(Hz), {} (gyro axis {})\n",
        yaml_float(k.0 * rad),
        k.1,
        k.2
    ));
    Some(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floats_read_as_floats_by_yaml_1_1() {
        assert_eq!(yaml_float(1.5e-5), "1.500000000e-5");
        assert_eq!(yaml_float(100.0), "1.000000000e+2");
        assert_eq!(yaml_float(1.0), "1.000000000e+0");
    }
}
