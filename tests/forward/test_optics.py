import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from forward.materials import LIBRARY
from forward.optics import EPSILON_0, SPEED_OF_LIGHT, brewster_angle, fresnel, index_from_conductivity, reflectance


@pytest.mark.parametrize("n", [1.33, 1.5, 1.5185, 2.4, 0.96 + 6.69j, 2.92 + 3.35j])
def test_normal_incidence_is_the_textbook_value(n):
    r_s, r_p = fresnel(0.0, n)
    expected = abs((n - 1) / (n + 1)) ** 2
    assert r_s == pytest.approx(expected, rel=1e-14)
    assert r_p == pytest.approx(expected, rel=1e-14)


@pytest.mark.parametrize("n", [1.5, LIBRARY["glass"].index.real])
def test_p_reflectance_vanishes_at_brewster(n):
    theta_b = brewster_angle(n)
    assert fresnel(theta_b, n)[1] < 1e-12
    assert fresnel(theta_b, n)[0] > 0.1  # s is still reflected


def test_brewster_angle_of_paper_glass_is_56_3_degrees():
    assert np.degrees(brewster_angle(1.5)) == pytest.approx(56.3099, abs=1e-4)
    with pytest.raises(ValueError, match="dielectric"):
        brewster_angle(2.92 + 3.35j)


@pytest.mark.parametrize("n", [1.5, 2.92 + 3.35j, 0.96 + 6.69j])
def test_grazing_incidence_reflects_everything(n):
    assert reflectance(np.pi / 2, n) == pytest.approx(1.0, abs=1e-12)
    # 1 - R grows linearly away from grazing: at 1e-4 rad it is below 1e-3
    assert 1.0 - reflectance(np.pi / 2 - 1e-4, n) < 1e-3


def test_matches_the_papers_form_of_eqs_2_and_3_for_dielectrics():
    th = np.linspace(0, np.pi / 2, 181)
    n = 1.5
    ct = np.sqrt(1 - (np.sin(th) / n) ** 2)
    rs = ((np.cos(th) - n * ct) / (np.cos(th) + n * ct)) ** 2
    rp = ((ct - n * np.cos(th)) / (ct + n * np.cos(th))) ** 2
    r_s, r_p = fresnel(th, n)
    np.testing.assert_allclose(r_s, rs, atol=1e-15)
    np.testing.assert_allclose(r_p, rp, atol=1e-15)


def test_total_internal_reflection_from_the_dense_side():
    critical = np.arcsin(1 / 1.5)
    th = np.linspace(critical + 1e-6, np.pi / 2, 50)
    r_s, r_p = fresnel(th, 1.0, n1=1.5)
    np.testing.assert_allclose(r_s, 1.0, atol=1e-12)
    np.testing.assert_allclose(r_p, 1.0, atol=1e-12)


def test_conductivity_index_obeys_hagen_rubens():
    sigma, lam = 1e7, 10e-6  # a good conductor in the thermal infrared
    n = index_from_conductivity(sigma, lam)
    omega = 2 * np.pi * SPEED_OF_LIGHT / lam
    hagen_rubens = 1 - 2 * np.sqrt(2 * EPSILON_0 * omega / sigma)
    assert reflectance(0.0, n) == pytest.approx(hagen_rubens, abs=1e-3)
    assert n.imag > 0  # absorbing


def test_vectorized_over_angle_and_index():
    th = np.linspace(0, 1.5, 7)[:, None]
    n = np.array([1.5, 2.92 + 3.35j])[None, :]
    r_s, r_p = fresnel(th, n)
    assert r_s.shape == r_p.shape == (7, 2)
    assert r_s[3, 1] == pytest.approx(fresnel(th[3, 0], n[0, 1])[0], rel=1e-15)


@settings(max_examples=300, deadline=None)
@given(theta=st.floats(0.0, np.pi / 2), re=st.floats(0.05, 20.0), im=st.floats(0.0, 20.0))
def test_reflectance_is_a_probability_for_any_absorbing_index(theta, re, im):
    r_s, r_p = fresnel(theta, complex(re, im))
    assert 0.0 <= r_s <= 1.0 + 1e-12
    assert 0.0 <= r_p <= 1.0 + 1e-12
