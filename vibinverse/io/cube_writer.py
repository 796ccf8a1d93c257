"""Image cubes out: a netCDF cube (float64, CF attributes, the scene and seed that make it) and an
8-bit grayscale video with a stated intensity-to-count mapping.

The video codecs were chosen by what survives a round trip (measured with PyAV 18 / FFmpeg 8):
H.264 (libx264) at qp 0 with full-range gray input decodes to the very 8-bit counts written
(FFmpeg's decoder returns the monochrome stream as yuvj420p: the luma plane, or the frame converted
to gray, is the counts; the chroma is a constant 128), and MP4 keeps each frame's time stamp as an
exact rational of the frame rate. FFV1 in Matroska is lossless too (and decodes as gray), but
Matroska stores time stamps in milliseconds, which jitters any rate that does not divide 1000 Hz.
Without full range (the default limited range), the counts come back off by up to 1 (yuv444p) or
20 (yuv420p) counts.
"""

from __future__ import annotations

import json
import logging
import math
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vibinverse.errors import InputError
from vibinverse.io.atomic import staged
from vibinverse.io.simulation import json_line

if TYPE_CHECKING:
    import xarray as xr

    from forward.imager import CubeObservation

logger = logging.getLogger(__name__)

CUBE_VARIABLE = "intensity"  # the one 3-D variable of a cube file (readers pick it without a name)
INTENSITY_UNITS = "sr-1"  # x(t) of eq. (22): radiance per unit irradiance, times sun.irradiance
QUANTIZATION_MARGIN = 0.05  # of the reference range, added below and above before mapping to counts
MAX_FPS = 1e6


@dataclass(frozen=True)
class Quantization:
    """The 8-bit mapping: count = clip(round((x - offset) / step), 0, 2^bits - 1), and back
    x = offset + step * count (to within step / 2 inside the range)."""

    offset: float
    step: float
    bits: int = 8

    @property
    def levels(self) -> int:
        return 2**self.bits - 1

    def counts(self, x: ArrayLike) -> NDArray[np.uint8]:
        """Intensities -> counts (values outside the range clip to 0 or 2^bits - 1)."""
        c = np.rint((np.asarray(x, dtype=float) - self.offset) / self.step)
        return np.clip(c, 0, self.levels).astype(np.uint8)

    def intensity(self, counts: ArrayLike) -> NDArray[np.float64]:
        """Counts -> intensities at the centre of each count's interval."""
        return self.offset + self.step * np.asarray(counts, dtype=float)

    def as_dict(self) -> dict[str, Any]:
        return {
            "offset": self.offset,
            "step": self.step,
            "bits": self.bits,
            "mapping": "intensity = offset + step * count",
        }


def quantization_for(reference: ArrayLike, margin: float = QUANTIZATION_MARGIN, bits: int = 8) -> Quantization:
    """The mapping of [min - margin * range, max + margin * range] of `reference` (e.g. the clean
    cube) onto [0, 2^bits - 1]; a constant reference gets a range of max(|value|, 1) * 1e-6."""
    ref = np.asarray(reference, dtype=float)
    if ref.size == 0 or not np.all(np.isfinite(ref)):
        raise InputError("video: the intensities to quantize must be finite and not empty")
    lo, hi = float(ref.min()), float(ref.max())
    width = hi - lo if hi > lo else max(abs(hi), 1.0) * 1e-6
    lo, hi = lo - margin * width, hi + margin * width
    return Quantization(lo, (hi - lo) / (2**bits - 1), bits)


@dataclass(frozen=True)
class VideoFormat:
    """A container and codec that keep 8-bit gray exactly."""

    container: str
    codec: str
    options: dict[str, str]
    pixel_format: str


#: video formats by file suffix
VIDEO_FORMATS: dict[str, VideoFormat] = {
    ".mp4": VideoFormat("mp4", "libx264", {"qp": "0", "preset": "medium"}, "gray"),
    ".mkv": VideoFormat("matroska", "ffv1", {}, "gray"),
}


# ---------------------------------------------------------------- netCDF


def cube_dataset(
    cube: CubeObservation, table: dict[str, Any] | None = None, seed: int | None = None, version: str = ""
) -> xr.Dataset:
    """The cube as an xarray Dataset: `intensity` (time, y, x) float64 with CF units and long
    names, time in s, x and y the pixel centres in m, each surface's coverage and the per-pixel
    sensitivity (eq. 21) as 2-D variables, and in the attributes the scene table (JSON) and the
    seed, so that the truth can be re-made (`forward.imager.render_cube`)."""
    import xarray as xr

    dims = ("time", "y", "x")
    coords = {
        "time": ("time", cube.time, {"units": "s", "long_name": "time since the start of the record", "axis": "T"}),
        "y": ("y", cube.y, {"units": "m", "long_name": "pixel centre, ground y", "axis": "Y"}),
        "x": ("x", cube.x, {"units": "m", "long_name": "pixel centre, ground x", "axis": "X"}),
    }
    data = {
        CUBE_VARIABLE: (
            dims,
            cube.intensity,
            {"units": INTENSITY_UNITS, "long_name": "pixel intensity x(t) (eq. 22), with sensor noise"},
        ),
        "sensitivity": (("y", "x"), cube.sensitivity, {"units": "1", "long_name": "sensitivity S (eq. 21)"}),
    }
    for name, cov in cube.coverage.items():
        data[coverage_variable(name, data)] = (
            ("y", "x"),
            cov,
            {"units": "1", "long_name": f"fraction of the pixel on {name}", "surface": name},
        )
    g = cube.grid
    attrs = {
        "Conventions": "CF-1.8",
        "title": str((table or {}).get("title", "")),
        "source": f"vibinverse {version} simulate --image".replace("  ", " "),
        "scene": json_line(table or {}),
        "seed": "none" if seed is None else int(seed),
        "fs": float(cube.fs),
        "field_of_view": [float(g.x_edges[0]), float(g.x_edges[-1]), float(g.y_edges[0]), float(g.y_edges[-1])],
        "subpixels": int(g.subpixels),
        "rtol": "dense" if cube.rtol is None else float(cube.rtol),
    }
    return xr.Dataset(data, coords=coords, attrs=attrs)


def coverage_variable(surface: str, taken: Iterable[str] = ()) -> str:
    """The netCDF variable of a surface's coverage: coverage_NAME, with every character that is not
    a letter, digit or underscore replaced by "_" (and a number appended if that name is taken)."""
    base = "coverage_" + re.sub(r"\W", "_", surface, flags=re.ASCII)
    taken = set(taken)
    name, k = base, 1
    while name in taken:
        name, k = f"{base}_{k}", k + 1
    return name


def write_cube_netcdf(
    path: str | Path,
    cube: CubeObservation,
    table: dict[str, Any] | None = None,
    seed: int | None = None,
    version: str = "",
) -> Path:
    """Write `cube_dataset(cube, table, seed)` to a netCDF-4 file, atomically (a temporary name
    beside `path`, renamed when complete)."""
    path = Path(path)
    ds = cube_dataset(cube, table, seed, version)
    with staged([path]) as (tmp,):
        ds.to_netcdf(tmp, engine="h5netcdf")
    return path


# ---------------------------------------------------------------- video


def write_video(
    path: str | Path,
    frames: ArrayLike,
    fps: float,
    *,
    quantization: Quantization | None = None,
    metadata: dict[str, Any] | None = None,
    suffix: str | None = None,
) -> Quantization | None:
    """Write frames (T, ny, nx) as an 8-bit grayscale video at `fps` frames per second (the
    container's nominal rate; frame i is stamped i / fps exactly), atomically.

    Float frames are mapped to counts by `quantization` (default `quantization_for(frames)`);
    uint8 frames are written as they are (returns None then). The mapping and `metadata` go into
    the container's comment tag as JSON. The format follows `suffix` (default: the path's):
    .mp4 (H.264, lossless) or .mkv (FFV1). Frame row i is cube row i (y[i]), as the cube is
    stored: a player shows y growing downwards."""
    path = Path(path)
    fmt = VIDEO_FORMATS.get((suffix or path.suffix).lower())
    if fmt is None:
        raise InputError(f"video: {path.name}: unknown video suffix; allowed: {', '.join(VIDEO_FORMATS)}")
    if not (isinstance(fps, (int, float)) and math.isfinite(fps) and 0 < fps <= MAX_FPS):
        raise InputError(f"--video-fps: {fps!r} is outside the allowed range (0, {MAX_FPS:g}]")
    arr = np.asarray(frames)
    if arr.ndim != 3 or 0 in arr.shape:
        raise InputError(f"video: frames must be a non-empty (time, y, x) array, got shape {arr.shape}")
    if arr.dtype == np.uint8:
        counts, quantization = arr, None
    else:
        quantization = quantization or quantization_for(arr)
        if not np.all(np.isfinite(arr)):
            raise InputError("video: the frames have non-finite intensities; they cannot be quantized")
        counts = quantization.counts(arr)
    comment = dict(metadata or {})
    comment["fps"] = float(fps)
    if quantization is not None:
        comment["quantization"] = quantization.as_dict()
    with staged([path]) as (tmp,):
        _encode(tmp, counts, Fraction(fps).limit_denominator(100000), fmt, json.dumps(comment, allow_nan=False))
    logger.debug(f"wrote {path}: {counts.shape[0]} frames of {counts.shape[2]} x {counts.shape[1]} at {fps:g} fps")
    return quantization


def _encode(path: Path, counts: NDArray[np.uint8], rate: Fraction, fmt: VideoFormat, comment: str) -> None:
    import av

    try:
        with av.open(str(path), "w", format=fmt.container) as out:
            out.metadata["comment"] = comment
            stream = out.add_stream(fmt.codec, rate=rate, options=dict(fmt.options))
            stream.width, stream.height = counts.shape[2], counts.shape[1]
            stream.pix_fmt = fmt.pixel_format
            stream.codec_context.color_range = 2  # full range (JPEG): gray 0..255 stays 0..255
            for frame in counts:
                out.mux(stream.encode(av.VideoFrame.from_ndarray(np.ascontiguousarray(frame), format="gray")))
            out.mux(stream.encode())
    except (av.FFmpegError, ValueError) as exc:
        raise InputError(f"video: {fmt.codec} in {fmt.container} failed: {str(exc).splitlines()[0]}") from None


# ---------------------------------------------------------------- quick look


def plot_cube(
    path: str | Path,
    cube: CubeObservation,
    outlines: Sequence[tuple[str, tuple[float, float], tuple[float, float]]] = (),
    title: str = "",
) -> None:
    """The mean frame (ground x, y in m) with the outlines (name, x range, y range) of the surfaces."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    g = cube.grid
    fig, ax = plt.subplots(figsize=(6.4, 5.4), constrained_layout=True)
    mesh = ax.pcolormesh(g.x_edges, g.y_edges, cube.intensity.mean(axis=0), cmap="gray", shading="flat")
    fig.colorbar(mesh, ax=ax, label=f"mean intensity ({INTENSITY_UNITS})")
    for k, (name, (x0, x1), (y0, y1)) in enumerate(outlines):
        color = f"C{(k + 1) % 10}"
        ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=False, ec=color, lw=1.5))
        ax.annotate(name, (x0, y1), xytext=(2, -2), textcoords="offset points", va="top", color=color)
    ax.set(
        xlim=(g.x_edges[0], g.x_edges[-1]),
        ylim=(g.y_edges[0], g.y_edges[-1]),
        xlabel="x (m)",
        ylabel="y (m)",
        aspect="equal",
        title=f"{title}\nmean frame, {cube.shape[2]} x {cube.shape[1]} pixels, {cube.shape[0]} samples".strip(),
    )
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)
