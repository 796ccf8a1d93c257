"""A model's deterministic mean and state-space tables at some parameter values (`Components`): what
a scene model (`vibinverse.models.frame.FrameModel`) hands the engine (`vibinverse.engines.kalman`)
and the Fisher information (`vibinverse.fisher`) reads."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Components:
    """The model at some values: the mean, the state-space matrices over the nominal (median) step
    (phi, q; a uniform grid's only step), and the per-step tables (phis[idx[k]], qs[idx[k]] from sample
    k - 1 to k; one entry on a uniform grid)."""

    mean: np.ndarray
    phi: np.ndarray
    q: np.ndarray
    h: np.ndarray
    r: float
    p0: np.ndarray
    phis: np.ndarray | None = None
    qs: np.ndarray | None = None
    idx: np.ndarray | None = None
    #: with nuisance terms (`vibinverse.terms`): each state's block (lo, hi), the tilt states (the
    #: first `n_tilt`, which a gain drift multiplies by `hm` at each sample; `hm` empty without one)
    lo: np.ndarray | None = None
    hi: np.ndarray | None = None
    n_tilt: int = 0
    hm: np.ndarray | None = None
    valid: bool = True  # False: a nuisance value outside its term's domain (the likelihood is -inf)

    @property
    def composed(self) -> bool:
        """Whether nuisance terms sit beside the tilt modes (the block engine runs it)."""
        return self.lo is not None

    def tilt_variance(self) -> float:
        """The stationary variance of the tilt's first-order observation (the nuisance states left out)."""
        n = self.n_tilt if self.composed else self.h.size
        return float(self.h[:n] @ self.p0[:n, :n] @ self.h[:n])

    def tables(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(phis, qs, idx) for the per-step filter (a uniform grid: its one step for every sample)."""
        if self.idx is not None:
            return self.phis, self.qs, self.idx
        return self.phi[None], self.q[None], np.zeros(self.mean.size, dtype=np.int64)
