"""A scene: sun, sensor, footprint, surfaces, background, sampling and noise.

Surfaces are flat horizontal rectangles at rest (roof, pane, ground patch) with a material and an
optional motion. Where surfaces overlap, the one listed later is on top. Footprint area that no
surface covers sees the static background material.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Literal, NamedTuple

import numpy as np
from numpy.typing import NDArray

from forward.errors import SceneError
from forward.geometry import direction
from forward.materials import Material
from forward.motion.base import Motion
from forward.polarizer import Polarizer
from forward.validation import one_line
from forward.validation import seed as check_seed

Radiometry = Literal["projected", "paper"]

MEMORY_LIMIT_ENV = "VIBINVERSE_MEMORY_LIMIT"
DEFAULT_MEMORY_LIMIT = 2 * 2**30  # bytes

# float64 values a simulation keeps per sample and per subpixel (measured peaks, rounded up: 56 B a
# sample for a plate, 352 B for the frame; 320 B a subpixel for a plate, 950 B for one ground wave)
_PER_SAMPLE = 8  # times, clean and noisy series, modal coordinates, temporaries
_PER_SAMPLE_REALIZED = 40  # a motion simulated per run (the frame's state-space response, base noise)
_PER_SUBPIXEL = 8  # cell centres, owner, masks
_PER_SUBPIXEL_MOVING = 48  # slope shapes and facet temporaries of a moving surface
_PER_SUBPIXEL_LINE = 4  # slope shapes per line (2 modal coordinates x 2 slopes)


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
        random stream per surface derived from `seed` (an integer in [0, 2^32), None or a SeedSequence)."""
        root = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(check_seed(seed))
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


# ----------------------------------------------------------------------------- memory


class Load(NamedTuple):
    """What one moving surface adds to a simulation's memory: its sinusoidal lines (drive or wave
    frequencies; the key that lists them names what to reduce) and whether its motion is simulated
    per run."""

    name: str
    lines: int = 1
    lines_key: str = ""
    realized: bool = False


def load_of(surface: Surface) -> Load:
    """The Load of a moving surface, from its motion: the lines are its drive's or its own frequencies."""
    motion = surface.motion
    drive = getattr(motion, "drive", None)
    freqs = getattr(drive, "frequencies", None) if drive is not None else getattr(motion, "frequencies", None)
    lines = max(1, int(np.size(freqs))) if freqs is not None else 1
    realized = type(motion).prepare is not Motion.prepare
    return Load(surface.name, lines, one_line(f"surfaces.{surface.name}.motion"), realized)


@dataclass(frozen=True)
class MemoryEstimate:
    """Float64 values a simulation needs, by term: (values, what, the keys that reduce it)."""

    terms: tuple[tuple[int, str, tuple[str, ...]], ...]

    @property
    def total(self) -> int:
        """Bytes."""
        return 8 * sum(v for v, _, _ in self.terms)

    def check(self, limit: int | None = None) -> None:
        """SceneError naming the estimate, the limit and the values to reduce when the total is
        above `limit` (default: `memory_limit()`)."""
        limit = memory_limit() if limit is None else limit
        total = self.total
        if total <= limit:
            return
        big = sorted((t for t in self.terms if 8 * t[0] >= total / 10), key=lambda t: -t[0])
        keys = list(dict.fromkeys(k for _, _, ks in big for k in ks))
        reduce = ", ".join(keys[:-1]) + (" or " if len(keys) > 1 else "") + keys[-1]
        raise SceneError(
            f"scene: needs about {format_bytes(total)} of memory ({' + '.join(w for _, w, _ in big)}), above "
            f"the limit {format_bytes(limit)} ({MEMORY_LIMIT_ENV}, in bytes); reduce {reduce}"
        )


def estimate_memory(n_samples: int, n_subpixels: int, loads: Iterable[Load], dense: bool = False) -> MemoryEstimate:
    """The memory a simulation of `n_samples` samples on `n_subpixels` subpixels needs, with one
    Load per moving surface; `dense` adds the dense evaluation's samples x subpixels (evaluated in
    blocks, but that is the work it does). An estimate (within ~2x of measured peaks), so that
    a scene far beyond the machine is refused before anything is allocated."""
    loads = list(loads)
    t, n = int(n_samples), int(n_subpixels)
    sampling = ("sampling.duration", "sampling.fs")
    per_sample = _PER_SAMPLE + _PER_SAMPLE_REALIZED * sum(ld.realized for ld in loads)
    per_subpixel = _PER_SUBPIXEL + _PER_SUBPIXEL_MOVING * len(loads)
    terms = [
        (t * per_sample, f"{t} samples x {per_sample} float64", sampling),
        (n * per_subpixel, f"{n} subpixels x {per_subpixel} float64", ("footprint.resolution",)),
    ]
    for ld in loads:
        key = (ld.lines_key or f"surfaces.{ld.name}.motion",)
        terms.append((t * ld.lines, f"{t} samples x {ld.lines} lines", key + sampling))
        terms.append(
            (
                n * ld.lines * _PER_SUBPIXEL_LINE,
                f"{n} subpixels x {ld.lines} lines x {_PER_SUBPIXEL_LINE} float64",
                key + ("footprint.resolution",),
            ),
        )
    if dense and loads:
        terms.append((t * n, f"{t} samples x {n} subpixels (dense evaluation)", ("footprint.resolution", *sampling)))
    return MemoryEstimate(tuple(terms))


def memory_estimate(scene: Scene, dense: bool = False) -> MemoryEstimate:
    """`estimate_memory` of a scene; `dense` for the dense evaluation (`pixel_signal`, rtol=None)."""
    n = scene.sampling.duration * scene.sampling.fs
    if not math.isfinite(n):
        raise SceneError(f"sampling: duration * fs = {n} samples; allowed: a finite number")
    loads = [load_of(s) for s in scene.surfaces if s.motion is not None]
    return estimate_memory(scene.sampling.n_samples, scene.footprint.resolution**2, loads, dense)


def memory_limit() -> int:
    """Bytes a simulation may use: the environment variable VIBINVERSE_MEMORY_LIMIT, else 2 GiB."""
    text = os.environ.get(MEMORY_LIMIT_ENV, "").strip()
    if not text:
        return DEFAULT_MEMORY_LIMIT
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value >= 1):
        raise SceneError(f"{MEMORY_LIMIT_ENV}: {one_line(repr(text))} is not a number of bytes; allowed range [1, inf)")
    return int(value)


def format_bytes(n: float) -> str:
    """2147483648 -> "2 GiB", 9.6e9 -> "9.6 GB", 1000 -> "1000 bytes"."""
    n = int(n)
    for unit, size in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20)):
        if n >= size and n % size == 0:
            return f"{n // size} {unit}"
    if n < 10**6:
        return f"{n} bytes"
    for unit, size in (("EB", 1e18), ("PB", 1e15), ("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n} bytes"  # pragma: no cover
