"""`bench --imaging` end to end on a small imager: every row present, the numbers consistent."""

import math

import pytest

from tests.conftest import SCENES
from vibinverse.bench.imaging_bench import plot, run


@pytest.mark.slow
def test_a_small_imaging_bench_has_every_row(tmp_path):
    # 16 x 16 pixels of 5 m over the 80 m field: 100 wholly on the roof
    result = run(SCENES, quick=True, size=16, frames=2000, counts=(1, 4))
    im, det, fits = result["imager"], result["detection"], result["fits"]
    assert im["pixels"] == 256 and im["frames"] == 2000 and im["warm_s"] > 0
    assert det["pixels"] == 256 and det["frames"] == 1000 and det["cube_mb"] == pytest.approx(256 * 1000 * 8 / 2**20)
    assert det["ratio"] == pytest.approx(det["rfft_s"] / det["detect_s"])
    assert det["peak_above_mb"] > 0  # tracemalloc saw the detection's arrays
    # the drive line (10 Hz) is found in the rendered cube (resolution 1 / 5 s = 0.2 Hz)
    assert any(abs(f - 10.0) <= 0.2 for f in det["lines_hz"])
    assert [r["pixels"] for r in fits] == [1, 4]
    assert fits[0]["cost_vs_one"] == 1.0 and math.isfinite(fits[1]["drive_frequency_sd"])
    # 4 pixels know the drive frequency better than one (on 5 s one pixel's Laplace sd is not yet
    # asymptotic, so the ratio is not the 1 / sqrt(N) of the full bench)
    assert fits[1]["drive_frequency_sd"] < fits[0]["drive_frequency_sd"]
    (real,) = result["real_videos"]  # the real-size case: measured with the corpus, said skipped without
    if "skipped" not in real:
        assert real["seconds"] > 0 and real["peak_mb"] > real["base_mb"] > 0
        assert any(abs(f - 32.0) < 0.6 for f in real["claimed_hz"])  # the fork
    else:
        assert "realdata" in real["skipped"] or "corpus" in real["skipped"]
    plot(result, tmp_path / "imaging.png")
    assert (tmp_path / "imaging.png").stat().st_size > 10_000
