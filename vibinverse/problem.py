"""A posterior over named parameters: prior x likelihood, in the sampler's unconstrained space."""

from __future__ import annotations

import math

import numpy as np

from forward.errors import SceneError
from vibinverse.data import Series
from vibinverse.frame_model import FrameLikelihood, is_frame
from vibinverse.scene_keys import get_value
from vibinverse.params import ParameterSpace, Prior
from vibinverse.response_model import ResponseLikelihood


def likelihood_for(table: dict, series: Series) -> FrameLikelihood | ResponseLikelihood:
    """The exact likelihood of the scene's kind: a Kalman filter when a frame is driven by white
    noise, white-noise residuals about the reduced forward model when every motion is deterministic."""
    return FrameLikelihood(table, series) if is_frame(table) else ResponseLikelihood(table, series)


class Problem:
    """log posterior of the free parameters; picklable, so a process pool can evaluate it."""

    def __init__(self, table: dict, series: Series, free: dict[str, Prior],
                 like: FrameLikelihood | ResponseLikelihood | None = None):
        self.like = like or likelihood_for(table, series)
        self.kind = self.like.kind
        self.space = ParameterSpace(free)
        self.series = series
        fittable = self.like.fittable()
        for name in self.space.names:
            if name not in fittable:
                raise SceneError(f"fit: {name} cannot be fitted (yet); free parameters of this scene: "
                                 f"{', '.join(sorted(fittable))}")
        if self.kind == "response" and "noise.sigma" not in self.space.names:
            if not self.like.variance(np.ones(1), {}) > 0:
                raise SceneError("noise.sigma: the scene's sensor noise is 0, so no data fit it; set noise.sigma > 0 "
                                 "or free it (--free 'noise.sigma=loguniform(a, b)')")

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
        table = modal_table(self.series.scene) if self.kind == "frame" else self.series.scene
        out = {}
        for n, p in zip(self.space.names, self.space.priors):
            try:
                out[n] = get_value(table, n)
            except Exception:
                out[n] = 0.0 if _is_phase(n) else (_SCENE_DEFAULTS.get(n) if self.kind == "response" else None)
            if out[n] is not None and _is_phase(n):  # the same angle inside the prior's window
                lo, hi = p.bounds
                period = self.like.phase_period(n) if self.kind == "response" else 2 * math.pi
                if math.isfinite(lo) and not lo <= out[n] <= hi:
                    out[n] = lo + (out[n] - lo) % period
        return out


_SCENE_DEFAULTS = {"sun.irradiance": 1.0}  # scene values a file may leave out (forward.scene.Sun)


def _is_phase(name: str) -> bool:
    return name.rsplit(".", 1)[-1].split("[")[0] in ("phase", "drive_phase")
