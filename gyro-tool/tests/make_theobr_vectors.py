#!/usr/bin/env python3
"""TheoBR and TheoH of the allantools oracle's phase record, built from
allantools 2024.06's own ``theo1`` and ``oadev`` by NIST SP 1065's
equations 31 and 32 (allantools has neither): the oracle for `dev.rs`'s
`theobr_and_theoh_match_allantools_theo1_and_oadev`.

    python3 -m venv /tmp/v && /tmp/v/bin/pip install allantools==2024.6
    /tmp/v/bin/python gyro-tool/tests/make_theobr_vectors.py gyro-tool/tests/vectors

Reads `allantools_phase.csv` (4 000 points, tau0 = 1 s) and writes
`allantools_theobr.csv` (kind, m, dev, n):

- the bias ratio (kind ``ratio``, m 0): the mean over i = 0 .. k,
  k = floor(0.1 N / 3 - 3), of OAVAR at factor 9 + 3i over Theo1's
  variance at 12 + 4i (the same averaging time: Theo1's is 0.75 m tau0);
- TheoBR at even Theo1 factors: Theo1 times the ratio's square root,
  reported at m tau0 as allantools reports Theo1 (n: Theo1's terms);
- TheoH at factors m, each at its averaging time m tau0: OADEV where
  10 m <= N - 1 (a tenth of the record's span), beyond it TheoBR at Theo1
  factor 4m/3 (m a multiple of 3; n: that Theo1's terms).

Some minutes: allantools' Theo1 is a Python loop of N m / 2 terms a factor.
"""
import sys
import numpy as np
import allantools as at

out = sys.argv[1]
x = np.loadtxt(f"{out}/allantools_phase.csv", skiprows=1)
N = len(x)


def theo1(ms):
    taus, devs, errs, ns = at.theo1(x, rate=1.0, data_type="phase", taus=np.array(ms, dtype=float))
    assert [int(round(t)) for t in taus] == list(ms), (taus, ms)
    return devs, ns


def oadev(ms):
    taus, devs, errs, ns = at.oadev(x, rate=1.0, data_type="phase", taus=np.array(ms, dtype=float))
    assert [int(round(t)) for t in taus] == list(ms), (taus, ms)
    return devs, ns


k = int(np.floor(0.1 * N / 3 - 3))
a, _ = oadev([9 + 3 * i for i in range(k + 1)])
t, _ = theo1([12 + 4 * i for i in range(k + 1)])
ratio = float(np.mean(a**2 / t**2))

br_ms = list(range(10, 41, 2)) + [2**j for j in range(6, 12)] + [3996]
br, br_n = theo1(br_ms)

h_oadev = [m for m in list(range(1, 41)) + [64, 128, 256, 399] if 10 * m <= N - 1]
h_br = [402, 450, 600, 900, 1500, 2250, 2997]
assert all(10 * m > N - 1 and m % 3 == 0 and 4 * m // 3 <= N - 1 for m in h_br)
ho, ho_n = oadev(h_oadev)
hb, hb_n = theo1([4 * m // 3 for m in h_br])

with open(f"{out}/allantools_theobr.csv", "w") as f:
    f.write("kind,m,dev,n\n")
    f.write(f"ratio,0,{ratio!r},{k + 1}\n")
    for m, d, n in zip(br_ms, br, br_n):
        f.write(f"theobr,{m},{float(d) * ratio**0.5!r},{int(n)}\n")
    for m, d, n in zip(h_oadev, ho, ho_n):
        f.write(f"theoh,{m},{float(d)!r},{int(n)}\n")
    for m, d, n in zip(h_br, hb, hb_n):
        f.write(f"theoh,{m},{float(d) * ratio**0.5!r},{int(n)}\n")
print(f"ratio {ratio:.6f} over {k + 1} pairs; {len(br_ms)} TheoBR, {len(h_oadev) + len(h_br)} TheoH points")
