"""The Kalman likelihood against two oracles: the dense multivariate normal and celerite2."""

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from vibinverse.kalman import discretize_continuous, log_likelihood, log_likelihood_reference, stationary_covariance


def small_model():
    a = np.array([[0.0, 1.0], [-((2 * np.pi * 3) ** 2), -0.4]])
    phi, q = discretize_continuous(a, np.array([0.0, 1.0]), 50.0, 0.02)
    phi = np.kron(np.eye(2), phi) + 0.0
    phi[2:, 2:] *= 0.97
    q = np.kron(np.eye(2), q)
    return phi, q, np.array([0.7, 0.0, -1.3, 0.1]), 0.05, stationary_covariance(phi, q)


def test_kalman_equals_the_dense_multivariate_normal_with_gaps():
    phi, q, h, r, p0 = small_model()
    n = 60
    # explicit covariance of y: Cov(x_i, x_j) = Phi^(i-j) P0 for the stationary process
    powers = [np.eye(4)]
    for _ in range(n):
        powers.append(phi @ powers[-1])
    cov = np.array(
        [[h @ (powers[i - j] @ p0 if i >= j else p0 @ powers[j - i].T) @ h for j in range(n)] for i in range(n)]
    ) + r * np.eye(n)
    y = np.random.default_rng(0).multivariate_normal(np.zeros(n), cov)
    y[[5, 17, 18, 40]] = np.nan
    keep = np.isfinite(y)
    dense = multivariate_normal(np.zeros(keep.sum()), cov[np.ix_(keep, keep)]).logpdf(y[keep])
    assert log_likelihood(y, phi, q, h, r, p0) == pytest.approx(dense, abs=1e-8)
    assert log_likelihood_reference(y, phi, q, h, r, p0) == pytest.approx(dense, abs=1e-8)


def test_kalman_equals_celerite2_sho():
    celerite2 = pytest.importorskip("celerite2")
    s0, w0, qf, dt, sig = 0.7, 2 * np.pi * 3.46, 20.0, 0.005, 0.3
    a = np.array([[0.0, 1.0], [-(w0**2), -w0 / qf]])
    phi, q = discretize_continuous(a, np.array([0.0, 1.0]), 2 * s0 * w0**4, dt)  # k(0) = S0 w0 Q
    t = np.arange(4000) * dt
    gp = celerite2.GaussianProcess(celerite2.terms.SHOTerm(S0=s0, w0=w0, Q=qf))
    gp.compute(t, yerr=sig)
    # any series compares the two likelihoods; an oscillating one exercises the model
    rng = np.random.default_rng(1)
    y = 20 * np.sin(w0 * t + rng.uniform(0, 6)) * np.exp(-0.01 * t) + rng.normal(0, sig, t.size)
    ours = log_likelihood(y, phi, q, np.array([1.0, 0.0]), sig**2, stationary_covariance(phi, q))
    assert ours == pytest.approx(gp.log_likelihood(y), abs=1e-6)


def test_compiled_kernels_are_cached_outside_the_package(tmp_path):
    """numba's cache goes to the user's cache directory: a cache inside an installed package
    outlives an uninstall and shadows a later editable install."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    import vibinverse

    package = Path(vibinverse.__file__).parent
    before = set(package.rglob("*.nbi"))
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env["XDG_CACHE_HOME"] = str(tmp_path)
    code = (
        "import numpy as np\n"
        "from vibinverse.kalman import log_likelihood\n"
        "print(log_likelihood(np.zeros(8), np.eye(2) * 0.5, np.eye(2), np.ones(2), 1.0, np.eye(2)))\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert r.returncode == 0, r.stderr
    assert set(package.rglob("*.nbi")) == before
    assert list((tmp_path / "vibinverse" / "numba").rglob("*.nbi"))
