"""The scene template of `vibinverse init`: it loads, every answer lands in the Scene with its unit,
bad answers give one-line errors naming the flag, and the title survives any text."""

import math
import re
import tomllib

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import vibinverse as vi
from forward.materials import LIBRARY, Fresnel, Lambertian
from forward.motion.frame import FrameParameters
from forward.scene_file import load_scene
from forward.solar import sun_angles
from vibinverse.errors import InputError
from vibinverse.io.builtin import builtin_scene
from vibinverse.io.scene_template import SceneAnswers, scene_template, toml_string, write_scene_template

K = "surfaces.roof.motion."


def load(tmp_path, answers=None, name="scene.toml"):
    path = write_scene_template(tmp_path / name, answers or SceneAnswers())
    return load_scene(path)


def roof(scene):
    (surface,) = scene.surfaces
    return surface


def test_the_defaults_load_as_the_papers_frame_scene(tmp_path):
    scene, table = load(tmp_path)
    ref, _ = load_scene(builtin_scene("roof_frame"))
    assert table["title"] == "Roof on a resonant frame (real observation)"
    # sun (60, 180) deg; the sensor 0.01 rad above the sun's mirror direction: the paper's geometry
    assert (scene.sun.inclination, scene.sun.azimuth) == pytest.approx((math.pi / 3, math.pi), abs=1e-15)
    assert scene.sensor.inclination == pytest.approx(math.pi / 3 + 0.01, abs=1e-15)
    assert scene.sensor.azimuth == pytest.approx(0.0, abs=1e-15)
    assert (scene.sampling.fs, scene.sampling.duration, scene.noise.sigma) == (200.0, 20.0, 0.0)
    assert (scene.footprint.x, scene.footprint.y, scene.footprint.resolution) == ((-25.0, 25.0), (-25.0, 25.0), 16)
    r, r_ref = roof(scene), roof(ref)
    assert (r.name, r.x, r.y, r.material, r.lobe_width) == ("roof", r_ref.x, r_ref.y, r_ref.material, 0.01)
    assert r.material.index == 2.92 + 3.35j  # steel
    assert scene.background.material == LIBRARY["ground"]
    modal = r.motion.params.modal()
    assert modal["tilt"] == pytest.approx((3.0, 0.02), rel=1e-12)
    assert modal["lateral"][0] == pytest.approx(3.0 * 2 / math.sqrt(3), rel=1e-12)
    np.testing.assert_array_equal(r.motion.drive.frequencies, [10.0])
    np.testing.assert_array_equal(r.motion.drive.amplitudes, [1e-3])
    assert r.motion.noise_rms == 1e-4


def test_every_key_carries_a_comment_on_its_line_or_just_above():
    text = scene_template(SceneAnswers(date="2024-06-21", hour=12.0, latitude=0.0, longitude=0.0))
    lines = text.splitlines()
    keys = [i for i, ln in enumerate(lines) if re.match(r"^[a-z_]+ = ", ln)]
    leaves = lambda t: sum(leaves(v) if isinstance(v, dict) else 1 for v in t.values())
    assert len(keys) == leaves(tomllib.loads(text)) == 33  # every key of the file is on its own line
    bare = [lines[i] for i in keys if "  # " not in lines[i] and not lines[i - 1].startswith("#")]
    assert bare == []


def test_the_sun_by_date_and_place_is_the_solar_position_of_pvlib(tmp_path):
    answers = SceneAnswers(date="2024-06-21", hour=13.5, latitude=48.1, longitude=11.6, utc_offset=2.0)
    scene, table = load(tmp_path, answers)
    elevation, azimuth = sun_angles("2024-06-21", 13.5, 48.1, 11.6, 2.0)
    assert (scene.sun.inclination, scene.sun.azimuth) == (elevation, azimuth)
    assert {k: table["sun"][k] for k in ("date", "hour", "latitude", "longitude", "utc_offset")} == {
        "date": "2024-06-21",
        "hour": 13.5,
        "latitude": 48.1,
        "longitude": 11.6,
        "utc_offset": 2.0,
    }
    # Munich at 11:30 UTC on the solstice: near the noon maximum 90 - 48.1 + 23.44 = 65.34 deg, just
    # west of south (scene azimuth -90 deg is south)
    assert math.degrees(elevation) == pytest.approx(65.18, abs=0.02)
    assert math.degrees(azimuth) == pytest.approx(-97.93, abs=0.02)
    # the default sensor: the sun's mirror direction, 0.01 rad higher
    assert scene.sensor.inclination == pytest.approx(elevation + 0.01, abs=1e-12)
    assert scene.sensor.azimuth == pytest.approx(math.remainder(azimuth + math.pi, 2 * math.pi), abs=1e-12)


def test_each_answer_lands_in_the_scene_with_its_unit(tmp_path):
    answers = SceneAnswers(
        title="Hangar 7",
        sun_inclination=40.0,
        sun_azimuth=-100.0,
        view_inclination=75.0,
        view_azimuth=-30.0,
        fs=30.0,
        duration=60.0,
        footprint=(40.0, 30.0),
        roof=(20.0,),
        resolution=8,
        material="aluminium",
        background="glass",
        lobe_width=0.05,
        resonance=2.5,
        damping_ratio=0.05,
        drive=(7.0, 12.0),
        drive_amplitude=2e-3,
        noise_sigma=0.3,
        base_noise=5e-5,
    )
    scene, table = load(tmp_path, answers)
    assert table["title"] == "Hangar 7"
    # degrees in, radians in the Scene
    assert (scene.sun.inclination, scene.sun.azimuth) == (math.radians(40.0), math.radians(-100.0))
    assert (scene.sensor.inclination, scene.sensor.azimuth) == (math.radians(75.0), math.radians(-30.0))
    assert table["sensor"]["inclination"] == "radians(75.0)"
    assert (scene.sampling.fs, scene.sampling.duration, scene.sampling.n_samples) == (30.0, 60.0, 1800)
    assert (scene.footprint.x, scene.footprint.y, scene.footprint.resolution) == ((-20.0, 20.0), (-15.0, 15.0), 8)
    r = roof(scene)
    assert (r.x, r.y) == ((-10.0, 10.0), (-10.0, 10.0))  # one size: a square
    assert r.material == Fresnel(0.96 + 6.69j, LIBRARY["aluminium"].source)
    assert r.lobe_width == 0.05
    assert scene.background.material == LIBRARY["glass"]
    assert scene.noise.sigma == 0.3
    p = r.motion.params
    assert p.modal()["tilt"] == pytest.approx((2.5, 0.05), rel=1e-12)
    assert p.k1 == pytest.approx(p.mass * (2 * math.pi * 2.5) ** 2 / 12, rel=1e-12)  # the file's comment
    np.testing.assert_array_equal(r.motion.drive.frequencies, [7.0, 12.0])
    np.testing.assert_array_equal(r.motion.drive.amplitudes, [2e-3, 2e-3])
    assert r.motion.noise_rms == 5e-5


def test_a_lambertian_roof_has_no_lobe_width(tmp_path):
    scene, table = load(tmp_path, SceneAnswers(material="ground", drive=()))
    assert isinstance(roof(scene).material, Lambertian)
    assert roof(scene).lobe_width is None and "lobe_width" not in table["surfaces"]["roof"]
    assert roof(scene).motion.drive is None


def test_the_comment_gives_the_physical_stiffness_of_the_tilt_guess():
    text = scene_template(SceneAnswers(resonance=3.0))
    k1 = FrameParameters.from_modal(50.0, 50.0, 1.0, tilt=(3.0, 0.02), lateral=(1.0, 0.0)).k1
    assert k1 == pytest.approx(29.6088, rel=1e-5)
    assert f"k_vertical = mass (2 pi f_tilt)^2 / 12 = {k1:.6g} N/m per kg" in text
    # the paper's frame: k1 = (2 pi)^2 gives its tilt resonance 2 sqrt(3) Hz
    assert FrameParameters(1.0, 50.0, 50.0, (2 * math.pi) ** 2, 0.0, 1.0, 0.0).modal()["tilt"][0] == pytest.approx(
        2 * math.sqrt(3), rel=1e-12
    )


@pytest.mark.parametrize(
    ("answers", "message"),
    [
        ({"fs": 0.0}, "--fs: 0 is outside the allowed range (0, inf)"),
        ({"fs": math.nan}, "--fs: must be a finite number, got nan"),
        ({"duration": -1.0}, "--duration: -1 is outside the allowed range (0, inf)"),
        ({"duration": 0.001}, "--duration: 0.001 s at 200 Hz is 0 samples; allowed range [2, 100000000] samples"),
        ({"sun_inclination": 95.0}, "--sun-inclination: 95 is outside the allowed range (0, 90]"),
        ({"view_inclination": 0.0}, "--view-inclination: 0 is outside the allowed range (0, 90]"),
        ({"view_azimuth": math.inf}, "--view-azimuth: must be a finite number, got inf"),
        ({"hour": 12.0}, "--date: missing; the sun by date needs --date, --hour, --latitude and --longitude"),
        (
            {"date": "2024-06-21", "hour": 12.0, "latitude": 1.0, "longitude": 1.0, "sun_azimuth": 3.0},
            "--sun-azimuth: give the sun either by --date/--hour/--latitude/--longitude or by",
        ),
        ({"date": "21.06.2024", "hour": 12.0, "latitude": 1.0, "longitude": 1.0}, "--date: expected YYYY-MM-DD"),
        ({"date": "2023-02-29", "hour": 12.0, "latitude": 1.0, "longitude": 1.0}, "--date: 2023-02-29 is not a"),
        ({"date": "2024-06-21", "hour": 25.0, "latitude": 1.0, "longitude": 1.0}, "--hour: 25 is outside the allowed"),
        ({"date": "2024-06-21", "hour": 23.0, "latitude": 48.1, "longitude": 11.6}, "--hour: the sun is below the"),
        ({"date": "2024-06-21", "hour": 12.0, "latitude": 91.0, "longitude": 1.0}, "--latitude: 91 is outside"),
        ({"utc_offset": 15.0}, "--utc-offset: 15 is outside the allowed range [-14, 14]"),
        ({"footprint": (1.0, 2.0, 3.0)}, "--footprint: give one size (a square) or two"),
        ({"roof": (0.0,)}, "--roof: 0 is outside the allowed range (0, inf)"),
        ({"resolution": 0}, "--resolution: 0 is not an integer in [1, 4096]"),
        ({"material": "wood"}, "--material: unknown material 'wood'; allowed: aluminium, glass, glass_paper, ground"),
        ({"background": "sky"}, "--background: unknown material 'sky'"),
        ({"lobe_width": 0.6}, "--lobe-width: 0.6 is outside the allowed range (0, 0.5]"),
        ({"resonance": 100.0}, "--resonance: 100 is outside the allowed range (0, 100) Hz (below fs/2)"),
        ({"damping_ratio": 1.0}, "--damping-ratio: 1 is outside the allowed range [0, 1)"),
        ({"drive": (10.0, 120.0)}, "--drive: 120 is outside the allowed range (0, 100) Hz (below fs/2)"),
        ({"drive_amplitude": -1.0}, "--drive-amplitude: -1 is outside the allowed range [0, inf)"),
        ({"noise_sigma": -0.1}, "--noise-sigma: -0.1 is outside the allowed range [0, inf)"),
        ({"base_noise": True}, "--base-noise: must be a number, got True"),
        ({"title": "x" * 1001}, "--title: 1001 characters; allowed at most 1000"),
        ({"title": "bad \udcff byte"}, "--title: not valid Unicode text"),
    ],
)
def test_a_bad_answer_is_one_line_naming_its_flag(answers, message):
    with pytest.raises(InputError) as err:
        scene_template(SceneAnswers(**answers))
    text = str(err.value)
    assert text.startswith(message), text
    assert "\n" not in text and len(text) < 200


HOSTILE = [
    'a "quoted" title',
    "back\\slash \\n not a newline",
    "two\nlines\r\nand a\ttab",
    '"""\n[sun]\ninclination = 0  # an injected table',
    "'''literal''' # not a comment",
    "bell \x07 escape \x1b[31m del \x7f nul \x00",
    "unicode: Größe 屋根 🏢 \u2028 \u0085",
    "",
]


@pytest.mark.parametrize("title", HOSTILE)
def test_a_hostile_title_round_trips(tmp_path, title):
    scene, table = load(tmp_path, SceneAnswers(title=title))
    assert table["title"] == title
    assert scene.sun.inclination == pytest.approx(math.pi / 3)  # nothing injected


@given(st.text(alphabet=st.characters(blacklist_categories=("Cs",)), max_size=60))
def test_toml_string_round_trips_any_text(text):
    assert tomllib.loads(f"t = {toml_string(text)}")["t"] == text


def test_write_refuses_to_replace_a_file_and_replaces_it_when_asked(tmp_path):
    path = write_scene_template(tmp_path / "s.toml", SceneAnswers(fs=100.0))
    with pytest.raises(InputError, match=r"s\.toml exists; refusing to replace it"):
        write_scene_template(path, SceneAnswers(fs=50.0))
    assert "fs = 100.0" in path.read_text()
    write_scene_template(path, SceneAnswers(fs=50.0), overwrite=True)
    assert "fs = 50.0" in path.read_text()
    with pytest.raises(InputError, match="no such directory"):
        write_scene_template(tmp_path / "missing" / "s.toml", SceneAnswers())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml"]  # no temporary file left


def test_the_commented_infer_table_gives_the_models_default_priors(tmp_path):
    # a small record, so that the frame model is cheap to build
    answers = SceneAnswers(fs=50.0, duration=4.0, resonance=3.0, drive=(10.0, 20.0), noise_sigma=0.01)
    text = scene_template(answers)
    table = tomllib.loads(text)
    obs = vi.simulate(table, seed=0)
    series = vi.series(obs.time, obs.intensity)
    default = vi.posterior(series, table).space
    # what an analyst does: remove "# " from the table's header and entries
    lines = [ln[2:] for ln in text.splitlines() if ln == "# [infer.free]" or ln.startswith('# "')]
    infer = tomllib.loads("\n".join(lines))
    assert "infer" not in table and len(infer["infer"]["free"]) == 10
    listed = vi.posterior(series, {**table, **infer}).space
    base = dict(zip(default.names, default.priors))
    mine = dict(zip(listed.names, listed.priors))
    assert set(base) < set(mine)
    for name, prior in base.items():  # the same priors (bounds rounded to 4 digits in the file) ...
        assert mine[name].kind == prior.kind
        if not name.endswith("tilt_frequency"):
            assert mine[name].args == pytest.approx(prior.args, rel=5e-4)  # 4 significant digits: at most 5e-4 relative
    # ... but the tilt resonance's: around the guess, not the whole band
    assert mine[K + "tilt_frequency"].args == (1.5, 6.0)  # guess / 2 .. 2 guess
    assert base[K + "tilt_frequency"].args == pytest.approx((1 / 3.98, 25.0))  # 1 cycle in 3.98 s .. fs/2
    assert mine[K + "drive_frequency[1]"].args == pytest.approx((19.0, 21.0))  # the second line, +-5 %
