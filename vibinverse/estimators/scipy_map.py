"""Derivative-free maximum a posteriori (Nelder-Mead -> BFGS) with restarts, and the Laplace
covariance from a finite-difference Hessian at the optimum: the fallback of the casadi MAP, for
any model.

The Hessian's steps are a tenth of each parameter's conditional sd (`laplace_steps`), not a fixed
fraction of z: a fixed step of 1e-4 |z| is a fixed step of a line's frequency (2e-3 Hz at 200 Hz
sampling), while the range over which the likelihood is quadratic in it shrinks as 1 / span; on a
100 s record the step was 0.2 / span, the frequency-phase cross difference no longer saw a
quadratic, and the Laplace sds of the frequency and the phase came out 17 % narrow (the exact
posterior, by importance sampling, agreed with the tenth-of-an-sd steps to 0.5 %)."""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import minimize

from vibinverse.estimators.base import Estimator, base_result, register_estimator
from vibinverse.posterior import Posterior
from vibinverse.result import FitResult


def hessian(f, z: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Central-difference Hessian of f at z."""
    n = z.size
    h = np.zeros((n, n))
    f0 = f(z)
    for i in range(n):
        ei = np.zeros(n)
        ei[i] = steps[i]
        h[i, i] = (f(z + ei) - 2 * f0 + f(z - ei)) / steps[i] ** 2
        for j in range(i):
            ej = np.zeros(n)
            ej[j] = steps[j]
            h[i, j] = h[j, i] = (f(z + ei + ej) - f(z + ei - ej) - f(z - ei + ej) + f(z - ei - ej)) / (
                4 * steps[i] * steps[j]
            )
    return h


def gradient_hessian(grad: Callable[[np.ndarray], np.ndarray], z: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """The Hessian at z by central differences of the gradient `grad` (2 n gradient calls against
    the ~2 n^2 calls of `hessian`), symmetrized."""
    n = z.size
    h = np.empty((n, n))
    for i in range(n):
        e = np.zeros(n)
        e[i] = steps[i]
        h[:, i] = (grad(z + e) - grad(z - e)) / (2 * steps[i])
    return 0.5 * (h + h.T)


def laplace_steps(f: Callable[[np.ndarray], float], z: np.ndarray, first: np.ndarray | None = None) -> np.ndarray:
    """Steps for the central-difference Hessian of f at its minimum z: a first pass with steps
    `first` (default 1e-4 max(1, |z|)) gives each coordinate's curvature c_i, the step is then
    0.1 / sqrt(c_i), a tenth of its conditional sd (where f changes by 0.005: a quadratic there,
    and far above rounding); `first` where c_i is not positive and finite."""
    first = 1e-4 * np.maximum(1.0, np.abs(z)) if first is None else np.asarray(first, dtype=float)
    f0 = f(z)
    steps = first.copy()
    for i in range(z.size):
        e = np.zeros(z.size)
        e[i] = first[i]
        curv = (f(z + e) - 2 * f0 + f(z - e)) / first[i] ** 2
        if curv > 0 and math.isfinite(curv):
            steps[i] = 0.1 / math.sqrt(curv)
    return steps


@dataclass(frozen=True)
class MapPoint:
    """A MAP in the samplers' unconstrained space: the point z, the Laplace covariance cov_z (the
    inverse Hessian of -log posterior), the log posterior there, and whether the Hessian was
    positive definite (when not, cov_z holds only the conditional variances of its diagonal)."""

    z: np.ndarray
    cov_z: np.ndarray
    log_post: float
    hessian_ok: bool = True


#: records longer than this many samples: the MAP by BFGS whitened by the Laplace covariance at the
#: start (`polish`), no Nelder-Mead. Their starts come from the order search's optimum, and
#: Nelder-Mead's up to 200 d iterations took minutes there (a 63,000-sample beam record, 40
#: parameters)
GRADIENT_RECORD = 20_000


def map_fit(problem: Posterior, start: dict[str, float], restarts: int = 2, seed: int = 0) -> MapPoint:
    """MAP in the unconstrained space from `start` and jittered restarts (Nelder-Mead, then BFGS;
    on a record longer than GRADIENT_RECORD samples, `polish`); Laplace covariance from a
    central-difference Hessian with steps of a tenth of each parameter's sd (`laplace_steps`)."""
    rng = np.random.default_rng(seed)
    neg = lambda z: -problem.log_posterior(z) if np.all(np.isfinite(z)) else np.inf
    z0 = problem.space.to_z(start)
    if problem.series.time.size > GRADIENT_RECORD:
        fits = []
        for k in range(restarts):
            zi = z0 if k == 0 else z0 + rng.normal(0.0, 0.05, z0.size)
            # whitened by the Laplace covariance at the start: a long record's curvatures span
            # orders of magnitude (a line's frequency against the noise's scale)
            fits.append(polish(problem, zi, laplace_point(neg, zi, -neg(zi), negative_gradient(problem)).cov_z))
        return max(fits, key=lambda f: f.log_post)
    best = None
    for k in range(restarts):
        zi = z0 if k == 0 else z0 + rng.normal(0.0, 0.05, z0.size)
        res = minimize(
            neg,
            zi,
            method="Nelder-Mead",
            options={"maxiter": 200 * z0.size, "xatol": 1e-9, "fatol": 1e-9, "adaptive": True},
        )
        res = minimize(neg, res.x, method="BFGS", options={"gtol": 1e-6})
        if best is None or res.fun < best.fun:
            best = res
    return laplace_point(neg, best.x, float(-best.fun))


def negative_gradient(problem: Posterior) -> Callable[[np.ndarray], np.ndarray] | None:
    """d (-log posterior) / dz of `problem` when its model has a slope of its own (else None); 0
    where it is not finite."""
    centre = {n: p.centre() for n, p in zip(problem.space.names, problem.space.priors)}
    if problem.model.slope(centre, []) is None:
        return None

    def grad(z: np.ndarray) -> np.ndarray:
        g = problem.gradient(z)
        return np.zeros(z.size) if g is None else np.where(np.isfinite(g), -g, 0.0)

    return grad


def laplace_point(
    neg: Callable[[np.ndarray], float],
    z: np.ndarray,
    log_post: float,
    grad: Callable[[np.ndarray], np.ndarray] | None = None,
) -> MapPoint:
    """The MapPoint at the optimum z of -log posterior `neg`: Laplace covariance from its
    central-difference Hessian (`laplace_steps`), of the gradient `grad` of `neg` when given
    (`gradient_hessian`)."""
    steps = laplace_steps(neg, z)
    h = hessian(neg, z, steps) if grad is None else gradient_hessian(grad, z, steps)
    ok = True
    try:
        cov = np.linalg.inv(h)
        cov = 0.5 * (cov + cov.T)
        if np.any(np.linalg.eigvalsh(cov) <= 0):
            raise np.linalg.LinAlgError
    except np.linalg.LinAlgError:  # conditional sds only: they understate correlated parameters
        ok = False
        cov = np.diag(1.0 / np.maximum(np.abs(np.diag(h)), 1e-12))
    return MapPoint(z, cov, log_post, ok)


#: the polish's finite-difference step and gradient tolerance, in units of the start's sd: the
#: gradient's truncation error is O(step^2), its rounding error (the log-likelihood of a long
#: record carries ~1e-6 of summation noise) ~1e-6 / step; at the tolerance the optimum is within
#: ~1e-2 sd of where BFGS stops
POLISH_STEP, POLISH_GTOL = 1e-3, 1e-2


def polish(problem: Posterior, z0: np.ndarray, cov0: np.ndarray) -> MapPoint:
    """The MAP near z0 by BFGS in coordinates whitened by `cov0` (the Laplace covariance of a
    close posterior: the same model on a shorter stretch of the record, scaled to this one's
    length), with central-difference gradients; then the Laplace covariance (`laplace_point`).
    Where the data add little (a tenfold longer stretch), a few iterations of 2 d + ~3 calls each
    reach the optimum, against the thousands of a Nelder-Mead search."""
    chol = np.linalg.cholesky(0.5 * (cov0 + cov0.T) + 1e-12 * np.eye(z0.size) * max(np.trace(cov0), 1e-300))

    def neg(z: np.ndarray) -> float:
        lp = problem.log_posterior(z) if np.all(np.isfinite(z)) else -math.inf
        return -lp if math.isfinite(lp) else math.inf

    def neg_u(u: np.ndarray) -> float:
        return neg(z0 + chol @ u)

    grad = negative_gradient(problem)

    def grad_u(u: np.ndarray) -> np.ndarray:
        if grad is not None:  # the model's own slope, through the whitening
            return chol.T @ grad(z0 + chol @ u)
        g = np.empty(u.size)
        for i in range(u.size):
            e = np.zeros(u.size)
            e[i] = POLISH_STEP
            g[i] = (neg_u(u + e) - neg_u(u - e)) / (2 * POLISH_STEP)
        return np.where(np.isfinite(g), g, 0.0)

    res = minimize(neg_u, np.zeros(z0.size), jac=grad_u, method="BFGS", options={"gtol": POLISH_GTOL})
    u = res.x if res.fun <= neg_u(np.zeros(z0.size)) else np.zeros(z0.size)
    z = z0 + chol @ u
    return laplace_point(neg, z, -neg(z), grad)


def laplace_draws(problem: Posterior, z: np.ndarray, cov_z: np.ndarray, seed: int, n: int = 2000) -> np.ndarray:
    """Draws (n, parameter) of the Laplace approximation N(z, cov_z), mapped to value units."""
    rng = np.random.default_rng(seed)
    zs = rng.multivariate_normal(z, cov_z, size=n, method="eigh")
    return np.array([list(problem.values(zi).values()) for zi in zs])


def map_result(problem: Posterior, method: str, fit: MapPoint, seed: int) -> FitResult:
    """The FitResult of a MAP: values, sds by the delta method (d value / d z per parameter), and
    draws of the Laplace approximation."""
    jac = np.array([np.exp(p.log_jacobian(float(v))) for p, v in zip(problem.space.priors, fit.z)])
    sd = np.sqrt(np.clip(np.diag(fit.cov_z), 0.0, None)) * jac
    return base_result(
        problem,
        method,
        problem.values(fit.z),
        sd=dict(zip(problem.space.names, sd.tolist())),
        z=fit.z,
        cov_z=fit.cov_z,
        log_post=fit.log_post,
        approximate_draws=laplace_draws(problem, fit.z, fit.cov_z, seed),
        diagnostics={
            "converged": bool(np.isfinite(fit.log_post)),
            "log_posterior": fit.log_post,
            "hessian_positive_definite": fit.hessian_ok,
        },
    )


@register_estimator
class ScipyMap(Estimator):
    """MAP from every start of the stage before (best of them), Laplace covariance."""

    name = "map"

    def estimate(self, posterior: Posterior, start: FitResult | None, *, seed: int = 0, **options: Any) -> FitResult:
        starts = start.starts or [start.point] if start is not None else _spectral_starts(posterior)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            fits = [map_fit(posterior, st, restarts=1, seed=seed) for st in starts]
        return map_result(posterior, self.name, max(fits, key=lambda f: f.log_post), seed)


def _spectral_starts(posterior: Posterior) -> list[dict[str, float]]:
    from vibinverse.estimators.spectral import ranked_starts

    return ranked_starts(posterior)
