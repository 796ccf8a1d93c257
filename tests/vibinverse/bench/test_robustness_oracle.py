"""The robustness bench's oracle: its gains are the exact Gaussian log-likelihood ratios, its
thresholds the order search's, its detection rates the Gaussian prediction."""

import math

import numpy as np
import pytest
from scipy.linalg import expm

from vibinverse.bench import robustness_cases as rc
from vibinverse.bench import robustness_oracle as ro

# ------------------------------------------------------------------ the oracle


def _autocovariance(mode, unit, kmax):
    """q's autocovariance at lags 0, unit, .., kmax unit: [Phi^k P]_00, Phi = expm(A unit)."""
    w, z = 2 * np.pi * mode["frequency"], mode["damping_ratio"]
    phi = expm(np.array([[0.0, 1.0], [-(w**2), -2 * z * w]]) * unit)
    x = np.diag([mode["rms"] ** 2, (w * mode["rms"]) ** 2])
    out = np.empty(kmax + 1)
    for k in range(kmax + 1):
        out[k] = x[0, 0]
        x = phi @ x
    return out


def _brute_force_log_likelihood(case, t, parts, y, truth, drop=None):
    """ln N(y; mean, C) of the observed samples from scratch: the oscillator's autocovariance by
    powers of the matrix exponential (`_autocovariance`), the noise's from its definition, the gain and the
    drift as the data set's own; `drop` ("modes"/"lines", i) leaves that component out."""
    from scipy.stats import multivariate_normal

    good = np.isfinite(y)
    tt, idx = t[good], np.flatnonzero(good)
    s = 1.0 + parts["gain"][good]
    lag = np.abs(tt[:, None] - tt[None, :])
    cov = {
        "white": lambda: case.sigma**2 * np.eye(tt.size),
        "ar1": lambda: case.sigma**2 * case.ar_phi ** np.abs(idx[:, None] - idx[None, :]),
        "1/f": lambda: sum(case.sigma**2 / 4 * np.exp(-lag / tau) for tau in case.flicker_times),
    }[case.noise]()
    unit = 1.0 / (case.fs * rc.FINE)  # every case's stamps lie on the fine grid
    steps = np.round(lag / unit).astype(int)
    for i, m in enumerate(truth["modes"]):
        if drop != ("modes", i):
            cov = cov + np.outer(s, s) * _autocovariance(m, unit, int(steps.max()))[steps]
    mean = np.full(tt.size, case.level)
    for j, ln in enumerate(truth["lines"]):
        if drop != ("lines", j):
            mean = mean + ln["amplitude"] * np.cos(2 * np.pi * ln["frequency"] * tt + ln["phase"])
    mean = s * mean + parts["drift"][good]
    return multivariate_normal.logpdf(y[good], mean, cov)


@pytest.mark.parametrize("name", ["ar1", "gaps", "irregular", "drift", "one_over_f", "gain_drift", "three_modes"])
def test_oracle_gain_is_the_dense_gaussian_log_likelihood_ratio(name):
    """On a 1.5 s record (300 samples; three_modes 20 s at 20 Hz, 400), each component's oracle gain, by
    the Kalman filter or the module's dense Gaussian, is ln L with it minus ln L without it from a
    brute-force dense Gaussian (autocovariances by powers of the matrix exponential): 1e-8 relative, the
    rounding of two log-likelihoods of ~-500 (each to ~1e-13 relative) over a gain of >= 0.1."""
    from dataclasses import replace

    case = replace(rc.CASES[name], duration=20.0 if name == "three_modes" else 1.5)
    out = ro.oracle(case, 3)
    t, parts, truth = rc.simulate_parts(case, 3)
    y = rc.simulate(case, 3).intensity
    assert [o["likelihood"] for o in out] == ["dense" if name in ("one_over_f", "gain_drift") else "kalman"] * len(out)
    full = _brute_force_log_likelihood(case, t, parts, y, truth)
    kinds = [(k, i) for k in ("modes", "lines") for i in range(len(truth[k]))]
    assert [o["kind"] for o in out] == [k for k, _ in kinds]
    for o, (kind, i) in zip(out, kinds):
        expected = full - _brute_force_log_likelihood(case, t, parts, y, truth, drop=(kind, i))
        assert abs(expected) > 0.1
        assert o["gain"] == pytest.approx(expected, rel=1e-8)
        assert o["detected"] == (o["gain"] > o["threshold"]) and o["threshold"] > o["threshold_known"]
    if out[0]["likelihood"] == "kalman":  # the dense path agrees on the cases the filter is exact for
        dense = ro.oracle(case, 3, likelihood="dense")
        np.testing.assert_allclose([o["gain"] for o in dense], [o["gain"] for o in out], rtol=1e-8)


def test_oracle_thresholds_are_the_order_search_and_detection_ones():
    """n = 4000 at 200 Hz over 20 s: a mode needs 1.5 ln n + ln M (M = (100 - 1/19.995) x 19.995,
    the order search's), a line the larger of that and 12.5 + ln N (N = prior width x (span + dt),
    the detection test's); at a known frequency 1.5 ln n, and max(1.5 ln n, 12.5) for a line."""
    out = {o["kind"]: o for o in ro.oracle("clean", 0)}
    span = 3999 / 200.0
    m = (100.0 - 1.0 / span) * span
    assert out["modes"]["threshold"] == pytest.approx(1.5 * math.log(4000) + math.log(m), rel=1e-12)
    assert out["modes"]["threshold_known"] == pytest.approx(1.5 * math.log(4000), rel=1e-12)
    n_line = (100.0 - 1.0 / span * (1 + 1e-9)) * 20.0
    assert out["lines"]["threshold"] == pytest.approx(12.5 + math.log(n_line), rel=1e-12)
    assert out["lines"]["threshold_known"] == 12.5
    with pytest.raises(ValueError, match="likelihood"):
        ro.oracle("one_over_f", 0, likelihood="kalman")  # four OU processes: not the filter's model
    with pytest.raises(ValueError, match="likelihood"):
        ro.oracle("clean", 0, likelihood="nope")
    assert ro.oracle("noise_only", 0) == []


def _line_information(case, seeds):
    """lambda = s' C^-1 s of each data set's line s (C: the resonance plus white noise, Toeplitz on
    the uniform 20 s record, its first column by powers of the matrix exponential)."""
    from scipy.linalg import solve_toeplitz

    t = rc.simulate_parts(case, seeds[0])[0]
    m = case.modes[0]
    col = _autocovariance({"frequency": m.frequency, "damping_ratio": m.damping_ratio, "rms": m.rms}, t[1], t.size - 1)
    col[0] += case.sigma**2
    ln = case.lines[0]
    x = np.column_stack([np.cos(2 * np.pi * ln.frequency * t), -np.sin(2 * np.pi * ln.frequency * t)])
    gram = x.T @ solve_toeplitz(col, x)  # s = A (cos phase, sin phase) . x: lambda a quadratic form
    lam = []
    for seed in seeds:
        phase = rc.simulate_parts(case, seed)[2]["lines"][0]["phase"]
        u = ln.amplitude * np.array([math.cos(phase), math.sin(phase)])
        lam.append(float(u @ gram @ u))
    return np.array(lam)


@pytest.mark.parametrize("name", ["weak_drive", "near_drive"])
def test_oracle_line_detection_rate_is_the_gaussian_prediction(name):
    """At the truth a line's gain is s' C^-1 (y - mean without it) - s' C^-1 s / 2 = lambda / 2 +
    s' C^-1 e: Gaussian, mean lambda / 2, variance lambda, exactly. Over seeds 0-49 the standardized
    gains are N(0, 1) (mean within 3 / sqrt 50, variance within 3 sqrt(2 / 49)), and the number of
    data sets passing each threshold is a sum of independent Bernoulli(p_s), p_s = P(N(lambda/2,
    lambda) > threshold): within 3 sd sqrt(sum p (1 - p)) of sum p, plus 1 for the discreteness.
    near_drive's amplitude is chosen so that the mean p_s (the expected oracle rate) is >= 0.97."""
    from scipy.stats import norm

    case = rc.CASES[name]
    seeds = list(range(50))
    lam = _line_information(case, seeds)
    tests = [next(o for o in ro.oracle(case, s) if o["kind"] == "lines") for s in seeds]
    gain = np.array([o["gain"] for o in tests])
    zs = (gain - lam / 2) / np.sqrt(lam)
    assert abs(zs.mean()) < 3 / math.sqrt(50) and abs(zs.var(ddof=1) - 1) < 3 * math.sqrt(2 / 49)
    for key, limit in (("detected", "threshold"), ("detected_known", "threshold_known")):
        p = norm.sf((tests[0][limit] - lam / 2) / np.sqrt(lam))
        hits = sum(o[key] for o in tests)
        assert abs(hits - p.sum()) <= 3 * math.sqrt(np.sum(p * (1 - p))) + 1, (key, hits, p.sum())
    p = norm.sf((tests[0]["threshold"] - lam / 2) / np.sqrt(lam))
    if name == "near_drive":
        assert p.mean() >= 0.97
    else:  # the weak drive is at the information limit: about half of the records decide it
        assert 0.2 < p.mean() < 0.7


def test_oracle_refit_gain_of_a_lone_line_exceeds_the_truth_by_wilks():
    """The 10 Hz line, far from the resonance: refitting both orders (the full one from the truth,
    the one without the line likewise) raises its gain by the noise the line's three free parameters
    fit, chi2(3) / 2 asymptotically: mean 1.5, sd 1.22, so the mean over 8 quick records is 1.5
    within 3 x 1.22 / sqrt 8 = 1.3. A mode's refitted gain is far lower (the white noise, refitted
    without it, takes its variance); the dense cases have none."""
    out = [ro.oracle("clean", seed, quick=True, refit=True) for seed in range(8)]
    lines = [next(o for o in x if o["kind"] == "lines") for x in out]
    diff = np.array([o["gain_refit"] - o["gain"] for o in lines])
    assert abs(diff.mean() - 1.5) < 1.3
    assert all(o["detected_refit"] == (o["gain_refit"] > o["threshold"]) for o in lines)
    modes = [next(o for o in x if o["kind"] == "modes") for x in out]
    assert np.median([o["gain_refit"] - o["gain"] for o in modes]) < -5
    assert ro.oracle("one_over_f", 0, quick=True, refit=True)[0]["gain_refit"] is None
