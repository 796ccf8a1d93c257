"""Materials: Fresnel reflectors (complex index) and Lambertian scatterers (albedo).

Built-in indices are for a vacuum wavelength of 550 nm (the peak of the solar spectrum):

- ``glass``: SCHOTT N-BK7, Sellmeier coefficients from the SCHOTT optical glass data sheet,
  evaluated at 0.55 um: n = 1.5185.
- ``glass_paper``: n = 1.5, the value the paper uses for Fig. 2 and its Brewster study.
- ``steel``: iron, Johnson & Christy, Phys. Rev. B 9, 5056 (1974), nearest tabulated point to
  550 nm (2.2 eV): n = 2.92 + 3.35i (normal-incidence R = 0.56). Polished carbon steel is
  optically close to iron; stainless grades reflect a few per cent less.
- ``aluminium``: Rakic, Appl. Opt. 34, 4755 (1995), 550 nm: n = 0.96 + 6.69i (R = 0.92).
- ``ground``: Lambertian, albedo 1 (the paper's sec. 4.1 background).

Values are rounded to the digits quoted; the reflectance they give is good to ~1 %.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from forward.errors import SceneError
from forward.optics import index_from_conductivity
from forward.validation import number


@dataclass(frozen=True)
class Fresnel:
    """A smooth reflector with complex refractive index `index` (Im > 0 absorbs)."""

    index: complex
    source: str = "user"


@dataclass(frozen=True)
class Lambertian:
    """A diffuse scatterer: BRDF = albedo / pi (eq. (5) with R_d = albedo / pi)."""

    albedo: float
    source: str = "user"


Material = Fresnel | Lambertian


def _bk7_index(wavelength_um: float) -> float:
    """N-BK7 Sellmeier equation (SCHOTT data sheet)."""
    b = (1.03961212, 0.231792344, 1.01046945)
    c = (0.00600069867, 0.0200179144, 103.560653)
    w2 = wavelength_um**2
    return float(np.sqrt(1.0 + sum(bi * w2 / (w2 - ci) for bi, ci in zip(b, c))))


LIBRARY: dict[str, Material] = {
    "glass": Fresnel(complex(round(_bk7_index(0.55), 4)), "SCHOTT N-BK7 Sellmeier, 550 nm, rounded to 1.5185"),
    "glass_paper": Fresnel(1.5 + 0j, "paper sec. 2.1 (n = 1.5)"),
    "steel": Fresnel(2.92 + 3.35j, "iron, Johnson & Christy 1974, ~550 nm"),
    "aluminium": Fresnel(0.96 + 6.69j, "Rakic 1995, 550 nm"),
    "ground": Lambertian(1.0, "paper sec. 4.1 (albedo 1)"),
}


def material_from_spec(spec: object, key: str) -> Material:
    """A material from a library name or a table {index = [re, im]} | {albedo} | {conductivity, wavelength}.

    `key` is the scene key used in error messages.
    """
    if isinstance(spec, str):
        if spec not in LIBRARY:
            raise SceneError(f"{key}: unknown material {spec!r}; allowed: {', '.join(sorted(LIBRARY))} or a table")
        return LIBRARY[spec]
    if not isinstance(spec, dict):
        raise SceneError(f"{key}: must be a material name or a table with index, albedo or conductivity")
    keys = set(spec)
    if keys == {"albedo"}:
        return Lambertian(number(spec["albedo"], f"{key}.albedo", 0.0, 1.0))
    if keys == {"index"}:
        idx = spec["index"]
        if isinstance(idx, (int, float)):
            idx = [idx, 0.0]
        if not (isinstance(idx, list) and len(idx) == 2):
            raise SceneError(f"{key}.index: must be a number or [real, imaginary]")
        re = number(idx[0], f"{key}.index[0]", 0.0, lo_open=True)
        im = number(idx[1], f"{key}.index[1]", 0.0)
        return Fresnel(complex(re, im))
    if keys == {"conductivity", "wavelength"}:
        sigma = number(spec["conductivity"], f"{key}.conductivity", 0.0)
        lam = number(spec["wavelength"], f"{key}.wavelength", 0.0, lo_open=True)
        return Fresnel(index_from_conductivity(sigma, lam), "eq. (4) from conductivity")
    raise SceneError(
        f"{key}: a material table has exactly one of: albedo | index | conductivity + wavelength; got {sorted(keys)}"
    )
