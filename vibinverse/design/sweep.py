"""`vibinverse design`: evaluate every configuration of a sweep, rank them, write CSV/JSON/PNG."""

from __future__ import annotations

import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from forward.errors import SceneError as ForwardSceneError
from forward.materials import Fresnel
from forward.scene_file import scene_from_table
from vibinverse.design import metrics
from vibinverse.design.plots import plot_design
from vibinverse.design.ranking import rank
from vibinverse.design.spec import Axis, configure, grid, parse_vary
from vibinverse.errors import SceneError
from vibinverse.io import jsonio
from vibinverse.io.atomic import write_all
from vibinverse.io.file_basics import csv_cell

PAPER_THRESHOLD = 1e-4  # the paper's detectability threshold on the sensitivity (21)
N_BEST = 10


def default_axes(table: dict) -> list[Axis]:
    """A sweep suited to the scene: view offset and footprint placement for a specular surface,
    sun elevation and footprint width for a diffuse one (the paper's sec. 4 studies)."""
    scene = scene_from_table(table)
    specular = [s for s in scene.surfaces if isinstance(s.material, Fresnel) and s.motion is not None]
    if specular:
        s = specular[0]
        half = max(s.x[1] - s.x[0], s.y[1] - s.y[0]) / 2
        centre = (s.x[0] + s.x[1]) / 2
        return [
            Axis("sensor.offset", tuple(np.linspace(-0.04, 0.04, 33).tolist())),
            Axis("footprint.center", tuple(np.linspace(centre, centre + half, 5).tolist())),
        ]
    width = max(scene.footprint.x[1] - scene.footprint.x[0], scene.footprint.y[1] - scene.footprint.y[0])
    return [
        Axis("sun.inclination", tuple(np.geomspace(0.01, 0.6, 16).tolist())),
        Axis("footprint.width", tuple(np.linspace(width / 10, 2 * width, 12).tolist())),
    ]


MAX_PIXELS = 1 << 24  # equal pixels combined (a 4096 x 4096 imager)


def run_design(
    table: dict,
    vary: list[str],
    targets: list[str] | None,
    threshold: float = PAPER_THRESHOLD,
    workers: int = 1,
    progress: bool = False,
    pixels: int = 1,
) -> dict[str, Any]:
    """Evaluate the sweep; returns {"axes", "targets", "rows", "best", "threshold", "seconds",
    "pixels"}. `pixels`: N equal pixels fitted jointly (the multi-pixel bound; 1: one pixel).

    Specification errors (unknown key, empty range, non-numeric value, unknown target) raise
    SceneError before any work; a configuration that is impossible (sun below the horizon, view
    outside (0, pi/2)) becomes a row with status naming why, not a failure of the sweep."""
    if not threshold > 0:
        raise SceneError(f"--threshold: {threshold:g}; allowed range (0, inf)")
    if isinstance(pixels, bool) or not isinstance(pixels, int) or not 1 <= pixels <= MAX_PIXELS:
        raise SceneError(f"--pixels: {pixels!r}; allowed range [1, {MAX_PIXELS}] (an integer)")
    axes = [parse_vary(v) for v in vary] if vary else default_axes(table)
    keys = [a.key for a in axes]
    if len(set(keys)) != len(keys):
        raise SceneError(f"--vary: a key is given twice ({', '.join(keys)})")
    targets = list(targets) if targets else metrics.default_targets(table)
    metrics.check_targets(table, targets)
    for axis in axes:  # a bad key fails here, with the scene's own one-line message
        for value in {axis.values[0], axis.values[-1]}:
            _validate(table, axis.key, value)
    configs = grid(axes)
    t0 = time.perf_counter()
    rows = _evaluate_all(table, configs, targets, workers, progress, pixels)
    seconds = time.perf_counter() - t0
    return {
        "pixels": pixels,
        "axes": axes,
        "targets": targets,
        "rows": rows,
        "threshold": threshold,
        "seconds": seconds,
        "best": rank(rows, targets, threshold)[:N_BEST],
    }


def _validate(table: dict, key: str, value: Any) -> None:
    try:
        scene_from_table(configure(table, {key: value}))
    except ForwardSceneError as exc:
        text = str(exc)
        if "unknown key" in text or "no such" in text or "not a table" in text or "is a value" in text:
            raise SceneError(f"--vary {key}: {text}") from None
        # an out-of-range value at one end is a row status, not a bad specification


def _evaluate_all(table, configs, targets, workers, progress, pixels=1) -> list[dict[str, Any]]:
    workers = min(workers, len(configs))
    if workers <= 1:
        return _evaluate_chunk((table, configs, targets, progress, pixels))
    import multiprocessing as mp

    # one-time set-up (lobe tables) before the fork
    first = _evaluate_chunk((table, configs[:1], targets, False, pixels))
    rest = configs[1:]
    chunks = [rest[i::workers] for i in range(workers)]
    with ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("fork")) as pool:
        parts = list(
            pool.map(_evaluate_chunk, [(table, c, targets, progress and i == 0, pixels) for i, c in enumerate(chunks)])
        )
    rows = [None] * len(rest)
    for w, part in enumerate(parts):
        rows[w::workers] = part
    return first + rows


def _evaluate_chunk(job) -> list[dict[str, Any]]:
    from threadpoolctl import threadpool_limits

    with threadpool_limits(1):  # tiny matrices: BLAS threads only contend (and spin across forked workers)
        return _evaluate_configs(*job)


def _evaluate_configs(table, configs, targets, progress, pixels=1) -> list[dict[str, Any]]:
    cache: dict = {}
    out = []
    iterator = configs
    if progress:
        from tqdm import tqdm

        iterator = tqdm(configs, desc="design", unit="config")
    for config in iterator:
        row: dict[str, Any] = dict(config)
        try:
            row.update(metrics.evaluate(configure(table, config), targets, cache, pixels))
            row["status"] = "ok"
        except ForwardSceneError as exc:
            row["status"] = str(exc)
        out.append(row)
    return out


def write_design(result: dict[str, Any], outdir: Path) -> list[Path]:
    """design.csv, design.json and the PNG maps, all or nothing."""
    rows, axes = result["rows"], result["axes"]
    columns = list(dict.fromkeys(k for r in rows for k in r if k != "status")) + ["status"]

    def csv(path: Path) -> None:
        import csv as csvlib

        with open(path, "w", encoding="utf-8", newline="") as fh:
            out = csvlib.writer(fh)
            out.writerow(columns)
            out.writerows([[_cell(r.get(c, "")) for c in columns] for r in rows])

    def js(path: Path) -> None:
        doc = {
            "best": result["best"],
            "n_configurations": len(rows),
            "n_ok": sum(r.get("status") == "ok" for r in rows),
            "n_detectable": sum(r.get("status") == "ok" and r["sensitivity"] >= result["threshold"] for r in rows),
            "threshold": result["threshold"],
            "targets": result["targets"],
            "axes": {a.key: list(a.values) for a in axes},
            "seconds": result["seconds"],
        }
        # strict JSON: an infinite Cramer-Rao sd (an unidentifiable target) is null, named in "non_finite"
        path.write_text(jsonio.dumps(doc, indent=2))

    writers = {outdir / "design.csv": csv, outdir / "design.json": js}
    for name, draw in plot_design(result).items():
        writers[outdir / name] = draw
    write_all(writers)
    return list(writers)


def _cell(v: Any) -> str:
    """A number to 10 digits; text that a spreadsheet will not run as a formula (`csv_cell`)."""
    return f"{v:.10g}" if isinstance(v, float) else str(csv_cell(v))
