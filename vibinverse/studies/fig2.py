"""Paper Fig. 2: quasi-static deformation of a 3 m x 3 m glass pane driven through its frame (eq. (10))."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from forward.motion.plate import PlateMotion, poisson_shape
from vibinverse.studies.common import write_study

L, F, RHO, A0, G = 3.0, 50.0, 2600.0, 1e-3, 26.2e9


def fig2(outdir: Path, quick: bool = False) -> str:
    q = PlateMotion.q_boundary(F, RHO, A0, G)
    n = 61 if quick else 201
    xs = np.linspace(0.0, L, n)
    gx, gy = np.meshgrid(xs, xs, indexing="ij")
    w, wx, wy = poisson_shape(gx.ravel(), gy.ravel(), L, L)
    u, grad = q * w.reshape(n, n), q * np.hypot(wx, wy).reshape(n, n)
    cells = (np.arange(12) + 0.5) * L / 12
    cx, cy = np.meshgrid(cells, cells, indexing="ij")
    _, cwx, cwy = poisson_shape(cx.ravel(), cy.ravel(), L, L)
    summary = {
        "max_displacement_m": float(u.max()),
        "max_gradient": float(grad.max()),
        "max_gradient_12x12_cell_centres": float(q * np.hypot(cwx, cwy).max()),
        "paper": {"max_displacement_m": 6e-6, "max_gradient": 1e-5},
        "case": {"side_m": L, "omega_rad_s": 2 * np.pi * F, "density": RHO, "A0_m": A0, "G_Pa": G},
    }
    mid = n // 2
    curve = {"x_m": xs, "u_mid_m": u[:, mid], "grad_mid": grad[:, mid]}

    def plot(fig):
        ax1, ax2 = fig.subplots(1, 2)
        for ax, field, label in ((ax1, u * 1e6, "displacement (um)"), (ax2, grad * 1e6, "|grad u| (1e-6)")):
            im = ax.imshow(field.T, origin="lower", extent=(0, L, 0, L), cmap="viridis")
            fig.colorbar(im, ax=ax, label=label, shrink=0.8)
            ax.set(xlabel="x (m)", ylabel="y (m)")
        ax1.set_title(f"max {summary['max_displacement_m'] * 1e6:.2f} um")
        ax2.set_title(f"max {summary['max_gradient']:.3g} (edge midpoints)")

    write_study(outdir, "fig2", curve, summary, plot)
    return (
        f"fig2: max displacement {summary['max_displacement_m'] * 1e6:.2f} um (paper ~6), max gradient "
        f"{summary['max_gradient']:.3g} (paper ~1e-5; "
        f"12x12 cell centres {summary['max_gradient_12x12_cell_centres']:.3g})"
    )
