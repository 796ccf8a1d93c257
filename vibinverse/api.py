"""The public Python API; `import vibinverse as vi` exposes every name here. The command line is a
thin layer over these functions.

    series = vi.load_series("frame.csv")
    scene = vi.load_scene("examples/scenes/roof_frame.toml", ["noise.sigma=0.6"])
    result = vi.fit(series, scene, method="casadi")
    result.summary()["parameters"]; result.detections; result.to_netcdf("result.nc")

An observation that is a video or an image cube:

    cube = vi.open_video("roof.mp4")                 # xarray (time, y, x), lazy, frame stamps as time
    found = vi.detect(cube)                           # per-pixel detection map, lines, pixel clusters
    result = vi.fit(cube, pixels=found.cluster(1))    # the cluster's pixels fitted jointly
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from forward.reduce import DEFAULT_RTOL
from forward.sensor import Observation, observe
from vibinverse.errors import InputError, scene_errors
from vibinverse.fitting import SceneLike, SeriesLike, build_posterior, fit_series, scene_table
from vibinverse.io.scenes import load_scene, scene_of
from vibinverse.io.series import Series, load_series, validate
from vibinverse.posterior import Posterior
from vibinverse.priors import Prior
from vibinverse.result import Detection, FitResult

__all__ = [
    "Observation",
    "design",
    "detect",
    "fit",
    "load_scene",
    "load_series",
    "open_cube",
    "open_video",
    "posterior",
    "series",
    "simulate",
    "simulate_cube",
]


def open_cube(
    path: str | Path,
    *,
    fps: float | None = None,
    channel: str = "luminance",
    chunks: int | None = None,
    variable: str | None = None,
) -> Any:
    """An image cube or a video as a lazy `xarray.DataArray` (time, y, x): video (each frame's
    presentation time stamp), Photron .cih/.mraw, TIFF stacks, .npy, netCDF, zarr
    (`vibinverse.io.cube.open_cube`)."""
    from vibinverse.io.cube import open_cube as _open

    return _open(path, fps=fps, channel=channel, chunks=chunks, variable=variable)


open_video = open_cube  # the same reader; the name an analyst with a video looks for


def _is_cube(data: Any) -> bool:
    import xarray as xr

    return isinstance(data, xr.DataArray) and data.ndim == 3


def series(time: Any, intensity: Any, *, scene: Mapping[str, Any] | None = None, source: str = "array") -> Series:
    """A validated series from arrays (NaN intensities are gaps); `scene`, when the data were
    simulated from one, gives the summary its true values."""
    return validate(time, intensity, source, None if scene is None else dict(scene))


def posterior(
    series: SeriesLike,
    scene: SceneLike | None = None,
    *,
    free: Mapping[str, Prior | str] | None = None,
    model: str | None = None,
    overrides: Sequence[str] = (),
) -> Posterior:
    """The posterior of the free parameters (default: the scene's [infer] table, else the model's
    default priors) given `series`; `model` names a registered signal model (default: the one
    that describes the scene). Without a scene, or with a `{"modal": {...}}` table, the modal
    model (`vibinverse.models.modal`), its order chosen from the data (`vibinverse.model_order`)
    unless the table fixes it."""
    return build_posterior(series, scene, free, model, overrides)[0]


def fit(
    series: SeriesLike,
    scene: SceneLike | None = None,
    *,
    method: str = "auto",
    free: Mapping[str, Prior | str] | None = None,
    model: str | None = None,
    overrides: Sequence[str] = (),
    seed: int = 0,
    chain: str | Path | None = None,
    resume: bool = False,
    workers: int | None = None,
    max_steps: int = 20000,
    progress: bool = False,
    pixels: Any = None,
    noise: str | None = None,
    drift: str | bool | None = None,
    gain: bool | int | str | None = None,
    white: bool | None = None,
    **cube_options: Any,
) -> FitResult:
    """Fit a measured series against the scene that describes the observation.

    A cube (`open_cube`; an `xarray.DataArray` (time, y, x)) is fitted jointly over `pixels`
    ("all", a boolean (y, x) mask, a mask file, or "DIR/detection.nc:K" for cluster K of a
    detection map; `DetectionMap.cluster(K)` gives that mask): shared vibration parameters, a gain
    (with its sign), offset and noise level per pixel, through the sufficient statistic
    (`vibinverse.imaging.joint_fit.fit_pixels`, whose options `cube_options` passes on:
    displacement, scale, band, reference).

    method: spectral | sindy | casadi | map | importance | mcmc | auto (spectral -> SINDy -> casadi
    -> emcee, each seeding the next; the modal model, and records of over 20,000 samples, by
    importance sampling of the Laplace approximation in place of emcee, emcee where its check fails).
    `chain` is the emcee checkpoint (HDF5; `resume` continues it); without it the sampler
    checkpoints to a temporary file that is removed afterwards. `workers`: the sampler's threads
    (or processes, for a likelihood that holds the GIL) and the modal order search's threads (the
    same numbers on any count); None (default): the cores this process may use, at most 4, as
    threads (`vibinverse.parallel.default_workers`).

    Without a scene (or with a `{"modal": {"modes": 2, ...}}` table) the series is fitted with the
    modal model: resonances, lines, drift and coloured noise, the order not fixed by the table
    chosen by BIC (`vibinverse.model_order`); `result.diagnostics["model_order"]` holds the
    criterion table (each step: what was tried, its BIC, kept or not; [] when the table fixes the
    order) and `result.data["components"]` the fitted components.

    Nuisance terms (`vibinverse.terms`), on a scene's model as on the modal one: `noise` ("white",
    "ar1", "1/f"), `drift` ("none", "walk", "integrated"; True is "walk"), `gain` (True or "drift": a
    multiplicative gain drift of 6 cosines; an integer: that many), `white` (False: no white sensor
    noise beside a coloured one). With a scene they go into its `nuisance` table, e.g.
    `vi.fit(series, scene, noise="ar1", drift="walk")` fits the frame's tilt beside AR(1) noise and
    a random-walk drift in one Kalman filter.
    """
    given = {"noise": noise, "drift": drift, "gain": gain, "white": white}
    nuisance = {k: v for k, v in given.items() if v is not None}
    if _is_cube(series) or pixels is not None:
        if not _is_cube(series):
            raise InputError("pixels: needs an image cube (vi.open_cube), not a single series")
        from vibinverse.imaging.joint_fit import fit_pixels

        if nuisance:
            raise InputError(f"{next(iter(nuisance))}: nuisance terms are fitted on a single series, not on a cube")
        options = {"method": method, "free": free, "model": model, "overrides": overrides, "seed": seed}
        options.update(chain=chain, resume=resume, workers=workers, max_steps=max_steps, progress=progress)
        return fit_pixels(series, "all" if pixels is None else pixels, scene, **cube_options, **options)
    if cube_options:
        raise InputError(f"{sorted(cube_options)[0]}: only for an image cube (with pixels=...)")
    return fit_series(
        series,
        scene,
        method=method,
        free=free,
        model=model,
        overrides=overrides,
        seed=seed,
        chain=chain,
        resume=resume,
        workers=workers,
        max_steps=max_steps,
        progress=progress,
        nuisance=nuisance,
    )


def detect(
    data: SeriesLike | FitResult | Any,
    scene: SceneLike | None = None,
    *,
    free: Mapping[str, Prior | str] | None = None,
    model: str | None = None,
    overrides: Sequence[str] = (),
    **map_options: Any,
) -> list[Detection] | Any:
    """Which lines the data show: the detection test of every line of the model (log-likelihood
    gain against a 5-sigma threshold with the look-elsewhere term) at the MAP, or of a fit's result.
    Without a scene: of the modal model's lines and modes, its order chosen from the data.

    An image cube (`open_cube`) gets its per-pixel detection map instead (a `DetectionMap`: maps,
    lines, pixel clusters; `vibinverse.imaging.detection_map.detection_map`, whose options
    `map_options` passes on: band, alpha, max_lines, scheduler, workers, memory)."""
    if _is_cube(data):
        from vibinverse.imaging.detection_map import detection_map

        if scene is not None or free or model or overrides:
            raise InputError("detect: a cube's detection map takes no scene, free parameters or model")
        return detection_map(data, **map_options)
    if map_options:
        raise InputError(f"{sorted(map_options)[0]}: only for an image cube")
    if isinstance(data, FitResult):
        return data.detections
    return fit(data, scene, method="casadi", free=free, model=model, overrides=overrides).detections


def simulate(
    scene: SceneLike, *, seed: int | None = None, overrides: Sequence[str] = (), rtol: float | None = DEFAULT_RTOL
) -> Observation:
    """The pixel series of a scene (time, intensity, intensity_clean, sensitivity (21)); rtol=None
    evaluates every subpixel at every sample (the dense reference)."""
    if rtol is not None and not (rtol > 0 and rtol < float("inf")):
        raise InputError(f"rtol: {rtol:g} is outside the allowed range (0, inf)")
    table = scene_table(scene, overrides)
    with scene_errors():
        return observe(scene_of(table), seed, rtol)


def simulate_cube(scene: SceneLike, nx: int, ny: int, *, seed: int | None = None, overrides: Sequence[str] = ()) -> Any:
    """An imager of nx x ny pixels over the scene's footprint (the field of view), each pixel its
    own footprint through the forward model's fast path (`forward.imager.render_cube`)."""
    from forward.imager import render_cube

    table = scene_table(scene, overrides)
    with scene_errors():
        return render_cube(scene_of(table), nx, ny, seed=seed)


def design(
    scene: SceneLike,
    *,
    vary: Sequence[str] = (),
    targets: Sequence[str] | None = None,
    threshold: float = 1e-4,
    workers: int = 1,
    overrides: Sequence[str] = (),
    progress: bool = False,
    pixels: int = 1,
) -> dict[str, Any]:
    """Design of observation over a sweep (`KEY=start:stop:num` or `KEY=a,b,c` each): sensitivity,
    line SNR and Cramer-Rao sds per configuration, ranked. Returns {"axes", "targets", "rows",
    "best", "threshold", "seconds", "pixels"} (`vibinverse.design.sweep.run_design`); `pixels`: N equal
    pixels fitted jointly (the multi-pixel Cramer-Rao bound of `vi.fit(cube, pixels=...)`)."""
    from vibinverse.design.sweep import run_design

    if workers < 1:
        raise InputError(f"--workers: {workers}; allowed range [1, inf)")
    table = scene_table(scene, overrides)
    with scene_errors():
        return run_design(
            table, list(vary), list(targets) if targets else None, threshold, workers, progress=progress, pixels=pixels
        )
