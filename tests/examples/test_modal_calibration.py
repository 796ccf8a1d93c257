"""examples/modal_calibration.py: its draws follow the priors it fits with, and its coverage counts
what it says."""

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from vibinverse.priors import parse_prior

PATH = Path(__file__).resolve().parents[2] / "examples" / "modal_calibration.py"
spec = importlib.util.spec_from_file_location("modal_calibration", PATH)
mc = importlib.util.module_from_spec(spec)
spec.loader.exec_module(mc)


def test_draws_lie_in_the_priors_the_fit_uses():
    for seed in range(20):
        t, y, truth = mc.draw(seed)
        assert t.size == 4000 and np.all(np.isfinite(y))
        for name, value in truth.items():
            lo, hi = parse_prior(mc.PRIORS[name], name).bounds
            assert lo <= value <= hi
    # log-uniform damping: the median of many draws is the priors' geometric mean sqrt(0.005 * 0.05)
    zetas = [mc.draw(s)[2]["modes[0].damping_ratio"] for s in range(400)]
    assert np.median(zetas) == pytest.approx(math.sqrt(0.005 * 0.05), rel=0.15)  # ~2.5 se of a median of 400


def test_coverage_counts_the_intervals_that_hold_the_truth():
    records = [
        {"truth": {"a": 1.0}, "map": {"a": (0.5, 1.5)}},
        {"truth": {"a": 1.0}, "map": {"a": (1.2, 1.5)}},  # truth below the interval
        {"truth": {"a": 2.0}, "map": {"a": (0.5, 1.5)}},  # truth above
        {"truth": {"a": 1.5}, "map": {"a": (0.5, 1.5)}},  # on the edge: held
    ]
    (row,) = mc.coverage(records, ("map",))
    assert row["coverage90"] == 0.5 and row["truth_above"] == 0.25 and row["truth_below"] == 0.25
    assert row["se"] == pytest.approx(0.15)


def test_one_draw_fits_with_intervals_around_the_estimate():
    out = mc.fit_draw(3, ("map",))
    for name, (lo, hi) in out["map"].items():
        assert lo < hi
        assert lo < out["truth"][name] * 3 and hi > out["truth"][name] / 3  # the right order of magnitude
