"""The series reader registry, and .npz files of named arrays (synthetic, and the real recordings of
shared/realdata-dev, skipped when absent)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from vibinverse.errors import DataError
from vibinverse.io.readers import FALLBACK, READERS, SeriesReader, reader_for
from vibinverse.io.series import load_series

REALDATA = Path(__file__).resolve().parents[3].parent / "shared" / "realdata-dev"
LIGO = REALDATA / "ligo_h1_gw150914" / "H-H1_LOSC_4_V2-1126259446-32.npz"
PLATE = REALDATA / "plate_sweep_force_acc"

N = 256
FS = 512.0
T = np.arange(N) / FS
FORCE, ACC, TRIGGER = np.sin(40 * T), np.cos(90 * T) + 0.1 * np.sin(7 * T), (np.arange(N) % 50 == 0).astype(float)


def one_line(err: pytest.ExceptionInfo) -> str:
    text = str(err.value)
    assert "\n" not in text and text.startswith("data: "), text
    return text


# -------------------------------------------------------------------------------------- registry


def test_every_format_has_one_registered_reader():
    assert {"npy", "npz", "netcdf", "parquet", "csv", "lvm"} <= set(READERS)
    assert all(isinstance(r, SeriesReader) and r.name == name for name, r in READERS.items())
    suffixes = [s for name, r in READERS.items() if name != FALLBACK for s in r.suffixes]
    assert len(suffixes) == len(set(suffixes))  # a suffix names one reader


@pytest.mark.parametrize(
    "name, head, reader",
    [
        ("a.npy", b"\x93NUMPY", "npy"),
        ("a.NPZ", b"PK\x03\x04", "npz"),
        ("a.nc", b"CDF\x01", "netcdf"),
        ("a.cdf", b"CDF\x01", "netcdf"),
        ("a.parquet", b"PAR1", "parquet"),
        ("a.lvm", b"LabVIEW Measurement\t\r\n", "lvm"),
        ("VI0.txt", b"LabVIEW Measurement,\n", "lvm"),  # by its first line, whatever the suffix
        ("a.csv", b"\xef\xbb\xbfLabVIEW Measurement\t\n", "lvm"),
        ("a.csv", b"time,intensity\n", "csv"),
        ("a.txt", b"time\tintensity\n", "csv"),
        ("a.weird", b"time;intensity\n", "csv"),  # anything else is read as a table
    ],
)
def test_the_reader_is_found_by_suffix_then_signature(tmp_path, name, head, reader):
    p = tmp_path / name
    p.write_bytes(head)
    assert reader_for(p).name == reader


def test_a_registered_reader_is_used_by_load_series(tmp_path, monkeypatch):
    from vibinverse.io import readers

    class Doubled(SeriesReader):
        name = "doubled"
        suffixes = (".dbl",)
        options = frozenset({"fs"})

        def read(self, p, *, time_column=None, value_column=None, fs=None):
            x = np.frombuffer(p.read_bytes(), dtype=np.float64)
            return readers.Raw(np.arange(x.size) / fs, 2 * x, None, ["doubled"])

    monkeypatch.setitem(READERS, "doubled", Doubled())
    p = tmp_path / "d.dbl"
    p.write_bytes(np.sin(np.arange(40.0)).tobytes())
    s = load_series(p, fs=10.0)
    np.testing.assert_allclose(s.intensity, 2 * np.sin(np.arange(40.0)))
    assert s.fs == pytest.approx(10.0) and s.notes == ["doubled"]
    with pytest.raises(DataError, match=r"apply to CSV/TSV and Parquet tables, not \.dbl files"):
        load_series(p, value_column="x")


@pytest.mark.parametrize("name", ["d.npy", "d.nc"])
def test_arrays_and_netcdf_still_refuse_table_options(tmp_path, name):
    p = tmp_path / name
    if name == "d.npy":
        np.save(p, np.column_stack([T, FORCE]))
    else:
        import xarray as xr

        xr.Dataset({"intensity": ("time", FORCE)}, coords={"time": T}).to_netcdf(p, engine="h5netcdf")
    for option in ({"fs": 100.0}, {"value_column": "x"}, {"time_column": "t"}):
        with pytest.raises(DataError, match=rf"apply to CSV/TSV and Parquet tables, not \{p.suffix} files") as err:
            load_series(p, **option)
        one_line(err)


# ---------------------------------------------------------------------------------- named .npz


def test_time_and_intensity_arrays_read_as_before(tmp_path):
    p = tmp_path / "d.npz"
    np.savez(p, time=T, intensity=FORCE, other=ACC)
    s = load_series(p)
    np.testing.assert_array_equal(s.intensity, FORCE)
    np.testing.assert_allclose(load_series(p, value_column="other").intensity, ACC)


def test_a_single_1d_array_with_a_scalar_rate(tmp_path):
    """As the LIGO file: strain, fs and strings."""
    p = tmp_path / "ligo.npz"
    np.savez(p, strain=FORCE * 1e-19, fs=np.float64(FS), gps_start=np.int64(1126259446), detector=np.array("H1"))
    for choice in (None, "strain", "STRAIN", "0"):
        s = load_series(p, value_column=choice)
        assert s.fs == pytest.approx(FS) and s.time[0] == 0.0 and s.time.size == N
        np.testing.assert_allclose(s.intensity, FORCE * 1e-19)
    with pytest.raises(DataError, match=r"gives fs = 512 Hz and fs was given as 100 Hz") as err:
        load_series(p, fs=100.0)
    one_line(err)
    assert load_series(p, fs=FS).fs == pytest.approx(FS)
    with pytest.raises(DataError, match="detector holds text") as err:
        load_series(p, value_column="detector")
    one_line(err)


@pytest.mark.parametrize("rate", ["sample_rate", "sampling_rate", "fs"])
@pytest.mark.parametrize("names", ["channel_names", "channels", "names"])
def test_named_columns_of_a_2d_array(tmp_path, rate, names):
    """As the plate files: data (n, 3), time, sample_rate, channel_names."""
    p = tmp_path / "plate.npz"
    np.savez(p, data=np.column_stack([FORCE, ACC, TRIGGER]), **{rate: np.float64(FS), names: ["force", "acc", "trig"]})
    s = load_series(p, value_column="acc")
    np.testing.assert_allclose(s.intensity, ACC)
    assert s.fs == pytest.approx(FS)
    np.testing.assert_allclose(load_series(p, value_column="2").intensity, TRIGGER)
    with pytest.raises(DataError) as err:
        load_series(p)
    assert "3 candidate series (force, acc, trig): choose one with --value-column" in one_line(err)


def test_channels_by_rows_and_unnamed_columns(tmp_path):
    p = tmp_path / "rows.npz"
    np.savez(p, data=np.vstack([FORCE, ACC]), time=T, channel_names=np.array(["f", "a"]))
    np.testing.assert_allclose(load_series(p, value_column="a").intensity, ACC)
    p = tmp_path / "unnamed.npz"
    np.savez(p, data=np.column_stack([FORCE, ACC]), time=T)
    np.testing.assert_allclose(load_series(p, value_column="data[1]").intensity, ACC)


def test_the_time_of_named_arrays(tmp_path):
    p = tmp_path / "t.npz"
    np.savez(p, x=ACC, stamps=2 * T)
    with pytest.raises(DataError, match=r"has no time: no array 'time' nor a sampling rate .* give fs= \(--fs\)") as e:
        load_series(p, value_column="x")
    one_line(e)
    assert load_series(p, value_column="x", fs=FS).fs == pytest.approx(FS)
    assert load_series(p, value_column="x", time_column="stamps").fs == pytest.approx(FS / 2)
    with pytest.raises(DataError, match=r"has no array 'nope' \(time_column\)") as e:
        load_series(p, value_column="x", time_column="nope")
    one_line(e)
    q = tmp_path / "both.npz"
    np.savez(q, x=ACC, time=T)
    with pytest.raises(DataError, match=r"has a time array \(time\) and fs was given: the time is ambiguous") as e:
        load_series(q, fs=FS)
    one_line(e)
    r = tmp_path / "short.npz"
    np.savez(r, x=ACC, time=T[:-1])
    with pytest.raises(DataError, match=r"time has shape \(255,\), x has shape \(256,\)") as e:
        load_series(r)
    one_line(e)


def test_without_a_choice_among_several_arrays_the_candidates_are_listed(tmp_path):
    p = tmp_path / "two.npz"
    np.savez(p, a=FORCE, b=ACC, fs=np.float64(FS), label=np.array("x"))
    with pytest.raises(DataError, match=r"2 candidate series \(a, b\): choose one with --value-column") as err:
        load_series(p)
    one_line(err)
    with pytest.raises(DataError, match=r"no candidate series 'c'; its candidate series: a, b") as err:
        load_series(p, value_column="c")
    one_line(err)
    q = tmp_path / "none.npz"
    np.savez(q, label=np.array("x"), fs=np.float64(FS))
    with pytest.raises(DataError, match="has no arrays 'time' and 'intensity' and no series") as err:
        load_series(q)
    one_line(err)


# ----------------------------------------------------------------------------------- real files

needs_realdata = pytest.mark.skipif(
    not REALDATA.is_dir(), reason=f"the real recordings are not here: {REALDATA} (shared/realdata-dev) is absent"
)


@needs_realdata
def test_the_ligo_strain_is_4096_hz():
    s = load_series(LIGO, value_column="strain")
    assert s.fs == pytest.approx(4096.0, rel=1e-12) and s.time.size == 131_072 and s.uniform


@needs_realdata
@pytest.mark.parametrize("name", ["view_0.npz", "view_0_02.npz", "view_0_03.npz", "view_0_04.npz", "view_1.npz"])
def test_the_plate_acceleration_is_25600_hz(name):
    s = load_series(PLATE / name, value_column="acc")
    assert s.fs == pytest.approx(25600.0, rel=1e-9) and s.time.size == 51_200 and s.uniform
    with pytest.raises(DataError, match=r"3 candidate series \(force, acc, trigger\)"):
        load_series(PLATE / name)
