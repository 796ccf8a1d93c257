"""examples/io_calibration.py: it runs, its counts add up, and -o writes the document it prints."""

import importlib.util
import json
from pathlib import Path

import pytest

PATH = Path(__file__).resolve().parents[2] / "examples" / "io_calibration.py"
spec = importlib.util.spec_from_file_location("io_calibration", PATH)
ic = importlib.util.module_from_spec(spec)
spec.loader.exec_module(ic)


def test_two_sets_give_counts_and_coverages(capsys):
    assert ic.main(["2"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["sets"] == 2 and out["fs"] == 200.0 and out["duration"] == ic.DURATION
    (level,) = out["levels"]
    assert level["noise"] == 0.05 and len(level["modes"]) == 2
    for m in level["modes"]:
        assert m["found"] + m["missed"] == 2
        assert m["found"] == 2  # two well-driven modes at 5 % sensor noise: both found every time
        for key in ("coverage_frequency", "coverage_damping_ratio"):
            assert m[key] in (0.0, 0.5, 1.0)


def test_output_writes_every_noise_level_with_its_settings(tmp_path, capsys):
    path = tmp_path / "sub" / "io_calibration.json"
    assert ic.main(["1", "200", "0.05", "0.1", "-o", str(path)]) == 0
    assert "wrote" in capsys.readouterr().out
    out = json.loads(path.read_text())
    assert out["sets"] == 1 and out["fs"] == 200.0 and out["band"] == list(ic.BAND)
    assert [level["noise"] for level in out["levels"]] == [0.05, 0.1]
    assert [m["frequency"] for m in out["true_modes"]] == [f for f, _ in ic.MODES]
    for level in out["levels"]:
        assert [m["found"] + m["missed"] for m in level["modes"]] == [1, 1]


@pytest.mark.parametrize(
    ("argv", "says"), [(["x"], "whole number"), (["2", "100"], "above 120"), (["2", "200", "-1"], "at least 0")]
)
def test_bad_arguments_stop_with_one_line(argv, says):
    with pytest.raises(SystemExit, match=says) as stop:
        ic.main(argv)
    assert "\n" not in str(stop.value.code)
