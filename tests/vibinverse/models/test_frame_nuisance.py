"""The frame model with nuisance terms beside its tilt modes (`nuisance` table, `vi.fit(...,
noise=, drift=, gain=)`, `fit --scene S --noise ar1`): the composed likelihood against the dense
Gaussian density of the same covariance, the tables' layout, bad input, and a fit of AR(1) sensor
noise that the white-noise frame model gets wrong."""

import math

import numpy as np
import pytest
import xarray as xr
from scipy.linalg import toeplitz
from scipy.stats import multivariate_normal

import vibinverse as vi
from tests.conftest import K, frame, frame_series
from vibinverse.errors import InputError, SceneError
from vibinverse.models import build_model
from vibinverse.posterior import Posterior
from vibinverse.terms.drift import slepian_gain_basis as gain_basis


def _series(table, seed=0, ar=None):
    return frame_series(table, seed, ar)


def _tilt_autocov(c, n):
    """The white-noise frame's tilt covariance at lags 0..n-1 (uniform grid): h Phi^k P0 h."""
    gamma, v = np.empty(n), c.p0 @ c.h
    for k in range(n):
        gamma[k] = c.h @ v
        v = c.phi @ v
    return gamma


def test_composed_frame_likelihood_is_the_dense_gaussian_density():
    """Tilt modes + AR(1) + random walk + gain drift: the engine's log-likelihood equals the
    normal density whose covariance is m_i m_j (the tilt's) + the AR(1)'s + the walk's + sigma^2."""
    table = frame("sampling.duration=1.0", "noise.sigma=0.6")
    data = _series(table)
    plain = build_model(table, data)
    t = data.time - data.time[0]
    v = {"ar.rms": 0.5, "ar.time": 0.03, "drift.rate": 0.2, "gain.a1": 0.1, "gain.a2": -0.05}
    composed = build_model({**table, "nuisance": {"noise": "ar1", "drift": "walk", "gain": 2}}, data)
    c0 = plain.components({})
    m = 1.0 + np.array([0.1, -0.05]) @ gain_basis(t, 2)
    cov = np.outer(m, m) * toeplitz(_tilt_autocov(c0, t.size))
    cov += 0.25 * np.exp(-np.abs(t[:, None] - t[None, :]) / 0.03) + 0.04 * np.minimum(t[:, None], t[None, :])
    cov += c0.r * np.eye(t.size)
    dense = multivariate_normal(m * c0.mean, cov).logpdf(data.intensity)
    assert composed.log_likelihood(v) == pytest.approx(dense, rel=1e-9)
    lls = composed.pointwise_log_likelihood(v)
    assert np.nansum(lls) == pytest.approx(dense, rel=1e-9)
    assert composed.residuals(v).shape == t.shape


def test_without_nuisance_terms_the_frame_model_is_unchanged():
    table = frame("sampling.duration=2.0", "noise.sigma=0.6")
    data = _series(table)
    model = build_model(table, data)
    assert not model.nuisance and not model.components({}).composed
    assert model.describe() is None
    composed = build_model({**table, "nuisance": {"noise": "ar1"}}, data)
    # an AR(1) term of (nearly) no variance changes the likelihood by rounding only
    tiny = {"ar.rms": 1e-12, "ar.time": 0.01}
    assert composed.log_likelihood(tiny) == pytest.approx(model.log_likelihood({}), rel=1e-12)


def test_nuisance_parameters_priors_units_and_description():
    table = frame("sampling.duration=2.0", "noise.sigma=0.6")
    data = _series(table)
    model = build_model({**table, "nuisance": {"noise": "1/f", "drift": "integrated", "white": False}}, data)
    priors = model.default_priors()
    assert {"flicker.rms", "flicker.corner", "drift.rate"} <= set(priors) <= model.fittable()
    assert "noise.sigma" not in priors and "noise.sigma" not in model.fittable()
    assert model.units("flicker.corner") == ("Hz", "1/f noise upper corner frequency")
    assert model.describe()["terms"] == "1/f noise, integrated random-walk drift"
    for g in model.guesses({n: p.bounds for n, p in priors.items()}):
        assert "noise.sigma" not in g and "flicker.rms" in g
    assert math.isfinite(model.log_likelihood(model.guesses({})[0]))
    assert model.log_likelihood({"flicker.corner": -1.0}) == -math.inf


@pytest.mark.parametrize(
    ("nuisance", "message"),
    [
        ({"noise": "pink"}, "nuisance.noise: 'pink'; allowed: 'white', 'ar1', '1/f'"),
        ({"drift": "linear"}, "nuisance.drift: 'linear'"),
        ({"colour": 1}, "nuisance.colour: unknown key"),
        ({"white": False}, "nuisance.white: false needs a coloured noise"),
    ],
)
def test_bad_nuisance_tables_are_one_line_errors(nuisance, message):
    table = frame("sampling.duration=1.0")
    with pytest.raises(SceneError, match=message.replace("(", r"\(").replace(")", r"\)")):
        build_model({**table, "nuisance": nuisance}, _series(table))


def test_fit_options_name_the_bad_value():
    table = frame("sampling.duration=1.0")
    data = _series(table)
    with pytest.raises(SceneError, match=r"nuisance\.noise: 'pink'"):
        vi.fit(data, table, noise="pink", method="spectral")
    with pytest.raises(InputError, match="nuisance terms are fitted on a single series"):
        cube = xr.DataArray(np.zeros((4, 2, 2)), dims=("time", "y", "x"), coords={"time": np.arange(4.0)})
        vi.fit(cube, table, noise="ar1", pixels="all")


@pytest.mark.slow
def test_ar1_sensor_noise_is_fitted_beside_the_frame():
    """AR(1) sensor noise (phi 0.9, the white case's variance): the white-noise frame model reads
    a broad 8 Hz "resonance" (the issue's failure); with `noise="ar1"` the tilt frequency is within
    1 % and its 90 % interval holds the truth (seed 0: a regression test, not a calibration)."""
    table = frame("noise.sigma=0")
    data = _series(table, seed=0, ar=(0.9, 0.6))
    analyst = frame("noise.sigma=0.6")
    truth = 2.0 * math.sqrt(3.0)
    only_white = {"noise": "white", "drift": "none", "gain": False, "white": True}  # no search
    white = vi.fit(data, analyst, method="map", **only_white).summary()["parameters"][K + "tilt_frequency"]
    assert abs(white["map"] / truth - 1) > 0.2
    result = vi.fit(data, analyst, method="map", noise="ar1", drift="none", gain=False, white=True)
    p = result.summary()["parameters"]
    tilt = p[K + "tilt_frequency"]
    assert abs(tilt["map"] / truth - 1) < 0.01
    assert tilt["q05"] <= truth <= tilt["q95"]
    assert p["ar.time"]["q05"] <= -0.005 / math.log(0.9) <= p["ar.time"]["q95"]
    assert result.summary()["data"]["model"]["terms"] == "AR(1) noise, white noise"


def test_the_drive_start_under_ar1_noise_is_the_drive():
    """AR(1) sensor noise (phi 0.9, sd 0.6) beside the sec. 4.2 roof, six data sets: every set's
    spectral starts (`guesses`) hold one with the drive within 0.05 Hz of 10 Hz. Ranked by raw power
    the candidates missed the drive in three of them (the tilt's 3.5 Hz and the noise's 0.3-1.8 Hz
    instead), and the nuisance search's MAP kept a drive where it started."""
    table = frame("noise.sigma=0")
    analyst = frame("noise.sigma=0.6")
    for seed in range(6):
        model = build_model(analyst, _series(table, seed=seed, ar=(0.9, 0.6)))
        drives = [g[K + "drive_frequency"] for g in model.guesses({})]
        assert any(abs(f - 10.0) < 0.05 for f in drives), (seed, drives)


def _gain_series(seed):
    from vibinverse.bench.robustness_scene import analyst_scene, simulate

    d = simulate("gain_drift", seed)
    return analyst_scene(), vi.series(d.time, d.intensity), d.truth


def test_a_gain_drift_scenes_starts_hold_the_drive_the_tilt_and_the_level():
    """The robustness bench's scene gain drift (the whole intensity, level 537, times 1 + g, max
    |g| 0.2), four data sets, under the model with a gain drift: one spectral start has the drive
    within 0.05 Hz of 10 Hz and the tilt within 10 % of 3.464 Hz (before: the tilt at the prior's
    lower edge, where the drift's leakage stood), and the gain's constant within 0.002 of the
    data set's mean relative change of the level (0 before: 300,000 ln-units down)."""
    for seed in range(4):
        analyst, series, truth = _gain_series(seed)
        model = build_model({**analyst, "nuisance": {"gain": True}}, series)
        guesses = model.guesses(Posterior(model).bounds)
        good = [g for g in guesses if abs(g[K + "drive_frequency"] - 10.0) < 0.05]
        assert good, (seed, [g[K + "drive_frequency"] for g in guesses])
        g = good[0]
        assert abs(g[K + "tilt_frequency"] / truth["tilt_frequency"] - 1) < 0.1, (seed, g[K + "tilt_frequency"])
        at_rest = model.observation(g)[0]
        assert abs(g["gain.a0"] - (np.nanmean(series.intensity) / at_rest - 1)) < 2e-3


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 2])
def test_the_nuisance_search_reads_a_gain_drift_as_a_gain_drift(seed):
    """The scene gain drift case (seeds 0, 2: the white-noise model's optimum reads the drift as a
    0.2 Hz tilt with the drive elsewhere): the search keeps a gain drift, and at its MAP the tilt
    is within 1.5 % of the truth and the drive within 0.01 Hz of 10 Hz (a regression test; the
    coverage over 50 data sets is on the robustness page)."""
    analyst, series, truth = _gain_series(seed)
    result = vi.fit(series, analyst, method="map")
    p = result.summary()["parameters"]
    assert "gain drift" in result.summary()["data"]["model"]["terms"]
    assert abs(p[K + "tilt_frequency"]["map"] / truth["tilt_frequency"] - 1) < 0.015
    assert abs(p[K + "drive_frequency"]["map"] - 10.0) < 0.01
