"""Fresnel reflectance of dielectrics and conductors (paper eqs. (2)-(4))."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

EPSILON_0 = 8.8541878128e-12  # F/m
SPEED_OF_LIGHT = 299_792_458.0  # m/s


def fresnel(theta_i: ArrayLike, n2: ArrayLike, n1: float = 1.0) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Power reflectances (R_s, R_p) at incidence angle `theta_i` (rad), eqs. (2) and (3).

    `n2` may be complex; a positive imaginary part absorbs. The transmitted normal wavenumber
    n2 cos(theta_t) = sqrt(n2^2 - n1^2 sin^2 theta_i) is taken on the principal branch, which for
    Im(n2) >= 0 gives the decaying wave (Im >= 0); this is eqs. (2)-(3) multiplied through by n2,
    and stays finite where cos(theta_t) of the paper's form would need a branch choice.
    Vectorized over `theta_i` and `n2`.
    """
    th = np.asarray(theta_i, dtype=float)
    n2c = np.asarray(n2, dtype=complex)
    n1c = complex(n1)
    cos_i = np.cos(th)
    kz = np.sqrt(n2c * n2c - (n1c * np.sin(th)) ** 2)  # = n2 cos(theta_t)
    r_s = (n1c * cos_i - kz) / (n1c * cos_i + kz)
    r_p = (n1c * kz - n2c * n2c * cos_i) / (n1c * kz + n2c * n2c * cos_i)
    return np.abs(r_s) ** 2, np.abs(r_p) ** 2


def reflectance(theta_i: ArrayLike, n2: ArrayLike, n1: float = 1.0) -> NDArray[np.float64]:
    """Unpolarized reflectance R = (R_s + R_p) / 2."""
    r_s, r_p = fresnel(theta_i, n2, n1)
    return 0.5 * (r_s + r_p)


def brewster_angle(n2: float, n1: float = 1.0) -> float:
    """Brewster's angle arctan(n2 / n1) (rad, from the normal) of a dielectric (real n2)."""
    if np.iscomplexobj(n2) and np.imag(n2) != 0:
        raise ValueError("brewster_angle: n2 must be real (a dielectric); R_p has no zero for a conductor")
    return float(np.arctan2(np.real(n2), n1))


def index_from_conductivity(sigma: float, wavelength: float) -> complex:
    """Free-electron complex index n2 = sqrt(1 + i sigma / (epsilon_0 omega)), eq. (4).

    sigma: DC conductivity (S/m); wavelength: vacuum wavelength of the light (m). Eq. (4) is a
    crude model at optical frequencies (it ignores the relaxation time and interband
    transitions); prefer the measured indices in `forward.materials`.
    """
    omega = 2.0 * np.pi * SPEED_OF_LIGHT / wavelength
    return complex(np.sqrt(1.0 + 1j * sigma / (EPSILON_0 * omega)))
