"""Image cubes: any recording as one lazy `xarray.DataArray` (time, y, x) with each frame's time.

`open_cube(path)` picks a reader by the file's suffix (`READERS`, a registry: `register_reader`):
video containers (PyAV, each frame's presentation time stamp), Photron .cih/.cihx/.mraw (pyMRAW),
TIFF stacks (tifffile's zarr store), .npy (memory-mapped), netCDF and zarr (xarray). The data are
a dask array in chunks of whole frames (~64 MB by default), never read whole; integer camera
counts stay integers, with their bit depth in the attrs. Time is float64 seconds since the first
frame; irregular stamps (variable frame rate, dropped frames) are kept as they are.

Every problem is a one-line `DataError` (the file) or `InputError` (an argument).
"""

from __future__ import annotations

import logging
import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from vibinverse.errors import DataError, InputError
from vibinverse.io.file_basics import UNIFORM_RTOL, netcdf_format, positive_option
from vibinverse.io.video import (
    ChannelFrames,
    FrameSource,
    MappedFrames,
    first_line,
    need,
    npy_frames,
    scan_mraw,
    scan_tiff,
    scan_video,
)

logger = logging.getLogger(__name__)

DIMS = ("time", "y", "x")
CHUNK_BYTES = 64 * 2**20  # the default chunk: whole frames, ~64 MB of the cube as returned
#: ITU-R BT.709 weights of R, G, B (the luminance of RGB frames)
REC709 = (0.2126, 0.7152, 0.0722)
#: channel -> weights of the R, G, B planes (a registry: a new channel is a new entry)
CHANNELS: dict[str, tuple[float, float, float]] = {
    "luminance": REC709,
    "r": (1.0, 0.0, 0.0),
    "g": (0.0, 1.0, 0.0),
    "b": (0.0, 0.0, 1.0),
}
# time units of a numeric netCDF/zarr time axis (without "since": those are decoded to datetime64)
TIME_UNITS = {
    **dict.fromkeys(("s", "sec", "second", "seconds"), 1.0),
    **dict.fromkeys(("ms", "millisecond", "milliseconds"), 1e-3),
    **dict.fromkeys(("us", "\u00b5s", "microsecond", "microseconds"), 1e-6),
    **dict.fromkeys(("ns", "nanosecond", "nanoseconds"), 1e-9),
    **dict.fromkeys(("min", "minute", "minutes"), 60.0),
    **dict.fromkeys(("h", "hour", "hours"), 3600.0),
    **dict.fromkeys(("d", "day", "days"), 86400.0),
}


@dataclass(frozen=True)
class RawCube:
    """What a reader found. `data`: a FrameSource or a lazy DataArray (time, y, x[, channel]);
    `time`: seconds since the first frame, None when the file carries no stamps."""

    data: Any
    time: NDArray[np.float64] | None
    camera: bool = False  # camera counts: units "counts" and a bit depth
    nominal_fps: float | None = None
    bit_depth: int | None = None
    units: str | None = None
    reference: str | None = None  # ISO date-time of the first frame
    stored_chunk: int | None = None  # frames per stored chunk (chunks are aligned to it)
    coords: dict[str, Any] = field(default_factory=dict)
    attrs: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class CubeFormat:
    """A reader: `read(path, variable, channel)` (each uses what applies to its format);
    `directory` for formats stored as a directory (zarr)."""

    name: str
    suffixes: tuple[str, ...]
    read: Callable[[Path, str | None, str], RawCube]
    directory: bool = False


READERS: dict[str, CubeFormat] = {}


def register_reader(fmt: CubeFormat) -> None:
    """Make `open_cube` read the suffixes of `fmt` with it (lower case, with the dot)."""
    for s in fmt.suffixes:
        READERS[s.lower()] = fmt


def supported_suffixes() -> list[str]:
    return sorted(READERS)


# ----------------------------------------------------------------------------------------- open_cube
def open_cube(
    path: str | Path,
    *,
    fps: float | None = None,
    channel: str = "luminance",
    chunks: int | None = None,
    variable: str | None = None,
) -> xr.DataArray:
    """Open a recording as a lazy DataArray (time, y, x) named "intensity".

    - coord time: float64 s since the first frame (attrs units, long_name, and `reference`, the
      first frame's ISO date-time, when the file gives absolute times);
    - attrs: units ("counts" for camera data, else the file's), long_name, bit_depth (camera data),
      source (the file name), nominal_fps (the container's rate, when it has one);
    - `channel`: "luminance" or "r", "g", "b" (counts kept); gray frames pass through. The
      luminance of RGB frames is the Rec. 709 weighted sum (float64); of YUV video, the luma plane
      the encoder stored (Y', its weighted sum of R', G', B'; integer counts, exact for gray video);
    - `fps` (Hz): overrides the container's rate. With stamps, time = stamps * nominal_fps / fps
      (a 600 fps capture stored as a 30 fps file keeps its jitter); without (.npy, TIFF, MRAW with
      no rate), time = index / fps, and omitting `fps` is an InputError naming it;
    - `chunks`: frames per dask chunk (default: ~64 MB, aligned to the file's own chunks; a video's
      chunks then start at keyframes where its groups of pictures fit, so they may differ in size);
    - `variable`: the 3-D variable of a netCDF/zarr file (default: its only one).
    """
    fps = positive_option(fps, "fps", "Hz")
    if chunks is not None and (isinstance(chunks, bool) or not isinstance(chunks, (int, np.integer)) or chunks < 1):
        raise InputError(f"chunks: {chunks!r}; allowed: an integer number of frames >= 1")
    if channel not in CHANNELS:
        raise InputError(f"channel: {channel!r}; allowed: {', '.join(CHANNELS)}")
    p = Path(path)
    fmt = READERS.get(p.suffix.lower())
    if fmt is None:
        raise DataError(f"input: {p}: unknown file type {p.suffix or '(no suffix)'!r}; supported: {', '.join(READERS)}")
    _check_input(p, fmt)
    raw = fmt.read(p, variable, channel)
    return _assemble(raw, p, fps, channel, chunks)


def _check_input(p: Path, fmt: CubeFormat) -> None:
    if not p.exists():
        raise DataError(f"input: file not found: {p}")
    if fmt.directory:
        if not p.is_dir():
            raise DataError(f"input: {p} is not a directory (a {fmt.name} store is one)")
        return
    if p.is_dir():
        raise DataError(f"input: {p} is a directory, not a file")
    try:
        size = p.stat().st_size
        with open(p, "rb"):
            pass
    except OSError as exc:
        raise DataError(f"input: cannot read {p}: {exc.strerror or exc}") from None
    if size == 0:
        raise DataError(f"input: {p} is empty")


def _assemble(raw: RawCube, p: Path, fps: float | None, channel: str, chunks: int | None) -> xr.DataArray:
    shape, dtype = tuple(raw.data.shape), np.dtype(raw.data.dtype)
    if len(shape) not in (3, 4) or (len(shape) == 4 and shape[3] not in (3, 4)):
        raise DataError(
            f"input: {p}: frames of shape {shape}; a cube (time, y, x) or colour frames (time, y, x, 3|4) are needed"
        )
    if dtype.kind not in "uif":
        raise DataError(f"input: {p}: values of dtype {dtype}; real numbers are needed")
    if shape[0] == 0:
        raise DataError(f"input: {p} has no frames")
    time, nominal = _time(raw, p, shape[0], fps)
    colour = len(shape) == 4
    out_itemsize = 8 if colour and channel == "luminance" else dtype.itemsize
    frame_bytes = max(math.prod(shape[1:]) * dtype.itemsize, math.prod(shape[1:3]) * out_itemsize)
    n = chunks or _frames_per_chunk(frame_bytes, raw.stored_chunk)
    source = ChannelFrames(raw.data, CHANNELS[channel]) if colour else raw.data  # colour: only FrameSources
    data = _dask(source, n, p, regular=chunks is not None)
    if not colour and channel != "luminance":
        logger.warning(f"channel {channel!r}: {p.name} has gray frames; they pass through")
    attrs = {**raw.attrs, "long_name": "intensity", "source": p.name}
    attrs["units"] = "counts" if raw.camera else raw.units or ("counts" if dtype.kind in "ui" else "1")
    if raw.bit_depth is not None:
        attrs["bit_depth"] = int(raw.bit_depth)
    if nominal is not None:
        attrs["nominal_fps"] = float(nominal)
    if colour:
        attrs["channel"] = "luminance (Rec. 709)" if channel == "luminance" else channel
    tattrs = {"units": "s", "long_name": "time since the first frame"}
    if raw.reference:
        tattrs["reference"] = raw.reference
    coords = {"time": ("time", time, tattrs), **raw.coords}
    return xr.DataArray(data, dims=DIMS, coords=coords, name="intensity", attrs=attrs)


def _frames_per_chunk(frame_bytes: int, stored: int | None) -> int:
    n = max(1, CHUNK_BYTES // max(frame_bytes, 1))
    if stored:
        n = max(stored, n // stored * stored)
    return int(n)


def _dask(data: Any, n: int, p: Path, regular: bool) -> Any:
    """A dask array of chunks of `n` frames (or, not `regular`, the source's own choice of about
    `n`: a video's chunks start at keyframes)."""
    import dask.array as da
    from dask.base import tokenize

    if isinstance(data, FrameSource):
        times = (n,) if regular else (data.chunk_sizes(n),)
        st = p.stat()
        token = tokenize(str(p.resolve()), st.st_mtime_ns, st.st_size, data.shape, str(data.dtype), data.token, times)
        name = f"{p.name}-{token}"
        chunks = (*times, *data.shape[1:])
        return da.from_array(data, chunks=chunks, name=name, lock=False, meta=np.empty((0,) * data.ndim, data.dtype))
    return data.chunk({data.dims[0]: n, **dict.fromkeys(data.dims[1:], -1)}).data


def _time(raw: RawCube, p: Path, n: int, fps: float | None) -> tuple[NDArray[np.float64], float | None]:
    """The time coordinate (validated stamps, rescaled by `fps`) and the nominal rate."""
    nominal = raw.nominal_fps
    if raw.time is None:
        rate = fps or nominal
        if rate is None:
            raise InputError(
                f"fps: {p.name} carries no time stamps nor a frame rate; give the rate (fps=, --fps), Hz in (0, inf)"
            )
        return np.arange(n) / rate, nominal
    t = np.asarray(raw.time, dtype=np.float64)
    if t.shape != (n,):
        raise DataError(f"input: {p}: {t.size} time stamps for {n} frames")
    if not np.all(np.isfinite(t)):
        k = int(np.argmin(np.isfinite(t)))
        raise DataError(f"input: {p}: the time stamp of frame {k} is not a finite number")
    steps = np.diff(t)
    if not np.all(steps > 0):
        k = int(np.argmin(steps > 0)) + 1
        raise DataError(
            f"input: {p}: the time stamps are not strictly increasing: frame {k} at {float(t[k])!r} s after frame "
            f"{k - 1} at {float(t[k - 1])!r} s"
        )
    if fps is not None and n > 1:
        source = nominal or 1.0 / float(np.median(steps))
        t = t * (source / fps)
    return t, nominal


def sampling(cube: xr.DataArray) -> dict[str, Any]:
    """{"fps": 1 / median step (Hz), "irregular": bool, "duration": s} of a cube's time coordinate;
    irregular when a stamp lies off the regular grid by more than UNIFORM_RTOL of its step."""
    t = np.asarray(cube["time"].values, dtype=np.float64)
    if t.size < 2:
        return {"fps": None, "irregular": False, "duration": 0.0}
    step = (t[-1] - t[0]) / (t.size - 1)
    grid = t[0] + np.arange(t.size) * step
    irregular = bool(np.max(np.abs(t - grid)) > UNIFORM_RTOL * step)
    return {"fps": 1.0 / float(np.median(np.diff(t))), "irregular": irregular, "duration": float(t[-1] - t[0])}


# ------------------------------------------------------------------------------------------ extract
def extract_region(
    cube: xr.DataArray,
    *,
    frames: slice | None = None,
    roi: tuple[int, int, int, int] | None = None,
    mask: NDArray[np.bool_] | None = None,
    binning: int = 1,
    line_time: float | None = None,
) -> xr.DataArray:
    """A part of a cube, still lazy: frames `frames` (time re-counted from the first one kept),
    `roi` = (x0, x1, y0, y1) half-open pixel indices or `mask` (a boolean frame: cropped to its
    bounding box, pixels outside become NaN), `binning` x `binning` mean binning (counts become float64,
    their bit_depth kept; rows and columns that do not fill a bin are dropped) and `line_time` (s)
    of a rolling shutter: coordinate row_offset = row * line_time, each pixel's time being
    time + row_offset[y]. Coordinates "row" and "col" keep each pixel's index in the source frame
    (the first pixel of a bin)."""
    if roi is not None and mask is not None:
        raise InputError("roi and mask: give one of them, not both")
    nt, ny, nx = cube.shape
    cube = _with_source_indices(cube)
    if frames is not None:
        cube = _frames(cube, frames, nt)
    if line_time is not None:
        cube = _line_time(cube, line_time)
    if roi is not None:
        x0, x1, y0, y1 = roi
        if not (0 <= x0 < x1 <= nx and 0 <= y0 < y1 <= ny):
            raise InputError(f"roi: x {x0}:{x1}, y {y0}:{y1}; allowed 0 <= x0 < x1 <= {nx}, 0 <= y0 < y1 <= {ny}")
        cube = cube.isel(y=slice(y0, y1), x=slice(x0, x1))
    if mask is not None:
        cube = _masked(cube, np.asarray(mask), (ny, nx))
    side = min(cube.shape[1:])
    if isinstance(binning, bool) or not (isinstance(binning, (int, np.integer)) and 1 <= binning <= side):
        raise InputError(f"binning: {binning!r}; allowed an integer in [1, {side}] (the region's smaller side)")
    if binning > 1:
        cube = _binned(cube, int(binning))
    return cube


def read_mask(path: str | Path) -> NDArray[np.bool_]:
    """A boolean frame from a .npy array or a .png image (true where non-zero; colour: any of R,
    G, B non-zero)."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"mask: file not found: {p}" if not p.exists() else f"mask: {p} is not a file")
    suffix = p.suffix.lower()
    try:
        if suffix == ".npy":
            arr = np.load(p, allow_pickle=False)
        elif suffix == ".png":
            from PIL import Image

            with Image.open(p) as img:
                arr = np.asarray(img)
        else:
            raise InputError(f"mask: {p}: unknown file type {suffix!r}; allowed .npy or .png")
    except (OSError, ValueError, EOFError) as exc:
        raise DataError(f"mask: cannot read {p}: {first_line(exc)}") from None
    if arr.ndim == 3:  # colour (and alpha): a pixel is in the mask when a colour channel is non-zero
        arr = arr[..., : 1 if arr.shape[2] <= 2 else 3].max(axis=2)  # L, LA: the gray; RGB(A): the colours
    if arr.ndim != 2:
        raise InputError(f"mask: {p} holds an array of shape {arr.shape}; a 2-D frame is needed")
    if arr.dtype.kind not in "biuf":
        raise InputError(f"mask: {p} holds {arr.dtype}; booleans (or 0 and 1) are needed")
    return arr != 0


def _with_source_indices(cube: xr.DataArray) -> xr.DataArray:
    new = {}
    for name, dim in (("row", "y"), ("col", "x")):
        if name not in cube.coords:
            new[name] = (dim, np.arange(cube.sizes[dim]), {"long_name": f"{name} index in the source frame"})
    return cube.assign_coords(new)


def _frames(cube: xr.DataArray, frames: slice, n: int) -> xr.DataArray:
    import pandas as pd

    if frames.step not in (None, 1):
        raise InputError(f"frames: step {frames.step}; frames are a contiguous range a:b")
    start, stop, _ = frames.indices(n)
    if start >= stop:
        raise InputError(f"frames: {frames.start}:{frames.stop} selects no frame; allowed a:b with 0 <= a < b <= {n}")
    cube = cube.isel(time=slice(start, stop))
    t = cube["time"]
    attrs = dict(t.attrs)
    t0 = float(t.values[0])
    if attrs.get("reference") and t0:
        attrs["reference"] = (pd.Timestamp(attrs["reference"]) + pd.Timedelta(seconds=t0)).isoformat()
    cube = cube.assign_coords(time=("time", t.values - t0, attrs))
    cube.attrs["first_frame"] = int(cube.attrs.get("first_frame", 0)) + start
    return cube


def _line_time(cube: xr.DataArray, line_time: float) -> xr.DataArray:
    if isinstance(line_time, bool) or not (math.isfinite(line_time) and line_time >= 0):
        raise InputError(f"line_time: {line_time!r} s; allowed range [0, inf)")
    rows = cube["row"].values
    info = sampling(cube)
    if info["fps"] is not None and line_time * (int(rows.max()) + 1) > 1.0 / info["fps"]:
        limit = 1.0 / info["fps"] / (int(rows.max()) + 1)
        raise InputError(
            f"line_time: {line_time:g} s x {int(rows.max()) + 1} rows exceeds the frame interval "
            f"{1.0 / info['fps']:g} s; allowed range [0, {limit:g}] s"
        )
    attrs = {"units": "s", "long_name": "exposure delay of the row (rolling shutter): pixel time = time + row_offset"}
    return cube.assign_coords(row_offset=("y", rows * float(line_time), attrs))


def _masked(cube: xr.DataArray, mask: np.ndarray, frame: tuple[int, int]) -> xr.DataArray:
    if mask.shape != frame:
        raise InputError(f"mask: shape {mask.shape}; the frame's shape {frame} (rows, columns) is needed")
    if mask.dtype.kind not in "biuf":
        raise InputError(f"mask: values of dtype {mask.dtype}; booleans (or 0 and 1) are needed")
    mask = mask.astype(bool)
    if not mask.any():
        raise InputError("mask: selects no pixel (all false)")
    ys, xs = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    box = (slice(ys[0], ys[-1] + 1), slice(xs[0], xs[-1] + 1))
    cube = cube.isel(y=box[0], x=box[1])
    keep = xr.DataArray(mask[box], dims=("y", "x"))
    out = cube.astype(np.float64).where(keep)
    out.attrs = dict(cube.attrs)
    return out


def _binned(cube: xr.DataArray, n: int) -> xr.DataArray:
    ny, nx = cube.sizes["y"], cube.sizes["x"]
    if ny % n or nx % n:
        logger.info(f"bin {n}: the last {ny % n} rows and {nx % n} columns do not fill a bin and are dropped")
    # a bin wholly outside a mask is NaN (numpy warns "Mean of empty slice" when it is computed)
    out = cube.coarsen(y=n, x=n, boundary="trim", coord_func={"row": "min", "col": "min"}).mean(keep_attrs=True)
    out.attrs["binning"] = n
    return out


# -------------------------------------------------------------------------------------------- readers
def _read_video(p: Path, variable: str | None, channel: str) -> RawCube:
    _no_variable(variable, p)
    scan = scan_video(p, channel)
    logger.debug(f"{p}: {scan.codec}, {scan.frames.shape[0]} frames, nominal {scan.nominal_fps} fps")
    keys = np.flatnonzero(scan.frames.keyframe)
    interval = int(np.median(np.diff(keys))) if keys.size > 1 else scan.frames.shape[0]
    attrs = {"codec": scan.codec, "keyframe_interval": interval}  # frames from one keyframe to the next
    if scan.luma:
        attrs["channel"] = "luminance (the video's luma plane Y')"
    return RawCube(
        scan.frames, scan.time, camera=True, nominal_fps=scan.nominal_fps, bit_depth=scan.bit_depth, attrs=attrs
    )


def _read_mraw(p: Path, variable: str | None, channel: str) -> RawCube:
    _no_variable(variable, p)
    scan = scan_mraw(p)
    return RawCube(scan.frames, None, camera=True, nominal_fps=scan.nominal_fps, bit_depth=scan.bit_depth)


def _read_npy(p: Path, variable: str | None, channel: str) -> RawCube:
    _no_variable(variable, p)
    frames = npy_frames(p)
    bits = frames.dtype.itemsize * 8 if frames.dtype.kind in "ui" else None
    return RawCube(frames, None, bit_depth=bits)


def _read_tiff(p: Path, variable: str | None, channel: str) -> RawCube:
    _no_variable(variable, p)
    scan = scan_tiff(p)
    camera = scan.frames.dtype.kind in "ui"
    return RawCube(scan.frames, None, camera=camera, nominal_fps=scan.nominal_fps, bit_depth=scan.bit_depth)


def _no_variable(variable: str | None, p: Path) -> None:
    if variable is not None:
        raise InputError(f"variable: {variable!r} applies to netCDF and zarr files, not {p.suffix}")


def _read_netcdf(p: Path, variable: str | None, channel: str) -> RawCube:
    hdf5 = netcdf_format(p, "input") == "hdf5"
    return _read_xarray(p, variable, "h5netcdf" if hdf5 else "scipy", mapped if hdf5 else None)


def mapped(p: Path, name: str) -> MappedFrames | None:
    """An HDF5 (netCDF-4) variable's values mapped from the file (`MappedFrames`, in its stored
    order), when HDF5 keeps it contiguous and uncompressed and xarray would not transform its
    values (no scale or offset; no fill value to mask, or NaN in a float variable, which masks to
    itself): the values xarray reads, without the per-read overhead and copy of its HDF5 stack (a
    detection reads every pixel twice). None otherwise."""
    import h5py

    with h5py.File(p, "r") as f:
        ds = f.get(name)
        if not isinstance(ds, h5py.Dataset) or ds.chunks is not None or ds.compression is not None:
            return None
        offset = ds.id.get_offset()
        attrs = set(ds.attrs)
        if offset is None or attrs & {"scale_factor", "add_offset", "missing_value", "valid_range", "valid_min"}:
            return None
        if "_FillValue" in attrs:
            fill = np.asarray(ds.attrs["_FillValue"])
            if ds.dtype.kind != "f" or not np.all(np.isnan(fill)):
                return None
        if ds.dtype.kind not in "uif" or (ds.dtype.byteorder not in "=<|" and ds.dtype.itemsize > 1):
            return None
        shape, dtype = ds.shape, ds.dtype
    return MappedFrames(p, int(offset), tuple(shape), dtype)


def _read_zarr(p: Path, variable: str | None, channel: str) -> RawCube:
    need("zarr", "reading zarr")
    return _read_xarray(p, variable, "zarr")


def _read_xarray(
    p: Path, variable: str | None, engine: str, mapper: Callable[[Path, str], Any] | None = None
) -> RawCube:
    try:
        with warnings.catch_warnings():  # a store without consolidated metadata is read all the same
            warnings.filterwarnings("ignore", "Failed to open Zarr store with consolidated metadata")
            ds = xr.open_dataset(p, engine=engine, decode_timedelta=False)
    except (OSError, ValueError, TypeError, KeyError, RuntimeError) as exc:
        raise DataError(f"input: cannot read {p}: {first_line(exc)}") from None
    cubes = [str(k) for k, v in ds.data_vars.items() if v.ndim == 3]
    if variable is not None:
        if variable not in ds.data_vars:
            raise InputError(f"variable: {p} has no variable {variable!r}; its 3-D variables: {', '.join(cubes)}")
        name = variable
    elif len(cubes) == 1:
        name = cubes[0]
    else:
        what = "no 3-D variable" if not cubes else f"several 3-D variables ({', '.join(cubes)}); choose one (variable=)"
        ranks = ", ".join(f"{k} {tuple(v.shape)}" for k, v in ds.data_vars.items())
        raise DataError(f"input: {p} has {what}" + ("" if cubes else f"; its variables: {ranks or 'none'}"))
    var = ds[name]
    if var.ndim != 3:
        raise DataError(f"input: {p}: variable {name!r} has shape {tuple(var.shape)}; a cube (time, y, x) is needed")
    direct = mapper(p, name) if mapper is not None else None
    tdim = _time_dim(var)
    ydim, xdim = (d for d in var.dims if d != tdim)
    if direct is not None and direct.shape == var.shape:  # the map, its axes as (time, y, x)
        direct = direct.with_axes(tuple(var.dims.index(d) for d in (tdim, ydim, xdim)))
    else:
        direct = None
    tcoord = next((var[c] for c in ("time", tdim) if c in var.coords and var[c].dims == (tdim,)), None)
    time, reference = _seconds(tcoord, p) if tcoord is not None else (None, None)
    var = var.drop_vars([c for c in {"time", tdim} if c in var.coords]).transpose(tdim, ydim, xdim)
    var = var.rename({d: n for d, n in zip((tdim, ydim, xdim), DIMS) if d != n})
    attrs = {k: v for k, v in var.attrs.items() if k not in ("units", "long_name", "source")}
    preferred = var.encoding.get("preferred_chunks", {}).get(tdim)
    stored = preferred or (var.encoding.get("chunksizes") or var.encoding.get("chunks") or (None,))[0]
    coords = {str(k): c.variable for k, c in var.coords.items()}
    return RawCube(
        direct if direct is not None else var.variable,
        time,
        nominal_fps=attrs.pop("nominal_fps", None),
        bit_depth=attrs.pop("bit_depth", None),
        units=str(var.attrs["units"]) if "units" in var.attrs else None,
        reference=reference,
        stored_chunk=int(stored) if stored else None,
        coords=coords,
        attrs=attrs,
    )


def _time_dim(var: xr.DataArray) -> str:
    """The time dimension: "time", else the one dimension whose coordinate holds date-times, time
    spans or numbers with time units, else the first."""
    if "time" in var.dims:
        return "time"
    timed = [
        d
        for d in var.dims
        if d in var.coords
        and (
            var[d].dtype.kind in "Mm"
            or str(var[d].attrs.get("units", "")).strip().lower() in TIME_UNITS
            or " since " in str(var[d].encoding.get("units", ""))
        )
    ]
    return str(timed[0]) if len(timed) == 1 else str(var.dims[0])


def _seconds(coord: xr.DataArray, p: Path) -> tuple[NDArray[np.float64], str | None]:
    """Seconds since the first stamp of a time coordinate (datetime64, timedelta64 or numbers with
    time units) and the ISO date-time of the first stamp when the coordinate gives one."""
    import pandas as pd

    v = coord.values
    if v.size == 0:
        return np.zeros(0), None
    if v.dtype.kind == "M":
        if np.isnat(v).any():
            raise DataError(f"input: {p}: the time stamp of frame {int(np.argmax(np.isnat(v)))} is missing (NaT)")
        return (v - v[0]) / np.timedelta64(1, "s"), pd.Timestamp(v[0]).isoformat()
    if v.dtype.kind == "m":
        return (v - v[0]) / np.timedelta64(1, "s"), None
    if v.dtype.kind not in "uif":
        raise DataError(f"input: {p}: the time coordinate holds {v.dtype}; numbers or date-times are needed")
    units = str(coord.attrs.get("units", "s")).strip()
    if units.lower() not in TIME_UNITS:
        raise DataError(f"input: {p}: time units {units!r}; allowed: {', '.join(sorted(set(TIME_UNITS)))}")
    t = v.astype(np.float64) * TIME_UNITS[units.lower()]
    reference = coord.attrs.get("reference")
    if reference is not None and t[0] != 0:
        reference = (pd.Timestamp(str(reference)) + pd.Timedelta(seconds=float(t[0]))).isoformat()
    return t - t[0], None if reference is None else str(reference)


for _fmt in (
    CubeFormat("video", (".mp4", ".mov", ".avi", ".mkv", ".webm"), _read_video),
    CubeFormat("Photron MRAW", (".cih", ".cihx", ".mraw"), _read_mraw),
    CubeFormat("TIFF stack", (".tif", ".tiff"), _read_tiff),
    CubeFormat("numpy", (".npy",), _read_npy),
    CubeFormat("netCDF", (".nc",), _read_netcdf),
    CubeFormat("zarr", (".zarr",), _read_zarr, directory=True),
):
    register_reader(_fmt)
