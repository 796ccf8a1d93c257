"""The command line as a user meets it: outputs, one-line errors, exit code 2, no partial files."""

import json
import subprocess
import sys

import numpy as np
import pytest

from tests.conftest import LOW_RES, SCENES, K, run_cli
from vibinverse.cli import main
from vibinverse.io.builtin import builtin_scene

ROOF = str(SCENES / "roof_elastic.toml")
FAST = ["--set", "footprint.resolution=32", "--set", "sampling.duration=0.1"]


def read_csv(path):
    lines = path.read_text().splitlines()
    comments = [ln for ln in lines if ln.startswith("#")]
    header = lines[len(comments)]
    return comments, header, np.loadtxt(path, delimiter=",", comments="#", skiprows=len(comments) + 1)


def test_simulate_writes_series_truth_and_plot(tmp_path):
    out, png = tmp_path / "roof.csv", tmp_path / "roof.png"
    r = run_cli("simulate", ROOF, *FAST, "--seed", "7", "-o", str(out), "--plot", str(png))
    assert r.returncode == 0, r.stderr
    assert "sensitivity S =" in r.stdout
    comments, header, data = read_csv(out)
    assert header == "time,intensity,intensity_clean"
    assert data.shape == (100, 3)
    assert any(c.startswith("# scene: {") and '"center_deflection":0.001' in c for c in comments)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    s = float(r.stdout.split("S =")[1].split()[0])
    assert s == pytest.approx((data[:, 2].max() - data[:, 2].min()) / data[:, 2].max(), rel=1e-3)


def test_seed_reproduces_and_set_overrides(tmp_path):
    a, b, c = (tmp_path / f"{n}.csv" for n in "abc")
    for path, seed in ((a, "1"), (b, "1")):
        assert run_cli("simulate", ROOF, *FAST, "--seed", seed, "-o", str(path)).returncode == 0
    assert a.read_text() == b.read_text()
    r = run_cli("simulate", ROOF, *FAST, "--set", "surfaces.roof.motion.frequency=25", "-o", str(c))
    assert r.returncode == 0
    _, _, data = read_csv(c)
    spec = np.abs(np.fft.rfft(data[:, 2] - data[:, 2].mean()))
    assert np.fft.rfftfreq(data.shape[0], 1e-3)[spec.argmax()] == pytest.approx(25.0, abs=10.0)


@pytest.mark.parametrize(
    "args, message",
    [
        (["--set", "sensr.inclination=1"], "sensr: unknown key"),
        (["--set", "surfaces.roof.x=[25, -25]"], "surfaces.roof.x"),
        (["--set", "sun.inclination=2"], "sun.inclination"),
        (["--set", "surfaces.roof.lobe_width=0"], "surfaces.roof.lobe_width"),
        (["--set", "noise.sigma=nan"], "noise.sigma"),
        (["--set", "noise.sigma"], "dotted.key=value"),
        (["--seed", "x"], "invalid int value"),
    ],
)
def test_bad_input_is_one_line_exit_2_and_no_file(tmp_path, args, message):
    out = tmp_path / "out.csv"
    r = run_cli("simulate", ROOF, *args, "-o", str(out))
    assert r.returncode == 2
    assert message in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert list(tmp_path.iterdir()) == []


def test_missing_scene_and_unwritable_output(tmp_path):
    r = run_cli("simulate", str(tmp_path / "nope.toml"), "-o", str(tmp_path / "o.csv"))
    assert r.returncode == 2 and "file not found" in r.stderr and "Traceback" not in r.stderr
    r = run_cli("simulate", ROOF, *FAST, "-o", str(tmp_path / "no" / "such" / "dir.csv"))
    assert r.returncode == 2 and "cannot write" in r.stderr and "Traceback" not in r.stderr
    # a good CSV with an unwritable plot: neither file is left behind
    r = run_cli("simulate", ROOF, *FAST, "-o", str(tmp_path / "ok.csv"), "--plot", str(tmp_path / "nodir" / "p.png"))
    assert r.returncode == 2 and list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_version_and_demo(tmp_path):
    r = run_cli("--version")
    assert r.returncode == 0 and r.stdout.startswith("vibinverse ")
    r = run_cli("demo", "-o", str(tmp_path / "demo"), "--no-progress")
    assert r.returncode == 0, r.stderr
    assert "report:" in r.stdout and "R-hat" in r.stdout
    for name in ("frame.csv", "frame.png", "result.nc", "result.json", "report.html"):
        assert (tmp_path / "demo" / name).exists(), name
    import json

    summary = json.loads((tmp_path / "demo" / "result.json").read_text())
    for name in ("tilt_frequency", "drive_frequency", "drive_amplitude"):
        p = summary["parameters"]["surfaces.roof.motion." + name]
        assert p["q05"] <= p["truth"] <= p["q95"], name


@pytest.mark.parametrize(
    "scene, override, message",
    [
        ("roof_frame", "surfaces.roof.motion.k_lateral=-1", "k_lateral"),
        ("roof_frame", "surfaces.roof.motion.mass=0", "mass"),
        ("roof_frame", "surfaces.roof.motion.drive_frequency=[120]", "Nyquist"),
        ("ground_rayleigh", "surfaces.ground.motion.radius=0", "radius"),
    ],
)
def test_invalid_motion_parameters_exit_2(tmp_path, scene, override, message):
    r = run_cli("simulate", str(SCENES / f"{scene}.toml"), "--set", override, "-o", str(tmp_path / "o.csv"))
    assert r.returncode == 2 and message in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert list(tmp_path.iterdir()) == []


def test_simulate_explain_dense_and_rtol(tmp_path):
    r = run_cli("simulate", ROOF, *FAST, "--explain", "-o", str(tmp_path / "a.csv"))
    assert r.returncode == 0 and "chebyshev" in r.stdout and "est. error" in r.stdout
    r2 = run_cli("simulate", ROOF, *FAST, "--dense", "-o", str(tmp_path / "b.csv"))
    assert r2.returncode == 0
    a = np.loadtxt(tmp_path / "a.csv", delimiter=",", comments="#", skiprows=6)
    b = np.loadtxt(tmp_path / "b.csv", delimiter=",", comments="#", skiprows=6)
    assert np.abs(a[:, 2] - b[:, 2]).max() <= 1e-5 * np.ptp(b[:, 2])
    r = run_cli("simulate", ROOF, "--rtol", "-1", "-o", str(tmp_path / "c.csv"))
    assert r.returncode == 2 and "--rtol" in r.stderr and not (tmp_path / "c.csv").exists()


@pytest.mark.parametrize(
    "args, message",
    [
        (
            ("fit", "nope.csv", "--scene", str(SCENES / "roof_frame.toml"), "-o", "r.nc", "--summary", "r.json"),
            "file not found",
        ),
        (
            (
                "fit",
                "DATA",
                "--scene",
                str(SCENES / "roof_frame.toml"),
                "--free",
                "noise.sigma=gauss(1)",
                "-o",
                "r.nc",
                "--summary",
                "r.json",
            ),
            "prior",
        ),
        (
            (
                "fit",
                "DATA",
                "--scene",
                str(SCENES / "roof_elastic.toml"),
                "--method",
                "sindy",
                "-o",
                "r.nc",
                "--summary",
                "r.json",
            ),
            "sindy",
        ),
        (
            (
                "fit",
                "DATA",
                "--scene",
                str(SCENES / "roof_frame.toml"),
                "--free",
                f"{K}tilt_frequency=uniform(0.1, 5)",
                "-o",
                "r.nc",
                "--summary",
                "r.json",
            ),
            "needs at least 30 s",
        ),  # the 4 s series is too short for 0.1 Hz
        (
            (
                "fit",
                "DATA",
                "--scene",
                str(SCENES / "roof_frame.toml"),
                "--free",
                f"{K}drive_frequency=uniform(5, 150)",
                "-o",
                "r.nc",
                "--summary",
                "r.json",
            ),
            "Nyquist",
        ),
        (
            (
                "fit",
                "DATA",
                "--scene",
                str(SCENES / "roof_frame.toml"),
                "--free",
                "surfaces.roof.x[0]=uniform(-6, -4)",
                "-o",
                "r.nc",
                "--summary",
                "r.json",
            ),
            "cannot be fitted",
        ),
        (
            (
                "fit",
                "DATA",
                "--scene",
                str(SCENES / "roof_frame.toml"),
                "--method",
                "ipopt",
                "-o",
                "r.nc",
                "--summary",
                "r.json",
            ),
            "--method",
        ),
    ],
)
def test_fit_bad_input_is_one_line_exit_2(short_data, tmp_path, args, message):
    args = tuple(str(short_data / "data.csv") if a == "DATA" else a for a in args)
    r = run_cli(*args, cwd=tmp_path)
    assert r.returncode == 2 and message in r.stderr and "Traceback" not in r.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_cli_fits_a_plate_and_refuses_sindy(tmp_path):
    scene = SCENES / "roof_elastic.toml"
    data = tmp_path / "plate.csv"
    run = lambda *a: subprocess.run(
        [sys.executable, "-m", "vibinverse.cli", *map(str, a)], capture_output=True, text=True
    )
    assert run("simulate", scene, "--seed", "3", "--set", LOW_RES, "-o", data).returncode == 0
    out = run(
        "fit",
        data,
        "--scene",
        scene,
        "--set",
        LOW_RES,
        "--method",
        "map",
        "-o",
        tmp_path / "r.nc",
        "--summary",
        tmp_path / "r.json",
    )
    assert out.returncode == 0, out.stderr
    summary = json.loads((tmp_path / "r.json").read_text())
    assert summary["parameters"][K + "frequency"]["truth"] == 40.0
    bad = run(
        "fit", data, "--scene", scene, "--method", "sindy", "-o", tmp_path / "s.nc", "--summary", tmp_path / "s.json"
    )
    assert bad.returncode == 2 and "sindy" in bad.stderr and "Traceback" not in bad.stderr
    assert not (tmp_path / "s.nc").exists()


@pytest.mark.parametrize(
    "args, message",
    [
        (["--vary", "sensor.bogus=0:1:3"], "--vary sensor.bogus: sensor.bogus: unknown key"),
        (["--vary", "sensor.offset=0:0.01:0"], "empty range"),
        (["--vary", "sampling.fs=abc"], "'abc' is not a number"),
        (["--target", K + "bogus"], "--target surfaces.roof.motion.bogus: no such scene value"),
        (["--threshold", "-1"], "--threshold"),
        (["--vary", "sensor.offset=0,0.01", "--vary", "sensor.offset=0.02"], "given twice"),
    ],
)
def test_cli_rejects_bad_sweeps_with_exit_2_and_no_output(tmp_path, capsys, args, message):
    out = tmp_path / "design"
    code = main(["design", str(builtin_scene("roof_elastic")), "-o", str(out), "--no-progress", *args])
    err = capsys.readouterr().err
    assert code == 2 and message in err and err.count("\n") == 1 and "Traceback" not in err
    assert not out.exists()


def test_cli_writes_csv_json_and_maps_and_workers_agree(tmp_path, capsys):
    args = [
        "design",
        str(builtin_scene("roof_elastic")),
        "--set",
        "footprint.resolution=32",
        "--vary",
        "sensor.offset=-0.02:0.02:5",
        "--vary",
        "footprint.center=0,25",
        "--no-progress",
    ]
    assert main([*args, "-o", str(tmp_path / "a")]) == 0
    assert main([*args, "-o", str(tmp_path / "b"), "--workers", "2"]) == 0
    assert "10 configurations" in capsys.readouterr().out
    doc = json.loads((tmp_path / "a" / "design.json").read_text())
    assert doc["n_configurations"] == 10 and doc["threshold"] == 1e-4 and len(doc["best"]) == 10
    assert doc["best"][0]["footprint.center"] == 25.0
    a = (tmp_path / "a" / "design.csv").read_text().splitlines()
    b = (tmp_path / "b" / "design.csv").read_text().splitlines()
    assert len(a) == 11 and a == b
    for png in ("design_sensitivity.png", "design_crlb.png"):
        assert (tmp_path / "a" / png).read_bytes()[:4] == b"\x89PNG"


@pytest.mark.parametrize(
    "make_args, message",
    [
        (lambda d: ["fit", d["csv"], "--scene", ROOF, "-o", d["csv"], "--summary", d["json"]], "replace the input"),
        (lambda d: ["fit", d["csv"], "--scene", ROOF, "-o", d["nc"], "--summary", ROOF], "replace the input"),
        (lambda d: ["fit", d["csv"], "--scene", ROOF, "-o", d["nc"], "--summary", d["nc"]], "its own path"),
        (lambda d: ["simulate", ROOF, "-o", ROOF], "replace the input"),
        (lambda d: ["simulate", ROOF, "-o", d["csv2"], "--plot", d["csv2"]], "its own path"),
        (lambda d: ["simulate", ROOF, "-o", d["dir"]], "is a directory"),
    ],
)
def test_an_output_never_replaces_an_input_or_another_output(tmp_path, make_args, message):
    d = {
        "csv": str(tmp_path / "data.csv"),
        "json": str(tmp_path / "s.json"),
        "nc": str(tmp_path / "r.nc"),
        "csv2": str(tmp_path / "new.csv"),
        "dir": str(tmp_path),
    }
    assert run_cli("simulate", ROOF, *FAST, "--seed", "1", "-o", d["csv"]).returncode == 0
    files = {p: p.read_bytes() for p in [tmp_path / "data.csv", *map(__import__("pathlib").Path, [ROOF])]}
    r = run_cli(*make_args(d))
    assert r.returncode == 2 and message in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert all(p.read_bytes() == b for p, b in files.items())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data.csv"]


def test_quiet_and_verbose_before_or_after_the_verb(tmp_path):
    out = tmp_path / "a.csv"
    for args in (["-q", "simulate", ROOF, *FAST, "-o", str(out)], ["simulate", "-q", ROOF, *FAST, "-o", str(out)]):
        r = run_cli(*args)
        assert r.returncode == 0 and r.stdout == "" and out.exists(), r.stderr
    r = run_cli("simulate", ROOF, *FAST, "-o", str(out))
    assert "sensitivity S =" in r.stdout


@pytest.mark.slow
def test_ctrl_c_at_any_moment_of_a_run_is_one_line_and_exit_130(tmp_path):
    """Ctrl-C while the interpreter imports, while the parser loads, while the fit runs."""
    import signal
    import time

    assert run_cli("simulate", ROOF, *FAST, "--seed", "1", "-o", str(tmp_path / "d.csv")).returncode == 0
    for delay in (0.4, 0.8, 1.5, 2.5):  # (earlier, CPython itself is still starting: not ours to catch)
        args = [
            "fit",
            str(tmp_path / "d.csv"),
            "--scene",
            ROOF,
            "--method",
            "map",
            "-o",
            str(tmp_path / "r.nc"),
            "--summary",
            str(tmp_path / "r.json"),
        ]
        proc = subprocess.Popen(
            [sys.executable, "-m", "vibinverse", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        time.sleep(delay)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
        assert "Traceback" not in err, (delay, err)
        if proc.returncode != 0:  # (a run that finished before the signal came is fine)
            assert proc.returncode == 130 and len(err.strip().splitlines()) == 1, (delay, proc.returncode, err)
            assert not (tmp_path / "r.nc").exists()
