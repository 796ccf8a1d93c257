"""A scene: sun, sensor, footprint, surfaces, background, sampling and noise.

Surfaces are flat horizontal rectangles at rest (roof, pane, ground patch) with a material and an
optional motion. Where surfaces overlap, the one listed later is on top. Footprint area that no
surface covers sees the static background material.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from forward.geometry import direction
from forward.materials import Material
from forward.motion.base import Motion
from forward.polarizer import Polarizer

Radiometry = Literal["projected", "paper"]


@dataclass(frozen=True)
class Sun:
    """Sun at `inclination` (elevation, rad) and `azimuth` (rad); irradiance scales the signal."""

    inclination: float
    azimuth: float
    irradiance: float = 1.0

    @property
    def direction(self) -> NDArray[np.float64]:
        return direction(self.inclination, self.azimuth)


@dataclass(frozen=True)
class Sensor:
    """Line of sight towards the sensor, polarizer, and radiometry.

    radiometry "projected" (default) weights each footprint element by its area projected towards
    the sensor, which is what a pixel integrates; "paper" is eq. (22)'s plain average of B.
    """

    inclination: float
    azimuth: float
    polarizer: Polarizer = field(default_factory=Polarizer)
    radiometry: Radiometry = "projected"

    @property
    def direction(self) -> NDArray[np.float64]:
        return direction(self.inclination, self.azimuth)


@dataclass(frozen=True)
class Footprint:
    """The rectangle [x0, x1] x [y0, y1] (m) a pixel sees, sampled by resolution^2 subpixel centres."""

    x: tuple[float, float]
    y: tuple[float, float]
    resolution: int = 128

    def subpixels(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Cell-centre coordinates (x, y), each shape (resolution^2,)."""
        n = self.resolution
        xs = self.x[0] + (np.arange(n) + 0.5) * (self.x[1] - self.x[0]) / n
        ys = self.y[0] + (np.arange(n) + 0.5) * (self.y[1] - self.y[0]) / n
        gx, gy = np.meshgrid(xs, ys, indexing="ij")
        return gx.ravel(), gy.ravel()


@dataclass(frozen=True)
class Surface:
    """A horizontal rectangle of `material`; `lobe_width` (rad) is the RMS facet slope m of eq. (6)."""

    name: str
    x: tuple[float, float]
    y: tuple[float, float]
    material: Material
    lobe_width: float | None = None
    motion: Motion | None = None

    def contains(self, x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.bool_]:
        return (x >= self.x[0]) & (x <= self.x[1]) & (y >= self.y[0]) & (y <= self.y[1])


@dataclass(frozen=True)
class Sampling:
    """Sample rate fs (Hz), duration (s) and start time (s)."""

    fs: float
    duration: float
    start: float = 0.0

    @property
    def n_samples(self) -> int:
        return round(self.duration * self.fs)

    def times(self) -> NDArray[np.float64]:
        return self.start + np.arange(self.n_samples) / self.fs


@dataclass(frozen=True)
class Noise:
    """Sensor noise in signal units: shot noise (photoelectrons per unit of x per sample; 0 = off),
    additive Gaussian read noise `sigma`, then an ADC of `adc_bits` (0 = off) over
    [0, adc_full_scale] (0 = twice the clean signal's maximum)."""

    sigma: float = 0.0
    photons_per_unit: float = 0.0
    adc_bits: int = 0
    adc_full_scale: float = 0.0


@dataclass(frozen=True)
class Scene:
    sun: Sun
    sensor: Sensor
    footprint: Footprint
    surfaces: tuple[Surface, ...]
    background: Surface
    sampling: Sampling
    noise: Noise = field(default_factory=Noise)

    def realize_motions(self, t: NDArray[np.float64], seed: int | np.random.SeedSequence | None) -> list[Motion | None]:
        """Each surface's motion realized on `t` (random motions draw here), one independent
        random stream per surface derived from `seed`."""
        root = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
        streams = root.spawn(len(self.surfaces))
        return [
            None if s.motion is None else s.motion.prepare(t, np.random.default_rng(st))
            for s, st in zip(self.surfaces, streams)
        ]

    def owners(self, x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.int64]:
        """Index into `surfaces` of the surface on top at each point; -1 = background."""
        owner = np.full(x.shape, -1, dtype=np.int64)
        for k, s in enumerate(self.surfaces):
            owner[s.contains(x, y)] = k
        return owner
