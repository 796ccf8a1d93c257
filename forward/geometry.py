"""Directions, normals from slopes, reflection and well-conditioned angles.

Conventions (DESIGN.md sec. 2): x, y horizontal, z up. *Inclination* is the elevation above
the horizon; *azimuth* is counter-clockwise from +x. All directions point away from the
surface (towards the sun, towards the sensor).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

Z_HAT = np.array([0.0, 0.0, 1.0])


def direction(inclination: ArrayLike, azimuth: ArrayLike) -> NDArray[np.float64]:
    """Unit vector at elevation `inclination` above the horizon and azimuth `azimuth` (rad).

    Shape: broadcast(inclination, azimuth) + (3,).
    """
    inc = np.asarray(inclination, dtype=float)
    az = np.asarray(azimuth, dtype=float)
    c = np.cos(inc)
    return np.stack(np.broadcast_arrays(c * np.cos(az), c * np.sin(az), np.sin(inc)), axis=-1)


def mirror(d: ArrayLike, normal: ArrayLike = Z_HAT) -> NDArray[np.float64]:
    """Specular direction n_r = 2 (n.d) n - d (paper, text under eq. (23))."""
    d = np.asarray(d, dtype=float)
    n = np.asarray(normal, dtype=float)
    return 2.0 * np.sum(n * d, axis=-1, keepdims=True) * n - d


def angle_between(a: ArrayLike, b: ArrayLike) -> NDArray[np.float64]:
    """Angle between unit vectors via atan2(|a x b|, a.b).

    arccos(a.b) loses half the digits for small angles (an angle of 1e-5 rad would carry a
    relative error of ~1e-3); the lobe term depends on exactly such angles.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1))


def normals_from_slopes(gx: ArrayLike, gy: ArrayLike) -> NDArray[np.float64]:
    """Unit normals of a height field z = h(x, y) with slopes (h_x, h_y): (-h_x, -h_y, 1)/norm."""
    gx = np.asarray(gx, dtype=float)
    gy = np.asarray(gy, dtype=float)
    inv = 1.0 / np.sqrt(1.0 + gx * gx + gy * gy)
    return np.stack(np.broadcast_arrays(-gx * inv, -gy * inv, inv), axis=-1)


def unit(v: ArrayLike) -> NDArray[np.float64]:
    """v / |v| along the last axis."""
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)
