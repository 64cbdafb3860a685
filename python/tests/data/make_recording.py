"""Makes ``highway.glk``: the first 120 000 bytes (cut at a frame's end) of
the board's link stream in pointing-eval's 30 deg/s highway run with faults
(emulated chips on their own clocks, through the firmware's drivers,
pipeline and link encoder), for the package's tests and example.

    python python/tests/data/make_recording.py   # from the repository root
"""

import pathlib
import subprocess
import tempfile

HERE = pathlib.Path(__file__).resolve().parent
KEEP = 120_000

with tempfile.TemporaryDirectory() as d:
    subprocess.run(
        [
            "cargo", "run", "-q", "--profile", "host", "-p", "evaluations", "--bin", "pointing-eval",
            "--", "--seconds", "4", "--realisations", "0", "--write", d,
        ],
        check=True,
        cwd=HERE.parents[2],
        stdout=subprocess.DEVNULL,
    )
    data = (pathlib.Path(d) / "highway.glk").read_bytes()
end = data.rindex(b"\x00", 0, KEEP) + 1
(HERE / "highway.glk").write_bytes(data[:end])
print(f"highway.glk: {end} of {len(data)} bytes")
