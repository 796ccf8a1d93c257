"""The one interface through which every motion reaches the scene: a slope field over time.

A surface z = h(x, y, t) tilts its normal to (-h_x, -h_y, 1)/norm; the slopes (h_x, h_y) are the
normal-perturbation field. Motions that are fixed spatial shapes times time coefficients (plate
modes, a single-frequency ground wave, small rigid tilts) implement `ModalMotion`, which the fast
paths of later issues can exploit; any other motion implements `slopes` directly.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray


class Motion(ABC):
    """A motion of a surface, seen through its slopes. `line_keys`: the keys of its scene table
    that list one value per sinusoidal line (what a simulation's memory grows with)."""

    line_keys: ClassVar[tuple[str, ...]] = ()

    @abstractmethod
    def slopes(
        self, x: NDArray[np.float64], y: NDArray[np.float64], t: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(h_x, h_y) at points (x, y) (shape (N,), m) and times t (shape (T,), s): shape (T, N) each."""

    def prepare(self, t: NDArray[np.float64], rng: np.random.Generator) -> Motion:
        """The motion realized for one simulation on times `t`: random motions draw their
        realization here (once, so that chunked evaluation stays consistent); deterministic
        motions return themselves."""
        return self

    def max_frequency(self) -> float:
        """Highest frequency (Hz) in the motion, for sampling checks; 0 if unknown."""
        return 0.0


class ModalMotion(Motion):
    """slopes(x, y, t) = sum_k q_k(t) * shape_k(x, y)."""

    @abstractmethod
    def shapes(self, x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
        """Slope shapes, shape (K, 2, N): [k, 0] is d/dx, [k, 1] is d/dy of mode k."""

    @abstractmethod
    def coefficients(self, t: NDArray[np.float64]) -> NDArray[np.float64]:
        """Modal coordinates q_k(t), shape (T, K)."""

    def shape_key(self) -> tuple | None:
        """The values `shapes` depends on (a hashable tuple), so that equal shapes on equal points
        can be reused across scenes; None when shapes are cheap or not worth keeping."""
        return None

    def slopes(self, x, y, t):
        cached = getattr(self, "_shape_cache", None)
        if cached is None or cached[0] is not x or cached[1] is not y:  # shapes are static: once per point set
            cached = (x, y, self.shapes(x, y))
            self._shape_cache = cached
        s = cached[2]
        q = self.coefficients(np.asarray(t, dtype=float))
        return q @ s[:, 0, :], q @ s[:, 1, :]
