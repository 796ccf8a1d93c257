"""`vibinverse init`: DIR/scene.toml from flags or prompts, one-line errors with exit 2, --json, and
the scene it writes fits a simulated observation of the paper's frame (sec. 4.2)."""

import builtins
import io
import json
import math
import sys

import pytest

import vibinverse as vi
from forward.scene_file import load_scene
from vibinverse.cli import main
from vibinverse.io.builtin import builtin_scene

K = "surfaces.roof.motion."
TRUE_TILT = 2 * math.sqrt(3)  # Hz: the builtin frame's tilt resonance, sqrt(12 k1 / M) / (2 pi) with k1 = (2 pi)^2
# the builtin roof_frame scene's geometry, in the command line's degrees
PAPER = [
    *("--sun-inclination", "60", "--sun-azimuth", "180"),
    *("--view-inclination", repr(math.degrees(math.pi / 3 + 0.01)), "--view-azimuth", "0"),
    *("--fs", "200", "--duration", "20", "--footprint", "50", "--roof", "50"),
    *("--material", "steel", "--lobe-width", "0.01"),
]


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def answer(monkeypatch, *replies):
    """input() returns `replies` in turn (then EOF); the questions asked are collected."""
    asked, it = [], iter(replies)

    def fake(prompt=""):
        asked.append(prompt)
        try:
            return next(it)
        except StopIteration:
            raise EOFError from None

    monkeypatch.setattr(builtins, "input", fake)
    return asked


def test_init_writes_scene_toml_into_a_new_directory(tmp_path, capsys):
    out = tmp_path / "new" / "dir"
    assert main(["init", "--no-input", "-o", str(out), "--fs", "30", "--duration", "60", "--resonance", "2.5"]) == 0
    path = out / "scene.toml"
    scene, table = load_scene(path)
    assert (scene.sampling.fs, scene.sampling.duration) == (30.0, 60.0)
    assert table["surfaces"]["roof"]["motion"]["tilt_frequency"] == 2.5
    log = capsys.readouterr()
    assert log.out.splitlines()[-1] == f"wrote {path}; fit with: vibinverse fit DATA --scene {path}"
    assert "--view-inclination and --view-azimuth not given" in log.err  # the assumed geometry is a warning


def test_degrees_on_the_command_line_are_radians_in_the_file(tmp_path):
    args = ["init", "-o", str(tmp_path), "--no-input", "--sun-inclination", "45", "--sun-azimuth", "-120"]
    args += ["--view-inclination", "80", "--view-azimuth", "30", "--footprint", "40", "30", "--roof", "20"]
    args += ["--drive", "7", "12.5", "--material", "aluminium", "--noise-sigma", "0.2", "--title", 'A "roof"\n2']
    assert main(args) == 0
    scene, table = load_scene(tmp_path / "scene.toml")
    assert (scene.sun.inclination, scene.sun.azimuth) == (math.radians(45), math.radians(-120))
    assert (scene.sensor.inclination, scene.sensor.azimuth) == (math.radians(80), math.radians(30))
    assert (scene.footprint.x, scene.footprint.y) == ((-20.0, 20.0), (-15.0, 15.0))
    assert scene.surfaces[0].x == (-10.0, 10.0) and scene.surfaces[0].material.index == 0.96 + 6.69j
    assert list(scene.surfaces[0].motion.drive.frequencies) == [7.0, 12.5]
    assert scene.noise.sigma == 0.2 and table["title"] == 'A "roof"\n2'


def test_the_sun_by_date_and_clock_time(tmp_path):
    args = ["init", "-o", str(tmp_path), "--no-input", "--date", "2024-06-21", "--hour", "13:30"]
    assert main([*args, "--latitude", "48.1", "--longitude", "11.6", "--utc-offset", "2"]) == 0
    scene, table = load_scene(tmp_path / "scene.toml")
    assert table["sun"]["hour"] == 13.5
    assert math.degrees(scene.sun.inclination) == pytest.approx(65.18, abs=0.02)


def test_it_refuses_to_replace_scene_toml_without_force(tmp_path, capsys):
    assert main(["init", "--no-input", "-o", str(tmp_path), "--fs", "100"]) == 0
    before = (tmp_path / "scene.toml").read_text()
    capsys.readouterr()
    assert main(["init", "--no-input", "-o", str(tmp_path), "--fs", "50"]) == 2
    err = capsys.readouterr().err
    path = tmp_path / "scene.toml"
    assert err == f"vibinverse: error: -o: {path} exists; refusing to replace it (--force replaces it)\n"
    assert (tmp_path / "scene.toml").read_text() == before
    assert main(["init", "--no-input", "-o", str(tmp_path), "--fs", "50", "--force"]) == 0
    assert "fs = 50.0" in (tmp_path / "scene.toml").read_text()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.toml"]  # no temporary file left


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--fs", "0"], "vibinverse init: argument --fs: 0 is outside the allowed range (0, inf)"),
        (["--fs", "fast"], "vibinverse init: argument --fs: invalid value 'fast'; allowed: the range (0, inf)"),
        (["--hour", "12"], "--date: missing; the sun by date needs --date, --hour, --latitude and --longitude"),
        (["--material", "wood"], "--material: unknown material 'wood'; allowed: aluminium, glass, glass_paper"),
        (["--drive", "150"], "--drive: 150 is outside the allowed range (0, 100) Hz (below fs/2)"),
        (["--footprint", "1", "2", "3"], "--footprint: give one size (a square) or two (east-west, north-south)"),
        (["--hour", "noon"], "vibinverse init: argument --hour: invalid value 'noon'; allowed: the range [0, 24]"),
    ],
)
def test_a_bad_answer_exits_2_with_one_line_and_writes_nothing(tmp_path, capsys, args, message):
    out = tmp_path / "out"
    assert main(["init", "--no-input", "-o", str(out), *args]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"vibinverse: error: {message}") and err.count("\n") == 1, err
    assert not out.exists()


def test_an_output_that_is_a_file_is_refused(tmp_path, capsys):
    (tmp_path / "scene.toml").write_text("x")
    assert main(["init", "--no-input", "-o", str(tmp_path / "scene.toml")]) == 2
    assert "-o names an output directory" in capsys.readouterr().err


def test_json_prints_the_path_on_stdout(tmp_path, capsys):
    assert main(["init", "--no-input", "--json", "-o", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    doc = json.loads(out)
    assert doc["scene"] == str(tmp_path / "scene.toml") and doc["paths"] == [doc["scene"]]
    assert "fit with" not in out


def test_stdin_that_is_not_a_terminal_is_never_read(tmp_path, monkeypatch):
    monkeypatch.setattr(sys, "stdin", io.StringIO("60\n"))
    asked = answer(monkeypatch)
    assert main(["init", "-o", str(tmp_path)]) == 0
    assert asked == []


def test_a_terminal_is_asked_for_missing_answers_and_a_bad_one_again(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sys, "stdin", _Terminal())
    asked = answer(
        monkeypatch,
        "Depot roof",  # title
        "",  # no date: the sun by angles
        "50",  # sun elevation
        "",  # sun azimuth: default 180
        "70",  # view inclination
        "10",  # view azimuth
        "0",  # fs: refused ...
        "30",  # ... asked again
        "",  # duration: default
        "40x30",  # footprint
        "25",  # roof
        "wood",  # refused ...
        "aluminium",  # ... asked again
        "2.5",  # resonance
        "7 12",  # drive lines
        "",  # noise sigma: unknown
    )
    assert main(["init", "-o", str(tmp_path), "--lobe-width", "0.02"]) == 0
    assert len(asked) == 16 and asked[0].startswith("title [")
    err = capsys.readouterr().err.splitlines()
    assert err == [
        "--fs: 0 is outside the allowed range (0, inf); try again",
        "--material: unknown material 'wood'; allowed: aluminium, glass, glass_paper, ground, steel; try again",
    ]
    scene, table = load_scene(tmp_path / "scene.toml")
    assert table["title"] == "Depot roof"
    assert (scene.sun.inclination, scene.sun.azimuth) == (math.radians(50), math.radians(180))
    assert (scene.sensor.inclination, scene.sensor.azimuth) == (math.radians(70), math.radians(10))
    assert (scene.sampling.fs, scene.sampling.duration) == (30.0, 20.0)
    assert (scene.footprint.x, scene.footprint.y) == ((-20.0, 20.0), (-15.0, 15.0))
    roof = scene.surfaces[0]
    assert (roof.x, roof.lobe_width, roof.material.index) == ((-12.5, 12.5), 0.02, 0.96 + 6.69j)
    assert roof.motion.params.modal()["tilt"][0] == pytest.approx(2.5)
    assert list(roof.motion.drive.frequencies) == [7.0, 12.0]


def test_a_terminal_answer_the_scene_check_refuses_is_asked_again(tmp_path, monkeypatch):
    # 23:00 is a valid clock time, but the sun is down then: the scene check names --hour
    monkeypatch.setattr(sys, "stdin", _Terminal())
    asked = answer(monkeypatch, "", "2024-06-21", "23:00", "48.1", "11.6", "2", *[""] * 10, "12:00")
    assert main(["init", "-o", str(tmp_path)]) == 0
    assert asked[-1].startswith("local clock time") and len(asked) == 17
    assert load_scene(tmp_path / "scene.toml")[1]["sun"]["hour"] == 12.0


def test_the_end_of_input_keeps_the_defaults(tmp_path, monkeypatch):
    monkeypatch.setattr(sys, "stdin", _Terminal())
    answer(monkeypatch, "Quick")
    assert main(["init", "-o", str(tmp_path)]) == 0
    scene, table = load_scene(tmp_path / "scene.toml")
    assert table["title"] == "Quick" and scene.sampling.fs == 200.0


@pytest.mark.slow  # ~13 s: simulation and a derivative-free MAP of 7 parameters on 4000 samples
def test_the_init_scene_of_the_papers_frame_fits_its_simulated_series(tmp_path):
    """Done when: a series simulated from the builtin sec. 4.2 scene (drive-line SNR ~10), fitted
    against the scene `init` writes from the analyst's answers (geometry; a 3 Hz resonance guess;
    a 10 Hz drive; noise unknown), recovers the 2 sqrt(3) Hz tilt resonance and detects the drive."""
    truth = vi.load_scene(builtin_scene("roof_frame"), ["noise.sigma=0.6"])
    obs = vi.simulate(truth, seed=0)
    series = vi.series(obs.time, obs.intensity)
    assert main(["init", "--no-input", "-o", str(tmp_path), *PAPER, "--resonance", "3", "--drive", "10"]) == 0
    table = vi.load_scene(tmp_path / "scene.toml")
    # the same observation as the builtin scene: its sun, sensor, footprint and roof
    mine, ref = load_scene(tmp_path / "scene.toml")[0], load_scene(builtin_scene("roof_frame"))[0]
    assert (mine.sun, mine.footprint, mine.surfaces[0].material) == (ref.sun, ref.footprint, ref.surfaces[0].material)
    assert mine.sensor.inclination == pytest.approx(ref.sensor.inclination, abs=1e-15)
    result = vi.fit(series, table, method="map", seed=0)
    p = {k: v["median"] for k, v in result.summary()["parameters"].items()}
    assert p[K + "tilt_frequency"] == pytest.approx(TRUE_TILT, rel=0.01)  # 3.4667 against 3.4641
    assert p[K + "drive_frequency"] == pytest.approx(10.0, abs=0.005)
    assert p[K + "drive_amplitude"] == pytest.approx(1e-3, rel=0.1)
    assert p["noise.sigma"] == pytest.approx(0.6, rel=0.05)
    assert {d.what: d.detected for d in result.detections} == {"drive": True, "resonance": True}
