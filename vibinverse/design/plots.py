"""Maps and curves of a design sweep: sensitivity (21) with the detectability threshold, and the
Cramer-Rao sd of the targets, over the swept axes."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from vibinverse.design.ranking import score


def plot_design(result: dict[str, Any]) -> dict[str, Callable[[Path], None]]:
    """{"design_sensitivity.png": writer, "design_crlb.png": writer}."""
    targets = result["targets"]
    sens = lambda r: r["sensitivity"] if r.get("status") == "ok" else math.nan
    worst = lambda r: score(r, targets) if r.get("status") == "ok" else math.nan
    return {
        "design_sensitivity.png": _writer(result, sens, "sensitivity S (21)", result["threshold"], best=max),
        "design_crlb.png": _writer(result, worst, "worst relative Cramer-Rao sd of the targets", None, best=min),
    }


def _writer(result, metric, label, threshold, best):
    def write(path: Path) -> None:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(8, 5.5), constrained_layout=True)
        _draw(ax, fig, result, metric, label, threshold, best)
        fig.savefig(path, dpi=100, format="png")
        plt.close(fig)

    return write


def _draw(ax, fig, result, metric, label, threshold, best) -> None:
    axes, rows = result["axes"], result["rows"]
    numeric = [a for a in axes if a.numeric and len(a.values) > 1]
    values = {id(r): metric(r) for r in rows}
    if len(numeric) >= 2:
        ax_x, ax_y = numeric[:2]
        z = np.full((len(ax_y.values), len(ax_x.values)), np.nan)
        for r in rows:
            i, j = ax_y.values.index(r[ax_y.key]), ax_x.values.index(r[ax_x.key])
            v = values[id(r)]
            if math.isfinite(v) and v > 0:
                z[i, j] = v if math.isnan(z[i, j]) else best(z[i, j], v)  # other axes: their best
        logz = np.log10(z)
        mesh = ax.pcolormesh(ax_x.values, ax_y.values, logz, shading="nearest", cmap="viridis")
        fig.colorbar(mesh, ax=ax, label=f"log10 {label}")
        if threshold is not None and np.isfinite(logz).any():
            ax.contour(ax_x.values, ax_y.values, logz, levels=[math.log10(threshold)], colors="r", linewidths=2)
            ax.plot([], [], "r-", label=f"threshold S = {threshold:g}")
            ax.legend(loc="upper right")
        ax.set_xlabel(ax_x.key)
        ax.set_ylabel(ax_y.key)
        rest = [a.key for a in axes if a not in (ax_x, ax_y) and len(a.values) > 1]
        ax.set_title(label + (f" (best over {', '.join(rest)})" if rest else ""))
        return
    if len(numeric) == 1:
        ax_x = numeric[0]
        others = [a for a in axes if a is not ax_x and len(a.values) > 1]
        for combo in itertools.islice(itertools.product(*[a.values for a in others]), 8):
            pick = [r for r in rows if all(r[a.key] == v for a, v in zip(others, combo))]
            xs = [r[ax_x.key] for r in pick]
            ys = [values[id(r)] for r in pick]
            name = ", ".join(f"{a.key}={v}" for a, v in zip(others, combo)) or label
            ax.semilogy(xs, ys, ".-", label=name)
        ax.set_xlabel(ax_x.key)
    else:
        names = [", ".join(f"{a.key}={r[a.key]}" for a in axes) for r in rows]
        ax.bar(range(len(rows)), [values[id(r)] for r in rows])
        ax.set_yscale("log")
        ax.set_xticks(range(len(rows)), names, rotation=30, ha="right", fontsize=8)
    if threshold is not None:
        ax.axhline(threshold, color="k", ls="--", label=f"threshold S = {threshold:g}")
    ax.set_ylabel(label)
    ax.legend(fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
