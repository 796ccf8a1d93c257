"""The robustness bench's peers: SSI's stabilization diagram gives its clusters, and each peer
recovers the resonance of a clean data set."""

import importlib.util

import numpy as np
import pytest

from vibinverse.bench import robustness_bench as rb
from vibinverse.bench import robustness_cases as rc
from vibinverse.bench import robustness_peers as rp

# ------------------------------------------------------------------ the peers


def test_stable_clusters_of_a_stabilization_diagram():
    """Poles stable at one frequency over most orders form a mode; a scatter of noise poles does not."""
    orders = 20
    fn = np.full((10, orders), np.nan)
    xi = np.full((10, orders), np.nan)
    rng = np.random.default_rng(0)
    fn[0, 2:] = 3.46 * (1 + 1e-3 * rng.standard_normal(orders - 2))
    xi[0, 2:] = 0.014 * (1 + 0.01 * rng.standard_normal(orders - 2))
    fn[1, 4:] = 10.0
    xi[1, 4:] = 1e-4 * rng.random(orders - 4)  # a line: damping ~0, stable only thanks to the floor
    fn[2, :] = rng.uniform(1, 20, orders)  # noise poles
    xi[2, :] = rng.uniform(0.01, 0.1, orders)
    lab = rp.stability_labels(fn, xi, 0.05, 0.1, 0.002)
    clusters = rp.stable_clusters(fn, xi, lab, 0.4, lo=0.5, hi=25.0)
    assert [round(f, 2) for f, _ in clusters] == [3.46, 10.0]
    assert clusters[1][1] < rp.LINE_DAMPING < clusters[0][1]
    assert rp.stability_labels(fn, xi, 0.05, 0.1, 0.0)[1].sum() <= 2  # without the floor the line is lost


@pytest.mark.skipif(importlib.util.find_spec("celerite2") is None, reason="celerite2 is not installed")
def test_celerite2_peer_recovers_the_clean_resonance():
    data = rc.simulate("clean", 1)
    out = rp.Celerite2Fitter().fit(data.time, data.intensity, (1, 1))
    assert not out.failed, out.note
    assert abs(out.frequencies[0] / rc.RESONANCE.frequency - 1) < 0.02
    assert abs(out.line_frequencies[0] - 10.0) < 0.01 and abs(out.line_amplitudes[0] - 0.15) < 0.05
    assert out.modes_detected == [True] and out.lines_detected == [True]
    lo, hi = out.intervals["modes[0].frequency"]
    assert lo < out.frequencies[0] < hi and hi - lo < 0.2
    assert "lines[0].amplitude" in out.intervals and "modes[0].damping_ratio" in out.intervals


@pytest.mark.skipif(importlib.util.find_spec("pyoma2") is None, reason="pyOMA2 is not installed")
def test_ssi_peer_finds_the_three_ambient_modes():
    data = rc.simulate("three_modes", 0)
    out = rp.SSIFitter().fit(data.time, data.intensity)
    assert not out.failed, out.note
    found = rb.match([1.6, 2.1, 2.7], out.frequencies, tol=0.02)
    assert None not in found and out.intervals == {}
