"""Sampling and sensor noise: observe(scene) -> the series a pixel records."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from forward.reduce import DEFAULT_RTOL, compile_scene
from forward.render import pixel_signal, sensitivity
from forward.scene import Noise, Scene


@dataclass(frozen=True)
class Observation:
    time: NDArray[np.float64]
    intensity: NDArray[np.float64]
    intensity_clean: NDArray[np.float64]
    sensitivity: float  # eq. (21) of the clean signal


def add_noise(clean: NDArray[np.float64], noise: Noise, rng: np.random.Generator) -> NDArray[np.float64]:
    """Shot noise (Poisson photoelectron counts), then Gaussian read noise, then ADC quantization."""
    x = np.array(clean, dtype=float)
    if noise.photons_per_unit > 0.0:
        x = rng.poisson(np.clip(x, 0.0, None) * noise.photons_per_unit) / noise.photons_per_unit
    if noise.sigma > 0.0:
        x = x + rng.normal(0.0, noise.sigma, size=x.shape)
    if noise.adc_bits > 0:
        full = noise.adc_full_scale if noise.adc_full_scale > 0.0 else 2.0 * float(np.max(clean))
        levels = 2**noise.adc_bits - 1
        step = full / levels
        x = np.clip(np.round(x / step), 0, levels) * step
    return x


def observe(scene: Scene, seed: int | None = None, rtol: float | None = DEFAULT_RTOL) -> Observation:
    """Simulate the pixel series of `scene`; `seed` makes the motion's and the sensor's noise
    reproducible. The clean signal comes from the scene compiler at accuracy `rtol` (relative to
    each surface's peak-to-peak); rtol=None evaluates every subpixel at every sample."""
    t = scene.sampling.times()
    motion_seed, sensor_seed = np.random.SeedSequence(seed).spawn(2)
    if rtol is None:
        clean = pixel_signal(scene, t, motion_seed)
    else:
        clean = compile_scene(scene, t, rtol, motion_seed).signal()
    noisy = add_noise(clean, scene.noise, np.random.default_rng(sensor_seed))
    return Observation(t, noisy, clean, sensitivity(clean))
