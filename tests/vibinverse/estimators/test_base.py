"""`vibinverse.estimators.base.predictive`: the model mean's 5-95 % band over the draws."""

from types import SimpleNamespace

import numpy as np
import pytest

from vibinverse.estimators.base import predictive


def posterior_of(mean):
    """A stand-in posterior whose model mean is `mean(values)` over 50 samples."""
    model = SimpleNamespace(mean=mean)
    return SimpleNamespace(model=model, space=SimpleNamespace(names=["level", "amp"]))


@pytest.mark.parametrize("varying", [False, True])
def test_the_band_is_the_draws_percentiles_whether_or_not_each_mean_is_constant(varying):
    t = np.linspace(0.0, 1.0, 50)
    mean = lambda v: v["level"] + (v["amp"] * np.sin(2 * np.pi * t) if varying else 0.0 * t)
    draws = np.random.default_rng(1).normal(size=(300, 2))
    out = predictive(posterior_of(mean), {"level": 0.0, "amp": 1.0}, draws)
    pick = draws[np.random.default_rng(0).choice(300, size=100, replace=False)]
    curves = np.array([mean({"level": a, "amp": b}) for a, b in pick])
    q05, q95 = np.percentile(curves, [5, 95], axis=0)
    np.testing.assert_allclose(out["model_q05"], q05, rtol=0, atol=1e-15)
    np.testing.assert_allclose(out["model_q95"], q95, rtol=0, atol=1e-15)
    assert np.ptp(out["model_q05"]) > 0 if varying else np.ptp(out["model_q05"]) == 0
