"""BRDF terms: Lambertian (5) and the specular lobe (6)/(23) with an energy-conserving C(m).

All functions return B = f * cos(theta_i), the radiance per unit solar irradiance (1/sr) that the
paper's eq. (23) calls B, so that the pixel signal (22) is the footprint average of B.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline

SUN_ANGULAR_RADIUS = 0.00465  # rad; the floor for a lobe width that the sun's disc sets
_LOBE_SUPPORT = 12.0  # exp(-alpha^2 / 2 m^2) < 1e-31 beyond 12 m


def lambertian(cos_i: ArrayLike, albedo: float) -> NDArray[np.float64]:
    """B = (albedo / pi) cos(theta_i): eq. (5) with R_d = albedo / pi (energy conserving).

    The view direction does not enter (DESIGN.md sec. 3). Zero where the sun is below the facet.
    """
    c = np.asarray(cos_i, dtype=float)
    return np.where(c > 0.0, albedo / np.pi * c, 0.0)


def lobe_solid_angle(m: float, theta_i: ArrayLike) -> NDArray[np.float64]:
    """I(m, theta_i) = integral over the outgoing hemisphere of exp(-alpha^2 / 2 m^2) d omega.

    alpha is measured from the mirror direction, which makes angle theta_i with the facet normal.
    Around the mirror direction, at cone angle alpha the azimuths above the facet's horizon
    span 2 arccos(-cot(theta_i) cot(alpha)), so I is a 1-D integral: 2 pi over the cones entirely
    above the horizon, the clipped azimuth span over those the horizon cuts. Each part by a fixed
    Gauss-Legendre rule for all theta_i at once; the cut part after a = lo + (hi - lo)(1 - cos u)/2,
    which smooths the square-root behaviour of the span where a cone starts or stops touching the
    horizon (within 1e-12 of adaptive quadrature, a test checks; for small m far from grazing
    I -> 2 pi m^2).
    """
    th = np.atleast_1d(np.asarray(theta_i, dtype=float)).ravel()[:, None]
    top = min(np.pi, _LOBE_SUPPORT * m)
    # cone angles: [0, above] entirely above the horizon, [below, cut] cut by it, and (a mirror
    # direction below the horizon, theta_i > pi / 2) [back, top] around the antipode above it again
    above = np.minimum(np.maximum(np.pi / 2 - th, 0.0), top)
    below = np.maximum(above, th - np.pi / 2)
    back = np.minimum(1.5 * np.pi - th, top)
    cut = np.minimum(np.minimum(np.pi / 2 + th, top), back)
    val = _whole_cones(m, 0.0, above) + _whole_cones(m, np.maximum(back, below), top)
    touched = cut[:, 0] > below[:, 0]
    if np.any(touched):
        x, w = _GAUSS_LEGENDRE
        lo, hi = below[touched], cut[touched]
        u = 0.5 * np.pi * (x + 1.0)
        a = lo + 0.5 * (hi - lo) * (1.0 - np.cos(u))
        da = 0.5 * (hi - lo) * np.sin(u) * (0.5 * np.pi)
        t = th[touched]
        c = -np.cos(t) / np.sin(t) * np.cos(a) / np.sin(a)
        span = 2.0 * np.arccos(np.clip(c, -1.0, 1.0))
        val[touched] += (np.exp(-0.5 * (a / m) ** 2) * np.sin(a) * span * da) @ w
    return val.reshape(np.shape(theta_i))


def _whole_cones(m: float, lo: ArrayLike, hi: ArrayLike) -> NDArray[np.float64]:
    """2 pi x the integral of exp(-a^2 / 2 m^2) sin(a) over [lo, hi] (columns), 0 where hi <= lo."""
    x, w = _GAUSS_LEGENDRE
    lo, hi = np.broadcast_arrays(np.asarray(lo, dtype=float), np.asarray(hi, dtype=float))
    width = np.maximum(hi - lo, 0.0)
    a = lo + 0.5 * width * (x + 1.0)
    return np.pi * width[:, 0] * ((np.exp(-0.5 * (a / m) ** 2) * np.sin(a)) @ w)


# nodes and weights on [-1, 1] of the rules in `lobe_solid_angle` (200 points: 1e-12 of quad)
_GAUSS_LEGENDRE = np.polynomial.legendre.leggauss(200)


@lru_cache(maxsize=64)
def _normalization_table(m: float) -> tuple[CubicSpline, float]:
    """Spline of C over s = (pi/2 - theta_i) / m on [0, s_max]; constant beyond s_max."""
    s_max = min(_LOBE_SUPPORT + 1.0, (np.pi / 2) / m)
    s = np.linspace(0.0, s_max, 321)
    c = 1.0 / lobe_solid_angle(m, np.pi / 2 - s * m)
    return CubicSpline(s, c), float(c[-1])


def lobe_normalization(m: float, theta_i: ArrayLike) -> NDArray[np.float64]:
    """C(m, theta_i) = 1 / I(m, theta_i): makes the lobe's directional-hemispherical reflectance
    equal R(theta_i) (eqs. (6)/(23), DESIGN.md sec. 3). ~1 / (2 pi m^2) away from grazing;
    larger at grazing, where the horizon clips the lobe. Interpolated from a cached table
    (relative error < 1e-6)."""
    spline, far = _normalization_table(float(m))
    s = (np.pi / 2 - np.asarray(theta_i, dtype=float)) / m
    return np.where(s >= spline.x[-1], far, spline(np.clip(s, 0.0, spline.x[-1])))


def specular_lobe(
    cos_i: ArrayLike, cos_v: ArrayLike, alpha: ArrayLike, reflectance: ArrayLike, m: float, theta_i: ArrayLike
) -> NDArray[np.float64]:
    """B = cos_i R(theta_i) C(m, theta_i) exp(-alpha^2 / 2 m^2) / cos_v, eq. (23).

    alpha: angle between the mirror direction and the view; m: lobe width (RMS slope, rad).
    Zero where cos_i or cos_v is not positive (the paper's "B = 0 otherwise").
    """
    cos_i = np.asarray(cos_i, dtype=float)
    cos_v = np.asarray(cos_v, dtype=float)
    lit = (cos_i > 0.0) & (cos_v > 0.0)
    safe_v = np.where(lit, cos_v, 1.0)
    a = np.asarray(alpha, dtype=float) / m
    b = cos_i * reflectance * lobe_normalization(m, theta_i) * np.exp(-0.5 * a * a) / safe_v
    return np.where(lit, b, 0.0)
