"""`optimize.maximize_near`: a dear one-dimensional maximum found near its start in few evaluations."""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vibinverse.optimize import maximize_near


def counted(f):
    calls = []

    def g(x):
        calls.append(x)
        return f(x)

    return g, calls


@settings(max_examples=200, deadline=None)
@given(top=st.floats(-8.0, 8.0), offset=st.floats(-6.0, 6.0), curvature=st.floats(1.0, 1e4))
def test_a_parabola_s_top_is_found_from_anywhere_within_the_limits(top, offset, curvature):
    f, calls = counted(lambda x: -curvature * (x - top) ** 2)
    x0 = min(max(top + offset, -10.0), 10.0)
    best, x = maximize_near(f, x0, f(x0), (-10.0, 10.0))
    assert x == pytest.approx(top, abs=1e-6)  # a parabola's vertex is exact
    assert best == pytest.approx(0.0, abs=1e-6 * curvature)
    assert len(calls) <= 3 + 2 * 5  # the start, the triple, <= 5 doublings of 0.25 to cover 6


def test_from_within_a_step_it_takes_two_or_three_evaluations():
    for x0 in (-0.2, 0.0, 0.05, 0.24):
        f, calls = counted(lambda x: -((x - 0.03) ** 2) - 0.1 * (x - 0.03) ** 4)
        f0 = f(x0)
        calls.clear()
        best, _ = maximize_near(f, x0, f0, (-5.0, 5.0), tol=0.01)
        assert len(calls) <= 3
        assert best >= max(f0, -0.01)  # within the tolerance of the top, f(0.03) = 0


def test_a_maximum_beyond_the_limits_stops_at_the_limit():
    best, x = maximize_near(lambda x: x, 0.0, 0.0, (-1.0, 2.5))
    assert x == 2.5 and best == 2.5


def test_non_finite_values_count_as_minus_infinity():
    f = lambda x: -math.inf if x > 0.1 else -((x + 1.0) ** 2)
    best, x = maximize_near(f, 0.0, f(0.0), (-5.0, 5.0))
    assert x == pytest.approx(-1.0, abs=1e-6) and best == pytest.approx(0.0, abs=1e-9)
