"""`vibinverse bench --imaging`: the path from an image cube to an answer, timed against its limits.

Four measurements, each a ratio against a reference computed in the same run (machines are noisy):

- **imager**: `forward.imager.render_cube` of the paper's sec. 4.2 roof seen as 64 x 64 pixels over
  4000 frames (the roof fills the middle of an 80 m field of view), against the 10 s goal.
- **detection throughput**: `vibinverse detect` read from a netCDF file on disk (the cube written by
  the imager) in pixel-samples per second, against a single-threaded numpy rfft of the same cube
  already in memory (the limit of any per-pixel spectral method); goal >= 0.5x at 2 workers.
- **peak memory**: the detection run again in that process, the peak of the memory its arrays held
  at once (tracemalloc, which sees numpy's buffers in every thread; not while timed: it takes the
  GIL at every allocation), against the cube's size.
- **real video**: `vibinverse detect` of real 640 x 420 tuning-fork videos (the real-data corpus,
  `realdata_cases.corpus_dir`; the 1,728- and 3,336-frame takes, `--quick` the 888-frame one) at the default
  `--memory` in a fresh process: wall seconds (goal <= 120 s on 2 cores), the process's peak
  resident memory and its baseline after the imports (`resource.getrusage`), the peak above the
  baseline against the memory budget; the lines it claims. Skipped, and said so, without the corpus.
- **multi-pixel fit**: `fit_pixels` (casadi MAP of the roof's frame model) over N = 1, 4, 16, 64
  roof pixels of equal SNR: seconds (goal: 64 pixels <= 3x one pixel), and the Laplace sd of the
  drive frequency times sqrt(N), constant when the pixels combine near-optimally (DESIGN.md sec. 9).
"""

from __future__ import annotations

import json
import logging
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from forward.imager import render_cube
from forward.scene_file import load_scene

logger = logging.getLogger(__name__)

ROOF = "roof_frame"
FIELD = ("footprint.x=[-40.0, 40.0]", "footprint.y=[-40.0, 40.0]")  # the roof (50 m) amid ground
NOISE = "noise.sigma=0.6"  # the demo's SNR ~10 at the drive line, per roof pixel
IMAGER_GOAL_S = 10.0
THROUGHPUT_GOAL = 0.5
FIT_COST_GOAL = 3.0
PIXEL_COUNTS = (1, 4, 16, 64)
REAL_VIDEOS = {  # the real-size cases: (path in the corpus, true frame rate), full run and --quick
    False: (
        ("tuningfork_video/hz32/fps500/tuning_hz32_fps500_50-1_640x420.mp4", 500.0),
        ("tuningfork_video/hz32/fps1000/tuning_hz32_fps1000_50-1_640x420.mp4", 1000.0),
    ),
    True: (("tuningfork_video/hz32/fps250/tuning_hz32_fps250_50-1_640x420.mp4", 250.0),),
}
REAL_VIDEO_GOAL_S = 120.0
DRIVE = "surfaces.roof.motion.drive_frequency"


def _scene(scene_dir: Path, frames: int, *extra: str):
    fs = load_scene(scene_dir / f"{ROOF}.toml")[0].sampling.fs
    return load_scene(scene_dir / f"{ROOF}.toml", [*FIELD, NOISE, f"sampling.duration={frames / fs!r}", *extra])


def imager_row(scene_dir: Path, frames: int, size: int = 64) -> tuple[dict[str, Any], Any]:
    """Render the roof as size x size pixels (first call, then the best of two warm ones)."""
    scene, table = _scene(scene_dir, frames)
    t0 = time.perf_counter()
    cube = render_cube(scene, size, size, seed=0)
    first = time.perf_counter() - t0
    warm = []
    for seed in (1, 2):
        t0 = time.perf_counter()
        render_cube(scene, size, size, seed=seed)
        warm.append(time.perf_counter() - t0)
    row = {
        "pixels": size * size,
        "frames": frames,
        "first_s": first,
        "warm_s": min(warm),
        "goal_s": IMAGER_GOAL_S,
        "meets_goal": min(warm) <= IMAGER_GOAL_S,
    }
    logger.info(
        f"imager: {size} x {size} pixels x {frames} frames of the sec. 4.2 roof: {min(warm):.2f} s warm "
        f"({first:.2f} s first call); goal <= {IMAGER_GOAL_S:g} s"
    )
    return row, (cube, table)


def _rfft_seconds(values: np.ndarray) -> float:
    """Single-threaded numpy rfft of every pixel's series (time axis first), best of two."""
    flat = values.reshape(values.shape[0], -1)
    best = math.inf
    for _ in range(2):
        t0 = time.perf_counter()
        for a in range(0, flat.shape[1], 512):  # blocks of pixels: the same memory traffic as ours
            np.abs(np.fft.rfft(flat[:, a : a + 512] - flat[:, a : a + 512].mean(axis=0), axis=0)) ** 2
        best = min(best, time.perf_counter() - t0)
    return best


# timed first, untraced: tracemalloc takes the GIL at every numpy allocation, which serializes the
# workers (measured: 1.6-2.3x the CPU time of the detection); then traced, for the peak memory.
# Best of two calls, as the rfft limit is (`_rfft_seconds`): each opens and reads the file; the first
# also pays the process's one-off imports of dask, scipy.ndimage and the like (measured: 1.1 s cold
# against 0.32-0.37 s warm on the 64 x 64 x 4000 cube), which are not throughput
_CHILD = """
import json, sys, time, tracemalloc
from vibinverse.io.cube import open_cube
from vibinverse.imaging.detection_map import detection_map
seconds = float("inf")
for _ in range(2):
    t0 = time.perf_counter()
    found = detection_map(open_cube(sys.argv[1]), workers=int(sys.argv[2]))
    seconds = min(seconds, time.perf_counter() - t0)
tracemalloc.start()  # numpy's buffers, in every thread: the arrays the detection holds at once
detection_map(open_cube(sys.argv[1]), workers=int(sys.argv[2]))
peak = tracemalloc.get_traced_memory()[1]
print(json.dumps({"peak_bytes": peak, "seconds": seconds, "lines": [line.frequency for line in found.lines]}))
"""


def _child(script: str, *args: Any) -> dict[str, Any]:
    """The JSON document a fresh Python process running `script` with `args` prints last."""
    out = subprocess.run(
        [sys.executable, "-c", script, *(str(a) for a in args)],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, "PYTHONWARNINGS": "ignore"},
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def detection_row(cube: Any, table: dict, workdir: Path, workers: int = 2) -> dict[str, Any]:
    """Detection read from disk against the in-memory rfft limit; peak memory against the cube."""
    from vibinverse.io.cube_writer import write_cube_netcdf

    path = write_cube_netcdf(workdir / "cube.nc", cube, table, 0)
    t, ny, nx = cube.shape
    samples = t * ny * nx
    limit = _rfft_seconds(cube.intensity)
    # a fresh process: the interpreter and the modules, then the detection timed (opening and reading
    # the file included); then again, the peak of the memory its arrays held at once (tracemalloc)
    run = _child(_CHILD, path, workers)
    size_mb = cube.intensity.nbytes / 2**20
    above_mb = run["peak_bytes"] / 2**20
    row = {
        "pixels": ny * nx,
        "frames": t,
        "workers": workers,
        "cube_mb": size_mb,
        "detect_s": run["seconds"],
        "rfft_s": limit,
        "throughput": samples / run["seconds"],
        "rfft_throughput": samples / limit,
        "ratio": limit / run["seconds"],
        "goal_ratio": THROUGHPUT_GOAL,
        "peak_above_mb": above_mb,
        "peak_fraction_of_cube": above_mb / size_mb,
        "lines_hz": run["lines"],
    }
    logger.info(
        f"detect: {ny} x {nx} x {t} cube ({size_mb:.0f} MB) from disk in {run['seconds']:.2f} s at {workers} workers: "
        f"{row['throughput']:.3g} pixel-samples/s = {row['ratio']:.2f}x a single-threaded numpy rfft of it in memory "
        f"(goal >= {THROUGHPUT_GOAL:g}x); peak memory of its arrays {above_mb:.0f} MB "
        f"({row['peak_fraction_of_cube']:.2f}x the cube); lines {', '.join(f'{f:.4g}' for f in run['lines'])} Hz"
    )
    return row


# a fresh process: the imports, its resident memory then (the baseline), the detection at the default
# --memory budget timed, and the process's peak resident memory
_REAL_CHILD = """
import json, resource, sys, time

def rss(field):  # bytes: VmRSS now, VmHWM the peak (Linux: reset at exec, unlike ru_maxrss, which keeps
    try:         # the forking parent's)
        with open("/proc/self/status") as fh:
            return next(int(x.split()[1]) * 1024 for x in fh if x.startswith(field + ":"))
    except OSError:
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024

from vibinverse.io.cube import open_cube
from vibinverse.imaging.detection_map import DEFAULT_MEMORY, detection_map
base = rss("VmRSS")
t0 = time.perf_counter()
found = detection_map(open_cube(sys.argv[1], fps=float(sys.argv[2])), workers=2)
seconds = time.perf_counter() - t0
peak = rss("VmHWM")
print(json.dumps({"seconds": seconds, "peak_bytes": peak, "base_bytes": base, "budget_bytes": DEFAULT_MEMORY,
                  "claimed": [ln.frequency for ln in found.lines if ln.claimed], "lines": len(found.lines)}))
"""


def real_video_rows(quick: bool) -> list[dict[str, Any]]:
    """`real_video_row` of each of the run's real videos (`REAL_VIDEOS`)."""
    return [real_video_row(rel, fps) for rel, fps in REAL_VIDEOS[bool(quick)]]


def real_video_row(rel: str, fps: float) -> dict[str, Any]:
    """`vibinverse detect` of a real 640 x 420 video, `rel` in the corpus at its true `fps` (module
    docstring); {"skipped": why} without the corpus."""
    from vibinverse.bench.realdata_cases import corpus_dir
    from vibinverse.errors import InputError

    try:
        path = corpus_dir() / rel
    except InputError as exc:
        logger.info(f"real video: skipped ({exc})")
        return {"skipped": str(exc)}
    if not path.is_file():
        return {"skipped": f"{path} is not in the corpus"}
    run = _child(_REAL_CHILD, path, fps)
    above = run["peak_bytes"] - run["base_bytes"]
    row = {
        "video": rel,
        "fps": fps,
        "seconds": run["seconds"],
        "goal_s": REAL_VIDEO_GOAL_S,
        "peak_mb": run["peak_bytes"] / 2**20,
        "base_mb": run["base_bytes"] / 2**20,
        "above_base_mb": above / 2**20,
        "budget_mb": run["budget_bytes"] / 2**20,
        "above_base_vs_budget": above / run["budget_bytes"],
        "claimed_hz": run["claimed"],
        "lines": run["lines"],
    }
    logger.info(
        f"real video {rel} at {fps:g} fps: {row['seconds']:.1f} s (goal <= {REAL_VIDEO_GOAL_S:g} s); peak resident "
        f"{row['peak_mb']:.0f} MB, {row['above_base_mb']:.0f} MB above the {row['base_mb']:.0f} MB baseline = "
        f"{row['above_base_vs_budget']:.2f}x the {row['budget_mb']:.0f} MB budget; claimed "
        f"{', '.join(f'{f:.4g}' for f in row['claimed_hz'])} Hz"
    )
    return row


def fit_rows(cube: Any, table: dict, counts: tuple[int, ...] = PIXEL_COUNTS) -> list[dict[str, Any]]:
    """fit_pixels over N roof pixels (casadi MAP of the frame model): seconds, drive-frequency sd."""
    import xarray as xr

    from vibinverse.imaging.joint_fit import fit_pixels

    coverage = cube.coverage["roof"]
    inside = np.argwhere(coverage >= 1.0)  # pixels wholly on the roof: equal gain and noise
    rng = np.random.default_rng(0)
    data = xr.DataArray(cube.intensity, dims=("time", "y", "x"), coords={"time": cube.time})
    rows = []
    # the scene of one roof pixel: the roof is rigid (one normal), so a pixel wholly on it sees what
    # the scene's own footprint (the roof) sees
    scene = {k: v for k, v in table.items() if k not in ("infer", "footprint")}
    scene["footprint"] = {**table["footprint"], "x": [-25.0, 25.0], "y": [-25.0, 25.0]}
    fit_pixels(data, _mask(inside[:1], coverage.shape), scene, method="casadi")  # compile the MAP once
    for n in counts:
        mask = _mask(inside[rng.choice(len(inside), size=n, replace=False)], coverage.shape)
        t0 = time.perf_counter()
        result = fit_pixels(data, mask, scene, method="casadi")
        seconds = time.perf_counter() - t0
        sd = float(result.summary()["parameters"][f"{DRIVE}[0]" if f"{DRIVE}[0]" in result.names else DRIVE]["sd"])
        rows.append({"pixels": n, "seconds": seconds, "drive_frequency_sd": sd, "sd_times_sqrt_n": sd * math.sqrt(n)})
    one = rows[0]
    for r in rows:
        r["cost_vs_one"] = r["seconds"] / one["seconds"]
        r["sd_sqrt_n_vs_one"] = r["sd_times_sqrt_n"] / one["sd_times_sqrt_n"]
        logger.info(
            f"fit {r['pixels']:>3} pixels: {r['seconds']:.2f} s ({r['cost_vs_one']:.2f}x one pixel; goal "
            f"<= {FIT_COST_GOAL:g}x); drive frequency sd {r['drive_frequency_sd']:.3g} Hz, sd x sqrt(N) "
            f"{r['sd_sqrt_n_vs_one']:.2f}x one pixel's (1 when the pixels combine optimally)"
        )
    return rows


def _mask(indices: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    mask = np.zeros(shape, dtype=bool)
    mask[indices[:, 0], indices[:, 1]] = True
    return mask


def run(
    scene_dir: Path,
    quick: bool = False,
    *,
    size: int = 64,
    frames: int = 4000,
    counts: tuple[int, ...] = PIXEL_COUNTS,
) -> dict[str, Any]:
    """Every measurement on a size x size imager; `quick` renders half the frames for the detection
    and the fits (the imager row keeps the goal's `frames`)."""
    t0 = time.perf_counter()
    imager, (cube, table) = imager_row(scene_dir, frames, size)
    if quick:
        cube, table = imager_row(scene_dir, frames // 2, size)[1]
    with tempfile.TemporaryDirectory(prefix="vibinverse-bench-") as tmp:
        detection = detection_row(cube, table, Path(tmp))
    fits = fit_rows(cube, table, counts)
    return {
        "imager": imager,
        "detection": detection,
        "real_videos": real_video_rows(quick),
        "fits": fits,
        "quick": quick,
        "seconds": time.perf_counter() - t0,
    }


def plot(result: dict[str, Any], path: Path) -> None:
    """Four panels: imager seconds against its goal; detection throughput against the rfft limit
    (peak memory against the cube in the title); the real video's seconds and memory as fractions of
    their goal and budget (or why it was skipped); fit cost and sd x sqrt(N) against N. Each legend
    sits below its panel, clear of the data."""
    import matplotlib

    matplotlib.use("Agg")
    import textwrap

    import matplotlib.pyplot as plt

    def legend_below(ax):  # below the tick labels (two lines at most), never on the data
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.2), frameon=False)

    with plt.rc_context({"font.size": 11}):  # read at the page's width, about 7 inches
        fig, axes = plt.subplots(2, 2, figsize=(10, 8.5), constrained_layout=True)
        (ax_im, ax_det), (ax_real, ax_fit) = axes
        im = result["imager"]
        ax_im.bar(["warm", "first call"], [im["warm_s"], im["first_s"]], color=["C0", "C7"])
        ax_im.axhline(im["goal_s"], color="C3", ls="--", label=f"goal {im['goal_s']:g} s")
        ax_im.set(ylabel="seconds", title=f"imager: {math.isqrt(im['pixels'])}$^2$ px x {im['frames']} frames")
        legend_below(ax_im)
        d = result["detection"]
        ax_det.bar(
            ["detect (from disk)", "numpy rfft (memory)"],
            [d["throughput"] / 1e6, d["rfft_throughput"] / 1e6],
            color=["C0", "C7"],
        )
        goal = d["goal_ratio"] * d["rfft_throughput"] / 1e6
        ax_det.axhline(goal, color="C3", ls="--", label=f"goal: {d['goal_ratio']:g}x the rfft")
        ax_det.set(
            ylabel="million pixel-samples / s",
            title=f"detection: {d['ratio']:.2f}x the rfft\npeak memory {d['peak_fraction_of_cube']:.2f}x the cube",
        )
        legend_below(ax_det)
        reals = [r for r in result.get("real_videos", []) if "seconds" in r]
        if reals:
            x = np.arange(len(reals))
            ax_real.bar(x - 0.2, [r["seconds"] / r["goal_s"] for r in reals], 0.4, color="C0", label="time / goal")
            ax_real.bar(
                x + 0.2,
                [r["above_base_vs_budget"] for r in reals],
                0.4,
                color="C7",
                label="memory above baseline / budget",
            )
            ax_real.set_xticks(
                x, [f"{r['fps']:g} fps\n{r['seconds']:.0f} s, +{r['above_base_mb']:.0f} MB" for r in reals]
            )
            ax_real.axhline(
                1.0, color="C3", ls="--", label=f"goal {reals[0]['goal_s']:g} s, budget {reals[0]['budget_mb']:.0f} MB"
            )
            ax_real.set(
                ylabel="fraction of goal or budget",
                ylim=(0, max(1.15, ax_real.get_ylim()[1])),
                title="real 640 x 420 videos (detect)",
            )
            legend_below(ax_real)
        else:
            ax_real.set_axis_off()
            ax_real.set_title("real video")
            why = next((r["skipped"] for r in result.get("real_videos", []) if "skipped" in r), "not run")
            why = textwrap.fill(f"skipped: {why}", 40)
            ax_real.text(0.5, 0.5, why, ha="center", va="center", transform=ax_real.transAxes)
        fits = result["fits"]
        n = [r["pixels"] for r in fits]
        ax_fit.plot(n, [r["cost_vs_one"] for r in fits], "o-", label="fit time / one pixel's")
        ax_fit.plot(n, [r["sd_sqrt_n_vs_one"] for r in fits], "s-", label="sd x sqrt(N) / one pixel's")
        ax_fit.axhline(FIT_COST_GOAL, color="C3", ls="--", label=f"cost goal {FIT_COST_GOAL:g}x")
        ax_fit.axhline(1.0, color="0.5", lw=0.8)
        ax_fit.set(xscale="log", xlabel="pixels fitted jointly", ylabel="ratio to one pixel", title="multi-pixel fit")
        ax_fit.set_xticks(n, [str(v) for v in n])
        ax_fit.minorticks_off()
        legend_below(ax_fit)
        fig.savefig(path, dpi=100, format="png")  # `path` may be a temporary name (atomic write)
    plt.close(fig)


def _met(ok: bool) -> str:
    return "met" if ok else "missed"


def table(result: dict[str, Any]) -> str:
    """`run`'s result (imaging.json) as fixed-width text: the imager against its goal, detection
    throughput against the numpy rfft and its peak memory against the cube, the real video's
    `detect` (seconds, peak resident memory above the baseline against the `--memory` budget) or
    why it was skipped, and the multi-pixel fit's cost and sd x sqrt(N) against one pixel's. Pure."""
    im, d = result["imager"], result["detection"]
    side = math.isqrt(im["pixels"])
    out = [
        f"imager, {side} x {side} pixels x {im['frames']} frames: {im['warm_s']:.2f} s warm "
        f"({im['first_s']:.2f} s first call); goal <= {im['goal_s']:g} s: {_met(im['meets_goal'])}",
        f"detect, {math.isqrt(d['pixels'])}^2 pixels x {d['frames']} frames ({d['cube_mb']:.0f} MB) from disk at "
        f"{d['workers']} workers: {d['detect_s']:.2f} s, {d['throughput']:.3g} pixel-samples/s",
        f"  against a single-threaded numpy rfft in memory ({d['rfft_s']:.2f} s, {d['rfft_throughput']:.3g} "
        f"pixel-samples/s): {d['ratio']:.2f}x (goal >= {d['goal_ratio']:g}x: {_met(d['ratio'] >= d['goal_ratio'])})",
        f"  peak memory of its arrays {d['peak_above_mb']:.0f} MB = {d['peak_fraction_of_cube']:.2f}x the cube; "
        f"lines {', '.join(f'{f:.4g}' for f in d['lines_hz'])} Hz",
    ]
    for real in result.get("real_videos") or [{}]:
        if "seconds" not in real:
            out.append(f"real video: skipped ({real.get('skipped', 'not run')})")
            continue
        out += [
            f"real video {real['video']} at {real['fps']:g} fps, default --memory: {real['seconds']:.1f} s "
            f"(goal <= {real['goal_s']:g} s: {_met(real['seconds'] <= real['goal_s'])})",
            f"  peak resident memory {real['peak_mb']:.0f} MB, {real['above_base_mb']:.0f} MB above the "
            f"{real['base_mb']:.0f} MB after the imports = {real['above_base_vs_budget']:.2f}x the "
            f"{real['budget_mb']:.0f} MB budget; {real['lines']} lines, claimed "
            f"{', '.join(f'{f:.4g}' for f in real['claimed_hz']) or 'none'} Hz",
        ]
    out += [
        "multi-pixel fit (casadi MAP of the frame model):",
        f"{'pixels':>8}{'s':>8}{'cost/1':>8}{'sd_Hz':>10}{'sd*sqrtN/1':>12}",
    ]
    out += [
        f"{r['pixels']:>8}{r['seconds']:8.2f}{r['cost_vs_one']:8.2f}{r['drive_frequency_sd']:10.3g}"
        f"{r['sd_sqrt_n_vs_one']:12.2f}"
        for r in result.get("fits", [])
    ]
    if result.get("fits"):
        last = result["fits"][-1]
        met = _met(last["cost_vs_one"] <= FIT_COST_GOAL)
        out.append(f"(goal: {last['pixels']} pixels <= {FIT_COST_GOAL:g}x one pixel's time: {met})")
    return "\n".join(out)
