"""The spectral estimator: the model's periodogram starts (`SignalModel.guesses`), ranked by the
exact posterior. Milliseconds, rough, no uncertainty; it seeds every other estimator."""

from __future__ import annotations

from typing import Any

import numpy as np

from vibinverse.estimators.base import Estimator, base_result, register_estimator
from vibinverse.posterior import Posterior
from vibinverse.result import FitResult


def ranked_starts(posterior: Posterior) -> list[dict[str, float]]:
    """The model's spectral starts inside the priors, best posterior first (which periodogram line
    is the drive: the candidates' exact posterior decides)."""
    space = posterior.space
    starts = [
        {n: p.inside(g.get(n, p.centre())) for n, p in zip(space.names, space.priors)}
        for g in posterior.model.guesses(posterior.bounds)
    ]
    score = [posterior.log_posterior_at(st) for st in starts]
    order = np.argsort([-(v if np.isfinite(v) else -np.inf) for v in score], kind="stable")
    return [starts[i] for i in order]


@register_estimator
class SpectralEstimator(Estimator):
    """Periodogram peaks and sinusoid fits calibrated through the forward model."""

    name = "spectral"
    approximation = "spectral"

    def estimate(self, posterior: Posterior, start: FitResult | None, **options: Any) -> FitResult:
        starts = ranked_starts(posterior)
        return base_result(posterior, "spectral", starts[0], starts=starts, diagnostics={"converged": None})
