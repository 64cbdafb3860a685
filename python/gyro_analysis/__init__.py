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
"""

import numpy as _np

from . import _native

__all__ = ["adev", "oadev", "mdev", "tdev", "hdev", "ohdev", "totdev", "deviation"]


def _series(data):
    """``data`` as a contiguous float64 vector, or a ValueError."""
    a = _np.ascontiguousarray(data, dtype=_np.float64)
    if a.ndim != 1:
        raise ValueError(f"data must be one-dimensional, not of shape {a.shape}")
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
        return native(_series(data), float(rate), data_type, _taus(taus))

    f.__name__ = name
    f.__qualname__ = name
    f.__doc__ = f"""{what}, allantools' ``{name}``.

    Parameters
    ----------
    data : array_like, 1-D
        Phase (s, or the rate's unit times s) or frequency (rate) samples.
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
        data_type or taus keyword, data that is not one-dimensional.
    """
    return f


adev = _wrap("adev", "Allan deviation, non-overlapping")
oadev = _wrap("oadev", "Overlapping Allan deviation")
mdev = _wrap("mdev", "Modified Allan deviation")
tdev = _wrap("tdev", "Time deviation, tau / sqrt(3) * MDEV, in the phase's unit")
hdev = _wrap("hdev", "Hadamard deviation, non-overlapping")
ohdev = _wrap("ohdev", "Overlapping Hadamard deviation")
totdev = _wrap("totdev", "Total deviation (phase extended by reflection, SP 1065 eq. 25)")


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
