"""The simulated-series CSV keeps one value per comment line whatever the scene's strings hold, and
`vibinverse simulate` refuses bad input with one line, exit code 2 and no output file."""

import re
from pathlib import Path

import numpy as np
import pytest

from forward.scene_file import load_scene, scene_from_table
from forward.sensor import observe
from tests.conftest import SCENES, run_cli
from vibinverse.io.series import load_series
from vibinverse.io.simulation import write_series_csv

CORPUS = Path(__file__).resolve().parents[2] / "corpus" / "scenes"
INJECTION = "a\nb\r\ntime,intensity\n1,2"
LINE_BREAKS = "\r|\x0b|\x0c|\x1c|\x1d|\x1e|\x85|\u2028|\u2029|\t|\x00"
FAST = ["sampling.duration=0.5"]  # roof_frame: 100 samples


def _simulated(tmp_path: Path, title: str, *overrides: str, name: str = "roof_frame"):
    _, table = load_scene(SCENES / f"{name}.toml", [*FAST, *overrides])
    table["title"] = title
    obs = observe(scene_from_table(table), seed=5)
    path = tmp_path / "sim.csv"
    write_series_csv(path, obs, table, 5, "test")
    return path, obs, table


@pytest.mark.parametrize("title", [INJECTION, LINE_BREAKS, "lone surrogate \ud800", "caf\xe9 \u2013 \U0001f600"])
def test_every_comment_line_stays_one_line_and_the_data_read_back_exactly(tmp_path, title):
    path, obs, table = _simulated(tmp_path, title)
    lines = path.read_text(encoding="utf-8").splitlines()  # str.splitlines breaks at every Unicode line break
    assert len(lines) == 5 + 1 + obs.time.size
    assert all(line.startswith("# ") for line in lines[:5]) and lines[5] == "time,intensity,intensity_clean"
    assert lines[1].startswith("# title: ")
    series = load_series(path)
    np.testing.assert_array_equal(series.time, obs.time)
    np.testing.assert_array_equal(series.intensity, obs.intensity)
    assert series.scene == table and series.scene["title"] == title


def test_toml_dates_are_written_as_text_and_the_scene_reads_back(tmp_path):
    sun = "sun={date=2024-06-21, hour=12.0, latitude=45.0, longitude=0.0}"  # a TOML date, not a string
    path, _, table = _simulated(tmp_path, "dated", sun, "sampling.duration=0.05", name="ground_rayleigh")
    series = load_series(path)
    assert series.scene["sun"]["date"] == "2024-06-21"
    assert scene_from_table(series.scene).sun == scene_from_table(table).sun


def test_the_cli_round_trips_a_title_with_line_breaks(tmp_path):
    out = tmp_path / "series.csv"
    r = run_cli(
        "simulate",
        str(SCENES / "roof_frame.toml"),
        "--set",
        'title="a\\nb\\r\\ntime,intensity\\n1,2"',
        *(a for o in FAST for a in ("--set", o)),
        "--seed",
        "5",
        "-o",
        str(tmp_path),
    )
    assert r.returncode == 0, r.stderr
    series = load_series(out)
    assert series.scene["title"] == INJECTION
    expected = observe(scene_from_table(series.scene), seed=5)
    np.testing.assert_array_equal(series.time, expected.time)
    np.testing.assert_array_equal(series.intensity, expected.intensity)


def _drive_lines_file(tmp_path: Path, n: int) -> Path:
    text = (SCENES / "roof_frame.toml").read_text()
    text = text.replace("drive_frequency = [10.0]", "drive_frequency = [" + ", ".join(["10"] * n) + "]")
    text = text.replace("drive_amplitude = [1e-3]", "drive_amplitude = [" + ", ".join(["1e-9"] * n) + "]")
    p = tmp_path / "lines.toml"
    p.write_text(text)
    return p


def _binary_file(tmp_path: Path) -> Path:
    p = tmp_path / "scene.png"
    p.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR" + bytes(range(256)))
    return p


ROOF = str(SCENES / "roof_frame.toml")
CASES = {
    "binary": (lambda d: [str(_binary_file(d))], "not a UTF-8 TOML file"),
    "nesting": (lambda d: [str(CORPUS / "deep_arrays.toml")], "nesting deeper than 32"),
    "long-expression": (lambda d: [ROOF, "--set", "sun.inclination=" + "1+" * 50_000 + "1"], "at most 200"),
    "noise": (lambda d: [ROOF, "--set", "noise.sigma=1e308"], "noise.sigma"),
    "negative-seed": (lambda d: [ROOF, "--seed", "-1"], r"seed: .*\[0, 2\^32\)"),
    "big-seed": (lambda d: [ROOF, "--seed", str(2**32)], r"seed: .*\[0, 2\^32\)"),
    "drive-lines": (lambda d: [str(_drive_lines_file(d, 300_000))], "300000 lines"),
    "samples": (lambda d: [str(CORPUS / "too_many_samples.toml")], "100000000 samples"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_simulate_refuses_bad_input_in_one_line_without_output(tmp_path, case):
    args, message = CASES[case]
    out = tmp_path / "out"
    out.mkdir()
    r = run_cli("simulate", *args(tmp_path), "-o", str(out), "--plot")
    assert r.returncode == 2, r.stderr[-2000:]
    assert "Traceback" not in r.stderr
    lines = r.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("vibinverse: error: "), r.stderr[:2000]
    assert len(lines[0]) < 500
    assert re.search(message, lines[0]), lines[0]
    assert list(out.iterdir()) == []
