import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from forward.geometry import direction, normals_from_slopes
from forward.polarizer import Polarizer, sensor_axes

SUN = direction(np.pi / 3, np.pi)
VIEW = direction(np.pi / 3, 0.0)
FLAT = np.array([0.0, 0.0, 1.0])


def test_sensor_axes_are_s_and_p_of_the_nominal_plane_of_incidence():
    s, p = sensor_axes(VIEW)
    np.testing.assert_allclose(s, [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(p, [-np.sin(np.pi / 3), 0, np.cos(np.pi / 3)], atol=1e-15)


def test_flat_facet_in_the_plane_of_incidence_passes_pure_s_or_p():
    assert Polarizer.parse("s").weights(FLAT, SUN, VIEW) == pytest.approx((0.5, 0.0), abs=1e-15)
    assert Polarizer.parse("p").weights(FLAT, SUN, VIEW) == pytest.approx((0.0, 0.5), abs=1e-15)
    assert Polarizer.parse("none").weights(FLAT, SUN, VIEW) == pytest.approx((0.5, 0.5))


@settings(max_examples=200, deadline=None)
@given(gx=st.floats(-0.3, 0.3), gy=st.floats(-0.3, 0.3), angle=st.floats(0.0, np.pi))
def test_crossed_polarizers_add_up_to_no_polarizer(gx, gy, angle):
    n = normals_from_slopes(gx, gy)
    ws1, wp1 = Polarizer(angle).weights(n, SUN, VIEW)
    ws2, wp2 = Polarizer(angle + np.pi / 2).weights(n, SUN, VIEW)
    assert ws1 + ws2 == pytest.approx(0.5, abs=1e-12)
    assert wp1 + wp2 == pytest.approx(0.5, abs=1e-12)


def test_out_of_plane_tilt_leaks_s_into_the_p_channel_at_second_order():
    p = Polarizer.parse("p")
    leak = [p.weights(normals_from_slopes(0.0, d), SUN, VIEW)[0] for d in (1e-5, 2e-5)]
    assert leak[0] > 0
    assert leak[1] / leak[0] == pytest.approx(4.0, rel=1e-4)
    # an in-plane tilt keeps the plane of incidence: no leak
    assert p.weights(normals_from_slopes(1e-5, 0.0), SUN, VIEW)[0] == pytest.approx(0.0, abs=1e-25)
