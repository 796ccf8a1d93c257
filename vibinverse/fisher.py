"""Fisher information of the parameters that shape the mean signal, and Cramer-Rao bounds.

For y ~ N(mu(theta), Sigma), I_ij = d_i mu^T Sigma^-1 d_j mu (+ a covariance term for parameters
that change Sigma). The Kalman filter whitens exactly: e(v) = L^-1 v with Sigma = L L^T, so
I_ij = e(d_i mu) . e(d_j mu). The mean derivatives are central differences of the forward model,
which is deterministic (no noise is simulated), so they are exact to O(h^2).
"""

from __future__ import annotations

import numpy as np

from vibinverse.frame_model import FrameLikelihood
from vibinverse.kalman import whiten


def mean_fisher(like: FrameLikelihood, values: dict[str, float], names: list[str],
                rel_step: float = 1e-6) -> np.ndarray:
    """Fisher information of `names` through the mean (the drive parameters enter only there)."""
    c = like.components(values)
    white = []
    for n in names:
        h = rel_step * max(abs(values[n]), 1e-3)
        up = like.components({**values, n: values[n] + h}).mean
        dn = like.components({**values, n: values[n] - h}).mean
        d = (up - dn) / (2 * h)
        d[~np.isfinite(like.series.intensity)] = np.nan  # gaps carry no information
        white.append(np.nan_to_num(whiten(d, c.phi, c.q, c.h, c.r, c.p0)))
    w = np.array(white)
    return w @ w.T


def crlb_sd(like: FrameLikelihood, values: dict[str, float], names: list[str]) -> dict[str, float]:
    """Cramer-Rao standard deviations of `names` (jointly estimated)."""
    cov = np.linalg.inv(mean_fisher(like, values, names))
    return dict(zip(names, np.sqrt(np.diag(cov))))
