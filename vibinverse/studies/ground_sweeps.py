"""Paper Figs. 14 and 15 (sec. 4.3): the vibrating ground's sensitivity against sun elevation and
against footprint width (quadrant footprints anchored at the source)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vibinverse.studies.common import interior_peak, one_cycle, sweep, write_study

SCENE = "ground_rayleigh"
WAVELENGTH = 3000.0 / 40.0


def _base(quick: bool) -> list[str]:
    return [*one_cycle(40.0, 100 if quick else 400), f"footprint.resolution={48 if quick else 128}"]


def fig14(outdir: Path, quick: bool = False) -> str:
    inc = np.geomspace(0.01, np.pi / 2, 12 if quick else 40)
    s = sweep(SCENE, _base(quick), [[f"sun.inclination={float(v)!r}"] for v in inc])
    below = inc[s > 1e-4]
    limit = float(below.max()) if below.size else None
    summary = {"sun_inclination_rad": inc, "sensitivity": s, "detectable_below_rad_at_1e-4": limit}

    def plot(fig):
        ax = fig.subplots()
        ax.loglog(inc, s, "o-", ms=3)
        ax.axhline(1e-4, color="0.6", ls=":", label="threshold 1e-4")
        ax.set(
            xlabel="sun inclination (rad)",
            ylabel="sensitivity S (eq. 21)",
            title="ground, 50 m quadrant footprint (paper Fig. 14)",
        )
        ax.legend()

    write_study(outdir, "fig14", {"sun_inclination_rad": inc, "sensitivity": s}, summary, plot)
    return f"fig14: S = {s[0]:.2e} at 0.01 rad falling to {s[-1]:.2e} at pi/2; S > 1e-4 up to {limit} rad"


def fig15(outdir: Path, quick: bool = False) -> str:
    widths = np.linspace(2.0, 80.0, 27 if quick else 79)
    s = sweep(
        SCENE, _base(quick), [[f"footprint.x=[0, {float(w)!r}]", f"footprint.y=[0, {float(w)!r}]"] for w in widths]
    )
    best = interior_peak(widths, s)
    summary = {
        "fov_width_m": widths,
        "sensitivity": s,
        "best_width_m": best,
        "best_over_wavelength": best / WAVELENGTH,
        "max_sensitivity": float(s.max()),
        "wavelength_m": WAVELENGTH,
    }

    def plot(fig):
        ax = fig.subplots()
        ax.plot(widths, s, "o-", ms=3)
        ax.axvline(WAVELENGTH / 3, color="0.6", ls=":", label="lambda_R / 3")
        ax.set(
            xlabel="footprint width (m)",
            ylabel="sensitivity S (eq. 21)",
            title="ground, sun at 0.01 rad (paper Fig. 15)",
        )
        ax.legend()

    write_study(outdir, "fig15", {"fov_width_m": widths, "sensitivity": s}, summary, plot)
    return f"fig15: maximum S = {s.max():.2e} at {best:.1f} m = {best / WAVELENGTH:.2f} lambda_R (paper ~5e-3 at ~24 m)"
