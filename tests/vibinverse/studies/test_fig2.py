"""Paper Figs. 2 and 6 (quick): the pane's displacement and gradient, the ground wave's numbers."""

import pytest


def test_fig2_and_fig6_numbers(results):
    _, _, d = results
    assert d["fig2"]["max_displacement_m"] == pytest.approx(6.49e-6, rel=0.01)
    assert d["fig2"]["max_gradient"] == pytest.approx(9.92e-6, rel=0.01)
    assert d["fig6"]["wavelength_m"] == pytest.approx(50.0)
    assert d["fig6"]["continuity_error"] < 1e-12
    assert d["fig6"]["far_field_exponent"] == pytest.approx(-0.5, abs=1e-3)
