"""The forward, likelihood and design bench rows have the documented fields."""

import pytest

from tests.conftest import SCENES


def test_forward_bench_rows_have_the_documented_fields():
    from vibinverse.bench.forward_bench import forward_rows, scaling_rows, speed_error_rows

    rows = forward_rows(SCENES, resolution=20, n_samples=400, log=lambda *a: None)
    assert [r["scene"] for r in rows] == ["roof_elastic", "glass_brewster", "roof_frame", "ground_rayleigh"]
    for r in rows:
        assert {"scene", "reference_s", "fast_s", "speedup", "rel_error"} <= set(r)
        assert r["rel_error"] <= 1e-3
    scaling = scaling_rows(SCENES, resolutions=(16,), samples=(100, 1000), log=lambda *a: None)
    assert [(r["subpixels"], r["samples"]) for r in scaling] == [(256, 100), (256, 1000)]
    se = speed_error_rows(SCENES, 24, n=200, coarse=(8,), log=lambda *a: None)
    assert {r["method"] for r in se} == {"fast", "dense"}
    from vibinverse.bench.likelihood_bench import likelihood_row

    lk = likelihood_row(SCENES / "roof_frame.toml", log=lambda *a: None)
    assert lk["samples"] == 4000 and lk["ours_us"] > 0 and lk["ratio"] > 0
    from vibinverse.bench.likelihood_bench import modal_likelihood_rows

    rows = modal_likelihood_rows(n=500, log=lambda *a: None)
    assert [r["goal"] for r in rows] == [1.0, 1.5] and all(r["ratio"] > 0 for r in rows)
    from vibinverse.bench.design_bench import design_row

    d = design_row(SCENES / "roof_elastic.toml", 4, workers=(1,), log=lambda *a: None)
    assert d["configurations"] == 16 and d["seconds"]["1"] > 0 and d["ms_per_configuration"]["1"] > 0


@pytest.mark.slow
def test_the_long_three_mode_row_fits_the_case_and_says_how(monkeypatch):
    """The bench's default-fit row on the three-mode case at its own 200 s (4000 samples; the bench
    stretches it to 1800 s) with IMPORTANCE_RECORD lowered below 4000, so the posterior comes from
    the path the 36 000-sample row takes: three modes, the largest frequency error under 1 % (the
    issue's target; the bench's 50 data sets give a median 0.22 %), the truths inside the
    intervals (seed 0), importance sampling named as the approximation."""
    import vibinverse.pipeline as pipeline
    from vibinverse.bench.likelihood_bench import long_modal_fit_row

    monkeypatch.setattr(pipeline, "IMPORTANCE_RECORD", 3999)
    row = long_modal_fit_row(duration=200.0, log=lambda *a: None)
    assert row["samples"] == 4000 and row["modes_found"] == 3
    assert row["max_frequency_error"] < 0.01 and row["intervals_hold_truth"]
    assert row["approximation"] == "importance" and row["wall_s"] > 0
    assert {"model_order_s", "importance_s"} <= set(row["timing"])


def test_the_hour_record_is_what_its_row_says():
    """`hour_record` (its first 5 minutes: the hour's simulation takes 8 s): 200 Hz, the three modes
    of HOUR_MODES as its truth, the first differences of the record carrying the walk's and the
    white noise's variance (plus the modes' small share), and a table that prints the hour row
    beside the three-mode row ("-" when skipped)."""
    import numpy as np

    from vibinverse.bench.forward_bench import table
    from vibinverse.bench.likelihood_bench import HOUR_MODES, HOUR_SIGMA, HOUR_WALK, hour_record

    data = hour_record(0, duration=300.0)
    assert data.time.size == 60_000 and np.allclose(np.diff(data.time), 0.005)
    assert [(m["frequency"], m["damping_ratio"], m["rms"]) for m in data.truth["modes"]] == list(HOUR_MODES)
    # over a step of 5 ms each mode moves little: the differences are walk + twice the white noise
    diff_var = float(np.var(np.diff(data.intensity)))
    expected = HOUR_WALK**2 * 0.005 + 2 * HOUR_SIGMA**2
    assert expected < diff_var < 1.2 * expected
    text = table({"long_modal_fit": None, "hour_fit": None})
    assert "a one-hour 200 Hz record (three modes, random-walk drift): - (skipped with --quick)" in text
