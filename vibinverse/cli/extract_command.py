"""`vibinverse extract INPUT -o DIR`: a region of a recording (video, Photron MRAW, TIFF stack, .npy,
netCDF or zarr cube), binned, over a frame range, written as a cube (DIR/cube.nc or DIR/cube.zarr)
and, if asked, as series CSVs that `vibinverse fit` reads: one per pixel (DIR/series/y{Y}_x{X}.csv)
or the region's mean (DIR/series.csv).

The cube streams from the input to the output chunk by chunk (dask), so a long video never sits in
memory; everything is written into a temporary directory inside DIR and moved into place at the
end, so a failed run leaves nothing behind and never a half-written file.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import re
import shutil
import tempfile
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from vibinverse.cli import ranges
from vibinverse.cli.outputs import one_line, output_dir
from vibinverse.errors import InputError

logger = logging.getLogger(__name__)

CUBE_FILES = {"netcdf": "cube.nc", "zarr": "cube.zarr"}  # --format -> the file written into DIR
SERIES_CSV, SERIES_DIR = "series.csv", "series"  # --series region, --series pixel
SERIES_HELP = {
    "none": "the cube only",
    "pixel": f"also one CSV per pixel, DIR/{SERIES_DIR}/y{{Y}}_x{{X}}.csv (source-frame indices)",
    "region": f"also DIR/{SERIES_CSV}, the mean over the region (mask or ROI) per frame",
}
MAX_PIXEL_SERIES = 100_000  # --series pixel: more files than this is a mistake (use --bin or a smaller --roi)
BLOCK_BYTES = 64 * 2**20  # pixel series are written from blocks of rows of about this size


# ------------------------------------------------------------------------------------ the parser
def _roi(text: str) -> tuple[int, int, int, int]:
    """ "x0:x1,y0:y1" -> (x0, x1, y0, y1)."""
    m = re.fullmatch(r"\s*(\d+)\s*:\s*(\d+)\s*,\s*(\d+)\s*:\s*(\d+)\s*", text)
    if not m:
        raise argparse.ArgumentTypeError(f"invalid region {text!r} (x0:x1,y0:y1, pixel indices, half-open)")
    x0, x1, y0, y1 = (int(g) for g in m.groups())
    if not (x0 < x1 and y0 < y1):
        raise argparse.ArgumentTypeError(f"empty region {text!r}; allowed: x0:x1,y0:y1 with x0 < x1 and y0 < y1")
    return x0, x1, y0, y1


def _frames(text: str) -> slice:
    """ "a:b", "a:" or ":b" -> slice(a, b)."""
    m = re.fullmatch(r"\s*(-?\d+)?\s*:\s*(-?\d+)?\s*", text)
    if not m:
        raise argparse.ArgumentTypeError(f"invalid frame range {text!r} (a:b, frame indices, half-open)")
    return slice(*(None if g is None else int(g) for g in m.groups()))


def add_extract_parser(sub: Any, parents: list) -> None:
    """Register the verb `extract` on the subparsers `sub` (each of `parents` adds its options)."""
    p = sub.add_parser(
        "extract",
        parents=parents,
        help="video or image cube -> a region as a cube (netCDF/zarr) and series CSVs",
        description="Read a recording lazily (video: .mp4 .mov .avi .mkv .webm, each frame's presentation time "
        "stamp; Photron .cih/.cihx/.mraw; TIFF stack; .npy; netCDF; zarr) and write a region of it: the cube "
        "(time, y, x) with each frame's time, and optionally series CSVs for `vibinverse fit`.",
    )
    p.add_argument("input", help="the recording or cube")
    region = p.add_argument_group("region").add_mutually_exclusive_group()
    region.add_argument(
        "--roi", type=_roi, metavar="x0:x1,y0:y1", help="pixel indices of the region, half-open (default: the frame)"
    )
    region.add_argument(
        "--mask",
        metavar="FILE",
        help="a boolean frame (.npy, or .png: non-zero is in) of the frame's shape; pixels outside become NaN",
    )
    p.add_argument("--bin", type=ranges.count, default=1, metavar="N", help="N x N mean binning (default 1: none)")
    p.add_argument("--frames", type=_frames, metavar="a:b", help="frame range, half-open (default: all)")
    timing = p.add_argument_group("time")
    timing.add_argument(
        "--fps",
        type=ranges.positive,
        metavar="HZ",
        help="the true frame rate: overrides the container's (a 600 fps capture stored as 30 fps: times scale by "
        "nominal/HZ); required for .npy, TIFF and MRAW without a rate",
    )
    timing.add_argument(
        "--line-time",
        type=ranges.real(0.0, float("inf"), low_open=False),
        metavar="SECONDS",
        help="rolling shutter: each row is exposed this much after the one above (coordinate row_offset; a "
        "pixel's time = time + row_offset)",
    )
    p.add_argument(
        "--channel",
        default="luminance",
        choices=("luminance", "r", "g", "b"),
        help="colour frames: Rec. 709 luminance or one channel (default luminance; gray frames pass through)",
    )
    p.add_argument("--variable", metavar="NAME", help="netCDF/zarr input: the 3-D variable (default: the only one)")
    p.add_argument(
        "--chunks",
        type=ranges.count,
        metavar="FRAMES",
        help="frames per chunk read (default: ~64 MB of whole frames; a video's chunks start at keyframes); for a "
        "video, a multiple of its keyframe interval decodes each frame once",
    )
    p.add_argument(
        "--series",
        default="none",
        choices=tuple(SERIES_HELP),
        help="; ".join(f"{k}: {v}" for k, v in SERIES_HELP.items()) + " (default none)",
    )
    p.add_argument("--format", default="netcdf", choices=tuple(CUBE_FILES), help="the cube's format (default netcdf)")
    p.add_argument(
        "-o",
        "--output",
        metavar="DIR",
        default="extract",
        help=f"output directory (default: extract); writes {CUBE_FILES['netcdf']} (--format netcdf) or "
        f"{CUBE_FILES['zarr']} (--format zarr), {SERIES_CSV} (--series region), "
        f"{SERIES_DIR}/y{{Y}}_x{{X}}.csv (--series pixel)",
    )
    p.set_defaults(func=cmd_extract)


# ----------------------------------------------------------------------------------- the command
def cmd_extract(args: argparse.Namespace) -> dict[str, Any]:
    """Write the region's cube (and series); returns its shape, rate and the paths written."""
    from vibinverse.io.cube import extract_region, open_cube, read_mask, sampling

    out = output_dir(args.output)
    series = SERIES_WRITERS[args.series]
    names = [CUBE_FILES[args.format], *([series[0]] if series else [])]
    _check_targets(out, names, Path(args.input))
    mask = read_mask(args.mask) if args.mask else None
    cube = open_cube(args.input, fps=args.fps, channel=args.channel, chunks=args.chunks, variable=args.variable)
    logger.info(f"input: {args.input}: {_describe(cube, sampling(cube))}")
    gop, chunk = cube.attrs.get("keyframe_interval"), max(cube.data.chunks[0])  # (videos only)
    if args.chunks is None and gop and gop > chunk:
        logger.info(
            f"input: a keyframe every {gop} frames, chunks of {chunk}: each chunk decodes from its keyframe "
            f"(up to {gop / chunk:.2g} x the frames); --chunks {gop} decodes each frame once (a region of interest "
            "keeps the memory small)"
        )
    cube = extract_region(cube, frames=args.frames, roi=args.roi, mask=mask, binning=args.bin, line_time=args.line_time)
    n_pixels = cube.sizes["y"] * cube.sizes["x"]
    if args.series == "pixel" and n_pixels > MAX_PIXEL_SERIES:
        raise InputError(
            f"--series pixel: {n_pixels} pixels would be {n_pixels} files; allowed at most {MAX_PIXEL_SERIES} "
            "(choose a smaller --roi or a larger --bin)"
        )
    info = sampling(cube)
    n_series = 0
    with _staged(out, names) as tmp:
        _write_cube(cube, tmp / names[0], args.format)
        if series:
            n_series = series[1](tmp / names[1], tmp / names[0], Path(args.input).name)
    paths = [out / n for n in names]
    logger.info(f"extract: {_describe(cube, info)}")
    logger.info(f"wrote {', '.join(map(str, paths))}" + (f" ({n_series} series)" if n_series else ""))
    attrs = cube.attrs
    return {
        "cube": str(paths[0]),
        "series": str(paths[1]) if len(paths) > 1 else None,
        "n_series": n_series,
        "shape": [int(n) for n in cube.shape],
        "dtype": str(cube.dtype),
        "units": str(attrs.get("units", "")),
        "bit_depth": int(attrs["bit_depth"]) if "bit_depth" in attrs else None,
        "fps": info["fps"],
        "irregular": info["irregular"],
        "duration": info["duration"],
        "paths": [str(p) for p in paths],
    }


def _describe(cube: Any, info: dict[str, Any]) -> str:
    nt, ny, nx = cube.shape
    rate = "one frame" if info["fps"] is None else f"median {info['fps']:.6g} fps"
    kind = "irregular stamps" if info["irregular"] else "regular stamps"
    bits = f", {cube.attrs['bit_depth']}-bit" if "bit_depth" in cube.attrs else ""
    return f"{nt} frames of {ny} x {nx} pixels over {info['duration']:.6g} s ({rate}, {kind}), {cube.dtype}{bits}"


# --------------------------------------------------------------------------------------- writing
def _write_cube(cube: Any, path: Path, fmt: str) -> None:
    """Stream the cube into `path` chunk by chunk (one pass over the input: the series are read
    back from this file, never by decoding a video twice)."""
    import dask

    ds = cube.to_dataset(name="intensity")
    ds["intensity"].attrs.pop("keyframe_interval", None)  # the input video's; the file has its own chunks
    for name in ds.variables:  # a fresh file: no chunking or codec carried over from the input
        ds[name].encoding = {}
    delayed = CUBE_WRITERS[fmt](ds, path, tuple(max(c) for c in cube.data.chunks))
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "Mean of empty slice", RuntimeWarning)  # a bin outside the mask: NaN
        warnings.filterwarnings("ignore", "invalid value encountered", RuntimeWarning)
        dask.compute(delayed)


def _to_netcdf(ds: Any, path: Path, chunks: tuple[int, ...]) -> Any:
    ds["intensity"].encoding = {"chunksizes": chunks}  # HDF5 chunks = the dask chunks: reading back per chunk
    ds["time"].encoding = {"_FillValue": None}
    return ds.to_netcdf(path, engine="h5netcdf", compute=False)


def _to_zarr(ds: Any, path: Path, chunks: tuple[int, ...]) -> Any:
    return ds.chunk({"time": chunks[0]}).to_zarr(path, mode="w", compute=False, consolidated=False)  # regular


# --format -> the delayed writer of the cube (the file name: CUBE_FILES)
CUBE_WRITERS: dict[str, Callable[[Any, Path, tuple[int, ...]], Any]] = {"netcdf": _to_netcdf, "zarr": _to_zarr}


def _times(cube: Any) -> np.ndarray:
    return np.asarray(cube["time"].values, dtype=np.float64)


def _header(cube: Any, what: str, source: str) -> list[str]:
    attrs = cube.attrs
    bits = f"; bit depth {one_line(attrs['bit_depth'])}" if "bit_depth" in attrs else ""
    units = one_line(attrs.get("units", ""))  # the input's text: one comment line whatever it holds
    lines = [f"vibinverse extract: {what} of {one_line(source)}", f"intensity units: {units}{bits}"]
    if cube["time"].attrs.get("reference"):
        lines.append(f"time: seconds since {one_line(cube['time'].attrs['reference'])} (the first frame)")
    return lines


def _write_csv(path: Path, time: np.ndarray, values: np.ndarray, header: list[str]) -> None:
    """A series in the CSV that `vibinverse.io.series.load_series` reads: '#' comments, then
    time,intensity; 17 significant digits (stamps and counts come back exactly); NaN = gap."""
    with open(path, "w", encoding="utf-8") as fh:
        fh.writelines(f"# {line}\n" for line in header)
        fh.write("time,intensity\n")
        np.savetxt(fh, np.column_stack([time, values]), delimiter=",", fmt="%.17g")


def _write_region(path: Path, cube_path: Path, source: str) -> int:
    """The mean over the region per frame of the cube written at `cube_path`; with a rolling
    shutter its time is shifted by the mean row offset of the pixels averaged."""
    from vibinverse.io.cube import open_cube

    cube = open_cube(cube_path)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "Mean of empty slice", RuntimeWarning)  # a frame all NaN: a gap
        mean = np.asarray(cube.mean(("y", "x")).values)
    per_row = np.isfinite(cube.isel(time=0).values).sum(axis=1)  # the pixels averaged, per row
    t = _times(cube)
    header = _header(cube, f"mean over the region ({int(per_row.sum())} pixels)", source)
    if "row_offset" in cube.coords and per_row.sum() > 0:
        shift = float(np.average(cube["row_offset"].values, weights=per_row))
        t = t + shift
        header.append(f"time includes the region's mean row offset {shift:.9g} s (rolling shutter)")
    _write_csv(path, t, mean, header)
    return 1


def _write_pixels(folder: Path, cube_path: Path, source: str) -> int:
    """One CSV per pixel of the cube written at `cube_path` (re-read in blocks of rows, so that
    the whole cube is never in memory); a pixel outside the mask (all NaN) gets none."""
    from vibinverse.io.cube import open_cube

    folder.mkdir()
    cube = open_cube(cube_path)
    nt, ny, nx = cube.shape
    t = _times(cube)
    offsets = cube["row_offset"].values if "row_offset" in cube.coords else np.zeros(ny)
    rows, cols = cube["row"].values, cube["col"].values
    step = max(1, BLOCK_BYTES // max(1, nt * nx * 8))
    written = 0
    for y0 in range(0, ny, step):
        block = np.asarray(cube.isel(y=slice(y0, y0 + step)).values)
        for i in range(block.shape[1]):
            iy = y0 + i
            for ix in range(nx):
                x = block[:, i, ix]
                if x.dtype.kind == "f" and np.isnan(x).all():
                    continue
                header = _header(cube, f"pixel row {rows[iy]}, column {cols[ix]}", source)
                if offsets[iy]:
                    header.append(f"time includes the row offset {offsets[iy]:.9g} s (rolling shutter)")
                _write_csv(folder / f"y{rows[iy]}_x{cols[ix]}.csv", t + offsets[iy], x, header)
                written += 1
    return written


# --series -> (the name written into DIR, its writer(path, cube_path, source) -> number of series)
SERIES_WRITERS: dict[str, tuple[str, Callable[[Path, Path, str], int]] | None] = {
    "none": None,
    "pixel": (SERIES_DIR, _write_pixels),
    "region": (SERIES_CSV, _write_region),
}


# --------------------------------------------------------------------------- -o DIR, all or nothing


def _check_targets(out: Path, names: list[str], source: Path) -> None:
    """Refuse, before any work, a target of the wrong kind (a directory where a file goes, or the
    reverse) and a target that is, or holds, the input (writing would replace it)."""
    src = source.resolve()
    for name in names:
        target = out / name
        is_dir = name in (SERIES_DIR, CUBE_FILES["zarr"])
        if target.exists() and target.is_dir() != is_dir:
            kind = "a directory" if target.is_dir() else "a file"
            raise InputError(f"-o: {target} is {kind}; remove it or choose another output directory")
        real = target.resolve()
        if real == src or real in src.parents:
            raise InputError(f"-o: {target} is the input {source}; writing it would replace the input")


@contextlib.contextmanager
def _staged(out: Path, names: list[str]) -> Iterator[Path]:
    """A temporary directory inside `out` (created with its missing parents) for the block; on
    success each of `names` in it replaces `out/name`, else everything made is removed."""
    made = [p for p in (out, *out.parents) if not p.exists()]  # deepest first
    try:
        out.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=".extract.", suffix=".part", dir=out))
    except OSError as exc:
        raise InputError(f"-o: cannot create directory {out}: {exc.strerror or exc}") from None
    try:
        yield tmp
        mode = 0o777 & ~_umask()
        for name in names:
            _replace(tmp / name, out / name, tmp, mode)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        for p in made:
            try:
                p.rmdir()
            except OSError:
                break
        raise
    shutil.rmtree(tmp, ignore_errors=True)


def _replace(src: Path, dest: Path, tmp: Path, mode: int) -> None:
    """Move `src` to `dest`; an old directory at `dest` is first moved aside into `tmp`."""
    if src.is_dir():
        os.chmod(src, mode)
        if dest.is_dir():
            os.replace(dest, tmp / f"old.{dest.name}")
    else:
        os.chmod(src, mode & 0o666)
    os.replace(src, dest)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
