"""Multi-channel records with known modes: each mode an exactly discretized white-noise-driven
resonance (the Oscillator term's (Phi, Q)), seen on every channel through its shape, plus white
sensor noise."""

from __future__ import annotations

import numpy as np

from vibinverse.io.channels import Channels
from vibinverse.kalman import oscillator_fill


def modal_record(
    modes: tuple[tuple[float, float], ...],
    shapes: np.ndarray,
    fs: float = 50.0,
    duration: float = 600.0,
    noise: float = 0.1,
    seed: int = 0,
) -> Channels:
    """`modes` (f Hz, zeta) with unit-rms modal displacement, `shapes` (modes, channels); white noise of
    `noise` x each channel's sd."""
    rng = np.random.default_rng(seed)
    n, dt = int(duration * fs), 1.0 / fs
    y = np.zeros((n, shapes.shape[1]))
    for (f, zeta), v in zip(modes, shapes, strict=True):
        w = 2 * np.pi * f
        phi, q = np.zeros((1, 2, 2)), np.zeros((1, 2, 2))
        oscillator_fill(w, zeta * w, 4 * zeta * w**3, np.array([dt]), phi, q, 0)
        e = rng.normal(size=(n, 2)) @ np.linalg.cholesky(q[0]).T
        x, xs = rng.normal(size=2) * [1.0, w], np.empty(n)
        p = phi[0]
        for k in range(n):
            x = p @ x + e[k]
            xs[k] = x[0]
        y += np.outer(xs, v)
    y += noise * rng.normal(size=y.shape) * y.std(axis=0)
    names = tuple(f"c{i}" for i in range(y.shape[1]))
    return Channels(np.arange(n) * dt, y, names, ("m",) * len(names), "simulated")
