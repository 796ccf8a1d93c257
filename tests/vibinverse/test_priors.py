"""Priors: parsing, the unbounded transform and its Jacobian, bad specifications."""

import numpy as np
import pytest

from tests.conftest import K
from vibinverse.errors import VibinverseError
from vibinverse.priors import parse_free, parse_prior


def test_priors_parse_transform_and_reject():
    p = parse_prior("loguniform(1e-4, 1e-1)", "k")
    for v in (2e-4, 3e-3, 0.09):
        assert p.from_unbounded(p.to_unbounded(v)) == pytest.approx(v, rel=1e-10)
    z, h = 0.3, 1e-6
    numeric = (p.from_unbounded(z + h) - p.from_unbounded(z - h)) / (2 * h)
    assert np.exp(p.log_jacobian(z)) == pytest.approx(numeric, rel=1e-6)
    assert parse_prior("truncnormal(3, 1, 0, pi)", "k").bounds == (0.0, pytest.approx(np.pi))
    for bad in ("uniform(2, 1)", "normal(0, -1)", "gauss(0, 1)", "uniform(1)"):
        with pytest.raises(VibinverseError):
            parse_prior(bad, "k")
    free = parse_free([f"{K}tilt_frequency=uniform(2, 5)"], {"free": {"noise.sigma": "loguniform(1e-3, 1)"}})
    assert set(free) == {f"{K}tilt_frequency", "noise.sigma"}
