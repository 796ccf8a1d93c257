"""A model's state-space tables at some parameter values: a composed model's (`StateSpace`, from
`vibinverse.terms.TermSum.state_space`), and a scene model's with its mean (`Components`): what
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
    #: with nuisance terms (`vibinverse.terms`): the composed state space (the model's own states
    #: first, `n_own` of them, which a gain drift multiplies) and whether the values lie inside the
    #: terms' domain
    state: StateSpace | None = None
    n_own: int = 0
    valid: bool = True

    @property
    def composed(self) -> bool:
        """Whether nuisance terms sit beside the tilt modes (the block engine runs it)."""
        return self.state is not None

    def tilt_variance(self) -> float:
        """The stationary variance of the model's own observation (the nuisance states left out)."""
        n = self.n_own if self.composed else self.h.size
        return float(self.h[:n] @ self.p0[:n, :n] @ self.h[:n])

    def tables(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(phis, qs, idx) for the per-step filter (a uniform grid: its one step for every sample)."""
        if self.idx is not None:
            return self.phis, self.qs, self.idx
        return self.phi[None], self.q[None], np.zeros(self.mean.size, dtype=np.int64)


@dataclass
class StateSpace:
    """The tables of a composed model at some values: (phis, qs) per distinct step, the initial
    covariance p0, the observation row h, the white measurement variance r, the block of each state
    (lo, hi), how many leading states the gain drift multiplies (`nscaled`) and the multiplier per
    sample (`hm`; empty without a gain drift)."""

    phis: np.ndarray
    qs: np.ndarray
    p0: np.ndarray
    h: np.ndarray
    r: float
    lo: np.ndarray
    hi: np.ndarray
    nscaled: int
    hm: np.ndarray
