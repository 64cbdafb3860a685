"""An Allan plot of a board recording, per axis, with confidence intervals.

    python python/examples/allan_plot.py RECORDING.glk [OUT.png]

Reads the recording (gyro record's file), takes the longest run of samples
with all three axes valid, and draws each axis's overlapping Allan deviation
with its 68 % confidence interval (Greenhall's EDF, exact chi-squared), and
the IEEE 952 fit's angle random walk where the fit sees it.
"""

import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import gyro_analysis as ga  # noqa: E402


def longest_valid_run(rec):
    """The longest stretch of consecutive samples with every axis valid."""
    s = rec["samples"]
    good = s["valid"] == 0b111
    follows = np.concatenate([[False], np.diff(s["seq"].astype(np.int64)) == 1])
    best, start = (0, 0), None
    for i in range(len(good)):
        if not good[i]:
            start = None
            continue
        if start is None or not follows[i]:
            start = i
        if i + 1 - start > best[1] - best[0]:
            best = (start, i + 1)
    return s["rate_dps"][best[0] : best[1]]


def main(path, out="allan.png"):
    rec = ga.read_recording(path)
    rate_hz = 1.0 / rec["tau0_s"] if np.isfinite(rec["tau0_s"]) else 1000.0
    y = longest_valid_run(rec)
    fig, ax = plt.subplots(figsize=(7, 5))
    for a, name in enumerate("xyz"):
        d = ga.deviation(y[:, a], kind="oadev", rate=rate_hz, data_type="freq", taus="octave")
        err = np.vstack([d["devs"] - d["lo"], d["hi"] - d["devs"]])
        line = ax.errorbar(d["taus"], d["devs"], yerr=err, marker="o", ms=3, capsize=2, label=f"{name} OADEV")
        # What the board measured of its noise alone (the array's noise
        # probe, free of the vehicle's motion), at its three tau.
        nz = rec["noise"]
        mine = nz["axis"] == a
        if mine.any():
            tau = np.asarray(rec["noise_tau"]) / rate_hz
            ax.plot(
                tau,
                np.median(nz["sigma_dps"][mine], axis=0),
                "x--",
                color=line[0].get_color(),
                label=f"{name} noise (board's E-DAVAR, median)",
            )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("tau, s")
    ax.set_ylabel("Allan deviation, deg/s")
    c = rec["counts"]
    ax.set_title(
        f"{path}: {len(y)} samples at {rate_hz:g} Hz (frames {c['frames']}, corrupt {c['corrupt']})",
        fontsize=9,
    )
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f"{out}: {len(y)} samples, {c['frames']} frames, {c['corrupt']} corrupt")


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    main(*sys.argv[1:3])
