"""Fisher information and Cramer-Rao bounds of the models' parameters (the frame model; the
deterministic model in `response_fisher`).

For y ~ N(mu(theta), Sigma(theta)):  I_ij = d_i mu^T Sigma^-1 d_j mu + tr(Sigma^-1 d_i Sigma Sigma^-1 d_j Sigma) / 2.

- Mean term: the Kalman filter whitens exactly, e(v) = L^-1 v with Sigma = L L^T, so the first
  term is e(d_i mu) . e(d_j mu); gaps are skipped as in the likelihood.
- Covariance term: the series is a stationary state-space process (the filter starts from the
  stationary covariance), so Whittle's approximation (1/2) sum_k d_i log S(w_k) d_j log S(w_k) over
  the T Fourier frequencies holds with relative error O(decay time / duration);
  `covariance_fisher_dense` is the exact trace formula, for tests on short series.

Derivatives are central differences of the model's deterministic pieces (the mean, Phi, Q, r),
which are smooth closed forms: there is no simulated noise in them.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from scipy.linalg import toeplitz

from vibinverse.engines.state_space import Components
from vibinverse.errors import InputError
from vibinverse.kalman import whiten


def _step(values: dict[str, float], name: str, rel_step: float) -> float:
    return rel_step * max(abs(values[name]), 1e-3)


def mean_fisher(like: Any, values: dict[str, float], names: list[str], rel_step: float = 1e-6) -> np.ndarray:
    """Fisher information of `names` through the mean (the drive parameters enter only there)."""
    c = like.components(values)
    white = []
    for n in names:
        h = _step(values, n, rel_step)
        up = like.components({**values, n: values[n] + h}).mean
        dn = like.components({**values, n: values[n] - h}).mean
        d = (up - dn) / (2 * h)
        d[~np.isfinite(like.series.intensity)] = np.nan  # gaps carry no information
        white.append(np.nan_to_num(whiten(d, c.phi, c.q, c.h, c.r, c.p0)))
    w = np.array(white)
    return w @ w.T


def spectrum(c: Components, n: int) -> np.ndarray:
    """S(w_k) at the n frequencies w_k = 2 pi k / n (see `spectrum_at`)."""
    return spectrum_at(c, 2 * np.pi * np.arange(n) / n)


def spectrum_at(c: Components, omega: np.ndarray) -> np.ndarray:
    """S(w) at normalized angular frequencies w (rad/sample) of y_k = h x_k + v_k, x_k = Phi x_{k-1} + w_k:
    S(w) = h M^-1 Q M^-H h^T + r with M = I - Phi e^{-iw}, per unit normalized frequency (the
    variance of y is the mean of S over the circle). Phi and Q are block diagonal in 2 x 2 modes
    (the frame likelihood's form), so each block is inverted in closed form."""
    z = np.exp(-1j * np.asarray(omega, dtype=float))
    out = np.full(z.shape, c.r, dtype=float)
    for b in range(0, c.h.size, 2):
        p, q, g = c.phi[b : b + 2, b : b + 2], c.q[b : b + 2, b : b + 2], c.h[b : b + 2]
        m00, m01, m10, m11 = 1 - p[0, 0] * z, -p[0, 1] * z, -p[1, 0] * z, 1 - p[1, 1] * z
        det = m00 * m11 - m01 * m10
        u0 = (g[0] * m11 - g[1] * m10) / det  # u = g M^-1 (row vector)
        u1 = (g[1] * m00 - g[0] * m01) / det
        out += q[0, 0] * np.abs(u0) ** 2 + q[1, 1] * np.abs(u1) ** 2 + 2 * q[0, 1] * (u0 * u1.conj()).real
    return out


def oversampling(c: Components, n: int, points_per_width: int = 4, limit: int = 32) -> int:
    """How much finer than the n Fourier frequencies the Whittle integral must be sampled so that
    the narrowest resonance (half-power width ~ -2 log|eigenvalue of Phi| rad) gets
    `points_per_width` points."""
    if c.h.size == 0:
        return 1
    radius = np.abs(np.linalg.eigvals(c.phi)).max()
    width = max(-2.0 * np.log(max(radius, 1e-300)), 1e-12)
    return int(np.clip(np.ceil(points_per_width * 2 * np.pi / (n * width)), 1, limit))


def covariance_fisher(
    like: Any, values: dict[str, float], names: list[str], rel_step: float = 1e-6, oversample: int | None = None
) -> np.ndarray:
    """Whittle's Fisher information of `names` through the covariance, (T / 4 pi) times the
    integral of d_i log S d_j log S over the circle, scaled by the fraction of samples observed
    (gaps). The integral runs on a grid `oversample` times finer than the Fourier frequencies, so
    that a resonance narrower than 1 / duration is resolved (default: `oversampling`)."""
    if oversample is None:
        oversample = oversampling(like.components(values), like.t.size)
    n = like.t.size * oversample
    observed = float(np.isfinite(like.series.intensity).mean())
    dlog = []
    for name in names:
        h = _step(values, name, rel_step)
        up = spectrum(like.components({**values, name: values[name] + h}), n)
        dn = spectrum(like.components({**values, name: values[name] - h}), n)
        dlog.append((np.log(up) - np.log(dn)) / (2 * h))
    d = np.array(dlog)
    return 0.5 * observed * d @ d.T / oversample


def covariance_fisher_dense(
    like: Any, values: dict[str, float], names: list[str], rel_step: float = 1e-6
) -> np.ndarray:
    """The exact covariance term tr(Sigma^-1 d_i Sigma Sigma^-1 d_j Sigma) / 2 from the explicit
    T x T covariance (O(T^3): an oracle for short series, not for design sweeps)."""
    n = like.t.size

    def sigma(c: Components) -> np.ndarray:
        gamma = np.empty(n)
        v = c.p0 @ c.h
        for k in range(n):
            gamma[k] = c.h @ v
            v = c.phi @ v
        gamma[0] += c.r
        return toeplitz(gamma)

    base = sigma(like.components(values))
    a = []
    for name in names:
        h = _step(values, name, rel_step)
        ds = (
            sigma(like.components({**values, name: values[name] + h}))
            - sigma(like.components({**values, name: values[name] - h}))
        ) / (2 * h)
        a.append(np.linalg.solve(base, ds))
    return 0.5 * np.array([[np.sum(ai * aj.T) for aj in a] for ai in a])


def frame_fisher(like: Any, values: dict[str, float], names: list[str]) -> np.ndarray:
    """Mean plus covariance Fisher information of `names`."""
    return mean_fisher(like, values, names) + covariance_fisher(like, values, names)


def crlb_from_fisher(fisher: np.ndarray, names: list[str]) -> dict[str, float]:
    """Cramer-Rao standard deviations (jointly estimated). A parameter the data do not inform
    (a zero row, or a direction the information cannot separate) gets an infinite bound."""
    fisher = np.asarray(fisher, dtype=float)
    d = np.sqrt(np.clip(np.diag(fisher), 0.0, None))
    ok = d > 0
    sd = np.full(len(names), np.inf)
    if ok.any():
        scaled = fisher[np.ix_(ok, ok)] / np.outer(d[ok], d[ok])
        eig = np.linalg.eigvalsh(scaled)
        if eig.min() > 1e-12 * eig.max():
            sd[ok] = np.sqrt(np.diag(np.linalg.inv(scaled))) / d[ok]
    return dict(zip(names, sd.tolist()))


def crlb_sd(like: Any, values: dict[str, float], names: list[str], covariance: bool = False) -> dict[str, float]:
    """Cramer-Rao standard deviations of `names` (jointly estimated); with `covariance`, the
    information carried by the noise-driven resonances is counted too."""
    fisher = frame_fisher(like, values, names) if covariance else mean_fisher(like, values, names)
    return crlb_from_fisher(fisher, names)


def response_fisher(like: Any, values: dict[str, float], names: list[str], rel_step: float = 1e-6) -> np.ndarray:
    """Fisher information of a deterministic scene's parameters (`DeterministicModel`): the mean
    term D^T diag(1/var) D over the observed samples, with D = d mu / d theta differenced on the
    AC part and the rest level separately (a 1e-12 signal keeps its digits), plus the variance
    term of noise.sigma, sum_k 2 sigma^2 / var_k^2. The variance is held fixed in the mean term
    (with shot noise it also depends on the mean; that information is left out, a lower bound)."""
    good = np.isfinite(like.series.intensity)
    level, ac = like.parts(values)
    var = np.broadcast_to(like.variance(level + ac, values), ac.shape)[good]
    rows = []
    for n in names:
        if n == "noise.sigma":
            rows.append(None)
            continue
        h = rel_step * (abs(values[n]) if values[n] != 0 else 1.0)
        (l_up, a_up), (l_dn, a_dn) = like.parts({**values, n: values[n] + h}), like.parts({**values, n: values[n] - h})
        rows.append((((l_up - l_dn) + (a_up - a_dn)) / (2 * h))[good])
    fisher = np.zeros((len(names), len(names)))
    for i, di in enumerate(rows):
        for j, dj in enumerate(rows):
            if di is not None and dj is not None:
                fisher[i, j] = np.sum(di * dj / var)
    if "noise.sigma" in names:
        i = names.index("noise.sigma")
        sigma = values["noise.sigma"]
        fisher[i, i] = float(np.sum(2 * sigma**2 / var**2))
    return fisher


def multi_pixel_fisher(
    single: Callable[[dict[str, float], list[str]], np.ndarray],
    values: dict[str, float],
    names: list[str],
    gains: Sequence[float] | np.ndarray,
    sigmas: Sequence[float] | np.ndarray,
    noise: str = "noise.sigma",
) -> np.ndarray:
    """Fisher information of the shared parameters `names` from N pixels y_i = c_i + g_i s + e_i
    (e_i white with sd sigma_i, independent; gains relative to the pixel `single` describes, whose
    Fisher information `single(values, names)` gives at its white-noise sd `values[noise]`).

    The joint likelihood is the likelihood of the combined series z = sum_i g_i (y_i - c_i) /
    sigma_i^2 / w, the one-pixel model with white noise of sd w^-1/2, w = sum_i g_i^2 / sigma_i^2,
    times a factor free of `names` (DESIGN.md sec. 9; derived in `vibinverse.imaging.joint_fit`),
    so the information is `single` at `values[noise]` = w^-1/2: for a deterministic signal (a
    drive line, a free decay) w times that of a unit pixel, N-fold for N equal pixels of either
    sign; for a noise-driven resonance more than N-fold while the white noise dominates its peak,
    and saturating once the process noise does. Gains, offsets and noise levels are taken as known:
    estimating them costs a frequency nothing to first order, an amplitude the uncertainty of the
    reference gain. Design: `multi_pixel_fisher(lambda v, n: frame_fisher(like, v, n), values,
    names, [1.0] * N, [sigma] * N)`; `crlb_from_fisher` gives the bounds."""
    g = np.asarray(gains, dtype=float).reshape(-1)
    s = np.asarray(sigmas, dtype=float).reshape(-1)
    if g.size != s.size or g.size == 0:
        raise InputError(f"gains and sigmas: {g.size} and {s.size} values; one of each per pixel is needed")
    if not (np.all(s > 0) and np.all(np.isfinite(s)) and np.all(np.isfinite(g))):
        raise InputError("sigmas: every pixel's noise sd must be finite and > 0 (gains finite)")
    w = float(np.sum(g**2 / s**2))
    if not w > 0:
        raise InputError("gains: all zero; the pixels carry no information on the shared signal")
    return single({**values, noise: 1.0 / np.sqrt(w)}, names)
