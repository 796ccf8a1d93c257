"""Paper Figs. 14 and 15 (quick): sun elevation and footprint width on the vibrating ground."""

import numpy as np

from tests.conftest import WAVELENGTH
from vibinverse.studies.common import interior_peak, one_cycle, sweep


def test_fig14_sensitivity_falls_as_the_sun_rises(results):
    _, _, d = results
    s = np.array(d["fig14"]["sensitivity"])
    assert s[0] > 30 * s[-1]
    assert np.mean(np.diff(s) < 0) > 0.8
    limit = d["fig14"]["detectable_below_rad_at_1e-4"]
    assert 0.05 < limit < 0.45  # the paper: ~0.15 rad


def test_fig15_has_an_interior_maximum_near_a_third_of_the_wavelength(results):
    _, _, d = results
    best = d["fig15"]["best_width_m"]
    w = d["fig15"]["fov_width_m"]
    assert w[0] < best < w[-1]
    assert WAVELENGTH / 5 <= best <= WAVELENGTH / 2


def test_fig15_optimum_follows_the_source_radius_not_the_wavelength():
    """Our disagreement with the paper's sec. 5 advice (README): at a fixed source radius the best
    footprint barely moves while the Rayleigh wavelength changes fourfold."""
    widths = np.linspace(2.0, 90.0, 45)
    best = []
    for f in (20.0, 80.0):
        s = sweep(
            "ground_rayleigh",
            [*one_cycle(f, 60), "footprint.resolution=40", f"surfaces.ground.motion.frequency={f}"],
            [[f"footprint.x=[0, {w}]", f"footprint.y=[0, {w}]"] for w in widths],
        )
        best.append(interior_peak(widths, s))
    assert best[0] / best[1] < 1.5  # a lambda/3 rule would give 4
