"""`vibinverse fit CUBE --pixels SELECTION`: the joint fit of many pixels of an image cube or video
(`vibinverse.imaging.joint_fit.fit_pixels`), written like a single fit (result.nc, summary.json)
plus the per-pixel table (pixels.csv). `cmd_fit` (vibinverse.cli.commands) calls in here when
--pixels is given; the options are added to the fit parser by `add_cube_options`."""

from __future__ import annotations

import argparse
import csv
import logging
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

from vibinverse.cli import ranges
from vibinverse.errors import InputError
from vibinverse.io.file_basics import csv_cell

if TYPE_CHECKING:
    from vibinverse.result import FitResult

logger = logging.getLogger("vibinverse")

PIXELS = "pixels.csv"  # the per-pixel table in -o DIR
CUBE_OPTIONS = (
    "displacement", "scale", "band", "reference", "fps", "channel", "variable", "sources"
)  # fmt: skip  # apply with --pixels only
SERIES_OPTIONS = ("time_column", "value_column", "fs")  # apply to a series table only


def add_cube_options(parser: argparse.ArgumentParser) -> None:
    """The fit parser's options of a cube fit (--pixels and what it needs)."""
    parser.add_argument(
        "--pixels",
        metavar="SELECTION",
        help="DATA is an image cube or video (netCDF, zarr, .npy, TIFF, Photron, video files): fit these pixels "
        "jointly, 'all', a mask (.npy or .png of the frame's shape, nonzero = selected) or DIR/detection.nc:K "
        f"(cluster K of `vibinverse detect`); also writes {PIXELS} (gain, sign, offset, noise, SNR share per pixel)",
    )
    parser.add_argument(
        "--displacement",
        choices=("x", "y"),
        help="with --pixels: optical flow, each pixel's gain is -dI/dx (or -dI/dy) of the mean frame, so that the "
        "signal and its amplitudes are a displacement in pixels (edges moving across pixels, ground-level video)",
    )
    parser.add_argument(
        "--scale", type=ranges.positive, metavar="METRES_PER_PIXEL", help="with --displacement: displacements in metres"
    )
    parser.add_argument(
        "--band",
        metavar="FMIN:FMAX",
        type=_band,
        help="with --pixels: the band (Hz) where the gains are seeded (default: the strongest line or resonance "
        "above 3 cycles per record)",
    )
    parser.add_argument(
        "--reference",
        metavar="Y,X",
        type=_pixel,
        help="with --pixels: the pixel whose gain is +1 and offset 0, in whose units the combined series is (with "
        "--scene: the pixel the scene describes; default: the pixel of the largest SNR share)",
    )
    parser.add_argument(
        "--fps", type=ranges.positive, metavar="HZ", help="with --pixels: the cube's frame rate, overriding the file's"
    )
    parser.add_argument(
        "--channel",
        choices=("luminance", "r", "g", "b"),
        default=None,
        help="with --pixels: the colour channel of a colour video (default: luminance)",
    )
    parser.add_argument("--variable", metavar="NAME", help="with --pixels: the cube's variable in a netCDF/zarr file")
    parser.add_argument(
        "--sources",
        type=ranges.count,
        metavar="K",
        help="with --pixels: K >= 2 sources (tilt modes, drive lines) seen by the pixels in different mixtures, "
        "fitted jointly: per source a gain column (gain_0, gain_1, ... in "
        f"{PIXELS}) from its own band (the K strongest separated peaks, or the lines of a detection.nc:K "
        "cluster), and one multi-output fit of the K combined series, each source a mode or a line "
        "(default 1: one shared signal); K from 1 to the number of selected pixels",
    )


def _band(text: str) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in text.split(":"))
    except ValueError:
        lo = hi = math.nan
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo < hi):
        raise argparse.ArgumentTypeError(
            f"invalid band {text[:40]!r} (FMIN:FMAX in Hz, 0 <= FMIN < FMAX, finite, e.g. 2:8)"
        ) from None
    return lo, hi


def _pixel(text: str) -> tuple[int, int]:
    try:
        y, x = (int(v) for v in text.split(","))
    except ValueError:
        y = x = -1
    if not (0 <= y < ranges.MAX_COUNT and 0 <= x < ranges.MAX_COUNT):
        raise argparse.ArgumentTypeError(
            f"invalid pixel {text[:40]!r} (Y,X: row and column indices >= 0, e.g. 3,7)"
        ) from None
    return y, x


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def check_series_options(args: argparse.Namespace, allow: tuple[str, ...] = ()) -> None:
    """A fit of one series refuses the cube's options but `allow` (one line naming the first)."""
    for name in CUBE_OPTIONS:
        if name not in allow and getattr(args, name, None) is not None:
            raise InputError(f"{_flag(name)}: applies to a cube fit; give --pixels (all, a mask or detection.nc:K)")


def selection_file(pixels: str) -> Path | None:
    """The file --pixels names (a mask or a detection map), None for 'all'."""
    from vibinverse.imaging.pixels import parse_cluster

    if pixels == "all":
        return None
    cluster = parse_cluster(pixels)
    return cluster[0] if cluster is not None else Path(pixels)


def fit_cube(args: argparse.Namespace, table: dict[str, Any], options: dict[str, Any]) -> FitResult:
    """Open the cube (`vibinverse.io.cube.open_cube`) and fit the selected pixels jointly with the
    fit's table and options."""
    from vibinverse.imaging.joint_fit import fit_pixels
    from vibinverse.io.cube import open_cube

    for name in SERIES_OPTIONS:
        if getattr(args, name, None) is not None:
            raise InputError(f"{_flag(name)}: applies to a series table; a cube's frame rate is --fps")
    if args.scale is not None and args.displacement is None:
        raise InputError("--scale: metres per pixel apply to a displacement fit; give --displacement x or y")
    cube = open_cube(args.data, fps=args.fps, channel=args.channel or "luminance", variable=args.variable)
    nt, ny, nx = (cube.sizes[d] for d in ("time", "y", "x"))
    logger.info(f"cube: {nt} frames of {ny} x {nx} pixels ({cube.dtype})")
    result = fit_pixels(
        cube,
        args.pixels,
        table,
        displacement=args.displacement,
        scale=args.scale,
        band=args.band,
        reference=args.reference,
        sources=1 if args.sources is None else args.sources,
        **options,
    )
    return result


def write_pixels_csv(path: Path, result: FitResult) -> None:
    """The per-pixel table (`result.data["pixels"]`) as CSV, the gain convention in '#' lines."""
    from vibinverse.imaging.joint_fit import TABLE_COLUMNS

    table = result.data["pixels"]
    d = result.diagnostics
    columns = list(table) if "gain_0" in table else list(TABLE_COLUMNS)  # several sources: gain_0, gain_1, ...
    with open(path, "w", newline="") as fh:
        fh.write(f"# gains: {d.get('gain_convention')}\n")
        if d.get("reference_pixel") is not None:
            ref = d["reference_pixel"]
            where = ", ".join(str(tuple(p)) for p in ref) if ref and isinstance(ref[0], list) else str(tuple(ref))
            fh.write(f"# reference pixel (y, x): {where}\n")
        if "gain_0" in table:
            kinds = d.get("source_kinds") or []
            bands = d.get("source_bands_hz") or []
            for j, (kind, band) in enumerate(zip(kinds, bands)):
                fh.write(f"# source {j}: {kind}, gains from the band {band[0]:.6g}-{band[1]:.6g} Hz\n")
            fh.write("# sigma: white-noise sd per pixel; snr_share_j: G_ij^2 / sigma_i^2 / its sum over pixels\n")
        else:
            fh.write("# sigma: white-noise sd per pixel; snr_share: g^2 / sigma^2 / sum of it (sums to 1)\n")
        writer = csv.writer(fh)
        writer.writerow(columns)
        for row in zip(*(table[c] for c in columns)):
            writer.writerow([repr(v) if isinstance(v, float) else csv_cell(v) for v in row])
