"""What an identification reports (vibinverse.oma.result): a mode without an interval says so."""

import json
import math

import numpy as np

from vibinverse.oma.report import oma_html
from vibinverse.oma.result import OmaMode, OmaResult


def _mode() -> OmaMode:
    return OmaMode(
        frequency=2.0,
        damping_ratio=0.02,
        shape=np.array([0.8, 0.6]),
        frequency_interval=(1.99, 2.01),
        damping_ratio_interval=(0.015, 0.025),
        shape_interval=np.array([[0.7, 0.9], [0.5, 0.7]]),
        frequency_sd=0.006,
        damping_ratio_sd=0.003,
        shape_sd=np.array([0.05, 0.05]),
        band=(1.5, 2.5),
        level=1.0,
        warnings=["the posterior is not locally Gaussian at the MAP: no interval"],
    )


def test_a_mode_without_interval_is_null_in_json_and_says_so_in_text():
    bare = _mode().without_interval()
    assert _mode().has_interval and not bare.has_interval
    assert bare.frequency == 2.0 and math.isnan(bare.frequency_sd)
    doc = bare.to_json(("a", "b"))
    assert doc["frequency_interval"] == [None, None] and doc["damping_ratio_sd"] is None
    assert doc["shape_interval"] == {"a": [None, None], "b": [None, None]}
    json.dumps(doc, allow_nan=False)  # valid JSON: no NaN
    result = OmaResult(
        [bare], ("a", "b"), ("m", "m"), "displacement", [], np.array([1.0]), np.ones((1, 1)), 10, 1.0, 0.1, (0.5, 5.0)
    )
    text = result.table()
    assert "no interval" in text and "nan" not in text.lower()
    page = oma_html(result, "x.csv")
    assert "no interval" in page and ">nan" not in page.lower()


def test_a_broad_mode_is_kept_but_not_claimed():
    """A mode damped above 0.2 (a broad hump: vibinverse.detection.BROAD_DAMPING) stays in the
    table, its JSON says claimed false, and the realdata bench does not count it as a claim."""
    from dataclasses import replace

    sharp, broad = _mode(), replace(_mode(), damping_ratio=0.35)
    assert sharp.claimed and sharp.to_json(("a", "b"))["claimed"] is True
    assert not broad.claimed and broad.to_json(("a", "b"))["claimed"] is False
