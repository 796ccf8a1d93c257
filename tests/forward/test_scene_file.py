import copy
import math
from pathlib import Path

import pytest

from forward.errors import SceneError
from forward.scene_file import apply_overrides, load_scene, parse_value, scene_from_table
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
        ("sun.inclination=0", r"sun.inclination: .*\[1e-09, pi/2\]"),
        ("sensor.inclination=1.7", r"sensor.inclination: .*\[1e-09, pi/2\]"),
        ("surfaces.roof.lobe_width=0", r"surfaces.roof.lobe_width: .*\[1e-09, 0.5\]"),
        ("surfaces.roof.lobe_width=-0.01", r"surfaces.roof.lobe_width: .*\[1e-09, 0.5\]"),
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


# ------------------------------------------------------------------ files and values that are not a scene

CORPUS = Path(__file__).resolve().parents[1] / "corpus" / "scenes"


def _one_line(err: pytest.ExceptionInfo) -> str:
    message = str(err.value)
    assert message and "\n" not in message and "\r" not in message and len(message) < 500, message
    return message


@pytest.mark.parametrize(
    "data",
    [
        b"\xff\xfe\x00garbage",
        b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\x00\x00\x00\x10" + bytes(range(256)),
        "title = 'caf\xe9'\n".encode("latin-1"),
        b"\x00" * 64,
    ],
    ids=["utf16-bom-garbage", "png", "latin-1", "nul-bytes"],
)
def test_binary_and_non_utf8_files_are_refused_in_one_line(tmp_path, data):
    p = tmp_path / "scene.toml"
    p.write_bytes(data)
    with pytest.raises(SceneError, match="not a UTF-8 TOML file") as err:
        load_scene(p)
    assert str(p) in _one_line(err)


def test_empty_files_directories_and_missing_files(tmp_path):
    for text in ("", "  \n\n\t\n"):
        (tmp_path / "empty.toml").write_text(text)
        with pytest.raises(SceneError, match=r"empty\.toml is empty") as err:
            load_scene(tmp_path / "empty.toml")
        _one_line(err)
    with pytest.raises(SceneError, match="is a directory") as err:
        load_scene(tmp_path)
    _one_line(err)
    with pytest.raises(SceneError, match="file not found") as err:
        load_scene(tmp_path / "nope.toml")
    _one_line(err)


def test_a_utf8_byte_order_mark_is_accepted(tmp_path):
    p = tmp_path / "bom.toml"
    p.write_bytes(b"\xef\xbb\xbf" + (SCENES / "roof_frame.toml").read_bytes())
    assert load_scene(p)[1] == load_scene(SCENES / "roof_frame.toml")[1]


def test_an_oversized_file_is_refused_before_parsing(tmp_path):
    p = tmp_path / "big.toml"
    p.write_bytes(b"# " + b"x" * (16 * 2**20 + 10) + b"\n")
    with pytest.raises(SceneError, match=r"allowed at most 16 MiB") as err:
        load_scene(p)
    _one_line(err)


@pytest.mark.parametrize("path", sorted(CORPUS.glob("*.toml")), ids=lambda p: p.stem)
def test_corpus_of_bad_scene_files(path):
    """Each file's first line says what the one-line error must match: '# expect: REGEX'."""
    expect = path.read_text().splitlines()[0].removeprefix("# expect: ")
    with pytest.raises(SceneError, match=expect) as err:
        load_scene(path)
    _one_line(err)


@pytest.mark.parametrize(
    "override, message",
    [
        ("title=" + "[" * 5000 + "]" * 5000, "nesting deeper than 32"),
        ("title=" + "{a=" * 2000 + "1" + "}" * 2000, "nesting deeper than 32"),
        ("title=" + "[" * 300 + "]" * 300, r"title\[0\]\[0\].*: nesting deeper than 32"),
        ("a" + ".b" * 5000 + "=1", "nesting deeper than 32"),
    ],
    ids=["arrays", "inline-tables", "arrays-300", "dotted-key"],
)
def test_deep_nesting_in_overrides(override, message):
    with pytest.raises(SceneError, match=message) as err:
        load_scene(SCENES / "roof_frame.toml", [override])
    _one_line(err)


def test_deep_and_cyclic_tables_from_python():
    _, table = load_scene(SCENES / "roof_frame.toml")
    deep = copy.deepcopy(table)
    node = deep["surfaces"]["roof"]
    for _ in range(3000):  # deeper than the interpreter's recursion limit
        node["x"] = {}
        node = node["x"]
    with pytest.raises(SceneError, match=r"surfaces.roof.x.x.x.*nesting deeper than 32") as err:
        scene_from_table(deep)
    _one_line(err)
    with pytest.raises(SceneError, match="nesting deeper than 32"):
        apply_overrides(deep, ["noise.sigma=1"])
    cyclic = copy.deepcopy(table)
    cyclic["infer"] = {"free": {}}
    cyclic["infer"]["free"]["loop"] = cyclic
    with pytest.raises(SceneError, match=r"infer\.free\.loop.*nesting deeper than 32") as err:
        scene_from_table(cyclic)
    _one_line(err)


@pytest.mark.parametrize(
    "text, message",
    [
        ("1+" * 200_000 + "1", "k: an expression of 400001 characters; allowed at most 200"),
        ("-" * 100_000 + "1", "allowed at most 200"),
        ("9**9**9**9", "k: '9\\*\\*9\\*\\*9\\*\\*9' overflows"),
        ("10**400", "overflows"),
        ("exp(1000)", "overflows"),
        ("1e308*10", r"k: '1e308\*10' evaluates to inf; allowed: a finite number"),
        ("1e400 - 1e400", "evaluates to nan; allowed: a finite number"),
        ("2 ** 1e308", "overflows"),
    ],
)
def test_expressions_are_bounded_and_finite(text, message):
    with pytest.raises(SceneError, match=message) as err:
        expression(text, "k")
    _one_line(err)


def test_expressions_within_the_bounds_still_work():
    assert expression("2 ** -2000", "k") == 0.0  # underflow to 0 is a finite number
    assert expression("-" * 150 + "1", "k") == 1.0
    assert expression("(" * 50 + "1" + ")" * 50, "k") == 1.0
    assert expression(" " * 300 + "1.5" + " " * 300, "k") == 1.5  # the limit counts the expression, not its padding


def test_non_finite_expressions_are_refused_in_intervals():
    with pytest.raises(SceneError, match=r"footprint.x: .*evaluates to -inf") as err:
        load_scene(SCENES / "roof_frame.toml", ["footprint.x=['-1e308*10', 25]"])
    _one_line(err)


# ------------------------------------------------------------------ work and memory, refused before allocation


def _lines_table(n: int) -> dict:
    _, table = load_scene(SCENES / "roof_frame.toml")
    motion = table["surfaces"]["roof"]["motion"]
    motion["drive_frequency"] = [10.0] * n
    motion["drive_amplitude"] = [1e-9] * n
    return table


def test_many_drive_lines_are_refused_before_work_naming_the_estimate_and_the_limit():
    table = _lines_table(300_000)
    with pytest.raises(SceneError) as err:
        scene_from_table(table)
    message = _one_line(err)
    for part in (
        "4000 samples x 300000 lines",
        "limit 2 GiB",
        "VIBINVERSE_MEMORY_LIMIT",
        "surfaces.roof.motion.drive_frequency",
        "sampling.duration",
    ):
        assert part in message, message


def test_an_unknown_key_holding_a_long_list_is_unknown_not_a_memory_estimate():
    """Only a motion kind's `line_keys` count lines before the motion is built: an unknown key
    holding 3 million numbers is refused as unknown (it was "needs about 121 GB ... reduce
    surfaces.roof.motion.bogus")."""
    _, table = load_scene(SCENES / "roof_frame.toml")
    table["surfaces"]["roof"]["motion"]["bogus"] = [0.0] * 3_000_000
    with pytest.raises(SceneError) as err:
        scene_from_table(table)
    message = _one_line(err)
    assert message.startswith("surfaces.roof.motion.bogus: unknown key") and "memory" not in message, message


def test_many_samples_at_high_resolution_are_refused_before_work():
    with pytest.raises(SceneError) as err:
        load_scene(
            SCENES / "roof_elastic.toml", ["sampling.fs=1000", "sampling.duration=1e5", "footprint.resolution=4096"]
        )
    message = _one_line(err)
    for part in ("100000000 samples", "16777216 subpixels", "limit 2 GiB", "sampling.duration", "footprint.resolution"):
        assert part in message, message


def test_the_memory_limit_can_be_raised_or_lowered(monkeypatch):
    table = _lines_table(2000)  # 4000 samples x 2000 lines: 64 MB
    scene_from_table(table)
    monkeypatch.setenv("VIBINVERSE_MEMORY_LIMIT", "50e6")
    with pytest.raises(SceneError, match=r"limit 50 MB \(VIBINVERSE_MEMORY_LIMIT"):
        scene_from_table(table)
    monkeypatch.setenv("VIBINVERSE_MEMORY_LIMIT", str(1 << 40))
    scene_from_table(_lines_table(30_000))
    for bad in ("lots", "-1", "0", "nan", "inf"):
        monkeypatch.setenv("VIBINVERSE_MEMORY_LIMIT", bad)
        with pytest.raises(SceneError, match=r"VIBINVERSE_MEMORY_LIMIT: .*allowed range") as err:
            scene_from_table(table)
        _one_line(err)


@pytest.mark.parametrize("name", ["roof_elastic", "glass_brewster", "roof_frame", "ground_rayleigh"])
def test_every_example_scene_is_well_within_the_default_limit(name):
    from forward.scene import memory_estimate, memory_limit

    scene, _ = load_scene(SCENES / f"{name}.toml")
    assert memory_estimate(scene).total < memory_limit() / 10


def test_a_sample_count_beyond_float64_is_refused():
    with pytest.raises(
        SceneError, match=r"sampling: duration \* fs = inf samples; allowed range \[2, 100000000\]"
    ) as err:
        load_scene(SCENES / "roof_frame.toml", ["sampling.fs=1e300", "sampling.duration=1e300"])
    _one_line(err)


def test_an_endless_file_is_refused_without_reading_it_all():
    if not Path("/dev/zero").exists():
        pytest.skip("no /dev/zero")
    with pytest.raises(SceneError, match="allowed at most 16 MiB") as err:
        load_scene("/dev/zero")
    _one_line(err)


def test_messages_stay_one_line_whatever_the_keys_and_values_hold(tmp_path):
    p = tmp_path / "keys.toml"
    p.write_text('"a\\nb\\u2028c" = 1\n' + (SCENES / "roof_frame.toml").read_text())
    with pytest.raises(SceneError, match=r"a\\nb\\u2028c: unknown key") as err:
        load_scene(p)
    _one_line(err)
    with pytest.raises(SceneError, match=r"sun\.azimuth: must be a finite number") as err:
        load_scene(SCENES / "roof_frame.toml", ["sun.azimuth=[" + ",".join(["1"] * 100_000) + "]"])
    assert len(_one_line(err)) < 200
    with pytest.raises(SceneError, match=r"^sun\\ninclination: unknown key") as err:
        load_scene(SCENES / "roof_frame.toml", ["sun\ninclination.x=1"])
    _one_line(err)
    with pytest.raises(SceneError, match=r"--set title.x\\ny: title is a value") as err:
        load_scene(SCENES / "roof_frame.toml", ["title.x\ny=1"])
    _one_line(err)
