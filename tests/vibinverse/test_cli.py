"""The command line as a user meets it: outputs, one-line errors, exit code 2, no partial files."""

import subprocess
import sys

import numpy as np
import pytest

from tests.conftest import SCENES

ROOF = str(SCENES / "roof_elastic.toml")
FAST = ["--set", "footprint.resolution=32", "--set", "sampling.duration=0.1"]


def run(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "vibinverse", *args], capture_output=True, text=True, cwd=cwd)


def read_csv(path):
    lines = path.read_text().splitlines()
    comments = [ln for ln in lines if ln.startswith("#")]
    header = lines[len(comments)]
    return comments, header, np.loadtxt(path, delimiter=",", comments="#", skiprows=len(comments) + 1)


def test_simulate_writes_series_truth_and_plot(tmp_path):
    out, png = tmp_path / "roof.csv", tmp_path / "roof.png"
    r = run("simulate", ROOF, *FAST, "--seed", "7", "-o", str(out), "--plot", str(png))
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
        assert run("simulate", ROOF, *FAST, "--seed", seed, "-o", str(path)).returncode == 0
    assert a.read_text() == b.read_text()
    r = run("simulate", ROOF, *FAST, "--set", "surfaces.roof.motion.frequency=25", "-o", str(c))
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
    r = run("simulate", ROOF, *args, "-o", str(out))
    assert r.returncode == 2
    assert message in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert list(tmp_path.iterdir()) == []


def test_missing_scene_and_unwritable_output(tmp_path):
    r = run("simulate", str(tmp_path / "nope.toml"), "-o", str(tmp_path / "o.csv"))
    assert r.returncode == 2 and "file not found" in r.stderr and "Traceback" not in r.stderr
    r = run("simulate", ROOF, *FAST, "-o", str(tmp_path / "no" / "such" / "dir.csv"))
    assert r.returncode == 2 and "cannot write" in r.stderr and "Traceback" not in r.stderr
    # a good CSV with an unwritable plot: neither file is left behind
    r = run("simulate", ROOF, *FAST, "-o", str(tmp_path / "ok.csv"), "--plot", str(tmp_path / "nodir" / "p.png"))
    assert r.returncode == 2 and list(tmp_path.iterdir()) == []


def test_version_and_demo(tmp_path):
    r = run("--version")
    assert r.returncode == 0 and r.stdout.startswith("vibinverse ")
    r = run("demo", "-o", str(tmp_path / "demo"), "--no-progress")
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
    r = run("simulate", str(SCENES / f"{scene}.toml"), "--set", override, "-o", str(tmp_path / "o.csv"))
    assert r.returncode == 2 and message in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert list(tmp_path.iterdir()) == []


def test_study_fig4_writes_figure_curve_and_numbers(tmp_path):
    import json

    r = run("study", "fig4", "-o", str(tmp_path))
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("fig4:")
    summary = json.loads((tmp_path / "fig4.json").read_text())
    res = summary["resonances_hz"]
    for name, f in {"vertical": 2.0, "lateral": 4.0, "tilt": 2 * np.sqrt(3), "twist": 4 * np.sqrt(3)}.items():
        assert res[name] == pytest.approx(f, rel=1e-3)
    peaks = summary["spectral_peaks_hz"]
    assert peaks["x_cm"] == pytest.approx(4.0, abs=0.01) and peaks["z_cm"] == pytest.approx(2.0, abs=0.01)
    assert peaks["tilt"] == pytest.approx(2 * np.sqrt(3), abs=0.01)
    assert (tmp_path / "fig4.png").read_bytes()[:4] == b"\x89PNG"
    assert (tmp_path / "fig4.csv").read_text().startswith("time_s,x_cm_m,z_cm_m,tilt_rad,frequency_hz")
    r = run("study", "fig99", "-o", str(tmp_path))
    assert r.returncode == 2 and "invalid choice" in r.stderr


def test_simulate_explain_dense_and_rtol(tmp_path):
    r = run("simulate", ROOF, *FAST, "--explain", "-o", str(tmp_path / "a.csv"))
    assert r.returncode == 0 and "chebyshev" in r.stdout and "est. error" in r.stdout
    r2 = run("simulate", ROOF, *FAST, "--dense", "-o", str(tmp_path / "b.csv"))
    assert r2.returncode == 0
    a = np.loadtxt(tmp_path / "a.csv", delimiter=",", comments="#", skiprows=6)
    b = np.loadtxt(tmp_path / "b.csv", delimiter=",", comments="#", skiprows=6)
    assert np.abs(a[:, 2] - b[:, 2]).max() <= 1e-5 * np.ptp(b[:, 2])
    r = run("simulate", ROOF, "--rtol", "-1", "-o", str(tmp_path / "c.csv"))
    assert r.returncode == 2 and "--rtol" in r.stderr and not (tmp_path / "c.csv").exists()


def test_forward_bench_rows_have_the_documented_fields():
    from vibinverse.bench.forward_bench import forward_rows, scaling_rows, speed_error_rows

    rows = forward_rows(SCENES, resolution=20, n_samples=400, log=lambda *a: None)
    assert [r["scene"] for r in rows] == ["roof_elastic", "glass_brewster", "roof_frame", "ground_rayleigh"]
    for r in rows:
        assert {"scene", "reference_s", "fast_s", "speedup", "rel_error"} <= set(r)
        assert r["rel_error"] <= 1e-3
    scaling = scaling_rows(SCENES, resolutions=(16,), samples=(100, 1000), log=lambda *a: None)
    assert [(r["subpixels"], r["samples"]) for r in scaling] == [(256, 100), (256, 1000)]
    se = speed_error_rows(SCENES, 24, n=200, coarse=(8,), log=lambda *a: None)
    assert {r["method"] for r in se} == {"fast", "dense"}
    from vibinverse.bench.likelihood_bench import likelihood_row

    lk = likelihood_row(SCENES / "roof_frame.toml", log=lambda *a: None)
    assert lk["samples"] == 4000 and lk["ours_us"] > 0 and lk["ratio"] > 0
    from vibinverse.bench.design_bench import design_row

    d = design_row(SCENES / "roof_elastic.toml", 4, workers=(1,), log=lambda *a: None)
    assert d["configurations"] == 16 and d["seconds"]["1"] > 0 and d["ms_per_configuration"]["1"] > 0
