"""MAP with casadi: exact derivatives, IPOPT, Laplace covariance from the exact Hessian, for any
model that writes its posterior in casadi (`SignalModel.casadi_objective`). The compiled solver is
cached per model, priors and sampling, so one compilation serves every series of one design.

IPOPT's iteration callback watches each solve: a solve whose line search has stalled in the rounding
of the objective ends with Newton steps on the exact derivatives, and a run given a `floor` (another
reading, which only matters if it comes near the best one) ends as soon as its optimum is predicted
well below that floor.
"""

from __future__ import annotations

import json
import logging
import math
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

BOX = 30.0  # |z| <= 30 keeps the logistic transforms finite (a prior's open ends are at |z| -> inf)
# IPOPT has stalled when two iterations in a row moved z by less than STALL_STEP (relative to
# 1 + max |z|) and -log posterior by less than STALL_F (relative to 1 + |f|): its line search can no
# longer see a decrease through the rounding of f (on the sec. 4.2 frame, f ~ 2e4 summed over 4000
# Kalman steps is uncertain by ~5e-9 while the last Newton steps would lower it by ~1e-12), and IPOPT
# went on for 11-21 more iterations (2-3 s) before it accepted a point that was still 1e-7 (in z)
# from the optimum (measured on seeds 1-3)
STALL_STEP, STALL_F = 1e-9, 1e-12
# a stalled solve ends with Newton steps on the exact gradient and Hessian: only from a point this
# close (max |step| in z) to a minimum whose Hessian is positive definite, each step accepted when f
# does not rise above its rounding (NEWTON_F relative), done when the step is below NEWTON_DONE in z
# or below NEWTON_DONE_SD in the posterior's own metric (sqrt(step' H step), in posterior standard
# deviations): on a weakly determined parameter the step the rounded gradient asks for can exceed
# 1e-8 in z while it is 1e-7 sd (sec. 4.2 frame, 20 s, seed 3: steps of 2-5e-8 in z, each changing
# f by +-3e-7, its rounding, so f could not confirm them and the solve ran 280 more iterations).
# That rounding, +-3e-7 on f ~ -2.1e4 (1.4e-11 relative), is why NEWTON_F is 1e-10: at 1e-11 the
# first Newton step from a stalled point (20 s, seed 1: gradient 0.08, predicted decrease 6e-11)
# was refused for an f 2.8e-7 higher, and the run ended at the stalled point
NEWTON_REACH, NEWTON_DONE, NEWTON_DONE_SD, NEWTON_F, NEWTON_STEPS = 1e-3, 1e-8, 1e-6, 1e-10, 5
# a run with a floor ends once f - CUT_FACTOR x (the decrease the Newton model still predicts) lies
# above the floor; checked at most MAX_CHECKS times a run (`_Watch.below_floor`)
CUT_FACTOR, MAX_CHECKS = 10.0, 3


class _Watch(ca.Callback):
    """IPOPT's iteration callback (casadi's `iteration_callback`): asks IPOPT to stop
    (`User_Requested_Stop`) once the solve has stalled (STALL_STEP, STALL_F), or, given a floor,
    once its optimum is predicted below it (`below_floor`). Disarmed, it never stops a solve."""

    def __init__(self, nx: int, np_: int):
        ca.Callback.__init__(self)
        self.nx, self.np_ = nx, np_
        self.exact: _Exact | None = None  # set once the solver exists
        self.arm(False)
        self.construct("map_watch", {})

    def arm(self, armed: bool = True, data=None, floor: float | None = None) -> None:
        """Start watching a new solve on `data` (or, with False, let it run as IPOPT decides);
        `floor` bounds f (-log posterior) from above for the runs worth finishing."""
        self.armed, self.data, self.floor = armed, data, floor
        self.last, self.still, self.iteration, self.next_check, self.checks = None, 0, 0, 0, 0
        self.stalled, self.abandoned = False, None

    def get_n_in(self) -> int:
        return ca.nlpsol_n_out()

    def get_n_out(self) -> int:
        return 1

    def get_name_in(self, i: int) -> str:
        return ca.nlpsol_out(i)

    def get_name_out(self, i: int) -> str:
        return "ret"

    def get_sparsity_in(self, i: int) -> ca.Sparsity:
        name = ca.nlpsol_out(i)
        size = {"f": 1, "x": self.nx, "lam_x": self.nx, "lam_p": self.np_}.get(name, 0)
        return ca.Sparsity.dense(size, 1)

    def eval(self, arg: list) -> list:
        x, f = np.array(arg[0]).ravel(), float(arg[1])
        drop = math.inf
        if self.last is not None:
            step, size = (np.max(np.abs(x - self.last[0])), np.max(np.abs(x))) if x.size else (0.0, 0.0)
            quiet = step <= STALL_STEP * (1 + size) and abs(f - self.last[1]) <= STALL_F * (1 + abs(f))
            self.still = self.still + 1 if quiet else 0
            drop = self.last[1] - f
        self.last = (x, f)
        self.iteration += 1
        if not self.armed:
            return [0.0]
        self.stalled = self.still >= 2
        return [1.0 if self.stalled or self.below_floor(x, f, drop) else 0.0]

    def below_floor(self, x: np.ndarray, f: float, drop: float) -> bool:
        """Whether this run's optimum lies above the floor in f (below it in log posterior), judged
        from the exact gradient g and Hessian H at the iterate: where H is positive definite the
        Newton model predicts the descent still to come as g'H^-1 g / 2, and the run ends when f
        minus CUT_FACTOR times that is still above the floor (the Hessian is then kept for the
        Laplace covariance at this point, `abandoned`).

        Why this is safe enough to end a run on: the posterior is not convex, so no local quantity
        proves where IPOPT would end; but these runs start from another reading of the spectrum and
        matter only if they come within the ambiguity margin of the best optimum. On the sec. 4.2
        exchanged reading (seeds 1 and 3) the Newton model was within a factor 1.8 of the descent
        that followed at every iterate with H positive definite, so CUT_FACTOR = 10 leaves a wide
        margin (tests/vibinverse/estimators/test_casadi_map.py: a floor 0.001 below that reading's
        optimum never ends it), and no run is judged while it still falls fast (the last
        iteration's decrease times CUT_FACTOR must be below the gap). A run that IPOPT would have
        carried out of its basin to a better optimum could be ended: the start margin
        (`map_start_margin`) takes that risk already, by a cruder rule. A check costs one Hessian
        (0.15 s); after one at iteration k the next waits until iteration 2k, MAX_CHECKS a run, so
        a run crossing an indefinite region (an exchanged reading of the test scene at damping
        ratio 1e-4 did for 16 of its 24 iterations) loses 0.5 s at most."""
        if self.floor is None or self.exact is None:
            return False
        gap = f - self.floor
        due = self.iteration >= self.next_check and self.checks < MAX_CHECKS
        if not (gap > 0 and CUT_FACTOR * drop < gap and due):
            return False
        self.checks += 1
        self.next_check = 2 * self.iteration  # at doubling iterations
        g = self.exact.gradient(x, self.data)[1]
        h = self.exact.hessian(x, self.data)
        if not np.all(np.isfinite(h)) or np.linalg.eigvalsh(h)[0] <= 0:
            return False
        descent = 0.5 * float(g @ np.linalg.solve(h, g))
        if not (np.isfinite(descent) and f - CUT_FACTOR * descent > self.floor):
            return False
        self.abandoned = (x, f, h)
        return True


def _compiled(problem: Posterior):
    """(objective, IPOPT solver, its watch) for this problem's scene, priors and sampling; built
    once and reused for every series of the same design (a bench, a study)."""
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
            watch = _Watch(len(problem.space), 2 * n)
            solver = ca.nlpsol(
                "map",
                "ipopt",
                {"x": z, "p": p, "f": f},
                {
                    "ipopt.print_level": 0,
                    "print_time": False,
                    "ipopt.sb": "yes",
                    # no SX expansion: on the frame's 4000-sample Kalman objective, expanding took 16 s
                    # and 290 kB a sample to save 2 s of solving; unexpanded, the MX graph over 50-step
                    # SX blocks builds in 0.4 s, and compiling plus one fit raised the peak memory by
                    # 83 MB at 4000 samples and 103 MB at 12000 (measured)
                    "expand": False,
                    "show_eval_warnings": False,  # IPOPT rejects inf trial points itself
                    "ipopt.hessian_approximation": "exact",  # converges in ~10 iterations; L-BFGS took 300
                    "ipopt.tol": 1e-8,
                    "ipopt.max_iter": 300,
                    "iteration_callback": watch,
                },
            )
            watch.exact = _Exact(solver)
        if len(_CACHE) >= 4:
            _CACHE.pop(next(iter(_CACHE)))
        _CACHE[key] = (obj, solver, watch)
    obj, solver, watch = _CACHE[key]
    obj.problem = problem  # the series of this call
    obj.like = like
    return obj, solver, watch


class _Exact:
    """The solver's own exact gradient and Hessian of -log posterior (holding its functions, not
    the solver, which holds the watch that holds this)."""

    def __init__(self, solver):
        self.grad, self.hess = solver.get_function("nlp_grad_f"), solver.get_function("nlp_hess_l")

    def gradient(self, z: np.ndarray, data) -> tuple[float, np.ndarray]:
        """(f, its gradient) at z."""
        f, g = self.grad(z, data)
        return float(f), np.array(g).ravel()

    def hessian(self, z: np.ndarray, data) -> np.ndarray:
        """The Hessian at z: the upper triangle of the Lagrangian's (objective factor 1, no
        constraints), made whole."""
        upper = np.array(self.hess(z, data, 1.0, []))
        return upper + np.triu(upper, 1).T


def _newton(exact: _Exact, z: np.ndarray, f: float, data) -> tuple[np.ndarray, float, np.ndarray] | None:
    """Newton steps on the exact gradient and Hessian from a stalled IPOPT point: (z, f, Hessian at
    z) once the step is below NEWTON_DONE, or None when z is not close to a minimum (the Hessian is
    not positive definite, a step is longer than NEWTON_REACH or leaves the box, or f rises)."""
    g = exact.gradient(z, data)[1]
    for k in range(NEWTON_STEPS):
        h = exact.hessian(z, data)
        if not np.all(np.isfinite(h)) or np.linalg.eigvalsh(h)[0] <= 0:
            return None
        step = -np.linalg.solve(h, g)
        if not np.all(np.isfinite(step)):
            return None
        size = np.max(np.abs(step))
        if size <= NEWTON_DONE or math.sqrt(max(-step @ g, 0.0)) <= NEWTON_DONE_SD or k == NEWTON_STEPS - 1:
            return z, f, h
        if size > NEWTON_REACH or np.max(np.abs(z + step)) >= BOX:
            return None
        f_new, g_new = exact.gradient(z + step, data)
        if not f_new <= f + NEWTON_F * (1 + abs(f)):
            return None
        z, f, g = z + step, f_new, g_new
    return None  # pragma: no cover - the loop returns at its last step


def _solve(solver, watch: _Watch, z0: np.ndarray, data, floor: float | None):
    """IPOPT from z0: (z, f, the Hessian at z when already computed else None, whether the run was
    ended below the floor). A solve that stalls ends with Newton steps (`_newton`); if z is not yet
    close enough for those, IPOPT goes on from there, and a second stall ends the run where it is
    (unwatched, IPOPT went on to its iteration limit: 280 iterations, 280 s on a slow machine, on a
    20 s frame series whose rounded f it could no longer lower)."""
    watch.arm(True, data, floor)
    for attempt in range(2):
        sol = solver(x0=z0, p=data, lbx=-BOX, ubx=BOX)
        z, f = np.array(sol["x"]).ravel(), float(sol["f"])
        if watch.abandoned is not None:
            return (*watch.abandoned, True)
        if not watch.stalled:
            break
        done = _newton(watch.exact, z, f, data) if np.isfinite(f) else None
        logger.debug(
            "IPOPT stalled after %d iterations at f = %.12g; %s",
            watch.iteration - 1,
            f,
            "finished with Newton steps"
            if done
            else ("not near a minimum: IPOPT goes on" if attempt == 0 else "ends there"),
        )
        if done is not None:
            return (*done, False)
        watch.arm(True, data, floor)
        z0 = z
    return z, f, None, False


def casadi_map(problem: Posterior, starts: list[dict[str, float]], *, floor: float | None = None) -> MapPoint:
    """MAP by IPOPT (exact gradients and Hessian) from the promising starts; Laplace covariance from the
    exact Hessian at the best optimum. `floor` (a log posterior): the caller has no use for an optimum
    below it, and a run predicted to end there stops early (`CasadiMap` reports it as abandoned)."""
    return _map_point(problem, starts, floor)[0]


def _map_point(problem: Posterior, starts: list[dict[str, float]], floor: float | None) -> tuple[MapPoint, bool]:
    """`casadi_map`, and whether its point is that of a run ended below the floor."""
    if not starts:
        raise InputError("casadi MAP: no starting point")
    obj, solver, watch = _compiled(problem)
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
        run = _solve(solver, watch, problem.space.to_z(st), data, None if floor is None else -floor)
        if np.isfinite(run[1]) and (best is None or run[1] < best[1]):
            best = run
    if best is None:
        raise NumericalError("casadi MAP: IPOPT found no finite optimum from any start")
    zs, f, h, abandoned = best
    h = watch.exact.hessian(zs, data) if h is None else h
    return MapPoint(zs, np.linalg.inv(0.5 * (h + h.T)), -f), abandoned


@register_estimator
class CasadiMap(Estimator):
    """IPOPT with exact derivatives from the promising starts of the stage before; Laplace
    covariance from the exact Hessian. Unsupported when the model has no casadi form for these
    free parameters. Option `floor` (a log posterior, e.g. the best reading's less the ambiguity
    margin): a run whose optimum is predicted below it ends early, and the result says so in
    `diagnostics["abandoned"]` (its point and log posterior are where it stopped)."""

    name = "casadi"

    def estimate(self, posterior: Posterior, start: FitResult | None, *, seed: int = 0, **options: Any) -> FitResult:
        if start is None:
            from vibinverse.estimators.spectral import ranked_starts

            starts = ranked_starts(posterior)
        else:
            starts = start.starts or [start.point]
        point, abandoned = _map_point(posterior, starts, options.get("floor"))
        result = map_result(posterior, self.name, point, seed)
        if abandoned:
            result.diagnostics["abandoned"] = f"ended below the floor {options['floor']:.6g} (log posterior)"
        return result
