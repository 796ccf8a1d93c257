"""The nuisance terms a fit asks for: coloured noise, drift, a gain drift and whether white sensor
noise is there (`NuisanceSpec`, read from a table's `nuisance` sub-table, which `vibinverse fit
--noise/--drift/--gain` and `vi.fit(..., noise=, drift=, gain=)` write). A scene model adds them to
its own state (`FrameModel`: the tilt modes + these terms, one Kalman engine)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from vibinverse.errors import SceneError
from vibinverse.terms.base import TERMS, TermSum
from vibinverse.terms.drift import GAIN_TERMS, GainDrift
from vibinverse.terms.noise import White

NOISE_KINDS = ("white", "ar1", "1/f")  # white: no coloured term; the others are `TERMS` keys
DRIFT_KINDS = ("none", "walk", "integrated")  # none: no drift; the others are `TERMS` keys
KEYS = ("noise", "drift", "gain", "white", "values", "start")


@dataclass(frozen=True)
class NuisanceSpec:
    """Which nuisance terms: the coloured noise ("white": none, "ar1", "1/f"), the drift ("none",
    "walk", "integrated"), the gain drift's cosines (0: none) and the white sensor noise (False only
    beside a coloured noise, which then is the whole noise)."""

    noise: str = "white"
    drift: str = "none"
    gain: int = 0
    white: bool = True

    def __post_init__(self) -> None:
        if not self.white and self.noise == "white":
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
        if gain is True or gain == "drift":
            gain = GAIN_TERMS
        elif gain is False or gain is None or gain == "none":
            gain = 0
        if isinstance(gain, bool) or not isinstance(gain, (int, np.integer)) or not 0 <= int(gain) <= 24:
            raise SceneError(f"{key}.gain: {m.get('gain')!r}; allowed: false, true ({GAIN_TERMS} cosines) or 0..24")
        white = m.get("white", True)
        if not isinstance(white, (bool, np.bool_)):
            raise SceneError(f"{key}.white: {white!r}; allowed: true, or false beside noise = 'ar1' or '1/f'")
        return cls(noise, drift, int(gain), bool(white))

    def table(self) -> dict[str, Any]:
        """The `nuisance` sub-table of this spec."""
        return {"noise": self.noise, "drift": self.drift, "gain": self.gain, "white": self.white}

    def terms(self, white: bool | None = None) -> TermSum:
        """The terms (the white noise only when `white`, default: the spec's)."""
        out = []
        if self.noise != "white":
            out.append(TERMS[self.noise]())
        if self.drift != "none":
            out.append(TERMS[self.drift]())
        if self.gain:
            out.append(GainDrift(self.gain))
        if self.white if white is None else white:
            out.append(White())
        return TermSum(*out)

    def describe(self) -> str:
        """In words, e.g. "AR(1) noise, random-walk drift, white noise" (each term's `label`)."""
        return ", ".join(t.label for t in self.terms()) or "none"
