"""Paper Fig. 11: a glass pane behind a p-polarizer as the sun's incidence sweeps through
Brewster's angle, the sensor staying on the lobe centre."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from forward.materials import LIBRARY
from forward.optics import brewster_angle
from vibinverse.studies.common import interior_peak, one_cycle, sweep, write_study

SCENE = "glass_brewster"


def fig11(outdir: Path, quick: bool = False) -> str:
    theta_b = brewster_angle(LIBRARY["glass"].index.real)
    dev = np.concatenate(
        [np.linspace(-0.02, 0.02, 21 if quick else 41), np.linspace(-0.002, 0.002, 9 if quick else 21)]
    )
    dev = np.unique(np.round(dev, 12))
    base = [*one_cycle(40.0, 100 if quick else 400), f"footprint.resolution={32 if quick else 96}"]
    elev = lambda d: np.pi / 2 - (theta_b + d)  # incidence theta_B + d is elevation pi/2 - theta_B - d
    variants = [[f"sun.inclination={float(elev(d))!r}", f"sensor.inclination={float(elev(d))!r}"] for d in dev]
    s = sweep(SCENE, base, variants)
    unpol = float(sweep(SCENE, [*base, "sensor.polarizer='none'"], [[]])[0])
    peak = interior_peak(dev, s)
    above = dev[s > 0.01]
    summary = {
        "incidence_rad": theta_b + dev,
        "sensitivity": s,
        "sensitivity_unpolarized": unpol,
        "brewster_rad": theta_b,
        "peak_incidence_rad": theta_b + peak,
        "peak_sensitivity": float(s.max()),
        "above_0.01_window_rad": [float(above.min()), float(above.max())] if above.size else None,
    }

    def plot(fig):
        ax = fig.subplots()
        ax.semilogy(dev, s, "o-", ms=3, label="p-polarizer")
        ax.axhline(unpol, color="C1", ls="--", label=f"no polarizer at Brewster: {unpol:.1e}")
        ax.axhline(0.01, color="0.6", ls=":", lw=0.8)
        ax.set(
            xlabel="incidence - Brewster's angle (rad)",
            ylabel="sensitivity S (eq. 21)",
            title="glass pane, sensor on the lobe centre (paper Fig. 11)",
        )
        ax.legend()

    write_study(outdir, "fig11", {"incidence_rad": theta_b + dev, "sensitivity": s}, summary, plot)
    win = summary["above_0.01_window_rad"]
    return (
        f"fig11: peak S = {s.max():.3f} at {peak:+.4f} rad from Brewster; S > 0.01 for "
        f"{'none' if win is None else f'[{win[0]:+.4f}, {win[1]:+.4f}] rad'}; no polarizer {unpol:.1e}"
    )
