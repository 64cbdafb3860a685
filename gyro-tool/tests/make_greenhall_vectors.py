#!/usr/bin/env python3
"""Greenhall EDF and 1-sigma confidence intervals from allantools 2024.06,
the oracle for gyro-tool's `edf` module (tests/greenhall.rs).

    python3 -m venv /tmp/v && /tmp/v/bin/pip install allantools==2024.6 scipy
    /tmp/v/bin/python gyro-tool/tests/make_greenhall_vectors.py > gyro-tool/tests/vectors/greenhall.csv

Columns: kind, alpha, m, n, edf, lo, hi (lo and hi are the interval of a
deviation of 1 at confidence erf(1/sqrt 2)). Cases allantools refuses
(NotImplementedError) are left out.
"""
import allantools as at

KINDS = {  # name: (d, overlapping, modified)
    "adev": (2, False, False),
    "oadev": (2, True, False),
    "mdev": (2, True, True),
    "hdev": (3, False, False),
    "ohdev": (3, True, False),
}
MS = [1, 2, 3, 4, 5, 8, 16, 33, 64, 100, 256, 1000, 4096, 65536]
NS = [40, 101, 1001, 10_000, 100_000, 1_000_000, 10_000_000, 30_000_000]

print("kind,alpha,m,n,edf,lo,hi")
for name, (d, ov, mod) in KINDS.items():
    for alpha in range(2, -5, -1):
        if alpha + 2 * d <= 1:
            continue
        for n in NS:
            for m in MS:
                length = m / (1 if mod else m) + m * d
                if n < length:
                    continue
                try:
                    e = at.edf_greenhall(alpha=alpha, d=d, m=m, N=n, overlapping=ov, modified=mod)
                except (NotImplementedError, AssertionError):
                    continue
                if not (e > 0):
                    continue
                lo, hi = at.confidence_interval(dev=1.0, edf=e)
                print(f"{name},{alpha},{m},{n},{float(e)!r},{float(lo)!r},{float(hi)!r}")
