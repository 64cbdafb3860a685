"""Allan-family deviations for gyro and clock data, on the gyro board's own
Rust analysis (the code behind the ``gyro`` command-line tool).

The deviation functions are shaped as allantools' are, so that switching is
a change of import::

    import gyro_analysis as at          # was: import allantools as at
    taus, devs, errs, ns = at.oadev(rate_dps, rate=1000.0, data_type="freq", taus="octave")

Each takes a one-dimensional array (``data``), the sample ``rate`` in Hz,
``data_type`` ("phase" or "freq": for a gyro, the rate samples are "freq")
and ``taus`` ("octave", the default, "decade", "all", or an array of tau in
seconds), and returns ``(taus, devs, errs, ns)`` as numpy arrays: the same tau
list and the same ``ns`` as allantools 2024.6, ``errs = devs / sqrt(ns)``.

Differences from allantools:

- a NaN or infinite sample is a ``ValueError`` naming its index (as
  ``gyro allan`` reports it), where allantools trims NaN at the ends of
  frequency data and lets others propagate;
- sums run in a different order (numpy sums pairwise), so values agree to
  about 1e-12 relative, not bit for bit.

What allantools lacks is in :func:`deviation`: each point's Greenhall EDF,
its confidence interval and the lag-1 noise type.

The rest of the ``gyro`` tool's analysis, on the same code:

- :func:`noise_fit` and :func:`kalibr_yaml`: the IEEE 952 noise model
  (quantisation, angle random walk, bias instability, rate random walk, rate
  ramp) with standard errors and visibility, and Kalibr's ``imu.yaml`` text;
- :func:`davar_surface`: the board's E-DAVAR (segmented window) over a rate
  series, the t-tau-sigma surface as numpy arrays;
- :func:`replay`: the board's fusion (online relative calibration, adaptive
  weights) over a multi-gyro array;
- :func:`read_recording` and :func:`recording_dataframe`: a board recording
  (``gyro record``'s ``.glk`` file) as numpy arrays or a pandas DataFrame,
  with the link's counts and errors.
- :func:`read_log`: a rate log as ``gyro`` reads it (text of any separator,
  with or without a header; a PX4 ULog; an ArduPilot dataflash log; a ROS 1
  or ROS 2 bag), gaps put back as NaN for :func:`gradev`, and several IMUs
  of a robot log on one time grid as :func:`replay`'s chips;
- beyond allantools' seven: :func:`mtotdev`, :func:`ttotdev`,
  :func:`htotdev`, :func:`theo1`, :func:`mtie`, :func:`tierms` and
  :func:`gradev` (equal to allantools 2024.6; ``gradev``'s bounds work),
  :func:`theobr` and :func:`theoh` (Stable32's, which allantools lacks:
  equal to allantools' own Theo1 and OADEV combined by SP 1065 eqs. 31–32);
  every deviation takes an (N, k) array, one column per series.

:class:`Dataset` is allantools' ``Dataset`` (``compute(name)`` gives the
same ``taus``, ``stat``, ``stat_err``, ``stat_n`` as allantools') carrying
also each point's EDF and confidence interval, the noise fit, a table and
a picture.

The long ones (E-DAVAR, replay) run without the GIL and stop on Ctrl-C
(``KeyboardInterrupt``).
"""

import numpy as _np

from . import _native

#: The deviations by name, each ``f(data, rate, data_type, taus)`` shaped as
#: allantools' (and :meth:`Dataset.compute`'s names).
_DEVIATIONS = (
    "adev",
    "oadev",
    "mdev",
    "tdev",
    "hdev",
    "ohdev",
    "totdev",
    "mtotdev",
    "ttotdev",
    "htotdev",
    "theo1",
    "theobr",
    "theoh",
    "mtie",
    "tierms",
)

__all__ = [
    *_DEVIATIONS,
    "gradev",
    "frequency2phase",
    "phase2frequency",
    "deviation",
    "noise_fit",
    "kalibr_yaml",
    "screen",
    "davar_surface",
    "replay",
    "read_recording",
    "read_log",
    "allan_file",
    "recording_dataframe",
    "Dataset",
]

#: The IEEE 952 terms, in the order :func:`noise_fit` gives them.
TERMS = ("Q", "N", "B", "K", "R")


def _real(data):
    """``data`` as a float64 array, or a TypeError where it is not real
    numbers: NumPy would drop a complex array's imaginary part without a
    word, and take None as one NaN."""
    if data is None:
        raise TypeError("data is None, not samples")
    a = _np.asarray(data)
    if a.dtype.kind == "c":
        raise TypeError("data must be real numbers, not complex: take .real or abs() as you mean")
    return _np.ascontiguousarray(a, dtype=_np.float64)


def _series(data):
    """``data`` as a contiguous float64 vector, or a ValueError."""
    a = _real(data)
    if a.ndim != 1:
        raise ValueError(
            f"data must be one-dimensional (two-dimensional for the deviations: one series per column), not of shape {a.shape}"
        )
    if a.size < 2:
        raise ValueError("too few samples for this tau")
    return a


def _taus(taus):
    if taus is None or isinstance(taus, str):
        return taus
    return _np.ascontiguousarray(taus, dtype=_np.float64).ravel().tolist()


def _wrap(name, what):
    native = getattr(_native, name)

    def f(data, rate=1.0, data_type="phase", taus=None):
        a = _real(data)
        if a.ndim == 2:
            # One series per column (an (N, 3) gyro log): the same taus
            # and term counts for each, devs and errs one column each.
            cols = [native(_series(a[:, k]), float(rate), data_type, _taus(taus)) for k in range(a.shape[1])]
            if not cols:
                raise ValueError(f"data of shape {a.shape} has no column")
            return (
                cols[0][0],
                _np.column_stack([c[1] for c in cols]),
                _np.column_stack([c[2] for c in cols]),
                cols[0][3],
            )
        return native(_series(data), float(rate), data_type, _taus(taus))

    f.__name__ = name
    f.__qualname__ = name
    f.__doc__ = f"""{what}, allantools' ``{name}``.

    Parameters
    ----------
    data : array_like, 1-D, or 2-D with one series per column
        Phase (s, or the rate's unit times s) or frequency (rate) samples.
        An (N, k) array (a gyro log's axes) gives devs and errs of shape
        (len(taus), k), one column per series, beside the shared taus and
        ns.
    rate : float
        Sample rate, Hz (tau0 = 1 / rate).
    data_type : {{"phase", "freq"}}
    taus : {{"octave", "decade", "all"}} or array_like of float, optional
        Averaging times, s; "octave" when omitted.

    Returns
    -------
    taus, devs, errs, ns : numpy.ndarray
        Each tau with at least two terms, its deviation, devs / sqrt(ns), and
        the number of terms.

    Raises
    ------
    ValueError
        A non-positive rate, a sample that is not finite, an unknown
        data_type or taus keyword, data of more than two dimensions.
    """
    return f


adev = _wrap("adev", "Allan deviation, non-overlapping")
oadev = _wrap("oadev", "Overlapping Allan deviation")
mdev = _wrap("mdev", "Modified Allan deviation")
tdev = _wrap("tdev", "Time deviation, tau / sqrt(3) * MDEV, in the phase's unit")
hdev = _wrap("hdev", "Hadamard deviation, non-overlapping")
ohdev = _wrap("ohdev", "Overlapping Hadamard deviation")
totdev = _wrap("totdev", "Total deviation (phase extended by reflection, SP 1065 eq. 25)")
mtotdev = _wrap("mtotdev", "Modified total deviation (SP 1065 eq. 27)")
ttotdev = _wrap("ttotdev", "Time total deviation, tau / sqrt(3) * MTOTDEV, in the phase's unit")
htotdev = _wrap("htotdev", "Hadamard total deviation (SP 1065 eq. 29; OHDEV at m = 1)")
mtie = _wrap("mtie", "Maximum time interval error over windows of m + 1 points, in the phase's unit")


def gradev(data, rate=1.0, data_type="phase", taus=None, ci=0.9, noisetype="wp"):
    """Gap-resistant overlapping Allan deviation, allantools' ``gradev``:
    NaN marks a missing point. Phase: the terms whose three points are
    present (allantools' rule). Rates (``data_type="freq"``): the terms none
    of whose 2m rates is missing. Returns (taus, devs, [lo, hi], ns), the
    bounds at confidence ``ci`` from the simple EDF for ``noisetype`` (wp,
    fp, wf, ff, rf)."""
    a = _real(data)
    if a.ndim != 1:
        raise ValueError(f"data must be one-dimensional, not of shape {a.shape}")
    if a.size < 2:
        raise ValueError("too few samples for this tau")
    return _native.gradev(a, float(rate), data_type, _taus(taus), float(ci), noisetype)


def frequency2phase(freqdata, rate):
    """Phase from frequency (rate) samples, as allantools' ``frequency2phase``:
    the mean taken out, integrated at 1 / rate, a 0 in front (N + 1 points).
    NaN samples are left out of the mean and make every later point NaN."""
    y = _real(freqdata)
    if y.ndim != 1:
        raise ValueError(f"data must be one-dimensional, not of shape {y.shape}")
    if not (_np.isfinite(rate) and rate > 0):
        raise ValueError("tau0 must be a finite number of seconds > 0")
    return _np.concatenate([[0.0], _np.cumsum(y - _np.nanmean(y)) / float(rate)])


def phase2frequency(phase, rate):
    """Frequency (rate) from phase, as allantools' ``phase2frequency``:
    successive differences times the rate (N − 1 points)."""
    x = _real(phase)
    if x.ndim != 1:
        raise ValueError(f"data must be one-dimensional, not of shape {x.shape}")
    if not (_np.isfinite(rate) and rate > 0):
        raise ValueError("tau0 must be a finite number of seconds > 0")
    return _np.diff(x) * float(rate)
theo1 = _wrap("theo1", "Theo1 at even factors (SP 1065 eq. 30), reported at m tau0 as allantools does")
theobr = _wrap(
    "theobr",
    "Bias-removed Theo1 (SP 1065 eq. 31) at Theo1's even factors, reported as theo1 is; at most 20 000 points",
)
theoh = _wrap(
    "theoh",
    "TheoH (SP 1065 eq. 32): OADEV up to a tenth of the record, TheoBR beyond, each at its averaging time; at most 20 000 points",
)
tierms = _wrap("tierms", "Time interval error RMS, in the phase's unit (error 0, as allantools)")


def deviation(data, kind="oadev", rate=1.0, data_type="phase", taus=None, confidence=0.6826894921370859):
    """One deviation with what allantools does not give, as ``gyro allan``.

    Per tau (up to the factor Stable32 stops at: (N - 1) / 2 for the Allan
    family and TOTDEV, (N - 1) / 3 for MDEV, TDEV and Hadamard):
    the deviation, the bounds of its confidence interval at ``confidence``
    (exact chi-squared on Greenhall's EDF), the EDF, the noise type alpha by
    the lag-1 autocorrelation (2 white PM ... -2 random-walk FM; NaN with
    fewer than 30 decimated points, where the EDF takes the last alpha found
    at a shorter tau), and the number of terms.

    Returns
    -------
    dict of numpy.ndarray
        ``taus``, ``devs``, ``lo``, ``hi``, ``edf``, ``alpha``, ``ns``.
    """
    cols = _native.deviation(_series(data), kind, float(rate), data_type, _taus(taus), float(confidence))
    return dict(zip(["taus", "devs", "lo", "hi", "edf", "alpha", "ns"], cols))


def noise_fit(data, rate=1.0, data_type="freq", model_taus=None):
    """The gyro noise model fitted to the data's Allan variance, as ``gyro allan --fit``.

    IEEE Std 952's terms (Q quantisation, N angle random walk, B flicker bias
    instability, K rate random walk, R rate ramp) and up to two first-order
    Gauss-Markov processes, each as the discrete process a sampled gyro
    produces, fitted to the overlapping Allan variance at 8 tau per decade by
    generalised least squares: the weights are the inverse of the estimates'
    covariance under the fitted model (the EDF of the noise present at each
    tau and the correlation between neighbouring tau), refitted until it
    settles. A chi-square test says whether the model describes the curve.

    Parameters
    ----------
    data : array_like, 1-D
        Rate samples (``data_type="freq"``, the default) or phase (angle).
    rate : float
        Sample rate, Hz.
    data_type : {"freq", "phase"}
    model_taus : array_like of float, optional
        Where to evaluate the fitted model (s): adds ``model_taus`` and
        ``model_adev``, the whole model's Allan deviation (every term, the
        Gauss-Markov processes included).

    Returns
    -------
    dict
        ``terms`` ("Q", "N", "B", "K", "R"); ``value``, ``sd``, ``ci`` (95 %
        interval, shape (5, 2)), ``tangent`` (the IEEE 952 tangent reading,
        an upper bound), ``visible`` (the fit passes, the term is resolved by
        a chi-square test and carries a tenth of the model somewhere), all in
        the data's rate unit (Q in unit*s, N in unit*sqrt(s), B in unit, K in
        unit/sqrt(s), R in unit/s); ``gm`` (a list of dicts: ``sigma``,
        ``sigma_ci``, ``tau_c_s``, ``tau_c_ci``, ``visible``); ``arw`` and
        ``arw_ci`` (N with the sample-scale correlation folded in);
        ``bias_instability`` (IEEE 952: the model's flat level / 0.664, or
        None) and its ``bias_instability_tau_s``; ``chi2``, ``dof``,
        ``p_value``, ``outside`` and ``fits`` (the test's verdict);
        ``points``, ``tau0``, ``tau_min_s``, ``tau_max_s`` (the fitted tau)
        and ``short_left_out`` (shortest points left out so that the model
        describes the rest: an output filter or a tone shapes them). For degrees per second, N * 60 is
        deg/sqrt(h) and B * 3600 deg/h.

    Raises
    ------
    ValueError
        Too few samples for three points of 8 clusters, a sample that is not
        finite, a non-positive rate.
    """
    import json

    t = json.loads(_native.noise_fit(_series(data), float(rate), data_type, _taus(model_taus)))
    # The check the fit ran (rates only). As ``gyro allan`` says it: a log
    # that moves, steps or spikes is not a noise record, and its fit says
    # so only through chi2.
    s = t.pop("screen", None)
    if s is not None and (s["spike_count"] or not s["static"]):
        import warnings

        what = []
        if s["spike_count"]:
            what.append(f"{s['spike_count']} spike(s), the first at sample {s['spikes'][0][0]}")
        if s["moving"]:
            what.append("motion")
        if s["steps"]:
            what.append(f"{len(s['steps'])} step(s), the first at sample {s['steps'][0][0]}")
        a, b = s["quiet"]
        warnings.warn(
            f"not a static noise record ({', '.join(what)}): the fit mixes them in; "
            f"the longest stretch without is samples {a} to {b} (screen()['quiet'])",
            stacklevel=2,
        )
    model = ("model_taus", "model_adev") if model_taus is not None else ()
    return _fit_dict(t, model)


def _fit_dict(t, extra=()):
    """A fit as the native side writes it (JSON), with numpy arrays."""
    out = dict(t)
    out["terms"] = TERMS
    # JSON carries NaN (a term out of the fit) as null: numpy reads it back.
    for k in ("value", "sd", "tangent", "ci", "arw_ci", *extra):
        out[k] = _np.array(t[k], dtype=float)
    return out


def allan_file(
    path,
    dev=("oadev",),
    taus="octave",
    tau0=None,
    columns=None,
    time=None,
    unit="dps",
    lsb_per_dps=None,
    data_type="freq",
    fit=False,
    confidence=0.6826894921370859,
    memory_mib=256,
    raw=None,
    join_gaps=False,
):
    """A log too long to hold, in one pass and bounded memory, as ``gyro
    allan --stream``: a 72 h, 1 kHz soak (2.6e8 samples) in under 300 MiB.

    ``path`` is a ``.npy`` file (f4 or f8, shape (N,) or (N, K), read
    through a memory map; columns ``c1`` ...), a raw little-endian file
    (``raw="f32"``, ``"f64x3"``) or a text log (read a block at a time, as
    :func:`read_log` reads it). ``dev`` takes ``adev``, ``oadev``, ``mdev``,
    ``tdev``, ``hdev``, ``ohdev`` and ``tierms`` (the deviations that are
    differences of the phase at fixed lags; rates become phase as ``gyro``
    builds it, a running sum of y * tau0, so TIE rms keeps the mean rate as
    a drift where allantools takes the mean out first: a stream cannot
    know the mean before its end); ``taus`` ``"octave"``,
    ``"decade"`` or ``"per-decade=N"``. The phase's last ``memory_mib`` MiB
    stay in memory; longer lags are read back from a temporary file.

    Returns
    -------
    dict
        ``names``, ``tau0``, ``samples``, ``gaps`` (joined, with
        ``join_gaps``); ``curves[column][dev]``, a dict of numpy arrays as
        :func:`deviation` returns (``taus``, ``devs``, ``lo``, ``hi``,
        ``edf``, ``alpha``, ``ns``); with ``fit``, ``fits[column]`` as
        :func:`noise_fit` returns (None where too few points).

    Raises
    ------
    ValueError
        A sample that is not finite, a gap in the time column (unless
        ``join_gaps``), a deviation that does not stream.
    KeyboardInterrupt
        Ctrl-C, within a block's work.
    """
    import json

    if isinstance(dev, str):
        dev = [dev]
    r = json.loads(
        _native.allan_file(
            str(path),
            list(dev),
            taus,
            tau0,
            None if columns is None else list(columns),
            time,
            unit,
            lsb_per_dps,
            data_type,
            bool(fit),
            float(confidence),
            int(memory_mib),
            raw,
            bool(join_gaps),
        )
    )
    curves = {}
    for c in r["curves"]:
        p = c["points"]

        def col(key, p=p):
            return _np.array([_np.nan if q[key] is None else q[key] for q in p], dtype=float)

        curves.setdefault(c["column"], {})[c["deviation"]] = {
            "taus": col("tau"),
            "devs": col("dev"),
            "lo": col("lo"),
            "hi": col("hi"),
            "edf": col("edf"),
            "alpha": col("alpha"),
            "ns": col("terms"),
        }
    fits = {f["column"]: None if f["terms"] is None else _fit_dict(f["terms"]) for f in r["fits"]}
    return {
        "names": r["names"],
        "tau0": r["tau0"],
        "samples": r["samples"],
        "gaps": [tuple(g) for g in r["gaps"]],
        "curves": curves,
        "fits": fits,
    }


def screen(data, rate=1.0):
    """The check ``gyro allan`` runs on a rate log before believing its noise.

    Returns a dict: ``startup`` (leading samples at a chip's start-up value,
    left out by :func:`noise_fit`) and ``startup_value``; ``no_data_later``
    (that value later in the log); ``steps`` (``[index, size]`` pairs);
    ``moving``; ``quiet`` (the longest stretch without a step or motion,
    ``[start, end)``); ``block`` (samples a block); ``spikes`` (``[index,
    value]`` pairs of samples over twenty times the noise from both
    neighbours, the first ten) and ``spike_count``; ``constant`` (the one
    value of a column that has no other, else None); ``static``.
    """
    import json

    return json.loads(_native.screen(_series(data), float(rate)))


def kalibr_yaml(data, rate=1.0, data_type="freq", topic="/imu0", accel=None):
    """Kalibr's ``imu.yaml`` text, as ``gyro allan --kalibr`` writes it.

    Parameters
    ----------
    data : array_like, 1-D or 2-D
        The gyro's rate in deg/s: one axis, or axes as columns (N, 3).
    accel : array_like, 1-D or 2-D, optional
        The accelerometer in m/s^2, one axis or axes as columns. Without it
        the accelerometer keys are stated absent in a comment (Kalibr needs
        them: add your own).

    Each key is the largest over the axes of the fitted value (its 95 %
    upper bound where the term is not resolved): ``gyroscope_noise_density``
    (rad/s/sqrt(Hz)), ``gyroscope_random_walk`` (rad/s^2/sqrt(Hz)),
    ``accelerometer_noise_density`` (m/s^2/sqrt(Hz)),
    ``accelerometer_random_walk`` (m/s^3/sqrt(Hz)); every value a positive
    number that PyYAML reads as a float.
    """

    def axes(a, what):
        arr = _real(a)
        if arr.ndim == 1:
            return [_series(arr)]
        if arr.ndim == 2:
            return [_series(_np.ascontiguousarray(arr[:, j])) for j in range(arr.shape[1])]
        raise ValueError(f"{what} must be 1-D or 2-D (samples x axes), not of shape {arr.shape}")

    g = axes(data, "data")
    a = [] if accel is None else axes(accel, "accel")
    return _native.kalibr_yaml(g, a, float(rate), data_type, str(topic))


def davar_surface(data, rate=1.0, lambda2=1024):
    """The board's E-DAVAR over one rate series, as ``gyro davar``.

    The segmented window (lambda1 = lambda2 / 2) publishes one estimate per
    32-sample hop; each describes the time ``t`` and its window
    ``[start, end)``. The rates are quantised as the board's tracker does,
    with the smallest power-of-two step ``lsb`` that keeps them in range and
    still resolves their noise (it adds lsb^2 / 6 to sigma^2(tau0)).

    Parameters
    ----------
    data : array_like, 1-D
        Rate samples, finite.
    rate : float
        Sample rate, Hz.
    lambda2 : {256, 1024, 4096}
        The longest window, samples.

    Returns
    -------
    dict
        ``t``, ``start``, ``end`` (s from the first sample, one per
        estimate), ``taus`` (s, octaves from 1 / rate), ``adev`` (estimates x
        taus, in the rate's unit), ``lsb`` and ``clipped`` (samples beyond the
        range at that step, clipped as a saturating sensor would).

    Raises
    ------
    ValueError
        Fewer samples than one window and hop, a sample that is not finite,
        another lambda2.
    KeyboardInterrupt
        On Ctrl-C (the computation runs without the GIL).
    """
    y = _series(data)
    t, start, end, taus, adev, lsb = _native.davar_surface(y, float(rate), int(lambda2))
    # The step resolves the noise even when one sample is wild; samples
    # beyond the E-DAVAR's range (2^20 - 1 steps) at it are clipped.
    clipped = int(_np.count_nonzero(_np.round(_np.abs(y) / lsb) > (1 << 20) - 1))
    return {"t": t, "start": start, "end": end, "taus": taus, "adev": adev, "lsb": lsb, "clipped": clipped}


def replay(chips):
    """The board's fusion over several gyros measuring one axis, as ``gyro replay``.

    Each sample is fused as the firmware fuses an axis: the online relative
    calibration takes each chip's scale and bias out, then the adaptive
    fusion (median gate, frozen-chip check, inverse-variance weights learnt
    online) weighs them. The noise probe is noise with the fused rate's
    variance and none of the motion.

    Parameters
    ----------
    chips : array_like, 2-D, samples x chips (2 to 8 chips)
        Rates; NaN where a chip did not answer.

    Returns
    -------
    dict
        ``fused`` (NaN where no fused value), ``weights`` (samples x chips, 0
        where a chip was left out), ``probe`` (NaN where fewer than two chips
        were fused), ``offered`` and ``used`` (per chip, samples it answered
        and samples fusion used it).

    Raises
    ------
    ValueError
        Not 2-D, fewer than 2 or more than 8 chips.
    KeyboardInterrupt
        On Ctrl-C.
    """
    a = _np.ascontiguousarray(chips, dtype=_np.float64)
    if a.ndim != 2:
        raise ValueError(f"chips must be two-dimensional (samples x chips), not of shape {a.shape}")
    fused, weights, probe, offered, used = _native.replay(a)
    return {
        "fused": fused,
        "weights": weights,
        "probe": probe,
        "offered": _np.asarray(offered),
        "used": _np.asarray(used),
    }


def read_log(
    path, columns=None, time=None, tau0=None, unit="dps", lsb_per_dps=None, delimiter=None, header=None, chips=False
):
    """A rate log as ``gyro`` reads it: text of any separator, with or
    without a header (detected; ``delimiter`` and ``header`` overrule), a PX4
    ULog, an ArduPilot dataflash log, or a ROS 1 or ROS 2 (MCAP or sqlite3)
    bag. Returns a dict: ``names``, ``rates`` (an (N, k) float64 array in
    deg/s, with NaN where a gap's samples are missing, so that
    :func:`gradev` takes it as it is), ``tau0`` (s) and ``gaps`` (line or
    message index, step in s).

    With ``chips=True`` the columns are read as :func:`replay`'s chips, as
    ``gyro replay`` reads them: an empty cell is NaN (no answer), and
    columns of several IMU topics (``["IMU.0.z", "IMU.1.z"]``) are put on
    the first one's stamps, each other topic's sample nearest a stamp
    within half a period, NaN where none is."""
    return _native.read_log(
        str(path),
        None if columns is None else list(columns),
        time,
        tau0,
        unit,
        lsb_per_dps,
        delimiter,
        header,
        chips,
    )


def read_recording(path):
    """A board recording (``gyro record``'s ``.glk`` file) as numpy arrays.

    Every frame is decoded as ``gyro check`` and ``gyro decode`` decode it:
    COBS, the CRC and the protocol version checked; a damaged frame is
    counted and skipped, never guessed at.

    Returns
    -------
    dict
        ``samples``: per sample frame ``seq``, ``t_us`` (when it was queued,
        board us), ``age_us`` (n x 3: how long before ``t_us`` the rate was
        the true rate), ``predicted_us`` (NaN where the rates are measured,
        not predicted), ``rate_dps`` (n x 3, NaN where the axis is not
        valid), ``valid``, ``degraded``, ``used`` (n x 3 gyro masks),
        ``health`` (n x gyros), ``link_seq``, ``angle_deg`` (n x 3: the
        board's integrated angle, unwrapped from the frames' 2^-32 turn
        counts across lost or skipped frames, degrees from the first frame's
        wrapped value; NaN where the frames do not carry it). ``noise``: the E-DAVAR
        estimates the frames carried (``frame_seq``, ``axis``, ``seq`` it
        describes, window ``len``, ``bridged``, ``sigma_dps`` at the three
        ``noise_tau``). ``raw``: raw frames (``seq``, ``t_us``, ``rate_dps``
        n x gyros x 3). ``sync``: the sync frames (``state``: 0 Off,
        1 Acquiring, 2 Locked, 3 Lost; ``board_us``, ``ctrl_us``, ``ppm``,
        ``residual_us``: board instant t is ``ctrl_us + (t - board_us) *
        (1 + ppm * 1e-6)`` in the controller's clock while Locked).
        ``info``: the newest info frame (``uid`` hex, ``firmware`` tuple,
        ``build`` hex, ``chips``: per gyro ``part``, ``id``, ``start``,
        ``temp_c``), or None.
        ``tau0_s`` and ``noise_tau`` from the first status
        frame (NaN and the board's defaults without one). ``counts``: the
        decoder's (``frames``, ``corrupt``, ``too_long``, ``version``,
        ``malformed``, ``bytes_dropped``), ``status_frames``,
        ``ack_frames``, ``sample_gaps``, ``samples_missing``,
        ``link_frames_missing`` and ``link_restarts`` (the sequence numbers,
        counted as ``gyro check`` counts them) and ``partial_bytes_at_end``.

    Raises
    ------
    OSError
        The file cannot be read.
    """
    return _native.read_recording(str(path))


def recording_dataframe(path_or_recording):
    """The sample frames of a recording as a pandas DataFrame, indexed by ``seq``.

    Columns: ``t_us``, ``age_x_us`` ... ``age_z_us``, ``predicted_us``,
    ``x_dps``, ``y_dps``, ``z_dps``, ``valid``, ``degraded``, ``used_x`` ...
    ``used_z``, ``angle_x_deg`` ... ``angle_z_deg``. Needs pandas (``ImportError`` otherwise); takes a path or what
    :func:`read_recording` returned.
    """
    import pandas as pd

    rec = path_or_recording if isinstance(path_or_recording, dict) else read_recording(path_or_recording)
    s = rec["samples"]
    cols = {"t_us": s["t_us"]}
    for a, name in enumerate("xyz"):
        cols[f"age_{name}_us"] = s["age_us"][:, a]
    cols["predicted_us"] = s["predicted_us"]
    for a, name in enumerate("xyz"):
        cols[f"{name}_dps"] = s["rate_dps"][:, a]
    cols["valid"] = s["valid"]
    cols["degraded"] = s["degraded"]
    for a, name in enumerate("xyz"):
        cols[f"used_{name}"] = s["used"][:, a]
    for a, name in enumerate("xyz"):
        cols[f"angle_{name}_deg"] = s["angle_deg"][:, a]
    return pd.DataFrame(cols, index=pd.Index(s["seq"], name="seq"))


#: One standard deviation's two-sided confidence (Stable32's default).
_ONE_SIGMA = 0.6826894921370859


class Dataset:
    """allantools' ``Dataset``, on this package: the input in ``inp``, the
    last :meth:`compute`'s result in ``out``; and what allantools' lacks:
    each point's confidence interval and EDF, the noise model fit
    (:meth:`fit`), a table (:meth:`write_results`) and a picture
    (:meth:`plot`).

    ``out`` holds allantools' keys, ``taus``, ``stat``, ``stat_err``,
    ``stat_n`` and ``stat_id`` (equal to allantools 2024.6's to about 1e-12
    relative: the same functions as this package's), and ``stat_lo``,
    ``stat_hi``, ``stat_edf``, ``stat_alpha`` from :func:`deviation` (NaN
    at the tau beyond Stable32's last factor, where allantools still
    reports a value, and for the deviations without an EDF model here:
    MTOTDEV, TTOTDEV, HTOTDEV, Theo1, MTIE, TIE rms). ``fit_result`` is
    :func:`noise_fit`'s dict after :meth:`fit`.
    """

    def __init__(self, data=None, rate=1.0, data_type="phase", taus=None):
        self.inp = {"data": data, "rate": rate, "data_type": data_type, "taus": taus}
        self.out = {
            "taus": None,
            "stat": None,
            "stat_err": None,
            "stat_n": None,
            "stat_unc": None,
            "stat_id": None,
        }
        self.fit_result = None

    def set_input(self, data, rate=1.0, data_type="phase", taus=None):
        """The input, where it was not given to the constructor."""
        self.inp = {"data": data, "rate": rate, "data_type": data_type, "taus": taus}

    def compute(self, function, confidence=_ONE_SIGMA):
        """One deviation by name (``"oadev"``, ``"mdev"``, …, ``"theo1"``,
        ``"mtie"``, ``"tierms"``): allantools' keys, returned and kept in
        ``out`` with the confidence interval at ``confidence``."""
        if function not in _DEVIATIONS:
            raise ValueError(f"{function!r}: one of {', '.join(_DEVIATIONS)}")
        inp = self.inp
        taus, devs, errs, ns = globals()[function](
            inp["data"], rate=inp["rate"], data_type=inp["data_type"], taus=inp["taus"]
        )
        result = {"taus": taus, "stat": devs, "stat_err": errs, "stat_n": ns}
        extra = {k: _np.full(len(taus), _np.nan) for k in ("stat_lo", "stat_hi", "stat_edf", "stat_alpha")}
        if len(taus) and _np.asarray(inp["data"]).ndim == 1:
            d = deviation(inp["data"], function, inp["rate"], inp["data_type"], taus, confidence)
            # Each of deviation's tau is one of allantools' (the same factors).
            at = _np.searchsorted(taus, d["taus"] * (1 - 1e-12))
            for key, col in (("stat_lo", "lo"), ("stat_hi", "hi"), ("stat_edf", "edf"), ("stat_alpha", "alpha")):
                extra[key][at] = d[col]
        self.out = dict(result, stat_unc=None, stat_id=function, **extra)
        return result

    def fit(self):
        """The noise model of the data (:func:`noise_fit`), kept in
        ``fit_result`` and drawn by :meth:`plot`."""
        inp = self.inp
        # The model at 8 tau a decade from tau0 to half the record, for plot().
        n = _np.asarray(inp["data"]).shape[0]
        taus = _np.logspace(0, _np.log10(max(n / 2, 1.0)), max(2, int(8 * _np.log10(max(n / 2, 10.0)))))
        self.fit_result = noise_fit(
            inp["data"], rate=inp["rate"], data_type=inp["data_type"], model_taus=taus / float(inp["rate"])
        )
        return self.fit_result

    def write_results(self, filename, digits=5, header_params=None):
        """The last :meth:`compute`'s table as text, one tau a line
        (allantools' columns, then the interval, the EDF and alpha)."""
        if self.out["stat_id"] is None:
            raise ValueError("nothing computed yet: call compute() first")
        o = self.out
        cols = ("taus", "stat", "stat_err", "stat_n", "stat_lo", "stat_hi", "stat_edf", "stat_alpha")
        with open(filename, "w") as f:
            for k, v in (header_params or {}).items():
                f.write(f"# {k} = {v}\n")
            f.write(f"# {o['stat_id']}, rate {self.inp['rate']} Hz, {self.inp['data_type']} data\n")
            f.write("# " + " ".join(cols) + "\n")
            for row in zip(*(o[c] for c in cols)):
                f.write(" ".join(f"{float(v):.{digits}e}" for v in row) + "\n")

    def plot(self, ax=None, errorbars=True, fit=True):
        """The deviation on log-log axes (matplotlib), with its confidence
        interval and, after :meth:`fit`, the fitted model; returns the axes."""
        import matplotlib.pyplot as plt

        if self.out["stat_id"] is None:
            raise ValueError("nothing computed yet: call compute() first")
        if ax is None:
            _, ax = plt.subplots()
        o = self.out
        taus, devs = _np.asarray(o["taus"]), _np.asarray(o["stat"])
        ax.loglog(taus, devs, "o-", ms=3, label=o["stat_id"])
        if errorbars:
            lo, hi = _np.asarray(o["stat_lo"]), _np.asarray(o["stat_hi"])
            ok = _np.isfinite(lo) & _np.isfinite(hi)
            ax.fill_between(taus[ok], lo[ok], hi[ok], alpha=0.25, label="confidence interval")
        if fit and self.fit_result is not None and o["stat_id"] in ("adev", "oadev"):
            f = self.fit_result
            ax.loglog(f["model_taus"], f["model_adev"], "--", label="noise fit")
        ax.set_xlabel("tau (s)")
        ax.set_ylabel(o["stat_id"])
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
        return ax

