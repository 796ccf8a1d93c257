"""`vibinverse detect CUBE -o DIR`: which pixels of a video or image cube carry a vibration.

Writes DIR/detection.nc (per-pixel maps: peak frequency, SNR and false-alarm probability; the SNR
map at each detected line; `cluster` (y, x), 0 = none, k = cluster k, which `vibinverse fit CUBE
--pixels DIR/detection.nc:K` reads), DIR/detection.png (the map over the mean frame, clusters
outlined) and DIR/lines.csv (one row per line and cluster). The work runs chunk by chunk on Dask:
local threads (`--workers`), or an existing dask.distributed cluster (`--scheduler ADDRESS`);
`--memory` bounds what is in flight. See `vibinverse.imaging.detection_map` for the statistics.
"""

from __future__ import annotations

import argparse
import logging
import math
import re
import sys
from typing import Any

from vibinverse.cli import ranges
from vibinverse.cli.outputs import created, output_dir

logger = logging.getLogger("vibinverse")

DETECTION, DETECTION_PLOT, LINES = "detection.nc", "detection.png", "lines.csv"  # fixed names in -o DIR
DEFAULT_OUTPUT = "detect"
MAX_MEMORY = 2**50  # --memory: 1 PiB
DEFAULT_MEMORY = "512MiB"  # vibinverse.imaging.detection_map.DEFAULT_MEMORY, as the option shows it
CHANNELS = ("luminance", "r", "g", "b")  # vibinverse.io.cube's channels
LOGGED_CLUSTERS = 5  # the log names a line's strongest clusters; lines.csv has them all


# ------------------------------------------------------------------------------------ the parser
def parse_band(text: str) -> tuple[float, float]:
    """ "fmin:fmax" in Hz; either side may be left out ("5:" up to Nyquist, ":40" from 0)."""
    m = re.fullmatch(r"\s*([^:\s]*)\s*:\s*([^:\s]*)\s*", text)
    try:
        if not m:
            raise ValueError
        lo = float(m.group(1)) if m.group(1) else 0.0
        hi = float(m.group(2)) if m.group(2) else float("inf")
        if not (math.isfinite(lo) and lo >= 0) or math.isnan(hi):  # the order: against Nyquist, later
            raise ValueError
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"invalid band {text[:40]!r} (fmin:fmax in Hz, fmin >= 0, e.g. 1:40 or 5:)"
        ) from None
    return lo, hi


def parse_memory(text: str) -> int:
    """A size such as 512MB, 2GiB or 1e9 (bytes), by dask's parser (MB = 10^6, MiB = 2^20 bytes)."""
    from dask.utils import parse_bytes

    try:
        value = int(parse_bytes(text))
    except (ValueError, TypeError, OverflowError):
        raise argparse.ArgumentTypeError(f"invalid size {text[:40]!r} (e.g. 512MB, 2GiB; in [1 byte, 1 PiB])") from None
    if not 0 < value <= MAX_MEMORY:
        raise argparse.ArgumentTypeError(f"invalid size {text[:40]!r} (more than 0 bytes, at most 1 PiB)")
    return value


def add_detect_parser(sub: Any, parents: list) -> None:
    """Register the verb `detect` on the subparsers `sub` (each of `parents` adds its options)."""
    p = sub.add_parser(
        "detect",
        parents=parents,
        help="video or image cube -> per-pixel detection map, detected lines and the pixel clusters carrying them",
        description="For every pixel, the whitened periodogram (valid for irregular frame times), its strongest "
        "peak and the peak's false-alarm probability corrected for the frequencies and pixels searched; the lines "
        "seen anywhere in the frame, the SNR map of each, and the clusters of pixels that carry them. Reads a video "
        "(.mp4 .mov .avi .mkv .webm), Photron .cih/.cihx, a TIFF stack, .npy, netCDF or zarr, lazily.",
    )
    p.add_argument("cube", metavar="CUBE", help="the recording or cube (time, y, x)")
    p.add_argument(
        "-o",
        "--output",
        metavar="DIR",
        default=DEFAULT_OUTPUT,
        help=f"output directory (default: {DEFAULT_OUTPUT}); writes {DETECTION}, {DETECTION_PLOT}, {LINES}",
    )
    g = p.add_argument_group("detection")
    g.add_argument(
        "--band",
        type=parse_band,
        metavar="FMIN:FMAX",
        help="frequencies searched, Hz (default: from 5 / record length up to Nyquist)",
    )
    g.add_argument(
        "--alpha",
        type=ranges.real(0.0, 1.0),
        default=1e-3,
        help="false-alarm probability of a line over the whole map, and the expected fraction of a line's pixels "
        "that are noise, in (0, 1) (default 1e-3)",
    )
    g.add_argument(
        "--max-lines",
        type=ranges.integer(1, 1000),
        default=8,
        metavar="N",
        help="keep the N strongest lines (default 8)",
    )
    r = p.add_argument_group("reading")
    r.add_argument(
        "--fps", type=ranges.positive, metavar="HZ", help="the real frame rate, overriding the file's (slow motion)"
    )
    r.add_argument(
        "--channel", choices=CHANNELS, default="luminance", help="colour frames: luminance (default) or one channel"
    )
    r.add_argument("--variable", metavar="NAME", help="netCDF/zarr: the 3-D variable (default: the only one)")
    d = p.add_argument_group("dask")
    d.add_argument(
        "--scheduler", metavar="ADDRESS", help="run on this dask.distributed scheduler (default: local threads)"
    )
    d.add_argument("--workers", type=ranges.workers, metavar="N", help="local threads (default: the machine's cores)")
    d.add_argument(
        "--memory",
        type=parse_memory,
        default=parse_memory(DEFAULT_MEMORY),
        metavar="SIZE",
        help=f"bound on the chunks in flight and their work, e.g. 512MB or 2GiB (default {DEFAULT_MEMORY})",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_detect)


# ------------------------------------------------------------------------------ the output folder


# -------------------------------------------------------------------------------------- the verb
def cmd_detect(args: argparse.Namespace) -> dict[str, Any]:
    """Write DIR/detection.nc, DIR/detection.png and DIR/lines.csv; returns the lines table (one row
    per line and cluster), counts and the paths (printed by --json)."""
    from vibinverse.imaging.detection_map import detection_map
    from vibinverse.io.atomic import check_paths, write_all
    from vibinverse.io.cube import open_cube

    out = output_dir(args.output)
    paths = {name: out / name for name in (DETECTION, DETECTION_PLOT, LINES)}
    check_paths({f"-o {name}": path for name, path in paths.items()}, {"CUBE": args.cube})
    cube = open_cube(args.cube, fps=args.fps, channel=args.channel, variable=args.variable)
    progress = not args.no_progress and not args.json and _terminal()
    result = detection_map(
        cube,
        band=args.band,
        alpha=args.alpha,
        max_lines=args.max_lines,
        scheduler=args.scheduler,
        workers=args.workers,
        progress=progress,
        memory=args.memory,
    )
    with created(out):
        write_all(
            {
                paths[DETECTION]: result.to_netcdf,
                paths[DETECTION_PLOT]: result.plot,
                paths[LINES]: result.write_csv,
            }
        )
    for line in result.lines:
        shown = line.clusters[:LOGGED_CLUSTERS]
        where = ", ".join(f"cluster {c.cluster} ({c.n_pixels} px)" for c in shown)
        if len(line.clusters) > len(shown):
            rest = line.clusters[len(shown) :]
            where += f" and {len(rest)} more ({sum(c.n_pixels for c in rest)} px)"
        what = "" if line.claimed else f" [{line.kind}: not claimed as vibration; {line.reason}]"
        alias = f" (or {line.alias_frequency:.6g} Hz if aliased)" if math.isfinite(line.alias_frequency) else ""
        note = f" ({line.note})" if line.note else ""
        logger.info(
            f"line {line.index}: {line.frequency:.6g} Hz{alias}, SNR {line.snr:.3g}, false-alarm probability "
            f"{line.false_alarm_probability:.2g}: {where}{what}{note}"
        )
    if not result.lines:
        logger.info(f"no line with false-alarm probability < {args.alpha:g}")
    logger.info(f"wrote {', '.join(str(q) for q in paths.values())}")
    ds = result.maps
    return {
        "lines": result.table(),
        "n_lines": len(result.lines),
        "n_clusters": int(ds.sizes["cluster_id"]),
        "shape": [int(s) for s in cube.shape],
        "uniform_time": bool(ds.attrs["uniform_time"]),
        "frequency_resolution_hz": float(ds.attrs["frequency_resolution_hz"]),
        "band_searched_hz": [float(f) for f in ds.attrs["band_searched_hz"]],
        "paths": [str(q) for q in paths.values()],
    }


def _terminal() -> bool:
    try:
        return sys.stderr.isatty()
    except (ValueError, OSError):
        return False
