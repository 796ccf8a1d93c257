"""Sun position from date, clock time and place, through pvlib's solar position (NREL SPA).

Scene axes: x points east, y north, z up. A scene azimuth is counter-clockwise from +x (east), so
a solar azimuth A measured clockwise from north becomes pi/2 - A. The elevation is pvlib's
apparent elevation (with atmospheric refraction), which is what a sensor sees.
"""

from __future__ import annotations

import datetime as dt
import math

from forward.errors import SceneError


def sun_angles(
    date: str, hour: float, latitude: float, longitude: float, utc_offset: float = 0.0
) -> tuple[float, float]:
    """(elevation, scene azimuth) in rad of the sun on `date` (YYYY-MM-DD) at `hour` local clock
    time (hours after midnight, UTC + `utc_offset` hours), at `latitude`, `longitude` (degrees,
    north and east positive). SceneError names `sun.hour` when the sun is below the horizon."""
    import pandas as pd
    from pvlib.solarposition import get_solarposition

    try:
        day = dt.date.fromisoformat(str(date))
    except ValueError:
        raise SceneError(f"sun.date: expected YYYY-MM-DD, got {date!r}") from None
    local = dt.datetime(day.year, day.month, day.day) + dt.timedelta(hours=hour)
    utc = local - dt.timedelta(hours=utc_offset)
    sp = get_solarposition(pd.DatetimeIndex([utc], tz="UTC"), latitude, longitude)
    elevation = math.radians(float(sp["apparent_elevation"].iloc[0]))
    azimuth = math.radians(float(sp["azimuth"].iloc[0]))
    if elevation <= 0.0:
        raise SceneError(
            f"sun.hour: the sun is below the horizon at {hour:g} h on {day} "
            f"(elevation {elevation:.3f} rad); allowed: hours with the sun up"
        )
    return elevation, math.remainder(math.pi / 2 - azimuth, 2 * math.pi)
