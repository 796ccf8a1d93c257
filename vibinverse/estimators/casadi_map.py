"""MAP with casadi: exact derivatives, IPOPT, Laplace covariance from the exact Hessian, for any
model that writes its posterior in casadi (`SignalModel.casadi_objective`). The compiled solver is
cached per model, priors and sampling, so one compilation serves every series of one design.
"""

from __future__ import annotations

import json
import logging
from typing import Any

import casadi as ca
import numpy as np

from forward.scene import format_bytes, memory_limit
from vibinverse.errors import InputError, NumericalError, Unsupported
from vibinverse.estimators.base import Estimator, register_estimator
from vibinverse.estimators.scipy_map import MapPoint, map_result
from vibinverse.posterior import Posterior
from vibinverse.progress import spinner
from vibinverse.result import FitResult

logger = logging.getLogger(__name__)

_CACHE: dict = {}


def _compiled(problem: Posterior):
    """(objective, IPOPT solver, exact Hessian function) for this problem's scene, priors and
    sampling; built once and reused for every series of the same design (a bench, a study)."""
    like = problem.model
    n = like.series.time.size
    need, limit = like.casadi_bytes_per_sample * n, memory_limit()
    if need > limit:
        raise Unsupported(
            f"the casadi MAP would need about {format_bytes(need)} for {n} samples, above the memory "
            f"limit {format_bytes(limit)} (VIBINVERSE_MEMORY_LIMIT)"
        )
    key = (
        like.name,
        json.dumps(like.base, sort_keys=True, default=str),
        tuple(problem.space.names),
        tuple(str(p) for p in problem.space.priors),
        hash(like.series.time.tobytes()),
        json.dumps(like.describe(), sort_keys=True),
    )
    if key not in _CACHE:
        obj = like.casadi_objective(problem)  # Unsupported when the free values leave its form
        with spinner(f"compiling the casadi MAP (IPOPT with exact derivatives) for {n} samples"):
            z = ca.MX.sym("z", len(problem.space))
            p = ca.MX.sym("p", 2 * like.series.time.size)
            f = obj.function(z, p[: like.series.time.size], p[like.series.time.size :])
            solver = ca.nlpsol(
                "map",
                "ipopt",
                {"x": z, "p": p, "f": f},
                {
                    "ipopt.print_level": 0,
                    "print_time": False,
                    "ipopt.sb": "yes",
                    # no SX expansion: on the frame's 4000-sample Kalman objective, expanding took 16 s
                    # and 290 kB a sample to save 2 s of solving; unexpanded, the MX graph builds in
                    # ~2 s with 12 kB a sample, and the optimum is the same to 1e-12 (measured)
                    "expand": False,
                    "show_eval_warnings": False,  # IPOPT rejects inf trial points itself
                    "ipopt.hessian_approximation": "exact",  # converges in ~10 iterations; L-BFGS took 300
                    "ipopt.tol": 1e-8,
                    "ipopt.max_iter": 300,
                },
            )
            hess = ca.Function("H", [z, p], [ca.hessian(f, z)[0]])
        if len(_CACHE) >= 4:
            _CACHE.pop(next(iter(_CACHE)))
        _CACHE[key] = (obj, solver, hess)
    obj, solver, hess = _CACHE[key]
    obj.problem = problem  # the series of this call
    obj.like = like
    return obj, solver, hess


def casadi_map(problem: Posterior, starts: list[dict[str, float]]) -> MapPoint:
    """MAP by IPOPT (exact gradients and Hessian) from the promising starts; Laplace covariance from the
    exact Hessian at the best optimum."""
    if not starts:
        raise InputError("casadi MAP: no starting point")
    obj, solver, hess = _compiled(problem)
    data = obj.data()
    # the candidates differ in which line is the drive; IPOPT runs from those whose starting
    # posterior is within LOG_POST_MARGIN of the best (a swapped assignment starts far below)
    # (a deterministic scene's solve takes ~0.05 s: there every start runs; `map_start_margin`)
    margin = problem.model.map_start_margin
    lp = np.array([problem.log_posterior(problem.space.to_z(st)) for st in starts])
    top = np.nanmax(np.where(np.isfinite(lp), lp, -np.inf))
    chosen = [st for st, v in zip(starts, lp) if not np.isfinite(top) or v >= top - margin]
    best = None
    for st in chosen:
        # |z| <= 30 keeps the logistic transforms finite (a prior's open ends are at |z| -> inf)
        sol = solver(x0=problem.space.to_z(st), p=data, lbx=-30.0, ubx=30.0)
        f = float(sol["f"])
        if np.isfinite(f) and (best is None or f < best[1]):
            best = (np.array(sol["x"]).ravel(), f)
    if best is None:
        raise NumericalError("casadi MAP: IPOPT found no finite optimum from any start")
    zs, f = best
    h = np.array(hess(zs, data))
    return MapPoint(zs, np.linalg.inv(0.5 * (h + h.T)), -f)


@register_estimator
class CasadiMap(Estimator):
    """IPOPT with exact derivatives from the promising starts of the stage before; Laplace
    covariance from the exact Hessian. Unsupported when the model has no casadi form for these
    free parameters."""

    name = "casadi"

    def estimate(self, posterior: Posterior, start: FitResult | None, *, seed: int = 0, **options: Any) -> FitResult:
        if start is None:
            from vibinverse.estimators.spectral import ranked_starts

            starts = ranked_starts(posterior)
        else:
            starts = start.starts or [start.point]
        return map_result(posterior, self.name, casadi_map(posterior, starts), seed)
