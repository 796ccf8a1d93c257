"""The command line as a user meets it: outputs, one-line errors, exit code 2, no partial files."""

import argparse
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import LOW_RES, SCENES, K, run_cli
from vibinverse.cli import main
from vibinverse.cli.commands import build_parser
from vibinverse.io.builtin import builtin_scene

ROOF = str(SCENES / "roof_elastic.toml")
FAST = ["--set", "footprint.resolution=32", "--set", "sampling.duration=0.1"]
WRITES_NOTHING: set[str] = set()  # verbs that write no file and so have no -o (none today)


def verbs() -> dict[str, argparse.ArgumentParser]:
    """Every verb's parser, from the parser itself: a new verb is covered without a change here."""
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def output_option(verb: str) -> argparse.Action | None:
    return next((a for a in verbs()[verb]._actions if "-o" in a.option_strings), None)


def documented_files(verb: str) -> set[str]:
    """The file names that `vibinverse VERB --help` says -o DIR receives."""
    files = output_option(verb).help.split("; writes ", 1)[1]
    return set(re.findall(r"[\w*][\w.*]*\.(?:csv|png|json|nc|h5|html|toml|mp4|zarr)\b", files))


def strict_json(text: str):
    """stdout of --json: exactly one strict JSON document (no NaN or Infinity tokens)."""
    return json.loads(text, parse_constant=lambda c: pytest.fail(f"non-strict JSON token {c}"))


def cli_json(capsys, *args: str) -> tuple[dict, str]:
    """Run a verb in this process with --json: (the parsed stdout, stderr)."""
    code = main([*args, "--json"])
    out, err = capsys.readouterr()
    assert code == 0, err
    return strict_json(out), err


def names(folder: Path) -> set[str]:
    return {p.name for p in folder.iterdir()}


def read_csv(path):
    lines = path.read_text().splitlines()
    comments = [ln for ln in lines if ln.startswith("#")]
    header = lines[len(comments)]
    return comments, header, np.loadtxt(path, delimiter=",", comments="#", skiprows=len(comments) + 1)


def test_simulate_writes_series_truth_and_plot(tmp_path):
    out = tmp_path / "sim"
    r = run_cli("simulate", ROOF, *FAST, "--seed", "7", "-o", str(out), "--plot")
    assert r.returncode == 0, r.stderr
    assert "sensitivity S =" in r.stdout
    assert sorted(p.name for p in out.iterdir()) == ["series.csv", "series.png"]
    comments, header, data = read_csv(out / "series.csv")
    assert header == "time,intensity,intensity_clean"
    assert data.shape == (100, 3)
    assert any(c.startswith("# scene: {") and '"center_deflection":0.001' in c for c in comments)
    assert (out / "series.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    s = float(r.stdout.split("S =")[1].split()[0])
    assert s == pytest.approx((data[:, 2].max() - data[:, 2].min()) / data[:, 2].max(), rel=1e-3)


def test_seed_reproduces_and_set_overrides(tmp_path):
    a, b, c = (tmp_path / n for n in "abc")
    for path, seed in ((a, "1"), (b, "1")):
        assert run_cli("simulate", ROOF, *FAST, "--seed", seed, "-o", str(path)).returncode == 0
    assert (a / "series.csv").read_text() == (b / "series.csv").read_text()
    r = run_cli("simulate", ROOF, *FAST, "--set", "surfaces.roof.motion.frequency=25", "-o", str(c))
    assert r.returncode == 0
    _, _, data = read_csv(c / "series.csv")
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
        (["--seed", "x"], "is not an integer in the allowed range [0, 2^32)"),
    ],
)
def test_bad_input_is_one_line_exit_2_and_no_file(tmp_path, args, message):
    r = run_cli("simulate", ROOF, *args, "-o", str(tmp_path / "out" / "sim"))
    assert r.returncode == 2
    assert message in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert list(tmp_path.iterdir()) == []  # not even the output directory


def test_missing_scene_and_unwritable_output(tmp_path):
    r = run_cli("simulate", str(tmp_path / "nope.toml"), "-o", str(tmp_path / "o"))
    assert r.returncode == 2 and "file not found" in r.stderr and "Traceback" not in r.stderr
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "file").write_text("x")
    r = run_cli("simulate", ROOF, *FAST, "-o", str(tmp_path / "file" / "dir"))
    assert r.returncode == 2 and "-o: cannot create directory" in r.stderr and "Traceback" not in r.stderr
    r = run_cli("simulate", ROOF, *FAST, "-o", str(tmp_path / "file"))
    assert r.returncode == 2 and "is not a directory" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert (tmp_path / "file").read_text() == "x"
    # a directory where the plot goes: refused before any work, and no series is written either
    (tmp_path / "o" / "series.png").mkdir(parents=True)
    r = run_cli("simulate", ROOF, *FAST, "-o", str(tmp_path / "o"), "--plot")
    assert r.returncode == 2 and "is a directory" in r.stderr
    assert [p.name for p in (tmp_path / "o").iterdir()] == ["series.png"]


@pytest.mark.slow
def test_version_and_demo(tmp_path):
    r = run_cli("--version", fresh=True)
    assert r.returncode == 0 and r.stdout.startswith("vibinverse ")
    out = tmp_path / "demo"
    r = run_cli("demo", "-o", str(out), "--no-progress", "--json", fresh=True)  # the main job, cold
    assert r.returncode == 0, r.stderr
    assert "report:" in r.stderr and "R-hat" in r.stderr  # the log, on stderr with --json
    doc = strict_json(r.stdout)
    files = {"series.csv", "series.png", "result.nc", "summary.json", "result.chain.h5", "report.html"}
    assert {p.name for p in out.iterdir()} == files == documented_files("demo")
    assert sorted(doc.pop("paths")) == sorted(str(out / n) for n in files)
    summary = json.loads((out / "summary.json").read_text())
    assert doc == summary
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
    r = run_cli("simulate", str(SCENES / f"{scene}.toml"), "--set", override, "-o", str(tmp_path / "o"))
    assert r.returncode == 2 and message in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    assert list(tmp_path.iterdir()) == []


def test_simulate_explain_dense_and_rtol(tmp_path):
    r = run_cli("simulate", ROOF, *FAST, "--explain", "-o", str(tmp_path / "a"))
    assert r.returncode == 0 and "chebyshev" in r.stdout and "est. error" in r.stdout
    r2 = run_cli("simulate", ROOF, *FAST, "--dense", "-o", str(tmp_path / "b"))
    assert r2.returncode == 0
    a = np.loadtxt(tmp_path / "a" / "series.csv", delimiter=",", comments="#", skiprows=6)
    b = np.loadtxt(tmp_path / "b" / "series.csv", delimiter=",", comments="#", skiprows=6)
    assert np.abs(a[:, 2] - b[:, 2]).max() <= 1e-5 * np.ptp(b[:, 2])
    r = run_cli("simulate", ROOF, "--rtol", "-1", "-o", str(tmp_path / "c"))
    assert r.returncode == 2 and "--rtol" in r.stderr and not (tmp_path / "c").exists()


FRAME = str(SCENES / "roof_frame.toml")


@pytest.mark.parametrize(
    "args, message",
    [
        (("nope.csv", "--scene", FRAME), "file not found"),
        (("DATA", "--scene", FRAME, "--free", "noise.sigma=gauss(1)"), "prior"),
        (("DATA", "--scene", ROOF, "--method", "sindy"), "sindy"),
        # the 4 s series is too short for 0.1 Hz (one cycle needs 10 s)
        (("DATA", "--scene", FRAME, "--free", f"{K}tilt_frequency=uniform(0.1, 5)"), "needs at least 10 s"),
        (("DATA", "--scene", FRAME, "--free", f"{K}drive_frequency=uniform(5, 150)"), "Nyquist"),
        (("DATA", "--scene", FRAME, "--free", "surfaces.roof.x[0]=uniform(-6, -4)"), "cannot be fitted"),
        (("DATA", "--scene", FRAME, "--method", "ipopt"), "--method"),
        (("DATA", "--scene", FRAME, "--summary", "no/such/dir/s.json"), "--summary: cannot write"),
        (("DATA", "--scene", FRAME, "--modes", "2"), "--modes: fixes the order of the scene-less modal model"),
        (("DATA", "--modes", "9"), "--modes: 9 is outside the allowed range [0, 6]"),
        (("DATA", "--set", "noise.sigma=1"), "--set: overrides a scene value"),
    ],
)
def test_fit_bad_input_is_one_line_exit_2(short_data, tmp_path, args, message):
    args = tuple(str(short_data / "series.csv") if a == "DATA" else a for a in args)
    r = run_cli("fit", *args, "-o", "r", cwd=tmp_path)
    assert r.returncode == 2 and message in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert list(tmp_path.iterdir()) == []  # not even the output directory


def test_cli_fits_a_scene_beside_nuisance_terms(short_data, tmp_path):
    """`fit --scene S --noise ar1 --drift walk`: the frame's tilt beside AR(1) noise and a drift,
    the terms in the summary's model."""
    data = str(short_data / "series.csv")
    r = run_cli(
        "fit", data, "--scene", FRAME, "--noise", "ar1", "--drift", "walk", "--method", "map", "-o", "r", cwd=tmp_path
    )
    assert r.returncode == 0, r.stderr
    summary = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert {"ar.rms", "ar.time", "drift.rate"} <= set(summary["parameters"])
    assert summary["data"]["model"]["terms"] == "AR(1) noise, random-walk drift, white noise"


@pytest.mark.slow
def test_cli_fits_a_plate_and_refuses_sindy(tmp_path):
    scene = SCENES / "roof_elastic.toml"
    run = lambda *a: subprocess.run(
        [sys.executable, "-m", "vibinverse.cli", *map(str, a)], capture_output=True, text=True
    )
    assert run("simulate", scene, "--seed", "3", "--set", LOW_RES, "-o", tmp_path).returncode == 0
    data = tmp_path / "series.csv"
    out = run("fit", data, "--scene", scene, "--set", LOW_RES, "--method", "map", "-o", tmp_path / "r")
    assert out.returncode == 0, out.stderr
    summary = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert summary["parameters"][K + "frequency"]["truth"] == 40.0
    bad = run("fit", data, "--scene", scene, "--method", "sindy", "-o", tmp_path / "s")
    assert bad.returncode == 2 and "sindy" in bad.stderr and "Traceback" not in bad.stderr
    assert not (tmp_path / "s").exists()


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
        (lambda d: ["fit", d["csv"], "--scene", ROOF, "-o", d["data"], "--summary", ROOF], "replace the input"),
        (lambda d: ["fit", d["csv"], "--scene", ROOF, "-o", d["data"], "--chain", d["csv"]], "replace the input"),
        (lambda d: ["fit", d["csv"], "--scene", ROOF, "-o", d["data"], "--summary", d["nc"]], "its own path"),
        (lambda d: ["fit", d["nc_input"], "--scene", ROOF, "-o", d["other"]], "replace the input"),
        (lambda d: ["simulate", d["scene_csv"], "-o", d["other"]], "replace the input"),
        (lambda d: ["report", d["html_input"]], "replace the input"),
        (lambda d: ["simulate", ROOF, "-o", ROOF], "is not a directory"),
        (lambda d: ["simulate", ROOF, "-o", d["csv"]], "is not a directory"),
    ],
)
def test_an_output_never_replaces_an_input_or_another_output(tmp_path, make_args, message):
    """Inputs that sit where a verb writes its fixed names: refused before any work."""
    assert run_cli("simulate", ROOF, *FAST, "--seed", "1", "-o", str(tmp_path / "data")).returncode == 0
    other = tmp_path / "other"
    other.mkdir()
    for name in ("series.csv", "result.nc", "report.html"):  # inputs named like outputs
        shutil.copy(tmp_path / "data" / "series.csv", other / name)
    d = {
        "data": str(tmp_path / "data"),
        "csv": str(tmp_path / "data" / "series.csv"),
        "nc": str(tmp_path / "data" / "result.nc"),
        "other": str(other),
        "nc_input": str(other / "result.nc"),
        "scene_csv": str(other / "series.csv"),
        "html_input": str(other / "report.html"),
    }
    files = {p: p.read_bytes() for p in [*tmp_path.rglob("*.*"), Path(ROOF)] if p.is_file()}
    r = run_cli(*make_args(d))
    assert r.returncode == 2 and message in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert all(p.read_bytes() == b for p, b in files.items())
    assert sorted(tmp_path.rglob("*")) == sorted([tmp_path / "data", other, *(p for p in files if p != Path(ROOF))])


def test_quiet_and_verbose_before_or_after_the_verb(tmp_path):
    out = tmp_path / "a"
    for args in (["-q", "simulate", ROOF, *FAST, "-o", str(out)], ["simulate", "-q", ROOF, *FAST, "-o", str(out)]):
        r = run_cli(*args)
        assert r.returncode == 0 and r.stdout == "" and (out / "series.csv").exists(), r.stderr
    r = run_cli("simulate", ROOF, *FAST, "-o", str(out))
    assert "sensitivity S =" in r.stdout


@pytest.mark.slow
def test_ctrl_c_at_any_moment_of_a_run_is_one_line_and_exit_130(tmp_path):
    """Ctrl-C while the interpreter imports, while the parser loads, while the fit runs."""
    import signal
    import time

    assert run_cli("simulate", ROOF, *FAST, "--seed", "1", "-o", str(tmp_path)).returncode == 0
    for delay in (0.4, 0.8, 1.5, 2.5):  # (earlier, CPython itself is still starting: not ours to catch)
        out = tmp_path / f"r{delay}"  # its own directory: an earlier delay's run may have finished and written one
        args = ["fit", str(tmp_path / "series.csv"), "--scene", ROOF, "--method", "map", "-o", str(out)]
        proc = subprocess.Popen(
            [sys.executable, "-m", "vibinverse", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        time.sleep(delay)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
        assert "Traceback" not in err, (delay, err)
        if proc.returncode != 0:  # (a run that finished before the signal came is fine)
            assert proc.returncode == 130 and len(err.strip().splitlines()) == 1, (delay, proc.returncode, err)
            assert not (out / "result.nc").exists()


# ---------------------------------------------------------------- one meaning of -o DIR and --json


def test_every_verb_documents_its_output_directory_and_json():
    """Each verb's help: --json, and (if it writes files) `-o DIR, --output DIR  output directory
    (default: X); writes a.csv, b.png`, with X the real default."""
    assert {"simulate", "fit", "report", "design", "study", "bench", "demo"} <= set(verbs())
    for name, verb in verbs().items():
        text = " ".join(verb.format_help().split())
        options = {o for a in verb._actions for o in a.option_strings}
        assert "--json" in options and "--json print" in text, name
        o = output_option(name)
        if name in WRITES_NOTHING:
            assert o is None, name
            continue
        assert o is not None and o.option_strings == ["-o", "--output"] and o.metavar == "DIR", name
        m = re.fullmatch(r"output directory \(default: (?P<default>[^)]+)\); writes (?P<files>.+)", o.help)
        assert m, (name, o.help)
        assert f"-o DIR, --output DIR {o.help}" in text, name
        assert m["default"] == (str(o.default) if o.default is not None else "the result file's directory"), name
        assert documented_files(name), name


def test_json_and_layout_of_simulate_fit_and_report(tmp_path, capsys):
    scene, run = str(SCENES / "roof_frame.toml"), tmp_path / "run"
    doc, err = cli_json(
        capsys, "simulate", scene, "--set", "sampling.duration=2", "--seed", "1", "-o", str(run), "--plot"
    )
    assert "sensitivity S =" in err  # the log goes to stderr
    assert doc["paths"] == [str(run / "series.csv"), str(run / "series.png")] and set(doc) == {"sensitivity", "paths"}
    assert 0 < doc["sensitivity"] < 1
    assert names(run) == {"series.csv", "series.png"} <= documented_files("simulate")

    doc, err = cli_json(
        capsys, "fit", str(run / "series.csv"), "--scene", scene, "--method", "spectral", "-o", str(run)
    )
    assert "data: 400 samples" in err
    assert doc.pop("paths") == [str(run / "result.nc"), str(run / "summary.json")]  # no chain without MCMC
    assert doc == json.loads((run / "summary.json").read_text()) and doc["method"] == "spectral"
    assert names(run) == {"series.csv", "series.png", "result.nc", "summary.json"}
    assert {"result.nc", "summary.json"} <= documented_files("fit")

    doc, _ = cli_json(capsys, "report", str(run / "result.nc"))  # default: the result's own directory
    assert doc == {"paths": [str(run / "report.html")]}
    assert names(run) == {"series.csv", "series.png", "result.nc", "summary.json", "report.html"}
    assert documented_files("report") == {"report.html"}


def test_json_and_layout_of_design_and_study(tmp_path, capsys):
    out = tmp_path / "nested" / "design"  # created with its parent
    args = ["--set", "footprint.resolution=32", "--vary", "sensor.offset=-0.02:0.02:3", "--no-progress"]
    doc, err = cli_json(capsys, "design", str(builtin_scene("roof_elastic")), *args, "-o", str(out))
    assert "3 configurations" in err
    assert doc["n_configurations"] == 3 and len(doc["best"]) == 3 and doc["threshold"] == 1e-4
    assert doc["best"] == json.loads((out / "design.json").read_text())["best"]
    assert sorted(doc["paths"]) == sorted(str(p) for p in out.iterdir())
    assert names(out) == documented_files("design")

    out = tmp_path / "studies"
    doc, err = cli_json(capsys, "study", "fig6", "-o", str(out))
    assert err.startswith("fig6:")
    assert doc["studies"]["fig6"]["summary"] == err.strip()
    assert doc["studies"]["fig6"]["results"] == json.loads((out / "fig6.json").read_text())
    assert sorted(doc["paths"]) == sorted(str(p) for p in out.iterdir())
    assert {n.replace("fig6", "NAME") for n in names(out)} == documented_files("study")


@pytest.mark.parametrize("mode", [None, "estimators", "robustness"])
def test_json_and_layout_of_bench(tmp_path, capsys, monkeypatch, mode):
    """The bench's wiring (its runs take minutes: stand-ins here; examples/benchmarks.md runs them)."""
    from vibinverse.bench import estimators_bench, forward_bench, robustness_bench

    result = {"rows": [], "speed_error": [{"error": float("nan")}], "seconds": 1.5}
    module = {None: forward_bench, "estimators": estimators_bench, "robustness": robustness_bench}[mode]
    monkeypatch.setattr(module, "run", lambda *a, **k: result)
    for name in ("plot_speed_error", "plot"):
        if hasattr(module, name):
            monkeypatch.setattr(module, name, lambda rows, path: path.write_bytes(b"\x89PNG"))
    if mode == "robustness":
        monkeypatch.setattr(module, "table", lambda r: "a table")
    doc, _ = cli_json(capsys, "bench", "--quick", "-o", str(tmp_path), *([f"--{mode}"] if mode else []))
    stem = mode or "bench"
    assert doc.pop("paths") == [str(tmp_path / f"{stem}.json"), str(tmp_path / f"{stem}.png")]
    assert doc["speed_error"] == [{"error": None}] and doc["non_finite"] == {"/speed_error/0/error": "NaN"}
    assert names(tmp_path) == {f"{stem}.json", f"{stem}.png"} <= documented_files("bench")


def test_bench_modes_are_one_at_a_time(tmp_path):
    r = run_cli("bench", "--estimators", "--robustness", "-o", str(tmp_path / "b"))
    assert r.returncode == 2 and "not allowed with argument" in r.stderr


def test_fit_without_a_scene_uses_the_modal_model_with_the_order_fixed_or_chosen(tmp_path, capsys):
    """A series and no scene: resonances and lines in intensity units; --modes/--lines/--noise/--drift/--gain
    fix them; --gain drift forces the multiplicative gain drift in (6 cosines, near 0 here)."""
    rng = np.random.default_rng(4)
    fs, n = 20.0, 2400
    t = np.arange(n) / fs
    w, zeta = 2 * np.pi * 2.2, 0.02  # one mode by its exact AR(2) form, plus white noise
    r, th = np.exp(-zeta * w / fs), w * np.sqrt(1 - zeta**2) / fs
    x, e = np.zeros(n), rng.normal(size=n)
    for k in range(2, n):
        x[k] = 2 * r * np.cos(th) * x[k - 1] - r * r * x[k - 2] + e[k]
    data = tmp_path / "ambient.csv"
    np.savetxt(
        data, np.c_[t, x / x.std() + 0.5 * rng.normal(size=n)], delimiter=",", header="time,intensity", comments=""
    )
    fixed, _ = cli_json(
        capsys,
        "fit",
        str(data),
        "--method",
        "map",
        "--modes",
        "1",
        "--lines",
        "0",
        "--noise",
        "white",
        "--drift",
        "none",
        "--gain",
        "none",
        "-o",
        str(tmp_path / "fixed"),
    )
    assert fixed["diagnostics"]["model_order"] == []  # nothing searched
    f = fixed["parameters"]["modes[0].frequency"]
    assert f["units"] == "Hz" and f["q05"] < 2.2 < f["q95"]
    chosen, _ = cli_json(capsys, "fit", str(data), "--method", "map", "-o", str(tmp_path / "chosen"))
    assert [k for k in chosen["parameters"] if k.endswith(".frequency")] == ["modes[0].frequency"]
    assert chosen["diagnostics"]["model_order"]  # the BIC table of the search
    assert chosen["parameters"]["modes[0].frequency"]["median"] == pytest.approx(2.2, rel=0.01)
    forced, _ = cli_json(
        capsys,
        *("fit", str(data), "--method", "map", "--modes", "1", "--lines", "0", "--noise", "white"),
        *("--drift", "none", "--gain", "drift", "-o", str(tmp_path / "forced")),
    )
    gains = [forced["parameters"][f"gain.a{j}"]["median"] for j in range(1, 7)]
    assert max(abs(g) for g in gains) < 0.2  # no gain drift in the data: each coefficient ~ its sd
    assert forced["parameters"]["modes[0].frequency"]["median"] == pytest.approx(2.2, rel=0.01)


def test_ctrl_c_that_an_extension_turns_into_its_own_error_is_one_line_and_130(monkeypatch, capsys):
    """Ctrl-C inside casadi's IPOPT callback comes back as casadi's RuntimeError, the
    KeyboardInterrupt not in its chain (seen in the Ctrl-C test at 2.5 s): main remembers the
    signal (its SIGINT handler), so still one line, 130; without a signal the error is raised."""
    import argparse
    import os
    import signal

    from vibinverse import cli
    from vibinverse.cli import commands

    def verb(args):
        try:
            os.kill(os.getpid(), signal.SIGINT)  # main's handler raises KeyboardInterrupt here
            for _ in range(1000):  # the signal is handled between bytecodes
                pass
        except KeyboardInterrupt:
            pass  # what the extension does: its own error, no chain
        raise RuntimeError("Error in Function::call for 'solver': returned a result with an exception set")

    monkeypatch.setattr(
        commands, "build_parser", lambda: type("P", (), {"parse_args": lambda s, a: argparse.Namespace(func=verb)})()
    )
    assert cli.main([]) == 130
    assert capsys.readouterr().err.strip() == "vibinverse: interrupted"
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # restored

    def failing(args):
        raise RuntimeError("a real solver error")

    monkeypatch.setattr(
        commands, "build_parser", lambda: type("P", (), {"parse_args": lambda s, a: argparse.Namespace(func=failing)})()
    )
    with pytest.raises(RuntimeError, match="a real solver error"):
        cli.main([])


def test_ctrl_c_inside_an_extension_import_is_one_line_and_130(monkeypatch, capsys):
    """Ctrl-C while a C extension initializes comes back as "ImportError: initialization failed"
    raised from the KeyboardInterrupt (seen in the Ctrl-C test at 1.5 s): still one line, 130."""
    import argparse

    from vibinverse import cli
    from vibinverse.cli import commands

    def verb(args):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt as exc:
            raise ImportError("initialization failed") from exc

    class Parser:
        def parse_args(self, argv):
            return argparse.Namespace(func=verb)

    monkeypatch.setattr(commands, "build_parser", lambda: Parser())
    assert cli.main([]) == 130
    assert capsys.readouterr().err.strip() == "vibinverse: interrupted"

    def broken(args):
        raise ImportError("a real import error")

    monkeypatch.setattr(
        commands, "build_parser", lambda: type("P", (), {"parse_args": lambda s, a: argparse.Namespace(func=broken)})()
    )
    with pytest.raises(ImportError, match="a real import error"):
        cli.main([])


def test_an_unknown_method_is_refused_before_the_order_search(tmp_path):
    """A scene-less fit searches the model's order first (minutes on a long record): an unknown
    `--method` is refused before it, in one line naming the allowed methods, exit 2, no output."""
    t = np.arange(4000) / 200.0
    y = np.sin(2 * np.pi * 10.0 * t) + np.random.default_rng(0).normal(size=t.size)
    data = tmp_path / "series.csv"
    np.savetxt(data, np.column_stack([t, y]), delimiter=",", header="time,intensity", comments="")
    out = tmp_path / "out"
    r = run_cli("fit", str(data), "--method", "bogus", "-o", str(out))
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "--method: 'bogus' is not one of" in r.stderr and "importance" in r.stderr
    assert "model order" not in r.stderr + r.stdout  # no search ran
    assert not out.exists()


def test_fit_decays_fixes_the_free_decays_and_refuses_a_count_out_of_range(tmp_path, capsys):
    t = np.arange(800) / 200.0
    u = np.clip(t - 1.0, 0.0, None)
    ring = np.where(t >= 1.0, np.exp(-0.01 * 2 * np.pi * 15.0 * u) * np.sin(2 * np.pi * 15.0 * u), 0.0)
    y = 1.0 + ring + 0.05 * np.random.default_rng(4).normal(size=t.size)
    data = tmp_path / "blow.csv"
    np.savetxt(data, np.c_[t, y], delimiter=",", header="time,intensity", comments="")
    order = ("--modes", "0", "--lines", "0", "--drift", "none", "--noise", "white", "--gain", "none")
    fixed, _ = cli_json(capsys, "fit", str(data), "--method", "map", "--decays", "1", *order, "-o", str(tmp_path / "f"))
    f = fixed["parameters"]["decays[0].frequency"]
    assert f["units"] == "Hz" and f["q05"] < 15.0 < f["q95"]
    assert fixed["diagnostics"]["decay_0_detected"] is True
    bad = run_cli("fit", str(data), "--decays", "7", "-o", str(tmp_path / "bad"))
    assert bad.returncode == 2 and "--decays" in bad.stderr and "[0, 6]" in bad.stderr
    assert "Traceback" not in bad.stderr and not (tmp_path / "bad").exists()
