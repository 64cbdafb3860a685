"""The overlapping Allan deviation curves of the six ADIS16405 static records
in SMAC-Group/imudata (``data/adis_16405_imu{1..6}.rda``), as ``oadev.csv``.

Only the curves are committed: the records are CC BY-NC-SA 4.0, and a curve
(the deviation at each tau) is what the noise model fit reads. Run from a
snapshot of the source repository:

    pip install rdata==1.1.0 numpy
    python make_curves.py /path/to/imudata/data   # needs ../../../../target/host/gyro

Each record: 1 000 000 samples at 100 Hz (2.78 h), gyro x, y, z in deg/s
(0.05 deg/s LSB), accelerometer x, y, z in g. The curves are the tool's own
(``gyro allan --dev oadev --grid per-decade=8``, checked against allantools to
7e-11 elsewhere), with each point's EDF.
"""

import csv
import os
import subprocess
import sys
import tempfile
import warnings

import numpy as np
import rdata

HERE = os.path.dirname(os.path.abspath(__file__))
GYRO = os.path.join(HERE, "..", "..", "..", "..", "target", "host", "gyro")


def main(src):
    rows = []
    for i in range(1, 7):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            obj = rdata.conversion.convert(rdata.parser.parse_file(os.path.join(src, f"adis_16405_imu{i}.rda")))
        a = np.asarray(list(obj.values())[0], dtype=float)
        assert a.shape == (1_000_000, 6), a.shape
        with tempfile.TemporaryDirectory() as tmp:
            log = os.path.join(tmp, "log.csv")
            out = os.path.join(tmp, "oadev.csv")
            np.savetxt(log, a, delimiter=",", header="gx,gy,gz,ax,ay,az", comments="", fmt="%.6g")
            subprocess.run(
                [GYRO, "allan", log, "--tau0", "0.01", "--dev", "oadev", "--grid", "per-decade=8",
                 "--format", "csv", "-o", out],
                check=True,
            )
            with open(out) as f:
                for r in csv.DictReader(f):
                    rows.append([i, r["column"], a.shape[0] + 1, r["m"], r["tau_s"], r["value"], r["edf"]])
    with open(os.path.join(HERE, "oadev.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["record", "column", "phase_points", "m", "tau_s", "oadev", "edf"])
        w.writerows(rows)


if __name__ == "__main__":
    main(sys.argv[1])
