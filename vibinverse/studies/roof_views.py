"""Paper Figs. 8, 9 and 10 (sec. 4.1): the elastic steel roof's sensitivity against view offset
(centered and quadrant footprints) and against vibration amplitude."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vibinverse.studies.common import one_cycle, sweep, write_study

SCENE = "roof_elastic"
CENTERED = ["footprint.x=[-25, 25]", "footprint.y=[-25, 25]"]


def _base(quick: bool) -> list[str]:
    return [*one_cycle(40.0, 100 if quick else 400), f"footprint.resolution={48 if quick else 128}"]


def view_sweep(outdir: Path, name: str, footprint: list[str], label: str, quick: bool) -> str:
    offsets = np.linspace(-0.02, 0.02, 17 if quick else 41)
    s = sweep(SCENE, [*_base(quick), *footprint], [[f"sensor.inclination={float(np.pi / 3 + d)!r}"] for d in offsets])
    summary = {
        "view_offset_rad": offsets,
        "sensitivity": s,
        "footprint": label,
        "min_sensitivity": float(s.min()),
        "at_0.015_rad": float(np.interp(0.015, offsets, s)),
    }

    def plot(fig):
        ax = fig.subplots()
        ax.semilogy(offsets, s, "o-", ms=3)
        ax.set(
            xlabel="view offset from the lobe centre (rad)",
            ylabel="sensitivity S (eq. 21)",
            title=f"elastic steel roof, {label} footprint (paper Fig. {name[3:]})",
        )

    write_study(outdir, name, {"view_offset_rad": offsets, "sensitivity": s}, summary, plot)
    return (
        f"{name}: {label} footprint, S from {s.min():.2e} to {s.max():.2e} over +-0.02 rad; "
        f"{summary['at_0.015_rad']:.2e} at 0.015 rad"
    )


def fig8(outdir: Path, quick: bool = False) -> str:
    return view_sweep(outdir, "fig8", CENTERED, "centered", quick)


def fig9(outdir: Path, quick: bool = False) -> str:
    return view_sweep(outdir, "fig9", [], "quadrant", quick)


def fig10(outdir: Path, quick: bool = False) -> str:
    amps = np.logspace(-7, -1, 13 if quick else 31)
    s = sweep(SCENE, _base(quick), [[f"surfaces.roof.motion.center_deflection={float(a)!r}"] for a in amps])
    small = amps <= 1e-5
    slope = float(np.polyfit(np.log(amps[small]), np.log(s[small]), 1)[0])
    summary = {
        "amplitude_m": amps,
        "sensitivity": s,
        "small_amplitude_loglog_slope": slope,
        "max_sensitivity": float(s.max()),
    }

    def plot(fig):
        ax = fig.subplots()
        ax.loglog(amps, s, "o-", ms=3)
        ax.set(
            xlabel="centre deflection (m)",
            ylabel="sensitivity S (eq. 21)",
            title="elastic roof, quadrant, 0.015 rad off the lobe (paper Fig. 10, captioned 'Figure 1')",
        )

    write_study(outdir, "fig10", {"amplitude_m": amps, "sensitivity": s}, summary, plot)
    return f"fig10: log-log slope {slope:.3f} below 10 um, saturating at S = {s.max():.3f}"
