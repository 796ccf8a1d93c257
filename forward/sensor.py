"""Sampling and sensor noise: observe(scene) -> the series a pixel records."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from forward.errors import SceneError
from forward.reduce import DEFAULT_RTOL, CompiledScene, compile_scene
from forward.render import pixel_signal, sensitivity
from forward.scene import Noise, Scene, memory_estimate
from forward.validation import one_line
from forward.validation import seed as check_seed

# numpy's largest Poisson mean (Generator.poisson raises above it)
POISSON_MAX = float(np.iinfo(np.int64).max - np.sqrt(np.iinfo(np.int64).max) * 10)


@dataclass(frozen=True)
class Observation:
    time: NDArray[np.float64]
    intensity: NDArray[np.float64]
    intensity_clean: NDArray[np.float64]
    sensitivity: float  # eq. (21) of the clean signal


def add_noise(clean: NDArray[np.float64], noise: Noise, rng: np.random.Generator) -> NDArray[np.float64]:
    """Shot noise (Poisson photoelectron counts), then Gaussian read noise, then ADC quantization.

    SceneError names the noise value when a stage cannot be formed in float64 (a Poisson mean above
    POISSON_MAX, a series that overflows, a quantization step of 0)."""
    x = np.array(clean, dtype=float)
    if noise.photons_per_unit > 0.0:
        top = float(np.max(np.clip(x, 0.0, None), initial=0.0))
        if not top * noise.photons_per_unit <= POISSON_MAX:
            raise SceneError(
                f"noise.photons_per_unit: {noise.photons_per_unit:g} photoelectrons per unit x the clean maximum "
                f"{top:g} = {top * noise.photons_per_unit:g} per sample; allowed at most {POISSON_MAX:.3g} per sample"
            )
        x = rng.poisson(np.clip(x, 0.0, None) * noise.photons_per_unit) / noise.photons_per_unit
        _finite(x, f"noise.photons_per_unit: {noise.photons_per_unit:g}")
    if noise.sigma > 0.0:
        x = x + rng.normal(0.0, noise.sigma, size=x.shape)
        _finite(x, f"noise.sigma: {noise.sigma:g}")
    if noise.adc_bits > 0:
        full = noise.adc_full_scale if noise.adc_full_scale > 0.0 else 2.0 * float(np.max(clean))
        levels = 2**noise.adc_bits - 1
        step = full / levels
        if not (step > 0.0 and np.isfinite(step)):
            raise SceneError(
                f"noise.adc_full_scale: {full:g} over {levels} levels gives a quantization step of {step:g}; "
                f"allowed: a step > 0 (raise adc_full_scale or lower adc_bits)"
            )
        x = np.clip(np.round(x / step), 0, levels) * step
    return x


def _finite(x: NDArray[np.float64], what: str) -> None:
    if not np.all(np.isfinite(x)):
        raise SceneError(f"{what} makes the noisy series overflow (non-finite samples); reduce it")


def observe(scene: Scene, seed: int | None = None, rtol: float | None = DEFAULT_RTOL) -> Observation:
    """Simulate the pixel series of `scene`; `seed` (an integer in [0, 2^32), or None) makes the
    motion's and the sensor's noise reproducible. The clean signal comes from the scene compiler at
    accuracy `rtol` (relative to each surface's peak-to-peak); rtol=None evaluates every subpixel
    at every sample.

    SceneError (one line, naming the value) for a bad seed, a scene whose memory estimate is above
    `forward.scene.memory_limit()` (checked before anything is allocated), and a series that is not
    finite or a signal without light (no sensitivity): never a non-finite series."""
    seed = check_seed(seed)
    memory_estimate(scene, dense=rtol is None).check()  # before anything is allocated
    t = scene.sampling.times()
    motion_seed, sensor_seed = np.random.SeedSequence(seed).spawn(2)
    compiled = None
    try:
        with np.errstate(over="ignore", invalid="ignore"):  # overflow is reported below, naming the value
            if rtol is None:
                clean = pixel_signal(scene, t, motion_seed)
            else:
                compiled = compile_scene(scene, t, rtol, motion_seed)
                clean = compiled.signal()
    except OverflowError:  # Python float arithmetic in a motion (e.g. the square of a huge noise_rms)
        raise SceneError(
            f"{_motion_keys(scene)}: a value overflows float64 while the motion is simulated; reduce its amplitudes"
        ) from None
    if not np.all(np.isfinite(clean)):
        raise SceneError(_not_finite(scene, t, compiled, motion_seed))
    try:
        s = sensitivity(clean)
    except ValueError:
        raise SceneError(
            f"scene: the clean signal's maximum is {float(np.max(clean)):g}: the pixel receives no light, so the "
            "sensitivity (eq. 21) is undefined; allowed: a scene that reflects light into the sensor"
        ) from None
    noisy = add_noise(clean, scene.noise, np.random.default_rng(sensor_seed))
    return Observation(t, noisy, clean, s)


def _motion_keys(scene: Scene) -> str:
    return " or ".join(one_line(f"surfaces.{s.name}.motion") for s in scene.surfaces if s.motion is not None) or "scene"


def _not_finite(
    scene: Scene, t: NDArray[np.float64], compiled: CompiledScene | None, seed: np.random.SeedSequence
) -> str:
    """Which value made the clean signal non-finite: a surface's motion or optics, else the irradiance."""
    if compiled is None:  # the dense path has no parts: the reduced models show which surface it is
        try:
            with np.errstate(all="ignore"):
                compiled = compile_scene(scene, t, DEFAULT_RTOL, seed)
        except (ArithmeticError, ValueError):
            compiled = None
    for part in compiled.surfaces if compiled is not None else ():
        with np.errstate(all="ignore"):
            values = np.asarray(part.series(), dtype=float)
        if np.all(np.isfinite(values)):
            continue
        key = "background" if part.name == "background" else one_line(f"surfaces.{part.name}")
        if part.kind == "static" or not np.isfinite(part.value0):
            return f"{key}: its reflectance at rest is not finite ({part.value0:g}); raise its lobe_width"
        return f"{key}.motion: its signal is not finite (its slopes overflow); reduce its amplitudes"
    irr = scene.sun.irradiance
    if compiled is not None or irr > 1.0:
        return f"sun.irradiance: {irr:g} makes the clean signal overflow (non-finite samples); reduce it"
    return f"scene: the clean signal is not finite; reduce sun.irradiance or the amplitudes of {_motion_keys(scene)}"
