"""The figure of a multi-channel identification: the stabilization-style diagram (each band's poles
over model order, the chosen order marked, over the singular values of the spectral matrix), the
mode shapes with their 90 % intervals, and the MAC matrix."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vibinverse.oma.result import OmaResult


def plot_oma(result: OmaResult, path: str | Path) -> None:
    """Write the figure (PNG) to `path`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(result.modes)
    fig = plt.figure(figsize=(11, 7.5), layout="constrained")
    grid = fig.add_gridspec(2, 2, height_ratios=(1.2, 1.0), width_ratios=(2.0, 1.0))
    ax = fig.add_subplot(grid[0, :])
    for c in range(result.sv_values.shape[1]):
        ax.semilogy(
            result.sv_freqs,
            result.sv_values[:, c],
            lw=0.8 if c else 1.2,
            color=f"C{c % 10}",
            label=f"{result.spectrum.split(' (')[0]} {c + 1}" if result.sv_values.shape[1] > 1 else result.spectrum,
        )
    lo, hi = result.search
    if result.bands:  # the searched band, or up to a little past the last band
        hi = min(hi, 1.25 * max(b.hi for b in result.bands))
    ax.set_xlim(lo, hi)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel(result.spectrum)
    order_ax = ax.twinx()
    for b in result.bands:
        order_ax.axvspan(b.lo, b.hi, color="0.85", alpha=0.4, lw=0)
        for m, fit in b.orders.items():
            fs = fit["frequencies"]
            chosen = m == b.chosen
            order_ax.plot(
                fs, [m] * len(fs), "o" if chosen else "x", color="k" if chosen else "0.5", ms=6 if chosen else 4
            )
    order_ax.set_ylabel("modes in band (o: chosen by BIC)")
    order_ax.set_ylim(-0.5, max([3] + [max(b.orders, default=0) for b in result.bands]) + 0.5)
    for m in result.modes:
        ax.axvline(m.frequency, color="C3", lw=0.6, ls="--")
    ax.legend(loc="upper right", fontsize=7)
    ax.set_title(f"stabilization: each band's fits over model order, on the {result.spectrum.split(' (')[0]}")

    ax2 = fig.add_subplot(grid[1, 0])
    if n:
        x = np.arange(len(result.names))
        width = 0.8 / n
        for i, m in enumerate(result.modes):
            err = np.abs(m.shape_interval.T - m.shape)
            ax2.bar(x + (i - (n - 1) / 2) * width, m.shape, width, yerr=err, capsize=2, label=f"{m.frequency:.4g} Hz")
        ax2.set_xticks(x, result.names, rotation=30, ha="right", fontsize=8)
        ax2.axhline(0.0, color="k", lw=0.5)
        ax2.legend(fontsize=7, ncol=max(1, n // 6))
    ax2.set_ylabel("unit shape (90 % interval)")
    ax2.set_title("mode shapes")

    ax3 = fig.add_subplot(grid[1, 1])
    if n:
        im = ax3.imshow(result.mac, vmin=0.0, vmax=1.0, cmap="viridis")
        labels = [f"{m.frequency:.3g}" for m in result.modes]
        ax3.set_xticks(range(n), labels, rotation=90, fontsize=7)
        ax3.set_yticks(range(n), labels, fontsize=7)
        fig.colorbar(im, ax=ax3, shrink=0.8)
    ax3.set_title("MAC between modes (Hz)")
    fig.savefig(path, dpi=110, format="png")
    plt.close(fig)
