"""The nuisance terms a fit asks for: coloured noise, drift, a gain drift and whether white sensor
noise is there (`NuisanceSpec`, read from a table's `nuisance` sub-table, which `vibinverse fit
--noise/--drift/--gain` and `vi.fit(..., noise=, drift=, gain=)` write). A scene model adds them to
its own state (`FrameModel`: the tilt modes + these terms, one Kalman engine)."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from vibinverse.engines.kalman import run_blocks, simulate_blocks
from vibinverse.engines.state_space import StateSpace
from vibinverse.errors import SceneError
from vibinverse.priors import Prior
from vibinverse.terms.base import DataFacts, Term, TermSum, one_dummy_state
from vibinverse.terms.drift import GAIN_LIMIT, SCENE_GAIN_TERMS, GainDrift, IntegratedWalk, RandomWalk
from vibinverse.terms.noise import AR1, Flicker, White

#: the coloured noise by its table spelling ("white": none) and the drift ("none": none)
NOISE_TERMS: dict[str, type[Term] | None] = {"white": None, "ar1": AR1, "1/f": Flicker}
DRIFT_TERMS: dict[str, type[Term] | None] = {"none": None, "walk": RandomWalk, "integrated": IntegratedWalk}
NOISE_KINDS = tuple(NOISE_TERMS)
DRIFT_KINDS = tuple(DRIFT_TERMS)
NO_NOISE = next(k for k, cls in NOISE_TERMS.items() if cls is None)  # the table's spelling of "none"
NO_DRIFT = next(k for k, cls in DRIFT_TERMS.items() if cls is None)
GAIN_WORDS = {"drift": SCENE_GAIN_TERMS, "none": 0}  # --gain drift / none
SPEC_KEYS = ("noise", "drift", "gain", "white")  # what a spec holds (the search's open or fixed keys)
KEYS = (*SPEC_KEYS, "values", "start")


class NuisanceKinds:
    """What a spec's `noise` and `drift` spellings say, through the registries (`NOISE_TERMS`,
    `DRIFT_TERMS`): a base of every spec that holds them (`NuisanceSpec`, the modal model's
    `ModalSpec`)."""

    noise: str
    drift: str

    @property
    def coloured(self) -> bool:
        """Whether a coloured noise (AR(1), 1/f) is there."""
        return NOISE_TERMS[self.noise] is not None

    @property
    def drifting(self) -> bool:
        """Whether an additive drift is there."""
        return DRIFT_TERMS[self.drift] is not None

    @property
    def drift_names(self) -> list[str]:
        """The additive drift's parameters ([] without one)."""
        term = DRIFT_TERMS[self.drift]
        return term().names() if term is not None else []


@dataclass(frozen=True)
class NuisanceSpec(NuisanceKinds):
    """Which nuisance terms: the coloured noise ("white": none, "ar1", "1/f"), the drift ("none",
    "walk", "integrated"), the gain drift's slow functions (0: none) and the white sensor noise (False only
    beside a coloured noise, which then is the whole noise)."""

    noise: str = "white"
    drift: str = "none"
    gain: int = 0
    white: bool = True

    def __post_init__(self) -> None:
        if not self.white and not self.coloured:
            raise SceneError("nuisance.white: false needs a coloured noise (noise = 'ar1' or '1/f') in its place")

    @classmethod
    def from_table(cls, table: dict[str, Any], key: str = "nuisance") -> NuisanceSpec:
        """The spec of `table[key]` (absent: none); one-line SceneError naming the bad key."""
        m = table.get(key) or {}
        if not isinstance(m, dict):
            raise SceneError(f"{key}: must be a table, e.g. {{noise = 'ar1', drift = 'walk', gain = true}}")
        unknown = sorted(set(m) - set(KEYS))
        if unknown:
            raise SceneError(f"{key}.{unknown[0]}: unknown key; allowed: {', '.join(KEYS)}")
        noise = m.get("noise", "white")
        if noise not in NOISE_KINDS:
            raise SceneError(f"{key}.noise: {noise!r}; allowed: {', '.join(repr(k) for k in NOISE_KINDS)}")
        drift = m.get("drift", "none")
        drift = {True: "walk", False: "none", None: "none"}.get(drift, drift) if not isinstance(drift, str) else drift
        if drift not in DRIFT_KINDS:
            raise SceneError(f"{key}.drift: {m.get('drift')!r}; allowed: false, true, 'none', 'walk', 'integrated'")
        gain = m.get("gain", 0)
        if isinstance(gain, str):
            gain = GAIN_WORDS.get(gain, gain)
        elif gain is True or gain is False or gain is None:
            gain = SCENE_GAIN_TERMS if gain else 0
        if isinstance(gain, bool) or not isinstance(gain, (int, np.integer)) or not 0 <= int(gain) <= 24:
            raise SceneError(
                f"{key}.gain: {m.get('gain')!r}; allowed: false, true ({SCENE_GAIN_TERMS} slow functions) or 0..24"
            )
        white = m.get("white", True)
        if not isinstance(white, (bool, np.bool_)):
            raise SceneError(f"{key}.white: {white!r}; allowed: true, or false beside noise = 'ar1' or '1/f'")
        return cls(noise, drift, int(gain), bool(white))

    def table(self) -> dict[str, Any]:
        """The `nuisance` sub-table of this spec."""
        return {"noise": self.noise, "drift": self.drift, "gain": self.gain, "white": self.white}

    def terms(self, white: bool | None = None, level_free: bool = True) -> TermSum:
        """The terms (the white noise only when `white`, default: the spec's); a gain drift with its
        constant when the model's level is not free (`level_free` False: a scene model)."""
        out = [cls() for cls in (NOISE_TERMS[self.noise], DRIFT_TERMS[self.drift]) if cls is not None]
        if self.gain:
            out.append(GainDrift(self.gain, constant=not level_free))
        if self.white if white is None else white:
            out.append(White())
        return TermSum(*out)

    def describe(self) -> str:
        """In words, e.g. "AR(1) noise, random-walk drift, white noise" (each term's `label`)."""
        return ", ".join(t.label for t in self.terms()) or "none"


class NuisanceState:
    """The nuisance terms a scene model holds beside its own states (`SignalModel.accepts_nuisance`):
    their spec, parameters, priors and values (given, else the table's `nuisance.values` (fixed) or
    `nuisance.start` (the nuisance search's optimum), else their spectral starts), and the composed
    state space the engine runs (`compose`, `run`)."""

    def __init__(self, table: dict[str, Any], facts: DataFacts):
        self.spec = NuisanceSpec.from_table(table)
        self.terms = self.spec.terms(white=False, level_free=False)
        self.facts = facts
        given = table.get("nuisance") or {}
        self._given = {k: float(x) for key in ("start", "values") for k, x in (given.get(key) or {}).items()}
        self._base: dict[str, float] | None = None

    def __bool__(self) -> bool:
        """Whether any nuisance state or multiplier sits beside the model's own."""
        return bool(self.terms)

    @property
    def white(self) -> bool:
        """Whether the white sensor noise is there."""
        return self.spec.white

    def names(self) -> list[str]:
        return self.terms.names()

    def priors(self) -> dict[str, Prior]:
        return self.terms.priors(self.facts)

    def complete(
        self, guesses: list[dict[str, float]], level: Callable[[dict[str, float]], float] | None = None
    ) -> list[dict[str, float]]:
        """The model's starting values with the terms' added (and the white noise's sigma dropped
        when the spec has none), in place. `level`: the model's own level at a guess (its mean at
        rest); a gain drift's constant `gain.a0` then starts at the data's mean over it, less 1, and
        its slow coefficients (fitted relative to the data's mean) are rescaled to that level. From
        0, a 20 % gain drift's mean of -1.7 % (9 intensity units on a level of 537, 15x the noise)
        put the start 300,000 ln-units down and the optimum reached from it at a 0.23 Hz tilt."""
        for g in guesses:
            g.update({n: self.value({}, n) for n in self.names()})
            if "gain.a0" in g and level is not None and "gain.a0" not in self._given:
                at_rest = float(level(g))
                if math.isfinite(at_rest) and abs(at_rest) > 0:
                    ratio = self.facts.level / at_rest
                    limit = 0.9 * GAIN_LIMIT
                    g["gain.a0"] = float(np.clip(ratio - 1.0, -limit, limit))
                    for n in self.names():
                        if n.startswith("gain.") and n != "gain.a0" and n not in self._given:
                            g[n] = float(np.clip(g[n] * ratio, -limit, limit))
            if not self.white:
                g.pop("noise.sigma", None)
        return guesses

    def value(self, values: Mapping[str, float], name: str) -> float:
        """A nuisance parameter's value (class docstring)."""
        if name in values:
            return values[name]
        if self._base is None:
            self._base = {**self.terms.starts(self.facts), **self._given}
        return self._base[name]

    def compose(
        self,
        values: Mapping[str, float],
        steps: np.ndarray,
        lead: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
        blocks: list[int],
        r: float,
        samples: int,
    ) -> tuple[StateSpace, bool]:
        """(the state space, whether the values are inside the terms' domain): the model's own
        states first (`lead` = (phis, qs, p0, h) in `blocks` of 1 or 2 states, which a gain drift
        multiplies), the terms' after them, measurement variance `r`, the multiplier cut to
        `samples` (a stretch of the record keeps the whole record's slow functions). Outside the domain the
        tables are formed at the starts."""
        v = {n: self.value(values, n) for n in self.names()}
        valid = self.terms.valid(v)
        if not valid:
            v = {n: self.value({}, n) for n in self.names()}
        phis, qs, p0, h = lead
        n = h.size
        ss = self.terms.state_space(v, steps, self.facts, lead=n)
        ss.phis[:, :n, :n], ss.qs[:, :n, :n], ss.p0[:n, :n], ss.h[:n] = phis, qs, p0, h
        o = 0
        for size in blocks:
            ss.lo[o : o + size], ss.hi[o : o + size] = o, o + size
            o += size
        ss.r = r
        ss.hm = ss.hm[:samples]
        if ss.h.size == 0:  # no state at all (white noise and a gain drift): one nobody sees
            ss = one_dummy_state(ss, steps.size)
        if ss.hm.size:
            valid = valid and bool(ss.hm.min() > 0.0)  # 1 + g must stay positive
        return ss, valid

    def run(
        self,
        residual: np.ndarray,
        ss: StateSpace,
        idx: np.ndarray,
        white: np.ndarray | None = None,
        lls: np.ndarray | None = None,
    ) -> float:
        """log p(residual) of the composed state space by the engine, the converged gain held
        (`kalman.hold_samples`) unless a gain drift varies the observation."""
        from vibinverse.kalman import hold_samples

        hold = 0 if ss.hm.size else hold_samples(ss.phis)
        return run_blocks(
            residual, ss.phis, ss.qs, idx, ss.lo, ss.hi, ss.h, ss.r, ss.p0,
            hold=hold, white=white, lls=lls, hm=ss.hm, nscaled=ss.nscaled,
        )  # fmt: skip

    def simulate(self, ss: StateSpace, idx: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """A draw of the composed state space at every sample of `idx` (no mean)."""
        return simulate_blocks(
            ss.phis, ss.qs, idx, ss.lo, ss.hi, ss.h, ss.r, ss.p0, rng, hm=ss.hm, nscaled=ss.nscaled
        )  # fmt: skip
