"""Drift terms: a random walk, an integrated random walk (both additive, started at 0 so that the
model's level is the level at the first sample), and a multiplicative gain drift (a cloud dims the
whole signal, the vibration included).

- `RandomWalk` (`drift.rate`, intensity / sqrt(s)): Phi = 1, Q = rate^2 dt; PSD rate^2 / (2 pi^2 f^2).
- `IntegratedWalk` (`drift.rate`, intensity / s^1.5): level and slope, the slope driven by white
  noise of intensity rate^2: Phi = [[1, dt], [0, 1]], Q = rate^2 [[dt^3/3, dt^2/2], [dt^2/2, dt]];
  PSD 2 rate^2 / (2 pi f)^4.
- `GainDrift` (`gain.a1` .. `gain.aJ`): 1 + g(t), g = sum_j a_j cos(pi j u), u = (t - t0) / span,
  0.5 to J / 2 cycles per record, multiplying the signal terms and the deterministic mean. Given
  the coefficients the model stays linear-Gaussian (the observation row varies per sample).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from vibinverse.priors import Prior
from vibinverse.terms.base import INTEGRATED_WALK_FORM, WALK_FORM, DataFacts, Term, register_term

GAIN_TERMS = 6  # the gain drift's cosines: 0.5 to 3 cycles per record
GAIN_LIMIT = 0.5  # each coefficient's prior: uniform (-limit, limit)


def gain_names(terms: int) -> list[str]:
    """The gain drift's coefficients, `gain.a1` .. `gain.a<terms>`."""
    return [f"gain.a{j}" for j in range(1, terms + 1)]


def gain_basis(t: np.ndarray, terms: int) -> np.ndarray:
    """(terms, T): cos(pi j u), u = (t - t0) / span from 0 to 1, j = 1..terms: j / 2 cycles per
    record, none with a mean over the record of more than 1 / (pi j) (the level stays the level)."""
    u = (t - t[0]) / max(float(t[-1] - t[0]), 1e-300)
    return np.ascontiguousarray(np.cos(np.pi * np.arange(1, terms + 1)[:, None] * u[None, :]))


def _rate_prior(facts: DataFacts, integrated: bool) -> dict[str, Prior]:
    scale = facts.sd / math.sqrt(facts.span) / (facts.span if integrated else 1.0)
    return {"drift.rate": Prior("loguniform", (1e-5 * scale, 30.0 * scale))}


def _rate_start(facts: DataFacts, integrated: bool) -> dict[str, float]:
    rate = 0.1 * facts.sd / math.sqrt(facts.span)
    return {"drift.rate": rate / facts.span if integrated else rate}


@register_term
class RandomWalk(Term):
    """A random-walk drift of the level (`drift.rate`), started at 0."""

    kind = "walk"
    label = "random-walk drift"
    block_form = WALK_FORM

    def names(self) -> list[str]:
        return ["drift.rate"]

    def blocks(self, facts: DataFacts) -> list[int]:
        return [1]

    def form_parameters(self, values: Mapping[str, float], facts: DataFacts) -> list[tuple[float, ...]]:
        return [(float(values["drift.rate"]) ** 2,)]

    def fill(self, values, steps, phis, qs, p0, offset, facts) -> None:
        phis[:, offset, offset] = 1.0
        qs[:, offset, offset] = float(values["drift.rate"]) ** 2 * steps

    def psd(self, values: Mapping[str, float], f: np.ndarray, facts: DataFacts) -> np.ndarray:
        return float(values["drift.rate"]) ** 2 / (2.0 * math.pi**2 * np.asarray(f) ** 2)

    def priors(self, facts: DataFacts) -> dict[str, Prior]:
        return _rate_prior(facts, False)

    def starts(self, facts: DataFacts) -> dict[str, float]:
        return _rate_start(facts, False)

    def units(self, name: str, intensity: str) -> tuple[str, str]:
        return f"{intensity} s-0.5", "drift rate (RMS change per sqrt(second))"

    def component(self, values: Mapping[str, float], facts: DataFacts) -> dict[str, Any]:
        return {"kind": "drift", "model": "walk", "rate": float(values["drift.rate"])}


@register_term
class IntegratedWalk(Term):
    """An integrated random-walk drift (`drift.rate`): level and slope started at 0."""

    kind = "integrated"
    label = "integrated random-walk drift"
    block_form = INTEGRATED_WALK_FORM

    def names(self) -> list[str]:
        return ["drift.rate"]

    def blocks(self, facts: DataFacts) -> list[int]:
        return [2]

    def form_parameters(self, values: Mapping[str, float], facts: DataFacts) -> list[tuple[float, ...]]:
        return [(float(values["drift.rate"]) ** 2,)]

    def fill(self, values, steps, phis, qs, p0, offset, facts) -> None:
        o, q = offset, float(values["drift.rate"]) ** 2
        phis[:, o, o] = phis[:, o + 1, o + 1] = 1.0
        phis[:, o, o + 1] = steps
        qs[:, o, o] = q * steps**3 / 3.0
        qs[:, o, o + 1] = qs[:, o + 1, o] = q * steps**2 / 2.0
        qs[:, o + 1, o + 1] = q * steps

    def psd(self, values: Mapping[str, float], f: np.ndarray, facts: DataFacts) -> np.ndarray:
        return 2.0 * float(values["drift.rate"]) ** 2 / (2.0 * math.pi * np.asarray(f)) ** 4

    def priors(self, facts: DataFacts) -> dict[str, Prior]:
        return _rate_prior(facts, True)

    def starts(self, facts: DataFacts) -> dict[str, float]:
        return _rate_start(facts, True)

    def units(self, name: str, intensity: str) -> tuple[str, str]:
        return f"{intensity} s-1.5", "drift rate (RMS slope change per sqrt(second))"

    def component(self, values: Mapping[str, float], facts: DataFacts) -> dict[str, Any]:
        return {"kind": "drift", "model": "integrated", "rate": float(values["drift.rate"])}


@register_term
class GainDrift(Term):
    """A multiplicative gain drift 1 + g(t) of `terms` cosines (`gain.a1` ..)."""

    kind = "gain"
    label = "gain drift"

    def __init__(self, terms: int = GAIN_TERMS):
        if not 1 <= int(terms) <= 24:
            raise ValueError(f"gain terms: {terms}; allowed range [1, 24]")
        self.terms = int(terms)
        self._basis: tuple[int, np.ndarray] | None = None

    def names(self) -> list[str]:
        return gain_names(self.terms)

    def basis(self, facts: DataFacts) -> np.ndarray:
        """The cosines at the data's stamps (computed once per record)."""
        if self._basis is None or self._basis[0] != id(facts.time):
            self._basis = (id(facts.time), gain_basis(facts.time, self.terms))
        return self._basis[1]

    def multiplier(self, values: Mapping[str, float], facts: DataFacts) -> np.ndarray:
        c = np.array([float(values[n]) for n in self.names()])
        return 1.0 + c @ self.basis(facts)

    def valid(self, values: Mapping[str, float]) -> bool:
        return all(math.isfinite(values[n]) for n in self.names())

    def psd(self, values: Mapping[str, float], f: np.ndarray, facts: DataFacts) -> np.ndarray:
        """A multiplier adds no stationary power of its own (0)."""
        return np.zeros(np.shape(f))

    def priors(self, facts: DataFacts) -> dict[str, Prior]:
        return {n: Prior("uniform", (-GAIN_LIMIT, GAIN_LIMIT)) for n in self.names()}

    def starts(self, facts: DataFacts) -> dict[str, float]:
        """The least-squares fit of the cosines (and a constant, dropped) to y / mean(y) - 1 (the
        projection on smooth cosines averages the vibration out); zeros when the level is not well
        above the data's sd, clipped inside the prior."""
        y = facts.intensity
        good = np.isfinite(y)
        if not abs(facts.level) > facts.sd:
            return dict.fromkeys(self.names(), 0.0)
        basis = self.basis(facts)[:, good]
        design = np.vstack([np.ones(basis.shape[1]), basis]).T
        coef = np.linalg.lstsq(design, y[good] / facts.level - 1.0, rcond=None)[0][1:]
        coef = np.clip(coef, -0.9 * GAIN_LIMIT, 0.9 * GAIN_LIMIT)
        return {n: float(c) for n, c in zip(self.names(), coef)}

    def units(self, name: str, intensity: str) -> tuple[str, str]:
        return "1", f"gain drift, cosine of {int(name[6:]) / 2:g} cycles per record"

    def component(self, values: Mapping[str, float], facts: DataFacts) -> dict[str, Any]:
        g = self.multiplier(values, facts) - 1.0
        return {
            "kind": "gain drift",
            "terms": self.terms,
            "largest": float(np.max(np.abs(g))),
            "coefficients": [float(values[n]) for n in self.names()],
        }
