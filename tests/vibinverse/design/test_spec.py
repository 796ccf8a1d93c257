"""Sweep specifications and the design keys."""

import math

import pytest

from forward.scene_file import scene_from_table
from tests.conftest import table
from vibinverse.design.spec import configure, parse_vary
from vibinverse.errors import VibinverseError


def test_vary_ranges_lists_and_categories():
    assert parse_vary("sensor.offset=-0.01:0.01:5").values == pytest.approx((-0.01, -0.005, 0.0, 0.005, 0.01))
    assert parse_vary("sun.inclination=pi/6").values == pytest.approx((math.pi / 6,))
    assert parse_vary("sampling.fs=100, 200,400").values == (100.0, 200.0, 400.0)
    assert parse_vary("sensor.polarizer=none,p,s").values == ("none", "p", "s")


@pytest.mark.parametrize(
    "spec, message",
    [
        ("sensor.offset=0:1:0", "empty range"),
        ("sensor.offset=", "empty range"),
        ("sensor.offset=0:1", "start:stop:num"),
        ("sensor.offset=0:1:x", "num must be an integer"),
        ("sampling.fs=fast,slow", "'fast' is not a number"),
        ("sensor.offset=1,,2", "empty item"),
        ("noequals", "expected dotted.key"),
    ],
)
def test_bad_specifications_name_the_problem(spec, message):
    with pytest.raises(VibinverseError, match=message):
        parse_vary(spec)


def test_design_keys_place_view_and_footprint():
    base = table("roof_elastic")
    scene = scene_from_table(configure(base, {"sensor.offset": 0.02, "footprint.center": 0.0}))
    assert scene.sensor.inclination == pytest.approx(scene.sun.inclination + 0.02)
    assert scene.sensor.azimuth == pytest.approx(scene.sun.azimuth + math.pi)
    assert scene.footprint.x == (-25.0, 25.0) and scene.footprint.y == (-25.0, 25.0)
    scene = scene_from_table(configure(base, {"footprint.width": 20.0}))
    assert scene.footprint.x == (0.0, 20.0) and scene.footprint.y == (0.0, 20.0)


def test_sweeps_too_large_to_run_are_refused_before_any_work():
    from vibinverse.design.spec import MAX_CONFIGURATIONS, grid

    with pytest.raises(VibinverseError, match=r"100000 values; allowed 1\.\.10000 per axis"):
        parse_vary("sensor.offset=0:1:100000")
    axes = [parse_vary(f"k{i}=0:1:30") for i in range(4)]  # 30^4 = 810 000 configurations
    with pytest.raises(VibinverseError, match="810,000 configurations; allowed at most"):
        grid(axes)
    assert len(grid([parse_vary("a=0:1:200"), parse_vary("b=0:1:250")])) == MAX_CONFIGURATIONS
