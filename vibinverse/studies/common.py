"""What every study shares: scene loading with overrides, sensitivity sweeps through the scene
compiler, and writing NAME.png / NAME.csv / NAME.json all-or-nothing."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from forward.reduce import compile_scene
from forward.render import pixel_signal, sensitivity
from forward.scene import Scene
from forward.scene_file import load_scene
from vibinverse.io import jsonio
from vibinverse.io.atomic import write_all
from vibinverse.io.builtin import builtin_scene


def scene_path(name: str) -> Path:
    """A built-in scene by name (see vibinverse.builtin)."""
    return builtin_scene(name)


def one_cycle(frequency: float, per_cycle: int = 400) -> list[str]:
    """Sampling overrides that resolve one period of `frequency` finely: the sensitivity (21) of a
    periodic signal is then its true peak-to-peak, not that of a coarse sampling."""
    return [f"sampling.fs={float(frequency * per_cycle)!r}", f"sampling.duration={float(1.0 / frequency)!r}"]


def signal(scene: Scene, rtol: float | None, seed: int = 0) -> np.ndarray:
    """The clean pixel signal: through the scene compiler at `rtol`, or dense if rtol is None."""
    return pixel_signal(scene, seed=seed) if rtol is None else compile_scene(scene, rtol=rtol, seed=seed).signal()


def sweep(
    name: str, base: Sequence[str], variants: Sequence[Sequence[str]], rtol: float | None = 1e-6, seed: int = 0
) -> np.ndarray:
    """Sensitivity (21) of scene `name` with `base` overrides, for each list of extra overrides."""
    out = []
    for extra in variants:
        scene = load_scene(scene_path(name), [*base, *extra])[0]
        out.append(sensitivity(signal(scene, rtol, seed)))
    return np.array(out)


def write_study(
    outdir: Path, name: str, curve: dict[str, np.ndarray], summary: dict[str, Any], plot: Callable[[Any], None]
) -> None:
    """NAME.csv (columns of `curve`, padded with empty cells), NAME.json and NAME.png, all or nothing.

    `plot(fig)` draws on a fresh matplotlib figure.
    """

    def csv(path: Path) -> None:
        cols = list(curve)
        n = max(len(v) for v in curve.values())
        with open(path, "w", encoding="utf-8") as fh:
            fh.write(",".join(cols) + "\n")
            for i in range(n):
                fh.write(",".join(f"{curve[c][i]:.10g}" if i < len(curve[c]) else "" for c in cols) + "\n")

    def js(path: Path) -> None:
        path.write_text(jsonio.dumps(summary, indent=2))

    def png(path: Path) -> None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig = plt.figure(figsize=(10, 7), constrained_layout=True)
        plot(fig)
        fig.savefig(path, dpi=100, format="png")
        plt.close(fig)

    write_all({outdir / f"{name}.png": png, outdir / f"{name}.csv": csv, outdir / f"{name}.json": js})


def interior_peak(x: np.ndarray, y: np.ndarray) -> float:
    """x at the maximum of y, refined by a parabola through the top three points."""
    i = int(np.argmax(y))
    if 0 < i < len(x) - 1:
        a, b, c = y[i - 1], y[i], y[i + 1]
        den = a - 2 * b + c
        if den < 0:
            return float(x[i] + 0.5 * (a - c) / den * (x[i + 1] - x[i]))
    return float(x[i])
