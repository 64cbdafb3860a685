//! `gyro_analysis._native`: the `gyro` tool's analysis (`gyro_tool`) for
//! Python. Thin: arguments are checked and turned into the tool's types,
//! the tool's code computes, and its errors become `ValueError`s with the
//! tool's own messages. The Python-facing names, docstrings and stubs are
//! in `gyro_analysis/__init__.py` and `__init__.pyi`.

use gyro_tool::dev::{self, Alphas, DevError, Kind};
use gyro_tool::edf::{Chi2, ONE_SIGMA};
use numpy::{IntoPyArray, PyArray1, PyReadonlyArray1};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyString;

/// Four float arrays, as allantools returns them.
type Arrays4<'py> = (
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
);

fn value_error(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

fn kind_of(name: &str) -> PyResult<Kind> {
    Kind::from_name(name).ok_or_else(|| {
        value_error(format!(
            "{name:?}: expected adev, oadev, mdev, tdev, hdev, ohdev or totdev"
        ))
    })
}

/// The phase the deviations read, checked finite. Frequency (rate) data
/// becomes phase as allantools makes it: the mean taken out first (the
/// deviations do not see a constant rate; its running sum would cost
/// digits), then the running sum of the samples times τ0 after a leading
/// 0 (allantools multiplies the sum by τ0 afterwards: the same to
/// rounding). A
/// non-finite sample is an error naming it, as in `gyro allan`. (For
/// frequency data the finiteness comes from the sums: a NaN or infinite
/// sample makes the total so, and only then is it looked for.)
fn phase_of(data: &[f64], rate: f64, data_type: &str) -> PyResult<Vec<f64>> {
    if !(rate.is_finite() && rate > 0.0) {
        return Err(value_error(DevError::Tau0));
    }
    let bad = |data: &[f64]| {
        let i = data.iter().position(|v| !v.is_finite()).unwrap_or(0);
        value_error(DevError::NonFinite(i))
    };
    match data_type {
        "phase" => {
            if data.iter().any(|v| !v.is_finite()) {
                return Err(bad(data));
            }
            Ok(data.to_vec())
        }
        "freq" => {
            let tau0 = 1.0 / rate;
            let total = data.iter().sum::<f64>();
            if !total.is_finite() {
                return Err(bad(data));
            }
            let mean = total / data.len().max(1) as f64;
            let mut x = Vec::with_capacity(data.len() + 1);
            let mut acc = 0.0;
            x.push(0.0);
            x.extend(data.iter().map(|&y| {
                acc += (y - mean) * tau0;
                acc
            }));
            // Once not finite a running sum stays so: its end says.
            if !acc.is_finite() {
                return Err(value_error(
                    "the phase (the running sum of the rate times tau0) is not finite",
                ));
            }
            Ok(x)
        }
        _ => Err(value_error(format!(
            "data_type {data_type:?}: expected \"phase\" or \"freq\""
        ))),
    }
}

/// The averaging factors for `taus` over `n` phase points, as allantools'
/// `tau_generator` makes them: "octave" (the default) 1, 2, 4, … up to
/// 2^⌊log₂ n⌋; "decade" 1, 2, 4, 10, 20, 40, … up to ⌊log₁₀ n⌋ decades;
/// "all" 1 … n; an array of τ (s), each rounded to the nearest factor
/// (half to even, as numpy's round); then only 0 < m < n, sorted, once.
fn factors(taus: Option<&Bound<'_, PyAny>>, n: usize, rate: f64) -> PyResult<Vec<usize>> {
    let mut ms: Vec<f64> = Vec::new();
    let keyword = match taus {
        None => Some("octave".to_string()),
        Some(t) if t.is_instance_of::<PyString>() => Some(t.extract::<String>()?),
        Some(_) => None,
    };
    let nf = n as f64;
    match keyword.as_deref() {
        Some("octave") => {
            let top = nf.log2().floor().max(0.0) as i32;
            ms.extend((0..=top).map(|k| 2f64.powi(k)));
        }
        Some("decade") => {
            let top = nf.log10().floor().max(0.0) as i32;
            for k in 0..=top {
                let d = 10f64.powi(k);
                ms.extend([d, 2.0 * d, 4.0 * d]);
            }
        }
        Some("all") => ms.extend((1..=n).map(|m| m as f64)),
        Some(other) => {
            return Err(value_error(format!(
                "taus {other:?}: expected \"all\", \"octave\", \"decade\" or an array of tau in seconds"
            )))
        }
        None => {
            let given: Vec<f64> = match taus {
                Some(t) => t.extract().map_err(|_| {
                    value_error("taus must be \"all\", \"octave\", \"decade\" or an array of tau in seconds")
                })?,
                None => Vec::new(),
            };
            if let Some(t) = given.iter().find(|t| !t.is_finite()) {
                return Err(value_error(format!("tau {t} is not a finite number of seconds")));
            }
            ms.extend(given.iter().map(|t| (t * rate).round_ties_even()));
        }
    }
    let mut out: Vec<usize> = ms
        .into_iter()
        .filter(|&m| m > 0.0 && m < nf)
        .map(|m| m as usize)
        .collect();
    out.sort_unstable();
    out.dedup();
    Ok(out)
}

/// Terms a batch of factors sums before Ctrl-C is checked.
const CHECK_TERMS: usize = 100_000_000;

/// One deviation over the factors, allantools-shaped: (τ, dev, dev/√n, n)
/// where n > 1 (allantools' `remove_small_ns`). Computed without the GIL,
/// one τ at a time, with Ctrl-C checked between them.
fn deviation_arrays<'py>(
    py: Python<'py>,
    kind: Kind,
    data: PyReadonlyArray1<'py, f64>,
    rate: f64,
    data_type: &str,
    taus: Option<&Bound<'py, PyAny>>,
) -> PyResult<Arrays4<'py>> {
    let x = phase_of(data.as_slice()?, rate, data_type)?;
    let tau0 = 1.0 / rate;
    let ms = factors(taus, x.len(), rate)?;
    let (mut t, mut d, mut e, mut n) = (vec![], vec![], vec![], vec![]);
    // In batches of about a second's work on 10⁷ points, Ctrl-C checked
    // between them (every factor costs about the same).
    // OADEV's octaves are one sweep whatever their number.
    let sweep = kind == Kind::Oadev && ms.iter().all(|m| m.is_power_of_two());
    let batch = if sweep {
        ms.len().max(1)
    } else {
        (CHECK_TERMS / x.len().max(1)).max(1)
    };
    for chunk in ms.chunks(batch) {
        let points = py
            .detach(|| dev::deviations_of_finite(kind, &x, tau0, chunk))
            .map_err(value_error)?;
        py.check_signals()?;
        for p in points.into_iter().flatten().filter(|p| p.terms > 1) {
            t.push(p.m as f64 / rate);
            d.push(p.dev);
            e.push(p.dev / (p.terms as f64).sqrt());
            n.push(p.terms as f64);
        }
    }
    Ok((
        t.into_pyarray(py),
        d.into_pyarray(py),
        e.into_pyarray(py),
        n.into_pyarray(py),
    ))
}

macro_rules! allantools_fn {
    ($name:ident, $kind:expr) => {
        #[pyfunction]
        #[pyo3(signature = (data, rate = 1.0, data_type = "phase", taus = None))]
        fn $name<'py>(
            py: Python<'py>,
            data: PyReadonlyArray1<'py, f64>,
            rate: f64,
            data_type: &str,
            taus: Option<&Bound<'py, PyAny>>,
        ) -> PyResult<Arrays4<'py>> {
            deviation_arrays(py, $kind, data, rate, data_type, taus)
        }
    };
}

allantools_fn!(adev, Kind::Adev);
allantools_fn!(oadev, Kind::Oadev);
allantools_fn!(mdev, Kind::Mdev);
allantools_fn!(tdev, Kind::Tdev);
allantools_fn!(hdev, Kind::Hdev);
allantools_fn!(ohdev, Kind::Ohdev);
allantools_fn!(totdev, Kind::Totdev);

/// What allantools lacks, per τ: the deviation with its Greenhall EDF,
/// its confidence interval at `confidence` (exact χ²), and the lag-1
/// noise type α (None where fewer than 30 decimated points; the EDF then
/// takes the last α identified at a shorter τ), as `gyro allan` prints
/// them. Returns (taus, devs, lo, hi, edf, alpha, ns) with NaN where a
/// value is absent.
#[pyfunction]
#[pyo3(signature = (data, kind = "oadev", rate = 1.0, data_type = "phase", taus = None, confidence = ONE_SIGMA))]
#[allow(clippy::type_complexity)]
fn deviation<'py>(
    py: Python<'py>,
    data: PyReadonlyArray1<'py, f64>,
    kind: &str,
    rate: f64,
    data_type: &str,
    taus: Option<&Bound<'py, PyAny>>,
    confidence: f64,
) -> PyResult<Vec<Bound<'py, PyArray1<f64>>>> {
    let kind = kind_of(kind)?;
    if !(confidence > 0.0 && confidence < 1.0) {
        return Err(value_error(format!(
            "confidence {confidence}: must lie in (0, 1)"
        )));
    }
    let x = phase_of(data.as_slice()?, rate, data_type)?;
    let tau0 = 1.0 / rate;
    let ms: Vec<usize> = factors(taus, x.len(), rate)?
        .into_iter()
        .filter(|&m| m <= kind.max_factor(x.len()))
        .collect();
    let points = py
        .detach(|| {
            let mut alphas = Alphas::new();
            dev::curve_at(kind, &x, tau0, &ms, (confidence, Chi2::Exact), &mut alphas)
        })
        .map_err(value_error)?;
    let col = |f: &dyn Fn(&dev::Point) -> Option<f64>| -> Vec<f64> {
        points.iter().map(|p| f(p).unwrap_or(f64::NAN)).collect()
    };
    Ok(vec![
        col(&|p| Some(p.tau)).into_pyarray(py),
        col(&|p| Some(p.dev)).into_pyarray(py),
        col(&|p| p.lo).into_pyarray(py),
        col(&|p| p.hi).into_pyarray(py),
        col(&|p| p.edf).into_pyarray(py),
        col(&|p| p.alpha.map(f64::from)).into_pyarray(py),
        col(&|p| Some(p.terms as f64)).into_pyarray(py),
    ])
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(adev, m)?)?;
    m.add_function(wrap_pyfunction!(oadev, m)?)?;
    m.add_function(wrap_pyfunction!(mdev, m)?)?;
    m.add_function(wrap_pyfunction!(tdev, m)?)?;
    m.add_function(wrap_pyfunction!(hdev, m)?)?;
    m.add_function(wrap_pyfunction!(ohdev, m)?)?;
    m.add_function(wrap_pyfunction!(totdev, m)?)?;
    m.add_function(wrap_pyfunction!(deviation, m)?)?;
    Ok(())
}
