"""gyro_analysis against allantools (same arrays, 1e-9 relative, the same
tau list and ns), against Stable32's tables for PHASE.DAT (the ones
``cargo test -p gyro-tool`` checks), and every error path."""

import pathlib

import allantools
import numpy as np
import pytest

import gyro_analysis as ga

KINDS = ["adev", "oadev", "mdev", "tdev", "hdev", "ohdev", "totdev"]
TAUS = [None, "octave", "decade", "all", [0.1, 0.25, 1.0, 3.3, 7.5, 40.0, 1e9]]
STABLE32 = pathlib.Path(__file__).resolve().parents[2] / "gyro-tool" / "tests" / "stable32"


def noise(kind, n, seed):
    """White, flicker (1/f, by an FFT shaping) or random-walk frequency noise."""
    rng = np.random.default_rng(seed)
    w = rng.standard_normal(n)
    if kind == "white":
        return w
    if kind == "random walk":
        return np.cumsum(w) * 1e-2 + w
    f = np.fft.rfftfreq(n)
    f[0] = f[1]
    return np.fft.irfft(np.fft.rfft(w) / np.sqrt(f), n)


@pytest.mark.parametrize("shape", ["white", "flicker", "random walk"])
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("data_type", ["freq", "phase"])
def test_equals_allantools(shape, kind, data_type):
    y = noise(shape, 3000, seed=len(shape) + KINDS.index(kind))
    for taus in TAUS:
        want = getattr(allantools, kind)(y, rate=20.0, data_type=data_type, taus=taus)
        got = getattr(ga, kind)(y, rate=20.0, data_type=data_type, taus=taus)
        assert len(got[0]) == len(want[0]) > 0, (taus, len(got[0]), len(want[0]))
        np.testing.assert_array_equal(got[3], want[3])
        np.testing.assert_allclose(got[0], want[0], rtol=1e-12, atol=0)
        np.testing.assert_allclose(got[1], want[1], rtol=1e-9, atol=0)
        np.testing.assert_allclose(got[2], want[2], rtol=1e-9, atol=0)


FAMILY = ["mtotdev", "ttotdev", "htotdev", "mtie", "tierms", "theo1"]


@pytest.mark.parametrize("shape", ["white", "flicker", "random walk"])
@pytest.mark.parametrize("kind", FAMILY)
@pytest.mark.parametrize("data_type", ["freq", "phase"])
def test_the_total_family_and_tie_equal_allantools(shape, kind, data_type):
    # allantools' total estimators are Python loops: a short record.
    y = noise(shape, 400, seed=len(shape) + FAMILY.index(kind))
    for taus in [None, "octave", [0.05, 0.1, 0.35, 1.0, 2.5, 6.0]]:
        want = getattr(allantools, kind)(y, rate=20.0, data_type=data_type, taus=taus)
        got = getattr(ga, kind)(y, rate=20.0, data_type=data_type, taus=taus)
        assert len(got[0]) == len(want[0]) > 0, (taus, len(got[0]), len(want[0]))
        np.testing.assert_array_equal(got[3], want[3])
        np.testing.assert_allclose(got[0], want[0], rtol=1e-12, atol=0)
        np.testing.assert_allclose(got[1], want[1], rtol=1e-9, atol=0)
        np.testing.assert_allclose(got[2], want[2], rtol=1e-9, atol=0)


@pytest.mark.parametrize("shape", ["white", "flicker", "random walk"])
def test_theobr_and_theoh_are_allantools_theo1_and_oadev_by_sp1065(shape):
    # allantools has neither: its own Theo1 and OADEV combined by NIST
    # SP 1065 eq. 31 (the bias ratio over the record's first tenth) and
    # eq. 32 (OADEV to a tenth of the record, TheoBR beyond).
    x = np.cumsum(noise(shape, 600, seed=3))
    n = len(x)
    k = int(np.floor(0.1 * n / 3 - 3))
    a = allantools.oadev(x, rate=1.0, data_type="phase", taus=[9 + 3 * i for i in range(k + 1)])[1]
    t = allantools.theo1(x, rate=1.0, data_type="phase", taus=[12 + 4 * i for i in range(k + 1)])[1]
    ratio = np.mean(a**2 / t**2)
    ms = [10, 16, 32, 64, 128, 256, 598]
    want = allantools.theo1(x, rate=1.0, data_type="phase", taus=ms)
    got = ga.theobr(x, rate=1.0, data_type="phase", taus=ms)
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[3], want[3])
    np.testing.assert_allclose(got[1], want[1] * np.sqrt(ratio), rtol=1e-9, atol=0)
    # TheoH: factor m at m tau0; beyond 10 m > N - 1, Theo1's 4m/3.
    low, high = [1, 2, 5, 20, 59], [60, 66, 150, 300, 447]
    got = ga.theoh(x, rate=1.0, data_type="phase", taus=low + high + [61, 62])
    np.testing.assert_array_equal(got[0], low + high)  # 61, 62: no value there
    o = allantools.oadev(x, rate=1.0, data_type="phase", taus=low)[1]
    b = allantools.theo1(x, rate=1.0, data_type="phase", taus=[4 * m // 3 for m in high])[1]
    np.testing.assert_allclose(got[1], np.concatenate([o, b * np.sqrt(ratio)]), rtol=1e-9, atol=0)
    # A keyword grid's long factors move to multiples of 3, as the CLI's.
    octave = ga.theoh(x, rate=1.0, data_type="phase", taus="octave")[0]
    np.testing.assert_array_equal(octave, [1, 2, 4, 8, 16, 32, 63, 129, 255])
    with pytest.raises(ValueError, match="at most 20000 phase points"):
        ga.theobr(np.zeros(20001), rate=1.0, data_type="phase", taus=[10])


@pytest.mark.parametrize("shape", ["white", "flicker", "random walk"])
def test_gradev_equals_allantools_on_phase_with_holes(shape):
    x = np.cumsum(noise(shape, 3000, seed=11))
    x[400:430] = np.nan
    x[1777] = np.nan
    x[2000:2600] = np.nan
    for taus in [None, "octave", [0.05, 0.1, 0.35, 1.0, 2.5, 6.0]]:
        want = allantools.gradev(x, rate=20.0, data_type="phase", taus=taus)
        got = ga.gradev(x, rate=20.0, data_type="phase", taus=taus)
        assert len(got[0]) == len(want[0]) > 0
        np.testing.assert_array_equal(got[3], want[3])
        np.testing.assert_allclose(got[0], want[0], rtol=1e-12, atol=0)
        np.testing.assert_allclose(got[1], want[1], rtol=1e-9, atol=0)
        # allantools' bounds are NaN (two arguments swapped); ours bracket.
        lo, hi = got[2]
        assert np.all(lo < got[1]) and np.all(got[1] < hi)


def test_gradev_of_rates_skips_only_the_terms_a_missing_rate_reaches():
    y = noise("white", 2000, seed=5)
    whole = ga.oadev(y, rate=10.0, data_type="freq", taus=[0.1, 0.4, 1.6])
    same = ga.gradev(y, rate=10.0, data_type="freq", taus=[0.1, 0.4, 1.6])
    np.testing.assert_allclose(same[1], whole[1], rtol=1e-9)
    np.testing.assert_array_equal(same[3], whole[3])
    y[700] = np.nan
    holed = ga.gradev(y, rate=10.0, data_type="freq", taus=[0.1, 0.4, 1.6])
    # m = 1, 4, 16: 2m terms reach the missing rate.
    np.testing.assert_array_equal(holed[3], whole[3] - 2 * np.array([1, 4, 16]))


def test_phase_and_frequency_convert_as_allantools_converts():
    y = noise("random walk", 500, seed=2) + 3.0
    np.testing.assert_allclose(ga.frequency2phase(y, 50.0), allantools.frequency2phase(y, 50.0), rtol=1e-12, atol=1e-15)
    x = np.cumsum(y)
    np.testing.assert_allclose(ga.phase2frequency(x, 50.0), allantools.phase2frequency(x, 50.0), rtol=1e-12)
    # There and back: the rates less their mean.
    np.testing.assert_allclose(ga.phase2frequency(ga.frequency2phase(y, 50.0), 50.0), y - y.mean(), atol=1e-12)


VECTORS = pathlib.Path(__file__).resolve().parents[2] / "gyro-tool" / "tests" / "vectors"


def test_robot_logs_read_as_the_cli_reads_them():
    ulog = ga.read_log(VECTORS / "ulog" / "sample_log_small.ulg")
    assert ulog["names"] == ["sensor_combined.0.x", "sensor_combined.0.y", "sensor_combined.0.z"]
    # One dropout at the start, put back as NaN on the time grid.
    assert ulog["rates"].shape[1] == 3 and np.isnan(ulog["rates"]).any()
    for bag, step in [
        (VECTORS / "ros1" / "imu.bag", 0.01),
        (VECTORS / "ros2" / "imu_bag", 0.005),
        (VECTORS / "ros2" / "imu_bag_db3", 0.005),
    ]:
        log = ga.read_log(bag)
        want = np.loadtxt(bag.parent / "expected.csv", delimiter=",", skiprows=1)
        assert abs(log["tau0"] - step) < 1e-12
        assert len(log["gaps"]) == 1
        rates = log["rates"][~np.isnan(log["rates"][:, 0])]
        np.testing.assert_array_equal(rates, np.degrees(want[:, 1:]))
        # The gap's samples are NaN: gradev takes the log as it is.
        g = ga.gradev(log["rates"][:, 2], rate=1 / log["tau0"], data_type="freq", taus=[step])
        # m = 1: N - 1 terms on the grid, two of them touching the gap.
        assert g[3][0] == len(log["rates"]) - 3
    with pytest.raises(ValueError, match="no column"):
        ga.read_log(VECTORS / "ros1" / "imu.bag", columns=["/imu.w"])


def test_an_ardupilot_log_reads_as_pymavlink_reads_it():
    # pymavlink's own test log; expected.csv is what its DFReader decodes.
    path = VECTORS / "dataflash" / "test.BIN"
    want = np.genfromtxt(path.parent / "expected.csv", delimiter=",", skip_header=1, usecols=(1, 2, 3, 4, 5))
    for inst in (0, 1):
        cols = [f"IMU.{inst}.{a}" for a in "xyz"]
        log = ga.read_log(path, columns=cols)
        assert log["names"] == cols
        rates = log["rates"][~np.isnan(log["rates"][:, 0])]
        np.testing.assert_array_equal(rates, np.degrees(want[want[:, 0] == inst][:, 2:]))
    # Both IMUs' z as one replay's chips (the log stamps them alike).
    with pytest.raises(ValueError, match="one topic instance a read"):
        ga.read_log(path, columns=["IMU.0.z", "IMU.1.z"])
    log = ga.read_log(path, columns=["IMU.0.z", "IMU.1.z"], chips=True)
    z = log["rates"][~np.isnan(log["rates"][:, 0])]
    np.testing.assert_array_equal(z[:, 1], np.degrees(want[want[:, 0] == 1][:, 4]))
    fused = ga.replay(z)["fused"]
    assert np.isfinite(fused).all()


def table(name):
    """(AF, #, sigma) rows of a Stable32 table."""
    rows = []
    for line in (STABLE32 / name).read_text().splitlines():
        f = line.split()
        if len(f) >= 6 and f[0].isdigit():
            rows.append((int(f[0]), int(f[2]), float(f[5])))
    return rows


@pytest.mark.parametrize("kind", KINDS)
def test_matches_stable32_on_phase_dat(kind):
    lines = (STABLE32 / "PHASE.DAT").read_text().splitlines()
    x = np.array([float(v) for v in lines if v.strip() and not v.startswith("#")])
    assert len(x) == 1001
    rows = table(f"phase_dat_{kind}.txt")
    assert rows
    taus, devs, _, ns = getattr(ga, kind)(x, rate=1.0, taus=[af for af, _, _ in rows])
    got = dict(zip(taus.astype(int), zip(devs, ns)))
    for af, terms, sigma in rows:
        dev, n = got[af]
        half = 0.5e-4 * 10 ** np.floor(np.log10(abs(sigma)))
        assert abs(dev - sigma) <= half + 1e-7 * abs(sigma), (kind, af, dev, sigma)
        assert n == terms, (kind, af, n, terms)


def test_deviation_gives_edf_intervals_and_noise_type():
    y = noise("white", 20000, seed=3)
    d = ga.deviation(y, "oadev", rate=100.0, data_type="freq", taus="octave")
    assert set(d) == {"taus", "devs", "lo", "hi", "edf", "alpha", "ns"}
    want = allantools.oadev(y, rate=100.0, data_type="freq", taus=d["taus"])
    np.testing.assert_allclose(d["devs"], want[1], rtol=1e-9)
    ok = ~np.isnan(d["lo"])
    assert ok[:8].all()
    assert (d["lo"][ok] < d["devs"][ok]).all() and (d["devs"][ok] < d["hi"][ok]).all()
    # White FM: alpha 0 where identified.
    alpha = d["alpha"][~np.isnan(d["alpha"])]
    assert len(alpha) > 5 and (alpha == 0).mean() > 0.8, alpha


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: ga.oadev([1.0, np.nan, 2.0, 3.0]), "sample 1 is not finite"),
        (lambda: ga.oadev(np.zeros(10), rate=0.0), "tau0 must be a finite number"),
        (lambda: ga.oadev(np.zeros(10), rate=-1.0), "tau0 must be a finite number"),
        (lambda: ga.oadev(np.zeros(10), data_type="frequency"), "expected \"phase\" or \"freq\""),
        (lambda: ga.oadev(np.zeros(10), taus="weekly"), "expected \"all\", \"octave\""),
        (lambda: ga.oadev(np.zeros(10), taus=[1.0, np.inf]), "not a finite number of seconds"),
        (lambda: ga.oadev(np.zeros((3, 4, 2))), "one-dimensional"),
        (lambda: ga.oadev(np.zeros((10, 0))), "has no column"),
        (lambda: ga.oadev([1.0]), "too few samples"),
        (lambda: ga.deviation(np.zeros(100), kind="bdev"), "expected adev, oadev"),
        (lambda: ga.deviation(np.zeros(100), confidence=1.5), "must lie in (0, 1)"),
    ],
)
def test_errors_are_value_errors_with_the_tools_messages(call, message):
    with pytest.raises(ValueError) as e:
        call()
    assert message in str(e.value)


def test_a_gyro_log_of_three_axes_gives_one_column_per_axis():
    y = np.column_stack([noise(s, 2000, seed=3) for s in ["white", "flicker", "random walk"]])
    for kind in ["oadev", "mtotdev", "mtie"]:
        t, d, e, n = getattr(ga, kind)(y, rate=100.0, data_type="freq", taus="octave")
        assert d.shape == e.shape == (len(t), 3)
        for k in range(3):
            one = getattr(ga, kind)(y[:, k], rate=100.0, data_type="freq", taus="octave")
            np.testing.assert_array_equal(one[0], t)
            np.testing.assert_array_equal(one[1], d[:, k])
            np.testing.assert_array_equal(one[3], n)


def test_long_inputs_and_lists():
    # A list works as an array does; a long input runs (without the GIL).
    y = noise("white", 200_000, seed=9)
    a = ga.oadev(list(y[:1000]), rate=1.0, data_type="freq")
    b = ga.oadev(y[:1000], rate=1.0, data_type="freq")
    np.testing.assert_array_equal(a[1], b[1])
    t, d, _, _ = ga.oadev(y, rate=1000.0, data_type="freq")
    assert len(t) == 17 and np.all(np.isfinite(d))


def test_dataset_is_allantools_dataset_with_intervals_fit_table_and_plot(tmp_path):
    at = pytest.importorskip("allantools")
    y = np.random.default_rng(7).standard_normal(20_000) + 0.01 * np.cumsum(np.random.default_rng(8).standard_normal(20_000))
    ours = ga.Dataset(data=y, rate=100.0, data_type="freq", taus="octave")
    theirs = at.Dataset(data=y, rate=100.0, data_type="freq", taus="octave")
    # Theo1 on a shorter log: allantools' takes minutes on 20 000 points.
    short = (ga.Dataset(data=y[:2000], rate=100.0, data_type="freq"), at.Dataset(data=y[:2000], rate=100.0, data_type="freq"))
    r, t = short[0].compute("theo1"), short[1].compute("theo1")
    np.testing.assert_allclose(r["stat"], t["stat"], rtol=1e-9)
    # Theo1's interval (Howe's EDF) brackets it where the noise type is
    # known; MTIE has no EDF model: no interval, said as NaN.
    lo, hi = short[0].out["stat_lo"], short[0].out["stat_hi"]
    known = np.isfinite(lo)
    assert known.any() and np.all(lo[known] < r["stat"][known]) and np.all(r["stat"][known] < hi[known])
    short[0].compute("mtie")
    assert np.isnan(short[0].out["stat_lo"]).all()
    for fn in ("oadev", "mdev", "totdev"):
        r, t = ours.compute(fn), theirs.compute(fn)
        assert set(t) <= set(r)
        np.testing.assert_allclose(r["taus"], t["taus"], rtol=1e-12)
        np.testing.assert_allclose(r["stat"], t["stat"], rtol=1e-9)
        np.testing.assert_array_equal(r["stat_n"], t["stat_n"])
        assert ours.out["stat_id"] == fn
        # The interval brackets the value wherever Stable32's factors reach.
        lo, hi, dev = ours.out["stat_lo"], ours.out["stat_hi"], ours.out["stat"]
        ok = np.isfinite(lo)
        assert ok.sum() >= len(dev) - 2 and (lo[ok] < dev[ok]).all() and (dev[ok] < hi[ok]).all()
    ours.compute("oadev")
    d = ga.deviation(y, "oadev", rate=100.0, data_type="freq", taus="octave")
    np.testing.assert_array_equal(ours.out["stat_edf"][: len(d["edf"])], d["edf"])
    fit = ours.fit()
    assert fit is ours.fit_result and "value" in fit
    # The drawn model is the fit's own (Terms::avar), at tau0 the data's.
    assert fit["model_taus"][0] == pytest.approx(0.01) and np.all(np.isfinite(fit["model_adev"]))
    np.testing.assert_allclose(fit["model_adev"][0], ours.out["stat"][0], rtol=0.2)
    path = tmp_path / "oadev.txt"
    ours.write_results(path, header_params={"source": "test"})
    table = np.loadtxt(path)
    assert table.shape == (len(ours.out["taus"]), 8)
    np.testing.assert_allclose(table[:, 1], ours.out["stat"], rtol=1e-4)
    pytest.importorskip("matplotlib")
    import matplotlib

    matplotlib.use("Agg")
    ax = ours.plot()
    png = tmp_path / "oadev.png"
    ax.figure.savefig(png)
    assert png.stat().st_size > 10_000
    with pytest.raises(ValueError, match="one of"):
        ours.compute("nodev")


def test_a_file_streams_to_the_in_memory_curves_and_fit(tmp_path):
    # 300 000 samples with a 1 MiB ring: the longer factors' lags come back
    # from the spill file. The same curves as the arrays give, the same fit.
    rng = np.random.default_rng(5)
    y = 0.05 + 0.1 * rng.standard_normal(300_000) + np.cumsum(1e-4 * rng.standard_normal(300_000))
    path = tmp_path / "soak.npy"
    np.save(path, np.column_stack([y, -y]))
    r = ga.allan_file(path, dev=["oadev", "mdev"], tau0=0.001, fit=True, memory_mib=1)
    assert r["names"] == ["c1", "c2"] and r["samples"] == y.size and r["tau0"] == 0.001
    for kind in ("oadev", "mdev"):
        want = ga.deviation(y, kind, rate=1000.0, data_type="freq", taus="octave")
        got = r["curves"]["c1"][kind]
        np.testing.assert_allclose(got["taus"], want["taus"], rtol=1e-12)
        np.testing.assert_allclose(got["devs"], want["devs"], rtol=1e-12)
        np.testing.assert_allclose(got["lo"], want["lo"], rtol=1e-9)
        np.testing.assert_array_equal(got["alpha"], want["alpha"])
        np.testing.assert_allclose(r["curves"]["c2"][kind]["devs"], want["devs"], rtol=1e-12)
    fit = ga.noise_fit(y, rate=1000.0)
    np.testing.assert_allclose(r["fits"]["c1"]["value"], fit["value"], rtol=1e-6, atol=1e-15)
    # A text log as the tool reads it, and the refusals.
    text = tmp_path / "soak.txt"
    np.savetxt(text, y[:20_000], header="z", comments="")
    # (TIE rms of rates: the phase as gyro builds it, the mean rate kept in
    # it, where allantools takes the mean out first.)
    t = ga.allan_file(text, dev="tierms", tau0=0.001)
    x = np.concatenate([[0.0], np.cumsum(np.loadtxt(text, skiprows=1) * 0.001)])
    want = ga.deviation(x, "tierms", rate=1000.0, data_type="phase", taus="octave")
    np.testing.assert_allclose(t["curves"]["z"]["tierms"]["devs"], want["devs"], rtol=1e-12)
    y[1000] = np.nan
    np.save(path, y)
    with pytest.raises(ValueError, match="sample 1000 .row 1001. is not finite"):
        ga.allan_file(path, tau0=0.001)
    with pytest.raises(ValueError, match="TOTDEV is not computed in one pass"):
        ga.allan_file(text, dev="totdev", tau0=0.001)
