"""Sampling with emcee: intervals that hold the truth, multimodal walkers flagged, and an
interrupted run that resumes to the same samples."""

import json
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from tests.conftest import LOW_RES, SNR10, G, K, fit_args, fitted, frame_problem, run_cli, simulate
from vibinverse.fisher import crlb_sd
from vibinverse.pipeline import run


@pytest.mark.slow
def test_mcmc_intervals_contain_the_truth(tmp_path):
    prob = frame_problem(SNR10)
    summary = run(prob, "mcmc", max_steps=1500, progress=False, backend=tmp_path / "c.h5", seed=1).summary()
    truth = prob.truth()
    for n in ("tilt_frequency", "tilt_damping_ratio", "drive_frequency", "drive_amplitude"):
        p = summary["parameters"][K + n]
        assert p["q05"] <= truth[K + n] <= p["q95"], (n, p)
    crlb = crlb_sd(prob.model, truth, [K + "drive_frequency", K + "drive_amplitude", K + "drive_phase"])
    assert summary["parameters"][K + "drive_frequency"]["sd"] <= 1.5 * crlb[K + "drive_frequency"]


@pytest.mark.slow
def test_ground_wave_mcmc_intervals_contain_the_truth(tmp_path):
    table, series = simulate("ground_rayleigh", LOW_RES, "noise.sigma=3e-6", seed=2)
    _problem, summary = fitted(table, series, "mcmc", backend=tmp_path / "c.h5", max_steps=3000)
    for n in (G + "frequency[0]", G + "amplitude[0]", G + "phase[0]", "noise.sigma"):
        p = summary["parameters"][n]
        assert p["q05"] <= p["truth"] <= p["q95"], (n, p)
    assert summary["diagnostics"]["converged"]


def test_multimodal_walkers_are_flagged():
    from vibinverse.estimators.mcmc import multimodal
    from vibinverse.report import warnings_for

    rng = np.random.default_rng(0)
    one = rng.normal(0.0, 1.0, (16, 500, 2))
    two = one.copy()
    two[:6, :, 1] += 40.0  # six walkers stuck in a second mode of parameter 1
    assert multimodal(one, ["a", "b"]) == []
    assert multimodal(two, ["a", "b"]) == ["b"]
    summary = {"diagnostics": {"multimodal": ["b"], "converged": True}, "parameters": {}}
    assert any("b is multimodal" in w for w in warnings_for(summary, None, []))


@pytest.mark.slow
def test_interrupted_run_resumes_to_the_same_samples(short_data):
    import h5py

    d = short_data
    steps = 800
    full = run_cli(*fit_args(d, "full800", steps=steps))
    assert full.returncode == 0, full.stderr
    proc = subprocess.Popen(
        [sys.executable, "-m", "vibinverse", *fit_args(d, "cut", steps=steps)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    for line in proc.stdout:  # the fit says when sampling starts; interrupt a little later
        if line.startswith("sampling with emcee"):
            break
    time.sleep(2.0)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130 and "resume with --resume" in err and "Traceback" not in err, err
    assert not (d / "cut" / "result.nc").exists()
    with h5py.File(d / "cut" / "result.chain.h5", "r") as f:
        assert 0 < f["mcmc"].attrs["iteration"] < steps  # really interrupted mid-run
    resumed = run_cli(*fit_args(d, "cut", "--resume", steps=steps))
    assert resumed.returncode == 0, resumed.stderr
    with h5py.File(d / "full800" / "result.chain.h5", "r") as a, h5py.File(d / "cut" / "result.chain.h5", "r") as b:
        assert a["mcmc"].attrs["iteration"] == b["mcmc"].attrs["iteration"] == steps
        np.testing.assert_array_equal(a["mcmc/chain"][...], b["mcmc/chain"][...])
    assert json.loads((d / "cut" / "summary.json").read_text())["diagnostics"]["n_steps"] == steps


def _interrupt(d, name, sig, *extra, steps=800):
    """Start a fit, send `sig` once sampling runs, return (return code, stderr)."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "vibinverse", *fit_args(d, name, *extra, steps=steps)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    for line in proc.stdout:
        if line.startswith("sampling with emcee"):
            break
    time.sleep(1.5)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    return proc.returncode, err


@pytest.mark.slow
def test_sigterm_exits_143_and_workers_stop_without_tracebacks(short_data):
    d = short_data
    code, err = _interrupt(d, "term", signal.SIGTERM)
    assert code == 143 and "resume with --resume" in err and "Traceback" not in err, err
    assert len(err.strip().splitlines()) == 1, err
    # with a pool, Ctrl-C reaches the workers too (one process group): they leave it to the parent
    code, err = _interrupt(d, "pool", signal.SIGINT, "--workers", "2")
    assert code == 130 and "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert not (d / "pool" / "result.nc").exists() and not (d / "term" / "result.nc").exists()


@pytest.mark.slow
def test_resume_refuses_a_checkpoint_of_other_data_scene_or_priors(short_data, tmp_path):
    d = short_data
    first = run_cli(*fit_args(d, "ident", steps=100))
    assert first.returncode == 0, first.stderr
    other = tmp_path / "other.csv"
    text = (d / "series.csv").read_text().splitlines()
    k = next(i for i, ln in enumerate(text) if ln and ln[0].isdigit())
    t, y, *rest = text[k + 5].split(",")
    text[k + 5] = ",".join([t, repr(float(y) + 1e-3), *rest])  # one sample changed
    other.write_text("\n".join(text) + "\n")
    chain = str(d / "ident" / "result.chain.h5")
    before = (d / "ident" / "result.chain.h5").read_bytes()
    args = fit_args(d, "ident2", "--resume", "--chain", chain, steps=200)
    r = run_cli(*[str(other) if a == str(d / "series.csv") else a for a in args])
    assert r.returncode == 2 and "other data" in r.stderr and "Traceback" not in r.stderr, r.stderr
    r = run_cli(*args, "--free", "noise.sigma=loguniform(1e-3, 1)")
    assert r.returncode == 2 and "other free parameters" in r.stderr, r.stderr
    r = run_cli(*args, "--set", "sensor.inclination=pi/3+0.012")
    assert r.returncode == 2 and "other scene" in r.stderr, r.stderr
    assert (d / "ident" / "result.chain.h5").read_bytes() == before  # refused before touching the checkpoint
    assert not (d / "ident2" / "result.nc").exists()


def test_a_corrupt_or_foreign_checkpoint_is_a_one_line_error(short_data, tmp_path):
    d = short_data
    bad = tmp_path / "bad.h5"
    bad.write_bytes(b"\x89HDF\r\n\x1a\n" + b"\0" * 64)  # an HDF5 signature and then garbage
    for path in (bad, tmp_path):
        r = run_cli(*fit_args(d, "bad", "--resume", "--chain", str(path), steps=100))
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr, r.stderr
    text = tmp_path / "notes.h5"
    text.write_text("not a checkpoint")
    r = run_cli(*fit_args(d, "bad", "--chain", str(text), steps=100))
    assert r.returncode == 2 and "not an HDF5 checkpoint" in r.stderr, r.stderr
    assert text.read_text() == "not a checkpoint"
    # a result file (HDF5, no sampler chain) given as the checkpoint: refused with or without
    # --resume, and left as it was (a run without --resume would have written its chain into it)
    result = d / "ident" / "result.nc"
    if not result.exists():
        assert run_cli(*fit_args(d, "ident", steps=100)).returncode == 0
    before = result.read_bytes()
    for extra in (("--resume",), ()):
        r = run_cli(*fit_args(d, "bad", *extra, "--chain", str(result), steps=100))
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
        assert "without a sampler chain" in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert result.read_bytes() == before


def test_threaded_walkers_give_the_serial_chain(tmp_path):
    """The frame likelihood releases the GIL, so `workers` > 1 evaluates walkers in threads
    (`ThreadMap`): the chain is the serial one, bit for bit, and the checkpoint holds every step."""
    from vibinverse.estimators import mcmc
    from vibinverse.estimators.casadi_map import casadi_map
    from vibinverse.estimators.spectral import ranked_starts

    prob = frame_problem("sampling.duration=4", "noise.sigma=0.05", seed=2)
    assert prob.model.releases_gil
    m = casadi_map(prob, ranked_starts(prob)[:1])
    runs = [
        mcmc.run(prob, m.z, m.cov_z, tmp_path / f"w{w}.h5", workers=w, max_steps=60, progress=False, seed=4)
        for w in (1, 2)
    ]
    np.testing.assert_array_equal(runs[0]["chain"], runs[1]["chain"])
    np.testing.assert_array_equal(runs[0]["log_prob"], runs[1]["log_prob"])
    assert runs[1]["chain"].shape[0] == 60
