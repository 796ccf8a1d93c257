"""The one interface of every estimator, and the registry the pipeline and the CLI choose from.

An estimator takes a `Posterior` and, optionally, the `FitResult` of the stage before it (whose
`starts`, `point`, `z` and `cov_z` seed it), and returns a complete `FitResult`: its own numbers,
plus the truth when the data carry it, the detection test of every line at its point estimate,
and the model's predictive band.
"""

from __future__ import annotations

import logging
import math
import re
import time
from abc import ABC, abstractmethod
from functools import partial
from typing import Any, ClassVar

import numpy as np

from vibinverse.checks import residual_checks
from vibinverse.detection import line_detection
from vibinverse.errors import Unsupported
from vibinverse.io.series import FEW_CYCLES, Series
from vibinverse.models.base import intensity_units
from vibinverse.posterior import Posterior
from vibinverse.result import FitResult
from vibinverse.stationarity import line_stationarity

logger = logging.getLogger(__name__)


class Estimator(ABC):
    """fit(posterior, start) -> FitResult; subclasses implement `estimate`."""

    name: ClassVar[str]
    #: what the intervals of a result without posterior draws are (the summary labels them)
    approximation: ClassVar[str] = "laplace"

    def fit(self, posterior: Posterior, start: FitResult | None = None, **options: Any) -> FitResult:
        """Estimate, time it (`timing[{name}_s]`), and complete the result (`complete`)."""
        return complete(self.timed(posterior, start, **options), posterior)

    def timed(self, posterior: Posterior, start: FitResult | None = None, **options: Any) -> FitResult:
        """Estimate and time it, without `complete`: for a stage whose result only starts the next
        (the detection test of each line refits its null: ~2 s a line on a 60,000-sample record)."""
        t0 = time.perf_counter()
        result = self.estimate(posterior, start, **options)
        result.timing.setdefault(f"{self.name}_s", time.perf_counter() - t0)
        result.approximation = None if result.chains is not None else self.approximation
        return result

    @abstractmethod
    def estimate(self, posterior: Posterior, start: FitResult | None, **options: Any) -> FitResult:
        """The estimator's own numbers (method, point, sd or draws, diagnostics)."""


ESTIMATORS: dict[str, type[Estimator]] = {}


def register_estimator(cls: type[Estimator]) -> type[Estimator]:
    """Class decorator: make an estimator available by its name (`--method NAME`)."""
    ESTIMATORS[cls.name] = cls
    return cls


def base_result(posterior: Posterior, method: str, point: dict[str, float], **fields: Any) -> FitResult:
    """A FitResult of `posterior`'s parameters."""
    return FitResult(
        method=method,
        names=list(posterior.space.names),
        priors=list(posterior.space.priors),
        point=dict(point),
        series=posterior.series,
        **fields,
    )


def complete(result: FitResult, posterior: Posterior) -> FitResult:
    """Add what every result carries: the truth, the data's description, the detection test of
    every line at the point estimate, the predictive band, the parameters' units, the residual
    checks at the point estimate, and (computed when first asked for) the pointwise log-likelihood
    and replicate series of a subset of the draws (ArviZ's log_likelihood and posterior_predictive
    groups)."""
    series = posterior.series
    model = posterior.model
    data = {
        "source": series.source,
        "description": series.describe(),
        "n_gaps": series.n_gaps,
        "n_samples": int(series.time.size),
        "intensity_units": intensity_units(series),
        "time_units": "s",
    }
    if series.time_reference:
        data["time_reference"] = series.time_reference
    if series.passband is not None:  # fitted below a logger's anti-alias roll-off (`Series.passband`)
        data["passband_hz"] = float(series.passband)
    described = model.describe()
    if described is not None:
        data["model"] = dict(described)
    result.data = {**data, **result.data}
    result.truth = posterior.truth()
    result.units = {n: model.units(n) for n in result.names}
    result.diagnostics.update(line_detection(posterior, result.point))
    result.diagnostics["few_cycles"] = few_cycles(series, result.point)
    draws = result.draws if result.chains is not None else result.approximate_draws
    result.predictive = predictive(posterior, result.point, draws)
    try:
        residual = model.residuals(result.point)
    except Unsupported as exc:
        logger.debug("no residual checks: %s", exc)
    else:
        result.predictive["residual"] = residual
        top = None if series.passband is None else series.passband * series.dt
        result.diagnostics["residual_checks"] = residual_checks(residual, top)
    lines = {
        t.label: result.point[t.frequency]
        for t in model.line_tests(result.point, posterior.space.names)
        if t.deterministic and t.frequency is not None and t.frequency in result.point
    }
    if lines:
        result.diagnostics["line_stationarity"] = line_stationarity(series.time, series.intensity, lines)
    chains = (
        result.chains
        if result.chains is not None
        else (None if result.approximate_draws is None else result.approximate_draws[None])
    )
    if chains is not None and chains.size:
        result.pointwise, result.pointwise_source = {}, partial(pointwise, posterior, chains)
    return result


def few_cycles(series: Series, point: dict[str, float]) -> dict[str, float]:
    """Frequencies (Hz) at the point estimate that go through fewer than FEW_CYCLES cycles in the
    record, with their number of cycles: poorly constrained, whatever their interval says.
    (`drive_frequency[0]` and `modes[0].frequency` alike: the name without its indices ends in it.)"""
    span = float(series.time[-1] - series.time[0]) if series.time.size > 1 else 0.0
    out = {}
    for name, value in point.items():
        if re.sub(r"\[\d+\]", "", name).endswith("frequency") and math.isfinite(value) and value * span < FEW_CYCLES:
            out[name] = float(value * span)
    return out


#: values stored per group (log_likelihood, posterior_predictive): draws x samples <= this
POINTWISE_BUDGET = 4_000_000
MIN_POINTWISE_DRAWS, MAX_POINTWISE_DRAWS = 40, 200  # PSIS-LOO smooths the top 3 sqrt(S) weights: 42 at 200


def pointwise(posterior: Posterior, chains: np.ndarray, seed: int = 0) -> dict[str, np.ndarray]:
    """The pointwise log-likelihood and one replicate series of each draw of an evenly thinned
    subset (every chain, the same draw indices): arrays (chain, draw, sample), plus `draw` (the
    indices kept). The subset has between MIN_ and MAX_POINTWISE_DRAWS draws in all, fewer the
    longer the series (POINTWISE_BUDGET), so that a result file stays tens of MB at most."""
    model, names = posterior.model, posterior.space.names
    n_chain, n_draw, _ = chains.shape
    t = posterior.series.time.size
    total = int(np.clip(POINTWISE_BUDGET // max(t, 1), MIN_POINTWISE_DRAWS, MAX_POINTWISE_DRAWS))
    per_chain = int(min(n_draw, max(1, round(total / n_chain))))
    keep = np.unique(np.linspace(0, n_draw - 1, per_chain).round().astype(int))
    rng = np.random.default_rng(seed)
    loglik = np.empty((n_chain, keep.size, t))
    reps = np.empty((n_chain, keep.size, t))
    for c in range(n_chain):
        for i, d in enumerate(keep):
            values = dict(zip(names, chains[c, d]))
            loglik[c, i] = model.pointwise_log_likelihood(values)
            reps[c, i] = model.replicate(values, rng)
    return {"log_likelihood": loglik, "replicates": reps, "draw": keep}


def predictive(posterior: Posterior, values: dict[str, float], draws: np.ndarray | None) -> dict[str, np.ndarray]:
    """The model mean at the point estimate and its 5-95 % band over up to 100 draws (one
    percentile when every draw's mean is constant in time: on an hour at 200 Hz the band's
    percentiles over 100 x 720,000 values cost 1.5 s a call, and holding them to find out ~1 s)."""
    model = posterior.model
    out = {"model_mean": model.mean(values)}
    if draws is not None and len(draws):
        rng = np.random.default_rng(0)
        pick = draws[rng.choice(len(draws), size=min(100, len(draws)), replace=False)]
        levels: list[float] = []  # each draw's mean while every one is a level (no lines) ...
        curves: np.ndarray | None = None  # ... else every draw's mean curve
        for i, d in enumerate(pick):
            mean = model.mean(dict(zip(posterior.space.names, d)))
            if curves is None and mean.size and np.all(mean == mean[0]):
                levels.append(float(mean[0]))
                continue
            if curves is None:
                curves = np.empty((len(pick), mean.size))
                curves[:i] = np.asarray(levels)[:, None]
            curves[i] = mean
        size = out["model_mean"].size
        q05, q95 = np.empty(size), np.empty(size)
        if curves is None:  # a level per draw: one percentile, not 100 x n values held and sorted
            q05[:], q95[:] = np.percentile(levels, [5, 95])
            out["model_q05"], out["model_q95"] = q05, q95
            return out
        for a in range(0, size, PERCENTILE_COLUMNS):  # np.percentile copies: a slice at a time
            q05[a : a + PERCENTILE_COLUMNS], q95[a : a + PERCENTILE_COLUMNS] = np.percentile(
                curves[:, a : a + PERCENTILE_COLUMNS], [5, 95], axis=0
            )
        out["model_q05"], out["model_q95"] = q05, q95
    return out


PERCENTILE_COLUMNS = 65536  # the predictive band's percentiles, samples at a time (a long record's copy)
