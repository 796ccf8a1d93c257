"""Paper Fig. 4 through `vibinverse study fig4`: the frame's resonances, figure and curve."""

import numpy as np
import pytest

from tests.conftest import run_cli


def test_study_fig4_writes_figure_curve_and_numbers(tmp_path):
    import json

    r = run_cli("study", "fig4", "-o", str(tmp_path))
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("fig4:")
    summary = json.loads((tmp_path / "fig4.json").read_text())
    res = summary["resonances_hz"]
    for name, f in {"vertical": 2.0, "lateral": 4.0, "tilt": 2 * np.sqrt(3), "twist": 4 * np.sqrt(3)}.items():
        assert res[name] == pytest.approx(f, rel=1e-3)
    peaks = summary["spectral_peaks_hz"]
    assert peaks["x_cm"] == pytest.approx(4.0, abs=0.01) and peaks["z_cm"] == pytest.approx(2.0, abs=0.01)
    assert peaks["tilt"] == pytest.approx(2 * np.sqrt(3), abs=0.01)
    assert (tmp_path / "fig4.png").read_bytes()[:4] == b"\x89PNG"
    assert (tmp_path / "fig4.csv").read_text().startswith("time_s,x_cm_m,z_cm_m,tilt_rad,frequency_hz")
    r = run_cli("study", "fig99", "-o", str(tmp_path))
    assert r.returncode == 2 and "invalid choice" in r.stderr
