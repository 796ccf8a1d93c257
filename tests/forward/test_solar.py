"""Sun position from date, clock time and place."""

import math

import numpy as np
import pytest

from forward.errors import SceneError
from forward.solar import sun_angles


def test_sun_position_equinox_noon_and_below_horizon():
    # at an equinox the noon sun stands 90 deg - |latitude| high (declination ~0; refraction < 0.1 deg)
    for lat in (0.0, 30.0, -45.0):
        best = max(sun_angles("2026-03-20", h, lat, 0.0)[0] for h in np.arange(11.9, 12.3, 0.01))
        assert math.degrees(best) == pytest.approx(90.0 - abs(lat), abs=0.6)
    # morning sun in the east: scene azimuth (from +x = east) near 0
    el, az = sun_angles("2026-03-20", 7.0, 0.0, 0.0)
    assert 0 < el < 0.5 and abs(az) < 0.1
    with pytest.raises(SceneError, match=r"sun\.hour: the sun is below the horizon"):
        sun_angles("2026-03-20", 0.0, 0.0, 0.0)
