"""Radiance of facets with given normals: eq. (23) for Fresnel lobes, eq. (5) for Lambertian.

`facet_signal` returns B times the radiometric weight of DESIGN.md sec. 3, so that the pixel
signal is the plain mean of it over the footprint's subpixels (eq. (22)).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from forward.brdf import lambertian, specular_lobe
from forward.geometry import angle_between, mirror
from forward.materials import Fresnel, Lambertian
from forward.optics import fresnel
from forward.scene import Sensor, Surface


def facet_signal(
    normals: NDArray[np.float64], surface: Surface, sun: NDArray[np.float64], sensor: Sensor
) -> NDArray[np.float64]:
    """B(n_s; n_i, n_v) * weight for unit normals of shape (..., 3); result shape (...).

    weight = 1 for radiometry "paper" (eq. (22)); for "projected" it is the facet's area projected
    towards the sensor per unit of the footprint's projected area, (n_s.n_v) / ((n_s.z)(n_v.z)):
    a tilted facet of a height field covers 1/(n_s.z) of its horizontal cell and is seen
    foreshortened by n_s.n_v, against n_v.z for the flat reference.
    """
    view = sensor.direction
    cos_i = normals @ sun
    cos_v = normals @ view
    material = surface.material
    if isinstance(material, Lambertian):
        b = lambertian(cos_i, material.albedo) * sensor.polarizer.diffuse_factor()
        b = np.where(cos_v > 0.0, b, 0.0)
    elif isinstance(material, Fresnel):
        theta_i = angle_between(normals, sun)
        alpha = angle_between(mirror(sun, normals), view)
        r_s, r_p = fresnel(theta_i, material.index)
        w_s, w_p = sensor.polarizer.weights(normals, sun, view)
        b = specular_lobe(cos_i, cos_v, alpha, w_s * r_s + w_p * r_p, surface.lobe_width, theta_i)
    else:  # pragma: no cover - the material union is closed
        raise TypeError(f"unknown material {material!r}")
    if sensor.radiometry == "projected":
        b = b * (np.clip(cos_v, 0.0, None) / (normals[..., 2] * view[2]))
    return b
