"""What several test modules share: the example scenes, simulated series and posteriors of the frame
and deterministic models, built-in scene tables, the quick study results and the command line."""

import contextlib
import io
import json
import os
import subprocess
import sys
from pathlib import Path

# One BLAS thread per test process, and in the processes the tests start (the variables): the tests
# run on every core already (pytest -n auto), and OpenBLAS's threads spinning beside the other
# workers cost the suite ~40 % (test_model_order + test_scipy_map on 2 cores: 203 s -> 116 s)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
# ... and one thread per fit (`vibinverse.parallel.default_workers`) for the same reason: two per fit
# beside the other workers took the fast suite from 209 s to 271 s on 2 cores
os.environ.setdefault("VIBINVERSE_WORKERS", "1")

import numpy as np
import pytest
from hypothesis import settings
from scipy.linalg import expm
from threadpoolctl import threadpool_limits

from forward.scene_file import apply_overrides, load_scene, read_table, scene_from_table
from forward.sensor import observe
from vibinverse.cli import main
from vibinverse.io.builtin import builtin_scene
from vibinverse.io.series import Series, validate
from vibinverse.models import build_model
from vibinverse.models.frame import modal_table
from vibinverse.pipeline import run
from vibinverse.posterior import Posterior
from vibinverse.scene_keys import set_value
from vibinverse.studies import STUDIES

SCENES = Path(__file__).resolve().parents[1] / "examples" / "scenes"

# ... numpy may have been imported (by a plugin) before the variables were set: limit it here too
threadpool_limits(1, user_api="blas")

# property-based tests: a bounded, reproducible run by default (CI); HYPOTHESIS_PROFILE=long for more
settings.register_profile("ci", max_examples=25, derandomize=True, deadline=None, print_blob=True)
settings.register_profile("long", max_examples=500, deadline=None, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

# CI (.ci/run sets VIBINVERSE_NO_SKIPS=1): a skipped test fails, unless its reason holds one of these
# (a wheel's FFmpeg build without an h264 encoder is the platform's, not the project's, to fix)
ALLOWED_SKIPS = ("this FFmpeg build has no h264 encoder",)


def unexpected_skip(reason: str, environ: dict | None = None) -> bool:
    """Whether a skip with this reason fails the run: under VIBINVERSE_NO_SKIPS=1, any reason not
    in ALLOWED_SKIPS (a missing package or recording is an install to fix, not a pass)."""
    env = os.environ if environ is None else environ
    return env.get("VIBINVERSE_NO_SKIPS") == "1" and not any(a in reason for a in ALLOWED_SKIPS)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """An unexpected skip (`unexpected_skip`) is reported as a failure naming its reason."""
    outcome = yield
    report = outcome.get_result()
    if report.skipped and not hasattr(report, "wasxfail"):
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
        if unexpected_skip(reason):
            report.outcome = "failed"
            report.longrepr = f"unexpected skip under VIBINVERSE_NO_SKIPS=1: {reason}"


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector):
    """A module skipped whole at collection (a module-level importorskip): the same rule."""
    outcome = yield
    report = outcome.get_result()
    if report.skipped:
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else str(report.longrepr)
        if unexpected_skip(reason):
            report.outcome = "failed"
            report.longrepr = f"unexpected skip under VIBINVERSE_NO_SKIPS=1: {reason}"


K = "surfaces.roof.motion."  # the roof's motion keys (frame and plate scenes)
G = "surfaces.ground.motion."  # the ground's motion keys
FAST = ("footprint.resolution=48", "sampling.duration=0.1")  # a quick render of an example scene
LOW_RES = "footprint.resolution=32"  # 1024 subpixels: the dense oracle stays cheap
SNR10 = "noise.sigma=0.6"  # drive-line amplitude / standard error of a sinusoid fit ~ 10 (README)
WAVELENGTH = 75.0  # ground scene: 3000 m/s at 40 Hz


@pytest.fixture
def scene():
    """scene("roof_elastic", "footprint.resolution=32", ...) -> Scene from an example file with overrides."""

    def make(name, *overrides):
        return load_scene(SCENES / f"{name}.toml", list(overrides))[0]

    return make


# ------------------------------------------------------------------ the frame model (sec. 4.2)


def held_reference(w, zeta, frame, step):
    """(Phi, Q) of a force held over each of round(step / frame) equal parts of the step at variance
    1 / part: the augmented matrix exponential exp([[A, B], [0, 0]] h) gives (Phi, Gamma) of a part,
    the parts are composed one by one."""
    parts = max(1, round(step / frame))
    h = step / parts
    aug = np.zeros((3, 3))
    aug[:2, :2] = [[0.0, 1.0], [-w * w, -2 * zeta * w]]
    aug[1, 2] = 1.0
    e = expm(aug * h)
    phi, q = e[:2, :2], np.outer(e[:2, 2], e[:2, 2]) / h
    out_phi, out_q = np.eye(2), np.zeros((2, 2))
    for _ in range(parts):
        out_phi, out_q = phi @ out_phi, phi @ out_q @ phi.T + q
    return out_phi, out_q


def frame_problem(*overrides, seed=3, gaps=0.0):
    scene, table = load_scene(SCENES / "roof_frame.toml", list(overrides))
    o = observe(scene, seed=seed)
    y = o.intensity.copy()
    if gaps:
        y[np.random.default_rng(seed).random(y.size) < gaps] = np.nan
    series = validate(o.time, y, "sim", table)
    return Posterior(build_model(table, series))


def frame(*overrides: str, modal: dict | None = None) -> dict:
    table = apply_overrides(read_table(builtin_scene("roof_frame")), list(overrides))
    if modal:
        table = modal_table(table)
        for key, value in modal.items():
            set_value(table, K + key, value)
    return table


def series(table: dict, seed: int, gaps: float = 0.0) -> Series:
    obs = observe(scene_from_table(table), seed)
    y = obs.intensity.copy()
    if gaps:
        y[np.random.default_rng(100 + seed).random(y.size) < gaps] = np.nan
    return Series(obs.time, y, f"seed {seed}", scene=table)


def frame_series(table: dict, seed: int, ar: tuple[float, float] | None = None) -> Series:
    """A series of the frame scene `table`, with AR(1) sensor noise (phi, sd) added when `ar` is
    given (the robustness bench's independent simulator, `robustness_cases.ar1`)."""
    from vibinverse.bench.robustness_cases import ar1

    obs = observe(scene_from_table(table), seed)
    y = obs.intensity.copy()
    if ar is not None:
        y += ar1(y.size, *ar, np.random.default_rng(1000 + seed))
    return Series(obs.time, y, f"seed {seed}", scene=table)


# ------------------------------------------------------------------ the deterministic model (plate roof, ground waves)


def simulate(name, *overrides, seed=0, truth_overrides=(), gaps=0.0, keep=None):
    """(analyst's scene table, Series) of a simulated scene; `truth_overrides` change only the scene
    the data come from, `keep` selects samples (non-uniform sampling)."""
    scene, table = load_scene(SCENES / f"{name}.toml", [*overrides, *truth_overrides])
    _, analyst = load_scene(SCENES / f"{name}.toml", list(overrides))
    o = observe(scene, seed)
    t, y = o.time, o.intensity.copy()
    if gaps:
        y[np.random.default_rng(seed).random(y.size) < gaps] = np.nan
    if keep is not None:
        t, y = t[keep], y[keep]
    return analyst, validate(t, y, "sim", table)


def fitted(table, series, method="map", **kw):
    problem = Posterior(build_model(table, series))
    summary = run(problem, method, progress=False, **kw).summary()
    return problem, summary


def z_scores(summary):
    return {n: (p["median"] - p["truth"]) / p["sd"] for n, p in summary["parameters"].items()}


# ------------------------------------------------------------------ design and studies


def table(name: str, *overrides: str) -> dict:
    return apply_overrides(read_table(builtin_scene(name)), list(overrides))


@pytest.fixture(scope="session")
def results(tmp_path_factory):
    """Every paper study, quick: (output directory, each study's line, each study's JSON). Once per
    session: the tests of every study module read it."""
    out = tmp_path_factory.mktemp("studies")
    lines = {name: fn(out, quick=True) for name, (fn, _) in STUDIES.items()}
    return out, lines, {name: json.loads((out / f"{name}.json").read_text()) for name in STUDIES}


# ------------------------------------------------------------------ the command line


def run_cli(*args: str, cwd: str | Path | None = None, fresh: bool = False) -> subprocess.CompletedProcess:
    """The command line on `args`: its exit code, stdout and stderr. By default in this process,
    through `main` as `python -m vibinverse` runs it but without starting an interpreter and
    importing the toolkit again (~3 s a call on a slow machine); with `fresh`, in a new interpreter
    (the entry point itself, signals, a cold start). An error `main` lets through (a traceback in a
    real run) fails the test here."""
    if fresh:
        command = [sys.executable, "-m", "vibinverse", *args]
        return subprocess.run(command, capture_output=True, text=True, cwd=cwd)
    out, err, here = io.StringIO(), io.StringIO(), os.getcwd()
    try:
        if cwd is not None:
            os.chdir(cwd)
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(list(args))
            except SystemExit as exc:  # argparse: --version, --help, a usage error
                code = exc.code if isinstance(exc.code, int) else int(exc.code is not None)
    finally:
        os.chdir(here)
    return subprocess.CompletedProcess(["vibinverse", *args], code, out.getvalue(), err.getvalue())


@pytest.fixture(scope="session")
def short_data(tmp_path_factory):
    """A 4 s frame series simulated by the command line (series.csv), once per session: each test
    that fits it writes into its own directory beside it (`fit_args`)."""
    d = tmp_path_factory.mktemp("fit")
    r = run_cli(
        "simulate",
        str(SCENES / "roof_frame.toml"),
        "--set",
        "sampling.duration=4",
        "--set",
        "noise.sigma=0.05",
        "--seed",
        "2",
        "-o",
        str(d),
    )
    assert r.returncode == 0, r.stderr
    return d


def fit_args(d, name, *extra, steps=400):
    """An MCMC fit of `short_data` into the directory d/name (result.nc, summary.json, result.chain.h5)."""
    return (
        "fit",
        str(d / "series.csv"),
        "--scene",
        str(SCENES / "roof_frame.toml"),
        "--method",
        "mcmc",
        "--max-steps",
        str(steps),
        "--no-progress",
        "-o",
        str(d / name),
        *extra,
    )


def unbounded_result():
    """A result with a normal prior (bounds -inf, inf), NaN MCMC diagnostics and an infinite timing."""
    import math

    import vibinverse as vi
    from vibinverse.priors import Prior
    from vibinverse.result import FitResult

    t = np.arange(64) * 0.01
    return FitResult(
        method="mcmc",
        names=["noise.sigma", "surfaces.roof.motion.frequency"],
        priors=[Prior("normal", (0.6, 0.1)), Prior("uniform", (1.0, 50.0))],
        point={"noise.sigma": 0.55, "surfaces.roof.motion.frequency": 20.0},
        series=vi.series(t, np.sin(2 * np.pi * 20 * t)),
        sd={"noise.sigma": 0.05, "surfaces.roof.motion.frequency": math.inf},
        diagnostics={
            "converged": False,
            "rhat_max": math.nan,
            "ess_min": np.float64("nan"),
            "tau_max": math.inf,
            "n_steps": 10,
        },
        timing={"mcmc_s": 1.5},
    )


#: the decimated building record's modes: (Hz, damping ratio, rms)
BUILDING_MODES = ((1.92, 0.012, 1.0), (2.31, 0.015, 0.7), (2.68, 0.010, 0.5))


def building_record(seed: int, seconds: float, fs: float = 10.0, white: float = 0.095) -> Series:
    """A building's ambient record at `fs`: the three modes of `BUILDING_MODES`, each an oscillator
    driven by continuous white noise, propagated by its exact discretization (Van Loan: scipy's
    matrix exponential) from its stationary law, plus white noise `white`; no drift."""
    from scipy.linalg import expm

    rng = np.random.default_rng(seed)
    n = round(seconds * fs)
    y = white * rng.standard_normal(n)
    for f, zeta, rms in BUILDING_MODES:
        w = 2.0 * np.pi * f
        a = np.array([[0.0, 1.0], [-w * w, -2.0 * zeta * w]])
        m = np.zeros((4, 4))
        m[:2, :2], m[:2, 2:], m[2:, 2:] = -a, np.diag([0.0, 4.0 * zeta * w**3 * rms**2]), a.T
        e = expm(m / fs)
        phi = e[2:, 2:].T
        q = phi @ e[:2, 2:]
        z = rng.standard_normal((n, 2)) @ np.linalg.cholesky(0.5 * (q + q.T)).T
        x = np.array([rms * rng.standard_normal(), w * rms * rng.standard_normal()])
        out = np.empty(n)
        for k in range(n):
            if k:
                x = phi @ x + z[k]
            out[k] = x[0]
        y += out
    return Series(np.arange(n) / fs, y, f"building (seed {seed})")


def decimated_building(seed: int, seconds: float, ftype: str = "iir") -> Series:
    """A logger's building record: three modes (`BUILDING_MODES`, each an oscillator driven by
    white noise, simulated at 100 Hz by its exact zero-order-hold discretization), white noise of
    0.3 and a random walk of rate 0.02 per sqrt(s), decimated to 10 Hz by `scipy.signal.decimate`
    (`ftype` "iir": its Chebyshev low-pass from 0.8 x Nyquist, zero phase)."""
    from scipy import signal

    rng = np.random.default_rng(seed)
    fs = 100.0
    n = round(seconds * fs)
    y = np.zeros(n)
    for f, zeta, rms in BUILDING_MODES:
        w = 2.0 * np.pi * f
        a = np.array([[0.0, 1.0], [-w * w, -2.0 * zeta * w]])
        ad, bd, *_ = signal.cont2discrete((a, np.array([[0.0], [1.0]]), np.eye(2), np.zeros((2, 1))), 1.0 / fs)
        num, den = signal.ss2tf(ad, bd, np.array([[1.0, 0.0]]), np.zeros((1, 1)))
        x = signal.lfilter(num[0], den, rng.standard_normal(n))
        y += rms * x / x.std()
    y += 0.3 * rng.standard_normal(n) + 0.02 * np.cumsum(rng.standard_normal(n)) / np.sqrt(fs)
    yd = signal.decimate(y, 10, ftype=ftype, zero_phase=True)
    return Series(np.arange(yd.size) / 10.0, yd, f"decimated building (seed {seed})")
