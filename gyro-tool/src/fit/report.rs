//! The fitted model as a table, in the units gyro datasheets use: what
//! `gyro allan --fit` prints and `allan-report` prints for the emulated
//! chip, one text so the two cannot drift apart.

use super::Terms;
use crate::short;
use std::io::Write;

/// The fit as a table, in the units gyro datasheets use.
pub fn write_table(w: &mut dyn Write, name: &str, t: &Terms) -> std::io::Result<()> {
    let units = [
        ("Q", 1.0, "deg"),
        ("N", 60.0, "deg/sqrt(h)"),
        ("B", 3600.0, "deg/h"),
        ("K", 3600.0 * 60.0, "deg/h/sqrt(h)"),
        ("R", 3600.0 * 3600.0, "deg/h^2"),
    ];
    writeln!(
        w,
        "{name}: noise model over {} OADEV points (tau {} to {} s): chi2 {:.1} on {} dof, p = {:.3}, {} well-resolved points outside their 99.9 % interval: {}",
        t.points,
        short(t.tau_min_s),
        short(t.tau_max_s),
        t.chi2,
        t.dof,
        t.p_value,
        t.outside,
        if t.fits {
            "the model describes the curve"
        } else {
            "the model does NOT describe the curve (no term is called visible)"
        }
    )?;
    if t.short_left_out > 0 {
        writeln!(
            w,
            "  the model describes the curve from tau = {} s on: the {} shorter points (a sensor's output filter or a tone) were left out of the fit",
            short(t.tau_min_s),
            t.short_left_out
        )?;
    }
    writeln!(
        w,
        "{:>4} {:>14} {:>29} {:>16}  unit",
        "term", "fit", "95 % interval", "IEEE 952 tangent"
    )?;
    for (i, (n, k, u)) in units.iter().enumerate() {
        writeln!(
            w,
            "{n:>4} {:>14.6e} [{:>12.4e}, {:>12.4e}] {:>16.6e}  {u}{}",
            t.value[i] * k,
            t.ci[i][0] * k,
            t.ci[i][1] * k,
            t.tangent[i] * k,
            if t.visible[i] { "  visible" } else { "" }
        )?;
    }
    for g in &t.gm {
        writeln!(
            w,
            "  GM sigma {:.4e} deg/h [{:.3e}, {:.3e}], tau_c {:.4e} s [{:.3e}, {:.3e}]{}",
            g.sigma * 3600.0,
            g.sigma_ci[0] * 3600.0,
            g.sigma_ci[1] * 3600.0,
            g.tau_c_s,
            g.tau_c_ci[0],
            g.tau_c_ci[1],
            if g.visible { "  visible" } else { "" }
        )?;
    }
    writeln!(
        w,
        "  angle random walk beyond the sample-scale correlation (N and processes of tau_c < 3 tau0): {:.4e} deg/sqrt(h) [{:.3e}, {:.3e}]",
        t.arw * 60.0,
        t.arw_ci[0] * 60.0,
        t.arw_ci[1] * 60.0
    )?;
    match (t.bias_instability, t.bias_instability_tau_s) {
        (Some(b), Some(at)) => writeln!(
            w,
            "  bias instability (IEEE 952: the model's flat level / 0.664): {:.4e} deg/h at {} s",
            b * 3600.0,
            short(at)
        )?,
        _ => writeln!(
            w,
            "  bias instability: no flat region (the model still falls at the longest tau)"
        )?,
    }
    if t.visible[3] {
        writeln!(
            w,
            "  K is a rate random walk or a Gauss-Markov bias whose tau_c lies beyond the longest tau (K = sigma sqrt(2/tau_c)): this record cannot tell them apart"
        )?;
    }
    Ok(())
}
