"""examples/oma_calibration.py: a tiny quick run counts what it says, and -o writes the document it
prints (docs/validation/oma.md's calibration table is made from it)."""

import importlib.util
import json
from pathlib import Path

import pytest

PATH = Path(__file__).resolve().parents[2] / "examples" / "oma_calibration.py"
spec = importlib.util.spec_from_file_location("oma_calibration", PATH)
oc = importlib.util.module_from_spec(spec)
spec.loader.exec_module(oc)


def test_output_writes_the_settings_and_each_case(tmp_path, capsys):
    path = tmp_path / "oma_calibration.json"
    assert oc.main(["1", "three_storey", "--quick", "-o", str(path)]) == 0
    assert "wrote" in capsys.readouterr().out
    out = json.loads(path.read_text())
    assert out["settings"] == {"n_sets": 1, "quick": True, "cases": ["three_storey"]}
    (case,) = out["cases"]
    assert case["case"] == "three_storey" and case["n_sets"] == 1 and case["quick"] is True
    assert case["modes"] == 3 and case["channels"] == 3 and case["duration"] == 300.0 and case["fs"] == 100.0
    assert case["what"]
    for key in ("frequency", "damping_ratio", "shape"):
        entry = case[key]
        assert entry["n"] <= case["modes"] * (case["channels"] if key == "shape" else 1)
        assert entry["coverage"] is None or 0.0 <= entry["coverage"] <= 1.0


@pytest.mark.parametrize(
    ("argv", "says"), [(["x"], "whole number"), (["0"], "at least 1"), (["2", "nope"], "unknown case")]
)
def test_bad_arguments_stop_with_one_line(argv, says):
    with pytest.raises(SystemExit, match=says) as stop:
        oc.main(argv)
    assert "\n" not in str(stop.value.code)
