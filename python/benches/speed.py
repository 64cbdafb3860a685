"""Speed against allantools, one thread, numpy in and out, in one run.

    python python/benches/speed.py   # after pip install ./python[test]

Targets: octave OADEV of 10^7 samples >= 15x allantools; every tau of 10^5
samples >= 10x. Each figure is the best of three runs of each library.
"""

import os
import time

# One thread for both (numpy's BLAS is not used by either, but be sure).
os.environ.setdefault("OMP_NUM_THREADS", "1")

import allantools
import numpy as np

import gyro_analysis


def best(f, *args, **kw):
    t = float("inf")
    for _ in range(3):
        s = time.perf_counter()
        f(*args, **kw)
        t = min(t, time.perf_counter() - s)
    return t


def main():
    rng = np.random.default_rng(1)
    cases = [
        ("octave OADEV, 1e7 samples", 10_000_000, "octave", 15.0),
        ("every-tau OADEV, 1e5 samples", 100_000, "all", 10.0),
    ]
    for name, n, taus, target in cases:
        y = rng.standard_normal(n)
        ours = best(gyro_analysis.oadev, y, rate=1000.0, data_type="freq", taus=taus)
        theirs = best(allantools.oadev, y, rate=1000.0, data_type="freq", taus=taus)
        ratio = theirs / ours
        verdict = "met" if ratio >= target else "NOT met"
        print(f"{name}: gyro_analysis {ours:.3f} s, allantools {theirs:.3f} s: {ratio:.1f}x (target {target:.0f}x, {verdict})")


if __name__ == "__main__":
    main()
