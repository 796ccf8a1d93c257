"""Paper Figs. 8-10 (quick): quadrant against centred footprint, linear then saturating."""

import numpy as np
import pytest


def test_quadrant_beats_centered_by_100x(results):
    _, _, d = results
    off = np.array(d["fig9"]["view_offset_rad"])
    ratio = np.array(d["fig9"]["sensitivity"]) / np.array(d["fig8"]["sensitivity"])
    assert ratio[np.argmin(abs(off - 0.015))] >= 100
    assert np.median(ratio[np.abs(off) >= 0.005]) >= 100


def test_fig10_linear_then_saturating(results):
    _, _, d = results
    assert d["fig10"]["small_amplitude_loglog_slope"] == pytest.approx(1.0, abs=0.1)
    s = np.array(d["fig10"]["sensitivity"])
    assert 0.3 < s.max() < 1.0
    a = np.array(d["fig10"]["amplitude_m"])
    assert np.log(s[-1] / s[-2]) / np.log(a[-1] / a[-2]) < 0.8  # the log-log slope has bent away from 1
