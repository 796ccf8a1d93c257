"""Drift terms: a random walk, an integrated random walk (both additive, started at 0 so that the
model's level is the level at the first sample), and a multiplicative gain drift (a cloud dims the
whole signal, the vibration included).

- `RandomWalk` (`drift.rate`, intensity / sqrt(s)): Phi = 1, Q = rate^2 dt; PSD rate^2 / (2 pi^2 f^2).
- `IntegratedWalk` (`drift.rate`, intensity / s^1.5): level and slope, the slope driven by white
  noise of intensity rate^2: Phi = [[1, dt], [0, 1]], Q = rate^2 [[dt^3/3, dt^2/2], [dt^2/2, dt]];
  PSD 2 rate^2 / (2 pi f)^4.
- `GainDrift` (`gain.a1` .. `gain.aJ`): 1 + g(t), g = sum_j a_j s_j(t), s_j the record's slow
  Slepian functions (`slepian_gain_basis`: up to (J - 4) / 2 cycles per record, 4 for J = 12), multiplying
  the signal terms and the deterministic mean. Given
  the coefficients the model stays linear-Gaussian (the observation row varies per sample).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from vibinverse.priors import Prior
from vibinverse.terms.base import INTEGRATED_WALK_FORM, WALK_FORM, DataFacts, Term, register_term

GAIN_TERMS = 6  # the modal model's gain drift cosines (`gain_basis`): 0.5 to 3 cycles per record
SCENE_GAIN_TERMS = 12  # the gain drift term's slow functions (`slepian_gain_basis`): up to 4 cycles per record
GAIN_GRID = 8192  # `slepian_gain_basis` computes its sequences on at most this many points, then interpolates
GAIN_LIMIT = 0.5  # each coefficient's prior: uniform (-limit, limit)


def gain_names(terms: int) -> list[str]:
    """The gain drift's coefficients, `gain.a1` .. `gain.a<terms>`."""
    return [f"gain.a{j}" for j in range(1, terms + 1)]


def gain_basis(t: np.ndarray, terms: int) -> np.ndarray:
    """(terms, T): cos(pi j u), u = (t - t0) / span from 0 to 1, j = 1..terms: j / 2 cycles per
    record, none with a mean over the record of more than 1 / (pi j) (the level stays the level).
    The modal model's gain drift; the `GainDrift` term's is `slepian_gain_basis`."""
    u = (t - t[0]) / max(float(t[-1] - t[0]), 1e-300)
    return np.ascontiguousarray(np.cos(np.pi * np.arange(1, terms + 1)[:, None] * u[None, :]))


def gain_bandwidth(terms: int) -> float:
    """The time-bandwidth product NW (cycles per record) of a gain drift of `terms` slow functions:
    (terms - 4) / 2, at least 1 (SCENE_GAIN_TERMS = 12: 4 cycles per record)."""
    return max(1.0, (int(terms) - 4) / 2.0)


def slepian_gain_basis(t: np.ndarray, terms: int) -> np.ndarray:
    """(terms, T): slow Slepian functions of the record, each scaled to a largest |value| of 1.

    The first terms + 1 discrete prolate spheroidal sequences of time-bandwidth NW =
    `gain_bandwidth(terms)` (the basis that holds most of the energy of anything slower than NW
    cycles per record over a finite record; Slepian 1978, scipy's `dpss`), made orthogonal to the
    constant (the level stays the level) and the last of them dropped; computed on a grid of at most
    GAIN_GRID points over the span and interpolated at the stamps (any stamps, gaps included).
    The 6 cosines of `gain_basis` left a median 5.8 (up to 25) intensity units of a 20 % gain
    drift of 0.5-3 cycles per record on a level of 537 (the roof scene), 10x the sensor noise: a
    cosine's zero slope at both ends cannot follow a sinusoid's; a random-walk drift took the rest
    and buried a 3.5 Hz resonance. These 12 leave 0.02 (at most 0.07), and absorb 21 % of a 6-cycle
    sinusoid, 7 % of a 10-cycle one (12 cosines: 1.7 units left, 78 % and 2 % absorbed). The
    modal model keeps its cosines: with these, a 0.12 Hz mode of 2.4 cycles in 20 s alone in the
    record was read as a gain drift (`test_model_order`'s slow-mode tests)."""
    from scipy.signal.windows import dpss

    terms = int(terms)
    t = np.asarray(t, dtype=float)
    span = float(t[-1] - t[0]) if t.size > 1 else 0.0
    u = (t - t[0]) / span if span > 0 else np.zeros_like(t)
    m = int(min(max(t.size, 2 * (terms + 2)), GAIN_GRID))
    grid = np.linspace(0.0, 1.0, m)
    seq = np.atleast_2d(dpss(m, gain_bandwidth(terms), terms + 1))
    q, _ = np.linalg.qr(np.column_stack([np.ones(m), seq.T]))
    rows = q[:, 1 : terms + 1].T
    rows = rows / np.max(np.abs(rows), axis=1, keepdims=True)
    return np.ascontiguousarray([np.interp(u, grid, r) for r in rows])


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
    """A multiplicative gain drift 1 + g(t) of `terms` slow functions (`slepian_gain_basis`;
    `gain.a1` ..).

    `constant`: g also holds a constant (`gain.a0`), for a model whose level is not free (a scene
    model's level is the forward model's): a gain drift's mean over the record is then a change of
    the level that only this can describe (a random-walk drift, started at 0, took it as a steep
    walk and buried the resonance under its 1/f^2 power)."""

    kind = "gain"
    label = "gain drift"

    def __init__(self, terms: int = SCENE_GAIN_TERMS, constant: bool = False):
        if not 1 <= int(terms) <= 24:
            raise ValueError(f"gain terms: {terms}; allowed range [1, 24]")
        self.terms = int(terms)
        self.constant = bool(constant)
        self._basis: tuple[int, np.ndarray] | None = None

    def names(self) -> list[str]:
        return (["gain.a0"] if self.constant else []) + gain_names(self.terms)

    def basis(self, facts: DataFacts) -> np.ndarray:
        """The slow functions at the data's stamps (computed once per record); the constant first
        with `constant`."""
        if self._basis is None or self._basis[0] != id(facts.time):
            rows = slepian_gain_basis(facts.time, self.terms)
            if self.constant:
                rows = np.vstack([np.ones((1, rows.shape[1])), rows])
            self._basis = (id(facts.time), rows)
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
        """The least-squares fit of the slow functions (and a constant, dropped) to y / mean(y) - 1
        (the projection on slow functions averages the vibration out); zeros when the level is not well
        above the data's sd, clipped inside the prior. The constant (`constant`) starts at 0: the
        data's mean is the level the model's own level is compared with."""
        y = facts.intensity
        good = np.isfinite(y)
        if not abs(facts.level) > facts.sd:
            return dict.fromkeys(self.names(), 0.0)
        basis = self.basis(facts)[int(self.constant) :, good]
        design = np.vstack([np.ones(basis.shape[1]), basis]).T
        coef = np.linalg.lstsq(design, y[good] / facts.level - 1.0, rcond=None)[0][1:]
        coef = np.clip(coef, -0.9 * GAIN_LIMIT, 0.9 * GAIN_LIMIT)
        return {**({"gain.a0": 0.0} if self.constant else {}), **dict(zip(gain_names(self.terms), map(float, coef)))}

    def units(self, name: str, intensity: str) -> tuple[str, str]:
        if name == "gain.a0":
            return "1", "gain drift, constant (the level's relative change over the record)"
        cycles = gain_bandwidth(self.terms)
        return "1", f"gain drift, slow function {int(name[6:])} of {self.terms} (up to {cycles:g} cycles per record)"

    def component(self, values: Mapping[str, float], facts: DataFacts) -> dict[str, Any]:
        g = self.multiplier(values, facts) - 1.0
        return {
            "kind": "gain drift",
            "terms": self.terms,
            "largest": float(np.max(np.abs(g))),
            "coefficients": [float(values[n]) for n in self.names()],
        }
