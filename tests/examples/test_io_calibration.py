"""examples/io_calibration.py: it runs and its counts add up."""

import importlib.util
import json
from pathlib import Path

PATH = Path(__file__).resolve().parents[2] / "examples" / "io_calibration.py"
spec = importlib.util.spec_from_file_location("io_calibration", PATH)
ic = importlib.util.module_from_spec(spec)
spec.loader.exec_module(ic)


def test_two_sets_give_counts_and_coverages(capsys):
    assert ic.main(["2"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["sets"] == 2 and len(out["modes"]) == 2
    for m in out["modes"]:
        assert m["found"] + m["missed"] == 2
        assert m["found"] == 2  # two well-driven modes at 5 % sensor noise: both found every time
        for key in ("coverage_frequency", "coverage_damping_ratio"):
            assert m[key] in (0.0, 0.5, 1.0)
