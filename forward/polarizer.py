"""A linear polarizer fixed in the sensor frame, and how it mixes each facet's R_s and R_p.

Sunlight is unpolarized, so light reflected by a facet is an incoherent sum: half the power
reflected with R_s along the facet's own s axis (normal to its plane of incidence) and half with
R_p along its p axis (DESIGN.md sec. 3, paper sec. 4.1 Brewster study). A facet that tilts out of
the nominal plane of incidence rotates its s/p axes against the polarizer; near Brewster's angle,
where R_p -> 0, the leak of R_s into the p channel drives the signal by order 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from forward.errors import SceneError
from forward.geometry import Z_HAT, unit


@dataclass(frozen=True)
class Polarizer:
    """Transmission axis at `angle` (rad) from the sensor's s axis towards its p axis; None = no polarizer.

    The sensor's s axis is horizontal and perpendicular to the line of sight (z x n_v); its p axis
    is n_v x s. "s" is angle 0, "p" is angle pi/2.
    """

    angle: float | None = None

    @classmethod
    def parse(cls, spec: object, key: str = "sensor.polarizer") -> Polarizer:
        """From "none" | "s" | "p" | an angle in rad."""
        if spec is None or spec == "none":
            return cls(None)
        if spec == "s":
            return cls(0.0)
        if spec == "p":
            return cls(np.pi / 2)
        if isinstance(spec, (int, float)) and not isinstance(spec, bool) and np.isfinite(spec):
            return cls(float(spec))
        raise SceneError(f'{key}: must be "none", "s", "p" or an angle in rad, got {spec!r}')

    def axis(self, view: NDArray[np.float64]) -> NDArray[np.float64]:
        """Transmission axis (unit, perpendicular to the line of sight `view`)."""
        e_s, e_p = sensor_axes(view)
        return np.cos(self.angle) * e_s + np.sin(self.angle) * e_p

    def weights(
        self, normals: NDArray[np.float64], sun: NDArray[np.float64], view: NDArray[np.float64]
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(w_s, w_p) per facet: the seen reflectance is w_s R_s + w_p R_p; w_s + w_p = 1 without
        a polarizer and 1/2 with one (an ideal polarizer passes half of unpolarized light).

        The facet's s axis n_i x n_s is projected on the plane normal to the line of sight so that
        s' and p' = n_v x s' are an orthonormal transverse basis: the weights of two crossed
        polarizers add up exactly to the unpolarized ones.
        """
        if self.angle is None:
            half = np.full(normals.shape[:-1], 0.5)
            return half, half
        s = np.cross(sun, normals)
        s_norm = np.linalg.norm(s, axis=-1, keepdims=True)
        e_s, _ = sensor_axes(view)
        s = np.where(s_norm > 1e-300, s / np.where(s_norm > 1e-300, s_norm, 1.0), e_s)  # normal incidence: R_s = R_p
        s_t = unit(s - np.sum(s * view, axis=-1, keepdims=True) * view)
        c2 = np.sum(s_t * self.axis(view), axis=-1) ** 2
        return 0.5 * c2, 0.5 * (1.0 - c2)

    def diffuse_factor(self) -> float:
        """Fraction of depolarized (Lambertian) light passed: 1 without a polarizer, 1/2 with one."""
        return 1.0 if self.angle is None else 0.5


def sensor_axes(view: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The sensor's (s, p) axes for line of sight `view`: s = z x n_v (horizontal), p = n_v x s.

    Looking straight down, s is +y.
    """
    s = np.cross(Z_HAT, view)
    n = np.linalg.norm(s)
    s = s / n if n > 1e-12 else np.array([0.0, 1.0, 0.0])
    return s, np.cross(view, s)
