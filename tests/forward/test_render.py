"""The pixel signal (22)-(23) and sensitivity (21) on the paper's sec. 4.1 scenes."""

import numpy as np
import pytest

from forward.brdf import lobe_normalization
from forward.materials import LIBRARY
from forward.optics import reflectance
from forward.render import pixel_signal, sensitivity
from tests.conftest import FAST

CENTERED = ("footprint.x=[-25, 25]", "footprint.y=[-25, 25]")


def dominant_frequency(scene):
    x = pixel_signal(scene)
    spec = np.abs(np.fft.rfft(x - x.mean()))
    return np.fft.rfftfreq(x.size, 1 / scene.sampling.fs)[spec.argmax()]


def test_quadrant_sees_the_drive_and_centered_sees_twice_the_drive(scene):
    assert dominant_frequency(scene("roof_elastic", *FAST)) == pytest.approx(40.0)
    assert dominant_frequency(scene("roof_elastic", *FAST, *CENTERED)) == pytest.approx(80.0)


def test_quadrant_is_at_least_100x_more_sensitive_than_centered(scene):
    quadrant = sensitivity(pixel_signal(scene("roof_elastic", *FAST)))
    centered = sensitivity(pixel_signal(scene("roof_elastic", *FAST, *CENTERED)))
    assert quadrant / centered >= 100.0
    assert 1e-6 < centered < 1e-3  # the paper: ~1e-4 within 0.03 rad of the lobe


def test_brewster_p_polarizer_beats_no_polarizer_by_1000x(scene):
    p = sensitivity(pixel_signal(scene("glass_brewster", *FAST)))
    none = sensitivity(pixel_signal(scene("glass_brewster", *FAST, "sensor.polarizer='none'")))
    assert p > 0.5  # order 1: R_p = 0 whenever the pane is flat
    assert p / none >= 1000.0
    assert none == pytest.approx(3e-5, rel=0.5)  # the paper: 3e-5


def test_flat_specular_roof_matches_the_closed_form(scene):
    # static roof filling the footprint, sensor on the lobe centre: x = cos_i R C / v_z (projected)
    s = scene("roof_elastic", *FAST, *CENTERED, "sensor.inclination='pi/3'", "surfaces.roof.motion.center_deflection=0")
    theta_i = np.pi / 6
    expected = np.cos(theta_i) * reflectance(theta_i, LIBRARY["steel"].index) * lobe_normalization(0.01, theta_i)
    np.testing.assert_allclose(pixel_signal(s), expected / np.sin(np.pi / 3), rtol=1e-12)
    paper = scene(
        "roof_elastic",
        *FAST,
        *CENTERED,
        "sensor.inclination='pi/3'",
        "sensor.radiometry='paper'",
        "surfaces.roof.motion.center_deflection=0",
    )
    np.testing.assert_allclose(pixel_signal(paper), expected / np.cos(theta_i), rtol=1e-12)  # eq. (23) as printed


def test_lambertian_background_alone_is_albedo_over_pi_times_cos_i(scene):
    s = scene("roof_elastic", *FAST, "footprint.x=[100, 150]", "background.material={albedo=0.3}")
    np.testing.assert_allclose(pixel_signal(s), 0.3 / np.pi * np.sin(np.pi / 3), rtol=1e-14)
    assert sensitivity(pixel_signal(s)) == 0.0


def test_radiometry_options_differ_at_first_order_in_tilt(scene):
    proj = pixel_signal(scene("roof_elastic", *FAST))
    paper = pixel_signal(scene("roof_elastic", *FAST, "sensor.radiometry='paper'"))
    rel = np.abs(proj / proj.mean() - paper / paper.mean()).max()
    assert 1e-7 < rel < 1e-3  # tilt ~1e-4 rad: a first-order difference, small but not zero


def test_sensitivity_is_linear_in_small_amplitudes_down_to_1e_9(scene):
    s = [
        sensitivity(pixel_signal(scene("roof_elastic", *FAST, f"surfaces.roof.motion.center_deflection={a}")))
        for a in (1e-9, 1e-7, 1e-5)
    ]
    assert s[1] / s[0] == pytest.approx(100.0, rel=0.02)
    assert s[2] / s[1] == pytest.approx(100.0, rel=0.02)


def test_large_amplitude_saturates_below_one(scene):
    s = sensitivity(pixel_signal(scene("roof_elastic", *FAST, "surfaces.roof.motion.center_deflection=0.05")))
    assert 0.5 < s < 1.0


@pytest.mark.parametrize(
    "overrides",
    [
        ("sun.inclination=0.01", "sensor.inclination=0.01"),  # grazing sun, grazing view on the lobe
        ("sensor.inclination='pi/3 + 0.05'",),  # far out on the lobe edge
        ("sun.inclination='pi/2'", "sensor.inclination='pi/2'"),  # overhead: normal incidence
    ],
)
def test_hard_geometries_give_finite_signals(scene, overrides):
    x = pixel_signal(scene("roof_elastic", *FAST, *overrides))
    assert np.all(np.isfinite(x)) and np.all(x > 0)
    assert np.isfinite(sensitivity(x))


def test_frequency_near_nyquist_is_sampled_not_rejected(scene):
    s = scene("roof_elastic", *FAST, "surfaces.roof.motion.frequency=475")
    assert dominant_frequency(s) == pytest.approx(475.0, abs=10.0)


def test_sensitivity_ignores_gaps_and_refuses_undefined_cases():
    assert sensitivity([1.0, np.nan, 2.0]) == 0.5
    with pytest.raises(ValueError, match="no finite"):
        sensitivity([np.nan, np.nan])
    with pytest.raises(ValueError, match="maximum"):
        sensitivity([0.0, 0.0])
