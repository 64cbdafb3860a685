#!/usr/bin/env python3
"""The gyro rates of pymavlink's test log (`test.BIN`, an ArduCopter
dataflash log from pymavlink's tests, LGPL-3.0: LICENSE.md) as pymavlink's
own reader (`DFReader`) decodes them: the fixture of `gyro_tool::dataflash`
(test `pymavlinks_test_log_reads_as_pymavlink_reads_it`).

    python3 -m venv /tmp/v && /tmp/v/bin/pip install pymavlink==2.4.50
    /tmp/v/bin/python gyro-tool/tests/vectors/dataflash/make_expected.py gyro-tool/tests/vectors/dataflash

Writes `expected.csv`: per IMU message in the log's order, its name, the
instance (the `I` field, or the digit of the old names `IMU2`, `IMU3`),
TimeUS and GyrX, GyrY, GyrZ (rad/s) as pymavlink reads them.
"""
import sys
from pathlib import Path

from pymavlink import DFReader

out = Path(sys.argv[1])
log = DFReader.DFReader_binary(str(out / "test.BIN"))
rows = []
while True:
    m = log.recv_match(type=["IMU", "IMU2", "IMU3"])
    if m is None:
        break
    name = m.get_type()
    inst = getattr(m, "I", None)
    if inst is None:
        inst = 0 if name == "IMU" else int(name[3:]) - 1
    rows.append(f"{name},{inst},{m.TimeUS},{m.GyrX!r},{m.GyrY!r},{m.GyrZ!r}")
(out / "expected.csv").write_text("name,instance,time_us,x,y,z\n" + "\n".join(rows) + "\n")
