//! `gyro_analysis._native`: the `gyro` tool's analysis (`gyro_tool`) for
//! Python. Thin: arguments are checked and turned into the tool's types,
//! the tool's code computes, and its errors become `ValueError`s with the
//! tool's own messages. The Python-facing names, docstrings and stubs are
//! in `gyro_analysis/__init__.py` and `__init__.pyi`.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, RecvTimeoutError};
use std::time::Duration;

use gyro_array::link::msg::Frame;
use gyro_tool::dev::{self, Alphas, DevError, Kind};
use gyro_tool::edf::{self, Chi2, ONE_SIGMA};
use gyro_tool::{fit, replay as tool_replay, surface};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::{PyOSError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString};

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
            "{name:?}: expected adev, oadev, mdev, tdev, hdev, ohdev, totdev, mtotdev, ttotdev, htotdev, mtie, tierms or theo1"
        ))
    })
}

/// An empty vector with room for `n` values. Where it is large, its pages
/// are asked to come as transparent huge pages (Linux `MADV_HUGEPAGE`):
/// the phase of 10⁷ points is 80 MB of fresh memory on every call, and in
/// 4 KiB pages its 20 000 page faults cost about as much as the octave
/// sweep's arithmetic.
fn buffer(n: usize) -> Vec<f64> {
    let v = Vec::<f64>::with_capacity(n);
    #[cfg(target_os = "linux")]
    if n >= 1 << 18 {
        let page = 4096usize;
        let start = (v.as_ptr() as usize).next_multiple_of(page);
        let end = (v.as_ptr() as usize + n * core::mem::size_of::<f64>()) / page * page;
        if end > start {
            // SAFETY: the range lies inside the vector's own allocation,
            // and MADV_HUGEPAGE is advice: it changes no contents or
            // mapping the vector relies on, and on failure nothing happens.
            unsafe {
                libc::madvise(start as *mut libc::c_void, end - start, libc::MADV_HUGEPAGE);
            }
        }
    }
    v
}

/// The phase the deviations read, checked finite. Frequency (rate) data
/// becomes phase as allantools makes it: a mean taken out first (the
/// deviations do not see a constant rate; its running sum would cost
/// digits), then the running sum of the samples times τ0 after a leading
/// 0 (allantools multiplies the sum by τ0 afterwards: the same to
/// rounding). A non-finite sample is an error naming it, as in `gyro
/// allan`. (For frequency data the finiteness comes from the sums: a NaN
/// or infinite sample makes the head's total or the running sum so, and
/// only then is it looked for.)
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
            let mut x = buffer(data.len());
            x.extend_from_slice(data);
            Ok(x)
        }
        "freq" => {
            let tau0 = 1.0 / rate;
            // The phase is integrated about the mean of the first rates
            // (a constant rate is a line in phase, which every deviation's
            // differences cancel; taking it out keeps the phase's values,
            // and so their rounding, small). The first 2¹⁶ stand for all of
            // them: the mean of the whole series took a pass over 80 MB of
            // its own on 10⁷ points.
            let head = &data[..data.len().min(1 << 16)];
            let total = head.iter().sum::<f64>();
            if !total.is_finite() {
                return Err(bad(head));
            }
            let mean = total / head.len().max(1) as f64;
            let mut x = buffer(data.len() + 1);
            let mut acc = 0.0;
            x.push(0.0);
            x.extend(data.iter().map(|&y| {
                acc += (y - mean) * tau0;
                acc
            }));
            // Once not finite a running sum stays so: its end says.
            if !acc.is_finite() {
                if data.iter().any(|v| !v.is_finite()) {
                    return Err(bad(data));
                }
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

/// [`factors`] for deviation `kind`: a keyword grid's factors moved to
/// where the kind has values (TheoH's long τ at multiples of 3, as
/// `gyro allan` does); given τ as they are.
fn grid_factors(
    kind: Kind,
    taus: Option<&Bound<'_, PyAny>>,
    n: usize,
    rate: f64,
) -> PyResult<Vec<usize>> {
    let keyword = taus.is_none_or(|t| t.is_instance_of::<PyString>());
    let mut ms = factors(taus, n, rate)?;
    if keyword {
        for m in ms.iter_mut() {
            *m = kind.snap_factor(*m, n);
        }
        ms.dedup();
    }
    Ok(ms)
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
    let ms = grid_factors(kind, taus, x.len(), rate)?;
    let (mut t, mut d, mut e, mut n) = (vec![], vec![], vec![], vec![]);
    // In batches of about a second's work on 10⁷ points, Ctrl-C checked
    // between them (every factor costs about the same).
    // OADEV's octaves are one sweep whatever their number.
    let sweep = kind == Kind::Oadev && ms.iter().all(|m| m.is_power_of_two());
    // TheoBR's bias ratio is the series', computed once for every factor.
    let whole = sweep || matches!(kind, Kind::Theobr | Kind::Theoh);
    let batch = if whole {
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
            // allantools states no error for TIE rms (0), and Theo1's
            // over its N − m outer sums, not its terms.
            e.push(match kind {
                Kind::Tierms => 0.0,
                Kind::Theo1 => p.dev / ((2 * p.terms / p.m) as f64).sqrt(),
                _ => p.dev / (p.terms as f64).sqrt(),
            });
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
allantools_fn!(mtotdev, Kind::Mtotdev);
allantools_fn!(ttotdev, Kind::Ttotdev);
allantools_fn!(htotdev, Kind::Htotdev);
allantools_fn!(mtie, Kind::Mtie);
allantools_fn!(tierms, Kind::Tierms);
allantools_fn!(theo1, Kind::Theo1);
allantools_fn!(theobr, Kind::Theobr);
allantools_fn!(theoh, Kind::Theoh);

/// allantools' `gradev`: the gap-resistant overlapping Allan deviation of
/// data whose missing points are NaN. Phase: the terms whose three points
/// are present (allantools' rule, its values and term counts). Rates
/// (`data_type="freq"`): the terms none of whose 2m rates is missing
/// (allantools integrates the rates first, so one NaN takes every later
/// phase point with it). Returns (taus, devs, [lo, hi], ns), the bounds at
/// confidence `ci` from the simple EDF for `noisetype` (wp, fp, wf, ff,
/// rf; allantools 2024.6 swaps two arguments there and returns NaN).
#[pyfunction]
#[pyo3(signature = (data, rate = 1.0, data_type = "phase", taus = None, ci = 0.9, noisetype = "wp"))]
#[allow(clippy::type_complexity)]
fn gradev<'py>(
    py: Python<'py>,
    data: PyReadonlyArray1<'py, f64>,
    rate: f64,
    data_type: &str,
    taus: Option<&Bound<'py, PyAny>>,
    ci: f64,
    noisetype: &str,
) -> PyResult<(
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>),
    Bound<'py, PyArray1<f64>>,
)> {
    if !(rate.is_finite() && rate > 0.0) {
        return Err(value_error(DevError::Tau0));
    }
    if !(ci > 0.0 && ci < 1.0) {
        return Err(value_error(format!("ci {ci}: a confidence in (0, 1)")));
    }
    let alpha = match noisetype {
        "wp" => 2,
        "fp" => 1,
        "wf" => 0,
        "ff" => -1,
        "rf" => -2,
        other => {
            return Err(value_error(format!(
                "noisetype {other:?}: expected wp, fp, wf, ff or rf"
            )))
        }
    };
    let data = data.as_slice()?;
    let tau0 = 1.0 / rate;
    let (phase_points, present) = match data_type {
        "phase" => (data.len(), data.iter().filter(|v| !v.is_nan()).count()),
        "freq" => (
            data.len() + 1,
            data.iter().filter(|v| !v.is_nan()).count() + 1,
        ),
        other => {
            return Err(value_error(format!(
                "data_type {other:?}: expected \"phase\" or \"freq\""
            )))
        }
    };
    let ms = factors(taus, phase_points, rate)?;
    let (mut t, mut d, mut lo, mut hi, mut n) = (vec![], vec![], vec![], vec![], vec![]);
    for m in ms {
        let p = match data_type {
            "phase" => dev::gradev(data, tau0, m),
            _ => dev::gradev_rate(data, tau0, m),
        };
        let p = match p {
            Ok(p) => p,
            Err(DevError::TooShort) => continue,
            Err(e) => return Err(value_error(e)),
        };
        if p.terms < 2 {
            continue;
        }
        let ci = edf::simple(present, m, alpha)
            .and_then(|e| edf::interval_with(p.dev, e, ci, Chi2::Exact));
        t.push(m as f64 * tau0);
        d.push(p.dev);
        lo.push(ci.map_or(f64::NAN, |c| c.0));
        hi.push(ci.map_or(f64::NAN, |c| c.1));
        n.push(p.terms as f64);
    }
    Ok((
        t.into_pyarray(py),
        d.into_pyarray(py),
        (lo.into_pyarray(py), hi.into_pyarray(py)),
        n.into_pyarray(py),
    ))
}

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
    let ms: Vec<usize> = grid_factors(kind, taus, x.len(), rate)?
        .into_iter()
        .filter(|&m| m <= kind.max_factor(x.len()) && kind.takes_factor(m, x.len()))
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

/// `work` on a thread of its own, without the GIL; every 50 ms this
/// thread looks for Ctrl-C, and on one sets the stop flag `work` watches
/// (`gyro_tool::STOP_EVERY` samples apart), waits for it to give up and
/// raises KeyboardInterrupt.
fn until_interrupted<T: Send>(
    py: Python<'_>,
    work: impl FnOnce(&AtomicBool) -> T + Send,
) -> PyResult<T> {
    let stop = AtomicBool::new(false);
    let (tx, rx) = mpsc::channel();
    std::thread::scope(|s| {
        let flag = &stop;
        s.spawn(move || {
            let _ = tx.send(work(flag));
        });
        let mut rx = rx;
        loop {
            // (The receiver goes to the GIL-free side and back: it may be
            // sent between threads, not shared.)
            let got;
            (got, rx) = py.detach(move || (rx.recv_timeout(Duration::from_millis(50)), rx));
            match got {
                Ok(v) => return Ok(v),
                Err(RecvTimeoutError::Disconnected) => {
                    return Err(PyRuntimeError::new_err(
                        "the analysis thread ended without a result",
                    ))
                }
                Err(RecvTimeoutError::Timeout) => {
                    if let Err(e) = py.check_signals() {
                        stop.store(true, Ordering::Relaxed);
                        return Err(e);
                    }
                }
            }
        }
    })
}

/// The noise model fitted to the data's overlapping Allan deviation at 8 τ
/// per decade, as `gyro allan --fit` makes it: `gyro_tool::fit::Terms` as
/// JSON (the Python side turns it into a dict); with `model_taus`, also
/// the whole model's Allan deviation there (`Terms::avar`: every term,
/// the Gauss–Markov processes included) as `model_adev`.
#[pyfunction]
#[pyo3(signature = (data, rate = 1.0, data_type = "freq", model_taus = None))]
fn noise_fit(
    py: Python<'_>,
    data: PyReadonlyArray1<'_, f64>,
    rate: f64,
    data_type: &str,
    model_taus: Option<Vec<f64>>,
) -> PyResult<String> {
    let (t, sc) = terms_of(py, data, rate, data_type)?;
    let mut v = serde_json::to_value(&t).map_err(value_error)?;
    if let serde_json::Value::Object(o) = &mut v {
        if let Some(taus) = model_taus {
            let adev: Vec<f64> = taus.iter().map(|&tau| t.avar(tau).sqrt()).collect();
            o.insert("model_taus".into(), taus.into());
            o.insert("model_adev".into(), adev.into());
        }
        // The check the fit ran, for the Python side's warning.
        if let Some(sc) = sc {
            o.insert("screen".into(), screen_json(&sc)?);
        }
    }
    serde_json::to_string(&v).map_err(value_error)
}

fn terms_of(
    py: Python<'_>,
    data: PyReadonlyArray1<'_, f64>,
    rate: f64,
    data_type: &str,
) -> PyResult<(fit::Terms, Option<gyro_tool::screen::Screen>)> {
    let mut y = data.as_slice()?;
    // As `gyro allan`: a chip's start-up value is never fitted as a rate.
    let mut screened = None;
    if data_type == "freq" && rate.is_finite() && rate > 0.0 {
        let sc = gyro_tool::screen::screen(y, 1.0 / rate);
        if let Some(v) = sc.constant {
            return Err(pyo3::exceptions::PyValueError::new_err(format!(
                "every sample reads {v}: a constant has no noise to fit (a stuck or saturated sensor?)"
            )));
        }
        if sc.no_data_later > 0 {
            return Err(pyo3::exceptions::PyValueError::new_err(format!(
                "the start-up value {} recurs at {} samples after the start: a chip that stopped converting",
                sc.startup_value.unwrap_or(f64::NAN),
                sc.no_data_later
            )));
        }
        y = &y[sc.startup..];
        screened = Some(sc);
    }
    let x = phase_of(y, rate, data_type)?;
    let tau0 = 1.0 / rate;
    let t = py
        .detach(|| fit::fit_phase(&x, tau0))
        .map_err(value_error)?;
    Ok((t, screened))
}

/// A screen as JSON, with its verdict (`static`).
fn screen_json(sc: &gyro_tool::screen::Screen) -> PyResult<serde_json::Value> {
    let mut v = serde_json::to_value(sc).map_err(value_error)?;
    v["static"] = serde_json::Value::Bool(sc.is_static());
    Ok(v)
}

/// The check `gyro allan` runs before believing a rate log
/// (`gyro_tool::screen`), as JSON.
#[pyfunction]
#[pyo3(signature = (data, rate = 1.0))]
fn screen(data: PyReadonlyArray1<'_, f64>, rate: f64) -> PyResult<String> {
    if !(rate.is_finite() && rate > 0.0) {
        return Err(value_error(DevError::Tau0));
    }
    let y = data.as_slice()?;
    if let Some(i) = y.iter().position(|v| !v.is_finite()) {
        return Err(value_error(DevError::NonFinite(i)));
    }
    let sc = gyro_tool::screen::screen(y, 1.0 / rate);
    serde_json::to_string(&screen_json(&sc)?).map_err(value_error)
}

/// Kalibr's `imu.yaml` from the fits of the gyro axes (°/s) and the
/// accelerometer axes (m/s², may be none), as `gyro allan --kalibr`
/// writes it.
#[pyfunction]
#[pyo3(signature = (gyro, accel, rate = 1.0, data_type = "freq", topic = "/imu0"))]
fn kalibr_yaml(
    py: Python<'_>,
    gyro: Vec<PyReadonlyArray1<'_, f64>>,
    accel: Vec<PyReadonlyArray1<'_, f64>>,
    rate: f64,
    data_type: &str,
    topic: &str,
) -> PyResult<String> {
    let g = gyro
        .into_iter()
        .map(|d| terms_of(py, d, rate, data_type).map(|(t, _)| t))
        .collect::<PyResult<Vec<_>>>()?;
    let a = accel
        .into_iter()
        .map(|d| terms_of(py, d, rate, data_type).map(|(t, _)| t))
        .collect::<PyResult<Vec<_>>>()?;
    fit::kalibr_yaml(&g, &a, gyro_tool::short(rate), topic)
        .ok_or_else(|| pyo3::exceptions::PyValueError::new_err("no gyro axis to fit"))
}

/// The tool's error, as it crosses back from the analysis thread: None
/// for a computation stopped by its flag, else the tool's message.
fn sendable(e: Box<dyn std::error::Error>) -> Option<String> {
    (!e.is::<gyro_tool::Stopped>()).then(|| e.to_string())
}

/// A stopped computation is KeyboardInterrupt (Ctrl-C is what stops
/// one); every other error a ValueError with the tool's message.
fn tool_error(e: Option<String>) -> PyErr {
    match e {
        None => pyo3::exceptions::PyKeyboardInterrupt::new_err("stopped"),
        Some(m) => value_error(m),
    }
}

/// The board's E-DAVAR surface of one rate series, as `gyro davar` makes
/// it: (t, start, end, taus, adev (estimates × τ), lsb).
#[pyfunction]
#[pyo3(signature = (data, rate = 1.0, lambda2 = 1024))]
#[allow(clippy::type_complexity)]
fn davar_surface<'py>(
    py: Python<'py>,
    data: PyReadonlyArray1<'py, f64>,
    rate: f64,
    lambda2: u32,
) -> PyResult<(
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray2<f64>>,
    f64,
)> {
    let l2 = match lambda2 {
        256 => surface::Lambda2::L256,
        1024 => surface::Lambda2::L1024,
        4096 => surface::Lambda2::L4096,
        _ => {
            return Err(value_error(format!(
                "lambda2 {lambda2}: expected 256, 1024 or 4096"
            )))
        }
    };
    let tau0 = 1.0 / rate;
    let y = data.as_slice()?;
    let (rows, lsb, l2n) = until_interrupted(py, |stop| {
        surface::surface_until(y, tau0, l2, stop).map_err(sendable)
    })?
    .map_err(tool_error)?;
    if rows.is_empty() {
        return Err(value_error(format!(
            "too few samples: the E-DAVAR publishes once its span of lambda2 = {l2n} samples and one hop have filled, got {}",
            y.len()
        )));
    }
    let taus: Vec<f64> = (0..rows[0].adev.len())
        .map(|j| tau0 * f64::from(1u32 << j))
        .collect();
    let flat: Vec<f64> = rows.iter().flat_map(|r| r.adev.iter().copied()).collect();
    let adev = flat.into_pyarray(py).reshape([rows.len(), taus.len()])?;
    let col =
        |f: fn(&surface::Row) -> f64| rows.iter().map(f).collect::<Vec<f64>>().into_pyarray(py);
    Ok((
        col(|r| r.t_s),
        col(|r| r.start_s),
        col(|r| r.end_s),
        taus.into_pyarray(py),
        adev,
        lsb,
    ))
}

/// The board's fusion over `chips` (samples × chips, NaN where a chip did
/// not answer), as `gyro replay` runs it: (fused, weights (samples ×
/// chips), probe, offered, used).
#[pyfunction]
#[allow(clippy::type_complexity)]
fn replay<'py>(
    py: Python<'py>,
    chips: PyReadonlyArray2<'py, f64>,
) -> PyResult<(
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<f64>>,
    Vec<usize>,
    Vec<usize>,
)> {
    let a = chips.as_array();
    let (n, k) = a.dim();
    let cols: Vec<Vec<f64>> = (0..k).map(|c| a.column(c).to_vec()).collect();
    let r = until_interrupted(py, |stop| {
        tool_replay::replay_until(&cols, stop).map_err(sendable)
    })?
    .map_err(tool_error)?;
    let w: Vec<f64> = r
        .weights
        .iter()
        .flat_map(|w| w[..k].iter().map(|&v| f64::from(v)))
        .collect();
    Ok((
        r.fused.into_pyarray(py),
        w.into_pyarray(py).reshape([n, k])?,
        r.probe.into_pyarray(py),
        r.offered,
        r.used,
    ))
}

/// A rate log as `gyro` reads it (text of any separator, with or without a
/// header; a PX4 ULog; an ArduPilot log; a ROS 1 or ROS 2 bag): a dict with
/// `names`, `rates` (an (N, k) array, °/s; NaN where a gap's samples are
/// missing, each gap put back on the time grid), `tau0` (s) and `gaps` (a
/// list of (line or message index, step in s)). With `chips`, as `gyro
/// replay` reads its chips: an empty cell is NaN, and columns of several
/// IMU topics are put on the first's stamps.
#[pyfunction]
#[pyo3(signature = (path, columns = None, time = None, tau0 = None, unit = "dps", lsb_per_dps = None, delimiter = None, header = None, chips = false))]
#[allow(clippy::too_many_arguments)]
fn read_log<'py>(
    py: Python<'py>,
    path: std::path::PathBuf,
    columns: Option<Vec<String>>,
    time: Option<String>,
    tau0: Option<f64>,
    unit: &str,
    lsb_per_dps: Option<f64>,
    delimiter: Option<String>,
    header: Option<bool>,
    chips: bool,
) -> PyResult<Bound<'py, PyDict>> {
    use gyro_tool::table::{self, Layout};
    let unit = unit_of(unit)?;
    let delimiter = match delimiter.as_deref() {
        None => None,
        Some(d) if d.len() == 1 && d.is_ascii() => Some(d.as_bytes()[0]),
        Some(d) => return Err(value_error(format!("delimiter {d:?}: one ASCII character"))),
    };
    let columns = columns.unwrap_or_default();
    let s = py
        .detach(|| {
            table::read_layout(
                &path,
                &columns,
                (time.as_deref(), tau0),
                (unit, lsb_per_dps),
                chips,
                Layout { delimiter, header },
            )
            .map_err(|e| e.to_string())
        })
        .map_err(value_error)?;
    let cols: Vec<Vec<f64>> = (0..s.rates.len()).map(|c| s.with_gaps(c)).collect();
    let n = cols.first().map_or(0, Vec::len);
    let mut flat = Vec::with_capacity(n * cols.len());
    for i in 0..n {
        for c in &cols {
            flat.push(c[i]);
        }
    }
    let rates = numpy::ndarray::Array2::from_shape_vec((n, cols.len()), flat)
        .map_err(value_error)?
        .into_pyarray(py);
    let d = PyDict::new(py);
    d.set_item("names", s.names.clone())?;
    d.set_item("rates", rates)?;
    d.set_item("tau0", s.tau0)?;
    d.set_item("gaps", s.gaps.clone())?;
    Ok(d)
}

/// A rate unit by its `gyro` name.
fn unit_of(unit: &str) -> PyResult<gyro_tool::table::Unit> {
    use gyro_tool::table::Unit;
    Ok(match unit {
        "dps" => Unit::Dps,
        "rads" => Unit::Rads,
        "dph" => Unit::Dph,
        "lsb" => Unit::Lsb,
        other => {
            return Err(value_error(format!(
                "unit {other:?}: expected dps, rads, dph or lsb"
            )))
        }
    })
}

/// A log too long to hold, in one pass and bounded memory, as `gyro allan
/// --stream` runs it (`gyro_tool::stream::analyse_file`): JSON of `names`,
/// `tau0`, `samples`, `spilled`, `gaps`, `curves` (per column and deviation
/// the points, as `gyro allan --format json` writes them) and `fits` (per
/// column the noise model, with `fit`).
#[pyfunction]
#[pyo3(signature = (path, dev, taus = "octave", tau0 = None, columns = None, time = None, unit = "dps", lsb_per_dps = None, data_type = "freq", fit = false, confidence = ONE_SIGMA, memory_mib = 256, raw = None, join_gaps = false))]
#[allow(clippy::too_many_arguments)]
fn allan_file(
    py: Python<'_>,
    path: std::path::PathBuf,
    dev: Vec<String>,
    taus: &str,
    tau0: Option<f64>,
    columns: Option<Vec<String>>,
    time: Option<String>,
    unit: &str,
    lsb_per_dps: Option<f64>,
    data_type: &str,
    fit: bool,
    confidence: f64,
    memory_mib: usize,
    raw: Option<String>,
    join_gaps: bool,
) -> PyResult<String> {
    use gyro_tool::stream;
    let kinds = dev
        .iter()
        .map(|d| Kind::from_name(d).ok_or_else(|| value_error(format!("unknown deviation {d:?}"))))
        .collect::<PyResult<Vec<_>>>()?;
    let grid: dev::Grid = taus.parse().map_err(value_error)?;
    let phase = match data_type {
        "freq" => false,
        "phase" => true,
        other => return Err(value_error(format!("data_type {other:?}: freq or phase"))),
    };
    if !(confidence > 0.0 && confidence < 1.0) {
        return Err(value_error(format!("confidence {confidence}: in (0, 1)")));
    }
    let job = stream::FileJob {
        path,
        columns: columns.unwrap_or_default(),
        time,
        tau0,
        unit: (unit_of(unit)?, lsb_per_dps),
        layout: gyro_tool::table::Layout::default(),
        raw: raw.map(|r| r.parse()).transpose().map_err(value_error)?,
        phase,
        join_gaps,
        memory_mib,
    };
    let plan = stream::Plan {
        kinds,
        grid,
        ci: (confidence, Chi2::Exact),
        fit,
        ring: 0,
        spill_dir: None,
    };
    let f = until_interrupted(py, |stop| {
        stream::analyse_file(&job, plan, &mut |_, _| {}, stop).map_err(sendable)
    })?
    .map_err(tool_error)?;
    let mut curves = Vec::new();
    let mut fits = Vec::new();
    for (c, name) in f.columns.iter().zip(&f.names) {
        for (kind, points) in &c.curves {
            curves.push(serde_json::json!({"column": name, "deviation": kind, "points": points}));
        }
        if fit {
            fits.push(match gyro_tool::fit::fit(&c.fit_points, c.n) {
                Some(t) => serde_json::json!({"column": name, "terms": t}),
                None => serde_json::json!({
                    "column": name,
                    "terms": null,
                    "error": gyro_tool::fit::FitError::TooFewPoints.to_string(),
                }),
            });
        }
    }
    serde_json::to_string(&serde_json::json!({
        "names": f.names,
        "tau0": f.tau0,
        "samples": f.samples,
        "spilled": f.spilled,
        "gaps": f.gaps,
        "curves": curves,
        "fits": fits,
    }))
    .map_err(value_error)
}

/// A board recording (`gyro record`'s file) decoded: a dict of numpy
/// arrays for the sample frames, the E-DAVAR estimates they carry and the
/// raw frames, the first status frame's sample period and τ, and the
/// decoder's and sequence counts.
#[pyfunction]
fn read_recording<'py>(py: Python<'py>, path: std::path::PathBuf) -> PyResult<Bound<'py, PyDict>> {
    let (frames, dec) = py
        .detach(|| gyro_tool::read_recording(&path).map_err(|e| e.to_string()))
        .map_err(PyOSError::new_err)?;
    let mut s = SampleCols::default();
    let mut nz = NoiseCols::default();
    let mut raw = RawCols::default();
    // The counts as `gyro check` makes them (gaps by the divider, a board
    // reset's link restart counted, not read as frames lost).
    let mut sum = gyro_tool::summary::Summary::default();
    let mut first_status = None;
    let mut gyros = 0usize;
    let mut sync = Vec::new();
    let mut info = None;
    for r in &frames {
        sum.add(r);
        let Ok(d) = r else { continue };
        match &d.body {
            Frame::Sample(f) => {
                s.push(d.link_seq, f);
                if let Some(n) = &f.noise {
                    nz.push(f.seq, n);
                }
                gyros = gyros.max(f.health.len());
            }
            Frame::Raw(r) => raw.push(r),
            Frame::Status(st) => {
                first_status.get_or_insert_with(|| (gyro_tool::summary::tau0_s(st), st.noise_tau));
            }
            Frame::Ack(_) => {}
            Frame::Sync(y) => sync.push(*y),
            Frame::Info(i) => info = Some(i.clone()),
        }
    }
    let (tau0_s, noise_tau) =
        first_status.unwrap_or((f64::NAN, gyro_tool::summary::DEFAULT_NOISE_TAU));
    let stats = dec.stats();
    let out = PyDict::new(py);
    out.set_item("samples", s.into_dict(py, gyros)?)?;
    // The controller's clock as the board tracked it, one row a sync frame.
    let sd = PyDict::new(py);
    sd.set_item(
        "state",
        sync.iter()
            .map(|y| y.state as u8)
            .collect::<Vec<_>>()
            .into_pyarray(py),
    )?;
    sd.set_item(
        "board_us",
        sync.iter()
            .map(|y| y.board_us)
            .collect::<Vec<_>>()
            .into_pyarray(py),
    )?;
    sd.set_item(
        "ctrl_us",
        sync.iter()
            .map(|y| y.ctrl_us)
            .collect::<Vec<_>>()
            .into_pyarray(py),
    )?;
    sd.set_item(
        "ppm",
        sync.iter()
            .map(|y| y.ppm)
            .collect::<Vec<_>>()
            .into_pyarray(py),
    )?;
    sd.set_item(
        "residual_us",
        sync.iter()
            .map(|y| y.residual_us)
            .collect::<Vec<_>>()
            .into_pyarray(py),
    )?;
    out.set_item("sync", sd)?;
    // The newest info frame: the board, its firmware, its chips.
    match info {
        Some(i) => {
            let d = PyDict::new(py);
            d.set_item(
                "uid",
                i.uid.iter().map(|b| format!("{b:02x}")).collect::<String>(),
            )?;
            d.set_item("firmware", (i.firmware[0], i.firmware[1], i.firmware[2]))?;
            d.set_item("build", format!("{:08x}", i.build))?;
            let chips = pyo3::types::PyList::empty(py);
            for c in &i.chips {
                let cd = PyDict::new(py);
                cd.set_item("part", format!("{:?}", c.part))?;
                cd.set_item("id", c.id)?;
                cd.set_item("start", format!("{:?}", c.start))?;
                cd.set_item("temp_c", c.temp_cc.map(|t| f64::from(t) / 100.0))?;
                chips.append(cd)?;
            }
            d.set_item("chips", chips)?;
            out.set_item("info", d)?;
        }
        None => out.set_item("info", py.None())?,
    }
    out.set_item("noise", nz.into_dict(py)?)?;
    out.set_item("raw", raw.into_dict(py)?)?;
    out.set_item("tau0_s", tau0_s)?;
    out.set_item("noise_tau", noise_tau.to_vec())?;
    let counts = PyDict::new(py);
    counts.set_item("frames", stats.frames)?;
    counts.set_item("corrupt", stats.corrupt)?;
    counts.set_item("too_long", stats.too_long)?;
    counts.set_item("version", stats.version)?;
    counts.set_item("malformed", stats.malformed)?;
    counts.set_item("bytes_dropped", stats.bytes_dropped)?;
    counts.set_item("status_frames", sum.statuses)?;
    counts.set_item("ack_frames", sum.acks.len())?;
    counts.set_item("sample_gaps", sum.sample_gaps)?;
    counts.set_item("samples_missing", sum.samples_missing)?;
    counts.set_item("link_frames_missing", sum.link_missing)?;
    counts.set_item("link_restarts", sum.link_restarts)?;
    counts.set_item("partial_bytes_at_end", dec.pending())?;
    out.set_item("counts", counts)?;
    Ok(out)
}

/// The sample frames' fields as columns.
#[derive(Default)]
struct SampleCols {
    link_seq: Vec<u32>,
    seq: Vec<u32>,
    t_us: Vec<u64>,
    age_us: Vec<u16>,
    predicted_us: Vec<f64>,
    rate_dps: Vec<f64>,
    valid: Vec<u8>,
    degraded: Vec<u8>,
    used: Vec<u8>,
    health: Vec<Vec<u8>>,
    /// The integrated angle, unwrapped, degrees (NaN where not sent), and
    /// the last wrapped value with the sum so far.
    angle_deg: Vec<f64>,
    angle_last: Option<([u32; 3], [f64; 3])>,
}

impl SampleCols {
    fn push(&mut self, link_seq: u32, f: &gyro_array::link::msg::Sample) {
        self.link_seq.push(link_seq);
        self.seq.push(f.seq);
        self.t_us.push(f.t_us);
        self.age_us.extend(f.age_us);
        self.predicted_us
            .push(f.predicted_us.map_or(f64::NAN, f64::from));
        // A rate the frame marks not valid is NaN, whatever its bytes.
        self.rate_dps.extend((0..3).map(|a| {
            if f.valid & (1 << a) != 0 {
                f64::from(f.rate_dps[a])
            } else {
                f64::NAN
            }
        }));
        self.valid.push(f.valid);
        self.degraded.push(f.degraded);
        self.used.extend(f.used);
        self.health.push(f.health.to_vec());
        // Each frame's wrapping difference from the one before (any
        // frames between lost or skipped, up to half a turn), summed.
        const UNIT: f64 = 360.0 / 4_294_967_296.0;
        match f.angle.map(|a| a.turns32()) {
            Some(now) => {
                let sum = match self.angle_last {
                    Some((last, sum)) => std::array::from_fn(|a| {
                        sum[a] + f64::from(now[a].wrapping_sub(last[a]) as i32) * UNIT
                    }),
                    None => now.map(|v| f64::from(v as i32) * UNIT),
                };
                self.angle_deg.extend(sum);
                self.angle_last = Some((now, sum));
            }
            None => self.angle_deg.extend([f64::NAN; 3]),
        }
    }

    fn into_dict(self, py: Python<'_>, gyros: usize) -> PyResult<Bound<'_, PyDict>> {
        let n = self.seq.len();
        let d = PyDict::new(py);
        d.set_item("link_seq", self.link_seq.into_pyarray(py))?;
        d.set_item("seq", self.seq.into_pyarray(py))?;
        d.set_item("t_us", self.t_us.into_pyarray(py))?;
        d.set_item("age_us", self.age_us.into_pyarray(py).reshape([n, 3])?)?;
        d.set_item("predicted_us", self.predicted_us.into_pyarray(py))?;
        d.set_item("rate_dps", self.rate_dps.into_pyarray(py).reshape([n, 3])?)?;
        d.set_item("valid", self.valid.into_pyarray(py))?;
        d.set_item("degraded", self.degraded.into_pyarray(py))?;
        d.set_item("used", self.used.into_pyarray(py).reshape([n, 3])?)?;
        d.set_item(
            "angle_deg",
            self.angle_deg.into_pyarray(py).reshape([n, 3])?,
        )?;
        // Health per gyro; 0xFF where a frame names fewer gyros.
        let h: Vec<u8> = self
            .health
            .iter()
            .flat_map(|v| (0..gyros).map(|g| v.get(g).copied().unwrap_or(0xFF)))
            .collect();
        d.set_item("health", h.into_pyarray(py).reshape([n, gyros])?)?;
        Ok(d)
    }
}

/// The E-DAVAR estimates the sample frames carried.
#[derive(Default)]
struct NoiseCols {
    frame_seq: Vec<u32>,
    axis: Vec<u8>,
    seq: Vec<u32>,
    len: Vec<u16>,
    bridged: Vec<u8>,
    sigma_dps: Vec<f64>,
}

impl NoiseCols {
    fn push(&mut self, frame_seq: u32, n: &gyro_array::link::msg::Noise) {
        self.frame_seq.push(frame_seq);
        self.axis.push(n.axis);
        self.seq.push(n.seq);
        self.len.push(n.len);
        self.bridged.push(n.bridged);
        self.sigma_dps.extend(n.sigma_dps.map(f64::from));
    }

    fn into_dict(self, py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
        let n = self.seq.len();
        let d = PyDict::new(py);
        d.set_item("frame_seq", self.frame_seq.into_pyarray(py))?;
        d.set_item("axis", self.axis.into_pyarray(py))?;
        d.set_item("seq", self.seq.into_pyarray(py))?;
        d.set_item("len", self.len.into_pyarray(py))?;
        d.set_item("bridged", self.bridged.into_pyarray(py))?;
        d.set_item(
            "sigma_dps",
            self.sigma_dps.into_pyarray(py).reshape([n, 3])?,
        )?;
        Ok(d)
    }
}

/// The raw frames (every gyro's reading), padded with NaN to the most
/// gyros a frame names.
#[derive(Default)]
struct RawCols {
    seq: Vec<u32>,
    t_us: Vec<u64>,
    rows: Vec<Vec<[f32; 3]>>,
}

impl RawCols {
    fn push(&mut self, r: &gyro_array::link::msg::Raw) {
        self.seq.push(r.seq);
        self.t_us.push(r.t_us);
        self.rows.push(r.rate_dps.to_vec());
    }

    fn into_dict(self, py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
        let n = self.seq.len();
        let g = self.rows.iter().map(Vec::len).max().unwrap_or(0);
        let flat: Vec<f64> = self
            .rows
            .iter()
            .flat_map(|v| {
                (0..g).flat_map(move |i| v.get(i).map_or([f64::NAN; 3], |r| r.map(f64::from)))
            })
            .collect();
        let d = PyDict::new(py);
        d.set_item("seq", self.seq.into_pyarray(py))?;
        d.set_item("t_us", self.t_us.into_pyarray(py))?;
        d.set_item("rate_dps", flat.into_pyarray(py).reshape([n, g, 3])?)?;
        Ok(d)
    }
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
    m.add_function(wrap_pyfunction!(mtotdev, m)?)?;
    m.add_function(wrap_pyfunction!(ttotdev, m)?)?;
    m.add_function(wrap_pyfunction!(htotdev, m)?)?;
    m.add_function(wrap_pyfunction!(mtie, m)?)?;
    m.add_function(wrap_pyfunction!(tierms, m)?)?;
    m.add_function(wrap_pyfunction!(gradev, m)?)?;
    m.add_function(wrap_pyfunction!(theo1, m)?)?;
    m.add_function(wrap_pyfunction!(theobr, m)?)?;
    m.add_function(wrap_pyfunction!(theoh, m)?)?;
    m.add_function(wrap_pyfunction!(read_log, m)?)?;
    m.add_function(wrap_pyfunction!(allan_file, m)?)?;
    m.add_function(wrap_pyfunction!(deviation, m)?)?;
    m.add_function(wrap_pyfunction!(noise_fit, m)?)?;
    m.add_function(wrap_pyfunction!(kalibr_yaml, m)?)?;
    m.add_function(wrap_pyfunction!(screen, m)?)?;
    m.add_function(wrap_pyfunction!(davar_surface, m)?)?;
    m.add_function(wrap_pyfunction!(replay, m)?)?;
    m.add_function(wrap_pyfunction!(read_recording, m)?)?;
    Ok(())
}
