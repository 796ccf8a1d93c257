"""Ground Rayleigh waves (17)-(20): closed form of (19), continuity, far field, slopes."""

import numpy as np
import pytest

from forward.errors import SceneError
from forward.motion.ground import RayleighMotion, continuity, green_2d, green_2d_quadrature
from forward.render import pixel_signal, sensitivity

K, W = 2 * np.pi * 40 / 3000, 2 * np.pi * 40
RADII = [0.5, 1.0, 3.0, 10.0, 24.0, 50.0, 75.0, 150.0, 400.0, 1000.0]


@pytest.mark.parametrize("r", RADII)
def test_closed_form_matches_quadrature_of_eq_19(r):
    scale = np.hypot(green_2d(r, 0.0, K, W), green_2d(r, np.pi / (2 * W), K, W))  # envelope pi |H0(kr)|
    for t in (0.0, 0.0037, 0.011):
        assert abs(green_2d(r, t, K, W) - green_2d_quadrature(r, t, K, W)) < 1e-6 * scale


def test_displacement_is_continuous_at_the_source_radius():
    m = RayleighMotion((0.0, 0.0), 5.0, 3000.0, np.array([40.0, 55.0]), np.array([1e-3, 4e-4]))
    t = np.linspace(0, 0.2, 101)
    inside, outside = m.displacement(np.nextafter(5.0, 0), t), m.displacement(5.0, t)
    assert np.abs(inside - outside).max() < 1e-12 * 1.4e-3
    c, phi = continuity(5.0, K, 1e-3)
    assert c > 0 and -np.pi <= phi <= np.pi


def test_far_field_decays_as_inverse_square_root():
    m = RayleighMotion((0.0, 0.0), 5.0, 3000.0, np.array([40.0]), np.array([1e-3]))
    env = lambda r: np.hypot(m.displacement(r, 0.0), m.displacement(r, np.pi / (2 * W)))
    assert env(4000.0) / env(1000.0) == pytest.approx(0.5, rel=1e-3)
    assert env(16000.0) / env(4000.0) == pytest.approx(0.5, rel=1e-4)


@pytest.mark.parametrize("phases", [None, np.array([0.7, -2.1])])
def test_slopes_are_the_gradient_of_the_displacement_and_superpose(phases):
    lines = ((40.0, 1e-3), (55.0, 4e-4))
    m = RayleighMotion((3.0, -2.0), 5.0, 3000.0, np.array([40.0, 55.0]), np.array([1e-3, 4e-4]), phases)
    x, y = np.array([10.0, 30.0, -20.0]), np.array([4.0, -25.0, 7.0])
    t = np.array([0.0, 0.004, 0.013])
    gx, gy = m.slopes(x, y, t)
    h = 1e-4
    u = lambda xx, yy: m.displacement(np.hypot(xx - 3.0, yy + 2.0)[None, :], t[:, None])
    np.testing.assert_allclose(gx, (u(x + h, y) - u(x - h, y)) / (2 * h), rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(gy, (u(x, y + h) - u(x, y - h)) / (2 * h), rtol=1e-6, atol=1e-12)
    one = [
        RayleighMotion(
            (3.0, -2.0), 5.0, 3000.0, np.array([f]), np.array([a]), None if phases is None else phases[i : i + 1]
        )
        for i, (f, a) in enumerate(lines)
    ]
    np.testing.assert_allclose(gx, one[0].slopes(x, y, t)[0] + one[1].slopes(x, y, t)[0], rtol=1e-12)


def test_a_source_phase_is_a_time_shift():
    f, ph = np.array([40.0, 55.0]), np.array([0.7, -2.1])
    x, y = np.array([10.0, 30.0, -20.0]), np.array([4.0, -25.0, 7.0])
    t = np.array([0.0, 0.004, 0.013])
    for i in range(2):  # phase p at t is no phase at t + p / omega
        shifted = RayleighMotion((3.0, -2.0), 5.0, 3000.0, f[i : i + 1], np.array([1.0]), ph[i : i + 1])
        plain = RayleighMotion((3.0, -2.0), 5.0, 3000.0, f[i : i + 1], np.array([1.0]))
        np.testing.assert_allclose(
            shifted.slopes(x, y, t)[0], plain.slopes(x, y, t + ph[i] / (2 * np.pi * f[i]))[0], rtol=1e-9, atol=1e-15
        )
    with pytest.raises(SceneError, match="phase"):
        RayleighMotion((0.0, 0.0), 5.0, 3000.0, f, np.array([1e-3, 4e-4]), np.array([0.1]))


def test_centre_and_tiny_source_are_finite():
    m = RayleighMotion((0.0, 0.0), 1e-6, 3000.0, np.array([40.0]), np.array([1e-3]))
    gx, gy = m.slopes(np.array([0.0, 1e-7, 1e-3, 1.0]), np.array([0.0, 0.0, 0.0, 0.0]), np.array([0.0, 0.01]))
    assert np.all(np.isfinite(gx)) and np.all(np.isfinite(gy))
    assert gx[:, 0] == pytest.approx(0.0) and gx[:, 1] == pytest.approx(0.0)  # inside the piston: flat


def test_invalid_ground_parameters(scene):
    with pytest.raises(SceneError, match="radius"):
        RayleighMotion((0.0, 0.0), 0.0, 3000.0, np.array([40.0]), np.array([1e-3]))
    with pytest.raises(SceneError, match="radius"):
        scene("ground_rayleigh", "surfaces.ground.motion.radius=-1")
    with pytest.raises(SceneError, match="wave_speed"):
        scene("ground_rayleigh", "surfaces.ground.motion.wave_speed=0")


def test_sec_4_3_low_sun_is_more_sensitive(scene):
    fast = ("footprint.resolution=48", "sampling.duration=0.1")
    low = sensitivity(pixel_signal(scene("ground_rayleigh", *fast)))
    high = sensitivity(pixel_signal(scene("ground_rayleigh", *fast, "sun.inclination=1.0")))
    assert low > 1e-4 and low > 10 * high
