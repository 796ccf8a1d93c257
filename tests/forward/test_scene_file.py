import math

import pytest

from forward.errors import SceneError
from forward.scene_file import apply_overrides, load_scene, parse_value
from forward.validation import expression
from tests.conftest import SCENES


def test_expressions_and_overrides():
    assert expression("pi/3 + 0.015", "k") == pytest.approx(math.pi / 3 + 0.015)
    assert expression("pi/2 - arctan(1.5)", "k") == pytest.approx(math.pi / 2 - math.atan(1.5))
    assert parse_value("[0, 25]") == [0, 25] and parse_value("p") == "p" and parse_value("1e-3") == 1e-3
    t = apply_overrides({"a": {"b": 1}}, ["a.b=2", "a.c.d='x'"])
    assert t == {"a": {"b": 2, "c": {"d": "x"}}}


def test_example_scenes_load_with_the_papers_geometry():
    s, _ = load_scene(SCENES / "roof_elastic.toml")
    assert s.sensor.inclination == pytest.approx(math.pi / 3 + 0.015)
    assert s.surfaces[0].motion.frequency == 40.0
    g, _ = load_scene(SCENES / "glass_brewster.toml")
    assert math.pi / 2 - g.sun.inclination == pytest.approx(math.atan(g.surfaces[0].material.index.real), abs=1e-12)


@pytest.mark.parametrize(
    "override, message",
    [
        ("sensr.inclination=1", "sensr: unknown key"),
        ("surfaces.roof.colour=1", "surfaces.roof.colour: unknown key"),
        ("footprint.x=[5, -5]", "footprint.x: .*size > 0"),
        ("surfaces.roof.x=[1, 1]", "surfaces.roof.x: .*size > 0"),
        ("sun.inclination=0", r"sun.inclination: .*\(0, pi/2\]"),
        ("sensor.inclination=1.7", r"sensor.inclination: .*\(0, pi/2\]"),
        ("surfaces.roof.lobe_width=0", r"surfaces.roof.lobe_width: .*\(0, 0.5\]"),
        ("surfaces.roof.lobe_width=-0.01", r"surfaces.roof.lobe_width: .*\(0, 0.5\]"),
        ("sun.azimuth=nan", "sun.azimuth: must be a finite number"),
        ("sampling.fs='fast'", "sampling.fs: 'fast' is not a number"),
        ("surfaces.roof.motion.frequency=600", "Nyquist"),
        ("surfaces.roof.material='wood'", "unknown material 'wood'"),
        ("sensor.polarizer='q'", "sensor.polarizer"),
        ("footprint.resolution=0", r"footprint.resolution: .*\[1, 4096\]"),
        ("surfaces.roof.motion.pressure=20", "exactly one amplitude"),
        ("sampling.duration=1e-9", "samples"),
    ],
)
def test_bad_values_name_the_key_and_the_allowed_range(override, message):
    with pytest.raises(SceneError, match=message) as err:
        load_scene(SCENES / "roof_elastic.toml", [override])
    assert "\n" not in str(err.value)


def test_missing_and_malformed_files(tmp_path):
    with pytest.raises(SceneError, match="file not found"):
        load_scene(tmp_path / "nope.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[sun\n")
    with pytest.raises(SceneError, match="not valid TOML"):
        load_scene(bad)
