"""Is a fitted line stationary: segment amplitudes, the chi-squared test with a material change,
the time of the change; on simulations, on a fit, and on the real beam whose 150 Hz drive stops."""

import math
from pathlib import Path

import numpy as np
import pytest

import vibinverse as vi
from vibinverse.stationarity import describe_change, line_stationarity, segment_amplitudes
from vibinverse.verdict import verdict

REALDATA = Path(__file__).resolve().parents[2].parent / "shared" / "realdata-dev"
BEAM = REALDATA / "beam_shaker_tones"


def record(rng, n=6000, fs=200.0, stop=None, step=1.0, noise=1.0):
    t = np.arange(n) / fs
    gate = np.ones(n) if stop is None else np.where(t < stop, 1.0, step)
    y = 0.6 * gate * np.sin(2 * np.pi * 12.3 * t) + 0.5 * np.sin(2 * np.pi * 31.7 * t + 1) + rng.normal(0, noise, n)
    return t, y


def test_segment_amplitudes_recover_each_line():
    rng = np.random.default_rng(0)
    t, y = record(rng, noise=0.01)
    amp, se, edges = segment_amplitudes(t, y, [12.3, 31.7], 4)
    np.testing.assert_allclose(amp, np.tile([0.6, 0.5], (4, 1)), rtol=0.01)
    assert (se < 0.002).all() and edges.size == 5


def test_a_stationary_line_is_rarely_flagged():
    """200 data sets of two stationary lines in white noise: flagged in at most ALPHA plus three
    standard errors of them (the material condition makes it rarer still)."""
    rng = np.random.default_rng(1)
    n, flagged = 200, 0
    for _ in range(n):
        t, y = record(rng)
        out = line_stationarity(t, y, {"line_0": 12.3, "line_1": 31.7})
        flagged += any(not e["stationary"] for e in out.values())
    assert flagged / n <= 1e-3 + 3 * math.sqrt(1e-3 * (1 - 1e-3) / n)


@pytest.mark.parametrize(("step", "word"), [(0.0, "stops"), (1.6, "changes amplitude")])
def test_a_line_that_stops_or_steps_is_flagged_with_its_time(step, word):
    rng = np.random.default_rng(2)
    t, y = record(rng, stop=18.0, step=step)
    out = line_stationarity(t, y, {"line_0": 12.3, "line_1": 31.7})
    entry = out["line_0"]
    assert not entry["stationary"] and out["line_1"]["stationary"]
    assert abs(entry["change_time_s"] - 18.0) <= 30.0 / entry["segments"]  # one segment
    assert word in describe_change("line_0", entry)


def test_too_short_a_record_is_not_checked():
    t = np.arange(100) / 100.0
    assert line_stationarity(t, np.sin(2 * np.pi * 3 * t), {"line_0": 3.0}) == {}


def test_a_fit_of_a_drive_that_stops_says_so():
    """The modal model fixed to two lines, one of which stops at 18 s of 30: the fit's diagnostics
    and its verdict name the change; the stationary line passes."""
    rng = np.random.default_rng(3)
    t, y = record(rng, stop=18.0, step=0.0, noise=0.5)
    result = vi.fit(vi.series(t, y, source="stopping drive"), {"modal": {"modes": 0, "lines": 2}}, method="map")
    checks = result.diagnostics["line_stationarity"]
    moving = [e for e in checks.values() if not e["stationary"]]
    assert len(moving) == 1 and abs(moving[0]["frequency_hz"] - 12.3) < 0.01
    v = verdict(result.summary())
    assert v.trusted is False and any("stops at t = " in r for r in v.reasons)


@pytest.mark.skipif(not BEAM.is_dir(), reason=f"the real recordings are not here: {BEAM} is absent")
def test_the_real_beam_drive_that_stops_mid_record():
    """Beam shaker, acceleration channel (../shared/realdata-dev, CC BY-SA 4.0, Chowdhury, Downey,
    Bakos, Conrad 2021): test 3 drops its 150 Hz tone at mid-record (9.85 s of 19.7) and steps the
    others; test 1 holds all three."""
    tones = {"line_0": 100.0, "line_1": 120.0, "line_2": 150.0}
    one = vi.load_series(BEAM / "data_set_1_downsampled_by_16.lvm", value_column="2")
    assert all(e["stationary"] for e in line_stationarity(one.time, one.intensity, tones).values())
    three = vi.load_series(BEAM / "data_set_3_downsampled_by_16.lvm", value_column="2")
    out = line_stationarity(three.time, three.intensity, tones)
    assert not out["line_2"]["stationary"] and "stops" in describe_change("line_2", out["line_2"])
    assert abs(out["line_2"]["change_time_s"] - 9.85) < 19.7 / out["line_2"]["segments"]
