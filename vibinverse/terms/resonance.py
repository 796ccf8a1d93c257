"""A noise-driven resonance (`Oscillator`): q'' + 2 zeta w q' + w^2 q = xi(t), w = 2 pi f, xi
continuous white noise of intensity kappa = 4 zeta w^3 rms^2 (so that `rms` is q's stationary RMS).
Two states (q, q'), discretized exactly over any step in closed form
(`vibinverse.kalman.oscillator_fill`: the Van Loan matrix exponential's entries, a Taylor series of
the impulse response where they cancel). One-sided PSD 2 kappa / |w^2 - W^2 + 2 i zeta w W|^2,
W = 2 pi f, whose integral is rms^2. A signal term: a gain drift multiplies it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from vibinverse.io.series import MIN_CYCLES
from vibinverse.kalman import oscillator_fill
from vibinverse.priors import Prior
from vibinverse.terms.base import OSCILLATOR_FORM, DataFacts, Term, register_term


@register_term
class Oscillator(Term):
    """A stochastic resonance: `<prefix>.frequency` (Hz), `.damping_ratio`, `.rms` (intensity)."""

    kind = "oscillator"
    label = "resonance"
    scaled = True
    block_form = OSCILLATOR_FORM

    def __init__(self, prefix: str = "modes[0]"):
        self.prefix = prefix

    def names(self) -> list[str]:
        p = self.prefix
        return [f"{p}.frequency", f"{p}.damping_ratio", f"{p}.rms"]

    def blocks(self, facts: DataFacts) -> list[int]:
        return [2]

    def _wa(self, values: Mapping[str, float]) -> tuple[float, float, float]:
        f, zeta, rms = (float(values[n]) for n in self.names())
        w = 2.0 * math.pi * f
        return w, zeta * w, rms

    def form_parameters(self, values: Mapping[str, float], facts: DataFacts) -> list[tuple[float, ...]]:
        return [self._wa(values)]

    def fill(self, values, steps, phis, qs, p0, offset, facts) -> None:
        w, a, rms = self._wa(values)
        kappa = 4.0 * a * w * w * rms * rms
        sub_p = np.zeros((steps.size, 2, 2))
        sub_q = np.zeros((steps.size, 2, 2))
        oscillator_fill(w, a, kappa, np.ascontiguousarray(steps, dtype=np.float64), sub_p, sub_q, 0)
        block = slice(offset, offset + 2)
        phis[:, block, block] = sub_p
        qs[:, block, block] = sub_q
        p0[offset, offset] = rms * rms
        p0[offset + 1, offset + 1] = w * w * rms * rms

    def psd(self, values: Mapping[str, float], f: np.ndarray, facts: DataFacts) -> np.ndarray:
        w, a, rms = self._wa(values)
        kappa = 4.0 * a * w * w * rms * rms
        big_w = 2.0 * math.pi * np.asarray(f, dtype=float)
        return 2.0 * kappa / ((w * w - big_w * big_w) ** 2 + (2.0 * a * big_w) ** 2)

    def slowest_period(self, values: Mapping[str, float]) -> float | None:
        f = float(values[self.names()[0]])
        return 1.0 / f if f > 0 else math.inf

    def valid(self, values: Mapping[str, float]) -> bool:
        f, zeta, rms = (float(values[n]) for n in self.names())
        return all(math.isfinite(v) for v in (f, zeta, rms)) and f > 0.0 and zeta > 0.0 and rms >= 0.0

    def priors(self, facts: DataFacts) -> dict[str, Prior]:
        f, zeta, rms = self.names()
        lo = MIN_CYCLES / facts.span * (1.0 + 1e-9)
        return {
            f: Prior("uniform", (lo, facts.nyquist)),
            zeta: Prior("loguniform", (1e-4, 0.9)),
            rms: Prior("loguniform", (1e-4 * facts.sd, 10.0 * facts.sd)),
        }

    def starts(self, facts: DataFacts) -> dict[str, float]:
        """The strongest peak of the smoothed periodogram, its half-power width and band power."""
        from vibinverse.io.series import Series
        from vibinverse.spectrum import periodogram

        y = facts.intensity - np.nanmean(facts.intensity)
        fr, pw = periodogram(Series(facts.time, y, "terms"))
        width = max(3, len(fr) // 200) | 1
        sm = np.convolve(pw, np.ones(width) / width, "same")
        sm[fr < MIN_CYCLES / facts.span] = 0.0
        i = int(np.argmax(sm))
        lo, hi = i, i
        while lo > 0 and sm[lo] > 0.5 * sm[i]:
            lo -= 1
        while hi < sm.size - 1 and sm[hi] > 0.5 * sm[i]:
            hi += 1
        f0 = float(fr[i])
        zeta = float(np.clip((fr[hi] - fr[lo]) / (2.0 * max(f0, 1e-12)), 2e-3, 0.3))
        f, z, r = self.names()
        return {f: f0, z: zeta, r: float(np.nanstd(y))}

    def units(self, name: str, intensity: str) -> tuple[str, str]:
        last = name.rsplit(".", 1)[-1]
        return {
            "frequency": ("Hz", "resonance frequency"),
            "damping_ratio": ("1", "resonance damping ratio"),
            "rms": (intensity, "resonance stationary RMS"),
        }[last]

    def component(self, values: Mapping[str, float], facts: DataFacts) -> dict[str, Any]:
        f, z, r = self.names()
        return {
            "kind": "mode",
            "frequency": float(values[f]),
            "damping_ratio": float(values[z]),
            "rms": float(values[r]),
        }
