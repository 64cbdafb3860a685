#!/usr/bin/env python3
"""allantools 2024.06 `gradev` (gap-resistant overlapping ADEV) of the phase
record `make_allantools_vectors.py` writes, with holes cut in it: the oracle
for `dev::gradev` (test `gradev_matches_allantools_on_a_holed_record`).

    python3 -m venv /tmp/v && /tmp/v/bin/pip install allantools==2024.6
    /tmp/v/bin/python gyro-tool/tests/make_gradev_vectors.py gyro-tool/tests/vectors

Writes `allantools_gradev.csv` (m, dev, n) at factors 1..40 and octaves to
1024, with the points 500..519, 1 700, and 2 500..2 899 missing (NaN).
Only the deviations and term counts are taken: allantools 2024.06 passes
its confidence and EDF to `confidence_interval` in swapped order, so its
error bars come out NaN.
"""
import sys

import numpy as np
import allantools as at

out = sys.argv[1]
x = np.loadtxt(f"{out}/allantools_phase.csv", skiprows=1)
x[500:520] = np.nan
x[1700] = np.nan
x[2500:2900] = np.nan
ms = sorted(set(list(range(1, 41)) + [2**k for k in range(6, 11)]))
taus, devs, errs, ns = at.gradev(x, rate=1.0, data_type="phase", taus=np.array(ms, dtype=float))
with open(f"{out}/allantools_gradev.csv", "w") as f:
    f.write("m,dev,n\n")
    for t, d, k in zip(taus, devs, ns):
        f.write(f"{int(round(t))},{float(d)!r},{int(k)}\n")
