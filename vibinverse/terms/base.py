"""Terms, composed with `+` into a model's state space (celerite2's shape: `SHOTerm() + RealTerm()`).

A term is one small class that owns everything the engine and the estimators need of it:

- its parameter names (`names`), units (`units`), default priors (`priors`) and spectral starting
  values (`starts`), the last two from the data's facts (`DataFacts`);
- its state-space block(s) (`blocks`, `fill`): transition and process noise discretized exactly over
  any time step, uniform or irregular, and the initial covariance;
- its observation row (`observe`), and whether a gain drift multiplies it (`scaled`);
- for a compiled kernel (the modal model's), which elementary form its blocks are (`block_form`) and
  their parameters (`form_parameters`);
- the white measurement noise it adds (`measurement_variance`) and its multiplier on the whole
  signal (`multiplier`, the gain drift's);
- its one-sided power spectral density (`psd`, intensity^2 / Hz, whose integral over (0, inf) is
  the term's variance), which gives Whittle's Fisher information (`TermSum.whittle_fisher`);
- a JSON-able description of its fitted values (`component`).

A `TermSum` lays the terms' blocks out one after the other (the scaled ones first, so that the
engine's gain drift multiplies the leading states: `vibinverse.engines.kalman.block_filter`), fills
the tables at given values, and runs the engine (`log_likelihood`). A term class is found by its
`kind` in `TERMS` (`register_term`), never by a string switch.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from vibinverse.engines.kalman import run_blocks
from vibinverse.engines.state_space import StateSpace
from vibinverse.io.series import Series
from vibinverse.priors import Prior


@dataclass(frozen=True)
class DataFacts:
    """What a term's priors and starts read from the data: its standard deviation, span (s), median
    step (s), Nyquist frequency (Hz: the top of the band fitted, `Series.top`), range, level and
    the stamps (s)."""

    sd: float
    span: float
    dt: float
    nyquist: float
    ymin: float
    ymax: float
    level: float
    time: np.ndarray
    intensity: np.ndarray

    @classmethod
    def of(cls, series: Series) -> DataFacts:
        """The facts of a series (gaps ignored)."""
        y = np.asarray(series.intensity, dtype=float)
        t = np.asarray(series.time, dtype=float)
        return cls(
            sd=float(np.nanstd(y)) or 1.0,
            span=max(float(t[-1] - t[0]), float(series.dt)),
            dt=float(series.dt),
            nyquist=series.top,
            ymin=float(np.nanmin(y)),
            ymax=float(np.nanmax(y)),
            level=float(np.nanmean(y)),
            time=t,
            intensity=y,
        )


#: the elementary blocks a compiled kernel fills by number (`vibinverse.models.modal`'s tables): a
#: 2 x 2 oscillator (w, zeta w, rms), a random walk (rate^2), an integrated random walk (rate^2),
#: an Ornstein-Uhlenbeck state (time, variance) and a free decay (w, zeta w, amplitude: an
#: oscillator without process noise, its initial state drawn at its onset)
OSCILLATOR_FORM, WALK_FORM, INTEGRATED_WALK_FORM, OU_FORM, FREE_DECAY_FORM = 0, 1, 2, 3, 4


class Term(ABC):
    """One additive (or, for a gain drift, multiplicative) part of a measured series."""

    kind: ClassVar[str]  # the registry key (`TERMS`)
    label: ClassVar[str]  # what it is, in words (reports)
    #: the gain drift multiplies this term's observation (a signal term: the vibration is dimmed
    #: with the light), not a nuisance term's (sensor noise, a drift of the electronics)
    scaled: ClassVar[bool] = False
    #: the elementary form (`OSCILLATOR_FORM` ..) of each of its blocks; None: it has no blocks
    block_form: ClassVar[int | None] = None

    def names(self) -> list[str]:
        """Its parameters' names, in a fixed order."""
        return []

    def blocks(self, facts: DataFacts) -> list[int]:
        """The sizes (1 or 2) of its diagonal blocks of the state."""
        return []

    def fill(  # noqa: B027 - a term without states (white noise, a gain drift) fills nothing
        self,
        values: Mapping[str, float],
        steps: np.ndarray,
        phis: np.ndarray,
        qs: np.ndarray,
        p0: np.ndarray,
        offset: int,
        facts: DataFacts,
    ) -> None:
        """Write its blocks' exact (Phi, Q) for every step (phis[u], qs[u]) and its initial
        covariance into the tables, starting at state `offset`."""

    def form_parameters(self, values: Mapping[str, float], facts: DataFacts) -> list[tuple[float, ...]]:
        """The parameters of each of its blocks in its `block_form`, for a compiled kernel."""
        return []

    def observe(self, h: np.ndarray, offset: int, facts: DataFacts) -> None:
        """Write its observation row (the first state of each block is seen, by default)."""
        o = offset
        for size in self.blocks(facts):
            h[o] = 1.0
            o += size

    def measurement_variance(self, values: Mapping[str, float]) -> float:
        """The white measurement noise variance it adds (0 for a state term)."""
        return 0.0

    def multiplier(self, values: Mapping[str, float], facts: DataFacts) -> np.ndarray | None:
        """The factor it multiplies the signal terms by at each stamp (None: it multiplies nothing)."""
        return None

    @abstractmethod
    def psd(self, values: Mapping[str, float], f: np.ndarray, facts: DataFacts) -> np.ndarray:
        """One-sided power spectral density at frequencies f (Hz), intensity^2 / Hz."""

    def priors(self, facts: DataFacts) -> dict[str, Prior]:
        """Default priors of its parameters."""
        return {}

    def starts(self, facts: DataFacts) -> dict[str, float]:
        """Spectral starting values of its parameters."""
        return {}

    def units(self, name: str, intensity: str) -> tuple[str, str]:
        """(units, long name) of one of its parameters."""
        return "1", name

    def component(self, values: Mapping[str, float], facts: DataFacts) -> dict[str, Any]:
        """Its fitted values, JSON-able (the report's and the summary's components)."""
        return {"kind": self.kind, **{n: float(values[n]) for n in self.names()}}

    def slowest_period(self, values: Mapping[str, float]) -> float | None:
        """The period (s) of its slowest oscillation (None: it does not oscillate)."""
        return None

    def valid(self, values: Mapping[str, float]) -> bool:
        """Whether `values` lie where the term is defined (positive scales and times)."""
        return all(math.isfinite(values[n]) and values[n] >= 0.0 for n in self.names())

    def __add__(self, other: Term | TermSum) -> TermSum:
        return TermSum(self) + other

    def __radd__(self, other: Any) -> TermSum:  # sum([...]) starts from 0
        if other == 0:
            return TermSum(self)
        return NotImplemented


class TermSum:
    """Terms added: their blocks side by side (the scaled terms first), one observation row, the
    sum of their measurement variances, the product of their multipliers, the sum of their PSDs."""

    def __init__(self, *terms: Term):
        self.terms: tuple[Term, ...] = tuple(sorted(terms, key=lambda t: not t.scaled))
        names = [n for t in self.terms for n in t.names()]
        if len(set(names)) != len(names):
            dup = next(n for n in names if names.count(n) > 1)
            raise ValueError(f"terms: two terms name the parameter {dup!r}; give one of them another prefix")

    def __add__(self, other: Term | TermSum) -> TermSum:
        more = other.terms if isinstance(other, TermSum) else (other,)
        return TermSum(*self.terms, *more)

    def __radd__(self, other: Any) -> TermSum:
        if other == 0:
            return self
        return NotImplemented

    def __bool__(self) -> bool:
        return bool(self.terms)

    def __iter__(self):
        return iter(self.terms)

    def names(self) -> list[str]:
        return [n for t in self.terms for n in t.names()]

    def size(self, facts: DataFacts) -> int:
        """Number of states."""
        return sum(sum(t.blocks(facts)) for t in self.terms)

    def priors(self, facts: DataFacts) -> dict[str, Prior]:
        return {k: v for t in self.terms for k, v in t.priors(facts).items()}

    def starts(self, facts: DataFacts) -> dict[str, float]:
        return {k: v for t in self.terms for k, v in t.starts(facts).items()}

    def valid(self, values: Mapping[str, float]) -> bool:
        return all(t.valid(values) for t in self.terms)

    def psd(self, values: Mapping[str, float], f: np.ndarray, facts: DataFacts) -> np.ndarray:
        out = np.zeros(np.shape(f))
        for t in self.terms:
            out = out + t.psd(values, f, facts)
        return out

    def units(self, name: str, intensity: str) -> tuple[str, str] | None:
        for t in self.terms:
            if name in t.names():
                return t.units(name, intensity)
        return None

    def components(self, values: Mapping[str, float], facts: DataFacts) -> list[dict[str, Any]]:
        return [t.component(values, facts) for t in self.terms]

    def multiplier(self, values: Mapping[str, float], facts: DataFacts) -> np.ndarray:
        """The product of the terms' multipliers at the stamps (empty: none)."""
        out = None
        for t in self.terms:
            m = t.multiplier(values, facts)
            if m is not None:
                out = m if out is None else out * m
        return np.empty(0) if out is None else out

    def state_space(
        self, values: Mapping[str, float], steps: np.ndarray, facts: DataFacts, lead: int = 0
    ) -> StateSpace:
        """The tables at `values` for the distinct `steps`, with `lead` states left empty in front
        (a model's own blocks, e.g. the physics' tilt modes: the caller fills them, and they count
        as scaled)."""
        steps = np.asarray(steps, dtype=float).reshape(-1)
        n = lead + self.size(facts)
        phis, qs = np.zeros((steps.size, n, n)), np.zeros((steps.size, n, n))
        p0, h = np.zeros((n, n)), np.zeros(n)
        lo, hi = np.arange(n, dtype=np.int64), np.arange(1, n + 1, dtype=np.int64)
        o, nscaled, r = lead, lead, 0.0
        for t in self.terms:
            t.fill(values, steps, phis, qs, p0, o, facts)
            t.observe(h, o, facts)
            for size in t.blocks(facts):
                lo[o : o + size], hi[o : o + size] = o, o + size
                o += size
            if t.scaled:
                nscaled = o
            r += t.measurement_variance(values)
        return StateSpace(phis, qs, p0, h, r, lo, hi, nscaled, self.multiplier(values, facts))

    def log_likelihood(
        self,
        values: Mapping[str, float],
        series: Series,
        mean: np.ndarray | None = None,
        facts: DataFacts | None = None,
    ) -> float:
        """log p(y - m mean) of the composed model by the engine (`run_blocks`; m the gain drift's
        multiplier, 1 without one); -inf outside the terms' domain. Irregular stamps: one table
        per distinct step (`unique_steps`)."""
        from vibinverse.kalman import unique_steps

        facts = facts or DataFacts.of(series)
        if not self.valid(values):
            return -math.inf
        if series.uniform:
            steps, idx = np.array([series.dt]), np.zeros(series.time.size, dtype=np.int64)
        else:
            steps, idx = unique_steps(series.time, rtol=1e-9)
        ss = self.state_space(values, steps, facts)
        if ss.h.size == 0:  # white noise alone: one state nobody sees
            ss = one_dummy_state(ss, steps.size)
        if ss.hm.size and not ss.hm.min() > 0.0:
            return -math.inf
        y = series.intensity
        if mean is not None:  # the deterministic signal, dimmed with the light
            y = y - (mean * ss.hm if ss.hm.size else mean)
        hold = 0 if ss.hm.size else self.hold(values, float(np.min(steps)), series.time.size)
        ll = run_blocks(
            y, ss.phis, ss.qs, idx, ss.lo, ss.hi, ss.h, ss.r, ss.p0, hold=hold, hm=ss.hm, nscaled=ss.nscaled
        )
        return ll if math.isfinite(ll) else -math.inf

    def hold(self, values: Mapping[str, float], step: float, samples: int) -> int:
        """Samples over which the engine's gain must stay converged before it is held
        (`block_filter`'s `freeze`): one period of the slowest oscillation any term has
        (`Term.slowest_period`) at the shortest step, plus one; 1 when none oscillates (walks and
        Ornstein-Uhlenbeck states converge without oscillating)."""
        periods = [p for t in self.terms if (p := t.slowest_period(values)) is not None]
        if not periods:
            return 1
        if not max(periods) < math.inf or not step > 0:
            return samples
        return int(min(samples, math.ceil(max(periods) / step) + 1))

    def whittle_fisher(self, values: Mapping[str, float], names: list[str], facts: DataFacts, n: int) -> np.ndarray:
        """Whittle's Fisher information of `names` from the summed PSD on the n-sample record's
        Fourier frequencies k / (n dt), k = 1..n/2: F_ij = sum_f (d log S / d theta_i)(d log S /
        d theta_j) (each ordinate a complex Gaussian coefficient: two degrees of freedom; the
        covariance term of a stationary series; derivatives by central differences of the terms'
        PSDs, steps of 1e-4 relative). White noise alone: 2 n / sigma^2 for sigma, the exact value."""
        f = np.arange(1, n // 2 + 1) / (n * facts.dt)
        s = self.psd(values, f, facts)
        grads = []
        for name in names:
            v = float(values[name])
            h = 1e-4 * max(abs(v), 1e-12)
            up = self.psd({**values, name: v + h}, f, facts)
            dn = self.psd({**values, name: v - h}, f, facts)
            grads.append((up - dn) / (2.0 * h))
        g = np.array(grads) / s
        return g @ g.T


def one_dummy_state(ss: StateSpace, steps: int) -> StateSpace:
    """A state space with one unseen, unmoving state (the engine needs at least one)."""
    z = np.zeros((steps, 1, 1))
    return StateSpace(
        z,
        z.copy(),
        np.zeros((1, 1)),
        np.zeros(1),
        ss.r,
        np.zeros(1, dtype=np.int64),
        np.ones(1, dtype=np.int64),
        0,
        ss.hm,
    )


TERMS: dict[str, type[Term]] = {}


def register_term(cls: type[Term]) -> type[Term]:
    """Class decorator: make a term available by its `kind` (`TERMS`)."""
    TERMS[cls.kind] = cls
    return cls
