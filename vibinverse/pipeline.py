"""The fitting pipeline: spectral -> SINDy -> MAP (casadi, else scipy) -> emcee, each stage seeding
the next; `--method` stops it at a stage. A stage that fails is recorded and the chain goes on: a
declined SINDy leaves the MAP to start from the spectral candidates, and a casadi MAP that does not
cover the model or fails falls back to the derivative-free MAP. A model that cannot describe how the
pixel sees the motion under any spectral reading (`check_observation`) stops the fit with a
one-line DataError before any estimate is returned."""

from __future__ import annotations

import logging
import math
from pathlib import Path
from typing import Protocol, runtime_checkable

from forward.scene import format_bytes, memory_limit
from vibinverse.detection import DETECTION_GAIN
from vibinverse.errors import InputError, NumericalError, Unsupported
from vibinverse.estimators import CasadiMap, Emcee, ScipyMap, SindyEstimator, SpectralEstimator
from vibinverse.estimators.base import base_result
from vibinverse.io.series import check_resolves
from vibinverse.posterior import Posterior
from vibinverse.result import FitResult

logger = logging.getLogger(__name__)

METHODS = ("spectral", "sindy", "casadi", "map", "mcmc", "auto")
# another reading of the spectrum closer than this in log posterior is reported as ambiguous (the
# 5-sigma gain of the detection test: one reading is claimed only when the other is that far below)
AMBIGUITY_MARGIN = DETECTION_GAIN


FIT_BYTES_PER_SAMPLE = 3e3  # the scipy MAP, predictive band and draws: 2.3 kB a sample measured (frame)


def check_fit(posterior: Posterior) -> None:
    """One-line errors for frequency priors the data cannot resolve (above Nyquist, too few cycles),
    and for a series whose fit would not fit in memory (estimated before any allocation)."""
    series = posterior.series
    need, limit = FIT_BYTES_PER_SAMPLE * series.time.size, memory_limit()
    if need > limit:
        raise InputError(
            f"data: a fit of {series.time.size} samples needs about {format_bytes(need)}, above the memory "
            f"limit {format_bytes(limit)} (VIBINVERSE_MEMORY_LIMIT, in bytes); fit a shorter stretch"
        )
    nyq = 0.5 * series.fs
    for n, (lo, hi) in posterior.bounds.items():
        if n.split("[")[0].endswith("frequency"):
            if hi > nyq * (1 + 1e-12):
                raise InputError(
                    f"{n}: the prior reaches {hi:g} Hz, above the Nyquist frequency {nyq:g} Hz of the data"
                )
            check_resolves(series, max(lo, 1e-12), n)  # the lowest frequency needs the longest record


@runtime_checkable
class ObservationCheck(Protocol):
    """A model whose observation of the motion holds only in part of the scene's space (the frame
    model's linearized tilt: `FrameModel.check_first_order`)."""

    def check_first_order(self, readings: list[dict[str, float]]) -> None: ...


def check_observation(posterior: Posterior, spectral: FitResult) -> None:
    """DataError (from the model) when its observation describes the pixel under none of the
    spectral readings of the data: a frame scene whose pixel sees the tilt mostly at second order
    (view on the lobe centre, symmetric footprint), where the Kalman likelihood would fit a wrong
    resonance with confident intervals. A deterministic line seen at second order needs no check:
    its mean is the second-order model itself (`DeterministicModel`)."""
    if isinstance(posterior.model, ObservationCheck):
        posterior.model.check_first_order(spectral.starts or [spectral.point])


def run(
    posterior: Posterior,
    method: str = "auto",
    *,
    seed: int = 0,
    backend: Path | None = None,
    resume: bool = False,
    workers: int = 1,
    max_steps: int = 20000,
    progress: bool = True,
) -> FitResult:
    """Fit `posterior` by `method` (one of METHODS); the result's timing holds every stage's seconds."""
    if method not in METHODS:
        raise InputError(f"--method: {method!r} is not one of {', '.join(METHODS)}")
    check_fit(posterior)
    if method == "sindy" and not SindyEstimator.covers(posterior):
        SindyEstimator().estimate(posterior, None)  # raises Unsupported with the reason
    timing: dict[str, float] = {}
    spectral = SpectralEstimator().fit(posterior)
    check_observation(posterior, spectral)
    timing.update(spectral.timing)
    if method == "spectral":
        return spectral
    start, sindy = spectral, None
    if method == "sindy" or (method == "auto" and SindyEstimator.covers(posterior)):
        stage = SindyEstimator().fit(posterior, spectral)
        timing.update(stage.timing)
        if method == "sindy":
            stage.timing = timing
            return stage
        sindy = stage.diagnostics["sindy"]
        start = stage
    best = map_stage(posterior, start, method, seed)
    timing.update(best.timing)
    if method in ("map", "casadi"):
        best.timing = timing
        return best
    result = Emcee().fit(
        posterior,
        best,
        backend=backend,
        resume=resume,
        workers=workers,
        seed=seed,
        max_steps=max_steps,
        progress=progress,
    )
    timing.update(result.timing)
    result.timing = timing
    result.method = "mcmc" if method == "mcmc" else "auto"
    result.data = {**result.data, **({"model": best.data["model"]} if "model" in best.data else {})}
    if sindy is not None:
        result.diagnostics["sindy"] = sindy
    return result


def map_stage(posterior: Posterior, start: FitResult, method: str, seed: int) -> FitResult:
    """MAP from every candidate start: casadi + IPOPT with exact derivatives, except for method
    "map" (derivative-free scipy), which is also the fallback when casadi does not cover the model
    or fails. When the model changes its evaluation at the optimum (`SignalModel.refine`), the MAP
    runs again from there."""
    result = _alternatives(posterior, _map(posterior, start, method, seed), method, seed)
    facts, message = posterior.model.refine(result.point)
    if message:
        logger.info("%s", message)
        again = _map(posterior, result, method, seed)
        again.timing = {
            k: again.timing.get(k, 0.0) + result.timing.get(k, 0.0) for k in {*again.timing, *result.timing}
        }
        if "ambiguous" in result.diagnostics:
            again.diagnostics["ambiguous"] = result.diagnostics["ambiguous"]
        result = again
    if facts:
        result.data["model"] = {**result.data.get("model", {}), **posterior.model.describe(), **facts}
    return result


def _alternatives(posterior: Posterior, best: FitResult, method: str, seed: int) -> FitResult:
    """The MAP from each other reading of the spectrum the model knows (`SignalModel.alternatives`);
    the best posterior wins, and a reading that is not AMBIGUITY_MARGIN below it is reported in
    `diagnostics["ambiguous"]` instead of being dropped in silence."""
    space = posterior.space
    runs = []
    for what, values in posterior.model.alternatives(best.point, space.names):
        start = {n: p.inside(values.get(n, best.point[n])) for n, p in zip(space.names, space.priors)}
        # a casadi run whose optimum is predicted more than the ambiguity margin below the best is
        # abandoned (`casadi_map`'s floor): it could neither win nor be reported as ambiguous
        floor = _finite(best.log_post) - AMBIGUITY_MARGIN
        first = base_result(posterior, "start", start, starts=[start])
        runs.append((what, _map(posterior, first, method, seed, floor=floor if math.isfinite(floor) else None)))
    if not runs:
        return best
    every = [best, *(r for _, r in runs)]
    timing = {k: sum(r.timing.get(k, 0.0) for r in every) for k in dict.fromkeys(k for r in every for k in r.timing)}
    chosen = max([("the first reading", best), *runs], key=lambda wr: _finite(wr[1].log_post))
    winner = chosen[1]
    ambiguous = []
    for what, other in [("the first reading", best), *runs]:
        if other is winner or _same(other.point, winner.point):
            continue
        gap = _finite(winner.log_post) - _finite(other.log_post)
        if gap < AMBIGUITY_MARGIN:
            ambiguous.append(
                {
                    "alternative": what if other is not best else "the reading the MAP found first",
                    "delta_log_posterior": float(gap),
                    "values": {n: other.point[n] for n in space.names if n.split("[")[0].endswith("frequency")},
                }
            )
    if chosen[0] != "the first reading":
        logger.info("the MAP moved to another reading of the spectrum: %s", chosen[0])
    winner.timing = timing
    winner.diagnostics["ambiguous"] = ambiguous
    return winner


def _same(a: dict[str, float], b: dict[str, float]) -> bool:
    """Two optima are one reading when every frequency agrees to 1e-3."""
    names = [n for n in a if n.split("[")[0].endswith("frequency")]
    return all(abs(a[n] - b[n]) <= 1e-3 * max(abs(b[n]), 1e-12) for n in names)


def _finite(v: float | None) -> float:
    return v if v is not None and math.isfinite(v) else -math.inf


def _map(posterior: Posterior, start: FitResult, method: str, seed: int, floor: float | None = None) -> FitResult:
    if method != "map":
        try:
            return CasadiMap().fit(posterior, start, seed=seed, floor=floor)
        except Unsupported as exc:
            logger.info("the casadi MAP does not cover this fit (%s); using the scipy MAP", exc)
        except (NumericalError, RuntimeError) as exc:  # any solver failure falls back, and says so
            logger.warning("casadi MAP failed (%s); using the derivative-free MAP", str(exc).splitlines()[0][:120])
    return ScipyMap().fit(posterior, start, seed=seed)
