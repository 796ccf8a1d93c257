"""Measured series: the file formats, validation, and what a series can resolve."""

from pathlib import Path

import numpy as np
import pytest

import vibinverse as vi
from vibinverse.errors import DataError, InputError, VibinverseError
from vibinverse.io.builtin import builtin_scene
from vibinverse.io.series import Series, check_resolves, load_series, validate


def test_csv_with_comments_truth_and_gaps(tmp_path):
    p = tmp_path / "d.csv"
    rows = "\n".join(f"{0.01 * i},{'' if i == 7 else np.sin(i)},{np.sin(i)}" for i in range(40))
    p.write_text('# vibinverse simulate\n# scene: {"a": 1}\ntime,intensity,intensity_clean\n' + rows + "\n")
    s = load_series(p)
    assert s.scene == {"a": 1} and s.n_gaps == 1 and s.uniform and s.fs == pytest.approx(100.0)
    np.save(tmp_path / "d.npy", np.column_stack([s.time, s.intensity]))
    np.savez(tmp_path / "d.npz", time=s.time, intensity=s.intensity)
    import xarray as xr

    xr.Dataset({"intensity": ("time", s.intensity)}, coords={"time": s.time}).to_netcdf(
        tmp_path / "d.nc", engine="h5netcdf"
    )
    for name in ("d.npy", "d.npz", "d.nc"):
        other = load_series(tmp_path / name)
        np.testing.assert_array_equal(other.time, s.time)
        assert other.n_gaps == 1


@pytest.mark.parametrize(
    "t, x, message",
    [
        (np.r_[0.0, 2.0, 1.0, np.arange(3, 30.0)], np.zeros(30), "strictly increasing"),
        (np.arange(30.0), np.r_[np.inf, np.zeros(29)], "infinite"),
        (np.arange(5.0), np.zeros(5), "at least 16"),
        (np.arange(30.0), np.r_[np.zeros(10), np.full(20, np.nan)], "valid samples"),
    ],
)
def test_bad_series(t, x, message):
    with pytest.raises(VibinverseError, match=message):
        validate(t, x)


@pytest.mark.parametrize(
    "t, message",
    [
        (30.0 - np.arange(30.0), r"^data: time must be strictly increasing \(sample 1: 29 after 30\)$"),
        (np.r_[np.arange(10.0), 9.0, np.arange(11.0, 30.0)], r"\(sample 10: 9 after 9\)$"),
        # stamps that print alike at 6 digits are written with the digits that tell them apart
        (
            1e5 + np.r_[np.arange(10) * 1e-3, 9e-3 - 1e-9, np.arange(11, 30) * 1e-3],
            r"100000\.008999999 after 100000\.009",
        ),
    ],
)
def test_stamps_that_do_not_increase_are_one_line_naming_the_sample_and_both_stamps(t, message):
    with pytest.raises(DataError, match=message) as err:
        validate(t, np.sin(np.arange(t.size)))
    assert "\n" not in str(err.value)


def test_irregular_stamps_are_accepted_and_described():
    """Jitter of +-20 % of a frame and 10 % dropped frames: not uniform, and described (median
    step, jitter as the RMS deviation from the regular grid, dropped frames) by describe() and in
    the notes; a drifting clock is a grid; uniform stamps (within UNIFORM_RTOL) get no note."""
    from vibinverse.io.file_basics import UNIFORM_RTOL
    from vibinverse.io.series import sampling_summary

    rng = np.random.default_rng(0)
    n, dt = 4000, 0.005
    keep = rng.random(n) >= 0.1
    jitter = rng.uniform(-0.2, 0.2, n)
    t = ((np.arange(n) + jitter) * dt)[keep]
    s = validate(t, np.sin(t), "jittered")
    assert not s.uniform
    step, rms, dropped = sampling_summary(s.time)
    inside = np.flatnonzero(keep)
    assert dropped == inside[-1] - inside[0] + 1 - keep.sum()  # the frames missing inside the record
    assert rms == pytest.approx(0.2 / np.sqrt(3), rel=0.05)  # uniform in +-0.2: rms 0.2 / sqrt(3)
    line = f"irregular sampling: median step {step:.6g} s, jitter {100 * rms:.3g} % (rms), {dropped} dropped frames"
    assert line in s.describe() and s.notes == [f"time: {line}"]
    # a clock that runs 0.1 % fast from 5 s on, frames dropped: a grid, no jitter
    clock = validate(5.0 + np.flatnonzero(keep) * dt * 1.001, np.sin(np.arange(keep.sum())))
    assert sampling_summary(clock.time)[1:] == (pytest.approx(0.0, abs=1e-9), dropped)
    almost = validate(
        np.arange(100) * 0.01 + 0.5 * UNIFORM_RTOL * 0.01 * (-1.0) ** np.arange(100), np.sin(np.arange(100.0))
    )
    assert almost.uniform and almost.notes == [] and "uniform at" in almost.describe()
    off = validate(np.arange(100) * 0.01 + 2 * UNIFORM_RTOL * 0.01 * (-1.0) ** np.arange(100), np.sin(np.arange(100.0)))
    assert not off.uniform and "irregular sampling" in off.notes[0]


def test_series_too_short_or_too_slow_for_a_frequency():
    s = validate(np.arange(100) * 0.01, np.sin(np.arange(100)))
    with pytest.raises(VibinverseError, match="Nyquist"):
        check_resolves(s, 60.0, "drive_frequency")
    with pytest.raises(VibinverseError, match="1 cycle"):
        check_resolves(s, 0.9, "tilt_frequency")  # 0.89 cycles in 0.99 s
    check_resolves(s, 1.02, "tilt_frequency")  # one cycle is enough to be fitted (and flagged: FEW_CYCLES)


# ------------------------------------------------------------------ files and values that are not a series

CORPUS = Path(__file__).resolve().parents[2] / "corpus" / "data"
T = np.arange(40) * 0.01
X = np.sin(2 * np.pi * 5 * T)


def _nc(path, intensity=X, time=T, time_attrs=None, coords=True):
    import xarray as xr

    ds = (
        xr.Dataset({"intensity": ("time", intensity)}, coords={"time": ("time", time, time_attrs or {})})
        if coords
        else xr.Dataset({"intensity": ("i", intensity)})
    )
    # complex values are not netCDF: h5netcdf writes them only when told the file may be invalid
    ds.to_netcdf(path, engine="h5netcdf", invalid_netcdf=np.iscomplexobj(intensity))
    return path


BAD_FILES = {
    "text.npy": (lambda p: np.save(p, np.array([["a", "b"]] * 20)), "text .*real numbers are needed"),
    "text.npz": (lambda p: np.savez(p, time=T, intensity=np.array(["b"] * 40)), "intensity holds text"),
    "complex.npz": (lambda p: np.savez(p, time=T, intensity=X + 1j), "intensity holds complex values"),
    "complex.npy": (lambda p: np.save(p, np.column_stack([T, X + 0.5j])), "complex values"),
    "bool.npy": (lambda p: np.save(p, np.ones((40, 2), bool)), "booleans"),
    "bool.npz": (lambda p: np.savez(p, time=T, intensity=X > 0), "intensity holds booleans"),
    "object.npy": (lambda p: np.save(p, np.array([[1, 2]] * 20, dtype=object), allow_pickle=True), "Python objects"),
    "scalar.npy": (lambda p: np.save(p, np.array(3.0)), r"N x 2 array .*got shape \(\)"),
    "scalar.npz": (lambda p: np.savez(p, time=np.array(1.0), intensity=np.array(2.0)), "1-D"),
    "three_columns.npy": (
        lambda p: np.save(p, np.column_stack([T, X, X])),
        r"exactly 2 columns \(time, intensity\), got 3",
    ),
    "transposed.npy": (lambda p: np.save(p, np.vstack([T, X])), r"exactly 2 columns .*transpose"),
    "dates.npz": (lambda p: np.savez(p, time=np.datetime64("2024-01-01") + np.arange(40), intensity=X), "dates"),
    "truncated.npz": (lambda p: p.write_bytes(b"PK\x03\x04 not a zip"), "cannot read"),
    "text_time.nc": (lambda p: _nc(p, time=np.array([f"t{i}" for i in range(40)])), "time holds text"),
    "text_intensity.nc": (lambda p: _nc(p, intensity=np.array(["a"] * 40)), "intensity holds text"),
    "complex.nc": (lambda p: _nc(p, intensity=X + 1j), "complex values"),
    "no_time.nc": (lambda p: _nc(p, coords=False), "no variable 'time'"),
    "furlongs.nc": (lambda p: _nc(p, time_attrs={"units": "furlongs"}), "time units 'furlongs'"),
    "a_directory.csv": (lambda p: p.mkdir(), "is a directory"),
}


@pytest.mark.parametrize("name", sorted(BAD_FILES))
def test_a_file_that_is_not_a_series_is_one_line(name, tmp_path):
    make, message = BAD_FILES[name]
    path = tmp_path / name
    make(path)
    with pytest.raises(DataError, match=message) as err:
        load_series(path)
    assert "\n" not in str(err.value) and str(err.value).startswith("data: ")


@pytest.mark.parametrize("path", sorted(CORPUS.glob("*_*.csv")), ids=lambda p: p.name)
def test_the_csv_corpus(path):
    """ok_*: a BOM, CRLF line ends and a quoted header, extra named columns read as they should;
    bad_*: one line each."""
    if path.name.startswith("ok_"):
        s = load_series(path)
        np.testing.assert_allclose(s.time, T)
        np.testing.assert_allclose(s.intensity, X, atol=1e-6)
        return
    with pytest.raises(DataError) as err:
        load_series(path)
    assert "\n" not in str(err.value) and str(err.value).startswith("data: ")


def test_csv_extra_cells_and_not_netcdf_files_are_named():
    with pytest.raises(DataError, match=r"line 2: 3 cells; the header names 2 \(time,intensity\)"):
        load_series(CORPUS / "bad_extra_cells.csv")
    with pytest.raises(DataError, match="intensity has infinite values"):
        load_series(CORPUS / "bad_inf.csv")
    for name in ("random_bytes.nc", "text.nc"):
        with pytest.raises(DataError, match=f"{name} is not a netCDF"):
            load_series(CORPUS / name)


def test_netcdf_cf_times_are_read_in_seconds(tmp_path):
    """A CF time axis ("milliseconds since 2024-01-01") is converted to seconds from its epoch; a
    plain numeric time (no units) is in seconds."""
    ms = load_series(
        _nc(tmp_path / "ms.nc", time=1000 * (T + 3.0), time_attrs={"units": "milliseconds since 2024-01-01"})
    )
    np.testing.assert_allclose(ms.time, T + 3.0)
    s = load_series(_nc(tmp_path / "s.nc", time=T + 3.0, time_attrs={"units": "s"}))
    np.testing.assert_allclose(s.time, T + 3.0)
    h = load_series(_nc(tmp_path / "h.nc", time=T / 3600, time_attrs={"units": "hours"}))
    np.testing.assert_allclose(h.time, T, atol=1e-12)


@pytest.mark.parametrize(
    "x, message",
    [
        (np.ones(40), r"data: the intensity is constant \(all 40 valid samples are 1\); nothing to fit"),
        (np.r_[np.full(39, 2.0), np.nan], "constant"),
        (1.0 + 1e-17 * X, "constant"),  # differs only in rounding
        (1e300 * X, r"data: intensity .*e\+299 at sample \d+ is outside the allowed range \[-1e\+100, 1e\+100\]"),
        (1e-300 * X, r"varies by only .*; at least 1e-100 is needed"),
        (X + 0.5j, "complex values"),
        (np.array(["1.0"] * 40), "text"),
        (X > 0, "booleans"),
    ],
)
def test_values_that_cannot_be_fitted(x, message):
    with pytest.raises(DataError, match=message) as err:
        validate(T, x)
    assert "\n" not in str(err.value)


def test_a_time_axis_outside_float_range_is_refused():
    with pytest.raises(DataError, match=r"time .* outside the allowed range"):
        validate(1e300 + T * 1e290, X)


@pytest.mark.parametrize("scene", ["roof_elastic", "roof_frame"])
def test_fitting_a_constant_series_is_one_line(scene):
    """Today's math domain error (plate scene) and garbage fit (frame scene) become one line."""
    table = vi.load_scene(builtin_scene(scene), ["noise.sigma=0.6"])
    t = np.arange(800) * 0.005
    with pytest.raises(DataError, match="constant"):
        vi.fit(vi.series(t, np.ones(t.size)), table, method="spectral")


def test_real_data_scales_are_accepted():
    """What a sensor gives: counts near 6e4 with a spread of a few counts, radiances near 1e-9,
    time stamps in seconds of the epoch."""
    rng = np.random.default_rng(0)
    validate(T, 60000 + np.round(3 * rng.standard_normal(T.size)))
    validate(T, 1e-9 * (1 + 1e-3 * X))
    validate(1.7e9 + T, X)
    validate(T, 1e90 * X)


# ------------------------------------------------------------------ tables: delimiters, named columns, dates, fs

ROOF_ELASTIC = Path(__file__).resolve().parents[3] / "examples" / "scenes" / "roof_elastic.toml"
START = np.datetime64("2024-06-21T09:30:00", "us")


@pytest.fixture(scope="module")
def plate(tmp_path_factory):
    """A short simulated plate series, its canonical CSV (`vibinverse simulate`'s) and that CSV's
    spectral fit (medians)."""
    from vibinverse.io.simulation import write_series_csv

    table = vi.load_scene(ROOF_ELASTIC)
    obs = vi.simulate(table, seed=1)
    folder = tmp_path_factory.mktemp("plate")
    write_series_csv(folder / "canonical.csv", obs, table, 1, "test")
    return obs, folder, _medians(folder / "canonical.csv")


def _medians(data, **options) -> dict[str, float]:
    series = load_series(data, **options) if options else data
    result = vi.fit(series, ROOF_ELASTIC, method="spectral")
    return {k: v["median"] for k, v in result.summary()["parameters"].items()}


def _stamps(t: np.ndarray) -> np.ndarray:
    return START + np.round(t * 1e6).astype("timedelta64[us]")  # ISO date-times to the microsecond


def _same_fit(got: dict[str, float], want: dict[str, float], rtol: float = 1e-9) -> None:
    assert got.keys() == want.keys()
    for name, value in want.items():
        assert got[name] == pytest.approx(value, rel=rtol, abs=1e-300), name


def test_semicolon_csv_with_iso_times_and_named_columns_fits_like_the_csv(plate):
    obs, folder, want = plate
    p = folder / "stamped.csv"
    rows = "".join(f"{s};{float(x)!r};7\n" for s, x in zip(np.datetime_as_string(_stamps(obs.time)), obs.intensity))
    p.write_text("# from a logger\nStamp;Pixel (counts);Other\n" + rows)
    s = load_series(p, time_column="stamp", value_column="pixel (counts)")
    assert s.notes == ["time: seconds since 2024-06-21T09:30:00"]
    np.testing.assert_allclose(s.time, obs.time, rtol=0, atol=1e-6)  # what the rounding to microseconds allows
    _same_fit(_medians(s), want)  # at 1 kHz the microsecond stamps are exact


def test_values_only_with_fs_fits_like_the_csv(plate):
    obs, folder, want = plate
    p = folder / "values.csv"
    p.write_text("intensity\n" + "".join(f"{float(x)!r}\n" for x in obs.intensity))
    _same_fit(_medians(p, fs=1000.0), want)
    q = folder / "volts.csv"  # one column: it is the value column whatever its name
    q.write_text("Volts\n" + "".join(f"{float(x)!r}\n" for x in obs.intensity))
    np.testing.assert_array_equal(load_series(q, fs=1000.0).intensity, obs.intensity)


def test_netcdf_with_datetime64_time_and_units_fits_like_the_csv(plate):
    import xarray as xr

    obs, folder, want = plate
    p = folder / "dated.nc"
    stamps = START.astype("datetime64[ns]") + np.round(obs.time * 1e9).astype("timedelta64[ns]")
    xr.Dataset({"intensity": ("time", obs.intensity, {"units": "mV"})}, coords={"time": stamps}).to_netcdf(
        p, engine="h5netcdf"
    )
    s = load_series(p)
    assert any(n.startswith("time: seconds since 2024-06-21") for n in s.notes)
    assert any(n.startswith("intensity units: mV") for n in s.notes)
    np.testing.assert_array_equal(s.intensity, obs.intensity)  # units noted, values kept
    _same_fit(_medians(s), want)


def test_parquet_fits_like_the_csv(plate):
    pd = pytest.importorskip("pandas")
    pytest.importorskip("pyarrow")
    obs, folder, want = plate
    p = folder / "d.parquet"
    pd.DataFrame({"Time": obs.time, "INTENSITY": obs.intensity, "other": 1.0}).to_parquet(p)
    _same_fit(_medians(p), want)
    q = folder / "dated.parquet"
    pd.DataFrame({"when": _stamps(obs.time), "v": obs.intensity}).to_parquet(q)
    s = load_series(q, time_column="when", value_column="v")
    assert s.notes == ["time: seconds since 2024-06-21T09:30:00"]
    np.testing.assert_allclose(s.time, obs.time, rtol=0, atol=1e-6)
    # one column besides the time: the value column, whatever its name
    np.testing.assert_array_equal(load_series(q, time_column="when").intensity, s.intensity)
    with pytest.raises(DataError, match=r"no value column intensity .*value_column.*; its columns: when,v,w"):
        pd.DataFrame({"when": _stamps(obs.time), "v": obs.intensity, "w": 1.0}).to_parquet(q)
        load_series(q, time_column="when")
    r = folder / "indexed.parquet"  # a named index (pandas' usual time axis) is a column
    pd.DataFrame({"intensity": obs.intensity}, index=pd.Index(obs.time, name="time")).to_parquet(r)
    np.testing.assert_array_equal(load_series(r).time, obs.time)


def test_tsv_and_whitespace_tables_read_as_the_csv(tmp_path):
    for name, sep in (("d.tsv", "\t"), ("d.txt", "   ")):
        p = tmp_path / name
        rows = "".join(f"{float(t)!r}{sep}{float(x)!r}\n" for t, x in zip(T, X))
        p.write_text(f"# tab or spaces\ntime{sep}intensity\n" + rows)
        s = load_series(p)
        np.testing.assert_array_equal(s.time, T)
        np.testing.assert_array_equal(s.intensity, X)
    gap = tmp_path / "gap.tsv"  # a tab row ending in an empty cell is a gap
    gap.write_text("time\tintensity\n" + "".join(f"{t}\t{'' if i == 3 else x}\n" for i, (t, x) in enumerate(zip(T, X))))
    assert load_series(gap).n_gaps == 1


BAD_TABLES = {
    "two_values.csv": (
        "time,left,right\n" + "".join(f"{t},{x},{x}\n" for t, x in zip(T, X)),
        {},
        r"no value column intensity \(choose it with value_column=, --value-column\); its columns: time,left,right",
    ),
    "decimal_commas.csv": (
        "time;intensity\n" + "".join(f"{t:.2f};{x:.6f}\n".replace(".", ",") for t, x in zip(T, X)),
        {},
        r"line 2: '0,00' has a decimal comma; write decimal points",
    ),
    "fs_and_time.csv": (
        "time,intensity\n" + "".join(f"{t},{x}\n" for t, x in zip(T, X)),
        {"fs": 100.0},
        r"has a time column \(time\) and fs was given: the time is ambiguous",
    ),
    "no_such_column.csv": (
        "time,intensity\n" + "".join(f"{t},{x}\n" for t, x in zip(T, X)),
        {"value_column": "volts"},
        r"no value column 'volts' .*; its columns: time,intensity",
    ),
    "bad_stamp.csv": (
        "time,intensity\n2024-06-21T09:30:00,1\n2024-06-21T09:30:01,2\nlater,3\n",
        {},
        r"line 4: not an ISO 8601 date-time: later",
    ),
    "zero_fs.csv": ("intensity\n" + "".join(f"{x}\n" for x in X), {"fs": 0.0}, r"fs: 0.0 Hz; allowed range \(0, inf\)"),
    "nan_fs.csv": ("intensity\n" + "".join(f"{x}\n" for x in X), {"fs": float("nan")}, r"fs: nan Hz"),
}


@pytest.mark.parametrize("name", sorted(BAD_TABLES))
def test_a_table_that_is_ambiguous_is_refused_in_one_line(name, tmp_path):
    text, options, message = BAD_TABLES[name]
    p = tmp_path / name
    p.write_text(text)
    with pytest.raises(DataError, match=message) as err:
        load_series(p, **options)
    assert "\n" not in str(err.value) and str(err.value).startswith("data: ")


def test_table_options_on_arrays_are_refused(tmp_path):
    np.save(tmp_path / "d.npy", np.column_stack([T, X]))
    with pytest.raises(DataError, match=r"apply to CSV/TSV and Parquet tables, not \.npy files"):
        load_series(tmp_path / "d.npy", fs=100.0)


def test_cli_fit_reads_named_columns_and_fs(tmp_path, plate):
    import contextlib
    import io
    import json

    from vibinverse.cli import main

    obs, _, want = plate
    p = tmp_path / "v.csv"
    p.write_text("frame;Pixel\n" + "".join(f"{i};{float(x)!r}\n" for i, x in enumerate(obs.intensity)))
    out, err = io.StringIO(), io.StringIO()
    args = ["fit", str(p), "--scene", str(ROOF_ELASTIC), "--method", "spectral", "--no-progress", "-q"]
    files = ["-o", str(tmp_path)]
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        assert main([*args, "--value-column", "pixel", "--fs", "1000", *files]) == 0
        assert main([*args, "--fs", "1000", *files]) == 2  # two columns, none named intensity
    summary = json.loads((tmp_path / "summary.json").read_text())
    _same_fit({k: v["median"] for k, v in summary["parameters"].items()}, want)
    lines = err.getvalue().strip().splitlines()
    assert len(lines) == 1 and "no value column intensity" in lines[0] and "--value-column" in lines[0]


def test_a_series_is_one_value_per_stamp():
    """A table of two columns given as the intensity, or a length that does not match the stamps,
    is a one-line InputError naming both shapes, not an index error deep in a fit."""
    with pytest.raises(InputError, match=r"got shapes \(4,\) and \(4, 2\)"):
        Series(np.arange(4.0), np.zeros((4, 2)), "table")
    with pytest.raises(InputError, match=r"\(4,\) and \(3,\)"):
        Series(np.arange(4.0), np.zeros(3), "short")
    s = Series([0, 1, 2], [1, 2, 3], "lists")
    assert s.time.dtype == float and s.intensity.dtype == float
