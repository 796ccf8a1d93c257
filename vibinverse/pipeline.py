"""The fitting pipeline: spectral -> SINDy -> MAP (casadi, else scipy) -> emcee, each stage seeding
the next. Each `--method` is a class (`FitMethod`, found by its name in FIT_METHODS) that says which
stages it runs and where the chain stops. A record longer than LONG_RECORD samples finds its MAP over
growing stretches (`stretched_map`). A record of more than IMPORTANCE_RECORD samples, and any
record of a model that asks for it (`SignalModel.importance_first`: the scene-less modal model),
has its posterior by default by importance sampling of the Laplace approximation
(`estimators.importance`), emcee only when that fails its check; `importance` asks for that stage
on a record of any length, `mcmc` for emcee.

A stage that fails is recorded and the chain goes on: a declined SINDy leaves the MAP to start from
the spectral candidates, and a casadi MAP that does not cover the model or fails falls back to the
derivative-free MAP. A model that cannot describe how the pixel sees the motion under any spectral
reading (`check_observation`) stops the fit with a one-line DataError before any estimate is
returned."""

from __future__ import annotations

import itertools
import logging
import math
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Protocol, runtime_checkable

from forward.scene import format_bytes, memory_limit
from vibinverse.detection import DETECTION_GAIN
from vibinverse.errors import InputError, NumericalError, Unsupported
from vibinverse.estimators import CasadiMap, Emcee, LaplaceImportance, ScipyMap, SindyEstimator, SpectralEstimator
from vibinverse.estimators.base import base_result, complete
from vibinverse.estimators.scipy_map import MapPoint, map_result, polish
from vibinverse.io.series import check_resolves
from vibinverse.posterior import Posterior
from vibinverse.result import FitResult

logger = logging.getLogger(__name__)

# another reading of the spectrum closer than this in log posterior is reported as ambiguous (the
# 5-sigma gain of the detection test: one reading is claimed only when the other is that far below)
AMBIGUITY_MARGIN = DETECTION_GAIN


#: the MAP, predictive band and draws: 2.3 kB a sample measured (the default fit of a one-hour 200 Hz
#: frame record peaked at 1.68 GB), so that such a record fits the default 2 GiB limit
FIT_BYTES_PER_SAMPLE = 2.5e3


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


def check_method(method: str) -> None:
    """InputError (one line, the allowed methods) unless `method` is one of METHODS."""
    if method not in METHODS:
        raise InputError(f"--method: {method!r} is not one of {', '.join(METHODS)}")


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
    """Fit `posterior` by `method` (one of METHODS, `fit_method`); the result's timing holds every
    stage's seconds."""
    how = fit_method(method)()
    check_fit(posterior)
    how.check(posterior)
    return how.fit(posterior, RunOptions(seed, backend, resume, workers, max_steps, progress))


@dataclass(frozen=True)
class RunOptions:
    """What `run` hands the sampling stages (its keyword arguments)."""

    seed: int = 0
    backend: Path | None = None
    resume: bool = False
    workers: int = 1
    max_steps: int = 20000
    progress: bool = True


#: the fitting methods by name (`--method NAME`), in the order `register_method` saw them
FIT_METHODS: dict[str, type[FitMethod]] = {}


def register_method(cls: type[FitMethod]) -> type[FitMethod]:
    """Class decorator: make a fitting method available by its name (`--method NAME`)."""
    FIT_METHODS[cls.name] = cls
    return cls


def fit_method(method: str) -> type[FitMethod]:
    """The class of `--method NAME`; InputError (one line, the allowed methods) for another name."""
    check_method(method)
    return FIT_METHODS[method]


def spectral_stage(posterior: Posterior, final: bool = True) -> FitResult:
    """The spectral stage, every method's first; DataError when the model's observation describes
    none of its readings (`check_observation`). Not `final`: only the next stage's start, not
    completed (`Estimator.timed`)."""
    estimator = SpectralEstimator()
    spectral = estimator.fit(posterior) if final else estimator.timed(posterior)
    check_observation(posterior, spectral)
    return spectral


class FitMethod(ABC):
    """A value of `--method`: the stages of the chain it runs and where it stops (`fit`), and what
    the bench, the verdict and the report need to know of it."""

    name: ClassVar[str]
    #: how the bench's log names it
    label: ClassVar[str]
    #: its MAP is the derivative-free scipy one, never casadi's
    derivative_free: ClassVar[bool] = False
    #: SINDy runs between the spectral stage and the MAP, when it covers the model
    sindy_seeds: ClassVar[bool] = False
    #: its posterior is always emcee's (the result reports the sampler's convergence)
    samples_by_emcee: ClassVar[bool] = False
    #: its last stage may decline and hand back the stage before it (SINDy: the spectral start)
    may_decline: ClassVar[bool] = False
    #: what the intervals of its summary are when the summary does not say (one written before the
    #: summary's `approximation`, `vibinverse.verdict.approximation`): None for posterior draws
    approximation: ClassVar[str | None] = "laplace"

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if "label" not in cls.__dict__ and "name" in cls.__dict__:
            cls.label = cls.name

    def check(self, posterior: Posterior) -> None:
        """Unsupported, with the reason, before any stage runs when the method cannot fit `posterior`
        (none by default)."""
        return None

    @abstractmethod
    def fit(self, posterior: Posterior, options: RunOptions) -> FitResult:
        """The method's stages on `posterior`; the result's timing holds every stage's seconds."""

    def to_map(self, posterior: Posterior, seed: int) -> tuple[FitResult, dict | None, dict[str, float]]:
        """(the MAP, SINDy's diagnostics or None, every stage's seconds): the spectral stage, SINDy
        when `sindy_seeds` and it covers the model, and the MAP from the last of them (`map_stage`)."""
        spectral = spectral_stage(posterior, final=False)
        timing = dict(spectral.timing)
        start, sindy = spectral, None
        if self.sindy_seeds and SindyEstimator.covers(posterior):
            stage = SindyEstimator().timed(posterior, spectral)
            timing.update(stage.timing)
            sindy, start = stage.diagnostics["sindy"], stage
        best = map_stage(posterior, start, self, seed)
        timing.update(best.timing)
        return best, sindy, timing

    def emcee(
        self, posterior: Posterior, best: FitResult, sindy: dict | None, timing: dict, options: RunOptions
    ) -> FitResult:
        """emcee's posterior from the MAP `best` (`finish`ed)."""
        result = Emcee().fit(
            posterior,
            best,
            backend=options.backend,
            resume=options.resume,
            workers=options.workers,
            seed=options.seed,
            max_steps=options.max_steps,
            progress=options.progress,
        )
        return self.finish(result, best, sindy, timing)

    def finish(self, result: FitResult, best: FitResult, sindy: dict | None, timing: dict) -> FitResult:
        """The sampling stage's result with every stage's seconds, this method's name, the model
        facts of the MAP stage and SINDy's diagnostics."""
        timing.update(result.timing)
        result.timing = timing
        result.method = self.name
        result.data = {**result.data, **({"model": best.data["model"]} if "model" in best.data else {})}
        if sindy is not None:
            result.diagnostics["sindy"] = sindy
        return result


@register_method
class SpectralMethod(FitMethod):
    """The spectral stage alone."""

    name = "spectral"
    approximation = "spectral"

    def fit(self, posterior: Posterior, options: RunOptions) -> FitResult:
        return spectral_stage(posterior)


@register_method
class SindyMethod(FitMethod):
    """Spectral, then SINDy (a model with a resonance it identifies; else Unsupported before any
    stage). A declined SINDy hands back the spectral start."""

    name = "sindy"
    may_decline = True
    approximation = "jackknife"

    def check(self, posterior: Posterior) -> None:
        if not SindyEstimator.covers(posterior):
            SindyEstimator().estimate(posterior, None)  # raises Unsupported with the reason

    def fit(self, posterior: Posterior, options: RunOptions) -> FitResult:
        spectral = spectral_stage(posterior)
        stage = SindyEstimator().fit(posterior, spectral)
        stage.timing = {**spectral.timing, **stage.timing}
        return stage


@register_method
class CasadiMethod(FitMethod):
    """Spectral, then the MAP by casadi + IPOPT (the derivative-free MAP where casadi does not
    cover the model or fails) with its Laplace approximation."""

    name = "casadi"

    def fit(self, posterior: Posterior, options: RunOptions) -> FitResult:
        best, _, timing = self.to_map(posterior, options.seed)
        best.timing = timing
        return best


@register_method
class MapMethod(CasadiMethod):
    """Spectral, then the derivative-free MAP (scipy) with its Laplace approximation."""

    name = "map"
    derivative_free = True


@register_method
class ImportanceMethod(FitMethod):
    """Spectral, MAP, then its Laplace approximation importance-sampled (`LaplaceImportance`), on a
    record of any length; emcee when that fails its check."""

    name = "importance"

    def fit(self, posterior: Posterior, options: RunOptions) -> FitResult:
        best, sindy, timing = self.to_map(posterior, options.seed)
        try:
            result = LaplaceImportance().fit(posterior, best, seed=options.seed, workers=options.workers)
        except Unsupported as exc:
            logger.warning("%s; sampling with emcee", exc)
            return self.emcee(posterior, best, sindy, timing, options)
        return self.finish(result, best, sindy, timing)


@register_method
class McmcMethod(FitMethod):
    """Spectral, MAP, then emcee."""

    name = "mcmc"
    label = "emcee"
    samples_by_emcee = True
    approximation = None

    def fit(self, posterior: Posterior, options: RunOptions) -> FitResult:
        best, sindy, timing = self.to_map(posterior, options.seed)
        return self.emcee(posterior, best, sindy, timing, options)


@register_method
class AutoMethod(FitMethod):
    """The default: spectral, SINDy where it covers the model, MAP, then the posterior: importance
    sampling first for a record longer than IMPORTANCE_RECORD samples or a model that asks for it
    (`SignalModel.importance_first`), else emcee. When importance sampling fails its check, a long
    record keeps the Laplace approximation (with the failed check in `importance_check`), any
    other is sampled by emcee."""

    name = "auto"
    sindy_seeds = True
    approximation = None

    def fit(self, posterior: Posterior, options: RunOptions) -> FitResult:
        best, sindy, timing = self.to_map(posterior, options.seed)
        long_record = posterior.series.time.size > IMPORTANCE_RECORD
        if not (long_record or posterior.model.importance_first):
            return self.emcee(posterior, best, sindy, timing, options)
        try:
            result = LaplaceImportance().fit(posterior, best, seed=options.seed, workers=options.workers)
        except Unsupported as exc:
            if long_record:
                # emcee's walkers on a long record: tens of minutes to hours (a 63,000-sample beam
                # record with 6 modes and 5 lines: 35 parameters, ~1 ms a call); the Laplace
                # approximation answers, and says that its check failed
                logger.warning(
                    "%s; the intervals are the Laplace approximation's (--method mcmc samples the posterior)", exc
                )
                best.diagnostics["importance_check"] = str(exc).removeprefix("the Laplace approximation fails its ")
                return self.finish(best, best, sindy, timing)
            logger.info("%s; sampling with emcee", exc)
            return self.emcee(posterior, best, sindy, timing, options)
        return self.finish(result, best, sindy, timing)


METHODS = tuple(FIT_METHODS)


#: records longer than this many samples have their MAP found on a leading stretch of
#: LONG_RECORD // STRETCH_GROWTH samples and carried to the whole record through stretches
#: STRETCH_GROWTH times longer each (`stretched_map`)
LONG_RECORD = 100_000
STRETCH_GROWTH = 4
#: records longer than this many samples are sampled by importance sampling of the Laplace
#: approximation first (2000 independent likelihood calls); when its check fails, the intervals are
#: the Laplace approximation's, with the failed check in the verdict (`--method mcmc` samples): there a
#: posterior is near Gaussian as a rule, and emcee's walkers cost 5-10x more calls (a three-mode
#: record of 36 000 samples: 700 steps x 24 walkers, 90 s, against 2000 calls)
IMPORTANCE_RECORD = 20_000


def map_stage(posterior: Posterior, start: FitResult, method: str | FitMethod, seed: int) -> FitResult:
    """MAP from every candidate start: casadi + IPOPT with exact derivatives, except for a
    `derivative_free` method (`method`: its name or an instance) such as "map" (derivative-free
    scipy), which is also the fallback when casadi does not cover the model or fails. When the
    model changes its evaluation at the optimum (`SignalModel.refine`), the MAP runs again from
    there. A record longer than LONG_RECORD samples goes through `stretched_map`."""
    if isinstance(method, str):
        method = fit_method(method)()
    if posterior.series.time.size > LONG_RECORD:
        try:
            return stretched_map(posterior, start, method, seed)
        except Unsupported as exc:
            logger.info("the MAP runs on the whole record: %s", exc)
    result = _alternatives(posterior, _map(posterior, start, method, seed), method, seed)
    facts, message = posterior.model.refine(result.point)
    if message:
        logger.info("%s", message)
        again = _map(posterior, result, method, seed)
        again.timing = _summed([again, result])
        if "ambiguous" in result.diagnostics:
            again.diagnostics["ambiguous"] = result.diagnostics["ambiguous"]
        result = again
    if facts:
        result.data["model"] = {**result.data.get("model", {}), **posterior.model.describe(), **facts}
    return result


def stretch_lengths(n: int) -> list[int]:
    """The samples of each stretch of a long record's MAP: LONG_RECORD // STRETCH_GROWTH, then
    STRETCH_GROWTH times longer each, the whole record last (at most 1.25 STRETCH_GROWTH times the
    one before it, so that no stretch is nearly the whole record)."""
    lengths = [LONG_RECORD // STRETCH_GROWTH]
    while n > 1.25 * STRETCH_GROWTH * lengths[-1]:
        lengths.append(lengths[-1] * STRETCH_GROWTH)
    return [*lengths, n]


def stretched_map(posterior: Posterior, start: FitResult, method: FitMethod, seed: int) -> FitResult:
    """The MAP of a long record: the MAP from every start and every reading of the spectrum on its
    first stretch (`stretch_lengths`); then each reading within AMBIGUITY_MARGIN of the best there
    is polished on ever longer stretches (`scipy_map.polish`, whitened by the Laplace covariance of
    the stretch before, scaled by the ratio of lengths) up to the whole record, where the readings
    are compared again and the Laplace approximation is formed.

    A stretch 4x longer narrows the posterior 2x (a line's frequency 8x), so each start lies within
    about one sd of the next optimum, where the likelihood is close to quadratic and a gradient
    method needs a few dozen calls; the Nelder-Mead searches of the first stage cost calls on
    LONG_RECORD / 4 samples, not on the whole record (a one-hour 200 Hz record: 18 ms a call).
    Unsupported when the model cannot be cut (`SignalModel.head`)."""
    t0 = time.perf_counter()
    series, space = posterior.series, posterior.space
    lengths = stretch_lengths(series.time.size)
    free = dict(zip(space.names, space.priors))
    first = Posterior(posterior.model.head(lengths[0]), free)
    logger.info(
        "a long record (%d samples): the MAP starts on its first %d samples, then %s",
        series.time.size,
        lengths[0],
        ", ".join(str(n) for n in lengths[1:]),
    )
    found = _map(first, base_result(first, "start", start.point, starts=start.starts), method, seed)
    runs = _readings(first, found, method, seed)
    top = max(_finite(r.log_post) for _, r in runs)
    kept = [
        (what, MapPoint(r.z, r.cov_z, _finite(r.log_post)))
        for what, r in runs
        if top - _finite(r.log_post) < AMBIGUITY_MARGIN
    ]
    for before, length in itertools.pairwise(lengths):
        stage = posterior if length == series.time.size else Posterior(posterior.model.head(length), free)
        kept = [(what, polish(stage, p.z, p.cov_z * (before / length))) for what, p in kept]
    winner, ambiguous = _decide(posterior, [(what, posterior.values(p.z), p.log_post) for what, p in kept])
    facts, message = posterior.model.refine(posterior.values(kept[winner][1].z))
    if message:
        logger.info("%s", message)
        kept = [(what, polish(posterior, p.z, p.cov_z)) for what, p in kept]
        winner, ambiguous = _decide(posterior, [(what, posterior.values(p.z), p.log_post) for what, p in kept])
    searched = _summed([r for _, r in runs])
    result = map_result(posterior, found.method, kept[winner][1], seed)
    result.timing = {**searched, "polish_s": time.perf_counter() - t0 - sum(searched.values())}
    result.diagnostics["ambiguous"] = ambiguous
    result.diagnostics["map_stretches"] = lengths
    result = complete(result, posterior)
    if facts:
        result.data["model"] = {**result.data.get("model", {}), **posterior.model.describe(), **facts}
    return result


def _summed(results: list[FitResult]) -> dict[str, float]:
    """Every stage's seconds over several results."""
    keys = dict.fromkeys(k for r in results for k in r.timing)
    return {k: sum(r.timing.get(k, 0.0) for r in results) for k in keys}


def _alternatives(posterior: Posterior, best: FitResult, method: FitMethod, seed: int) -> FitResult:
    """The best of the MAPs from every reading of the spectrum (`_readings`); a reading that is not
    AMBIGUITY_MARGIN below it is reported in `diagnostics["ambiguous"]` instead of being dropped
    in silence."""
    every = _readings(posterior, best, method, seed)
    if len(every) == 1:
        return best
    winner_at, ambiguous = _decide(posterior, [(what, r.point, r.log_post) for what, r in every])
    if winner_at:
        logger.info("the MAP moved to another reading of the spectrum: %s", every[winner_at][0])
    winner = every[winner_at][1]
    winner.timing = _summed([r for _, r in every])
    winner.diagnostics["ambiguous"] = ambiguous
    return winner


def _readings(posterior: Posterior, best: FitResult, method: FitMethod, seed: int) -> list[tuple[str, FitResult]]:
    """`best` (the MAP found first) and the MAP from each other reading of the spectrum the model
    knows (`SignalModel.alternatives`), each with what it changes."""
    space = posterior.space
    runs = [("the reading the MAP found first", best)]
    for what, values in posterior.model.alternatives(best.point, space.names):
        start = {n: p.inside(values.get(n, best.point[n])) for n, p in zip(space.names, space.priors)}
        # a casadi run whose optimum is predicted more than the ambiguity margin below the best is
        # abandoned (`casadi_map`'s floor): it could neither win nor be reported as ambiguous
        floor = _finite(best.log_post) - AMBIGUITY_MARGIN
        first = base_result(posterior, "start", start, starts=[start])
        runs.append((what, _map(posterior, first, method, seed, floor=floor if math.isfinite(floor) else None)))
    return runs


def _decide(posterior: Posterior, readings: list[tuple[str, dict[str, float], float | None]]) -> tuple[int, list]:
    """(index of the best of (what, values, log posterior) readings, the others that are another
    reading than it and less than AMBIGUITY_MARGIN below it: what, gap, frequencies)."""
    best = max(range(len(readings)), key=lambda i: _finite(readings[i][2]))
    _, top, top_lp = readings[best]
    ambiguous = []
    for i, (what, values, lp) in enumerate(readings):
        if i == best or _same(values, top):
            continue
        gap = _finite(top_lp) - _finite(lp)
        if gap < AMBIGUITY_MARGIN:
            freqs = {n: values[n] for n in posterior.space.names if n.split("[")[0].endswith("frequency")}
            ambiguous.append({"alternative": what, "delta_log_posterior": float(gap), "values": freqs})
    return best, ambiguous


def _same(a: dict[str, float], b: dict[str, float]) -> bool:
    """Two optima are one reading when every frequency agrees to 1e-3."""
    names = [n for n in a if n.split("[")[0].endswith("frequency")]
    return all(abs(a[n] - b[n]) <= 1e-3 * max(abs(b[n]), 1e-12) for n in names)


def _finite(v: float | None) -> float:
    return v if v is not None and math.isfinite(v) else -math.inf


def _map(posterior: Posterior, start: FitResult, method: FitMethod, seed: int, floor: float | None = None) -> FitResult:
    """The MAP from `start`: casadi's unless `method` is `derivative_free`, scipy's where casadi
    does not cover the model or fails."""
    if not method.derivative_free:
        try:
            return CasadiMap().fit(posterior, start, seed=seed, floor=floor)
        except Unsupported as exc:
            logger.info("the casadi MAP does not cover this fit (%s); using the scipy MAP", exc)
        except (NumericalError, RuntimeError) as exc:  # any solver failure falls back, and says so
            logger.warning("casadi MAP failed (%s); using the derivative-free MAP", str(exc).splitlines()[0][:120])
    return ScipyMap().fit(posterior, start, seed=seed)
