#!/usr/bin/env python3
"""pyulog's reading of `sample_log_small.ulg`, the oracle for `gyro_tool::ulog`
(test `ulog::tests::the_gyro_topics_read_as_pyulog_reads_them`).

`sample_log_small.ulg` is pyulog's test log (PX4/pyulog, `test/sample_log_small.ulg`
at commit 3cf17793f14709713ab297d3743314c658874068; BSD 3-Clause, LICENSE.md
beside it).

    python3 -m venv /tmp/v && /tmp/v/bin/pip install pyulog==1.3.0 numpy
    /tmp/v/bin/python gyro-tool/tests/vectors/ulog/make_expected.py gyro-tool/tests/vectors/ulog

Writes `expected.csv`: per gyro topic instance, its sample count, the
median stamp step (s), and its first and last rates in deg/s.
"""
import sys

import numpy as np
from pyulog import ULog

out = sys.argv[1]
u = ULog(f"{out}/sample_log_small.ulg")
rows = []
for d in u.data_list:
    if d.name == "sensor_gyro":
        axes, stamp = ["x", "y", "z"], "timestamp_sample"
    elif d.name == "sensor_combined":
        axes, stamp = ["gyro_rad[0]", "gyro_rad[1]", "gyro_rad[2]"], "timestamp"
    else:
        continue
    t = d.data[stamp].astype(np.int64)
    step = float(np.sort(np.diff(t))[(len(t) - 1) // 2]) * 1e-6
    deg = 180.0 / np.pi
    for k, a in zip("xyz", axes):
        v = d.data[a].astype(np.float64) * deg
        rows.append(f"{d.name}.{d.multi_id}.{k},{len(t)},{step!r},{float(v[0])!r},{float(v[-1])!r}")
with open(f"{out}/expected.csv", "w") as f:
    f.write("column,samples,tau0,first,last\n")
    f.write("\n".join(sorted(rows)) + "\n")
