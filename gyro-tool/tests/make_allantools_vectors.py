#!/usr/bin/env python3
"""allantools 2024.06 deviations of a generated phase record, the oracle for
gyro-tool's `dev` module on data other than Stable32's (`dev.rs` test
`every_deviation_matches_allantools`).

    python3 -m venv /tmp/v && /tmp/v/bin/pip install allantools==2024.6
    /tmp/v/bin/python gyro-tool/tests/make_allantools_vectors.py gyro-tool/tests/vectors

Writes `allantools_phase.csv` (4 000 phase points: white PM, white FM and
random-walk FM, seed 2024) and `allantools_devs.csv` (kind, m, dev, n):
ADEV, OADEV, MDEV, TDEV, HDEV, OHDEV and TOTDEV at every factor 1..40 and
then octave factors, with tau0 = 1 s; and `allantools_family.csv` (the
same columns): MTOTDEV, TTOTDEV, HTOTDEV, MTIE and TIERMS at factors 1..12
and then octave factors (allantools' total estimators are O(N·m) Python
loops: some minutes); and `allantools_theo1.csv`: Theo1 at the even factors
2..40 and 64..2048 by octaves.
"""
import sys
import numpy as np
import allantools as at

out = sys.argv[1]
rng = np.random.default_rng(2024)
n = 4000
y = 1e-3 * rng.standard_normal(n - 1) + np.cumsum(2e-5 * rng.standard_normal(n - 1))
x = np.concatenate([[0.0], np.cumsum(y)]) + 2e-4 * rng.standard_normal(n)
np.savetxt(f"{out}/allantools_phase.csv", x, fmt="%.17g", header="x", comments="")
ms = sorted(set(list(range(1, 41)) + [2**k for k in range(6, 12)]))
funcs = {"adev": at.adev, "oadev": at.oadev, "mdev": at.mdev, "tdev": at.tdev,
         "hdev": at.hdev, "ohdev": at.ohdev, "totdev": at.totdev}
with open(f"{out}/allantools_devs.csv", "w") as f:
    f.write("kind,m,dev,n\n")
    for name, fn in funcs.items():
        taus, devs, errs, ns = fn(x, rate=1.0, data_type="phase", taus=np.array(ms, dtype=float))
        for t, d, k in zip(taus, devs, ns):
            f.write(f"{name},{int(round(t))},{float(d)!r},{int(k)}\n")

ms = sorted(set(list(range(1, 13)) + [2**k for k in range(4, 11)]))
funcs = {"mtotdev": at.mtotdev, "ttotdev": at.ttotdev, "htotdev": at.htotdev,
         "mtie": at.mtie, "tierms": at.tierms}
with open(f"{out}/allantools_family.csv", "w") as f:
    f.write("kind,m,dev,n\n")
    for name, fn in funcs.items():
        taus, devs, errs, ns = fn(x, rate=1.0, data_type="phase", taus=np.array(ms, dtype=float))
        for t, d, k in zip(taus, devs, ns):
            f.write(f"{name},{int(round(t))},{float(d)!r},{int(k)}\n")

ms = list(range(2, 41, 2)) + [2**k for k in range(6, 12)]
taus, devs, errs, ns = at.theo1(x, rate=1.0, data_type="phase", taus=np.array(ms, dtype=float))
with open(f"{out}/allantools_theo1.csv", "w") as f:
    f.write("kind,m,dev,n\n")
    for t, d, k in zip(taus, devs, ns):
        f.write(f"theo1,{int(round(t))},{float(d)!r},{int(k)}\n")
