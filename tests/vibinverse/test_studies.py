"""Reduced-resolution versions of every paper study, asserting the paper's trends."""

import json

import numpy as np
import pytest

from vibinverse.studies import STUDIES
from vibinverse.studies.common import interior_peak, one_cycle, sweep

WAVELENGTH = 75.0
KEYS = {
    "fig2": {"max_displacement_m", "max_gradient"},
    "fig4": {"resonances_hz", "spectral_peaks_hz"},
    "fig6": {"wavelength_m", "continuity_error"},
    "fig8": {"view_offset_rad", "sensitivity"},
    "fig9": {"view_offset_rad", "sensitivity"},
    "fig10": {"amplitude_m", "sensitivity"},
    "fig11": {"incidence_rad", "sensitivity", "sensitivity_unpolarized"},
    "fig13": {"view_offset_rad", "sensitivity", "spectral_peaks_hz"},
    "fig14": {"sun_inclination_rad", "sensitivity"},
    "fig15": {"fov_width_m", "sensitivity"},
}


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    out = tmp_path_factory.mktemp("studies")
    lines = {name: fn(out, quick=True) for name, (fn, _) in STUDIES.items()}
    return out, lines, {name: json.loads((out / f"{name}.json").read_text()) for name in STUDIES}


def test_every_study_writes_its_files_and_keys(results):
    out, lines, data = results
    for name in STUDIES:
        assert lines[name].startswith(f"{name}:") and "\n" not in lines[name]
        assert (out / f"{name}.png").read_bytes()[:4] == b"\x89PNG"
        assert (out / f"{name}.csv").stat().st_size > 0
        assert KEYS[name] <= set(data[name])


def test_fig2_and_fig6_numbers(results):
    _, _, d = results
    assert d["fig2"]["max_displacement_m"] == pytest.approx(6.49e-6, rel=0.01)
    assert d["fig2"]["max_gradient"] == pytest.approx(9.92e-6, rel=0.01)
    assert d["fig6"]["wavelength_m"] == pytest.approx(50.0)
    assert d["fig6"]["continuity_error"] < 1e-12
    assert d["fig6"]["far_field_exponent"] == pytest.approx(-0.5, abs=1e-3)


def test_quadrant_beats_centered_by_100x(results):
    _, _, d = results
    off = np.array(d["fig9"]["view_offset_rad"])
    ratio = np.array(d["fig9"]["sensitivity"]) / np.array(d["fig8"]["sensitivity"])
    assert ratio[np.argmin(abs(off - 0.015))] >= 100
    assert np.median(ratio[np.abs(off) >= 0.005]) >= 100


def test_fig10_linear_then_saturating(results):
    _, _, d = results
    assert d["fig10"]["small_amplitude_loglog_slope"] == pytest.approx(1.0, abs=0.1)
    s = np.array(d["fig10"]["sensitivity"])
    assert 0.3 < s.max() < 1.0
    a = np.array(d["fig10"]["amplitude_m"])
    assert np.log(s[-1] / s[-2]) / np.log(a[-1] / a[-2]) < 0.8  # the log-log slope has bent away from 1


def test_fig11_peaks_at_brewster(results):
    _, _, d = results
    f = d["fig11"]
    assert abs(f["peak_incidence_rad"] - f["brewster_rad"]) < 0.002
    assert f["peak_sensitivity"] > 0.5
    assert f["peak_sensitivity"] / f["sensitivity_unpolarized"] > 1000


def test_fig13_lines_at_tilt_resonance_and_drive(results):
    _, _, d = results
    assert d["fig13"]["drive_line_hz"] == pytest.approx(10.0, abs=0.3)
    assert d["fig13"]["tilt_line_hz"] == pytest.approx(2 * np.sqrt(3), abs=0.4)


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
