"""A posterior over named parameters: prior x likelihood, in the sampler's unconstrained space."""

from __future__ import annotations

import math

import numpy as np

from forward.errors import SceneError
from vibinverse.data import Series
from vibinverse.frame_model import FrameLikelihood, get_value
from vibinverse.params import ParameterSpace, Prior


class Problem:
    """log posterior of the free parameters; picklable, so a process pool can evaluate it."""

    def __init__(self, table: dict, series: Series, free: dict[str, Prior]):
        self.like = FrameLikelihood(table, series)
        self.space = ParameterSpace(free)
        self.series = series
        fittable = self.like.fittable()
        for name in self.space.names:
            if name not in fittable:
                raise SceneError(f"fit: {name} cannot be fitted (yet); free parameters of this scene: "
                                 f"{', '.join(sorted(fittable))}")

    def __call__(self, z: np.ndarray) -> float:
        return self.log_posterior(z)

    def log_posterior(self, z: np.ndarray) -> float:
        lp = self.space.log_prior_z(z)
        if not math.isfinite(lp):
            return -math.inf
        ll = self.like.log_likelihood(self.space.from_z(z))
        return lp + ll if math.isfinite(ll) else -math.inf

    def values(self, z: np.ndarray) -> dict[str, float]:
        return self.space.from_z(z)

    def truth(self) -> dict[str, float | None]:
        """True values of the free parameters when the data carry the scene (vibinverse simulate)."""
        if self.series.scene is None:
            return {n: None for n in self.space.names}
        from vibinverse.frame_model import modal_table
        table = modal_table(self.series.scene)
        out = {}
        for n in self.space.names:
            try:
                out[n] = get_value(table, n)
            except Exception:
                out[n] = 0.0 if n.endswith("drive_phase") else None
        return out
