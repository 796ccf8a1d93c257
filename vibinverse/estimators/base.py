"""The one interface of every estimator, and the registry the pipeline and the CLI choose from.

An estimator takes a `Posterior` and, optionally, the `FitResult` of the stage before it (whose
`starts`, `point`, `z` and `cov_z` seed it), and returns a complete `FitResult`: its own numbers,
plus the truth when the data carry it, the detection test of every line at its point estimate,
and the model's predictive band.
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from typing import Any, ClassVar

import numpy as np

from vibinverse.detection import line_detection
from vibinverse.posterior import Posterior
from vibinverse.result import FitResult


class Estimator(ABC):
    """fit(posterior, start) -> FitResult; subclasses implement `estimate`."""

    name: ClassVar[str]

    def fit(self, posterior: Posterior, start: FitResult | None = None, **options: Any) -> FitResult:
        """Estimate, time it (`timing[{name}_s]`), and complete the result (`complete`)."""
        t0 = time.perf_counter()
        result = self.estimate(posterior, start, **options)
        result.timing.setdefault(f"{self.name}_s", time.perf_counter() - t0)
        return complete(result, posterior)

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
    every line at the point estimate, and the predictive band."""
    series = posterior.series
    data = {
        "source": series.source,
        "description": series.describe(),
        "n_gaps": series.n_gaps,
        "n_samples": int(series.time.size),
    }
    described = posterior.model.describe()
    if described is not None:
        data["model"] = dict(described)
    result.data = {**data, **result.data}
    result.truth = posterior.truth()
    result.diagnostics.update(line_detection(posterior, result.point))
    draws = result.draws if result.chains is not None else result.approximate_draws
    result.predictive = predictive(posterior, result.point, draws)
    return result


def predictive(posterior: Posterior, values: dict[str, float], draws: np.ndarray | None) -> dict[str, np.ndarray]:
    """The model mean at the point estimate and its 5-95 % band over up to 100 draws."""
    model = posterior.model
    out = {"model_mean": model.mean(values)}
    if draws is not None and len(draws):
        rng = np.random.default_rng(0)
        pick = draws[rng.choice(len(draws), size=min(100, len(draws)), replace=False)]
        curves = np.array([model.mean(dict(zip(posterior.space.names, d))) for d in pick])
        out["model_q05"], out["model_q95"] = np.percentile(curves, [5, 95], axis=0)
    return out
