"""Paper Fig. 6: the ground model's radial slices over half a period (f = 60 Hz, R = 25 m)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from forward.motion.ground import RayleighMotion
from vibinverse.studies.common import write_study

F, R, V, A0 = 60.0, 25.0, 3000.0, 1e-3


def fig6(outdir: Path, quick: bool = False) -> str:
    m = RayleighMotion((0.0, 0.0), R, V, np.array([F]), np.array([A0]))
    r = np.linspace(0.0, 200.0, 401 if quick else 2001)
    times = np.linspace(0.0, 0.5 / F, 6)
    slices = {f"u_t{i}_m": m.displacement(r, t) for i, t in enumerate(times)}
    tt = np.linspace(0.0, 1.0 / F, 2001)
    cont = float(np.abs(m.displacement(np.nextafter(R, 0.0), tt) - m.displacement(R, tt)).max() / A0)
    env = lambda x: np.hypot(m.displacement(x, 0.0), m.displacement(x, 0.25 / F))
    decay = float(np.log(env(4000.0) / env(1000.0)) / np.log(4.0))
    summary = {
        "wavelength_m": float(m.wavelength()[0]),
        "continuity_error": cont,
        "far_field_exponent": decay,
        "case": {"frequency_hz": F, "radius_m": R, "wave_speed_m_s": V, "amplitude_m": A0},
    }

    def plot(fig):
        ax = fig.subplots()
        for (_k, u), t in zip(slices.items(), times):
            ax.plot(r, u * 1e3, label=f"t = {t * 1e3:.1f} ms")
        ax.axvline(R, color="0.5", ls=":", lw=0.8)
        ax.set(
            xlabel="r (m)",
            ylabel="u (mm)",
            title=f"Rayleigh waves, f = {F:g} Hz, R = {R:g} m, wavelength {summary['wavelength_m']:g} m",
        )
        ax.legend()

    write_study(outdir, "fig6", {"r_m": r, **slices}, summary, plot)
    return (
        f"fig6: wavelength {summary['wavelength_m']:g} m, continuity error {cont:.1e} of A0, far field ~ r^{decay:.3f}"
    )
