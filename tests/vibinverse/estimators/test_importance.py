"""The importance-sampled Laplace approximation (the long-record sampler): exact where the Laplace
approximation is, corrected where one parameter's posterior is skewed, refused where it misses a
mode."""

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from vibinverse.errors import Unsupported
from vibinverse.estimators.base import base_result
from vibinverse.estimators.importance import KHAT_MAX, LaplaceImportance, systematic_resample
from vibinverse.estimators.mcmc import ESS_MIN
from vibinverse.priors import parse_prior


class Target:
    """A posterior over z = (a, b) with a given log density, the identity map to values."""

    def __init__(self, log_density):
        self.log_density = log_density
        self.space = SimpleNamespace(names=["a", "b"], priors=[parse_prior("uniform(-100, 100)", n) for n in "ab"])
        self.series = None
        self.model = SimpleNamespace(releases_gil=True)

    def log_posterior(self, z):
        return float(self.log_density(np.asarray(z)))

    def values(self, z):
        return dict(zip(self.space.names, np.asarray(z, dtype=float).tolist()))


def importance(target, z_map, cov, seed=0):
    start = base_result(target, "map", target.values(z_map), z=np.asarray(z_map, float), cov_z=np.asarray(cov, float))
    start.log_post = target.log_posterior(z_map)
    return LaplaceImportance().estimate(target, start, seed=seed, workers=2)


def test_a_gaussian_posterior_is_its_laplace_approximation():
    """Laplace exact: k well below KHAT_MAX, nearly every draw effective, and the resampled draws'
    5 and 95 % quantiles at mean -+ 1.645 sd to 0.2 sd (their standard error at ~1500 effective
    draws is ~0.06 sd)."""
    cov = np.array([[1.0, 0.6], [0.6, 2.0]])
    target = Target(lambda z: multivariate_normal.logpdf(z, [1.0, -2.0], cov))
    r = importance(target, [1.0, -2.0], cov)
    d = r.diagnostics
    assert d["psis_khat"] < 0.5 and d["importance_ess"] > 1000
    for j, (m, s) in enumerate([(1.0, 1.0), (-2.0, np.sqrt(2.0))]):
        q05, q95 = np.percentile(r.approximate_draws[:, j], [5, 95])
        assert abs(q05 - (m - 1.645 * s)) < 0.2 * s and abs(q95 - (m + 1.645 * s)) < 0.2 * s


def test_a_skewed_parameter_is_corrected():
    """b = log of an exponential variable (density e^(b - e^b)): mode 0 and curvature 1, so the
    Laplace interval is -+1.645, while the truth is [log(-log 0.95), log(-log 0.05)] = [-2.97, 1.10];
    the weighted draws find it (to 0.25)."""
    target = Target(lambda z: -0.5 * z[0] ** 2 + z[1] - np.exp(z[1]))
    r = importance(target, [0.0, 0.0], np.eye(2))
    assert r.diagnostics["psis_khat"] < KHAT_MAX and r.diagnostics["importance_ess"] >= ESS_MIN
    q05, q95 = np.percentile(r.approximate_draws[:, 1], [5, 95])
    assert q05 == pytest.approx(np.log(-np.log(0.95)), abs=0.25)
    assert q95 == pytest.approx(np.log(-np.log(0.05)), abs=0.25)


def test_a_missed_mode_is_refused():
    """Two equal modes 8 sd apart, the Laplace approximation at one: the weights of the other mode's
    draws are enormous, and the check refuses (the pipeline then runs emcee)."""
    target = Target(lambda z: -0.5 * z[1] ** 2 + np.logaddexp(-0.5 * z[0] ** 2, -0.5 * (z[0] - 8.0) ** 2))
    with pytest.raises(Unsupported, match=r"fails its importance check \(Pareto k"):
        importance(target, [0.0, 0.0], np.eye(2))


def test_systematic_resampling_keeps_each_draw_its_share():
    """Draw i is kept floor(n w_i) or ceil(n w_i) times."""
    rng = np.random.default_rng(1)
    w = rng.random(500) ** 3
    w /= w.sum()
    counts = np.bincount(systematic_resample(w, rng), minlength=w.size)
    assert counts.sum() == w.size
    assert np.all(counts >= np.floor(w * w.size)) and np.all(counts <= np.ceil(w * w.size))
