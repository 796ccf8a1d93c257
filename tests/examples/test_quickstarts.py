"""examples/api_quickstart.py and examples/custom_model.py run from the repository root, as their
docstrings say, and leave nothing behind in the temporary directory."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
@pytest.mark.parametrize("example", ["api_quickstart.py", "custom_model.py"])
def test_an_example_runs_and_leaves_no_files(example, tmp_path):
    env = {**os.environ, "TMPDIR": str(tmp_path), "MPLBACKEND": "Agg"}
    run = subprocess.run(
        [sys.executable, str(ROOT / "examples" / example)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert run.returncode == 0, run.stderr[-2000:]
    assert "90%" in run.stdout  # it printed its intervals
    assert list(tmp_path.iterdir()) == []  # its scratch (a result file, an emcee checkpoint) is gone
