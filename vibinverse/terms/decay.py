"""A free decay (`FreeDecay`): a resonance rung by one excitation and left alone (a pluck, a hammer
blow, a struck fork, a ring-down),

    q'' + 2 zeta w q' + w^2 q = 0 after its onset t_e,    q = 0 before,

w = 2 pi f. Two states (q, q'), the oscillator's exact transition (`vibinverse.kalman.oscillator_fill`
with no process noise: kappa = 0), and at the onset a fresh state (q, q'/w) drawn N(0, A^2) each:
the amplitude A (`amplitude`, intensity) is the Rayleigh scale of the ring's initial envelope, its
phase uniform. The Kalman filter integrates the initial state out (its covariance is the prior of
the ring's amplitude and phase), so only f, zeta and A are fitted: as many parameters as a
noise-driven resonance or a line, which it differs from by its envelope (decaying from the onset,
not stationary; nothing before it).

The onset is a sample of the record, held (a blow's arrival is sharp: its time is not a parameter
the intervals carry). The modal model takes it from its table (`modal.onset`, which the order
search sets where the likelihood is highest: `vibinverse.model_order.set_onset`), else from the
data (`excitation_onset`: a rise of the record's variance by ONSET_RISE or more at its most likely
change point, else the first sample).

Its one-sided PSD (`psd`, for Whittle's Fisher information only: a decay is not stationary) is the
record's average: the oscillator's Lorentzian shape carrying the ring's energy over the span,
A^2 (1 - e^{-2 zeta w T}) / (2 zeta w T) for the ring's T seconds after the onset.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from vibinverse.io.series import MIN_CYCLES
from vibinverse.kalman import oscillator_fill
from vibinverse.priors import Prior
from vibinverse.terms.base import FREE_DECAY_FORM, DataFacts, register_term
from vibinverse.terms.resonance import Oscillator

#: a blow: the record's variance, split at its most likely change point, rises at least this
#: many times (the RMS 1.22 times) from before to after ...
ONSET_RISE = 1.5
#: ... and the change gains this much in twice the log-likelihood (white noise's largest rise
#: reaches 11-12 in 1 % of records of 200-20,000 samples, 16-19 in 0.1 %)
ONSET_EVIDENCE = 20.0
#: the blow arrives at the sample before the first near the change point whose excursion exceeds
#: this many times the quiet's RMS (a Gaussian sample's chance of it: 0.3 %)
ONSET_DEPARTURE = 3.0
#: the shortest quiet and ring the change point leaves (a fraction of the record)
ONSET_EDGE = 0.02


def excitation_onset(time: np.ndarray, intensity: np.ndarray) -> int:
    """The sample at which a free decay starts: 0 (the record's start: rung before it) unless the
    record holds a blow. The blow: the record's most likely rise of variance (the split k, s2 > s1,
    that maximizes the two Gaussian segments' likelihood, -k ln s1 - (n - k) ln s2 with s1, s2 the
    mean squares about the median, at least ONSET_EDGE of the record on each side; a ring's own
    fall into the noise is a more likely change, of the other sign) when it gains ONSET_EVIDENCE in
    twice the log-likelihood ratio and the variance after it is at least ONSET_RISE times the
    variance before (the quiet). It arrives at the sample before the
    first within ONSET_EDGE of the change point whose excursion exceeds ONSET_DEPARTURE times the
    quiet's RMS (the state drawn there is free: a sample early costs little, a sample late leaves
    the blow's first swing to the noise)."""
    y = np.asarray(intensity, dtype=float)
    y = np.nan_to_num(y - np.nanmedian(y), nan=0.0)
    n = y.size
    edge = max(8, int(ONSET_EDGE * n))
    if n < 4 * edge:
        return 0
    c = np.concatenate(([0.0], np.cumsum(y * y)))
    k = np.arange(edge, n - edge)
    s1 = np.maximum(c[k] / k, 1e-300)
    s2 = np.maximum((c[n] - c[k]) / (n - k), 1e-300)
    # twice the log-likelihood ratio of a change of variance at k against none, rises only
    gain = np.where(s2 > s1, n * math.log(max(c[n] / n, 1e-300)) - k * np.log(s1) - (n - k) * np.log(s2), -np.inf)
    i = int(np.argmax(gain))
    split, quiet, after = int(k[i]), float(s1[i]), float(s2[i])
    if not (gain[i] >= ONSET_EVIDENCE and after >= ONSET_RISE * quiet):
        return 0
    lo = max(1, split - edge)
    seg = np.abs(y[lo : split + edge])
    over = np.flatnonzero(seg > ONSET_DEPARTURE * math.sqrt(quiet))
    first = lo + int(over[0]) if over.size else split
    return max(first - 1, 1)


def ring_start(prefix: str, f: float, zeta: float, rms: float, ring: float, span: float) -> dict[str, float]:
    """A decay's start from a reading of its peak as a resonance's (f, zeta, the record's RMS
    there): the initial amplitude whose ring of `ring` seconds has that mean square over the
    record's `span` (`FreeDecay.psd`)."""
    a = 2.0 * math.pi * f * zeta
    share = -math.expm1(-2.0 * a * ring) / (2.0 * a * span) if a > 0 and span > 0 else 1.0
    amp = rms / math.sqrt(max(share, 1e-12))
    return {f"{prefix}.frequency": f, f"{prefix}.damping_ratio": zeta, f"{prefix}.amplitude": amp}


def envelope_decay(y: np.ndarray, dt: float, f: float, half_width: float) -> float:
    """The damping ratio an exponential envelope of the series' band f +- half_width Hz has from
    its first third to its last (0 when the band's energy does not fall; the series taken as
    uniform at step dt, gaps as 0): a cheap reading of whether a component decays."""
    x = np.nan_to_num(np.asarray(y, dtype=float) - np.nanmean(y), nan=0.0)
    n = x.size
    if n < 12 or not f > 0:
        return 0.0
    spec = np.fft.rfft(x, 2 * n)  # zero-padded: the ring's start does not wrap onto its end
    spec[np.abs(np.fft.rfftfreq(2 * n, dt) - f) > half_width] = 0.0
    band = np.fft.irfft(spec, 2 * n)[:n]
    third = n // 3
    first, last = float(np.mean(band[:third] ** 2)), float(np.mean(band[-third:] ** 2))
    if not first > last > 0:
        return 0.0 if not first > 0 else 0.5
    # energy ~ e^{-2 a t}, the thirds' centres 2/3 of the span apart
    a = math.log(first / last) / (2.0 * (2.0 / 3.0) * n * dt)
    return float(a / (2.0 * math.pi * f))


@register_term
class FreeDecay(Oscillator):
    """A ring-down from an onset: `<prefix>.frequency` (Hz), `.damping_ratio`, `.amplitude`
    (intensity; the oscillator's third parameter, the scale of its state). `event`: the entry of
    the step tables whose step ends at the onset (its process noise carries the fresh state); None:
    the onset is the first sample (the initial covariance carries it)."""

    kind = "free_decay"
    label = "free decay"
    block_form = FREE_DECAY_FORM

    def __init__(self, prefix: str = "decays[0]", event: int | None = None, ring: float | None = None):
        """`ring`: the seconds from the onset to the record's end (default: the whole span)."""
        super().__init__(prefix)
        self.event = event
        self.ring = ring

    def names(self) -> list[str]:
        p = self.prefix
        return [f"{p}.frequency", f"{p}.damping_ratio", f"{p}.amplitude"]

    def excite(self, values: Mapping[str, float], qs: np.ndarray, p0: np.ndarray, offset: int) -> None:
        """Write the fresh state's covariance A^2 diag(1, w^2) at the onset: into P0 (onset at the
        first sample) or into the event step's process noise, the block's only one."""
        w, _, amp = self._wa(values)
        target = p0 if self.event is None else qs[self.event]
        target[offset, offset] = amp * amp
        target[offset + 1, offset + 1] = w * w * amp * amp

    def fill(self, values, steps, phis, qs, p0, offset, facts) -> None:
        w, a, _ = self._wa(values)
        sub_p = np.zeros((steps.size, 2, 2))
        sub_q = np.zeros((steps.size, 2, 2))
        oscillator_fill(w, a, 0.0, np.ascontiguousarray(steps, dtype=np.float64), sub_p, sub_q, 0)
        block = slice(offset, offset + 2)
        phis[:, block, block] = sub_p
        qs[:, block, block] = 0.0
        self.excite(values, qs, p0, offset)

    def psd(self, values: Mapping[str, float], f: np.ndarray, facts: DataFacts) -> np.ndarray:
        """The record's average PSD (module docstring): the ring's energy over the span, in the
        oscillator's Lorentzian shape."""
        w, a, amp = self._wa(values)
        ring = facts.span if self.ring is None else self.ring
        energy = amp * amp * (-math.expm1(-2.0 * a * ring) / (2.0 * a) if a > 0 else ring)
        mean_square = energy / max(facts.span, facts.dt)
        big_w = 2.0 * math.pi * np.asarray(f, dtype=float)
        shape = 4.0 * a * w * w / ((w * w - big_w * big_w) ** 2 + (2.0 * a * big_w) ** 2)  # unit integral
        return 2.0 * mean_square * shape

    def priors(self, facts: DataFacts) -> dict[str, Prior]:
        f, zeta, amp = self.names()
        lo = MIN_CYCLES / facts.span * (1.0 + 1e-9)
        return {
            f: Prior("uniform", (lo, facts.nyquist)),
            zeta: Prior("loguniform", (1e-5, 0.9)),
            amp: Prior("loguniform", (1e-4 * facts.sd, 30.0 * facts.sd)),
        }

    def units(self, name: str, intensity: str) -> tuple[str, str]:
        last = name.rsplit(".", 1)[-1]
        return {
            "frequency": ("Hz", "free decay frequency"),
            "damping_ratio": ("1", "free decay damping ratio"),
            "amplitude": (intensity, "free decay initial amplitude (Rayleigh scale)"),
        }[last]

    def component(self, values: Mapping[str, float], facts: DataFacts) -> dict[str, Any]:
        f, z, a = (float(values[n]) for n in self.names())
        return {
            "kind": "decay",
            "frequency": f,
            "damping_ratio": z,
            "amplitude": a,
            "decay_time": 1.0 / (2.0 * math.pi * f * z) if f > 0 and z > 0 else math.inf,
        }
