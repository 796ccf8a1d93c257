"""What one configuration buys an observer: sensitivity (21), the SNR of each spectral line, and
the Cramer-Rao standard deviation of each target parameter.

- Deterministic scenes (plate, ground waves): y = mu(theta) + white sensor noise, so the Fisher
  information is D^T D / var with D = d mu / d theta from the reduced model (`compile_scene`),
  differenced on its AC part so that 1e-9 m amplitudes keep their digits. Nuisances estimated
  jointly, as a fit would: a DC level and a time shift (the vibration's phase).
- Frame scenes (noise-driven resonances): the frame likelihood's Fisher information, mean term
  through the Kalman filter plus Whittle's covariance term (`vibinverse.fisher`). Nuisances: the
  drive phases, the base-noise level and the sensor noise, as `vibinverse fit` frees them.

A line's SNR is its amplitude over the standard error of a sinusoid's amplitude fitted in the
local noise, A / sqrt(2 S(f) / N), with S(f) the noise spectrum at the line (sensor variance for
white noise).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from forward.errors import SceneError as ForwardSceneError
from forward.motion import MOTION_KINDS
from forward.motion.frame import FrameMotion
from forward.reduce import compile_scene, footprint_layout, taylor_surface_ac
from forward.scene import Noise, Scene
from forward.scene_file import scene_from_table
from forward.validation import Table
from vibinverse.errors import SceneError
from vibinverse.fisher import crlb_from_fisher, frame_fisher, multi_pixel_fisher, spectrum_at
from vibinverse.io.series import Series
from vibinverse.models import DeterministicModel, FrameModel, model_class_for
from vibinverse.scene_keys import get_value, set_value
from vibinverse.spectrum import sinusoid

# Design evaluates every configuration with the second-order (Taylor) reduced model: one model
# for a configuration and its perturbations, so that derivatives are smooth, at ~ms per scene.
# Its error estimate (relative to the peak-to-peak signal) is reported per row as model_error.
DESIGN_MODEL = "taylor2"


def default_targets(table: dict) -> list[str]:
    """Frequency and amplitude of each vibration: for a frame, its tilt resonance, damping ratio
    and first drive line (`SignalModel.default_targets`)."""
    return model_class_for(table).default_targets(table)


def check_targets(table: dict, targets: list[str]) -> None:
    """One-line errors for targets that are not numbers of this scene (or not fittable)."""
    DESIGNS[model_class_for(table).name].check_targets(table, targets)


def evaluate(table: dict, targets: list[str], cache: dict, pixels: int = 1) -> dict[str, Any]:
    """Metrics of the configuration `table` (a complete scene table), for `pixels` equal pixels
    fitted jointly (each seeing the footprint, with its own independent noise; the joint fit's
    bound, `vibinverse.fisher.multi_pixel_fisher`)."""
    scene = scene_from_table(table)
    return DESIGNS[model_class_for(table).name].metrics(table, scene, targets, cache, pixels)


def _deterministic_targets(table: dict, targets: list[str]) -> None:
    for t in targets:
        try:
            get_value(table, t)
        except ForwardSceneError as exc:
            raise SceneError(f"--target {exc}") from None


def _frame_targets(table: dict, targets: list[str]) -> None:
    t = scene_from_table(table).sampling.times()
    names = FrameModel(table, Series(t, np.zeros(t.size), "design")).fittable()
    for target in targets:
        if target not in names:
            raise SceneError(
                f"--target {target}: not a parameter of this frame scene; choose from {', '.join(sorted(names))}"
            )


def _sensitivity(dc: float, ac: np.ndarray) -> float:
    """S = (max x - min x) / max x, eq. (21), from the rest value and the AC part (no digits lost)."""
    top = dc + float(ac.max())
    if not top > 0:
        raise SceneError(f"sensitivity: undefined for a signal whose maximum is {top:g} (must be > 0)")
    return float(np.ptp(ac)) / top


def noise_variance(noise: Noise, mean_level: float, peak: float) -> float:
    """Per-sample variance of the sensor noise: read noise, shot noise at the mean level, and the
    ADC's quantization step^2 / 12."""
    var = noise.sigma**2
    if noise.photons_per_unit > 0:
        var += max(mean_level, 0.0) / noise.photons_per_unit
    if noise.adc_bits > 0:
        full = noise.adc_full_scale if noise.adc_full_scale > 0 else 2.0 * peak
        var += (full / (2**noise.adc_bits - 1)) ** 2 / 12.0
    return var


def line_amplitude(t: np.ndarray, x: np.ndarray, f: float) -> float:
    """Amplitude of the sinusoid at f (Hz) in x (least squares with a constant)."""
    return sinusoid(t - t[0], x, f)[0]


def _line_frequencies(scene: Scene) -> list[float]:
    out = []
    for s in scene.surfaces:
        m = s.motion
        if m is None:
            continue
        freqs = getattr(m, "frequencies", None)
        out += list(np.atleast_1d(freqs if freqs is not None else getattr(m, "frequency", [])))
    return [float(f) for f in out]


def _step(name: str, value: float, fs: float) -> float:
    return 1e-3 / fs if name == "sampling.start" else 1e-6 * max(abs(value), 1e-6)


def _deterministic_metrics(
    table: dict, scene: Scene, targets: list[str], cache: dict, pixels: int = 1
) -> dict[str, Any]:
    compiled = compile_scene(scene, seed=0, force=DESIGN_MODEL, shape_cache=cache)
    dc, ac = compiled.parts()
    t = compiled.t
    # N equal pixels: the combined series has white noise of variance var / N (`multi_pixel_fisher`)
    var = noise_variance(scene.noise, dc + float(ac.mean()), dc + float(ac.max())) / pixels
    if not var > 0:
        raise SceneError("noise.sigma: design needs sensor noise (sigma > 0, photons or an ADC) to bound parameters")
    row: dict[str, Any] = {
        "sensitivity": _sensitivity(dc, ac),
        "model_error": compiled.error_bound() / max(float(np.ptp(ac)), 1e-300),
    }
    fs, n = scene.sampling.fs, t.size
    for f in _line_frequencies(scene):
        for h, label in ((1, ""), (2, " (2f)")):
            if h * f < fs / 2:
                row[f"snr {h * f:g} Hz{label}"] = line_amplitude(t, ac, h * f) / np.sqrt(2 * var / n)
    names = [*targets, "sampling.start"]
    moving = footprint_layout(scene, cache).moving
    d = np.array([np.ones(n)] + [_mean_derivative(table, scene, name, moving, cache) for name in names])
    crlb = crlb_from_fisher(d @ d.T / var, ["dc", *names])
    return {**row, **_bounds(table, targets, crlb)}


def _mean_derivative(table: dict, scene: Scene, name: str, moving: list, cache: dict) -> np.ndarray:
    """d mu / d name through the reduced model: a motion parameter (or the start time) changes only
    that motion's coefficients and shapes, so its surface's Taylor model is re-formed at name +- h
    with the facet derivatives at rest held (they do not depend on the motion)."""
    t = scene.sampling.times()
    irr = scene.sun.irradiance
    if name == "sampling.start":
        h = _step(name, 0.0, scene.sampling.fs)
        out = np.zeros(t.size)
        for k, x, y, weight, d in moving:
            m = scene.surfaces[k].motion
            out += (
                irr
                * weight
                * (taylor_surface_ac(m, x, y, d, t + h, cache) - taylor_surface_ac(m, x, y, d, t - h, cache))
                / (2 * h)
            )
        return out
    parts = name.split(".")
    if len(parts) >= 4 and parts[0] == "surfaces" and parts[2] == "motion":
        k = next(i for i, s in enumerate(scene.surfaces) if s.name == parts[1])
        v = get_value(table, name)
        h = _step(name, v, scene.sampling.fs)
        for kk, x, y, weight, d in moving:
            if kk == k:
                up, dn = (_motion_with(table, scene.surfaces[k], name, v + s * h) for s in (1, -1))
                return (
                    irr
                    * weight
                    * (taylor_surface_ac(up, x, y, d, t, cache) - taylor_surface_ac(dn, x, y, d, t, cache))
                    / (2 * h)
                )
        return np.zeros(t.size)  # the surface is outside the footprint
    v = get_value(table, name)  # any other scene value: re-compile the scene at name +- h
    h = _step(name, v, scene.sampling.fs)
    (dc_up, ac_up), (dc_dn, ac_dn) = (
        compile_scene(
            scene_from_table(_with(table, name, v + s * h)), seed=0, force=DESIGN_MODEL, shape_cache=cache
        ).parts()
        for s in (1, -1)
    )
    return ((ac_up - ac_dn) + (dc_up - dc_dn)) / (2 * h)


def _motion_with(table: dict, surface: Any, name: str, value: float) -> Any:
    """The surface's motion rebuilt from its scene table with `name` set to `value`."""
    tab = _with(table, name, value)
    sub = tab["surfaces"][surface.name]["motion"]
    mt = Table(sub, f"surfaces.{surface.name}.motion")
    kind = mt.choice("kind", None, tuple(MOTION_KINDS))
    return MOTION_KINDS[kind](mt, surface.x, surface.y)


def _with(table: dict, key: str, value: float) -> dict:
    import copy

    out = copy.deepcopy(table)
    set_value(out, key, value)
    return out


def _bounds(table: dict, targets: list[str], crlb: dict[str, float]) -> dict[str, float]:
    out = {}
    for name in targets:
        v = get_value(table, name)
        out[f"crlb {name}"] = crlb[name]
        out[f"rel_crlb {name}"] = crlb[name] / abs(v) if v != 0 else np.inf
    return out


def _frame_metrics(table: dict, scene: Scene, targets: list[str], cache: dict, pixels: int = 1) -> dict[str, Any]:
    t = scene.sampling.times()
    like = FrameModel(table, Series(t, np.zeros(t.size), "design"))
    base = like.base
    k = like.key
    n_lines = len(base["surfaces"][like.roof]["motion"].get("drive_frequency") or [])
    nuisance = [f"{k}drive_phase[{i}]" for i in range(n_lines)] + [k + "noise_rms", "noise.sigma"]
    canonical = [_canonical(n, k) for n in targets]
    names = list(dict.fromkeys([*canonical, *nuisance]))
    values = {n: _value(base, n) for n in names}
    sigma = values["noise.sigma"]
    if pixels > 1 and not sigma > 0:
        raise SceneError("noise.sigma: a design for several pixels needs each pixel's sensor noise (sigma > 0)")
    # N equal pixels, each with its own white noise: the joint fit is the one-pixel model at sd sigma / sqrt(N)
    comps = like.components({**values, "noise.sigma": sigma / np.sqrt(pixels)})
    if comps.r <= 0 and not comps.q.any():
        raise SceneError(
            "noise.sigma: design needs noise (sensor sigma > 0 or frame noise_rms > 0) to bound parameters"
        )
    compiled = compile_scene(scene, seed=0, force=DESIGN_MODEL, shape_cache=cache)
    dc, ac = compiled.parts()
    row: dict[str, Any] = {
        "sensitivity": _sensitivity(dc, ac),
        "model_error": compiled.error_bound() / max(float(np.ptp(ac)), 1e-300),
    }
    dt = like.dt
    motion = next(s.motion for s in scene.surfaces if isinstance(s.motion, FrameMotion))
    for f in np.atleast_1d(motion.drive.frequencies if motion.drive is not None else []):
        level = float(spectrum_at(comps, np.array([2 * np.pi * f * dt]))[0])
        amp = line_amplitude(t, comps.mean - comps.mean.mean(), float(f))
        row[f"snr {float(f):g} Hz"] = amp / np.sqrt(2 * level / t.size)
    fisher = multi_pixel_fisher(lambda v, n: frame_fisher(like, v, n), values, names, [1.0] * pixels, [sigma] * pixels)
    crlb = crlb_from_fisher(fisher, names)
    crlb = {orig: crlb[c] for orig, c in zip(targets, canonical)}
    return {**row, **_bounds(FrameModel.truth_table(table), targets, crlb)}


def _canonical(name: str, key: str) -> str:
    """drive_* without an index is line 0."""
    for n in ("drive_frequency", "drive_amplitude", "drive_phase"):
        if name == key + n:
            return f"{key}{n}[0]"
    return name


def _value(table: dict, name: str) -> float:
    try:
        return get_value(table, name)
    except ForwardSceneError:
        if "drive_phase" in name:
            return 0.0
        raise


@dataclass(frozen=True)
class Design:
    """How design evaluates one signal model's configurations."""

    check_targets: Callable[[dict, list[str]], None]
    metrics: Callable[[dict, Scene, list[str], dict, int], dict[str, Any]]  # (table, scene, targets, cache, pixels)


# one entry per registered signal model (by its registry name)
DESIGNS: dict[str, Design] = {
    FrameModel.name: Design(_frame_targets, _frame_metrics),
    DeterministicModel.name: Design(_deterministic_targets, _deterministic_metrics),
}
