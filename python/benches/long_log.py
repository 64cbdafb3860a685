"""A long static log through `gyro allan --stream`, beside allantools.

    cargo build -p gyro-tool --profile host
    python python/benches/long_log.py                 # 72 h at 1 kHz
    python python/benches/long_log.py --samples 1e8 --allantools 3e7

Writes the log (white noise, a random walk and a bias, as a gyro at rest)
as a binary `.npy` of f64 and f32 and, with --text, a text log of the same
length from `gyro emulate --flicker --rrw 40` (one column, as a logger
writes; numpy's savetxt would take longer than the analysis). Runs `gyro
allan FILE --stream --dev oadev,mdev --fit` on each and prints its time,
input speed and peak memory (gyro's own VmHWM). Then allantools' octave
OADEV and MDEV on the first N samples, for each N of --allantools, with
its time and peak memory (VmHWM in its own process), gyro --stream's on
the same samples, and the largest difference between the two tools'
deviations. Targets: 72 h (2.6e8 samples) in <= 500 MB; binary >= 500
MB/s, text >= 100 MB/s of input, one thread.

Every figure is measured here, in this run; nothing is assumed.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

TAU0 = 0.001


def write_log(path_f64, path_f32, n, seed=1):
    """The log a block at a time: bounded memory here too."""
    rng = np.random.default_rng(seed)
    out64 = np.lib.format.open_memmap(path_f64, mode="w+", dtype="<f8", shape=(n,))
    out32 = np.lib.format.open_memmap(path_f32, mode="w+", dtype="<f4", shape=(n,))
    walk = 0.0
    block = 1 << 22
    for a in range(0, n, block):
        b = min(n, a + block)
        white = 0.0028 * np.sqrt(1.0 / TAU0) * rng.standard_normal(b - a)
        steps = 1e-5 * np.sqrt(TAU0) * rng.standard_normal(b - a)
        rw = walk + np.cumsum(steps)
        walk = rw[-1]
        y = 0.05 + white + rw
        out64[a:b] = y
        out32[a:b] = y.astype("<f4")
    out64.flush()
    out32.flush()
    del out64, out32


def child(cmd):
    """Run `cmd`: its wall time, stdout and stderr (each tool prints its own
    peak memory: the children's maxrss here would be the largest child's)."""
    t = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True)
    dt = time.perf_counter() - t
    if r.returncode != 0:
        sys.exit(f"{cmd[0]} failed:\n{r.stderr}")
    return dt, r.stdout, r.stderr


ALLANTOOLS = """
import json, sys, time
import numpy as np, allantools
path, n = sys.argv[1], int(sys.argv[2])
y = np.load(path, mmap_mode="r")[:n].astype(np.float64)
t = time.perf_counter()
out = {}
for name in ("oadev", "mdev"):
    taus, dev, _, _ = getattr(allantools, name)(y, rate=1000.0, data_type="freq", taus="octave")
    out[name] = [list(map(float, taus)), list(map(float, dev))]
out["seconds"] = time.perf_counter() - t
# VmHWM, not ru_maxrss: the latter keeps the parent's peak across exec.
hwm = [l for l in open("/proc/self/status") if l.startswith("VmHWM:")][0]
out["peak_mib"] = int(hwm.split()[1]) / 1024.0
print(json.dumps(out))
"""


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--samples", type=float, default=2.592e8, help="72 h at 1 kHz")
    ap.add_argument("--allantools", type=float, nargs="*", default=[1e7, 3e7, 1e8])
    ap.add_argument("--text", action="store_true", help="also a text log (13 bytes a sample)")
    ap.add_argument("--gyro", default="target/host/gyro")
    ap.add_argument("--dir", default=None, help="where the logs go (default: a temporary directory)")
    a = ap.parse_args()
    n = int(a.samples)
    with tempfile.TemporaryDirectory(dir=a.dir) as d:
        p64, p32 = os.path.join(d, "log64.npy"), os.path.join(d, "log32.npy")
        ptxt = os.path.join(d, "log.txt") if a.text else None
        t = time.perf_counter()
        write_log(p64, p32, n)
        if ptxt:
            hours = n / 1000 / 3600
            child([a.gyro, "emulate", "--hours", str(hours), "--hz", "1000", "--flicker", "--rrw", "40", "-o", ptxt])
        print(f"wrote {n} samples ({n / 1000 / 3600:.1f} h at 1 kHz) in {time.perf_counter() - t:.0f} s", flush=True)
        ours = {}
        for label, path, extra in [("f64 .npy", p64, []), ("f32 .npy", p32, []), ("text", ptxt, ["--tau0", str(TAU0)])]:
            if path is None:
                continue
            cmd = [a.gyro, "allan", path, "--stream", "--dev", "oadev,mdev", "--fit", "--format", "json"]
            cmd += extra or ["--tau0", str(TAU0)]
            dt, out, err = child(cmd)
            size = os.path.getsize(path)
            cost = [l for l in err.splitlines() if "one pass" in l]
            print(f"gyro --stream, {label}: {size / 1e6:.0f} MB in {dt:.1f} s: {size / 1e6 / dt:.0f} MB/s; {cost[-1] if cost else ''}", flush=True)
            ours[label] = json.loads(out)
        for k in a.allantools:
            k = int(min(k, n))
            cmd = [sys.executable, "-c", ALLANTOOLS, p64, str(k)]
            dt, out, _ = child(cmd)
            at = json.loads(out)
            # The same first k samples through gyro, to compare values.
            head = os.path.join(d, f"head{k}.npy")
            np.save(head, np.load(p64, mmap_mode="r")[:k])
            took, mine, err = child([a.gyro, "allan", head, "--stream", "--dev", "oadev,mdev", "--tau0", str(TAU0), "--format", "json"])
            peak = [l.rsplit("peak memory ", 1)[-1] for l in err.splitlines() if "one pass" in l]
            mine = json.loads(mine)
            worst = 0.0
            for c in mine["curves"]:
                taus, devs = at[c["deviation"]]
                for p in c["points"]:
                    for tau, dv in zip(taus, devs):
                        if abs(tau / p["tau"] - 1) < 1e-9:
                            worst = max(worst, abs(p["dev"] / dv - 1))
            os.remove(head)
            print(
                f"octave OADEV + MDEV of {k} samples: allantools {at['seconds']:.1f} s computing (the array loaded), peak memory {at['peak_mib']:.0f} MiB; "
                f"gyro --stream {took:.1f} s in all, peak memory {peak[-1] if peak else '?'}: {at['seconds'] / took:.1f}x; "
                f"the deviations differ by at most {worst:.1e} (relative)",
                flush=True,
            )


if __name__ == "__main__":
    main()
