"""LabVIEW Measurement (.lvm) files: synthetic files written here, and the real recordings of
shared/realdata-dev (skipped when absent)."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import run_cli
from vibinverse.errors import DataError
from vibinverse.io.lvm import read_lvm, regular_grid
from vibinverse.io.series import load_series

REALDATA = Path(__file__).resolve().parents[3].parent / "shared" / "realdata-dev"
BEAM = REALDATA / "beam_shaker_tones"
FOOTBRIDGE = REALDATA / "footbridge_impulse" / "VI0.txt"

N = 200
FS = 1000.0
T = np.arange(N) / FS
CHANNELS = {
    "Voltage": (np.sin(2 * np.pi * 50 * T), "Volts"),
    "Force": (np.cos(2 * np.pi * 80 * T), "Newtons"),
    "Acceleration": (np.sin(2 * np.pi * 120 * T) + 0.1 * np.cos(2 * np.pi * 7 * T), "g"),
}
SEP_NAMES = {"\t": "Tab", ",": "Comma", ";": "Semicolon"}


def lvm_text(
    channels: dict | None = None,
    t: np.ndarray = T,
    *,
    sep: str = "\t",
    dec: str = ".",
    x_columns: str = "One",
    delta_x: float | None = None,
    x0: float = 0.0,
    segments: int = 1,
    comment: bool = True,
    time_format: str = "%.6f",
) -> str:
    """An lvm file as LabVIEW writes it: the file header, then `segments` segments (each its header,
    column row and rows; the time of segment k continues after segment k - 1)."""
    channels = CHANNELS if channels is None else channels
    names = list(channels)
    fmt = lambda v, f="%.6f": (f % v).replace(".", dec)
    dx = t[1] - t[0] if delta_x is None else delta_x
    head = [
        f"LabVIEW Measurement{sep}",
        f"Writer_Version{sep}2",
        f"Reader_Version{sep}2",
        f"Separator{sep}{SEP_NAMES[sep]}",
        f"Decimal_Separator{sep}{dec}",
        f"Multi_Headings{sep}No",
        f"X_Columns{sep}{x_columns}",
        f"Time_Pref{sep}Relative",
        f"Operator{sep}tests",
        f"Date{sep}2024/01/01",
        f"Time{sep}12:00:00",
        f"***End_of_Header***{sep}",
    ]
    # the data columns: an X_Value column first (One, No: empty), or before each channel (Multi)
    columns = ["X_Value", *names] if x_columns != "Multi" else [c for n in names for c in ("X_Value", n)]
    span = t[-1] - t[0] + dx
    out = list(head)
    for s in range(segments):
        ts = t + s * span
        cells = lambda f: sep.join("" if c == "X_Value" else f(c) for c in columns[1:])
        out += [
            sep,
            f"Channels{sep}{len(names)}{sep}",
            f"Samples{sep}{cells(lambda c: str(t.size))}{sep}",
            f"Y_Unit_Label{sep}{cells(lambda c: channels[c][1])}{sep}",
            f"X_Dimension{sep}{cells(lambda c: 'Time')}{sep}",
            f"X0{sep}{cells(lambda c: fmt(x0 + ts[0], '%.16E'))}{sep}",
            f"Delta_X{sep}{cells(lambda c: fmt(dx, '%.7g'))}{sep}",
            f"***End_of_Header***{sep * len(columns)}",
            sep.join(columns) + (f"{sep}Comment" if comment else ""),
        ]
        for k in range(t.size):
            row = [
                ("" if x_columns == "No" else fmt(x0 + ts[k], time_format))
                if c == "X_Value"
                else fmt(channels[c][0][k])
                for c in columns
            ]
            out.append(sep.join(row))
        out.append("")
    return "\r\n".join(out) + "\r\n"


def write(tmp_path: Path, text: str, name: str = "d.lvm") -> Path:
    p = tmp_path / name
    p.write_text(text, newline="")
    return p


def one_line(err: pytest.ExceptionInfo) -> str:
    text = str(err.value)
    assert "\n" not in text and text.startswith("data: "), text
    return text


# ------------------------------------------------------------------------------------- synthetic


def test_tab_lvm_with_one_time_column_reads_a_channel_by_name_and_by_index(tmp_path):
    p = write(tmp_path, lvm_text())
    for choice in ("Force", " force ", "1"):
        s = load_series(p, value_column=choice)
        np.testing.assert_allclose(s.intensity, CHANNELS["Force"][0], atol=1e-6)
        np.testing.assert_allclose(s.time, T, atol=1e-12)
        assert s.uniform and s.fs == pytest.approx(FS, rel=1e-9)
        assert s.intensity_units == "Newtons" and "channel: Force (of Voltage, Force, Acceleration)" in s.notes
    assert load_series(p, value_column="Acceleration").intensity_units == "g"


def test_several_channels_without_a_choice_are_one_line_naming_them(tmp_path):
    p = write(tmp_path, lvm_text(sep=","), "VI0.txt")
    with pytest.raises(DataError) as err:
        load_series(p)
    assert one_line(err) == (f"data: {p} has 3 channels (Voltage, Force, Acceleration): choose one with --value-column")
    for bad in ("Torque", "3"):
        with pytest.raises(DataError, match=r"no channel '.+'; its channels: Voltage, Force, Acceleration") as err:
            load_series(p, value_column=bad)
        one_line(err)


def test_one_channel_is_the_default(tmp_path):
    p = write(tmp_path, lvm_text({"Only": CHANNELS["Voltage"]}))
    s = load_series(p)
    np.testing.assert_allclose(s.intensity, CHANNELS["Voltage"][0], atol=1e-6)
    assert not any(n.startswith("channel:") for n in s.notes)


def test_comma_separated_txt_is_recognised_by_its_first_line(tmp_path):
    """Comma separator, a Comment column the rows leave out, and a .txt suffix."""
    p = write(tmp_path, lvm_text(sep=","), "VI0.txt")
    s = load_series(p, value_column="Acceleration")
    np.testing.assert_allclose(s.intensity, CHANNELS["Acceleration"][0], atol=1e-6)
    assert s.fs == pytest.approx(FS)


@pytest.mark.parametrize("sep", ["\t", ";"])
def test_decimal_comma(tmp_path, sep):
    p = write(tmp_path, lvm_text(sep=sep, dec=","))
    s = load_series(p, value_column="Voltage")
    np.testing.assert_allclose(s.intensity, CHANNELS["Voltage"][0], atol=1e-6)
    assert s.fs == pytest.approx(FS)


def test_without_x_columns_the_time_is_x0_plus_delta_x_or_fs(tmp_path, caplog):
    p = write(tmp_path, lvm_text(x_columns="No", x0=2.5))
    s = load_series(p, value_column="Force")
    np.testing.assert_allclose(s.time, 2.5 + T, atol=1e-12)
    np.testing.assert_allclose(s.intensity, CHANNELS["Force"][0], atol=1e-6)
    with caplog.at_level(logging.WARNING, logger="vibinverse.io.lvm"):
        s = load_series(p, value_column="Force", fs=500.0)
    assert s.fs == pytest.approx(500.0)
    assert any("Delta_X 0.001 s (1000 Hz) disagrees with fs (500 Hz): fs is used" in n for n in s.notes)
    assert "disagrees with fs" in caplog.text


def test_multi_x_columns_give_each_channel_its_time(tmp_path):
    p = write(tmp_path, lvm_text(x_columns="Multi"))
    s = load_series(p, value_column="Acceleration")
    np.testing.assert_allclose(s.intensity, CHANNELS["Acceleration"][0], atol=1e-6)
    np.testing.assert_allclose(s.time, T, atol=1e-12)
    assert load_series(p, value_column="0").intensity_units == "Volts"


def test_segments_are_concatenated(tmp_path):
    p = write(tmp_path, lvm_text(segments=3))
    s = load_series(p, value_column="Voltage")
    assert s.time.size == 3 * N and s.uniform and s.fs == pytest.approx(FS)
    np.testing.assert_allclose(s.intensity, np.tile(CHANNELS["Voltage"][0], 3), atol=1e-6)
    # a segment header right after the rows of the previous segment (no blank line between)
    packed = write(tmp_path, lvm_text(segments=2).replace("\r\n\r\n\t\r\nChannels", "\r\nChannels"), "p.lvm")
    assert "\r\n\r\n" not in packed.read_bytes().decode()[:-4]
    assert load_series(packed, value_column="Voltage").time.size == 2 * N
    # more rows after a blank line, without a header of their own, continue as a segment
    text = lvm_text(segments=1)
    extra = "".join(f"{(N + k) / FS:.6f}\t1.0\t{k % 3}.5\t-0.25\r\n" for k in range(20))
    s = load_series(write(tmp_path, text + "\r\n" + extra, "e.lvm"), value_column="Force")
    assert s.time.size == N + 20 and s.uniform


def test_segments_whose_time_restarts_are_refused_naming_the_line(tmp_path):
    one = lvm_text()
    body = one[one.index("\r\n\t\r\nChannels") :]  # a second segment, its time from 0 again
    p = write(tmp_path, one + body.lstrip("\r\n"))
    with pytest.raises(DataError, match=r"line \d+: segment 2's time starts at 0 s, not after segment 1's") as err:
        load_series(p, value_column="Force")
    one_line(err)


def test_a_wrong_delta_x_is_noted_and_logged_and_the_column_used(tmp_path, caplog):
    t = np.arange(N) / 3200.0
    p = write(tmp_path, lvm_text({"a": (np.sin(300 * t), "g")}, t, delta_x=1.953125e-5))
    with caplog.at_level(logging.WARNING, logger="vibinverse.io.lvm"):
        s = load_series(p)
    assert s.fs == pytest.approx(3200.0, rel=1e-5) and s.uniform  # 200 stamps printed to 1 µs
    note = (
        "time: the lvm header's Delta_X 1.953125e-05 s (51200 Hz) disagrees with the X_Value column (3200 Hz): "
        "the column is used"
    )
    assert note in s.notes and note in caplog.text
    # a Delta_X within 0.1 % is not noted
    s = load_series(write(tmp_path, lvm_text({"a": (np.sin(300 * t), "g")}, t, delta_x=3.126e-4), "ok.lvm"))
    assert not any("Delta_X" in n for n in s.notes)


def test_stamps_rounded_to_their_printed_digits_are_read_as_their_grid(tmp_path):
    """51200/7 Hz printed with 6 decimals: the stamps are off their grid by up to 0.4 % of a step."""
    fs = 51200 / 7
    t = np.arange(5000) / fs
    p = write(tmp_path, lvm_text({"a": (np.sin(40 * t), "g")}, t, delta_x=0.000137))
    raw = np.round(t, 6)
    assert np.max(np.abs(raw - t)) * fs > 1e-3  # not uniform as printed
    s = load_series(p)
    assert s.uniform and s.fs == pytest.approx(fs, rel=1e-7)
    assert any(n.startswith("time: the X_Value column is written to 1e-06 s") for n in s.notes)
    # jittered stamps are not a grid: kept, and described as irregular
    jitter = t + np.random.default_rng(0).uniform(-0.2, 0.2, t.size) / fs
    assert not regular_grid(np.round(jitter, 6))[2]
    s = load_series(write(tmp_path, lvm_text({"a": (np.sin(40 * t), "g")}, jitter, delta_x=1 / fs), "j.lvm"))
    assert not s.uniform and any("irregular sampling" in n for n in s.notes)


def test_absolute_stamps_count_from_the_first(tmp_path):
    x0 = 3.7e9  # seconds since 1904-01-01 UTC: 2021-03-31
    p = write(tmp_path, lvm_text({"a": CHANNELS["Voltage"]}, x0=x0))
    s = load_series(p)
    assert s.uniform and s.fs == pytest.approx(FS, rel=1e-6) and s.time[0] == 0.0
    assert s.time_reference.startswith("2021-03-31T")
    p = write(tmp_path, lvm_text({"a": CHANNELS["Voltage"]}, x0=x0, x_columns="No"), "no.lvm")
    assert load_series(p).time_reference.startswith("2021-03-31T")


def test_read_lvm_returns_the_channel_and_its_unit(tmp_path):
    lvm = read_lvm(write(tmp_path, lvm_text()), value_column="2")
    assert lvm.channel == "Acceleration" and lvm.unit == "g" and lvm.time.size == N


def _replace_line(text: str, n: int, new: str) -> str:
    lines = text.split("\r\n")
    lines[n - 1] = new
    return "\r\n".join(lines)


def _line_of(text: str, start: str) -> int:
    return next(i for i, line in enumerate(text.split("\r\n"), 1) if line.startswith(start))


BASE = lvm_text()
ROW = _line_of(BASE, "0.010000")  # the 11th data row

MALFORMED = {
    "no_file_header_end.lvm": (
        BASE.replace("***End_of_Header***", "***End***"),
        r"the file header \(line 1\) never ends: no \*\*\*End_of_Header\*\*\* line",
    ),
    "no_segment_header_end.lvm": (
        BASE.replace("***End_of_Header***\t\t\t\t", "Delta_Y\t1"),
        r"line 22: numbers inside the segment header of line 14",
    ),
    "ragged.lvm": (_replace_line(BASE, ROW, "0.010000\t0.5\t0.25"), rf"line {ROW}: 3 cells; the column row"),
    "too_many_cells.lvm": (
        _replace_line(lvm_text(comment=False), ROW, "0.010000\t0.5\t0.25\t1\t7"),
        rf"line {ROW}: 5 cells; the column row \(line 21\) names 4",
    ),
    "not_a_number.lvm": (_replace_line(BASE, ROW, "0.010000\tabc\t0.25\t1"), rf"line {ROW}: not a number: 'abc'"),
    "no_time.lvm": (_replace_line(BASE, ROW, "\t0.5\t0.25\t1"), rf"line {ROW}: the X_Value cell .* is empty"),
    "text_row.lvm": (_replace_line(BASE, ROW, "oops\t0.5\t0.25\t1"), rf"line {ROW}: not a number: oops"),
    "x_columns.lvm": (BASE.replace("X_Columns\tOne", "X_Columns\tTwo"), r"line 7: X_Columns 'Two'; allowed: No, One"),
    "separator.lvm": (BASE.replace("Separator\tTab", "Separator\tPipes"), r"line 4: Separator 'Pipes'; allowed"),
    "decimal.lvm": (BASE.replace("Decimal_Separator\t.", "Decimal_Separator\t:"), r"line 5: Decimal_Separator ':'"),
    "no_column_row.lvm": (BASE.replace("X_Value\tVoltage", "Time\tVoltage"), r"line 21: the column row .* is missing"),
    "bad_delta_x.lvm": (
        BASE.replace("Delta_X\t0.001\t", "Delta_X\tfast\t"),
        r"line 19: Delta_X 'fast' is not a number",
    ),
    "not_lvm.lvm": ("time,intensity\n" + "".join(f"{t},{t}\n" for t in T), r"line 1: not a LabVIEW Measurement file"),
    "no_rows.lvm": (BASE[: BASE.index("0.000000\t")], r"has no data rows"),
}


@pytest.mark.parametrize("name", sorted(MALFORMED))
def test_a_malformed_file_is_one_line_naming_the_file_and_line(tmp_path, name):
    text, message = MALFORMED[name]
    p = write(tmp_path, text, name)
    with pytest.raises(DataError, match=message) as err:
        load_series(p, value_column="Voltage")
    assert str(p) in one_line(err)


def test_options_that_do_not_apply_are_refused(tmp_path):
    p = write(tmp_path, lvm_text())
    with pytest.raises(DataError, match="time_column does not apply to the LabVIEW Measurement file") as err:
        load_series(p, time_column="X_Value", value_column="Force")
    one_line(err)
    with pytest.raises(DataError, match=r"has a time column \(X_Value\) and fs was given") as err:
        load_series(p, value_column="Force", fs=1000.0)
    one_line(err)


def test_a_large_file_reads_every_sample(tmp_path):
    t = np.arange(100_000) / 3200.0
    chans = {name: (np.sin((k + 1) * 100 * t), "g") for k, name in enumerate("abc")}
    p = write(tmp_path, lvm_text(chans, t))
    s = load_series(p, value_column="b")
    assert s.time.size == t.size
    np.testing.assert_allclose(s.intensity, chans["b"][0], atol=1e-5)


# ----------------------------------------------------------------------------------- real files

needs_realdata = pytest.mark.skipif(
    not REALDATA.is_dir(), reason=f"the real recordings are not here: {REALDATA} (shared/realdata-dev) is absent"
)


@needs_realdata
@pytest.mark.parametrize("name", ["data_set_1_downsampled_by_16.lvm", "data_set_3_downsampled_by_16.lvm"])
def test_the_beam_recordings_are_3200_hz_not_the_header_51200(name):
    s = load_series(BEAM / name, value_column="2")
    assert s.time.size == 63_041 and s.uniform
    assert s.fs == pytest.approx(3200.0, rel=1e-4)
    assert s.intensity_units == "g"
    assert any("Delta_X 1.953125e-05 s (51200 Hz) disagrees with the X_Value column (3200 Hz)" in n for n in s.notes)
    assert load_series(BEAM / name, value_column="Force").intensity_units == "Pounds"


@needs_realdata
def test_the_footbridge_recording_is_51200_over_7_hz():
    s = load_series(FOOTBRIDGE, value_column="Acceleration_0")
    assert s.time.size == 88_800 and s.uniform
    assert s.fs == pytest.approx(7314.29, rel=5e-4)
    assert any("Delta_X 0.000137 s" in n and "the column is used" in n for n in s.notes)
    for choice in ("1", "Acceleration_2"):
        assert load_series(FOOTBRIDGE, value_column=choice).intensity_units == "g"


@needs_realdata
@pytest.mark.slow
def test_fit_without_a_channel_identifies_the_modes_of_all_three(tmp_path):
    """Several channels and no --value-column: operational modal analysis of all of them (issue 43);
    the footbridge's ~12 Hz first mode (reference 12.05 Hz, read off the source's figure) is found."""
    import json

    out = tmp_path / "out"
    r = run_cli("fit", str(FOOTBRIDGE), "--band", "5:100", "--no-progress", "-o", str(out))
    assert r.returncode == 0, r.stderr
    doc = json.loads((out / "summary.json").read_text())
    assert doc["channels"] == ["Acceleration_0", "Acceleration_1", "Acceleration_2"]
    near = [m for m in doc["modes"] if abs(m["frequency"] - 12.05) < 0.5]
    assert near and all(len(m["shape"]) == 3 for m in near)
    assert (out / "modes.csv").read_text().startswith("mode,frequency_hz")
    assert (out / "oma.png").stat().st_size > 10_000


def test_the_grid_step_is_the_same_whatever_blas_s_threads():
    """`regular_grid`'s step by numpy's pairwise sums: the same bits under one BLAS thread and
    several (BLAS's dot changed its last bits with its threads, and the beam record's fit, chaotic
    in them, took another order in the bench's one-thread processes than at the command line)."""
    from threadpoolctl import threadpool_limits

    t = np.round(np.arange(88_800) / 7314.2857142857, 6)
    with threadpool_limits(1):
        one = regular_grid(t)
    with threadpool_limits(2):
        two = regular_grid(t)
    assert one[1] == two[1] and np.array_equal(one[0], two[0])
