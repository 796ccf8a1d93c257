"""A posterior over named parameters: prior x a signal model's likelihood, in the samplers'
unconstrained space."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from forward.errors import SceneError as ForwardSceneError
from vibinverse.io.series import Series
from vibinverse.models.base import SignalModel
from vibinverse.priors import ParameterSpace, Prior
from vibinverse.scene_keys import get_value


class Posterior:
    """log posterior of the free parameters of `model`; picklable, so a process pool can evaluate it."""

    def __init__(self, model: SignalModel, free: dict[str, Prior] | None = None):
        self.model = model
        self.space = ParameterSpace(free if free is not None else model.default_priors())
        model.check_free(self.space.names)
        #: the best (ln L, values) found so far of the model without each line, by the line's label
        #: (`vibinverse.detection.null_optimum`: the stages of one fit refine one optimum)
        self.null_optima: dict[str, tuple[float, dict[str, float]]] = {}
        #: the line tests already made, by the point they were made at (the MAP's, and the same
        #: point again when a sampler's stage keeps it: `vibinverse.detection.line_detection`)
        self.line_tests: dict[tuple[tuple[str, float], ...], dict[str, Any]] = {}

    @property
    def series(self) -> Series:
        return self.model.series

    def __call__(self, z: np.ndarray) -> float:
        return self.log_posterior(z)

    def log_posterior(self, z: np.ndarray) -> float:
        lp = self.space.log_prior_z(z)
        if not math.isfinite(lp):
            return -math.inf
        ll = self.model.log_likelihood(self.space.from_z(z))
        return lp + ll if math.isfinite(ll) else -math.inf

    def gradient(self, z: np.ndarray) -> np.ndarray | None:
        """d log posterior / dz: the model's own slope of its log-likelihood (`SignalModel.slope`,
        e.g. Whittle's analytic gradient) through the transform, plus the prior's and the
        Jacobian's (`ParameterSpace.log_prior_gradient_z`); None when the model has no slope."""
        values = self.space.from_z(z)
        slope = self.model.slope(values, self.space.names)
        if slope is None:
            return None
        return self.space.gradient_z(z, slope) + self.space.log_prior_gradient_z(z)

    def log_posterior_at(self, values: dict[str, float]) -> float:
        """log posterior at parameter values (in the sampler's space, Jacobian included)."""
        return self.log_posterior(self.space.to_z(values))

    def values(self, z: np.ndarray) -> dict[str, float]:
        return self.space.from_z(z)

    @property
    def bounds(self) -> dict[str, tuple[float, float]]:
        return {n: p.bounds for n, p in zip(self.space.names, self.space.priors)}

    def truth(self) -> dict[str, float | None]:
        """True values of the free parameters when the data carry the scene (vibinverse simulate);
        a phase is wrapped into its prior's window by the period the data see."""
        if self.series.scene is None:
            return dict.fromkeys(self.space.names)
        table = self.model.truth_table(self.series.scene)
        out: dict[str, float | None] = {}
        for n, p in zip(self.space.names, self.space.priors):
            try:
                out[n] = get_value(table, n)
            except ForwardSceneError:
                out[n] = 0.0 if _is_phase(n) else self.model.scene_defaults.get(n)
            value = out[n]
            if value is not None and _is_phase(n):  # the same angle inside the prior's window
                lo, hi = p.bounds
                if math.isfinite(lo) and not lo <= value <= hi:
                    out[n] = lo + (value - lo) % self.model.phase_period(n)
        return out


def _is_phase(name: str) -> bool:
    return name.rsplit(".", 1)[-1].split("[")[0] in ("phase", "drive_phase")
