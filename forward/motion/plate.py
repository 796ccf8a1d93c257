"""Quasi-static elastic substructure (paper sec. 2.2.1, eqs. (7)-(10)).

Below ~1 kHz the wave equation (7) reduces to the Poisson problem (8)/(10):
    laplacian(u) = -q cos(omega t + phase),  u = 0 on the rectangle's edge,
so u(x, y, t) = q w(x, y) cos(omega t + phase), where w solves laplacian(w) = -1 with w = 0 on
the edge. Cases (8) and (10) differ only in q.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from forward.errors import SceneError
from forward.motion.base import ModalMotion
from forward.validation import Table

_N_TERMS = 20000  # odd terms; slope truncation error on the edge itself <= 0.3 / N_TERMS of max|grad w|


def poisson_shape(
    x: NDArray[np.float64], y: NDArray[np.float64], lx: float, ly: float, n_terms: int = _N_TERMS
) -> tuple[NDArray[np.float64], ...]:
    """(w, w_x, w_y) for laplacian(w) = -1 on [0, lx] x [0, ly], w = 0 on the edge.

    Levy's single series, exact: w = x (a - x) / 2 - sum_{m odd} 4 a^2 / (pi m)^3 sin(k x)
    cosh(k (y - b/2)) / cosh(k b / 2), k = m pi / a, with a the shorter side (the series then
    converges fastest). The series of w converges like m^-3 and of the slopes like m^-2 (only
    on the edge itself; exponentially inside). The hyperbolic ratios are formed as exponentials
    of non-positive numbers, so nothing overflows. Points on a tensor grid cost O((nx + ny) M).
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if ly < lx:  # solve on the transposed rectangle, whose x side is the short one
        w, wy, wx = poisson_shape(y, x, ly, lx, n_terms)
        return w, wx, wy
    a, b = lx, ly
    ux, ix = np.unique(x, return_inverse=True)
    uy, iy = np.unique(y, return_inverse=True)
    n_terms = min(n_terms, _terms_needed(a, float(np.min(np.minimum(uy, b - uy)))))
    m = 2.0 * np.arange(n_terms) + 1.0
    k = m * np.pi / a
    coef = 4.0 * a * a / (np.pi * m) ** 3
    sin_x = np.sin(np.outer(ux, k))
    cos_x = np.cos(np.outer(ux, k)) * k
    d = np.abs(uy - b / 2)[:, None]
    den = 1.0 + np.exp(-k * b)
    e1 = np.exp(k * (d - b / 2))  # cosh(k d) / cosh(k b/2) = (e1 + e2) / den
    e2 = np.exp(-k * (d + b / 2))
    ch = (e1 + e2) / den * coef
    sh = np.sign(uy - b / 2)[:, None] * (e1 - e2) / den * coef * k
    w = (ux * (a - ux) / 2)[:, None] - sin_x @ ch.T
    wx = (a / 2 - ux)[:, None] - cos_x @ ch.T
    wy = -(sin_x @ sh.T)
    return w[ix, iy], wx[ix, iy], wy[ix, iy]


def _terms_needed(a: float, edge_distance: float) -> int:
    """Odd terms after which the slope series is below 1e-16 of its first term at points no
    closer than `edge_distance` to the edges y = 0, b: term m ~ m^-2 exp(-m pi d / a)."""
    if edge_distance <= 0:
        return _N_TERMS
    m = 40.0 * a / (np.pi * edge_distance)  # exp(-40) ~ 4e-18
    return int(min(_N_TERMS, max(64, m / 2 + 1)))


def center_value(lx: float, ly: float) -> float:
    """w at the centre of the rectangle (0.07367 a^2 for a square of side a)."""
    return float(poisson_shape(np.array([lx / 2]), np.array([ly / 2]), lx, ly)[0][0])


class PlateMotion(ModalMotion):
    """u = q w(x - x0, y - y0) cos(2 pi f t + phase) on the rectangle [x0, x1] x [y0, y1].

    q (1/m) is the right-hand side of (8)/(10); use the constructors for the paper's cases.
    """

    def __init__(
        self, x_range: tuple[float, float], y_range: tuple[float, float], frequency: float, q: float, phase: float = 0.0
    ):
        self.x0, self.x1 = map(float, x_range)
        self.y0, self.y1 = map(float, y_range)
        self.frequency = float(frequency)
        self.q = float(q)
        self.phase = float(phase)

    @staticmethod
    def q_acoustic(pressure: float, thickness: float, shear_modulus: float) -> float:
        """q = p0 / (delta G), eq. (8): acoustic pressure p0 (Pa) on a sheet of thickness delta (m)."""
        return pressure / (thickness * shear_modulus)

    @staticmethod
    def q_boundary(frequency: float, density: float, boundary_amplitude: float, shear_modulus: float) -> float:
        """q = omega^2 rho A0 / G, eq. (10): the frame moves by A0 (m) at omega = 2 pi f."""
        return (2 * np.pi * frequency) ** 2 * density * boundary_amplitude / shear_modulus

    def q_for_center_deflection(self, deflection: float) -> float:
        """q that gives a centre deflection `deflection` (m)."""
        return deflection / center_value(self.x1 - self.x0, self.y1 - self.y0)

    def displacement_shape(self, x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
        """q w(x, y): the displacement amplitude (m); zero outside the rectangle."""
        return self._shape(x, y)[0]

    def shapes(self, x, y):
        """Slopes of w (q = 1): the amplitude q lives in the modal coordinate, so that the shape
        is shared by every amplitude (a fit varies q without recomputing the series)."""
        _, sx, sy = self._shape(x, y, 1.0)
        return np.stack([sx, sy])[None]

    def shape_key(self) -> tuple:
        return ("plate", self.x0, self.x1, self.y0, self.y1)

    def coefficients(self, t):
        return self.q * np.cos(2 * np.pi * self.frequency * np.asarray(t, dtype=float) + self.phase)[:, None]

    def max_frequency(self) -> float:
        return self.frequency

    def _shape(self, x, y, q: float | None = None):
        q = self.q if q is None else q
        x = np.asarray(x, dtype=float)
        y = np.asarray(y, dtype=float)
        inside = (x >= self.x0) & (x <= self.x1) & (y >= self.y0) & (y <= self.y1)
        out = [np.zeros(x.shape) for _ in range(3)]
        if inside.any():
            vals = poisson_shape(x[inside] - self.x0, y[inside] - self.y0, self.x1 - self.x0, self.y1 - self.y0)
            for o, v in zip(out, vals):
                o[inside] = q * v
        return tuple(out)

    @classmethod
    def from_table(cls, t: Table, x_range: tuple[float, float], y_range: tuple[float, float]) -> PlateMotion:
        """From a scene table: frequency (Hz), phase (rad), and one amplitude group:
        center_deflection (m) | pressure (Pa), thickness (m), shear_modulus (Pa) [eq. (8)] |
        boundary_amplitude (m), density (kg/m^3), shear_modulus (Pa) [eq. (10)]."""
        f = t.number("frequency", lo=0.0, lo_open=True)
        phase = t.number("phase", 0.0)
        groups = {
            "center_deflection": ("center_deflection",),
            "acoustic (8)": ("pressure", "thickness", "shear_modulus"),
            "boundary (10)": ("boundary_amplitude", "density", "shear_modulus"),
        }
        given = {k for keys in groups.values() for k in keys if t.has(k)}
        present = [g for g, keys in groups.items() if set(keys) == given]
        if len(present) != 1:
            raise SceneError(
                f"{t.key}: give exactly one amplitude: center_deflection | pressure, thickness, "
                f"shear_modulus | boundary_amplitude, density, shear_modulus"
            )
        motion = cls(x_range, y_range, f, 0.0, phase)
        pos = {"lo": 0.0, "lo_open": True}
        if present[0] == "center_deflection":
            motion.q = motion.q_for_center_deflection(t.number("center_deflection", lo=0.0))
        elif present[0] == "acoustic (8)":
            motion.q = cls.q_acoustic(
                t.number("pressure", lo=0.0), t.number("thickness", **pos), t.number("shear_modulus", **pos)
            )
        else:
            motion.q = cls.q_boundary(
                f, t.number("density", **pos), t.number("boundary_amplitude", lo=0.0), t.number("shear_modulus", **pos)
            )
        return motion
