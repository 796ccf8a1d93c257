"""Multi-channel files read into `Channels` (`load_channels`): every format written here by its own
library and read back, the choice and order of channels, measured inputs, sensor geometry, gaps,
the one-line errors, and the real recordings of shared/realdata-dev (skipped when absent)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from tests.vibinverse.io.test_lvm import lvm_text
from vibinverse.errors import DataError, InputError
from vibinverse.io.channel_readers import CHANNEL_READERS, TEXT_FALLBACK, ChannelReader, channel_reader_for
from vibinverse.io.channels import Channels, load_channels, read_geometry

N = 64
FS = 1000.0
T = np.arange(N) / FS
_rng = np.random.default_rng(7)
# values with at most 7 significant digits: every format (UFF's 13-digit text too) keeps them exactly
DATA = np.round(_rng.normal(size=(N, 3)) * [1.0, 0.01, 20.0], 6)
NAMES = ("acc1", "acc2", "force")
UNITS = ("g", "m/s^2", "N")
TOL = 1e-12


def one_line(err: pytest.ExceptionInfo, *words: str) -> str:
    """The error's message: one line that names each of `words`."""
    text = str(err.value)
    assert "\n" not in text, text
    for w in words:
        assert w in text, f"{w!r} not in {text!r}"
    return text


def check(c: Channels, names=NAMES, units=UNITS, data=DATA, t=T) -> None:
    assert c.names == tuple(names)
    assert c.units == tuple(units)
    assert c.n_channels == len(names) and c.time.size == t.size
    np.testing.assert_allclose(c.time, t, rtol=0, atol=TOL)
    np.testing.assert_allclose(c.values, data, rtol=0, atol=TOL)


def write_csv(p: Path, header: list[str], rows: np.ndarray, sep: str = ",") -> Path:
    lines = [sep.join(header)] + [sep.join(repr(float(v)) for v in row) for row in rows]
    p.write_text("\n".join(lines) + "\n")
    return p


def table_rows() -> np.ndarray:
    return np.column_stack([T, DATA])


# -------------------------------------------------------------------------------------- registry


def test_every_format_has_one_registered_reader():
    assert {"csv", "parquet", "npy", "npz", "netcdf", "lvm", "tdms", "mat", "uff"} <= set(CHANNEL_READERS)
    assert all(isinstance(r, ChannelReader) and r.name == name for name, r in CHANNEL_READERS.items())
    suffixes = [s for name, r in CHANNEL_READERS.items() if name != TEXT_FALLBACK for s in r.suffixes]
    assert len(suffixes) == len(set(suffixes))


@pytest.mark.parametrize(
    "name, head, reader",
    [
        ("a.npy", b"\x93NUMPY", "npy"),
        ("a.bin", b"\x93NUMPY", "npy"),
        ("a.NPZ", b"PK\x03\x04", "npz"),
        ("a.nc", b"CDF\x01", "netcdf"),
        ("a.h5", b"\x89HDF\r\n\x1a\n", "netcdf"),
        ("a.parquet", b"PAR1", "parquet"),
        ("a.tdms", b"TDSm", "tdms"),
        ("a.bin", b"TDSm\x00\x00", "tdms"),
        ("a.mat", b"MATLAB 5.0 MAT-file", "mat"),
        ("a.dat", b"MATLAB 7.3 MAT-file", "mat"),
        ("a.uff", b"    -1\n    58\n", "uff"),
        ("a.txt", b"    -1\n    58\n", "uff"),
        ("VI0.txt", b"LabVIEW Measurement,\n", "lvm"),
        ("a.csv", b"time,acc\n", "csv"),
        ("a.weird", b"time;acc\n", "csv"),  # text no other format claims is a table
    ],
)
def test_the_reader_is_found_by_suffix_then_signature(tmp_path, name, head, reader):
    p = tmp_path / name
    p.write_bytes(head)
    assert channel_reader_for(p).name == reader


def test_an_unknown_binary_format_is_refused_naming_the_formats(tmp_path):
    p = tmp_path / "a.xyz"
    p.write_bytes(b"\x00\x01\x02garbage\xff" * 10)
    with pytest.raises(DataError) as err:
        load_channels(p)
    one_line(err, str(p), "unknown format", "CSV/TSV", "TDMS", "UFF 58")


# ------------------------------------------------------------------------------------ round trips


@pytest.mark.parametrize("sep, suffix", [(",", ".csv"), ("\t", ".tsv"), (";", ".csv"), (" ", ".txt")])
def test_csv_and_tsv_round_trip_with_units_in_the_header(tmp_path, sep, suffix):
    header = (
        ["time", "acc1[g]", "acc2(m/s^2)", "force[N]"]
        if sep == " "
        else ["time", "acc1 [g]", "acc2 (m/s^2)", "force [N]"]
    )
    c = load_channels(write_csv(tmp_path / f"t{suffix}", header, table_rows(), sep))
    check(c)
    assert c.source == str(tmp_path / f"t{suffix}")


def test_csv_time_by_name_anywhere_in_ms_and_from_the_first_column(tmp_path):
    rows = np.column_stack([DATA[:, 0], T * 1000.0, DATA[:, 1]])
    c = load_channels(write_csv(tmp_path / "a.csv", ["acc1", "Time (ms)", "acc2"], rows))
    check(c, ("acc1", "acc2"), (None, None), DATA[:, :2])
    c = load_channels(write_csv(tmp_path / "b.csv", ["stamp", "acc1", "acc2"], np.column_stack([T, DATA[:, :2]])))
    check(c, ("acc1", "acc2"), (None, None), DATA[:, :2])  # no column named like a time: the first one
    c = load_channels(tmp_path / "b.csv", time_column="STAMP")
    check(c, ("acc1", "acc2"), (None, None), DATA[:, :2])


def test_csv_without_a_time_column_takes_fs_and_a_headerless_one_names_ch0(tmp_path):
    c = load_channels(write_csv(tmp_path / "a.csv", ["acc1", "acc2", "force"], DATA), fs=FS)
    check(c, units=(None, None, None))
    p = tmp_path / "b.csv"
    p.write_text("\n".join(",".join(repr(float(v)) for v in row) for row in table_rows()))
    check(load_channels(p), ("ch0", "ch1", "ch2"), (None, None, None))
    check(load_channels(p, fs=FS), ("ch0", "ch1", "ch2", "ch3"), (None,) * 4, table_rows())


def test_parquet_round_trip_units_from_brackets_and_field_metadata(tmp_path):
    pa = pytest.importorskip("pyarrow")
    pq = pytest.importorskip("pyarrow.parquet")
    fields = [
        pa.field("time", pa.float64()),
        pa.field("acc1 [g]", pa.float64()),
        pa.field("acc2", pa.float64(), metadata={"units": "m/s^2"}),
        pa.field("force", pa.float64(), metadata={"unit": "N"}),
    ]
    table = pa.Table.from_arrays([pa.array(col) for col in table_rows().T], schema=pa.schema(fields))
    pq.write_table(table, tmp_path / "a.parquet")
    check(load_channels(tmp_path / "a.parquet"))


def test_parquet_date_times_become_seconds_since_the_first(tmp_path):
    pd = pytest.importorskip("pandas")
    pytest.importorskip("pyarrow")
    stamps = pd.Timestamp("2024-05-01T12:00:00Z") + pd.to_timedelta(T, unit="s")
    pd.DataFrame({"timestamp": stamps, "acc1 [g]": DATA[:, 0]}).to_parquet(tmp_path / "a.parquet")
    c = load_channels(tmp_path / "a.parquet")
    check(c, ("acc1",), ("g",), DATA[:, :1])
    assert any("2024-05-01T12:00:00" in n for n in c.notes)


def test_npy_with_a_time_column_or_fs(tmp_path):
    np.save(tmp_path / "a.npy", table_rows())
    check(load_channels(tmp_path / "a.npy"), ("ch0", "ch1", "ch2"), (None,) * 3)
    np.save(tmp_path / "b.npy", DATA)
    check(load_channels(tmp_path / "b.npy", fs=FS), ("ch0", "ch1", "ch2"), (None,) * 3)
    np.save(tmp_path / "c.npy", DATA[:, 0])
    check(load_channels(tmp_path / "c.npy", fs=FS), ("ch0",), (None,), DATA[:, :1])


def test_npz_named_vectors_and_a_named_2d_array(tmp_path):
    np.savez(tmp_path / "a.npz", time=T, acc1=DATA[:, 0], acc2=DATA[:, 1], force=DATA[:, 2])
    check(load_channels(tmp_path / "a.npz"), units=(None,) * 3)
    np.savez(
        tmp_path / "b.npz", data=DATA.T.copy(), sample_rate=FS, channel_names=np.array(NAMES), units=np.array(UNITS)
    )
    check(load_channels(tmp_path / "b.npz"))  # channels x samples, its time from the rate
    np.savez(tmp_path / "c.npz", data=DATA)
    check(load_channels(tmp_path / "c.npz", fs=FS), ("ch0", "ch1", "ch2"), (None,) * 3)


def test_netcdf_2d_variable_with_a_channel_coordinate(tmp_path):
    xr = pytest.importorskip("xarray")
    ds = xr.Dataset(
        {"accel": (("time", "channel"), DATA, {"units": "g"})},
        coords={"time": ("time", T * 1000.0, {"units": "milliseconds"}), "channel": list(NAMES)},
    )
    ds.to_netcdf(tmp_path / "a.nc", engine="h5netcdf")
    check(load_channels(tmp_path / "a.nc"), units=("g", "g", "g"))
    ds = ds.assign_coords(units=("channel", list(UNITS)))
    ds.to_netcdf(tmp_path / "b.nc", engine="h5netcdf")
    check(load_channels(tmp_path / "b.nc"))  # a units coordinate on the channels: one each


def test_netcdf3_1d_variables_on_time_with_units(tmp_path):
    xr = pytest.importorskip("xarray")
    ds = xr.Dataset(
        {n: ("time", DATA[:, j], {"units": u}) for j, (n, u) in enumerate(zip(NAMES, UNITS))},
        coords={"time": ("time", T, {"units": "seconds since 2024-01-01"})},
    )
    ds.to_netcdf(tmp_path / "a.nc", engine="scipy")
    c = load_channels(tmp_path / "a.nc")
    check(c)
    assert any("2024-01-01" in n for n in c.notes)


def test_tdms_round_trip_from_waveform_properties_and_from_a_time_channel(tmp_path):
    nptdms = pytest.importorskip("nptdms")
    wf = {"wf_increment": 1 / FS, "wf_start_offset": 0.0}
    objects = [
        nptdms.ChannelObject("logger", n, DATA[:, j], properties={"unit_string": u, **wf})
        for j, (n, u) in enumerate(zip(NAMES, UNITS))
    ]
    with nptdms.TdmsWriter(tmp_path / "a.tdms") as w:
        w.write_segment(objects)
    check(load_channels(tmp_path / "a.tdms"))
    timed = [nptdms.ChannelObject("logger", "Time", T, properties={"unit_string": "s"})] + [
        nptdms.ChannelObject("logger", n, DATA[:, j], properties={"unit_string": u})
        for j, (n, u) in enumerate(zip(NAMES, UNITS))
    ]
    with nptdms.TdmsWriter(tmp_path / "b.tdms") as w:
        w.write_segment(timed)
    check(load_channels(tmp_path / "b.tdms"))


def test_mat_v5_round_trip(tmp_path):
    from scipy.io import savemat

    names = np.array(NAMES, dtype=object)
    savemat(
        tmp_path / "a.mat",
        {"t": T[:, None], "data": DATA, "channel_names": names, "units": np.array(UNITS, dtype=object)},
    )
    check(load_channels(tmp_path / "a.mat"))
    savemat(tmp_path / "b.mat", {"rec": {"time": T, "acc1": DATA[:, 0], "acc2": DATA[:, 1], "force": DATA[:, 2]}})
    check(load_channels(tmp_path / "b.mat"), units=(None,) * 3)  # a lone struct: its fields


def _matlab_text(h5, name: str, text: str) -> None:
    d = h5.create_dataset(name, data=np.array([ord(ch) for ch in text], dtype=np.uint16)[:, None])
    d.attrs["MATLAB_class"] = np.bytes_("char")


def test_mat_v73_round_trip(tmp_path):
    h5py = pytest.importorskip("h5py")
    p = tmp_path / "a.mat"
    with h5py.File(p, "w", userblock_size=512) as h5:
        d = h5.create_dataset("data", data=DATA.T)  # MATLAB's N x C, stored column-major
        d.attrs["MATLAB_class"] = np.bytes_("double")
        h5.create_dataset("fs", data=np.array([[FS]])).attrs["MATLAB_class"] = np.bytes_("double")
        refs = h5.create_group("#refs#")
        cells = []
        for j, n in enumerate(NAMES):
            _matlab_text(refs, f"n{j}", n)
            cells.append(refs[f"n{j}"].ref)
        names = h5.create_dataset("channel_names", data=np.array(cells, dtype=h5py.ref_dtype)[:, None])
        names.attrs["MATLAB_class"] = np.bytes_("cell")
        _matlab_text(h5, "units", "g")
    with open(p, "r+b") as fh:
        fh.write(
            b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 HDF5 schema 1.00 .".ljust(
                116
            )
        )
    check(load_channels(p), units=("g", "g", "g"))


def test_uff58_round_trip(tmp_path):
    pyuff = pytest.importorskip("pyuff")
    sets = [
        pyuff.prepare_58(
            func_type=1, rsp_node=j + 1, rsp_dir=3, ref_node=0, ref_dir=0, data=DATA[:, j], x=T, id1=n,
            rsp_ent_name=n, abscissa_spacing=1, abscissa_min=0.0, abscissa_inc=1 / FS, abscissa_spec_data_type=17,
            ordinate_spec_data_type=12, orddenom_spec_data_type=0, ordinate_axis_units_lab=u,
            abscissa_axis_units_lab="s",
        )
        for j, (n, u) in enumerate(zip(NAMES, UNITS))
    ]  # fmt: skip
    pyuff.UFF(str(tmp_path / "a.uff")).write_sets(sets, mode="overwrite")
    check(load_channels(tmp_path / "a.uff"))
    for s in sets:
        s["id1"] = "Time Response"  # the same ID line for all: node and direction name them
    pyuff.UFF(str(tmp_path / "b.uff")).write_sets(sets, mode="overwrite")
    check(load_channels(tmp_path / "b.uff"), ("1+Z", "2+Z", "3+Z"))


def test_lvm_every_channel_its_time_from_the_x_value_column(tmp_path):
    chans = {n: (DATA[:, j], u) for j, (n, u) in enumerate(zip(NAMES, UNITS))}
    p = tmp_path / "a.lvm"
    p.write_text(lvm_text(chans, T, delta_x=1 / 51200))  # a header rate that is wrong
    c = load_channels(p)
    check(c, data=np.round(DATA, 6))
    assert c.fs == pytest.approx(FS, rel=1e-9)
    assert any("Delta_X" in n for n in c.notes)


@pytest.mark.parametrize("module, suffix, head", [("nptdms", ".tdms", b"TDSm"), ("pyuff", ".uff", b"    -1\n    58\n")])
def test_a_missing_library_names_the_extra(tmp_path, monkeypatch, module, suffix, head):
    monkeypatch.setitem(sys.modules, module, None)  # import fails
    p = tmp_path / f"a{suffix}"
    p.write_bytes(head + b"\x00" * 32)
    with pytest.raises(InputError) as err:
        load_channels(p)
    one_line(err, "vibinverse[loggers]")


# -------------------------------------------------------------------------- selection, inputs, gaps


@pytest.fixture
def csv_file(tmp_path) -> Path:
    return write_csv(tmp_path / "a.csv", ["time", "acc1 [g]", "acc2 (m/s^2)", "force [N]"], table_rows())


def test_channels_chosen_and_ordered_by_list_or_comma_string(csv_file):
    for chosen in (["force", "acc1"], "force, acc1", ["FORCE", "Acc1"]):
        c = load_channels(csv_file, channels=chosen)
        check(c, ("force", "acc1"), ("N", "g"), DATA[:, [2, 0]])
    check(load_channels(csv_file, channels="all"))


@pytest.mark.parametrize("chosen", [["acc9"], "acc1,acc9", ["time"]])
def test_an_unknown_channel_names_the_allowed_ones(csv_file, chosen):
    with pytest.raises(InputError) as err:
        load_channels(csv_file, channels=chosen)
    one_line(err, "channels", "allowed: acc1, acc2, force")


def test_a_channel_given_twice_or_an_empty_choice_is_refused(csv_file):
    for chosen in (["acc1", "acc1"], [], "acc1,,acc2"):
        with pytest.raises(InputError) as err:
            load_channels(csv_file, channels=chosen)
        one_line(err, "channels")


def test_inputs_are_flagged_and_kept(csv_file):
    c = load_channels(csv_file, inputs=["force"])
    check(c)
    assert c.inputs == ("force",) and c.responses == ("acc1", "acc2")
    with pytest.raises(InputError) as err:
        load_channels(csv_file, inputs=["hammer"])
    one_line(err, "inputs", "'hammer'", "allowed: acc1, acc2, force")
    with pytest.raises(InputError) as err:
        load_channels(csv_file, channels=["acc1"], inputs="force")  # not among the chosen
    one_line(err, "inputs", "'force'", "allowed: acc1")


def test_gaps_stay_nan(tmp_path):
    p = tmp_path / "a.csv"
    p.write_text("time,a,b\n0,1,\n0.001,NaN,2\n,,\n0.002,3,4\n0.003,,NA\n")  # a row of empty cells is no sample
    c = load_channels(p)
    assert c.gaps.tolist() == [[False, True], [True, False], [False, False], [True, True]]
    assert c.values[2].tolist() == [3.0, 4.0]
    np.savez(tmp_path / "g.npz", time=T, a=np.where(T > 0.03, np.nan, 1.0))
    assert load_channels(tmp_path / "g.npz").gaps.sum() == int((T > 0.03).sum())


# ------------------------------------------------------------------------------------------ geometry


def test_only_a_measured_input_may_have_no_position():
    kw = {"time": T, "values": DATA, "names": NAMES, "units": UNITS, "source": "s"}
    placed = np.array([[0, 0, 0], [1, 0, 0], [np.nan] * 3])
    assert Channels(**kw, positions=placed, inputs=("force",)).inputs == ("force",)
    with pytest.raises(InputError) as err:
        Channels(**kw, positions=placed)  # force is a response here: it needs a place
    one_line(err, "positions", "measured input")
    with pytest.raises(InputError):
        Channels(**kw, positions=np.where(np.arange(3)[:, None] == 0, np.nan, placed * 0), inputs=("force",))


def write_geometry(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "geometry.csv"
    p.write_text(text)
    return p


def test_geometry_places_the_chosen_channels(tmp_path, csv_file):
    g = write_geometry(tmp_path, "# sensors\nname,x,y,z\nacc2,1.5,0,0.25\nacc1,0,0,0\nforce,3,0,0\nspare,9,9,9\n")
    c = load_channels(csv_file, channels=["acc2", "acc1"], geometry=g)
    np.testing.assert_array_equal(c.positions, [[1.5, 0, 0.25], [0, 0, 0]])
    assert read_geometry(g)["spare"] == (9.0, 9.0, 9.0)
    g2 = write_geometry(tmp_path, "z,y,x,NAME\n1,2,3,acc1\n4,5,6,acc2\n")  # any order of the four columns
    c = load_channels(csv_file, inputs=["force"], geometry=g2)  # an input need not be placed
    np.testing.assert_array_equal(c.positions[:2], [[3, 2, 1], [6, 5, 4]])
    assert np.isnan(c.positions[2]).all()
    assert c.select(["acc2"]).positions.tolist() == [[6.0, 5.0, 4.0]]


@pytest.mark.parametrize(
    "text, words",
    [
        ("name,x,y,z\nacc1,0,0,0\n", ["acc2, force", "no position"]),  # a response channel missing
        ("name,x,y,z\nacc1,0,zero,0\nacc2,0,0,0\nforce,0,0,0\n", ["line 2", "y", "'zero'", "not a number"]),
        ("name,x,y,z\nacc1,0,inf,0\n", ["line 2", "not finite"]),
        ("name,x,y\nacc1,0,0\n", ["line 1", "allowed: name,x,y,z"]),
        ("sensor,x,y,z\nacc1,0,0,0\n", ["line 1", "allowed: name,x,y,z"]),
        ("name,x,y,z\nacc1,0,0\n", ["line 2", "3 cells"]),
        ("name,x,y,z\nacc1,0,0,0\nacc1,1,1,1\n", ["line 3", "placed twice"]),
        ("name,x,y,z\n", ["no rows"]),
        ("", ["empty"]),
    ],
)
def test_a_malformed_geometry_is_one_line_naming_it(tmp_path, csv_file, text, words):
    g = write_geometry(tmp_path, text)
    with pytest.raises(DataError) as err:
        load_channels(csv_file, geometry=g)
    one_line(err, "geometry", *words)


# ---------------------------------------------------------------------------------------- errors


@pytest.mark.parametrize(
    "text, words",
    [
        ("", ["empty"]),
        ("# only a comment\n\n", ["no header row"]),
        ("time,a,b\n", ["no data rows"]),
        ("time,a,b\n0,1,2\n", ["1 sample", "at least 2"]),
        ("time,a,b\n0,1,2\n0.1,3\n0.2,4,5\n", ["line 3", "2 cells", "header names 3"]),
        ("time,a,b\n0,1,2\n0.1,3,4,5\n", ["line 3", "4 cells"]),
        ("time,a,b\n0,1,2\n0.1,3,x7\n", ["line 3", "column b", "'x7'", "not a number"]),
        ("time;a;b\n0;1;2\n0,1;3,5;4\n", ["line 3", "column time", "'0,1'", "decimal comma"]),
        ("time,a,b\n0,1,2\n0.1,3,4\n0.1,5,6\n", ["line 4", "strictly increasing"]),
        ("stamp,a,b\n3,1,2\n2,3,4\n", ["line 3", "strictly increasing", "first column stamp", "time_column"]),
        ("time,a,b\n0,1,2\n,3,4\n", ["line 3", "time", "empty"]),
        ("time,a,a\n0,1,2\n0.1,3,4\n", ["line 1", "'a' twice"]),
        ("time,a,b\n0,1,2\n0.1,inf,4\n", ["line 3", "channel a", "infinite"]),
        ("time [furlongs],a\n0,1\n1,2\n", ["time column", "'furlongs'", "not a time unit"]),
        ("acc\n1\n2\n", ["one column", "fs"]),
        ("t,time,a\n0,0,1\n1,1,2\n", ["2 time columns", "time_column"]),
    ],
)
def test_a_malformed_table_is_one_line_naming_the_file_and_field(tmp_path, text, words):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(DataError) as err:
        load_channels(p)
    one_line(err, str(p), *words) if text else one_line(err, *words)


def test_options_that_do_not_apply_or_conflict_are_refused(tmp_path, csv_file):
    cases = [
        (csv_file, {"fs": FS}, ["time column", "fs", "ambiguous"]),
        (csv_file, {"time_column": "clock"}, ["'clock'", "time_column", "acc1 [g]"]),
        (csv_file, {"fs": -1.0}, ["fs", "(0, inf)"]),
        (csv_file, {"fs": "fast"}, ["fs", "not a number"]),
    ]
    np.save(tmp_path / "a.npy", table_rows())
    cases.append((tmp_path / "a.npy", {"time_column": "t"}, ["time_column", "first column"]))
    np.savez(tmp_path / "a.npz", time=T, a=DATA[:, 0], fs=FS)
    cases.append((tmp_path / "a.npz", {"fs": 2 * FS}, ["fs", "drop fs"]))
    for path, options, words in cases:
        with pytest.raises(InputError) as err:
            load_channels(path, **options)
        one_line(err, *words)


def test_duplicate_channel_names_in_a_file_are_refused(tmp_path):
    xr = pytest.importorskip("xarray")
    xr.Dataset({"v": (("time", "channel"), DATA[:, :2])}, coords={"time": T, "channel": ["acc", "acc"]}).to_netcdf(
        tmp_path / "a.nc", engine="h5netcdf"
    )
    with pytest.raises(DataError) as err:
        load_channels(tmp_path / "a.nc")
    one_line(err, str(tmp_path / "a.nc"), "'acc' appears twice")


def test_npy_of_one_column_without_fs_and_mat_without_numbers_are_refused(tmp_path):
    from scipy.io import savemat

    np.save(tmp_path / "a.npy", DATA[:, :1])
    with pytest.raises(DataError) as err:
        load_channels(tmp_path / "a.npy")
    one_line(err, str(tmp_path / "a.npy"), "1 column", "fs")
    savemat(tmp_path / "a.mat", {"note": "no numbers here", "flag": True, "fs": FS})
    for options in ({}, {"fs": FS}):
        with pytest.raises(DataError) as err:
            load_channels(tmp_path / "a.mat", **options)
        one_line(err, str(tmp_path / "a.mat"), "no 2-D numeric array", "note")
    np.savez(tmp_path / "short.npz", time=T, a=DATA[:10, 0])
    with pytest.raises(DataError) as err:
        load_channels(tmp_path / "short.npz")
    one_line(err, "no channels of 64 samples", "a (10 values)")
    savemat(tmp_path / "b.mat", {"data": DATA})
    with pytest.raises(DataError) as err:
        load_channels(tmp_path / "b.mat")
    one_line(err, "no time", "give fs=")


@pytest.mark.parametrize("suffix", [".npy", ".npz", ".parquet", ".nc", ".tdms", ".mat", ".uff"])
def test_a_file_that_is_not_its_format_is_one_line(tmp_path, suffix):
    p = tmp_path / f"bad{suffix}"
    p.write_bytes(b"this is not that format at all\n" * 4)
    with pytest.raises(InputError) as err:
        load_channels(p)
    one_line(err, str(p))


# ------------------------------------------------------------------------------- real recordings


def _corpus() -> Path | None:
    from vibinverse.bench.realdata_cases import corpus_dir

    try:
        return corpus_dir()
    except InputError:
        return None


CORPUS = _corpus()
needs_realdata = pytest.mark.skipif(CORPUS is None, reason="the real recordings (shared/realdata-dev) are absent")


FOOTBRIDGE = ("Acceleration_0", "Acceleration_1", "Acceleration_2"), ("g",) * 3
BEAM = ("Voltage", "Force", "Acceleratio"), ("Volts", "Pounds", "g")  # the file's third name is cut short


@needs_realdata
@pytest.mark.parametrize(
    "path, names, units, fs, n",
    [
        ("footbridge_impulse/VI0.txt", *FOOTBRIDGE, 51200 / 7, 88800),  # the header's Delta_X says 7299 Hz
        ("beam_shaker_tones/data_set_1_downsampled_by_16.lvm", *BEAM, 3200.0, 63041),  # the header says 51200 Hz
        ("plate_sweep_force_acc/view_0.npz", ("force", "acc", "trigger"), (None,) * 3, 25600.0, 51200),
    ],
)
def test_real_recordings(path, names, units, fs, n):
    c = load_channels(CORPUS / path)
    assert c.names == names and c.units == units
    assert c.n_channels == 3 and c.time.size == n
    assert c.fs == pytest.approx(fs, rel=1e-6)
    assert c.uniform and not c.gaps.any()


@needs_realdata
def test_real_shaker_record_with_its_drive_and_force_as_inputs():
    c = load_channels(CORPUS / "beam_shaker_tones" / "data_set_1_downsampled_by_16.lvm", inputs="Voltage,Force")
    assert c.inputs == ("Voltage", "Force") and c.responses == ("Acceleratio",)


@needs_realdata
def test_real_smartphone_csv_irregular_stamps():
    c = load_channels(CORPUS / "slab_smartphone" / "Example02_Smartphone_Data.csv", inputs=())
    assert c.names == ("X-Axis", "Y- Axis", "Z-Axis") and c.units == ("m/s2",) * 3
    assert c.time.size == 25291 and c.time[0] == 0.0
    assert c.fs == pytest.approx(425.0797, rel=1e-6)
    assert not c.uniform
