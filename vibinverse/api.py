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

import copy
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from forward.reduce import DEFAULT_RTOL
from forward.sensor import Observation, observe
from vibinverse.errors import InputError, scene_errors
from vibinverse.io.scenes import load_scene, scene_of
from vibinverse.io.series import Series, load_series, validate
from vibinverse.models import build_model
from vibinverse.posterior import Posterior
from vibinverse.priors import Prior, parse_free, parse_prior
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

SceneLike = str | Path | Mapping[str, Any]
SeriesLike = str | Path | Series


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


def _table(scene: SceneLike, overrides: Sequence[str] = ()) -> dict[str, Any]:
    if isinstance(scene, Mapping):
        from forward.validation import check_depth

        with scene_errors():
            check_depth(dict(scene), "scene")  # before copying: a deep or cyclic table would recurse
        if overrides:
            from forward.scene_file import apply_overrides

            with scene_errors():
                return apply_overrides(copy.deepcopy(dict(scene)), list(overrides))
        return copy.deepcopy(dict(scene))
    return load_scene(scene, overrides)


def _series(series: SeriesLike) -> Series:
    return series if isinstance(series, Series) else load_series(series)


def series(time: Any, intensity: Any, *, scene: Mapping[str, Any] | None = None, source: str = "array") -> Series:
    """A validated series from arrays (NaN intensities are gaps); `scene`, when the data were
    simulated from one, gives the summary its true values."""
    return validate(time, intensity, source, None if scene is None else dict(scene))


def _priors(free: Mapping[str, Prior | str] | None, table: dict[str, Any]) -> dict[str, Prior] | None:
    """Free parameters: `free` (priors or prior strings), else the scene's [infer] table, else None
    (the model's defaults)."""
    out = parse_free([], table.get("infer"))
    for name, prior in (free or {}).items():
        out[name] = prior if isinstance(prior, Prior) else parse_prior(str(prior), name)
    return out or None


def _is_modal(scene: SceneLike | None, model: str | None) -> bool:
    """No scene, a `{"modal": {...}}` table, or model="modal": the scene-less modal model."""
    from vibinverse.models.modal import ModalModel

    return scene is None or model == ModalModel.name or (isinstance(scene, Mapping) and "modal" in scene)


def _modal_table(data: Series, scene: SceneLike | None, overrides: Sequence[str]) -> tuple[dict[str, Any], Any]:
    """The modal table to fit and the order search behind it (None when the table fixes the whole
    order): `modes`, `lines`, `drift` and `noise` given in the table are kept, the others chosen
    by `vibinverse.model_order.choose_order` (stepwise BIC), whose optimum seeds the fit."""
    from vibinverse.model_order import SEARCHED, choose_order

    table = {"modal": {}} if scene is None else _table(scene, overrides)
    modal = table.get("modal")
    if modal is None:
        modal = table["modal"] = {}
    if not isinstance(modal, dict):
        raise InputError("modal: must be a table, e.g. {'modes': 2}")
    with scene_errors():
        from vibinverse.models.modal import ModalSpec

        ModalSpec.from_table(table)  # one-line errors before any work
        if all(k in modal for k in SEARCHED):
            return table, None
        order = choose_order(data, table)
    chosen = order.table()["modal"]
    table["modal"] = {**chosen, **{k: v for k, v in modal.items() if k in ("values",)}}
    if "start" in modal:
        table["modal"]["start"] = {**chosen["start"], **modal["start"]}
    return table, order


def _posterior(
    series: SeriesLike,
    scene: SceneLike | None,
    free: Mapping[str, Prior | str] | None,
    model: str | None,
    overrides: Sequence[str],
) -> tuple[Posterior, Any, bool]:
    """(posterior, the order search or None, whether the model is the modal model)."""
    from vibinverse.models.modal import ModalModel

    data = _series(series)
    order = None
    modal = _is_modal(scene, model)
    if modal:
        table, order = _modal_table(data, scene, overrides)
        model = ModalModel.name
    else:
        table = _table(scene, overrides)
    with scene_errors():
        sm = build_model(table, data, model)
        return Posterior(sm, _priors(free, table)), order, modal


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
    return _posterior(series, scene, free, model, overrides)[0]


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
    workers: int = 1,
    max_steps: int = 20000,
    progress: bool = False,
    pixels: Any = None,
    **cube_options: Any,
) -> FitResult:
    """Fit a measured series against the scene that describes the observation.

    A cube (`open_cube`; an `xarray.DataArray` (time, y, x)) is fitted jointly over `pixels`
    ("all", a boolean (y, x) mask, a mask file, or "DIR/detection.nc:K" for cluster K of a
    detection map; `DetectionMap.cluster(K)` gives that mask): shared vibration parameters, a gain
    (with its sign), offset and noise level per pixel, through the sufficient statistic
    (`vibinverse.imaging.joint_fit.fit_pixels`, whose options `cube_options` passes on:
    displacement, scale, band, reference).

    method: spectral | sindy | casadi | map | mcmc | auto (spectral -> SINDy -> casadi -> emcee,
    each seeding the next). `chain` is the emcee checkpoint (HDF5; `resume` continues it); without
    it the sampler checkpoints to a temporary file that is removed afterwards.

    Without a scene (or with a `{"modal": {"modes": 2, ...}}` table) the series is fitted with the
    modal model: resonances, lines, drift and coloured noise, the order not fixed by the table
    chosen by BIC (`vibinverse.model_order`); `result.diagnostics["model_order"]` holds the
    criterion table (each step: what was tried, its BIC, kept or not; [] when the table fixes the
    order) and `result.data["components"]` the fitted components.
    """
    from vibinverse.pipeline import run

    if _is_cube(series) or pixels is not None:
        if not _is_cube(series):
            raise InputError("pixels: needs an image cube (vi.open_cube), not a single series")
        from vibinverse.imaging.joint_fit import fit_pixels

        options = {"method": method, "free": free, "model": model, "overrides": overrides, "seed": seed}
        options.update(chain=chain, resume=resume, workers=workers, max_steps=max_steps, progress=progress)
        return fit_pixels(series, "all" if pixels is None else pixels, scene, **cube_options, **options)
    if cube_options:
        raise InputError(f"{sorted(cube_options)[0]}: only for an image cube (with pixels=...)")
    if workers < 1 or max_steps < 1:
        raise InputError("workers and max_steps: must be >= 1")
    if resume and chain is None:
        raise InputError("resume: needs the chain (checkpoint) file of the run to continue")
    post, order, modal = _posterior(series, scene, free, model, overrides)
    with scene_errors(), tempfile.TemporaryDirectory(prefix="vibinverse-") as tmp:
        result = run(
            post,
            method,
            seed=seed,
            backend=Path(chain) if chain else Path(tmp) / "chain.h5",  # no checkpoint asked for: a temporary one
            resume=resume,
            workers=workers,
            max_steps=max_steps,
            progress=progress,
        )
    if modal:
        result.diagnostics["model_order"] = [] if order is None else order.criterion
        result.data["components"] = post.model.components(result.point)
        if order is not None:
            result.timing["model_order_s"] = order.seconds
    return result


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
    table = _table(scene, overrides)
    with scene_errors():
        return observe(scene_of(table), seed, rtol)


def simulate_cube(scene: SceneLike, nx: int, ny: int, *, seed: int | None = None, overrides: Sequence[str] = ()) -> Any:
    """An imager of nx x ny pixels over the scene's footprint (the field of view), each pixel its
    own footprint through the forward model's fast path (`forward.imager.render_cube`)."""
    from forward.imager import render_cube

    table = _table(scene, overrides)
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
    table = _table(scene, overrides)
    with scene_errors():
        return run_design(
            table, list(vary), list(targets) if targets else None, threshold, workers, progress=progress, pixels=pixels
        )
