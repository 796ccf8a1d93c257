"""The result file: strict JSON in it (and everywhere we write JSON), and one-line errors for a file
that is not a readable vibinverse result."""

import json
import math
import os
from pathlib import Path

import numpy as np
import pytest

import vibinverse as vi
from tests.conftest import run_cli, unbounded_result
from vibinverse.errors import DataError
from vibinverse.io import jsonio
from vibinverse.io.builtin import builtin_scene
from vibinverse.result import read_result

CORPUS = Path(__file__).resolve().parents[1] / "corpus" / "data"


def strict_loads(text: str):
    """json.loads that refuses the NaN / Infinity / -Infinity tokens (not JSON, RFC 8259)."""
    return json.loads(text, parse_constant=lambda c: (_ for _ in ()).throw(ValueError(f"non-JSON token {c}")))


@pytest.fixture(scope="module")
def result_file(tmp_path_factory) -> Path:
    """A valid result netCDF of a quick spectral fit of the plate scene."""
    scene = vi.load_scene(builtin_scene("roof_elastic"))
    obs = vi.simulate(scene, seed=1)
    path = tmp_path_factory.mktemp("result") / "result.nc"
    vi.fit(vi.series(obs.time, obs.intensity, scene=scene), scene, method="spectral").to_netcdf(path)
    return path


# ------------------------------------------------------------------ strict JSON


def test_the_summary_in_the_result_is_strict_json_and_says_which_values_were_not_finite(tmp_path):
    result = unbounded_result()
    text = result.to_inference_data().observed_data.attrs["vibinverse_summary"]
    doc = strict_loads(text)
    sigma = doc["parameters"]["noise.sigma"]
    assert sigma["prior"] == "normal(0.6, 0.1)" and sigma["prior_bounds"] == [None, None]
    assert doc["diagnostics"]["rhat_max"] is None and doc["diagnostics"]["ess_min"] is None
    # each null that stands for a non-finite number is named, with the number, in "non_finite"
    assert doc["non_finite"]["/parameters/noise.sigma/prior_bounds/0"] == "-Infinity"
    assert doc["non_finite"]["/diagnostics/rhat_max"] == "NaN"
    assert doc["non_finite"]["/diagnostics/tau_max"] == "Infinity"
    # reading the result back restores them: the summary is the one in memory
    summary, _ = read_result(result.to_netcdf(tmp_path / "r.nc"))
    assert summary["parameters"]["noise.sigma"]["prior_bounds"] == [-math.inf, math.inf]
    assert math.isnan(summary["diagnostics"]["rhat_max"]) and summary["diagnostics"]["tau_max"] == math.inf
    assert "non_finite" not in summary


def test_a_map_fit_with_a_normal_prior_writes_strict_json(tmp_path):
    scene = vi.load_scene(builtin_scene("roof_elastic"))
    obs = vi.simulate(scene, seed=1)
    result = vi.fit(
        vi.series(obs.time, obs.intensity, scene=scene),
        scene,
        free={"noise.sigma": "normal(0.05, 0.01)", "surfaces.roof.motion.frequency": "uniform(30, 50)"},
        method="map",
    )
    doc = strict_loads(jsonio.dumps(result.summary()))
    assert doc["parameters"]["noise.sigma"]["prior_bounds"] == [None, None]
    strict_loads(result.to_inference_data().observed_data.attrs["vibinverse_summary"])


def test_jsonio_dumps_numpy_and_non_finite_values_as_strict_json():
    doc = {
        "a": np.float32(1.5),
        "b": np.arange(3),
        "c": [np.nan, -np.inf, (1, np.inf)],
        "d": np.bool_(True),
        "e": {"f/g~h": np.array([[np.nan]])},
        np.int64(3): "x",
    }
    text = jsonio.dumps(doc, indent=1)
    back = strict_loads(text)
    assert back["a"] == 1.5 and back["b"] == [0, 1, 2] and back["c"] == [None, None, [1, None]] and back["d"] is True
    assert back["3"] == "x" and back["e"]["f/g~h"] == [[None]]
    assert back["non_finite"] == {"/c/0": "NaN", "/c/1": "-Infinity", "/c/2/1": "Infinity", "/e/f~1g~0h/0/0": "NaN"}
    restored = jsonio.loads(text)
    assert math.isnan(restored["c"][0]) and restored["c"][1:] == [-math.inf, [1, math.inf]]
    assert math.isnan(restored["e"]["f/g~h"][0][0]) and "non_finite" not in restored
    # a list at the top has no place for the record: the nulls stay plain nulls
    assert strict_loads(jsonio.dumps([math.nan, 1.0])) == [None, 1.0]
    assert strict_loads(jsonio.dumps({"x": 1.0})) == {"x": 1.0}  # nothing to record, no record
    with pytest.raises(TypeError):
        jsonio.dumps({"x": 1j})


def test_design_and_study_json_are_strict(tmp_path):
    from vibinverse.design.spec import Axis
    from vibinverse.design.sweep import write_design
    from vibinverse.studies.common import write_study

    rows = [
        {"sensor.offset": 0.0, "sensitivity": 1e-3, "rel_crlb frequency": math.inf, "status": "ok"},
        {"sensor.offset": 0.1, "sensitivity": 2e-3, "rel_crlb frequency": 0.01, "status": "ok"},
    ]
    design = {
        "axes": [Axis("sensor.offset", (0.0, 0.1))],
        "targets": ["frequency"],
        "rows": rows,
        "threshold": 1e-4,
        "seconds": np.float64(0.5),
        "best": [rows[1], rows[0]],
    }
    write_design(design, tmp_path)
    doc = strict_loads((tmp_path / "design.json").read_text())
    assert doc["best"][1]["rel_crlb frequency"] is None and doc["best"][0]["rel_crlb frequency"] == 0.01
    assert doc["non_finite"] == {"/best/1/rel_crlb frequency": "Infinity"}
    write_study(
        tmp_path, "s", {"x": np.arange(3.0)}, {"peak": np.float64(math.inf), "n": np.int64(2)}, lambda fig: None
    )
    assert strict_loads((tmp_path / "s.json").read_text()) == {
        "peak": None,
        "n": 2,
        "non_finite": {"/peak": "Infinity"},
    }


# ------------------------------------------------------------------ unreadable result files


def _write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def _truncated(src: Path, dst: Path) -> Path:
    data = src.read_bytes()
    dst.write_bytes(data[: len(data) // 2])
    return dst


def _foreign(dst: Path) -> Path:
    import xarray as xr

    xr.Dataset({"x": ("i", np.arange(5.0))}).to_netcdf(dst, engine="h5netcdf")
    return dst


def _edited(src: Path, dst: Path, summary: str | None = None, drop: str | None = None) -> Path:
    import h5py

    dst.write_bytes(src.read_bytes())
    with h5py.File(dst, "a") as f:
        if summary is not None:
            f["observed_data"].attrs["vibinverse_summary"] = summary
        if drop is not None:
            del f[drop]
    return dst


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda d, good: d / "missing.nc", "file not found"),
        (lambda d, good: d, "is a directory"),
        (lambda d, good: _write(d / "empty.nc", b""), "is empty"),
        (lambda d, good: _write(d / "random.nc", os.urandom(4096)), "not a netCDF"),
        (lambda d, good: CORPUS / "random_bytes.nc", "not a netCDF"),
        (lambda d, good: CORPUS / "text.nc", "not a netCDF"),
        (lambda d, good: _truncated(good, d / "half.nc"), "truncated or corrupt"),
        (lambda d, good: _foreign(d / "foreign.nc"), "not a vibinverse result"),
        (lambda d, good: _edited(good, d / "badjson.nc", summary="{not json"), "vibinverse_summary"),
        (lambda d, good: _edited(good, d / "list.nc", summary="[1, 2]"), "vibinverse_summary"),
        (lambda d, good: _edited(good, d / "noparams.nc", summary='{"method": "x"}'), "parameters"),
        (
            lambda d, good: _edited(
                good, d / "badnum.nc", summary=_summary_with(good, lambda s: _set_first(s, "median", "abc"))
            ),
            "median",
        ),
        (lambda d, good: _edited(good, d / "notime.nc", drop="constant_data"), "constant_data"),
    ],
)
def test_an_unreadable_result_is_one_line_naming_the_file(make, message, result_file, tmp_path):
    path = make(tmp_path, result_file)
    with pytest.raises(DataError, match=message) as err:
        read_result(path)
    text = str(err.value)
    assert "\n" not in text and text.startswith("result: ") and str(path) in text


def _summary_with(good: Path, edit) -> str:
    summary, _ = read_result(good)
    edit(summary)
    return jsonio.dumps(summary)


def _set_first(summary: dict, key: str, value) -> None:
    next(iter(summary["parameters"].values()))[key] = value


def test_report_on_a_foreign_file_exits_2_with_one_line(result_file, tmp_path):
    bad = _truncated(result_file, tmp_path / "half.nc")
    r = run_cli("report", str(bad), "-o", str(tmp_path / "rep"))
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.strip().count("\n") == 0 and "truncated or corrupt" in r.stderr
    assert not (tmp_path / "rep" / "report.html").exists()
