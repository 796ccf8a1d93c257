import math

import numpy as np
import pytest

from vibinverse.oma.band_model import BandLayout, BandLikelihood, modal_density, modal_log_slopes
from vibinverse.terms.base import DataFacts
from vibinverse.terms.resonance import Oscillator


def _band(seed=0, modes=2, channels=4, background=False):
    rng = np.random.default_rng(seed)
    freqs = np.linspace(1.8, 2.4, 200)
    lay = BandLayout(modes, channels, tuple(range(modes)))
    x = lay.pack(
        np.array([2.0, 2.1][:modes]),
        np.array([0.02, 0.015][:modes]),
        np.array([1.0, 0.5][:modes]),
        rng.normal(size=(modes, channels)),
        np.full(channels, 0.01),
        np.linspace(-1.5, 2.0, channels),  # coloured channel noise
        np.array([1.5, -2.0][:modes]),  # coloured modal forces
    )
    bg = None
    if background:
        u = rng.normal(size=channels)
        bg = np.einsum("j,c,d->jcd", 0.3 / (1 + freqs), u, u)
    lik = BandLikelihood(freqs, np.zeros((freqs.size, channels), complex), lay, 2, bg)
    e, _ = lik.covariance(x)
    z = (rng.normal(size=(freqs.size, channels)) + 1j * rng.normal(size=(freqs.size, channels))) / math.sqrt(2)
    lik.y = np.einsum("jcd,jd->jc", np.linalg.cholesky(e), z)
    return lik, x


@pytest.mark.parametrize("background", [False, True])
def test_gradient_equals_central_differences(background):
    lik, x = _band(background=background)
    _, grad = lik.value_and_gradient(x)
    h = 1e-5
    num = np.array([(lik.log_likelihood(x + h * e) - lik.log_likelihood(x - h * e)) / (2 * h) for e in np.eye(x.size)])
    assert np.allclose(grad, num, rtol=1e-4, atol=1e-3 * (1 + np.abs(grad).max()) * 1e-3)


def test_log_likelihood_is_the_complex_gaussian_density():
    lik, x = _band(seed=3, background=True)
    e, _ = lik.covariance(x)
    direct = 0.0
    for ej, yj in zip(e, lik.y, strict=True):
        direct += -math.log(np.linalg.det(math.pi * ej)) - (yj.conj() @ np.linalg.solve(ej, yj)).real
    assert lik.log_likelihood(x) == pytest.approx(direct, rel=1e-10)


def test_pack_unpack_round_trip_moves_scale_into_level():
    lay = BandLayout(2, 3, (1, 0))
    v = np.array([[0.5, -2.0, 1.0], [3.0, 1.0, -1.0]])
    x = lay.pack(
        np.array([1.0, 2.0]), np.array([0.01, 0.02]), np.array([1.0, 1.0]), v, np.array([1.0, 2.0, 3.0]),
        np.array([0.1, 0.2, 0.3]), np.array([-1.0, 2.0]),
    )  # fmt: skip
    f, zeta, s, u, n = lay.unpack(x)
    assert np.allclose(lay.tilt(x), [0.1, 0.2, 0.3]) and np.allclose(lay.alpha(x), [-1.0, 2.0])
    assert np.allclose(f, [1, 2]) and np.allclose(zeta, [0.01, 0.02]) and np.allclose(n, [1, 2, 3])
    # the model's s v v^T is unchanged by the gauge
    for k in range(2):
        assert np.allclose(s[k] * np.outer(u[k], u[k]), np.outer(v[k], v[k]))
    assert u[0, 1] == 1.0 and u[1, 0] == 1.0


def test_modal_density_is_the_oscillator_terms_psd():
    f = np.linspace(0.5, 5.0, 50)
    facts = DataFacts(1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0, np.zeros(0), np.zeros(0))
    psd = Oscillator("m").psd({"m.frequency": 2.0, "m.damping_ratio": 0.03, "m.rms": 1.0}, f, facts)
    assert np.allclose(modal_density(2.0, 0.03, f, 0), psd, rtol=1e-14)
    assert np.allclose(modal_density(2.0, 0.03, f, 2), psd * (2 * np.pi * f) ** 4, rtol=1e-14)
    # its integral over (0, inf) is the unit rms^2 (trapezoid on a fine grid)
    grid = np.linspace(1e-4, 200.0, 2_000_001)
    assert np.trapezoid(modal_density(2.0, 0.03, grid, 0), grid) == pytest.approx(1.0, rel=2e-3)


def test_log_slopes_equal_differences():
    f = np.linspace(1.0, 3.0, 40)
    dlf, dlz = modal_log_slopes(2.0, 0.05, f)
    h = 1e-6
    num_f = (
        np.log(modal_density(2.0 * math.exp(h), 0.05, f, 2)) - np.log(modal_density(2.0 * math.exp(-h), 0.05, f, 2))
    ) / (2 * h)
    num_z = (
        np.log(modal_density(2.0, 0.05 * math.exp(h), f, 2)) - np.log(modal_density(2.0, 0.05 * math.exp(-h), f, 2))
    ) / (2 * h)
    assert np.allclose(dlf, num_f, atol=1e-6) and np.allclose(dlz, num_z, atol=1e-6)


def test_fisher_diagonal_is_the_mean_curvature():
    """The expected Fisher information's diagonal equals the mean of -d2 ln L / dx2 over data sets
    drawn from the model (40 sets; the curvature by differences of the closed-form gradient)."""
    lik, x = _band(seed=5, modes=1, channels=3)
    e, _ = lik.covariance(x)
    chol = np.linalg.cholesky(e)
    rng = np.random.default_rng(11)
    curv = []
    for _ in range(40):
        z = (rng.normal(size=lik.y.shape) + 1j * rng.normal(size=lik.y.shape)) / math.sqrt(2)
        lik.y = np.einsum("jcd,jd->jc", chol, z)
        h = 1e-5
        row = []
        for i in range(x.size):
            d = np.zeros(x.size)
            d[i] = h
            row.append(-(lik.value_and_gradient(x + d)[1][i] - lik.value_and_gradient(x - d)[1][i]) / (2 * h))
        curv.append(row)
    mean = np.mean(curv, axis=0)
    assert np.allclose(lik.fisher_diagonal(x), mean, rtol=0.15)
