"""Exact Gaussian log-likelihood of a linear-Gaussian state-space model, by the Kalman filter.

    x_k = Phi x_{k-1} + w_k,  w_k ~ N(0, Q);   y_k = h . x_k + v_k,  v_k ~ N(0, r);   x_0 ~ N(0, P0)

O(T n^2) for n states, scalar observations; a NaN observation is a gap: the update is skipped, and
the likelihood is that of the observed samples only. The filter is the hot loop of every fit, so it
runs as a compiled numba kernel; `log_likelihood_reference` is the same recursion in numpy, for
tests.
"""

from __future__ import annotations

import math
import os

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import expm, solve_discrete_lyapunov

try:
    import numba
    from numba import njit
except ImportError:  # pragma: no cover - numba is a dependency; this keeps the module importable

    def njit(*args, **kwargs):
        return (lambda f: f) if not (args and callable(args[0])) else args[0]
else:
    if not numba.config.CACHE_DIR:  # NUMBA_CACHE_DIR unset: compiled kernels go to the user's cache,
        # never into the installed package (a later editable install would leave them as a shadow package)
        numba.config.CACHE_DIR = os.path.join(
            os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "vibinverse", "numba"
        )


_LOG_2PI = math.log(2.0 * math.pi)


@njit(cache=True, fastmath=False)
def _filter(y, phi, q, h, r, p0, white):  # pragma: no cover - compiled; checked against the reference
    n = phi.shape[0]
    x = np.zeros(n)
    p = p0.copy()
    xp = np.zeros(n)
    pp = np.zeros((n, n))
    tmp = np.zeros((n, n))
    ph = np.zeros(n)
    ll = 0.0
    for k in range(y.shape[0]):
        if k > 0:
            for i in range(n):
                s = 0.0
                for j in range(n):
                    s += phi[i, j] * x[j]
                xp[i] = s
            for i in range(n):
                for j in range(n):
                    s = 0.0
                    for m in range(n):
                        s += phi[i, m] * p[m, j]
                    tmp[i, j] = s
            for i in range(n):
                for j in range(n):
                    s = q[i, j]
                    for m in range(n):
                        s += tmp[i, m] * phi[j, m]
                    pp[i, j] = s
            for i in range(n):
                x[i] = xp[i]
                for j in range(n):
                    p[i, j] = 0.5 * (pp[i, j] + pp[j, i])
        yk = y[k]
        if yk != yk:  # NaN: a gap
            if white.shape[0]:
                white[k] = np.nan
            continue
        s = r
        v = yk
        for i in range(n):
            acc = 0.0
            for j in range(n):
                acc += p[i, j] * h[j]
            ph[i] = acc
            s += h[i] * acc
            v -= h[i] * x[i]
        if not s > 0.0:
            return -np.inf
        for i in range(n):
            x[i] += ph[i] * v / s
        for i in range(n):
            for j in range(n):
                p[i, j] -= ph[i] * ph[j] / s
        ll += -0.5 * (math.log(s) + _LOG_2PI + v * v / s)
        if white.shape[0]:
            white[k] = v / math.sqrt(s)
    return ll


def log_likelihood(
    y: NDArray[np.float64],
    phi: NDArray[np.float64],
    q: NDArray[np.float64],
    h: NDArray[np.float64],
    r: float,
    p0: NDArray[np.float64],
) -> float:
    """log p(y) for the model above; y may contain NaN gaps."""
    return float(_filter(*_args(y, phi, q, h, r, p0), np.empty(0)))


def whiten(y, phi, q, h, r, p0) -> NDArray[np.float64]:
    """Standardized innovations e = L^-1 y (Sigma = L L^T the model's covariance of y); NaN at gaps.
    e.e = y^T Sigma^-1 y, which gives the Fisher information of the mean: sum of e(d mu_i) e(d mu_j)."""
    out = np.empty(len(y))
    _filter(*_args(y, phi, q, h, r, p0), out)
    return out


def _args(y, phi, q, h, r, p0):
    c = lambda a: np.ascontiguousarray(a, dtype=np.float64)
    return c(y), c(phi), c(q), c(h), float(r), c(p0)


def log_likelihood_reference(y, phi, q, h, r, p0) -> float:
    """The same recursion in plain numpy (slow; for tests)."""
    n = phi.shape[0]
    x, p, ll = np.zeros(n), np.array(p0, dtype=float), 0.0
    for k, yk in enumerate(y):
        if k > 0:
            x, p = phi @ x, phi @ p @ phi.T + q
        if not np.isfinite(yk):
            continue
        s = h @ p @ h + r
        v = yk - h @ x
        gain = p @ h / s
        x, p = x + gain * v, p - np.outer(gain, h @ p)
        ll += -0.5 * (np.log(s) + _LOG_2PI + v * v / s)
    return float(ll)


def stationary_covariance(phi: NDArray[np.float64], q: NDArray[np.float64]) -> NDArray[np.float64]:
    """P with P = Phi P Phi^T + Q (the process started in its stationary state)."""
    p = solve_discrete_lyapunov(phi, q)
    return 0.5 * (p + p.T)


def discretize_continuous(
    a: NDArray[np.float64], g: NDArray[np.float64], qc: float, dt: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(Phi, Q) of x' = A x + G w with continuous white noise w of intensity qc, step dt (Van Loan)."""
    n = a.shape[0]
    m = np.zeros((2 * n, 2 * n))
    m[:n, :n] = -a
    m[:n, n:] = qc * np.outer(g, g)
    m[n:, n:] = a.T
    e = expm(m * dt)
    phi = e[n:, n:].T
    q = phi @ e[:n, n:]
    return phi, 0.5 * (q + q.T)
