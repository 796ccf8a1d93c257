"""Maximum of a log-likelihood over some coordinates of the samplers' unconstrained space, the rest
held: the optimizer the order search (`vibinverse.model_order.fit_order`) and the detection test's
refitted null (`vibinverse.detection`) share."""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence

import numpy as np
from scipy.optimize import minimize

#: |z| of a bounded parameter's logit beyond which the optimizer does not go (the value is then
#: within e^-30 of its prior's bound: further steps only slow the search on a flat likelihood)
Z_BOX = 30.0


def preconditioner(neg: Callable[[np.ndarray], float], z: np.ndarray, h: float = 1e-3) -> np.ndarray:
    """Per-coordinate scales 1 / sqrt(curvature) of `neg` at z (central differences; clipped to
    [1e-6, 1]): the optimizer works in units of each parameter's width, so that a sharp frequency
    and a broad noise level take steps of the same size (fewer iterations)."""
    f0 = neg(z)
    out = np.ones(z.size)
    for i in range(z.size):
        e = np.zeros(z.size)
        e[i] = h
        c = (neg(z + e) - 2.0 * f0 + neg(z - e)) / (h * h)
        if math.isfinite(c) and c > 0:
            out[i] = 1.0 / math.sqrt(c)
    return np.clip(out, 1e-6, 1.0)


def maximize(
    log_likelihood: Callable[[np.ndarray], float],
    z0: np.ndarray,
    free: Sequence[int],
    bounded: Sequence[bool] | None = None,
    maxiter: int = 300,
    ftol: float = 1e-10,
    gradient: Callable[[np.ndarray], np.ndarray] | None = None,
) -> tuple[float, np.ndarray]:
    """(max, argmax) of `log_likelihood(z)` over the coordinates `free` of z, the others held at
    z0's: L-BFGS-B with the `gradient` (d log_likelihood / dz, every coordinate) or finite-difference
    gradients, in units of each coordinate's width at z0 (`preconditioner`), a bounded parameter's
    logit (`bounded`, default all) kept within +-Z_BOX. A non-finite log-likelihood counts as
    -1e300. The start is returned when nothing beats it."""
    z0 = np.asarray(z0, dtype=float)
    pos = list(free)
    if not pos:
        return float(log_likelihood(z0)), z0.copy()
    box = [True] * len(pos) if bounded is None else [bool(bounded[i]) for i in pos]

    def neg(zf: np.ndarray) -> float:
        z = z0.copy()
        z[pos] = zf
        ll = log_likelihood(z)
        return -ll if math.isfinite(ll) else 1e300

    zf0 = z0[pos]
    scale = preconditioner(neg, zf0)
    limits = [
        ((-Z_BOX - a) / s, (Z_BOX - a) / s) if b else (None, None) for a, s, b in zip(zf0, scale, box, strict=True)
    ]
    jac = None
    if gradient is not None:

        def jac(w: np.ndarray) -> np.ndarray:
            z = z0.copy()
            z[pos] = zf0 + scale * w
            g = np.asarray(gradient(z), dtype=float)[pos]
            return np.where(np.isfinite(g), -g * scale, 0.0)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        res = minimize(
            lambda w: neg(zf0 + scale * w),
            np.zeros(len(pos)),
            jac=jac,
            method="L-BFGS-B",
            bounds=limits,
            options={"maxiter": maxiter, "ftol": ftol, "gtol": 1e-6, "eps": 1e-6},
        )
    z = z0.copy()
    start = neg(zf0)
    if float(res.fun) <= start:
        z[pos] = zf0 + scale * res.x
        return -float(res.fun), z
    return -start, z


def maximize_near(
    f: Callable[[float], float],
    x0: float,
    f0: float,
    limits: tuple[float, float],
    step: float = 0.25,
    tol: float = 0.0,
) -> tuple[float, float]:
    """(max, argmax) of a smooth one-dimensional f near x0 (f(x0) = f0 given) within `limits`, for
    an f dear to evaluate (the Kalman filter's ln L of a long record): f at x0 -+ `step`; while an
    end is higher, the triple moves that way with its step doubled (to the limit); then one
    parabola through the triple, its vertex evaluated unless the parabola rises there by `tol` or
    less over the triple's best. 2-3 evaluations when x0 is within a step of the maximum; the best value seen is
    returned (a non-finite one counts as -inf). Why not scipy's bounded or bracketed Brent: from the
    same starts it took 9 filter runs a call on the one-hour record, this 4."""
    lo, hi = limits
    seen: dict[float, float] = {x0: f0 if math.isfinite(f0) else -math.inf}

    def ev(x: float) -> float:
        x = min(max(x, lo), hi)
        if x not in seen:
            v = f(x)
            seen[x] = v if math.isfinite(v) else -math.inf
        return seen[x]

    c, h = x0, step
    a, b = max(c - h, lo), min(c + h, hi)
    for _ in range(12):
        fa, fc, fb = ev(a), ev(c), ev(b)
        if fa > fc and a > lo:
            c, b, h = a, c, 2.0 * h
            a = max(c - h, lo)
        elif fb > fc and b < hi:
            c, a, h = b, c, 2.0 * h
            b = min(c + h, hi)
        else:
            break
    fa, fc, fb = ev(a), ev(c), ev(b)
    den = (c - a) * (fc - fb) - (c - b) * (fc - fa)
    if a < c < b and den != 0.0 and all(math.isfinite(v) for v in (fa, fb, fc)):
        v = c - 0.5 * ((c - a) ** 2 * (fc - fb) - (c - b) ** 2 * (fc - fa)) / den
        # the parabola's value there (Lagrange's form), against the triple's best
        p = (
            fa * (v - c) * (v - b) / ((a - c) * (a - b))
            + fc * (v - a) * (v - b) / ((c - a) * (c - b))
            + fb * (v - a) * (v - c) / ((b - a) * (b - c))
        )
        if p - max(fa, fb, fc) > tol:
            ev(v)
    x, v = max(seen.items(), key=lambda kv: kv[1])
    return v, x
