"""The deterministic (plate, ground) model with nuisance terms: its likelihood is the engine's, the
dense normal density of mean (times a gain drift) and the terms' covariance; the white-noise
likelihood is unchanged without them; a per-sample sensor variance is refused with them."""

import math

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from tests.conftest import LOW_RES, K, simulate
from vibinverse.errors import SceneError
from vibinverse.models import build_model
from vibinverse.terms.drift import slepian_gain_basis as gain_basis

SHORT = (LOW_RES, "sampling.duration=0.15")  # 150 samples at 1 kHz: the dense oracle stays cheap


def test_plate_beside_ar1_and_a_walk_is_the_dense_gaussian_density():
    table, data = simulate("roof_elastic", *SHORT, seed=2)
    model = build_model({**table, "nuisance": {"noise": "ar1", "drift": "walk"}}, data)
    v = {"ar.rms": 0.04, "ar.time": 0.01, "drift.rate": 0.05, "noise.sigma": 0.03, K + "frequency": 40.5}
    mean = model.mean(v)
    t = data.time - data.time[0]
    cov = 0.0016 * np.exp(-np.abs(t[:, None] - t[None, :]) / 0.01) + 0.0025 * np.minimum(t[:, None], t[None, :])
    cov += 0.0009 * np.eye(t.size)
    dense = multivariate_normal(mean, cov).logpdf(data.intensity)
    assert model.log_likelihood(v) == pytest.approx(dense, rel=1e-9)
    assert np.nansum(model.pointwise_log_likelihood(v)) == pytest.approx(dense, rel=1e-9)
    assert model.describe()["terms"] == "AR(1) noise, random-walk drift, white noise"
    assert {"ar.rms", "ar.time", "drift.rate"} <= set(model.default_priors())


def test_a_gain_drift_multiplies_the_plates_mean():
    table, data = simulate("roof_elastic", *SHORT, seed=3)
    model = build_model({**table, "nuisance": {"gain": 2}}, data)
    v = {"gain.a0": 0.02, "gain.a1": 0.1, "gain.a2": -0.2, "noise.sigma": 0.05}
    t = data.time - data.time[0]
    m = 1.02 + np.array([0.1, -0.2]) @ gain_basis(t, 2)
    plain = build_model(table, data)
    dense = multivariate_normal(m * plain.mean(v), 0.0025 * np.eye(t.size)).logpdf(data.intensity)
    assert model.log_likelihood(v) == pytest.approx(dense, rel=1e-9)
    assert model.log_likelihood({**v, "gain.a1": 2.0}) == -math.inf  # 1 + g below 0 somewhere
    draw = model.replicate(v, np.random.default_rng(0))
    assert draw.shape == t.shape and np.all(np.isfinite(draw))


def test_without_nuisance_terms_the_white_likelihood_is_unchanged():
    table, data = simulate("roof_elastic", *SHORT, seed=4)
    model = build_model(table, data)
    assert not model.composed
    r = data.intensity - model.mean({})
    n = r.size
    assert model.log_likelihood({}) == pytest.approx(
        -0.5 * (np.dot(r, r) / 0.0025 + n * math.log(2 * math.pi * 0.0025)), rel=1e-12
    )


def test_nuisance_terms_refuse_a_per_sample_sensor_variance():
    table, data = simulate("roof_elastic", *SHORT, "noise.photons_per_unit=1e6", seed=5)
    with pytest.raises(SceneError, match=r"noise\.photons_per_unit"):
        build_model({**table, "nuisance": {"noise": "ar1"}}, data)
