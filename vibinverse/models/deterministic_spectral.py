"""Spectral starting values for a deterministic vibration (plate, Rayleigh source): periodogram
peaks for the frequencies, sinusoid fits calibrated through the forward model for amplitudes and
phases. Rough, in milliseconds, and gap-tolerant; the MAP fit refines them.

A line of frequency f shows at f (first order in the tilt) and at 2f (second order). When the
footprint is symmetric the first order cancels and the only peak is at 2f, so the peaks in twice
the frequency prior are tried as 2f too; the posterior decides between the candidates.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from vibinverse.io.series import Series
from vibinverse.models.base import SignalModel
from vibinverse.spectrum import harmonics, line_candidates


def free_name(line_name: str, free: set[str]) -> str | None:
    """The name under which a line's value is free: indexed, or plain for a list's first element."""
    if line_name in free:
        return line_name
    if line_name.endswith("[0]") and line_name[:-3] in free:
        return line_name[:-3]
    return None


def gain_from_level(series: Series, like: SignalModel) -> float:
    """The sun.irradiance that makes the model's mean level the data's (the calibration gain)."""
    rest = float(np.mean(like.mean({line.amplitude: 0.0 for line in like.lines()})))
    return like.scene.sun.irradiance * float(np.nanmean(series.intensity)) / rest if rest > 0 else float("nan")


def response_guesses(
    series: Series, like: SignalModel, bounds: dict[str, tuple[float, float]], n_candidates: int = 3
) -> list[dict[str, float]]:
    """Candidate starting values of the free parameters in `bounds` (names as the fit's), one per
    plausible frequency of the first free line; further lines take their strongest peak."""
    free = set(bounds)
    base: dict[str, float] = {}
    if "sun.irradiance" in free:
        base["sun.irradiance"] = gain_from_level(series, like)
    lines = [
        ln
        for ln in like.lines()
        if free_name(ln.frequency, free) or free_name(ln.amplitude, free) or free_name(ln.phase, free)
    ]
    nyq = 0.5 * series.fs
    firsts: list[float | None] = [None]
    if lines and free_name(lines[0].frequency, free):
        band = bounds[free_name(lines[0].frequency, free)]
        peaks = line_candidates(series, band, n_candidates)
        doubled = (
            line_candidates(series, (2 * band[0], min(2 * band[1], nyq)), n_candidates) if 2 * band[0] < nyq else []
        )
        firsts = list(dict.fromkeys([*peaks, *(p / 2 for p in doubled)]))
    out = []
    for f0 in firsts:
        guess = dict(base)
        for i, line in enumerate(lines):
            f = f0 if i == 0 else None
            _line_guess(series, like, line, bounds, guess, f, nyq)
        if "sun.irradiance" in free:  # the vibration has a mean of its own (its 2f term): refine the gain
            model = like.mean(_as_free(guess, like, free))
            guess["sun.irradiance"] *= float(np.nanmean(series.intensity[np.isfinite(model)]) / np.mean(model))
        if "noise.sigma" in free:
            values = _as_free(guess, like, free)
            resid = series.intensity - like.mean(values)
            guess["noise.sigma"] = float(max(np.nanstd(resid), 1e-300))
        out.append(_as_free(guess, like, free))
    return out


def _line_guess(
    series: Series, like: SignalModel, line: Any, bounds: dict, guess: dict, f: float | None, nyq: float
) -> None:
    """Frequency, amplitude and phase of one line into `guess` (canonical names)."""
    free = set(bounds)
    fname = free_name(line.frequency, free)
    if f is None:
        if fname:
            found = line_candidates(series, bounds[fname], n_candidates=1)
            f = found[0] if found else 0.5 * sum(bounds[fname])
        else:
            f = like.base_value(line.frequency)
    guess[line.frequency] = f
    t, y = series.time, series.intensity
    a_ref = like.base_value(line.amplitude) or 1e-3
    others = {ln.amplitude: 0.0 for ln in like.lines() if ln != line}
    probe = like.mean(
        {
            **_as_free(guess, like, free, keep_all=True),
            **others,
            line.frequency: f,
            line.amplitude: a_ref,
            line.phase: 0.0,
        }
    )
    first, second = harmonics(t, probe, f, nyq)
    data1, data2 = harmonics(t, y, f, nyq)
    if first[0] >= second[0] or second[0] == 0.0:  # first order: x ~ a
        amp = a_ref * data1[0] / max(first[0], 1e-300)
        phase = data1[1] - first[1]
    else:  # the first order cancels: x ~ a^2 at 2f, phase doubled
        amp = a_ref * math.sqrt(data2[0] / max(second[0], 1e-300))
        phase = 0.5 * (data2[1] - second[1])
    guess[line.amplitude] = float(amp)
    guess[line.phase] = float(np.angle(np.exp(1j * phase)))
    pname = free_name(line.phase, free)
    if pname:  # the prior may be any window: start inside it, wrapped by the phase's period (pi
        # for a line seen only at second order), not clipped to the window's edge
        lo, hi = bounds[pname]
        centre, period = 0.5 * (lo + hi), like.phase_period(line.phase)
        guess[line.phase] = float(centre + (guess[line.phase] - centre + period / 2) % period - period / 2)


def _as_free(guess: dict[str, float], like: SignalModel, free: set[str], keep_all: bool = False) -> dict[str, float]:
    """`guess` under the fit's names (plain names for list first elements where the fit uses them);
    keep_all keeps values that are not free (as a probe of the model needs them)."""
    out = {}
    for n, v in guess.items():
        name = free_name(n, free)
        if name:
            out[name] = v
        elif keep_all:
            out[n] = v
    return out
