"""The pixel signal x(t) (eq. (22)) and its sensitivity (eq. (21)), by dense evaluation.

Every footprint subpixel is evaluated at every sample, except static surfaces (and the
background), whose constant contribution is evaluated once: that is exact. This is the reference
that faster evaluations are checked against.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from forward.geometry import normals_from_slopes
from forward.radiance import facet_signal
from forward.scene import Scene

_CHUNK_ELEMENTS = 1 << 21  # facets per vectorized block (~16 MB per temporary)


def pixel_signal(
    scene: Scene, t: ArrayLike | None = None, seed: int | np.random.SeedSequence | None = None
) -> NDArray[np.float64]:
    """Noise-free x(t) = (1/N) sum_k B_k w_k over the N footprint subpixels, eq. (22), times irradiance.

    `t` defaults to the scene's sampling times; `seed` fixes the realization of random motions
    (e.g. the frame's white-noise forcing), one independent stream per surface.
    """
    t = scene.sampling.times() if t is None else np.asarray(t, dtype=float)
    motions = scene.realize_motions(t, seed)
    x, y = scene.footprint.subpixels()
    owner = scene.owners(x, y)
    sun = scene.sun.direction
    total = np.zeros(t.shape)
    flat = np.array([0.0, 0.0, 1.0])
    for k, surface in enumerate((*scene.surfaces, scene.background)):
        idx = np.flatnonzero(owner == (k if k < len(scene.surfaces) else -1))
        if idx.size == 0:
            continue
        if surface.motion is None:
            total += idx.size * float(facet_signal(flat, surface, sun, scene.sensor))
            continue
        motion = motions[k]
        xs, ys = x[idx], y[idx]
        step = max(1, _CHUNK_ELEMENTS // idx.size)
        for a in range(0, t.size, step):
            gx, gy = motion.slopes(xs, ys, t[a : a + step])
            total[a : a + step] += facet_signal(normals_from_slopes(gx, gy), surface, sun, scene.sensor).sum(axis=1)
    return scene.sun.irradiance * total / x.size


def sensitivity(signal: ArrayLike) -> float:
    """S = (max x - min x) / max x, eq. (21); NaN samples (gaps) are ignored.

    Raises ValueError for a signal that is all gaps or whose maximum is not positive (S undefined).
    """
    s = np.asarray(signal, dtype=float)
    finite = s[np.isfinite(s)]
    if finite.size == 0:
        raise ValueError("sensitivity: the signal has no finite samples")
    top = finite.max()
    if top <= 0.0:
        raise ValueError(f"sensitivity: undefined for a signal whose maximum is {top:g} (must be > 0)")
    return float((top - finite.min()) / top)
