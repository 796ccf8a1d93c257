"""Modes driven by a measured force: the simulated truth of input-output modal identification
(an impact hammer, a shaker's load cell).

Each mode k of natural frequency f_k (Hz) and damping ratio zeta_k moves its modal coordinate

    q_k'' + 2 zeta_k w_k q_k' + w_k^2 q_k = p(t),    w_k = 2 pi f_k,

under the one force p(t) (N), and channel c reads y_c = sum_k a_kc q_k (displacement; the residue
a_kc is the mode's shape at the sensor times its participation at the input), so that in the
frequency domain Y_c(W) = sum_k a_kc H_k(W) P(W) with H_k(W) = 1 / (w_k^2 - W^2 + 2 i zeta_k w_k W).

A measurement samples a band-limited force: a data-acquisition system low-passes every channel
below its Nyquist frequency before it samples. The simulation does the same: a white force is
simulated `oversample` times faster than the record's rate, low-passed (zero-phase FIR) below
`cutoff` times the record's rate, each mode's response to it discretized by a first-order hold at
the fast rate (piecewise-linear force between the fast samples: near exact for a force this
smooth), and both the force and the responses are then read every `oversample`-th sample. Between
the samples the force has no power above the record's Nyquist frequency, so the sampled records obey
Y = H P at every DFT frequency up to the record ends' transients (what a real measurement obeys; a
first-order hold at the record's own rate would not: its force has aliased images).

Sensor noise: white, `noise` times each response channel's standard deviation.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import signal

from forward.errors import SceneError

START_UP = 4000  # fast samples dropped at the start: the filter's and the modes' start-up


def forced_modes(
    modes: Sequence[tuple[float, float]],
    residues: ArrayLike,
    *,
    fs: float,
    duration: float,
    noise: float = 0.05,
    seed: int = 0,
    oversample: int = 8,
    cutoff: float = 0.4,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """(time (N,), force (N,), responses (N, C)) of `modes` ((f, zeta) each) with `residues`
    (modes x channels) driven by a band-limited white force (module docstring)."""
    a = np.atleast_2d(np.asarray(residues, dtype=float))
    if a.shape[0] != len(modes):
        raise SceneError(f"residues: {a.shape[0]} rows for {len(modes)} modes; need one row a mode")
    if not 0.0 < cutoff < 0.5:
        raise SceneError(f"cutoff: {cutoff!r}; allowed: (0, 0.5) times the sampling rate")
    nyquist = 0.5 * fs
    for f, zeta in modes:
        if not (0.0 < f < nyquist and 0.0 < zeta < 1.0):
            raise SceneError(f"modes: ({f!r}, {zeta!r}); allowed: 0 < f < {nyquist:g} Hz, 0 < zeta < 1")
    rng = np.random.default_rng(seed)
    fast = fs * oversample
    n = round(fs * duration)
    total = n * oversample + START_UP
    taps = signal.firwin(100 * oversample + 1, cutoff * fs, fs=fast)
    force = signal.filtfilt(taps, [1.0], rng.normal(size=total))
    y = np.zeros((total, a.shape[1]))
    for (f, zeta), row in zip(modes, a, strict=True):
        w = 2.0 * math.pi * f
        num, den, _ = signal.cont2discrete(([1.0], [1.0, 2.0 * zeta * w, w * w]), 1.0 / fast, method="foh")
        y += np.outer(signal.lfilter(np.ravel(num), den, force), row)
    keep = slice(START_UP, START_UP + n * oversample, oversample)
    force, y = force[keep], y[keep]
    y = y + noise * y.std(axis=0) * rng.normal(size=y.shape)
    return np.arange(n) / fs, force, y
