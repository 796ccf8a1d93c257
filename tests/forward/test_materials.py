"""The material library: the quoted reflectances and indices."""

import pytest

from forward.materials import LIBRARY
from forward.optics import reflectance


def test_library_materials_reflect_as_quoted():
    assert reflectance(0.0, LIBRARY["steel"].index) == pytest.approx(0.56, abs=0.01)
    assert reflectance(0.0, LIBRARY["aluminium"].index) == pytest.approx(0.92, abs=0.01)
    assert LIBRARY["glass"].index.real == pytest.approx(1.5185, abs=1e-4)
