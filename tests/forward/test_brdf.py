import numpy as np
import pytest
from scipy.integrate import quad

from forward.brdf import lambertian, lobe_normalization, lobe_solid_angle, specular_lobe
from forward.geometry import angle_between


def directional_hemispherical_reflectance(m, theta_i, reflectance=0.7):
    """Integral of the lobe BRDF f = B / cos_i times cos_v over the outgoing hemisphere, by a
    tensor Gauss-Legendre rule in the facet frame, windowed around the mirror direction."""
    n_r = np.array([np.sin(theta_i), 0.0, np.cos(theta_i)])
    w = min(14 * m, np.pi)
    t_lo, t_hi = max(0.0, theta_i - w), min(np.pi / 2, theta_i + w)
    phi_half = np.pi if theta_i <= w else min(np.pi, np.arcsin(min(1.0, np.sin(w) / np.sin(theta_i))))
    g, gw = np.polynomial.legendre.leggauss(600)
    t = 0.5 * (t_hi - t_lo) * g + 0.5 * (t_hi + t_lo)
    tw = 0.5 * (t_hi - t_lo) * gw
    p, pw = phi_half * g, phi_half * gw
    T, P = np.meshgrid(t, p, indexing="ij")
    view = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
    cos_i = np.cos(theta_i)
    b = specular_lobe(cos_i, view[..., 2], angle_between(view, n_r), reflectance, m, np.full(T.shape, theta_i))
    return np.sum(b / cos_i * view[..., 2] * np.sin(T) * tw[:, None] * pw[None, :]) / reflectance


def solid_angle_by_adaptive_quadrature(m, theta_i, support=12.0):
    """The lobe's solid angle as two adaptive quadratures (scipy's quad at 1e-12): the cones around
    the mirror direction entirely above the horizon, then those the horizon cuts, whose azimuth span
    above it is 2 arccos(-cot(theta_i) cot(alpha))."""
    top = min(np.pi, support * m)
    full, cut = min(max(np.pi / 2 - theta_i, 0.0), top), min(np.pi / 2 + theta_i, top)
    val = 2 * np.pi * quad(lambda a: np.exp(-0.5 * (a / m) ** 2) * np.sin(a), 0.0, full, epsabs=0.0, epsrel=1e-12)[0]
    if cut > full:
        cot_t = np.cos(theta_i) / np.sin(theta_i)

        def clipped(a):
            span = 2.0 * np.arccos(np.clip(-cot_t * np.cos(a) / np.sin(a), -1.0, 1.0))
            return np.exp(-0.5 * (a / m) ** 2) * np.sin(a) * span

        val += quad(clipped, full, cut, epsabs=0.0, epsrel=1e-11, limit=400)[0]
    return val


@pytest.mark.parametrize("m", [0.001, 0.0047, 0.05, 0.3, 2.0])
def test_lobe_solid_angle_equals_adaptive_quadrature(m):
    # the normalization table's own grid (incidence from grazing to 13 lobe widths inside it), plus
    # normal incidence, grazing and just either side of it: the fixed rules within 1e-11 (measured
    # 5e-13 at worst), where the table itself promises 1e-6
    theta = np.pi / 2 - np.linspace(0.0, min(13.0, (np.pi / 2) / m), 41) * m
    theta = np.concatenate([theta, [0.0, 1e-9, 0.3, np.pi / 2 - 1e-9, np.pi / 2, np.pi / 2 + 0.5 * m]])
    expected = np.array([solid_angle_by_adaptive_quadrature(m, t) for t in theta])
    np.testing.assert_allclose(lobe_solid_angle(m, theta), expected, rtol=1e-11)
    assert lobe_solid_angle(m, 0.3) == pytest.approx(expected[-4], rel=1e-11)  # a scalar in, a scalar out


@pytest.mark.parametrize("m", [0.002, 0.0047, 0.01, 0.05, 0.3])
@pytest.mark.parametrize("deg", [0.0, 30.0, 60.0, 80.0])
def test_lobe_conserves_energy(m, deg):
    assert directional_hemispherical_reflectance(m, np.radians(deg)) == pytest.approx(1.0, abs=1e-3)


def test_narrow_lobe_normalization_is_one_over_two_pi_m_squared():
    m = 0.01
    assert lobe_normalization(m, np.radians(30)) == pytest.approx(1 / (2 * np.pi * m * m), rel=1e-4)


def test_horizon_clips_the_lobe_at_grazing():
    m = 0.05
    c_mid, c_grazing = lobe_normalization(m, np.radians(30)), lobe_normalization(m, np.pi / 2)
    assert c_grazing == pytest.approx(2 * c_mid, rel=0.05)  # half the lobe is below the horizon


def test_lambertian_reflects_its_albedo():
    # integral of (albedo/pi) cos_v over the hemisphere = albedo
    g, w = np.polynomial.legendre.leggauss(64)
    th = 0.25 * np.pi * (g + 1)
    integral = 2 * np.pi * np.sum(0.25 * np.pi * w * np.cos(th) * np.sin(th))
    assert lambertian(1.0, 0.3) * integral == pytest.approx(0.3, rel=1e-12)
    assert lambertian(-0.1, 0.3) == 0.0


def test_lobe_is_zero_when_sun_or_view_is_behind_the_facet():
    assert specular_lobe(-0.1, 0.5, 0.0, 1.0, 0.01, 1.0) == 0.0
    assert specular_lobe(0.5, -0.1, 0.0, 1.0, 0.01, 1.0) == 0.0
    assert np.isfinite(specular_lobe(0.5, 0.0, 0.0, 1.0, 0.01, 1.0))
