"""Inverse core: data, priors, the Kalman likelihood against two oracles, fits on sec. 4.2 data."""

import json
import math
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from forward.scene_file import load_scene
from forward.sensor import observe
from tests.conftest import SCENES
from vibinverse.errors import VibinverseError
from vibinverse.fisher import crlb_sd
from vibinverse.io.series import check_resolves, load_series, validate
from vibinverse.kalman import discretize_continuous, log_likelihood, log_likelihood_reference, stationary_covariance
from vibinverse.models import build_model
from vibinverse.pipeline import run
from vibinverse.posterior import Posterior
from vibinverse.priors import parse_free, parse_prior

K = "surfaces.roof.motion."
SNR10 = "noise.sigma=0.6"  # drive-line amplitude / standard error of a sinusoid fit ~ 10 (README)


def frame_problem(*overrides, seed=3, gaps=0.0):
    scene, table = load_scene(SCENES / "roof_frame.toml", list(overrides))
    o = observe(scene, seed=seed)
    y = o.intensity.copy()
    if gaps:
        y[np.random.default_rng(seed).random(y.size) < gaps] = np.nan
    series = validate(o.time, y, "sim", table)
    return Posterior(build_model(table, series))


# ------------------------------------------------------------------ Kalman likelihood oracles


def small_model():
    a = np.array([[0.0, 1.0], [-((2 * np.pi * 3) ** 2), -0.4]])
    phi, q = discretize_continuous(a, np.array([0.0, 1.0]), 50.0, 0.02)
    phi = np.kron(np.eye(2), phi) + 0.0
    phi[2:, 2:] *= 0.97
    q = np.kron(np.eye(2), q)
    return phi, q, np.array([0.7, 0.0, -1.3, 0.1]), 0.05, stationary_covariance(phi, q)


def test_kalman_equals_the_dense_multivariate_normal_with_gaps():
    phi, q, h, r, p0 = small_model()
    n = 60
    # explicit covariance of y: Cov(x_i, x_j) = Phi^(i-j) P0 for the stationary process
    powers = [np.eye(4)]
    for _ in range(n):
        powers.append(phi @ powers[-1])
    cov = np.array(
        [[h @ (powers[i - j] @ p0 if i >= j else p0 @ powers[j - i].T) @ h for j in range(n)] for i in range(n)]
    ) + r * np.eye(n)
    y = np.random.default_rng(0).multivariate_normal(np.zeros(n), cov)
    y[[5, 17, 18, 40]] = np.nan
    keep = np.isfinite(y)
    dense = multivariate_normal(np.zeros(keep.sum()), cov[np.ix_(keep, keep)]).logpdf(y[keep])
    assert log_likelihood(y, phi, q, h, r, p0) == pytest.approx(dense, abs=1e-8)
    assert log_likelihood_reference(y, phi, q, h, r, p0) == pytest.approx(dense, abs=1e-8)


def test_kalman_equals_celerite2_sho():
    celerite2 = pytest.importorskip("celerite2")
    s0, w0, qf, dt, sig = 0.7, 2 * np.pi * 3.46, 20.0, 0.005, 0.3
    a = np.array([[0.0, 1.0], [-(w0**2), -w0 / qf]])
    phi, q = discretize_continuous(a, np.array([0.0, 1.0]), 2 * s0 * w0**4, dt)  # k(0) = S0 w0 Q
    t = np.arange(4000) * dt
    gp = celerite2.GaussianProcess(celerite2.terms.SHOTerm(S0=s0, w0=w0, Q=qf))
    gp.compute(t, yerr=sig)
    # any series compares the two likelihoods; an oscillating one exercises the model
    rng = np.random.default_rng(1)
    y = 20 * np.sin(w0 * t + rng.uniform(0, 6)) * np.exp(-0.01 * t) + rng.normal(0, sig, t.size)
    ours = log_likelihood(y, phi, q, np.array([1.0, 0.0]), sig**2, stationary_covariance(phi, q))
    assert ours == pytest.approx(gp.log_likelihood(y), abs=1e-6)


# ------------------------------------------------------------------ data and priors


def test_csv_with_comments_truth_and_gaps(tmp_path):
    p = tmp_path / "d.csv"
    rows = "\n".join(f"{0.01 * i},{'' if i == 7 else np.sin(i)},{np.sin(i)}" for i in range(40))
    p.write_text('# vibinverse simulate\n# scene: {"a": 1}\ntime,intensity,intensity_clean\n' + rows + "\n")
    s = load_series(p)
    assert s.scene == {"a": 1} and s.n_gaps == 1 and s.uniform and s.fs == pytest.approx(100.0)
    np.save(tmp_path / "d.npy", np.column_stack([s.time, s.intensity]))
    np.savez(tmp_path / "d.npz", time=s.time, intensity=s.intensity)
    import xarray as xr

    xr.Dataset({"intensity": ("time", s.intensity)}, coords={"time": s.time}).to_netcdf(
        tmp_path / "d.nc", engine="h5netcdf"
    )
    for name in ("d.npy", "d.npz", "d.nc"):
        other = load_series(tmp_path / name)
        np.testing.assert_array_equal(other.time, s.time)
        assert other.n_gaps == 1


@pytest.mark.parametrize(
    "t, x, message",
    [
        (np.r_[0.0, 2.0, 1.0, np.arange(3, 30.0)], np.zeros(30), "strictly increasing"),
        (np.arange(30.0), np.r_[np.inf, np.zeros(29)], "infinite"),
        (np.arange(5.0), np.zeros(5), "at least 16"),
        (np.arange(30.0), np.r_[np.zeros(10), np.full(20, np.nan)], "valid samples"),
    ],
)
def test_bad_series(t, x, message):
    with pytest.raises(VibinverseError, match=message):
        validate(t, x)


def test_series_too_short_or_too_slow_for_a_frequency():
    s = validate(np.arange(100) * 0.01, np.zeros(100))
    with pytest.raises(VibinverseError, match="Nyquist"):
        check_resolves(s, 60.0, "drive_frequency")
    with pytest.raises(VibinverseError, match="3 cycles"):
        check_resolves(s, 1.0, "tilt_frequency")


def test_priors_parse_transform_and_reject():
    p = parse_prior("loguniform(1e-4, 1e-1)", "k")
    for v in (2e-4, 3e-3, 0.09):
        assert p.from_unbounded(p.to_unbounded(v)) == pytest.approx(v, rel=1e-10)
    z, h = 0.3, 1e-6
    numeric = (p.from_unbounded(z + h) - p.from_unbounded(z - h)) / (2 * h)
    assert np.exp(p.log_jacobian(z)) == pytest.approx(numeric, rel=1e-6)
    assert parse_prior("truncnormal(3, 1, 0, pi)", "k").bounds == (0.0, pytest.approx(np.pi))
    for bad in ("uniform(2, 1)", "normal(0, -1)", "gauss(0, 1)", "uniform(1)"):
        with pytest.raises(VibinverseError):
            parse_prior(bad, "k")
    free = parse_free([f"{K}tilt_frequency=uniform(2, 5)"], {"free": {"noise.sigma": "loguniform(1e-3, 1)"}})
    assert set(free) == {f"{K}tilt_frequency", "noise.sigma"}


# ------------------------------------------------------------------ fits on sec. 4.2 data


def within(summary, truth, names, n_sd):
    for n in names:
        p = summary["parameters"][n]
        assert abs(p["map"] - truth[n]) <= n_sd * p["sd"], (n, p, truth[n])


def test_map_recovers_the_frame_and_its_sd_matches_the_cramer_rao_bound():
    prob = frame_problem(SNR10)
    summary = run(prob, "map").summary()
    truth = prob.truth()
    within(
        summary,
        truth,
        [K + n for n in ("tilt_frequency", "tilt_damping_ratio", "drive_frequency", "drive_amplitude")],
        3,
    )
    crlb = crlb_sd(prob.model, truth, [K + "drive_frequency", K + "drive_amplitude", K + "drive_phase"])
    assert summary["parameters"][K + "drive_frequency"]["sd"] / crlb[K + "drive_frequency"] == pytest.approx(
        1.0, abs=0.5
    )
    assert summary["diagnostics"]["drive_detected"] and summary["diagnostics"]["resonance_detected"]


def test_mcmc_intervals_contain_the_truth(tmp_path):
    prob = frame_problem(SNR10)
    summary = run(prob, "mcmc", max_steps=1500, progress=False, backend=tmp_path / "c.h5", seed=1).summary()
    truth = prob.truth()
    for n in ("tilt_frequency", "tilt_damping_ratio", "drive_frequency", "drive_amplitude"):
        p = summary["parameters"][K + n]
        assert p["q05"] <= truth[K + n] <= p["q95"], (n, p)
    crlb = crlb_sd(prob.model, truth, [K + "drive_frequency", K + "drive_amplitude", K + "drive_phase"])
    assert summary["parameters"][K + "drive_frequency"]["sd"] <= 1.5 * crlb[K + "drive_frequency"]


def test_casadi_objective_equals_the_numpy_posterior_and_its_map_agrees():
    from vibinverse.models.frame_casadi import CasadiFrameObjective

    prob = frame_problem(SNR10, gaps=0.05)
    obj = CasadiFrameObjective(prob)
    z0 = prob.space.to_z(prob.truth())
    rng = np.random.default_rng(0)
    for dz in (0.0, 0.02, 0.1):
        z = z0 + dz * rng.normal(size=z0.size)
        assert obj(z) == pytest.approx(-prob.log_posterior(z), rel=1e-10)
    cas = run(prob, "casadi").summary()
    scipy_map = run(prob, "map").summary()
    assert cas["method"] == "casadi"
    for n in (K + "tilt_frequency", K + "drive_frequency", K + "drive_amplitude"):
        a, b = cas["parameters"][n], scipy_map["parameters"][n]
        assert abs(a["map"] - b["map"]) < 0.1 * b["sd"]
        assert a["sd"] == pytest.approx(b["sd"], rel=0.1)  # exact vs finite-difference Hessian


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


def test_ten_percent_gaps():
    prob = frame_problem(SNR10, gaps=0.1)
    assert 0.08 < prob.series.n_gaps / prob.series.time.size < 0.12
    summary = run(prob, "map").summary()
    within(summary, prob.truth(), [K + "tilt_frequency", K + "drive_frequency", K + "drive_amplitude"], 3)


def test_drive_line_near_nyquist():
    # far above the 3.46 Hz resonance the tilt response falls as (3.46/95)^2: a 4 cm drive and low
    # sensor noise keep the line detectable (a weak one is reported as not detected, tested below)
    prob = frame_problem(
        "noise.sigma=0.05", "surfaces.roof.motion.drive_frequency=[95.0]", "surfaces.roof.motion.drive_amplitude=[0.04]"
    )
    summary = run(prob, "map").summary()
    assert summary["diagnostics"]["drive_detected"]
    p = summary["parameters"][K + "drive_frequency"]
    assert abs(p["map"] - 95.0) <= 3 * p["sd"]


def test_weak_line_is_not_reported_as_a_detection():
    prob = frame_problem(
        SNR10, "surfaces.roof.motion.drive_frequency=[95.0]", "surfaces.roof.motion.drive_amplitude=[0.01]"
    )  # line SNR ~1
    summary = run(prob, "map").summary()
    assert not summary["diagnostics"]["drive_detected"]


def test_noise_only_series_reports_no_detection():
    prob = frame_problem(
        "surfaces.roof.motion.drive_amplitude=[0.0]", "surfaces.roof.motion.noise_rms=0", "noise.sigma=0.05"
    )
    summary = run(prob, "map").summary()
    assert not summary["diagnostics"]["drive_detected"]
    assert not summary["diagnostics"]["resonance_detected"]


# ------------------------------------------------------------------ CLI: fit, resume, report


def run_cli(*args, **kw):
    return subprocess.run([sys.executable, "-m", "vibinverse", *args], capture_output=True, text=True, **kw)


@pytest.fixture(scope="module")
def short_data(tmp_path_factory):
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
        str(d / "data.csv"),
    )
    assert r.returncode == 0, r.stderr
    return d


def fit_args(d, name, *extra, steps=400):
    return (
        "fit",
        str(d / "data.csv"),
        "--scene",
        str(SCENES / "roof_frame.toml"),
        "--method",
        "mcmc",
        "--max-steps",
        str(steps),
        "--no-progress",
        "-o",
        str(d / f"{name}.nc"),
        "--summary",
        str(d / f"{name}.json"),
        *extra,
    )


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
    assert not (d / "cut.nc").exists()
    with h5py.File(d / "cut.chain.h5", "r") as f:
        assert 0 < f["mcmc"].attrs["iteration"] < steps  # really interrupted mid-run
    resumed = run_cli(*fit_args(d, "cut", "--resume", steps=steps))
    assert resumed.returncode == 0, resumed.stderr
    with h5py.File(d / "full800.chain.h5", "r") as a, h5py.File(d / "cut.chain.h5", "r") as b:
        assert a["mcmc"].attrs["iteration"] == b["mcmc"].attrs["iteration"] == steps
        np.testing.assert_array_equal(a["mcmc/chain"][...], b["mcmc/chain"][...])
    assert json.loads((d / "cut.json").read_text())["diagnostics"]["n_steps"] == steps


def test_report_renders_table_figures_and_warnings(short_data):
    d = short_data
    if not (d / "full.nc").exists():
        assert run_cli(*fit_args(d, "full")).returncode == 0
    r = run_cli("report", str(d / "full.nc"), "-o", str(d / "rep"))
    assert r.returncode == 0, r.stderr
    html = (d / "rep" / "report.html").read_text()
    assert "<table>" in html and html.count("data:image/png;base64,") >= 4
    assert "not converged" in html  # 400 steps is far from 50 tau: the report must say so


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


def test_fast_likelihood_components_equal_the_forward_models_linear_frame():
    """The likelihood scales a unit frame's tilt rows and writes the ZOH in closed form; the
    forward model's `linearize`, `steady_state` and matrix-exponential ZOH are the oracle."""
    from scipy.linalg import expm

    from forward.motion.frame import Drive, FrameParameters, linearize, steady_state

    prob = frame_problem(SNR10)
    like = prob.model
    values = {**prob.truth(), K + "tilt_frequency": 3.1, K + "tilt_damping_ratio": 0.05, K + "drive_phase": 0.4}
    c = like.components(values)
    m = like.base["surfaces"][like.roof]["motion"]
    params = FrameParameters.from_modal(like.lx, like.ly, like.mass, tilt=(3.1, 0.05), lateral=(4.0, 0.004))
    lin = linearize(params)
    plane = np.array(m["drive_plane"], dtype=float)
    drive = Drive(
        np.array([values[K + "drive_frequency"]]),
        np.array([values[K + "drive_amplitude"]]),
        int(m.get("drive_corner", 0)),
        plane[0],
        plane[1],
        np.array([0.4]),
    )
    q, _ = steady_state(lin, drive, like.t, coords=slice(3, 5))
    gx, gy = -q[:, 1], q[:, 0]
    hs = like.hess
    mean = (
        like.x0
        + like.jac[0] * gx
        + like.jac[1] * gy
        + 0.5 * (hs[0, 0] * gx**2 + 2 * hs[0, 1] * gx * gy + hs[1, 1] * gy**2)
    )
    assert np.abs(c.mean - mean).max() <= 1e-12 * np.ptp(mean)
    aug = np.zeros((3, 3))
    i = 4 if abs(like.jac[0]) > 0 else 3
    aug[0, 1] = like.dt
    aug[1, 0], aug[1, 1], aug[1, 2] = (
        -lin.stiffness[i] / lin.mass[i] * like.dt,
        -lin.damping[i] / lin.mass[i] * like.dt,
        like.dt / lin.mass[i],
    )
    assert np.abs(c.phi[:2, :2] - expm(aug)[:2, :2]).max() < 1e-12


def test_mode_zoh_closed_form_equals_the_matrix_exponential():
    from scipy.linalg import expm

    from forward.motion.frame import mode_zoh

    for zeta in (0.0, 1e-6, 0.0138, 0.5, 0.9, 0.95, 1.0, 2.0):  # above 0.9: the matrix exponential path
        for f, dt in ((3.46, 1 / 200), (99.0, 1 / 200), (0.1, 1e-3)):
            w, mass = 2 * math.pi * f, 2.0
            k, c = mass * w * w, 2 * zeta * w * mass
            aug = np.zeros((3, 3))
            aug[0, 1], aug[1, 0], aug[1, 1], aug[1, 2] = dt, -k / mass * dt, -c / mass * dt, dt / mass
            ref = expm(aug)
            phi, gam = mode_zoh(k, c, mass, dt)
            assert np.abs(phi - ref[:2, :2]).max() <= 1e-12 * np.abs(ref[:2, :2]).max()
            assert np.abs(gam - ref[:2, 2]).max() <= 1e-12 * np.abs(ref[:2, 2]).max()


def test_frame_geometry_is_fittable_through_the_observation():
    """A geometry value re-forms the observation: the likelihood equals one built from a scene with
    that value, and a MAP with the view angle free recovers it (the casadi MAP, which holds the
    observation fixed, hands over to the scipy MAP)."""
    import copy

    from vibinverse.models.frame import FrameModel
    from vibinverse.priors import Prior
    from vibinverse.scene_keys import set_value

    problem = frame_problem(SNR10, "footprint.resolution=32")
    table = problem.model.base
    view = float(load_scene(SCENES / "roof_frame.toml", [])[0].sensor.inclination)
    other = copy.deepcopy(table)
    set_value(other, "sensor.inclination", view + 0.004)
    ref = FrameModel(other, problem.series).log_likelihood({})
    assert problem.model.log_likelihood({"sensor.inclination": view + 0.004}) == pytest.approx(ref, rel=1e-12)
    assert problem.model.log_likelihood({}) != pytest.approx(ref, rel=1e-6)
    free = {
        K + "drive_amplitude": Prior("uniform", (0.0, 0.05)),
        "sensor.inclination": Prior("normal", (view, 0.01)),
        "noise.sigma": Prior("loguniform", (0.01, 10.0)),
    }
    summary = run(Posterior(build_model(table, problem.series), free), "casadi", progress=False).summary()
    p = summary["parameters"]["sensor.inclination"]
    assert summary["method"] == "map" and abs(p["median"] - view) < 3 * p["sd"]


def test_compiled_drive_mean_equals_the_complex_exponential_on_a_long_series():
    """The drive mean's kernel (per-sample rotations re-anchored every 64 samples) against
    exp(i w t) in numpy: three lines up to 0.98 Nyquist over 200 000 samples."""
    from vibinverse.models.frame import FrameModel

    problem = frame_problem(SNR10, "footprint.resolution=32")
    t = np.arange(200_000) * 0.005 + 3.0
    like = FrameModel(problem.model.base, validate(t, np.zeros(t.size), "grid"))
    assert like._grid is not None
    w = 2 * np.pi * np.array([10.0, 37.3, 98.0])
    qx, qy = np.array([1e-5 + 2e-5j, -3e-6j, 4e-6]), np.array([2e-6 - 1e-6j, 5e-6, 1e-6 + 1e-6j])
    fast = like._drive_mean(w, qx, qy, like.x0, like.jac, like.hess)
    like._grid = None
    slow = like._drive_mean(w, qx, qy, like.x0, like.jac, like.hess)
    # both round the phase w t (up to 6e5 rad here) to ~|w t| eps: the bound is that, not 1e-12
    phase_rounding = np.finfo(float).eps * w.max() * np.abs(t).max()
    assert np.abs(fast - slow).max() <= 4 * phase_rounding * np.ptp(slow)
    short = slice(0, 4000)  # where w t is small, the two agree to the level's ulps
    assert np.abs(fast[short] - slow[short]).max() <= 1e-10 * np.ptp(slow)


def test_bound_warning_is_for_a_posterior_cut_by_its_prior_not_for_a_wide_prior():
    """A 1 mm amplitude under uniform(0, 0.1) and sigma under loguniform(1e-7, 4) sit far from
    their bounds in posterior sds (and, for sigma, in the prior's log scale); a posterior piled
    against 0 does not."""
    from vibinverse.report import warnings_for

    def summary(median, q05, q95, prior, bounds):
        p = {"median": median, "q05": q05, "q95": q95, "prior": prior, "prior_bounds": bounds}
        return {"diagnostics": {}, "parameters": {"x": p}}

    assert warnings_for(summary(0.00099, 0.00098, 0.001, "uniform(0, 0.1)", [0.0, 0.1]), None, ["x"]) == []
    assert warnings_for(summary(0.0467, 0.0446, 0.0492, "loguniform(7e-08, 4.2)", [7e-8, 4.2]), None, ["x"]) == []
    cut = warnings_for(summary(0.0005, 0.00003, 0.0015, "uniform(0, 0.1)", [0.0, 0.1]), None, ["x"])
    assert len(cut) == 1 and "sits at a bound" in cut[0]
    wide = warnings_for(summary(0.5, 0.05, 0.95, "uniform(0, 1)", [0.0, 1.0]), None, ["x"])
    assert len(wide) == 1 and "not informed" in wide[0]
