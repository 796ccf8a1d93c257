"""examples/custom_term.py: a term written outside the package composes with the built-in ones and
runs through the engine exactly (the dense normal density of its autocovariance), its PSD integrates
to its variance, and it needs nothing of the engine's."""

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.stats import multivariate_normal

from vibinverse.io.series import validate
from vibinverse.terms import AR1, TERMS, DataFacts, White

PATH = Path(__file__).resolve().parents[2] / "examples" / "custom_term.py"
spec = importlib.util.spec_from_file_location("custom_term", PATH)
ct = importlib.util.module_from_spec(spec)
spec.loader.exec_module(ct)


def test_the_custom_term_is_exact_through_the_engine():
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.0008, 0.0012, 150))
    y = rng.normal(size=t.size)
    y[[20, 21, 90]] = np.nan
    series = validate(t - t[0], y, "test")
    v = {"cycle.frequency": 100.0, "cycle.rms": 0.8, "cycle.time": 0.05, "ar.rms": 0.3, "ar.time": 0.004}
    v["noise.sigma"] = 0.2
    model = ct.StochasticCycle() + AR1() + White()
    lag = series.time[:, None] - series.time[None, :]
    cov = 0.64 * np.exp(-np.abs(lag) / 0.05) * np.cos(2 * math.pi * 100.0 * lag)
    cov += 0.09 * np.exp(-np.abs(lag) / 0.004) + 0.04 * np.eye(t.size)
    good = np.isfinite(y)
    dense = multivariate_normal(np.zeros(good.sum()), cov[np.ix_(good, good)]).logpdf(y[good])
    assert model.log_likelihood(v, series) == pytest.approx(dense, rel=1e-9)
    assert TERMS["cycle"] is ct.StochasticCycle


def test_the_custom_terms_psd_integrates_to_its_variance():
    facts = DataFacts.of(validate(np.arange(100) / 1000.0, np.zeros(100) + np.arange(100), "test"))
    v = {"cycle.frequency": 100.0, "cycle.rms": 0.8, "cycle.time": 0.05}
    f = lambda x: float(ct.StochasticCycle().psd(v, np.array([x]), facts)[0])
    total = sum(
        quad(f, a, b, limit=400, points=[100.0] if a < 100 < b else None)[0] for a, b in ((0, 200), (200, np.inf))
    )
    assert total == pytest.approx(0.64, rel=1e-4)


def test_the_example_needs_nothing_of_the_engine():
    source = PATH.read_text()
    assert "engines" not in source.split('"""', 2)[2]  # only the docstring names it
    assert len(source.splitlines()) < 80
