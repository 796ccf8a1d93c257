"""`vibinverse fit TABLE` of several channels: operational modal analysis (vibinverse.cli.fit_channels)."""

import csv
import json

import numpy as np
import pytest

from forward.motion.forced_modes import forced_modes
from vibinverse.cli import main
from vibinverse.oma import mac

from ..oma.conftest import modal_record

SHAPES = np.array([[0.3, 0.9, -0.3], [0.8, -0.2, 0.55]])


@pytest.fixture(scope="module")
def table(tmp_path_factory):
    ch = modal_record(((1.3, 0.02), (3.1, 0.015)), SHAPES, duration=300.0, seed=4)
    p = tmp_path_factory.mktemp("channels") / "building.csv"
    with p.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["time", "roof [m]", "mid [m]", "base [m]"])
        for t, row in zip(ch.time, ch.values, strict=True):
            w.writerow([f"{t:.6f}", *(f"{v:.9g}" for v in row)])
    return p


def _run(capsys, *args):
    code = main(list(args))
    captured = capsys.readouterr()
    return code, captured.err


def test_a_table_of_channels_gives_modes_shapes_and_files(table, tmp_path, capsys):
    out = tmp_path / "out"
    code, err = _run(capsys, "fit", str(table), "--no-progress", "-o", str(out))
    assert code == 0, err
    doc = json.loads((out / "summary.json").read_text())
    assert doc["channels"] == ["roof", "mid", "base"] and doc["quantity"] == "displacement"
    freqs = sorted(m["frequency"] for m in doc["modes"])
    assert len(freqs) == 2 and abs(freqs[0] - 1.3) < 0.02 and abs(freqs[1] - 3.1) < 0.03
    for m, v in zip(sorted(doc["modes"], key=lambda m: m["frequency"]), SHAPES, strict=True):
        assert mac(np.array(list(m["shape"].values())), v) > 0.99
    rows = list(csv.reader((out / "modes.csv").open()))
    assert rows[0][:3] == ["mode", "frequency_hz", "frequency_q05"] and len(rows) == 3
    assert (out / "oma.png").stat().st_size > 10_000
    page = (out / "report.html").read_text()
    assert "<h2>Modes</h2>" in page and "roof" in page and "data:image/png;base64," in page


def test_an_input_channel_is_left_out_of_the_responses(table, tmp_path, capsys):
    out = tmp_path / "out"
    code, err = _run(capsys, "fit", str(table), "--input", "base", "--band", "0.5:5", "--no-progress", "-o", str(out))
    assert code == 0, err
    doc = json.loads((out / "summary.json").read_text())
    assert doc["channels"] == ["roof", "mid"] and doc["search_band"] == [0.5, 5.0]
    assert all(set(m["shape"]) == {"roof", "mid"} for m in doc["modes"])
    assert any("input-output" in n for n in doc["notes"])


def test_a_measured_force_gives_input_output_identification(tmp_path, capsys):
    """`--input force` on a record of two modes driven by a measured force: both modes, their
    residue shapes, intervals that hold them (one data set: a regression test)."""
    modes, residues = ((12.0, 0.02), (31.0, 0.015)), np.array([[1.0, 0.6], [0.4, -0.9]])
    t, force, y = forced_modes(modes, residues, fs=200.0, duration=60.0, seed=2)
    p = tmp_path / "forced.csv"
    with p.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["time", "force [N]", "a [m]", "b [m]"])
        for row in zip(t, force, *y.T, strict=True):
            w.writerow([f"{v:.9g}" for v in row])
    out = tmp_path / "out"
    code, err = _run(capsys, "fit", str(p), "--input", "force", "--band", "5:60", "--no-progress", "-o", str(out))
    assert code == 0, err
    doc = json.loads((out / "summary.json").read_text())
    assert doc["channels"] == ["a", "b"] and any("input-output" in n for n in doc["notes"])
    found = sorted(doc["modes"], key=lambda m: m["frequency"])
    assert [round(m["frequency"]) for m in found] == [12, 31]
    for m, (f, _), a in zip(found, modes, residues, strict=True):
        assert m["frequency_interval"][0] - 0.01 <= f <= m["frequency_interval"][1] + 0.01
        assert mac(np.array(list(m["shape"].values())), a) > 0.99


def test_value_column_still_fits_one_series(table, tmp_path, capsys):
    out = tmp_path / "out"
    code, err = _run(
        capsys, "fit", str(table), "--value-column", "roof [m]", "--method", "spectral", "--no-progress", "-o", str(out)
    )
    assert code == 0, err
    doc = json.loads((out / "summary.json").read_text())
    assert "parameters" in doc and not (out / "modes.csv").exists()


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--channels", "roof,attic"], "'attic' is not a channel"),
        (["--method", "mcmc"], "--method mcmc: a multi-channel table is fitted by the spectral"),
        (["--lines", "1"], "--lines: applies to a single-series fit"),
        (["--channels", "all", "--value-column", "roof"], "--channels: applies to a multi-channel table"),
        (["--quantity", "velocity", "--pixels", "all"], "--quantity: applies to a multi-channel table"),
        (["--input", "roof,mid,base"], "every channel is a measured input"),
        (["--band", "4:3"], "band"),
    ],
)
def test_bad_options_are_one_line_and_leave_nothing(table, tmp_path, capsys, extra, message):
    out = tmp_path / "out"
    code, err = _run(capsys, "fit", str(table), *extra, "--no-progress", "-o", str(out))
    assert code == 2 and message in err, err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert not out.exists()
