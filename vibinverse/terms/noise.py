"""Noise terms: white sensor noise, AR(1) (Ornstein-Uhlenbeck) noise and 1/f (flicker) noise.

- `White` (`noise.sigma`): independent N(0, sigma^2) on every sample, the measurement noise r of
  the state-space model; its one-sided PSD is 2 sigma^2 dt, flat to Nyquist.
- `AR1` (`ar.rms`, `ar.time`): one Ornstein-Uhlenbeck state of stationary variance rms^2 and
  correlation time tau; exactly Phi = e^{-dt/tau}, Q = rms^2 (1 - e^{-2 dt/tau}) over a step dt (an
  AR(1) with phi = e^{-dt/tau} on a uniform grid); PSD 4 rms^2 tau / (1 + (2 pi f tau)^2).
- `Flicker` (`flicker.rms`, `flicker.corner`): K Ornstein-Uhlenbeck states of equal variance
  rms^2 / K, their corners spread evenly in log frequency from one cycle per record to `corner`
  (Hz; `flicker_times`), K one for each decade from one cycle per record to Nyquist
  (`flicker_terms`): a spectrum ~ 1/f between those, ~ 1/f^2 above.

AR(1) and 1/f noise are `ColouredNoise`: each also says where the modal model's order search
(`vibinverse.model_order`) starts it, beside white noise or in another coloured noise's place.
"""

from __future__ import annotations

import math
from abc import abstractmethod
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from vibinverse.priors import Prior
from vibinverse.terms.base import OU_FORM, DataFacts, Term, register_term

FLICKER_MIN_TERMS = 3  # the 1/f term's fewest Ornstein-Uhlenbeck states (`flicker_terms`)
FLICKER_LOWEST_CORNER = 10.0  # cycles per record: the 1/f term's upper corner's prior starts here


def flicker_terms(span: float, dt: float) -> int:
    """The 1/f term's number of Ornstein-Uhlenbeck states: one for each decade from one cycle per
    record up to the Nyquist frequency (1, 10, 100, ... cycles per record below span / 2 dt), at
    least `FLICKER_MIN_TERMS`. A 20 s record at 200 Hz (Nyquist 2000 cycles per record): 4."""
    nyquist_cycles = max(span, dt) / (2.0 * dt)
    return max(FLICKER_MIN_TERMS, math.floor(math.log10(max(nyquist_cycles, 1.0)) + 1e-9) + 1)


def flicker_times(span: float, corner: float, terms: int) -> list[float]:
    """The 1/f term's correlation times (s), 1 / (2 pi f_k): `terms` corners f_k spread evenly in
    log frequency from one cycle per record (1 / span) to `corner` (Hz). Scalars: it runs in every
    likelihood call (np.geomspace took ~10 us of it)."""
    ratio = (corner * span) ** (1.0 / max(terms - 1, 1))
    return [span / (2.0 * math.pi * ratio**k) for k in range(terms)]


def ou_fill(tau: float, var: float, steps: np.ndarray, phis: np.ndarray, qs: np.ndarray, o: int) -> None:
    """The exact (Phi, Q) of an Ornstein-Uhlenbeck state (time tau, stationary variance var) over
    each step, at state o."""
    phis[:, o, o] = np.exp(-steps / tau)
    qs[:, o, o] = -var * np.expm1(-2.0 * steps / tau)


def ou_psd(tau: float, var: float, f: np.ndarray) -> np.ndarray:
    """One-sided PSD of an Ornstein-Uhlenbeck process: 4 var tau / (1 + (2 pi f tau)^2)."""
    return 4.0 * var * tau / (1.0 + (2.0 * math.pi * np.asarray(f) * tau) ** 2)


def _white_rest(sigma: float, share: float) -> float:
    """The white noise's sd when a coloured noise takes `share` of a noise of sd `sigma` (at least
    5 % of its variance left)."""
    return sigma * math.sqrt(max(1 - share * share, 0.05))


@register_term
class White(Term):
    """White sensor noise of standard deviation `noise.sigma` (the measurement noise)."""

    kind = "white"
    label = "white noise"

    def names(self) -> list[str]:
        return ["noise.sigma"]

    def measurement_variance(self, values: Mapping[str, float]) -> float:
        return float(values["noise.sigma"]) ** 2

    def psd(self, values: Mapping[str, float], f: np.ndarray, facts: DataFacts) -> np.ndarray:
        return np.full(np.shape(f), 2.0 * float(values["noise.sigma"]) ** 2 * facts.dt)

    def priors(self, facts: DataFacts) -> dict[str, Prior]:
        return {"noise.sigma": Prior("loguniform", (1e-6 * facts.sd, 10.0 * facts.sd))}

    def starts(self, facts: DataFacts) -> dict[str, float]:
        """sigma from second differences, which white noise dominates (var(d2) = 6 sigma^2)."""
        d2 = np.diff(facts.intensity, 2)
        return {"noise.sigma": float(max(np.nanstd(d2) / math.sqrt(6.0), 1e-6 * facts.sd))}

    def units(self, name: str, intensity: str) -> tuple[str, str]:
        return intensity, "sensor noise standard deviation"

    def component(self, values: Mapping[str, float], facts: DataFacts) -> dict[str, Any]:
        return {"kind": "white noise", "sigma": float(values["noise.sigma"])}


class ColouredNoise(Term):
    """A coloured sensor noise, of stationary RMS `rms_name`; it also says where the order search
    (`vibinverse.model_order`) starts it."""

    rms_name: ClassVar[str]
    block_form = OU_FORM

    @abstractmethod
    def correlation_time(self, values: Mapping[str, float]) -> float:
        """Its (shortest) correlation time (s) at `values`."""

    @abstractmethod
    def screen_starts(self, sigma: float, dt: float, span: float) -> list[dict[str, float]]:
        """Its values, and the white noise's sd, on a grid to screen when it joins white noise of sd
        `sigma` (samples `dt` s apart over `span` s): it takes a share of that noise."""

    @abstractmethod
    def replacing(self, old: ColouredNoise, values: Mapping[str, float], dt: float) -> list[dict[str, float]]:
        """Starts in the place of the coloured noise `old`: `values` (which hold `old`'s) with its
        own values added (samples `dt` s apart)."""


@register_term
class AR1(ColouredNoise):
    """AR(1) noise: one Ornstein-Uhlenbeck state (`ar.rms`, `ar.time`)."""

    kind = "ar1"
    label = "AR(1) noise"
    rms_name = "ar.rms"

    def names(self) -> list[str]:
        return ["ar.rms", "ar.time"]

    def blocks(self, facts: DataFacts) -> list[int]:
        return [1]

    def form_parameters(self, values: Mapping[str, float], facts: DataFacts) -> list[tuple[float, ...]]:
        return [(float(values["ar.time"]), float(values["ar.rms"]) ** 2)]

    def correlation_time(self, values: Mapping[str, float]) -> float:
        return float(values["ar.time"])

    def screen_starts(self, sigma: float, dt: float, span: float) -> list[dict[str, float]]:
        """Shares 0.3 and 0.9 of the noise, correlation times of 2, 10 and 50 samples."""
        return [
            {"ar.rms": c * sigma, "ar.time": tau * dt, "noise.sigma": _white_rest(sigma, c)}
            for tau in (2.0, 10.0, 50.0)
            for c in (0.3, 0.9)
        ]

    def replacing(self, old: ColouredNoise, values: Mapping[str, float], dt: float) -> list[dict[str, float]]:
        """`old`'s rms, correlation times of 3 and 30 samples."""
        return [{**values, "ar.rms": values[old.rms_name], "ar.time": tau * dt} for tau in (3.0, 30.0)]

    def fill(self, values, steps, phis, qs, p0, offset, facts) -> None:
        var = float(values["ar.rms"]) ** 2
        ou_fill(float(values["ar.time"]), var, steps, phis, qs, offset)
        p0[offset, offset] = var

    def psd(self, values: Mapping[str, float], f: np.ndarray, facts: DataFacts) -> np.ndarray:
        return ou_psd(float(values["ar.time"]), float(values["ar.rms"]) ** 2, f)

    def valid(self, values: Mapping[str, float]) -> bool:
        return super().valid(values) and values["ar.time"] > 0.0

    def priors(self, facts: DataFacts) -> dict[str, Prior]:
        return {
            "ar.rms": Prior("loguniform", (1e-6 * facts.sd, 10.0 * facts.sd)),
            "ar.time": Prior("loguniform", (facts.dt / 5.0, facts.span)),
        }

    def starts(self, facts: DataFacts) -> dict[str, float]:
        return {"ar.rms": 0.5 * facts.sd, "ar.time": 10.0 * facts.dt}

    def units(self, name: str, intensity: str) -> tuple[str, str]:
        return (intensity, "AR(1) noise stationary RMS") if name == "ar.rms" else ("s", "AR(1) correlation time")

    def component(self, values: Mapping[str, float], facts: DataFacts) -> dict[str, Any]:
        return {
            "kind": "coloured noise",
            "model": "ar1",
            "rms": float(values["ar.rms"]),
            "time": float(values["ar.time"]),
        }


@register_term
class Flicker(ColouredNoise):
    """1/f noise: Ornstein-Uhlenbeck states spread in log frequency (`flicker.rms`, `flicker.corner`)."""

    kind = "1/f"
    label = "1/f noise"
    rms_name = "flicker.rms"

    def names(self) -> list[str]:
        return ["flicker.rms", "flicker.corner"]

    def blocks(self, facts: DataFacts) -> list[int]:
        return [1] * flicker_terms(facts.span, facts.dt)

    def _states(self, values: Mapping[str, float], facts: DataFacts) -> tuple[list[float], float]:
        k = flicker_terms(facts.span, facts.dt)
        return flicker_times(facts.span, float(values["flicker.corner"]), k), float(values["flicker.rms"]) ** 2 / k

    def form_parameters(self, values: Mapping[str, float], facts: DataFacts) -> list[tuple[float, ...]]:
        times, var = self._states(values, facts)
        return [(tau, var) for tau in times]

    def correlation_time(self, values: Mapping[str, float]) -> float:
        """That of its fastest state, at the upper corner: 1 / (2 pi corner)."""
        return 1.0 / (2.0 * math.pi * float(values["flicker.corner"]))

    def screen_starts(self, sigma: float, dt: float, span: float) -> list[dict[str, float]]:
        """Shares 0.1, 0.3 and 0.9 of the noise, upper corners at 1, 0.2 and 0.04 of Nyquist (at
        least its prior's lowest, FLICKER_LOWEST_CORNER cycles per record)."""
        nyq = 0.5 / dt
        return [
            {
                "flicker.rms": c * sigma,
                "flicker.corner": max(corner * nyq, FLICKER_LOWEST_CORNER / span),
                "noise.sigma": _white_rest(sigma, c),
            }
            for corner in (1.0, 0.2, 0.04)
            for c in (0.1, 0.3, 0.9)
        ]

    def replacing(self, old: ColouredNoise, values: Mapping[str, float], dt: float) -> list[dict[str, float]]:
        """`old`'s rms, the upper corner at Nyquist and at `old`'s correlation time's corner."""
        corners = (0.5 / dt, 1.0 / (2.0 * math.pi * old.correlation_time(values)))
        return [{**values, "flicker.rms": values[old.rms_name], "flicker.corner": c} for c in corners]

    def fill(self, values, steps, phis, qs, p0, offset, facts) -> None:
        times, var = self._states(values, facts)
        for i, tau in enumerate(times):
            ou_fill(tau, var, steps, phis, qs, offset + i)
            p0[offset + i, offset + i] = var

    def psd(self, values: Mapping[str, float], f: np.ndarray, facts: DataFacts) -> np.ndarray:
        times, var = self._states(values, facts)
        return sum(ou_psd(tau, var, f) for tau in times)

    def valid(self, values: Mapping[str, float]) -> bool:
        return super().valid(values) and values["flicker.corner"] > 0.0

    def priors(self, facts: DataFacts) -> dict[str, Prior]:
        lowest = min(FLICKER_LOWEST_CORNER / facts.span, 0.1 * facts.nyquist)
        return {
            "flicker.rms": Prior("loguniform", (1e-6 * facts.sd, 10.0 * facts.sd)),
            "flicker.corner": Prior("loguniform", (lowest, facts.nyquist)),
        }

    def starts(self, facts: DataFacts) -> dict[str, float]:
        return {"flicker.rms": 0.3 * facts.sd, "flicker.corner": 0.5 * facts.nyquist}

    def units(self, name: str, intensity: str) -> tuple[str, str]:
        if name == "flicker.rms":
            return intensity, "1/f noise stationary RMS"
        return "Hz", "1/f noise upper corner frequency"

    def component(self, values: Mapping[str, float], facts: DataFacts) -> dict[str, Any]:
        return {
            "kind": "coloured noise",
            "model": "1/f",
            "rms": float(values["flicker.rms"]),
            "corner": float(values["flicker.corner"]),
        }
