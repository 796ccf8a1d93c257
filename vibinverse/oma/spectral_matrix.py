"""The record's Fourier ordinates and spectral density matrix: what the multi-channel frequency-domain
likelihood (`vibinverse.oma.band_model`) and the band picking read.

The C response channels y_k (k = 0 .. N - 1, step dt) are de-meaned and de-trended (a least-squares
line per channel: a slow drift's end-to-end jump would otherwise leak into every ordinate), and
transformed once,

    Y_j = sqrt(dt / N) sum_k y_k e^{-2 pi i j k / N},   f_j = j / (N dt),  j = 1 .. floor((N - 1) / 2),

so that E[Y_j Y_j^H] -> S(f_j) / 2, S the one-sided cross-spectral density matrix (units^2 / Hz), and
the Y_j are asymptotically independent complex Gaussian vectors (Whittle; Au's Bayesian FFT). The
singular values of a Welch-averaged S(f) (`singular_values`) show the modes as peaks of the first one
(frequency-domain decomposition) and close modes in the second.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy import signal

from vibinverse.errors import DataError
from vibinverse.io.channels import Channels
from vibinverse.io.file_basics import STEADY_RTOL, steady

log = logging.getLogger(__name__)

#: the largest fraction of missing values the frequency-domain fit fills with zeros (the ordinates'
#: scale drops by the kept fraction, which the modal and noise levels absorb; f, zeta and the shapes
#: are unchanged to first order); beyond it the record is refused with a one-line error
MAX_GAP_FRACTION = 0.05


@dataclass(frozen=True)
class Ordinates:
    """Fourier ordinates of the response channels: `freqs` (J,), `y` (J, C) complex, the record's
    length `n` and step `dt`, channel `names`, and what was done to the record (`notes`)."""

    freqs: np.ndarray
    y: np.ndarray
    n: int
    dt: float
    names: tuple[str, ...]
    units: tuple[str | None, ...]
    notes: tuple[str, ...]

    @property
    def resolution(self) -> float:
        """Spacing of the ordinates (Hz): 1 / record length."""
        return 1.0 / (self.n * self.dt)

    def band(self, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray]:
        """(freqs, y) of the ordinates in [lo, hi]."""
        keep = (self.freqs >= lo) & (self.freqs <= hi)
        return self.freqs[keep], self.y[keep]


def responses(channels: Channels) -> Channels:
    """The response channels (measured inputs left out); a one-line DataError when there is none."""
    names = channels.responses
    if not names:
        raise DataError(f"channels {channels.source}: every channel is a measured input; give at least one response")
    return channels.select(list(names))


def check_values(channels: Channels) -> None:
    """One-line DataError when the spectral fit cannot take the channels' values: more than
    MAX_GAP_FRACTION of them missing, or a channel of fewer than 3 (before any work is announced)."""
    good = np.isfinite(np.asarray(channels.values, dtype=float))
    frac = 1.0 - float(good.mean())
    if frac > MAX_GAP_FRACTION:
        worst = channels.names[int(np.argmin(good.mean(axis=0)))]
        raise DataError(
            f"channels {channels.source}: {frac:.1%} of the values are missing (worst: {worst}); the spectral "
            f"fit fills at most {MAX_GAP_FRACTION:.0%} with zeros"
        )
    counts = good.sum(axis=0)
    if np.any(counts < 3):
        raise DataError(
            f"channels {channels.source}: channel {channels.names[int(np.argmin(counts))]} has fewer than 3 values"
        )


def detrended(channels: Channels) -> tuple[np.ndarray, list[str]]:
    """(samples, channels) values less each channel's least-squares line; gaps (NaN) set to 0 after it
    (`MAX_GAP_FRACTION`). Notes say what was filled."""
    check_values(channels)
    v = np.array(channels.values, dtype=float)
    n = v.shape[0]
    notes: list[str] = []
    good = np.isfinite(v)
    frac = 1.0 - float(good.mean())
    k = np.arange(n, dtype=float)
    for c in range(v.shape[1]):
        g = good[:, c]
        slope, icept = np.polyfit(k[g], v[g, c], 1)
        v[:, c] = np.where(g, v[:, c] - (icept + slope * k), 0.0)
        if not np.any(np.abs(v[g, c]) > 1e-14 * max(float(np.max(np.abs(channels.values[g, c]))), 1e-300)):
            raise DataError(
                f"channels {channels.source}: channel {channels.names[c]} is constant (or a straight line): it "
                "carries no signal; leave it out (--channels)"
            )
    if frac > 0:
        notes.append(f"{int((~good).sum())} missing values ({frac:.2%}) filled with zeros after de-trending")
    return v, notes


def step_of(channels: Channels) -> tuple[float, list[str]]:
    """The sample step: uniform stamps' median step, or the mean step of steady stamps (every step
    within `vibinverse.io.file_basics.STEADY_RTOL` of the mean: a logger's or phone's clock), which are
    read on the regular grid (noted); a one-line DataError for irregular stamps."""
    if channels.uniform:
        return channels.dt, []
    t = channels.time
    if not steady(t):
        raise DataError(
            f"channels {channels.source}: the spectral fit needs uniform sampling; the stamps are irregular "
            f"(steps differ from their mean by more than {STEADY_RTOL:.0%}: resample to a regular grid first)"
        )
    dt = float((t[-1] - t[0]) / (t.size - 1))
    return dt, [f"stamps within {STEADY_RTOL:.0%} of their mean step {dt:.6g} s: read on the regular grid"]


def ordinates(channels: Channels) -> Ordinates:
    """The Fourier ordinates of the (uniformly sampled) response channels (module docstring)."""
    dt, grid_note = step_of(channels)
    resp = responses(channels)
    v, notes = detrended(resp)
    notes = notes + grid_note
    n = v.shape[0]
    if n < 16:
        raise DataError(f"channels {channels.source}: {n} samples; the spectral fit needs at least 16")
    spec = np.fft.rfft(v, axis=0) * np.sqrt(dt / n)
    j = np.arange(1, (n - 1) // 2 + 1)
    return Ordinates(
        freqs=j / (n * dt),
        y=np.ascontiguousarray(spec[j]),
        n=n,
        dt=dt,
        names=resp.names,
        units=resp.units,
        notes=tuple(notes),
    )


@dataclass(frozen=True)
class SingularValues:
    """Singular values (descending) of the Welch-averaged spectral density matrix per frequency,
    normalized per channel to unit variance first (so that channels in different units weigh alike),
    with the first singular vector: `freqs` (F,), `values` (F, C), `vectors` (F, C), `segments`."""

    freqs: np.ndarray
    values: np.ndarray
    vectors: np.ndarray
    segments: int


def singular_values(channels: Channels, resolution: float | None = None) -> SingularValues:
    """Welch's spectral density matrix (Hann, half overlap) with segments of at most 1/8 of the
    record, or long enough for `resolution` (Hz), and its singular values per frequency."""
    resp = responses(channels)
    v, _ = detrended(resp)
    v = v / np.maximum(v.std(axis=0), 1e-300)
    n, fs = v.shape[0], 1.0 / step_of(channels)[0]
    nper = max(16, n // 8)
    if resolution is not None and resolution > 0:
        nper = min(nper, max(16, int(2 ** np.ceil(np.log2(fs / resolution)))))
    nper = min(nper, n)
    f, sxy = signal.csd(v[:, None, :], v[:, :, None], fs=fs, nperseg=nper, axis=0)  # (F, C, C)
    u, s, _ = np.linalg.svd(sxy)
    segments = max(1, int(2 * n // nper - 1))
    keep = f > 0
    return SingularValues(f[keep], s[keep].real, np.abs(u[keep, :, 0]), segments)
